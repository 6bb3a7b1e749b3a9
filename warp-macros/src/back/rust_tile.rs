//! Rust back end for tiles: the tile operations as calls of `warp_core::tile`, and the body of
//! a tiled kernel's CPU block, printed from `middle::lanes`'s plan.
//!
//! A block runs as one task. Each block-level statement is printed once; each lane region is
//! a loop over the block's lanes (`for __lane in 0..__nl`, where `__nl` is the block size, or
//! 1 for a lane-invariant kernel). A variable kept per lane lives in a `PerLane` array
//! (`__pl_x_5`): a region loads it into a local of the same name at the top of each lane's
//! turn and stores it back at the end, so the region's statements are printed by the ordinary
//! emitter unchanged; a block-level statement that reads it reads lane 0's value, which the
//! validator has proved is every lane's.

use super::rust::{ty_tokens, RustEmitter};
use crate::builtins::Builtin;
use crate::ir::*;
use crate::middle::lanes::{region_vars, LanePlan, Storage};
use crate::types::Ty;
use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote, quote_spanned};

impl RustEmitter<'_> {
    /// The CPU call of a tile row (the rows that need the lane plan, `tile`, `untile` and the
    /// accumulating matmul, are the block printer's).
    pub(super) fn tile_op(&self, b: &Builtin, args: &[VarId], ty: &Ty, sp: Span) -> TokenStream {
        let name = proc_macro2::Literal::string(&self.f.name);
        let v: Vec<syn::Ident> = args.iter().map(|a| self.var(*a)).collect();
        let t = ty_tokens(ty);
        let rank = |x: &VarId| match self.f.ty(*x) {
            Ty::Tile(_, d) => d.len(),
            _ => 0,
        };
        match b.name {
            "tile_zeros" => quote_spanned!(sp=> <#t>::zeros()),
            "tile_ones" => quote_spanned!(sp=> <#t>::ones()),
            "tile_arange" => {
                let (s, d) = (&v[0], &v[1]);
                quote_spanned!(sp=> <#t>::arange(#s, #d))
            }
            "tile_load" => {
                let a = &v[0];
                let offs = &v[1..];
                let f = format_ident!("load{}", offs.len());
                quote_spanned!(sp=> __wp::tile::#f(&#a, #(#offs),*)?)
            }
            "tile_store" | "tile_atomic_add" => {
                let (a, tile) = (&v[0], &v[1]);
                let offs = &v[2..];
                let f = if b.name == "tile_store" {
                    format_ident!("store{}", offs.len())
                } else {
                    format_ident!("atomic_add{}", offs.len())
                };
                quote_spanned!(sp=> __wp::tile::#f(&#a, #(#offs,)* &#tile)?)
            }
            "tile_sum" | "tile_min" | "tile_max" | "tile_argmin" | "tile_argmax" => {
                let f = format_ident!("{}", &b.name[5..]);
                let x = &v[0];
                quote_spanned!(sp=> __wp::tile::#f(&#x, __bd))
            }
            "tile_matmul" => {
                let (x, y) = (&v[0], &v[1]);
                quote_spanned!(sp=> __wp::tile::matmul(&#x, &#y))
            }
            "tile_scan_inclusive"
            | "tile_scan_exclusive"
            | "tile_scan_max_inclusive"
            | "tile_scan_min_inclusive" => {
                let f = format_ident!("{}", &b.name[5..]);
                let x = &v[0];
                quote_spanned!(sp=> __wp::tile::#f(&#x, __bd))
            }
            // `p = tile_sort(keys)`, then `x = tile_sort(x, p)` (the row's comment).
            "tile_sort" => match &v[..] {
                [k] => quote_spanned!(sp=> __wp::tile::sort_perm(&#k)),
                [x, p] => quote_spanned!(sp=> __wp::tile::permute(&#x, &#p)),
                _ => unreachable!("tile_sort's statements have one or two operands"),
            },
            "tile_full" => {
                let x = &v[0];
                quote_spanned!(sp=> <#t>::splat(#x))
            }
            "tile_astype" => {
                let x = &v[0];
                let u = match ty {
                    Ty::Tile(e, _) => ty_tokens(e),
                    _ => None,
                };
                quote_spanned!(sp=> #x.map(|__x| __wp::ops::AsScalar::<#u>::as_scalar(__x)))
            }
            "tile_reshape" | "tile_squeeze" => {
                let x = &v[0];
                let to = match ty {
                    Ty::Tile(_, d) => d.len(),
                    _ => 0,
                };
                if rank(&args[0]) > 2 || to > 2 {
                    // Ranks 3 and 4: the rank-generic reshape, told its result type.
                    quote_spanned!(sp=> __wp::tile::reshape::<_, #t>(&#x))
                } else {
                    let f = format_ident!("reshape{}{}", rank(&args[0]), to);
                    quote_spanned!(sp=> __wp::tile::#f(&#x))
                }
            }
            "tile_diag_add" => {
                let (a, d) = (&v[0], &v[1]);
                quote_spanned!(sp=> __wp::tile::diag_add(&#a, &#d))
            }
            "tile_cholesky" => {
                let x = &v[0];
                quote_spanned!(sp=> __wp::tile::cholesky(&#x))
            }
            "tile_cholesky_solve" | "tile_lower_solve" | "tile_upper_solve" => {
                // By the right-hand side's rank: `lower_solve1`, `lower_solve2`, ..
                let f = format_ident!("{}{}", &b.name[5..], rank(&args[1]));
                let (m, y) = (&v[0], &v[1]);
                quote_spanned!(sp=> __wp::tile::#f(&#m, &#y))
            }
            "tile_fft" | "tile_ifft" => {
                // `t = fft(&t)`: the statement assigns the tile its transform.
                let f = format_ident!("{}", &b.name[5..]);
                let x = &v[0];
                quote_spanned!(sp=> __wp::tile::#f(&#x))
            }
            "tile_view" => {
                let (x, offs) = (&v[0], &v[1..]);
                let to = match ty {
                    Ty::Tile(_, d) => d.len(),
                    _ => 0,
                };
                let f = format_ident!("view{}{}", rank(&args[0]), to);
                quote_spanned!(sp=> __wp::tile::#f(&#x, #(#offs,)* #name)?)
            }
            // `d = window(&d, &s, o..)`: the statement assigns the destination its new value.
            "tile_assign"
            | "tile_add_inplace"
            | "tile_sub_inplace"
            | "tile_bit_and_inplace"
            | "tile_bit_or_inplace"
            | "tile_bit_xor_inplace" => {
                let (d, s, offs) = (&v[0], &v[1], &v[2..]);
                let f = format_ident!("window{}", offs.len());
                let op = format_ident!(
                    "{}",
                    b.name
                        .trim_start_matches("tile_")
                        .trim_end_matches("_inplace")
                );
                quote_spanned!(sp=> __wp::tile::#f(&#d, &#s, #(#offs,)* #name, __wp::tile::view::op::#op)?)
            }
            "tile_transpose" => {
                let x = &v[0];
                quote_spanned!(sp=> __wp::tile::transpose(&#x))
            }
            "tile_broadcast" => {
                let x = &v[0];
                let to = match ty {
                    Ty::Tile(_, d) => d.len(),
                    _ => 0,
                };
                let f = format_ident!("broadcast{}{}", rank(&args[0]), to);
                quote_spanned!(sp=> __wp::tile::#f(&#x))
            }
            "tile_extract" => {
                let x = &v[0];
                let idx = &v[1..];
                quote_spanned!(sp=> #x.extract(#(#idx,)* #name)?)
            }
            // As a value (the adjoint's replay assigns it to `c` itself): the updated `c`.
            "tile_matmul_acc" => {
                let (a, b, c) = (&v[0], &v[1], &v[2]);
                quote_spanned!(sp=> { __wp::tile::matmul_acc(&#a, &#b, &mut #c); #c })
            }
            other => {
                let msg = format!("internal: `{other}` outside a tiled kernel's block");
                quote_spanned!(sp=> ::core::compile_error!(#msg))
            }
        }
    }

    /// The closure of a `tile_map` or `tile_reduce` function.
    fn tile_fn(&self, f: TileFn, arity: usize) -> TokenStream {
        match f {
            TileFn::Op(op) => {
                let m = format_ident!(
                    "{}",
                    match op {
                        BinOp::Add => "s_add",
                        BinOp::Sub => "s_sub",
                        BinOp::Mul => "s_mul",
                        _ => "s_div",
                    }
                );
                if op == BinOp::Div {
                    quote!(|__x, __y| __x / __y)
                } else {
                    quote!(|__x, __y| __wp::builtins::Scalar::#m(__x, __y))
                }
            }
            TileFn::Builtin(b) => {
                let g = format_ident!("{}", b.rust);
                if arity == 1 {
                    quote!(|__x| __wp::builtins::#g(__x))
                } else {
                    quote!(|__x, __y| __wp::builtins::#g(__x, __y))
                }
            }
            TileFn::Func(_) => {
                unreachable!("user funcs are applied by `tile_map_func` and `tile_reduce`")
            }
        }
    }

    /// `tile_map(func, a..)` of a user `#[func]`: `a.try_map(..)?`, which stops at the first
    /// element whose call faults, as a scalar call does. The func is called through
    /// `TileMapFn<(elements..), result>`, whose bound rustc checks at the func's path (the
    /// macro cannot see the func's signature): a func that does not fit the elements is that
    /// one error, with the trait's message.
    fn tile_map_func(&self, k: usize, args: &[VarId], dst_elem: &Ty, sp: Span) -> TokenStream {
        let Some(path) = self.f.callees.get(k) else {
            return quote_spanned!(sp=> ::core::compile_error!("internal: tile_map's func is not among the callees"));
        };
        let Some(func) = tile_map_fn(self.f, path, args, dst_elem) else {
            return quote_spanned!(sp=> ::core::compile_error!("internal: tile_map of a func over tiles without Rust element types"));
        };
        let entry = if self.replay {
            format_ident!("replay")
        } else {
            format_ident!("call")
        };
        let v: Vec<syn::Ident> = args.iter().map(|a| self.var(*a)).collect();
        let all_tiles = args.iter().all(|a| self.f.ty(*a).is_tile());
        match &v[..] {
            [a] => quote_spanned!(sp=> #a.try_map(|__x| #func::#entry((__x,)))?),
            [a, b] if all_tiles => {
                quote_spanned!(sp=> #a.try_map2(&#b, |__x, __y| #func::#entry((__x, __y)))?)
            }
            // Three or more, or scalar constants (the tiles' shapes are equal: the front end
            // checked them): the other tiles read at the element's index, the scalars as
            // they are.
            [a, ..] => {
                let rest = args[1..].iter().zip(&v[1..]).map(|(x, n)| {
                    if self.f.ty(*x).is_tile() {
                        quote!(__wp::tile::Tile::as_flat(&#n)[__e])
                    } else {
                        quote!(#n)
                    }
                });
                quote_spanned!(sp=> #a.try_map_flat(|__e, __x| #func::#entry((
                    __x, #(#rest,)*
                )))?)
            }
            [] => unreachable!("tile_map takes a tile"),
        }
    }

    /// `tile_map(f, a)`: `a.map(f)`, `a.map2(&b, f)`.
    pub(super) fn tile_map(&self, f: TileFn, args: &[VarId], ty: &Ty, sp: Span) -> TokenStream {
        if let TileFn::Func(k) = f {
            let Ty::Tile(e, _) = ty else {
                return quote_spanned!(sp=> ::core::compile_error!("internal: tile_map makes no tile"));
            };
            return self.tile_map_func(k, args, e, sp);
        }
        let v: Vec<syn::Ident> = args.iter().map(|a| self.var(*a)).collect();
        let call = self.tile_fn(f, v.len());
        match &v[..] {
            [a] => quote_spanned!(sp=> #a.map(#call)),
            // A scalar constant: the same second operand for every element.
            [a, b] if !self.f.ty(args[1]).is_tile() => quote_spanned!(sp=> {
                let (__f, __s) = (#call, #b);
                #a.map(|__x| __f(__x, __s))
            }),
            [a, b] => quote_spanned!(sp=> #a.map2(&#b, #call)),
            _ => unreachable!("tile_map takes one or two operands with a builtin"),
        }
    }

    /// `tile_reduce(f, t)`: warp-core's reduction in the GPU's order. A user func goes through
    /// `TileMapFn<(T, T), T>` (rustc checks it at the func's path) and `try_reduce`, which
    /// stops at the first call that faults.
    pub(super) fn tile_reduce(&self, f: TileFn, arg: VarId, sp: Span) -> TokenStream {
        let x = self.var(arg);
        if let TileFn::Func(k) = f {
            let Some(path) = self.f.callees.get(k) else {
                return quote_spanned!(sp=> ::core::compile_error!("internal: tile_reduce's func is not among the callees"));
            };
            let func = match self.f.ty(arg) {
                Ty::Tile(e, _) => tile_map_fn(self.f, path, &[arg, arg], e),
                _ => None,
            };
            let Some(func) = func else {
                return quote_spanned!(sp=> ::core::compile_error!("internal: tile_reduce of a func over a tile without a Rust element type"));
            };
            let entry = if self.replay {
                format_ident!("replay")
            } else {
                format_ident!("call")
            };
            return quote_spanned!(sp=> __wp::tile::try_reduce(&#x, __bd, |__x, __y| #func::#entry((__x, __y)))?);
        }
        let call = self.tile_fn(f, 2);
        quote_spanned!(sp=> __wp::tile::reduce(&#x, __bd, #call))
    }
}

/// Prints a tiled kernel's block body.
pub struct BlockPrinter<'a> {
    pub em: RustEmitter<'a>,
    pub plan: LanePlan,
}

impl<'a> BlockPrinter<'a> {
    pub fn new(f: &'a Function) -> Result<Self, String> {
        Ok(BlockPrinter {
            em: RustEmitter::new(f),
            plan: LanePlan::of(f)?,
        })
    }

    fn per_lane(&self, v: VarId) -> syn::Ident {
        format_ident!("__pl_{}", self.em.var(v))
    }

    fn is_per_lane(&self, v: VarId) -> bool {
        self.plan.storage[v] == Storage::PerLane
    }

    /// The block's setup (the lane count, the per-lane arrays) and body.
    pub fn body(&self) -> TokenStream {
        let f = self.em.f;
        let invariant = self.plan.lane_invariant;
        let per_lane = (0..f.vars.len()).filter(|v| self.is_per_lane(*v)).map(|v| {
            let pl = self.per_lane(v);
            match ty_tokens(&f.vars[v].ty) {
                Some(t) => quote!(let mut #pl = __wp::block::PerLane::<#t>::new(__bd);),
                None => quote!(let mut #pl = __wp::block::PerLane::new(__bd);),
            }
        });
        let alive = self
            .plan
            .lane_returns
            .then(|| quote!(let mut __alive = [true; __wp::block::MAX_BLOCK_DIM];));
        let body = self.list(&f.body);
        quote! {
            let __bd = __grid.block_dim;
            // A lane-invariant kernel's lanes all compute the same: one does it for all.
            let __nl = if #invariant { 1 } else { __bd };
            #alive
            #(#per_lane)*
            #body
        }
    }

    fn list(&self, b: &Block) -> TokenStream {
        let mut out = TokenStream::new();
        let mut run: Vec<&Stmt> = Vec::new();
        for s in b {
            if self.plan.is_block_level(s) {
                out.extend(self.region(&run));
                run.clear();
                out.extend(self.block_stmt(s));
            } else {
                run.push(s);
            }
        }
        out.extend(self.region(&run));
        out
    }

    /// A lane region: the loop over the lanes.
    fn region(&self, run: &[&Stmt]) -> TokenStream {
        if run.is_empty() {
            return TokenStream::new();
        }
        let (vars, set) = region_vars(run);
        let kept: Vec<VarId> = vars.into_iter().filter(|v| self.is_per_lane(*v)).collect();
        let loads = kept.iter().map(|v| {
            let (x, pl) = (self.em.var(*v), self.per_lane(*v));
            quote!(let mut #x = #pl[__lane];)
        });
        let stores = kept.iter().filter(|v| set.contains(v)).map(|v| {
            let (x, pl) = (self.em.var(*v), self.per_lane(*v));
            quote!(#pl[__lane] = #x;)
        });
        self.em.in_lanes.set(true);
        let body: TokenStream = run
            .iter()
            .map(|s| match &s.kind {
                // A per-lane variable is declared by its array; the load above is its value.
                StmtKind::Declare { var } if self.is_per_lane(*var) => TokenStream::new(),
                _ => self.em.stmt_tokens(s),
            })
            .collect();
        self.em.in_lanes.set(false);
        let skip_dead = self.plan.lane_returns.then(|| {
            quote!(if !__alive[__lane] {
                continue '__lanes;
            })
        });
        quote! {
            '__lanes: for __lane in 0..__nl {
                #skip_dead
                #(#loads)*
                #body
                #(#stores)*
            }
        }
    }

    /// Loads, before a block-level statement, the per-lane values it reads (lane 0's).
    fn lane0_reads(&self, s: &Stmt) -> TokenStream {
        let mut out = TokenStream::new();
        let mut seen = Vec::new();
        s.kind.for_each_read(&mut |v| {
            if self.is_per_lane(v) && !seen.contains(&v) {
                seen.push(v);
                let (x, pl) = (self.em.var(v), self.per_lane(v));
                out.extend(quote!(let #x = #pl[0];));
            }
        });
        out
    }

    fn block_stmt(&self, s: &Stmt) -> TokenStream {
        let sp = s.span;
        let reads = self.lane0_reads(s);
        let name = proc_macro2::Literal::string(&self.em.f.name);
        let body = match &s.kind {
            StmtKind::If { cond, then, els } => {
                let c = self.em.var(*cond);
                let (t, e) = (self.list(then), self.list(els));
                quote_spanned!(sp=> if #c { #t } else { #e })
            }
            StmtKind::For { .. } => {
                // The loop as the ordinary emitter prints it, with this printer's body.
                self.em.for_loop(s, &|b| self.list(b))
            }
            StmtKind::Loop { body } => {
                let b = self.list(body);
                quote_spanned!(sp=> loop { #b })
            }
            StmtKind::Break => quote_spanned!(sp=> break;),
            StmtKind::Continue => quote_spanned!(sp=> continue;),
            StmtKind::Return { .. } => quote_spanned!(sp=> return ::core::result::Result::Ok(());),
            StmtKind::Assign {
                dst,
                op: Op::Builtin { builtin, args },
                define,
            } if builtin.lanes || builtin.name == "tile_matmul_acc" => {
                let d = self.em.var(*dst);
                match builtin.name {
                    "tile" => {
                        let x = args[0];
                        let t = ty_tokens(self.em.f.ty(*dst));
                        let lanes = if self.is_per_lane(x) {
                            let pl = self.per_lane(x);
                            quote!(&#pl)
                        } else {
                            // One value for the block: every lane holds it.
                            let x = self.em.var(x);
                            quote!(&__wp::block::PerLane::splat(#x, __bd))
                        };
                        let call = quote!(__wp::block::from_lanes(#lanes, __bd, #name)?);
                        if *define {
                            quote_spanned!(sp=> let #d: #t = #call;)
                        } else {
                            quote_spanned!(sp=> #d = #call;)
                        }
                    }
                    "untile" => {
                        let t = self.em.var(args[0]);
                        let pl = self.per_lane(*dst);
                        quote_spanned! {sp=>
                            for __l in 0..__bd {
                                #pl[__l] = __wp::block::untile(&#t, __l, #name)?;
                            }
                        }
                    }
                    _ => {
                        let (a, b) = (self.em.var(args[0]), self.em.var(args[1]));
                        quote_spanned!(sp=> __wp::tile::matmul_acc(&#a, &#b, &mut #d);)
                    }
                }
            }
            _ => self.em.stmt_tokens(s),
        };
        quote!(#reads #body)
    }
}

/// `<func as __wp::tile::TileMapFn<(elements of args.. or the scalars), result>>`, spanned at the func's path
/// (where rustc reports a func that does not fit); `None` where an element has no Rust type.
pub(super) fn tile_map_fn(
    f: &Function,
    path: &syn::Path,
    args: &[VarId],
    dst_elem: &Ty,
) -> Option<TokenStream> {
    // A tile gives its element; a scalar constant (broadcast) is its own type.
    let elem = |t: &Ty| match t {
        Ty::Tile(e, _) => ty_tokens(e),
        t => ty_tokens(t),
    };
    let ins: Vec<TokenStream> = args.iter().map(|a| elem(f.ty(*a))).collect::<Option<_>>()?;
    let out = ty_tokens(dst_elem)?;
    let ps = syn::spanned::Spanned::span(path);
    Some(quote_spanned!(ps=> <#path as __wp::tile::TileMapFn<(#(#ins,)*), #out>>))
}
