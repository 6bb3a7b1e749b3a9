//! The CPU backend: kernels are Rust code built by cargo, run over the grid in chunks on the
//! rayon pool (`executor`); arrays live in host memory (`memory`). A CPU launch has finished
//! when `launch` returns, so there is nothing to wait for and no fault record to read.
//! `primitives`: scan, reductions, radix sort and compaction with rayon. Host objects' build
//! steps bring their own CPU code (`ObjectStep::run_cpu`, next to each object). `race`: the
//! write-race check of launches (`config::set_race_check`). `shared_grads`: when adjoint
//! launches running at once make gradient updates atomic. `capture`: graph capture, the
//! operations recorded and replayed in order. `deterministic`: the records and ordered
//! reduction of `#[kernel(deterministic)]` launches.

mod backend;
pub(crate) mod capture;
pub(crate) mod deterministic;
mod executor;
pub(crate) mod memory;
mod primitives;
mod race;
mod shared_grads;

pub(crate) use backend::Cpu;
