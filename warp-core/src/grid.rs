//! The launch grid as kernel code sees it: up to four dimensions, flattened row-major.

/// The launch dimensions (of blocks, for a tiled launch). Thread `flat` of a launch has the multi-index obtained by
/// [`Grid::unflatten`] (row-major: the last dimension varies fastest, as in Warp).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Grid {
    /// Extents; unused trailing entries are 1.
    pub dims: [usize; 4],
    /// Number of dimensions (1 to 4).
    pub ndim: usize,
    /// Product of the extents.
    pub total: usize,
    /// Threads per block: 1 for an ordinary launch. For a tiled launch (`launch_tiled`) the
    /// extents above count blocks (`tid()` is the block index) and each block runs this many
    /// lanes cooperatively.
    pub block_dim: usize,
}

impl Grid {
    /// The multi-index of thread `flat` in a grid of `N` dimensions (`N` = `self.ndim`).
    #[inline(always)]
    pub fn unflatten<const N: usize>(&self, mut flat: usize) -> [usize; N] {
        let mut out = [0usize; N];
        for d in (1..N).rev() {
            let e = self.dims[d];
            out[d] = flat % e;
            flat /= e;
        }
        if N > 0 {
            out[0] = flat;
        }
        out
    }
}
