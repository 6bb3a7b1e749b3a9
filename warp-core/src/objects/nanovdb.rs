//! The NanoVDB format facts (docs/book/src/nanovdb.md has the layout with offsets), in one place for
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
/// Bytes of one blind-data metadata entry (GridBlindMetaData).
pub const BLIND_META: usize = 288;
/// The byte offsets of GridData's fields (docs/book/src/nanovdb.md, section 2).
pub mod grid {
    /// u64 checksum: head CRC in the low half, tail CRC in the high half; all ones = none.
    pub const CHECKSUM: usize = 8;
    /// u32 packed version.
    pub const VERSION: usize = 16;
    /// u32 flags ([`super::FLAG_BREADTH_FIRST`], ...).
    pub const FLAGS: usize = 20;
    /// u32 index of this grid in its buffer.
    pub const INDEX: usize = 24;
    /// u32 grids in the buffer.
    pub const COUNT: usize = 28;
    /// u64 bytes of this grid.
    pub const SIZE: usize = 32;
    /// 256 bytes: the NUL-terminated name.
    pub const NAME: usize = 40;
    /// Bytes of the name field (NUL included).
    pub const NAME_SIZE: usize = 256;
    /// 6 x f64: world bbox min xyz, max xyz.
    pub const WORLD_BBOX: usize = 560;
    /// 3 x f64: the voxel size.
    pub const VOXEL_SIZE: usize = 608;
    /// u32 grid class (0 unknown, 8 index grid).
    pub const CLASS: usize = 632;
    /// u32 grid type code.
    pub const TYPE: usize = 636;
    /// i64 offset of the blind metadata table from the grid's start.
    pub const BLIND_OFFSET: usize = 640;
    /// u32 entries in the blind metadata table.
    pub const BLIND_COUNT: usize = 648;
    /// u32 mData0 (unused).
    pub const DATA0: usize = 652;
    /// u64 mData1: for index grids, the number of values (slot 0 included).
    pub const DATA1: usize = 656;
    /// u64 mData2 (unused).
    pub const DATA2: usize = 664;
}
/// The byte offsets of TreeData's fields, from the TreeData's start ([`GRID_DATA`]).
pub mod tree {
    /// 4 x i64 node offsets from the TreeData: leaf, lower, upper, root.
    pub const NODE_OFFSET: usize = 0;
    /// 3 x u32 node counts: leaf, lower, upper.
    pub const NODE_COUNT: usize = 32;
    /// 3 x u32 tile counts: lower, upper, root levels (Warp writes the node counts).
    pub const TILE_COUNT: usize = 44;
    /// u64 active voxels.
    pub const VOXEL_COUNT: usize = 56;
}
/// The byte offsets of RootData's and a root tile's fields.
pub mod root {
    /// 2 x 3 x i32: the index bbox of the active values, inclusive.
    pub const BBOX: usize = 0;
    /// u32 tiles in the table.
    pub const TABLE_SIZE: usize = 24;
    /// u64 key of a tile ([`super::root_key`]).
    pub const TILE_KEY: usize = 0;
    /// i64 child offset of a tile, from the RootData (0: a value tile).
    pub const TILE_CHILD: usize = 8;
    /// u32 state (active) of a tile.
    pub const TILE_STATE: usize = 16;
}
/// GridData flag: the real name is in blind data (class [`BLIND_CLASS_GRID_NAME`]).
pub const FLAG_LONG_NAME: u32 = 1;
/// GridData flag: the bboxes are set.
pub const FLAG_HAS_BBOX: u32 = 2;
/// GridData flag: nodes are stored breadth first, each level contiguous (the only layout read).
pub const FLAG_BREADTH_FIRST: u32 = 32;
/// Blind data class of a long grid name.
pub const BLIND_CLASS_GRID_NAME: u32 = 3;
/// GridClass of index grids (Warp writes 0 for value grids).
pub const CLASS_INDEX_GRID: u32 = 8;
/// Offset of a leaf's bbox dif (3 x u8) and flags (u8).
pub const LEAF_BBOX_DIF: usize = 12;

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

/// The offsets and sizes that depend on the value type (docs/book/src/nanovdb.md, section 2): bytes,
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

    /// The fewest bytes a grid of this layout with `nodes` (leaves, lower nodes, upper
    /// nodes: TreeData's `nodeCount` order, which a file's metadata record repeats) can
    /// take: GridData, TreeData, RootData and every node; root tiles and blind data only add
    /// to it. A declared gridSize below it cannot be the grid's, so a reader can refuse it
    /// before allocating or inflating anything. (The u32 counts times node sizes below 2^20
    /// cannot overflow a u64.)
    pub fn min_grid_size(&self, nodes: [u32; 3]) -> u64 {
        let [leaves, lowers, uppers] = nodes.map(u64::from);
        (GRID_DATA + TREE_DATA + self.root_size) as u64
            + leaves * self.leaf_size as u64
            + lowers * self.lo_size as u64
            + uppers * self.up_size as u64
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

    /// The inverse of `mat`, computed exactly as Warp's `volume_set_map` does (so the stored
    /// inverse matches Warp's bit for bit): the cofactor formula of Warp's `inverse` applied
    /// to the transpose, times `1/det`, transposed back.
    ///
    /// # Errors
    /// A non-finite entry (of `mat` or `translation`), a singular matrix (`det == 0`, where
    /// Warp would store a zero inverse), or an inverse that overflows.
    pub fn inverse(&self) -> Result<[[f64; 3]; 3], String> {
        let finite = |x: &f64| x.is_finite();
        if !self.mat.iter().flatten().all(finite) || !self.translation.iter().all(finite) {
            return Err(format!("the transform {self:?} is not finite"));
        }
        let m = transpose(self.mat);
        let cross = [
            m[1][1] * m[2][2] - m[1][2] * m[2][1],
            m[1][2] * m[2][0] - m[1][0] * m[2][2],
            m[1][0] * m[2][1] - m[1][1] * m[2][0],
        ];
        let det = m[0][0] * cross[0] + m[0][1] * cross[1] + m[0][2] * cross[2];
        if det == 0.0 {
            return Err(format!("the transform {:?} is singular", self.mat));
        }
        let cofactors = [
            [
                m[1][1] * m[2][2] - m[1][2] * m[2][1],
                m[0][2] * m[2][1] - m[0][1] * m[2][2],
                m[0][1] * m[1][2] - m[0][2] * m[1][1],
            ],
            [
                m[1][2] * m[2][0] - m[1][0] * m[2][2],
                m[0][0] * m[2][2] - m[0][2] * m[2][0],
                m[0][2] * m[1][0] - m[0][0] * m[1][2],
            ],
            [
                m[1][0] * m[2][1] - m[1][1] * m[2][0],
                m[0][1] * m[2][0] - m[0][0] * m[2][1],
                m[0][0] * m[1][1] - m[0][1] * m[1][0],
            ],
        ];
        let rcp = 1.0 / det;
        let inv = cofactors.map(|row| row.map(|c| c * rcp));
        if !inv.iter().flatten().all(finite) {
            return Err(format!(
                "the inverse of the transform {:?} overflows",
                self.mat
            ));
        }
        Ok(transpose(inv))
    }

    /// The world size of a voxel along each axis: `mat * (1, 1, 1)`, the row sums. (NanoVDB
    /// computes `(mat*1 + t) - t`; for Warp's transforms, whose entries are all f32 values,
    /// both are exact and equal.)
    pub fn voxel_size(&self) -> [f64; 3] {
        self.mat.map(|r| r[0] + r[1] + r[2])
    }

    /// `mat * p + translation`.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let (m, t) = (&self.mat, &self.translation);
        [0, 1, 2].map(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + t[r])
    }
}

fn transpose(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|r| [m[0][r], m[1][r], m[2][r]])
}

/// Bytes of the Map in GridData.
const MAP_SIZE: usize = 264;

/// Writes `map` into a grid's GridData as NanoVDB stores it: `matF`, `invMatF`, `vecF`,
/// `taperF` = 1, then the f64 copies `matD`, `invMatD`, `vecD`, `taperD` = 1 (the f32
/// copies are the f64 values rounded), and the voxel size ([`Map::voxel_size`]). The world
/// bbox is left as it is (the builders write it).
///
/// # Errors
/// A buffer shorter than GridData; a map without an inverse ([`Map::inverse`]). Nothing is
/// written then.
pub fn write_map(grid: &mut [u8], map: &Map) -> Result<(), String> {
    if grid.len() < GRID_DATA {
        return Err(format!(
            "a buffer of {} bytes has no room for GridData ({GRID_DATA})",
            grid.len()
        ));
    }
    let inv = map.inverse()?;
    let mut f32s = Vec::with_capacity(22);
    let mut f64s = Vec::with_capacity(22);
    for x in map.mat.iter().flatten().chain(inv.iter().flatten()) {
        f32s.push(*x as f32);
        f64s.push(*x);
    }
    for x in map.translation {
        f32s.push(x as f32);
        f64s.push(x);
    }
    f32s.push(1.0);
    f64s.push(1.0);
    let mut at = MAP;
    for x in f32s {
        put(grid, at, &x.to_le_bytes());
        at += 4;
    }
    for x in f64s {
        put(grid, at, &x.to_le_bytes());
        at += 8;
    }
    debug_assert_eq!(at, MAP + MAP_SIZE);
    for (k, x) in map.voxel_size().into_iter().enumerate() {
        put(grid, grid::VOXEL_SIZE + 8 * k, &x.to_le_bytes());
    }
    Ok(())
}

/// The transform a grid stores (its f64 copies `matD` and `vecD`).
///
/// # Errors
/// A buffer shorter than GridData.
pub fn read_map(grid: &[u8]) -> Result<Map, String> {
    let f = |k: usize| f64_at(grid, MAP + 88 + 8 * k);
    let mut m = Map::uniform(1.0, [0.0; 3]);
    for r in 0..3 {
        for c in 0..3 {
            m.mat[r][c] = f(3 * r + c)?;
        }
        m.translation[r] = f(18 + r)?;
    }
    Ok(m)
}

/// Copies `bytes` into `b` at `off` (the caller sized `b`).
fn put(b: &mut [u8], off: usize, bytes: &[u8]) {
    b[off..off + bytes.len()].copy_from_slice(bytes);
}

/// `N` bytes at `off`, or an error naming the read.
fn bytes_at<const N: usize>(b: &[u8], off: usize) -> Result<[u8; N], String> {
    off.checked_add(N)
        .and_then(|end| b.get(off..end))
        .and_then(|s| s.try_into().ok())
        .ok_or_else(|| {
            format!(
                "a read of {N} bytes at {off} is past the end of the buffer ({})",
                b.len()
            )
        })
}
/// `name(b, off)`: the little-endian `ty` at `off`, checked ([`bytes_at`]).
macro_rules! le_reader {
    ($($name:ident: $ty:ty),* $(,)?) => {$(
        fn $name(b: &[u8], off: usize) -> Result<$ty, String> {
            bytes_at(b, off).map(<$ty>::from_le_bytes)
        }
    )*};
}
le_reader!(u32_at: u32, u64_at: u64, i64_at: i64, f64_at: f64);

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
    /// The first upper node, lower node, leaf. An empty level's is where it would start:
    /// the end of the level before it (the root's tiles for the uppers).
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

// ---------------------------------------------------------------------------------------
// The validator (docs/book/src/nanovdb.md, section 7): a port of Warp 1.19's `wp_volume_validate_host`.
// ---------------------------------------------------------------------------------------

/// Checks that the grid at the start of `bytes` is one lookups can walk without reading
/// outside it, and decodes what they need. A port of Warp 1.19's `volume_validate_grid`
/// (the per-grid step of `wp_volume_validate_host`), every serialized field untrusted:
/// - the magic (NanoVDB0 or NanoVDB1); gridSize at least GridData + TreeData (736), a
///   multiple of 32, and no more than `bytes` holds (more bytes may follow: the next grid);
/// - the name NUL-terminated; the blind metadata table inside the grid, each entry's name
///   NUL-terminated and its data range inside the grid;
/// - a grid type this crate has a [`Layout`] for (stricter than Warp's 1..=26: the others
///   cannot be looked up here anyway);
/// - the IsBreadthFirst flag;
/// - the root and each non-empty node array 32-aligned, after the headers, inside the grid,
///   in the order root, root tiles, uppers, lowers, leaves without overlap, and ending
///   before the blind metadata;
/// - every child offset (root tiles to uppers, upper tables to lowers, lower tables to
///   leaves) landing exactly on a node start of the next level;
/// - beyond Warp, for index grids: each leaf's indices inside GridData's value count
///   (mData1): `mOffset + 512` (Index) or `mOffset +` its active voxels (OnIndex), and an
///   OnIndex leaf's `mPrefixSum` equal to its mask's running popcounts, so every index a
///   lookup computes is below the value count.
///
/// # Errors
/// The first check that fails, saying what is wrong and where.
pub fn validate(bytes: &[u8]) -> Result<GridInfo, String> {
    let size = grid_size(bytes)?;
    let g = &bytes[..size as usize];
    validate_name(g)?;
    let blind_start = validate_blind_data(g)?;
    let code = u32_at(g, grid::TYPE)?;
    let grid_type = GridType::from_code(code);
    let layout = Layout::of(grid_type)
        .ok_or_else(|| format!("grid type {code} is not one with a known layout"))?;
    let flags = u32_at(g, grid::FLAGS)?;
    if flags & FLAG_BREADTH_FIRST == 0 {
        return Err(format!(
            "unsupported layout: flags {flags:#x} lack IsBreadthFirst ({FLAG_BREADTH_FIRST:#x})"
        ));
    }
    let levels = Levels::of(g, &layout, blind_start)?;
    validate_children(g, &layout, &levels)?;
    if grid_type.is_index() {
        validate_index_leaves(g, &layout, &levels.leaf, grid_type)?;
    }
    Ok(GridInfo {
        grid_type,
        layout,
        size,
        version: u32_at(g, grid::VERSION)?,
        flags,
        root: levels.root.begin,
        tile_count: levels.tile_count,
        first_upper: levels.upper.begin,
        first_lower: levels.lower.begin,
        first_leaf: levels.leaf.begin,
        upper_count: levels.upper.count,
        lower_count: levels.lower.count,
        leaf_count: levels.leaf.count,
    })
}

/// [`validate`] of every grid of a buffer of grids one after another (as a file's grids
/// are loaded), whose sizes must add up to the buffer's length exactly (Warp's
/// `wp_volume_validate_host`). The offsets of each [`GridInfo`] are from its grid's start.
///
/// # Errors
/// An empty buffer; the first grid that fails, named by its index and offset.
pub fn validate_all(bytes: &[u8]) -> Result<Vec<GridInfo>, String> {
    if bytes.is_empty() {
        return Err("an empty buffer holds no grid".into());
    }
    let mut infos = Vec::new();
    let mut at = 0usize;
    while at < bytes.len() {
        let info = validate(&bytes[at..])
            .map_err(|e| format!("grid {} (at byte {at}): {e}", infos.len()))?;
        at += info.size as usize;
        infos.push(info);
    }
    Ok(infos)
}

/// The grid's size, checked against its headers and the buffer.
fn grid_size(bytes: &[u8]) -> Result<u64, String> {
    const HEADERS: u64 = (GRID_DATA + TREE_DATA) as u64;
    if (bytes.len() as u64) < HEADERS {
        return Err(format!(
            "{} bytes, fewer than GridData and TreeData ({HEADERS})",
            bytes.len()
        ));
    }
    let magic = u64_at(bytes, 0)?;
    if magic != MAGIC_GRID && magic != MAGIC_0 {
        return Err(format!("magic {magic:#018x} is not a NanoVDB grid's"));
    }
    let size = u64_at(bytes, grid::SIZE)?;
    if size < HEADERS {
        return Err(format!(
            "gridSize {size} is smaller than GridData and TreeData ({HEADERS})"
        ));
    }
    if !size.is_multiple_of(32) {
        return Err(format!("gridSize {size} is not a multiple of 32"));
    }
    if size > bytes.len() as u64 {
        return Err(format!(
            "gridSize {size} is more than the {} bytes there are (truncated?)",
            bytes.len()
        ));
    }
    Ok(size)
}

/// Whether the `len` bytes at `at` hold a NUL.
fn has_nul(g: &[u8], at: usize, len: usize) -> bool {
    g.get(at..at + len).is_some_and(|s| s.contains(&0))
}

fn validate_name(g: &[u8]) -> Result<(), String> {
    if has_nul(g, grid::NAME, grid::NAME_SIZE) {
        Ok(())
    } else {
        Err("the grid name is not NUL-terminated".into())
    }
}

/// The blind metadata table and each entry's data inside the grid; returns where the tree
/// must end (the table's start, or the grid's end when there is no table).
fn validate_blind_data(g: &[u8]) -> Result<u64, String> {
    let size = g.len() as u64;
    let offset = i64_at(g, grid::BLIND_OFFSET)?;
    let count = u32_at(g, grid::BLIND_COUNT)? as u64;
    let table = u64::try_from(offset)
        .ok()
        .filter(|t| *t <= size)
        .ok_or_else(|| {
            format!("blind metadata offset {offset} is outside the grid ({size} bytes)")
        })?;
    if count > (size - table) / BLIND_META as u64 {
        return Err(format!(
            "{count} blind metadata entries at {table} do not fit in the grid ({size} bytes)"
        ));
    }
    for n in 0..count {
        let entry = table + n * BLIND_META as u64;
        let e = entry as usize;
        if !has_nul(g, e + 32, 256) {
            return Err(format!(
                "blind metadata entry {n}'s name is not NUL-terminated"
            ));
        }
        let (data, values, value_size) = (i64_at(g, e)?, u64_at(g, e + 8)?, u32_at(g, e + 16)?);
        let start = relative(entry, data, size).ok_or_else(|| {
            format!("blind data {n}'s offset {data} from {entry} leaves the grid")
        })?;
        if value_size != 0 && values > (size - start) / value_size as u64 {
            return Err(format!(
                "blind data {n} ({values} values of {value_size} bytes at {start}) runs past the grid's end ({size})"
            ));
        }
    }
    Ok(if count == 0 && offset == 0 {
        size
    } else {
        table
    })
}

/// `base + rel` when it lies in `0..=size` (Warp's `volume_resolve_relative_offset`).
fn relative(base: u64, rel: i64, size: u64) -> Option<u64> {
    if base > size {
        return None;
    }
    let to = base as i128 + rel as i128;
    (0..=size as i128).contains(&to).then_some(to as u64)
}

/// One level's node array: `count` nodes of `stride` bytes from `begin` (absolute).
#[derive(Clone, Copy, Debug)]
struct NodeRange {
    begin: u64,
    count: u32,
    stride: u64,
}

impl NodeRange {
    fn end(&self) -> u64 {
        self.begin + self.count as u64 * self.stride
    }

    /// Whether `at` is exactly the start of one of the nodes.
    fn starts_node(&self, at: u64) -> bool {
        at >= self.begin && at < self.end() && (at - self.begin).is_multiple_of(self.stride)
    }
}

/// The root, its tiles and the three node levels, each proven inside the grid and in order.
struct Levels {
    root: NodeRange,
    tile_count: u32,
    upper: NodeRange,
    lower: NodeRange,
    leaf: NodeRange,
}

impl Levels {
    fn of(g: &[u8], l: &Layout, tree_end: u64) -> Result<Levels, String> {
        let size = g.len() as u64;
        let level = |k: usize, count: u32, stride: usize, name: &str| {
            let rel = u64_at(g, GRID_DATA + tree::NODE_OFFSET + 8 * k)?;
            node_range(rel, count, stride as u64, size).map_err(|e| format!("the {name} array {e}"))
        };
        let counts = |k: usize| u32_at(g, GRID_DATA + tree::NODE_COUNT + 4 * k);
        let root = level(3, 1, l.root_size, "root")?;
        let upper = level(2, counts(2)?, l.up_size, "upper node")?;
        let lower = level(1, counts(1)?, l.lo_size, "lower node")?;
        let leaf = level(0, counts(0)?, l.leaf_size, "leaf")?;
        let tile_count = u32_at(g, root.begin as usize + root::TABLE_SIZE)?;
        if tile_count as u64 > (size - root.end()) / l.tile_size as u64 {
            return Err(format!(
                "the root's {tile_count} tiles at {} run past the grid's end ({size})",
                root.end()
            ));
        }
        let mut end = root.end() + tile_count as u64 * l.tile_size as u64;
        for (r, name) in [(&upper, "upper"), (&lower, "lower"), (&leaf, "leaf")] {
            if r.count == 0 {
                continue;
            }
            if r.begin < end {
                return Err(format!(
                    "the {name} nodes at {} overlap what comes before them (up to {end})",
                    r.begin
                ));
            }
            end = r.end();
        }
        if end > tree_end {
            return Err(format!(
                "the tree (up to {end}) overlaps the blind metadata at {tree_end}"
            ));
        }
        // An empty level starts where the previous one ends (as Warp's builders put it).
        let empty_at = |r: NodeRange, prev: u64| {
            if r.count == 0 {
                NodeRange { begin: prev, ..r }
            } else {
                r
            }
        };
        let tiles_end = root.end() + tile_count as u64 * l.tile_size as u64;
        let upper = empty_at(upper, tiles_end);
        let lower = empty_at(lower, upper.end());
        let leaf = empty_at(leaf, lower.end());
        Ok(Levels {
            root,
            tile_count,
            upper,
            lower,
            leaf,
        })
    }
}

/// A node array at `rel` from the TreeData: after the TreeData, 32-aligned, inside the grid
/// (Warp's `volume_resolve_node_range`). An empty array's offset is not checked.
fn node_range(rel: u64, count: u32, stride: u64, size: u64) -> Result<NodeRange, String> {
    let range = |begin| NodeRange {
        begin,
        count,
        stride,
    };
    if count == 0 {
        return Ok(range(0));
    }
    let tree = GRID_DATA as u64;
    if rel < TREE_DATA as u64 || rel > size - tree || !rel.is_multiple_of(32) {
        return Err(format!(
            "offset {rel} (from TreeData) is not a 32-aligned place after the headers inside the grid ({size} bytes)"
        ));
    }
    let begin = tree + rel;
    if count as u64 > (size - begin) / stride {
        return Err(format!(
            "of {count} nodes of {stride} bytes at {begin} runs past the grid's end ({size})"
        ));
    }
    Ok(range(begin))
}

/// Every child offset lands exactly on a node of the next level: root tiles (offsets from
/// the root, 0 = a value tile) on uppers, upper tables on lowers, lower tables on leaves.
fn validate_children(g: &[u8], l: &Layout, lv: &Levels) -> Result<(), String> {
    let size = g.len() as u64;
    for t in 0..lv.tile_count as u64 {
        let tile = lv.root.end() + t * l.tile_size as u64;
        let child = i64_at(g, tile as usize + root::TILE_CHILD)?;
        if child != 0
            && !relative(lv.root.begin, child, size).is_some_and(|c| lv.upper.starts_node(c))
        {
            return Err(format!(
                "root tile {t}'s child offset {child} does not land on an upper node"
            ));
        }
    }
    let levels = [
        (
            &lv.upper,
            UPPER_CHILD_MASK,
            l.up_table,
            UPPER_LOG2,
            &lv.lower,
            "upper",
            "lower",
        ),
        (
            &lv.lower,
            LOWER_CHILD_MASK,
            l.lo_table,
            LOWER_LOG2,
            &lv.leaf,
            "lower",
            "leaf",
        ),
    ];
    for (parents, mask, table, log2, children, parent, child) in levels {
        for n in 0..parents.count as u64 {
            let node = parents.begin + n * parents.stride;
            for w in 0..(1usize << (3 * log2)) / 64 {
                let mut word = u64_at(g, node as usize + mask + 8 * w)?;
                while word != 0 {
                    let slot = 64 * w + word.trailing_zeros() as usize;
                    word &= word - 1;
                    let rel = i64_at(g, node as usize + table + slot * l.stride)?;
                    if !relative(node, rel, size).is_some_and(|c| children.starts_node(c)) {
                        return Err(format!(
                            "{parent} node {n}'s child offset {rel} (slot {slot}) does not land on a {child} node"
                        ));
                    }
                }
            }
        }
    }
    Ok(())
}

/// Index grids: every leaf's indices below GridData's value count (mData1), and OnIndex
/// prefix sums that match the masks.
fn validate_index_leaves(
    g: &[u8],
    l: &Layout,
    leaves: &NodeRange,
    t: GridType,
) -> Result<(), String> {
    let values = u64_at(g, grid::DATA1)?;
    for n in 0..leaves.count as u64 {
        let leaf = (leaves.begin + n * leaves.stride) as usize;
        let offset = u64_at(g, leaf + l.leaf_table)?;
        let used = if t == GridType::OnIndex {
            let words: Vec<u64> = (0..8)
                .map(|w| u64_at(g, leaf + LEAF_VALUE_MASK + 8 * w))
                .collect::<Result<_, _>>()?;
            let prefix = u64_at(g, leaf + l.leaf_table + 8)?;
            let mut sum = 0u64;
            for (f, w) in words[..7].iter().enumerate() {
                sum += w.count_ones() as u64;
                if (prefix >> (9 * f)) & 511 != sum {
                    return Err(format!(
                        "OnIndex leaf {n}'s prefix sum {prefix:#x} does not match its mask (field {f})"
                    ));
                }
            }
            sum + words[7].count_ones() as u64
        } else {
            512
        };
        if offset.checked_add(used).is_none_or(|end| end > values) {
            return Err(format!(
                "index leaf {n}'s {used} indices from {offset} pass the grid's value count {values}"
            ));
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// The CPU builder (docs/book/src/nanovdb.md, section 6).
// ---------------------------------------------------------------------------------------

/// What [`build_from_tiles`] builds.
#[derive(Clone, Copy, Debug)]
pub enum BuildKind<'a> {
    /// A value grid of `grid_type` (Float, Double, Int32, Vec3f, Vec3d): every leaf value,
    /// every internal table entry and the root background hold `background`, the value's
    /// little-endian bytes ([`Layout::value_size`] of them).
    Value {
        /// The value type.
        grid_type: GridType,
        /// The background value's bytes.
        background: &'a [u8],
    },
    /// An `Index` grid: every voxel of leaf `n` has the index `n*512 + 1 + voxel`.
    Index,
}

/// A grid with a leaf (8^3 voxels, all active) for every tile named in `tiles` (any voxel of
/// a leaf names it, `ijk & !7`; duplicates are fine), laid out byte for byte as Warp 1.19's
/// `Volume.allocate_by_tiles` lays it out (docs/book/src/nanovdb.md, section 6): uppers in the order
/// of their signed origins, lowers by (upper, slot), leaves by (lower, slot); magic
/// NanoVDB1, no checksum, version 32.8.0, flags HasBBox | IsBreadthFirst, an empty name,
/// node and tile counts, bboxes propagated from the leaves. Root tile values are left zero,
/// as Warp leaves them; index grids store no background (their tables stay zero).
///
/// The one deliberate difference from Warp's CPU builder is the world bbox (GridData bytes
/// 560..608): ours maps the corners of the inclusive index bbox `min..max`, as Warp's CUDA
/// builder does, where Warp's CPU builder maps `min..max+1`. With no tiles it is the empty
/// box (f64::MAX, -f64::MAX), as both of Warp's builders write.
///
/// No tiles give the 800-byte (Float) empty grid Warp's builders make when every point is
/// masked out (a root with no tiles: every lookup returns the background). Warp refuses an
/// empty point array outright, but the empty grid is a valid grid and callers that want
/// Warp's refusal can check for it; the builder stays total.
///
/// # Errors
/// A grid type without a [`Layout`] or an index type in [`BuildKind::Value`], a background
/// of the wrong size, a map without an inverse ([`Map::inverse`]), a grid too large for
/// memory.
pub fn build_from_tiles(kind: BuildKind, tiles: &[[i32; 3]], map: &Map) -> Result<Vec<u8>, String> {
    let (grid_type, background) = match kind {
        BuildKind::Value {
            grid_type,
            background,
        } => {
            let layout = Layout::of(grid_type)
                .filter(|_| !grid_type.is_index())
                .ok_or_else(|| format!("{grid_type:?} is not a value type the builder makes"))?;
            if background.len() != layout.value_size {
                return Err(format!(
                    "a {grid_type:?} background has {} bytes, not {}",
                    background.len(),
                    layout.value_size
                ));
            }
            (grid_type, Some(background))
        }
        BuildKind::Index => (GridType::Index, None),
    };
    build(grid_type, background, &Topology::of(tiles, false), map)
}

/// An `OnIndex` grid whose active voxels are `voxels` (duplicates are fine), laid out as
/// Warp 1.19's `Volume.allocate_by_voxels` lays it out: a leaf for every voxel's tile, its
/// value mask the listed voxels, `mOffset` = 1 + the active voxels of the leaves before it,
/// `mPrefixSum` the running popcounts of the mask words (docs/book/src/nanovdb.md, section 2), and
/// GridData's mData1 = active voxels + 1 (the value count, slot 0 being the background). The
/// world bbox and an empty input are as [`build_from_tiles`] says.
///
/// # Errors
/// A map without an inverse; a grid too large for memory.
pub fn build_from_voxels(voxels: &[[i32; 3]], map: &Map) -> Result<Vec<u8>, String> {
    build(GridType::OnIndex, None, &Topology::of(voxels, true), map)
}

/// The signed origin order of an upper node as an unsigned key: each coordinate plus 2^31,
/// shifted by the upper's 12 bits (Warp's sort key for the root table).
fn upper_sort_key(ijk: [i32; 3]) -> u64 {
    let [i, j, k] = ijk.map(|x| ((x as i64 + (1 << 31)) as u32 >> 12) as u64);
    k | (j << 21) | (i << 42)
}

/// The origin of the upper node whose sort key is `key`.
fn upper_origin(key: u64) -> [i32; 3] {
    [42, 21, 0].map(|s| ((((key >> s) & 0x1F_FFFF) << 12) as i64 - (1 << 31)) as i32)
}

/// The slot of `ijk`'s child in an internal node of `log2` (5: upper, 4: lower) over
/// children of `child_bits` (7: lowers, 3: leaves), or a voxel's in its leaf (3, 0).
fn slot(ijk: [i32; 3], log2: u32, child_bits: u32) -> u64 {
    let mask = (1u32 << (log2 + child_bits)) - 1;
    let [i, j, k] = ijk.map(|x| ((x as u32 & mask) >> child_bits) as u64);
    (i << (2 * log2)) | (j << log2) | k
}

/// The coordinates of `slot` of a node of `log2`, in children of `child_bits` voxels.
fn slot_offset(slot: u64, log2: u32, child_bits: u32) -> [i32; 3] {
    let m = (1u64 << log2) - 1;
    [2 * log2, log2, 0].map(|s| (((slot >> s) & m) as i32) << child_bits)
}

fn sort_unique(v: &mut Vec<u64>) {
    v.sort_unstable();
    v.dedup();
}

/// The nodes of a tree, each level sorted and deduplicated as Warp's builder orders them.
struct Topology {
    /// Upper nodes by sort key ([`upper_sort_key`]).
    uppers: Vec<u64>,
    /// Lower nodes: `upper id << 15 | slot in the upper`.
    lowers: Vec<u64>,
    /// Leaves: `lower key << 12 | slot in the lower`.
    leaves: Vec<u64>,
    /// Active voxels (OnIndex builds only): `leaf key << 9 | slot in the leaf`.
    voxels: Vec<u64>,
}

impl Topology {
    /// Warp's hierarchy keys of `points` (`upper id << 36 | upper slot << 21 | lower slot
    /// << 9 | leaf slot`), sorted, each level the unique prefixes.
    fn of(points: &[[i32; 3]], keep_voxels: bool) -> Topology {
        let mut uppers: Vec<u64> = points.iter().map(|p| upper_sort_key(*p)).collect();
        sort_unique(&mut uppers);
        let mut keys: Vec<u64> = points
            .iter()
            .map(|&p| {
                // Every point's upper is in the list (it was built from them).
                let id = uppers.partition_point(|k| *k < upper_sort_key(p)) as u64;
                id << 36
                    | slot(p, UPPER_LOG2, 7) << 21
                    | slot(p, LOWER_LOG2, 3) << 9
                    | slot(p, 3, 0)
            })
            .collect();
        sort_unique(&mut keys);
        let level = |shift: u32| {
            let mut v: Vec<u64> = keys.iter().map(|k| k >> shift).collect();
            v.dedup();
            v
        };
        Topology {
            lowers: level(21),
            leaves: level(9),
            voxels: if keep_voxels {
                keys.clone()
            } else {
                Vec::new()
            },
            uppers,
        }
    }

    /// The index of `key` in the sorted `level` (present by construction).
    fn find(level: &[u64], key: u64) -> usize {
        level.partition_point(|k| *k < key)
    }
}

/// Where each part of a built grid starts, and its size.
struct Placement {
    root: usize,
    upper: usize,
    lower: usize,
    leaf: usize,
    size: usize,
}

impl Placement {
    fn of(l: &Layout, t: &Topology) -> Result<Placement, String> {
        let part = |count: usize, size: usize| count.checked_mul(size);
        let root = GRID_DATA + TREE_DATA;
        let too_big = || {
            format!(
                "a grid of {} uppers, {} lowers, {} leaves is too large",
                t.uppers.len(),
                t.lowers.len(),
                t.leaves.len()
            )
        };
        let upper = part(t.uppers.len(), l.tile_size)
            .and_then(|b| b.checked_add(root + l.root_size))
            .ok_or_else(too_big)?;
        let lower = part(t.uppers.len(), l.up_size)
            .and_then(|b| b.checked_add(upper))
            .ok_or_else(too_big)?;
        let leaf = part(t.lowers.len(), l.lo_size)
            .and_then(|b| b.checked_add(lower))
            .ok_or_else(too_big)?;
        let size = part(t.leaves.len(), l.leaf_size)
            .and_then(|b| b.checked_add(leaf))
            .filter(|s| *s <= isize::MAX as usize)
            .ok_or_else(too_big)?;
        Ok(Placement {
            root,
            upper,
            lower,
            leaf,
            size,
        })
    }
}

/// An inclusive index bbox, `[min, max]`; the empty one is `[i32::MAX; 3]..[i32::MIN; 3]`.
type IndexBox = [[i32; 3]; 2];
const EMPTY_BOX: IndexBox = [[i32::MAX; 3], [i32::MIN; 3]];

fn union(a: IndexBox, b: IndexBox) -> IndexBox {
    [
        [0, 1, 2].map(|c| a[0][c].min(b[0][c])),
        [0, 1, 2].map(|c| a[1][c].max(b[1][c])),
    ]
}

/// The grid buffer being built: little-endian writes at byte offsets the builder computed.
struct Grid<'a> {
    b: Vec<u8>,
    l: Layout,
    at: &'a Placement,
    background: Option<&'a [u8]>,
}

impl Grid<'_> {
    fn put(&mut self, off: usize, bytes: &[u8]) {
        put(&mut self.b, off, bytes);
    }
    fn bbox(&mut self, node: usize, bbox: IndexBox) {
        for (k, x) in bbox.iter().flatten().enumerate() {
            self.put(node + 4 * k, &x.to_le_bytes());
        }
    }
    fn set_bit(&mut self, mask: usize, n: u64) {
        let word = mask + 8 * (n as usize >> 6);
        self.b[word + (n as usize & 63) / 8] |= 1 << (n & 7);
    }
    fn upper(&self, id: usize) -> usize {
        self.at.upper + id * self.l.up_size
    }
    fn lower(&self, id: usize) -> usize {
        self.at.lower + id * self.l.lo_size
    }
    fn leaf(&self, id: usize) -> usize {
        self.at.leaf + id * self.l.leaf_size
    }
    /// `count` background values of `stride` bytes from `first` (value grids only).
    fn fill_background(&mut self, first: usize, count: usize, stride: usize) {
        if let Some(bg) = self.background {
            for n in 0..count {
                put(&mut self.b, first + n * stride, bg);
            }
        }
    }
}

/// Builds the grid of `t` (docs/book/src/nanovdb.md, section 6, each step as Warp's host builder).
fn build(
    grid_type: GridType,
    background: Option<&[u8]>,
    t: &Topology,
    map: &Map,
) -> Result<Vec<u8>, String> {
    let l = Layout::of(grid_type).ok_or_else(|| format!("no layout for {grid_type:?}"))?;
    map.inverse()?;
    let at = Placement::of(&l, t)?;
    let mut g = Grid {
        b: vec![0; at.size],
        l,
        at: &at,
        background,
    };
    let voxel_count = if grid_type == GridType::OnIndex {
        t.voxels.len() as u64
    } else {
        t.leaves.len() as u64 * 512
    };
    write_header(&mut g, grid_type, voxel_count, map)?;
    write_tree(&mut g, t, voxel_count);
    write_uppers(&mut g, t);
    write_lowers(&mut g, t);
    write_leaves(&mut g, t, grid_type);
    if grid_type == GridType::OnIndex {
        write_active_voxels(&mut g, t);
    }
    write_bboxes(&mut g, t, map);
    Ok(g.b)
}

/// GridData: Warp's header fields and the map.
fn write_header(
    g: &mut Grid,
    grid_type: GridType,
    voxel_count: u64,
    map: &Map,
) -> Result<(), String> {
    let size = g.at.size as u64;
    g.put(0, &MAGIC_GRID.to_le_bytes());
    g.put(grid::CHECKSUM, &u64::MAX.to_le_bytes());
    g.put(grid::VERSION, &VERSION_BUILT.to_le_bytes());
    g.put(
        grid::FLAGS,
        &(FLAG_HAS_BBOX | FLAG_BREADTH_FIRST).to_le_bytes(),
    );
    g.put(grid::INDEX, &0u32.to_le_bytes());
    g.put(grid::COUNT, &1u32.to_le_bytes());
    g.put(grid::SIZE, &size.to_le_bytes());
    write_map(&mut g.b, map)?;
    let class = if grid_type.is_index() {
        CLASS_INDEX_GRID
    } else {
        0
    };
    g.put(grid::CLASS, &class.to_le_bytes());
    g.put(grid::TYPE, &grid_type.code().to_le_bytes());
    g.put(grid::BLIND_OFFSET, &size.to_le_bytes());
    if grid_type.is_index() {
        g.put(grid::DATA1, &(voxel_count + 1).to_le_bytes());
    }
    Ok(())
}

/// TreeData (node offsets from it, counts; Warp stores the node counts as the tile counts)
/// and RootData (the table size, the background of value grids).
fn write_tree(g: &mut Grid, t: &Topology, voxel_count: u64) {
    let at = g.at;
    let counts = [t.leaves.len(), t.lowers.len(), t.uppers.len()].map(|c| c as u32);
    for (k, off) in [at.leaf, at.lower, at.upper, at.root]
        .into_iter()
        .enumerate()
    {
        g.put(
            GRID_DATA + tree::NODE_OFFSET + 8 * k,
            &((off - GRID_DATA) as u64).to_le_bytes(),
        );
    }
    for (k, c) in counts.into_iter().enumerate() {
        g.put(GRID_DATA + tree::NODE_COUNT + 4 * k, &c.to_le_bytes());
        g.put(GRID_DATA + tree::TILE_COUNT + 4 * k, &c.to_le_bytes());
    }
    g.put(GRID_DATA + tree::VOXEL_COUNT, &voxel_count.to_le_bytes());
    g.put(at.root + root::TABLE_SIZE, &counts[2].to_le_bytes());
    if let Some(bg) = g.background {
        put(&mut g.b, at.root + g.l.background, bg);
    }
}

/// The root tiles (key, child offset; value and state zero) and the upper nodes (origin,
/// tables of background).
fn write_uppers(g: &mut Grid, t: &Topology) {
    for (id, &key) in t.uppers.iter().enumerate() {
        let (upper, origin) = (g.upper(id), upper_origin(key));
        let tile = g.at.root + g.l.root_size + id * g.l.tile_size;
        g.put(tile + root::TILE_KEY, &root_key(origin).to_le_bytes());
        g.put(
            tile + root::TILE_CHILD,
            &((upper - g.at.root) as i64).to_le_bytes(),
        );
        g.bbox(upper, [origin, [0; 3]]);
        let (table, stride) = (upper + g.l.up_table, g.l.stride);
        g.fill_background(table, 1 << (3 * UPPER_LOG2), stride);
    }
}

/// The lower nodes: each its parent's child (mask bit and offset), origin, tables of
/// background. (The child offset overwrites the first 8 bytes of a background entry; the
/// rest of a wider entry keeps the background's bytes, as in Warp's grids.)
fn write_lowers(g: &mut Grid, t: &Topology) {
    for (id, &key) in t.lowers.iter().enumerate() {
        let (upper_id, slot) = ((key >> 15) as usize, key & 0x7FFF);
        let (upper, lower) = (g.upper(upper_id), g.lower(id));
        g.set_bit(upper + UPPER_CHILD_MASK, slot);
        let entry = upper + g.l.up_table + slot as usize * g.l.stride;
        g.put(entry, &((lower - upper) as i64).to_le_bytes());
        let up_origin = upper_origin(t.uppers[upper_id]);
        let off = slot_offset(slot, UPPER_LOG2, 7);
        g.bbox(lower, [[0, 1, 2].map(|c| up_origin[c] + off[c]), [0; 3]]);
        let (table, stride) = (lower + g.l.lo_table, g.l.stride);
        g.fill_background(table, 1 << (3 * LOWER_LOG2), stride);
    }
}

/// The origin of lower node `id`.
fn lower_origin(t: &Topology, id: usize) -> [i32; 3] {
    let key = t.lowers[id];
    let up = upper_origin(t.uppers[(key >> 15) as usize]);
    let off = slot_offset(key & 0x7FFF, UPPER_LOG2, 7);
    [0, 1, 2].map(|c| up[c] + off[c])
}

/// The origin of leaf `id`.
fn leaf_origin(t: &Topology, id: usize) -> [i32; 3] {
    let key = t.leaves[id];
    let lo = lower_origin(t, Topology::find(&t.lowers, key >> 12));
    let off = slot_offset(key & 0xFFF, LOWER_LOG2, 3);
    [0, 1, 2].map(|c| lo[c] + off[c])
}

/// The leaves: each its lower's child, origin, flags (has bbox); tile grids: every voxel
/// active and the values the background (value grids) or `mOffset = id*512 + 1` (Index);
/// OnIndex: `mOffset` 1 until [`write_active_voxels`].
fn write_leaves(g: &mut Grid, t: &Topology, grid_type: GridType) {
    for (id, &key) in t.leaves.iter().enumerate() {
        let lower_id = Topology::find(&t.lowers, key >> 12);
        let (lower, leaf, slot) = (g.lower(lower_id), g.leaf(id), key & 0xFFF);
        g.set_bit(lower + LOWER_CHILD_MASK, slot);
        let entry = lower + g.l.lo_table + slot as usize * g.l.stride;
        g.put(entry, &((leaf - lower) as i64).to_le_bytes());
        // A leaf stores its bbox as a min corner and u8 extents.
        g.put(leaf, &leaf_origin(t, id).map(i32::to_le_bytes).concat());
        g.put(leaf + LEAF_BBOX_DIF, &[0, 0, 0, 2]);
        let table = leaf + g.l.leaf_table;
        match grid_type {
            GridType::OnIndex => g.put(table, &1u64.to_le_bytes()),
            _ => {
                g.put(leaf + LEAF_VALUE_MASK, &[0xFF; 64]);
                g.put(leaf + LEAF_BBOX_DIF, &[7, 7, 7, 2]);
                if grid_type == GridType::Index {
                    g.put(table, &(id as u64 * 512 + 1).to_le_bytes());
                }
                let value_size = g.l.value_size;
                g.fill_background(table, 512, value_size);
            }
        }
    }
}

/// OnIndex leaves: the value masks, `mOffset` (1 + the active voxels before the leaf) and
/// `mPrefixSum` (field `f`, 9 bits at `9f`, = popcount of mask words `0..=f`).
fn write_active_voxels(g: &mut Grid, t: &Topology) {
    let mut leaf_id = 0;
    for &key in &t.voxels {
        while t.leaves[leaf_id] != key >> 9 {
            leaf_id += 1;
        }
        let leaf = g.leaf(leaf_id);
        g.set_bit(leaf + LEAF_VALUE_MASK, key & 511);
    }
    let mut before = 0u64;
    for id in 0..t.leaves.len() {
        let (leaf, table) = (g.leaf(id), g.leaf(id) + g.l.leaf_table);
        let words = leaf_mask(&g.b, leaf);
        g.put(table, &(1 + before).to_le_bytes());
        let (mut sum, mut prefix) = (0u64, 0u64);
        for (f, w) in words[..7].iter().enumerate() {
            sum += w.count_ones() as u64;
            prefix |= sum << (9 * f);
        }
        g.put(table + 8, &prefix.to_le_bytes());
        before += words.iter().map(|w| w.count_ones() as u64).sum::<u64>();
    }
}

/// The 8 words of a leaf's value mask.
fn leaf_mask(b: &[u8], leaf: usize) -> [u64; 8] {
    let m = leaf + LEAF_VALUE_MASK;
    [0, 1, 2, 3, 4, 5, 6, 7]
        .map(|w| u64::from_le_bytes(b[m + 8 * w..m + 8 * w + 8].try_into().expect("8 bytes")))
}

/// The bbox of a leaf's active voxels from its mask (Warp's `rebuild_update_leaf_bbox`):
/// the mask word is x, bits 3..6 of a word y, bits 0..3 z.
fn leaf_active_box(origin: [i32; 3], words: [u64; 8]) -> IndexBox {
    let xs: Vec<i32> = (0..8)
        .filter(|&x| words[x] != 0)
        .map(|x| x as i32)
        .collect();
    let (Some(&x0), Some(&x1)) = (xs.first(), xs.last()) else {
        return EMPTY_BOX;
    };
    let any = words.iter().fold(0, |a, w| a | w);
    let (y0, y1) = (
        any.trailing_zeros() as i32 >> 3,
        (63 - any.leading_zeros() as i32) >> 3,
    );
    let byte = (0..8).fold(0u8, |a, y| a | (any >> (8 * y)) as u8);
    let (z0, z1) = (
        byte.trailing_zeros() as i32,
        7 - byte.leading_zeros() as i32,
    );
    let o = origin;
    [
        [o[0] + x0, o[1] + y0, o[2] + z0],
        [o[0] + x1, o[1] + y1, o[2] + z1],
    ]
}

/// Every node's bbox, the union of its children's, from the leaves' active voxels up to the
/// root; then the world bbox (the index bbox's corners `min..max` mapped to world).
fn write_bboxes(g: &mut Grid, t: &Topology, map: &Map) {
    let mut lowers = vec![EMPTY_BOX; t.lowers.len()];
    for (id, &key) in t.leaves.iter().enumerate() {
        let leaf = g.leaf(id);
        let origin = leaf_origin(t, id);
        let bbox = leaf_active_box(origin, leaf_mask(&g.b, leaf));
        g.put(leaf, &bbox[0].map(i32::to_le_bytes).concat());
        let dif = [0, 1, 2].map(|c| (bbox[1][c] - bbox[0][c]) as u8);
        g.put(leaf + LEAF_BBOX_DIF, &[dif[0], dif[1], dif[2], 2]);
        let lower_id = Topology::find(&t.lowers, key >> 12);
        lowers[lower_id] = union(lowers[lower_id], bbox);
    }
    let mut uppers = vec![EMPTY_BOX; t.uppers.len()];
    for (id, &key) in t.lowers.iter().enumerate() {
        g.bbox(g.lower(id), lowers[id]);
        let up = (key >> 15) as usize;
        uppers[up] = union(uppers[up], lowers[id]);
    }
    let mut root_box = EMPTY_BOX;
    for (id, bbox) in uppers.iter().enumerate() {
        g.bbox(g.upper(id), *bbox);
        root_box = union(root_box, *bbox);
    }
    g.bbox(g.at.root, root_box);
    let world = world_bbox(map, root_box, !t.uppers.is_empty());
    for (k, x) in world.iter().flatten().enumerate() {
        g.put(grid::WORLD_BBOX + 8 * k, &x.to_le_bytes());
    }
}

/// The world bbox of the inclusive index box `b`: its 8 corners mapped, min and max; the
/// empty box `(f64::MAX, -f64::MAX)` for an empty grid.
fn world_bbox(map: &Map, b: IndexBox, any: bool) -> [[f64; 3]; 2] {
    let mut w = [[f64::MAX; 3], [-f64::MAX; 3]];
    if any {
        for corner in 0..8 {
            let p = [0, 1, 2].map(|c| b[(corner >> c) & 1][c] as f64);
            let q = map.apply(p);
            for c in 0..3 {
                w[0][c] = w[0][c].min(q[c]);
                w[1][c] = w[1][c].max(q[c]);
            }
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    le_reader!(i32_at: i32);

    /// A case written by Warp (see [`compares_with_warp_dumps`]): the build's inputs and
    /// Warp's buffer.
    struct WarpCase {
        kind: String,
        background: Vec<u8>,
        map: Map,
        points: Vec<[i32; 3]>,
        warp: Vec<u8>,
    }

    fn parse_case(text: &str, warp: Vec<u8>) -> WarpCase {
        let mut lines = text.lines();
        let kind = lines.next().unwrap().to_string();
        let bg = lines.next().unwrap();
        let background = if bg == "-" {
            Vec::new()
        } else {
            (0..bg.len() / 2)
                .map(|k| u8::from_str_radix(&bg[2 * k..2 * k + 2], 16).unwrap())
                .collect()
        };
        let floats = |l: &str| -> Vec<f64> { l.split(' ').map(|x| x.parse().unwrap()).collect() };
        let m = floats(lines.next().unwrap());
        let t = floats(lines.next().unwrap());
        let map = Map {
            mat: [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]],
            translation: [t[0], t[1], t[2]],
        };
        let points = lines
            .map(|l| {
                let v: Vec<i32> = l.split(' ').map(|x| x.parse().unwrap()).collect();
                [v[0], v[1], v[2]]
            })
            .collect();
        WarpCase {
            kind,
            background,
            map,
            points,
            warp,
        }
    }

    fn build_case(c: &WarpCase) -> Result<Vec<u8>, String> {
        let value = |grid_type| BuildKind::Value {
            grid_type,
            background: &c.background,
        };
        match c.kind.as_str() {
            "float" => build_from_tiles(value(GridType::Float), &c.points, &c.map),
            "int32" => build_from_tiles(value(GridType::Int32), &c.points, &c.map),
            "double" => build_from_tiles(value(GridType::Double), &c.points, &c.map),
            "vec3f" => build_from_tiles(value(GridType::Vec3f), &c.points, &c.map),
            "vec3d" => build_from_tiles(value(GridType::Vec3d), &c.points, &c.map),
            "index" => build_from_tiles(BuildKind::Index, &c.points, &c.map),
            "onindex" => build_from_voxels(&c.points, &c.map),
            k => Err(format!("unknown kind {k}")),
        }
    }

    /// The world bbox bytes Warp's CPU builder writes for our grid: the corners of the root
    /// bbox `min..max+1` mapped (ours maps `min..max`, as Warp's CUDA builder does).
    fn warp_cpu_world_bbox(grid: &[u8], map: &Map) -> Vec<u8> {
        let info = validate(grid).unwrap();
        let at = |k: usize| i32_at(grid, info.root as usize + 4 * k).unwrap();
        let min = [at(0), at(1), at(2)];
        let max = [at(3) + 1, at(4) + 1, at(5) + 1];
        let w = world_bbox(map, [min, max], info.tile_count > 0);
        w.iter().flatten().flat_map(|x| x.to_le_bytes()).collect()
    }

    /// The first differing byte of two buffers outside the world bbox (560..608), if any.
    fn first_difference(ours: &[u8], warp: &[u8]) -> Option<usize> {
        if ours.len() != warp.len() {
            return Some(ours.len().min(warp.len()));
        }
        (0..ours.len())
            .filter(|k| !(grid::WORLD_BBOX..grid::WORLD_BBOX + 48).contains(k))
            .find(|&k| ours[k] != warp[k])
    }

    /// Compares the builder with buffers Warp 1.19 built from the same inputs, written by a
    /// Python script into `$WARP_NVDB_CASES` (`case_NN.txt`: kind, background bytes in hex,
    /// the 9 matrix entries, the translation, one point per line; `case_NN.bin`: Warp's
    /// `volume.array().numpy().tobytes()`). Hundreds of MB, so not in the repository; the
    /// fixtures test ([`rebuilds_warp_fixtures`]) keeps three small ones.
    #[test]
    #[ignore = "needs $WARP_NVDB_CASES, written by Warp 1.19"]
    fn compares_with_warp_dumps() {
        let dir = std::env::var("WARP_NVDB_CASES").expect("$WARP_NVDB_CASES");
        let mut names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "txt"))
            .collect();
        names.sort();
        assert!(!names.is_empty());
        for txt in names {
            let c = parse_case(
                &std::fs::read_to_string(&txt).unwrap(),
                std::fs::read(txt.with_extension("bin")).unwrap(),
            );
            let ours = build_case(&c).unwrap();
            let diff = first_difference(&ours, &c.warp);
            assert_eq!(
                diff,
                None,
                "{} ({}, {} points)",
                txt.display(),
                c.kind,
                c.points.len()
            );
            assert_eq!(
                warp_cpu_world_bbox(&ours, &c.map),
                c.warp[grid::WORLD_BBOX..grid::WORLD_BBOX + 48],
                "{}: Warp's CPU world bbox is ours with max + 1",
                txt.display()
            );
            println!("{}: {} bytes, identical", txt.display(), ours.len());
        }
    }

    /// The leaf holding `ijk` (its byte offset), walking the tree as a lookup does.
    fn leaf_at(g: &[u8], info: &GridInfo, ijk: [i32; 3]) -> Option<usize> {
        let l = &info.layout;
        let root = info.root as usize;
        let tile = (0..info.tile_count as usize)
            .map(|t| root + l.root_size + t * l.tile_size)
            .find(|t| u64_at(g, *t).unwrap() == root_key(ijk))?;
        let child = i64_at(g, tile + root::TILE_CHILD).unwrap();
        let upper = (root as i64 + child) as usize;
        let down = |node: usize, mask: usize, table: usize, n: u64| -> Option<usize> {
            let word = u64_at(g, node + mask + 8 * (n as usize >> 6)).unwrap();
            (word >> (n & 63) & 1 == 1).then(|| {
                (node as i64 + i64_at(g, node + table + n as usize * l.stride).unwrap()) as usize
            })
        };
        let lower = down(
            upper,
            UPPER_CHILD_MASK,
            l.up_table,
            slot(ijk, UPPER_LOG2, 7),
        )?;
        down(
            lower,
            LOWER_CHILD_MASK,
            l.lo_table,
            slot(ijk, LOWER_LOG2, 3),
        )
    }

    fn float_bg(bg: &[u8]) -> BuildKind<'_> {
        BuildKind::Value {
            grid_type: GridType::Float,
            background: bg,
        }
    }

    /// Any voxel of a tile names its leaf (`ijk & !7`, negative coordinates included); the
    /// leaf's bbox is the whole tile, the root's the union, and the root keys decode back to
    /// the uppers' origins.
    #[test]
    fn tiles_name_their_leaves() {
        let bg = 2.5f32.to_le_bytes();
        let tiles = [[8, 3, -9], [-1, -4097, 4095], [8, 0, -16]];
        let g = build_from_tiles(float_bg(&bg), &tiles, &Map::uniform(1.0, [0.0; 3])).unwrap();
        let info = validate(&g).unwrap();
        assert_eq!(
            (info.leaf_count, info.lower_count, info.upper_count),
            (2, 2, 2)
        );
        let leaf = leaf_at(&g, &info, [8, 0, -16]).unwrap();
        assert_eq!(leaf_at(&g, &info, [15, 7, -9]), Some(leaf));
        assert_eq!(i32_at(&g, leaf + 8).unwrap(), -16);
        assert_eq!(leaf_at(&g, &info, [16, 0, -16]), None);
        let other = leaf_at(&g, &info, [-8, -4104, 4088]).unwrap();
        assert_ne!(other, leaf);
        let root_box: Vec<i32> = (0..6)
            .map(|k| i32_at(&g, info.root as usize + 4 * k).unwrap())
            .collect();
        assert_eq!(root_box, [-8, -4104, -16, 15, 7, 4095]);
        for t in 0..2 {
            let tile = info.root as usize + info.layout.root_size + t * info.layout.tile_size;
            let key = u64_at(&g, tile).unwrap();
            let upper = (info.root as i64 + i64_at(&g, tile + 8).unwrap()) as usize;
            let origin: Vec<i32> = (0..3)
                .map(|c| i32_at(&g, upper + 4 * c).unwrap() & !4095)
                .collect();
            assert_eq!(root_key([origin[0], origin[1], origin[2]]), key);
        }
        // Values, tables and the root background hold the background; masks are all on.
        let bg_at = |off: usize| g[off..off + 4] == bg;
        assert!(bg_at(info.root as usize + info.layout.background));
        assert!((0..512).all(|n| bg_at(leaf + info.layout.leaf_table + 4 * n)));
        assert!(g[leaf + LEAF_VALUE_MASK..leaf + LEAF_VALUE_MASK + 64]
            .iter()
            .all(|b| *b == 0xFF));
    }

    /// Index grids: voxel `n` of leaf `id` has index `id*512 + 1 + n`; mData1 counts every
    /// value and slot 0.
    #[test]
    fn index_grids_number_every_voxel() {
        let g = build_from_tiles(
            BuildKind::Index,
            &[[0, 0, 0], [-8, 0, 0]],
            &Map::uniform(0.5, [0.0; 3]),
        )
        .unwrap();
        let info = validate(&g).unwrap();
        assert_eq!(info.grid_type, GridType::Index);
        assert_eq!(u64_at(&g, grid::DATA1).unwrap(), 2 * 512 + 1);
        assert_eq!(u32_at(&g, grid::CLASS).unwrap(), CLASS_INDEX_GRID);
        // Leaves in (lower, slot) order: the one at x = -8 is in another upper, first.
        let first = leaf_at(&g, &info, [-8, 0, 0]).unwrap();
        let second = leaf_at(&g, &info, [0, 0, 0]).unwrap();
        assert_eq!(first as u64, info.first_leaf);
        assert_eq!(u64_at(&g, first + 80).unwrap(), 1);
        assert_eq!(u64_at(&g, second + 80).unwrap(), 513);
    }

    /// OnIndex grids: the listed voxels active, numbered 1..=N in leaf order, the prefix sums
    /// as docs/book/src/nanovdb.md's worked example (words [0x103, 0x1, 0, 0x20, 0..] give the
    /// fields [3, 4, 4, 5, 5, 5, 5]).
    #[test]
    fn onindex_grids_number_active_voxels() {
        // Voxel n = x<<6 | y<<3 | z: word x, bit y*8+z.
        let voxels = [
            [0, 0, 0],
            [0, 0, 1],
            [0, 1, 0],
            [1, 0, 0],
            [3, 0, 5],
            [3, 0, 5],
            [-1, 0, 0],
        ];
        let g = build_from_voxels(&voxels, &Map::uniform(1.0, [0.0; 3])).unwrap();
        let info = validate(&g).unwrap();
        assert_eq!(u64_at(&g, grid::DATA1).unwrap(), 6 + 1);
        let leaf = leaf_at(&g, &info, [0, 0, 0]).unwrap();
        let words: Vec<u64> = (0..8)
            .map(|w| u64_at(&g, leaf + 16 + 8 * w).unwrap())
            .collect();
        assert_eq!(words, [0x103, 0x1, 0, 0x20, 0, 0, 0, 0]);
        let prefix = u64_at(&g, leaf + 88).unwrap();
        let fields: Vec<u64> = (0..7).map(|f| (prefix >> (9 * f)) & 511).collect();
        assert_eq!(fields, [3, 4, 4, 5, 5, 5, 5]);
        // The leaf at x = -8 comes first (another upper): one voxel, then this leaf's five.
        assert_eq!(u64_at(&g, leaf + 80).unwrap(), 2);
        // Its bbox: the active voxels' (x 0..3, y 0..1, z 0..5).
        assert_eq!(i32_at(&g, leaf).unwrap(), 0);
        assert_eq!(g[leaf + 12..leaf + 16], [3, 1, 5, 2]);
    }

    /// No tiles: the empty grid Warp makes from all-masked input (800 bytes for Float, a
    /// root with no tiles, the empty world box), which validates.
    #[test]
    fn no_tiles_give_the_empty_grid() {
        let bg = 1.0f32.to_le_bytes();
        let g = build_from_tiles(float_bg(&bg), &[], &Map::uniform(0.5, [0.0; 3])).unwrap();
        assert_eq!(g.len(), 800);
        let info = validate(&g).unwrap();
        assert_eq!((info.tile_count, info.leaf_count), (0, 0));
        assert_eq!(f64_at(&g, grid::WORLD_BBOX).unwrap(), f64::MAX);
        assert_eq!(
            build_from_voxels(&[], &Map::uniform(0.5, [0.0; 3]))
                .unwrap()
                .len(),
            736 + 96
        );
    }

    /// Bad requests are errors: a background of the wrong size, an index or unknown type as
    /// a value type, a singular or non-finite transform.
    #[test]
    fn bad_builds_are_errors() {
        let map = Map::uniform(1.0, [0.0; 3]);
        let tiles = [[0, 0, 0]];
        let err = |kind, map: &Map| build_from_tiles(kind, &tiles, map).unwrap_err();
        let vec3 = |bg| BuildKind::Value {
            grid_type: GridType::Vec3f,
            background: bg,
        };
        assert!(
            err(vec3(&[0; 8]), &map).contains("has 8 bytes, not 12"),
            "{}",
            err(vec3(&[0; 8]), &map)
        );
        let index = BuildKind::Value {
            grid_type: GridType::OnIndex,
            background: &[0; 8],
        };
        assert!(err(index, &map).contains("OnIndex"));
        let other = BuildKind::Value {
            grid_type: GridType::Other(5),
            background: &[0; 8],
        };
        assert!(err(other, &map).contains("Other(5)"));
        let bg = [0; 4];
        let singular = Map {
            mat: [[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [0.0; 3],
        };
        assert!(err(float_bg(&bg), &singular).contains("singular"));
        let nan = Map::uniform(f64::NAN, [0.0; 3]);
        assert!(err(float_bg(&bg), &nan).contains("not finite"));
        let inf_t = Map::uniform(1.0, [f64::INFINITY, 0.0, 0.0]);
        assert!(build_from_voxels(&tiles, &inf_t)
            .unwrap_err()
            .contains("not finite"));
    }

    /// The map as NanoVDB stores it: the matrix as given (row-major, world = M*ijk + t), its
    /// inverse, f32 copies, taper 1, voxel size = row sums (docs/book/src/nanovdb.md: the transform
    /// [[1,2,0],[0,1,0],[0,0,3]] gave (3,1,3) in Warp); read back unchanged.
    #[test]
    fn maps_are_written_and_read() {
        let map = Map {
            mat: [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]],
            translation: [0.5, -1.0, 2.0],
        };
        let mut g = vec![0u8; GRID_DATA];
        write_map(&mut g, &map).unwrap();
        assert_eq!(read_map(&g).unwrap(), map);
        let vs: Vec<f64> = (0..3)
            .map(|k| f64_at(&g, grid::VOXEL_SIZE + 8 * k).unwrap())
            .collect();
        assert_eq!(vs, [3.0, 1.0, 3.0]);
        let inv: Vec<f64> = (0..9)
            .map(|k| f64_at(&g, MAP + 160 + 8 * k).unwrap())
            .collect();
        assert_eq!(inv, [1.0, -2.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0 / 3.0]);
        let f32s: Vec<f32> = (0..22)
            .map(|k| f32::from_le_bytes(g[MAP + 4 * k..MAP + 4 * k + 4].try_into().unwrap()))
            .collect();
        assert_eq!(f32s[..9], [1.0, 2.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 3.0]);
        assert_eq!(f32s[17], (1.0f64 / 3.0) as f32);
        assert_eq!(f32s[18..], [0.5, -1.0, 2.0, 1.0]);
        assert_eq!(f64_at(&g, MAP + 256).unwrap(), 1.0);
        assert!(write_map(&mut [0u8; 100], &map)
            .unwrap_err()
            .contains("100 bytes"));
        assert!(read_map(&[0u8; 100]).is_err());
    }

    /// A Float grid of three uppers, four lowers, four leaves.
    fn small_grid() -> Vec<u8> {
        let bg = 2.5f32.to_le_bytes();
        let tiles = [[0, 0, 0], [8, 3, -9], [-1, -1, -1], [130, 0, 0]];
        build_from_tiles(float_bg(&bg), &tiles, &Map::uniform(0.5, [0.0; 3])).unwrap()
    }

    /// The byte offset of the first set child-mask slot's table entry of a node.
    fn first_child_entry(g: &[u8], node: usize, mask: usize, table: usize, stride: usize) -> usize {
        let slot = (0..)
            .find(|n: &usize| u64_at(g, node + mask + 8 * (n >> 6)).unwrap() >> (n & 63) & 1 == 1)
            .unwrap();
        node + table + slot * stride
    }

    fn add_i64(g: &mut [u8], at: usize, delta: i64) {
        let v = i64_at(g, at).unwrap() + delta;
        g[at..at + 8].copy_from_slice(&v.to_le_bytes());
    }

    fn set_u32(g: &mut [u8], at: usize, v: u32) {
        g[at..at + 4].copy_from_slice(&v.to_le_bytes());
    }

    /// What the validator decodes from a grid it accepts.
    #[test]
    fn validate_decodes_built_grids() {
        let g = small_grid();
        let info = validate(&g).unwrap();
        let l = Layout::of(GridType::Float).unwrap();
        assert_eq!(info.grid_type, GridType::Float);
        assert_eq!(info.layout, l);
        assert_eq!(info.size, g.len() as u64);
        assert_eq!((info.version, info.flags), (VERSION_BUILT, 0x22));
        assert_eq!((info.root, info.tile_count), (736, 3));
        assert_eq!(info.first_upper, 736 + 64 + 3 * 32);
        assert_eq!(info.first_lower, info.first_upper + 3 * l.up_size as u64);
        assert_eq!(info.first_leaf, info.first_lower + 4 * l.lo_size as u64);
        assert_eq!(
            (info.upper_count, info.lower_count, info.leaf_count),
            (3, 4, 4)
        );
        assert_eq!(info.first_leaf + 4 * l.leaf_size as u64, info.size);
        // The least a grid with these nodes takes: all of it but the root's three tiles.
        assert_eq!(l.min_grid_size([4, 4, 3]), info.size - 3 * 32);
        assert_eq!(l.min_grid_size([0; 3]), 736 + 64);
        // Every type the builder makes passes.
        let map = Map::uniform(1.0, [0.0; 3]);
        for (t, bg) in [
            (GridType::Double, 8),
            (GridType::Int32, 4),
            (GridType::Vec3f, 12),
            (GridType::Vec3d, 24),
        ] {
            let kind = BuildKind::Value {
                grid_type: t,
                background: &[7; 32][..bg],
            };
            let g = build_from_tiles(kind, &[[1, 2, 3], [-900, 5000, 7]], &map).unwrap();
            assert_eq!(validate(&g).unwrap().grid_type, t);
        }
        // Grids one after another, as a file's grids are loaded.
        let two = [g.clone(), build_from_voxels(&[[1, 1, 1]], &map).unwrap()].concat();
        let infos = validate_all(&two).unwrap();
        assert_eq!(infos.len(), 2);
        assert_eq!(infos[1].grid_type, GridType::OnIndex);
        let e = validate_all(&[two.as_slice(), &[0; 32]].concat()).unwrap_err();
        assert!(e.starts_with("grid 2 (at byte"), "{e}");
        assert!(validate_all(&[]).is_err());
    }

    /// Each broken grid is an `Err` naming what is wrong (the cases Warp 1.19's validator
    /// raises on, and more).
    #[test]
    fn validate_rejects_broken_grids() {
        let g = small_grid();
        let info = validate(&g).unwrap();
        let l = info.layout;
        let (root, upper, lower) = (
            info.root as usize,
            info.first_upper as usize,
            info.first_lower as usize,
        );
        let tile0 = root + l.root_size;
        let check = |what: &str, broken: &[u8], expect: &str| {
            let e = validate(broken).expect_err(what);
            assert!(e.contains(expect), "{what}: {e}");
        };
        check(
            "the last 100 bytes cut off",
            &g[..g.len() - 100],
            "more than",
        );
        check("shorter than the headers", &g[..700], "fewer than");
        let broken = |f: &dyn Fn(&mut Vec<u8>)| {
            let mut b = g.clone();
            f(&mut b);
            b
        };
        check("bad magic", &broken(&|b| b[0] ^= 1), "magic");
        check(
            "misaligned size",
            &broken(&|b| {
                b.truncate(g.len() - 16);
                let n = b.len() as u64;
                b[grid::SIZE..grid::SIZE + 8].copy_from_slice(&n.to_le_bytes());
            }),
            "not a multiple of 32",
        );
        check(
            "gridType 99",
            &broken(&|b| set_u32(b, grid::TYPE, 99)),
            "grid type 99",
        );
        check(
            "float data relabelled Vec3f",
            &broken(&|b| set_u32(b, grid::TYPE, 6)),
            "",
        );
        check(
            "not breadth first",
            &broken(&|b| set_u32(b, grid::FLAGS, FLAG_HAS_BBOX)),
            "IsBreadthFirst",
        );
        check(
            "an unterminated name",
            &broken(&|b| b[40..296].fill(b'a')),
            "name",
        );
        check(
            "a root tile's child past the last upper",
            &broken(&|b| add_i64(b, tile0 + 8, l.up_size as i64 * 3)),
            "root tile 0's child offset",
        );
        check(
            "a root tile's child into the middle of an upper",
            &broken(&|b| add_i64(b, tile0 + 8, 4096)),
            "root tile 0's child offset",
        );
        check(
            "a root tile's child before the root",
            &broken(&|b| add_i64(b, tile0 + 8, -100_000)),
            "root tile 0's child offset",
        );
        let up_entry = first_child_entry(&g, upper, UPPER_CHILD_MASK, l.up_table, l.stride);
        check(
            "an upper's child 32 bytes into a lower",
            &broken(&|b| add_i64(b, up_entry, 32)),
            "upper node 0's child offset",
        );
        check(
            "an upper's child on a leaf",
            &broken(&|b| add_i64(b, up_entry, (info.first_leaf - info.first_lower) as i64)),
            "does not land on a lower node",
        );
        let lo_entry = first_child_entry(&g, lower, LOWER_CHILD_MASK, l.lo_table, l.stride);
        check(
            "a lower's child past the end",
            &broken(&|b| add_i64(b, lo_entry, i64::MAX / 2)),
            "lower node 0's child offset",
        );
        check(
            "a lower's child one leaf past the last",
            &broken(&|b| add_i64(b, lo_entry, 4 * l.leaf_size as i64)),
            "does not land on a leaf node",
        );
        check(
            "a child bit set over a background entry",
            &broken(&|b| b[upper + UPPER_CHILD_MASK] |= 1),
            "upper node 0's child offset",
        );
        check(
            "too many tiles",
            &broken(&|b| set_u32(b, root + root::TABLE_SIZE, 4)),
            "overlap",
        );
        check(
            "huge tile count",
            &broken(&|b| set_u32(b, root + root::TABLE_SIZE, u32::MAX)),
            "run past",
        );
        check(
            "a leaf array past the end",
            &broken(&|b| set_u32(b, GRID_DATA + tree::NODE_COUNT, 5)),
            "leaf array",
        );
        check(
            "a misaligned lower array",
            &broken(&|b| add_i64(b, GRID_DATA + tree::NODE_OFFSET + 8, 8)),
            "lower node array",
        );
        check(
            "lowers over the uppers",
            &broken(&|b| {
                let upper = i64_at(b, GRID_DATA + 16).unwrap();
                b[GRID_DATA + 8..GRID_DATA + 16].copy_from_slice(&upper.to_le_bytes());
            }),
            "overlap",
        );
        check(
            "the tree over the blind metadata",
            &broken(&|b| {
                let at = (g.len() - 4096) as i64;
                b[grid::BLIND_OFFSET..grid::BLIND_OFFSET + 8].copy_from_slice(&at.to_le_bytes());
            }),
            "blind metadata at",
        );
        check(
            "a blind table past the end",
            &broken(&|b| {
                let at = (g.len() - 256) as i64;
                b[grid::BLIND_OFFSET..grid::BLIND_OFFSET + 8].copy_from_slice(&at.to_le_bytes());
                set_u32(b, grid::BLIND_COUNT, 1);
            }),
            "do not fit",
        );
    }

    /// Blind data: an entry inside the grid passes; its data past the end, or its name
    /// unterminated, does not.
    #[test]
    fn validate_checks_blind_data() {
        let mut g = small_grid();
        let table = g.len();
        g.resize(table + BLIND_META + 32, 0);
        let size = g.len() as u64;
        g[grid::SIZE..grid::SIZE + 8].copy_from_slice(&size.to_le_bytes());
        g[grid::BLIND_OFFSET..grid::BLIND_OFFSET + 8]
            .copy_from_slice(&(table as i64).to_le_bytes());
        set_u32(&mut g, grid::BLIND_COUNT, 1);
        g[table..table + 8].copy_from_slice(&(BLIND_META as i64).to_le_bytes());
        g[table + 8..table + 16].copy_from_slice(&8u64.to_le_bytes());
        set_u32(&mut g, table + 16, 4);
        validate(&g).unwrap();
        let mut b = g.clone();
        set_u32(&mut b, table + 16, 5);
        assert!(validate(&b).unwrap_err().contains("runs past"));
        let mut b = g.clone();
        b[table..table + 8].copy_from_slice(&(-(table as i64) - 1).to_le_bytes());
        assert!(validate(&b).unwrap_err().contains("leaves the grid"));
        let mut b = g.clone();
        b[table + 32..table + 288].fill(b'x');
        assert!(validate(&b).unwrap_err().contains("name"));
    }

    /// Index grids: leaf indices beyond the value count, or OnIndex prefix sums that do not
    /// match the mask, are errors.
    #[test]
    fn validate_checks_index_leaves() {
        let map = Map::uniform(1.0, [0.0; 3]);
        let g = build_from_tiles(BuildKind::Index, &[[0, 0, 0], [8, 0, 0]], &map).unwrap();
        // The last leaf: its indices end exactly at the value count.
        let leaf = validate(&g).unwrap().first_leaf as usize + 96;
        let mut b = g.clone();
        add_i64(&mut b, leaf + 80, 1);
        assert!(validate(&b).unwrap_err().contains("value count"));
        let mut b = g.clone();
        add_i64(&mut b, grid::DATA1, -1);
        assert!(validate(&b).unwrap_err().contains("value count"));
        let g = build_from_voxels(&[[0, 0, 0], [1, 1, 1], [9, 0, 0]], &map).unwrap();
        let leaf = validate(&g).unwrap().first_leaf as usize;
        let mut b = g.clone();
        b[leaf + 16] |= 0x40;
        assert!(validate(&b).unwrap_err().contains("prefix sum"));
        let mut b = g.clone();
        b[leaf + 80..leaf + 88].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(validate(&b).unwrap_err().contains("value count"));
    }

    /// The value a kernel lookup reads at `ijk`, with unchecked-style slice indexing (a
    /// read outside the grid panics): what validation must make safe.
    fn unchecked_lookup(g: &[u8], info: &GridInfo, ijk: [i32; 3]) -> u8 {
        let l = &info.layout;
        let root = info.root as usize;
        let rd = |at: usize| u64::from_le_bytes(g[at..at + 8].try_into().unwrap());
        let Some(tile) = (0..info.tile_count as usize)
            .map(|t| root + l.root_size + t * l.tile_size)
            .find(|t| rd(*t) == root_key(ijk))
        else {
            return g[root + l.background];
        };
        let child = rd(tile + 8) as i64;
        if child == 0 {
            return g[tile + l.tile_value];
        }
        let mut node = (root as i64 + child) as usize;
        for (mask, table, n) in [
            (UPPER_CHILD_MASK, l.up_table, slot(ijk, UPPER_LOG2, 7)),
            (LOWER_CHILD_MASK, l.lo_table, slot(ijk, LOWER_LOG2, 3)),
        ] {
            let entry = node + table + n as usize * l.stride;
            if rd(node + mask + 8 * (n as usize >> 6)) >> (n & 63) & 1 == 0 {
                return g[entry];
            }
            node = (node as i64 + rd(entry) as i64) as usize;
        }
        g[node + l.leaf_table + slot(ijk, 3, 0) as usize * l.value_size + l.value_size - 1]
    }

    /// Random byte changes of a valid grid (in its headers, root, tiles, child masks and
    /// child offsets, where they matter) never make the validator panic, and every grid it
    /// still accepts is walked by unchecked lookups without a read outside it. A fixed-seed
    /// xorshift, 3000 rounds of 1-4 changed bytes.
    #[test]
    fn validate_survives_random_damage() {
        let g = small_grid();
        let info = validate(&g).unwrap();
        let l = info.layout;
        let mut places: Vec<usize> = (0..info.first_upper as usize).collect();
        for (first, count, size, mask, table, log2) in [
            (
                info.first_upper,
                info.upper_count,
                l.up_size,
                UPPER_CHILD_MASK,
                l.up_table,
                UPPER_LOG2,
            ),
            (
                info.first_lower,
                info.lower_count,
                l.lo_size,
                LOWER_CHILD_MASK,
                l.lo_table,
                LOWER_LOG2,
            ),
        ] {
            for n in 0..count as usize {
                let node = first as usize + n * size;
                let slots = 1usize << (3 * log2);
                places.extend(node + mask..node + mask + slots / 8);
                for s in 0..slots {
                    if u64_at(&g, node + mask + 8 * (s >> 6)).unwrap() >> (s & 63) & 1 == 1 {
                        places.extend(node + table + s * l.stride..node + table + s * l.stride + 8);
                    }
                }
            }
        }
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        let probes = [
            [0, 0, 0],
            [8, 3, -9],
            [-1, -1, -1],
            [130, 0, 0],
            [5, 5, 5],
            [-4096, 0, 9],
        ];
        let mut accepted = 0;
        for _ in 0..3000 {
            let mut b = g.clone();
            for _ in 0..1 + next() % 4 {
                let at = places[(next() % places.len() as u64) as usize];
                b[at] ^= 1 << (next() % 8);
            }
            if let Ok(info) = validate(&b) {
                accepted += 1;
                for ijk in probes {
                    unchecked_lookup(&b, &info, ijk);
                }
            }
        }
        eprintln!("{accepted} of 3000 damaged grids accepted");
        // Some damage is harmless (a name byte, a bbox, a flag outside the ones checked).
        assert!(accepted > 0 && accepted < 3000, "{accepted} accepted");
    }
}
