//! The CPU adjoint of a tiled kernel: the adjoint IR (`middle::adjoint`) printed as one task
//! per block, the way `back::rust_tile` prints the forward.
//!
//! The statements the whole block runs together (`middle::adjoint::is_block_level`: the
//! replay's tile operations, tile adjoint calls, a tile adjoint's seed, clear and
//! accumulation, and control flow around them) are printed once; each run of other
//! statements between them is a loop over the lanes. A variable that lane code touches is kept
//! per lane, with its adjoint (`__pl_x`, `__pl_adj_x`: `warp_core::block::PerLane`); a lane loop
//! loads it into a local of the ordinary name and stores it back, so the statements print as in
//! any adjoint. A block-level statement reads and writes lane 0's copy: its scalar operands are
//! uniform, and the adjoint it accumulates into one is added once for the block (the
//! uniform-operand rule of `middle::adjoint::tiles`).
//!
//! The adjoint stack: each lane has its own (`__lanes`, `warp_core::AdStack::lanes`), which
//! `__stack` names inside a lane loop, so a lane pushes and pops its own history in its own
//! order, as a CUDA thread does. Block-level control flow (a loop around tile operations, an
//! `if` on a uniform condition) pushes and pops its trip counts on lane 0's stack, in the order
//! lane 0 would; a decision recorded per lane is popped from every lane's stack.

use super::rust_adjoint::{counted_loop, reversed_loop, temp, Printer};
use crate::ir::*;
use crate::middle::adjoint::*;
use crate::types::Ty;
use proc_macro2::{Literal, Span, TokenStream};
use quote::{format_ident, quote, quote_spanned};

impl Printer<'_> {
    /// The body of a tiled kernel's CPU adjoint for one block (`__flat` is the block's index).
    pub(super) fn tiled_body(mut self) -> Result<TokenStream, String> {
        let adj = self.adj;
        self.per_lane = per_lane_vars(adj);
        let p = &self;
        let mut out = quote!(let __bd = __grid.block_dim;);
        if adj.uses_stack {
            out.extend(quote!(let __lanes: &mut [__wp::AdStack] = __stack.lanes(__bd);));
        }
        out.extend(p.declarations());
        for v in 0..adj.f.vars.len() {
            if !p.per_lane[v] {
                continue;
            }
            let (x, pl) = (p.var(v), p.pl(v));
            out.extend(quote!(let mut #pl = __wp::block::PerLane::splat(#x, __bd);));
            if adj.adjs.contains(&v) {
                let (a, pa) = (p.adj(v), p.pl_adj(v));
                out.extend(quote!(let mut #pa = __wp::block::PerLane::splat(#a, __bd);));
            }
        }
        out.extend(p.list(&adj.body)?);
        Ok(out)
    }
}

/// Whether `v` may be kept per lane: not a parameter, array or tile (those are the block's).
fn laneable(f: &Function, v: VarId) -> bool {
    !f.params.iter().any(|p| p.var == v) && !matches!(f.ty(v), Ty::Array(..) | Ty::Tile(..))
}

/// The variables kept per lane: those lane code touches, the per-lane operand of `tile(x)`
/// and the result of `untile`.
fn per_lane_vars(adj: &Adjoint) -> Vec<bool> {
    let f = &adj.f;
    let mut out = vec![false; f.vars.len()];
    fn walk(f: &Function, b: &[AStmt], out: &mut Vec<bool>) {
        for s in b {
            if !is_block_level(f, s) {
                vars_of(s, &mut |v| out[v] = out[v] || laneable(f, v));
                continue;
            }
            match &s.kind {
                AKind::If { then, els, .. } => {
                    walk(f, then, out);
                    walk(f, els, out);
                }
                AKind::Scope(b) | AKind::RevLoop { body: b } => walk(f, b, out),
                AKind::Loop {
                    range, exit, body, ..
                } => {
                    // The header reads lane 0's copies of what lane code computed.
                    let mut header = exit.clone();
                    if let Some(r) = range {
                        header.extend([r.start, r.end]);
                        for a in &r.adapters {
                            if let RangeAdapter::StepBy(k) = a {
                                header.push(*k);
                            }
                        }
                    }
                    for v in header {
                        out[v] = out[v] || laneable(f, v);
                    }
                    walk(f, body, out)
                }
                _ => {}
            }
            for v in lane_operands(s) {
                out[v] = laneable(f, v);
            }
        }
    }
    walk(f, &adj.body, &mut out);
    out
}

/// The per-lane operands of a block-level statement that reads or writes all lanes' copies:
/// `tile(x)` and `untile(t)` of the replay, and [`AKind::LaneAdj`].
fn lane_operands(s: &AStmt) -> Vec<VarId> {
    match &s.kind {
        AKind::Assign {
            dst,
            value: Value::Op(Op::Builtin { builtin, args }),
        } if builtin.lanes => match builtin.name {
            "tile" => vec![args[0]],
            _ => vec![*dst],
        },
        AKind::LaneAdj { lanes, .. } => vec![*lanes],
        AKind::Scope(b) => b.iter().flat_map(lane_operands).collect(),
        _ => Vec::new(),
    }
}

/// Every variable `s` names (values and adjoints alike), nested statements included.
fn vars_of(s: &AStmt, out: &mut dyn FnMut(VarId)) {
    let index = |i: &Index, out: &mut dyn FnMut(VarId)| {
        if let Index::At(vs) = i {
            vs.iter().for_each(|v| out(*v));
        }
    };
    let grad = |g: &GradSrc, out: &mut dyn FnMut(VarId)| match g {
        GradSrc::Adj { var, .. } | GradSrc::Zero(var) => out(*var),
        GradSrc::Take {
            array,
            index: i,
            like,
        }
        | GradSrc::Get {
            array,
            index: i,
            like,
        } => {
            out(*array);
            out(*like);
            index(i, out);
        }
        GradSrc::Custom { args, .. } => args.iter().for_each(|v| out(*v)),
        GradSrc::AdjElem { var, index } => {
            out(*var);
            out(*index);
        }
        _ => {}
    };
    let garg = |g: &GradArg, out: &mut dyn FnMut(VarId)| match g {
        GradArg::Adj(v) | GradArg::ArrayGrad(v) => out(*v),
        GradArg::Temp(_) => {}
    };
    match &s.kind {
        AKind::Assign { dst, value } => {
            out(*dst);
            match value {
                Value::Op(op) => op.for_each_read(&mut |v| out(v)),
                Value::Zero { like } => out(*like),
            }
        }
        AKind::SetMember { var, value, .. } => {
            out(*var);
            out(*value);
        }
        AKind::SetElem { var, index, value } => {
            out(*var);
            out(*index);
            out(*value);
        }
        AKind::ClearAdjElem { var, index } => {
            out(*var);
            out(*index);
        }
        AKind::Push { var, .. } | AKind::Pop { var } | AKind::ClearAdj { var, .. } => out(*var),
        AKind::Loop {
            range, exit, body, ..
        } => {
            if let Some(r) = range {
                out(r.start);
                out(r.end);
                for a in &r.adapters {
                    if let RangeAdapter::StepBy(k) = a {
                        out(*k);
                    }
                }
            }
            exit.iter().for_each(|v| out(*v));
            body.iter().for_each(|s| vars_of(s, out));
        }
        AKind::StepVar { var, end } => {
            out(*var);
            out(*end);
        }
        AKind::If { cond, then, els } => {
            if let Cond::Var(c) = cond {
                out(*c);
            }
            then.iter().chain(els).for_each(|s| vars_of(s, out));
        }
        AKind::Scope(b) | AKind::RevLoop { body: b } => b.iter().for_each(|s| vars_of(s, out)),
        AKind::Seed(g) => grad(g, out),
        AKind::Accum { to, from } => {
            match to {
                AdjOf::Var { var, .. } => out(*var),
                AdjOf::Elem { var, index } => {
                    out(*var);
                    out(*index);
                }
                AdjOf::Out(_) => {}
            }
            grad(from, out);
        }
        AKind::ZeroTemp { like, .. } => match like {
            TempLike::Var(v) | TempLike::Param { arg: v, .. } => out(*v),
        },
        AKind::AdjCall { values, grads, .. } => {
            for a in values {
                match a {
                    Arg::Value(v) | Arg::Array(v) => out(*v),
                }
            }
            grads.iter().for_each(|g| garg(g, out));
        }
        AKind::FuncAdj { values, grads, .. } | AKind::TileMapAdj { values, grads, .. } => {
            values.iter().for_each(|v| out(*v));
            grads.iter().for_each(|g| garg(g, out));
        }
        AKind::GradAccum {
            array,
            index: i,
            from,
            ..
        } => {
            out(*array);
            index(i, out);
            grad(from, out);
        }
        AKind::GradClearOwn { array, index: i } => {
            out(*array);
            index(i, out);
        }
        AKind::LaneAdj { lanes, tile, .. } => {
            out(*lanes);
            out(*tile);
        }
    }
}

impl Printer<'_> {
    fn pl(&self, v: VarId) -> syn::Ident {
        format_ident!("__pl_{}", self.var(v))
    }

    fn pl_adj(&self, v: VarId) -> syn::Ident {
        format_ident!("__pl_adj_{}", self.var(v))
    }

    fn name(&self) -> Literal {
        Literal::string(&self.f().name)
    }

    /// A list of statements: lane loops and block-level statements.
    fn list(&self, b: &[AStmt]) -> Result<TokenStream, String> {
        let mut out = TokenStream::new();
        let mut run: Vec<&AStmt> = Vec::new();
        for s in b {
            if is_block_level(self.f(), s) {
                out.extend(self.region(&run)?);
                run.clear();
                out.extend(self.block_stmt(s)?);
            } else {
                run.push(s);
            }
        }
        out.extend(self.region(&run)?);
        Ok(out)
    }

    /// The per-lane variables (with their adjoints) `stmts` name, in first-occurrence order,
    /// except `skip`.
    fn lane_vars(&self, stmts: &[&AStmt], skip: &[VarId]) -> Vec<VarId> {
        let mut seen = Vec::new();
        for s in stmts {
            vars_of(s, &mut |v| {
                if self.per_lane[v] && !seen.contains(&v) && !skip.contains(&v) {
                    seen.push(v);
                }
            });
        }
        seen
    }

    /// Loads of lane `lane`'s copies of `vars` into locals, and the stores back.
    fn lane_copies(&self, vars: &[VarId], lane: TokenStream) -> (TokenStream, TokenStream) {
        let (mut load, mut store) = (TokenStream::new(), TokenStream::new());
        for &v in vars {
            let (x, pl) = (self.var(v), self.pl(v));
            load.extend(quote!(let mut #x = #pl[#lane];));
            store.extend(quote!(#pl[#lane] = #x;));
            if self.adj.adjs.contains(&v) {
                let (a, pa) = (self.adj(v), self.pl_adj(v));
                load.extend(quote!(let mut #a = #pa[#lane];));
                store.extend(quote!(#pa[#lane] = #a;));
            }
        }
        (load, store)
    }

    /// A run of lane-level statements: the loop over the lanes.
    fn region(&self, run: &[&AStmt]) -> Result<TokenStream, String> {
        if run.is_empty() {
            return Ok(TokenStream::new());
        }
        let vars = self.lane_vars(run, &[]);
        let (load, store) = self.lane_copies(&vars, quote!(__lane));
        let body: TokenStream = run
            .iter()
            .map(|s| self.stmt(s))
            .collect::<Result<_, String>>()?;
        let stack = self.lane_stack(quote!(__lane));
        Ok(quote! {
            for __lane in 0..__bd {
                #stack
                #load
                #body
                #store
            }
        })
    }

    /// `__stack` as lane `lane`'s stack, where the adjoint has one.
    fn lane_stack(&self, lane: TokenStream) -> TokenStream {
        match self.adj.uses_stack {
            true => quote!(let __stack = &mut __lanes[#lane];),
            false => TokenStream::new(),
        }
    }

    /// Lane 0's copies of the per-lane values among `vars`, loaded into locals of their names.
    fn lane0_reads(&self, vars: &[VarId]) -> TokenStream {
        let vars: Vec<VarId> = vars.iter().copied().filter(|v| self.per_lane[*v]).collect();
        self.lane_copies(&vars, quote!(0)).0
    }

    /// A loop around tile operations, run by the block together: its header reads lane 0's
    /// copies, its trip count goes on lane 0's stack.
    fn block_loop(&self, s: &AStmt) -> Result<TokenStream, String> {
        let sp = s.span;
        let lane0 = quote!(__lanes[0]);
        match &s.kind {
            AKind::Loop {
                range,
                exit,
                body,
                line,
            } => {
                let range = range.as_ref().map(|r| {
                    let mut vars = vec![r.start, r.end];
                    for a in &r.adapters {
                        if let RangeAdapter::StepBy(k) = a {
                            vars.push(*k);
                        }
                    }
                    let (reads, r) = (self.lane0_reads(&vars), self.range_tokens(r));
                    quote!({ #reads #r })
                });
                let exit = match exit.is_empty() {
                    true => TokenStream::new(),
                    false => {
                        let reads = self.lane0_reads(exit);
                        let fs = exit.iter().map(|v| self.var(*v));
                        quote!(if { #reads false #(|| #fs)* } { break; })
                    }
                };
                let body = self.list(body)?;
                Ok(counted_loop(range, exit, body, lane0, *line, sp))
            }
            AKind::RevLoop { body } => Ok(reversed_loop(self.list(body)?, lane0, sp)),
            _ => Err("internal: not a loop".into()),
        }
    }

    /// A block-level statement, with lane 0's copies of the per-lane values it names.
    fn block_stmt(&self, s: &AStmt) -> Result<TokenStream, String> {
        let sp = s.span;
        if let AKind::If { cond, then, els } = &s.kind {
            let read = match cond {
                Cond::Var(c) if self.per_lane[*c] => {
                    let pl = self.pl(*c);
                    quote!(#pl[0])
                }
                Cond::Var(c) => {
                    let x = self.var(*c);
                    quote!(#x)
                }
                // Every lane pushed the (uniform) decision: each pops its own.
                Cond::Popped => quote! {{
                    let mut __d = false;
                    for __lane in (0..__bd).rev() {
                        __d = __lanes[__lane].pop::<bool>();
                    }
                    __d
                }},
                Cond::Fast => return Err("internal: `__FAST` in a tiled adjoint".into()),
            };
            let (t, e) = (self.list(then)?, self.list(els)?);
            return Ok(quote_spanned!(sp=> if #read { #t } else { #e }));
        }
        if matches!(s.kind, AKind::Loop { .. } | AKind::RevLoop { .. }) {
            return self.block_loop(s);
        }
        let skip = lane_operands(s);
        let vars = self.lane_vars(&[s], &skip);
        let (mut load, store) = self.lane_copies(&vars, quote!(0));
        if !tile_stack_op(self.f(), s) {
            load.extend(self.lane_stack(quote!(0)));
        }
        let body = match &s.kind {
            AKind::Assign {
                dst,
                value: Value::Op(Op::Builtin { builtin, args }),
            } if builtin.lanes => self.lanes_replay(builtin.name, *dst, args[0], sp),
            // A tile's history, spread over the lanes' stacks.
            AKind::Push { var, line } => {
                let x = self.var(*var);
                quote_spanned!(sp=> __wp::tile::adjoint::push_tile(&#x, __lanes, #line)?;)
            }
            AKind::Pop { var } => {
                let x = self.var(*var);
                quote_spanned!(sp=> __wp::tile::adjoint::pop_tile(&mut #x, __lanes);)
            }
            AKind::Scope(b) => self.block(b)?,
            _ => self.stmt(s)?,
        };
        Ok(quote!({ #load #body #store }))
    }

    /// The replay of `t = tile(x)` or `x = untile(t)`, which read or write every lane.
    fn lanes_replay(&self, name: &str, dst: VarId, arg: VarId, sp: Span) -> TokenStream {
        let kernel = self.name();
        let d = self.var(dst);
        if name == "tile" {
            let lanes = match self.per_lane[arg] {
                true => {
                    let x = self.pl(arg);
                    quote!(&#x)
                }
                // One value for the block (a parameter): every lane holds it.
                false => {
                    let x = self.var(arg);
                    quote!(&__wp::block::PerLane::splat(#x, __bd))
                }
            };
            quote_spanned!(sp=> #d = __wp::block::from_lanes(#lanes, __bd, #kernel)?;)
        } else {
            let (t, pl) = (self.var(arg), self.pl(dst));
            quote_spanned! {sp=>
                for __l in 0..__bd {
                    #pl[__l] = __wp::block::untile(&#t, __l, #kernel)?;
                }
            }
        }
    }

    /// A tile operation's library adjoint (`warp_core::tile::adjoint`): tiles and arrays by
    /// reference, an adjoint named twice through a copy of its own (`&mut` twice cannot be),
    /// then the seed and the block size (a lane's `t[i]`: the seed and the kernel's name).
    pub(super) fn tile_adj_call(
        &self,
        func: &str,
        values: &[Arg],
        grads: &[GradArg],
        faults: bool,
        sp: Span,
    ) -> TokenStream {
        let f = format_ident!("{}", func);
        let xs = values.iter().map(|a| match a {
            Arg::Array(v) => {
                let x = self.var(*v);
                quote!(&#x)
            }
            Arg::Value(v) if self.f().ty(*v).is_tile() => {
                let x = self.var(*v);
                quote!(&#x)
            }
            Arg::Value(v) => {
                let x = self.var(*v);
                quote!(#x)
            }
        });
        let (gs, before, after) = self.grads_once(grads);
        let tail = match is_block_call(func) {
            true => quote!(&__r, __bd),
            false => {
                let kernel = self.name();
                quote!(__r, #kernel)
            }
        };
        let q = if faults { quote!(?) } else { quote!() };
        quote_spanned! {sp=>
            #before
            __wp::tile::adjoint::#f(#(#xs,)* #(#gs,)* #tail)#q;
            #after
        }
    }

    /// The adjoint arguments, each adjoint named at most once: a repeat goes to a zeroed copy
    /// (`__dup<k>`, declared in `before`) that `after` adds in.
    fn grads_once(&self, grads: &[GradArg]) -> (Vec<TokenStream>, TokenStream, TokenStream) {
        let (mut gs, mut before, mut after) = (Vec::new(), TokenStream::new(), TokenStream::new());
        for (k, g) in grads.iter().enumerate() {
            match g {
                GradArg::Adj(v) if grads[..k].contains(g) => {
                    let (d, a) = (format_ident!("__dup{}", k), self.adj(*v));
                    before.extend(quote!(let mut #d = __wp::zero_like(&#a);));
                    after.extend(quote!(__wp::adjoint::Adjoint::adj_accum(&mut #a, #d);));
                    gs.push(quote!(&mut #d));
                }
                GradArg::ArrayGrad(a) => {
                    let a = self.adj(*a);
                    gs.push(quote!(&mut #a.clone()));
                }
                GradArg::Temp(k) => {
                    let t = temp(*k);
                    gs.push(quote!(&mut #t));
                }
                g => gs.push(self.grad_arg(g)),
            }
        }
        (gs, before, after)
    }

    /// `tile_map`'s adjoint: the scalar adjoint of its function on each element.
    pub(super) fn tile_map_adj(
        &self,
        f: TileFn,
        values: &[VarId],
        grads: &[GradArg],
        dst: VarId,
        sp: Span,
    ) -> TokenStream {
        if values.iter().any(|v| !self.f().ty(*v).is_tile()) {
            return self.tile_map_consts_adj(f, values, grads, dst, sp);
        }
        let scalar = match f {
            TileFn::Builtin(b) => format_ident!("adj_{}", b.name),
            TileFn::Op(o) => format_ident!("{}", o.adjoint_fn().unwrap_or("adj_add")),
            TileFn::Func(k) => return self.tile_map_func_adj(k, values, grads, dst, sp),
        };
        let xs = values.iter().map(|v| {
            let x = self.var(*v);
            quote!(&#x)
        });
        let (gs, before, after) = self.grads_once(grads);
        let call = match values.len() {
            1 => quote! {
                __wp::tile::adjoint::adj_tile_map1(#(#xs,)* #(#gs,)* &__r,
                    |__x, __ax: &mut _, __g| __wp::adjoint::#scalar(__x, __ax, __g));
            },
            _ => quote! {
                __wp::tile::adjoint::adj_tile_map2(#(#xs,)* #(#gs,)* &__r,
                    |__x, __y, __ax: &mut _, __ay: &mut _, __g| __wp::adjoint::#scalar(__x, __y, __ax, __ay, __g));
            },
        };
        quote_spanned!(sp=> #before #call #after)
    }

    /// `tile_map`'s adjoint with scalar constants (broadcast to every element): the scalar
    /// adjoint of its function (a builtin's rule or a func's own adjoint) on each element in
    /// row-major order, the tiles' adjoints element by element, each float constant's adjoint
    /// (a temporary, `GradArg::Temp`) the sum of the elements' contributions in the
    /// reductions' order, as for `t * s` (so the GPU's is the same). An integer constant's
    /// contributions are dropped.
    fn tile_map_consts_adj(
        &self,
        f: TileFn,
        values: &[VarId],
        grads: &[GradArg],
        dst: VarId,
        sp: Span,
    ) -> TokenStream {
        let fun = self.f();
        let is_tile: Vec<bool> = values.iter().map(|v| fun.ty(*v).is_tile()).collect();
        let float = |v: VarId| matches!(fun.ty(v), Ty::Scalar(s) if s.is_float());
        let n = values.len();
        let (gs, before, after) = self.grads_once(grads);
        let g: Vec<syn::Ident> = (0..n).map(|k| format_ident!("__ga{}", k)).collect();
        let c: Vec<syn::Ident> = (0..n).map(|k| format_ident!("__gc{}", k)).collect();
        let k: Vec<syn::Index> = (0..n).map(syn::Index::from).collect();
        let xs: Vec<TokenStream> = values
            .iter()
            .zip(&is_tile)
            .map(|(v, t)| {
                let x = self.var(*v);
                match t {
                    true => quote!(__wp::tile::Tile::as_flat(&#x)[__e]),
                    false => quote!(#x),
                }
            })
            .collect();
        let mut init = Vec::new();
        let (mut collect, mut put, mut total, mut store) = (
            TokenStream::new(),
            TokenStream::new(),
            TokenStream::new(),
            TokenStream::new(),
        );
        for j in 0..n {
            let (gj, cj, kj) = (&g[j], &c[j], &k[j]);
            if is_tile[j] {
                init.push(quote!(__wp::tile::Tile::as_flat(&*#gj)[__e]));
                put.extend(quote!(__wp::tile::Tile::as_flat_mut(&mut *#gj)[__e] = __a.#kj;));
            } else {
                init.push(quote!(__wp::zero_like(&*#gj)));
                if float(values[j]) {
                    collect.extend(quote!(let mut #cj = ::std::vec::Vec::with_capacity(__n);));
                    put.extend(quote!(#cj.push(__a.#kj);));
                    total.extend(quote!(
                        __wp::adjoint::Adjoint::adj_accum(&mut *#gj, __wp::tile::adjoint::block_sum(&#cj, __bd));
                    ));
                }
            }
        }
        let seed = quote!(__wp::tile::Tile::as_flat(&__r)[__e]);
        let call = match f {
            TileFn::Func(q) => {
                let func = match (fun.callees.get(q), fun.ty(dst)) {
                    (Some(path), Ty::Tile(e, _)) => {
                        super::rust_tile::tile_map_fn(fun, path, values, e)
                    }
                    _ => None,
                };
                let Some(func) = func else {
                    return quote_spanned!(sp=> ::core::compile_error!("internal: tile_map's func or element types are missing"););
                };
                quote!(#func::adj((#(#xs,)*), &mut __a, #seed, &mut __lanes[0])?;)
            }
            TileFn::Builtin(b) => {
                let h = format_ident!("adj_{}", b.name);
                quote!(__wp::adjoint::#h(#(#xs,)* #(&mut __a.#k,)* #seed);)
            }
            TileFn::Op(o) => {
                let h = format_ident!("{}", o.adjoint_fn().unwrap_or("adj_add"));
                quote!(__wp::adjoint::#h(#(#xs,)* #(&mut __a.#k,)* #seed);)
            }
        };
        store.extend(total);
        quote_spanned!(sp=> #before {
            #(let #g = #gs;)*
            let __n = __wp::tile::Tile::as_flat(&__r).len();
            #collect
            for __e in 0..__n {
                let mut __a = (#(#init,)*);
                #call
                #put
            }
            #store
        } #after)
    }

    /// `tile_map(func, ..)`'s adjoint: the func's own adjoint on each element, in row-major
    /// order, on lane 0's adjoint stack (a block-level statement; each call pushes and pops
    /// its own history, so the stack is as before after each element).
    fn tile_map_func_adj(
        &self,
        k: usize,
        values: &[VarId],
        grads: &[GradArg],
        dst: VarId,
        sp: Span,
    ) -> TokenStream {
        let f = self.f();
        let func = match (f.callees.get(k), f.ty(dst)) {
            (Some(path), Ty::Tile(e, _)) => super::rust_tile::tile_map_fn(f, path, values, e),
            _ => None,
        };
        let Some(func) = func else {
            return quote_spanned!(sp=> ::core::compile_error!("internal: tile_map's func or element types are missing"););
        };
        let xs = values.iter().map(|v| {
            let x = self.var(*v);
            quote!(&#x)
        });
        let (gs, before, after) = self.grads_once(grads);
        // The func's adjoint accumulates into its adjoint arguments: copies in and out.
        let call = match values.len() {
            1 => quote! {
                __wp::tile::adjoint::adj_tile_map_func1(#(#xs,)* #(#gs,)* &__r,
                    |__x, __ax: &mut _, __g| {
                        let mut __a = (*__ax,);
                        #func::adj((__x,), &mut __a, __g, &mut __lanes[0])?;
                        *__ax = __a.0;
                        ::core::result::Result::Ok(())
                    })?;
            },
            2 => quote! {
                __wp::tile::adjoint::adj_tile_map_func2(#(#xs,)* #(#gs,)* &__r,
                    |__x, __y, __ax: &mut _, __ay: &mut _, __g| {
                        let mut __a = (*__ax, *__ay);
                        #func::adj((__x, __y), &mut __a, __g, &mut __lanes[0])?;
                        (*__ax, *__ay) = __a;
                        ::core::result::Result::Ok(())
                    })?;
            },
            // Three or more: the same, written out over the flat elements (the adjoints are
            // distinct tiles: `grads_once`).
            n => {
                let vs: Vec<syn::Ident> = values.iter().map(|v| self.var(*v)).collect();
                let g: Vec<syn::Ident> = (0..n).map(|k| format_ident!("__ga{}", k)).collect();
                let k: Vec<syn::Index> = (0..n).map(syn::Index::from).collect();
                quote! {
                    {
                        #(let #g = #gs;)*
                        for __e in 0..__wp::tile::Tile::as_flat(&__r).len() {
                            let mut __a = (#(__wp::tile::Tile::as_flat(&*#g)[__e],)*);
                            #func::adj(
                                (#(__wp::tile::Tile::as_flat(&#vs)[__e],)*),
                                &mut __a,
                                __wp::tile::Tile::as_flat(&__r)[__e],
                                &mut __lanes[0],
                            )?;
                            #(__wp::tile::Tile::as_flat_mut(&mut *#g)[__e] = __a.#k;)*
                        }
                    }
                }
            }
        };
        quote_spanned!(sp=> #before #call #after)
    }

    /// `adj_tile_lanes` / `adj_untile`: between a tile's adjoint and every lane's adjoint of a
    /// per-lane value.
    pub(super) fn lane_adj(&self, func: &str, lanes: VarId, tile: VarId, sp: Span) -> TokenStream {
        let (pa, t) = (self.pl_adj(lanes), self.adj(tile));
        match func {
            "adj_tile_lanes" => {
                quote_spanned!(sp=> __wp::tile::adjoint::adj_tile_lanes(&mut #pa, &#t, __bd);)
            }
            _ => quote_spanned!(sp=> __wp::tile::adjoint::adj_untile(&mut #t, &#pa, __bd);),
        }
    }
}
