//! Typing of the windows of tiles: `tile_view` (a copy of a sub-tile) and the in-place forms
//! that write a tile into a window of another (`tile_assign`, `tile_add_inplace`, ..). A window
//! that the macro can see does not fit (literal dims, literal offsets) is an error at the call;
//! the rest is checked when the kernel runs (a `TileIndex` fault: warp-core's `tile::view`).

use super::*;

/// An integer literal, possibly negated: a constant offset the macro can check.
fn lit_offset(e: &Expr) -> Option<i128> {
    let (neg, inner) = match strip(e) {
        Expr::Unary(u) if matches!(u.op, syn::UnOp::Neg(_)) => (true, strip(&u.expr)),
        other => (false, other),
    };
    match inner {
        Expr::Lit(syn::ExprLit {
            lit: syn::Lit::Int(i),
            ..
        }) => i
            .base10_parse::<i128>()
            .ok()
            .map(|v| if neg { -v } else { v }),
        _ => None,
    }
}

impl Lowerer {
    /// The offsets of a window in a tile of `rank` dims: one integer or a tuple of at most
    /// `rank` (`exact`: of `rank`); absent, zeros. Returns their variables and their literal
    /// values where they are literals.
    fn window_offsets(
        &mut self,
        name: &str,
        e: Option<&Expr>,
        rank: usize,
        exact: bool,
        span: Span,
    ) -> R<(Vec<VarId>, Vec<Option<i128>>)> {
        let Some(e) = e else {
            let zeros = (0..rank)
                .map(|_| self.def(Op::Lit(Lit::Int(0)), crate::types::I32, span))
                .collect();
            return Ok((zeros, vec![Some(0); rank]));
        };
        let parts: Vec<&Expr> = match strip(e) {
            Expr::Tuple(t) => t.elems.iter().collect(),
            other => vec![other],
        };
        if parts.is_empty() || parts.len() > rank || (exact && parts.len() != rank) {
            return err(
                e.span(),
                format!(
                    "`{name}` into a tile of {rank} dimension(s) takes {rank} offset(s), found {}",
                    parts.len()
                ),
            );
        }
        let (mut vars, mut lits) = (Vec::new(), Vec::new());
        for p in parts {
            let v = self.expr(p, None)?;
            let t = self.ty(v);
            if !(t.is_deferred() || t.is_int_scalar()) {
                return err(p.span(), format!("tile offsets are integers, found `{t}`"));
            }
            vars.push(v);
            lits.push(lit_offset(p));
        }
        Ok((vars, lits))
    }

    /// The checks the macro can make of a window of dims `w` at offsets `lits` in a tile of dims
    /// `t` (the window's axes are the tile's trailing ones): an error at `span` when a literal
    /// dim is larger than the tile's, or a literal offset puts the window outside it.
    fn window_fits(name: &str, t: &[Dim], w: &[Dim], lits: &[Option<i128>], span: Span) -> R<()> {
        let drop = t.len() - w.len();
        for (k, td) in t.iter().enumerate() {
            let n = match td {
                Dim::Lit(n) => Some(*n as i128),
                Dim::Const(_) => None,
            };
            let m = match k.checked_sub(drop).map(|a| &w[a]) {
                Some(Dim::Lit(m)) => Some(*m as i128),
                Some(Dim::Const(_)) => None,
                None => Some(1),
            };
            if let (Some(n), Some(m)) = (n, m) {
                if m > n {
                    return err(
                        span,
                        format!("`{name}`: the window is {m} long on axis {k}, longer than the tile's {n}"),
                    );
                }
            }
            match (lits.get(k).copied().flatten(), n, m) {
                (Some(o), _, _) if o < 0 => {
                    return err(
                        span,
                        format!("`{name}`: offset {o} on axis {k} is negative: the window starts outside the tile"),
                    )
                }
                (Some(o), Some(n), Some(m)) if o + m > n => {
                    return err(
                        span,
                        format!("`{name}`: the window at offset {o} on axis {k} ends at {}, past the tile's {n}", o + m),
                    )
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// `tile_view::<M, N>(t, (i, j))`, Warp's `tile_view(t, (i, j), (M, N))`, or the shape from
    /// the annotation: a copy of the window; `tile_view(t, i)` of a 2-D tile without a shape:
    /// row `i` (Warp's view of the trailing dims).
    pub(super) fn tile_view(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        fish: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<VarId> {
        let (te, oe, se) = match args[..] {
            [t, o] => (t, o, None),
            [t, o, s] => (t, o, Some(s)),
            _ => {
                return err(
                    span,
                    "`tile_view` takes a tile and the window's offsets, `tile_view::<M, N>(t, (i, j))`, or Warp's `tile_view(t, (i, j), (M, N))`",
                )
            }
        };
        let t = self.tile_arg("tile_view", te)?;
        let tt = self.ty(t);
        let (e, td) = tile_parts(&tt).expect("a tile");
        let (e, td) = (e.clone(), td.to_vec());
        // Windows are written for ranks 1 and 2 (warp-core's `view11` .. `window2`).
        if td.len() > 2 {
            return err(
                te.span(),
                format!("`tile_view` is defined for 1-D and 2-D tiles, found `{tt}`"),
            );
        }
        let explicit = match se {
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
            None => fish,
        };
        let (mut offs, mut lits) =
            self.window_offsets("tile_view", Some(oe), td.len(), false, span)?;
        let (shape, drops) = match explicit {
            Some(d) => (d, false),
            // Warp's view without a shape: the dims after the offsets'.
            None if offs.len() < td.len() => (td[offs.len()..].to_vec(), true),
            None => match want {
                Some((_, d)) => (d.to_vec(), false),
                None => {
                    return err(
                        span,
                        "`tile_view` needs the view's shape: `tile_view::<M, N>(t, (i, j))`, `tile_view(t, (i, j), (M, N))`, or the annotation's",
                    )
                }
            },
        };
        if !drops {
            if shape.len() != td.len() {
                return err(
                    span,
                    format!(
                        "`tile_view`: a view of `{tt}` has its rank, {}; the shape ({}) has {}",
                        td.len(),
                        dims_text(&shape),
                        shape.len()
                    ),
                );
            }
            // Offsets not given are zero (Warp's default).
            while offs.len() < td.len() {
                offs.push(self.def(Op::Lit(Lit::Int(0)), crate::types::I32, span));
                lits.push(Some(0));
            }
        }
        Self::window_fits("tile_view", &td, &shape, &lits, span)?;
        let mut vars = vec![t];
        vars.extend(offs);
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vars,
            },
            Ty::Tile(Box::new(e), shape),
            span,
        ))
    }

    /// `tile_assign(&mut d, s, (i, j))` and the `_inplace` forms: `d = op(d, s)` in the window
    /// of `s`'s shape at the offsets (zeros when absent), an assignment of `d`.
    pub(super) fn tile_window(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        span: Span,
    ) -> R<VarId> {
        let name = row.name;
        let usage = format!(
            "`{name}` writes a tile into a tile variable in place: `{name}(&mut d, s, (i, j))`"
        );
        let (de, se, oe) = match args[..] {
            [d, s] => (d, s, None),
            [d, s, o] => (d, s, Some(o)),
            _ => return err(span, usage),
        };
        let (d, dname) = self.mut_target(de, &usage)?;
        let dt = self.ty(d);
        let Some((del, dd)) = tile_parts(&dt) else {
            return err(
                de.span(),
                format!("`{name}` writes into a tile, found `{dt}`"),
            );
        };
        let (del, dd) = (del.clone(), dd.to_vec());
        if dd.len() > 2 {
            return err(
                de.span(),
                format!("`{name}` is defined for 1-D and 2-D tiles, found `{dt}`"),
            );
        }
        let s = self.tile_arg(name, se)?;
        let st = self.ty(s);
        let (sel, sd) = tile_parts(&st).expect("a tile");
        let (sel, sd) = (sel.clone(), sd.to_vec());
        if sel != del {
            return err(
                se.span(),
                format!("`{name}`: a `{st}` into a `{dt}`: their elements differ"),
            );
        }
        if sd.len() != dd.len() {
            return err(
                se.span(),
                format!("`{name}`: a `{st}` into a `{dt}`: their ranks must agree"),
            );
        }
        let scalar = matches!(del, Ty::Scalar(_));
        let int = del.is_int_scalar();
        let ok = match name {
            "tile_assign" => true,
            "tile_add_inplace" | "tile_sub_inplace" => scalar,
            _ => int,
        };
        if !ok {
            let what = if scalar || name.starts_with("tile_bit") {
                "integer tiles"
            } else {
                "tiles of scalars"
            };
            return err(de.span(), format!("`{name}` takes {what}, found `{dt}`"));
        }
        let (offs, lits) = self.window_offsets(name, oe, dd.len(), true, span)?;
        Self::window_fits(name, &dd, &sd, &lits, span)?;
        self.require_mutable(d, &dname, de)?;
        let mut vars = vec![d, s];
        vars.extend(offs);
        self.push(
            StmtKind::Assign {
                dst: d,
                op: Op::Builtin {
                    builtin: row,
                    args: vars,
                },
                define: false,
            },
            span,
        );
        // The call is a statement; as a value it is the destination.
        Ok(d)
    }
}
