//! Port of Warp's `warp/tests/test_fixedarray.py`: fixed-size arrays made in kernels and funcs
//! (Warp's in-kernel `wp.zeros(shape=.., dtype=..)`, here Rust's `[[0i32; 3]; 2]`), filled by
//! nested loops over their lengths, passed to and returned from funcs, and launched inside a
//! captured conditional. Warp's kernels check themselves with `wp.expect_eq`; so do these (a
//! failed expectation fails the launch, so each `unwrap` is the assertion). All values are
//! integers or exact, so every comparison is exact, as in Warp.
//!
//! Ported (Warp test -> here): `test_zeros` -> [`zeros_2d`], `test_func_arg` ->
//! [`func_arg`], `test_func_return` -> [`func_return`], `test_func_return_annotation` ->
//! [`func_return_annotation`], `test_capture_if` -> [`capture_if`] (Warp runs it on CUDA only;
//! here the CPU records the conditional too, so it runs on both),
//! `test_fixedarray_array_polymorphism` -> [`array_polymorphism`] (adapted, below).
//!
//! Adapted: Warp passes a fixed array to a func by reference (its arrays are references), so
//! `test_func_arg_func` fills the caller's array; a Rust array is a value, and the func takes
//! `&mut [[i32; 3]; 2]` to do the same. Warp's `arr.shape[0]`, `arr.shape[1]` are `a.len()`
//! and `a[0].len()`. `test_fixedarray_array_polymorphism` passes fixed arrays to funcs that
//! take a `wp.array` (concrete dtype, and `wp.array[Any]`); here the funcs take the local
//! array type, one func per element type, since generics are over float types only (`int`
//! and `vec3` instances of one generic func cannot be written).
//!
//! Not ported: the row view's `r0.shape[1] == 0` and the slice `arr[:2, 1:]` of `test_zeros`
//! (a row is a copied `[i32; 3]` here, whose `len()` is checked; there is no slicing of local
//! arrays); `test_func_struct` (structs as elements of a local array are not supported yet:
//! the kernels chapter lists them under "Not yet"); `test_fixedarray_ptr` (reinterprets the
//! array's address as an array of `vec2`: there are no pointers or `wp.array(ptr=..)` in
//! kernels); `test_error_invalid_func_return_annotation` and `test_error_runtime_shape`
//! (Warp's code-generation errors: here a mismatched return type and a non-constant length
//! are rustc errors at `cargo build`, which the runtime suite cannot run).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    zeros_2d,
    func_arg,
    func_return,
    func_return_annotation,
    capture_if,
    array_polymorphism,
);

#[wp::kernel]
fn k_zeros() {
    let mut a = [[0i32; 3]; 2];
    for i in 0..a.len() {
        for j in 0..a[0].len() {
            a[i][j] = (i * a[0].len() + j) as i32;
        }
    }
    expect_eq(a[0][0], 0);
    expect_eq(a[0][1], 1);
    expect_eq(a[0][2], 2);
    expect_eq(a[1][0], 3);
    expect_eq(a[1][1], 4);
    expect_eq(a[1][2], 5);

    let r0 = a[0];
    expect_eq(r0.len() as i32, 3);
    expect_eq(r0[0], 0);
    expect_eq(r0[1], 1);
    expect_eq(r0[2], 2);

    let r1 = a[1];
    expect_eq(r1.len() as i32, 3);
    expect_eq(r1[0], 3);
    expect_eq(r1[1], 4);
    expect_eq(r1[2], 5);
}

fn zeros_2d(dev: &wp::Device) {
    wp::launch(k_zeros, 1, (), dev).unwrap();
}

#[wp::func]
fn fill_rows(a: &mut [[i32; 3]; 2]) {
    for i in 0..2 {
        for j in 0..3 {
            a[i][j] = (i * 3 + j) as i32;
        }
    }
}

#[wp::kernel]
fn k_func_arg() {
    let mut a = [[0i32; 3]; 2];
    fill_rows(&mut a);
    expect_eq(a[0][0], 0);
    expect_eq(a[0][1], 1);
    expect_eq(a[0][2], 2);
    expect_eq(a[1][0], 3);
    expect_eq(a[1][1], 4);
    expect_eq(a[1][2], 5);
}

fn func_arg(dev: &wp::Device) {
    wp::launch(k_func_arg, 1, (), dev).unwrap();
}

#[wp::func]
fn func_return_f() -> [i32; 2] {
    let mut a = [0i32; 2];
    for i in 0..a.len() {
        a[i] = i as i32;
    }
    a
}

#[wp::kernel]
fn k_func_return() {
    let a: [i32; 2] = func_return_f();
    expect_eq(a[0], 0);
    expect_eq(a[1], 1);
}

fn func_return(dev: &wp::Device) {
    wp::launch(k_func_return, 1, (), dev).unwrap();
}

#[wp::func]
fn func_return_annotation_f() -> [[i32; 3]; 2] {
    let mut a = [[0i32; 3]; 2];
    for i in 0..a.len() {
        for j in 0..a[0].len() {
            a[i][j] = (i * a[0].len() + j) as i32;
        }
    }
    a
}

#[wp::kernel]
fn k_func_return_annotation() {
    let a: [[i32; 3]; 2] = func_return_annotation_f();
    expect_eq(a[0][0], 0);
    expect_eq(a[0][1], 1);
    expect_eq(a[0][2], 2);
    expect_eq(a[1][0], 3);
    expect_eq(a[1][1], 4);
    expect_eq(a[1][2], 5);
}

fn func_return_annotation(dev: &wp::Device) {
    wp::launch(k_func_return_annotation, 1, (), dev).unwrap();
}

/// `test_capture_if_kernel`: `k_zeros`'s body, which also counts its threads so that the port
/// can see the branch ran (Warp's test only checks that nothing failed).
#[wp::kernel]
fn k_capture_if(count: Array<i32>) {
    let mut a = [[0i32; 3]; 2];
    for i in 0..a.len() {
        for j in 0..a[0].len() {
            a[i][j] = (i * a[0].len() + j) as i32;
        }
    }
    expect_eq(a[0][0], 0);
    expect_eq(a[0][1], 1);
    expect_eq(a[0][2], 2);
    expect_eq(a[1][0], 3);
    expect_eq(a[1][1], 4);
    expect_eq(a[1][2], 5);
    atomic_add(count, 0, 1);
}

fn capture_if(dev: &wp::Device) {
    // A graph cannot compile a kernel at its first launch: load it first.
    wp::load(&[wp::kernel_info(k_capture_if)], dev).unwrap();
    let cond = arr(&[1i32], dev);
    let count = zeros::<i32, 1>(1, dev);
    let graph = wp::capture(dev, || {
        wp::capture_if(
            &cond,
            || wp::launch(k_capture_if, 512, (&count,), dev),
            || Ok(()),
        )
    })
    .unwrap();
    graph.launch().unwrap();
    wp::synchronize().unwrap();
    assert_eq!(
        host(&count),
        vec![512],
        "the true branch ran once, 512 threads"
    );
}

#[wp::func]
fn first_vec2(a: [Vec2; 3]) -> Vec2 {
    a[0]
}

#[wp::func]
fn first_i32(a: [i32; 5]) -> i32 {
    a[0]
}

#[wp::func]
fn first_f32(a: [f32; 4]) -> f32 {
    a[0]
}

#[wp::func]
fn first_vec3(a: [Vec3; 2]) -> Vec3 {
    a[0]
}

#[wp::kernel]
fn k_array_polymorphism() {
    let mut fixed_arr_vec2 = [Vec2::ZERO; 3];
    fixed_arr_vec2[0] = vec2(1.0, 2.0);
    expect_eq(first_vec2(fixed_arr_vec2), vec2(1.0, 2.0));

    let mut fixed_arr_int = [0i32; 5];
    fixed_arr_int[0] = 42;
    expect_eq(first_i32(fixed_arr_int), 42);

    let mut fixed_arr_float = [0.0f32; 4];
    // Warp stores 3.14, which clippy reads as an approximation of pi; any f32 does.
    fixed_arr_float[0] = 3.25;
    expect_eq(first_f32(fixed_arr_float), 3.25);

    let mut fixed_arr_vec3 = [Vec3::ZERO; 2];
    fixed_arr_vec3[0] = vec3(1.0, 2.0, 3.0);
    expect_eq(first_vec3(fixed_arr_vec3), vec3(1.0, 2.0, 3.0));
}

fn array_polymorphism(dev: &wp::Device) {
    wp::launch(k_array_polymorphism, 1, (), dev).unwrap();
}
