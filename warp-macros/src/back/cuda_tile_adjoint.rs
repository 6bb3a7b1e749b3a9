//! The CUDA adjoint of a tiled kernel: what `back::cuda_adjoint` prints differently for one
//! (see `middle::adjoint::tiles` for the scheme).
//!
//! Every thread of a block runs the whole adjoint, as it runs the forward. Tiles and their
//! adjoint tiles are on slots of the block's dynamic shared memory: the forward's slots (the
//! replay recomputes the tiles there), then one per tile with an adjoint
//! (`middle::adjoint::adjoint_tiles`, the order `TileInfo::adjoint_shared_bytes` counts), zeroed
//! at the start. A cooperative statement (a tile operation of the replay, a tile adjoint call, a
//! tile adjoint's clear or accumulation) ends in a barrier, and gets one before it when lane
//! code ran since the last one, as in the forward (`back::cuda_tile`). A tile's seed `__r` is a
//! second `tile_t` over the adjoint's slot.

use super::cuda_adjoint::Printer;
use crate::ir::*;
use crate::middle::adjoint::*;
use crate::types::Ty;
use std::fmt::Write as _;

impl Printer<'_> {
    /// The replay's tile statements, printed as the forward prints them (`None`: not one).
    pub(super) fn tile_replay(&mut self, s: &AStmt) -> Option<Result<(), String>> {
        let AKind::Assign {
            dst,
            value: Value::Op(op),
        } = &s.kind
        else {
            return None;
        };
        let f = self.f();
        let tile_row = matches!(op, Op::Builtin { builtin, .. } if builtin.is_tile());
        if !(f.is_cooperative_op(*dst, op) || tile_row) {
            return None;
        }
        let st = Stmt {
            span: s.span,
            kind: StmtKind::Assign {
                dst: *dst,
                op: op.clone(),
                define: false,
            },
        };
        Some(self.e.tile_stmt(&st))
    }

    /// Whether `s` is a cooperative statement of the sweep (not control flow around one).
    pub(super) fn is_coop_leaf(&self, s: &AStmt) -> bool {
        let tile = |v: &VarId| self.f().ty(*v).is_tile();
        match &s.kind {
            AKind::AdjCall { func, .. } => is_block_call(func),
            AKind::TileMapAdj { .. } | AKind::LaneAdj { .. } => true,
            AKind::Push { .. } | AKind::Pop { .. } => tile_stack_op(self.f(), s),
            AKind::ClearAdj { var, .. } => tile(var),
            AKind::Accum {
                to: AdjOf::Var { var, .. },
                ..
            } => tile(var),
            _ => false,
        }
    }

    /// The slots: the forward's tiles, then the adjoint tiles, which start zero.
    pub(super) fn tile_slots(&mut self) -> Result<(), String> {
        self.e.section("tile");
        self.e.tile_slots()?;
        let f = self.f();
        let mut prev = f.tile_vars().last().map(|v| self.var(*v));
        let adj_tiles = adjoint_tiles(f);
        for &v in &adj_tiles {
            let t = super::cuda_tile::tile_type(f, f.ty(v))?;
            let name = self.adj(v);
            let off = match &prev {
                None => "0".to_string(),
                Some(p) => format!("wp::tile_slot_end(__off_{p}, decltype({p})::BYTES)"),
            };
            let _ = writeln!(
                self.e.out,
                "    constexpr wp::usize __off_{name} = {off};\n    {t} {name}(__smem + __off_{name});"
            );
            prev = Some(name);
        }
        for &v in &adj_tiles {
            let _ = writeln!(self.e.out, "    wp::tile_zeros({});", self.adj(v));
        }
        self.e.after_tile_op = !adj_tiles.is_empty();
        Ok(())
    }

    /// `@@ENTRY@@_adj` of a tiled kernel: CUDA block `b` runs block `b` of the launch
    /// (`__flat = b`; the launch has one CUDA block per block), all of its threads together. Each thread keeps its own history on its own stack
    /// (`WP_ADSTACK_BYTES` of local memory, emptied for each block), as in any adjoint; tiles
    /// are never pushed (`middle::adjoint::tiles::plan`).
    pub(super) fn tile_entry(&mut self) -> Result<(), String> {
        let mut decl = vec![
            "wp::launch_t __launch".into(),
            super::cuda::ENTRY_CTX_PARAM.into(),
        ];
        decl.extend(self.params()?);
        let mut call: Vec<String> = self.f().params.iter().map(|p| self.var(p.var)).collect();
        for gp in &self.adj.grad_params {
            if let GradParam::Array(v) = *gp {
                call.push(self.adj(v));
            }
        }
        call.extend(["__launch", "__flat", "&__ctx_value", "&__st"].map(String::from));
        let bytes = match self.adj.uses_stack {
            true => "WP_ADSTACK_BYTES",
            false => "0",
        };
        let _ = write!(
            self.e.out,
            "#ifdef __CUDACC__\nextern \"C\" __global__ void __launch_bounds__(WP_TILE_BLOCK_DIM) @@ENTRY@@_adj({}) {{\n    \
             char __buf[{bytes} > 0 ? {bytes} : 1];\n    \
             wp::adstack_t __st = wp::adstack_new(__buf, {bytes});\n    \
             const wp::i64 __flat = (wp::i64)blockIdx.x;\n    \
             {}\n    \
             if (__flat < __launch.total) @@SELF@@_adj({});\n}}\n#endif\n",
            decl.join(", "),
            super::cuda::THREAD_CTX,
            call.join(", ")
        );
        Ok(())
    }

    /// `tile_map`'s adjoint with scalar constants, as the CPU's (`rust_tile_adjoint`): the
    /// scalar adjoint of its function on each element, the tiles' adjoints element by element,
    /// each float constant's temporary (`__g<k>`) the block total of the elements'
    /// contributions in the reductions' order (`tile_detail::block_total`, returned to every
    /// thread, as `t * s` gives `s` its adjoint). One pass per float constant, through a local
    /// functor of the element index holding copies of the tile views it reads; the first also
    /// accumulates the tiles' adjoints, the others give them to locals they drop. Without a
    /// float constant one loop over the elements does it.
    fn tile_map_consts_adj(
        &mut self,
        g: TileFn,
        values: &[VarId],
        grads: &[GradArg],
        sp: proc_macro2::Span,
    ) -> Result<String, String> {
        let f = self.f();
        let n = values.len();
        let is_tile: Vec<bool> = values.iter().map(|v| f.ty(*v).is_tile()).collect();
        let elem = |v: VarId| match f.ty(v) {
            Ty::Tile(e, _) => super::cuda::cpp_type(e).ok_or("a tile element type"),
            t => super::cuda::cpp_type(t).ok_or("a scalar constant's type"),
        };
        let types: Vec<String> = values.iter().map(|v| elem(*v)).collect::<Result<_, _>>()?;
        let floats: Vec<usize> = (0..n)
            .filter(|j| !is_tile[*j] && matches!(f.ty(values[*j]), Ty::Scalar(s) if s.is_float()))
            .collect();
        let xs: Vec<String> = values.iter().map(|v| self.var(*v)).collect();
        let gs: Vec<String> = grads.iter().map(|g| self.grad_arg(g)).collect();
        let (name, extra) = match g {
            TileFn::Builtin(b) => {
                self.e.section(b.section);
                (format!("wp::adj_{}", b.name), "")
            }
            TileFn::Op(o) => (format!("wp::{}", o.adjoint_fn().unwrap_or("adj_add")), ""),
            TileFn::Func(k) => (format!("@@F{k}@@_adj"), ", __ctx, __stack"),
        };
        // The locals and the call of one pass, naming the outer values through `at` (a
        // functor's members have names of their own: a member named as the outer variable its
        // type is taken from would change that name's meaning in the class); `writes`: the
        // tiles' adjoints are the real ones.
        let body = |writes: bool, at: &dyn Fn(&str) -> String| {
            let mut locals = String::new();
            let mut adjs = Vec::new();
            for j in 0..n {
                if is_tile[j] && writes {
                    adjs.push(format!("{}.data[__e]", at(&gs[j])));
                } else {
                    let _ = write!(locals, "{t} __z{j} = {t}(0); ", t = types[j]);
                    adjs.push(format!("__z{j}"));
                }
            }
            let ops: Vec<String> = (0..n)
                .map(|j| match is_tile[j] {
                    true => format!("{}.data[__e]", at(&xs[j])),
                    false => at(&xs[j]),
                })
                .collect();
            let call = format!(
                "{name}({}, {}, {}.data[__e]{extra});",
                ops.join(", "),
                adjs.join(", "),
                at("__r"),
            );
            (locals, call)
        };
        let size = "wp::detail::remove_cvref<decltype(__r)>::type::SIZE";
        if floats.is_empty() {
            let (locals, call) = body(true, &|x| x.to_string());
            return Ok(format!(
                "for (int __e = (int)threadIdx.x; __e < {size}; __e += WP_TILE_BLOCK_DIM) {{ {locals}{call} }} __syncthreads();"
            ));
        }
        let mut text = String::new();
        for (pass, &j) in floats.iter().enumerate() {
            let writes = pass == 0;
            // What the functor reads: the operands, the tiles' adjoints it writes, the seed.
            let mut names: Vec<String> = xs.clone();
            if writes {
                names.extend((0..n).filter(|q| is_tile[*q]).map(|q| gs[q].clone()));
            }
            names.push("__r".into());
            let mut seen = std::collections::HashSet::new();
            names.retain(|m| seen.insert(m.clone()));
            let members: String = names
                .iter()
                .enumerate()
                .map(|(i, m)| format!("wp::detail::remove_cvref<decltype({m})>::type __m{i}; "))
                .collect();
            let at = |x: &str| match names.iter().position(|m| m == x) {
                Some(i) => format!("__m{i}"),
                None => x.to_string(),
            };
            let (locals, call) = body(writes, &at);
            // A func's adjoint takes the fault context and the thread's stack last.
            let (ctx_members, ctx_values) = match g {
                TileFn::Func(_) => (
                    "wp::ctx_t* __ctx; wp::adstack_t* __stack; ",
                    ", __ctx, __stack",
                ),
                _ => ("", ""),
            };
            self.e.tmp += 1;
            let m = format!("__cfn{}", self.e.tmp);
            let t = &types[j];
            self.line(
                sp,
                format!(
                    "struct {m} {{ {members}{ctx_members}WP_FN {t} operator()(int __e) const {{ {locals}{call} return __z{j}; }} }};"
                ),
            );
            let _ = write!(
                text,
                "{} += wp::tile_detail::block_total<{t}, {size}>({m}{{{}{ctx_values}}}); ",
                gs[j],
                names.join(", ")
            );
        }
        Ok(text)
    }

    /// `tile_map`'s adjoint: a local functor calling the scalar adjoint of its function, and
    /// `wp::adj_tile_map1/2` with it.
    pub(super) fn tile_map_adj(
        &mut self,
        g: TileFn,
        values: &[VarId],
        grads: &[GradArg],
        dst: VarId,
        sp: proc_macro2::Span,
    ) -> Result<String, String> {
        if values.iter().any(|v| !self.f().ty(*v).is_tile()) {
            return self.tile_map_consts_adj(g, values, grads, sp);
        }
        // A func over three or more tiles: its adjoint on each element, the loop written out.
        if let (TileFn::Func(k), true) = (g, values.len() > 2) {
            let xs: Vec<String> = values
                .iter()
                .map(|v| format!("{}.data[__e]", self.var(*v)))
                .collect();
            let gs: Vec<String> = grads
                .iter()
                .map(|g| format!("{}.data[__e]", self.grad_arg(g)))
                .collect();
            return Ok(format!(
                "for (int __e = (int)threadIdx.x; __e < wp::detail::remove_cvref<decltype(__r)>::type::SIZE; __e += WP_TILE_BLOCK_DIM) @@F{k}@@_adj({}, {}, __r.data[__e], __ctx, __stack); __syncthreads();",
                xs.join(", "),
                gs.join(", ")
            ));
        }
        let f = self.f();
        let elem = |v: VarId| match f.ty(v) {
            Ty::Tile(e, _) => super::cuda::cpp_type(e).ok_or("a tile element type"),
            _ => Err("a tile"),
        };
        let scalar = match g {
            TileFn::Builtin(b) => {
                self.e.section(b.section);
                format!("wp::adj_{}", b.name)
            }
            TileFn::Op(o) => format!("wp::{}", o.adjoint_fn().unwrap_or("adj_add")),
            // A user func's adjoint takes the fault context and the thread's adjoint stack
            // last (each thread runs it for the elements it owns, on its own stack).
            TileFn::Func(k) => format!("@@F{k}@@_adj"),
        };
        let ts: Vec<String> = values.iter().map(|v| elem(*v)).collect::<Result<_, _>>()?;
        // The seed's element is the result's: the first operand's for every builtin and
        // operator a tile map differentiates (one float type), the annotated one for a func.
        let rt = elem(dst)?;
        let (member, extra, make) = match g {
            TileFn::Func(_) => (
                "wp::ctx_t* __ctx; wp::adstack_t* __stack; ",
                ", __ctx, __stack",
                "{__ctx, __stack}",
            ),
            _ => ("", "", "{}"),
        };
        let (ps, call) = match values.len() {
            1 => (
                format!("{} x, {}& ax, {rt} g", ts[0], ts[0]),
                format!("{scalar}(x, ax, g{extra});"),
            ),
            _ => (
                format!(
                    "{} x, {} y, {}& ax, {}& ay, {rt} g",
                    ts[0], ts[1], ts[0], ts[1]
                ),
                format!("{scalar}(x, y, ax, ay, g{extra});"),
            ),
        };
        self.e.tmp += 1;
        let m = format!("__afn{}", self.e.tmp);
        self.line(
            sp,
            format!("struct {m} {{ {member}WP_FN void operator()({ps}) const {{ {call} }} }};"),
        );
        let xs: Vec<String> = values.iter().map(|v| self.var(*v)).collect();
        let gs: Vec<String> = grads.iter().map(|g| self.grad_arg(g)).collect();
        Ok(format!(
            "wp::adj_tile_map{}({}, {}, __r, {m}{make});",
            values.len(),
            xs.join(", "),
            gs.join(", ")
        ))
    }
}
