// wp_marching_cubes.h: marching cubes over a dense field on a GPU, the build steps of
// warp-runtime's objects/marching_cubes.rs (`MarchingCubes::surface`), which runs the same
// steps on the CPU with rayon. Both produce the same mesh, bit for bit: the integer steps are
// exact and every float operation below is spelled with __fadd_rn/__fmul_rn/__fdiv_rn (never
// contracted into an FMA, whatever `--fmad` says), in the Rust code's order.
//
// The field is nx x ny x nz f32 values at the grid's nodes, row-major with z fastest (node
// (i, j, k) is n = (i * ny + j) * nz + k), as Warp's `array3d[x, y, z]`. A node is "outside"
// where its value is >= the threshold (Warp's rule: bit c of a cell's case is set where corner
// c is outside); for a signed distance (negative inside) the triangles wind counter-clockwise
// seen from outside, so their normals point out of the surface.
//
// Numbering (Warp's, the classic tables'): corner c of the cell at node (i, j, k) is the node
// (i, j, k) + mc_corner(c), with corners 0..3 (0,0,0) (1,0,0) (1,1,0) (0,1,0) and 4..7 the same
// plus z. Grid edges are owned by their lower node: edge (n, a) joins node n to its neighbour
// along axis a (0 = x). Cell edge e (0..11) is grid edge mc_edge_offsets[e] = {dx, dy, dz, a}:
// the edge of axis a at the cell's node plus (dx, dy, dz).
//
// Steps (one kernel each, grid-stride over the record's count):
//   wp_mc_count   per node: which of its (up to) three edges the surface crosses (bits 0..2 of
//                 the edge mask: endpoints on different sides), the case of the cell at the node
//                 (0 where no cell starts: the last node of an axis), and from them its vertex
//                 count (crossed edges) and triangle count (the case's); codes[n] = case |
//                 mask << 8. The smallest node with a NaN or infinite value lowers *bad.
//   (the runtime's inclusive scans of both counts, in place)
//   wp_mc_totals  one thread: the last entries of both scans (the vertex and triangle totals)
//                 into totals[0] and totals[1], so the host reads one small buffer.
//   wp_mc_emit    per node: its vertices at positions [vscan[n] - count, vscan[n]) in axis
//                 order, each interpolated on its edge; its cell's triangles at
//                 [tscan[n] - count, tscan[n]), each corner the vertex id of a cell edge: grid
//                 edge (m, a) has id vscan[m] - popc(mask_m) + popc(mask_m & ((1 << a) - 1)).
//
// So vertex ids follow (node, axis) order and triangles follow cell order, as in Warp 1.19's
// marching cubes. Writes outside the vertex and index counts in the record are skipped (they
// cannot happen: the counts come from the same scans).
#pragma once
#include "wp_core.h"

namespace wp {

#if defined(__CUDACC__)
// Global memory, not __constant__: a warp's threads read different entries (one per cell's
// case), which the constant cache would serialise.
#define WP_MC_TABLE __device__
#else
#define WP_MC_TABLE
#endif

// The case tables (the classic marching cubes tables, as Warp 1.19 has them): case c's
// triangles are mc_tri_local_indices[mc_case_to_tri_range[c] .. mc_case_to_tri_range[c + 1]],
// three cell edges each, one line per case that has any. The one copy: warp-runtime's CPU
// steps read these initializers at compile time (objects/marching_cubes.rs, cpp_table.rs), and
// check mc_edge_offsets against the corner and edge tables they derive it from; so keep them
// plain: decimal integers, comments, braces.
WP_MC_TABLE static const u16 mc_case_to_tri_range[257] = {
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
};
WP_MC_TABLE static const u8 mc_tri_local_indices[2460] = {
    0, 8, 3,  // 1
    0, 1, 9,  // 2
    1, 8, 3, 9, 8, 1,  // 3
    1, 2, 10,  // 4
    0, 8, 3, 1, 2, 10,  // 5
    9, 2, 10, 0, 2, 9,  // 6
    2, 8, 3, 2, 10, 8, 10, 9, 8,  // 7
    3, 11, 2,  // 8
    0, 11, 2, 8, 11, 0,  // 9
    1, 9, 0, 2, 3, 11,  // 10
    1, 11, 2, 1, 9, 11, 9, 8, 11,  // 11
    3, 10, 1, 11, 10, 3,  // 12
    0, 10, 1, 0, 8, 10, 8, 11, 10,  // 13
    3, 9, 0, 3, 11, 9, 11, 10, 9,  // 14
    9, 8, 10, 10, 8, 11,  // 15
    4, 7, 8,  // 16
    4, 3, 0, 7, 3, 4,  // 17
    0, 1, 9, 8, 4, 7,  // 18
    4, 1, 9, 4, 7, 1, 7, 3, 1,  // 19
    1, 2, 10, 8, 4, 7,  // 20
    3, 4, 7, 3, 0, 4, 1, 2, 10,  // 21
    9, 2, 10, 9, 0, 2, 8, 4, 7,  // 22
    2, 10, 9, 2, 9, 7, 2, 7, 3, 7, 9, 4,  // 23
    8, 4, 7, 3, 11, 2,  // 24
    11, 4, 7, 11, 2, 4, 2, 0, 4,  // 25
    9, 0, 1, 8, 4, 7, 2, 3, 11,  // 26
    4, 7, 11, 9, 4, 11, 9, 11, 2, 9, 2, 1,  // 27
    3, 10, 1, 3, 11, 10, 7, 8, 4,  // 28
    1, 11, 10, 1, 4, 11, 1, 0, 4, 7, 11, 4,  // 29
    4, 7, 8, 9, 0, 11, 9, 11, 10, 11, 0, 3,  // 30
    4, 7, 11, 4, 11, 9, 9, 11, 10,  // 31
    9, 5, 4,  // 32
    9, 5, 4, 0, 8, 3,  // 33
    0, 5, 4, 1, 5, 0,  // 34
    8, 5, 4, 8, 3, 5, 3, 1, 5,  // 35
    1, 2, 10, 9, 5, 4,  // 36
    3, 0, 8, 1, 2, 10, 4, 9, 5,  // 37
    5, 2, 10, 5, 4, 2, 4, 0, 2,  // 38
    2, 10, 5, 3, 2, 5, 3, 5, 4, 3, 4, 8,  // 39
    9, 5, 4, 2, 3, 11,  // 40
    0, 11, 2, 0, 8, 11, 4, 9, 5,  // 41
    0, 5, 4, 0, 1, 5, 2, 3, 11,  // 42
    2, 1, 5, 2, 5, 8, 2, 8, 11, 4, 8, 5,  // 43
    10, 3, 11, 10, 1, 3, 9, 5, 4,  // 44
    4, 9, 5, 0, 8, 1, 8, 10, 1, 8, 11, 10,  // 45
    5, 4, 0, 5, 0, 11, 5, 11, 10, 11, 0, 3,  // 46
    5, 4, 8, 5, 8, 10, 10, 8, 11,  // 47
    9, 7, 8, 5, 7, 9,  // 48
    9, 3, 0, 9, 5, 3, 5, 7, 3,  // 49
    0, 7, 8, 0, 1, 7, 1, 5, 7,  // 50
    1, 5, 3, 3, 5, 7,  // 51
    9, 7, 8, 9, 5, 7, 10, 1, 2,  // 52
    10, 1, 2, 9, 5, 0, 5, 3, 0, 5, 7, 3,  // 53
    8, 0, 2, 8, 2, 5, 8, 5, 7, 10, 5, 2,  // 54
    2, 10, 5, 2, 5, 3, 3, 5, 7,  // 55
    7, 9, 5, 7, 8, 9, 3, 11, 2,  // 56
    9, 5, 7, 9, 7, 2, 9, 2, 0, 2, 7, 11,  // 57
    2, 3, 11, 0, 1, 8, 1, 7, 8, 1, 5, 7,  // 58
    11, 2, 1, 11, 1, 7, 7, 1, 5,  // 59
    9, 5, 8, 8, 5, 7, 10, 1, 3, 10, 3, 11,  // 60
    5, 7, 0, 5, 0, 9, 7, 11, 0, 1, 0, 10, 11, 10, 0,  // 61
    11, 10, 0, 11, 0, 3, 10, 5, 0, 8, 0, 7, 5, 7, 0,  // 62
    11, 10, 5, 7, 11, 5,  // 63
    10, 6, 5,  // 64
    0, 8, 3, 5, 10, 6,  // 65
    9, 0, 1, 5, 10, 6,  // 66
    1, 8, 3, 1, 9, 8, 5, 10, 6,  // 67
    1, 6, 5, 2, 6, 1,  // 68
    1, 6, 5, 1, 2, 6, 3, 0, 8,  // 69
    9, 6, 5, 9, 0, 6, 0, 2, 6,  // 70
    5, 9, 8, 5, 8, 2, 5, 2, 6, 3, 2, 8,  // 71
    2, 3, 11, 10, 6, 5,  // 72
    11, 0, 8, 11, 2, 0, 10, 6, 5,  // 73
    0, 1, 9, 2, 3, 11, 5, 10, 6,  // 74
    5, 10, 6, 1, 9, 2, 9, 11, 2, 9, 8, 11,  // 75
    6, 3, 11, 6, 5, 3, 5, 1, 3,  // 76
    0, 8, 11, 0, 11, 5, 0, 5, 1, 5, 11, 6,  // 77
    3, 11, 6, 0, 3, 6, 0, 6, 5, 0, 5, 9,  // 78
    6, 5, 9, 6, 9, 11, 11, 9, 8,  // 79
    5, 10, 6, 4, 7, 8,  // 80
    4, 3, 0, 4, 7, 3, 6, 5, 10,  // 81
    1, 9, 0, 5, 10, 6, 8, 4, 7,  // 82
    10, 6, 5, 1, 9, 7, 1, 7, 3, 7, 9, 4,  // 83
    6, 1, 2, 6, 5, 1, 4, 7, 8,  // 84
    1, 2, 5, 5, 2, 6, 3, 0, 4, 3, 4, 7,  // 85
    8, 4, 7, 9, 0, 5, 0, 6, 5, 0, 2, 6,  // 86
    7, 3, 9, 7, 9, 4, 3, 2, 9, 5, 9, 6, 2, 6, 9,  // 87
    3, 11, 2, 7, 8, 4, 10, 6, 5,  // 88
    5, 10, 6, 4, 7, 2, 4, 2, 0, 2, 7, 11,  // 89
    0, 1, 9, 4, 7, 8, 2, 3, 11, 5, 10, 6,  // 90
    9, 2, 1, 9, 11, 2, 9, 4, 11, 7, 11, 4, 5, 10, 6,  // 91
    8, 4, 7, 3, 11, 5, 3, 5, 1, 5, 11, 6,  // 92
    5, 1, 11, 5, 11, 6, 1, 0, 11, 7, 11, 4, 0, 4, 11,  // 93
    0, 5, 9, 0, 6, 5, 0, 3, 6, 11, 6, 3, 8, 4, 7,  // 94
    6, 5, 9, 6, 9, 11, 4, 7, 9, 7, 11, 9,  // 95
    10, 4, 9, 6, 4, 10,  // 96
    4, 10, 6, 4, 9, 10, 0, 8, 3,  // 97
    10, 0, 1, 10, 6, 0, 6, 4, 0,  // 98
    8, 3, 1, 8, 1, 6, 8, 6, 4, 6, 1, 10,  // 99
    1, 4, 9, 1, 2, 4, 2, 6, 4,  // 100
    3, 0, 8, 1, 2, 9, 2, 4, 9, 2, 6, 4,  // 101
    0, 2, 4, 4, 2, 6,  // 102
    8, 3, 2, 8, 2, 4, 4, 2, 6,  // 103
    10, 4, 9, 10, 6, 4, 11, 2, 3,  // 104
    0, 8, 2, 2, 8, 11, 4, 9, 10, 4, 10, 6,  // 105
    3, 11, 2, 0, 1, 6, 0, 6, 4, 6, 1, 10,  // 106
    6, 4, 1, 6, 1, 10, 4, 8, 1, 2, 1, 11, 8, 11, 1,  // 107
    9, 6, 4, 9, 3, 6, 9, 1, 3, 11, 6, 3,  // 108
    8, 11, 1, 8, 1, 0, 11, 6, 1, 9, 1, 4, 6, 4, 1,  // 109
    3, 11, 6, 3, 6, 0, 0, 6, 4,  // 110
    6, 4, 8, 11, 6, 8,  // 111
    7, 10, 6, 7, 8, 10, 8, 9, 10,  // 112
    0, 7, 3, 0, 10, 7, 0, 9, 10, 6, 7, 10,  // 113
    10, 6, 7, 1, 10, 7, 1, 7, 8, 1, 8, 0,  // 114
    10, 6, 7, 10, 7, 1, 1, 7, 3,  // 115
    1, 2, 6, 1, 6, 8, 1, 8, 9, 8, 6, 7,  // 116
    2, 6, 9, 2, 9, 1, 6, 7, 9, 0, 9, 3, 7, 3, 9,  // 117
    7, 8, 0, 7, 0, 6, 6, 0, 2,  // 118
    7, 3, 2, 6, 7, 2,  // 119
    2, 3, 11, 10, 6, 8, 10, 8, 9, 8, 6, 7,  // 120
    2, 0, 7, 2, 7, 11, 0, 9, 7, 6, 7, 10, 9, 10, 7,  // 121
    1, 8, 0, 1, 7, 8, 1, 10, 7, 6, 7, 10, 2, 3, 11,  // 122
    11, 2, 1, 11, 1, 7, 10, 6, 1, 6, 7, 1,  // 123
    8, 9, 6, 8, 6, 7, 9, 1, 6, 11, 6, 3, 1, 3, 6,  // 124
    0, 9, 1, 11, 6, 7,  // 125
    7, 8, 0, 7, 0, 6, 3, 11, 0, 11, 6, 0,  // 126
    7, 11, 6,  // 127
    7, 6, 11,  // 128
    3, 0, 8, 11, 7, 6,  // 129
    0, 1, 9, 11, 7, 6,  // 130
    8, 1, 9, 8, 3, 1, 11, 7, 6,  // 131
    10, 1, 2, 6, 11, 7,  // 132
    1, 2, 10, 3, 0, 8, 6, 11, 7,  // 133
    2, 9, 0, 2, 10, 9, 6, 11, 7,  // 134
    6, 11, 7, 2, 10, 3, 10, 8, 3, 10, 9, 8,  // 135
    7, 2, 3, 6, 2, 7,  // 136
    7, 0, 8, 7, 6, 0, 6, 2, 0,  // 137
    2, 7, 6, 2, 3, 7, 0, 1, 9,  // 138
    1, 6, 2, 1, 8, 6, 1, 9, 8, 8, 7, 6,  // 139
    10, 7, 6, 10, 1, 7, 1, 3, 7,  // 140
    10, 7, 6, 1, 7, 10, 1, 8, 7, 1, 0, 8,  // 141
    0, 3, 7, 0, 7, 10, 0, 10, 9, 6, 10, 7,  // 142
    7, 6, 10, 7, 10, 8, 8, 10, 9,  // 143
    6, 8, 4, 11, 8, 6,  // 144
    3, 6, 11, 3, 0, 6, 0, 4, 6,  // 145
    8, 6, 11, 8, 4, 6, 9, 0, 1,  // 146
    9, 4, 6, 9, 6, 3, 9, 3, 1, 11, 3, 6,  // 147
    6, 8, 4, 6, 11, 8, 2, 10, 1,  // 148
    1, 2, 10, 3, 0, 11, 0, 6, 11, 0, 4, 6,  // 149
    4, 11, 8, 4, 6, 11, 0, 2, 9, 2, 10, 9,  // 150
    10, 9, 3, 10, 3, 2, 9, 4, 3, 11, 3, 6, 4, 6, 3,  // 151
    8, 2, 3, 8, 4, 2, 4, 6, 2,  // 152
    0, 4, 2, 4, 6, 2,  // 153
    1, 9, 0, 2, 3, 4, 2, 4, 6, 4, 3, 8,  // 154
    1, 9, 4, 1, 4, 2, 2, 4, 6,  // 155
    8, 1, 3, 8, 6, 1, 8, 4, 6, 6, 10, 1,  // 156
    10, 1, 0, 10, 0, 6, 6, 0, 4,  // 157
    4, 6, 3, 4, 3, 8, 6, 10, 3, 0, 3, 9, 10, 9, 3,  // 158
    10, 9, 4, 6, 10, 4,  // 159
    4, 9, 5, 7, 6, 11,  // 160
    0, 8, 3, 4, 9, 5, 11, 7, 6,  // 161
    5, 0, 1, 5, 4, 0, 7, 6, 11,  // 162
    11, 7, 6, 8, 3, 4, 3, 5, 4, 3, 1, 5,  // 163
    9, 5, 4, 10, 1, 2, 7, 6, 11,  // 164
    6, 11, 7, 1, 2, 10, 0, 8, 3, 4, 9, 5,  // 165
    7, 6, 11, 5, 4, 10, 4, 2, 10, 4, 0, 2,  // 166
    3, 4, 8, 3, 5, 4, 3, 2, 5, 10, 5, 2, 11, 7, 6,  // 167
    7, 2, 3, 7, 6, 2, 5, 4, 9,  // 168
    9, 5, 4, 0, 8, 6, 0, 6, 2, 6, 8, 7,  // 169
    3, 6, 2, 3, 7, 6, 1, 5, 0, 5, 4, 0,  // 170
    6, 2, 8, 6, 8, 7, 2, 1, 8, 4, 8, 5, 1, 5, 8,  // 171
    9, 5, 4, 10, 1, 6, 1, 7, 6, 1, 3, 7,  // 172
    1, 6, 10, 1, 7, 6, 1, 0, 7, 8, 7, 0, 9, 5, 4,  // 173
    4, 0, 10, 4, 10, 5, 0, 3, 10, 6, 10, 7, 3, 7, 10,  // 174
    7, 6, 10, 7, 10, 8, 5, 4, 10, 4, 8, 10,  // 175
    6, 9, 5, 6, 11, 9, 11, 8, 9,  // 176
    3, 6, 11, 0, 6, 3, 0, 5, 6, 0, 9, 5,  // 177
    0, 11, 8, 0, 5, 11, 0, 1, 5, 5, 6, 11,  // 178
    6, 11, 3, 6, 3, 5, 5, 3, 1,  // 179
    1, 2, 10, 9, 5, 11, 9, 11, 8, 11, 5, 6,  // 180
    0, 11, 3, 0, 6, 11, 0, 9, 6, 5, 6, 9, 1, 2, 10,  // 181
    11, 8, 5, 11, 5, 6, 8, 0, 5, 10, 5, 2, 0, 2, 5,  // 182
    6, 11, 3, 6, 3, 5, 2, 10, 3, 10, 5, 3,  // 183
    5, 8, 9, 5, 2, 8, 5, 6, 2, 3, 8, 2,  // 184
    9, 5, 6, 9, 6, 0, 0, 6, 2,  // 185
    1, 5, 8, 1, 8, 0, 5, 6, 8, 3, 8, 2, 6, 2, 8,  // 186
    1, 5, 6, 2, 1, 6,  // 187
    1, 3, 6, 1, 6, 10, 3, 8, 6, 5, 6, 9, 8, 9, 6,  // 188
    10, 1, 0, 10, 0, 6, 9, 5, 0, 5, 6, 0,  // 189
    0, 3, 8, 5, 6, 10,  // 190
    10, 5, 6,  // 191
    11, 5, 10, 7, 5, 11,  // 192
    11, 5, 10, 11, 7, 5, 8, 3, 0,  // 193
    5, 11, 7, 5, 10, 11, 1, 9, 0,  // 194
    10, 7, 5, 10, 11, 7, 9, 8, 1, 8, 3, 1,  // 195
    11, 1, 2, 11, 7, 1, 7, 5, 1,  // 196
    0, 8, 3, 1, 2, 7, 1, 7, 5, 7, 2, 11,  // 197
    9, 7, 5, 9, 2, 7, 9, 0, 2, 2, 11, 7,  // 198
    7, 5, 2, 7, 2, 11, 5, 9, 2, 3, 2, 8, 9, 8, 2,  // 199
    2, 5, 10, 2, 3, 5, 3, 7, 5,  // 200
    8, 2, 0, 8, 5, 2, 8, 7, 5, 10, 2, 5,  // 201
    9, 0, 1, 5, 10, 3, 5, 3, 7, 3, 10, 2,  // 202
    9, 8, 2, 9, 2, 1, 8, 7, 2, 10, 2, 5, 7, 5, 2,  // 203
    1, 3, 5, 3, 7, 5,  // 204
    0, 8, 7, 0, 7, 1, 1, 7, 5,  // 205
    9, 0, 3, 9, 3, 5, 5, 3, 7,  // 206
    9, 8, 7, 5, 9, 7,  // 207
    5, 8, 4, 5, 10, 8, 10, 11, 8,  // 208
    5, 0, 4, 5, 11, 0, 5, 10, 11, 11, 3, 0,  // 209
    0, 1, 9, 8, 4, 10, 8, 10, 11, 10, 4, 5,  // 210
    10, 11, 4, 10, 4, 5, 11, 3, 4, 9, 4, 1, 3, 1, 4,  // 211
    2, 5, 1, 2, 8, 5, 2, 11, 8, 4, 5, 8,  // 212
    0, 4, 11, 0, 11, 3, 4, 5, 11, 2, 11, 1, 5, 1, 11,  // 213
    0, 2, 5, 0, 5, 9, 2, 11, 5, 4, 5, 8, 11, 8, 5,  // 214
    9, 4, 5, 2, 11, 3,  // 215
    2, 5, 10, 3, 5, 2, 3, 4, 5, 3, 8, 4,  // 216
    5, 10, 2, 5, 2, 4, 4, 2, 0,  // 217
    3, 10, 2, 3, 5, 10, 3, 8, 5, 4, 5, 8, 0, 1, 9,  // 218
    5, 10, 2, 5, 2, 4, 1, 9, 2, 9, 4, 2,  // 219
    8, 4, 5, 8, 5, 3, 3, 5, 1,  // 220
    0, 4, 5, 1, 0, 5,  // 221
    8, 4, 5, 8, 5, 3, 9, 0, 5, 0, 3, 5,  // 222
    9, 4, 5,  // 223
    4, 11, 7, 4, 9, 11, 9, 10, 11,  // 224
    0, 8, 3, 4, 9, 7, 9, 11, 7, 9, 10, 11,  // 225
    1, 10, 11, 1, 11, 4, 1, 4, 0, 7, 4, 11,  // 226
    3, 1, 4, 3, 4, 8, 1, 10, 4, 7, 4, 11, 10, 11, 4,  // 227
    4, 11, 7, 9, 11, 4, 9, 2, 11, 9, 1, 2,  // 228
    9, 7, 4, 9, 11, 7, 9, 1, 11, 2, 11, 1, 0, 8, 3,  // 229
    11, 7, 4, 11, 4, 2, 2, 4, 0,  // 230
    11, 7, 4, 11, 4, 2, 8, 3, 4, 3, 2, 4,  // 231
    2, 9, 10, 2, 7, 9, 2, 3, 7, 7, 4, 9,  // 232
    9, 10, 7, 9, 7, 4, 10, 2, 7, 8, 7, 0, 2, 0, 7,  // 233
    3, 7, 10, 3, 10, 2, 7, 4, 10, 1, 10, 0, 4, 0, 10,  // 234
    1, 10, 2, 8, 7, 4,  // 235
    4, 9, 1, 4, 1, 7, 7, 1, 3,  // 236
    4, 9, 1, 4, 1, 7, 0, 8, 1, 8, 7, 1,  // 237
    4, 0, 3, 7, 4, 3,  // 238
    4, 8, 7,  // 239
    9, 10, 8, 10, 11, 8,  // 240
    3, 0, 9, 3, 9, 11, 11, 9, 10,  // 241
    0, 1, 10, 0, 10, 8, 8, 10, 11,  // 242
    3, 1, 10, 11, 3, 10,  // 243
    1, 2, 11, 1, 11, 9, 9, 11, 8,  // 244
    3, 0, 9, 3, 9, 11, 1, 2, 9, 2, 11, 9,  // 245
    0, 2, 11, 8, 0, 11,  // 246
    3, 2, 11,  // 247
    2, 3, 8, 2, 8, 10, 10, 8, 9,  // 248
    9, 10, 2, 0, 9, 2,  // 249
    2, 3, 8, 2, 8, 10, 0, 1, 8, 1, 10, 8,  // 250
    1, 10, 2,  // 251
    1, 3, 8, 9, 1, 8,  // 252
    0, 9, 1,  // 253
    0, 3, 8,  // 254
};
WP_MC_TABLE static const u8 mc_edge_offsets[12][4] = {
    {0, 0, 0, 0},
    {1, 0, 0, 1},
    {0, 1, 0, 0},
    {0, 0, 0, 1},
    {0, 0, 1, 0},
    {1, 0, 1, 1},
    {0, 1, 1, 0},
    {0, 0, 1, 1},
    {0, 0, 0, 2},
    {1, 0, 0, 2},
    {1, 1, 0, 2},
    {0, 1, 0, 2},
};

/// Offset of cell corner c (0..7) from the cell's node.
WP_FN i32 mc_corner_dx(i32 c) { return ((c + 1) >> 1) & 1; }
WP_FN i32 mc_corner_dy(i32 c) { return (c >> 1) & 1; }
WP_FN i32 mc_corner_dz(i32 c) { return (c >> 2) & 1; }

/// The bits set in a 3-bit edge mask.
WP_FN i32 mc_popc3(i32 m) { return (m & 1) + ((m >> 1) & 1) + ((m >> 2) & 1); }

namespace detail {
// IEEE operations that the compiler may not fuse or approximate.
#if defined(__CUDA_ARCH__)
WP_FN f32 mc_mul(f32 a, f32 b) { return __fmul_rn(a, b); }
WP_FN f32 mc_add(f32 a, f32 b) { return __fadd_rn(a, b); }
WP_FN f32 mc_sub(f32 a, f32 b) { return __fsub_rn(a, b); }
WP_FN f32 mc_div(f32 a, f32 b) { return __fdiv_rn(a, b); }
#else
WP_FN f32 mc_mul(f32 a, f32 b) { return a * b; }
WP_FN f32 mc_add(f32 a, f32 b) { return a + b; }
WP_FN f32 mc_sub(f32 a, f32 b) { return a - b; }
WP_FN f32 mc_div(f32 a, f32 b) { return a / b; }
#endif
}  // namespace detail

/// MarchingCubesCount (56 bytes): field (f32*, dims[0] * dims[1] * dims[2]), codes, vcount,
/// tcount (i32*, one per node), bad (i32*, one), dims, threshold.
struct mc_count_t {
  u64 field;
  u64 codes;
  u64 vcount;
  u64 tcount;
  u64 bad;
  i32 dims[3];
  f32 threshold;
};
static_assert(sizeof(mc_count_t) == 56, "mc_count_t layout");

/// MarchingCubesTotals (32 bytes): vscan, tscan (i32*, n each, scanned), totals (i32*, 2), n.
struct mc_totals_t {
  u64 vscan;
  u64 tscan;
  u64 totals;
  i64 n;
};
static_assert(sizeof(mc_totals_t) == 32, "mc_totals_t layout");

/// MarchingCubesEmit (96 bytes): field, codes, vscan, tscan (as above), verts (3 f32 per
/// vertex), indices (3 i32 per triangle), dims, threshold, lower (the position of node 0),
/// delta (the node spacing), num_verts, num_tris (the sizes of verts and indices).
struct mc_emit_t {
  u64 field;
  u64 codes;
  u64 vscan;
  u64 tscan;
  u64 verts;
  u64 indices;
  i32 dims[3];
  f32 threshold;
  f32 lower[3];
  f32 delta[3];
  i32 num_verts;
  i32 num_tris;
};
static_assert(sizeof(mc_emit_t) == 96, "mc_emit_t layout");

/// Node n's coordinates (n below dims[0] * dims[1] * dims[2] < 2^31).
WP_FN void mc_node(const i32* dims, i32 n, i32* i, i32* j, i32* k) {
  const u32 u = (u32)n;
  const u32 r = u / (u32)dims[2];
  *k = (i32)(u - r * (u32)dims[2]);
  *j = (i32)(r % (u32)dims[1]);
  *i = (i32)(r / (u32)dims[1]);
}

/// The count step at node n; returns whether the node's value is finite.
WP_FN bool mc_count_node(const mc_count_t& s, i32 n) {
  const f32* f = (const f32*)s.field;
  i32 i, j, k;
  mc_node(s.dims, n, &i, &j, &k);
  const i32 sz = 1, sy = s.dims[2], sx = s.dims[1] * s.dims[2];
  const bool hx = i + 1 < s.dims[0], hy = j + 1 < s.dims[1], hz = k + 1 < s.dims[2];
  const f32 thr = s.threshold;
  const f32 v0 = f[n];
  const bool o0 = v0 >= thr;
  i32 mask = 0;
  if (hx && ((f[n + sx] >= thr) != o0)) mask |= 1;
  if (hy && ((f[n + sy] >= thr) != o0)) mask |= 2;
  if (hz && ((f[n + sz] >= thr) != o0)) mask |= 4;
  i32 code = 0;
  i32 ntri = 0;
  if (hx && hy && hz) {
    for (i32 c = 0; c < 8; ++c) {
      const i32 m = n + mc_corner_dx(c) * sx + mc_corner_dy(c) * sy + mc_corner_dz(c) * sz;
      if (f[m] >= thr) code |= 1 << c;
    }
    ntri = ((i32)mc_case_to_tri_range[code + 1] - (i32)mc_case_to_tri_range[code]) / 3;
  }
  ((i32*)s.codes)[n] = code | (mask << 8);
  ((i32*)s.vcount)[n] = mc_popc3(mask);
  ((i32*)s.tcount)[n] = ntri;
  return v0 - v0 == 0.0f;
}

/// The totals step (one thread).
WP_FN void mc_totals(const mc_totals_t& s) {
  ((i32*)s.totals)[0] = ((const i32*)s.vscan)[s.n - 1];
  ((i32*)s.totals)[1] = ((const i32*)s.tscan)[s.n - 1];
}

/// The emit step at node n.
WP_FN void mc_emit_node(const mc_emit_t& s, i32 n) {
  const f32* f = (const f32*)s.field;
  const i32* codes = (const i32*)s.codes;
  const i32* vscan = (const i32*)s.vscan;
  const i32 c = codes[n];
  const i32 mask = (c >> 8) & 7;
  const i32 code = c & 255;
  const i32 sy = s.dims[2], sx = s.dims[1] * s.dims[2];
  if (mask != 0) {
    i32 idx[3];
    mc_node(s.dims, n, &idx[0], &idx[1], &idx[2]);
    const i32 stride[3] = {sx, sy, 1};
    f32 p[3];
    for (i32 a = 0; a < 3; ++a) p[a] = detail::mc_add(s.lower[a], detail::mc_mul((f32)idx[a], s.delta[a]));
    const f32 v0 = f[n];
    i32 id = vscan[n] - mc_popc3(mask);
    for (i32 a = 0; a < 3; ++a) {
      if (!((mask >> a) & 1)) continue;
      const f32 v1 = f[n + stride[a]];
      // Only overflow (both differences infinite) can make t NaN or leave [0, 1]; NaN -> 0.
      f32 t = detail::mc_div(detail::mc_sub(s.threshold, v0), detail::mc_sub(v1, v0));
      if (!(t > 0.0f)) t = 0.0f;
      else if (t > 1.0f) t = 1.0f;
      const f32 q = detail::mc_add(s.lower[a], detail::mc_mul((f32)(idx[a] + 1), s.delta[a]));
      f32 out[3] = {p[0], p[1], p[2]};
      out[a] = detail::mc_add(detail::mc_mul(p[a], detail::mc_sub(1.0f, t)), detail::mc_mul(q, t));
      if (id >= 0 && id < s.num_verts) {
        f32* v = (f32*)s.verts + 3 * (i64)id;
        v[0] = out[0];
        v[1] = out[1];
        v[2] = out[2];
      }
      ++id;
    }
  }
  const i32 lo = (i32)mc_case_to_tri_range[code];
  const i32 hi = (i32)mc_case_to_tri_range[code + 1];
  if (hi > lo) {
    const i64 first = 3 * ((i64)((const i32*)s.tscan)[n] - (hi - lo) / 3);
    if (first < 0 || first + (hi - lo) > 3 * (i64)s.num_tris) return;
    i32* out = (i32*)s.indices + first;
    for (i32 e = lo; e < hi; ++e) {
      const u8* off = mc_edge_offsets[mc_tri_local_indices[e]];
      const i32 m = n + (i32)off[0] * sx + (i32)off[1] * sy + (i32)off[2];
      const i32 mm = (codes[m] >> 8) & 7;
      out[e - lo] = vscan[m] - mc_popc3(mm) + mc_popc3(mm & ((1 << off[3]) - 1));
    }
  }
}

}  // namespace wp

// The kernels (warp-runtime's objects/marching_cubes.rs runs them through the generic
// object-step launcher, which compiles this header with WP_MARCHING_CUBES_BUILD defined once
// per GPU). Each takes one record, laid out as the Rust step's `#[repr(C)]` struct (both sides
// assert the size); grid-stride loops, one node per thread, consecutive threads on consecutive
// nodes (coalesced reads of the field and the per-node buffers).
#if defined(__CUDACC__) && defined(WP_MARCHING_CUBES_BUILD)
extern "C" __global__ void wp_mc_count(wp::mc_count_t s) {
  const wp::i32 n = s.dims[0] * s.dims[1] * s.dims[2];
  const wp::i32 stride = (wp::i32)(blockDim.x * gridDim.x);
  for (wp::i32 i = (wp::i32)(blockIdx.x * blockDim.x + threadIdx.x); i < n; i += stride) {
    // Only a NaN or infinite value reaches the atomic (off the hot path).
    if (!wp::mc_count_node(s, i)) atomicMin((wp::i32*)s.bad, i);
  }
}
extern "C" __global__ void wp_mc_totals(wp::mc_totals_t s) {
  if (blockIdx.x == 0 && threadIdx.x == 0) wp::mc_totals(s);
}
extern "C" __global__ void wp_mc_emit(wp::mc_emit_t s) {
  const wp::i32 n = s.dims[0] * s.dims[1] * s.dims[2];
  const wp::i32 stride = (wp::i32)(blockDim.x * gridDim.x);
  for (wp::i32 i = (wp::i32)(blockIdx.x * blockDim.x + threadIdx.x); i < n; i += stride)
    wp::mc_emit_node(s, i);
}
#endif
