//! The NanoVDB format facts (docs/nanovdb.md has the layout with offsets), in one place for
//! every reader and writer of grids: the value types, the per-type node layout, the tree's
//! shape, the root key, the index-to-world map; the validator that makes a buffer safe for
//! kernel lookups ([`validate`]); and the CPU builder of grids laid out as Warp's
//! ([`build_from_tiles`], [`build_from_voxels`]).
//!
//! All integers are little-endian; nothing here assumes the buffer is aligned.

/// "NanoVDB0": the file magic Warp writes (and the grid magic of old grids).
pub const MAGIC_0: u64 = 0x3042_4456_6F6E_614E;
/// "NanoVDB1": the grid magic.
pub const MAGIC_GRID: u64 = 0x3142_4456_6F6E_614E;
/// "NanoVDB2": upstream's file magic since 32.7.
pub const MAGIC_FILE: u64 = 0x3242_4456_6F6E_614E;

/// Bytes of GridData, at offset 0 of a grid.
pub const GRID_DATA: usize = 672;
/// Bytes of TreeData, right after GridData.
pub const TREE_DATA: usize = 64;
/// Offset of the Map in GridData.
pub const MAP: usize = 296;

/// A version packed as NanoVDB does: major in bits 21.., minor in 10..21, patch in 0..10.
pub const fn version(major: u32, minor: u32, patch: u32) -> u32 {
    (major << 21) | (minor << 10) | patch
}
/// The major of a packed version.
pub const fn version_major(v: u32) -> u32 {
    v >> 21
}
/// 32.6.0 packed: the checksum's layout changed after it.
pub const VERSION_32_6_0: u32 = version(32, 6, 0);
/// The version Warp 1.19's builders write (and ours).
pub const VERSION_BUILT: u32 = version(32, 8, 0);

/// Leaf: 8^3 voxels (`LOG2DIM` 3). Lower internal node: 16^3 leaves (128^3 voxels). Upper
/// internal node: 32^3 lower nodes (4096^3 voxels). The root: a sparse table of uppers.
pub const LEAF_LOG2: u32 = 3;
/// Lower internal node `LOG2DIM`.
pub const LOWER_LOG2: u32 = 4;
/// Upper internal node `LOG2DIM`.
pub const UPPER_LOG2: u32 = 5;
/// Offset of the child mask in an upper node (the value mask is at 32).
pub const UPPER_CHILD_MASK: usize = 4128;
/// Offset of the child mask in a lower node.
pub const LOWER_CHILD_MASK: usize = 544;
/// Offset of the value (active) mask in every node and leaf.
pub const VALUE_MASK: usize = 32;
/// Offset of the value mask in a leaf.
pub const LEAF_VALUE_MASK: usize = 16;

/// The root table key of the upper node holding `ijk` (each coordinate reinterpreted as
/// unsigned, shifted by the upper node's 12 bits).
#[inline(always)]
pub fn root_key(ijk: [i32; 3]) -> u64 {
    let [i, j, k] = ijk.map(|x| (x as u32 >> 12) as u64);
    k | (j << 21) | (i << 42)
}

/// The value types of a grid (NanoVDB's `GridType` codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridType {
    /// `f32` values (1).
    Float,
    /// `f64` values (2).
    Double,
    /// `i32` values (4).
    Int32,
    /// `[f32; 3]` values (6).
    Vec3f,
    /// `[f64; 3]` values (7).
    Vec3d,
    /// An index grid (19): every voxel of a leaf has an index into a separate value array.
    Index,
    /// An index grid over the active voxels only (20).
    OnIndex,
    /// Any other type (its NanoVDB code).
    Other(u32),
}

impl GridType {
    /// The type of a NanoVDB code.
    pub fn from_code(c: u32) -> GridType {
        match c {
            1 => GridType::Float,
            2 => GridType::Double,
            4 => GridType::Int32,
            6 => GridType::Vec3f,
            7 => GridType::Vec3d,
            19 => GridType::Index,
            20 => GridType::OnIndex,
            c => GridType::Other(c),
        }
    }

    /// The NanoVDB code.
    pub fn code(self) -> u32 {
        match self {
            GridType::Float => 1,
            GridType::Double => 2,
            GridType::Int32 => 4,
            GridType::Vec3f => 6,
            GridType::Vec3d => 7,
            GridType::Index => 19,
            GridType::OnIndex => 20,
            GridType::Other(c) => c,
        }
    }

    /// Whether it is an index grid (values live in an external array).
    pub fn is_index(self) -> bool {
        matches!(self, GridType::Index | GridType::OnIndex)
    }
}

/// The offsets and sizes that depend on the value type (docs/nanovdb.md, section 2): bytes,
/// from the start of the node they belong to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Bytes of one value (index grids: 8, their u64 table entries).
    pub value_size: usize,
    /// Bytes of RootData (the tiles follow it).
    pub root_size: usize,
    /// The background value in RootData.
    pub background: usize,
    /// Bytes of a root tile.
    pub tile_size: usize,
    /// The value in a root tile.
    pub tile_value: usize,
    /// Bytes of an internal node's table entry.
    pub stride: usize,
    /// The table in an upper node.
    pub up_table: usize,
    /// Bytes of an upper node.
    pub up_size: usize,
    /// The table in a lower node.
    pub lo_table: usize,
    /// Bytes of a lower node.
    pub lo_size: usize,
    /// The values in a leaf (index grids: `mOffset`, then `mPrefixSum` at +8).
    pub leaf_table: usize,
    /// Bytes of a leaf.
    pub leaf_size: usize,
}

impl Layout {
    /// The layout of a value type (`None` for the types not read).
    pub fn of(t: GridType) -> Option<Layout> {
        #[allow(clippy::too_many_arguments)]
        const fn l(
            value_size: usize,
            root_size: usize,
            background: usize,
            tile_size: usize,
            tile_value: usize,
            stride: usize,
            up: (usize, usize),
            lo: (usize, usize),
            leaf: (usize, usize),
        ) -> Layout {
            Layout {
                value_size,
                root_size,
                background,
                tile_size,
                tile_value,
                stride,
                up_table: up.0,
                up_size: up.1,
                lo_table: lo.0,
                lo_size: lo.1,
                leaf_table: leaf.0,
                leaf_size: leaf.1,
            }
        }
        Some(match t {
            GridType::Float | GridType::Int32 => l(
                4,
                64,
                28,
                32,
                20,
                8,
                (8256, 270400),
                (1088, 33856),
                (96, 2144),
            ),
            GridType::Double => l(
                8,
                96,
                32,
                32,
                24,
                8,
                (8256, 270400),
                (1088, 33856),
                (128, 4224),
            ),
            GridType::Vec3f => l(
                12,
                96,
                28,
                32,
                20,
                16,
                (8256, 532544),
                (1088, 66624),
                (128, 6272),
            ),
            GridType::Vec3d => l(
                24,
                128,
                32,
                64,
                24,
                24,
                (8288, 794720),
                (1120, 99424),
                (160, 12448),
            ),
            GridType::Index | GridType::OnIndex => l(
                8,
                96,
                32,
                32,
                24,
                8,
                (8256, 270400),
                (1088, 33856),
                (80, 96),
            ),
            GridType::Other(_) => return None,
        })
    }
}

/// The index-to-world transform of a grid: `world = mat * ijk + translation`, `mat`
/// row-major (NanoVDB's Map stores it with its inverse, in f32 and f64 copies).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Map {
    /// Row-major 3x3.
    pub mat: [[f64; 3]; 3],
    /// The world position of index (0, 0, 0).
    pub translation: [f64; 3],
}

impl Map {
    /// A uniform scale by `voxel_size` and a translation.
    pub fn uniform(voxel_size: f64, translation: [f64; 3]) -> Map {
        let v = voxel_size;
        Map {
            mat: [[v, 0.0, 0.0], [0.0, v, 0.0], [0.0, 0.0, v]],
            translation,
        }
    }
}

/// What [`validate`] decodes from a grid buffer: the facts lookups and writers need, every
/// offset proven inside the grid. Offsets are bytes from the grid's start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridInfo {
    /// The value type.
    pub grid_type: GridType,
    /// Its layout.
    pub layout: Layout,
    /// Bytes of the grid (GridData's gridSize).
    pub size: u64,
    /// The packed version.
    pub version: u32,
    /// GridData's flags.
    pub flags: u32,
    /// RootData.
    pub root: u64,
    /// Tiles in the root table.
    pub tile_count: u32,
    /// The first upper node, lower node, leaf.
    pub first_upper: u64,
    /// See `first_upper`.
    pub first_lower: u64,
    /// See `first_upper`.
    pub first_leaf: u64,
    /// Upper nodes, lower nodes, leaves.
    pub upper_count: u32,
    /// See `upper_count`.
    pub lower_count: u32,
    /// See `upper_count`.
    pub leaf_count: u32,
}
