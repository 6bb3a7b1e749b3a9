//! [`MarchingCubes`]: Warp's marching cubes (`wp.MarchingCubes(nx, ny, nz)`,
//! `mc.surface(field, threshold)`, `mc.verts`, `mc.indices`): the triangle mesh of the surface
//! where a dense field of `nx x ny x nz` node values crosses a threshold.
//!
//! Conventions (Warp 1.19's, `warp/_src/geometry/marching_cubes.py`):
//! - the field is an `Array<f32, 3>` of shape `(nx, ny, nz)` indexed `[x, y, z]` (z fastest);
//! - vertex positions are in grid-index space, node `(i, j, k)` at `(i, j, k)`, unless bounds
//!   are set ([`MarchingCubes::set_bounds`]: node `(0, 0, 0)` at `lower`, node
//!   `(nx - 1, ny - 1, nz - 1)` at `upper`, linearly between);
//! - a node is *outside* where its value is `>= threshold`, *inside* where it is below; the
//!   triangles wind counter-clockwise seen from outside, so for a signed distance (negative
//!   inside, e.g. `|p - c| - r`) their normals `(b - a) x (c - a)` point out of the surface
//!   and a closed surface has positive signed volume;
//! - one vertex per crossed grid edge, shared by the (up to four) cells around the edge, so a
//!   surface that stays inside the box is a closed, consistently oriented mesh (what the mesh
//!   queries' inside/outside sign needs); vertex ids follow (node, axis) order and triangles
//!   cell order, as in Warp;
//! - a vertex on the edge from node value `a` to node value `b` is at the edge's parameter
//!   `t = (threshold - a) / (b - a)` (clamped to `[0, 1]`), interpolated as
//!   `p_a * (1 - t) + p_b * t` along the edge's axis; its other two coordinates are the
//!   edge's exactly (Warp interpolates all three, which can move them by an ulp).
//!
//! A surface is three steps, the same on every device through the `ObjectStep` seam (rayon
//! on the CPU, the kernels of `warp-cuda/cuda/wp_marching_cubes.h` on a GPU, written step for
//! step alike so that both give the same mesh bit for bit): (1) per node, which of its three
//! grid edges the surface crosses, the case of the cell at the node, its vertex and triangle
//! counts and the check for NaN and infinite values; (2) the primitives' inclusive scans of
//! both counts (the vertex and triangle offsets), then a one-thread step copying both totals
//! into one small buffer, the one read back; (3) per node, its vertices and its cell's
//! triangles. The case tables live here ([`MarchingCubes::CASE_TO_TRI_RANGE`],
//! [`MarchingCubes::TRI_LOCAL_INDICES`]); the header holds a rendering of them that
//! `tests/marching_cubes.rs` compares with these (and rewrites with `WARP_LANG_BLESS=1`).

use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicI32, Ordering};

use super::mesh::Mesh;
use crate::array::Array;
use crate::backend::{ObjectLibrary, ObjectStep};
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};
use crate::primitives::array_scan;

// ------------------------------------------------------------------------------------------
// The tables (the classic marching cubes tables, as Warp 1.19 has them)
// ------------------------------------------------------------------------------------------

/// Offset of each cell corner from the cell's node; corner `c` is bit `c` of a cell's case.
const CUBE_CORNER_OFFSETS: [[i32; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];

/// The two corners each cell edge joins (the lower corner first).
const EDGE_TO_CORNERS: [[usize; 2]; 12] = [
    [0, 1],
    [1, 2],
    [3, 2],
    [0, 3],
    [4, 5],
    [5, 6],
    [7, 6],
    [4, 7],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

/// Each cell edge as a grid edge: `[dx, dy, dz, axis]`, the edge along `axis` owned by the node
/// at the cell's node plus `(dx, dy, dz)`. Derived from the two tables above.
const EDGE_GRID_OFFSETS: [[u8; 4]; 12] = {
    let mut out = [[0u8; 4]; 12];
    let mut e = 0;
    while e < 12 {
        let a = CUBE_CORNER_OFFSETS[EDGE_TO_CORNERS[e][0]];
        let b = CUBE_CORNER_OFFSETS[EDGE_TO_CORNERS[e][1]];
        let mut axis = 0;
        let mut differ = 0;
        let mut k = 0;
        while k < 3 {
            if a[k] != b[k] {
                // The first corner is the lower one: the edge runs up its axis.
                assert!(b[k] == a[k] + 1);
                axis = k;
                differ += 1;
            }
            out[e][k] = a[k] as u8;
            k += 1;
        }
        assert!(differ == 1);
        out[e][3] = axis as u8;
        e += 1;
    }
    out
};

/// For case `c`, its triangles are `TRI_LOCAL_INDICES[CASE_TO_TRI_RANGE[c]..CASE_TO_TRI_RANGE[c + 1]]`.
#[rustfmt::skip]
const CASE_TO_TRI_RANGE: [u16; 257] = [
    0, 0, 3, 6, 12, 15, 21, 27, 36, 39, 45, 51,
    60, 66, 75, 84, 90, 93, 99, 105, 114, 120, 129, 138,
    150, 156, 165, 174, 186, 195, 207, 219, 228, 231, 237, 243,
    252, 258, 267, 276, 288, 294, 303, 312, 324, 333, 345, 357,
    366, 372, 381, 390, 396, 405, 417, 429, 438, 447, 459, 471,
    480, 492, 507, 522, 528, 531, 537, 543, 552, 558, 567, 576,
    588, 594, 603, 612, 624, 633, 645, 657, 666, 672, 681, 690,
    702, 711, 723, 735, 750, 759, 771, 783, 798, 810, 825, 840,
    852, 858, 867, 876, 888, 897, 909, 915, 924, 933, 945, 957,
    972, 984, 999, 1008, 1014, 1023, 1035, 1047, 1056, 1068, 1083, 1092,
    1098, 1110, 1125, 1140, 1152, 1167, 1173, 1185, 1188, 1191, 1197, 1203,
    1212, 1218, 1227, 1236, 1248, 1254, 1263, 1272, 1284, 1293, 1305, 1317,
    1326, 1332, 1341, 1350, 1362, 1371, 1383, 1395, 1410, 1419, 1425, 1437,
    1446, 1458, 1467, 1482, 1488, 1494, 1503, 1512, 1524, 1533, 1545, 1557,
    1572, 1581, 1593, 1605, 1620, 1632, 1647, 1662, 1674, 1683, 1695, 1707,
    1716, 1728, 1743, 1758, 1770, 1782, 1791, 1806, 1812, 1827, 1839, 1845,
    1848, 1854, 1863, 1872, 1884, 1893, 1905, 1917, 1932, 1941, 1953, 1965,
    1980, 1986, 1995, 2004, 2010, 2019, 2031, 2043, 2058, 2070, 2085, 2100,
    2106, 2118, 2127, 2142, 2154, 2163, 2169, 2181, 2184, 2193, 2205, 2217,
    2232, 2244, 2259, 2268, 2280, 2292, 2307, 2322, 2328, 2337, 2349, 2355,
    2358, 2364, 2373, 2382, 2388, 2397, 2409, 2415, 2418, 2427, 2433, 2445,
    2448, 2454, 2457, 2460, 2460,
];

/// Each case's triangles, three cell edges each (one line per case that has any).
#[rustfmt::skip]
const TRI_LOCAL_INDICES: [u8; 2460] = [
    0, 8, 3, // 1
    0, 1, 9, // 2
    1, 8, 3, 9, 8, 1, // 3
    1, 2, 10, // 4
    0, 8, 3, 1, 2, 10, // 5
    9, 2, 10, 0, 2, 9, // 6
    2, 8, 3, 2, 10, 8, 10, 9, 8, // 7
    3, 11, 2, // 8
    0, 11, 2, 8, 11, 0, // 9
    1, 9, 0, 2, 3, 11, // 10
    1, 11, 2, 1, 9, 11, 9, 8, 11, // 11
    3, 10, 1, 11, 10, 3, // 12
    0, 10, 1, 0, 8, 10, 8, 11, 10, // 13
    3, 9, 0, 3, 11, 9, 11, 10, 9, // 14
    9, 8, 10, 10, 8, 11, // 15
    4, 7, 8, // 16
    4, 3, 0, 7, 3, 4, // 17
    0, 1, 9, 8, 4, 7, // 18
    4, 1, 9, 4, 7, 1, 7, 3, 1, // 19
    1, 2, 10, 8, 4, 7, // 20
    3, 4, 7, 3, 0, 4, 1, 2, 10, // 21
    9, 2, 10, 9, 0, 2, 8, 4, 7, // 22
    2, 10, 9, 2, 9, 7, 2, 7, 3, 7, 9, 4, // 23
    8, 4, 7, 3, 11, 2, // 24
    11, 4, 7, 11, 2, 4, 2, 0, 4, // 25
    9, 0, 1, 8, 4, 7, 2, 3, 11, // 26
    4, 7, 11, 9, 4, 11, 9, 11, 2, 9, 2, 1, // 27
    3, 10, 1, 3, 11, 10, 7, 8, 4, // 28
    1, 11, 10, 1, 4, 11, 1, 0, 4, 7, 11, 4, // 29
    4, 7, 8, 9, 0, 11, 9, 11, 10, 11, 0, 3, // 30
    4, 7, 11, 4, 11, 9, 9, 11, 10, // 31
    9, 5, 4, // 32
    9, 5, 4, 0, 8, 3, // 33
    0, 5, 4, 1, 5, 0, // 34
    8, 5, 4, 8, 3, 5, 3, 1, 5, // 35
    1, 2, 10, 9, 5, 4, // 36
    3, 0, 8, 1, 2, 10, 4, 9, 5, // 37
    5, 2, 10, 5, 4, 2, 4, 0, 2, // 38
    2, 10, 5, 3, 2, 5, 3, 5, 4, 3, 4, 8, // 39
    9, 5, 4, 2, 3, 11, // 40
    0, 11, 2, 0, 8, 11, 4, 9, 5, // 41
    0, 5, 4, 0, 1, 5, 2, 3, 11, // 42
    2, 1, 5, 2, 5, 8, 2, 8, 11, 4, 8, 5, // 43
    10, 3, 11, 10, 1, 3, 9, 5, 4, // 44
    4, 9, 5, 0, 8, 1, 8, 10, 1, 8, 11, 10, // 45
    5, 4, 0, 5, 0, 11, 5, 11, 10, 11, 0, 3, // 46
    5, 4, 8, 5, 8, 10, 10, 8, 11, // 47
    9, 7, 8, 5, 7, 9, // 48
    9, 3, 0, 9, 5, 3, 5, 7, 3, // 49
    0, 7, 8, 0, 1, 7, 1, 5, 7, // 50
    1, 5, 3, 3, 5, 7, // 51
    9, 7, 8, 9, 5, 7, 10, 1, 2, // 52
    10, 1, 2, 9, 5, 0, 5, 3, 0, 5, 7, 3, // 53
    8, 0, 2, 8, 2, 5, 8, 5, 7, 10, 5, 2, // 54
    2, 10, 5, 2, 5, 3, 3, 5, 7, // 55
    7, 9, 5, 7, 8, 9, 3, 11, 2, // 56
    9, 5, 7, 9, 7, 2, 9, 2, 0, 2, 7, 11, // 57
    2, 3, 11, 0, 1, 8, 1, 7, 8, 1, 5, 7, // 58
    11, 2, 1, 11, 1, 7, 7, 1, 5, // 59
    9, 5, 8, 8, 5, 7, 10, 1, 3, 10, 3, 11, // 60
    5, 7, 0, 5, 0, 9, 7, 11, 0, 1, 0, 10, 11, 10, 0, // 61
    11, 10, 0, 11, 0, 3, 10, 5, 0, 8, 0, 7, 5, 7, 0, // 62
    11, 10, 5, 7, 11, 5, // 63
    10, 6, 5, // 64
    0, 8, 3, 5, 10, 6, // 65
    9, 0, 1, 5, 10, 6, // 66
    1, 8, 3, 1, 9, 8, 5, 10, 6, // 67
    1, 6, 5, 2, 6, 1, // 68
    1, 6, 5, 1, 2, 6, 3, 0, 8, // 69
    9, 6, 5, 9, 0, 6, 0, 2, 6, // 70
    5, 9, 8, 5, 8, 2, 5, 2, 6, 3, 2, 8, // 71
    2, 3, 11, 10, 6, 5, // 72
    11, 0, 8, 11, 2, 0, 10, 6, 5, // 73
    0, 1, 9, 2, 3, 11, 5, 10, 6, // 74
    5, 10, 6, 1, 9, 2, 9, 11, 2, 9, 8, 11, // 75
    6, 3, 11, 6, 5, 3, 5, 1, 3, // 76
    0, 8, 11, 0, 11, 5, 0, 5, 1, 5, 11, 6, // 77
    3, 11, 6, 0, 3, 6, 0, 6, 5, 0, 5, 9, // 78
    6, 5, 9, 6, 9, 11, 11, 9, 8, // 79
    5, 10, 6, 4, 7, 8, // 80
    4, 3, 0, 4, 7, 3, 6, 5, 10, // 81
    1, 9, 0, 5, 10, 6, 8, 4, 7, // 82
    10, 6, 5, 1, 9, 7, 1, 7, 3, 7, 9, 4, // 83
    6, 1, 2, 6, 5, 1, 4, 7, 8, // 84
    1, 2, 5, 5, 2, 6, 3, 0, 4, 3, 4, 7, // 85
    8, 4, 7, 9, 0, 5, 0, 6, 5, 0, 2, 6, // 86
    7, 3, 9, 7, 9, 4, 3, 2, 9, 5, 9, 6, 2, 6, 9, // 87
    3, 11, 2, 7, 8, 4, 10, 6, 5, // 88
    5, 10, 6, 4, 7, 2, 4, 2, 0, 2, 7, 11, // 89
    0, 1, 9, 4, 7, 8, 2, 3, 11, 5, 10, 6, // 90
    9, 2, 1, 9, 11, 2, 9, 4, 11, 7, 11, 4, 5, 10, 6, // 91
    8, 4, 7, 3, 11, 5, 3, 5, 1, 5, 11, 6, // 92
    5, 1, 11, 5, 11, 6, 1, 0, 11, 7, 11, 4, 0, 4, 11, // 93
    0, 5, 9, 0, 6, 5, 0, 3, 6, 11, 6, 3, 8, 4, 7, // 94
    6, 5, 9, 6, 9, 11, 4, 7, 9, 7, 11, 9, // 95
    10, 4, 9, 6, 4, 10, // 96
    4, 10, 6, 4, 9, 10, 0, 8, 3, // 97
    10, 0, 1, 10, 6, 0, 6, 4, 0, // 98
    8, 3, 1, 8, 1, 6, 8, 6, 4, 6, 1, 10, // 99
    1, 4, 9, 1, 2, 4, 2, 6, 4, // 100
    3, 0, 8, 1, 2, 9, 2, 4, 9, 2, 6, 4, // 101
    0, 2, 4, 4, 2, 6, // 102
    8, 3, 2, 8, 2, 4, 4, 2, 6, // 103
    10, 4, 9, 10, 6, 4, 11, 2, 3, // 104
    0, 8, 2, 2, 8, 11, 4, 9, 10, 4, 10, 6, // 105
    3, 11, 2, 0, 1, 6, 0, 6, 4, 6, 1, 10, // 106
    6, 4, 1, 6, 1, 10, 4, 8, 1, 2, 1, 11, 8, 11, 1, // 107
    9, 6, 4, 9, 3, 6, 9, 1, 3, 11, 6, 3, // 108
    8, 11, 1, 8, 1, 0, 11, 6, 1, 9, 1, 4, 6, 4, 1, // 109
    3, 11, 6, 3, 6, 0, 0, 6, 4, // 110
    6, 4, 8, 11, 6, 8, // 111
    7, 10, 6, 7, 8, 10, 8, 9, 10, // 112
    0, 7, 3, 0, 10, 7, 0, 9, 10, 6, 7, 10, // 113
    10, 6, 7, 1, 10, 7, 1, 7, 8, 1, 8, 0, // 114
    10, 6, 7, 10, 7, 1, 1, 7, 3, // 115
    1, 2, 6, 1, 6, 8, 1, 8, 9, 8, 6, 7, // 116
    2, 6, 9, 2, 9, 1, 6, 7, 9, 0, 9, 3, 7, 3, 9, // 117
    7, 8, 0, 7, 0, 6, 6, 0, 2, // 118
    7, 3, 2, 6, 7, 2, // 119
    2, 3, 11, 10, 6, 8, 10, 8, 9, 8, 6, 7, // 120
    2, 0, 7, 2, 7, 11, 0, 9, 7, 6, 7, 10, 9, 10, 7, // 121
    1, 8, 0, 1, 7, 8, 1, 10, 7, 6, 7, 10, 2, 3, 11, // 122
    11, 2, 1, 11, 1, 7, 10, 6, 1, 6, 7, 1, // 123
    8, 9, 6, 8, 6, 7, 9, 1, 6, 11, 6, 3, 1, 3, 6, // 124
    0, 9, 1, 11, 6, 7, // 125
    7, 8, 0, 7, 0, 6, 3, 11, 0, 11, 6, 0, // 126
    7, 11, 6, // 127
    7, 6, 11, // 128
    3, 0, 8, 11, 7, 6, // 129
    0, 1, 9, 11, 7, 6, // 130
    8, 1, 9, 8, 3, 1, 11, 7, 6, // 131
    10, 1, 2, 6, 11, 7, // 132
    1, 2, 10, 3, 0, 8, 6, 11, 7, // 133
    2, 9, 0, 2, 10, 9, 6, 11, 7, // 134
    6, 11, 7, 2, 10, 3, 10, 8, 3, 10, 9, 8, // 135
    7, 2, 3, 6, 2, 7, // 136
    7, 0, 8, 7, 6, 0, 6, 2, 0, // 137
    2, 7, 6, 2, 3, 7, 0, 1, 9, // 138
    1, 6, 2, 1, 8, 6, 1, 9, 8, 8, 7, 6, // 139
    10, 7, 6, 10, 1, 7, 1, 3, 7, // 140
    10, 7, 6, 1, 7, 10, 1, 8, 7, 1, 0, 8, // 141
    0, 3, 7, 0, 7, 10, 0, 10, 9, 6, 10, 7, // 142
    7, 6, 10, 7, 10, 8, 8, 10, 9, // 143
    6, 8, 4, 11, 8, 6, // 144
    3, 6, 11, 3, 0, 6, 0, 4, 6, // 145
    8, 6, 11, 8, 4, 6, 9, 0, 1, // 146
    9, 4, 6, 9, 6, 3, 9, 3, 1, 11, 3, 6, // 147
    6, 8, 4, 6, 11, 8, 2, 10, 1, // 148
    1, 2, 10, 3, 0, 11, 0, 6, 11, 0, 4, 6, // 149
    4, 11, 8, 4, 6, 11, 0, 2, 9, 2, 10, 9, // 150
    10, 9, 3, 10, 3, 2, 9, 4, 3, 11, 3, 6, 4, 6, 3, // 151
    8, 2, 3, 8, 4, 2, 4, 6, 2, // 152
    0, 4, 2, 4, 6, 2, // 153
    1, 9, 0, 2, 3, 4, 2, 4, 6, 4, 3, 8, // 154
    1, 9, 4, 1, 4, 2, 2, 4, 6, // 155
    8, 1, 3, 8, 6, 1, 8, 4, 6, 6, 10, 1, // 156
    10, 1, 0, 10, 0, 6, 6, 0, 4, // 157
    4, 6, 3, 4, 3, 8, 6, 10, 3, 0, 3, 9, 10, 9, 3, // 158
    10, 9, 4, 6, 10, 4, // 159
    4, 9, 5, 7, 6, 11, // 160
    0, 8, 3, 4, 9, 5, 11, 7, 6, // 161
    5, 0, 1, 5, 4, 0, 7, 6, 11, // 162
    11, 7, 6, 8, 3, 4, 3, 5, 4, 3, 1, 5, // 163
    9, 5, 4, 10, 1, 2, 7, 6, 11, // 164
    6, 11, 7, 1, 2, 10, 0, 8, 3, 4, 9, 5, // 165
    7, 6, 11, 5, 4, 10, 4, 2, 10, 4, 0, 2, // 166
    3, 4, 8, 3, 5, 4, 3, 2, 5, 10, 5, 2, 11, 7, 6, // 167
    7, 2, 3, 7, 6, 2, 5, 4, 9, // 168
    9, 5, 4, 0, 8, 6, 0, 6, 2, 6, 8, 7, // 169
    3, 6, 2, 3, 7, 6, 1, 5, 0, 5, 4, 0, // 170
    6, 2, 8, 6, 8, 7, 2, 1, 8, 4, 8, 5, 1, 5, 8, // 171
    9, 5, 4, 10, 1, 6, 1, 7, 6, 1, 3, 7, // 172
    1, 6, 10, 1, 7, 6, 1, 0, 7, 8, 7, 0, 9, 5, 4, // 173
    4, 0, 10, 4, 10, 5, 0, 3, 10, 6, 10, 7, 3, 7, 10, // 174
    7, 6, 10, 7, 10, 8, 5, 4, 10, 4, 8, 10, // 175
    6, 9, 5, 6, 11, 9, 11, 8, 9, // 176
    3, 6, 11, 0, 6, 3, 0, 5, 6, 0, 9, 5, // 177
    0, 11, 8, 0, 5, 11, 0, 1, 5, 5, 6, 11, // 178
    6, 11, 3, 6, 3, 5, 5, 3, 1, // 179
    1, 2, 10, 9, 5, 11, 9, 11, 8, 11, 5, 6, // 180
    0, 11, 3, 0, 6, 11, 0, 9, 6, 5, 6, 9, 1, 2, 10, // 181
    11, 8, 5, 11, 5, 6, 8, 0, 5, 10, 5, 2, 0, 2, 5, // 182
    6, 11, 3, 6, 3, 5, 2, 10, 3, 10, 5, 3, // 183
    5, 8, 9, 5, 2, 8, 5, 6, 2, 3, 8, 2, // 184
    9, 5, 6, 9, 6, 0, 0, 6, 2, // 185
    1, 5, 8, 1, 8, 0, 5, 6, 8, 3, 8, 2, 6, 2, 8, // 186
    1, 5, 6, 2, 1, 6, // 187
    1, 3, 6, 1, 6, 10, 3, 8, 6, 5, 6, 9, 8, 9, 6, // 188
    10, 1, 0, 10, 0, 6, 9, 5, 0, 5, 6, 0, // 189
    0, 3, 8, 5, 6, 10, // 190
    10, 5, 6, // 191
    11, 5, 10, 7, 5, 11, // 192
    11, 5, 10, 11, 7, 5, 8, 3, 0, // 193
    5, 11, 7, 5, 10, 11, 1, 9, 0, // 194
    10, 7, 5, 10, 11, 7, 9, 8, 1, 8, 3, 1, // 195
    11, 1, 2, 11, 7, 1, 7, 5, 1, // 196
    0, 8, 3, 1, 2, 7, 1, 7, 5, 7, 2, 11, // 197
    9, 7, 5, 9, 2, 7, 9, 0, 2, 2, 11, 7, // 198
    7, 5, 2, 7, 2, 11, 5, 9, 2, 3, 2, 8, 9, 8, 2, // 199
    2, 5, 10, 2, 3, 5, 3, 7, 5, // 200
    8, 2, 0, 8, 5, 2, 8, 7, 5, 10, 2, 5, // 201
    9, 0, 1, 5, 10, 3, 5, 3, 7, 3, 10, 2, // 202
    9, 8, 2, 9, 2, 1, 8, 7, 2, 10, 2, 5, 7, 5, 2, // 203
    1, 3, 5, 3, 7, 5, // 204
    0, 8, 7, 0, 7, 1, 1, 7, 5, // 205
    9, 0, 3, 9, 3, 5, 5, 3, 7, // 206
    9, 8, 7, 5, 9, 7, // 207
    5, 8, 4, 5, 10, 8, 10, 11, 8, // 208
    5, 0, 4, 5, 11, 0, 5, 10, 11, 11, 3, 0, // 209
    0, 1, 9, 8, 4, 10, 8, 10, 11, 10, 4, 5, // 210
    10, 11, 4, 10, 4, 5, 11, 3, 4, 9, 4, 1, 3, 1, 4, // 211
    2, 5, 1, 2, 8, 5, 2, 11, 8, 4, 5, 8, // 212
    0, 4, 11, 0, 11, 3, 4, 5, 11, 2, 11, 1, 5, 1, 11, // 213
    0, 2, 5, 0, 5, 9, 2, 11, 5, 4, 5, 8, 11, 8, 5, // 214
    9, 4, 5, 2, 11, 3, // 215
    2, 5, 10, 3, 5, 2, 3, 4, 5, 3, 8, 4, // 216
    5, 10, 2, 5, 2, 4, 4, 2, 0, // 217
    3, 10, 2, 3, 5, 10, 3, 8, 5, 4, 5, 8, 0, 1, 9, // 218
    5, 10, 2, 5, 2, 4, 1, 9, 2, 9, 4, 2, // 219
    8, 4, 5, 8, 5, 3, 3, 5, 1, // 220
    0, 4, 5, 1, 0, 5, // 221
    8, 4, 5, 8, 5, 3, 9, 0, 5, 0, 3, 5, // 222
    9, 4, 5, // 223
    4, 11, 7, 4, 9, 11, 9, 10, 11, // 224
    0, 8, 3, 4, 9, 7, 9, 11, 7, 9, 10, 11, // 225
    1, 10, 11, 1, 11, 4, 1, 4, 0, 7, 4, 11, // 226
    3, 1, 4, 3, 4, 8, 1, 10, 4, 7, 4, 11, 10, 11, 4, // 227
    4, 11, 7, 9, 11, 4, 9, 2, 11, 9, 1, 2, // 228
    9, 7, 4, 9, 11, 7, 9, 1, 11, 2, 11, 1, 0, 8, 3, // 229
    11, 7, 4, 11, 4, 2, 2, 4, 0, // 230
    11, 7, 4, 11, 4, 2, 8, 3, 4, 3, 2, 4, // 231
    2, 9, 10, 2, 7, 9, 2, 3, 7, 7, 4, 9, // 232
    9, 10, 7, 9, 7, 4, 10, 2, 7, 8, 7, 0, 2, 0, 7, // 233
    3, 7, 10, 3, 10, 2, 7, 4, 10, 1, 10, 0, 4, 0, 10, // 234
    1, 10, 2, 8, 7, 4, // 235
    4, 9, 1, 4, 1, 7, 7, 1, 3, // 236
    4, 9, 1, 4, 1, 7, 0, 8, 1, 8, 7, 1, // 237
    4, 0, 3, 7, 4, 3, // 238
    4, 8, 7, // 239
    9, 10, 8, 10, 11, 8, // 240
    3, 0, 9, 3, 9, 11, 11, 9, 10, // 241
    0, 1, 10, 0, 10, 8, 8, 10, 11, // 242
    3, 1, 10, 11, 3, 10, // 243
    1, 2, 11, 1, 11, 9, 9, 11, 8, // 244
    3, 0, 9, 3, 9, 11, 1, 2, 9, 2, 11, 9, // 245
    0, 2, 11, 8, 0, 11, // 246
    3, 2, 11, // 247
    2, 3, 8, 2, 8, 10, 10, 8, 9, // 248
    9, 10, 2, 0, 9, 2, // 249
    2, 3, 8, 2, 8, 10, 0, 1, 8, 1, 10, 8, // 250
    1, 10, 2, // 251
    1, 3, 8, 9, 1, 8, // 252
    0, 9, 1, // 253
    0, 3, 8, // 254
];

const _: () = assert!(CASE_TO_TRI_RANGE[256] as usize == TRI_LOCAL_INDICES.len());

/// The most triangles one cell's case has (15 table entries).
const MAX_TRIS_PER_CELL: usize = 5;

/// The most nodes a grid may have: every count the steps keep is an `i32` (as Warp's), and a
/// grid of `n` nodes has fewer than `3n` vertices and `5n` triangles.
pub const MAX_NODES: usize = i32::MAX as usize / MAX_TRIS_PER_CELL;

const _: () = {
    let mut c = 0;
    while c < 256 {
        let n = CASE_TO_TRI_RANGE[c + 1] - CASE_TO_TRI_RANGE[c];
        assert!(n.is_multiple_of(3) && n as usize <= 3 * MAX_TRIS_PER_CELL);
        c += 1;
    }
};

// ------------------------------------------------------------------------------------------
// The steps
// ------------------------------------------------------------------------------------------

/// The marching cubes build library: `wp_marching_cubes.h` with its kernels enabled.
pub(crate) static LIBRARY: ObjectLibrary = ObjectLibrary::of("marching_cubes");

/// Step 1, per node `n` of the `dims` grid (field values `f32`, row-major, z fastest): which of
/// its three grid edges the surface crosses (bits 0..2 of the edge mask: the endpoints on
/// different sides of `threshold`), the case of the cell at the node (0 where none starts),
/// into `codes[n] = case | mask << 8`; its vertex count (crossed edges) into `vcount[n]`; the
/// case's triangle count into `tcount[n]`; the smallest node whose value is NaN or infinite
/// into the `i32` at `bad` (atomically lowered; left alone when all are finite).
/// `wp::mc_count_t` in C++ (56 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MarchingCubesCount {
    pub field: u64,
    pub codes: u64,
    pub vcount: u64,
    pub tcount: u64,
    pub bad: u64,
    pub dims: [i32; 3],
    pub threshold: f32,
}

const _: () = assert!(std::mem::size_of::<MarchingCubesCount>() == 56);

/// Step 2 (one thread): the last entries of the `n`-long inclusive scans at `vscan` and
/// `tscan` (the vertex and triangle totals) into `totals[0]` and `totals[1]`.
/// `wp::mc_totals_t` in C++ (32 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MarchingCubesTotals {
    pub vscan: u64,
    pub tscan: u64,
    pub totals: u64,
    pub n: i64,
}

const _: () = assert!(std::mem::size_of::<MarchingCubesTotals>() == 32);

/// Step 3, per node: its vertices (`num_verts` `Vec3`s at `verts`) and its cell's triangles
/// (`3 * num_tris` `i32`s at `indices`), from the field, the codes of step 1 and the inclusive
/// scans of its counts (`vscan`, `tscan`); node `(i, j, k)` is at `lower + (i, j, k) * delta`.
/// `wp::mc_emit_t` in C++ (96 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MarchingCubesEmit {
    pub field: u64,
    pub codes: u64,
    pub vscan: u64,
    pub tscan: u64,
    pub verts: u64,
    pub indices: u64,
    pub dims: [i32; 3],
    pub threshold: f32,
    pub lower: [f32; 3],
    pub delta: [f32; 3],
    pub num_verts: i32,
    pub num_tris: i32,
}

const _: () = assert!(std::mem::size_of::<MarchingCubesEmit>() == 96);

/// The nodes of a `dims` grid (below `MAX_NODES` by construction, so an `i32` product).
fn node_count(dims: [i32; 3]) -> usize {
    dims.iter().map(|d| *d as usize).product()
}

/// Node `n`'s coordinates (row-major, z fastest).
fn node_coords(dims: [i32; 3], n: usize) -> [usize; 3] {
    let (ny, nz) = (dims[1] as usize, dims[2] as usize);
    let r = n / nz;
    [r / ny, r % ny, n % nz]
}

/// The bits set in a 3-bit edge mask (`wp::mc_popc3`).
fn popc3(m: i32) -> i32 {
    (m & 7).count_ones() as i32
}

/// Step 1 at node `n`: `(codes[n], vcount[n], tcount[n], value is finite)` (the C++
/// `mc_count_node`).
fn count_node(f: &[f32], dims: [i32; 3], threshold: f32, n: usize) -> (i32, i32, i32, bool) {
    let [i, j, k] = node_coords(dims, n);
    let stride = [(dims[1] * dims[2]) as usize, dims[2] as usize, 1];
    let has = [
        i + 1 < dims[0] as usize,
        j + 1 < dims[1] as usize,
        k + 1 < dims[2] as usize,
    ];
    let v0 = f[n];
    let o0 = v0 >= threshold;
    let mut mask = 0;
    for a in 0..3 {
        if has[a] && (f[n + stride[a]] >= threshold) != o0 {
            mask |= 1 << a;
        }
    }
    let (mut code, mut ntri) = (0usize, 0);
    if has[0] && has[1] && has[2] {
        for (c, o) in CUBE_CORNER_OFFSETS.iter().enumerate() {
            let m = n + o[0] as usize * stride[0] + o[1] as usize * stride[1] + o[2] as usize;
            if f[m] >= threshold {
                code |= 1 << c;
            }
        }
        ntri = (CASE_TO_TRI_RANGE[code + 1] - CASE_TO_TRI_RANGE[code]) as i32 / 3;
    }
    (code as i32 | mask << 8, popc3(mask), ntri, v0.is_finite())
}

/// A pointer that rayon tasks share, for writes to elements no two tasks share.
#[derive(Clone, Copy)]
struct Shared<T>(*mut T);
// SAFETY: every use writes elements that no other task touches (see the callers).
unsafe impl<T> Send for Shared<T> {}
unsafe impl<T> Sync for Shared<T> {}

impl<T> Shared<T> {
    /// Element `i` (a method, so that closures capture the `Shared`, not its raw pointer).
    fn at(self, i: usize) -> *mut T {
        self.0.wrapping_add(i)
    }
}

// SAFETY (all three steps): `#[repr(C)]` records laid out as the C++ structs of
// `wp_marching_cubes.h` (both sides assert the sizes); `MarchingCubes::surface` passes its own
// scratch (one `i32` per node, 4 totals), a contiguous field of `dims` nodes, and output
// arrays of `num_verts` vertices and `3 * num_tris` indices.
unsafe impl ObjectStep for MarchingCubesCount {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_mc_count";

    fn len(&self) -> usize {
        node_count(self.dims)
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        // SAFETY: `n` field values and `n` codes and counts in distinct host arrays the surface
        // owns (the field is the caller's, only read); nothing else touches them meanwhile.
        let (f, codes, vcount, tcount) = unsafe {
            (
                std::slice::from_raw_parts(self.field as *const f32, n),
                std::slice::from_raw_parts_mut(self.codes as *mut i32, n),
                std::slice::from_raw_parts_mut(self.vcount as *mut i32, n),
                std::slice::from_raw_parts_mut(self.tcount as *mut i32, n),
            )
        };
        // SAFETY: an i32 of the scratch, aligned and sized as an AtomicI32.
        let bad = unsafe { &*(self.bad as *const AtomicI32) };
        let (dims, threshold) = (self.dims, self.threshold);
        codes
            .par_iter_mut()
            .zip(vcount.par_iter_mut())
            .zip(tcount.par_iter_mut())
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, ((c, v), t))| {
                let (code, nv, nt, finite) = count_node(f, dims, threshold, i);
                if !finite {
                    bad.fetch_min(i as i32, Ordering::Relaxed);
                }
                (*c, *v, *t) = (code, nv, nt);
            });
        Ok(())
    }
}

unsafe impl ObjectStep for MarchingCubesTotals {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_mc_totals";

    fn len(&self) -> usize {
        1
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.n as usize;
        // SAFETY: two scans of `n >= 1` i32s and 2 totals, the surface's own host scratch.
        unsafe {
            let totals = self.totals as *mut i32;
            totals.write(*(self.vscan as *const i32).add(n - 1));
            totals.add(1).write(*(self.tscan as *const i32).add(n - 1));
        }
        Ok(())
    }
}

unsafe impl ObjectStep for MarchingCubesEmit {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_mc_emit";

    fn len(&self) -> usize {
        node_count(self.dims)
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        // SAFETY: `n` field values, codes and scans, the surface's (read only here).
        let (f, codes, vscan, tscan) = unsafe {
            (
                std::slice::from_raw_parts(self.field as *const f32, n),
                std::slice::from_raw_parts(self.codes as *const i32, n),
                std::slice::from_raw_parts(self.vscan as *const i32, n),
                std::slice::from_raw_parts(self.tscan as *const i32, n),
            )
        };
        let verts = Shared(self.verts as *mut Vec3);
        let indices = Shared(self.indices as *mut i32);
        let s = *self;
        (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .for_each(|node| emit_node(&s, f, codes, vscan, tscan, verts, indices, node));
        Ok(())
    }
}

/// Step 3 at node `n` (the C++ `mc_emit_node`, operation for operation).
#[allow(clippy::too_many_arguments)]
fn emit_node(
    s: &MarchingCubesEmit,
    f: &[f32],
    codes: &[i32],
    vscan: &[i32],
    tscan: &[i32],
    verts: Shared<Vec3>,
    indices: Shared<i32>,
    n: usize,
) {
    let dims = s.dims;
    let c = codes[n];
    let mask = (c >> 8) & 7;
    let code = (c & 255) as usize;
    let stride = [(dims[1] * dims[2]) as usize, dims[2] as usize, 1];
    if mask != 0 {
        let idx = node_coords(dims, n);
        let p: [f32; 3] = std::array::from_fn(|a| s.lower[a] + idx[a] as f32 * s.delta[a]);
        let v0 = f[n];
        let mut id = vscan[n] - popc3(mask);
        for a in 0..3 {
            if (mask >> a) & 1 == 0 {
                continue;
            }
            let v1 = f[n + stride[a]];
            // Only overflow (both differences infinite) can make t NaN or leave [0, 1]; NaN -> 0.
            let mut t = (s.threshold - v0) / (v1 - v0);
            // `!(t > 0)` in C++: NaN and -0 become +0.
            if t.is_nan() || t <= 0.0 {
                t = 0.0;
            } else if t > 1.0 {
                t = 1.0;
            }
            let q = s.lower[a] + (idx[a] + 1) as f32 * s.delta[a];
            let mut out = p;
            out[a] = p[a] * (1.0 - t) + q * t;
            if id >= 0 && id < s.num_verts {
                // SAFETY: `id` is below the vertex count, and vertex ids are unique to their
                // edge, so no other task writes this element.
                unsafe { verts.at(id as usize).write(Vec3::from(out)) };
            }
            id += 1;
        }
    }
    let (lo, hi) = (
        CASE_TO_TRI_RANGE[code] as usize,
        CASE_TO_TRI_RANGE[code + 1] as usize,
    );
    if hi > lo {
        let count = hi - lo;
        let first = 3 * (tscan[n] as i64 - (count / 3) as i64);
        if first < 0 || first + count as i64 > 3 * s.num_tris as i64 {
            return;
        }
        for e in lo..hi {
            let [dx, dy, dz, a] = EDGE_GRID_OFFSETS[TRI_LOCAL_INDICES[e] as usize];
            let m = n + dx as usize * stride[0] + dy as usize * stride[1] + dz as usize;
            let mm = (codes[m] >> 8) & 7;
            let id = vscan[m] - popc3(mm) + popc3(mm & ((1 << a) - 1));
            // SAFETY: inside the index array (checked above); the range is this cell's
            // triangles', which no other task writes.
            unsafe { indices.at(first as usize + (e - lo)).write(id) };
        }
    }
}

// ------------------------------------------------------------------------------------------
// The host object
// ------------------------------------------------------------------------------------------

/// The scratch of one grid size on the object's device: one `i32` per node each.
#[derive(Clone)]
struct Scratch {
    /// Step 1's `case | edge mask << 8`.
    codes: Array<i32>,
    /// The vertex counts, then (scanned in place) their inclusive prefix sums.
    vscan: Array<i32>,
    /// The triangle counts, then their inclusive prefix sums.
    tscan: Array<i32>,
    /// `[vertices, triangles, first bad node (i32::MAX: none), unused]`.
    totals: Array<i32>,
}

/// Marching cubes on one device (Warp's `wp.MarchingCubes`): make one for a grid size, then
/// [`surface`](MarchingCubes::surface) fields of that size; the mesh of the last surface is
/// [`verts`](MarchingCubes::verts) and [`indices`](MarchingCubes::indices) (or
/// [`to_mesh`](MarchingCubes::to_mesh) for the mesh queries). See the [module docs](self) for
/// the conventions.
///
/// ```
/// # use warp_runtime as wp;
/// # use glam::Vec3;
/// let dev = wp::cpu();
/// let n = 16;
/// // A sphere of radius 5 around the grid's centre: negative inside.
/// let c = Vec3::splat(7.5);
/// let mut field = Vec::new();
/// for i in 0..n {
///     for j in 0..n {
///         for k in 0..n {
///             field.push((Vec3::new(i as f32, j as f32, k as f32) - c).length() - 5.0);
///         }
///     }
/// }
/// let field = wp::Array::from_slice_shape(&field, (n, n, n), &dev)?;
/// let mut mc = wp::MarchingCubes::new(n, n, n, &dev)?;
/// mc.surface(&field, 0.0)?;
/// let verts = mc.verts().to_vec()?;
/// assert!(verts.iter().all(|v| ((*v - c).length() - 5.0).abs() < 0.1));
/// assert_eq!(mc.indices().len() % 3, 0);
/// # Ok::<(), wp::Error>(())
/// ```
pub struct MarchingCubes {
    dims: [i32; 3],
    device: Device,
    lower: Option<Vec3>,
    upper: Option<Vec3>,
    /// Allocated by the first surface (and again after a resize to another node count).
    scratch: Option<Scratch>,
    verts: Array<Vec3>,
    indices: Array<i32>,
}

impl std::fmt::Debug for MarchingCubes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MarchingCubes")
            .field("dims", &self.dims)
            .field("device", &self.device.alias())
            .field("lower", &self.lower)
            .field("upper", &self.upper)
            .field("num_verts", &self.verts.len())
            .field("num_tris", &(self.indices.len() / 3))
            .finish()
    }
}

/// An `InvalidArgument` from `what` (`"MarchingCubes::surface"`) about its argument `arg`.
fn bad(what: &str, arg: &str, why: impl std::fmt::Display) -> Error {
    Error::InvalidArgument {
        what: format!("{what}: argument `{arg}` {why}"),
    }
}

/// The grid size as `i32`s: every extent at least 2 (a cell), at most `MAX_NODES` nodes.
fn check_dims(what: &str, nx: usize, ny: usize, nz: usize) -> Result<[i32; 3]> {
    for (name, d) in [("nx", nx), ("ny", ny), ("nz", nz)] {
        if d < 2 {
            return Err(bad(
                what,
                name,
                format!("is {d}: a grid needs at least 2 nodes per axis (one cell)"),
            ));
        }
    }
    match nx.checked_mul(ny).and_then(|p| p.checked_mul(nz)) {
        Some(n) if n <= MAX_NODES => Ok([nx as i32, ny as i32, nz as i32]),
        _ => Err(bad(
            what,
            "nx * ny * nz",
            format!(
                "is {nx} x {ny} x {nz}, more than {MAX_NODES} nodes (i32::MAX / 5: the vertex \
                 and triangle counts are i32, as in Warp)"
            ),
        )),
    }
}

impl MarchingCubes {
    /// The offset of each cell corner from the cell's node; corner `c` is bit `c` of a cell's
    /// case (set where the corner's value is `>= threshold`). Warp's `CUBE_CORNER_OFFSETS`.
    pub const CUBE_CORNER_OFFSETS: [[i32; 3]; 8] = CUBE_CORNER_OFFSETS;
    /// The two corners (of [`CUBE_CORNER_OFFSETS`](Self::CUBE_CORNER_OFFSETS)) each of the 12
    /// cell edges joins, the lower corner first. Warp's `EDGE_TO_CORNERS`.
    pub const EDGE_TO_CORNERS: [[usize; 2]; 12] = EDGE_TO_CORNERS;
    /// Each cell edge as a grid edge `[dx, dy, dz, axis]`: the edge along `axis` (0 = x) from
    /// the cell's node plus `(dx, dy, dz)` (derived from the two tables above).
    pub const EDGE_GRID_OFFSETS: [[u8; 4]; 12] = EDGE_GRID_OFFSETS;
    /// 257 offsets: case `c`'s triangles are
    /// `TRI_LOCAL_INDICES[CASE_TO_TRI_RANGE[c]..CASE_TO_TRI_RANGE[c + 1]]`. Warp's
    /// `CASE_TO_TRI_RANGE`.
    pub const CASE_TO_TRI_RANGE: [u16; 257] = CASE_TO_TRI_RANGE;
    /// Every case's triangles, three cell edges (0..12) each, the vertices of a triangle in
    /// counter-clockwise order seen from outside. Warp's `TRI_LOCAL_INDICES`.
    pub const TRI_LOCAL_INDICES: [u8; 2460] = TRI_LOCAL_INDICES;

    /// Marching cubes for fields of `nx x ny x nz` nodes on `device` (Warp's
    /// `wp.MarchingCubes(nx, ny, nz)`; there the device is the field's). Its scratch (16 bytes
    /// per node) is allocated by the first [`surface`](MarchingCubes::surface).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the extent when one is below 2, or naming their
    /// product when the grid has more than [`MAX_NODES`] nodes; allocation errors.
    pub fn new(nx: usize, ny: usize, nz: usize, device: &Device) -> Result<MarchingCubes> {
        let dims = check_dims("MarchingCubes::new", nx, ny, nz)?;
        Ok(MarchingCubes {
            dims,
            device: device.clone(),
            lower: None,
            upper: None,
            scratch: None,
            verts: Array::zeros(0, device)?,
            indices: Array::zeros(0, device)?,
        })
    }

    /// Nodes per axis, `[nx, ny, nz]`.
    pub fn dims(&self) -> [usize; 3] {
        self.dims.map(|d| d as usize)
    }

    /// The device of the object's arrays (and of the fields it takes).
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Changes the grid size for the next surfaces (Warp's `resize`); the mesh of the last
    /// surface stays. The scratch is reallocated at the next surface if the node count changed.
    ///
    /// # Errors
    /// As [`new`](MarchingCubes::new); a failed resize changes nothing.
    pub fn resize(&mut self, nx: usize, ny: usize, nz: usize) -> Result<()> {
        self.dims = check_dims("MarchingCubes::resize", nx, ny, nz)?;
        Ok(())
    }

    /// Sets where the grid lies (Warp's `lower` and `upper`): node `(0, 0, 0)` at `lower`
    /// (`None`: the origin), node `(nx - 1, ny - 1, nz - 1)` at `upper` (`None`:
    /// `(nx - 1, ny - 1, nz - 1)`, so that with neither set a node's position is its index).
    /// Node `(i, j, k)` is at `lower + (i, j, k) * (upper - lower) / (n - 1)`, in f32 in that
    /// order. Takes effect at the next surface.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the bound when it has a NaN or infinite coordinate (a
    /// failed call changes nothing).
    pub fn set_bounds(&mut self, lower: Option<Vec3>, upper: Option<Vec3>) -> Result<()> {
        for (name, b) in [("lower", lower), ("upper", upper)] {
            if let Some(v) = b.filter(|v| !v.is_finite()) {
                return Err(bad(
                    "MarchingCubes::set_bounds",
                    name,
                    format!("is {v:?}: bounds must be finite"),
                ));
            }
        }
        (self.lower, self.upper) = (lower, upper);
        Ok(())
    }

    /// The lower bound set by [`set_bounds`](MarchingCubes::set_bounds) (`None`: the origin).
    pub fn lower(&self) -> Option<Vec3> {
        self.lower
    }

    /// The upper bound set by [`set_bounds`](MarchingCubes::set_bounds) (`None`: the last
    /// node's index).
    pub fn upper(&self) -> Option<Vec3> {
        self.upper
    }

    /// The vertices of the last surface (empty before one, or after a failed one): one per
    /// crossed grid edge, in (node, axis) order. Each surface makes new arrays, so a clone
    /// taken earlier keeps its mesh.
    pub fn verts(&self) -> &Array<Vec3> {
        &self.verts
    }

    /// The triangles of the last surface as a flat array, three vertex indices per triangle
    /// (counter-clockwise seen from outside), in cell order (empty before a surface, or after
    /// a failed one).
    pub fn indices(&self) -> &Array<i32> {
        &self.indices
    }

    /// A [`Mesh`] of the last surface (sharing its vertex array; see [`Mesh::new`]), for the
    /// mesh queries. The empty surface gives the empty mesh.
    ///
    /// # Errors
    /// As [`Mesh::new`] (device errors; the surface's indices and vertices are valid by
    /// construction).
    pub fn to_mesh(&self) -> Result<Mesh> {
        Mesh::new(&self.verts, &self.indices, None)
    }

    /// Extracts the surface where `field` crosses `threshold` (Warp's `surface(field,
    /// threshold)`): afterwards [`verts`](MarchingCubes::verts) and
    /// [`indices`](MarchingCubes::indices) hold its mesh. On a GPU the steps are queued like
    /// launches; the call waits once, to read the totals and the field check back (after the
    /// scans), and returns with the last step queued.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the argument: `field` of another shape than the
    /// grid's `(nx, ny, nz)`, on another device than the object, or with a NaN or infinite
    /// value (naming the first such node, in row-major order, and its value); `threshold` NaN
    /// or infinite; device errors. A failed surface leaves the object with the empty mesh.
    pub fn surface(&mut self, field: &Array<f32, 3>, threshold: f32) -> Result<()> {
        const WHAT: &str = "MarchingCubes::surface";
        // Whatever happens below, the last surface's mesh is no longer this call's result.
        self.verts = Array::zeros(0, &self.device)?;
        self.indices = Array::zeros(0, &self.device)?;
        let dims = self.dims;
        let want = self.dims();
        if field.shape() != want {
            return Err(bad(
                WHAT,
                "field",
                format!(
                    "has shape {:?} but the grid is {want:?} nodes (resize the MarchingCubes \
                     for another size)",
                    field.shape()
                ),
            ));
        }
        if field.device() != &self.device {
            return Err(bad(
                WHAT,
                "field",
                format!(
                    "is on device \"{}\" but the MarchingCubes is on \"{}\"",
                    field.device().alias(),
                    self.device.alias()
                ),
            ));
        }
        if !threshold.is_finite() {
            return Err(bad(
                WHAT,
                "threshold",
                format!("is {threshold}: it must be finite"),
            ));
        }
        let n = node_count(dims);
        // The steps read the field as one contiguous run.
        let field = if field.is_contiguous() {
            field.reshape(n)?
        } else {
            let copy = Array::<f32, 3>::empty(want, &self.device)?;
            copy.copy_from(field)?;
            copy.reshape(n)?
        };
        let s = self.scratch(n)?;
        s.totals.fill(i32::MAX)?;
        dispatch::object_step(
            &self.device,
            &MarchingCubesCount {
                field: field.device_address(),
                codes: s.codes.device_address(),
                vcount: s.vscan.device_address(),
                tcount: s.tscan.device_address(),
                bad: s.totals.device_address() + 8,
                dims,
                threshold,
            },
        )?;
        array_scan(&s.vscan, &s.vscan, true)?;
        array_scan(&s.tscan, &s.tscan, true)?;
        dispatch::object_step(
            &self.device,
            &MarchingCubesTotals {
                vscan: s.vscan.device_address(),
                tscan: s.tscan.device_address(),
                totals: s.totals.device_address(),
                n: n as i64,
            },
        )?;
        // The one wait of a surface.
        let totals = s.totals.to_vec()?;
        if totals[2] != i32::MAX {
            let b = totals[2] as usize;
            let v = field.view(b..b + 1)?.to_vec()?[0];
            let [i, j, k] = node_coords(dims, b);
            return Err(bad(
                WHAT,
                "field",
                format!(
                    "has a non-finite value {v} at node [{i}, {j}, {k}] (the first in row-major \
                     order): marching cubes needs finite values"
                ),
            ));
        }
        let (nv, nt) = (totals[0], totals[1]);
        // The counts are bounded by construction (at most 3 and 5 per node, MAX_NODES nodes):
        // anything else is a broken step, not bad input.
        if nv < 0 || nv as usize > 3 * n || nt < 0 || nt as usize > MAX_TRIS_PER_CELL * n {
            return Err(Error::invalid(format!(
                "{WHAT}: internal error: the counting step found {nv} vertices and {nt} \
                 triangles for {n} nodes"
            )));
        }
        let verts = Array::<Vec3>::empty(nv as usize, &self.device)?;
        let indices = Array::<i32>::empty(3 * nt as usize, &self.device)?;
        let lower = self.lower.unwrap_or(Vec3::ZERO);
        let upper = self.upper.unwrap_or_else(|| {
            Vec3::new(
                (dims[0] - 1) as f32,
                (dims[1] - 1) as f32,
                (dims[2] - 1) as f32,
            )
        });
        // Warp's spacing: (upper - lower) / cells, per axis in f32.
        let delta = std::array::from_fn(|a| (upper[a] - lower[a]) / (dims[a] - 1) as f32);
        dispatch::object_step(
            &self.device,
            &MarchingCubesEmit {
                field: field.device_address(),
                codes: s.codes.device_address(),
                vscan: s.vscan.device_address(),
                tscan: s.tscan.device_address(),
                verts: verts.device_address(),
                indices: indices.device_address(),
                dims,
                threshold,
                lower: lower.to_array(),
                delta,
                num_verts: nv,
                num_tris: nt,
            },
        )?;
        self.verts = verts;
        self.indices = indices;
        Ok(())
    }

    /// The scratch for `n` nodes (allocated when there is none of that size; a clone of
    /// arrays sharing the object's memory).
    fn scratch(&mut self, n: usize) -> Result<Scratch> {
        let s = match self.scratch.take() {
            Some(s) if s.codes.len() == n => s,
            old => {
                // Dropped first: two grids' scratch never coexist.
                drop(old);
                Scratch {
                    codes: Array::zeros(n, &self.device)?,
                    vscan: Array::zeros(n, &self.device)?,
                    tscan: Array::zeros(n, &self.device)?,
                    totals: Array::zeros(4, &self.device)?,
                }
            }
        };
        Ok(self.scratch.insert(s).clone())
    }
}
