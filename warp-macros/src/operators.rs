//! The language's operators and their type rule. A leaf module (it names only the types): the
//! IR's statements and the builtin table (whose `mod` row is emitted as `%`) both name them,
//! and the front end (lowering user code) and the middle end (writing tangent operations) both
//! type operations with [`binary_result`], and none should import another for it.

use crate::types::{Ty, BOOL};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnOp {
    Neg,
    Not,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Rem,
    BitAnd,
    BitOr,
    BitXor,
    Shl,
    Shr,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

impl BinOp {
    pub fn is_comparison(self) -> bool {
        matches!(
            self,
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
        )
    }
    /// The name of the operator's adjoint in both adjoint libraries (`adj_add`, ..), for the
    /// arithmetic operators (the others have no gradient).
    pub fn adjoint_fn(self) -> Option<&'static str> {
        Some(match self {
            BinOp::Add => "adj_add",
            BinOp::Sub => "adj_sub",
            BinOp::Mul => "adj_mul",
            BinOp::Div => "adj_div",
            BinOp::Rem => "adj_rem",
            _ => return None,
        })
    }

    pub fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Rem => "%",
            BinOp::BitAnd => "&",
            BinOp::BitOr => "|",
            BinOp::BitXor => "^",
            BinOp::Shl => "<<",
            BinOp::Shr => ">>",
            BinOp::Eq => "==",
            BinOp::Ne => "!=",
            BinOp::Lt => "<",
            BinOp::Le => "<=",
            BinOp::Gt => ">",
            BinOp::Ge => ">=",
        }
    }
}

/// The result type of `l op r`, or why there is none.
pub fn binary_result(op: BinOp, l: &Ty, r: &Ty) -> Result<Ty, String> {
    use crate::types::Scalar;
    use Ty::*;
    let bad = || Err(format!("cannot apply `{}` to `{l}` and `{r}`", op.symbol()));
    if l.is_deferred() || r.is_deferred() {
        return Ok(if op.is_comparison() { BOOL } else { Deferred });
    }
    if let (Tile(..), _) | (_, Tile(..)) = (l, r) {
        return tile_binary(op, l, r);
    }
    if let (MatRC(..), _) | (_, MatRC(..)) = (l, r) {
        return nonsquare_binary(op, l, r);
    }
    match op {
        BinOp::Eq | BinOp::Ne => {
            if l == r
                && matches!(
                    l,
                    Scalar(_)
                        | Vector(..)
                        | Quat(_)
                        | Matrix(..)
                        | Transform(_)
                        | SpatialVector(_)
                        | SpatialMatrix(_)
                        | MatRC(..)
                )
            {
                Ok(BOOL)
            } else {
                bad()
            }
        }
        BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => match (l, r) {
            (Scalar(a), Scalar(b)) if a == b => Ok(BOOL),
            _ => bad(),
        },
        // Integer vectors too (glam's operators), lane by lane, a scalar splatted.
        BinOp::BitAnd | BinOp::BitOr | BinOp::BitXor => match (l, r) {
            (Scalar(a), Scalar(b)) if a == b && !a.is_float() => Ok(l.clone()),
            (Vector(a, n), Vector(b, m)) if a == b && n == m && !a.is_float() => Ok(l.clone()),
            (Vector(a, _), Scalar(b)) if a == b && !a.is_float() => Ok(l.clone()),
            (Scalar(a), Vector(b, _)) if a == b && !a.is_float() => Ok(r.clone()),
            _ => bad(),
        },
        // A vector shifts every lane by one scalar amount.
        BinOp::Shl | BinOp::Shr => match (l, r) {
            (Scalar(a) | Vector(a, _), Scalar(b)) if a.is_int() && b.is_int() => Ok(l.clone()),
            _ => bad(),
        },
        BinOp::Add | BinOp::Sub | BinOp::Mul | BinOp::Div | BinOp::Rem => match (l, r) {
            (Scalar(a), Scalar(b)) if a == b && *a != Scalar::Bool => Ok(l.clone()),
            (Vector(a, n), Vector(b, m)) if a == b && n == m => Ok(l.clone()),
            (Vector(a, _), Scalar(b)) if a == b => Ok(l.clone()),
            (Scalar(a), Vector(b, _)) if a == b => Ok(r.clone()),
            (Matrix(a, n), Matrix(b, m))
                if a == b && n == m && matches!(op, BinOp::Add | BinOp::Sub | BinOp::Mul) =>
            {
                Ok(l.clone())
            }
            (Matrix(a, n), Vector(b, m)) if a == b && n == m && op == BinOp::Mul => Ok(r.clone()),
            (Matrix(a, _), Scalar(b)) if a == b && matches!(op, BinOp::Mul | BinOp::Div) => {
                Ok(l.clone())
            }
            (Scalar(a), Matrix(b, _)) if a == b && op == BinOp::Mul => Ok(r.clone()),
            (Quat(a), Quat(b)) if a == b && matches!(op, BinOp::Add | BinOp::Sub | BinOp::Mul) => {
                Ok(l.clone())
            }
            (Quat(a), Vector(b, 3)) if a == b && op == BinOp::Mul => Ok(r.clone()),
            (Quat(a), Scalar(b)) if a == b && matches!(op, BinOp::Mul | BinOp::Div) => {
                Ok(l.clone())
            }
            // Transforms: `*` composes (Warp's transform_multiply); `+`, `-` and `*` by a
            // scalar are lane by lane (Warp's add, sub, mul overloads).
            (Transform(a), Transform(b))
                if a == b && matches!(op, BinOp::Add | BinOp::Sub | BinOp::Mul) =>
            {
                Ok(l.clone())
            }
            (Transform(a), Scalar(b)) if a == b && op == BinOp::Mul => Ok(l.clone()),
            (Scalar(a), Transform(b)) if a == b && op == BinOp::Mul => Ok(r.clone()),
            // Spatial vectors and matrices (Warp's vec_t<6> and mat_t<6, 6>): `+`, `-` of two
            // of one type, `*` and `/` by their scalar, the matrix's products.
            (SpatialVector(a), SpatialVector(b)) | (SpatialMatrix(a), SpatialMatrix(b))
                if a == b && matches!(op, BinOp::Add | BinOp::Sub) =>
            {
                Ok(l.clone())
            }
            (SpatialMatrix(a), SpatialMatrix(b)) if a == b && op == BinOp::Mul => Ok(l.clone()),
            (SpatialMatrix(a), SpatialVector(b)) if a == b && op == BinOp::Mul => Ok(r.clone()),
            (SpatialVector(a) | SpatialMatrix(a), Scalar(b))
                if a == b && matches!(op, BinOp::Mul | BinOp::Div) =>
            {
                Ok(l.clone())
            }
            (Scalar(a), SpatialVector(b) | SpatialMatrix(b)) if a == b && op == BinOp::Mul => {
                Ok(r.clone())
            }
            _ => bad(),
        },
    }
}

/// Operators with a non-square matrix (Warp's `mat_t<R, C>`): `==`, `!=`, `+`, `-` of two of
/// one shape, `*` and `/` by their scalar (a scalar on the left with `*`), `m * x` with `x`
/// the vector of the column count (the vector of the row count), and `a * b` of matrices
/// whose inner dimensions agree, square glam and spatial ones included (the matrix of the
/// outer shape, [`Ty::mat_of`]: `Mat23 * Mat32` is a `Mat2`).
fn nonsquare_binary(op: BinOp, l: &Ty, r: &Ty) -> Result<Ty, String> {
    use Ty::*;
    let bad = |why: String| {
        Err(format!(
            "cannot apply `{}` to `{l}` and `{r}`{why}",
            op.symbol()
        ))
    };
    match (op, l, r) {
        (BinOp::Eq | BinOp::Ne, _, _) if l == r => Ok(BOOL),
        (BinOp::Add | BinOp::Sub, _, _) if l == r => Ok(l.clone()),
        (BinOp::Mul | BinOp::Div, MatRC(a, ..), Scalar(b)) if a == b => Ok(l.clone()),
        (BinOp::Mul, Scalar(a), MatRC(b, ..)) if a == b => Ok(r.clone()),
        (BinOp::Mul, MatRC(s, rows, cols), v) if v.vec_shape().is_some() => match v.vec_shape() {
            Some((t, n)) if t == *s && n == *cols => {
                Ty::vec_of(*s, *rows).ok_or_else(|| "no vector type".into())
            }
            _ => bad(format!(
                ": `{l}` has {cols} columns, so it multiplies a vector of {cols} lanes of `{}`",
                s.name()
            )),
        },
        (BinOp::Mul, a, b) if a.mat_shape().is_some() && b.mat_shape().is_some() => {
            let ((s, ra, ca), (t, rb, cb)) = (a.mat_shape().unwrap(), b.mat_shape().unwrap());
            if s != t {
                return bad(String::new());
            }
            if ca != rb {
                return bad(format!(
                    ": the left matrix has {ca} columns and the right one {rb} rows"
                ));
            }
            Ty::mat_of(s, ra, cb).ok_or_else(|| "no matrix type".into())
        }
        _ => bad(String::new()),
    }
}

/// `+ - * /` on tiles (Warp's `tile_add`, ..): elementwise on two tiles of one element type
/// and shape, or a tile and a scalar of its element type (`s * t`, `t / s`; a scalar on the
/// left with `+ - *`). Shapes the macro cannot compare (a const against a literal) are left to
/// rustc, which sees the dims as const generics.
fn tile_binary(op: BinOp, l: &Ty, r: &Ty) -> Result<Ty, String> {
    use Ty::*;
    let bad = || Err(format!("cannot apply `{}` to `{l}` and `{r}`", op.symbol()));
    let arith = matches!(op, BinOp::Add | BinOp::Sub | BinOp::Mul | BinOp::Div);
    if !arith {
        return bad();
    }
    match (l, r) {
        // Tiles of 2-vectors add and subtract; their other operations would be componentwise,
        // which for complex values is not what `*` and `/` mean.
        (Tile(a, _), Tile(..)) if a.is_vec2_float() && !matches!(op, BinOp::Add | BinOp::Sub) => {
            Err(format!(
                "cannot apply `{}` to tiles of `{a}`: tiles of vectors add, subtract and scale by a scalar",
                op.symbol()
            ))
        }
        (Tile(a, da), Tile(b, db)) if a == b => {
            let differ =
                da.len() != db.len() || da.iter().zip(db).any(|(x, y)| x.same(y) == Some(false));
            if differ {
                Err(format!(
                    "`{}` on tiles of different shapes: `{l}` and `{r}`",
                    op.symbol()
                ))
            } else {
                Ok(l.clone())
            }
        }
        (Tile(a, _), s @ Scalar(_)) if **a == *s => Ok(l.clone()),
        (s @ Scalar(_), Tile(b, _)) if **b == *s && op != BinOp::Div => Ok(r.clone()),
        // Tiles of 2-vectors (complex values): scaled by their scalar, on either side.
        (Tile(a, _), Scalar(s)) | (Scalar(s), Tile(a, _))
            if op == BinOp::Mul && matches!(**a, Vector(v, 2) if v == *s) =>
        {
            Ok(if l.is_tile() { l.clone() } else { r.clone() })
        }
        _ => bad(),
    }
}
