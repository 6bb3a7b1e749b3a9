use warp_lang as wp;
use wp::prelude::*;

// Rank and shape errors of the 3-D and 4-D tiles, each at its call.
#[wp::kernel]
fn store_rank3_into_2d(a: Array<f32, 3>, b: Array<f32, 2>) {
    let t = tile_load::<2, 3, 4>(a, (0, 0, 0));
    tile_store(b, t, (0, 0));
}

#[wp::kernel]
fn load_offsets_arity(a: Array<f32, 3>) {
    let t = tile_load::<2, 3, 4>(a, (0, 0));
}

#[wp::kernel]
fn store_offsets_arity(a: Array<f32, 4>) {
    let t = tile_zeros::<f32, 1, 2, 3, 4>();
    tile_store(a, t, (0, 0, 0));
}

#[wp::kernel]
fn load_rank4_from_3d(a: Array<f32, 3>) {
    let t = tile_load(a, (2, 2, 2, 2), (0, 0, 0, 0));
}

#[wp::kernel]
fn reshape_size(a: Array<f32, 3>) {
    let t = tile_load::<2, 3, 4>(a, (0, 0, 0));
    let r: Tile<f32, 5, 5> = tile_reshape(t);
}

#[wp::kernel]
fn index_arity(a: Array<f32, 3>, o: Array<f32>) {
    let t = tile_load::<2, 3, 4>(a, (0, 0, 0));
    o[0] = t[(1, 2)];
}

// What stays rank 1-2: matrix products, transposes, broadcasts and windows.
#[wp::kernel]
fn matmul_rank3(a: Array<f32, 3>) {
    let t = tile_load::<2, 2, 2>(a, (0, 0, 0));
    let p = tile_matmul(t, t);
}

#[wp::kernel]
fn transpose_rank3(a: Array<f32, 3>) {
    let t = tile_load::<2, 2, 2>(a, (0, 0, 0));
    let p = tile_transpose(t);
}

#[wp::kernel]
fn broadcast_to_rank3(a: Array<f32>) {
    let t = tile_load::<4>(a, 0);
    let b = tile_broadcast::<2, 3, 4>(t);
}

#[wp::kernel]
fn view_rank3(a: Array<f32, 3>) {
    let t = tile_load::<2, 3, 4>(a, (0, 0, 0));
    let v = tile_view::<3, 4>(t, (1,));
}

fn main() {}
