//! The per-lane side of a block on the CPU: storage for values that differ between the lanes
//! of a block ([`PerLane`]), and the conversions between lanes and tiles (`tile(x)`:
//! [`from_lanes`], `untile`: [`untile`]).
//!
//! A tiled kernel's block runs as one task; the lanes pass (`docs/design/tiles.md`, §4) runs
//! its lane-level statements in loops over `0..bd` and keeps variables that live across
//! cooperative statements in a `PerLane`. Nothing here allocates: a `PerLane` is a fixed
//! array of [`MAX_BLOCK_DIM`] slots, a stack value.

use std::ops::{Index, IndexMut};

use bytemuck::Zeroable;

use crate::fault::{Fault, FaultKind, KResult};
pub use crate::tile::reduce::MAX_BLOCK_DIM;
use crate::tile::Tile1;

/// A value stored per lane: anything `Copy` whose all-zero bit pattern is a value (scalars,
/// `f16`, glam vectors and matrices, `#[repr(C)]` Pod structs).
pub trait LaneValue: Copy + Zeroable {}
impl<T: Copy + Zeroable> LaneValue for T {}

/// One value per lane of a block, for up to [`MAX_BLOCK_DIM`] lanes; every slot starts at
/// zero.
///
/// Indexed by lane. A lane at or past [`MAX_BLOCK_DIM`] is outside the storage and panics
/// like any array index: generated code only indexes lanes `0..bd`, and no launch has
/// `bd > 1024` (`launch_tiled` refuses it).
#[derive(Clone, Copy)]
pub struct PerLane<T> {
    lanes: [T; MAX_BLOCK_DIM],
    bd: usize,
}

impl<T: LaneValue> PerLane<T> {
    /// Zeroed storage for a block of `bd` lanes (`bd` is clamped into `1..=1024`; it sets only
    /// what `Debug` and [`PerLane::lanes`] show).
    #[inline]
    pub fn new(bd: usize) -> Self {
        PerLane {
            lanes: [T::zeroed(); MAX_BLOCK_DIM],
            bd: bd.clamp(1, MAX_BLOCK_DIM),
        }
    }

    /// Every lane holding `v`: a block-level value seen as per-lane (`tile(x)` of a value
    /// that is the same in every thread).
    #[inline]
    pub fn splat(v: T, bd: usize) -> Self {
        PerLane {
            lanes: [v; MAX_BLOCK_DIM],
            bd: bd.clamp(1, MAX_BLOCK_DIM),
        }
    }

    /// The block's lanes, `0..bd`.
    #[inline(always)]
    pub fn lanes(&self) -> &[T] {
        &self.lanes[..self.bd]
    }

    /// The block size given to [`PerLane::new`] (clamped).
    #[inline(always)]
    pub fn block_dim(&self) -> usize {
        self.bd
    }
}

/// The block's lanes only, not all 1024 slots.
impl<T: std::fmt::Debug> std::fmt::Debug for PerLane<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PerLane")
            .field("bd", &self.bd)
            .field("lanes", &&self.lanes[..self.bd])
            .finish()
    }
}

impl<T> Index<usize> for PerLane<T> {
    type Output = T;
    #[inline(always)]
    fn index(&self, lane: usize) -> &T {
        &self.lanes[lane]
    }
}

impl<T> IndexMut<usize> for PerLane<T> {
    #[inline(always)]
    fn index_mut(&mut self, lane: usize) -> &mut T {
        &mut self.lanes[lane]
    }
}

/// `tile(x)`: the tile whose element `l` is lane `l`'s value, for a block of `bd` lanes.
///
/// The width `N` must equal `bd` (the front end fixes `N` from `#[kernel(block_dim = ..)]`,
/// and the launch checks `bd` against it); a mismatch, or `bd` outside `1..=1024`, is a
/// [`FaultKind::TileWidth`] fault of `kernel`, never a panic.
#[inline]
pub fn from_lanes<T: LaneValue, const N: usize>(
    x: &PerLane<T>,
    bd: usize,
    kernel: &'static str,
) -> KResult<Tile1<T, N>> {
    if N != bd || !(1..=MAX_BLOCK_DIM).contains(&bd) {
        return width_fault(kernel, N, bd);
    }
    let mut t = Tile1 {
        data: [T::zeroed(); N],
    };
    t.data.copy_from_slice(&x.lanes[..N]);
    Ok(t)
}

/// `untile(t)` in lane `lane`: element `lane` of `t`. A lane outside the tile (only possible
/// when the block is wider than the tile, which the launch refuses) is a
/// [`FaultKind::TileWidth`] fault of `kernel`.
#[inline(always)]
pub fn untile<T: Copy, const N: usize>(
    t: &Tile1<T, N>,
    lane: usize,
    kernel: &'static str,
) -> KResult<T> {
    match t.data.get(lane) {
        Some(&v) => Ok(v),
        None => width_fault(kernel, N, lane + 1),
    }
}

/// The fault of a tile width that differs from the block's lane count.
#[cold]
#[inline(never)]
fn width_fault<T>(kernel: &'static str, width: usize, block_dim: usize) -> KResult<T> {
    Err(Fault::new(
        kernel,
        FaultKind::TileWidth { width, block_dim },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lanes_round_trip_through_a_tile() {
        let mut x = PerLane::<f32>::new(64);
        for lane in 0..64 {
            x[lane] = lane as f32 * 0.5;
        }
        let t: Tile1<f32, 64> = from_lanes(&x, 64, "k").unwrap();
        assert_eq!(t.data[10], 5.0);
        for lane in 0..64 {
            assert_eq!(untile(&t, lane, "k").unwrap(), x[lane]);
        }
        assert_eq!(x.lanes().len(), 64);
        assert_eq!(x.block_dim(), 64);
        let s = format!("{:?}", PerLane::<u8>::new(3));
        assert_eq!(s, "PerLane { bd: 3, lanes: [0, 0, 0] }");
        let v = PerLane::<glam::Vec3>::new(1024);
        assert_eq!(v[1023], glam::Vec3::ZERO);
    }

    #[test]
    fn a_width_mismatch_faults() {
        let x = PerLane::<i32>::new(32);
        let e = from_lanes::<i32, 64>(&x, 32, "k").unwrap_err();
        assert_eq!(
            e.kind,
            FaultKind::TileWidth {
                width: 64,
                block_dim: 32
            }
        );
        assert!(e.to_string().contains("width 64"), "{e}");
        assert!(from_lanes::<i32, 0>(&x, 0, "k").is_err());
        let t = Tile1::<i32, 4>::zeros();
        let e = untile(&t, 4, "k").unwrap_err();
        assert_eq!(
            e.kind,
            FaultKind::TileWidth {
                width: 4,
                block_dim: 5
            }
        );
    }
}
