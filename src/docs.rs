//! Reference pages, rendered from the repository's markdown so that they ship with the crate
//! and its rustdoc.
//!
//! - [`language`]: the kernel language in brief (ARCHITECTURE.md, which also maps the code:
//!   the compiler, the runtime, the backends, their invariants).
//! - [`builtins`]: every builtin of NVIDIA Warp's kernel language and where it stands here,
//!   with the table of every builtin a kernel can call (signature, types, gradient).
//! - [`primitives`]: the parallel primitives (scan, reductions, radix sort, compaction).
//!
//! These modules hold no items: their documentation is the page.

#[doc = include_str!("../ARCHITECTURE.md")]
pub mod language {}

#[doc = include_str!("../docs/book/src/builtins.md")]
pub mod builtins {}

#[doc = include_str!("../docs/book/src/primitives.md")]
pub mod primitives {}
