use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn sample_vec(vol: Volume<Vec3>, q: Array<Vec3>, out: Array<Vec3>) {
    let i = tid();
    out[i] = volume_sample(vol, q[i], VOLUME_LINEAR);
}

// An integer grid is not interpolated; an index grid holds no values; the value type is the
// volume's; a volume holds one of the volume value types.
#[wp::kernel]
fn misuse(a: Volume<i32>, b: Volume<VoxelIndex>, c: Volume<f32>, q: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    let x = volume_sample(a, q[i], VOLUME_LINEAR);
    let y = volume_sample(b, q[i], VOLUME_CLOSEST);
    let z: Vec3 = volume_sample(c, q[i], VOLUME_LINEAR);
    volume_store(c, 0, 0, 0, q[i]);
}

#[wp::kernel]
fn bad_element(v: Volume<u8>) {}

fn main() -> wp::Result<()> {
    let dev = wp::cpu();
    let map = wp::VolumeMap::uniform(1.0, [0.0; 3]);
    let floats = wp::Volume::allocate_by_tiles(&[IVec3::ZERO], 0.0f32, &map, &dev)?;
    let q = wp::Array::from_slice(&[Vec3::ZERO], &dev)?;
    // A float grid where the kernel declares a Vec3 grid.
    wp::launch(sample_vec, 1, (&floats, &q, &q), &dev)?;
    Ok(())
}
