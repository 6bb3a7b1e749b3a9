//! Typing of the tile linear algebra: `tile_cholesky(a)`, `tile_cholesky_solve(L, y)`,
//! `tile_lower_solve(L, y)`, `tile_upper_solve(U, z)` (Warp's rules, checked here at the call
//! where Warp checks them at code generation): the matrix is a square 2-D tile of f32 or f64,
//! the right-hand side a 1-D or 2-D tile of the same element with as many rows, and a solve's
//! result has the right-hand side's type. A const dim the macro cannot compare becomes an
//! obligation rustc checks (`same_shapes`).

use super::*;

impl Lowerer {
    /// The square matrix argument `what` of `name`: its variable, element and side.
    fn square_tile(&mut self, name: &str, what: &str, e: &Expr) -> R<(VarId, Ty, Dim)> {
        let v = self.tile_arg(name, e)?;
        let t = self.ty(v);
        let (el, d) = tile_parts(&t).expect("a tile");
        if !matches!(el, Ty::Scalar(Scalar::F32 | Scalar::F64)) {
            return err(
                e.span(),
                format!("`{name}` takes f32 or f64 tiles, found `{t}`"),
            );
        }
        if d.len() != 2 {
            return err(
                e.span(),
                format!("`{name}`: `{what}` must be a square 2-D tile, found `{t}`"),
            );
        }
        let (el, d0, d1) = (el.clone(), d[0].clone(), d[1].clone());
        let msg = format!("`{name}`: `{what}` must be square, found `{t}`");
        self.same_shapes(std::slice::from_ref(&d0), &[d1], e.span(), msg)?;
        Ok((v, el, d0))
    }

    /// A call of one of the four rows.
    pub(super) fn tile_linalg(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        span: Span,
    ) -> R<VarId> {
        let name = row.name;
        if name == "tile_cholesky" {
            let [a] = args[..] else {
                let msg = if args.len() == 2 {
                    "`tile_cholesky(a)` takes one tile: Warp's `fill_mode` is not supported (the factor is lower triangular)"
                } else {
                    "`tile_cholesky(a)` takes one square tile"
                };
                return err(span, msg);
            };
            let (v, _, _) = self.square_tile(name, "a", a)?;
            let ty = self.ty(v);
            return Ok(self.def(
                Op::Builtin {
                    builtin: row,
                    args: vec![v],
                },
                ty,
                span,
            ));
        }
        let (m_name, r_name) = if name == "tile_upper_solve" {
            ("U", "z")
        } else {
            ("L", "y")
        };
        let [m, y] = args[..] else {
            let extra = if args.len() == 3 && name == "tile_cholesky_solve" {
                " (Warp's `fill_mode` is not supported: `L` is lower triangular)"
            } else {
                ""
            };
            return err(
                span,
                format!(
                    "`{name}({m_name}, {r_name})` takes a square tile and a right-hand side{extra}"
                ),
            );
        };
        let (mv, el, n) = self.square_tile(name, m_name, m)?;
        let mt = self.ty(mv);
        let yv = self.tile_arg(name, y)?;
        let yt = self.ty(yv);
        let (ye, yd) = tile_parts(&yt).expect("a tile");
        if *ye != el {
            return err(
                y.span(),
                format!("`{name}`: `{r_name}` is a `{yt}` and `{m_name}` a `{mt}`: their elements differ"),
            );
        }
        if yd.len() > 2 {
            return err(
                y.span(),
                format!("`{name}`: `{r_name}` is a 1-D or 2-D tile, found `{yt}`"),
            );
        }
        let rows = yd[0].clone();
        let msg = format!(
            "`{name}`: `{m_name}` is a `{mt}`, so `{r_name}` must have {n} rows; found `{yt}`"
        );
        self.same_shapes(&[n], &[rows], y.span(), msg)?;
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![mv, yv],
            },
            yt,
            span,
        ))
    }
}
