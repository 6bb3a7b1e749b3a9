// wp.h: the whole warp-lang CUDA C++ builtin library (include this from generated code).
// Sections: wp_core.h (types, operators, integer semantics, casts, faults, arrays, ranges,
// launch grid), wp_scalar.h ("scalar"), wp_vector.h ("vector"), wp_linalg.h ("linalg"), wp_svd.h ("svd"), wp_misc.h ("misc"), wp_transform.h ("transform"), wp_spatial.h ("spatial"), wp_atomic.h ("atomic"),
// wp_rand.h ("rand": random numbers and Perlin noise), wp_hash_grid.h ("hash_grid": Warp's
// hash grid and its queries), wp_print.h (print_value).
#pragma once
#include "wp_core.h"
#include "wp_scalar.h"
#include "wp_vector.h"
#include "wp_linalg.h"
#include "wp_transform.h"
#include "wp_spatial.h"
#include "wp_matrix.h"
#include "wp_svd.h"
#include "wp_misc.h"
#include "wp_atomic.h"
#include "wp_rand.h"
#include "wp_hash_grid.h"
#include "wp_print.h"
