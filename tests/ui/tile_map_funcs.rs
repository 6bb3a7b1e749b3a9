use warp_lang as wp;
use wp::prelude::*;

// `tile_map` with user #[func]s: what the kernel macro itself refuses.

#[wp::func]
fn double(x: f32) -> f32 {
    x * 2.0
}

// A local variable is no function.
#[wp::kernel]
fn local_var(a: Array<f32>) {
    let g = 2.0f32;
    let t = tile_load::<8>(a, 0);
    let u = tile_map(g, t);
}

// A module-level constant is no function.
const SCALE: f32 = 2.0;

#[wp::kernel]
fn constant(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map(SCALE, t);
}

// `tile_reduce` takes a builtin, an operator or a #[func] by name: not a local variable, a
// constant or a call.
#[wp::kernel]
fn reduce_with_local(a: Array<f32>) {
    let plus = 1.0f32;
    let t = tile_load::<8>(a, 0);
    let s = tile_reduce(plus, t);
    let u = tile_reduce(SCALE, t);
    let v = tile_reduce(double(1.0), t);
    let w = tile_reduce(sin, t);
}

// The turbofish names the result's element, not a shape, and only for a func.
#[wp::kernel]
fn fish_dims(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map::<f32, 8>(double, t);
    let v = tile_map::<f64>(sin, t);
}

// Tiles hold no `bool`s.
#[wp::kernel]
fn bool_result(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map::<bool>(double, t);
}

// More than two tiles take a #[func]; more than eight are too many.
#[wp::kernel]
fn arities(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map(add, t, t, t);
    let v = tile_map(max, t, t, t);
    let w = tile_map(double, t, t, t, t, t, t, t, t, t);
}

// After the function comes a tile (it gives the shape); later arguments may be tiles or
// integer or float scalars, broadcast to every element.
#[wp::kernel]
fn constants(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_map(mul, 2.0, t);
    let v = tile_map(max, t, true);
    let w = tile_map(mul, t, vec3(1.0, 2.0, 3.0));
}

fn main() {}
