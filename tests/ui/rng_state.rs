use warp_lang as wp;
use wp::prelude::*;

// The RNG advances its state in place: the argument is `&mut` of an assignable `u32` place.
#[wp::kernel]
fn k(a: Array<f32>, seeds: Array<i32>) {
    let i = tid();
    let s = rand_init(seeds[i]);
    let mut t = rand_init(seeds[i], i as i32);
    let mut f = 1.5;
    let x = randf(t);
    let y = randf(&t);
    let z = randf(&mut s);
    let w = randf(&mut (t + 1));
    let v = randn(&mut f);
    let r = randi(&mut t, 0);
    let q = rand_init(i);
    let o = rand_init(1, 2, 3);
    let n = pnoise(t, vec2(0.5, 0.5), 2, 3, 4);
    a[i] = x + y + z + w + v;
}

fn main() {}
