//! Launch plans of the CUDA primitives: which kernels of `wp_primitives.h` run, in which
//! order, over how many blocks, with which buffers.
//!
//! A plan is plain data computed from the sizes alone (never from array contents, which stay
//! on the GPU). The CUDA executor (`cuda.rs`) runs it on a stream; the host test
//! (`tests/cuda_primitives_host.rs`) runs the very same plan over the same kernel source
//! compiled by g++ under a block emulator. So the orchestration tested on the host is the one
//! the GPU runs, and only the NVRTC compile and the hardware are left to the GPU tests.

use crate::cpp_table;

/// The block shape the kernels are compiled for (`WP_PRIM_THREADS`, `WP_PRIM_ITEMS`): a block
/// handles a tile of `threads * items` elements.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Tile {
    /// Threads per block: 16, or a multiple of 32 (whole warps).
    pub threads: u32,
    /// Consecutive elements per thread.
    pub items: u32,
}

impl Tile {
    /// Elements per block.
    pub fn elements(self) -> u64 {
        self.threads as u64 * self.items as u64
    }

    /// Blocks covering `n` elements; at least one, so that a device count is always checked.
    pub fn blocks(self, n: u64) -> u64 {
        n.div_ceil(self.elements()).max(1)
    }

    /// The preprocessor definitions that compile the kernels for this shape.
    pub fn defines(self) -> [(&'static str, String); 2] {
        [
            ("WP_PRIM_THREADS", self.threads.to_string()),
            ("WP_PRIM_ITEMS", self.items.to_string()),
        ]
    }
}

/// The shape the runtime compiles for GPUs: 256 threads of 8 elements (tiles of 2048).
pub const GPU_TILE: Tile = Tile {
    threads: 256,
    items: 8,
};

/// The onesweep kernel of the GPU sort (`WP_PRIM_SORT_VARIANT` in `wp_primitives.h`): how a
/// block ranks its tile's keys by the pass's 8-bit digit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SortVariant {
    /// Two stable 4-bit counting passes in shared memory, values gathered from global memory
    /// (the first GPU sort, kept to measure the others against).
    Nibbles = 0,
    /// Each warp ranks its keys by the whole digit: the lanes of one digit find one another
    /// with eight ballots, counts are per warp; values are loaded coalesced and scattered from
    /// shared memory.
    Ballot = 1,
    /// As `Ballot`, the lanes of one digit found by `__match_any_sync`.
    MatchAny = 2,
}

/// What the GPU sort module is compiled for: the onesweep kernel, the block shape, and the
/// blocks per multiprocessor the onesweep kernel's registers must allow (the minimum of its
/// `__launch_bounds__`: more blocks, fewer registers per thread).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SortConfig {
    /// The onesweep kernel.
    pub variant: SortVariant,
    /// Threads and keys per thread of a block.
    pub tile: Tile,
    /// Resident blocks per multiprocessor the registers must allow (at least 1).
    pub min_blocks: u32,
}

impl SortConfig {
    /// Whether the kernels compile for this configuration: the block is 16 threads or whole
    /// warps (a power of two dividing or divisible by 256 for `Nibbles`), a tile holds at
    /// most 65536 keys (ranks are 16-bit), and at least one block fits. (A tile whose keys and
    /// values pass the 48 KiB of static shared memory, about 6000 keys, is NVRTC's error at
    /// the module's first use.)
    pub fn check(self) -> std::result::Result<(), String> {
        let Tile { threads, items } = self.tile;
        let warps = threads == 16 || (threads >= 32 && threads % 32 == 0);
        let nibbles = threads.is_power_of_two() && (256 % threads == 0 || threads % 256 == 0);
        if !warps || (self.variant == SortVariant::Nibbles && !nibbles) || threads > 1024 {
            return Err(format!(
                "{} threads per block: the sort needs 16, or a multiple of 32 up to 1024 (a \
                 power of two dividing or divisible by 256 for {:?})",
                threads,
                SortVariant::Nibbles
            ));
        }
        if items == 0 || self.tile.elements() > 65536 {
            return Err(format!(
                "{threads} x {items} keys per block: the sort needs 1 to 65536 keys per tile"
            ));
        }
        if self.min_blocks == 0 {
            return Err("`min_blocks` is 0: at least one block must fit".into());
        }
        Ok(())
    }
}

/// The sort module's configuration on GPUs: warp ballots ranking 512 threads of 8 keys
/// (tiles of 4096, so that a tile holds about 16 keys of each of the 256 digits and writes go
/// out in runs), registers for 2 blocks per multiprocessor. Timed on an H200 against the
/// other configurations in one run (`cargo bench --bench spatial -- --primitives`, random
/// i32 keys, CUDA events): 0.088 ms for 1M pairs and 0.758 ms for 16M (21-bit keys, the hash
/// grid's: 0.070 and 0.564), against 0.096 and 0.756 for 256 x 16 with 4 blocks and 0.099
/// and 0.801 with 3 (PyTorch's stable sort: 0.167 and 1.148).
pub const GPU_SORT: SortConfig = SortConfig {
    variant: SortVariant::Ballot,
    tile: Tile {
        threads: 512,
        items: 8,
    },
    min_blocks: 2,
};

/// A configuration a benchmark chose in place of [`GPU_SORT`] (`set_gpu_sort_config`).
static SORT_CHOICE: std::sync::RwLock<Option<SortConfig>> = std::sync::RwLock::new(None);

/// The configuration GPU sorts use now: [`GPU_SORT`], unless a benchmark chose another.
pub fn gpu_sort_config() -> SortConfig {
    SORT_CHOICE
        .read()
        .unwrap_or_else(|p| p.into_inner())
        .unwrap_or(GPU_SORT)
}

/// For benchmarks that compare sort kernels in one process: makes the GPU sorts that follow
/// use `config` (`None`: [`GPU_SORT`] again). Each configuration is its own module, compiled
/// and loaded at its first use; a configuration the kernels do not support is refused.
///
/// # Errors
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming what the kernels do not
/// support.
#[doc(hidden)]
pub fn set_gpu_sort_config(config: Option<SortConfig>) -> crate::Result<()> {
    if let Some(c) = config {
        c.check()
            .map_err(|why| crate::Error::invalid(format!("set_gpu_sort_config({c:?}): {why}")))?;
    }
    *SORT_CHOICE.write().unwrap_or_else(|p| p.into_inner()) = config;
    Ok(())
}

/// How a GPU scans (`array_scan`; compaction and the reductions are not affected).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ScanAlgorithm {
    /// Three launches without inter-block waiting: tile totals, one block scanning them (the
    /// "spine"), tiles rescanned from their offsets ([`scan`]). Reads the input twice; float
    /// results are the same from run to run.
    ThreePass,
    /// One launch after a small init step: decoupled look-back over per-tile status words
    /// ([`scan_onepass`]). Reads the input once. Integer results equal `ThreePass`'s. Float
    /// results are the same from run to run, whichever tiles a look-back finds published:
    /// the tiles' totals are added in one fixed grouping (`scan_lookback_grouped` in
    /// `wp_primitives.h`), another order than `ThreePass`'s, so other bits within the same
    /// rounding bound.
    OnePass,
}

impl ScanAlgorithm {
    /// The plan of a scan by this algorithm (arguments as [`scan`]).
    pub fn plan(self, tile: Tile, t: &'static str, size: u64, len: Len, inclusive: bool) -> Plan {
        match self {
            ScanAlgorithm::ThreePass => scan(tile, t, size, len, inclusive),
            ScanAlgorithm::OnePass => scan_onepass(tile, t, size, len, inclusive),
        }
    }
}

/// The scan and block shape GPUs use for elements of C++ type `t` (`size` bytes) unless a
/// benchmark chose others ([`set_gpu_scan_algorithm`], [`set_gpu_scan_tile`]); the
/// reductions of `t` use the same shape (one module per type).
///
/// - Integers: the single-pass scan in tiles of 512 threads of 16 elements (8 for 8-byte
///   types, whose tile must fit the static shared memory). Integer sums do not depend on
///   their order, so its results are the three-phase scan's.
/// - `f32`: the single-pass scan in tiles of 256 threads of 16. Its float results are the
///   same from run to run (the grouped look-back, `scan_lookback_grouped` in
///   `wp_primitives.h`), as the three-phase scan's are; the two add in other orders, so other
///   bits within the same rounding bound.
/// - Other floats (`f64`, `f16`, `bf16`): the three-phase scan, 256 threads of 8 (their
///   single-pass scan, whose values lie apart from the status words, is untimed).
///
/// Timed in one run (`cargo bench --bench spatial -- --primitives`, CUDA events, H200,
/// 2026-12-03; PyTorch's `cumsum` 0.034 and 0.074 ms), inclusive f32 scans at 1M and 16M:
/// single-pass 256 x 16 0.016 and 0.078 ms (512 x 16 and 1024 x 8 0.080 at 16M), three-phase
/// 256 x 8 0.020 and 0.086 (its best shape, 512 x 8, 0.080 at 16M); the single-pass scan's
/// earlier look-back, which added tiles one after another, took 0.104-0.344 ms at 16M. i32
/// (2026-12-01; `cumsum` 0.031 and 0.069 ms): single-pass 512 x 16 0.015 and 0.072 ms,
/// three-phase 256 x 8 0.021 and 0.096. The f32 sum took 0.027-0.030 ms at 16M in every shape
/// (PyTorch 0.032-0.035).
pub fn default_gpu_scan(t: &str, size: u64) -> (ScanAlgorithm, Tile) {
    if t.starts_with('i') || t.starts_with('u') {
        let items = if size <= 4 { 16 } else { 8 };
        (
            ScanAlgorithm::OnePass,
            Tile {
                threads: 512,
                items,
            },
        )
    } else if size == 4 {
        (
            ScanAlgorithm::OnePass,
            Tile {
                threads: 256,
                items: 16,
            },
        )
    } else {
        (ScanAlgorithm::ThreePass, GPU_TILE)
    }
}

/// The scan and block shape GPUs use now for elements of C++ type `t` (`size` bytes):
/// [`default_gpu_scan`]'s, or what a benchmark or test chose in their place.
pub fn gpu_scan(t: &str, size: u64) -> (ScanAlgorithm, Tile) {
    let (algorithm, tile) = default_gpu_scan(t, size);
    let chosen_alg = *SCAN_CHOICE.read().unwrap_or_else(|p| p.into_inner());
    let chosen_tile = *SCAN_TILE_CHOICE.read().unwrap_or_else(|p| p.into_inner());
    (chosen_alg.unwrap_or(algorithm), chosen_tile.unwrap_or(tile))
}

/// An algorithm a benchmark or test chose in place of the default (`set_gpu_scan_algorithm`).
static SCAN_CHOICE: std::sync::RwLock<Option<ScanAlgorithm>> = std::sync::RwLock::new(None);

/// For benchmarks and tests that compare the scans in one process: makes the GPU scans that
/// follow use `algorithm` for every element type (`None`: [`default_gpu_scan`]'s again). Both
/// are in every scan module.
#[doc(hidden)]
pub fn set_gpu_scan_algorithm(algorithm: Option<ScanAlgorithm>) {
    *SCAN_CHOICE.write().unwrap_or_else(|p| p.into_inner()) = algorithm;
}

/// A block shape a benchmark chose for the GPU scans and reductions in place of the default
/// (`set_gpu_scan_tile`).
static SCAN_TILE_CHOICE: std::sync::RwLock<Option<Tile>> = std::sync::RwLock::new(None);

/// For benchmarks that time block shapes in one process: makes the GPU scans and reductions
/// (`array_scan`, `array_sum/min/max`) that follow compile for `tile`, for every element type
/// (`None`: [`default_gpu_scan`]'s again). Each shape is a module of its
/// own per element type, compiled and loaded at its first use. The kernels need whole warps
/// (a multiple of 32 threads, at most 1024) and, for the scans' tile in shared memory, at
/// most 8192 elements (4-byte types: 8-byte ones need at most 4096, or NVRTC refuses the
/// module's static shared memory).
///
/// # Errors
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming the shape the kernels do
/// not support.
#[doc(hidden)]
pub fn set_gpu_scan_tile(tile: Option<Tile>) -> crate::Result<()> {
    if let Some(t) = tile {
        let warps = t.threads >= 32 && t.threads % 32 == 0 && t.threads <= 1024;
        if !warps || t.items == 0 || t.elements() > 8192 {
            return Err(crate::Error::invalid(format!(
                "set_gpu_scan_tile({t:?}): the scans need whole warps (32 to 1024 threads) and \
                 1 to 8192 elements per block"
            )));
        }
    }
    *SCAN_TILE_CHOICE.write().unwrap_or_else(|p| p.into_inner()) = tile;
    Ok(())
}

/// The tile a module is compiled for on GPUs.
pub fn gpu_tile(module: &Module) -> Tile {
    match module {
        Module::Sort(_, config) => config.tile,
        Module::Scan(_, tile) => *tile,
        Module::Compact { .. } => GPU_TILE,
    }
}

/// The kernels' header, whose sort constants the plans read at compile time (one copy).
const HEADER: &str = include_str!("../../../warp-cuda/cuda/wp_primitives.h");
/// Bits sorted per radix pass on the GPU (`SORT_BITS` in `wp_primitives.h`).
pub const RADIX_BITS: u32 = cpp_table::integer(HEADER, "SORT_BITS");
const RADIX: u64 = 1 << RADIX_BITS;
/// Most passes of a sort (32-bit keys), `SORT_MAX_PASSES`.
const MAX_PASSES: u64 = cpp_table::integer(HEADER, "SORT_MAX_PASSES") as u64;
/// Blocks of the upfront histogram at most (`SORT_HIST_BLOCKS`).
const HIST_BLOCKS: u64 = cpp_table::integer(HEADER, "SORT_HIST_BLOCKS") as u64;

/// A buffer a plan uses: one of the caller's arrays (by position in the primitive's list) or
/// scratch memory the executor allocates for the call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Buf {
    /// The caller's array number `k` (each primitive documents its order).
    User(usize),
    /// Scratch buffer number `k` of [`Plan::scratch`].
    Scratch(usize),
}

/// One 64-bit word of a kernel's `args_t`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Word {
    /// The address of a buffer (plus a byte offset).
    Addr(Buf, u64),
    /// A null pointer (no device count).
    Null,
    /// An integer.
    Int(i64),
    /// The address of the device's fault record (`wp::fault_t`).
    Fault,
    /// The address of the fault record's flag.
    FaultFlag,
}

/// One kernel launch: `blocks` blocks of the tile's threads, no dynamic shared memory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Step {
    /// The entry point (`extern "C"` name).
    pub entry: String,
    /// Grid size.
    pub blocks: u64,
    /// The kernel's argument words (unused words are zero).
    pub args: Vec<Word>,
}

/// Which module of `wp_primitives.h` a plan needs (each is compiled once per GPU and cached).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Module {
    /// Scan and reductions of one element type (its C++ name: `i32`, `f64`, ...), compiled for
    /// one block shape.
    Scan(&'static str, Tile),
    /// Radix sort with one key type (`u32`, `i32`, `f32`), in one configuration.
    Sort(&'static str, SortConfig),
    /// Compaction of elements of `words` words of `word` bytes.
    Compact {
        /// Bytes per word: 1, 2, 4 or 8.
        word: u32,
        /// Words per element.
        words: u32,
    },
}

impl Module {
    /// A name unique to the module (cache key and NVRTC program name).
    pub fn name(&self) -> String {
        match self {
            Module::Scan(t, tile) => {
                format!("wp_prim_scan_{t}_{}x{}", tile.threads, tile.items)
            }
            Module::Sort(k, c) => format!(
                "wp_prim_sort_{k}_v{}_{}x{}_m{}",
                c.variant as u32, c.tile.threads, c.tile.items, c.min_blocks
            ),
            Module::Compact { word, words } => format!("wp_prim_compact_{word}x{words}"),
        }
    }

    /// The module's translation unit: the library header and the entry macro.
    pub fn source(&self) -> String {
        let entries = match self {
            Module::Scan(t, _) => format!("WP_PRIM_SCAN_MODULE({t})"),
            Module::Sort(k, _) => format!("WP_PRIM_SORT_MODULE({k})"),
            Module::Compact { word, words } => {
                let w = match word {
                    1 => "u8",
                    2 => "u16",
                    4 => "u32",
                    _ => "u64",
                };
                format!("WP_PRIM_COMPACT_MODULE({w}, {words})")
            }
        };
        format!("#include \"wp_primitives.h\"\n{entries}\n")
    }

    /// The preprocessor definitions that compile the module for block shape `tile`: the
    /// tile's, and a sort module's kernel variant and blocks per multiprocessor.
    pub fn defines(&self, tile: Tile) -> Vec<(&'static str, String)> {
        let mut d = tile.defines().to_vec();
        if let Module::Sort(_, c) = self {
            d.push(("WP_PRIM_SORT_VARIANT", (c.variant as u32).to_string()));
            d.push(("WP_PRIM_SORT_MIN_BLOCKS", c.min_blocks.to_string()));
        }
        d
    }
}

/// A primitive's launches.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plan {
    /// The module holding every entry the steps name.
    pub module: Module,
    /// Sizes in bytes of the scratch buffers (`Buf::Scratch(k)`); their contents start
    /// unspecified: every plan writes scratch before reading it.
    pub scratch: Vec<u64>,
    /// The launches, in stream order.
    pub steps: Vec<Step>,
}

/// How a primitive's length is given: a host value, or a 1-element i32 array on the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Len {
    /// Exactly this many elements.
    Host(u64),
    /// Read on the device from the caller's array `count` (a `Buf::User`), at most
    /// `capacity`; `arg` is the parameter index faults name.
    Device {
        /// The count array's position in the caller's list.
        count: usize,
        /// The most elements the arrays hold.
        capacity: u64,
        /// The parameter index of `count` in the primitive's fault reports.
        arg: i64,
    },
}

impl Len {
    /// The most elements the kernels may touch (grid sizes follow from it).
    fn capacity(self) -> u64 {
        match self {
            Len::Host(n) => n,
            Len::Device { capacity, .. } => capacity,
        }
    }

    /// The count word and capacity word of a kernel's arguments.
    fn words(self) -> [Word; 2] {
        match self {
            Len::Host(n) => [Word::Null, Word::Int(n as i64)],
            Len::Device {
                count, capacity, ..
            } => [Word::Addr(Buf::User(count), 0), Word::Int(capacity as i64)],
        }
    }

    /// The words of a kernel that checks a device count: fault, flag, count's argument index,
    /// and whether this kernel reports.
    fn report_words(self, report: bool) -> [Word; 4] {
        let arg = match self {
            Len::Host(_) => 0,
            Len::Device { arg, .. } => arg,
        };
        [
            Word::Fault,
            Word::FaultFlag,
            Word::Int(arg),
            Word::Int(report as i64),
        ]
    }
}

fn user(k: usize) -> Word {
    Word::Addr(Buf::User(k), 0)
}

fn scratch(k: usize) -> Word {
    Word::Addr(Buf::Scratch(k), 0)
}

fn step(entry: impl Into<String>, blocks: u64, args: impl IntoIterator<Item = Word>) -> Step {
    Step {
        entry: entry.into(),
        blocks,
        args: args.into_iter().collect(),
    }
}

/// The entry names of the scan module for element type `t`, by operation.
fn scan_entries(t: &str) -> ScanEntries {
    let name = |what: &str| format!("wp_prim_{what}_{t}");
    ScanEntries {
        total: [name("total_sum"), name("total_min"), name("total_max")],
        spine: [name("spine_sum"), name("spine_min"), name("spine_max")],
        down: name("scan_down"),
    }
}

struct ScanEntries {
    total: [String; 3],
    spine: [String; 3],
    down: String,
}

/// A reduction's operator (index into the scan module's entries).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReduceOp {
    /// Sum (wrapping for integers).
    Sum = 0,
    /// Minimum (NaN ignored).
    Min = 1,
    /// Maximum (NaN ignored).
    Max = 2,
}

/// Three-phase scan of `T` (C++ name `t`, `size` bytes). Caller's arrays: 0 input, 1 output
/// (may be the input), then the count array if any. Steps: tile totals (reports a bad device
/// count), the one-block spine, the tiles rescanned; scratch 0 the tile totals.
pub fn scan(tile: Tile, t: &'static str, size: u64, len: Len, inclusive: bool) -> Plan {
    let e = scan_entries(t);
    let nb = tile.blocks(len.capacity());
    let [count, cap] = len.words();
    let s = ReduceOp::Sum as usize;
    Plan {
        module: Module::Scan(t, tile),
        scratch: vec![nb * size],
        steps: vec![
            step(
                e.total[s].clone(),
                nb,
                [user(0), count, cap, scratch(0)]
                    .into_iter()
                    .chain(len.report_words(true)),
            ),
            step(
                e.spine[s].clone(),
                1,
                [scratch(0), Word::Int(nb as i64), Word::Int(1), Word::Null],
            ),
            step(
                e.down.clone(),
                nb,
                [
                    user(0),
                    user(1),
                    count,
                    cap,
                    scratch(0),
                    Word::Int(inclusive as i64),
                ],
            ),
        ],
    }
}

/// Single-pass scan of `T` (C++ name `t`, `size` bytes): decoupled look-back. Caller's arrays
/// as [`scan`].
///
/// Steps: `wp_prim_scan_init` (zeroes the look-back status words and the tile counter,
/// reports a bad device count; a block per tile's worth of words), then
/// `wp_prim_scan_onepass_T` (one block per tile, tiles handed out by the counter).
///
/// Scratch: 0 the tile counter (u32), 1 the status words (u64, one per tile), 2 the tiles'
/// values (T, two per tile: used only where T does not fit beside its flag in the status
/// word, which is the kernel's to decide).
pub fn scan_onepass(tile: Tile, t: &'static str, size: u64, len: Len, inclusive: bool) -> Plan {
    let nb = tile.blocks(len.capacity());
    let [count, cap] = len.words();
    Plan {
        module: Module::Scan(t, tile),
        scratch: vec![4, nb * 8, 2 * nb * size],
        steps: vec![
            step(
                "wp_prim_scan_init",
                nb.div_ceil(tile.elements()),
                [count, cap, scratch(1), Word::Int(nb as i64), scratch(0)]
                    .into_iter()
                    .chain(len.report_words(true)),
            ),
            step(
                format!("wp_prim_scan_onepass_{t}"),
                nb,
                [
                    user(0),
                    user(1),
                    count,
                    cap,
                    Word::Int(inclusive as i64),
                    scratch(1),
                    scratch(2),
                    scratch(0),
                    Word::Int(nb as i64),
                ],
            ),
        ],
    }
}

/// Tiles a block of a reduction totals (`per` of `k_tile_total`).
pub const REDUCE_TILES_PER_BLOCK: u64 = 4;

/// Reduction of `T` into a 1-element array. Caller's arrays: 0 input, 1 out, then the count.
/// Two launches: block totals of `REDUCE_TILES_PER_BLOCK` tiles each, then one block
/// reducing them.
pub fn reduce(tile: Tile, t: &'static str, size: u64, op: ReduceOp, len: Len) -> Plan {
    let e = scan_entries(t);
    let nb = tile.blocks(len.capacity()).div_ceil(REDUCE_TILES_PER_BLOCK);
    let [count, cap] = len.words();
    Plan {
        module: Module::Scan(t, tile),
        scratch: vec![nb * size],
        steps: vec![
            step(
                e.total[op as usize].clone(),
                nb,
                [user(0), count, cap, scratch(0)]
                    .into_iter()
                    .chain(len.report_words(true))
                    .chain([Word::Int(REDUCE_TILES_PER_BLOCK as i64)]),
            ),
            step(
                e.spine[op as usize].clone(),
                1,
                [scratch(0), Word::Int(nb as i64), Word::Int(0), user(1)],
            ),
        ],
    }
}

/// Compaction of elements of `words` words of `word` bytes. Caller's arrays: 0 values,
/// 1 flags (i32), 2 out, 3 out_count (i32), then the count.
pub fn compact(tile: Tile, word: u32, words: u32, len: Len) -> Plan {
    let nb = tile.blocks(len.capacity());
    let [count, cap] = len.words();
    Plan {
        module: Module::Compact { word, words },
        scratch: vec![nb * 4],
        steps: vec![
            step(
                "wp_prim_compact_count",
                nb,
                [user(1), count, cap, scratch(0)]
                    .into_iter()
                    .chain(len.report_words(true)),
            ),
            step(
                "wp_prim_compact_spine",
                1,
                [scratch(0), Word::Int(nb as i64), Word::Int(1), user(3)],
            ),
            step(
                "wp_prim_compact_down",
                nb,
                [user(0), user(1), user(2), count, cap, scratch(0)],
            ),
        ],
    }
}

/// The radix passes of a sort of `key_bits` bits: (shift, mask) per pass.
pub fn radix_passes(key_bits: u32, radix_bits: u32) -> Vec<(u32, u32)> {
    (0..key_bits)
        .step_by(radix_bits as usize)
        .map(|shift| {
            let bits = radix_bits.min(key_bits - shift);
            (shift, (1u32 << bits) - 1)
        })
        .collect()
}

/// LSD radix sort of 32-bit keys (C++ type `k`: `u32`, `i32`, `f32`) with 32-bit values,
/// `key_bits` (1 to 32) low bits of the ordered key, 8 bits per pass (`ceil(key_bits / 8)`
/// passes), by the kernels of `config` (its tile sets the grids). Caller's arrays: 0 keys,
/// 1 values, then the count.
///
/// Steps: `wp_prim_sort_init` (one block: zeroes the histograms and tile counters, reports a
/// bad count), `wp_prim_sort_upsweep_K` (one read of the keys: the digit counts of every pass,
/// and zeroed look-back status words), then one `wp_prim_sort_onesweep_K` per pass.
///
/// Scratch: 0 the histograms (u32, 4 x 256), 1 the tile counters (u32, 4), 2 the look-back
/// status words (u64, passes x tiles x 256), 3 keys and 4 values of ping-pong side B, and for
/// an odd number of passes (3) 5 keys and 6 values of side C, so that the passes go
/// user -> B -> C -> user and no copy is needed. A single pass ends in B and copies back.
pub fn sort(config: SortConfig, k: &'static str, key_bits: u32, len: Len) -> Plan {
    let tile = config.tile;
    let cap = len.capacity();
    let nb = tile.blocks(cap);
    let [count, capw] = len.words();
    let passes = radix_passes(key_bits, RADIX_BITS);
    let np = passes.len();
    // The ping-pong sides each pass reads and writes: 0 the caller's arrays, 1 B, 2 C.
    let sides: Vec<usize> = if np.is_multiple_of(2) || np == 1 {
        (0..=np).map(|p| p % 2).collect()
    } else {
        (0..=np)
            .map(|p| match p {
                0 => 0,
                p if p == np => 0,
                p => 2 - p % 2,
            })
            .collect()
    };
    let side = |s: usize| -> [Word; 2] {
        match s {
            0 => [user(0), user(1)],
            1 => [scratch(3), scratch(4)],
            _ => [scratch(5), scratch(6)],
        }
    };
    let status_pass = nb * RADIX * 8;
    let mut steps = vec![
        step(
            "wp_prim_sort_init",
            1,
            [count, capw, scratch(0), scratch(1)]
                .into_iter()
                .chain(len.report_words(true)),
        ),
        step(
            format!("wp_prim_sort_upsweep_{k}"),
            nb.min(HIST_BLOCKS),
            [
                user(0),
                count,
                capw,
                scratch(0),
                Word::Int(np as i64),
                Word::Int(key_bits as i64),
                scratch(2),
                Word::Int(nb as i64),
                Word::Int(nb.min(HIST_BLOCKS) as i64),
            ],
        ),
    ];
    for (p, &(shift, mask)) in passes.iter().enumerate() {
        let [src_k, src_v] = side(sides[p]);
        let [dst_k, dst_v] = side(if np == 1 { 1 } else { sides[p + 1] });
        steps.push(step(
            format!("wp_prim_sort_onesweep_{k}"),
            nb,
            [
                src_k,
                src_v,
                dst_k,
                dst_v,
                count,
                capw,
                Word::Int(shift as i64),
                Word::Int(mask as i64),
                Word::Addr(Buf::Scratch(0), p as u64 * RADIX * 4),
                Word::Addr(Buf::Scratch(2), p as u64 * status_pass),
                Word::Addr(Buf::Scratch(1), p as u64 * 4),
                Word::Int(nb as i64),
            ],
        ));
    }
    if np == 1 {
        steps.push(step(
            "wp_prim_copy_pairs",
            tile.blocks(cap),
            [scratch(3), scratch(4), user(0), user(1), count, capw],
        ));
    }
    let mut scratch_sizes = vec![
        MAX_PASSES * RADIX * 4,
        MAX_PASSES * 4,
        np as u64 * status_pass,
        cap * 4,
        cap * 4,
    ];
    if !np.is_multiple_of(2) && np > 1 {
        scratch_sizes.extend([cap * 4, cap * 4]);
    }
    Plan {
        module: Module::Sort(k, config),
        scratch: scratch_sizes,
        steps,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_cover_the_key_bits() {
        assert_eq!(radix_passes(32, 4).len(), 8);
        assert_eq!(radix_passes(5, 4), vec![(0, 15), (4, 1)]);
        assert_eq!(radix_passes(1, 4), vec![(0, 1)]);
        assert_eq!(radix_passes(12, 8), vec![(0, 255), (8, 15)]);
        assert_eq!(radix_passes(21, RADIX_BITS).len(), 3);
        assert_eq!(radix_passes(32, RADIX_BITS).len(), 4);
    }

    #[test]
    fn grids_and_scratch_follow_the_sizes() {
        let t = GPU_TILE;
        assert_eq!((t.blocks(0), t.blocks(2048), t.blocks(2049)), (1, 1, 2));
        let p = scan(t, "f32", 4, Len::Host(5000), true);
        assert_eq!(p.scratch, vec![3 * 4]);
        assert_eq!(
            p.steps
                .iter()
                .map(|s| (s.entry.as_str(), s.blocks))
                .collect::<Vec<_>>(),
            vec![
                ("wp_prim_total_sum_f32", 3),
                ("wp_prim_spine_sum_f32", 1),
                ("wp_prim_scan_down_f32", 3)
            ]
        );
        // init, upsweep, one onesweep per 8 bits; a single pass copies back; three passes go
        // user -> B -> C -> user.
        let entries = |s: &Plan| s.steps.iter().map(|s| s.entry.clone()).collect::<Vec<_>>();
        let c = SortConfig {
            tile: t,
            ..GPU_SORT
        };
        let s = sort(c, "u32", 5, Len::Host(10));
        assert_eq!(
            entries(&s),
            [
                "wp_prim_sort_init",
                "wp_prim_sort_upsweep_u32",
                "wp_prim_sort_onesweep_u32",
                "wp_prim_copy_pairs"
            ]
        );
        assert_eq!(sort(c, "u32", 16, Len::Host(10)).steps.len(), 4);
        assert_eq!(sort(c, "u32", 32, Len::Host(10)).steps.len(), 6);
        let s = sort(c, "u32", 21, Len::Host(10));
        assert_eq!(s.steps.len(), 5);
        assert_eq!(s.scratch.len(), 7);
        let hops: Vec<_> = s.steps[2..]
            .iter()
            .map(|s| (s.args[0], s.args[2]))
            .collect();
        assert_eq!(
            hops,
            vec![
                (user(0), scratch(3)),
                (scratch(3), scratch(5)),
                (scratch(5), user(0))
            ]
        );
        // Only the first kernel reports a bad device count.
        let len = Len::Device {
            count: 2,
            capacity: 100,
            arg: 2,
        };
        let s = sort(c, "i32", 32, len);
        assert_eq!(s.steps[0].args[7], Word::Int(1));
        assert!(s
            .steps
            .iter()
            .all(|s| !s.args.contains(&Word::Fault) || s.entry == "wp_prim_sort_init"));
    }

    #[test]
    fn sort_configs_the_kernels_support() {
        assert_eq!(GPU_SORT.check(), Ok(()));
        let with = |variant, threads, items, min_blocks| SortConfig {
            variant,
            tile: Tile { threads, items },
            min_blocks,
        };
        for ok in [
            with(SortVariant::Ballot, 16, 3, 1),
            with(SortVariant::MatchAny, 384, 16, 2),
            with(SortVariant::Nibbles, 512, 8, 1),
        ] {
            assert_eq!(ok.check(), Ok(()), "{ok:?}");
        }
        for bad in [
            with(SortVariant::Ballot, 48, 2, 1),
            with(SortVariant::Ballot, 2048, 2, 1),
            with(SortVariant::Nibbles, 384, 16, 1),
            with(SortVariant::Ballot, 256, 0, 1),
            with(SortVariant::Ballot, 1024, 65, 1),
            with(SortVariant::Ballot, 256, 16, 0),
        ] {
            assert!(bad.check().is_err(), "{bad:?}");
        }
        let e = set_gpu_sort_config(Some(with(SortVariant::Ballot, 48, 2, 1))).unwrap_err();
        assert!(e.to_string().contains("48 threads per block"), "{e}");
        assert_eq!(gpu_sort_config(), GPU_SORT);
        let m = Module::Sort("f32", GPU_SORT);
        assert_eq!(m.name(), "wp_prim_sort_f32_v1_512x8_m2");
        assert_eq!(
            m.defines(GPU_SORT.tile)[2..],
            [
                ("WP_PRIM_SORT_VARIANT", "1".to_string()),
                ("WP_PRIM_SORT_MIN_BLOCKS", "2".to_string())
            ]
        );
    }

    #[test]
    fn onepass_scan_plan() {
        let t = GPU_TILE;
        let p = scan_onepass(t, "f64", 8, Len::Host(5000), false);
        assert_eq!(p.module, Module::Scan("f64", GPU_TILE));
        // Counter, a status word per tile, two values per tile.
        assert_eq!(p.scratch, vec![4, 3 * 8, 2 * 3 * 8]);
        assert_eq!(
            p.steps
                .iter()
                .map(|s| (s.entry.as_str(), s.blocks))
                .collect::<Vec<_>>(),
            vec![("wp_prim_scan_init", 1), ("wp_prim_scan_onepass_f64", 3)]
        );
        assert_eq!(p.steps[1].args[4], Word::Int(0));
        assert_eq!(p.steps[1].args[8], Word::Int(3));
        // More tiles than one init block zeroes; an empty scan still checks its count.
        let p = scan_onepass(t, "i32", 4, Len::Host(2048 * 2048 + 1), true);
        assert_eq!((p.steps[0].blocks, p.steps[1].blocks), (2, 2049));
        assert_eq!(
            scan_onepass(t, "i32", 4, Len::Host(0), true).steps[1].blocks,
            1
        );
        // Only the init step reports a bad device count, with the count's argument index.
        let len = Len::Device {
            count: 2,
            capacity: 100,
            arg: 2,
        };
        let p = scan_onepass(t, "u32", 4, len, true);
        assert_eq!(
            p.steps[0].args[5..],
            [Word::Fault, Word::FaultFlag, Word::Int(2), Word::Int(1)]
        );
        assert!(!p.steps[1].args.contains(&Word::Fault));
        assert_eq!(p.steps[1].args[2], Word::Addr(Buf::User(2), 0));
        // The switch picks the plan; the defaults: integers single-pass, floats three-phase.
        assert_eq!(
            default_gpu_scan("i32", 4),
            (
                ScanAlgorithm::OnePass,
                Tile {
                    threads: 512,
                    items: 16
                }
            )
        );
        assert_eq!(
            default_gpu_scan("u64", 8),
            (
                ScanAlgorithm::OnePass,
                Tile {
                    threads: 512,
                    items: 8
                }
            )
        );
        assert_eq!(
            default_gpu_scan("f32", 4),
            (
                ScanAlgorithm::OnePass,
                Tile {
                    threads: 256,
                    items: 16
                }
            )
        );
        assert_eq!(
            default_gpu_scan("f64", 8),
            (ScanAlgorithm::ThreePass, GPU_TILE)
        );
        assert_eq!(
            ScanAlgorithm::OnePass.plan(t, "u32", 4, len, true),
            scan_onepass(t, "u32", 4, len, true)
        );
        assert_eq!(
            ScanAlgorithm::ThreePass.plan(t, "u32", 4, len, true),
            scan(t, "u32", 4, len, true)
        );
    }

    #[test]
    fn module_sources_name_their_entries() {
        assert_eq!(
            Module::Compact { word: 4, words: 3 }.source(),
            "#include \"wp_primitives.h\"\nWP_PRIM_COMPACT_MODULE(u32, 3)\n"
        );
        assert_eq!(
            Module::Scan("i64", GPU_TILE).name(),
            "wp_prim_scan_i64_256x8"
        );
        // Each block shape is a module of its own.
        let wide = Tile {
            threads: 512,
            items: 16,
        };
        assert_eq!(gpu_tile(&Module::Scan("f32", wide)), wide);
        assert_eq!(Module::Scan("f32", wide).name(), "wp_prim_scan_f32_512x16");
        assert!(set_gpu_scan_tile(Some(Tile {
            threads: 48,
            items: 8
        }))
        .is_err());
        assert!(set_gpu_scan_tile(Some(Tile {
            threads: 1024,
            items: 16
        }))
        .is_err());
    }
}
