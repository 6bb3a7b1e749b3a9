use warp_lang as wp;
use wp::prelude::*;

const TM: usize = 16;
const KB: usize = 4;

// `tile_sort`'s rules, each an error at its argument.
#[wp::kernel]
fn lengths_differ(k: Array<f32>, v: Array<i32>) {
    let mut keys = tile_load::<16>(k, 0);
    let mut vals = tile_load::<8>(v, 0);
    tile_sort(&mut keys, &mut vals);
}

#[wp::kernel]
fn two_dims(k: Array<f32, 2>, v: Array<i32, 2>) {
    let mut keys = tile_load::<4, 4>(k, (0, 0));
    let mut vals = tile_load::<4, 4>(v, (0, 0));
    tile_sort(&mut keys, &mut vals);
}

#[wp::kernel]
fn small_int_keys(k: Array<u8>, v: Array<i32>) {
    let mut keys = tile_load::<8>(k, 0);
    let mut vals = tile_load::<8>(v, 0);
    tile_sort(&mut keys, &mut vals);
}

#[wp::kernel]
fn not_mut_refs(k: Array<f32>, v: Array<i32>) {
    let mut keys = tile_load::<8>(k, 0);
    let mut vals = tile_load::<8>(v, 0);
    tile_sort(keys, &mut vals);
}

#[wp::kernel]
fn not_mutable(k: Array<f32>, v: Array<i32>) {
    let mut keys = tile_load::<8>(k, 0);
    let vals = tile_load::<8>(v, 0);
    tile_sort(&mut keys, &mut vals);
}

#[wp::kernel]
fn same_tile(k: Array<f32>) {
    let mut keys = tile_load::<8>(k, 0);
    tile_sort(&mut keys, &mut keys);
}

// Named consts the macro cannot compare: rustc does (TM is 16, KB is 4).
#[wp::kernel]
fn consts(k: Array<f32>, v: Array<i32>) {
    let mut keys = tile_load::<TM>(k, 0);
    let mut vals = tile_load::<KB>(v, 0);
    tile_sort(&mut keys, &mut vals);
}

fn main() {}
