use warp_lang as wp;
use wp::prelude::*;

// The windows' shape rules (`tile_view`, `tile_assign` and the in-place forms), each an error
// at its call: a window larger than the tile, or a literal offset that puts it outside.
#[wp::kernel]
fn view_too_large(a: Array<f32, 2>) {
    let t = tile_load::<4, 6>(a, (0, 0));
    let v = tile_view::<5, 2>(t, (0, 0));
}

#[wp::kernel]
fn view_past_the_end(a: Array<f32, 2>) {
    let t = tile_load::<4, 6>(a, (0, 0));
    let v = tile_view::<2, 3>(t, (3, 0));
}

#[wp::kernel]
fn view_negative_offset(a: Array<f32, 2>) {
    let t = tile_load::<4, 6>(a, (0, 0));
    let v = tile_view(t, (0, -1), (2, 2));
}

#[wp::kernel]
fn view_without_shape(a: Array<f32, 2>) {
    let t = tile_load::<4, 6>(a, (0, 0));
    let v = tile_view(t, (1, 2));
}

#[wp::kernel]
fn view_rank(a: Array<f32, 2>) {
    let t = tile_load::<4, 6>(a, (0, 0));
    let v = tile_view::<2>(t, (1, 2));
}

#[wp::kernel]
fn assign_too_large(a: Array<f32, 2>) {
    let s = tile_load::<4, 7>(a, (0, 0));
    let mut d = tile_load::<4, 6>(a, (0, 0));
    tile_assign(&mut d, s, (0, 0));
}

#[wp::kernel]
fn add_past_the_end(a: Array<f32, 2>) {
    let s = tile_load::<2, 3>(a, (0, 0));
    let mut d = tile_load::<4, 6>(a, (0, 0));
    tile_add_inplace(&mut d, s, (0, 4));
}

#[wp::kernel]
fn assign_elements_differ(a: Array<f32, 2>, b: Array<i32, 2>) {
    let s = tile_load::<2, 3>(b, (0, 0));
    let mut d = tile_load::<4, 6>(a, (0, 0));
    tile_assign(&mut d, s, (0, 0));
}

#[wp::kernel]
fn assign_ranks_differ(a: Array<f32, 2>, b: Array<f32>) {
    let s = tile_load::<3>(b, 0);
    let mut d = tile_load::<4, 6>(a, (0, 0));
    tile_sub_inplace(&mut d, s, (0, 0));
}

#[wp::kernel]
fn bitwise_of_floats(a: Array<f32, 2>) {
    let s = tile_load::<2, 3>(a, (0, 0));
    let mut d = tile_load::<4, 6>(a, (0, 0));
    tile_bit_xor_inplace(&mut d, s, (0, 0));
}

#[wp::kernel]
fn assign_needs_mut(a: Array<f32, 2>) {
    let s = tile_load::<2, 3>(a, (0, 0));
    let d = tile_load::<4, 6>(a, (0, 0));
    tile_assign(&mut d, s, (0, 0));
}

fn main() {}
