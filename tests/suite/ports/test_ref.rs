//! Port of Warp's `warp/tests/test_ref.py`: pass-by-reference func parameters (Warp's
//! `wp.ref[T]`), here `&mut T` parameters: a func writes its caller's local, array element,
//! struct field (also inside a struct array element), vector, matrix, quaternion and
//! transform lane through them, forwards them to other funcs, and assigns them by tuple
//! destructuring. Every value is exact, so comparisons are exact (Warp's
//! `assert_allclose` with its default `rtol=1e-7` on small integers).
//!
//! Ported (Warp test -> here): `test_ref_mutates_local`, `test_ref_mutates_array_element`,
//! `test_ref_mutates_struct_field`, `test_ref_simple_assignment_mutates`, `test_ref_forwarding`,
//! `test_by_value_unchanged` -> [`mutates_locals_elements_and_structs`];
//! `test_ref_tuple_unpack_assignment`, `test_ref_tuple_unpack_assignment_swaps`,
//! `test_ref_tuple_unpack_assignment_mixed_targets` -> [`tuple_unpack_assignment`];
//! `test_array_tuple_unpack_preserves_adjoint` -> [`array_tuple_unpack_preserves_adjoint`];
//! `test_ref_mutates_struct_array_field`, `test_ref_mutates_nested_struct_array_field`,
//! `test_ref_mutates_composite_struct_array_fields`,
//! `test_ref_mutates_struct_array_quat_component`,
//! `test_ref_mutates_struct_array_transform_position` -> [`struct_array_fields`];
//! `test_ref_augassign_composite_subscripts`, `test_ref_copy_from_component_is_local`,
//! `test_ref_mutates_quat_component`, `test_ref_copy_from_quat_component_is_local`,
//! `test_ref_mutates_quat_subscript`, `test_ref_mutates_transform_position_component`,
//! `test_ref_copy_from_transform_position_is_local` -> [`lanes_and_copies`];
//! `test_ref_parameter_nested_field_forwarding`, `test_ref_parameter_struct_field_forwarding`
//! -> [`field_forwarding`]; the `test_native_ref_param_adjoint_*` tests (local, array element,
//! 2-D array element, struct field, lanes, struct array components, nested struct array field)
//! -> [`adjoints_through_mut_params`].
//!
//! Adapted: Warp's native C++ snippet `native_store_double_ref` (`x = 2 y`, with a hand-written
//! adjoint) is the `#[func]` [`store_double`], whose adjoint is generated: the gradient tests
//! check the same values and gradients through it. Warp's run-time subscripts `v[0]`,
//! `m[1, 2]`, `q[2]` are glam's lanes `v.x`, `m.z_axis.y` (row 1, column 2), `q.z`. Warp
//! refuses backward through a `wp.ref` func (`test_ref_backward_enabled_kernel_raises`); here
//! reverse mode goes through `&mut` parameters, so the port's [`backward_through_mut_param`]
//! checks the gradient instead. Tuple-unpack assignment `x, y = a, b` is Rust's destructuring
//! assignment `(*x, *y) = (a, b)` (added to the language for this port); a local it binds is
//! declared first (`let mut old = 0.0;`), since `let old;` without a value is not in the
//! kernel language.
//!
//! Not ported: `test_ref_mutates_negative_subscripts` (negative indices, `v[-1]`: not in Rust);
//! the `test_native_ref_param_adjoint_array_slice` and `..._nested_slice` cases (an element of
//! an in-kernel view lent as `&mut`: views cannot be passed to funcs yet, nor lent);
//! `test_native_ref_param_alias` and the `wp.address_of` tests (native snippets and raw
//! addresses: not in the language); the Python-side tests of the `wp.ref` type object and the
//! code-generation rejections (a literal, a func's result, a constant local lent by reference,
//! refness-only overloads): here rustc and the macro reject those at `cargo build`, which the
//! runtime suite cannot run (the trybuild tests under `tests/ui` hold such cases).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    mutates_locals_elements_and_structs,
    tuple_unpack_assignment,
    array_tuple_unpack_preserves_adjoint,
    struct_array_fields,
    lanes_and_copies,
    field_forwarding,
    adjoints_through_mut_params,
    backward_through_mut_param,
);

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Counter {
    value: i32,
}

#[wp::func]
fn increment_ref(x: &mut i32) {
    *x += 1;
}

#[wp::func]
fn add_to_ref(x: &mut f32, delta: f32) {
    *x += delta;
}

#[wp::func]
fn increment_counter(c: &mut Counter) {
    c.value += 1;
}

#[wp::func]
fn double_ref(x: &mut f32) {
    *x = *x * 2.0;
}

#[wp::func]
fn outer_ref(x: &mut i32) {
    increment_ref(x);
}

#[wp::func]
fn by_value_increment(mut x: i32) -> i32 {
    x += 1;
    x
}

#[wp::kernel]
fn k_mutates(arr_f: Array<f32>, ints: Array<i32>, floats: Array<f32>) {
    let i = tid();
    add_to_ref(&mut arr_f[i], 10.0);
    if i == 0 {
        let mut val = 0i32;
        increment_ref(&mut val);
        ints[0] = val;

        let mut c = Counter { value: 5 };
        increment_counter(&mut c);
        ints[1] = c.value;

        let mut d = 3.0f32;
        double_ref(&mut d);
        floats[0] = d;

        let mut fwd = 0i32;
        outer_ref(&mut fwd);
        ints[2] = fwd;

        let v = 10i32;
        let out = by_value_increment(v);
        ints[3] = v;
        ints[4] = out;
    }
}

fn mutates_locals_elements_and_structs(dev: &wp::Device) {
    let a = arr(&[1.0f32, 2.0, 3.0], dev);
    let (ints, floats) = (zeros::<i32, 1>(5, dev), zeros::<f32, 1>(1, dev));
    wp::launch(k_mutates, 3, (&a, &ints, &floats), dev).unwrap();
    assert_eq!(host(&a), vec![11.0, 12.0, 13.0], "array elements");
    // local, struct field, forwarded, by value (unchanged, returned).
    assert_eq!(host(&ints), vec![1, 6, 1, 10, 11]);
    assert_eq!(host(&floats), vec![6.0], "simple assignment");
}

#[wp::func]
fn store_pair_ref(x: &mut f32, y: &mut f32, a: f32, b: f32) {
    (*x, *y) = (a, b);
}

#[wp::func]
fn swap_pair_ref(x: &mut f32, y: &mut f32) {
    (*x, *y) = (*y, *x);
}

#[wp::func]
fn ref_tuple_local_first(x: &mut f32) -> f32 {
    // Warp's `old, x = x, 2.0` makes `old`; a kernel's `let` needs a value, so it is made
    // first (`ref_tuple_existing_local` is Warp's own version of this form).
    let mut old = 0.0f32;
    (old, *x) = (*x, 2.0);
    old
}

#[wp::func]
fn ref_tuple_ref_first(x: &mut f32) -> f32 {
    let mut old = 0.0f32;
    (*x, old) = (1.0, *x);
    old
}

#[wp::func]
fn ref_tuple_existing_local(x: &mut f32) -> f32 {
    let mut old = 0.0f32;
    (old, *x) = (*x, 2.0);
    old
}

#[wp::kernel]
fn k_tuple_unpack(out: Array<f32>) {
    let mut x = 0.0f32;
    let mut y = 0.0f32;
    store_pair_ref(&mut x, &mut y, 3.0, 4.0);
    out[0] = x;
    out[1] = y;

    let mut s = 3.0f32;
    let mut t = 4.0f32;
    swap_pair_ref(&mut s, &mut t);
    out[2] = s;
    out[3] = t;

    let mut a = 9.0f32;
    out[4] = ref_tuple_local_first(&mut a);
    out[5] = a;
    let mut b = 7.0f32;
    out[6] = ref_tuple_ref_first(&mut b);
    out[7] = b;
    let mut c = 9.0f32;
    out[8] = ref_tuple_existing_local(&mut c);
    out[9] = c;
}

fn tuple_unpack_assignment(dev: &wp::Device) {
    let out = zeros::<f32, 1>(10, dev);
    wp::launch(k_tuple_unpack, 1, (&out,), dev).unwrap();
    assert_eq!(
        host(&out),
        vec![3.0, 4.0, 4.0, 3.0, 9.0, 2.0, 7.0, 1.0, 9.0, 2.0]
    );
}

#[wp::kernel]
fn k_array_tuple_unpack_adjoint(a: Array<f32>, b: Array<f32>, out: Array<f32>) {
    let tid = tid();
    let (ai, bi) = (a[tid], b[tid]);
    out[tid] = ai * bi;
}

fn array_tuple_unpack_preserves_adjoint(dev: &wp::Device) {
    let a = arr(&[2.0f32, 3.0], dev).with_grad().unwrap();
    let b = arr(&[4.0f32, 5.0], dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_array_tuple_unpack_adjoint, 2, (&a, &b, &out), dev).unwrap();
    }
    tape.backward(&out).unwrap();
    assert_eq!(host(&a.grad().unwrap()), vec![4.0, 5.0]);
    assert_eq!(host(&b.grad().unwrap()), vec![2.0, 3.0]);
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct RefBox {
    value: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct RefInner {
    value: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct RefOuter {
    inner: RefInner,
}

/// Warp's `RefCompositeBox`, with `inner` moved after the 16-byte-aligned quaternion and
/// transform and a pad lane, so that the struct has no padding (kernel structs have none).
#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct RefCompositeBox {
    quat: Quat,
    xform: Transform,
    vec: Vec3,
    mat: Mat3,
    inner: RefInner,
    pad: [f32; 3],
}

#[wp::func]
fn set_ref_float(x: &mut f32, value: f32) {
    *x = value;
}

#[wp::func]
fn set_ref_vec3(x: &mut Vec3, value: Vec3) {
    *x = value;
}

#[wp::kernel]
fn k_struct_array_fields(
    boxes: Array<RefBox>,
    outers: Array<RefOuter>,
    comps: Array<RefCompositeBox>,
    out: Array<f32, 2>,
) {
    let i = tid();
    let fi = i as f32;
    set_ref_float(&mut boxes[i].value, fi + 10.0);
    out[(i, 0)] = boxes[i].value;
    set_ref_float(&mut outers[i].inner.value, fi + 20.0);
    out[(i, 1)] = outers[i].inner.value;
    set_ref_float(&mut comps[i].vec.y, fi + 30.0);
    set_ref_float(&mut comps[i].mat.z_axis.y, fi + 40.0);
    out[(i, 2)] = comps[i].vec.y;
    out[(i, 3)] = comps[i].mat.z_axis.y;
    set_ref_float(&mut comps[i].quat.w, fi + 10.0);
    out[(i, 4)] = comps[i].quat.w;
    set_ref_float(&mut comps[i].xform.p.x, fi + 10.0);
    out[(i, 5)] = comps[i].xform.p.x;
    set_ref_vec3(&mut comps[i].vec, vec3(fi, 1.0, 2.0));
    out[(i, 6)] = comps[i].vec.x + comps[i].vec.y;
}

fn struct_array_fields(dev: &wp::Device) {
    let boxes = zeros::<RefBox, 1>(3, dev);
    let outers = zeros::<RefOuter, 1>(3, dev);
    let comps = zeros::<RefCompositeBox, 1>(3, dev);
    let out = zeros::<f32, 2>((3, 7), dev);
    wp::launch(
        k_struct_array_fields,
        3,
        (&boxes, &outers, &comps, &out),
        dev,
    )
    .unwrap();
    let want: Vec<f32> = (0..3)
        .flat_map(|i| {
            let f = i as f32;
            [
                f + 10.0,
                f + 20.0,
                f + 30.0,
                f + 40.0,
                f + 10.0,
                f + 10.0,
                f + 1.0,
            ]
        })
        .collect();
    assert_eq!(host(&out), want);
    // The writes reached the arrays (the element is read before the call and stored after).
    assert_eq!(host(&comps)[2].mat.z_axis.y, 42.0);
    assert_eq!(host(&outers)[1].inner.value, 21.0);
}

#[wp::func]
fn bump_ref_vec_lane(v: &mut Vec3) {
    v.x += 1.0;
}

#[wp::func]
fn bump_ref_mat_lane(m: &mut Mat3) {
    m.x_axis.x += 1.0;
}

#[wp::kernel]
fn k_lanes_and_copies(out: Array<f32>) {
    // Warp's mat33(1, .., 9) lists rows; as glam columns:
    let mut v = vec3(1.0, 2.0, 3.0);
    let mut m = Mat3::from_cols(
        vec3(1.0, 4.0, 7.0),
        vec3(2.0, 5.0, 8.0),
        vec3(3.0, 6.0, 9.0),
    );
    bump_ref_vec_lane(&mut v);
    bump_ref_mat_lane(&mut m);
    out[0] = v.x;
    out[1] = v.y;
    out[2] = m.x_axis.x;
    out[3] = m.y_axis.x;

    let w = vec3(1.0, 2.0, 3.0);
    let mut y = w.x;
    set_ref_float(&mut y, 9.0);
    out[4] = w.x;
    out[5] = y;

    let mut q = Quat::from_xyzw(1.0, 2.0, 3.0, 4.0);
    set_ref_float(&mut q.y, 9.0);
    set_ref_float(&mut q.z, 8.0);
    out[6] = q.x;
    out[7] = q.y;
    out[8] = q.z;
    out[9] = q.w;

    let q2 = Quat::from_xyzw(1.0, 2.0, 3.0, 4.0);
    let mut qw = q2.w;
    set_ref_float(&mut qw, 9.0);
    out[10] = q2.w;
    out[11] = qw;

    let mut t = Transform::new(vec3(1.0, 2.0, 3.0), Quat::IDENTITY);
    set_ref_float(&mut t.p.x, 9.0);
    out[12] = t.p.x;
    out[13] = t.p.y;
    out[14] = t.p.z;

    let t2 = Transform::new(vec3(1.0, 2.0, 3.0), Quat::IDENTITY);
    let mut px = t2.p.x;
    set_ref_float(&mut px, 9.0);
    out[15] = t2.p.x;
    out[16] = px;
}

fn lanes_and_copies(dev: &wp::Device) {
    let out = zeros::<f32, 1>(17, dev);
    wp::launch(k_lanes_and_copies, 1, (&out,), dev).unwrap();
    assert_eq!(
        host(&out),
        vec![
            2.0, 2.0, 2.0, 2.0, // lanes bumped through &mut
            1.0, 9.0, // a copy of a lane is a local of its own
            1.0, 9.0, 8.0, 4.0, // quaternion lanes (Warp's q.y and q[2])
            4.0, 9.0, // a copy of a quaternion lane
            9.0, 2.0, 3.0, // a transform's position lane
            1.0, 9.0, // a copy of it
        ]
    );
}

#[wp::func]
fn forward_ref_outer_inner_value(outer: &mut RefOuter, value: f32) {
    set_ref_float(&mut outer.inner.value, value);
}

#[wp::func]
fn forward_ref_box_value(b: &mut RefBox, y: f32) {
    store_double(&mut b.value, y);
}

#[wp::kernel]
fn k_field_forwarding(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let mut outer = RefOuter {
        inner: RefInner { value: 0.0 },
    };
    forward_ref_outer_inner_value(&mut outer, x[i]);
    out[(i, 0)] = outer.inner.value;
    let mut b = RefBox { value: 0.0 };
    forward_ref_box_value(&mut b, x[i]);
    out[(i, 1)] = b.value;
}

fn field_forwarding(dev: &wp::Device) {
    let x = arr(&[1.0f32, 2.0, 3.0], dev);
    let out = zeros::<f32, 2>((3, 2), dev);
    wp::launch(k_field_forwarding, 3, (&x, &out), dev).unwrap();
    assert_eq!(host(&out), vec![1.0, 2.0, 2.0, 4.0, 3.0, 6.0]);
}

/// Warp's `native_store_double_ref`: `x = 2 y`.
#[wp::func]
fn store_double(x: &mut f32, y: f32) {
    *x = 2.0 * y;
}

/// Each of Warp's `kernel_native_ref_adjoint_*` kernels, one output column each: a local, an
/// array element, an element of a 2-D array, a struct field, a vector, matrix, quaternion
/// and transform lane, a quaternion and a transform lane of a struct array element, and a
/// nested field of a struct array element.
#[wp::kernel]
fn k_store_double_adjoints(
    x: Array<f32>,
    direct: Array<f32>,
    grid: Array<f32, 2>,
    comps: Array<RefCompositeBox>,
    outers: Array<RefOuter>,
    out: Array<f32, 2>,
) {
    let i = tid();
    let mut local = 0.0f32;
    store_double(&mut local, x[i]);
    out[(i, 0)] = local;

    store_double(&mut direct[i], x[i]);
    out[(i, 1)] = direct[i];

    store_double(&mut grid[(i, 1)], x[i]);
    out[(i, 2)] = grid[(i, 1)];

    let mut b = RefBox { value: 0.0 };
    store_double(&mut b.value, x[i]);
    out[(i, 3)] = b.value;

    let mut v = Vec3::ZERO;
    let mut m = Mat3::ZERO;
    let mut q = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    let mut t = Transform::new(Vec3::ZERO, Quat::IDENTITY);
    store_double(&mut v.y, x[i]);
    store_double(&mut m.z_axis.y, x[i]);
    store_double(&mut q.w, x[i]);
    store_double(&mut t.p.x, x[i]);
    out[(i, 4)] = v.y;
    out[(i, 5)] = m.z_axis.y;
    out[(i, 6)] = q.w;
    out[(i, 7)] = t.p.x;

    store_double(&mut comps[i].quat.w, x[i]);
    store_double(&mut comps[i].xform.p.x, x[i]);
    out[(i, 8)] = comps[i].quat.w;
    out[(i, 9)] = comps[i].xform.p.x;

    store_double(&mut outers[i].inner.value, x[i]);
    out[(i, 10)] = outers[i].inner.value;
}

fn adjoints_through_mut_params(dev: &wp::Device) {
    let xs = [1.0f32, 2.0, 3.0];
    let x = arr(&xs, dev).with_grad().unwrap();
    let direct = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let grid = zeros::<f32, 2>((3, 2), dev).with_grad().unwrap();
    let comps = zeros::<RefCompositeBox, 1>(3, dev).with_grad().unwrap();
    let outers = zeros::<RefOuter, 1>(3, dev).with_grad().unwrap();
    let out = zeros::<f32, 2>((3, 11), dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(
            k_store_double_adjoints,
            3,
            (&x, &direct, &grid, &comps, &outers, &out),
            dev,
        )
        .unwrap();
    }
    let want: Vec<f32> = xs.iter().flat_map(|x| [2.0 * x; 11]).collect();
    assert_eq!(host(&out), want);
    tape.backward(&out).unwrap();
    // Each of the 11 columns is 2 x: d/dx = 11 * 2 (Warp checks each kernel alone: 2 each,
    // 8 for its four lanes, 4 for its two struct-array lanes).
    assert_eq!(host(&x.grad().unwrap()), vec![22.0; 3]);
}

#[wp::func]
fn ref_func(x: &mut f32) {
    *x += 1.0;
}

#[wp::kernel]
fn k_backward_through_mut_param(a: Array<f32>, out: Array<f32>) {
    let i = tid();
    let mut v = a[i] * 3.0;
    ref_func(&mut v);
    out[i] = v;
}

fn backward_through_mut_param(dev: &wp::Device) {
    let a = arr(&[1.0f32, 2.0], dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_backward_through_mut_param, 2, (&a, &out), dev).unwrap();
    }
    assert_eq!(host(&out), vec![4.0, 7.0]);
    tape.backward(&out).unwrap();
    assert_eq!(host(&a.grad().unwrap()), vec![3.0, 3.0]);
}
