//! Typing of `tile_sort(&mut keys, &mut values)` and the conversions `tile_full`,
//! `tile_astype`, `tile_reshape`, `tile_squeeze` and `tile_diag_add`: shape rules the macro can
//! decide are errors at the call; a const dim the macro cannot compare becomes an obligation
//! rustc checks (`same_shapes`), and a reshape's size with const dims is warp-core's const
//! assertion.

use super::*;

impl Lowerer {
    /// `tile_sort(&mut keys, &mut values)`: both sorted in place by the keys (the row's comment
    /// says how it lowers). As a value the call is the keys, as the accumulating matmul's is
    /// its accumulator.
    pub(super) fn tile_sort(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        span: Span,
    ) -> R<VarId> {
        let [ke, ve] = args[..] else {
            return err(
                span,
                "`tile_sort` sorts a key tile and a value tile in place: `tile_sort(&mut keys, &mut values)`",
            );
        };
        let (k, kname) = self.mut_target(
            ke,
            "`tile_sort` sorts tile variables in place, passed as `&mut keys`",
        )?;
        let (v, vname) = self.mut_target(
            ve,
            "`tile_sort` sorts tile variables in place, passed as `&mut values`",
        )?;
        let (kt, vt) = (self.ty(k), self.ty(v));
        let (Some((kel, kd)), Some((_, vd))) = (tile_parts(&kt), tile_parts(&vt)) else {
            let (bad, e) = if kt.is_tile() { (&vt, ve) } else { (&kt, ke) };
            return err(e.span(), format!("`tile_sort` sorts tiles, found `{bad}`"));
        };
        let (kel, kd, vd) = (kel.clone(), kd.to_vec(), vd.to_vec());
        if kd.len() != 1 || vd.len() != 1 {
            let (bad, e) = if kd.len() != 1 { (&kt, ke) } else { (&vt, ve) };
            return err(
                e.span(),
                format!("`tile_sort` sorts one-dimensional tiles, found `{bad}`"),
            );
        }
        if !row.classes.iter().any(|c| c.admits(&kel)) {
            return err(
                ke.span(),
                format!("`tile_sort` sorts keys of i32, u32, i64, u64, f32 or f64, not `{kel}`"),
            );
        }
        if k == v {
            return err(
                ve.span(),
                format!("`tile_sort` takes two different tiles, found `{kname}` twice"),
            );
        }
        let msg = format!(
            "`tile_sort`: the keys `{kname}` are a `{kt}` and the values `{vname}` a `{vt}`: their lengths differ"
        );
        self.same_shapes(&kd, &vd, ve.span(), msg)?;
        self.require_mutable(k, &kname, ke)?;
        self.require_mutable(v, &vname, ve)?;
        let p = self.def(
            Op::Builtin {
                builtin: row,
                args: vec![k],
            },
            Ty::Tile(Box::new(crate::types::I32), kd),
            span,
        );
        // Both permutations read `p`, not the keys, so their order does not matter.
        for dst in [v, k] {
            self.push(
                StmtKind::Assign {
                    dst,
                    op: Op::Builtin {
                        builtin: row,
                        args: vec![dst, p],
                    },
                    define: false,
                },
                span,
            );
        }
        Ok(k)
    }

    /// `tile_full::<T, M, N>(x)` or by the annotation: every element `x`.
    pub(super) fn tile_full(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        fish_elem: Option<Ty>,
        fish_dims: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<VarId> {
        let [x] = args[..] else {
            return err(
                span,
                "`tile_full` takes the value, its shape and element as a turbofish: `tile_full::<f32, 16, 8>(x)`, or from the annotation",
            );
        };
        let ty = self.made_tile("tile_full", fish_elem, fish_dims, want, span)?;
        let e = tile_parts(&ty).expect("a tile").0.clone();
        let v = self.expr(x, Some(&e))?;
        let vt = self.ty(v);
        if vt != e {
            return err(
                x.span(),
                format!("`tile_full` fills a `{ty}`: the value must be a `{e}`, found `{vt}`"),
            );
        }
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![v],
            },
            ty,
            span,
        ))
    }

    /// `tile_astype::<U>(t)` (or by the annotation's element): each element `as U`.
    pub(super) fn tile_astype(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        fish_elem: Option<Ty>,
        fish_dims: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<VarId> {
        let [t] = args[..] else {
            return err(
                span,
                "`tile_astype` takes one tile: `tile_astype::<f64>(t)`",
            );
        };
        if fish_dims.is_some() {
            return err(
                span,
                "`tile_astype::<U>` names the element only: the shape is the tile's",
            );
        }
        let Some(u) = fish_elem.or_else(|| want.map(|(e, _)| e.clone())) else {
            return err(
                span,
                "`tile_astype` needs the element to convert to: `tile_astype::<f64>(t)`, or the annotation's",
            );
        };
        let v = self.tile_arg("tile_astype", t)?;
        let tt = self.ty(v);
        let d = tile_parts(&tt).expect("a tile").1.to_vec();
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![v],
            },
            Ty::Tile(Box::new(u), d),
            span,
        ))
    }

    /// `tile_reshape::<M, N>(t)` (or by the annotation), `tile_squeeze(t)`: the same elements in
    /// row-major order in another shape of the same size.
    pub(super) fn tile_reshape(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        fish_dims: Option<Vec<Dim>>,
        want: Option<(&Ty, &[Dim])>,
        span: Span,
    ) -> R<VarId> {
        let name = row.name;
        let [t] = args[..] else {
            return err(span, format!("`{name}` takes one tile"));
        };
        let v = self.tile_arg(name, t)?;
        let tt = self.ty(v);
        let (e, src) = tile_parts(&tt).expect("a tile");
        let (e, src) = (e.clone(), src.to_vec());
        let target = if name == "tile_squeeze" {
            if fish_dims.is_some() {
                return err(
                    span,
                    "`tile_squeeze` takes no shape: it drops the tile's dims of 1",
                );
            }
            // Only literal 1s are dropped: a const dim's value is rustc's to know.
            let kept: Vec<Dim> = src.iter().filter(|d| **d != Dim::Lit(1)).cloned().collect();
            if kept.is_empty() {
                vec![Dim::Lit(1)]
            } else {
                kept
            }
        } else {
            let Some(target) = fish_dims.or_else(|| want.map(|(_, d)| d.to_vec())) else {
                return err(
                    span,
                    "`tile_reshape` needs the target shape: `tile_reshape::<M, N>(t)`, or the annotation's",
                );
            };
            // The sizes, where every dim is a literal; otherwise warp-core's const assertion
            // (and the CUDA static_assert) decide.
            let size = |d: &[Dim]| {
                d.iter().try_fold(1u64, |acc, x| match x {
                    Dim::Lit(n) => Some(acc * u64::from(*n)),
                    Dim::Const(_) => None,
                })
            };
            if let (Some(a), Some(b)) = (size(&src), size(&target)) {
                if a != b {
                    return err(
                        span,
                        format!(
                            "`tile_reshape`: `{tt}` has {a} elements, and the shape ({}) has {b}",
                            dims_text(&target)
                        ),
                    );
                }
            }
            target
        };
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![v],
            },
            Ty::Tile(Box::new(e), target),
            span,
        ))
    }

    /// `tile_diag_add(a, d)`: `a` square, `d` as long as its side, of one element type.
    pub(super) fn tile_diag_add(
        &mut self,
        row: &'static Builtin,
        args: &[&Expr],
        span: Span,
    ) -> R<VarId> {
        let [a, d] = args[..] else {
            return err(
                span,
                "`tile_diag_add` takes a square tile and a 1-D tile: `tile_diag_add(a, d)`",
            );
        };
        let va = self.tile_arg("tile_diag_add", a)?;
        let vd = self.tile_arg("tile_diag_add", d)?;
        let (ta, td) = (self.ty(va), self.ty(vd));
        let ((ea, da), (ed, dd)) = (tile_parts(&ta).unwrap(), tile_parts(&td).unwrap());
        let (da, dd) = (da.to_vec(), dd.to_vec());
        if da.len() != 2 {
            return err(
                a.span(),
                format!("`tile_diag_add`: `a` must be a square 2-D tile, found `{ta}`"),
            );
        }
        if dd.len() != 1 || ea != ed {
            return err(
                d.span(),
                format!("`tile_diag_add`: `d` must be a 1-D tile of `a`'s element, found `{td}` for `{ta}`"),
            );
        }
        let msg = format!("`tile_diag_add`: `a` must be square, found `{ta}`");
        self.same_shapes(&da[..1], &da[1..], a.span(), msg)?;
        let msg =
            format!("`tile_diag_add`: `d` must be as long as `a`'s side, found `{td}` for `{ta}`");
        self.same_shapes(&da[..1], &dd, d.span(), msg)?;
        Ok(self.def(
            Op::Builtin {
                builtin: row,
                args: vec![va, vd],
            },
            ta,
            span,
        ))
    }
}
