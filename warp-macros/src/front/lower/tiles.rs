//! Tiles in the front end: the calls of the tile rows typed by their shapes, `lane()`, and
//! `t[i]`. A tile's type is its element and its shape (`Tile<f32, 16, 8>`), so these calls are
//! not matched by `Builtin::resolve` (whose type variable is one type) but here: each call's
//! shape comes from its turbofish (`tile_zeros::<f32, 16, 8>()`), Warp's positional shape
//! (`tile_load(a, (16, 8), (i, j))`), the `let` annotation (the `want` type), or its operands.
//!
//! Shape rules the macro can decide (two literals, or the same const) are errors here, at the
//! call. The others (a const against a literal) are left to rustc: the generated code types
//! every tile with its dims as const generics, so a mismatch is a type error at the statement.

use super::*;
use crate::front::signature::{dim_of, dim_of_path, tile_rank};
use crate::types::Dim;

#[path = "tiles_convert.rs"]
mod convert;
#[path = "tiles_linalg.rs"]
mod linalg;
#[path = "tiles_view.rs"]
mod view;

/// A tile's element and dims, from its type.
fn tile_parts(t: &Ty) -> Option<(&Ty, &[Dim])> {
    match t {
        Ty::Tile(e, d) => Some((e, d)),
        _ => None,
    }
}

fn dims_text(d: &[Dim]) -> String {
    d.iter()
        .map(|d| d.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Whether two shapes are known to differ (rank, or a pair of dims the macro can compare).
fn shapes_differ(a: &[Dim], b: &[Dim]) -> bool {
    a.len() != b.len() || a.iter().zip(b).any(|(x, y)| x.same(y) == Some(false))
}

impl Lowerer {
    /// Checks that shapes `a` and `b` agree: an error at `span` where the macro can tell they
    /// differ (`msg`), and an obligation for rustc for each pair of dims only rustc can compare.
    pub(super) fn same_shapes(&mut self, a: &[Dim], b: &[Dim], span: Span, msg: String) -> R<()> {
        if shapes_differ(a, b) {
            return err(span, msg);
        }
        for (x, y) in a.iter().zip(b) {
            if x.same(y).is_none() {
                self.obligations.push(ShapeObligation {
                    span,
                    lhs: x.clone(),
                    rhs: y.clone(),
                    msg: msg.clone(),
                    or_one: false,
                    pow2: false,
                });
            }
        }
        Ok(())
    }

    /// Marks the function a tiled kernel (its first tile operation or `lane()`).
    fn mark_tiled(&mut self) {
        self.tiled.get_or_insert_with(Tiled::default);
    }

    /// Registers the consts that tile dims name, so that the CUDA template can write their
    /// values (`@@K<k>@@`), as for consts read as values.
    pub(super) fn note_tile_consts(&mut self) {
        let mut paths = Vec::new();
        for v in &self.vars {
            if let Ty::Tile(_, dims) = &v.ty {
                for d in dims {
                    if let Dim::Const(p) = d {
                        paths.push(syn::parse_str::<syn::Path>(p).expect("a const path"));
                    }
                }
            }
        }
        if let Some(Tiled {
            width: Some(Dim::Const(p)),
        }) = &self.tiled
        {
            paths.push(syn::parse_str::<syn::Path>(p).expect("a const path"));
        }
        for p in paths {
            if !self.consts.contains(&p) {
                self.consts.push(p);
            }
        }
    }

    /// A call of `lane()` or of a tile row; `None` when `name` is neither.
    pub(super) fn tile_call(
        &mut self,
        name: &str,
        c: &syn::ExprCall,
        turbofish: Option<&syn::AngleBracketedGenericArguments>,
        want: Option<&Ty>,
        span: Span,
    ) -> R<Option<VarId>> {
        let args: Vec<&Expr> = c.args.iter().collect();
        if name == "lane" {
            if !args.is_empty() {
                return err(span, "lane() takes no arguments");
            }
            if self.kind == FnKind::Func {
                return err(span, "`lane()` is only defined in kernels");
            }
            self.mark_tiled();
            return Ok(Some(self.def(Op::Lane, USIZE, span)));
        }
        let row = match builtins::lookup_overload(name, args.len()) {
            Some(b) if b.is_tile() => b,
            _ => match builtins::lookup_user(name) {
                Some(b) if b.is_tile() => b,
                _ => return Ok(None),
            },
        };
        if self.kind == FnKind::Func {
            return err(
                span,
                format!("`{name}` is a tile operation: funcs cannot use tiles yet"),
            );
        }
        self.mark_tiled();
        // The turbofish: an element type first where the row makes one, then dims.
        let (fish_elem, fish_dims) = self.turbofish(name, turbofish)?;
        let want_tile = want.and_then(tile_parts);
        let v = match row.name {
            "tile_zeros" | "tile_ones" => {
                if !args.is_empty() {
                    return err(
                        span,
                        format!("`{name}` takes its shape and element as a turbofish, `{name}::<f32, 16, 8>()`, or from the annotation, `let t: Tile<f32, 16, 8> = {name}();`"),
                    );
                }
                let ty = self.made_tile(name, fish_elem, fish_dims, want_tile, span)?;
                self.def(
                    Op::Builtin {
                        builtin: row,
                        args: vec![],
                    },
                    ty,
                    span,
                )
            }
            "tile_arange" => self.tile_arange(row, &args, fish_elem, fish_dims, want_tile, span)?,
            "tile_load" => self.tile_load(row, &args, fish_dims, want_tile, span)?,
            "tile_store" => self.tile_store(row, &args, span)?,
            "tile" => {
                let [x] = args[..] else {
                    return err(span, "`tile(x)` takes one value");
                };
                let x = self.expr(x, want_tile.map(|(e, _)| e))?;
                let e = self.ty(x);
                if !matches!(e, Ty::Scalar(s) if s != Scalar::Bool) {
                    return err(
                        span,
                        format!("`tile(x)` makes a tile of integer or float scalars, not of `{e}`"),
                    );
                }
                let attr = self.tiled.as_ref().and_then(|t| t.width.clone());
                let width = fish_dims
                    .map(|d| d.to_vec())
                    .or_else(|| want_tile.map(|(_, d)| d.to_vec()))
                    .or_else(|| attr.clone().map(|w| vec![w]));
                let Some(width) = width else {
                    return err(
                        span,
                        "`tile(x)` makes a tile as wide as the block: give the width with `#[kernel(block_dim = 64)]`, `tile::<64>(x)` or a `Tile<f32, 64>` annotation",
                    );
                };
                if width.len() != 1 {
                    return err(span, "`tile(x)` makes a one-dimensional tile");
                }
                if let Some(a) = &attr {
                    let msg = format!("`tile(x)` makes a tile as wide as the block, {a} (`#[kernel(block_dim = {a})]`), not {}", width[0]);
                    self.same_shapes(std::slice::from_ref(a), &width[..1], span, msg)?;
                }
                let ty = Ty::Tile(Box::new(e), width);
                self.def(
                    Op::Builtin {
                        builtin: row,
                        args: vec![x],
                    },
                    ty,
                    span,
                )
            }
            "untile" => {
                let [t] = args[..] else {
                    return err(span, "`untile(t)` takes one tile");
                };
                let t = self.scalar_tile_arg(name, t)?;
                let ty = self.ty(t);
                let (e, d) = tile_parts(&ty).expect("a tile");
                if d.len() != 1 {
                    return err(
                        span,
                        format!("`untile` takes a one-dimensional tile, found `{ty}`"),
                    );
                }
                let e = e.clone();
                self.def(
                    Op::Builtin {
                        builtin: row,
                        args: vec![t],
                    },
                    e,
                    span,
                )
            }
            "tile_sum" | "tile_min" | "tile_max" | "tile_argmin" | "tile_argmax" => {
                let [t] = args[..] else {
                    return err(span, format!("`{name}` takes one tile"));
                };
                let t = self.scalar_tile_arg(name, t)?;
                let ty = self.ty(t);
                let (e, _) = tile_parts(&ty).expect("a tile");
                let e = if name.starts_with("tile_arg") {
                    crate::types::I32
                } else {
                    e.clone()
                };
                self.def(
                    Op::Builtin {
                        builtin: row,
                        args: vec![t],
                    },
                    Ty::Tile(Box::new(e), vec![Dim::Lit(1)]),
                    span,
                )
            }
            "tile_scan_inclusive"
            | "tile_scan_exclusive"
            | "tile_scan_max_inclusive"
            | "tile_scan_min_inclusive" => {
                let [t] = args[..] else {
                    return err(span, format!("`{name}` takes one tile"));
                };
                let t = self.scalar_tile_arg(name, t)?;
                let ty = self.ty(t);
                if !matches!(&ty, Ty::Tile(_, d) if d.len() == 1) {
                    return err(
                        span,
                        format!("`{name}` scans a one-dimensional tile, found `{ty}`"),
                    );
                }
                self.def(
                    Op::Builtin {
                        builtin: row,
                        args: vec![t],
                    },
                    ty,
                    span,
                )
            }
            "tile_map" => self.tile_map(&args, fish_elem, fish_dims, want_tile, span)?,
            "tile_reduce" => self.tile_reduce(&args, span)?,
            "tile_transpose" => self.tile_transpose(row, &args, span)?,
            "tile_broadcast" => self.tile_broadcast(row, &args, fish_dims, want_tile, span)?,
            "tile_atomic_add" => self.tile_atomic_add(row, &args, span)?,
            "tile_matmul" => self.tile_matmul(row, &args, span)?,
            "tile_matmul_acc" => self.tile_matmul_acc(row, &args, span)?,
            "tile_sort" => self.tile_sort(row, &args, span)?,
            "tile_full" => self.tile_full(row, &args, fish_elem, fish_dims, want_tile, span)?,
            "tile_astype" => self.tile_astype(row, &args, fish_elem, fish_dims, want_tile, span)?,
            "tile_reshape" | "tile_squeeze" => {
                self.tile_reshape(row, &args, fish_dims, want_tile, span)?
            }
            "tile_diag_add" => self.tile_diag_add(row, &args, span)?,
            "tile_cholesky" | "tile_cholesky_solve" | "tile_lower_solve" | "tile_upper_solve" => {
                self.tile_linalg(row, &args, span)?
            }
            "tile_fft" | "tile_ifft" => self.tile_fft(row, &args, span)?,
            "tile_view" => self.tile_view(row, &args, fish_dims, want_tile, span)?,
            "tile_assign"
            | "tile_add_inplace"
            | "tile_sub_inplace"
            | "tile_bit_and_inplace"
            | "tile_bit_or_inplace"
            | "tile_bit_xor_inplace" => self.tile_window(row, &args, span)?,
            "tile_extract" => {
                return err(
                    span,
                    "read a tile's element by indexing it: `t[i]`, `t[(i, j)]`",
                )
            }
            other => unreachable!("tile row `{other}` has no typing rule"),
        };
        // A shape the annotation states must be the one made (decidable dims only).
        if let (Some((we, wd)), Ty::Tile(e, d)) = (want_tile, self.ty(v)) {
            let msg = format!(
                "`{name}` makes a `{}`, but a `{}` is expected here",
                self.ty(v),
                want.expect("a want")
            );
            if *we != *e {
                return err(span, msg);
            }
            self.same_shapes(wd, &d, span, msg)?;
        }
        Ok(Some(v))
    }

    /// The turbofish's element type (when its first argument is a scalar type) and its dims.
    fn turbofish(
        &self,
        name: &str,
        fish: Option<&syn::AngleBracketedGenericArguments>,
    ) -> R<(Option<Ty>, Option<Vec<Dim>>)> {
        let Some(fish) = fish else {
            return Ok((None, None));
        };
        let mut it = fish.args.iter().peekable();
        let mut elem = None;
        if let Some(syn::GenericArgument::Type(syn::Type::Path(tp))) = it.peek() {
            if let Some(id) = tp.path.get_ident() {
                if let Some(s) = Scalar::from_name(&id.to_string()) {
                    if s == Scalar::Bool {
                        return err(tp.span(), "tiles hold integer or float scalars, not `bool`");
                    }
                    elem = Some(Ty::Scalar(s));
                    it.next();
                } else if let Some(v) = Ty::from_glam_name(&id.to_string()) {
                    if !v.is_vec2_float() {
                        return err(
                            tp.span(),
                            format!(
                                "tiles hold integer or float scalars, or `Vec2`/`DVec2`, not `{v}`"
                            ),
                        );
                    }
                    elem = Some(v);
                    it.next();
                }
            }
        }
        let dims = it.map(dim_of).collect::<R<Vec<_>>>()?;
        if !dims.is_empty() {
            tile_rank(&dims, fish.span())?;
        }
        if elem.is_none() && dims.is_empty() {
            return err(
                fish.span(),
                format!("`{name}::<..>` names the tile's element or shape"),
            );
        }
        Ok((elem, (!dims.is_empty()).then_some(dims)))
    }

    /// The type of a tile made from nothing (`tile_zeros`): element and shape from the
    /// turbofish, else from the annotation.
    fn made_tile(
        &self,
        name: &str,
        elem: Option<Ty>,
        dims: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<Ty> {
        let elem = elem.or_else(|| want.map(|(e, _)| e.clone()));
        let dims = dims.or_else(|| want.map(|(_, d)| d.to_vec()));
        match (elem, dims) {
            (Some(e), Some(d)) => Ok(Ty::Tile(Box::new(e), d)),
            _ => err(
                span,
                format!("`{name}` needs its element and shape: `{name}::<f32, 16, 8>()`, or `let t: Tile<f32, 16, 8> = {name}();`"),
            ),
        }
    }

    /// An argument that must be a tile of scalars: the operations that combine elements other
    /// than by `+`, `-` and scaling (reductions, scans, maps, products) refuse tiles of vectors.
    fn scalar_tile_arg(&mut self, name: &str, e: &Expr) -> R<VarId> {
        let v = self.tile_arg(name, e)?;
        let t = self.ty(v);
        if t.is_vector_tile() {
            return err(e.span(), vector_tile_msg(name, &t));
        }
        Ok(v)
    }

    /// An argument that must be a tile.
    fn tile_arg(&mut self, name: &str, e: &Expr) -> R<VarId> {
        let v = self.expr(e, None)?;
        let t = self.ty(v);
        if !t.is_tile() {
            return err(e.span(), format!("`{name}` takes a tile here, found `{t}`"));
        }
        Ok(v)
    }

    /// A dim written as a call argument (Warp's positional shape): a literal or a const.
    fn dim_expr(e: &Expr) -> R<Dim> {
        let bad = || {
            syn::Error::new(
                e.span(),
                "a tile dimension must be an integer literal or a module const (`16`, `TM`)",
            )
        };
        match strip(e) {
            Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Int(i),
                ..
            }) => i.base10_parse::<u32>().map(Dim::Lit).map_err(|_| bad()),
            Expr::Path(p) if p.qself.is_none() => dim_of_path(&p.path).ok_or_else(bad),
            _ => Err(bad()),
        }
    }

    /// Offsets into an array of `ndim` dimensions: one integer, or a tuple of `ndim`; absent
    /// (Warp's default), zeros.
    fn offsets(&mut self, name: &str, e: Option<&Expr>, ndim: u8, span: Span) -> R<Vec<VarId>> {
        let Some(e) = e else {
            return Ok((0..ndim)
                .map(|_| self.def(Op::Lit(Lit::Int(0)), crate::types::I32, span))
                .collect());
        };
        let parts: Vec<&Expr> = match strip(e) {
            Expr::Tuple(t) => t.elems.iter().collect(),
            other => vec![other],
        };
        if parts.len() != ndim as usize {
            return err(
                e.span(),
                format!(
                    "`{name}` into an array of {ndim} dimension(s) takes {ndim} offset(s), found {}",
                    parts.len()
                ),
            );
        }
        let mut out = Vec::new();
        for p in parts {
            let v = self.expr(p, None)?;
            let t = self.ty(v);
            if !(t.is_deferred() || t.is_int_scalar()) {
                return err(p.span(), format!("tile offsets are integers, found `{t}`"));
            }
            out.push(v);
        }
        Ok(out)
    }

    /// An array argument of a tile load or store: its element and dimensions (1 to 4).
    fn tile_array(&mut self, name: &str, e: &Expr) -> R<(VarId, Ty, u8)> {
        let a = self.expr(e, None)?;
        match self.ty(a) {
            Ty::Array(elem, n) if elem.is_tile_elem() => Ok((a, *elem, n)),
            Ty::Array(elem, _) => err(
                e.span(),
                format!("`{name}`: tiles hold integer or float scalars, or `Vec2`/`DVec2`, and this array holds `{elem}`"),
            ),
            t => err(e.span(), format!("`{name}` takes an array first, found `{t}`")),
        }
    }

    fn tile_load(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        fish: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<VarId> {
        let known = fish.clone().or_else(|| want.map(|(_, d)| d.to_vec()));
        // `tile_load(a, shape, offsets)` (Warp's order); with the shape known from the turbofish
        // or the annotation, `tile_load(a, offsets)`; `tile_load(a, shape)` reads at zero.
        let (shape_arg, offs_arg) = match (args.len(), &known) {
            (3, _) => (Some(args[1]), Some(args[2])),
            (2, Some(_)) => (None, Some(args[1])),
            (2, None) => (Some(args[1]), None),
            (1, Some(_)) => (None, None),
            (n, _) => {
                return err(
                    span,
                    format!("`tile_load` takes an array, the tile's shape and the offsets, `tile_load(a, (16, 8), (i, j))`, or `tile_load::<16, 8>(a, (i, j))`; found {n} argument(s)"),
                )
            }
        };
        let (a, elem, ndim) = self.tile_array("tile_load", args[0])?;
        let dims = match shape_arg {
            Some(s) => {
                let parts: Vec<&Expr> = match strip(s) {
                    Expr::Tuple(t) => t.elems.iter().collect(),
                    other => vec![other],
                };
                let d = parts
                    .into_iter()
                    .map(Self::dim_expr)
                    .collect::<R<Vec<_>>>()?;
                tile_rank(&d, s.span())?;
                if let Some(k) = known.clone() {
                    let msg = format!(
                        "`tile_load`: the shape ({}) differs from the expected ({})",
                        dims_text(&d),
                        dims_text(&k)
                    );
                    self.same_shapes(&k, &d, s.span(), msg)?;
                }
                d
            }
            None => known.expect("a known shape"),
        };
        if dims.len() != ndim as usize {
            return err(
                span,
                format!(
                    "`tile_load`: a tile of {} dimension(s) from an array of {ndim}; their ranks must agree",
                    dims.len()
                ),
            );
        }
        let mut vars = vec![a];
        vars.extend(self.offsets("tile_load", offs_arg, ndim, span)?);
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vars,
            },
            Ty::Tile(Box::new(elem), dims),
            span,
        ))
    }

    /// The arguments of a tile written into an array (`tile_store`, `tile_atomic_add`):
    /// `(array, tile, offsets)`, the offsets optional; the tile's element and rank must be the
    /// array's. Returns the argument variables and the tile's type.
    fn array_tile_offsets(
        &mut self,
        name: &str,
        args: &[&Expr],
        span: Span,
    ) -> R<(Vec<VarId>, Ty)> {
        if !(2..=3).contains(&args.len()) {
            return err(
                span,
                format!("`{name}` takes an array, a tile and the offsets: `{name}(a, t, (i, j))`"),
            );
        }
        let (a, elem, ndim) = self.tile_array(name, args[0])?;
        let t = self.tile_arg(name, args[1])?;
        let tt = self.ty(t);
        let (te, td) = tile_parts(&tt).expect("a tile");
        if *te != elem {
            return err(
                args[1].span(),
                format!("`{name}`: a `{tt}` into an array of `{elem}`"),
            );
        }
        if td.len() != ndim as usize {
            return err(
                args[1].span(),
                format!(
                    "`{name}`: a tile of {} dimension(s) into an array of {ndim}; their ranks must agree",
                    td.len()
                ),
            );
        }
        let mut vars = vec![a, t];
        vars.extend(self.offsets(name, args.get(2).copied(), ndim, span)?);
        Ok((vars, tt))
    }

    fn tile_store(&mut self, row: &'static Builtin, args: &[&Expr], span: Span) -> R<VarId> {
        let (vars, _) = self.array_tile_offsets("tile_store", args, span)?;
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vars,
            },
            Ty::Unit,
            span,
        ))
    }

    /// `tile_arange::<T, N>()` (0 to N-1), or Warp's integer-literal forms `tile_arange(n)`,
    /// `(start, stop)`, `(start, stop, step)`; the element is the turbofish's or the
    /// annotation's, `i32` otherwise (Warp's default `int`).
    fn tile_arange(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        fish_elem: Option<Ty>,
        fish_dims: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<VarId> {
        let elem = fish_elem
            .or_else(|| want.map(|(e, _)| e.clone()))
            .unwrap_or(crate::types::I32);
        let lit = |e: &Expr| -> R<i64> {
            let (neg, inner) = match strip(e) {
                Expr::Unary(u) if matches!(u.op, syn::UnOp::Neg(_)) => (true, strip(&u.expr)),
                other => (false, other),
            };
            match inner {
                Expr::Lit(syn::ExprLit {
                    lit: syn::Lit::Int(i),
                    ..
                }) => i
                    .base10_parse::<i64>()
                    .map(|v| if neg { -v } else { v }),
                _ => err(
                    e.span(),
                    "`tile_arange`'s bounds are integer literals (its length is part of the tile's type)",
                ),
            }
        };
        let (start, step, dims) = match args.len() {
            0 => {
                let d = fish_dims.or_else(|| want.map(|(_, d)| d.to_vec()));
                match d {
                    Some(d) if d.len() == 1 => (0, 1, d),
                    _ => {
                        return err(
                            span,
                            "`tile_arange` needs its length: `tile_arange::<f32, 16>()` or `tile_arange(16)`",
                        )
                    }
                }
            }
            1..=3 => {
                let v = args.iter().map(|e| lit(e)).collect::<R<Vec<_>>>()?;
                let (start, stop, step) = match v[..] {
                    [n] => (0, n, 1),
                    [a, b] => (a, b, 1),
                    [a, b, s] => (a, b, s),
                    _ => unreachable!(),
                };
                if step == 0 {
                    return err(span, "`tile_arange`: the step must not be zero");
                }
                let n = (stop - start + step - step.signum()) / step;
                if n < 1 || n > u32::MAX as i64 {
                    return err(
                        span,
                        format!("`tile_arange({start}, {stop}, {step})` would be empty: a tile has at least one element"),
                    );
                }
                (start, step, vec![Dim::Lit(n as u32)])
            }
            n => {
                return err(
                    span,
                    format!("`tile_arange` takes at most 3 arguments, found {n}"),
                )
            }
        };
        let lit_of = |this: &mut Self, v: i64| {
            let l = if matches!(elem, Ty::Scalar(s) if s.is_float()) {
                Lit::Float(v as f64)
            } else {
                Lit::Int(v as i128)
            };
            this.def(Op::Lit(l), elem.clone(), span)
        };
        let s0 = lit_of(self, start);
        let s1 = lit_of(self, step);
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![s0, s1],
            },
            Ty::Tile(Box::new(elem.clone()), dims),
            span,
        ))
    }

    /// The function of `tile_map` or `tile_reduce`: a builtin taking `arity` values, Warp's
    /// operator names `add`, `sub`, `mul`, `div` (binary), or a user `#[func]`, recorded among
    /// the callees. A func's signature is not visible here: rustc checks it
    /// against the elements where the CPU code is generated (`TileMapFn`).
    fn tile_fn(&mut self, which: &str, e: &Expr, arity: usize) -> R<TileFn> {
        let Expr::Path(p) = strip(e) else {
            return err(
                e.span(),
                format!("`{which}` takes a function by name: `{which}(max, ..)`"),
            );
        };
        let segs: Vec<String> = p
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        let ok = p.qself.is_none()
            && (segs.len() == 1 || (segs.len() == 2 && crate::paths::names_facade(&segs[0])));
        let last = segs.last().cloned().unwrap_or_default();
        let op = match last.as_str() {
            "add" => Some(BinOp::Add),
            "sub" => Some(BinOp::Sub),
            "mul" => Some(BinOp::Mul),
            "div" => Some(BinOp::Div),
            _ => None,
        };
        match (op, builtins::lookup_user(&last)) {
            (Some(op), _) if ok && arity == 2 => Ok(TileFn::Op(op)),
            (Some(_), _) if ok => err(
                e.span(),
                format!("`{which}` applies a function of {arity} value(s) here; `{last}` takes 2"),
            ),
            (_, Some(b)) if ok && !b.is_tile() && b.params.len() == arity => {
                if b.is_atomic() || b.faults() || b.draw.is_some() || b.iterate.is_some() {
                    return err(e.span(), format!("`{which}` cannot apply `{}`", b.name));
                }
                Ok(TileFn::Builtin(b))
            }
            (_, Some(b)) if ok && !b.is_tile() => err(
                e.span(),
                format!(
                    "`{which}` applies a function of {arity} value(s) here; `{last}` takes {}",
                    b.params.len()
                ),
            ),
            _ => self.tile_user_fn(which, p, e.span()),
        }
    }

    /// A user `#[func]` as `tile_map`'s or `tile_reduce`'s function: a path that is no local variable, constant
    /// or the kernel itself, recorded among the callees (so its CUDA code, adjoint and call
    /// depth come with the kernel's, as for a call).
    fn tile_user_fn(&mut self, which: &str, p: &syn::ExprPath, span: Span) -> R<TileFn> {
        let path = &p.path;
        if p.qself.is_some() {
            return err(
                span,
                format!("`{which}` takes a builtin or a #[func] by its path"),
            );
        }
        if let Some(id) = path.get_ident() {
            let name = id.to_string();
            if self.lookup(&name).is_some() {
                return err(
                    span,
                    format!("`{which}` takes a builtin or a #[func] by name; `{name}` is a local variable"),
                );
            }
            if name == self.fn_name {
                return err(
                    span,
                    format!("recursion is not supported in kernels: `{name}` calls itself"),
                );
            }
        }
        let last = path
            .segments
            .last()
            .map(|s| s.ident.to_string())
            .unwrap_or_default();
        if last
            .chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
        {
            return err(
                span,
                format!("`{which}` takes a builtin or a #[func]; `{last}` names a constant"),
            );
        }
        let k = match self.callees.iter().position(|c| c == path) {
            Some(k) => k,
            None => {
                self.callees.push(path.clone());
                self.callees.len() - 1
            }
        };
        Ok(TileFn::Func(k))
    }

    /// The element type `f` makes of elements `elems`.
    fn tile_fn_result(&self, which: &str, f: TileFn, elems: &[Ty], span: Span) -> R<Ty> {
        if let (TileFn::Op(BinOp::Div), Ty::Scalar(s)) = (f, &elems[0]) {
            if !s.is_float() {
                return err(span, format!("`{which}` with `div` divides float tiles only (integer division would need a fault per element)"));
            }
        }
        let r = match f {
            TileFn::Op(op) => crate::operators::binary_result(op, &elems[0], &elems[1])
                .map_err(|m| syn::Error::new(span, format!("in `{which}`: {m}")))?,
            TileFn::Builtin(b) => {
                let args: Vec<ArgTy> = elems.iter().cloned().map(ArgTy::Known).collect();
                b.resolve(&args)
                    .map_err(|m| syn::Error::new(span, format!("in `{which}`: {m}")))?
                    .ret
            }
            TileFn::Func(_) => unreachable!("a func's result is the annotated element"),
        };
        if !matches!(r, Ty::Scalar(s) if s != Scalar::Bool) {
            return err(
                span,
                format!("`{which}` makes tiles of scalars, not of `{r}`"),
            );
        }
        Ok(r)
    }

    /// `tile_map(f, a)`, `tile_map(f, a, b)`, `tile_map(f, a, 2.0)`: the first argument after
    /// `f` is a tile, each later one a tile of its shape or a scalar constant (given to every
    /// element, as Warp broadcasts it). With a user func, whose result type the macro
    /// cannot see, the result's element is the one named (`tile_map::<i32>(f, a)`, or the
    /// annotation `let r: Tile<i32, 8> = tile_map(f, a)`), else the first tile's (Warp takes
    /// the func's return type; here rustc checks the func against the elements chosen).
    fn tile_map(
        &mut self,
        args: &[&Expr],
        fish_elem: Option<Ty>,
        fish_dims: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<VarId> {
        // Warp's variadic form takes up to eight tiles, for user funcs.
        if !(2..=9).contains(&args.len()) {
            return err(
                span,
                "`tile_map` takes a function, a tile and up to seven more tiles or scalars: `tile_map(sin, a)`, `tile_map(my_func, a, b, 2.0)`",
            );
        }
        let f = self.tile_fn("tile_map", args[0], args.len() - 1)?;
        let user = matches!(f, TileFn::Func(_));
        if !user && args.len() > 3 {
            return err(
                args[0].span(),
                "`tile_map` of more than two tiles takes a #[func]",
            );
        }
        if fish_dims.is_some() || (fish_elem.is_some() && !user) {
            return err(
                span,
                "`tile_map::<T>(f, ..)` names the result's element, for a #[func] only (a builtin's result follows from its operands)",
            );
        }
        let mut vars = Vec::new();
        let mut shape: Option<Vec<Dim>> = None;
        let mut elems: Vec<Ty> = Vec::new();
        for (i, a) in args[1..].iter().enumerate() {
            // After the first tile (which gives the shape, as in Warp), an argument may be a
            // scalar constant, broadcast to every element. An unsuffixed literal takes the
            // first tile's element type.
            let v = match elems.first() {
                None => {
                    let v = self.expr(a, None)?;
                    let t = self.ty(v);
                    if !t.is_tile() {
                        return err(
                            a.span(),
                            format!("`tile_map` takes a tile after the function (it gives the result's shape), found `{t}`; scalar constants may follow it: `tile_map(f, t, 2.0)`"),
                        );
                    }
                    if t.is_vector_tile() {
                        return err(a.span(), vector_tile_msg("tile_map", &t));
                    }
                    v
                }
                Some(first) => {
                    let first = first.clone();
                    let v = self.expr(a, Some(&first))?;
                    let t = self.ty(v);
                    if !t.is_tile() {
                        if !matches!(t, Ty::Scalar(s) if s != Scalar::Bool) {
                            return err(
                                a.span(),
                                format!("`tile_map` broadcasts integer or float scalars (and takes tiles); argument {} is `{t}`{}", i + 1, if t.is_deferred() { " (a value whose type the kernel cannot see: bind it with a type, `let s: f32 = ..`)" } else { "" }),
                            );
                        }
                        elems.push(t);
                        vars.push(v);
                        continue;
                    }
                    if t.is_vector_tile() {
                        return err(a.span(), vector_tile_msg("tile_map", &t));
                    }
                    v
                }
            };
            let t = self.ty(v);
            let (e, d) = tile_parts(&t).expect("a tile");
            let d = d.to_vec();
            if let Some(s) = shape.clone() {
                let msg = format!(
                    "`tile_map`: the tiles' shapes differ ({} and {})",
                    dims_text(&s),
                    dims_text(&d)
                );
                self.same_shapes(&s, &d, a.span(), msg)?;
            }
            shape = Some(d);
            elems.push(e.clone());
            vars.push(v);
        }
        let r = if user {
            let r = fish_elem
                .or_else(|| want.map(|(e, _)| e.clone()))
                .unwrap_or_else(|| elems[0].clone());
            if !matches!(r, Ty::Scalar(s) if s != Scalar::Bool)
                || elems.iter().any(|e| !matches!(e, Ty::Scalar(_)))
            {
                return err(
                    args[0].span(),
                    format!("`tile_map` applies a #[func] to tiles of scalars, giving scalars, not `{r}`"),
                );
            }
            r
        } else {
            self.tile_fn_result("tile_map", f, &elems, args[0].span())?
        };
        Ok(self.def(
            Op::TileMap { f, args: vars },
            Ty::Tile(Box::new(r), shape.expect("a tile")),
            span,
        ))
    }

    /// `tile_reduce(f, t)`: a `Tile<T, 1>`; `f` must give `T` back. A user `#[func]` is taken
    /// as `f(T, T) -> T`, which rustc checks at its path (`TileMapFn<(T, T), T>`).
    fn tile_reduce(&mut self, args: &[&Expr], span: Span) -> R<VarId> {
        let [f, t] = args[..] else {
            return err(
                span,
                "`tile_reduce` takes a function and a tile: `tile_reduce(max, t)`, `tile_reduce(my_func, t)`",
            );
        };
        let f = self.tile_fn("tile_reduce", f, 2)?;
        let v = self.scalar_tile_arg("tile_reduce", t)?;
        let tt = self.ty(v);
        let e = tile_parts(&tt).expect("a tile").0.clone();
        let r = match f {
            TileFn::Func(_) => e.clone(),
            _ => self.tile_fn_result("tile_reduce", f, &[e.clone(), e.clone()], args[0].span())?,
        };
        if r != e {
            return err(
                args[0].span(),
                format!("`tile_reduce` combines `{e}`s into a `{e}`; this function gives `{r}`"),
            );
        }
        Ok(self.def(
            Op::TileReduce { f, arg: v },
            Ty::Tile(Box::new(e), vec![Dim::Lit(1)]),
            span,
        ))
    }

    /// `tile_transpose(t)` of a 2-D tile.
    fn tile_transpose(&mut self, row: &'static Builtin, args: &[&Expr], span: Span) -> R<VarId> {
        let [t] = args[..] else {
            return err(span, "`tile_transpose` takes one tile");
        };
        let v = self.tile_arg("tile_transpose", t)?;
        let tt = self.ty(v);
        let (e, d) = tile_parts(&tt).expect("a tile");
        if d.len() != 2 {
            return err(
                t.span(),
                format!("`tile_transpose` takes a 2-D tile, found `{tt}`"),
            );
        }
        let ty = Ty::Tile(Box::new(e.clone()), vec![d[1].clone(), d[0].clone()]);
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![v],
            },
            ty,
            span,
        ))
    }

    /// `tile_broadcast::<M, N>(t)`, `tile_broadcast(t, (M, N))` or by the annotation: numpy's
    /// rule (shapes aligned on the right, each source dim 1 or the target's).
    fn tile_broadcast(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        fish: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<VarId> {
        let (t, shape_arg) = match args[..] {
            [t] => (t, None),
            [t, s] => (t, Some(s)),
            _ => {
                return err(
                    span,
                    "`tile_broadcast` takes a tile and the target shape: `tile_broadcast::<M, N>(t)` or `tile_broadcast(t, (M, N))`",
                )
            }
        };
        let target = match shape_arg {
            Some(s) => {
                let parts: Vec<&Expr> = match strip(s) {
                    Expr::Tuple(t) => t.elems.iter().collect(),
                    other => vec![other],
                };
                let d = parts
                    .into_iter()
                    .map(Self::dim_expr)
                    .collect::<R<Vec<_>>>()?;
                tile_rank(&d, s.span())?;
                Some(d)
            }
            None => fish.or_else(|| want.map(|(_, d)| d.to_vec())),
        };
        let Some(target) = target else {
            return err(
                span,
                "`tile_broadcast` needs the target shape: `tile_broadcast::<M, N>(t)`",
            );
        };
        let v = self.tile_arg("tile_broadcast", t)?;
        let tt = self.ty(v);
        let (e, src) = tile_parts(&tt).expect("a tile");
        let (e, src) = (e.clone(), src.to_vec());
        // Broadcasts are written for ranks 1 and 2 (warp-core's `broadcast11` .. `broadcast22`
        // and their adjoints); a 3-D or 4-D one is a clear error, not a missing function.
        if target.len() > 2 {
            return err(
                span,
                format!(
                    "`tile_broadcast` is defined for 1-D and 2-D tiles; the target ({}) has {} dimensions",
                    dims_text(&target),
                    target.len()
                ),
            );
        }
        if src.len() > target.len() {
            return err(
                span,
                format!(
                    "`tile_broadcast` cannot lower the rank: `{tt}` to ({})",
                    dims_text(&target)
                ),
            );
        }
        let msg = format!(
            "`tile_broadcast`: `{tt}` does not broadcast to ({}): each dim must be 1 or the target's",
            dims_text(&target)
        );
        // Aligned on the right.
        let off = target.len() - src.len();
        for (k, s) in src.iter().enumerate() {
            let t = &target[off + k];
            match (s, s.same(t)) {
                (Dim::Lit(1), _) | (_, Some(true)) => {}
                (_, Some(false)) => return err(span, msg),
                (_, None) => self.obligations.push(ShapeObligation {
                    span,
                    lhs: s.clone(),
                    rhs: t.clone(),
                    msg: msg.clone(),
                    or_one: true,
                    pow2: false,
                }),
            }
        }
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![v],
            },
            Ty::Tile(Box::new(e), target),
            span,
        ))
    }

    /// `tile_atomic_add(a, t, offsets)`: the tile of the old values.
    fn tile_atomic_add(&mut self, row: &'static Builtin, args: &[&Expr], span: Span) -> R<VarId> {
        let (vars, tt) = self.array_tile_offsets("tile_atomic_add", args, span)?;
        let elem = tile_parts(&tt).expect("a tile").0;
        if !row.classes.iter().any(|c| c.admits(elem)) {
            return err(
                args[0].span(),
                format!("`tile_atomic_add` adds i32, u32, i64, u64, f32 or f64, not `{elem}`"),
            );
        }
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vars,
            },
            tt,
            span,
        ))
    }

    /// The operands of a matmul: two 2-D tiles of one float element whose inner dims agree.
    fn matmul_operands(&mut self, args: &[&Expr]) -> R<(VarId, VarId, Ty, Dim, Dim)> {
        let a = self.tile_arg("tile_matmul", args[0])?;
        let b = self.tile_arg("tile_matmul", args[1])?;
        let (ta, tb) = (self.ty(a), self.ty(b));
        let ((ea, da), (eb, db)) = (tile_parts(&ta).unwrap(), tile_parts(&tb).unwrap());
        if da.len() != 2 || db.len() != 2 {
            return err(
                args[0].span(),
                format!("`tile_matmul` multiplies 2-D tiles, found `{ta}` and `{tb}`"),
            );
        }
        if ea != eb
            || !matches!(
                ea,
                Ty::Scalar(Scalar::F16 | Scalar::BF16 | Scalar::F32 | Scalar::F64)
            )
        {
            return err(
                args[0].span(),
                format!("`tile_matmul` multiplies f16, bf16, f32 or f64 tiles of one element type, found `{ta}` and `{tb}`"),
            );
        }
        let msg =
            format!("`tile_matmul`: the inner dimensions differ: `a` is `{ta}`, `b` is `{tb}`");
        let (inner_a, inner_b) = (da[1].clone(), db[0].clone());
        self.same_shapes(&[inner_a], &[inner_b], args[1].span(), msg)?;
        Ok((a, b, ea.clone(), da[0].clone(), db[1].clone()))
    }

    fn tile_matmul(&mut self, row: &'static Builtin, args: &[&Expr], span: Span) -> R<VarId> {
        if args.len() != 2 {
            return err(span, "`tile_matmul` takes two tiles, `c = tile_matmul(a, b)`, or accumulates, `tile_matmul(a, b, &mut c)`");
        }
        let (a, b, e, m, n) = self.matmul_operands(args)?;
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![a, b],
            },
            Ty::Tile(Box::new(e), vec![m, n]),
            span,
        ))
    }

    /// `tile_matmul(a, b, &mut c)`: `c = c + a b`, an assignment of `c`.
    fn tile_matmul_acc(&mut self, row: &'static Builtin, args: &[&Expr], span: Span) -> R<VarId> {
        let (a, b, e, m, n) = self.matmul_operands(args)?;
        let (c, cname) = self.mut_target(
            args[2],
            "`tile_matmul` accumulates into a tile variable passed as `&mut c`",
        )?;
        let ct = self.ty(c);
        // The accumulator's element: f16 and bf16 products accumulate in f32 (rounding a
        // 16-bit accumulator at every step of a k-loop would lose the sum's low bits), the
        // others in their own type.
        let e = if matches!(e, Ty::Scalar(Scalar::F16 | Scalar::BF16)) {
            Ty::Scalar(Scalar::F32)
        } else {
            e
        };
        let (e2, d2) = (e.clone(), vec![m.clone(), n.clone()]);
        let want = Ty::Tile(Box::new(e), vec![m, n]);
        let msg =
            format!("`tile_matmul`: `{cname}` is a `{ct}`, but `a b` accumulates into a `{want}`");
        match tile_parts(&ct) {
            Some((ce, cd)) if *ce == e2 => {
                let cd = cd.to_vec();
                self.same_shapes(&cd, &d2, args[2].span(), msg)?;
            }
            _ => return err(args[2].span(), msg),
        }
        self.require_mutable(c, &cname, args[2])?;
        self.push(
            StmtKind::Assign {
                dst: c,
                op: Op::Builtin {
                    builtin: row,
                    args: vec![a, b, c],
                },
                define: false,
            },
            span,
        );
        // The call is a statement; as a value it is the accumulator.
        Ok(c)
    }

    /// A variable passed as `&mut x` (`what` says how otherwise): its id and name.
    pub(super) fn mut_target(&mut self, e: &Expr, what: &str) -> R<(VarId, String)> {
        let target = match strip(e) {
            Expr::Reference(r) if r.mutability.is_some() => match strip(&r.expr) {
                Expr::Path(p) => p.path.get_ident().map(|i| i.to_string()),
                _ => None,
            },
            _ => None,
        };
        let Some(name) = target else {
            return err(e.span(), what);
        };
        let Some(v) = self.lookup(&name) else {
            return err(e.span(), format!("cannot find `{name}`"));
        };
        Ok((v, name))
    }

    pub(super) fn require_mutable(&self, v: VarId, name: &str, e: &Expr) -> R<()> {
        if !self.vars[v].mutable {
            return err(
                e.span(),
                format!("`{name}` is not mutable: declare it `let mut {name}`"),
            );
        }
        Ok(())
    }

    /// `tile_fft(&mut t)`, `tile_ifft(&mut t)`: `t = tile_fft(t)`, an assignment of `t`, which
    /// must be a `Tile<Vec2 | DVec2, M, N>` whose `N` is a power of two.
    fn tile_fft(&mut self, row: &'static Builtin, args: &[&Expr], span: Span) -> R<VarId> {
        let name = row.name;
        let usage = format!("`{name}` transforms a tile variable in place: `{name}(&mut t)`");
        let [arg] = args[..] else {
            return err(span, usage);
        };
        let (t, tname) = self.mut_target(arg, &usage)?;
        let tt = self.ty(t);
        let ok = match tile_parts(&tt) {
            Some((e, d)) => e.is_vec2_float() && d.len() == 2,
            None => false,
        };
        if !ok {
            return err(
                arg.span(),
                format!("`{name}` transforms 2-D tiles of complex values, `Tile<Vec2, M, N>` or `Tile<DVec2, M, N>` (each row along the last axis), found `{tt}`"),
            );
        }
        let n = tile_parts(&tt).expect("a tile").1[1].clone();
        let msg = format!("`{name}`: the transform's length, the last dim of `{tt}`, must be a power of two (radix-2)");
        match &n {
            Dim::Lit(v) if !v.is_power_of_two() => return err(arg.span(), msg),
            Dim::Lit(_) => {}
            Dim::Const(_) => self.obligations.push(ShapeObligation {
                span: arg.span(),
                lhs: n.clone(),
                rhs: n.clone(),
                msg,
                or_one: false,
                pow2: true,
            }),
        }
        self.require_mutable(t, &tname, arg)?;
        self.push(
            StmtKind::Assign {
                dst: t,
                op: Op::Builtin {
                    builtin: row,
                    args: vec![t],
                },
                define: false,
            },
            span,
        );
        // The call is a statement; as a value it is the tile.
        Ok(t)
    }

    /// `t[i]`, `t[(i, j)]`: an element of a tile (a read by each thread; an index outside the
    /// tile faults).
    pub(super) fn tile_index(&mut self, t: VarId, index: &Expr, span: Span) -> R<VarId> {
        let tt = self.ty(t);
        let (e, d) = tile_parts(&tt).expect("a tile");
        let (e, n) = (e.clone(), d.len() as u8);
        let parts: Vec<&Expr> = match strip(index) {
            Expr::Tuple(t) => t.elems.iter().collect(),
            other => vec![other],
        };
        if parts.len() != n as usize {
            return err(
                index.span(),
                format!("`{tt}` has {n} dimension(s): index it with {n} integer(s)"),
            );
        }
        let mut args = vec![t];
        for p in parts {
            let v = self.expr(p, Some(&USIZE))?;
            let it = self.ty(v);
            if !(it.is_deferred() || it.is_int_scalar()) {
                return err(p.span(), format!("tile indices are integers, found `{it}`"));
            }
            args.push(v);
        }
        let row = builtins::lookup("tile_extract").expect("the tile_extract row");
        Ok(self.def(Op::Builtin { builtin: row, args }, e, span))
    }
}

/// The error for a tile of vectors where an operation takes tiles of scalars.
fn vector_tile_msg(name: &str, t: &Ty) -> String {
    format!("`{name}` takes a tile of scalars, found `{t}`: tiles of `Vec2`/`DVec2` support loads, stores, `t[(i, j)]`, `tile_zeros`, `+`, `-`, `*` by a scalar, `tile_fft` and `tile_ifft`")
}
