//! The table's rows held to their signatures and to each other, and the matcher's typing.

use super::rows::{BOOL, BVH_AABB, BVH_RAY, GRID_QUERY, MESH_AABB};
use super::*;
use crate::types::{ObjectKind, Scalar, F32, I32};

fn k(t: Ty) -> ArgTy {
    ArgTy::Known(t)
}

#[test]
fn every_entry_is_unique_and_well_formed() {
    for (i, b) in BUILTINS.iter().enumerate() {
        assert!(
            BUILTINS[..i].iter().all(|o| o.name != b.name),
            "duplicate {}",
            b.name
        );
        // A tile row's `T` is its tile's element, from a tile argument or the shape written
        // with it (the turbofish or the annotation: `front::lower::tiles`).
        let tile_pos = |p: &Pos| matches!(p, Pos::Tile | Pos::TileShape);
        assert_eq!(
            b.is_tile(),
            b.params.iter().chain([&b.ret]).any(tile_pos),
            "{}: a tile row, and only a tile row, has tile positions",
            b.name
        );
        let binds_t = b.params.contains(&Pos::T)
            || b.params.contains(&Pos::ArrayOfT)
            || b.params.contains(&Pos::VolumeOfT)
            || b.params.contains(&Pos::BsrOfT)
            || b.params.iter().any(tile_pos);
        let all_fixed = b.params.iter().chain([&b.ret]).all(Pos::fixed);
        assert!(binds_t || all_fixed, "{} cannot bind T", b.name);
        assert_eq!(b.classes.is_empty(), all_fixed, "{}: classes", b.name);
        // The facts beyond the signature agree with it and with the other rows.
        for a in b.aliases {
            assert!(
                lookup(a).is_none(),
                "{}: alias {a} is a builtin's name",
                b.name
            );
            assert_eq!(lookup_method(a).map(|m| m.name), Some(b.name), "{a}");
        }
        if let Some((name, arity)) = b.overload {
            assert_eq!(b.params.len(), arity, "{}: overload's arity", b.name);
            let base = lookup_user(name).expect("an overload of a builtin");
            assert_ne!(base.params.len(), arity, "{}", b.name);
            assert_eq!(lookup_overload(name, arity).map(|o| o.name), Some(b.name));
        }
        if let Some(lit) = b.default_last {
            assert!(syn::parse_str::<syn::Lit>(lit).is_ok(), "{}: {lit}", b.name);
        }
        if let Some(draw) = b.draw {
            assert_eq!(
                b.params.first(),
                Some(&Pos::Fixed(Scalar::U32)),
                "{}",
                b.name
            );
            if let Draw::NextState(row) = draw {
                let next = lookup(row).expect("the next-state row");
                assert!(next.internal && next.params == b.params, "{}", b.name);
            }
        }
        match (b.ret, b.results) {
            (Pos::Tuple(parts), Some(names)) => {
                assert_eq!(names.split(',').count(), parts.len(), "{}", b.name)
            }
            (Pos::Tuple(_), None) => panic!("{}: a tuple result needs its names", b.name),
            (_, results) => assert!(results.is_none(), "{}", b.name),
        }
        if let Emit::Operator(_) = b.emit {
            assert_eq!(b.params.len(), 2, "{}: a binary operator", b.name);
        }
        assert!(
            !(b.internal && (b.method || !b.aliases.is_empty() || b.ctor.is_some())),
            "{}: internal rows have no other spelling",
            b.name
        );
        if let Some(it) = b.iterate {
            // The steps: internal rows of the query's state, `next` taking the object the
            // query takes first.
            let Pos::Object(state) = b.ret else {
                panic!("{}: a query returns its state", b.name)
            };
            let st = Pos::Object(state);
            let (next, done, item) = (
                lookup(it.next).expect("next"),
                lookup(it.done).expect("done"),
                lookup(it.item).expect("item"),
            );
            assert!(
                next.internal && done.internal && item.internal,
                "{}",
                b.name
            );
            assert_eq!(next.params, &[b.params[0], st], "{}", b.name);
            assert_eq!(next.ret, st, "{}", b.name);
            assert_eq!((done.params, done.ret), (&[st][..], BOOL), "{}", b.name);
            assert_eq!(item.params, &[st], "{}", b.name);
            assert!(b.reads_object() && next.reads_object(), "{}", b.name);
        }
        // A query state is made by its query and consumed by its steps only.
        if [GRID_QUERY, BVH_AABB, BVH_RAY, MESH_AABB].contains(&b.ret) {
            assert!(b.iterate.is_some() || b.internal, "{}", b.name);
        }
    }
    for name in [
        "min",
        "max",
        "abs",
        "sign",
        "clamp",
        "floor",
        "ceil",
        "sqrt",
        "exp",
        "log",
        "sin",
        "cos",
        "tan",
        "atan2",
        "pow",
        "dot",
        "cross",
        "length",
        "normalize",
        "lerp",
        "atomic_add",
        "atomic_sub",
        "atomic_min",
        "atomic_max",
        "asin",
        "acos",
        "atan",
        "sinh",
        "cosh",
        "tanh",
        "exp2",
        "log2",
        "log10",
        "cbrt",
        "erf",
        "erfc",
        "erfinv",
        "erfcinv",
        "round",
        "rint",
        "trunc",
        "frac",
        "step",
        "smoothstep",
        "degrees",
        "radians",
        "isfinite",
        "isnan",
        "isinf",
        "mod",
    ] {
        assert!(lookup(name).is_some(), "{name} missing");
    }
}

#[test]
fn literals_take_the_bound_type() {
    let max = lookup("max").unwrap();
    let r = max
        .resolve(&[k(Ty::Scalar(Scalar::F64)), ArgTy::Literal { float: true }])
        .unwrap();
    assert_eq!(r.params, vec![Ty::Scalar(Scalar::F64); 2]);
    assert_eq!(r.ret, Ty::Scalar(Scalar::F64));
    // An integer literal next to a float is typed as the float.
    let r = max
        .resolve(&[ArgTy::Literal { float: false }, k(F32)])
        .unwrap();
    assert_eq!(r.params, vec![F32, F32]);
}

#[test]
fn vector_builtins() {
    let v3 = Ty::Vector(Scalar::F32, 3);
    let dot = lookup_method("dot").unwrap();
    assert_eq!(
        dot.resolve(&[k(v3.clone()), k(v3.clone())]).unwrap().ret,
        F32
    );
    let lerp = lookup("lerp").unwrap();
    let r = lerp
        .resolve(&[k(v3.clone()), k(v3.clone()), ArgTy::Literal { float: true }])
        .unwrap();
    assert_eq!(r.params[2], F32);
    assert!(lookup("length")
        .unwrap()
        .resolve(&[k(Ty::Vector(Scalar::I32, 3))])
        .is_err());
    assert!(lookup("cross")
        .unwrap()
        .resolve(&[k(Ty::Vector(Scalar::F32, 2)), k(Ty::Vector(Scalar::F32, 2))])
        .is_err());
}

#[test]
fn mismatches_are_reported() {
    let min = lookup("min").unwrap();
    let e = min
        .resolve(&[k(F32), k(Ty::Scalar(Scalar::F64))])
        .unwrap_err();
    assert!(e.contains("mismatched"), "{e}");
    assert!(lookup("sqrt")
        .unwrap()
        .resolve(&[k(I32)])
        .unwrap_err()
        .contains("not defined for `i32`"));
    assert!(lookup("sqrt")
        .unwrap()
        .resolve(&[k(F32), k(F32)])
        .unwrap_err()
        .contains("takes 1 argument"));
    // Literal-only calls follow the literal rule's defaults.
    assert_eq!(
        lookup("sqrt")
            .unwrap()
            .resolve(&[ArgTy::Literal { float: true }])
            .unwrap()
            .ret,
        F32
    );
    assert!(lookup("sqrt")
        .unwrap()
        .resolve(&[ArgTy::Literal { float: false }])
        .unwrap_err()
        .contains("i32"));
    assert_eq!(
        lookup("max")
            .unwrap()
            .resolve(&[
                ArgTy::Literal { float: false },
                ArgTy::Literal { float: false }
            ])
            .unwrap()
            .ret,
        I32
    );
    assert!(lookup("sqrt")
        .unwrap()
        .resolve(&[k(Ty::Deferred)])
        .unwrap()
        .ret
        .is_deferred());
}

#[test]
fn atomics_bind_from_the_array() {
    let add = lookup("atomic_add").unwrap();
    let arr = Ty::Array(Box::new(F32), 1);
    let r = add
        .resolve(&[k(arr.clone()), k(I32), ArgTy::Literal { float: false }])
        .unwrap();
    assert_eq!(r.params, vec![arr, I32, F32]);
    assert_eq!(r.ret, F32);
    let arr2 = Ty::Array(Box::new(F32), 2);
    assert!(
        add.resolve(&[k(arr2), k(I32), k(F32)]).is_err(),
        "1-D index into 2-D array"
    );
    let bad = Ty::Array(Box::new(Ty::Scalar(Scalar::I8)), 1);
    assert!(add
        .resolve(&[k(bad), k(I32), k(Ty::Scalar(Scalar::I8))])
        .is_err());
}

#[test]
fn decompositions_return_tuples() {
    let m3 = Ty::Matrix(Scalar::F32, 3);
    let v3 = Ty::Vector(Scalar::F32, 3);
    let r = lookup("svd3").unwrap().resolve(&[k(m3.clone())]).unwrap();
    assert_eq!(r.ret, Ty::Tuple(vec![m3.clone(), v3.clone(), m3.clone()]));
    let r = lookup("eig3").unwrap().resolve(&[k(m3.clone())]).unwrap();
    assert_eq!(r.ret, Ty::Tuple(vec![m3.clone(), v3]));
    let r = lookup("qr3").unwrap().resolve(&[k(m3.clone())]).unwrap();
    assert_eq!(r.ret, Ty::Tuple(vec![m3.clone(), m3.clone()]));
    let m2 = Ty::Matrix(Scalar::F64, 2);
    let r = lookup("svd2").unwrap().resolve(&[k(m2.clone())]).unwrap();
    assert_eq!(
        r.ret,
        Ty::Tuple(vec![m2.clone(), Ty::Vector(Scalar::F64, 2), m2.clone()])
    );
    assert!(lookup("svd3").unwrap().resolve(&[k(m2.clone())]).is_err());
    assert!(lookup("svd2").unwrap().resolve(&[k(m3)]).is_err());
    // Deferred argument: the tuple's arity is still known.
    let r = lookup("svd3").unwrap().resolve(&[k(Ty::Deferred)]).unwrap();
    assert_eq!(r.ret, Ty::Tuple(vec![Ty::Deferred; 3]));
    assert!(lookup_method("svd3").is_none(), "function syntax only");
}

#[test]
fn glam_constructors_and_overloads() {
    let ctor = |ty: Ty, f: &str| lookup_ctor(&ty, f).map(|b| b.name);
    assert_eq!(
        ctor(Ty::Quat(Scalar::F64), "from_axis_angle"),
        Some("quat_from_axis_angle")
    );
    assert_eq!(
        ctor(Ty::Matrix(Scalar::F32, 3), "from_quat"),
        Some("quat_to_matrix")
    );
    assert_eq!(ctor(Ty::Matrix(Scalar::F32, 4), "from_quat"), None);
    assert_eq!(
        ctor(Ty::Transform(Scalar::F32), "new"),
        Some("transformation")
    );
    assert_eq!(ctor(Ty::Vector(Scalar::F32, 3), "new"), None);
    assert_eq!(
        lookup_overload("min", 1).map(|b| b.name),
        Some("min_element")
    );
    assert!(lookup_overload("min", 2).is_none());
    assert_eq!(lookup("min_element").unwrap().warp_name(), Some("min"));
    assert_eq!(lookup("exp2").unwrap().warp_name(), None);
    assert_eq!(lookup("sqrt").unwrap().warp_name(), Some("sqrt"));
}

#[test]
fn method_aliases() {
    assert_eq!(lookup_method("powf").unwrap().name, "pow");
    assert_eq!(lookup_method("ln").unwrap().name, "log");
    assert!(
        lookup_method("log").is_none(),
        "x.log(base) means something else in Rust"
    );
    assert!(lookup_method("pow").is_none());
    for (alias, name) in [
        ("round_ties_even", "rint"),
        ("fract", "frac"),
        ("to_degrees", "degrees"),
        ("to_radians", "radians"),
        ("is_finite", "isfinite"),
        ("is_nan", "isnan"),
        ("is_infinite", "isinf"),
    ] {
        assert_eq!(lookup_method(alias).unwrap().name, name);
    }
    for m in ["asin", "tanh", "cbrt", "exp2", "log10", "round", "trunc"] {
        assert_eq!(lookup_method(m).unwrap().name, m);
    }
    // Warp's names without a Rust method of that meaning are function syntax only.
    for m in ["frac", "rint", "erf", "isnan", "degrees", "signum", "mod"] {
        assert!(lookup_method(m).is_none(), "{m}");
    }
}

#[test]
fn rand_rows_have_fixed_types() {
    let u32t = Ty::Scalar(Scalar::U32);
    // Fixed signatures: literals take the parameter's type, other types are mismatches.
    let init = lookup("rand_init").unwrap();
    let r = init.resolve(&[ArgTy::Literal { float: false }]).unwrap();
    assert_eq!((r.params, r.ret.clone()), (vec![I32], u32t.clone()));
    assert!(init
        .resolve(&[k(Ty::Scalar(Scalar::Usize))])
        .unwrap_err()
        .contains("expected `i32`"));
    let range = lookup("randf_range").unwrap();
    let r = range
        .resolve(&[
            k(u32t.clone()),
            ArgTy::Literal { float: false },
            ArgTy::Literal { float: true },
        ])
        .unwrap();
    assert_eq!(r.params, vec![u32t.clone(), F32, F32]);
    assert_eq!(
        lookup("sample_unit_disk")
            .unwrap()
            .resolve(&[k(u32t.clone())])
            .unwrap()
            .ret,
        Ty::Vector(Scalar::F32, 2)
    );
    // Noise: T is the position (f32 only), the periods follow its size.
    let pn = lookup("pnoise").unwrap();
    let v3 = Ty::Vector(Scalar::F32, 3);
    let r = pn
        .resolve(&[
            k(u32t.clone()),
            k(v3.clone()),
            k(Ty::Vector(Scalar::I32, 3)),
        ])
        .unwrap();
    assert_eq!(r.ret, F32);
    assert!(pn
        .resolve(&[k(u32t.clone()), k(v3), k(Ty::Vector(Scalar::I32, 2))])
        .is_err());
    assert!(lookup("noise")
        .unwrap()
        .resolve(&[k(u32t.clone()), k(Ty::Scalar(Scalar::F64))])
        .unwrap_err()
        .contains("f32, Vec2, Vec3 or Vec4"));
    // Internal rows exist and are hidden from user code.
    for b in BUILTINS.iter().filter(|b| b.internal) {
        assert!(lookup_user(b.name).is_none(), "{}", b.name);
    }
    assert!(lookup_user("rand_pcg").is_none());
    assert!(lookup_user("randn").is_some());
}

#[test]
fn transform_builtins() {
    let (x, d) = (Ty::Transform(Scalar::F32), Ty::Transform(Scalar::F64));
    let v3 = Ty::Vector(Scalar::F32, 3);
    let q = Ty::Quat(Scalar::F32);
    let r = lookup("transformation")
        .unwrap()
        .resolve(&[k(v3.clone()), k(q.clone())])
        .unwrap();
    assert_eq!(r.ret, x);
    assert!(lookup("transformation")
        .unwrap()
        .resolve(&[k(v3.clone()), k(Ty::Quat(Scalar::F64))])
        .is_err());
    let tp = lookup_method("transform_point").unwrap();
    assert_eq!(tp.resolve(&[k(x.clone()), k(v3.clone())]).unwrap().ret, v3);
    let m4 = Ty::Matrix(Scalar::F64, 4);
    assert_eq!(
        lookup_method("transform_point3")
            .unwrap()
            .resolve(&[k(m4.clone()), k(Ty::Vector(Scalar::F64, 3))])
            .unwrap()
            .ret,
        Ty::Vector(Scalar::F64, 3)
    );
    assert!(tp
        .resolve(&[k(Ty::Matrix(Scalar::F32, 3)), k(v3.clone())])
        .is_err());
    assert_eq!(
        lookup("transform_to_matrix")
            .unwrap()
            .resolve(&[k(d.clone())])
            .unwrap()
            .ret,
        m4
    );
    assert_eq!(
        lookup("transform_from_matrix")
            .unwrap()
            .resolve(&[k(m4)])
            .unwrap()
            .ret,
        d
    );
    assert_eq!(
        lookup_method("inverse")
            .unwrap()
            .resolve(&[k(x.clone())])
            .unwrap()
            .ret,
        x
    );
    let lerp = lookup_method("lerp").unwrap();
    let r = lerp
        .resolve(&[k(d.clone()), k(d.clone()), ArgTy::Literal { float: true }])
        .unwrap();
    assert_eq!(r.params[2], Ty::Scalar(Scalar::F64));
    assert_eq!(
        lookup("transform_get_rotation")
            .unwrap()
            .resolve(&[k(d)])
            .unwrap()
            .ret,
        Ty::Quat(Scalar::F64)
    );
}

#[test]
fn misc_rows() {
    let (v3, d3) = (Ty::Vector(Scalar::F32, 3), Ty::Vector(Scalar::F64, 3));
    let (q, dq) = (Ty::Quat(Scalar::F32), Ty::Quat(Scalar::F64));
    let r = lookup("transform_compose")
        .unwrap()
        .resolve(&[k(d3.clone()), k(dq.clone()), k(d3.clone())])
        .unwrap();
    assert_eq!(r.ret, Ty::Matrix(Scalar::F64, 4));
    let r = lookup("transform_decompose")
        .unwrap()
        .resolve(&[k(Ty::Matrix(Scalar::F32, 4))])
        .unwrap();
    assert_eq!(r.ret, Ty::Tuple(vec![v3.clone(), q.clone(), v3.clone()]));
    let r = lookup("quat_to_axis_angle")
        .unwrap()
        .resolve(&[k(dq)])
        .unwrap();
    assert_eq!(r.ret, Ty::Tuple(vec![d3, Ty::Scalar(Scalar::F64)]));
    let r = lookup("quat_rpy")
        .unwrap()
        .resolve(&[
            ArgTy::Literal { float: true },
            ArgTy::Literal { float: true },
            ArgTy::Literal { float: true },
        ])
        .unwrap();
    assert_eq!(r.ret, q);
    let iv = Ty::Vector(Scalar::I32, 4);
    assert_eq!(
        lookup_method("min_element")
            .unwrap()
            .resolve(&[k(iv.clone())])
            .unwrap()
            .ret,
        I32
    );
    assert_eq!(
        lookup("argmax").unwrap().resolve(&[k(iv)]).unwrap().ret,
        Ty::Scalar(Scalar::U32)
    );
    assert!(lookup("get_diag")
        .unwrap()
        .resolve(&[k(v3.clone())])
        .is_err());
    let arr = Ty::Array(Box::new(Ty::Scalar(Scalar::I64)), 1);
    let r = lookup("lower_bound")
        .unwrap()
        .resolve(&[k(arr), ArgTy::Literal { float: false }])
        .unwrap();
    assert_eq!(r.params[1], Ty::Scalar(Scalar::I64));
    assert!(lookup("lower_bound_range").unwrap().reads_array());
    assert!(!lookup("atomic_add").unwrap().reads_array());
    assert!(lookup_user("lower_bound_range").is_none());
    for name in ["isfinite", "isnan", "isinf"] {
        let b = lookup(name).unwrap();
        assert!(b.resolve(&[k(Ty::Matrix(Scalar::F64, 2))]).is_ok());
        assert!(b.resolve(&[k(Ty::Quat(Scalar::F32))]).is_ok());
    }
    for b in BUILTINS.iter().filter(|b| b.default_last.is_some()) {
        assert_eq!(b.params.len(), 2, "{}", b.name);
    }
}

#[test]
fn volume_rows_take_their_type_from_the_volume() {
    use crate::types::VolumeElem;
    let vol = |e| k(Ty::Object(ObjectKind::Volume(e)));
    let v3 = Ty::Vector(Scalar::F32, 3);
    let sample = lookup_user("volume_sample").unwrap();
    let r = sample
        .resolve(&[vol(VolumeElem::Vec3), k(v3.clone()), k(I32)])
        .unwrap();
    assert_eq!(r.ret, v3);
    assert!(sample.faults());
    let r = sample
        .resolve(&[vol(VolumeElem::F64), k(v3.clone()), k(I32)])
        .unwrap();
    assert_eq!(r.ret, Ty::Scalar(Scalar::F64));
    // Integer grids are looked up, not interpolated; index grids hold no values.
    let e = sample
        .resolve(&[vol(VolumeElem::I32), k(v3.clone()), k(I32)])
        .unwrap_err();
    assert!(e.contains("is not defined for `i32`"), "{e}");
    let e = sample
        .resolve(&[vol(VolumeElem::Index), k(v3.clone()), k(I32)])
        .unwrap_err();
    assert!(e.contains("volume_sample_index"), "{e}");
    let e = sample
        .resolve(&[k(F32), k(v3.clone()), k(I32)])
        .unwrap_err();
    assert!(e.contains("expects a `Volume<T>`"), "{e}");
    let grad = lookup_user("volume_sample_grad").unwrap();
    let r = grad
        .resolve(&[vol(VolumeElem::Vec3), k(v3.clone()), k(I32)])
        .unwrap();
    assert_eq!(
        r.ret,
        Ty::Tuple(vec![v3.clone(), Ty::Matrix(Scalar::F32, 3)])
    );
    let r = grad
        .resolve(&[vol(VolumeElem::F32), k(v3.clone()), k(I32)])
        .unwrap();
    assert_eq!(r.ret, Ty::Tuple(vec![F32, v3.clone()]));
    let store = lookup_user("volume_store").unwrap();
    let r = store
        .resolve(&[vol(VolumeElem::I32), k(I32), k(I32), k(I32), k(I32)])
        .unwrap();
    assert_eq!(r.ret, Ty::Unit);
    let e = store
        .resolve(&[vol(VolumeElem::F32), k(I32), k(I32), k(I32), k(v3.clone())])
        .unwrap_err();
    assert!(e.contains("mismatched types"), "{e}");
    // The index reads take any volume and type `T` from the data array.
    let index = lookup_user("volume_sample_index").unwrap();
    let arr = k(Ty::Array(Box::new(v3.clone()), 1));
    let r = index
        .resolve(&[
            vol(VolumeElem::Index),
            k(v3.clone()),
            k(I32),
            arr,
            k(v3.clone()),
        ])
        .unwrap();
    assert_eq!(r.ret, v3);
    assert!(index.reads_array() && index.faults());
    let w = lookup_user("volume_world_to_index").unwrap();
    assert!(w.resolve(&[vol(VolumeElem::Index), k(v3.clone())]).is_ok());
}

#[test]
fn bvh_and_mesh_rows() {
    let mesh = Ty::Object(ObjectKind::Mesh);
    let bvh = Ty::Object(ObjectKind::Bvh);
    let v3 = Ty::Vector(Scalar::F32, 3);
    let b = Ty::Scalar(Scalar::Bool);
    // The point queries' tuples, whatever the literal.
    for name in [
        "mesh_query_point",
        "mesh_query_point_no_sign",
        "mesh_query_point_sign_normal",
        "mesh_query_point_sign_parity",
        "mesh_query_furthest_point_no_sign",
    ] {
        let q = lookup_user(name).unwrap();
        let r = q
            .resolve(&[
                k(mesh.clone()),
                k(v3.clone()),
                ArgTy::Literal { float: true },
            ])
            .unwrap();
        assert_eq!(r.params, vec![mesh.clone(), v3.clone(), F32], "{name}");
        assert_eq!(
            r.ret,
            Ty::Tuple(vec![b.clone(), F32, I32, F32, F32]),
            "{name}"
        );
        assert!(q.faults(), "{name}");
        // A BVH is not a mesh.
        let e = q
            .resolve(&[k(bvh.clone()), k(v3.clone()), k(F32)])
            .unwrap_err();
        assert!(e.contains("expected `Mesh`"), "{e}");
    }
    let r = lookup_user("mesh_query_ray")
        .unwrap()
        .resolve(&[k(mesh.clone()), k(v3.clone()), k(v3.clone()), k(F32)])
        .unwrap();
    assert_eq!(
        r.ret,
        Ty::Tuple(vec![b.clone(), F32, I32, F32, F32, F32, v3.clone()])
    );
    // Faces of any integer type.
    let ev = lookup_user("mesh_eval_position").unwrap();
    for t in [I32, Ty::Scalar(Scalar::Usize)] {
        let r = ev
            .resolve(&[k(mesh.clone()), k(t.clone()), k(F32), k(F32)])
            .unwrap();
        assert_eq!((r.params[1].clone(), r.ret), (t, v3.clone()));
    }
    // The loops' items are i32.
    for (q, item) in [
        ("bvh_query_aabb", "bvh_query_aabb_item"),
        ("bvh_query_ray", "bvh_query_ray_item"),
        ("mesh_query_aabb", "mesh_query_aabb_item"),
    ] {
        assert_eq!(lookup_user(q).unwrap().iterate.unwrap().item, item);
        assert_eq!(lookup(item).unwrap().ret, Pos::Fixed(Scalar::I32));
        assert!(lookup_user(item).is_none());
    }
    let r = lookup_user("closest_point_triangle")
        .unwrap()
        .resolve(&[k(v3.clone()), k(v3.clone()), k(v3.clone()), k(v3.clone())])
        .unwrap();
    assert_eq!(r.ret, v3);
    assert!(!lookup("closest_point_triangle").unwrap().faults());
}

#[test]
fn hash_grid_rows() {
    let grid = Ty::Object(ObjectKind::HashGrid);
    let state = Ty::Object(ObjectKind::HashGridQuery);
    let v3 = Ty::Vector(Scalar::F32, 3);
    let q = lookup_user("hash_grid_query").unwrap();
    let r = q
        .resolve(&[
            k(grid.clone()),
            k(v3.clone()),
            ArgTy::Literal { float: true },
        ])
        .unwrap();
    assert_eq!(r.params, vec![grid.clone(), v3.clone(), F32]);
    assert_eq!(r.ret, state);
    // A wrong object or point type is a mismatch naming the types.
    let e = q
        .resolve(&[k(Ty::Array(Box::new(v3.clone()), 1)), k(v3.clone()), k(F32)])
        .unwrap_err();
    assert!(e.contains("expected `HashGrid`"), "{e}");
    assert!(q
        .resolve(&[k(grid.clone()), k(Ty::Vector(Scalar::F64, 3)), k(F32)])
        .is_err());
    // point_id takes any integer index.
    let pid = lookup_user("hash_grid_point_id").unwrap();
    for t in [I32, Ty::Scalar(Scalar::Usize), Ty::Scalar(Scalar::U64)] {
        let r = pid.resolve(&[k(grid.clone()), k(t.clone())]).unwrap();
        assert_eq!(r.params[1], t);
        assert_eq!(r.ret, Ty::Scalar(Scalar::Usize));
    }
    assert!(pid.resolve(&[k(grid.clone()), k(F32)]).is_err());
    assert!(pid.faults() && q.faults() && !lookup("hash_grid_query_done").unwrap().faults());
    for step in [
        "hash_grid_query_next",
        "hash_grid_query_done",
        "hash_grid_query_point",
    ] {
        assert!(lookup_user(step).is_none(), "{step}");
    }
}

#[test]
fn classification_returns_bool() {
    let isnan = lookup("isnan").unwrap();
    assert_eq!(isnan.resolve(&[k(F32)]).unwrap().ret, crate::types::BOOL);
    let v3 = Ty::Vector(Scalar::F64, 3);
    assert_eq!(isnan.resolve(&[k(v3)]).unwrap().ret, crate::types::BOOL);
    assert!(isnan.resolve(&[k(I32)]).is_err());
    // step takes integers too (Warp's); smoothstep only floats.
    assert_eq!(lookup("step").unwrap().resolve(&[k(I32)]).unwrap().ret, I32);
    assert!(lookup("smoothstep")
        .unwrap()
        .resolve(&[k(I32), k(I32), k(I32)])
        .is_err());
}
