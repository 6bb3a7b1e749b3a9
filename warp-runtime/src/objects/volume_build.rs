//! Building a NanoVDB grid where its points are: the steps behind `Volume::allocate_by_tiles`,
//! `allocate_index_by_tiles`, `allocate_by_voxels` and `allocate_by_points`, the same on every
//! device through the [`ObjectStep`] seam (rayon here, the kernels of
//! `warp-cuda/cuda/wp_volume_build.h` on a GPU, written step for step alike). A GPU build never
//! copies the points to the host: the host reads back two small records (the voxels' bbox with
//! a bad-point flag, which lays out the sort key; then the four node counts, which size the
//! grid), writes the grid's headers, and queues the rest.
//!
//! The grid is byte for byte the one warp-core's CPU builder makes from the same voxels
//! ([`nanovdb::build_from_tiles`], [`nanovdb::build_from_voxels`]), which is laid out as Warp
//! 1.19's `volume_builder.cu` lays grids out (docs/book/src/nanovdb.md, sections 2 and 6): uppers in the
//! order of their signed origins, lowers by (upper, slot), leaves by (lower, slot).
//!
//! The steps (the header's comment has each one's details):
//! 1. world points only: each point's voxel, `floor(invMatF * (p - vecF) + 0.5)` as Warp's
//!    builder computes it (f32 with NanoVDB's `fmaf` order, the rounding in f64), the first
//!    point without one (NaN, infinite, outside `i32`) recorded on the device;
//! 2. the voxels' index bbox, read back with the bad-point flag (the first of two waits): it
//!    compacts the sort key. Warp's order is the lexicographic order of the upper origin, the
//!    upper slot, the lower slot and for voxel grids the leaf slot (87 or 96 bits); a field
//!    that the bbox says cannot vary gets no bits, the others only their range's, so that
//!    typical inputs sort one 32-bit word (3 or 4 radix passes) where the whole key takes
//!    three (12). That is most of a GPU build's time: it is worth the extra wait;
//! 3. one to three rounds of: one 32-bit word of each point's compact key (least significant
//!    first), then the primitives' stable radix sort of (word, point index): an LSD sort of
//!    the whole key, so equal nodes end up as runs in Warp's node order;
//! 4. per sorted point, whether it starts a new upper, lower, leaf, voxel (two packed u64 flags),
//!    then the primitives' inclusive scans of both: every point's node ids; one thread copies
//!    the four totals, which the host reads back (the second wait);
//! 5. the host allocates the zeroed grid and writes GridData, TreeData and RootData (it knows
//!    every count now: `nanovdb::write_map` writes the map);
//! 6. value grids: the background into every table entry and leaf value;
//! 7. per sorted point at a run start, the node's links: root tiles, child masks (atomic OR) and
//!    child offsets, leaf origins and masks, `mOffset` of index grids; OnIndex: every point's
//!    voxel bit;
//! 8. the bboxes: per leaf from its mask (and OnIndex `mPrefixSum`), atomic min/max into its
//!    lower, each lower's into its upper, each upper's into the root; one thread maps the
//!    root's box to the world bbox.

use glam::{IVec3, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicI32, AtomicU64, Ordering};
use warp_core::objects::nanovdb::{
    self, grid, root, tree, GridInfo, GridType, Layout, Map, CLASS_INDEX_GRID, FLAG_BREADTH_FIRST,
    FLAG_HAS_BBOX, GRID_DATA, LEAF_BBOX_DIF, LEAF_VALUE_MASK, LOWER_CHILD_MASK, MAGIC_GRID,
    TREE_DATA, UPPER_CHILD_MASK, VERSION_BUILT,
};

use crate::array::Array;
use crate::backend::{ObjectLibrary, ObjectStep};
use crate::cpp_table;
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};
use crate::primitives::{array_scan, radix_sort_pairs};

/// The volume build library: `wp_volume_build.h` with its kernels enabled.
pub(crate) static LIBRARY: ObjectLibrary = ObjectLibrary::of("volume_build");

/// The kinds of grid the link step builds (`wp::vb_kind_*`, read from the header at compile
/// time).
const KIND_VALUE: u32 = cpp_table::integer(HEADER, "vb_kind_value");
const KIND_INDEX: u32 = cpp_table::integer(HEADER, "vb_kind_index");
const KIND_ON_INDEX: u32 = cpp_table::integer(HEADER, "vb_kind_on_index");
const HEADER: &str = include_str!("../../../warp-cuda/cuda/wp_volume_build.h");

/// `i32::MAX` in the bad-point slot: every point has a voxel.
const NO_BAD_POINT: i32 = i32::MAX;

// ------------------------------------------------------------------------------------------
// The records (each `#[repr(C)]` as the C++ struct of its kernel; both sides assert the size)
// ------------------------------------------------------------------------------------------

/// Step 1, per point `i` of `n` (`Vec3`s at `points`): its voxel into `ijk[i]` (`IVec3`), or 0
/// and the atomic lowering of the `i32` at `bad` to `i` when it has none. `inv` is the map's
/// `invMatF` (row-major), `t` its `vecF`. `wp::vb_ijk_t` (80 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildIjk {
    points: u64,
    ijk: u64,
    bad: u64,
    n: u64,
    inv: [f32; 9],
    t: [f32; 3],
}
const _: () = assert!(std::mem::size_of::<VolumeBuildIjk>() == 80);

/// Step 2, over the `n` voxels at `ijk`: their index bbox, atomically narrowed into the 6 `i32`s
/// at `bounds` (min xyz, max xyz; the caller sets them to the empty box). `wp::vb_bounds_t`
/// (24 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildBounds {
    ijk: u64,
    bounds: u64,
    n: u64,
}
const _: () = assert!(std::mem::size_of::<VolumeBuildBounds>() == 24);

/// Step 3, per point `i`: word `word` of its compact key (the layout `lo`, `bits` of
/// [`key_layout`]) into `keys[i]` (`u32`); word 0 reads point `i` and sets `perm[i] = i`,
/// words 1 and 2 read point `perm[i]` (the order so far). `wp::vb_keys_t` (136 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildKeys {
    ijk: u64,
    perm: u64,
    keys: u64,
    n: u64,
    word: u32,
    pad: u32,
    lo: [u32; 12],
    bits: [u32; 12],
}
const _: () = assert!(std::mem::size_of::<VolumeBuildKeys>() == 136);

/// Step 4, per sorted position `i`: `sorted[i] = ijk[perm[i]]`, and the packed run-start flags
/// `scan_a[i] = upper << 32 | lower`, `scan_b[i] = leaf << 32 | voxel` (`u64`s, scanned after;
/// the voxel flag only when `voxels` is nonzero). `wp::vb_flags_t` (56 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildFlags {
    ijk: u64,
    perm: u64,
    sorted: u64,
    scan_a: u64,
    scan_b: u64,
    n: u64,
    voxels: u32,
    pad: u32,
}
const _: () = assert!(std::mem::size_of::<VolumeBuildFlags>() == 56);

/// Step 4 (one thread): the totals of the `n >= 1` scanned flags into `counts[0..4]` (`i32`:
/// uppers, lowers, leaves, voxels). `wp::vb_totals_t` (32 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildTotals {
    scan_a: u64,
    scan_b: u64,
    counts: u64,
    n: u64,
}
const _: () = assert!(std::mem::size_of::<VolumeBuildTotals>() == 32);

/// Step 6, per table entry `e` of `count`: the background's `words` u32s `bg` at `base +
/// (e >> log2) * node_size + (e & (2^log2 - 1)) * stride`. `wp::vb_fill_t` (64 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildFill {
    base: u64,
    count: u64,
    node_size: u64,
    log2: u32,
    stride: u32,
    words: u32,
    pad: u32,
    bg: [u32; 6],
}
const _: () = assert!(std::mem::size_of::<VolumeBuildFill>() == 64);

/// Step 7, per sorted position: the links of the nodes whose runs start there (see the
/// module docs). Offsets are bytes from the grid's start (`grid`, its address); the sizes and
/// table offsets are the layout's. `wp::vb_link_t` (136 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildLink {
    sorted: u64,
    scan_a: u64,
    scan_b: u64,
    grid: u64,
    leaf_lower: u64,
    lower_upper: u64,
    n: u64,
    root: u64,
    tiles: u64,
    upper: u64,
    lower: u64,
    leaf: u64,
    tile_size: u32,
    up_size: u32,
    up_table: u32,
    lo_size: u32,
    lo_table: u32,
    leaf_size: u32,
    leaf_table: u32,
    stride: u32,
    kind: u32,
    pad: u32,
}
const _: () = assert!(std::mem::size_of::<VolumeBuildLink>() == 136);

/// Step 8a, per leaf `f` of `count`: its active bbox (and OnIndex `mPrefixSum`), then atomic
/// min/max into the bbox of its lower `leaf_lower[f]`. `wp::vb_leaf_box_t` (56 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildLeafBox {
    grid: u64,
    leaf: u64,
    lower: u64,
    leaf_lower: u64,
    count: u64,
    leaf_size: u32,
    leaf_table: u32,
    lo_size: u32,
    on_index: u32,
}
const _: () = assert!(std::mem::size_of::<VolumeBuildLeafBox>() == 56);

/// Step 8b, per child node `k` of `count`: atomic min/max of its bbox into its parent's (node
/// `parent_of[k]`, or node 0 when `parent_of` is 0: the root). `wp::vb_node_box_t` (48 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildNodeBox {
    grid: u64,
    child: u64,
    parent: u64,
    parent_of: u64,
    count: u64,
    child_size: u32,
    parent_size: u32,
}
const _: () = assert!(std::mem::size_of::<VolumeBuildNodeBox>() == 48);

/// Step 8c (one thread): the world bbox, the root bbox's corners mapped by `mat` and `t`.
/// `wp::vb_world_t` (112 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct VolumeBuildWorld {
    grid: u64,
    root: u64,
    mat: [f64; 9],
    t: [f64; 3],
}
const _: () = assert!(std::mem::size_of::<VolumeBuildWorld>() == 112);

// ------------------------------------------------------------------------------------------
// The steps' elements (the C++ functions of the same names, operation for operation)
// ------------------------------------------------------------------------------------------

/// Writes `v` at byte address `addr`.
///
/// # Safety
/// `addr` is aligned for `T`, inside memory the step owns, written by no other task meanwhile.
#[inline(always)]
unsafe fn put<T>(addr: u64, v: T) {
    (addr as *mut T).write(v)
}

/// Reads a `T` at byte address `addr`.
///
/// # Safety
/// `addr` is aligned for `T` and inside memory no other task writes meanwhile.
#[inline(always)]
unsafe fn get<T: Copy>(addr: u64) -> T {
    (addr as *const T).read()
}

/// Atomic OR of `bits` into the `u64` at `addr`.
///
/// # Safety
/// `addr` is 8-aligned, inside the grid, accessed only atomically during the step.
#[inline(always)]
unsafe fn or64(addr: u64, bits: u64) {
    AtomicU64::from_ptr(addr as *mut u64).fetch_or(bits, Ordering::Relaxed);
}

/// Atomic min/max of the box `from` (`[min xyz, max xyz]`) into the box at `into`.
///
/// # Safety
/// `into` is 4-aligned, 24 bytes inside the grid, accessed only atomically during the step.
#[inline(always)]
unsafe fn union_into(into: u64, from: [i32; 6]) {
    for k in 0..3 {
        AtomicI32::from_ptr((into + 4 * k as u64) as *mut i32)
            .fetch_min(from[k], Ordering::Relaxed);
        AtomicI32::from_ptr((into + 12 + 4 * k as u64) as *mut i32)
            .fetch_max(from[3 + k], Ordering::Relaxed);
    }
}

/// `vb_ijk_at`: point `i`'s voxel (written), and whether it has one.
///
/// # Safety
/// The record's arrays hold `n > i` points and voxels.
unsafe fn ijk_at(s: &VolumeBuildIjk, i: u64) -> bool {
    let p = get::<[f32; 3]>(s.points + 12 * i);
    let d = [p[0] - s.t[0], p[1] - s.t[1], p[2] - s.t[2]];
    let mut ok = true;
    let mut v = [0i32; 3];
    for (r, out) in v.iter_mut().enumerate() {
        let m = &s.inv[3 * r..3 * r + 3];
        // NanoVDB's matMult (fmaf(x, m0, fmaf(y, m1, z * m2))), then Vec3::round: floor(x +
        // 0.5) with a double 0.5 (exact for every f32).
        let x = d[0].mul_add(m[0], d[1].mul_add(m[1], d[2] * m[2]));
        let f = (x as f64 + 0.5).floor();
        // False for NaN too.
        let inside = (-2147483648.0..=2147483647.0).contains(&f);
        *out = if inside { f as i32 } else { 0 };
        ok &= inside;
    }
    if !ok {
        v = [0; 3];
    }
    put(s.ijk + 12 * i, v);
    ok
}

/// `vb_field`: field `level` (0 upper origin, 1 upper slot, 2 lower slot, 3 leaf slot) of
/// coordinate `v`.
fn field(v: i32, level: usize) -> u32 {
    let u = v as u32;
    match level {
        0 => (u ^ 0x8000_0000) >> 12,
        1 => (u >> 7) & 31,
        2 => (u >> 3) & 15,
        _ => u & 7,
    }
}

/// `vb_key_layout`: the compact key's layout for voxels in the index bbox `b` (min xyz, max
/// xyz): field `f` (level `f / 3`, axis `f % 3`, most significant first) is stored as its value
/// minus `lo[f]` in `bits[f]` bits. An upper origin ranges over the fields of the bbox's
/// corners (the field is monotone); a slot over the corners' slots when the coarser level of
/// its axis is the same at both corners, else over every slot; `leaf_slots` false leaves the
/// leaf slots out (tile grids). Returns `(lo, bits, total bits)` (at most 96). Any such layout
/// keeps the key's order, so the grid does not depend on it.
fn key_layout(b: [i32; 6], leaf_slots: bool) -> ([u32; 12], [u32; 12], u32) {
    const FULL: [u32; 4] = [0xf_ffff, 31, 15, 7];
    const PARENT_SHIFT: [u32; 4] = [0, 12, 7, 3];
    let (mut lo, mut bits, mut total) = ([0u32; 12], [0u32; 12], 0);
    for f in 0..12 {
        let (level, axis) = (f / 3, f % 3);
        let (mn, mx) = (b[axis], b[3 + axis]);
        let sh = PARENT_SHIFT[level];
        let (mut l, mut h) = (0, FULL[level]);
        if level == 0 || mn >> sh == mx >> sh {
            (l, h) = (field(mn, level), field(mx, level));
        }
        if level == 3 && !leaf_slots {
            (l, h) = (0, 0);
        }
        lo[f] = l;
        bits[f] = 32 - (h - l).leading_zeros();
        total += bits[f];
    }
    (lo, bits, total)
}

/// `vb_key_word`: word `word` (0 least significant) of voxel `c`'s compact key.
fn key_word(c: [i32; 3], word: u32, lo: &[u32; 12], bits: &[u32; 12]) -> u32 {
    let (mut hi, mut low) = (0u64, 0u64);
    for f in 0..12 {
        let b = bits[f];
        if b == 0 {
            continue;
        }
        let v = (field(c[f % 3], f / 3) - lo[f]) as u64;
        hi = (hi << b) | (low >> (64 - b));
        low = (low << b) | v;
    }
    match word {
        0 => low as u32,
        1 => (low >> 32) as u32,
        _ => hi as u32,
    }
}

/// `vb_flags_at` at sorted position `i`.
///
/// # Safety
/// The record's arrays hold `n > i` elements; `perm` is a permutation of `0..n`.
unsafe fn flags_at(s: &VolumeBuildFlags, i: u64) {
    let c = get::<[i32; 3]>(s.ijk + 12 * get::<u32>(s.perm + 4 * i) as u64);
    put(s.sorted + 12 * i, c);
    let (mut up, mut lo, mut lf, mut vx) = (1u64, 1u64, 1u64, 1u64);
    if i > 0 {
        let q = get::<[i32; 3]>(s.ijk + 12 * get::<u32>(s.perm + 4 * (i - 1)) as u64);
        // The highest differing bit of any coordinate says which levels change.
        let d =
            (c[0] as u32 ^ q[0] as u32) | (c[1] as u32 ^ q[1] as u32) | (c[2] as u32 ^ q[2] as u32);
        up = (d > 4095) as u64;
        lo = (d > 127) as u64;
        lf = (d > 7) as u64;
        vx = (d != 0) as u64;
    }
    if s.voxels == 0 {
        vx = 0;
    }
    put(s.scan_a + 8 * i, (up << 32) | lo);
    put(s.scan_b + 8 * i, (lf << 32) | vx);
}

/// `vb_fill_at` at entry `e`.
///
/// # Safety
/// The record's entries lie in the grid; each is written by one task.
unsafe fn fill_at(s: &VolumeBuildFill, e: u64) {
    let node = e >> s.log2;
    let k = e & ((1u64 << s.log2) - 1);
    let at = s.base + node * s.node_size + k * s.stride as u64;
    for w in 0..s.words as u64 {
        put(at + 4 * w, s.bg[w as usize]);
    }
}

/// `vb_slot`: the slot of `c`'s child in a node of `log2` over children of `child_bits` voxels.
fn slot(c: [i32; 3], log2: u32, child_bits: u32) -> u64 {
    let mask = (1u32 << (log2 + child_bits)) - 1;
    let [x, y, z] = c.map(|v| ((v as u32 & mask) >> child_bits) as u64);
    (x << (2 * log2)) | (y << log2) | z
}

/// `vb_empty_box`: the node's bbox ready for atomic min/max.
///
/// # Safety
/// `addr` is a node start in the grid, its bbox written by this task alone.
unsafe fn empty_box(addr: u64) {
    put(
        addr,
        [i32::MAX, i32::MAX, i32::MAX, i32::MIN, i32::MIN, i32::MIN],
    );
}

/// `vb_link_at` at sorted position `i`.
///
/// # Safety
/// The record describes a zeroed grid sized for the scans' counts and arrays of `n > i`
/// elements; a node's plain writes come from its run's first position alone (the other
/// shared words are written atomically).
unsafe fn link_at(s: &VolumeBuildLink, i: u64) {
    let c = get::<[i32; 3]>(s.sorted + 12 * i);
    let a = get::<u64>(s.scan_a + 8 * i);
    let b = get::<u64>(s.scan_b + 8 * i);
    let (pa, pb) = if i > 0 {
        (
            get::<u64>(s.scan_a + 8 * (i - 1)),
            get::<u64>(s.scan_b + 8 * (i - 1)),
        )
    } else {
        (0, 0)
    };
    const M32: u64 = 0xffff_ffff;
    let (uid, lid, fid) = ((a >> 32) - 1, (a & M32) - 1, (b >> 32) - 1);
    let upper = s.grid + s.upper + uid * s.up_size as u64;
    let lower = s.grid + s.lower + lid * s.lo_size as u64;
    let leaf = s.grid + s.leaf + fid * s.leaf_size as u64;
    if a >> 32 != pa >> 32 {
        let tile = s.grid + s.tiles + uid * s.tile_size as u64;
        put(tile + root::TILE_KEY as u64, nanovdb::root_key(c));
        put(
            tile + root::TILE_CHILD as u64,
            (upper - (s.grid + s.root)) as i64,
        );
        empty_box(upper);
    }
    if a & M32 != pa & M32 {
        let sl = slot(c, 5, 7);
        or64(
            upper + UPPER_CHILD_MASK as u64 + 8 * (sl >> 6),
            1 << (sl & 63),
        );
        put(
            upper + s.up_table as u64 + sl * s.stride as u64,
            (lower - upper) as i64,
        );
        empty_box(lower);
        put(s.lower_upper + 4 * lid, uid as u32);
    }
    if b >> 32 != pb >> 32 {
        let sl = slot(c, 4, 3);
        or64(
            lower + LOWER_CHILD_MASK as u64 + 8 * (sl >> 6),
            1 << (sl & 63),
        );
        put(
            lower + s.lo_table as u64 + sl * s.stride as u64,
            (leaf - lower) as i64,
        );
        put(leaf, c.map(|x| x & !7));
        put(leaf + LEAF_BBOX_DIF as u64, 2u32 << 24);
        if s.kind == KIND_ON_INDEX {
            put(leaf + s.leaf_table as u64, b & M32);
        } else {
            put(leaf + LEAF_VALUE_MASK as u64, [u64::MAX; 8]);
            if s.kind == KIND_INDEX {
                put(leaf + s.leaf_table as u64, fid * 512 + 1);
            }
        }
        put(s.leaf_lower + 4 * fid, lid as u32);
    }
    if s.kind == KIND_ON_INDEX {
        let sl = slot(c, 3, 0);
        or64(
            leaf + LEAF_VALUE_MASK as u64 + 8 * (sl >> 6),
            1 << (sl & 63),
        );
    }
}

/// `vb_leaf_box_at` at leaf `f`.
///
/// # Safety
/// The record describes the linked grid; leaf `f` is this task's, its lower's bbox is written
/// atomically only.
unsafe fn leaf_box_at(s: &VolumeBuildLeafBox, f: u64) {
    let leaf = s.grid + s.leaf + f * s.leaf_size as u64;
    let o = get::<[i32; 3]>(leaf);
    let words = get::<[u64; 8]>(leaf + LEAF_VALUE_MASK as u64);
    let any = words.iter().fold(0, |a, w| a | w);
    // Every leaf has an active voxel by construction; an empty one keeps its origin.
    if any == 0 {
        return;
    }
    // The mask word is x; bits 3..6 of a word are y, bits 0..3 z.
    let x0 = words.iter().position(|w| *w != 0).unwrap_or(0) as i32;
    let x1 = words.iter().rposition(|w| *w != 0).unwrap_or(0) as i32;
    let (y0, y1) = (
        any.trailing_zeros() as i32 >> 3,
        (63 - any.leading_zeros() as i32) >> 3,
    );
    let zs = (0..8).fold(0u64, |a, y| a | ((any >> (8 * y)) & 0xff));
    let (z0, z1) = (zs.trailing_zeros() as i32, 63 - zs.leading_zeros() as i32);
    let bx = [
        o[0] + x0,
        o[1] + y0,
        o[2] + z0,
        o[0] + x1,
        o[1] + y1,
        o[2] + z1,
    ];
    put(leaf, [bx[0], bx[1], bx[2]]);
    let dif = (x1 - x0) as u32 | ((y1 - y0) as u32) << 8 | ((z1 - z0) as u32) << 16;
    put(leaf + LEAF_BBOX_DIF as u64, dif | 2 << 24);
    if s.on_index != 0 {
        let (mut sum, mut prefix) = (0u64, 0u64);
        for (w, word) in words[..7].iter().enumerate() {
            sum += word.count_ones() as u64;
            prefix |= sum << (9 * w);
        }
        put(leaf + s.leaf_table as u64 + 8, prefix);
    }
    let lid = get::<u32>(s.leaf_lower + 4 * f) as u64;
    union_into(s.grid + s.lower + lid * s.lo_size as u64, bx);
}

/// `vb_node_box_at` at child `k`.
///
/// # Safety
/// The record describes the grid; the parents' bboxes are written atomically only.
unsafe fn node_box_at(s: &VolumeBuildNodeBox, k: u64) {
    let from = get::<[i32; 6]>(s.grid + s.child + k * s.child_size as u64);
    let parent = if s.parent_of != 0 {
        get::<u32>(s.parent_of + 4 * k) as u64
    } else {
        0
    };
    union_into(s.grid + s.parent + parent * s.parent_size as u64, from);
}

/// `vb_world`: the world bbox from the root's index bbox.
///
/// # Safety
/// The record's grid holds a RootData at `root`; nothing else runs on it meanwhile.
unsafe fn world(s: &VolumeBuildWorld) {
    let b = get::<[i32; 6]>(s.grid + s.root);
    let (mut lo, mut hi) = ([f64::MAX; 3], [-f64::MAX; 3]);
    for corner in 0..8 {
        let p: [f64; 3] = std::array::from_fn(|c| b[((corner >> c) & 1) * 3 + c] as f64);
        for r in 0..3 {
            let m = &s.mat[3 * r..3 * r + 3];
            let q = m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + s.t[r];
            if q < lo[r] {
                lo[r] = q;
            }
            if q > hi[r] {
                hi[r] = q;
            }
        }
    }
    put(
        s.grid + grid::WORLD_BBOX as u64,
        [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]],
    );
}

/// Runs `f` over `0..n` with rayon (chunks of at least 4096: the elements are cheap).
fn par(n: u64, f: impl Fn(u64) + Sync + Send) {
    (0..n as usize)
        .into_par_iter()
        .with_min_len(4096)
        .for_each(|i| f(i as u64));
}

// SAFETY (every step): `#[repr(C)]` records laid out as the C++ structs of
// `wp_volume_build.h` (both sides assert the sizes); `build` passes addresses of arrays and a
// grid it allocated on the step's device, sized for the record's counts (the grid from the
// scanned counts it read back), and runs the steps in order, so each step's reads see the
// previous steps' writes; within a step the plain writes of two elements never overlap and
// shared words are only touched atomically (the functions above say which).
unsafe impl ObjectStep for VolumeBuildIjk {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_ijk";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: a 1-element i32 array, aligned.
        let bad = unsafe { AtomicI32::from_ptr(self.bad as *mut i32) };
        par(self.n, |i| {
            // SAFETY: see the impl's comment; point `i` and voxel `i` are this task's.
            if !unsafe { ijk_at(self, i) } {
                bad.fetch_min(i as i32, Ordering::Relaxed);
            }
        });
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildBounds {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_bounds";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        const EMPTY: [i32; 6] = [i32::MAX, i32::MAX, i32::MAX, i32::MIN, i32::MIN, i32::MIN];
        let b = (0..self.n as usize)
            .into_par_iter()
            .with_min_len(4096)
            .fold(
                || EMPTY,
                |mut acc, i| {
                    // SAFETY: see the impl's comment; voxel `i` is read only.
                    let c = unsafe { get::<[i32; 3]>(self.ijk + 12 * i as u64) };
                    for a in 0..3 {
                        acc[a] = acc[a].min(c[a]);
                        acc[3 + a] = acc[3 + a].max(c[a]);
                    }
                    acc
                },
            )
            .reduce(
                || EMPTY,
                |x, y| {
                    std::array::from_fn(|k| {
                        if k < 3 {
                            x[k].min(y[k])
                        } else {
                            x[k].max(y[k])
                        }
                    })
                },
            );
        // SAFETY: 6 aligned i32s of the build's own array, touched by nothing else meanwhile.
        unsafe { union_into(self.bounds, b) };
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildKeys {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_keys";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        par(self.n, |i| {
            // SAFETY: see the impl's comment; `keys[i]` and `perm[i]` are this task's.
            unsafe {
                let p = if self.word == 0 {
                    put(self.perm + 4 * i, i as u32);
                    i
                } else {
                    get::<u32>(self.perm + 4 * i) as u64
                };
                let c = get::<[i32; 3]>(self.ijk + 12 * p);
                put(
                    self.keys + 4 * i,
                    key_word(c, self.word, &self.lo, &self.bits),
                );
            }
        });
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildFlags {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_flags";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl's comment; position `i`'s outputs are this task's.
        par(self.n, |i| unsafe { flags_at(self, i) });
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildTotals {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_totals";
    fn len(&self) -> usize {
        1
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl's comment (`n >= 1` scanned flags, 4 counts).
        unsafe {
            let a = get::<u64>(self.scan_a + 8 * (self.n - 1));
            let b = get::<u64>(self.scan_b + 8 * (self.n - 1));
            put(
                self.counts,
                [
                    (a >> 32) as i32,
                    (a & 0xffff_ffff) as i32,
                    (b >> 32) as i32,
                    (b & 0xffff_ffff) as i32,
                ],
            );
        }
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildFill {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_fill";
    fn len(&self) -> usize {
        self.count as usize
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl's comment; entry `e` is this task's.
        par(self.count, |e| unsafe { fill_at(self, e) });
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildLink {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_link";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl's comment and `link_at`'s.
        par(self.n, |i| unsafe { link_at(self, i) });
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildLeafBox {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_leaf_box";
    fn len(&self) -> usize {
        self.count as usize
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl's comment and `leaf_box_at`'s.
        par(self.count, |f| unsafe { leaf_box_at(self, f) });
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildNodeBox {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_node_box";
    fn len(&self) -> usize {
        self.count as usize
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl's comment and `node_box_at`'s.
        par(self.count, |k| unsafe { node_box_at(self, k) });
        Ok(())
    }
}

unsafe impl ObjectStep for VolumeBuildWorld {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_vb_world";
    fn len(&self) -> usize {
        1
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl's comment.
        unsafe { world(self) };
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// The build
// ------------------------------------------------------------------------------------------

/// What a build makes.
#[derive(Clone, Copy, Debug)]
pub(crate) enum GridKind<'a> {
    /// A value grid of `grid_type` over tiles (every leaf voxel active), every value and table
    /// entry the `background` bytes.
    Value {
        /// The value type (Float, Double, Int32, Vec3f, Vec3d).
        grid_type: GridType,
        /// The background's little-endian bytes.
        background: &'a [u8],
    },
    /// An Index grid over tiles (`mOffset = leaf * 512 + 1`).
    Index,
    /// An OnIndex grid over exactly the given voxels.
    OnIndex,
}

/// Where a build's voxels come from.
#[derive(Clone, Copy, Debug)]
pub(crate) enum BuildInput<'a> {
    /// Index-space coordinates (tiles: any voxel of a leaf names it).
    Coords(&'a Array<IVec3>),
    /// World positions, each rounded to its voxel as Warp rounds them.
    World(&'a Array<Vec3>),
}

/// A built grid on the input's device: its words, what `nanovdb::validate` says of it, and
/// its active voxel count.
pub(crate) struct BuiltGrid {
    /// The grid's bytes as little-endian words (32-byte aligned: device allocations are).
    pub words: Array<u64>,
    /// The grid's facts, as `nanovdb::validate` decodes them.
    pub info: GridInfo,
    /// TreeData's active voxel count.
    pub voxel_count: u64,
}

/// The node counts the second read-back gives.
#[derive(Clone, Copy, Debug, Default)]
struct Counts {
    uppers: u64,
    lowers: u64,
    leaves: u64,
    voxels: u64,
}

/// Where each part of the grid starts (bytes from its start), and its size.
#[derive(Clone, Copy, Debug)]
struct Placement {
    root: u64,
    tiles: u64,
    upper: u64,
    lower: u64,
    leaf: u64,
    size: u64,
}

impl Placement {
    /// The breadth-first layout of `c`'s nodes (the CPU builder's, Warp's).
    fn of(l: &Layout, c: &Counts) -> Option<Placement> {
        let root = (GRID_DATA + TREE_DATA) as u64;
        let tiles = root + l.root_size as u64;
        let upper = tiles.checked_add(c.uppers.checked_mul(l.tile_size as u64)?)?;
        let lower = upper.checked_add(c.uppers.checked_mul(l.up_size as u64)?)?;
        let leaf = lower.checked_add(c.lowers.checked_mul(l.lo_size as u64)?)?;
        let size = leaf.checked_add(c.leaves.checked_mul(l.leaf_size as u64)?)?;
        (size <= isize::MAX as u64).then_some(Placement {
            root,
            tiles,
            upper,
            lower,
            leaf,
            size,
        })
    }
}

/// Copies `bytes` into `b` at `at`.
fn put_bytes(b: &mut [u8], at: usize, bytes: &[u8]) {
    b[at..at + bytes.len()].copy_from_slice(bytes);
}

/// GridData, TreeData and RootData (everything before the root tiles), as the CPU builder
/// writes them, except the bboxes the steps compute: the root's is empty (ready for atomic
/// min/max), the world bbox that of an empty grid (the world step overwrites it when there
/// are nodes).
fn headers(
    grid_type: GridType,
    background: Option<&[u8]>,
    l: &Layout,
    c: &Counts,
    at: &Placement,
    voxel_count: u64,
    map: &Map,
) -> std::result::Result<Vec<u8>, String> {
    let mut h = vec![0u8; at.tiles as usize];
    put_bytes(&mut h, 0, &MAGIC_GRID.to_le_bytes());
    put_bytes(&mut h, grid::CHECKSUM, &u64::MAX.to_le_bytes());
    put_bytes(&mut h, grid::VERSION, &VERSION_BUILT.to_le_bytes());
    let flags = FLAG_HAS_BBOX | FLAG_BREADTH_FIRST;
    put_bytes(&mut h, grid::FLAGS, &flags.to_le_bytes());
    put_bytes(&mut h, grid::INDEX, &0u32.to_le_bytes());
    put_bytes(&mut h, grid::COUNT, &1u32.to_le_bytes());
    put_bytes(&mut h, grid::SIZE, &at.size.to_le_bytes());
    nanovdb::write_map(&mut h, map)?;
    for (k, x) in [
        f64::MAX,
        f64::MAX,
        f64::MAX,
        -f64::MAX,
        -f64::MAX,
        -f64::MAX,
    ]
    .iter()
    .enumerate()
    {
        put_bytes(&mut h, grid::WORLD_BBOX + 8 * k, &x.to_le_bytes());
    }
    let class = if grid_type.is_index() {
        CLASS_INDEX_GRID
    } else {
        0
    };
    put_bytes(&mut h, grid::CLASS, &class.to_le_bytes());
    put_bytes(&mut h, grid::TYPE, &grid_type.code().to_le_bytes());
    put_bytes(&mut h, grid::BLIND_OFFSET, &at.size.to_le_bytes());
    if grid_type.is_index() {
        put_bytes(&mut h, grid::DATA1, &(voxel_count + 1).to_le_bytes());
    }
    for (k, off) in [at.leaf, at.lower, at.upper, at.root]
        .into_iter()
        .enumerate()
    {
        let rel = off - GRID_DATA as u64;
        put_bytes(
            &mut h,
            GRID_DATA + tree::NODE_OFFSET + 8 * k,
            &rel.to_le_bytes(),
        );
    }
    for (k, n) in [c.leaves, c.lowers, c.uppers].into_iter().enumerate() {
        let n = n as u32;
        put_bytes(
            &mut h,
            GRID_DATA + tree::NODE_COUNT + 4 * k,
            &n.to_le_bytes(),
        );
        put_bytes(
            &mut h,
            GRID_DATA + tree::TILE_COUNT + 4 * k,
            &n.to_le_bytes(),
        );
    }
    put_bytes(
        &mut h,
        GRID_DATA + tree::VOXEL_COUNT,
        &voxel_count.to_le_bytes(),
    );
    let r = at.root as usize;
    let empty: Vec<u8> = [i32::MAX, i32::MAX, i32::MAX, i32::MIN, i32::MIN, i32::MIN]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    put_bytes(&mut h, r + root::BBOX, &empty);
    put_bytes(
        &mut h,
        r + root::TABLE_SIZE,
        &(c.uppers as u32).to_le_bytes(),
    );
    if let Some(bg) = background {
        put_bytes(&mut h, r + l.background, bg);
    }
    Ok(h)
}

/// Little-endian words of `bytes` (a multiple of 8 long).
fn to_words(bytes: &[u8]) -> Vec<u64> {
    bytes
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect()
}

/// A contiguous copy of `a` when it is a strided view (the steps read flat arrays).
fn contiguous<T: crate::array::Element>(a: &Array<T>) -> Result<Array<T>> {
    if a.is_contiguous() {
        return Ok(a.clone());
    }
    let copy = Array::<T>::empty(a.len(), a.device())?;
    copy.copy_from(a)?;
    Ok(copy)
}

/// Builds the grid of `kind` over `input`'s voxels with the transform `map`, on the input's
/// device, as the module docs describe. `what` names the call in errors.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `what`: a grid type without a layout or a background of
/// the wrong size, a map without an inverse, more than `i32::MAX` points, a world point
/// without a voxel (NaN, infinite, or outside the `i32` index range: the first such point,
/// by index), a grid too large; device errors.
pub(crate) fn build(kind: GridKind, input: BuildInput, map: &Map, what: &str) -> Result<BuiltGrid> {
    let (grid_type, background, link_kind) = match kind {
        GridKind::Value {
            grid_type,
            background,
        } => (grid_type, Some(background), KIND_VALUE),
        GridKind::Index => (GridType::Index, None, KIND_INDEX),
        GridKind::OnIndex => (GridType::OnIndex, None, KIND_ON_INDEX),
    };
    let l = Layout::of(grid_type)
        .filter(|_| background.is_none() || !grid_type.is_index())
        .ok_or_else(|| {
            Error::invalid_in(
                what,
                format!("{grid_type:?} is not a grid type the builder makes"),
            )
        })?;
    if let Some(bg) = background.filter(|b| b.len() != l.value_size) {
        return Err(Error::invalid_in(
            what,
            format!(
                "a {grid_type:?} background has {} bytes, not {}",
                bg.len(),
                l.value_size
            ),
        ));
    }
    let inv = map.inverse().map_err(|e| Error::invalid_in(what, e))?;
    let (dev, n) = match input {
        BuildInput::Coords(a) => (a.device().clone(), a.len()),
        BuildInput::World(a) => (a.device().clone(), a.len()),
    };
    if n > i32::MAX as usize {
        return Err(Error::invalid_in(
            what,
            format!("{n} points: at most i32::MAX ({}) are allowed", i32::MAX),
        ));
    }
    // The build's small state, read back twice: the voxels' bbox (empty), the first point
    // without a voxel, a pad, then the four node counts.
    const EMPTY: [i32; 6] = [i32::MAX, i32::MAX, i32::MAX, i32::MIN, i32::MIN, i32::MIN];
    let mut init = [0i32; 12];
    init[..6].copy_from_slice(&EMPTY);
    init[6] = NO_BAD_POINT;
    let state = Array::from_slice(&init, &dev)?;
    let (ijk, world_points) = match input {
        BuildInput::Coords(a) => (contiguous(a)?, None),
        BuildInput::World(p) => {
            let points = contiguous(p)?;
            let ijk = Array::<IVec3>::empty(n, &dev)?;
            let f32s = |m: &[[f64; 3]; 3]| std::array::from_fn(|k| m[k / 3][k % 3] as f32);
            dispatch::object_step(
                &dev,
                &VolumeBuildIjk {
                    points: points.device_address(),
                    ijk: ijk.device_address(),
                    bad: state.device_address() + 24,
                    n: n as u64,
                    inv: f32s(&inv),
                    t: map.translation.map(|x| x as f32),
                },
            )?;
            (ijk, Some(points))
        }
    };
    // The sorted voxels and their scanned flags, for the link step.
    let mut scratch = None;
    let mut counts = Counts::default();
    if n > 0 {
        dispatch::object_step(
            &dev,
            &VolumeBuildBounds {
                ijk: ijk.device_address(),
                bounds: state.device_address(),
                n: n as u64,
            },
        )?;
        // The first wait: the bbox lays out the sort key (and a bad point ends the build).
        let head = state.view(0..7)?.to_vec()?;
        if head[6] != NO_BAD_POINT {
            let b = head[6] as usize;
            let p = match &world_points {
                Some(points) => points.view(b..b + 1)?.to_vec()?[0],
                None => Vec3::NAN,
            };
            return Err(Error::invalid_in(
                what,
                format!(
                    "point {b} ({p}) has no voxel: its index-space position is NaN, infinite \
                     or outside the i32 range (the first such point)"
                ),
            ));
        }
        let bbox: [i32; 6] = std::array::from_fn(|k| head[k]);
        let (lo, bits, total) = key_layout(bbox, link_kind == KIND_ON_INDEX);
        let keys = Array::<u32>::empty(n, &dev)?;
        let perm = Array::<u32>::empty(n, &dev)?;
        // Word 0 also sets the identity permutation, so it runs even for a key of no bits
        // (every point in one leaf, or one voxel).
        for word in 0..total.div_ceil(32).max(1) {
            dispatch::object_step(
                &dev,
                &VolumeBuildKeys {
                    ijk: ijk.device_address(),
                    perm: perm.device_address(),
                    keys: keys.device_address(),
                    n: n as u64,
                    word,
                    pad: 0,
                    lo,
                    bits,
                },
            )?;
            let word_bits = (total - 32 * word).min(32);
            if word_bits > 0 {
                radix_sort_pairs(&keys, &perm, n, Some(word_bits))?;
            }
        }
        let sorted = Array::<IVec3>::empty(n, &dev)?;
        let scan_a = Array::<u64>::empty(n, &dev)?;
        let scan_b = Array::<u64>::empty(n, &dev)?;
        dispatch::object_step(
            &dev,
            &VolumeBuildFlags {
                ijk: ijk.device_address(),
                perm: perm.device_address(),
                sorted: sorted.device_address(),
                scan_a: scan_a.device_address(),
                scan_b: scan_b.device_address(),
                n: n as u64,
                voxels: (link_kind == KIND_ON_INDEX) as u32,
                pad: 0,
            },
        )?;
        array_scan(&scan_a, &scan_a, true)?;
        array_scan(&scan_b, &scan_b, true)?;
        dispatch::object_step(
            &dev,
            &VolumeBuildTotals {
                scan_a: scan_a.device_address(),
                scan_b: scan_b.device_address(),
                counts: state.device_address() + 32,
                n: n as u64,
            },
        )?;
        scratch = Some((sorted, scan_a, scan_b));
        // The second wait: the node counts size the grid.
        let read = state.view(8..12)?.to_vec()?;
        counts = Counts {
            uppers: read[0] as u64,
            lowers: read[1] as u64,
            leaves: read[2] as u64,
            voxels: read[3] as u64,
        };
    }
    // Every count is positive and nested by construction; anything else is a broken step.
    let c = counts;
    if n > 0
        && !(1 <= c.uppers && c.uppers <= c.lowers && c.lowers <= c.leaves && c.leaves <= n as u64)
    {
        return Err(Error::invalid(format!(
            "{what}: internal error: the build counted {c:?} nodes for {n} points"
        )));
    }
    let at = Placement::of(&l, &c).ok_or_else(|| {
        Error::invalid_in(
            what,
            format!(
                "a grid of {} uppers, {} lowers and {} leaves is too large",
                c.uppers, c.lowers, c.leaves
            ),
        )
    })?;
    let voxel_count = if link_kind == KIND_ON_INDEX {
        c.voxels
    } else {
        c.leaves * 512
    };
    let h = headers(grid_type, background, &l, &c, &at, voxel_count, map)
        .map_err(|e| Error::invalid_in(what, e))?;
    let words = Array::<u64>::zeros(at.size as usize / 8, &dev)?;
    words
        .view(0..h.len() / 8)?
        .copy_from(&Array::from_slice(&to_words(&h), &dev)?)?;
    if let Some((sorted, scan_a, scan_b)) = &scratch {
        link(
            &dev, &l, &c, &at, &words, sorted, scan_a, scan_b, n, link_kind, background, map,
        )?;
    }
    let info = GridInfo {
        grid_type,
        layout: l,
        size: at.size,
        version: VERSION_BUILT,
        flags: FLAG_HAS_BBOX | FLAG_BREADTH_FIRST,
        root: at.root,
        tile_count: c.uppers as u32,
        first_upper: at.upper,
        first_lower: at.lower,
        first_leaf: at.leaf,
        upper_count: c.uppers as u32,
        lower_count: c.lowers as u32,
        leaf_count: c.leaves as u32,
    };
    // On the CPU the grid is host memory and validating it costs about what building it did:
    // check that it is what the kernels' views will assume. On a GPU that would mean reading
    // the whole grid back, which is what this builder exists to avoid: there the steps are
    // trusted (they are the same steps, and the tests compare the two devices byte for byte).
    if dev.is_cpu() {
        let bytes: Vec<u8> = words
            .to_vec()?
            .iter()
            .flat_map(|w| w.to_le_bytes())
            .collect();
        let checked = nanovdb::validate(&bytes)
            .map_err(|e| Error::invalid(format!("{what}: internal error: {e}")))?;
        if checked != info {
            return Err(Error::invalid(format!(
                "{what}: internal error: the built grid is {checked:?}, not {info:?}"
            )));
        }
    }
    Ok(BuiltGrid {
        words,
        info,
        voxel_count,
    })
}

/// Steps 6 to 8 over the sorted points and their scanned flags, into `words` (the grid with
/// its headers written).
#[allow(clippy::too_many_arguments)]
fn link(
    dev: &Device,
    l: &Layout,
    c: &Counts,
    at: &Placement,
    words: &Array<u64>,
    sorted: &Array<IVec3>,
    scan_a: &Array<u64>,
    scan_b: &Array<u64>,
    n: usize,
    kind: u32,
    background: Option<&[u8]>,
    map: &Map,
) -> Result<()> {
    let g = words.device_address();
    if let Some(bg) = background {
        let mut words = [0u32; 6];
        for (k, w) in bg.chunks_exact(4).enumerate() {
            words[k] = u32::from_le_bytes(w.try_into().expect("4 bytes"));
        }
        let levels = [
            (
                at.upper + l.up_table as u64,
                c.uppers,
                l.up_size,
                15,
                l.stride,
            ),
            (
                at.lower + l.lo_table as u64,
                c.lowers,
                l.lo_size,
                12,
                l.stride,
            ),
            (
                at.leaf + l.leaf_table as u64,
                c.leaves,
                l.leaf_size,
                9,
                l.value_size,
            ),
        ];
        for (first, nodes, node_size, log2, stride) in levels {
            dispatch::object_step(
                dev,
                &VolumeBuildFill {
                    base: g + first,
                    count: nodes << log2,
                    node_size: node_size as u64,
                    log2,
                    stride: stride as u32,
                    words: (bg.len() / 4) as u32,
                    pad: 0,
                    bg: words,
                },
            )?;
        }
    }
    let leaf_lower = Array::<u32>::empty(c.leaves as usize, dev)?;
    let lower_upper = Array::<u32>::empty(c.lowers as usize, dev)?;
    dispatch::object_step(
        dev,
        &VolumeBuildLink {
            sorted: sorted.device_address(),
            scan_a: scan_a.device_address(),
            scan_b: scan_b.device_address(),
            grid: g,
            leaf_lower: leaf_lower.device_address(),
            lower_upper: lower_upper.device_address(),
            n: n as u64,
            root: at.root,
            tiles: at.tiles,
            upper: at.upper,
            lower: at.lower,
            leaf: at.leaf,
            tile_size: l.tile_size as u32,
            up_size: l.up_size as u32,
            up_table: l.up_table as u32,
            lo_size: l.lo_size as u32,
            lo_table: l.lo_table as u32,
            leaf_size: l.leaf_size as u32,
            leaf_table: l.leaf_table as u32,
            stride: l.stride as u32,
            kind,
            pad: 0,
        },
    )?;
    dispatch::object_step(
        dev,
        &VolumeBuildLeafBox {
            grid: g,
            leaf: at.leaf,
            lower: at.lower,
            leaf_lower: leaf_lower.device_address(),
            count: c.leaves,
            leaf_size: l.leaf_size as u32,
            leaf_table: l.leaf_table as u32,
            lo_size: l.lo_size as u32,
            on_index: (kind == KIND_ON_INDEX) as u32,
        },
    )?;
    dispatch::object_step(
        dev,
        &VolumeBuildNodeBox {
            grid: g,
            child: at.lower,
            parent: at.upper,
            parent_of: lower_upper.device_address(),
            count: c.lowers,
            child_size: l.lo_size as u32,
            parent_size: l.up_size as u32,
        },
    )?;
    dispatch::object_step(
        dev,
        &VolumeBuildNodeBox {
            grid: g,
            child: at.upper,
            parent: at.root,
            parent_of: 0,
            count: c.uppers,
            child_size: l.up_size as u32,
            parent_size: 0,
        },
    )?;
    dispatch::object_step(
        dev,
        &VolumeBuildWorld {
            grid: g,
            root: at.root,
            mat: std::array::from_fn(|k| map.mat[k / 3][k % 3]),
            t: map.translation,
        },
    )?;
    Ok(())
}
