//! CUDA back end for tiles: the slots of a tiled kernel's tiles in shared memory, its tile
//! statements as calls of wp_tile.h, the barriers between lane code and tile operations, and
//! the entry that gives each block its block index.
//!
//! Every thread runs the whole body (lane code needs no plan here, unlike the CPU's). A tile
//! is a `wp::tile_t` over a slot of the block's dynamic shared memory: one slot per tile
//! variable, never reused, each 16-byte aligned; `expand`'s `TileInfo` computes the same total
//! with the same rule (`tile_slot_end`), which is the launch's dynamic shared memory size.
//!
//! Barriers: each tile operation of wp_tile.h ends with `__syncthreads()`, so its result is
//! visible when it returns. Before a tile operation that does not directly follow another,
//! the emitter adds one more: lane code since the last barrier may still be reading a slot the
//! operation is about to write (a tile read by `t[i]`, a loop's previous iteration). The entry
//! ends each block with one, before the block's slots are reused for the next block.

use super::cuda::Emitter;
use crate::ir::*;
use crate::types::{Dim, Ty};

/// The C++ spelling of a tile dim: a literal, or the const's value (`@@K<k>@@`).
fn dim_cpp(f: &Function, d: &Dim) -> Result<String, String> {
    match d {
        Dim::Lit(n) => Ok(n.to_string()),
        Dim::Const(p) => {
            let want: syn::Path = syn::parse_str(p).map_err(|e| e.to_string())?;
            let k =
                f.consts.iter().position(|c| c == &want).ok_or_else(|| {
                    format!("the tile dim `{p}` is not among the kernel's consts")
                })?;
            Ok(format!("@@K{k}@@"))
        }
    }
}

/// `wp::tile_t<float, 16, @@K0@@>`.
pub(crate) fn tile_type(f: &Function, t: &Ty) -> Result<String, String> {
    let Ty::Tile(e, dims) = t else {
        return Err(format!("`{t}` is not a tile"));
    };
    let e = super::cuda::cpp_type(e).ok_or("a tile element without a C++ type")?;
    let dims = dims
        .iter()
        .map(|d| dim_cpp(f, d))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(format!("wp::tile_t<{e}, {}>", dims.join(", ")))
}

impl Emitter<'_> {
    /// The slots: the block's shared memory, then each tile variable's `tile_t` on its slot.
    pub(crate) fn tile_slots(&mut self) -> Result<(), String> {
        let e = self;
        let f = e.f;
        e.out
            .push_str("    extern __shared__ __align__(16) unsigned char __smem[];\n");
        let mut prev: Option<String> = None;
        for v in f.tile_vars() {
            let t = tile_type(f, f.ty(v))?;
            let name = e.var(v);
            let off = match &prev {
                None => "0".to_string(),
                Some(p) => format!("wp::tile_slot_end(__off_{p}, decltype({p})::BYTES)"),
            };
            e.out.push_str(&format!(
            "    constexpr wp::usize __off_{name} = {off};\n    {t} {name}(__smem + __off_{name});\n"
        ));
            prev = Some(name);
        }
        Ok(())
    }

    /// Whether `s` is a tile statement this module prints: a cooperative one, or a tile row
    /// (`t[i]`).
    pub(crate) fn is_tile_stmt(&self, s: &Stmt) -> bool {
        let f = self.f;
        f.is_cooperative(s)
            || matches!(&s.kind, StmtKind::Assign { op: Op::Builtin { builtin, .. }, .. } if builtin.is_tile())
    }

    /// A tile statement.
    pub(crate) fn tile_stmt(&mut self, s: &Stmt) -> Result<(), String> {
        let e = self;
        let f = e.f;
        let sp = s.span;
        let StmtKind::Assign { dst, op, define } = &s.kind else {
            unreachable!("tile statements are assignments")
        };
        let d = e.var(*dst);
        let v = |e: &Emitter, x: &VarId| e.var(*x);
        let cooperative = f.is_cooperative(s);
        if cooperative && !e.after_tile_op {
            e.line(sp, "__syncthreads();");
        }
        let text = match op {
            Op::Builtin { builtin, args } => {
                let a: Vec<String> = args.iter().map(|x| v(e, x)).collect();
                match builtin.name {
                    "tile_zeros" | "tile_ones" => format!("wp::{}({d});", builtin.name),
                    "tile_arange" => format!("wp::tile_arange({d}, {}, {});", a[0], a[1]),
                    "tile_load" => format!("wp::tile_load({d}, {}, __ctx);", a.join(", ")),
                    "tile_store" => {
                        // (array, tile, offsets..) -> (array, offsets.., tile)
                        let mut r = vec![a[0].clone()];
                        r.extend(a[2..].iter().cloned());
                        r.push(a[1].clone());
                        format!("wp::tile_store({}, __ctx);", r.join(", "))
                    }
                    "tile" => format!("wp::tile({d}, {});", a[0]),
                    "tile_transpose" => format!("wp::tile_transpose({d}, {});", a[0]),
                    "tile_scan_inclusive"
                    | "tile_scan_exclusive"
                    | "tile_scan_max_inclusive"
                    | "tile_scan_min_inclusive" => format!("wp::{}({d}, {});", builtin.name, a[0]),
                    "tile_broadcast" => format!("wp::tile_broadcast({d}, {});", a[0]),
                    "tile_atomic_add" => {
                        e.section("atomic");
                        // (array, tile, offsets..) -> (old, array, offsets.., tile)
                        let mut r = vec![a[0].clone()];
                        r.extend(a[2..].iter().cloned());
                        r.push(a[1].clone());
                        format!("wp::tile_atomic_add({d}, {}, __ctx);", r.join(", "))
                    }
                    "untile" => {
                        let t = super::cuda::cpp_type(f.ty(*dst)).ok_or("an untile result type")?;
                        if *define {
                            format!("{t} {d} = wp::untile({});", a[0])
                        } else {
                            format!("{d} = wp::untile({});", a[0])
                        }
                    }
                    "tile_extract" => {
                        let t = super::cuda::cpp_type(f.ty(*dst)).ok_or("a tile element type")?;
                        let call = format!("wp::tile_extract({}, __ctx)", a.join(", "));
                        if *define {
                            format!("{t} {d} = {call};")
                        } else {
                            format!("{d} = {call};")
                        }
                    }
                    "tile_sum" | "tile_min" | "tile_max" | "tile_argmin" | "tile_argmax" => {
                        format!("wp::{}({d}, {});", builtin.name, a[0])
                    }
                    "tile_matmul" | "tile_matmul_acc" => {
                        // f16 and bf16 operands: the tensor-core matmul (its FMA fallback
                        // included).
                        if matches!(f.ty(args[0]), Ty::Tile(el, _) if matches!(**el, Ty::Scalar(crate::types::Scalar::F16 | crate::types::Scalar::BF16)))
                        {
                            e.section("tile_mma");
                        }
                        match &e.beside_pipe {
                            Some(pipe) if builtin.name == "tile_matmul_acc" => format!(
                                "wp::tile_matmul_acc_beside<{pipe}>({d}, {}, {});",
                                a[0], a[1]
                            ),
                            _ => format!("wp::{}({d}, {}, {});", builtin.name, a[0], a[1]),
                        }
                    }
                    // `p = tile_sort(keys)`, then `x = tile_sort(x, p)` (the row's comment);
                    // `wp::tile_permute` may write the tile it reads.
                    "tile_sort" => {
                        e.section("tile_sort");
                        match &a[..] {
                            [k] => format!("wp::tile_sort({d}, {k});"),
                            [x, p] => format!("wp::tile_permute({d}, {x}, {p});"),
                            _ => {
                                return Err("tile_sort's statements have one or two operands".into())
                            }
                        }
                    }
                    "tile_full" => format!("wp::tile_full({d}, {});", a[0]),
                    "tile_astype" => format!("wp::tile_astype({d}, {});", a[0]),
                    "tile_reshape" | "tile_squeeze" => format!("wp::tile_reshape({d}, {});", a[0]),
                    "tile_diag_add" => format!("wp::tile_diag_add({d}, {}, {});", a[0], a[1]),
                    "tile_cholesky" => {
                        e.section("tile_linalg");
                        format!("wp::tile_cholesky({d}, {});", a[0])
                    }
                    "tile_cholesky_solve" | "tile_lower_solve" | "tile_upper_solve" => {
                        e.section("tile_linalg");
                        format!("wp::{}({d}, {}, {});", builtin.name, a[0], a[1])
                    }
                    "tile_view" => format!("wp::tile_view({d}, {}, __ctx);", a.join(", ")),
                    // In place: the statement's destination is its first argument's slot.
                    "tile_assign"
                    | "tile_add_inplace"
                    | "tile_sub_inplace"
                    | "tile_bit_and_inplace"
                    | "tile_bit_or_inplace"
                    | "tile_bit_xor_inplace" => {
                        format!("wp::{}({d}, {}, __ctx);", builtin.name, a[1..].join(", "))
                    }
                    "tile_fft" | "tile_ifft" => {
                        // In place: the statement's destination is its argument's slot.
                        e.section("tile_fft");
                        format!("wp::{}({d});", builtin.name)
                    }
                    other => return Err(format!("`{other}` has no CUDA form yet")),
                }
            }
            // A func over three or more tiles, or a map with scalar constants: the loop
            // written out (each thread its elements, as `wp::tile_map`), a tile read at the
            // element, a scalar as it is (the same in every thread), a func taking the fault
            // context last.
            Op::TileMap { f: g, args }
                if (matches!(g, TileFn::Func(_)) && args.len() > 2)
                    || args.iter().any(|x| !f.ty(*x).is_tile()) =>
            {
                let xs: Vec<String> = args
                    .iter()
                    .map(|x| match f.ty(*x).is_tile() {
                        true => format!("{}.data[__e]", v(e, x)),
                        false => v(e, x),
                    })
                    .collect();
                let body = e.tile_fn_body(*g, args, &xs);
                format!(
                    "for (int __e = (int)threadIdx.x; __e < decltype({d})::SIZE; __e += WP_TILE_BLOCK_DIM) {d}.data[__e] = {body}; __syncthreads();"
                )
            }
            Op::TileMap { f: g, args } => {
                let a: Vec<String> = args.iter().map(|x| v(e, x)).collect();
                let m = e.tile_functor(*g, args, *dst, sp)?;
                match a.len() {
                    1 => format!("wp::tile_map({d}, {}, {m});", a[0]),
                    _ => format!("wp::tile_map2({d}, {}, {}, {m});", a[0], a[1]),
                }
            }
            Op::TileReduce { f: g, arg } => {
                let m = e.tile_functor(*g, &[*arg, *arg], *dst, sp)?;
                format!("wp::tile_reduce({d}, {}, {m});", v(e, arg))
            }
            Op::Copy(x) => format!("wp::tile_copy({d}, {});", v(e, x)),
            Op::Unary(UnOp::Neg, x) => format!("wp::tile_neg({d}, {});", v(e, x)),
            Op::Binary(o, l, r) => {
                let name = match o {
                    BinOp::Add => "tile_add",
                    BinOp::Sub => "tile_sub",
                    BinOp::Mul => "tile_mul",
                    BinOp::Div => "tile_div",
                    _ => return Err(format!("`{}` on tiles has no CUDA form", o.symbol())),
                };
                format!("wp::{name}({d}, {}, {});", v(e, l), v(e, r))
            }
            _ => return Err("this operation on tiles has no CUDA form yet".into()),
        };
        e.line(sp, &text);
        e.after_tile_op = cooperative;
        Ok(())
    }

    /// A local functor applying `g` to elements of the tiles `args`, giving elements of the tile
    /// `dst` (NVRTC compiles a lambda as a host function, and a local class may not have a member
    /// template, so its types are concrete); returns the expression making one. A user func's
    /// functor holds the fault context, which the func takes last (a fault in one element sets
    /// it and that element's result is zero, as for a scalar call).
    fn tile_functor(
        &mut self,
        g: TileFn,
        args: &[VarId],
        dst: VarId,
        sp: proc_macro2::Span,
    ) -> Result<String, String> {
        let f = self.f;
        let elem = |t: &Ty| match t {
            Ty::Tile(el, _) => super::cuda::cpp_type(el).ok_or("a tile element type"),
            _ => Err("a tile"),
        };
        let r = elem(f.ty(dst))?;
        let ps: Vec<String> = args
            .iter()
            .zip(["x", "y"])
            .map(|(x, n)| elem(f.ty(*x)).map(|t| format!("{t} {n}")))
            .collect::<Result<_, _>>()?;
        let xs: Vec<String> = ["x", "y"][..args.len()]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let body = self.tile_fn_body(g, args, &xs);
        self.tmp += 1;
        let m = format!("__fn{}", self.tmp);
        let (member, make) = match g {
            TileFn::Func(_) => ("wp::ctx_t* __ctx; ", format!("{m}{{__ctx}}")),
            _ => ("", format!("{m}{{}}")),
        };
        self.line(
            sp,
            &format!(
                "struct {m} {{ {member}WP_FN {r} operator()({}) const {{ return {body}; }} }};",
                ps.join(", ")
            ),
        );
        Ok(make)
    }

    /// `g` applied to the operands `xs` (C++ expressions of the elements of `args`, or of a
    /// scalar constant): integer `+ - *` wrap as on the CPU; a user func takes the fault
    /// context (`__ctx`) last.
    pub(crate) fn tile_fn_body(&mut self, g: TileFn, args: &[VarId], xs: &[String]) -> String {
        match (g, xs) {
            (TileFn::Op(o), [x, y]) if is_int_elem(self.f.ty(args[0])) => {
                let w = match o {
                    BinOp::Add => "w_add",
                    BinOp::Sub => "w_sub",
                    _ => "w_mul",
                };
                format!("wp::{w}({x}, {y})")
            }
            (TileFn::Op(o), [x, y]) => format!("({x} {} {y})", o.symbol()),
            (TileFn::Builtin(b), _) => {
                self.section(b.section);
                format!("{}({})", b.cuda, xs.join(", "))
            }
            (TileFn::Func(k), _) => {
                let suffix = if self.replay { "_replay" } else { "" };
                format!("@@F{k}@@{suffix}({}, __ctx)", xs.join(", "))
            }
            (TileFn::Op(_), _) => "/* an operator takes two operands */ 0".to_string(),
        }
    }

    /// The entry of a tiled kernel: CUDA block `b` runs block `b` of the launch, `@@SELF@@` with
    /// `__flat = b` (its `tid()`), every thread of the CUDA block together. The launch has one
    /// CUDA block per block (at most `i32::MAX`, checked when it is prepared): no grid-stride
    /// loop, whose hoisted address arithmetic cost the tile code a third more registers. With
    /// pipelined GEMM loops, the bounds carry their blocks-per-SM hint (`MIN_BLOCKS`: two where
    /// shared memory and accumulators allow, which caps registers so two blocks fit).
    pub(crate) fn tile_entry(&self, decl: &str, call: &str) -> String {
        let bounds = match self.pipes.split_first() {
            None => "WP_TILE_BLOCK_DIM".to_string(),
            Some((first, rest)) => {
                let min = rest.iter().fold(format!("{first}::MIN_BLOCKS"), |m, p| {
                    format!("({m} < {p}::MIN_BLOCKS ? {m} : {p}::MIN_BLOCKS)")
                });
                format!("WP_TILE_BLOCK_DIM, {min}")
            }
        };
        format!(
        "#ifdef __CUDACC__\nextern \"C\" __global__ void __launch_bounds__({bounds}) @@ENTRY@@({decl}) {{\n    \
         const wp::i64 __flat = (wp::i64)blockIdx.x;\n    \
         {}\n    \
         if (__flat < __launch.total) @@SELF@@({call});\n}}\n#endif\n",
        super::cuda::THREAD_CTX
    )
    }
}

/// Integer tiles: their `+ - *` wrap (`wp::w_add`, ..), as the CPU's.
fn is_int_elem(t: &Ty) -> bool {
    matches!(t, Ty::Tile(e, _) if e.is_int_scalar())
}
