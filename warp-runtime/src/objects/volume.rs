//! [`Volume`]: Warp's sparse volume, a NanoVDB grid on one device. Load one from an `.nvdb`
//! file ([`Volume::load`]), make one from a dense array ([`Volume::from_dense`]) or allocate
//! its leaves from tiles or voxels ([`Volume::allocate_by_tiles`],
//! [`Volume::allocate_by_voxels`]), pass it to kernels as `vol: Volume<T>` and sample it
//! there (`volume_sample`, `volume_lookup`, `volume_store`, the transforms).
//!
//! The grid's bytes are the NanoVDB layout itself (warp-core `objects::nanovdb`), kept as
//! 64-bit words so that every value is aligned for the kernels' atomic reads; nothing reaches
//! a kernel that `nanovdb::validate` has not accepted, which is what lets the kernel-side
//! lookups skip bounds checks. The value type is the Rust type parameter: a `Volume<f32>`
//! holds a Float grid, and loading a file of another type is an `Err` naming both.
//!
//! Gradients: [`Volume::with_grad`] adds a gradient grid, zeros of the grid's size; the
//! adjoints of `volume_sample`, `volume_sample_grad` and `volume_lookup` add into
//! it at the byte offsets the forward pass read (leaf values, tile values, the background),
//! and [`Volume::grad_volume`] reads it back as a volume of the same topology.

use std::marker::PhantomData;
use std::path::Path;

use glam::{IVec3, Vec3};
use warp_core::objects::nanovdb::{self, BuildKind, GridInfo, GridType, Map};
use warp_core::objects::volume::{VolumeGrid, VolumeValue, VolumeView, VoxelIndex};

use super::nvdb::{self, Codec, NvdbGrid};
use super::HostObject;
use crate::array::Array;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::ArgCtx;

/// Warp's volume sampling modes (`wp.Volume.CLOSEST`): the nearest voxel.
pub const VOLUME_CLOSEST: i32 = 0;
/// Warp's `wp.Volume.LINEAR`: trilinear interpolation of the 8 voxels around the position.
pub const VOLUME_LINEAR: i32 = 1;

/// The element's name in messages (`f32`, `Vec3`, `VoxelIndex`).
fn elem_name<T: VolumeGrid>() -> &'static str {
    let n = std::any::type_name::<T>();
    n.rsplit("::").next().unwrap_or(n)
}

/// 32-byte aligned bytes: what kernel views need of a host copy of a grid.
#[repr(C, align(32))]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Block([u64; 4]);

/// A copy of `bytes` in 32-byte aligned memory (zero-padded to a whole block; a grid's size
/// is a multiple of 32). Hosts are little-endian, as NanoVDB's bytes: copies are the values.
fn aligned<W: bytemuck::Pod + Default>(bytes: &[u8]) -> Vec<W> {
    let n = bytes.len().div_ceil(std::mem::size_of::<W>());
    let mut w = vec![W::default(); n];
    bytemuck::cast_slice_mut::<W, u8>(&mut w)[..bytes.len()].copy_from_slice(bytes);
    w
}

/// `v`'s bytes as the grid stores them.
fn value_bytes<T: VolumeValue>(v: T) -> Vec<u8> {
    let mut b = Block::default();
    // SAFETY: the block is 32 bytes, aligned, and ours; every value type fits (24 bytes at most).
    unsafe { T::store(b.0.as_mut_ptr().cast::<u8>(), v) };
    bytemuck::bytes_of(&b)[..T::SIZE as usize].to_vec()
}

/// A sparse volume on one device (Warp's `wp.Volume`): a NanoVDB grid of `T` values, or of
/// voxel indices for `Volume<VoxelIndex>`.
///
/// ```ignore
/// use warp_lang as wp;
/// use wp::prelude::*;
///
/// #[wp::kernel]
/// fn sample(vol: Volume<f32>, points: Array<Vec3>, out: Array<f32>) {
///     let i = tid();
///     let uvw = volume_world_to_index(vol, points[i]);
///     out[i] = volume_sample(vol, uvw, VOLUME_LINEAR);
/// }
/// ```
pub struct Volume<T: VolumeGrid> {
    device: Device,
    /// The grid's bytes as words (a grid's size is a multiple of 32 bytes).
    words: Array<u64>,
    /// The gradient: the grid's size in zeros, accumulated into by adjoints at value offsets.
    grad: Option<Array<u64>>,
    info: GridInfo,
    /// TreeData's active voxel count.
    voxel_count: u64,
    _t: PhantomData<fn() -> T>,
}

impl<T: VolumeGrid> Clone for Volume<T> {
    fn clone(&self) -> Self {
        Volume {
            device: self.device.clone(),
            words: self.words.clone(),
            grad: self.grad.clone(),
            info: self.info,
            voxel_count: self.voxel_count,
            _t: PhantomData,
        }
    }
}

impl<T: VolumeGrid> std::fmt::Debug for Volume<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Volume")
            .field("element", &elem_name::<T>())
            .field("device", &self.device.alias())
            .field("grid_type", &self.info.grid_type)
            .field("bytes", &self.info.size)
            .field("leaves", &self.info.leaf_count)
            .field("grad", &self.grad.is_some())
            .finish()
    }
}

/// Words back to bytes.
fn to_bytes(words: &[u64]) -> Vec<u8> {
    bytemuck::cast_slice(words).to_vec()
}

/// Every place a lookup can read a value from (the background, value tiles, internal table
/// entries without a child, leaf values), as byte ranges of the grid, handed to `f`.
fn for_each_value(bytes: &[u8], info: &GridInfo, mut f: impl FnMut(std::ops::Range<usize>)) {
    let l = info.layout;
    let vs = l.value_size;
    let word = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
    let root = info.root as usize;
    f(root + l.background..root + l.background + vs);
    for t in 0..info.tile_count as usize {
        let tile = root + l.root_size + t * l.tile_size;
        if word(tile + 8) == 0 {
            f(tile + l.tile_value..tile + l.tile_value + vs);
        }
    }
    let internal = [
        (
            info.first_upper,
            info.upper_count,
            l.up_size,
            l.up_table,
            nanovdb::UPPER_CHILD_MASK,
            nanovdb::UPPER_LOG2,
        ),
        (
            info.first_lower,
            info.lower_count,
            l.lo_size,
            l.lo_table,
            nanovdb::LOWER_CHILD_MASK,
            nanovdb::LOWER_LOG2,
        ),
    ];
    for (first, count, size, table, mask, log2) in internal {
        for n in 0..count as usize {
            let node = first as usize + n * size;
            for e in 0..1usize << (3 * log2) {
                if word(node + mask + 8 * (e >> 6)) >> (e & 63) & 1 == 0 {
                    let at = node + table + e * l.stride;
                    f(at..at + vs);
                }
            }
        }
    }
    for n in 0..info.leaf_count as usize {
        let values = info.first_leaf as usize + n * l.leaf_size + l.leaf_table;
        f(values..values + 512 * vs);
    }
}

impl<T: VolumeGrid> Volume<T> {
    /// A volume over a NanoVDB grid buffer (one grid, as [`Volume::grid_bytes`] gives it), on
    /// `device`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`]: the buffer fails NanoVDB's structural checks (truncated,
    /// corrupt offsets, an unknown layout), or holds another value type than `T`.
    pub fn from_grid_bytes(bytes: &[u8], device: &Device) -> Result<Self> {
        let what = format!("Volume<{}>", elem_name::<T>());
        let info = nanovdb::validate(bytes).map_err(|e| Error::invalid_in(&what, e))?;
        if !T::GRID_TYPES.contains(&info.grid_type.code()) {
            return Err(Error::invalid_in(
                &what,
                format!(
                    "the grid holds {:?} values, not {}: open it as a Volume of its type",
                    info.grid_type,
                    elem_name::<T>()
                ),
            ));
        }
        if bytes.len() as u64 != info.size {
            return Err(Error::invalid_in(
                &what,
                format!(
                    "{} bytes for a grid of {} (one grid per volume)",
                    bytes.len(),
                    info.size
                ),
            ));
        }
        let words = Array::from_slice(&aligned::<u64>(bytes), device)?;
        let at = nanovdb::GRID_DATA + 56;
        let voxel_count = u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
        Ok(Volume {
            device: device.clone(),
            words,
            grad: None,
            info,
            voxel_count,
            _t: PhantomData,
        })
    }

    /// The first grid of an `.nvdb` file (Warp's `Volume.load_from_nvdb`), on `device`.
    ///
    /// # Errors
    /// As [`nvdb::load_nvdb`] (an unreadable, truncated, corrupt or BLOSC-compressed file), a
    /// stored checksum that does not match, and [`Volume::from_grid_bytes`] (another value
    /// type), each naming the path.
    pub fn load(path: impl AsRef<Path>, device: &Device) -> Result<Self> {
        let path = path.as_ref();
        let grids = nvdb::load_nvdb(path)?;
        let what = format!("Volume::load(\"{}\")", path.display());
        let Some(g) = grids.first() else {
            return Err(Error::invalid_in(&what, "the file holds no grid"));
        };
        // A stored checksum must match (Warp's own grids store none, which is accepted).
        if g.checksum_matches()? == Some(false) {
            return Err(Error::invalid_in(
                &what,
                "the grid's checksum does not match its bytes: the file is corrupt",
            ));
        }
        Self::from_grid_bytes(g.as_bytes(), device).map_err(|e| match e {
            Error::InvalidArgument { what } => Error::InvalidArgument {
                what: format!("Volume::load(\"{}\"): {what}", path.display()),
            },
            e => e,
        })
    }

    /// Writes the grid to an `.nvdb` file (Warp's `Volume.save_to_nvdb`), uncompressed or
    /// ZIP-compressed, with NanoVDB's checksum of its current bytes (Warp writes none).
    ///
    /// # Errors
    /// Device errors of the read-back; an unwritable path.
    pub fn save(&self, path: impl AsRef<Path>, codec: Codec) -> Result<()> {
        // With its checksum (the values may have changed since the grid was made).
        let grid = NvdbGrid::from_bytes(self.grid_bytes()?)?.with_checksum();
        nvdb::save_nvdb(path, &[&grid], codec)
    }

    /// The grid buffer (read back from the device).
    ///
    /// # Errors
    /// Device errors.
    pub fn grid_bytes(&self) -> Result<Vec<u8>> {
        let mut b = to_bytes(&self.words.to_vec()?);
        b.truncate(self.info.size as usize);
        Ok(b)
    }

    /// What the grid's headers say (its type, size, nodes), as validated.
    pub fn info(&self) -> &GridInfo {
        &self.info
    }

    /// The active voxels (NanoVDB's TreeData count: every voxel of the leaves for grids
    /// allocated by tiles, the given voxels for [`Volume::allocate_by_voxels`]).
    pub fn voxel_count(&self) -> u64 {
        self.voxel_count
    }

    /// The device the volume lives on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The index-to-world transform.
    ///
    /// # Errors
    /// Device errors of the read-back.
    pub fn transform(&self) -> Result<Map> {
        nanovdb::read_map(&self.grid_bytes()?)
            .map_err(|e| Error::invalid_in("Volume::transform", e))
    }

    /// The voxel size (NanoVDB's: the rows' sums of the transform's matrix).
    ///
    /// # Errors
    /// Device errors of the read-back.
    pub fn voxel_size(&self) -> Result<[f64; 3]> {
        let m = self.transform()?.mat;
        Ok(m.map(|r| r[0] + r[1] + r[2]))
    }

    /// Adds a gradient grid: kernels' adjoints then accumulate the gradients of the values
    /// they read into it, at the byte offsets they read them from (its other bytes are never
    /// touched, so it starts as zeros and is read back through the grid's structure).
    ///
    /// # Errors
    /// An index grid (its values live in a separate array); device errors.
    pub fn with_grad(mut self) -> Result<Self> {
        if self.info.grid_type.is_index() {
            return Err(Error::invalid_in(
                "Volume::with_grad",
                "an index grid holds no values: give the value array a gradient instead",
            ));
        }
        self.grad = Some(Array::zeros(self.words.len(), &self.device)?);
        Ok(self)
    }

    /// Whether the volume has a gradient grid.
    pub fn requires_grad(&self) -> bool {
        self.grad.is_some()
    }

    /// The gradient as a volume of the same topology (a copy, read back: the grid's structure
    /// with the gradient's values), if the volume has one.
    ///
    /// # Errors
    /// Device errors.
    pub fn grad_volume(&self) -> Result<Option<Volume<T>>> {
        let Some(g) = &self.grad else {
            return Ok(None);
        };
        let grad = to_bytes(&g.to_vec()?);
        let grid = self.grid_bytes()?;
        let mut b = grid.clone();
        for_each_value(&grid, &self.info, |r| {
            b[r.clone()].copy_from_slice(&grad[r])
        });
        Volume::from_grid_bytes(&b, &self.device).map(Some)
    }

    /// Zeroes the gradient (nothing without one), on the device.
    ///
    /// # Errors
    /// Device errors.
    pub fn zero_grad(&self) -> Result<()> {
        match &self.grad {
            Some(g) => g.fill(0),
            None => Ok(()),
        }
    }

    /// The kernel view over the volume's device memory.
    fn view(&self, kernel: &'static str) -> VolumeView<T> {
        let grad = self.grad.as_ref().map_or(0, |g| g.device_address());
        // SAFETY: `info` is what `validate` returned for these very bytes (the buffer is the
        // grid, unchanged in structure: kernels only write values), which is the view's
        // contract; the addresses are of this volume's live buffers on its device.
        unsafe { VolumeView::from_info(&self.info, self.words.device_address(), grad) }
            .with_kernel_name(kernel)
    }
}

/// Warp's refusal of an empty allocation (the builder itself would make an empty grid).
fn not_empty<T>(v: &[T], what: &str, arg: &str) -> Result<()> {
    if v.is_empty() {
        return Err(Error::invalid_in(
            what,
            format!("`{arg}` is empty: a volume needs at least one leaf"),
        ));
    }
    Ok(())
}

impl<T: VolumeValue> Volume<T> {
    /// A value grid whose leaves cover the given tiles (Warp's `Volume.allocate_by_tiles`
    /// with a background value): each entry names the 8x8x8 leaf holding that voxel, every
    /// voxel of those leaves is active and holds `background`, as does everything outside.
    ///
    /// # Errors
    /// No tiles; a singular or non-finite transform; device errors.
    pub fn allocate_by_tiles(
        tiles: &[IVec3],
        background: T,
        map: &Map,
        device: &Device,
    ) -> Result<Self> {
        const WHAT: &str = "Volume::allocate_by_tiles";
        not_empty(tiles, WHAT, "tiles")?;
        let bg = value_bytes(background);
        let kind = super::volume_build::GridKind::Value {
            grid_type: GridType::from_code(T::GRID_TYPES[0]),
            background: &bg,
        };
        // Built on the device from the tiles (uploaded once): no grid crosses to the host.
        let tiles = Array::from_slice(tiles, device)?;
        let input = super::volume_build::BuildInput::Coords(&tiles);
        let b = super::volume_build::build(kind, input, map, WHAT)?;
        Ok(Volume {
            device: device.clone(),
            words: b.words,
            grad: None,
            info: b.info,
            voxel_count: b.voxel_count,
            _t: PhantomData,
        })
    }

    /// A value grid from a dense array (Warp's `Volume.load_from_numpy`): `values` in C
    /// order over `dims = [nx, ny, nz]` (value `(i * ny + j) * nz + k` at voxel `(i, j, k)`),
    /// leaves allocated over the whole box, `background` outside it.
    ///
    /// # Errors
    /// `values.len()` not the product of `dims`, an empty box, or a box beyond the `i32`
    /// index range; a singular transform; device errors.
    pub fn from_dense(
        values: &[T],
        dims: [usize; 3],
        background: T,
        map: &Map,
        device: &Device,
    ) -> Result<Self> {
        const WHAT: &str = "Volume::from_dense";
        let n = dims.iter().try_fold(1usize, |a, d| a.checked_mul(*d));
        if n != Some(values.len()) || values.is_empty() {
            return Err(Error::invalid_in(
                WHAT,
                format!(
                    "{} values for a box of {dims:?} (and the box must not be empty)",
                    values.len()
                ),
            ));
        }
        if dims.iter().any(|d| *d > i32::MAX as usize) {
            return Err(Error::invalid_in(WHAT, format!("a box of {dims:?} voxels")));
        }
        let leaves = dims.map(|d| d.div_ceil(8));
        let mut tiles = Vec::with_capacity(leaves.iter().product());
        for a in 0..leaves[0] {
            for b in 0..leaves[1] {
                for c in 0..leaves[2] {
                    tiles.push([8 * a as i32, 8 * b as i32, 8 * c as i32]);
                }
            }
        }
        let bg = value_bytes(background);
        let kind = BuildKind::Value {
            grid_type: GridType::from_code(T::GRID_TYPES[0]),
            background: &bg,
        };
        let bytes =
            nanovdb::build_from_tiles(kind, &tiles, map).map_err(|e| Error::invalid_in(WHAT, e))?;
        let info = nanovdb::validate(&bytes).map_err(|e| Error::invalid_in(WHAT, e))?;
        // The values, written on the host through the kernels' own store.
        let mut blocks = aligned::<Block>(&bytes);
        // SAFETY: `info` validated these bytes, copied into 32-byte aligned blocks that
        // outlive the view; nothing else touches them meanwhile.
        let view = unsafe { VolumeView::<T>::from_info(&info, blocks.as_mut_ptr() as u64, 0) };
        let [_, ny, nz] = dims;
        for (n, v) in values.iter().enumerate() {
            let (i, j, k) = (n / (ny * nz), n / nz % ny, n % nz);
            warp_core::objects::volume::volume_store(view, i as i32, j as i32, k as i32, *v)
                .map_err(|f| Error::invalid_in(WHAT, f))?;
        }
        Self::from_grid_bytes(bytemuck::cast_slice(&blocks), device)
    }
}

impl Volume<VoxelIndex> {
    /// An index grid over the given tiles (Warp's `Volume.allocate_by_tiles` without a
    /// background): every voxel of the named leaves gets an index, `leaf * 512 + voxel + 1`.
    ///
    /// # Errors
    /// No tiles; a singular or non-finite transform; device errors.
    pub fn allocate_index_by_tiles(tiles: &[IVec3], map: &Map, device: &Device) -> Result<Self> {
        const WHAT: &str = "Volume::allocate_index_by_tiles";
        not_empty(tiles, WHAT, "tiles")?;
        let tiles = Array::from_slice(tiles, device)?;
        let input = super::volume_build::BuildInput::Coords(&tiles);
        let b = super::volume_build::build(super::volume_build::GridKind::Index, input, map, WHAT)?;
        Ok(Volume {
            device: device.clone(),
            words: b.words,
            grad: None,
            info: b.info,
            voxel_count: b.voxel_count,
            _t: PhantomData,
        })
    }

    /// An index grid over exactly the given voxels (Warp's `Volume.allocate_by_voxels`, an
    /// OnIndex grid): active voxels are numbered 1.. in leaf order, everything else is 0.
    ///
    /// # Errors
    /// No voxels; a singular or non-finite transform; device errors.
    pub fn allocate_by_voxels(voxels: &[IVec3], map: &Map, device: &Device) -> Result<Self> {
        const WHAT: &str = "Volume::allocate_by_voxels";
        not_empty(voxels, WHAT, "voxels")?;
        let voxels = Array::from_slice(voxels, device)?;
        let input = super::volume_build::BuildInput::Coords(&voxels);
        let kind = super::volume_build::GridKind::OnIndex;
        let b = super::volume_build::build(kind, input, map, WHAT)?;
        Ok(Volume {
            device: device.clone(),
            words: b.words,
            grad: None,
            info: b.info,
            voxel_count: b.voxel_count,
            _t: PhantomData,
        })
    }

    /// [`Volume::allocate_by_voxels`] of the voxels holding world points (Warp's
    /// `allocate_by_voxels` of world positions: each point's voxel is the rounded index-space
    /// position), on the points' device.
    ///
    /// # Errors
    /// A non-finite point or one outside the `i32` index range (naming it); no points; a
    /// singular transform; device errors.
    pub fn allocate_by_points(points: &Array<Vec3>, map: &Map) -> Result<Self> {
        const WHAT: &str = "Volume::allocate_by_points";
        if points.is_empty() {
            return Err(Error::invalid_in(
                WHAT,
                "`points` is empty: a volume needs at least one leaf",
            ));
        }
        // Each point's voxel is computed where the points are (Warp's f32 rounding), and the
        // grid built there: the points never cross to the host.
        let input = super::volume_build::BuildInput::World(points);
        let kind = super::volume_build::GridKind::OnIndex;
        let b = super::volume_build::build(kind, input, map, WHAT)?;
        Ok(Volume {
            device: points.device().clone(),
            words: b.words,
            grad: None,
            info: b.info,
            voxel_count: b.voxel_count,
            _t: PhantomData,
        })
    }
}

/// The kernel's record on a GPU is the CPU view itself: `wp::volume_t<T>` is laid out as
/// `VolumeView<T>`; the gradient grid travels in it.
impl<T: VolumeGrid> HostObject for Volume<T> {
    type View = VolumeView<T>;
    type Cuda = VolumeView<T>;

    fn device(&self) -> &Device {
        &self.device
    }

    unsafe fn cpu_view(&self, ctx: &ArgCtx<'_>) -> Result<VolumeView<T>> {
        Ok(self.view(ctx.kernel))
    }

    fn cuda_record(&self, ctx: &ArgCtx<'_>) -> Result<VolumeView<T>> {
        Ok(self.view(ctx.kernel))
    }

    fn zero_grad(&self) -> Result<()> {
        Volume::zero_grad(self)
    }
}
