//! Tests of the forward CUDA emitter (`back::cuda`): the text it prints for small kernels.

use super::*;
use syn::parse_quote;

fn emit_kernel(item: syn::ItemFn) -> String {
    let f = crate::front::lower::lower_fn(&item, FnKind::Kernel).unwrap();
    emit(&f, "k.rs").unwrap().source
}

#[test]
fn particle_kernel() {
    let src = emit_kernel(parse_quote! {
        fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
            let i = tid();
            let a = -b * v[i] / mass + gravity;
            v[i] += a * dt;
            x[i] += v[i] * dt;
        }
    });
    assert!(
        src.contains("static WP_FN void @@SELF@@(wp::array_t<wp::Vec3, 1> x_0"),
        "{src}"
    );
    assert!(
        src.contains("(__FAST ? wp::load_unchecked(v_1, (wp::i64)(i_"),
        "{src}"
    );
    assert!(src.contains("wp::store(x_0,"), "{src}");
    assert!(
        src.contains("wp::unflatten(__launch, __flat, __tid, 1);"),
        "{src}"
    );
}

#[test]
fn loops_over_array_ranges_are_unswitched() {
    let src = emit_kernel(parse_quote! {
        fn k(a: Array<f32>, b: Array<f32, 2>, out: Array<f32>, n: i32) {
            let i = tid();
            let mut s = 0.0;
            for j in 0..n {
                s += a[j] + b[(j, 0)];
                out[j] = s;
                for q in 0..n { s += a[q]; for r in 0..n { s += a[r]; } }
            }
            out[i] = s;
        }
    });
    let one = |needle: &str| assert_eq!(src.matches(needle).count(), 1, "{needle}\n{src}");
    // One check of the whole range for the 1-D arrays at the loop variable, then a copy of
    // the loop without their checks and a copy with them; `b` (2-D) stays checked.
    one("const bool __inb1 = wp::range_inside(a_0, t");
    one("wp::range_inside(out_2, t");
    one("if (__inb1) {");
    assert!(src.contains("for (wp::i32 j_"), "{src}");
    assert!(
        src.contains("wp::store_unchecked(out_2, (wp::i64)(j_"),
        "{src}"
    );
    assert!(src.contains("wp::store(out_2, (wp::i64)(j_"), "{src}");
    assert!(!src.contains("wp::load_unchecked(b_1"), "{src}");
    // The end is a copy made before the loop.
    assert!(src.contains(", __end1 = n_3; j_"), "{src}");
    // Unswitching stops two levels deep: the innermost loop tests its flag per access.
    assert!(
        src.contains("? wp::load_unchecked(a_0, (wp::i64)(r_"),
        "{src}"
    );
}

#[test]
fn query_loops_with_checked_items_are_unswitched() {
    let src = emit_kernel(parse_quote! {
        fn k(grid: HashGrid, x: Array<Vec3>, m: Array<f32, 2>, out: Array<f32>, r: f32) {
            let i = tid();
            let mut s = 0.0;
            for j in hash_grid_query(grid, x[i], r) {
                s += x[j].x + m[(j, 0)];
            }
            for mut j in hash_grid_query(grid, x[i], r) {
                j += 0;
                s += x[j].x;
            }
            out[i] = s;
        }
    });
    let count = |needle: &str| src.matches(needle).count();
    // One check that `x` holds as many elements as the grid has points (every candidate
    // is below that: `hash_grid_query_next` checks each), then the loop without the check
    // of `x[j]` and the loop with it; the 2-D `m` stays checked in both.
    assert_eq!(
        count("const bool __inb1 = wp::range_inside(x_1, (wp::i64)0, wp::hash_grid_item_bound(grid_0));"),
        1,
        "{src}"
    );
    assert_eq!(count("if (__inb1) {"), 1, "{src}");
    assert_eq!(count("wp::load_unchecked(x_1, (wp::i64)(j_"), 1, "{src}");
    assert!(!src.contains("wp::load_unchecked(m_2"), "{src}");
    // A `mut` loop variable could leave the bound: that loop keeps its checks.
    assert_eq!(count("wp::range_inside("), 1, "{src}");
    assert_eq!(count("wp::load(x_1, (wp::i64)(j_"), 2, "{src}");
}

#[test]
fn literals_keep_their_type() {
    let src = emit_kernel(parse_quote! {
        fn k(a: Array<f32>, d: Array<f64>) {
            let i = tid();
            a[i] = a[i] * 0.1 + 2.0;
            d[i] = d[i] * 0.1;
        }
    });
    assert!(
        src.contains("wp::f32 t") && src.contains("= 0.1f;"),
        "{src}"
    );
    assert!(src.contains("wp::f64 t") && src.contains("= 0.1;"), "{src}");
    assert!(
        !src.contains("= 2.0;"),
        "an f32 literal must not be a double: {src}"
    );
}

#[test]
fn funcs_and_control_flow() {
    let item: syn::ItemFn = parse_quote! {
        fn f(x: f32, n: i32) -> f32 {
            let mut s = 0.0;
            for k in (0..n).rev().step_by(2) { if k == 3 { continue; } s += helper(x); }
            while s > 10.0 { s -= 1.0; }
            if s < 0.0 { return 0.0; }
            s / (n as f32)
        }
    };
    let f = crate::front::lower::lower_fn(&item, FnKind::Func).unwrap();
    let src = emit(&f, "k.rs").unwrap().source;
    assert!(
        src.contains("static WP_FN wp::f32 @@SELF@@(wp::f32 x_0, wp::i32 n_1, wp::ctx_t* __ctx)"),
        "{src}"
    );
    assert!(src.contains("@@F0@@(x_0, __ctx)"), "{src}");
    assert!(src.contains("wp::range_rev("), "{src}");
    assert!(src.contains("wp::range_step_by("), "{src}");
    assert!(src.contains("wp::cast<wp::f32>(n_1)"), "{src}");
    assert!(src.contains("#line "), "{src}");
}

#[test]
fn exact_float_literals() {
    assert_eq!(float_lit(0.1, Scalar::F32), "0.1f");
    assert_eq!(float_lit(1e30, Scalar::F32), "1e30f");
    assert_eq!(float_lit(0.1, Scalar::F64), "0.1");
    assert_eq!(float_lit(0.1, Scalar::F16), "wp::f16_from_bits(0x2e66)");
    assert_eq!(float_lit(-1e9, Scalar::F16), "wp::f16_from_bits(0xfc00)");
    assert_eq!(float_lit(0.1, Scalar::BF16), "wp::bf16_from_bits(0x3dcd)");
    assert_eq!(int_lit(i32::MIN as i128, Scalar::I32), "(-2147483647 - 1)");
}

#[test]
fn local_arrays_are_values_with_checked_elements() {
    let item: syn::ItemFn = parse_quote! {
        fn k(x: Array<f32>, n: Array<i32>) {
            let i = tid();
            let mut a = [0.0f32; N];
            let b = [x[i], 2.0];
            a[n[i]] = b[1];
            x[i] = a[0] + a.len() as f32;
        }
    };
    let f = crate::front::lower::lower_fn(&item, FnKind::Kernel).unwrap();
    let src = emit(&f, "k.rs").unwrap().source;
    // The const length is the const's value placeholder.
    assert_eq!(f.consts.len(), 1);
    assert!(
        src.contains("wp::local_array_t<wp::f32, @@K0@@>::splat("),
        "{src}"
    );
    assert!(!src.contains("@@LEN:"), "{src}");
    assert!(src.contains("wp::local_array_t<wp::f32, 2>{{t"), "{src}");
    // Element accesses name the user's line (the kernel's is 1 in a parsed test).
    assert!(src.contains("wp::local_set(a_"), "{src}");
    assert!(src.contains("wp::local_get(b_"), "{src}");
    assert!(src.contains(", __ctx)"), "{src}");
}
