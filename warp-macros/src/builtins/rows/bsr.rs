//! Block sparse matrices in kernels (section "bsr").

use super::*;

/// The sparse matrix's structure queries, row iteration and block access.
pub(super) const ROWS: &[Builtin] = rows! {
    // The sparse tier's `Bsr<B>` (warp-core `objects::bsr`, wp_bsr.h), warp-lang's own: Warp
    // reads its `BsrMatrix` in kernels through its arrays. Indices are `i32` (the matrix's);
    // a row outside `0..nrow` or a slot outside `0..nnz` faults on the matrix's parameter.
    // Rows are iterated as the hash grid's queries are (`for k in bsr_row(a, r)`, lowered by
    // `front::lower::query`). Kernels write values, never the structure; `bsr_block` is
    // differentiable into the values' gradient, the two writes have no adjoint.
    "bsr_nrow": NO_T, (AnyBsr) -> I32, "bsr", Zero, extension;
    "bsr_ncol": NO_T, (AnyBsr) -> I32, "bsr", Zero, extension;
    "bsr_nnz": NO_T, (AnyBsr) -> I32, "bsr", Zero, extension;
    "bsr_row": NO_T, (AnyBsr, I32) -> BSR_ROW, "bsr", Zero, extension,
        iterate("bsr_row_next", "bsr_row_done", "bsr_row_item");
    "bsr_row_next": NO_T, (AnyBsr, BSR_ROW) -> BSR_ROW, "bsr", Zero, internal;
    "bsr_row_done": NO_T, (BSR_ROW) -> BOOL, "bsr", Zero, internal;
    "bsr_row_item": NO_T, (BSR_ROW) -> I32, "bsr", Zero, internal;
    "bsr_col": NO_T, (AnyBsr, I32) -> I32, "bsr", Zero, extension;
    "bsr_block": BSR_BLOCK, (BsrOfT, I32) -> T, "bsr", Adjoint, no_tangent, extension;
    "bsr_set_block": BSR_BLOCK, (BsrOfT, I32, T) -> Unit, "bsr", Effect, no_tangent, extension;
    "bsr_add_block": BSR_BLOCK, (BsrOfT, I32, T) -> Unit, "bsr", Effect, no_tangent, extension;
    "bsr_block_index": NO_T, (AnyBsr, I32, I32) -> I32, "bsr", Zero, extension;
    "bsr_row_index": NO_T, (AnyBsr, I32) -> I32, "bsr", Zero, extension;
};
