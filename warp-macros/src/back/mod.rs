//! Back ends: code emitted from the IR. Each walks the same statements.

pub mod cuda;
pub mod cuda_adjoint;
pub mod cuda_tile;
pub mod cuda_tile_adjoint;
pub mod cuda_tile_pipe;
pub mod rust;
pub mod rust_adjoint;
pub mod rust_tile;
pub mod rust_tile_adjoint;
