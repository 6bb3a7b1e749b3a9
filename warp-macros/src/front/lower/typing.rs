//! Typing: the check that a condition is a `bool`, and the literal rule with the lowering of
//! literals. (The operators' type rule, [`binary_result`](crate::operators::binary_result), is
//! the operators' own: the tangent pass types the operations it writes with it too.)
//!
//! # The literal rule (shared by both backends)
//! An unsuffixed numeric literal takes its type from its context: the other operand of a
//! binary operator (its scalar, for `2.0 * v`), the parameter it is passed to, the annotated
//! `let` or the place it is assigned to, or the function's return type. An integer literal in
//! a float context becomes a float of that type (`2 * x` is `2.0 * x`). With no context, an
//! integer literal is `i32` and a float literal is `f32` (as in Warp; Rust would pick `f64`).
//! The Rust emitter writes every literal with its suffix, and the CUDA emitter with its C++
//! type, so a literal can never silently become a double on one backend only. Where the
//! context is a value whose type the macro cannot see (a user func's result), the literal is
//! left for the target compiler to type from that same operand.

use super::*;

/// Is `e` an unsuffixed numeric literal (possibly negated or parenthesised)? `Some(is_float)`.
pub(super) fn flex_literal(e: &Expr) -> Option<bool> {
    match e {
        Expr::Lit(l) => match &l.lit {
            syn::Lit::Int(i) if i.suffix().is_empty() => Some(false),
            syn::Lit::Float(f) if f.suffix().is_empty() => Some(true),
            _ => None,
        },
        Expr::Unary(u) if matches!(u.op, syn::UnOp::Neg(_)) => flex_literal(&u.expr),
        Expr::Paren(p) => flex_literal(&p.expr),
        Expr::Group(g) => flex_literal(&g.expr),
        _ => None,
    }
}

/// The value of an unsuffixed numeric literal (possibly negated or parenthesised).
pub(super) fn flex_value(e: &Expr) -> Option<Lit> {
    match e {
        Expr::Lit(l) => match &l.lit {
            syn::Lit::Int(i) if i.suffix().is_empty() => {
                i.base10_parse::<i128>().ok().map(Lit::Int)
            }
            // Not a value past f64's range (`1e309`): `literal` reports that one.
            syn::Lit::Float(f) if f.suffix().is_empty() => f
                .base10_parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .map(Lit::Float),
            _ => None,
        },
        Expr::Unary(u) if matches!(u.op, syn::UnOp::Neg(_)) => match flex_value(&u.expr)? {
            Lit::Int(v) => Some(Lit::Int(-v)),
            Lit::Float(v) => Some(Lit::Float(-v)),
            b => Some(b),
        },
        Expr::Paren(p) => flex_value(&p.expr),
        Expr::Group(g) => flex_value(&g.expr),
        // `else { 0.5 }`
        Expr::Block(b) if b.label.is_none() => match b.block.stmts.as_slice() {
            [syn::Stmt::Expr(e, None)] => flex_value(e),
            _ => None,
        },
        _ => None,
    }
}

/// The type a literal should take next to an operand of type `other` under `op`.
fn literal_hint(other: &Ty, op: BinOp) -> Option<Ty> {
    match op {
        BinOp::Shl | BinOp::Shr => None,
        _ => match other {
            Ty::Scalar(_) => Some(other.clone()),
            Ty::Vector(s, _)
            | Ty::Matrix(s, _)
            | Ty::Quat(s)
            | Ty::Transform(s)
            | Ty::SpatialVector(s)
            | Ty::SpatialMatrix(s)
            | Ty::MatRC(s, ..) => Some(Ty::Scalar(*s)),
            // A tile of vectors is scaled by their scalar.
            Ty::Tile(e, _) => literal_hint(e, op),
            Ty::Deferred => Some(Ty::Deferred),
            _ => None,
        },
    }
}

/// Whether the literal value `v` stays finite once rounded to the float type `s`. As Rust's
/// `overflowing_literals` (deny by default) rejects `1e39_f32`, so does the kernel language:
/// the value would otherwise become an infinity on one backend and an error on the other.
/// `v` as an f64 rounded to odd (truncated, its last bit set when that dropped anything):
/// rounding the result once more to a float of at most 51 significant bits (f32, f16, bf16)
/// rounds `v` once, where `v as f64` would round twice for integers past 2^53 (2^60 + 2^52 + 1
/// becomes the bf16 tie 2^60 + 2^52, which rounds to even, not up).
fn int_to_f64_odd(v: i128) -> f64 {
    let m = v.unsigned_abs();
    let bits = 128 - m.leading_zeros();
    if bits <= 53 {
        return v as f64;
    }
    let shift = bits - 53;
    let mut top = m >> shift;
    if m & ((1u128 << shift) - 1) != 0 {
        top |= 1;
    }
    // `top` has 53 bits (exact in f64), and the power of two at most 2^74.
    let r = top as f64 * 2f64.powi(shift as i32);
    if v < 0 {
        -r
    } else {
        r
    }
}

pub(super) fn float_literal_fits(v: f64, s: Scalar) -> bool {
    match s {
        // The largest f16 is 65504; from 65520 on, rounding to nearest gives infinity.
        Scalar::F16 => v.abs() < 65520.0,
        // The largest bf16 is (2 - 2^-7) 2^127; from the midpoint to 2^128 on, infinity.
        Scalar::BF16 => v.abs() < (2.0 - 2f64.powi(-8)) * 2f64.powi(127),
        Scalar::F32 => (v as f32).is_finite(),
        _ => v.is_finite(),
    }
}

/// The error for a literal whose value does not fit its float type.
fn float_out_of_range(span: Span, s: Scalar) -> syn::Error {
    syn::Error::new(
        span,
        format!(
            "literal out of range for `{0}`: it rounds to infinity (use `{0}::INFINITY` for an \
             infinity, `{0}::MAX` for the largest value)",
            s.name()
        ),
    )
}

pub(super) fn int_range(s: Scalar) -> (i128, i128) {
    match s {
        Scalar::I8 => (i8::MIN.into(), i8::MAX.into()),
        Scalar::I16 => (i16::MIN.into(), i16::MAX.into()),
        Scalar::I32 => (i32::MIN.into(), i32::MAX.into()),
        Scalar::I64 | Scalar::Isize => (i64::MIN.into(), i64::MAX.into()),
        Scalar::U8 => (0, u8::MAX.into()),
        Scalar::U16 => (0, u16::MAX.into()),
        Scalar::U32 => (0, u32::MAX.into()),
        _ => (0, u64::MAX.into()),
    }
}

impl Lowerer {
    pub(super) fn expect_bool(&self, v: VarId, span: Span) -> R<()> {
        let t = self.ty(v);
        if t.is_deferred() || t == BOOL {
            Ok(())
        } else {
            err(span, format!("expected `bool`, found `{t}`"))
        }
    }

    /// Lowers two operands, typing an unsuffixed literal on either side from the other.
    pub(super) fn operand_pair(
        &mut self,
        l: &Expr,
        r: &Expr,
        want: Option<&Ty>,
        op: BinOp,
    ) -> R<(VarId, VarId)> {
        let shift = matches!(op, BinOp::Shl | BinOp::Shr);
        match (flex_literal(l).is_some(), flex_literal(r).is_some()) {
            (true, false) => {
                // Literals have no side effects, so lowering the right side first is safe.
                let rv = self.expr(r, None)?;
                let lv = if shift {
                    self.expr(l, want)?
                } else {
                    self.literal_next_to(l, rv, op)?
                };
                Ok((lv, rv))
            }
            (false, true) => {
                let lv = self.expr(l, want)?;
                let rv = if shift {
                    self.expr(r, None)?
                } else {
                    self.literal_next_to(r, lv, op)?
                };
                Ok((lv, rv))
            }
            (true, true) => {
                let w = want.and_then(|w| literal_hint(w, op));
                let lv = self.expr(l, w.as_ref())?;
                let rv = if shift {
                    self.expr(r, None)?
                } else {
                    self.expr(r, w.as_ref())?
                };
                Ok((lv, rv))
            }
            (false, false) => Ok((self.expr(l, None)?, self.expr(r, None)?)),
        }
    }

    /// An unsuffixed literal `lit` that meets `other` under `op`: typed from `other`'s type, or,
    /// when the macro cannot see that type, made "a literal of the type of `other`".
    pub(super) fn literal_next_to(&mut self, lit: &Expr, other: VarId, op: BinOp) -> R<VarId> {
        if self.ty(other).is_deferred() {
            if let Some(value) = flex_value(lit) {
                return Ok(self.def(
                    Op::LitLike(value, other, Like::Value),
                    Ty::Deferred,
                    lit.span(),
                ));
            }
        }
        let hint = literal_hint(&self.ty(other), op);
        self.expr(lit, hint.as_ref())
    }

    pub(super) fn literal(
        &mut self,
        lit: &syn::Lit,
        neg: bool,
        want: Option<&Ty>,
        span: Span,
    ) -> R<VarId> {
        let want_scalar = want.map(|w| match w {
            Ty::Vector(s, _)
            | Ty::Matrix(s, _)
            | Ty::Quat(s)
            | Ty::Transform(s)
            | Ty::SpatialVector(s)
            | Ty::SpatialMatrix(s)
            | Ty::MatRC(s, ..) => Ty::Scalar(*s),
            t => t.clone(),
        });
        match lit {
            syn::Lit::Bool(b) => {
                if neg {
                    return err(span, "cannot negate a bool");
                }
                Ok(self.def(Op::Lit(Lit::Bool(b.value)), BOOL, span))
            }
            syn::Lit::Int(i) => {
                // Beyond i128 (a `u128` past `i128::MAX`) no type of the language holds it,
                // negated or not; a plain `as i128` would wrap it to a small value.
                let v = i
                    .base10_parse::<u128>()
                    .ok()
                    .and_then(|v| i128::try_from(v).ok())
                    .ok_or_else(|| syn::Error::new(span, "integer literal too large"))?;
                let v = if neg { -v } else { v };
                let float = |this: &mut Self, s: Scalar| {
                    // Rounded once to `s`: directly for f64, through f64 rounded to odd for
                    // the narrower floats (which the back ends round from the f64).
                    let x = if s == Scalar::F64 {
                        v as f64
                    } else {
                        int_to_f64_odd(v)
                    };
                    if !float_literal_fits(x, s) {
                        return Err(float_out_of_range(span, s));
                    }
                    Ok(this.def(Op::Lit(Lit::Float(x)), Ty::Scalar(s), span))
                };
                let ty = match i.suffix() {
                    "" => match want_scalar {
                        Some(Ty::Scalar(s)) if s.is_float() => return float(self, s),
                        Some(Ty::Scalar(s)) if s.is_int() => Ty::Scalar(s),
                        Some(Ty::Deferred) => Ty::Deferred,
                        _ => crate::types::I32,
                    },
                    suf => match Scalar::from_name(suf) {
                        Some(s) if s.is_float() => return float(self, s),
                        Some(s) if s.is_int() => Ty::Scalar(s),
                        _ => return err(span, format!("unknown literal suffix `{suf}`")),
                    },
                };
                if let Ty::Scalar(s) = ty {
                    let (lo, hi) = int_range(s);
                    if v < lo || v > hi {
                        return err(span, format!("literal out of range for `{}`", s.name()));
                    }
                }
                Ok(self.def(Op::Lit(Lit::Int(v)), ty, span))
            }
            syn::Lit::Float(f) => {
                let v: f64 = f
                    .base10_parse()
                    .map_err(|_| syn::Error::new(span, "bad float literal"))?;
                let v = if neg { -v } else { v };
                let ty = match f.suffix() {
                    "" => match want_scalar {
                        Some(Ty::Scalar(s)) if s.is_float() => Ty::Scalar(s),
                        Some(Ty::Scalar(s)) if s.is_int() => {
                            return err(
                                span,
                                format!("float literal where `{}` is expected", s.name()),
                            );
                        }
                        Some(Ty::Deferred) => Ty::Deferred,
                        _ => crate::types::F32,
                    },
                    "f32" => crate::types::F32,
                    "f64" => Ty::Scalar(Scalar::F64),
                    "f16" => Ty::Scalar(Scalar::F16),
                    "bf16" => Ty::Scalar(Scalar::BF16),
                    suf => return err(span, format!("unknown literal suffix `{suf}`")),
                };
                // A deferred type is some float the target compiler picks: f64 at least.
                let s = match &ty {
                    Ty::Scalar(s) => *s,
                    _ => Scalar::F64,
                };
                if !float_literal_fits(v, s) {
                    return Err(float_out_of_range(span, s));
                }
                Ok(self.def(Op::Lit(Lit::Float(v)), ty, span))
            }
            syn::Lit::Str(_) | syn::Lit::ByteStr(_) | syn::Lit::CStr(_) => err(
                span,
                "strings are not supported in kernels (except as print! formats)",
            ),
            _ => err(span, "this literal is not supported in kernels"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::int_to_f64_odd;
    use crate::types::bf16_bits;

    /// Integer literals past 2^53 round once to the narrower floats: through f64 rounded to
    /// odd, not to nearest (which makes ties that were not there).
    #[test]
    fn integer_literals_round_once() {
        let v: i128 = (1 << 60) + (1 << 52) + 1;
        // To nearest: the tie 2^60 + 2^52, even in bf16 (0x5D80); once: up (0x5D81).
        assert_eq!(bf16_bits(v as f64), 0x5D80);
        assert_eq!(bf16_bits(int_to_f64_odd(v)), 0x5D81);
        assert_eq!(bf16_bits(int_to_f64_odd(-v)), 0xDD81);
        // f32 alike: 2^60 + 2^36 + 1 is above the f32 tie 2^60 + 2^36.
        let w: i128 = (1 << 60) + (1 << 36) + 1;
        assert_eq!(int_to_f64_odd(w) as f32, 2f32.powi(60) + 2f32.powi(37));
        assert_eq!(w as f64 as f32, 2f32.powi(60));
        // Integers exact in f64 are unchanged.
        for v in [
            0i128,
            1,
            -7,
            (1 << 53) - 1,
            1 << 53,
            -(1 << 53),
            1 << 70,
            -(3 << 90),
        ] {
            assert_eq!(int_to_f64_odd(v), v as f64, "{v}");
        }
    }
}
