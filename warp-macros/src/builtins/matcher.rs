//! The matcher: a call's argument types against a row's signature ([`Builtin::resolve`]).
//!
//! Matching binds `T` from the first argument whose type is known and fixed by `T` (a `T` or
//! `Array<T>` position); literal arguments are then typed from `T`, which is the one literal
//! rule both backends share (see `front::lower::typing`).

use super::signature::Pos;
use super::Builtin;
use crate::types::{ObjectKind, Scalar, Ty};

/// An argument as the matcher sees it.
#[derive(Clone, Debug)]
pub enum ArgTy {
    /// A value of known (possibly deferred) type.
    Known(Ty),
    /// An unsuffixed numeric literal, typed by the signature.
    Literal { float: bool },
}

/// The outcome of matching a call against a builtin's signature.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    /// The type each argument takes (literals included); `Deferred` where unknown.
    pub params: Vec<Ty>,
    pub ret: Ty,
}

impl Builtin {
    /// Matches argument types against the signature, binding `T`.
    pub fn resolve(&self, args: &[ArgTy]) -> Result<Resolved, String> {
        if args.len() != self.params.len() {
            return Err(format!(
                "`{}` takes {} argument{}, found {}",
                self.name,
                self.params.len(),
                if self.params.len() == 1 { "" } else { "s" },
                args.len()
            ));
        }
        // Bind T from the first known argument in a T or Array<T> position.
        let mut t: Option<Ty> = None;
        let mut array_ndim = 1u8;
        for (pos, arg) in self.params.iter().zip(args) {
            match (pos, arg) {
                (Pos::T, ArgTy::Known(ty)) if !ty.is_deferred() && t.is_none() => {
                    t = Some(ty.clone())
                }
                (Pos::ArrayOfT, ArgTy::Known(Ty::Array(elem, n))) => {
                    array_ndim = *n;
                    if t.is_none() {
                        t = Some((**elem).clone());
                    }
                }
                (Pos::ArrayOfT, ArgTy::Known(ty)) if !ty.is_deferred() => {
                    return Err(format!(
                        "`{}` expects an array as its first argument, found `{ty}`",
                        self.name
                    ))
                }
                (Pos::VolumeOfT, ArgTy::Known(Ty::Object(ObjectKind::Volume(e)))) => match e.ty() {
                    Some(v) if t.is_none() => t = Some(v),
                    Some(_) => {}
                    None => {
                        return Err(format!(
                            "`{}` reads the values of a `Volume<T>`; a \
                                 `Volume<VoxelIndex>` holds indices: use `volume_sample_index`",
                            self.name
                        ))
                    }
                },
                (Pos::VolumeOfT | Pos::AnyVolume, ArgTy::Known(ty))
                    if !ty.is_deferred() && !matches!(ty, Ty::Object(ObjectKind::Volume(_))) =>
                {
                    return Err(format!(
                        "`{}` expects a `Volume<T>` as its first argument, found `{ty}`",
                        self.name
                    ))
                }
                (Pos::BsrOfT, ArgTy::Known(Ty::Object(ObjectKind::Bsr(b)))) if t.is_none() => {
                    t = Some(b.ty())
                }
                (Pos::BsrOfT | Pos::AnyBsr, ArgTy::Known(ty))
                    if !ty.is_deferred() && !matches!(ty, Ty::Object(ObjectKind::Bsr(_))) =>
                {
                    return Err(format!(
                        "`{}` expects a `Bsr<B>` (a sparse matrix) as its first argument, \
                         found `{ty}`",
                        self.name
                    ))
                }
                _ => {}
            }
        }
        // Only literals in T positions: the literal rule's defaults (f32, else i32).
        if t.is_none() {
            let t_lits: Vec<bool> = self
                .params
                .iter()
                .zip(args)
                .filter_map(|(p, a)| match (p, a) {
                    (Pos::T, ArgTy::Literal { float }) => Some(*float),
                    _ => None,
                })
                .collect();
            let deferred = args
                .iter()
                .any(|a| matches!(a, ArgTy::Known(t) if t.is_deferred()));
            if !t_lits.is_empty() && !deferred {
                t = Some(if t_lits.contains(&true) {
                    crate::types::F32
                } else {
                    crate::types::I32
                });
            }
        }
        let mentions_t = self.params.iter().chain([&self.ret]).any(|p| !p.fixed());
        let t = match t {
            // Every position fixed: nothing to bind (the classes are empty).
            None if !mentions_t => Some(Ty::Deferred),
            t => t,
        };
        let Some(t) = t else {
            // Nothing known: leave typing to the target compiler.
            let params = self.params.iter().map(|_| Ty::Deferred).collect();
            let ret = match self.ret {
                Pos::Tuple(ps) => Ty::Tuple(vec![Ty::Deferred; ps.len()]),
                _ => Ty::Deferred,
            };
            return Ok(Resolved { params, ret });
        };
        if mentions_t && !self.classes.iter().any(|c| c.admits(&t)) {
            let want: Vec<_> = self.classes.iter().map(|c| c.describe()).collect();
            return Err(format!(
                "`{}` is not defined for `{t}`: it takes {}",
                self.name,
                want.join(", or ")
            ));
        }
        let scalar = t.scalar().map(Ty::Scalar).unwrap_or(Ty::Deferred);
        let index_ty = if array_ndim == 1 {
            crate::types::USIZE
        } else {
            Ty::TidTuple(array_ndim)
        };
        let want = |p: &Pos| match p {
            Pos::T => t.clone(),
            Pos::ScalarOfT => scalar.clone(),
            Pos::ArrayOfT => Ty::Array(Box::new(t.clone()), array_ndim),
            Pos::Index => index_ty.clone(),
            Pos::Bool => crate::types::BOOL,
            Pos::MatOfT => match &t {
                Ty::Vector(s, n) => Ty::Matrix(*s, *n),
                Ty::Quat(s) => Ty::Matrix(*s, 3),
                Ty::Transform(s) => Ty::Matrix(*s, 4),
                Ty::SpatialVector(s) => Ty::SpatialMatrix(*s),
                _ => Ty::Deferred,
            },
            Pos::VecOfT => match &t {
                Ty::Matrix(s, n) => Ty::Vector(*s, *n),
                Ty::Quat(s) => Ty::Vector(*s, 3),
                _ => Ty::Deferred,
            },
            Pos::QuatOfT => scalar.scalar().map(Ty::Quat).unwrap_or(Ty::Deferred),
            Pos::IntOfT => match &t {
                Ty::Scalar(_) => crate::types::I32,
                Ty::Vector(_, n) => Ty::Vector(Scalar::I32, *n),
                _ => Ty::Deferred,
            },
            Pos::Fixed(s) => Ty::Scalar(*s),
            Pos::FixedVec(s, n) => Ty::Vector(*s, *n),
            Pos::Vec3OfT => scalar
                .scalar()
                .map(|s| Ty::Vector(s, 3))
                .unwrap_or(Ty::Deferred),
            Pos::XformOfT => scalar.scalar().map(Ty::Transform).unwrap_or(Ty::Deferred),
            Pos::SVecOfT => scalar
                .scalar()
                .map(Ty::SpatialVector)
                .unwrap_or(Ty::Deferred),
            Pos::SMatOfT => scalar
                .scalar()
                .map(Ty::SpatialMatrix)
                .unwrap_or(Ty::Deferred),
            Pos::TransposeOfT => match t.mat_shape() {
                Some((s, r, c)) => Ty::mat_of(s, c, r).unwrap_or(Ty::Deferred),
                None => Ty::Deferred,
            },
            // The argument's own type (checked below); the result from both arguments (below).
            Pos::AnyVecOfT | Pos::OuterOfT => Ty::Deferred,
            Pos::Mat4OfT => scalar
                .scalar()
                .map(|s| Ty::Matrix(s, 4))
                .unwrap_or(Ty::Deferred),
            Pos::Object(k) => Ty::Object(*k),
            Pos::VolumeOfT => crate::types::VolumeElem::of(&t)
                .map(|e| Ty::Object(ObjectKind::Volume(e)))
                .unwrap_or(Ty::Deferred),
            // Any element: the argument's own type (checked above).
            Pos::AnyVolume => Ty::Deferred,
            Pos::BsrOfT => crate::types::BlockElem::of(&t)
                .map(|b| Ty::Object(ObjectKind::Bsr(b)))
                .unwrap_or(Ty::Deferred),
            Pos::AnyBsr => Ty::Deferred,
            Pos::VolumeGradOfT => match &t {
                Ty::Scalar(s) => Ty::Vector(*s, 3),
                Ty::Vector(s, 3) => Ty::Matrix(*s, 3),
                _ => Ty::Deferred,
            },
            Pos::Unit => Ty::Unit,
            // Tile rows are typed by `front::lower::tiles`, never here.
            Pos::Tile | Pos::TileShape | Pos::Offsets | Pos::TileFn => Ty::Deferred,
            // Results only (below).
            Pos::Tuple(_) => Ty::Deferred,
        };
        let mut params = Vec::new();
        for (i, (pos, arg)) in self.params.iter().zip(args).enumerate() {
            let w = want(pos);
            match arg {
                ArgTy::Known(ty) if ty.is_deferred() => {}
                ArgTy::Known(ty) if *pos == Pos::Index => {
                    let ok = (array_ndim == 1 && ty.is_int_scalar())
                        || matches!(ty, Ty::TidTuple(n) if *n == array_ndim);
                    if !ok {
                        return Err(format!(
                            "argument {} of `{}` must be an index, found `{ty}`",
                            i + 1,
                            self.name
                        ));
                    }
                }
                ArgTy::Known(Ty::Array(e, _)) if *pos == Pos::ArrayOfT && **e != t => {
                    return Err(format!(
                        "`{}`: array of `{e}` where `{t}` was expected",
                        self.name
                    ));
                }
                ArgTy::Known(_) if *pos == Pos::ArrayOfT => {}
                ArgTy::Known(_) if matches!(pos, Pos::AnyVolume | Pos::AnyBsr) => {}
                ArgTy::Known(ty)
                    if *pos == Pos::AnyVecOfT
                        && ty.vec_shape().map(|(s, _)| Ty::Scalar(s)) != Some(scalar.clone()) =>
                {
                    return Err(format!(
                        "argument {} of `{}` must be a float vector of `{scalar}` (any \
                         length), found `{ty}`",
                        i + 1,
                        self.name
                    ))
                }
                ArgTy::Known(_) if *pos == Pos::AnyVecOfT => {}
                ArgTy::Literal { .. } if *pos == Pos::AnyVecOfT => {
                    return Err(format!(
                        "argument {} of `{}` must be a vector, found a literal",
                        i + 1,
                        self.name
                    ))
                }
                ArgTy::Known(ty) if *ty != w => {
                    return Err(format!(
                        "mismatched types in `{}`: argument {} is `{ty}`, expected `{w}`",
                        self.name,
                        i + 1
                    ))
                }
                ArgTy::Literal { float: true }
                    if !matches!(w, Ty::Scalar(s) if s.is_float()) && !w.is_deferred() =>
                {
                    return Err(format!(
                        "argument {} of `{}` is a float literal where `{w}` is expected",
                        i + 1,
                        self.name
                    ))
                }
                _ => {}
            }
            let ty = match (arg, pos) {
                (ArgTy::Known(ty), Pos::Index | Pos::AnyVolume | Pos::AnyBsr | Pos::AnyVecOfT) => {
                    ty.clone()
                }
                _ => w,
            };
            params.push(ty);
        }
        let ret = match self.ret {
            Pos::Tuple(ps) => Ty::Tuple(ps.iter().map(&want).collect()),
            // `outer(a, b)`: shape `(len a, len b)`.
            Pos::OuterOfT => {
                let b = self
                    .params
                    .iter()
                    .zip(&params)
                    .find(|(p, _)| **p == Pos::AnyVecOfT);
                match (t.vec_shape(), b.and_then(|(_, b)| b.vec_shape())) {
                    (Some((s, n)), Some((_, m))) => Ty::mat_of(s, n, m).unwrap_or(Ty::Deferred),
                    _ => Ty::Deferred,
                }
            }
            p => want(&p),
        };
        Ok(Resolved { params, ret })
    }
}
