//! The NanoVDB format layer (docs/nanovdb.md has the layout with offsets): `.nvdb` files and
//! grid buffers read on the host, checked (headers, sizes, every offset a lookup follows, the
//! CRC32 checksum), their metadata and index-to-world transform, and the value of a voxel by
//! its index coordinate. The sparse-volume host object will sit on this layer; for now it
//! reads what NanoVDB tools and Warp write (uncompressed or ZIP-compressed; not BLOSC).
//!
//! Every read is bounds-checked against the buffer: a truncated or corrupted grid is an
//! `Err`, never a panic or an out-of-bounds read.

use std::path::Path;

use crate::error::{Error, Result};

/// "NanoVDB0": the file magic Warp writes (and the grid magic of old grids).
const MAGIC_0: u64 = 0x3042_4456_6F6E_614E;
/// "NanoVDB1": the grid magic.
const MAGIC_GRID: u64 = 0x3142_4456_6F6E_614E;
/// "NanoVDB2": upstream's file magic since 32.7.
const MAGIC_FILE: u64 = 0x3242_4456_6F6E_614E;

const FILE_HEADER: usize = 16;
const FILE_META: usize = 176;
const GRID_DATA: usize = 672;
const TREE_DATA: usize = 64;

/// A version packed as NanoVDB does: major in bits 21.., minor in 10..21, patch in 0..10.
fn version_major(v: u32) -> u32 {
    v >> 21
}

/// 32.6.0 packed: the checksum's layout changed after it.
const VERSION_32_6_0: u32 = (32 << 21) | (6 << 10);

/// The value types a grid can hold (NanoVDB's `GridType`, the ones Warp reads).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridType {
    /// `f32` values.
    Float,
    /// `f64` values.
    Double,
    /// `i32` values.
    Int32,
    /// `[f32; 3]` values.
    Vec3f,
    /// An index grid: every voxel of a leaf has an index into a separate value array.
    Index,
    /// An index grid over the active voxels only.
    OnIndex,
    /// Any other type (its NanoVDB code).
    Other(u32),
}

impl GridType {
    fn from_code(c: u32) -> GridType {
        match c {
            1 => GridType::Float,
            2 => GridType::Double,
            4 => GridType::Int32,
            6 => GridType::Vec3f,
            19 => GridType::Index,
            20 => GridType::OnIndex,
            c => GridType::Other(c),
        }
    }
}

/// One grid buffer (NanoVDB's GridData, TreeData, root, nodes, blind data), as a file holds
/// it; read with bounds checks.
#[derive(Clone, PartialEq, Eq)]
pub struct NvdbGrid {
    bytes: Vec<u8>,
}

impl std::fmt::Debug for NvdbGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NvdbGrid")
            .field("name", &self.name())
            .field("grid_type", &self.grid_type())
            .field("bytes", &self.bytes.len())
            .finish()
    }
}

/// Little-endian reads, checked against the slice.
fn read<const N: usize>(b: &[u8], off: usize, what: &str) -> Result<[u8; N]> {
    off.checked_add(N)
        .and_then(|end| b.get(off..end))
        .map(|s| s.try_into().expect("N bytes"))
        .ok_or_else(|| {
            Error::invalid_in(
                what,
                format!("a read of {N} bytes at {off} is past its end ({})", b.len()),
            )
        })
}
/// `name(b, off, what)`: the little-endian `ty` at `off`, checked (as [`read`]).
macro_rules! le_reader {
    ($($name:ident: $ty:ty),* $(,)?) => {$(
        fn $name(b: &[u8], off: usize, what: &str) -> Result<$ty> {
            read(b, off, what).map(<$ty>::from_le_bytes)
        }
    )*};
}
le_reader!(u16_at: u16, u32_at: u32, u64_at: u64, i64_at: i64, f32_at: f32, f64_at: f64);

/// `base + rel` as a position in the buffer, or an error (a corrupt offset).
fn offset(base: usize, rel: i64, what: &str) -> Result<usize> {
    (base as i64)
        .checked_add(rel)
        .filter(|p| *p >= 0)
        .map(|p| p as usize)
        .ok_or_else(|| {
            Error::invalid_in(what, format!("offset {rel} from {base} leaves the buffer"))
        })
}

/// CRC-32/IEEE (reflected polynomial 0xEDB88320, initial and final xor all ones), as zlib's.
pub fn crc32(data: &[u8]) -> u32 {
    const TABLE: [u32; 256] = {
        let mut t = [0u32; 256];
        let mut i = 0;
        while i < 256 {
            let mut c = i as u32;
            let mut k = 0;
            while k < 8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
                k += 1;
            }
            t[i] = c;
            i += 1;
        }
        t
    };
    let mut c = !0u32;
    for &x in data {
        c = TABLE[((c ^ x as u32) & 0xff) as usize] ^ (c >> 8);
    }
    !c
}

impl NvdbGrid {
    /// A grid buffer, checked: its magic, its major version (32), its size against the
    /// buffer, and the TreeData's root offset.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] saying what is wrong.
    pub fn from_bytes(bytes: Vec<u8>) -> Result<NvdbGrid> {
        const WHAT: &str = "NanoVDB grid";
        let b = &bytes[..];
        if b.len() < GRID_DATA + TREE_DATA {
            return Err(Error::invalid_in(
                WHAT,
                format!(
                    "{} bytes, shorter than its headers ({})",
                    b.len(),
                    GRID_DATA + TREE_DATA
                ),
            ));
        }
        let magic = u64_at(b, 0, WHAT)?;
        if magic != MAGIC_GRID && magic != MAGIC_0 {
            return Err(Error::invalid_in(
                WHAT,
                format!("magic {magic:#018x} is not NanoVDB's"),
            ));
        }
        let version = u32_at(b, 16, WHAT)?;
        if version_major(version) != 32 {
            return Err(Error::invalid_in(
                WHAT,
                format!(
                    "version {} (major), only 32 is read",
                    version_major(version)
                ),
            ));
        }
        let size = u64_at(b, 32, WHAT)?;
        if size != b.len() as u64 {
            return Err(Error::invalid_in(
                WHAT,
                format!("says {size} bytes, has {}", b.len()),
            ));
        }
        let g = NvdbGrid { bytes };
        g.root()?;
        Ok(g)
    }

    /// The buffer.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The grid's name (empty when it has none).
    pub fn name(&self) -> String {
        let n = &self.bytes[40..296];
        let end = n.iter().position(|c| *c == 0).unwrap_or(n.len());
        String::from_utf8_lossy(&n[..end]).into_owned()
    }

    /// The value type.
    pub fn grid_type(&self) -> GridType {
        GridType::from_code(u32::from_le_bytes(
            self.bytes[636..640].try_into().expect("4 bytes"),
        ))
    }

    /// The index-to-world transform: `world = m * ijk + t`, `m` row-major (the double
    /// precision copy the grid stores).
    pub fn transform(&self) -> Result<([[f64; 3]; 3], [f64; 3])> {
        const WHAT: &str = "NanoVDB grid map";
        let (b, map) = (&self.bytes[..], 296);
        let mut m = [[0.0; 3]; 3];
        for (r, row) in m.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x = f64_at(b, map + 88 + 8 * (3 * r + c), WHAT)?;
            }
        }
        let mut t = [0.0; 3];
        for (k, x) in t.iter_mut().enumerate() {
            *x = f64_at(b, map + 232 + 8 * k, WHAT)?;
        }
        Ok((m, t))
    }

    /// Whether the checksum is present and matches (`None`: the grid has none, as Warp's
    /// builders leave it).
    ///
    /// # Errors
    /// When the offsets the checksum's ranges come from are corrupt.
    pub fn checksum_matches(&self) -> Result<Option<bool>> {
        let stored = u64_at(&self.bytes, 8, "NanoVDB grid checksum")?;
        if stored == u64::MAX {
            return Ok(None);
        }
        let (head, tail) = self.checksum()?;
        let head_ok = head == stored as u32;
        let tail_stored = (stored >> 32) as u32;
        Ok(Some(
            head_ok && (tail_stored == u32::MAX || tail == tail_stored),
        ))
    }

    /// The two CRC32s NanoVDB stores (docs/nanovdb.md, section 3): the head over the grid's
    /// headers, the tail over its nodes (as the grid's version lays them out).
    pub fn checksum(&self) -> Result<(u32, u32)> {
        const WHAT: &str = "NanoVDB grid checksum";
        let b = &self.bytes[..];
        let version = u32_at(b, 16, WHAT)?;
        let node_offset = |level: usize| -> Result<usize> {
            offset(GRID_DATA, i64_at(b, GRID_DATA + 8 * level, WHAT)?, WHAT)
        };
        let range = |lo: usize, hi: usize| {
            b.get(lo..hi)
                .ok_or_else(|| Error::invalid_in(WHAT, format!("range {lo}..{hi} past the end")))
        };
        if version > VERSION_32_6_0 {
            let mid = GRID_DATA + TREE_DATA;
            let head = crc32(range(16, mid)?);
            let rest = range(mid, b.len())?;
            let blocks = rest.len() >> 12;
            let tail = if rest.is_empty() {
                u32::MAX
            } else {
                let mut crcs = Vec::with_capacity(4 * blocks);
                for k in 0..blocks {
                    let end = if k + 1 == blocks {
                        rest.len()
                    } else {
                        (k + 1) << 12
                    };
                    crcs.extend(crc32(&rest[k << 12..end]).to_le_bytes());
                }
                crc32(&crcs)
            };
            Ok((head, tail))
        } else {
            let upper = node_offset(2)?;
            let head = crc32(range(16, upper)?);
            // Every node over its full size: the uppers, the lowers, the leaves.
            let l = self.layout()?;
            // TreeData's node counts: leaf @32, lower @36, upper @40.
            let count = |off: usize| u32_at(b, GRID_DATA + off, WHAT).map(|c| c as usize);
            let (n_leaf, n_lo, n_up) = (count(32)?, count(36)?, count(40)?);
            let mut crcs = Vec::new();
            for (first, count, size) in [
                (upper, n_up, l.up_size),
                (node_offset(1)?, n_lo, l.lo_size),
                (node_offset(0)?, n_leaf, l.leaf_size),
            ] {
                for k in 0..count {
                    let start = first + k * size;
                    crcs.extend(crc32(range(start, start + size)?).to_le_bytes());
                }
            }
            Ok((head, crc32(&crcs)))
        }
    }

    /// The per-type layout (docs/nanovdb.md, section 2).
    fn layout(&self) -> Result<Layout> {
        Layout::of(self.grid_type()).ok_or_else(|| {
            Error::invalid_in(
                "NanoVDB grid",
                format!("value type {:?} is not read", self.grid_type()),
            )
        })
    }

    /// The root's position in the buffer.
    fn root(&self) -> Result<usize> {
        const WHAT: &str = "NanoVDB tree";
        let root = offset(GRID_DATA, i64_at(&self.bytes, GRID_DATA + 24, WHAT)?, WHAT)?;
        if root.checked_add(28).is_none_or(|e| e > self.bytes.len()) {
            return Err(Error::invalid_in(
                WHAT,
                format!("root at {root} is past the end ({})", self.bytes.len()),
            ));
        }
        Ok(root)
    }

    /// The index bounding box of the active values (the root's), inclusive.
    pub fn index_bbox(&self) -> Result<([i32; 3], [i32; 3])> {
        let root = self.root()?;
        let at = |k: usize| u32_at(&self.bytes, root + 4 * k, "NanoVDB root").map(|v| v as i32);
        Ok(([at(0)?, at(1)?, at(2)?], [at(3)?, at(4)?, at(5)?]))
    }

    /// The value of voxel `ijk` of a `Float` grid: its leaf's stored value (active or not),
    /// a tile's value, or the background.
    ///
    /// # Errors
    /// Another value type; a corrupt buffer (an offset or a read past its end).
    pub fn value_f32(&self, ijk: [i32; 3]) -> Result<f32> {
        const WHAT: &str = "NanoVDB lookup";
        if self.grid_type() != GridType::Float {
            return Err(Error::invalid_in(
                WHAT,
                format!("value_f32 of a {:?} grid", self.grid_type()),
            ));
        }
        let l = self.layout()?;
        let b = &self.bytes[..];
        let root = self.root()?;
        let [i, j, k] = ijk.map(|x| x as u32);
        let key = (k >> 12) as u64 | ((j >> 12) as u64) << 21 | ((i >> 12) as u64) << 42;
        let tiles = u32_at(b, root + 24, WHAT)? as usize;
        let mut found = None;
        for t in 0..tiles {
            let tile = root + l.root_size + t * l.tile_size;
            if u64_at(b, tile, WHAT)? == key {
                found = Some(tile);
                break;
            }
        }
        let Some(tile) = found else {
            return f32_at(b, root + l.background, WHAT);
        };
        let child = i64_at(b, tile + 8, WHAT)?;
        if child == 0 {
            return f32_at(b, tile + l.tile_value, WHAT);
        }
        let bit = |node: usize, mask: usize, n: u32| -> Result<bool> {
            Ok(u64_at(b, node + mask + 8 * (n as usize >> 6), WHAT)? >> (n & 63) & 1 == 1)
        };
        let upper = offset(root, child, WHAT)?;
        let nu = ((i & 4095) >> 7) << 10 | ((j & 4095) >> 7) << 5 | (k & 4095) >> 7;
        let entry = upper + l.up_table + nu as usize * l.stride;
        if !bit(upper, 4128, nu)? {
            return f32_at(b, entry, WHAT);
        }
        let lower = offset(upper, i64_at(b, entry, WHAT)?, WHAT)?;
        let nl = ((i & 127) >> 3) << 8 | ((j & 127) >> 3) << 4 | (k & 127) >> 3;
        let entry = lower + l.lo_table + nl as usize * l.stride;
        if !bit(lower, 544, nl)? {
            return f32_at(b, entry, WHAT);
        }
        let leaf = offset(lower, i64_at(b, entry, WHAT)?, WHAT)?;
        let n = (i & 7) << 6 | (j & 7) << 3 | (k & 7);
        f32_at(b, leaf + l.leaf_table + 4 * n as usize, WHAT)
    }
}

/// The offsets and sizes that depend on the value type (docs/nanovdb.md, section 2).
struct Layout {
    root_size: usize,
    background: usize,
    tile_size: usize,
    tile_value: usize,
    stride: usize,
    up_table: usize,
    up_size: usize,
    lo_table: usize,
    lo_size: usize,
    leaf_table: usize,
    leaf_size: usize,
}

impl Layout {
    fn of(t: GridType) -> Option<Layout> {
        let l = |root_size,
                 background,
                 tile_size,
                 tile_value,
                 stride,
                 up: (usize, usize),
                 lo: (usize, usize),
                 leaf: (usize, usize)| Layout {
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
        };
        Some(match t {
            GridType::Float | GridType::Int32 => {
                l(64, 28, 32, 20, 8, (8256, 270400), (1088, 33856), (96, 2144))
            }
            GridType::Double => l(
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
                96,
                28,
                32,
                20,
                16,
                (8256, 532544),
                (1088, 66624),
                (128, 6272),
            ),
            GridType::Index | GridType::OnIndex => {
                l(96, 32, 32, 24, 8, (8256, 270400), (1088, 33856), (80, 96))
            }
            GridType::Other(_) => return None,
        })
    }
}

/// The grids of an `.nvdb` file's bytes, every segment's (uncompressed or ZIP; not BLOSC).
///
/// # Errors
/// [`Error::InvalidArgument`]: a short or unknown header, a major version other than 32, a
/// BLOSC or unknown codec, a ZIP stream that does not inflate to the grid's size, metadata
/// or a payload past the end, a payload whose size is not the
/// grid's, a grid that fails [`NvdbGrid::from_bytes`].
pub fn read_nvdb(bytes: &[u8]) -> Result<Vec<NvdbGrid>> {
    const WHAT: &str = "NanoVDB file";
    let mut grids = Vec::new();
    let mut at = 0usize;
    while at < bytes.len() {
        let magic = u64_at(bytes, at, WHAT)?;
        if magic != MAGIC_0 && magic != MAGIC_FILE {
            if magic.swap_bytes() == MAGIC_0 || magic.swap_bytes() == MAGIC_FILE {
                return Err(Error::invalid_in(WHAT, "written with the other byte order"));
            }
            return Err(Error::invalid_in(
                WHAT,
                format!("magic {magic:#018x} at {at} is not NanoVDB's"),
            ));
        }
        let version = u32_at(bytes, at + 8, WHAT)?;
        if version_major(version) != 32 {
            return Err(Error::invalid_in(
                WHAT,
                format!(
                    "version {} (major), only 32 is read",
                    version_major(version)
                ),
            ));
        }
        let count = u16_at(bytes, at + 12, WHAT)? as usize;
        let codec = u16_at(bytes, at + 14, WHAT)?;
        match codec {
            0 | 1 => {}
            2 => {
                return Err(Error::invalid_in(
                    WHAT,
                    "BLOSC-compressed: only uncompressed and ZIP files are read",
                ))
            }
            c => return Err(Error::invalid_in(WHAT, format!("unknown codec {c}"))),
        }
        at += FILE_HEADER;
        let mut sizes = Vec::with_capacity(count);
        for _ in 0..count {
            let grid_size = u64_at(bytes, at, WHAT)?;
            let file_size = u64_at(bytes, at + 8, WHAT)?;
            if codec == 0 && grid_size != file_size {
                return Err(Error::invalid_in(
                    WHAT,
                    format!("a grid of {grid_size} bytes stored in {file_size}"),
                ));
            }
            let name = u32_at(bytes, at + 136, WHAT)? as usize;
            at = at
                .checked_add(FILE_META + name)
                .filter(|e| *e <= bytes.len())
                .ok_or_else(|| Error::invalid_in(WHAT, "grid metadata past the end"))?;
            sizes.push(grid_size as usize);
        }
        for size in sizes {
            // ZIP: the stream's length (u64), then one zlib stream of the grid. (Upstream counts
            // the length word in the metadata's fileSize, Warp does not: neither is read.)
            let (start, stored) = if codec == 1 {
                let n = u64_at(bytes, at, WHAT)?;
                (at + 8, usize::try_from(n).unwrap_or(usize::MAX))
            } else {
                (at, size)
            };
            let end = start
                .checked_add(stored)
                .filter(|e| *e <= bytes.len())
                .ok_or_else(|| {
                    Error::invalid_in(
                        WHAT,
                        format!(
                            "a grid of {stored} bytes at {start} is past the end ({})",
                            bytes.len()
                        ),
                    )
                })?;
            let grid = if codec == 1 {
                let g = miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(
                    &bytes[start..end],
                    size,
                )
                .map_err(|e| {
                    Error::invalid_in(
                        WHAT,
                        format!("a ZIP stream at {start} does not inflate: {e:?}"),
                    )
                })?;
                if g.len() != size {
                    return Err(Error::invalid_in(
                        WHAT,
                        format!("a ZIP stream inflates to {} bytes, not {size}", g.len()),
                    ));
                }
                g
            } else {
                bytes[start..end].to_vec()
            };
            grids.push(NvdbGrid::from_bytes(grid)?);
            at = end;
        }
    }
    Ok(grids)
}

/// [`read_nvdb`] of the file at `path`.
///
/// # Errors
/// As [`read_nvdb`], and an unreadable file, each naming the path.
pub fn load_nvdb(path: impl AsRef<Path>) -> Result<Vec<NvdbGrid>> {
    let path = path.as_ref();
    let named = |why: String| Error::invalid_in(&format!("load_nvdb(\"{}\")", path.display()), why);
    let bytes = std::fs::read(path).map_err(|e| named(e.to_string()))?;
    read_nvdb(&bytes).map_err(|e| match e {
        Error::InvalidArgument { what } => named(what),
        e => e,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_is_zlibs() {
        assert_eq!(crc32(b""), 0);
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    /// `tests/data/warp_sphere_f32.nvdb`, written by NVIDIA Warp 1.19 (on the CPU) with:
    ///
    /// ```text
    /// i, j, k = np.meshgrid(*[np.arange(20)] * 3, indexing="ij")
    /// d = np.sqrt((i - 9.5) ** 2 + (j - 9.5) ** 2 + (k - 9.5) ** 2) - 6.0
    /// v = wp.Volume.load_from_numpy(d.astype(np.float32), min_world=(-1.0, 2.0, 0.5),
    ///                               voxel_size=0.25, bg_value=7.5, device="cpu")
    /// v.save_to_nvdb("warp_sphere_f32_zip.nvdb", codec="zip")
    /// ```
    fn warp_sphere_zip() -> Vec<u8> {
        std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/data/warp_sphere_f32_zip.nvdb"
        ))
        .expect("the fixture")
    }

    /// The same file as Warp writes it uncompressed (`codec="none"`, its default): the ZIP
    /// file's header and metadata with codec 0 and fileSize = gridSize, then the grid.
    fn warp_sphere() -> Vec<u8> {
        let zip = warp_sphere_zip();
        let grid = read_nvdb(&zip).unwrap().remove(0);
        let name = u32::from_le_bytes(zip[16 + 136..16 + 140].try_into().unwrap()) as usize;
        let mut out = zip[..FILE_HEADER + FILE_META + name].to_vec();
        out[14..16].copy_from_slice(&0u16.to_le_bytes());
        out[16 + 8..16 + 16].copy_from_slice(&(grid.as_bytes().len() as u64).to_le_bytes());
        out[16 + 168..16 + 170].copy_from_slice(&0u16.to_le_bytes());
        out.extend_from_slice(grid.as_bytes());
        out
    }

    /// The fixture's value at `ijk`: the array's inside it (the same f64 arithmetic, then
    /// rounded to f32 as numpy's `astype` does), the background outside.
    fn sphere_value(ijk: [i32; 3]) -> f32 {
        if ijk.iter().all(|c| (0..20).contains(c)) {
            let d = ijk.map(|c| c as f64 - 9.5);
            ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 6.0) as f32
        } else {
            7.5
        }
    }

    /// A file Warp wrote reads back: its metadata, its transform, and every voxel's value
    /// (inside the array, in its leaves beyond it, in other leaves' and the root's
    /// background, at negative coordinates) bit for bit. Lookups of this reader matched
    /// Warp's `volume_lookup_f` on 6000 random voxels of this file and two of Warp's test
    /// assets when it was written.
    #[test]
    fn reads_a_file_warp_wrote() {
        let grids = read_nvdb(&warp_sphere()).unwrap();
        assert_eq!(grids, read_nvdb(&warp_sphere_zip()).unwrap());
        assert_eq!(grids.len(), 1);
        let g = &grids[0];
        assert_eq!(g.grid_type(), GridType::Float);
        // Warp's builders leave the checksum out.
        assert_eq!(g.checksum_matches().unwrap(), None);
        assert_eq!(g.index_bbox().unwrap(), ([0, 0, 0], [23, 23, 23]));
        let (m, t) = g.transform().unwrap();
        assert_eq!(m, [[0.25, 0.0, 0.0], [0.0, 0.25, 0.0], [0.0, 0.0, 0.25]]);
        assert_eq!(t, [-1.0, 2.0, 0.5]);
        for i in -9..30 {
            for j in [-4100, -1, 0, 7, 8, 19, 20, 23, 24, 130, 5000] {
                for k in -3..26 {
                    let ijk = [i, j, k];
                    assert_eq!(
                        g.value_f32(ijk).unwrap().to_bits(),
                        sphere_value(ijk).to_bits(),
                        "voxel {ijk:?}"
                    );
                }
            }
        }
        assert!(g.value_f32([i32::MIN, i32::MAX, 0]).unwrap() == 7.5);
    }

    /// The checksum as NanoVDB computes it (verified, when written, against the stored
    /// checksums of four upstream 32.3.3 grids; this fixture is a 32.8 grid, whose tail
    /// layout is checked here only against itself): stored, it matches; a changed node or
    /// header byte does not.
    #[test]
    fn checksums_detect_changes() {
        let mut bytes = read_nvdb(&warp_sphere()).unwrap()[0].as_bytes().to_vec();
        let g = NvdbGrid::from_bytes(bytes.clone()).unwrap();
        let (head, tail) = g.checksum().unwrap();
        bytes[8..16].copy_from_slice(&(head as u64 | (tail as u64) << 32).to_le_bytes());
        let g = NvdbGrid::from_bytes(bytes.clone()).unwrap();
        assert_eq!(g.checksum_matches().unwrap(), Some(true));
        for at in [300, bytes.len() - 5] {
            let mut b = bytes.clone();
            b[at] ^= 1;
            let g = NvdbGrid::from_bytes(b).unwrap();
            assert_eq!(
                g.checksum_matches().unwrap(),
                Some(false),
                "byte {at} changed"
            );
        }
    }

    /// The inputs of the builder fixtures: Warp 1.19 wrote `tests/data/warp_tiles_f32_zip.nvdb`,
    /// `warp_tiles_index_zip.nvdb` and `warp_voxels_onindex_zip.nvdb` on the CPU with
    ///
    /// ```text
    /// M = wp.mat33(0.5, 0.125, 0.0, 0.0, 0.25, 0.0625, 0.03125, 0.0, 1.0)
    /// t = (1.5, -2.25, 3.0)
    /// tiles = wp.array(FIXTURE_TILES, dtype=wp.vec3i, device="cpu")
    /// wp.Volume.allocate_by_tiles(tiles, bg_value=2.5, translation=t, transform=M,
    ///     device="cpu").save_to_nvdb("warp_tiles_f32_zip.nvdb", codec="zip")
    /// wp.Volume.allocate_by_tiles(tiles, bg_value=None, translation=t, transform=M,
    ///     device="cpu").save_to_nvdb("warp_tiles_index_zip.nvdb", codec="zip")
    /// voxels = wp.array(FIXTURE_VOXELS, dtype=wp.vec3i, device="cpu")
    /// wp.Volume.allocate_by_voxels(voxels, voxel_size=0.25, translation=t,
    ///     device="cpu").save_to_nvdb("warp_voxels_onindex_zip.nvdb", codec="zip")
    /// ```
    const FIXTURE_TILES: [[i32; 3]; 7] = [
        [0, 0, 0],
        [8, 3, -9],
        [-1, -1, -1],
        [4095, 0, 7],
        [4096, -4097, 130],
        [-300, 20, -5],
        [8, 3, -9],
    ];
    /// See [`FIXTURE_TILES`].
    const FIXTURE_VOXELS: [[i32; 3]; 12] = [
        [0, 0, 0],
        [1, 0, 0],
        [7, 7, 7],
        [0, 1, 0],
        [0, 0, 1],
        [-1, -1, -1],
        [8, 3, -9],
        [9, 3, -9],
        [4095, 0, 7],
        [-4097, 5, 6],
        [63, 63, 63],
        [0, 0, 0],
    ];

    fn fixture(name: &str) -> NvdbGrid {
        let path = format!("{}/../tests/data/{name}", env!("CARGO_MANIFEST_DIR"));
        load_nvdb(path).unwrap().remove(0)
    }

    /// warp-core's builder makes Warp's buffers: every byte but the world bbox (560..608,
    /// which Warp's CPU builder computes from `min..max+1` and ours, like Warp's CUDA
    /// builder, from `min..max`; warp-core's `compares_with_warp_dumps` checks that this is
    /// the only difference on 43 larger random builds).
    #[test]
    fn builder_rebuilds_warp_fixtures() {
        use warp_core::objects::nanovdb as nv;
        let map = nv::Map {
            mat: [[0.5, 0.125, 0.0], [0.0, 0.25, 0.0625], [0.03125, 0.0, 1.0]],
            translation: [1.5, -2.25, 3.0],
        };
        let float = nv::BuildKind::Value {
            grid_type: nv::GridType::Float,
            background: &2.5f32.to_le_bytes(),
        };
        let voxel_map = nv::Map::uniform(0.25, map.translation);
        for (name, ours) in [
            (
                "warp_tiles_f32_zip.nvdb",
                nv::build_from_tiles(float, &FIXTURE_TILES, &map),
            ),
            (
                "warp_tiles_index_zip.nvdb",
                nv::build_from_tiles(nv::BuildKind::Index, &FIXTURE_TILES, &map),
            ),
            (
                "warp_voxels_onindex_zip.nvdb",
                nv::build_from_voxels(&FIXTURE_VOXELS, &voxel_map),
            ),
        ] {
            let (ours, warp) = (ours.unwrap(), fixture(name));
            let warp = warp.as_bytes();
            assert_eq!(ours.len(), warp.len(), "{name}");
            let bbox = nv::grid::WORLD_BBOX..nv::grid::WORLD_BBOX + 48;
            let diff = (0..ours.len()).find(|k| !bbox.contains(k) && ours[*k] != warp[*k]);
            assert_eq!(diff, None, "{name}: first differing byte");
        }
    }

    /// Truncated, foreign, compressed and corrupted input is an `Err` saying what is wrong,
    /// never a panic.
    #[test]
    fn bad_files_are_errors() {
        let file = warp_sphere();
        let msg = |r: Result<Vec<NvdbGrid>>| r.unwrap_err().to_string();
        assert!(msg(read_nvdb(&file[..10])).contains("past its end"));
        assert!(msg(read_nvdb(&file[..file.len() - 1])).contains("past the end"));
        let mut b = file.clone();
        b[0] ^= 0xff;
        assert!(msg(read_nvdb(&b)).contains("is not NanoVDB's"));
        let mut b = file.clone();
        b[..8].copy_from_slice(&MAGIC_0.swap_bytes().to_le_bytes());
        assert!(msg(read_nvdb(&b)).contains("byte order"));
        let mut b = file.clone();
        b[14] = 2;
        assert!(msg(read_nvdb(&b)).contains("BLOSC"));
        let zip = warp_sphere_zip();
        assert!(msg(read_nvdb(&zip[..zip.len() - 9])).contains("past the end"));
        let mut b = zip.clone();
        let last = b.len() - 20;
        b[last] ^= 0x55;
        assert!(msg(read_nvdb(&b)).contains("ZIP stream"));
        let mut b = file.clone();
        b[8..12].copy_from_slice(&(31u32 << 21).to_le_bytes());
        assert!(msg(read_nvdb(&b)).contains("only 32"));
        let e = load_nvdb("/nonexistent/x.nvdb").unwrap_err().to_string();
        assert!(e.contains("/nonexistent/x.nvdb"), "{e}");

        // Corrupt offsets inside the grid: every lookup is an Err or a value, never a panic.
        let grid = read_nvdb(&file).unwrap()[0].as_bytes().to_vec();
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..300 {
            let mut b = grid.clone();
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            // Somewhere in the tree structure (root, tiles, node tables).
            let at = GRID_DATA + (rng % 40_000) as usize;
            b[at] = (rng >> 32) as u8;
            if let Ok(g) = NvdbGrid::from_bytes(b) {
                for ijk in [[0, 0, 0], [9, 9, 9], [-5, 3, 30], [23, 23, 23]] {
                    let _ = g.value_f32(ijk);
                }
            }
        }
        let mut b = grid.clone();
        b[GRID_DATA + 24..GRID_DATA + 32].copy_from_slice(&i64::MAX.to_le_bytes());
        assert!(NvdbGrid::from_bytes(b).is_err());
        let int_grid = {
            let mut b = grid.clone();
            b[636..640].copy_from_slice(&4u32.to_le_bytes());
            NvdbGrid::from_bytes(b).unwrap()
        };
        assert!(int_grid
            .value_f32([0, 0, 0])
            .unwrap_err()
            .to_string()
            .contains("Int32"));
    }
}
