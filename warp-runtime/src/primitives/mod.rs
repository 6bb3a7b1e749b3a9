//! Parallel primitives on arrays, on the CPU (rayon) and on CUDA GPUs: scan, reduction
//! (sum, min, max), radix sort of key/value pairs and stream compaction, in the style of
//! Warp's `wp.utils.array_scan`, `radix_sort_pairs` and `array_sum`.
//!
//! | function | element types | what it writes |
//! |---|---|---|
//! | [`array_scan`], [`array_scan_n`] | [`ScanElement`]: i32, u32, i64, u64, f32, f64 | inclusive or exclusive prefix sums |
//! | [`array_sum`], [`array_min`], [`array_max`] (and `_n`) | [`ScanElement`] | one element |
//! | [`radix_sort_pairs`] | keys [`SortKey`]: u32, i32, f32; values [`SortValue`]: u32, i32, f32 | both arrays, in place |
//! | [`compact`], [`compact_n`] | any [`Element`], flags `i32` | the kept elements and their count |
//!
//! # Lengths
//! The plain functions work on whole arrays. The `_n` functions and [`radix_sort_pairs`] take
//! a [`Count`]: a host `usize`, or a 1-element `Array<i32>` on the arrays' device whose value
//! is read where the work runs. On a GPU that means no host synchronisation at all (the
//! kernels read the count), so a count computed by an earlier kernel (the `out_count` of
//! [`compact`], say) feeds the next primitive directly. The arrays must then hold at least
//! as many elements as the count may reach: grids are sized by the arrays' lengths.
//!
//! A host count larger than an array, like every other bad input (length mismatch, device
//! mismatch, a non-contiguous array, overlapping outputs), is an `Err` naming the function,
//! the argument and the values. A device count is checked where it is read: on the CPU
//! before anything is written (an `Err`); on a GPU a count outside `0..=capacity` is a fault
//! (`Error::Fault`, out of bounds on argument `count`, index `[count]`, shape
//! `[capacity + 1]`), reported like a kernel's at the next synchronisation (at once in debug
//! mode), and the primitive processes no element (a scan or sort writes nothing, a reduction
//! writes its identity, a compaction a count of 0).
//!
//! # Devices and streams
//! Everything runs on the arrays' device. On a GPU the kernels are queued on the calling
//! thread's current stream (a [`ScopedStream`](crate::ScopedStream)'s, else the default
//! stream), after the array operations queued before, without waiting: a primitive returns
//! before its result is ready, like a launch. Scratch memory is the device's workspace, which
//! grows to the largest need seen and is reused from call to call. On the CPU a primitive
//! has finished when it returns.
//!
//! # Graphs
//! A primitive reads nothing back, so a [capture](crate::capture) records it like a launch,
//! on every backend: each replay runs it on the arrays' contents at that time, with a device
//! count read where the work runs, and a host count fixed at capture (like a launch's dims).
//! On a GPU nothing is compiled or allocated inside a capture: call the primitive once with
//! the same lengths on the device before capturing (its first call loads its GPU module and
//! sizes the scratch memory that calls reuse).
//!
//! Primitives are not recorded by a [`Tape`](crate::Tape): they have no adjoint.

use crate::array::{Array, Element};
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};

pub mod elements;
#[doc(hidden)]
pub mod plan;

use elements::{Extent, ScanOps, SortKeyOps, SortValueOps};

/// An element type of [`array_scan`] and the reductions: `i32`, `u32`, `i64`, `u64`, `f32`,
/// `f64`.
///
/// Integer sums wrap on overflow (as integer arithmetic does in kernels). Float sums are
/// computed in blocks (a tree of partial sums), so they may differ from a serial sum in the
/// last bits, and differ between the CPU and a GPU; each backend's result is deterministic.
/// Float [`array_min`]/[`array_max`] ignore NaN as the `min`/`max` builtins do (with one NaN
/// operand, the other one): the result is NaN-free unless every element is NaN, in which
/// case it is the identity (+inf for min, -inf for max); which zero a minimum of -0.0 and
/// +0.0 gives is unspecified.
pub trait ScanElement: Element + ScanOps {}
impl<T: Element + ScanOps> ScanElement for T {}

/// A key type of [`radix_sort_pairs`]: `u32`, `i32` or `f32`.
///
/// Keys are sorted by a 32-bit unsigned image that preserves their order: `u32` as is, `i32`
/// with the sign bit flipped (numeric order), `f32` in the order of [`f32::total_cmp`]:
/// `-NaN < -inf < .. < -0.0 < +0.0 < .. < +inf < +NaN` (so -0.0 sorts before +0.0, and NaNs
/// with the sign bit clear sort after +inf; NaNs of different payloads keep a fixed order).
pub trait SortKey: Element + SortKeyOps {}
impl<T: Element + SortKeyOps> SortKey for T {}

/// A value type of [`radix_sort_pairs`]: `u32`, `i32` or `f32` (moved as 32-bit words).
pub trait SortValue: Element + SortValueOps {}
impl<T: Element + SortValueOps> SortValue for T {}

#[cfg(feature = "cuda")]
#[doc(hidden)]
pub use crate::cuda::primitives::compile_module;

/// How many leading elements a primitive processes: a host value, or a 1-element `Array<i32>`
/// on the arrays' device holding it (read where the work runs: no host synchronisation on a
/// GPU). `usize` and `&Array<i32>` convert into it, so `array_scan_n(&a, &b, 10, true)` and
/// `array_scan_n(&a, &b, &count, true)` both work.
#[derive(Clone, Copy, Debug)]
pub enum Count<'a> {
    /// Exactly this many elements.
    Host(usize),
    /// As many as element 0 of this array (on the arrays' device) says.
    Device(&'a Array<i32>),
}

impl From<usize> for Count<'_> {
    fn from(n: usize) -> Self {
        Count::Host(n)
    }
}

impl<'a> From<&'a Array<i32>> for Count<'a> {
    fn from(a: &'a Array<i32>) -> Self {
        Count::Device(a)
    }
}

// ------------------------------------------------------------------------------------------
// Checks shared by every primitive
// ------------------------------------------------------------------------------------------

/// The checks of one call, naming the function in every message (the sparse tier's calls use
/// them too).
pub(crate) struct Check {
    pub(crate) func: &'static str,
}

/// Whether the elements of `a` and `b` share any byte of memory.
pub(crate) fn overlap<T: Element, U: Element>(a: &Array<T>, b: &Array<U>) -> bool {
    if !a.shares_storage_with(b) || a.is_empty() || b.is_empty() {
        return false;
    }
    let (s, t) = (a.device_address() as usize, b.device_address() as usize);
    let (e, f) = (
        s + a.len() * std::mem::size_of::<T>(),
        t + b.len() * std::mem::size_of::<U>(),
    );
    s < f && t < e
}

impl Check {
    fn invalid(&self, what: String) -> Error {
        Error::invalid(format!("{}: {what}", self.func))
    }

    /// Primitives address arrays as flat runs of elements.
    pub(crate) fn contiguous<T: Element>(&self, name: &str, a: &Array<T>) -> Result<()> {
        if a.is_contiguous() {
            return Ok(());
        }
        Err(self.invalid(format!(
            "`{name}` is not contiguous (shape {:?}, strides {:?}); copy it into a new array \
             first",
            a.shape(),
            a.strides()
        )))
    }

    pub(crate) fn same_device(
        &self,
        first: (&str, &Device),
        other: (&'static str, &Device),
    ) -> Result<()> {
        if first.1 == other.1 {
            return Ok(());
        }
        Err(Error::DeviceMismatch {
            kernel: self.func,
            arg: other.0,
            expected: first.1.alias().to_string(),
            found: other.1.alias().to_string(),
        })
    }

    /// `written` must not share memory with `other`, except (when `in_place`) by being
    /// exactly the same elements.
    fn disjoint<T: Element, U: Element>(
        &self,
        written: (&str, &Array<T>),
        other: (&str, &Array<U>),
        in_place: bool,
    ) -> Result<()> {
        let (wn, w) = written;
        let (on, o) = other;
        if !overlap(w, o) {
            return Ok(());
        }
        if in_place
            && w.device_address() == o.device_address()
            && std::mem::size_of::<T>() == std::mem::size_of::<U>()
        {
            return Ok(());
        }
        let how = if in_place {
            "overlap without being the same elements (in place is allowed, partly \
             overlapping is not)"
        } else {
            "share memory (an output must not overlap the other arrays)"
        };
        Err(self.invalid(format!("`{wn}` and `{on}` {how}")))
    }

    /// The count as the backends take it. `capacity` is the most elements the arrays hold,
    /// `limit` names the array that sets it. A device count's value is the backend's to
    /// check (the CPU before writing anything, a GPU where its kernels read it).
    fn count(
        &self,
        count: Count<'_>,
        capacity: usize,
        limit: &'static str,
        device: &Device,
    ) -> Result<Extent> {
        match count {
            Count::Host(n) if n <= capacity => Ok(Extent::Host(n)),
            Count::Host(n) => Err(self.invalid(format!(
                "count {n} is larger than `{limit}` ({capacity} elements)"
            ))),
            Count::Device(c) => {
                self.same_device(("arrays", device), ("count", c.device()))?;
                if c.len() != 1 {
                    return Err(self.invalid(format!(
                        "`count` must be a 1-element array, got shape {:?}",
                        c.shape()
                    )));
                }
                Ok(Extent::Device {
                    count: c.device_address(),
                    capacity,
                    limit,
                })
            }
        }
    }

    /// Lengths the GPU kernels index with 32-bit counts (ranks, output positions).
    fn fits_i32(&self, name: &str, n: usize) -> Result<()> {
        if n <= i32::MAX as usize {
            return Ok(());
        }
        Err(self.invalid(format!(
            "`{name}` has {n} elements, more than the 2^31 - 1 this primitive counts"
        )))
    }
}

// ------------------------------------------------------------------------------------------
// Scan
// ------------------------------------------------------------------------------------------

/// Prefix sums of `input` into `output` (Warp's `array_scan`): `output[i]` is the sum of
/// `input[..=i]` (`inclusive`) or of `input[..i]` (exclusive; `output[0]` is 0).
///
/// `output` may be `input` itself (a scan in place) but may not otherwise overlap it. Both
/// are contiguous 1-D arrays of the same length on the same device. Integer sums wrap; float
/// sums are blocked, see [`ScanElement`].
///
/// ```
/// # use warp_runtime as wp;
/// let dev = wp::cpu();
/// let a = wp::Array::from_slice(&[3, 1, 4, 1, 5], &dev)?;
/// let s = wp::Array::<i32>::zeros(5, &dev)?;
/// wp::array_scan(&a, &s, false)?;
/// assert_eq!(s.to_vec()?, [0, 3, 4, 8, 9]);
/// # Ok::<(), wp::Error>(())
/// ```
///
/// # Errors
/// [`Error::InvalidArgument`] when the lengths differ, an array is not contiguous, or the
/// arrays overlap without being the same; [`Error::DeviceMismatch`] when they are on
/// different devices.
pub fn array_scan<T: ScanElement>(
    input: &Array<T>,
    output: &Array<T>,
    inclusive: bool,
) -> Result<()> {
    let ck = Check { func: "array_scan" };
    if input.len() != output.len() {
        return Err(ck.invalid(format!(
            "`output` has {} elements but `input` has {}",
            output.len(),
            input.len()
        )));
    }
    scan_impl(&ck, input, output, Count::Host(input.len()), inclusive)
}

/// [`array_scan`] of the first `count` elements: the elements of `output` past the count are
/// left alone. `count` is a `usize` or a 1-element `Array<i32>` on the arrays' device (see
/// the [module docs](self) on lengths); both arrays must hold at least `count` elements.
///
/// # Errors
/// As [`array_scan`] (lengths may differ), and [`Error::InvalidArgument`] for a count larger
/// than an array or a count array that is not 1 element; on a GPU, a device count out of
/// range is a fault reported at the next synchronisation.
pub fn array_scan_n<'c, T: ScanElement>(
    input: &Array<T>,
    output: &Array<T>,
    count: impl Into<Count<'c>>,
    inclusive: bool,
) -> Result<()> {
    let ck = Check {
        func: "array_scan_n",
    };
    scan_impl(&ck, input, output, count.into(), inclusive)
}

fn scan_impl<T: ScanElement>(
    ck: &Check,
    input: &Array<T>,
    output: &Array<T>,
    count: Count<'_>,
    inclusive: bool,
) -> Result<()> {
    ck.contiguous("input", input)?;
    ck.contiguous("output", output)?;
    let dev = input.device();
    ck.same_device(("input", dev), ("output", output.device()))?;
    ck.disjoint(("output", output), ("input", input), true)?;
    let (capacity, short) = shorter(("input", input.len()), ("output", output.len()));
    if let Count::Device(c) = count {
        ck.disjoint(("output", output), ("count", c), false)?;
    }
    let len = ck.count(count, capacity, short, dev)?;
    dispatch::scan::<T>(
        dev,
        ck.func,
        input.device_address(),
        output.device_address(),
        len,
        inclusive,
        || uses((input.clone(), output.clone()), count),
    )
}

/// What a graph that records a primitive keeps alive: its arrays and its count array.
fn uses<A: Send + 'static>(arrays: A, count: Count<'_>) -> crate::capturing::Keep {
    let count = match count {
        Count::Device(c) => Some(c.clone()),
        Count::Host(_) => None,
    };
    Box::new((arrays, count))
}

/// The smaller of two arrays' lengths and that array's name.
fn shorter(a: (&'static str, usize), b: (&'static str, usize)) -> (usize, &'static str) {
    if b.1 < a.1 {
        (b.1, b.0)
    } else {
        (a.1, a.0)
    }
}

// ------------------------------------------------------------------------------------------
// Reductions
// ------------------------------------------------------------------------------------------

/// Sum of `values` into `out[0]` (Warp's `array_sum`); 0 for an empty array. `out` is a
/// 1-element array on the same device, not overlapping `values`. Integer sums wrap; float
/// sums are blocked, see [`ScanElement`].
///
/// ```
/// # use warp_runtime as wp;
/// let dev = wp::cpu();
/// let a = wp::Array::from_slice(&[1.5f32, 2.0, -0.5], &dev)?;
/// let out = wp::Array::<f32>::zeros(1, &dev)?;
/// wp::array_sum(&a, &out)?;
/// assert_eq!(out.to_vec()?, [3.0]);
/// # Ok::<(), wp::Error>(())
/// ```
///
/// # Errors
/// [`Error::InvalidArgument`] when `out` is not 1 element, an array is not contiguous or they
/// overlap; [`Error::DeviceMismatch`] when they are on different devices.
pub fn array_sum<T: ScanElement>(values: &Array<T>, out: &Array<T>) -> Result<()> {
    reduce_impl(
        "array_sum",
        values,
        out,
        Count::Host(values.len()),
        plan::ReduceOp::Sum,
    )
}

/// [`array_sum`] of the first `count` elements (a `usize` or a 1-element `Array<i32>` on the
/// device; see the [module docs](self) on lengths).
///
/// # Errors
/// As [`array_sum`], and for a count larger than `values` or a bad count array.
pub fn array_sum_n<'c, T: ScanElement>(
    values: &Array<T>,
    out: &Array<T>,
    count: impl Into<Count<'c>>,
) -> Result<()> {
    reduce_impl(
        "array_sum_n",
        values,
        out,
        count.into(),
        plan::ReduceOp::Sum,
    )
}

/// Minimum of `values` into `out[0]`; NaNs are ignored, and an empty (or all-NaN) array
/// gives the identity (`T::MAX`, or +inf for floats). See [`array_sum`] for the arguments.
///
/// # Errors
/// As [`array_sum`].
pub fn array_min<T: ScanElement>(values: &Array<T>, out: &Array<T>) -> Result<()> {
    reduce_impl(
        "array_min",
        values,
        out,
        Count::Host(values.len()),
        plan::ReduceOp::Min,
    )
}

/// [`array_min`] of the first `count` elements.
///
/// # Errors
/// As [`array_sum_n`].
pub fn array_min_n<'c, T: ScanElement>(
    values: &Array<T>,
    out: &Array<T>,
    count: impl Into<Count<'c>>,
) -> Result<()> {
    reduce_impl(
        "array_min_n",
        values,
        out,
        count.into(),
        plan::ReduceOp::Min,
    )
}

/// Maximum of `values` into `out[0]`; NaNs are ignored, and an empty (or all-NaN) array
/// gives the identity (`T::MIN`, or -inf for floats). See [`array_sum`] for the arguments.
///
/// # Errors
/// As [`array_sum`].
pub fn array_max<T: ScanElement>(values: &Array<T>, out: &Array<T>) -> Result<()> {
    reduce_impl(
        "array_max",
        values,
        out,
        Count::Host(values.len()),
        plan::ReduceOp::Max,
    )
}

/// [`array_max`] of the first `count` elements.
///
/// # Errors
/// As [`array_sum_n`].
pub fn array_max_n<'c, T: ScanElement>(
    values: &Array<T>,
    out: &Array<T>,
    count: impl Into<Count<'c>>,
) -> Result<()> {
    reduce_impl(
        "array_max_n",
        values,
        out,
        count.into(),
        plan::ReduceOp::Max,
    )
}

fn reduce_impl<T: ScanElement>(
    func: &'static str,
    values: &Array<T>,
    out: &Array<T>,
    count: Count<'_>,
    op: plan::ReduceOp,
) -> Result<()> {
    let ck = Check { func };
    ck.contiguous("values", values)?;
    let dev = values.device();
    ck.same_device(("values", dev), ("out", out.device()))?;
    if out.len() != 1 {
        return Err(ck.invalid(format!(
            "`out` must be a 1-element array, got shape {:?}",
            out.shape()
        )));
    }
    ck.disjoint(("out", out), ("values", values), false)?;
    if let Count::Device(c) = count {
        ck.disjoint(("out", out), ("count", c), false)?;
    }
    let len = ck.count(count, values.len(), "values", dev)?;
    dispatch::reduce::<T>(
        dev,
        ck.func,
        values.device_address(),
        out.device_address(),
        len,
        op,
        || uses((values.clone(), out.clone()), count),
    )
}

// ------------------------------------------------------------------------------------------
// Radix sort
// ------------------------------------------------------------------------------------------

/// Sorts the first `count` pairs of `keys` and `values` by key, in place, stably (Warp's
/// `radix_sort_pairs`): equal keys keep their order, and each value moves with its key.
///
/// - Keys: `u32`, `i32` (numeric order) or `f32` (the order of [`f32::total_cmp`]: -0.0 before
///   +0.0, NaNs with the sign bit set first, other NaNs last); see [`SortKey`].
/// - `count`: a `usize` or a 1-element `Array<i32>` on the device (see the
///   [module docs](self) on lengths); elements past it are left alone.
/// - `key_bits`: `None` sorts by the whole key; `Some(b)` (1 to 32) by its low `b` bits
///   only, as an unsigned number (for `i32`, the low bits of the two's complement pattern),
///   which is the key order when every key lies in `0..2^b` and saves passes (a grid's cell
///   indices, Morton codes). Not for `f32` keys (their low bits have no order).
///
/// Unlike Warp, the arrays need not hold `2 * count` elements: the ping-pong buffers are
/// scratch memory (on a GPU the device's workspace, reused between calls), and nothing past
/// `count` is touched. Keys and values must not overlap; both are contiguous and on the same device.
///
/// Algorithm: LSD radix sort with 8-bit digits (on a GPU one "onesweep" kernel per digit,
/// ranking keys per warp), see `docs/book/src/primitives.md`.
///
/// ```
/// # use warp_runtime as wp;
/// let dev = wp::cpu();
/// let keys = wp::Array::from_slice(&[3.5f32, -1.0, 3.5, -0.0, 0.0], &dev)?;
/// let vals = wp::Array::from_slice(&[0u32, 1, 2, 3, 4], &dev)?;
/// wp::radix_sort_pairs(&keys, &vals, 5, None)?;
/// assert_eq!(vals.to_vec()?, [1, 3, 4, 0, 2]);
/// # Ok::<(), wp::Error>(())
/// ```
///
/// # Errors
/// [`Error::InvalidArgument`] when the count is larger than an array, `key_bits` is 0 or more
/// than 32 (or below 32 for `f32` keys), an array is not contiguous or has more than
/// `i32::MAX` elements, or the arrays overlap; [`Error::DeviceMismatch`] for arrays on
/// different devices. On a GPU, a device count out of range is a fault.
pub fn radix_sort_pairs<'c, K: SortKey, V: SortValue>(
    keys: &Array<K>,
    values: &Array<V>,
    count: impl Into<Count<'c>>,
    key_bits: Option<u32>,
) -> Result<()> {
    let ck = Check {
        func: "radix_sort_pairs",
    };
    ck.contiguous("keys", keys)?;
    ck.contiguous("values", values)?;
    let dev = keys.device();
    ck.same_device(("keys", dev), ("values", values.device()))?;
    let bits = key_bits.unwrap_or(32);
    if !(1..=32).contains(&bits) {
        return Err(ck.invalid(format!("`key_bits` is {bits}; it must be 1 to 32")));
    }
    if bits < 32 && !K::PARTIAL_BITS {
        return Err(ck.invalid(format!(
            "`key_bits` is {bits}, but {} keys are sorted by all 32 bits (their low bits alone \
             have no order)",
            K::TYPE_NAME
        )));
    }
    ck.disjoint(("values", values), ("keys", keys), false)?;
    let (capacity, short) = shorter(("keys", keys.len()), ("values", values.len()));
    ck.fits_i32(short, capacity)?;
    let count = count.into();
    if let Count::Device(c) = count {
        ck.disjoint(("keys", keys), ("count", c), false)?;
        ck.disjoint(("values", values), ("count", c), false)?;
    }
    let len = ck.count(count, capacity, short, dev)?;
    dispatch::radix_sort_pairs::<K, V>(
        dev,
        ck.func,
        keys.device_address(),
        values.device_address(),
        len,
        bits,
        || uses((keys.clone(), values.clone()), count),
    )
}

// ------------------------------------------------------------------------------------------
// Stream compaction
// ------------------------------------------------------------------------------------------

/// Stream compaction: copies the elements of `values` whose flag is nonzero, in order, to
/// the front of `out`, and writes how many to `out_count[0]`. Elements of `out` past the
/// count are left alone.
///
/// `flags` has the length of `values`; `out` holds at least as many elements as `values`
/// (every element may be kept, and on a GPU the count is not known on the host);
/// `out_count` is a 1-element array. All on one device, contiguous; `out` and `out_count`
/// overlap nothing. Any element type: GPUs move elements as raw bytes.
///
/// ```
/// # use warp_runtime as wp;
/// let dev = wp::cpu();
/// let v = wp::Array::from_slice(&[10u8, 11, 12, 13], &dev)?;
/// let keep = wp::Array::from_slice(&[1, 0, 0, 7], &dev)?;
/// let out = wp::Array::<u8>::zeros(4, &dev)?;
/// let n = wp::Array::<i32>::zeros(1, &dev)?;
/// wp::compact(&v, &keep, &out, &n)?;
/// assert_eq!((n.to_vec()?[0], &out.to_vec()?[..2]), (2, &[10u8, 13][..]));
/// # Ok::<(), wp::Error>(())
/// ```
///
/// # Errors
/// [`Error::InvalidArgument`] for lengths as above, more than `i32::MAX` elements, arrays
/// that are not contiguous or outputs that overlap; [`Error::DeviceMismatch`].
pub fn compact<T: Element>(
    values: &Array<T>,
    flags: &Array<i32>,
    out: &Array<T>,
    out_count: &Array<i32>,
) -> Result<()> {
    let ck = Check { func: "compact" };
    if flags.len() != values.len() {
        return Err(ck.invalid(format!(
            "`flags` has {} elements but `values` has {}",
            flags.len(),
            values.len()
        )));
    }
    if out.len() < values.len() {
        return Err(ck.invalid(format!(
            "`out` has {} elements, fewer than `values` ({}): every element may be kept",
            out.len(),
            values.len()
        )));
    }
    compact_impl(
        &ck,
        values,
        flags,
        out,
        out_count,
        Count::Host(values.len()),
    )
}

/// [`compact`] of the first `count` elements of `values` and `flags` (a `usize` or a
/// 1-element `Array<i32>` on the device; see the [module docs](self) on lengths). `values`,
/// `flags` and `out` each hold at least `count` elements.
///
/// # Errors
/// As [`compact`], and for a count larger than an array or a bad count array.
pub fn compact_n<'c, T: Element>(
    values: &Array<T>,
    flags: &Array<i32>,
    out: &Array<T>,
    out_count: &Array<i32>,
    count: impl Into<Count<'c>>,
) -> Result<()> {
    let ck = Check { func: "compact_n" };
    compact_impl(&ck, values, flags, out, out_count, count.into())
}

fn compact_impl<T: Element>(
    ck: &Check,
    values: &Array<T>,
    flags: &Array<i32>,
    out: &Array<T>,
    out_count: &Array<i32>,
    count: Count<'_>,
) -> Result<()> {
    ck.contiguous("values", values)?;
    ck.contiguous("flags", flags)?;
    ck.contiguous("out", out)?;
    let dev = values.device();
    ck.same_device(("values", dev), ("flags", flags.device()))?;
    ck.same_device(("values", dev), ("out", out.device()))?;
    ck.same_device(("values", dev), ("out_count", out_count.device()))?;
    if out_count.len() != 1 {
        return Err(ck.invalid(format!(
            "`out_count` must be a 1-element array, got shape {:?}",
            out_count.shape()
        )));
    }
    ck.disjoint(("out", out), ("values", values), false)?;
    ck.disjoint(("out", out), ("flags", flags), false)?;
    ck.disjoint(("out_count", out_count), ("values", values), false)?;
    ck.disjoint(("out_count", out_count), ("flags", flags), false)?;
    ck.disjoint(("out_count", out_count), ("out", out), false)?;
    let (cap, short) = shorter(("values", values.len()), ("flags", flags.len()));
    let (cap, short) = shorter((short, cap), ("out", out.len()));
    ck.fits_i32(short, cap)?;
    if let Count::Device(c) = count {
        ck.disjoint(("out", out), ("count", c), false)?;
        ck.disjoint(("out_count", out_count), ("count", c), false)?;
    }
    let len = ck.count(count, cap, short, dev)?;
    dispatch::compact::<T>(
        dev,
        ck.func,
        [
            values.device_address(),
            flags.device_address(),
            out.device_address(),
            out_count.device_address(),
        ],
        len,
        || {
            let arrays = (
                values.clone(),
                flags.clone(),
                out.clone(),
                out_count.clone(),
            );
            uses(arrays, count)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radix_images_preserve_order() {
        let floats = [
            f32::from_bits(0xffc0_0000), // -NaN
            f32::NEG_INFINITY,
            -1.5,
            -f32::MIN_POSITIVE,
            -0.0,
            0.0,
            1e-45,
            2.0,
            f32::INFINITY,
            f32::NAN,
        ];
        for w in floats.windows(2) {
            assert!(w[0].to_radix() < w[1].to_radix(), "{} {}", w[0], w[1]);
            assert_eq!(w[0].total_cmp(&w[1]), std::cmp::Ordering::Less);
        }
        for &x in &floats {
            assert_eq!(f32::from_radix(x.to_radix()).to_bits(), x.to_bits());
        }
        let ints = [i32::MIN, -7, -1, 0, 1, i32::MAX];
        for w in ints.windows(2) {
            assert!(w[0].to_radix() < w[1].to_radix());
        }
        for &x in &ints {
            assert_eq!(i32::from_radix(x.to_radix()), x);
        }
    }

    #[test]
    fn float_min_max_ignore_nan() {
        assert_eq!(f32::NAN.min_of(1.0), 1.0);
        assert_eq!(1.0f32.min_of(f32::NAN), 1.0);
        assert_eq!(f64::NAN.max_of(-3.0), -3.0);
        assert!(f32::NAN.min_of(f32::NAN).is_nan());
        assert_eq!(i32::MAX.add(1), i32::MIN);
    }
}
