//! The CUDA back end's pipelined tile GEMM loop: a tiled kernel's k-loop
//!
//! ```text
//! for k in a..b {
//!     let ta = tile_load(A, (.., ..));   // f16, M x K
//!     let tb = tile_load(B, (.., ..));   // f16, K x N
//!     tile_matmul(ta, tb, &mut acc);     // acc: f32, M x N
//! }
//! ```
//!
//! (with any integer arithmetic for the offsets) is printed over wp_tile_mma.h's
//! `tile_gemm_pipe`: the accumulator stays in tensor-core fragments for the whole loop, and
//! each iteration's two loads are issued with cp.async several iterations ahead, into stage
//! buffers made of slots the loop leaves idle. Written plainly, every `tile_matmul` reloads and
//! stores its accumulator through shared memory and every load stalls the block until it
//! lands: measured on an H200 at 4096^3, 2.55 ms against 0.50 ms pipelined.
//!
//! The pipelined loop computes the same bits as the loop as written (the same mma k-steps per
//! output in the same order); it is printed beside the plain loop, and `tile_gemm_pipe::ON`
//! (a compile-time constant: sm_80+, shapes the tensor-core path takes) picks one. Only the
//! forward kernel is pipelined; an adjoint's replay prints loops as written.
//!
//! The loop qualifies when nothing else can observe the difference: the loop is a plain
//! `a..b` over an integer; its body is the two loads, the accumulating `tile_matmul` last,
//! and otherwise only `let`s of pure scalar arithmetic (which the pipelined form evaluates for
//! iteration `k + AHEAD` while iteration `k` multiplies); the loaded tiles are read by
//! nothing but that `tile_matmul`, anywhere in the kernel.

use super::cuda::Emitter;
use crate::ir::*;
use crate::types::{Scalar, Ty};

/// A k-loop the pipelined form can print.
pub(crate) struct GemmLoop<'a> {
    /// The accumulator (`Tile<f32, M, N>`).
    acc: VarId,
    /// `ta = tile_load(A, o0, o1)` and `tb = tile_load(B, o0, o1)`, in the body.
    load_a: &'a Stmt,
    load_b: &'a Stmt,
    /// The body's scalar `let`s, in order.
    scalars: Vec<&'a Stmt>,
}

/// Whether `op` is pure scalar arithmetic (no memory access, no call, no tile).
fn pure_scalar(op: &Op) -> bool {
    matches!(
        op,
        Op::Lit(_)
            | Op::LitLike(..)
            | Op::ZeroLike(_)
            | Op::Copy(_)
            | Op::Unary(..)
            | Op::Binary(..)
            | Op::Cast(..)
            | Op::Const(_)
            | Op::Extent(..)
            | Op::Len(_)
    )
}

fn is_tile_of(t: &Ty, s: Scalar) -> bool {
    matches!(t, Ty::Tile(e, dims) if **e == Ty::Scalar(s) && dims.len() == 2)
}

/// The (accumulator, A, B) tiles of each k-loop of `f` the pipelined form prints, for
/// `TileInfo::pipe_extra_bytes` (the extra stages each may use).
pub(crate) fn gemm_loop_tiles(f: &Function) -> Vec<(VarId, VarId, VarId)> {
    let mut out = Vec::new();
    walk_stmts(&f.body, &mut |s| {
        if let Some(g) = gemm_loop(f, s) {
            out.push((g.acc, load_dst(g.load_a), load_dst(g.load_b)));
        }
    });
    out
}

impl Emitter<'_> {
    /// `s` as a k-loop the pipelined form prints, or `None` (the loop is printed as written).
    /// (A method, as the other tile printers': `back/cuda.rs` calls it without an import.)
    pub(crate) fn gemm_loop<'a>(&self, s: &'a Stmt) -> Option<GemmLoop<'a>> {
        gemm_loop(self.f, s)
    }
}

fn gemm_loop<'a>(f: &Function, s: &'a Stmt) -> Option<GemmLoop<'a>> {
    let StmtKind::For { var, range, body } = &s.kind else {
        return None;
    };
    // A range without adapters (its iterations are `wp::range_at` of a `wp::range_t`, as the
    // general loop's), over a variable the body does not assign.
    if !range.adapters.is_empty() || f.vars[*var].mutable {
        return None;
    }
    let (last, rest) = body.split_last()?;
    let StmtKind::Assign {
        dst: acc,
        op: Op::Builtin { builtin, args },
        ..
    } = &last.kind
    else {
        return None;
    };
    // (a, b, c): the accumulator is read as well as written.
    if builtin.name != "tile_matmul_acc" || args.len() != 3 || args[2] != *acc {
        return None;
    }
    let (ta, tb) = (args[0], args[1]);
    if ta == tb
        || ta == *acc
        || tb == *acc
        || !is_tile_of(f.ty(*acc), Scalar::F32)
        || !is_tile_of(f.ty(ta), Scalar::F16)
        || !is_tile_of(f.ty(tb), Scalar::F16)
    {
        return None;
    }
    let (mut load_a, mut load_b, mut scalars) = (None, None, Vec::new());
    for st in rest {
        let StmtKind::Assign { dst, op, define } = &st.kind else {
            return None;
        };
        match op {
            Op::Builtin { builtin, args }
                if builtin.name == "tile_load"
                    && *define
                    && args.len() == 3
                    && matches!(f.ty(args[0]), Ty::Array(e, 2) if **e == Ty::Scalar(Scalar::F16)) =>
            {
                let slot = if *dst == ta {
                    &mut load_a
                } else if *dst == tb {
                    &mut load_b
                } else {
                    return None;
                };
                if slot.replace(st).is_some() {
                    return None;
                }
            }
            op if *define && pure_scalar(op) && !f.ty(*dst).is_tile() => scalars.push(st),
            _ => return None,
        }
    }
    // The loaded tiles: assigned by their load alone, read by the matmul alone.
    let (mut writes, mut reads) = (vec![0usize; f.vars.len()], vec![0usize; f.vars.len()]);
    walk_stmts(&f.body, &mut |st| {
        if let StmtKind::Assign { dst, .. } = &st.kind {
            writes[*dst] += 1;
        }
        st.kind.for_each_read(&mut |v| reads[v] += 1);
    });
    if [ta, tb].iter().any(|&t| writes[t] != 1 || reads[t] != 1) {
        return None;
    }
    Some(GemmLoop {
        acc: *acc,
        load_a: load_a?,
        load_b: load_b?,
        scalars,
    })
}

impl Emitter<'_> {
    /// Prints the k-loop `s` (which `gemm_loop` matched as `g`): the pipelined form when
    /// `tile_gemm_pipe::ON`, else the loop as written.
    pub(crate) fn gemm_pipe_loop(&mut self, s: &Stmt, g: &GemmLoop) -> Result<(), String> {
        let sp = s.span;
        let StmtKind::For { var, range, .. } = &s.kind else {
            unreachable!("gemm_loop matched a for loop")
        };
        let (s0, e0) = (self.var(range.start), self.var(range.end));
        // The loop variable's type, as the general loop spells it.
        let t = self
            .type_expr(*var, 0)
            .unwrap_or_else(|| format!("decltype({e0})"));
        let ta = self.var(load_dst(g.load_a));
        let tb = self.var(load_dst(g.load_b));
        let acc = self.var(g.acc);
        self.tmp += 1;
        let k = self.tmp;
        let (pipe, p, n) = (format!("__gp{k}"), format!("__p{k}"), format!("__n{k}"));
        self.line(sp, "{");
        self.indent += 1;
        let of = format!(
            "wp::tile_gemm_pipe_of<{}, {}, {}>::type",
            super::cuda_tile::tile_type(self.f, self.f.ty(g.acc))?,
            super::cuda_tile::tile_type(self.f, self.f.ty(load_dst(g.load_a)))?,
            super::cuda_tile::tile_type(self.f, self.f.ty(load_dst(g.load_b)))?,
        );
        self.line(sp, &format!("typedef {of} {pipe};"));
        self.pipes.push(of);
        self.line(sp, &format!("if ({pipe}::usable({acc}, {ta}, {tb})) {{"));
        self.indent += 1;
        // The range, evaluated once as Rust does, and its trip count.
        self.line(
            sp,
            &format!(
                "const wp::range_t __r{k} = wp::range_new((wp::i64)({s0}), (wp::i64)({e0}), {});",
                range.inclusive
            ),
        );
        self.line(sp, &format!("const wp::i64 {n} = __r{k}.count;"));
        self.line(sp, &format!("{pipe} {p}({acc}, {ta}, {tb});"));
        self.line(sp, &format!("{p}.begin({acc});"));
        // The first AHEAD iterations' loads.
        self.line(
            sp,
            &format!("for (wp::i64 __j{k} = 0; __j{k} < {pipe}::AHEAD; ++__j{k}) {{"),
        );
        self.indent += 1;
        self.issue(g, *var, &t, k)?;
        self.indent -= 1;
        self.close();
        // Iteration i multiplies stage i % STAGES after issuing iteration i + AHEAD's loads into
        // a stage whose products are done (the wait's barrier is after them).
        self.line(
            sp,
            &format!("for (wp::i64 __i{k} = 0; __i{k} < {n}; ++__i{k}) {{"),
        );
        self.indent += 1;
        self.line(sp, &format!("{p}.wait();"));
        self.line(sp, "{");
        self.indent += 1;
        self.line(
            sp,
            &format!("const wp::i64 __j{k} = __i{k} + {pipe}::AHEAD;"),
        );
        self.issue(g, *var, &t, k)?;
        self.indent -= 1;
        self.close();
        self.line(sp, &format!("{p}.mma((int)(__i{k} % {pipe}::STAGES));"));
        self.indent -= 1;
        self.close();
        self.line(sp, &format!("{p}.end({acc});"));
        self.indent -= 1;
        self.line(sp, "} else {");
        self.indent += 1;
        self.pipeline = false;
        self.beside_pipe = Some(pipe.clone());
        let plain = self.stmt(s);
        self.beside_pipe = None;
        self.pipeline = true;
        plain?;
        self.indent -= 1;
        self.close();
        self.indent -= 1;
        self.close();
        Ok(())
    }

    /// Iteration `__j<k>`'s loads (when it is one), then the commit of its copy group (empty
    /// past the end, so that the wait's count of groups in flight holds).
    fn issue(&mut self, g: &GemmLoop, var: VarId, t: &str, k: usize) -> Result<(), String> {
        let sp = g.load_a.span;
        let v = self.var(var);
        self.line(sp, &format!("if (__j{k} < __n{k}) {{"));
        self.indent += 1;
        self.line(
            sp,
            &format!("const {t} {v} = wp::cast<{t}>(wp::range_at(__r{k}, __j{k}));"),
        );
        for st in &g.scalars {
            self.stmt(st)?;
        }
        self.line(
            sp,
            &format!("const int __stage{k} = (int)(__j{k} % __gp{k}::STAGES);"),
        );
        for (which, st) in [("a", g.load_a), ("b", g.load_b)] {
            let StmtKind::Assign {
                op: Op::Builtin { args, .. },
                ..
            } = &st.kind
            else {
                unreachable!("gemm_loop matched a tile_load")
            };
            let a: Vec<String> = args.iter().map(|x| self.var(*x)).collect();
            self.line(
                st.span,
                &format!("__p{k}.load_{which}(__stage{k}, {}, __ctx);", a.join(", ")),
            );
        }
        self.indent -= 1;
        self.close();
        self.line(sp, &format!("__p{k}.commit();"));
        Ok(())
    }
}

fn load_dst(s: &Stmt) -> VarId {
    match &s.kind {
        StmtKind::Assign { dst, .. } => *dst,
        _ => unreachable!("gemm_loop matched a tile_load"),
    }
}

#[cfg(test)]
mod tests {
    use crate::test_support::kernel;
    use syn::parse_quote;

    fn cuda(item: syn::ItemFn) -> String {
        crate::back::cuda::emit(&kernel(item), "k.rs")
            .unwrap()
            .source
    }

    /// The f16 GEMM k-loop is printed pipelined, beside the loop as written; its offsets'
    /// arithmetic is evaluated for the iteration whose loads are issued.
    #[test]
    fn an_f16_gemm_k_loop_is_pipelined() {
        let src = cuda(parse_quote! {
            fn gemm(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>) {
                let (i, j) = tid();
                let mut acc = tile_zeros::<f32, 128, 128>();
                let k_tiles = (a.shape()[1] + 63) / 64;
                for k in 0..k_tiles {
                    let ta = tile_load::<128, 64>(a, ((i * 128) as i32, (k * 64) as i32));
                    let tb = tile_load::<64, 128>(b, ((k * 64) as i32, (j * 128) as i32));
                    tile_matmul(ta, tb, &mut acc);
                }
                tile_store(c, acc, ((i * 128) as i32, (j * 128) as i32));
            }
        });
        if std::env::var("WARP_LANG_DUMP").is_ok() {
            println!("{src}");
        }
        let pipe = "wp::tile_gemm_pipe_of<wp::tile_t<wp::f32, 128, 128>, \
                    wp::tile_t<wp::f16, 128, 64>, wp::tile_t<wp::f16, 64, 128>>::type";
        assert!(src.contains(&format!("typedef {pipe} __gp1;")), "{src}");
        // The entry's occupancy hint.
        assert!(
            src.contains(&format!(
                "__launch_bounds__(WP_TILE_BLOCK_DIM, {pipe}::MIN_BLOCKS)"
            )),
            "{src}"
        );
        assert!(src.contains(".load_a(__stage"), "{src}");
        assert!(src.contains(".load_b(__stage"), "{src}");
        assert!(src.contains(".mma((int)(__i"), "{src}");
        // The plain loop is there too (the pipe is off below sm_80 and for other shapes).
        assert!(
            src.contains("wp::tile_matmul_acc_beside<__gp1>(acc_"),
            "{src}"
        );
        // Each copy of the offsets' arithmetic sees its own loop variable.
        assert_eq!(src.matches("const wp::usize k_").count(), 2, "{src}");
    }

    /// The example's kernel: tile dims and offsets through module consts (a loop over a range
    /// whose type the macro leaves to C++).
    #[test]
    fn a_gemm_k_loop_over_consts_is_pipelined() {
        let src = cuda(parse_quote! {
            fn gemm(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>) {
                let (i, j) = tid();
                let mut acc = tile_zeros::<f32, BM, BN>();
                let k_tiles = (a.shape()[1] + BK - 1) / BK;
                for k in 0..k_tiles {
                    let ta = tile_load::<BM, BK>(a, ((i * BM) as i32, (k * BK) as i32));
                    let tb = tile_load::<BK, BN>(b, ((k * BK) as i32, (j * BN) as i32));
                    tile_matmul(ta, tb, &mut acc);
                }
                tile_store(c, acc, ((i * BM) as i32, (j * BN) as i32));
            }
        });
        assert!(src.contains("::MIN_BLOCKS)"), "{src}");
        assert!(src.contains(".load_a(__stage"), "{src}");
        assert!(src.contains("wp::range_at(__r1, __j1)"), "{src}");
    }

    /// A loop whose loaded tile is read by anything but the matmul, or whose body does more
    /// than load and multiply, or whose operands are f32, is printed as written.
    #[test]
    fn other_loops_are_printed_as_written() {
        let cases: Vec<syn::ItemFn> = vec![
            parse_quote! {
                fn reads_a_tile(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>, d: Array<f16>) {
                    let mut acc = tile_zeros::<f32, 32, 32>();
                    for k in 0..4usize {
                        let ta = tile_load::<32, 32>(a, (0, (k * 32) as i32));
                        let tb = tile_load::<32, 32>(b, ((k * 32) as i32, 0));
                        d[k] = ta[(0, 0)];
                        tile_matmul(ta, tb, &mut acc);
                    }
                    tile_store(c, acc, (0, 0));
                }
            },
            parse_quote! {
                fn stores_in_the_loop(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>) {
                    let mut acc = tile_zeros::<f32, 32, 32>();
                    for k in 0..4usize {
                        let ta = tile_load::<32, 32>(a, (0, (k * 32) as i32));
                        let tb = tile_load::<32, 32>(b, ((k * 32) as i32, 0));
                        tile_matmul(ta, tb, &mut acc);
                        tile_store(c, acc, (0, 0));
                    }
                }
            },
            parse_quote! {
                fn f32_operands(a: Array<f32, 2>, b: Array<f32, 2>, c: Array<f32, 2>) {
                    let mut acc = tile_zeros::<f32, 32, 32>();
                    for k in 0..4usize {
                        let ta = tile_load::<32, 32>(a, (0, (k * 32) as i32));
                        let tb = tile_load::<32, 32>(b, ((k * 32) as i32, 0));
                        tile_matmul(ta, tb, &mut acc);
                    }
                    tile_store(c, acc, (0, 0));
                }
            },
        ];
        for item in cases {
            let name = item.sig.ident.to_string();
            let src = cuda(item);
            assert!(!src.contains("tile_gemm_pipe"), "{name}: {src}");
        }
    }
}
