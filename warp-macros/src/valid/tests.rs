//! The validator's rules on lowered IR, and the validator over every kernel and func of the
//! repository (none may be refused).

use super::uniformity::Uniformity;
use super::*;
use crate::builtins::{lookup, Builtin};
use crate::ir::*;
use syn::parse_quote;

fn lower(item: syn::ItemFn) -> Function {
    crate::front::lower::lower_fn(&item, FnKind::Kernel).unwrap_or_else(|es| {
        panic!(
            "{}",
            es.iter()
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join("\n")
        )
    })
}

fn messages(r: Result<Valid, Vec<syn::Error>>) -> Vec<String> {
    match r {
        Ok(_) => Vec::new(),
        Err(es) => es.iter().map(|e| e.to_string()).collect(),
    }
}

fn kernel_errors(item: syn::ItemFn) -> Vec<String> {
    messages(validate(&lower(item), Options::Kernel { same_shape: &[] }))
}

#[test]
fn break_and_continue_outside_loops() {
    let e = kernel_errors(parse_quote! {
        fn k(x: f32) {
            break;
        }
    });
    assert_eq!(e, ["`break` outside of a loop"]);
    let e = kernel_errors(parse_quote! {
        fn k(a: Array<f32>) {
            let i = tid();
            if a[i] > 0.0 { continue; }
            for j in 0..3 { if j == 1 { continue; } a[i] += 1.0; }
            while a[i] > 1.0 { a[i] *= 0.5; if a[i] < 2.0 { break; } }
        }
    });
    assert_eq!(e, ["`continue` outside of a loop"]);
}

#[test]
fn views_used_as_values_are_reported_once_per_statement() {
    let e = kernel_errors(parse_quote! {
        fn k(m: Array<f32, 2>, x: Array<f32>) {
            let i = tid();
            let r = m.row(i);
            let v = x.view(1..3);
            x[i] = r[0] + v[1] + r.len() as f32;
            println!("{:?} {:?}", r, v);
        }
    });
    assert_eq!(e.len(), 1, "{e:?}");
    assert!(
        e[0].starts_with("a view (`row`, `view`, `indexed`)"),
        "{e:?}"
    );
}

#[test]
fn options_are_checked_against_the_signature() {
    let f = lower(parse_quote! {
        fn k(a: Array<f32>, b: Array<f32>, s: f32) {}
    });
    let groups: Vec<Vec<syn::Ident>> = vec![
        vec![parse_quote!(a), parse_quote!(b), parse_quote!(dim)],
        vec![parse_quote!(a), parse_quote!(s), parse_quote!(c)],
    ];
    let e = messages(validate(
        &f,
        Options::Kernel {
            same_shape: &groups,
        },
    ));
    assert_eq!(
        e,
        ["`s` is not an array parameter", "no parameter named `c`"]
    );
    let ok = validate(
        &f,
        Options::Kernel {
            same_shape: &groups[..1],
        },
    )
    .unwrap();
    assert_eq!(ok.same_shape, vec![vec![0, 1, usize::MAX]]);
    let grad: Vec<(syn::Ident, syn::Path)> = vec![
        (parse_quote!(s), parse_quote!(ds)),
        (parse_quote!(a), parse_quote!(da)),
        (parse_quote!(t), parse_quote!(dt)),
    ];
    let e = messages(validate(&f, Options::Func { grad: &grad }));
    assert_eq!(e.len(), 2, "{e:?}");
    assert!(e[0].starts_with("custom gradients are for value parameters"));
    assert_eq!(e[1], "`t` is not a parameter of this func");
}

#[test]
fn capabilities_follow_atomics_and_gradient_sinks() {
    use Capability::*;
    let f = lower(parse_quote! {
        fn k(a: Array<f32>, d: Array<DVec3>, n: Array<i64>, c: Array<u64>, h: Array<f16>, m: Array<i32>) {
            let i = tid();
            atomic_add(d, i, DVec3::splat(1.0));
            atomic_min(n, i, 3);
            atomic_xor(c, i, 1);
            atomic_max(m, i, 1);
            atomic_add(a, i, 1.0);
        }
    });
    // d (atomic add and gradient), n and c (64-bit min/xor), h (its gradient).
    assert_eq!(
        required_capabilities(&f),
        [AtomicAddF64, AtomicF16, AtomicMinMaxBits64]
    );
    let f = lower(parse_quote! {
        fn k(a: Array<f32>, n: Array<i64>, v: Array<Vec3>) {
            let i = tid();
            atomic_add(n, i, 1);
            atomic_min(v, i, Vec3::ZERO);
            a[i] = 1.0;
        }
    });
    assert!(required_capabilities(&f).is_empty());
    assert_eq!(
        AtomicMinMaxBits64.tokens().to_string(),
        ":: warp_lang :: __private :: Capability :: AtomicMinMaxBits64"
    );
}

/// `f` with every call of the builtin `name` made cooperative (no real row is, before tiles).
fn mark_cooperative(f: &mut Function, name: &str) {
    let row: &'static Builtin = Box::leak(Box::new(
        Builtin {
            ..*lookup(name).expect("a row")
        }
        .cooperative(),
    ));
    fn walk(b: &mut Block, name: &str, row: &'static Builtin) {
        for s in b {
            match &mut s.kind {
                StmtKind::Assign {
                    op: Op::Builtin { builtin, .. },
                    ..
                } if builtin.name == name => *builtin = row,
                StmtKind::If { then, els, .. } => {
                    walk(then, name, row);
                    walk(els, name, row);
                }
                StmtKind::For { body, .. } | StmtKind::Loop { body } => walk(body, name, row),
                _ => {}
            }
        }
    }
    walk(&mut f.body, name, row);
}

/// The validator's errors for `item` with `sin` cooperative: the first line of each.
fn cooperative_errors(item: syn::ItemFn) -> Vec<String> {
    let mut f = lower(item);
    mark_cooperative(&mut f, "sin");
    match validate(&f, Options::Kernel { same_shape: &[] }) {
        Ok(_) => Vec::new(),
        Err(es) => es
            .iter()
            .map(|e| {
                let all: Vec<String> = e.clone().into_iter().map(|e| e.to_string()).collect();
                assert_eq!(all.len(), 2, "the call and the cause: {all:?}");
                all[0].clone()
            })
            .collect(),
    }
}

fn var(f: &Function, name: &str) -> VarId {
    f.vars
        .iter()
        .position(|v| v.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no variable `{name}`"))
}

#[test]
fn uniform_and_varying_values() {
    let f = lower(parse_quote! {
        fn k(a: Array<f32>, b: Array<f32>, s: f32, n: i32) {
            let i = tid();
            let u = s * 2.0 + n as f32;
            let w = a[0];
            let x = a[i];
            let y = b[n as usize];
            let z = b[i];
            let c = a.len();
            let old = atomic_add(b, 0, 1.0);
            let mut m = 0.0;
            if x > 0.0 { m = 1.0; }
            let mut p = 0.0;
            if u > 0.0 { p = 1.0; }
            let q = if i > 2 { 1.0 } else { 2.0 };
            let r = if n > 2 { 1.0 } else { 2.0 };
            let mut acc = 0.0;
            for j in 0..n { acc += s; }
            let mut acc2 = 0.0;
            for j in 0..i { acc2 += s; }
            b[i] = u + w + x + y + z + c as f32 + old + m + p + q + r + acc + acc2;
        }
    });
    let u = Uniformity::of(&f);
    let uniform = |n: &str| u.is_uniform(var(&f, n));
    for n in ["s", "n", "u", "w", "c", "p", "r", "acc", "a"] {
        assert!(uniform(n), "{n} is uniform");
    }
    // `y`: `b` is written (stored and updated atomically), so another thread may change it.
    for n in ["i", "x", "y", "z", "old", "m", "q", "acc2"] {
        assert!(!uniform(n), "{n} varies");
    }
}

#[test]
fn cooperative_calls_in_uniform_control_flow_are_accepted() {
    let e = cooperative_errors(parse_quote! {
        fn k(a: Array<f32>, b: Array<f32>, s: f32, n: i32) {
            let i = tid();
            let mut t = sin(s);
            if s > 0.0 { t += sin(s); }
            for j in 0..n { t += sin(a[j as usize]); }
            let mut k = 0;
            while k < n { k += 1; if k == 3 { break; } t += sin(s); }
            // After a loop some threads left early, all threads are together again.
            for j in 0..n { if a[i] > 0.0 { break; } }
            t += sin(s);
            b[i] = t;
        }
    });
    assert!(e.is_empty(), "{e:?}");
}

#[test]
fn cooperative_calls_under_divergent_control_flow_are_errors() {
    let cases: Vec<syn::ItemFn> = vec![
        // An `if` on the thread index.
        parse_quote! { fn k(a: Array<f32>) { let i = tid(); if i > 3 { a[i] = sin(a[0]); } } },
        // On a value read at the thread's index.
        parse_quote! { fn k(a: Array<f32>) { let i = tid(); if a[i] > 0.0 { } else { a[0] = sin(1.0); } } },
        // A loop whose trip count depends on the thread.
        parse_quote! { fn k(a: Array<f32>) { let i = tid(); for j in 0..i { a[j] = sin(1.0); } } },
        // After a `return` only some threads take.
        parse_quote! { fn k(a: Array<f32>) { let i = tid(); if i >= 10 { return; } a[i] = sin(1.0); } },
        // In a loop some threads leave early: before the `break` too (the next iteration).
        parse_quote! { fn k(a: Array<f32>, n: i32) {
            let i = tid();
            for j in 0..n { a[0] = sin(1.0); if a[i] > 0.0 { break; } }
        } },
        // On a variable only some threads assigned.
        parse_quote! { fn k(a: Array<f32>) {
            let i = tid();
            let mut m = 0;
            if i > 2 { m = 1; }
            if m == 0 { a[0] = sin(1.0); }
        } },
        // On an `if` value that depends on the thread.
        parse_quote! { fn k(a: Array<f32>) {
            let i = tid();
            let q = if i > 2 { 1.0 } else { 2.0 };
            while q > 0.5 { a[0] = sin(q); }
        } },
        // On a value another thread may have written.
        parse_quote! { fn k(a: Array<f32>) {
            let i = tid();
            a[i] = 1.0;
            if a[0] > 0.0 { a[1] = sin(1.0); }
        } },
    ];
    for item in cases {
        let src = quote::quote!(#item).to_string();
        let e = cooperative_errors(item);
        assert_eq!(e.len(), 1, "{src}: {e:?}");
        assert!(
            e[0].starts_with("`sin` is block-cooperative"),
            "{src}: {e:?}"
        );
    }
}

/// Every kernel and func of the repository's crates, tests, examples and benches validates
/// (the validator refuses nothing the front end accepts there, and so no IR the front end
/// makes is ill-formed): parsed from the sources, lowered as the macros lower them.
#[test]
fn every_function_in_the_repository_validates() {
    use syn::visit::Visit;
    struct Found(Vec<(syn::ItemFn, bool, proc_macro2::TokenStream)>);
    impl<'ast> Visit<'ast> for Found {
        fn visit_item_fn(&mut self, i: &'ast syn::ItemFn) {
            for a in &i.attrs {
                let last = a.path().segments.last().map(|s| s.ident.to_string());
                let args = match &a.meta {
                    syn::Meta::List(l) => l.tokens.clone(),
                    _ => proc_macro2::TokenStream::new(),
                };
                match last.as_deref() {
                    Some("kernel") => self.0.push((i.clone(), true, args)),
                    Some("func") => self.0.push((i.clone(), false, args)),
                    _ => {}
                }
            }
            syn::visit::visit_item_fn(self, i);
        }
    }
    fn sources(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
        let Ok(rd) = std::fs::read_dir(dir) else {
            return;
        };
        for e in rd.flatten() {
            let p = e.path();
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            // The compile-fail cases are wrong on purpose; build outputs are not sources.
            if p.is_dir() && !matches!(name, "ui" | "target" | ".git") {
                sources(&p, out);
            } else if name.ends_with(".rs") {
                out.push(p);
            }
        }
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files = Vec::new();
    for d in [
        "src",
        "tests",
        "examples",
        "benches",
        "warp-runtime",
        "warp-core",
    ] {
        sources(&root.join(d), &mut files);
    }
    let mut found = Found(Vec::new());
    for p in &files {
        let text = std::fs::read_to_string(p).unwrap();
        if let Ok(file) = syn::parse_file(&text) {
            found.visit_file(&file);
        }
    }
    let (mut kernels, mut funcs) = (0, 0);
    let mut refused = Vec::new();
    for (item, is_kernel, args) in &found.0 {
        let lists = if *is_kernel {
            crate::front::attrs::parse_kernel_attrs(args.clone())
                .map(|a| a.instances)
                .unwrap_or_default()
        } else {
            crate::front::attrs::parse_func_attrs(args.clone())
                .map(|a| a.instances)
                .unwrap_or_default()
        };
        let items = match crate::front::generics::parse(item, &lists) {
            Ok(Some(g)) => crate::front::generics::instances(item, &g)
                .into_iter()
                .map(|i| i.item)
                .collect(),
            Ok(None) => vec![item.clone()],
            Err(_) => continue,
        };
        for it in items {
            let kind = if *is_kernel {
                FnKind::Kernel
            } else {
                FnKind::Func
            };
            // Functions the front end refuses (doc examples of errors) are not the validator's.
            let Ok(f) = crate::front::lower::lower_fn(&it, kind) else {
                continue;
            };
            let r = if *is_kernel {
                kernels += 1;
                let opts =
                    crate::front::attrs::parse_kernel_attrs(args.clone()).unwrap_or_default();
                validate(
                    &f,
                    Options::Kernel {
                        same_shape: &opts.same_shape,
                    },
                )
            } else {
                funcs += 1;
                let opts = crate::front::attrs::parse_func_attrs(args.clone()).unwrap_or_default();
                validate(&f, Options::Func { grad: &opts.grad })
            };
            if let Err(es) = r {
                refused.push(format!("{}: {:?}", f.name, messages(Err(es))));
            }
            // The analysis runs on every function (it ends, whatever the loops).
            let _ = Uniformity::of(&f);
        }
    }
    assert!(refused.is_empty(), "{refused:#?}");
    assert!(
        kernels > 300 && funcs > 30,
        "found only {kernels} kernels and {funcs} funcs in {} files",
        files.len()
    );
}

/// `#[kernel(deterministic)]`: a float accumulation's old value and float exchanges are
/// errors at the call; integer atomics and unused results are fine; the record limit is the
/// count of accumulation calls outside loops, the default under a loop, or the one given.
#[test]
fn deterministic_kernels_refuse_order_dependent_atomics_and_count_records() {
    let check = |item: syn::ItemFn, explicit| {
        super::deterministic::check(&lower(item), explicit)
            .map_err(|es| es.iter().map(|e| e.to_string()).collect::<Vec<_>>())
    };
    let e = check(
        parse_quote! {
            fn k(a: Array<f32>, b: Array<f64>, out: Array<f32>, n: Array<i32>) {
                let i = tid();
                let old = atomic_add(a, 0, 1.0);
                out[i] = old;
                atomic_exch(b, 0, 2.0);
                out[i] += atomic_add(n, 0, 1) as f32;
            }
        },
        None,
    )
    .unwrap_err();
    assert_eq!(e.len(), 2, "{e:?}");
    assert!(e[0].contains("old value `atomic_add`"), "{e:?}");
    assert!(e[1].contains("`atomic_exch` on floats"), "{e:?}");
    let straight: syn::ItemFn = parse_quote! {
        fn k(a: Array<f32>, v: Array<Vec3>, n: Array<i32>) {
            let i = tid();
            atomic_add(a, 0, 1.0);
            if i > 2 { atomic_sub(v, 1, Vec3::new(1.0, 1.0, 1.0)); }
            atomic_add(n, 0, 1);
            atomic_max(a, 1, 2.0);
        }
    };
    assert_eq!(check(straight.clone(), None), Ok(2));
    assert_eq!(check(straight, Some(7)), Ok(7));
    let looped: syn::ItemFn = parse_quote! {
        fn k(a: Array<f32>) {
            for j in 0..3 { atomic_add(a, j, 1.0); }
        }
    };
    assert_eq!(
        check(looped, None),
        Ok(super::deterministic::DEFAULT_MAX_RECORDS)
    );
}
