//! Tiles (section "tile"): block-cooperative values that a whole block of a `launch_tiled`
//! kernel holds together.
//!
//! A tile row's signature is for the reference only: tile calls are typed by their shapes in
//! `front::lower::tiles`, not by [`Builtin::resolve`], since a tile's type is its element and
//! its shape. Every row but `tile_extract` is cooperative (the validator's uniformity rule).
//! The CPU functions are in `warp_core::tile` and `warp_core::block`, the CUDA ones in
//! wp_tile.h. Backward: the rows that state `Adjoint` have one where
//! `middle::adjoint::tiles::TILE_ADJOINTS` lists them (warp-core's `tile::adjoint`,
//! wp_adjoint_tile.h); backward through the others is refused with the reason.

use super::*;

/// Tiles hold integer and float scalars.
const TILE_ELEM: &[Class] = &[Number];
/// The elements atomics exist for on both backends.
const TILE_ATOMIC: &[Class] = &[AtomicScalar];
/// `tile_sort`'s keys: Warp's 32- and 64-bit integers and floats (the atomics' set).
const TILE_SORT_KEY: &[Class] = &[AtomicScalar];
/// The matmul's elements: f16 and bf16 (tensor cores on sm_80+, f32 accumulation), f32, f64.
const TILE_MATMUL: &[Class] = &[Float];

/// The FFTs' elements: `Vec2`, `DVec2` (complex values; the class says float vectors).
const TILE_FFT: &[Class] = &[FloatVector];

/// Warp's tile builtins that this slice has.
pub(super) const ROWS: &[Builtin] = rows! {
    // Construction. The shape (Warp's `shape=`) and element (`dtype=`) are the turbofish's
    // (`tile_zeros::<f32, 16, 8>()`) or the `let` annotation's; `tile_arange(n)`,
    // `(start, stop)` or `(start, stop, step)` take integer literals, as Warp's constants.
    "tile_zeros": TILE_ELEM, (TileShape) -> Tile, "tile", Zero, cooperative;
    "tile_ones": TILE_ELEM, (TileShape) -> Tile, "tile", Zero, cooperative;
    "tile_arange": TILE_ELEM, (T, T, T) -> Tile, "tile", Zero, cooperative;
    // Loads and stores: out-of-bounds elements read zero and are not written; offsets are
    // signed, and negative coordinates are out of bounds too. Tiles hold `Vec2`/`DVec2` too
    // (complex values): loads, stores, `t[(i, j)]`, `tile_zeros`, `+ -`, `*` by a scalar.
    "tile_load": TILE_ELEM, (ArrayOfT, TileShape, Offsets) -> Tile, "tile", Adjoint,
        no_tangent, cooperative;
    "tile_store": TILE_ELEM, (ArrayOfT, Tile, Offsets) -> Unit, "tile", Adjoint,
        no_tangent, cooperative;
    // Per-thread values and back: `tile(x)` is `Tile<T, block_dim>`, `untile(t)` lane `l`'s
    // element `l`.
    "tile": TILE_ELEM, (T) -> Tile, "tile", Adjoint, no_tangent, cooperative, lanes;
    "untile": TILE_ELEM, (Tile) -> T, "tile", Adjoint, no_tangent, cooperative, lanes;
    // `t[i]`, `t[(i, j)]`: a read, not cooperative; an index outside the tile faults.
    "tile_extract": TILE_ELEM, (Tile, Index) -> T, "tile", Adjoint, no_tangent;
    // Elementwise: `tile_map(f, a)`, `tile_map(f, a, b)`, `tile_map(f, a, 2.0)` with a builtin
    // function (`tile_map(sin, a)`), an operator name or a user #[func], scalar constants
    // after the first tile broadcast; operators `+ - * /` and unary `-` on tiles are Warp's `tile_add`...
    "tile_map": TILE_ELEM, (TileFn, Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    // Shapes: `tile_transpose(t)` of a 2-D tile; `tile_broadcast::<M, N>(t)` (or Warp's
    // `tile_broadcast(t, (M, N))`, or the annotation's shape): numpy's rule, shapes aligned on
    // the right, each source dim 1 or the target's.
    "tile_transpose": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_broadcast": TILE_ELEM, (Tile, TileShape) -> Tile, "tile", Adjoint, no_tangent,
        cooperative;
    // `tile_atomic_add(a, t, offsets)`: the tile added into the array atomically (elements
    // outside skipped); the result is the tile of the old values.
    "tile_atomic_add": TILE_ATOMIC, (ArrayOfT, Tile, Offsets) -> Tile, "tile", Atomic,
        no_tangent, cooperative;
    // `tile_reduce(f, t)` with a binary builtin, `add`/`mul`.., or a user #[func], in the
    // reductions' order.
    "tile_reduce": TILE_ELEM, (TileFn, Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    // Scans of 1-D tiles, in an order both backends share (warp-core's `tile::scan`).
    // Backward: all four (`TILE_ADJOINTS`, warp-core's `tile::adjoint_linalg`).
    "tile_scan_inclusive": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_scan_exclusive": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_scan_max_inclusive": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent,
        cooperative;
    "tile_scan_min_inclusive": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent,
        cooperative;
    // `tile_sort(&mut keys, &mut values)`: 1-D tiles of one length, sorted by (key, index), NaN
    // keys last (warp-core's `tile::sort`). It lowers to three statements of this row: the
    // sorting permutation `p = tile_sort(keys)` (a hidden `Tile<i32, N>`), then
    // `values = tile_sort(values, p)` and `keys = tile_sort(keys, p)`, which apply it (CPU
    // `sort_perm`, `permute`; CUDA `wp::tile_sort`, `wp::tile_permute`). Backward: refused.
    "tile_sort": TILE_SORT_KEY, (Tile, Tile) -> Unit, "tile", Adjoint, no_tangent, cooperative;
    // Reductions to a `Tile<T, 1>` (`Tile<i32, 1>` for the arg-extrema), in the GPU's order.
    "tile_sum": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_min": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_max": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_argmin": TILE_ELEM, (Tile) -> Tile, "tile", Zero, cooperative;
    "tile_argmax": TILE_ELEM, (Tile) -> Tile, "tile", Zero, cooperative;
    // `c = tile_matmul(a, b)`; `tile_matmul(a, b, &mut c)` is `c += a b` (Warp's `out`
    // argument), each element an FMA chain in ascending k. f16 and bf16 operands accumulate
    // in f32: `c` is a `Tile<f32, ..>`, and the returning form's 16-bit result is rounded once;
    // on CUDA (sm_80+, whole warps, M % 16, N % 8, K % 16) the tensor cores sum each k-step of
    // 16 in their own order.
    "tile_matmul": TILE_MATMUL, (Tile, Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_matmul_acc": TILE_MATMUL, (Tile, Tile, Tile) -> Unit, "tile", Adjoint, no_tangent,
        cooperative, overload("tile_matmul", 3);
    // Dense linear algebra (Warp's default `fill_mode="lower"`), in the order warp-core's
    // `tile::linalg` documents, which the CUDA section `tile_linalg` shares bit for bit.
    // `tile_cholesky(a)`: `L` with `L Lᵀ = a` from the lower triangle of a square tile; every
    // element NaN when `a` is not positive definite. The solves take `L` (or `U`) square and a
    // right-hand side of as many rows, 1-D or 2-D (`K` columns), and return its shape:
    // `tile_cholesky_solve(L, y)` solves `L Lᵀ x = y`, `tile_lower_solve(L, y)` `L z = y`,
    // `tile_upper_solve(U, z)` `U x = z`. Backward: every one (`TILE_ADJOINTS`; warp-core's
    // `tile::adjoint_linalg` documents the rules), into the triangle the forward reads.
    "tile_cholesky": TILE_MATMUL, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_cholesky_solve": TILE_MATMUL, (Tile, Tile) -> Tile, "tile", Adjoint, no_tangent,
        cooperative;
    "tile_lower_solve": TILE_MATMUL, (Tile, Tile) -> Tile, "tile", Adjoint, no_tangent,
        cooperative;
    "tile_upper_solve": TILE_MATMUL, (Tile, Tile) -> Tile, "tile", Adjoint, no_tangent,
        cooperative;
    // FFTs: `tile_fft(&mut t)`, `tile_ifft(&mut t)` transform each row of a
    // `Tile<Vec2 | DVec2, M, N>` (complex values, `x` the real part) in place along the last
    // axis, `N` a power of two; the inverse is unnormalised, as Warp's (`ifft(fft(x)) = N x`).
    // A radix-2 FFT in the order warp-core's `tile::fft` documents, which the CUDA section
    // `tile_fft` shares bit for bit. Backward: each is the other's adjoint, on the tile's
    // adjoint in place (`middle::adjoint::tiles`).
    "tile_fft": TILE_FFT, (Tile) -> Unit, "tile", Adjoint, no_tangent, cooperative;
    "tile_ifft": TILE_FFT, (Tile) -> Unit, "tile", Adjoint, no_tangent, cooperative;
    // Conversions (warp-core's `tile::convert`). `tile_full::<f32, 16, 8>(x)` (shape and element
    // as `tile_zeros`'s, or the annotation's): every element `x`. `tile_astype::<U>(t)`: each
    // element `as U`. `tile_reshape::<M, N>(t)` (or the annotation's shape): the elements in
    // row-major order, the size unchanged; `tile_squeeze(t)` drops the dims that are the
    // literal 1 (all of them: a `Tile<T, 1>`). `tile_diag_add(a, d)`: a square tile with `d`
    // added to its diagonal. Backward through all of them (`TILE_ADJOINTS`): `tile_full`'s value
    // gets the sum of the seed (Warp drops it), `tile_astype` converts the seed back between
    // floats (no gradient to or from integers, as Warp), the others are copies.
    "tile_full": TILE_ELEM, (T, TileShape) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_astype": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_reshape": TILE_ELEM, (Tile, TileShape) -> Tile, "tile", Adjoint, no_tangent,
        cooperative;
    "tile_squeeze": TILE_ELEM, (Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    "tile_diag_add": TILE_ELEM, (Tile, Tile) -> Tile, "tile", Adjoint, no_tangent, cooperative;
    // Windows (warp-core's `tile::view`, wp_tile.h's `tile_view`/`tile_window`): a window must
    // lie inside the tile (a constant offset outside is an error at the call; a run-time one,
    // a `TileIndex` fault, nothing read or written). `tile_view::<M, N>(t, (i, j))` (or
    // Warp's `tile_view(t, (i, j), (M, N))`, or the annotation's shape): a copy of the window;
    // `tile_view(t, i)` of a 2-D tile, row `i`. `tile_assign(&mut d, s, (i, j))` writes `s`
    // into `d`'s window at the offset (zeros when absent); the `_inplace` forms combine it
    // with the window's elements (`+`, `-`; `& | ^` of integer tiles). Backward: a view adds
    // its adjoint into the window's; `tile_assign` hands the window's adjoint to `s` and
    // clears it; the adds pass it through (`-` to `s` for the sub).
    "tile_view": TILE_ELEM, (Tile, Offsets, TileShape) -> Tile, "tile", Adjoint, no_tangent,
        cooperative;
    "tile_assign": TILE_ELEM, (Tile, Tile, Offsets) -> Unit, "tile", Adjoint, no_tangent,
        cooperative;
    "tile_add_inplace": TILE_ELEM, (Tile, Tile, Offsets) -> Unit, "tile", Adjoint, no_tangent,
        cooperative;
    "tile_sub_inplace": TILE_ELEM, (Tile, Tile, Offsets) -> Unit, "tile", Adjoint, no_tangent,
        cooperative;
    "tile_bit_and_inplace": TILE_ELEM, (Tile, Tile, Offsets) -> Unit, "tile", Zero,
        cooperative;
    "tile_bit_or_inplace": TILE_ELEM, (Tile, Tile, Offsets) -> Unit, "tile", Zero,
        cooperative;
    "tile_bit_xor_inplace": TILE_ELEM, (Tile, Tile, Offsets) -> Unit, "tile", Zero,
        cooperative;
};
