use warp_lang as wp;
use wp::prelude::*;

const TN: usize = 12;

// Tiles of complex values (`Vec2`, `DVec2`) and the FFTs: each misuse an error at its call.
#[wp::kernel]
fn scalar_tile(a: Array<f32, 2>) {
    let mut x = tile_load::<4, 8>(a, (0, 0));
    tile_fft(&mut x);
}

#[wp::kernel]
fn not_a_power_of_two(a: Array<Vec2, 2>) {
    let mut x = tile_load::<4, 6>(a, (0, 0));
    tile_fft(&mut x);
}

#[wp::kernel]
fn one_dim(a: Array<Vec2>) {
    let mut x = tile_load::<8>(a, 0);
    tile_ifft(&mut x);
}

#[wp::kernel]
fn not_in_place(a: Array<Vec2, 2>) {
    let x = tile_load::<4, 8>(a, (0, 0));
    tile_fft(x);
}

#[wp::kernel]
fn not_mutable(a: Array<Vec2, 2>) {
    let x = tile_load::<4, 8>(a, (0, 0));
    tile_fft(&mut x);
}

#[wp::kernel]
fn reduce_vectors(a: Array<Vec2, 2>, out: Array<Vec2>) {
    let x = tile_load::<4, 8>(a, (0, 0));
    let s = tile_sum(x);
}

#[wp::kernel]
fn map_vectors(a: Array<Vec2, 2>) {
    let x = tile_load::<4, 8>(a, (0, 0));
    let s = tile_map(length, x);
}

#[wp::kernel]
fn matmul_vectors(a: Array<Vec2, 2>) {
    let x = tile_load::<4, 4>(a, (0, 0));
    let s = tile_matmul(x, x);
}

#[wp::kernel]
fn multiply_vector_tiles(a: Array<Vec2, 2>) {
    let x = tile_load::<4, 4>(a, (0, 0));
    let s = x * x;
}

#[wp::kernel]
fn vec3_tile(a: Array<Vec3, 2>) {
    let x = tile_load::<4, 4>(a, (0, 0));
}

// A named const only rustc can check (TN is 12).
#[wp::kernel]
fn named_length(a: Array<Vec2, 2>) {
    let mut x = tile_load::<4, TN>(a, (0, 0));
    tile_fft(&mut x);
}

fn main() {}
