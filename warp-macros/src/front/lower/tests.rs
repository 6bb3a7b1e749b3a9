//! Tests of lowering as a whole: kernels in, IR or errors out.

use super::*;
use crate::types::{Dim, F32, I32};
use syn::parse_quote;

fn lower(item: syn::ItemFn) -> Function {
    lower_fn(&item, FnKind::Kernel)
        .unwrap_or_else(|e| panic!("{:?}", e.iter().map(|e| e.to_string()).collect::<Vec<_>>()))
}

fn errors(item: syn::ItemFn, kind: FnKind) -> Vec<String> {
    match lower_fn(&item, kind) {
        Ok(_) => vec![],
        Err(e) => e.iter().map(|e| e.to_string()).collect(),
    }
}

fn find_var(f: &Function, name: &str) -> Ty {
    f.vars
        .iter()
        .rev()
        .find(|v| v.name.as_deref() == Some(name))
        .unwrap()
        .ty
        .clone()
}

#[test]
fn mut_params_return_their_values_after_the_result() {
    let item: syn::ItemFn = parse_quote! {
        fn f(acc: &mut f32, x: f32, v: &mut Vec3) -> bool {
            if x < 0.0 {
                return false;
            }
            *acc += x;
            v.y = acc.max(x);
            true
        }
    };
    let f = lower_fn(&item, FnKind::Func).unwrap();
    assert_eq!(f.ret.to_string(), "(bool, f32, Vec3)");
    let by_ref: Vec<bool> = f.params.iter().map(|p| p.by_ref).collect();
    assert_eq!(by_ref, [true, false, true]);
    // Both returns give the tuple (result, *acc, *v).
    let mut returns = 0;
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Return { value: Some(v) } = &s.kind {
            assert_eq!(f.vars[*v].ty.to_string(), "(bool, f32, Vec3)");
            returns += 1;
        }
    });
    assert_eq!(returns, 2);
    // A unit func returns `((), ..)` at its end.
    let item: syn::ItemFn = parse_quote! {
        fn g(acc: &mut f32) { *acc = 1.0; }
    };
    let g = lower_fn(&item, FnKind::Func).unwrap();
    assert!(matches!(
        g.body.last().unwrap().kind,
        StmtKind::Return { value: Some(_) }
    ));
}

#[test]
fn mut_arguments_are_read_then_written_back() {
    let f = lower(parse_quote! {
        fn k(a: Array<f32>) {
            let i = tid();
            let mut s = 0.0f32;
            let mut v = Vec3::ZERO;
            let r = stepper(&mut s, &mut v.y, a[i]);
            stepper(&mut a[i], &mut s, 1.0);
        }
    });
    assert_eq!(f.call_checks.len(), 2);
    assert_eq!(f.call_checks[0].mut_args, 0b011);
    // `v.y` is read; the first call's result is element "0", `s` is written from "1", `v.y`
    // from "2"; the array element is stored from the second call's "1".
    let mut members = Vec::new();
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Assign {
            op: Op::Member(_, m),
            ..
        } = &s.kind
        {
            members.push(m.clone());
        }
    });
    assert_eq!(members, ["y", "1", "2", "0", "1", "2", "0"]);
    let stores = f
        .body
        .iter()
        .filter(|s| matches!(s.kind, StmtKind::Store { .. }))
        .count();
    assert_eq!(stores, 1);
}

#[test]
fn mut_arguments_refused() {
    let e = errors(
        parse_quote! {
            fn k(a: Array<f32>) {
                let i = tid();
                let mut s = 0.0f32;
                let t = 1.0f32;
                stepper(&mut s, &mut s);
                stepper(&mut s, s + 1.0);
                stepper(&mut t);
                stepper(&a[i]);
            }
        },
        FnKind::Kernel,
    );
    assert_eq!(e.len(), 4, "{e:?}");
    assert!(e[0].contains("lent as `&mut` twice"), "{e:?}");
    assert!(e[1].contains("cannot be read by another argument"), "{e:?}");
    assert!(e[2].contains("immutable"), "{e:?}");
    assert!(e[3].contains("shared reference"), "{e:?}");
    let e = errors(
        parse_quote! {
            fn f(acc: &mut f32, x: &f32) {
                let y = acc + 1.0;
                acc = 2.0;
                g(&mut acc);
            }
        },
        FnKind::Func,
    );
    assert_eq!(e.len(), 4, "{e:?}");
    assert!(e[0].contains("shared reference `&T` adds nothing"), "{e:?}");
    assert!(e[1].contains("its value is `*acc`"), "{e:?}");
    assert!(e[2].contains("assign through it"), "{e:?}");
    assert!(e[3].contains("is a `&mut` already"), "{e:?}");
}

#[test]
fn decompositions_destructure_into_members() {
    let f = lower(parse_quote! {
        fn k(a: Array<DMat3>, b: Array<Mat2>) {
            let i = tid();
            let (u, s, v) = svd3(a[i]);
            let (q, _): (DMat3, DVec3) = wp::eig3(a[i]);
            let (q2, r) = qr3(a[i]);
            let (u2, s2, v2) = svd2(b[i]);
        }
    });
    let m3 = Ty::Matrix(Scalar::F64, 3);
    assert_eq!(find_var(&f, "u"), m3);
    assert_eq!(find_var(&f, "s"), Ty::Vector(Scalar::F64, 3));
    assert_eq!(find_var(&f, "v"), m3);
    assert_eq!(find_var(&f, "q"), m3);
    assert_eq!(find_var(&f, "r"), m3);
    assert_eq!(find_var(&f, "s2"), Ty::Vector(Scalar::F32, 2));
    // One tuple temporary per call, read through members "0", "1", "2".
    let tuples: Vec<&Ty> = f
        .vars
        .iter()
        .map(|v| &v.ty)
        .filter(|t| matches!(t, Ty::Tuple(_)))
        .collect();
    assert_eq!(tuples.len(), 4);
    assert_eq!(
        tuples[0].to_string(),
        "(DMat3, DVec3, DMat3)",
        "the tuple type prints as Rust's"
    );
    let mut members = Vec::new();
    walk_stmts(&f.body, &mut |st| {
        if let StmtKind::Assign {
            op: Op::Member(_, m),
            ..
        } = &st.kind
        {
            members.push(m.clone());
        }
    });
    // `_` reads nothing.
    assert_eq!(members, ["0", "1", "2", "0", "0", "1", "0", "1", "2"]);
}

#[test]
fn destructuring_assignment_is_checked() {
    let e = errors(
        parse_quote! {
            fn k(a: Array<Mat3>, f: Array<f32>) {
                let i = tid();
                let mut x = 0.0f32;
                let mut y = 0.0f32;
                (x, y) += (1.0, 2.0);
                (x, y) = a[i];
                (x, y) = svd3(a[i]);
                (x, y) = (1.0, 2i32);
                (x, y) = (y, x);
                f[i] = x + y;
            }
        },
        FnKind::Kernel,
    );
    assert_eq!(e.len(), 4, "{e:?}");
    assert!(
        e[0].contains("cannot be the target of a compound assignment"),
        "{}",
        e[0]
    );
    assert!(
        e[1].contains("destructures 2 value(s), but the value is a `Mat3`"),
        "{}",
        e[1]
    );
    assert!(
        e[2].contains("destructures 2 value(s), but the value is a `(Mat3, Vec3, Mat3)`"),
        "{}",
        e[2]
    );
    assert!(
        e[3].contains("mismatched types: expected `f32`, found `i32`"),
        "{}",
        e[3]
    );
}

#[test]
fn tuples_are_checked_where_destructured() {
    let e = errors(
        parse_quote! {
            fn k(a: Array<Mat3>) {
                let i = tid();
                let t = svd3(a[i]);
                let (x, y) = a[i];
                let (p, q) = svd3(a[i]);
                let m = transpose(qr3(a[i]));
                let w = t.3;
            }
        },
        FnKind::Kernel,
    );
    assert_eq!(e.len(), 4, "{e:?}");
    assert!(
        e[0].contains("a tuple pattern destructures a tuple"),
        "{}",
        e[0]
    );
    assert!(
        e[1].contains("binds 2 value(s), but the value is a `(Mat3, Vec3, Mat3)`: `let (u, sigma, v) = svd3(..);`"),
        "{}",
        e[1]
    );
    assert!(
        e[2].contains("`transpose` is not defined for `(Mat3, Mat3)`"),
        "{}",
        e[2]
    );
    assert!(e[3].contains("has no field `3`"), "{}", e[3]);
}

#[test]
fn literal_rule() {
    let f = lower(parse_quote! {
        fn k(x: f64, v: Vec3, a: Array<f32>) {
            let i = tid();
            let a1 = 2.0 * x;      // f64 from x
            let a2 = 2.0;          // no context: f32
            let a3 = v * 0.5;      // f32 from Vec3's scalar
            let a4 = 3;            // i32
            let a5 = 2 * x;        // integer literal in a float context
            let a6: f64 = 1.0;     // annotation
            let a7 = a[i] + 1.0;   // element type
            let a8 = if x > 0.0 { 1.0 } else { 2.0 };
        }
    });
    assert_eq!(find_var(&f, "a1"), Ty::Scalar(Scalar::F64));
    assert_eq!(find_var(&f, "a2"), F32);
    assert_eq!(find_var(&f, "a3"), Ty::Vector(Scalar::F32, 3));
    assert_eq!(find_var(&f, "a4"), I32);
    assert_eq!(find_var(&f, "a5"), Ty::Scalar(Scalar::F64));
    assert_eq!(find_var(&f, "a6"), Ty::Scalar(Scalar::F64));
    assert_eq!(find_var(&f, "a7"), F32);
    assert_eq!(find_var(&f, "a8"), F32);
    assert_eq!(f.tid_ndim, Some(1));
}

#[test]
fn deferred_values_leave_literals_to_the_target() {
    let f = lower(parse_quote! {
        fn k(x: f32) { let y = helper(x) * 2.0; }
    });
    assert_eq!(find_var(&f, "y"), Ty::Deferred);
    assert_eq!(f.callees.len(), 1);
}

#[test]
fn type_errors_are_gathered() {
    let e = errors(
        parse_quote! {
            fn k(x: f32, y: f64, v: Vec3) {
                let a = x + y;
                let b = v.frobnicate();
                let c = |q: f32| q;
                let d = &x;
            }
        },
        FnKind::Kernel,
    );
    assert_eq!(e.len(), 4, "{e:?}");
    assert!(
        e[0].contains("cannot apply `+` to `f32` and `f64`"),
        "{}",
        e[0]
    );
    assert!(e[1].contains("unknown method `frobnicate`"), "{}", e[1]);
    assert!(e[2].contains("closures"), "{}", e[2]);
    assert!(e[3].contains("references"), "{}", e[3]);
}

#[test]
fn subset_errors() {
    let cases: Vec<(syn::ItemFn, &str)> = vec![
        (
            parse_quote!(
                fn k(a: Array<f32>) {
                    let s = String::new();
                }
            ),
            "heap type `String`",
        ),
        (
            parse_quote!(
                fn k(a: Vec<f32>) {}
            ),
            "heap type",
        ),
        (
            parse_quote!(
                fn k(a: &f32) {}
            ),
            "references",
        ),
        (
            parse_quote!(
                fn k(x: f32) {
                    x = 1.0;
                }
            ),
            "immutable",
        ),
        (
            parse_quote!(
                fn k(a: Array<f32, 2>) {
                    let v = a[0];
                }
            ),
            "2 dimension",
        ),
        (
            parse_quote!(
                fn k(x: i32) {
                    match x {
                        _ => {}
                    }
                }
            ),
            "match",
        ),
        (
            parse_quote!(
                fn k(x: f32) -> f32 {
                    x
                }
            ),
            "kernels return nothing",
        ),
        (
            parse_quote!(
                fn k(x: u8) {
                    let y = x + 300;
                }
            ),
            "out of range",
        ),
        (
            parse_quote!(
                fn k(x: i32) {
                    let y = x + 1.5;
                }
            ),
            "float literal",
        ),
    ];
    for (item, want) in cases {
        let e = errors(item.clone(), FnKind::Kernel);
        assert!(
            e.iter().any(|m| m.contains(want)),
            "{} -> {e:?}",
            quote::quote!(#item)
        );
    }
    let e = errors(
        parse_quote!(
            fn f(x: f32) -> f32 {
                f(x)
            }
        ),
        FnKind::Func,
    );
    assert!(e[0].contains("recursion"), "{e:?}");
}

#[test]
fn control_flow_lowers() {
    let f = lower(parse_quote! {
        fn k(a: Array<f32>, n: i32) {
            let mut s = 0.0;
            for j in (0..n).rev().step_by(2) { if j == 3 { continue; } s += 1.0; }
            let mut k = 0;
            while k < 10 && s > 0.0 { k += 1; if k > 5 { break; } }
            loop { break; }
            a[0] = s;
        }
    });
    let mut fors = 0;
    let mut loops = 0;
    walk_stmts(&f.body, &mut |s| match &s.kind {
        StmtKind::For { range, .. } => {
            fors += 1;
            assert!(matches!(
                range.adapters.as_slice(),
                [RangeAdapter::Rev, RangeAdapter::StepBy(_)]
            ));
        }
        StmtKind::Loop { .. } => loops += 1,
        _ => {}
    });
    assert_eq!((fors, loops), (1, 2));
    assert_eq!(find_var(&f, "j"), I32);
}

#[test]
fn tid_forms() {
    let f = lower(parse_quote!(
        fn k(a: Array<f32, 2>) {
            let (i, j) = tid();
            a[(i, j)] = 1.0;
        }
    ));
    assert_eq!(f.tid_ndim, Some(2));
    let e = errors(
        parse_quote!(
            fn k() {
                let i = tid();
                let (a, b) = tid();
            }
        ),
        FnKind::Kernel,
    );
    assert!(e[0].contains("1 and with 2"), "{e:?}");
}

#[test]
fn local_arrays_lower_to_elements_of_one_variable() {
    let f = lower(parse_quote!(
        fn k(x: Array<f32>, n: Array<i32>) {
            let i = tid();
            let mut a = [0.0f32; 4];
            let mut m = [[0.0; 3]; 2];
            let mut v = [Vec3::ZERO, Vec3::ONE];
            a[n[i]] = x[i];
            a[1] += 2.0;
            m[1][n[i]] = a[0];
            v[1].y = a.len() as f32;
            x[i] = a[3] + m[0][2] + v[0].x;
        }
    ));
    let f32_4 = Ty::LocalArray(Box::new(F32), Dim::Lit(4));
    assert_eq!(find_var(&f, "a"), f32_4);
    assert_eq!(find_var(&f, "a").to_string(), "[f32; 4]");
    assert_eq!(
        find_var(&f, "m").to_string(),
        "[[f32; 3]; 2]",
        "an unsuffixed repeat takes the literal rule's type"
    );
    let (mut sets, mut reads, mut members) = (Vec::new(), 0, 0);
    walk_stmts(&f.body, &mut |s| match &s.kind {
        StmtKind::SetElem { var, .. } => sets.push(f.vars[*var].name.clone()),
        StmtKind::SetMember { .. } => members += 1,
        StmtKind::Assign {
            op: Op::Index { .. },
            ..
        } => reads += 1,
        _ => {}
    });
    // `a[n] =`, `a[1] +=`, `m[1][n] =` (the inner row, then the row back into `m`), `v[1].y =`
    // (the element back into `v`, after a member write of its copy).
    let named = |n: &str| Some(n.to_string());
    assert_eq!(
        sets,
        [named("a"), named("a"), None, named("m"), named("v")],
        "{sets:?}"
    );
    assert_eq!(members, 1);
    // `a[1]` (the `+=`), `m[1]` and `v[1]` (read to be written inside), then the final reads.
    assert_eq!(reads, 3 + 1 + 4);
    // `len()` of a literal length is a constant.
    let lit4 = walk_find(&f, |op| matches!(op, Op::Lit(Lit::Int(4))));
    assert!(lit4, "a.len() as a literal");
}

/// Whether some assignment's operation satisfies `p`.
fn walk_find(f: &Function, p: impl Fn(&Op) -> bool) -> bool {
    let mut found = false;
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Assign { op, .. } = &s.kind {
            found |= p(op);
        }
    });
    found
}

#[test]
fn local_array_misuse_is_refused_at_the_use() {
    let cases: [(syn::ItemFn, FnKind, &str); 11] = [
        (
            parse_quote!(
                fn k() {
                    let a = [1.0f32, 2.0f64];
                }
            ),
            FnKind::Kernel,
            "the array's elements are `f32`, this is `f64`",
        ),
        (
            parse_quote!(
                fn k(n: usize) {
                    let a = [0.0f32; n];
                }
            ),
            FnKind::Kernel,
            "must be an integer literal or a module const",
        ),
        (
            parse_quote!(
                fn k() {
                    let a = [0.0f32; 0];
                }
            ),
            FnKind::Kernel,
            "at least one element",
        ),
        (
            parse_quote!(
                fn k(x: f32) {
                    let a = [0.0f32; 2];
                    let y = a[x];
                }
            ),
            FnKind::Kernel,
            "array indices are integers, found `f32`",
        ),
        (
            parse_quote!(
                fn k() {
                    let a = [0.0f32; 2];
                    let y = a + 1.0;
                }
            ),
            FnKind::Kernel,
            "[f32; 2]",
        ),
        (
            parse_quote!(
                fn k() {
                    let a = [0.0f32; 2];
                    let y: f32 = a;
                }
            ),
            FnKind::Kernel,
            "mismatched types: expected `f32`, found `[f32; 2]`",
        ),
        (
            parse_quote!(
                fn k(a: [f32; 4]) {}
            ),
            FnKind::Kernel,
            "a local array is not a kernel parameter",
        ),
        (
            parse_quote!(
                fn k() {
                    let a = [0.0f32; 2];
                    a[0] = 1.0;
                }
            ),
            FnKind::Kernel,
            "immutable variable `a`",
        ),
        (
            parse_quote!(
                fn k() {
                    let a = [0.0f32; 2];
                    println!("{:?}", a);
                }
            ),
            FnKind::Kernel,
            "cannot be printed",
        ),
        (
            parse_quote!(
                fn f(a: [Array<f32>; 2]) {}
            ),
            FnKind::Func,
            "cannot be a local array's element",
        ),
        (
            parse_quote!(
                fn k(x: Array<f32>) {
                    let t: Tile<f32, 8> = tile_zeros();
                    let a = [1.0f32; 2];
                }
            ),
            FnKind::Kernel,
            "local arrays are not supported in tiled kernels yet",
        ),
    ];
    for (item, kind, want) in cases {
        let text = quote::quote!(#item).to_string();
        let e = errors(item, kind);
        assert!(e.iter().any(|e| e.contains(want)), "{text}: {e:?}");
    }
}

/// A literal lane index is a member; a run-time one an element (`Op::Index`, `SetElem`), and
/// a glam matrix's entry `m[(i, j)]` is element `i` of column `j`.
#[test]
fn lanes_lower_to_members_and_elements() {
    let f = lower(parse_quote! {
        fn k(v: Vec3, m: Mat3, q: Quat, k: i32, out: Array<f32>) {
            let a = v[1];
            let b = v[k];
            let c = m[(k, 2)];
            let d = q[3];
            let mut w = v;
            w[k] += a;
            out[0] = a + b + c + d + w.x;
        }
    });
    let def = |name: &str| {
        let mut found = None;
        walk_stmts(&f.body, &mut |s| {
            if let StmtKind::Assign { dst, op, .. } = &s.kind {
                if f.vars[*dst].name.as_deref() == Some(name) {
                    found = Some(op.clone());
                }
            }
        });
        found.unwrap_or_else(|| panic!("no `{name}`"))
    };
    // Named locals are copies of the expression's temporary: follow one copy.
    let through = |op: Op| match op {
        Op::Copy(t) => {
            let mut found = None;
            walk_stmts(&f.body, &mut |s| {
                if let StmtKind::Assign { dst, op, .. } = &s.kind {
                    if *dst == t {
                        found = Some(op.clone());
                    }
                }
            });
            found.expect("a temporary's definition")
        }
        op => op,
    };
    assert!(matches!(through(def("a")), Op::Member(_, m) if m == "y"));
    assert!(matches!(through(def("d")), Op::Member(_, m) if m == "w"));
    assert!(matches!(through(def("b")), Op::Index { .. }));
    let Op::Index { array, .. } = through(def("c")) else {
        panic!("`m[(k, 2)]` is an element")
    };
    assert_eq!(f.vars[array].ty.to_string(), "Vec3", "column 2 of m");
    let mut sets = 0;
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::SetElem { var, .. } = &s.kind {
            assert_eq!(f.vars[*var].name.as_deref(), Some("w"));
            sets += 1;
        }
    });
    assert_eq!(sets, 1);
}

#[test]
fn literal_lets_take_the_type_their_uses_give_them() {
    let f = lower_fn(
        &parse_quote! {
            fn power(x: f64, n: i32) -> f64 {
                let mut acc = 1.0;
                for _ in 0..n {
                    acc *= x;
                }
                let mut best = 0.0;
                best = best.max(acc);
                let half = 0.5;
                let scaled = half * best;
                let mut tail = 0.0;
                tail += scaled;
                tail
            }
        },
        FnKind::Func,
    )
    .unwrap_or_else(|e| panic!("{:?}", e.iter().map(|e| e.to_string()).collect::<Vec<_>>()));
    for name in ["acc", "best", "half", "tail"] {
        assert_eq!(find_var(&f, name), Ty::Scalar(Scalar::F64), "{name}");
    }
    let k = lower(parse_quote! {
        fn k(out: Array<f32>) {
            let i = tid();
            let mut j = 0;
            j += i;
            let mut s = 0.0;
            s += out[j];
            out[i] = s;
        }
    });
    assert_eq!(find_var(&k, "j"), USIZE);
    assert_eq!(find_var(&k, "s"), F32);
}

#[test]
fn literal_lets_keep_errors_their_uses_cannot_resolve() {
    // An integer literal's `let` is not a float (Rust's rule), and an annotated `let` keeps
    // its annotation: both stay errors, reported once.
    let e = errors(
        parse_quote! {
            fn k(x: f64, out: Array<f64>) {
                let n = 2;
                let a: f32 = 1.0;
                out[0] = x * n + a;
            }
        },
        FnKind::Kernel,
    );
    assert_eq!(e.len(), 1, "{e:?}");
    assert!(
        e[0].contains("cannot apply `*` to `f64` and `i32`"),
        "{}",
        e[0]
    );
}
