//! Random numbers and Perlin noise (section "rand").

use super::*;

/// The generator, its draws and the noise functions.
pub(super) const ROWS: &[Builtin] = rows! {
    // Random numbers and Perlin noise (warp-core `builtins::{rand, noise}`, wp_rand.h). A draw
    // `randf(&mut s, ..)` is not a call of one row: `front::lower::rng` lowers it into the
    // row's pure function of the state before the draw and the write-back of the advanced
    // state (`draws(k)`: `rand_pcg` once per uniform draw; `next_state`: `poisson_state` for
    // `poisson`); `randi`/`randu` are the advanced state itself, in integer operators. The
    // internal rows are those pieces (`randf_range` is `randf` with a range) and overloads by
    // arity; user code cannot name them.
    "rand_init":  NO_T,           (I32) -> U32,             "rand", Zero;
    "rand_init_offset": NO_T, (I32, I32) -> U32, "rand", Zero, overload("rand_init", 2), internal;
    "rand_pcg":   NO_T,           (U32) -> U32,             "rand", Zero, internal;
    "randi":      NO_T,           (U32) -> I32,             "rand", Zero, draws(1), lowered;
    "randu":      NO_T,           (U32) -> U32,             "rand", Zero, draws(1), lowered;
    "randf":      NO_T,           (U32) -> F32,             "rand", Zero, draws(1);
    "randf_range": NO_T, (U32, F32, F32) -> F32, "rand", Zero, internal;
    "randn":      NO_T,           (U32) -> F32,             "rand", Zero, draws(2);
    "sample_triangle": NO_T, (U32) -> VEC2, "rand", Zero, draws(2);
    "sample_unit_ring": NO_T, (U32) -> VEC2, "rand", Zero, draws(1);
    "sample_unit_disk": NO_T, (U32) -> VEC2, "rand", Zero, draws(2);
    "sample_unit_square": NO_T, (U32) -> VEC2, "rand", Zero, draws(2);
    "sample_unit_cube": NO_T, (U32) -> VEC3, "rand", Zero, draws(3);
    "sample_unit_sphere_surface": NO_T, (U32) -> VEC3, "rand", Zero, draws(2);
    "sample_unit_sphere": NO_T, (U32) -> VEC3, "rand", Zero, draws(3);
    "sample_unit_hemisphere_surface": NO_T, (U32) -> VEC3, "rand", Zero, draws(2);
    "sample_unit_hemisphere": NO_T, (U32) -> VEC3, "rand", Zero, draws(3);
    "poisson":    NO_T,           (U32, F32) -> U32, "rand", Zero, next_state("poisson_state");
    "poisson_state": NO_T, (U32, F32) -> U32, "rand", Zero, internal;
    "noise":      NOISE,          (U32, T) -> F32,          "rand", Adjoint, no_tangent;
    "pnoise":     NOISE,          (U32, T, IntOfT) -> F32,  "rand", Adjoint, no_tangent;
};
