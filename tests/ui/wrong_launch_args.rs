use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn scale(v: Array<Vec3>, s: f32) {
    let i = tid();
    v[i] = v[i] * s;
}

fn main() -> wp::Result<()> {
    let dev = wp::cpu();
    let floats = wp::Array::<f32>::zeros(4, &dev)?;
    let vecs = wp::Array::<Vec3>::zeros(4, &dev)?;
    // An Array<f32> where the kernel takes Array<Vec3>.
    wp::launch(scale, 4, (&floats, 2.0), &dev)?;
    // An f64 where the kernel takes f32.
    wp::launch(scale, 4, (&vecs, 2.0f64), &dev)?;
    // Too few arguments.
    wp::launch(scale, 4, (&vecs,), &dev)?;
    // A 2-D array where the kernel takes a 1-D one.
    let grid = wp::Array::<Vec3, 2>::zeros([2, 2], &dev)?;
    wp::launch(scale, 4, (&grid, 2.0), &dev)?;
    Ok(())
}
