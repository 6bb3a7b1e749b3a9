//! The tiled GEMM kernels of `examples/tile_matmul.rs`, shared with the GPU benchmark's tile
//! GEMM section (benches/gpu.rs includes this file), so that both measure the same kernels.

// Each includer uses its own subset.
#![allow(dead_code)]
// The kernel language has no `div_ceil` (the book's GEMM spells it `(k + BK - 1) / BK`), and
// clippy sees that spelling in the kernels' CPU code (any other spelling too).
#![allow(clippy::manual_div_ceil)]

use warp_lang as wp;
use wp::prelude::*;

/// The tile of C a block owns (rows, columns), and the k-step of its loop.
pub const BM: usize = 64;
pub const BN: usize = 64;
pub const BK: usize = 16;
/// The k-step of the f64 kernel: its tiles are twice as large, and 64 x 64 + 2 (64 x 16) f64
/// (48 KiB) would leave no room under the 48 KiB of static shared memory a CUDA block gets.
pub const BK64: usize = 8;

/// C = A B, one `BM x BN` tile of C per block.
#[wp::kernel]
pub fn gemm_tiled_f32(a: Array<f32, 2>, b: Array<f32, 2>, c: Array<f32, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f32, BM, BN>();
    // The k-steps, the last one ragged (its loads read zeros past the edge).
    let k_tiles = (a.shape()[1] + BK - 1) / BK;
    for k in 0..k_tiles {
        let ta = tile_load::<BM, BK>(a, ((i * BM) as i32, (k * BK) as i32));
        let tb = tile_load::<BK, BN>(b, ((k * BK) as i32, (j * BN) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * BM) as i32, (j * BN) as i32));
}

/// `gemm_tiled_f32` in f64 (k-steps of `BK64`).
#[wp::kernel]
pub fn gemm_tiled_f64(a: Array<f64, 2>, b: Array<f64, 2>, c: Array<f64, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f64, BM, BN>();
    // The k-steps, the last one ragged (its loads read zeros past the edge).
    let k_tiles = (a.shape()[1] + BK64 - 1) / BK64;
    for k in 0..k_tiles {
        let ta = tile_load::<BM, BK64>(a, ((i * BM) as i32, (k * BK64) as i32));
        let tb = tile_load::<BK64, BN>(b, ((k * BK64) as i32, (j * BN) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * BM) as i32, (j * BN) as i32));
}

/// The same product as a plain kernel: one thread per entry of C, a dot product over k.
#[wp::kernel]
pub fn gemm_plain<T: Float>(a: Array<T, 2>, b: Array<T, 2>, c: Array<T, 2>) {
    let (i, j) = tid();
    let mut acc: T = 0.0;
    for p in 0..a.shape()[1] {
        acc += a[(i, p)] * b[(p, j)];
    }
    c[(i, j)] = acc;
}

/// The fp16 kernel's tiles: f16 A and B tiles (tensor-core operands), an f32 accumulator.
/// Larger than the f32 kernel's. On CUDA (sm_80+) the k-loop below is pipelined: the
/// accumulator stays in registers for the whole loop, and the loads are issued with cp.async
/// ahead into stages of 128 x 64 + 64 x 256 f16 (48 KiB): two in the accumulator's slot, one in
/// the operands' slots, and where the GPU has the shared memory a fourth that the runtime adds
/// (227 KiB a block on Hopper: 224 KiB in all, one block an SM either way). On Hopper each of
/// the two warpgroups of a 256-thread block multiplies a 64 x 256 half with `wgmma`; elsewhere
/// each of 8 warps its warp tiles with `mma.sync`. Shared memory without the extra stage:
/// 128 x 64 + 64 x 256 f16 and 128 x 256 f32 = 176 KiB, more than an A100's 163 KiB a block
/// (there, take `BN16 = 128`: 96 KiB, two blocks an SM). Measured on an H200 at 4096^3:
/// 0.34 ms, against 0.40 ms with 128 x 128 tiles (three stages, two blocks an SM).
pub const BM16: usize = 128;
pub const BN16: usize = 256;
pub const BK16: usize = 64;

/// C = A B of f16 inputs with f32 accumulation (tensor cores on sm_80+), one `BM16 x BN16`
/// tile of C per block.
#[wp::kernel]
pub fn gemm_tiled_f16(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f32, BM16, BN16>();
    // The k-steps, the last one ragged (its loads read zeros past the edge).
    let k_tiles = (a.shape()[1] + BK16 - 1) / BK16;
    for k in 0..k_tiles {
        let ta = tile_load::<BM16, BK16>(a, ((i * BM16) as i32, (k * BK16) as i32));
        let tb = tile_load::<BK16, BN16>(b, ((k * BK16) as i32, (j * BN16) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * BM16) as i32, (j * BN16) as i32));
}
