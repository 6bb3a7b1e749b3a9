use warp_lang as wp;
use wp::prelude::*;

// `tile_map` with user #[func]s: what rustc finds against the func's signature, at the
// func's path in the call.

#[wp::func]
fn two(x: f32, y: f32) -> f32 {
    x * y
}

#[wp::func]
fn to_int(x: f32) -> i32 {
    x as i32
}

#[wp::func]
fn of_vec(v: Vec3) -> f32 {
    v.x
}

fn plain_rust(x: f32) -> f32 {
    x
}

// Two parameters, one tile.
#[wp::kernel]
fn wrong_arity(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map(two, t);
}

// Returns i32, but the result is not annotated: the tile would be f32.
#[wp::kernel]
fn unannotated_other_result(a: Array<f32>, out: Array<i32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map(to_int, t);
}

// Takes a vector.
#[wp::kernel]
fn vector_param(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map(of_vec, t);
}

// Not a #[func].
#[wp::kernel]
fn not_a_func(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map(plain_rust, t);
}

// `tile_reduce(f, t)` takes `f(T, T) -> T`: one parameter is too few, an `i32` result is not
// the `f32` element, and a plain Rust fn is no #[func].
#[wp::kernel]
fn reduce_wrong_funcs(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_reduce(to_int, t);
    let v = tile_reduce(plain_rust, t);
}

#[wp::func]
fn unary(x: f32) -> f32 {
    x
}

#[wp::kernel]
fn reduce_unary(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_reduce(unary, t);
}

fn main() {}
