//! Atomics (section "atomic").

use super::*;

/// The atomic read-modify-writes of an array element.
pub(super) const ROWS: &[Builtin] = rows! {
    "atomic_add": &[Atomic],      (ArrayOfT, Index, T) -> T, "atomic", Atomic,
        tangent(Tangent::Atomic);
    "atomic_sub": &[Atomic],      (ArrayOfT, Index, T) -> T, "atomic", Atomic,
        tangent(Tangent::Atomic);
    "atomic_min": &[Atomic],      (ArrayOfT, Index, T) -> T, "atomic", Atomic, no_tangent;
    "atomic_max": &[Atomic],      (ArrayOfT, Index, T) -> T, "atomic", Atomic, no_tangent;
    "atomic_cas": &[AtomicScalar], (ArrayOfT, Index, T, T) -> T, "atomic", AtomicNone, no_tangent;
    "atomic_exch": &[AtomicScalar], (ArrayOfT, Index, T) -> T, "atomic", AtomicNone, no_tangent;
    "atomic_and": &[AtomicInt],   (ArrayOfT, Index, T) -> T, "atomic", AtomicNone, no_tangent;
    "atomic_or":  &[AtomicInt],   (ArrayOfT, Index, T) -> T, "atomic", AtomicNone, no_tangent;
    "atomic_xor": &[AtomicInt],   (ArrayOfT, Index, T) -> T, "atomic", AtomicNone, no_tangent;
};
