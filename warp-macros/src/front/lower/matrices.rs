//! Warp's scalar constructor of a non-square matrix, `Mat23::new(a00, a01, a02, a10, a11,
//! a12)` (Warp's `matrix(*scalars, shape=(2, 3))`, row-major): lowered to its rows, each a
//! vector's `new` of `C` scalars, then `from_rows`, so that both back ends, reverse and
//! forward mode see only constructors they already have.

use super::*;

impl Lowerer {
    /// `MatRC::new(..)` of `R * C` scalars of the matrix's precision.
    pub(super) fn matrix_from_scalars(
        &mut self,
        ty: Ty,
        c: &syn::ExprCall,
        span: Span,
    ) -> R<VarId> {
        let Ty::MatRC(s, rows, cols) = ty else {
            unreachable!("called for non-square matrices only")
        };
        let (rows, cols) = (rows as usize, cols as usize);
        let Some(row_ty @ Ty::Vector(..)) = Ty::vec_of(s, cols as u8) else {
            return err(
                c.func.span(),
                format!(
                    "`{ty}::new` of scalars is not supported for six columns: build the rows, \
                     `{ty}::from_rows(spatial_vector(..), ..)`"
                ),
            );
        };
        if c.args.len() != rows * cols {
            return err(
                span,
                format!(
                    "`{ty}::new` takes {} scalars, the entries row by row",
                    rows * cols
                ),
            );
        }
        let scalar = Ty::Scalar(s);
        let args: Vec<&Expr> = c.args.iter().collect();
        let mut row_vars = Vec::new();
        for r in 0..rows {
            let mut lanes = Vec::new();
            for a in &args[r * cols..(r + 1) * cols] {
                let v = self.expr(a, Some(&scalar))?;
                let t = self.ty(v);
                if !t.is_deferred() && t != scalar {
                    return err(
                        a.span(),
                        format!("mismatched types: expected `{scalar}`, found `{t}`"),
                    );
                }
                lanes.push(v);
            }
            let ctor = Ctor::Components;
            let op = Op::Construct {
                ty: row_ty.clone(),
                ctor,
                args: lanes,
            };
            row_vars.push(self.def(op, row_ty.clone(), span));
        }
        let op = Op::Construct {
            ty: ty.clone(),
            ctor: Ctor::Components,
            args: row_vars,
        };
        Ok(self.def(op, ty, span))
    }
}
