//! The middle end: transforms from the lowered IR to what the back ends print.
//!
//! - `adjoint_prep`: `break`, `continue` and early `return` become flags (the adjoint's input);
//! - `adjoint`: reverse mode as one pass, from a lowered function to its *adjoint IR*: the
//!   forward replay, the adjoint stack's pushes and pops, the reverse sweep, and every decision
//!   of how gradients flow. `back/rust_adjoint.rs` and `back/cuda_adjoint.rs` only print it,
//!   so the CPU and CUDA gradients come from one scheme;
//! - `lanes`: a tiled kernel's block as one CPU task: which statements run once per block and
//!   which in loops over its lanes, and where each variable lives;
//! - `tangent`: forward mode as one pass, from a lowered kernel to its *tangent kernel*, an
//!   ordinary kernel IR the back ends emit and the adjoint pass differentiates again.
//!
//! The middle end takes the IR and the facts it needs from the leaf modules (`ir`, `types`,
//! `operators` with the operators' type rule, `builtins` with each builtin's signature and
//! derivative rules), and nothing from the lowering that produces its input: a type rule both
//! need lives in a leaf. (Its tests lower their kernels through `crate::test_support`.)

pub mod adjoint;
pub mod adjoint_prep;
pub mod lanes;
pub mod tangent;
