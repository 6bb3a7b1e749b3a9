//! What a function's code needs of its target beyond the core language, by the names of
//! warp-core's capability table (`warp_core::capability`, which states per target whether and
//! from which CUDA architecture each one runs: the macros know only what the code uses).
//!
//! Read off the lowered code: the atomics it makes, by operation and element type, and the
//! gradient accumulation its adjoint makes (an atomic add into the gradient of each float
//! array or volume parameter). A user struct's fields are not visible to the macro, so an
//! adjoint's accumulation into the f64 fields of an array of structs is not listed; that
//! capability is emulated where it is not native, never refused.

use crate::ir::*;
use crate::types::{ObjectKind, Scalar, Ty, VolumeElem};
use proc_macro2::TokenStream;
use quote::{format_ident, quote};

/// A capability of warp-core's table that generated code can need; the variants are named as
/// there (the generated `requires` lists name them, so a variant missing there fails to
/// compile).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Capability {
    /// `atomic_add`/`atomic_sub` on f64 (and f64 vector components); gradient accumulation
    /// into f64 arrays and volumes.
    AtomicAddF64,
    /// Any atomic on f16 or bf16 elements (both a 16-bit compare-and-swap on CUDA); gradient
    /// accumulation into f16 and bf16 arrays.
    AtomicF16,
    /// `atomic_min/max/and/or/xor` on 64-bit integer elements.
    AtomicMinMaxBits64,
}

impl Capability {
    /// The path of warp-core's variant, as generated code names it.
    pub fn tokens(self) -> TokenStream {
        let v = format_ident!("{}", format!("{self:?}"));
        let wp = crate::paths::private();
        quote!(#wp::Capability::#v)
    }
}

/// The capabilities `f`'s code and its adjoint's need, each once, sorted.
pub fn required_capabilities(f: &Function) -> Vec<Capability> {
    let mut out = Vec::new();
    walk_stmts(&f.body, &mut |s| {
        let StmtKind::Assign {
            op: Op::Builtin { builtin, args },
            ..
        } = &s.kind
        else {
            return;
        };
        if !builtin.is_atomic() {
            return;
        }
        let Ty::Array(elem, _) = f.ty(args[0]) else {
            return;
        };
        let scalar = elem.scalar();
        let needs = match (builtin.name, scalar) {
            (_, Some(Scalar::F16 | Scalar::BF16)) => Some(Capability::AtomicF16),
            ("atomic_add" | "atomic_sub", Some(Scalar::F64)) => Some(Capability::AtomicAddF64),
            (
                "atomic_min" | "atomic_max" | "atomic_and" | "atomic_or" | "atomic_xor",
                Some(Scalar::I64 | Scalar::U64 | Scalar::Isize | Scalar::Usize),
            ) => Some(Capability::AtomicMinMaxBits64),
            _ => None,
        };
        out.extend(needs);
    });
    // The adjoint adds each gradient contribution into the parameter's gradient atomically.
    for p in &f.params {
        let needs = match &p.ty {
            Ty::Array(elem, _) => match elem.scalar() {
                Some(Scalar::F64) => Some(Capability::AtomicAddF64),
                Some(Scalar::F16 | Scalar::BF16) => Some(Capability::AtomicF16),
                _ => None,
            },
            Ty::Object(ObjectKind::Volume(VolumeElem::F64 | VolumeElem::DVec3)) => {
                Some(Capability::AtomicAddF64)
            }
            // `bsr_add_block` and `bsr_block`'s adjoint add f64 blocks atomically.
            Ty::Object(ObjectKind::Bsr(b)) if b.scalar == Scalar::F64 => {
                Some(Capability::AtomicAddF64)
            }
            _ => None,
        };
        out.extend(needs);
    }
    out.sort();
    out.dedup();
    out
}
