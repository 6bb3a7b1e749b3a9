use warp_lang as wp;
use wp::prelude::*;

// f16 is a scalar: no bitwise operators, no atomic_cas/atomic_exch, no mixing with f32
// without a cast, and no f16 vectors.
#[wp::kernel]
fn k(a: Array<f16>, x: f16, y: f32) {
    let i = tid();
    let b = x & x;
    let c = x + y;
    atomic_exch(a, i, x);
    let v = Vec3::new(x, x, x);
}

// f16 is not an instance of a generic kernel's `T: Float`.
#[wp::kernel]
fn g<T: Float>(a: Array<T>, s: T) {
    let i = tid();
    a[i] = a[i] * s;
}

fn main() {
    let dev = wp::cpu();
    let a = wp::Array::<f16>::zeros(4, &dev).unwrap();
    wp::launch(g, 4, (&a, f16::ONE), &dev).unwrap();
}
