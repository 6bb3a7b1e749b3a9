//! Property tests of the runtime's public API: random shapes (empty, 1 to 4 dimensions, extents
//! whose product overflows `usize`), element types, strided layouts over external memory
//! (negative, zero, overlapping and out-of-range strides, offsets), views, transposes,
//! reshapes and reinterpretations, launch dims (zero, huge, not matching the arrays) and
//! indices inside kernels (negative, huge, past the end).
//!
//! Every property is the same contract: the call returns `Ok` with the contents a plain-Rust
//! model says, or a clear `Err` (an out-of-bounds index is an `Error::Fault` naming the
//! kernel, the argument and the index); never a panic (each call runs under `catch_unwind`,
//! and a panic fails the property), never undefined behaviour (external memory is only
//! wrapped where the layout lies inside a buffer the test owns), never a hang (sizes are
//! bounded: an array the model says is huge must be refused, never allocated and filled).
//!
//! The number of cases per property is proptest's `PROPTEST_CASES` (default here: 64, which
//! keeps this binary to a few seconds in a debug build); `PROPTEST_CASES=10000 cargo test
//! --test proptest_runtime` searches harder. GPU variants run a few properties on `cuda:0`
//! and print `SKIPPED` without a CUDA device, as the suite's tests do.

use std::fmt::Debug;
use std::panic::{catch_unwind, AssertUnwindSafe};

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use warp_lang as wp;
use wp::prelude::*;
use wp::{Error, FaultKind};

// ---------------------------------------------------------------------------------------------
// Harness

/// Cases per property: `PROPTEST_CASES`, else `default`. Failures are persisted next to this
/// file (`tests/proptest-regressions/`), as the `proptest!` macro does.
fn config(default: u32) -> Config {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default);
    Config {
        cases,
        source_file: Some(file!()),
        ..Config::default()
    }
}

/// Runs `f`, failing the property if it panics (library code must return an `Err` instead).
fn no_panic<R>(what: &str, f: impl FnOnce() -> R) -> Result<R, TestCaseError> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|p| {
        let msg = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default();
        TestCaseError::fail(format!("{what} panicked: {msg}"))
    })
}

/// An error's message must say something (the contract's "clear" error).
fn clear(e: &Error) -> Result<(), TestCaseError> {
    let msg = e.to_string();
    prop_assert!(msg.len() > 10, "an unclear error: {msg:?} ({e:?})");
    Ok(())
}

/// Runs `property` over `strategy` on `dev` with `cases` cases (or `PROPTEST_CASES`).
fn run<S: Strategy>(
    dev: &wp::Device,
    cases: u32,
    strategy: S,
    property: impl Fn(&wp::Device, S::Value) -> Result<(), TestCaseError>,
) where
    S::Value: Debug,
{
    let mut runner = TestRunner::new(config(cases));
    if let Err(e) = runner.run(&strategy, |v| property(dev, v)) {
        panic!("{e}");
    }
}

/// The device of a GPU variant, or `None` after printing that it skipped.
fn cuda(test: &str) -> Option<wp::Device> {
    match wp::get_device("cuda:0") {
        Ok(d) => {
            wp::config::set_debug(true);
            Some(d)
        }
        Err(e) => {
            eprintln!("SKIPPED {test}: no CUDA device ({e})");
            None
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Element types and their model values

/// An element type of the properties: a distinct value per index, to see which element ended
/// where.
trait Elem: wp::Element + PartialEq + Debug {
    fn at(i: usize) -> Self;
}

impl Elem for f32 {
    fn at(i: usize) -> Self {
        i as f32 + 0.5
    }
}
impl Elem for f64 {
    fn at(i: usize) -> Self {
        i as f64 * 0.25 - 3.0
    }
}
impl Elem for i32 {
    fn at(i: usize) -> Self {
        i as i32 * 7 - 11
    }
}
impl Elem for u8 {
    fn at(i: usize) -> Self {
        (i * 13 + 1) as u8
    }
}
impl Elem for u64 {
    fn at(i: usize) -> Self {
        (i as u64) << 40 | 3
    }
}
impl Elem for f16 {
    fn at(i: usize) -> Self {
        f16::from_f32((i % 1000) as f32 + 0.5)
    }
}
impl Elem for Vec3 {
    fn at(i: usize) -> Self {
        vec3(i as f32, -(i as f32), 0.5)
    }
}
impl Elem for Mat3 {
    fn at(i: usize) -> Self {
        Mat3::from_diagonal(vec3(i as f32, 1.0, 2.0))
    }
}
impl Elem for DVec4 {
    fn at(i: usize) -> Self {
        DVec4::splat(i as f64)
    }
}

/// Calls `$body` with `$T` bound to the element type numbered `$k` (0..9).
macro_rules! with_elem {
    ($k:expr, $T:ident => $body:expr) => {
        match $k {
            0 => {
                type $T = f32;
                $body
            }
            1 => {
                type $T = f64;
                $body
            }
            2 => {
                type $T = i32;
                $body
            }
            3 => {
                type $T = u8;
                $body
            }
            4 => {
                type $T = u64;
                $body
            }
            5 => {
                type $T = f16;
                $body
            }
            6 => {
                type $T = Vec3;
                $body
            }
            7 => {
                type $T = Mat3;
                $body
            }
            _ => {
                type $T = DVec4;
                $body
            }
        }
    };
}
const ELEM_TYPES: usize = 9;

// ---------------------------------------------------------------------------------------------
// Shapes

/// An extent: mostly small, sometimes zero, sometimes so large that no array of it fits in
/// memory (at least 2^48 elements: every such allocation fails rather than succeeding lazily
/// and then being filled).
fn extent() -> impl Strategy<Value = usize> {
    prop_oneof![
        6 => 0usize..6,
        1 => proptest::sample::select(&[
            1usize << 48, 1 << 61, 1 << 62, isize::MAX as usize, (isize::MAX as usize) + 1,
            usize::MAX,
        ][..]),
    ]
}

/// What the model says a shape of `size`-byte elements gives: the element count, or `None`
/// when the array must be refused. The rule (NumPy's): the product of the non-zero extents,
/// in bytes, fits in `isize`; an empty array is then fine whatever its other extents.
fn model_len(shape: &[usize], size: usize) -> Option<usize> {
    let nonzero = shape
        .iter()
        .filter(|&&e| e != 0)
        .try_fold(size, |acc, &e| acc.checked_mul(e))?;
    if nonzero > isize::MAX as usize {
        return None;
    }
    Some(shape.iter().product())
}

/// Bytes past which the model expects an allocation to fail (only huge extents get there).
const HUGE_BYTES: usize = 1 << 40;

/// Row-major flat index of `idx` in `shape`.
fn flat(idx: &[usize], shape: &[usize]) -> usize {
    idx.iter().zip(shape).fold(0, |acc, (&i, &e)| acc * e + i)
}

/// All indices of `shape` in row-major order.
fn indices(shape: &[usize]) -> Vec<Vec<usize>> {
    let n: usize = shape.iter().product();
    (0..n)
        .map(|mut f| {
            let mut idx = vec![0; shape.len()];
            for d in (0..shape.len()).rev() {
                idx[d] = f % shape[d];
                f /= shape[d];
            }
            idx
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Property: constructors and every read-only method, any shape and element type

/// Constructors over `shape` (an `N`-dim shape from the first `N` of `dims`) and every method
/// of the result.
fn construct<T: Elem, const N: usize>(
    dev: &wp::Device,
    dims: &[usize; 4],
    slice_len: usize,
    view: (usize, usize),
    reshape: &[usize; 4],
) -> Result<(), TestCaseError> {
    let shape: [usize; N] = dims[..N].try_into().unwrap();
    let size = std::mem::size_of::<T>();
    let model = model_len(&shape, size);
    for ctor in 0..3 {
        let made = no_panic("a constructor", || match ctor {
            0 => wp::Array::<T, N>::zeros(shape, dev),
            1 => wp::Array::<T, N>::full(shape, T::at(7), dev),
            _ => {
                // A slice of the shape's length when small, else of `slice_len` (a mismatch).
                let n = match model {
                    Some(n) if n <= 4096 => n,
                    _ => slice_len,
                };
                let data: Vec<T> = (0..n).map(T::at).collect();
                wp::Array::<T, N>::from_slice_shape(&data, shape, dev)
            }
        })?;
        match (model, made) {
            (None, Ok(a)) => {
                return Err(TestCaseError::fail(format!(
                    "shape {shape:?} of {}-byte elements was accepted ({a:?})",
                    size
                )))
            }
            (None, Err(e)) => clear(&e)?,
            (Some(n), Err(e)) => {
                // Refused only as too large to allocate, or (from_slice_shape) a mismatch.
                clear(&e)?;
                let mismatch = ctor == 2 && n > 4096 && n != slice_len;
                prop_assert!(
                    n.saturating_mul(size) >= HUGE_BYTES || mismatch,
                    "shape {shape:?} ({n} elements) refused: {e}"
                );
            }
            (Some(n), Ok(a)) => {
                prop_assert!(n.saturating_mul(size) < HUGE_BYTES || n == 0);
                let want: Vec<T> = match ctor {
                    0 => vec![T::zeroed(); n],
                    1 => vec![T::at(7); n],
                    _ => (0..n).map(T::at).collect(),
                };
                check_array(&a, &want, view, reshape)?;
            }
        }
    }
    Ok(())
}

/// `a` holds `want` in row-major order; every method agrees, views and reshapes included.
fn check_array<T: Elem, const N: usize>(
    a: &wp::Array<T, N>,
    want: &[T],
    (lo, hi): (usize, usize),
    reshape: &[usize; 4],
) -> Result<(), TestCaseError> {
    let shape = a.shape();
    no_panic("the accessors", || {
        let _ = (a.strides(), a.byte_strides(), a.ndim(), a.is_contiguous());
        let _ = (a.device_ptr(), format!("{a:?}"), a.check_finite("x"));
    })?;
    prop_assert_eq!(no_panic("len", || a.len())?, want.len());
    // Contiguous: empty, or row-major strides wherever an extent is not one.
    let mut expected = 1isize;
    let mut row_major = true;
    for d in (0..N).rev() {
        row_major &= shape[d] == 1 || a.strides()[d] == expected;
        expected = expected.wrapping_mul(shape[d] as isize);
    }
    let contiguous = want.is_empty() || row_major;
    prop_assert_eq!(
        a.is_contiguous(),
        contiguous,
        "{:?} {:?}",
        shape,
        a.strides()
    );
    prop_assert_eq!(no_panic("is_empty", || a.is_empty())?, want.is_empty());
    let got = no_panic("to_vec", || a.to_vec())?.map_err(|e| TestCaseError::fail(e.to_string()))?;
    prop_assert_eq!(&got, &want);

    // The transpose: element [i0, .., iN] is the original's [iN, .., i0].
    let t = no_panic("transpose", || a.transpose())?;
    let tv = no_panic("to_vec of a transpose", || t.to_vec())?
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    let tshape = t.shape();
    for idx in indices(&tshape) {
        let rev: Vec<usize> = idx.iter().rev().copied().collect();
        prop_assert_eq!(&tv[flat(&idx, &tshape)], &want[flat(&rev, &shape)]);
    }
    // Views of the first dimension (any range, reversed and past the end included), of the
    // array and of its transpose.
    for (arr, vals, sh) in [(a, &want.to_vec(), shape), (&t, &tv, tshape)] {
        let v = no_panic("view", || arr.view(lo..hi))?;
        let row: usize = sh[1..].iter().product();
        match v {
            Ok(v) => {
                prop_assert!(
                    lo <= hi && hi <= sh[0],
                    "view {lo}..{hi} of {sh:?} accepted"
                );
                let vv = no_panic("to_vec of a view", || v.to_vec())?
                    .map_err(|e| TestCaseError::fail(e.to_string()))?;
                prop_assert_eq!(&vv[..], &vals[lo * row..hi * row]);
                // A view's view, transpose and fill (a fill of a view writes only its rows).
                no_panic("a view of a view", || {
                    let _ = v.view(..).map(|w| w.transpose().to_vec());
                })?;
            }
            Err(e) => {
                clear(&e)?;
                prop_assert!(
                    lo > hi || hi > sh[0],
                    "view {lo}..{hi} of {sh:?} refused: {e}"
                );
            }
        }
    }
    // Reshapes to any shape of 1 to 4 dims: fine exactly when the lengths agree.
    let r: Result<(), TestCaseError> = (|| {
        macro_rules! reshape_to {
            ($m:literal) => {{
                let s: [usize; $m] = reshape[..$m].try_into().unwrap();
                let r = no_panic("reshape", || a.reshape(s))?;
                let ok = contiguous && model_len(&s, std::mem::size_of::<T>()) == Some(want.len());
                match r {
                    Ok(b) => {
                        prop_assert!(ok, "reshape of {shape:?} to {s:?} accepted");
                        let bv = no_panic("to_vec of a reshape", || b.to_vec())?
                            .map_err(|e| TestCaseError::fail(e.to_string()))?;
                        prop_assert_eq!(&bv, &want);
                    }
                    Err(e) => {
                        clear(&e)?;
                        prop_assert!(!ok, "reshape of {shape:?} to {s:?} refused: {e}");
                    }
                }
                // And of the transpose (refused when it is not contiguous).
                let r = no_panic("reshape of a transpose", || t.reshape(s))?;
                if let Err(e) = r {
                    clear(&e)?;
                }
            }};
        }
        reshape_to!(1);
        reshape_to!(2);
        reshape_to!(3);
        reshape_to!(4);
        Ok(())
    })();
    r?;
    // Reinterpretation as bytes and back, and as a wider type.
    no_panic("reinterpret", || {
        let bytes = a.reinterpret::<u8>();
        if let Ok(b) = &bytes {
            assert_eq!(b.len(), std::mem::size_of_val(want));
            let back = b.reinterpret::<T>().unwrap();
            assert_eq!(back.to_vec().unwrap(), want);
        }
        let _ = a.reinterpret::<DVec4>();
        let _ = t.reinterpret::<u8>();
    })?;
    // Writes: copy the transpose back into a transpose-shaped array, fill, gradients.
    no_panic("copy_from, fill and gradients", || {
        if let Ok(c) = wp::Array::<T, N>::zeros(tshape, a.device()) {
            c.copy_from(&t).unwrap();
            assert_eq!(c.to_vec().unwrap(), tv);
            // A copy between different shapes is an error.
            if tshape != shape {
                assert!(c.copy_from(a).is_err());
            }
            c.fill(T::at(3)).unwrap();
            assert!(c.to_vec().unwrap().iter().all(|v| *v == T::at(3)));
            let g = c.clone().with_grad().unwrap();
            assert!(g
                .grad()
                .unwrap()
                .to_vec()
                .unwrap()
                .iter()
                .all(|v| *v == T::zeroed()));
            g.zero_grad().unwrap();
        }
    })?;
    Ok(())
}

fn construct_property(
    dev: &wp::Device,
    (ndim, elem, dims, slice_len, view, reshape): (
        usize,
        usize,
        [usize; 4],
        usize,
        (usize, usize),
        [usize; 4],
    ),
) -> Result<(), TestCaseError> {
    with_elem!(elem, T => match ndim {
        1 => construct::<T, 1>(dev, &dims, slice_len, view, &reshape),
        2 => construct::<T, 2>(dev, &dims, slice_len, view, &reshape),
        3 => construct::<T, 3>(dev, &dims, slice_len, view, &reshape),
        _ => construct::<T, 4>(dev, &dims, slice_len, view, &reshape),
    })
}

fn construct_strategy(
) -> impl Strategy<Value = (usize, usize, [usize; 4], usize, (usize, usize), [usize; 4])> {
    (
        1usize..=4,
        0..ELEM_TYPES,
        [extent(), extent(), extent(), extent()],
        0usize..40,
        (0usize..8, 0usize..8),
        [extent(), extent(), extent(), extent()],
    )
}

#[test]
fn constructors_and_views_cpu() {
    run(&wp::cpu(), 96, construct_strategy(), construct_property);
}

#[test]
fn constructors_and_views_cuda() {
    if let Some(dev) = cuda("constructors_and_views_cuda") {
        run(&dev, 24, construct_strategy(), construct_property);
    }
}

// ---------------------------------------------------------------------------------------------
// Property: external memory with any strides and offsets

/// A layout over external memory: shape, strides in elements (or a byte stride that is not a
/// multiple of the element size), and where element zero sits in the buffer.
#[derive(Debug, Clone)]
struct Layout {
    shape: [usize; 3],
    /// Byte strides.
    strides: [isize; 3],
    /// Element zero's index in the buffer.
    origin: usize,
    /// Wrap a null pointer instead of the buffer.
    null: bool,
}

fn layout() -> impl Strategy<Value = Layout> {
    let stride = prop_oneof![
        8 => (-6isize..7).prop_map(|s| s * 4),
        1 => -9isize..10,
        1 => proptest::sample::select(&[isize::MAX, isize::MIN, 1 << 60, -(1 << 60), 1 << 40][..]),
    ];
    (
        (extent(), 0usize..5, 0usize..5).prop_map(|(a, b, c)| [a, b, c]),
        [stride.clone(), stride.clone(), stride],
        0usize..64,
        proptest::bool::weighted(0.1),
    )
        .prop_map(|(shape, strides, origin, null)| Layout {
            shape,
            strides,
            origin,
            null,
        })
}

const BUFFER: usize = 64;

/// The buffer index of each element of the layout (f32 elements), row-major; `None` when
/// some element falls outside a buffer of `BUFFER` f32s (wrapping it would be UB).
fn layout_elements(l: &Layout) -> Option<Vec<usize>> {
    if l.strides.iter().any(|s| s % 4 != 0) {
        return None;
    }
    let n = l.shape.iter().try_fold(1usize, |a, &e| a.checked_mul(e))?;
    if n > 4096 {
        return None;
    }
    indices(&l.shape)
        .iter()
        .map(|idx| {
            let off = idx
                .iter()
                .zip(&l.strides)
                .try_fold(l.origin as i128, |acc, (&i, &s)| {
                    Some(acc + i as i128 * (s as i128 / 4))
                })?;
            (0..BUFFER as i128).contains(&off).then_some(off as usize)
        })
        .collect()
}

fn external_property(dev: &wp::Device, l: Layout) -> Result<(), TestCaseError> {
    let mut buffer: Vec<f32> = (0..BUFFER).map(|i| i as f32).collect();
    let elements = layout_elements(&l);
    let empty = l.shape.contains(&0);
    let base = buffer.as_mut_ptr();
    let ptr = if l.null {
        std::ptr::null_mut()
    } else {
        base.wrapping_add(l.origin)
    };
    // Only wrap what is sound: a layout inside the buffer, an empty one, or one the runtime
    // must refuse before touching memory (a null pointer, a stride not a multiple of the
    // element size, a span past the address space).
    let misaligned = l.strides.iter().any(|s| s % 4 != 0);
    let span_huge = !empty && {
        let reach: i128 = l
            .shape
            .iter()
            .zip(&l.strides)
            .map(|(&e, &s)| (e as i128 - 1) * (s as i128).abs())
            .sum();
        reach + 4 > isize::MAX as i128
    };
    // Arrays are writable, so a layout that overlaps itself is refused. The runtime's rule
    // (ndarray's): sorted by |stride|, each axis of extent > 1 steps past the span of the
    // smaller ones. It is conservative, so it must at least catch every real alias.
    let overlapping = !empty && !misaligned && {
        let mut axes: Vec<(i128, i128)> = (0..3)
            .filter(|&d| l.shape[d] > 1)
            .map(|d| ((l.strides[d] as i128).abs(), l.shape[d] as i128 - 1))
            .collect();
        axes.sort_unstable();
        let mut span = 0i128;
        axes.iter().any(|&(s, last)| {
            let hit = s <= span;
            span += s * last;
            hit
        })
    };
    if let Some(e) = &elements {
        let mut sorted = e.clone();
        sorted.sort_unstable();
        sorted.dedup();
        prop_assert!(overlapping || sorted.len() == e.len(), "{l:?} aliases");
    }
    let must_fail = misaligned
        || (!empty && (l.null || span_huge || overlapping))
        || model_len(&l.shape, 4).is_none();
    if elements.is_none() && !empty && !must_fail {
        return Ok(()); // Out of the buffer: the caller's contract, not the runtime's.
    }
    // SAFETY: every element of the layout lies in `buffer` (checked above), or the layout is
    // empty, or it is one the runtime refuses before reading; `buffer` outlives the array.
    let made = no_panic("from_host_ptr", || unsafe {
        wp::Array::<f32, 3>::from_host_ptr(ptr, l.shape, Some(l.strides), dev, ())
    })?;
    let a = match made {
        Err(e) => {
            clear(&e)?;
            prop_assert!(must_fail || !dev.is_cpu(), "{l:?} refused: {e}");
            return Ok(());
        }
        Ok(a) => {
            prop_assert!(!must_fail, "{l:?} accepted");
            a
        }
    };
    let elements = elements.unwrap_or_default();
    let want: Vec<f32> = elements.iter().map(|&i| i as f32).collect();
    check_array(&a, &want, (0, 1), &[want.len(), 1, 1, 1])?;
    // A kernel reading every element through the strides.
    if !want.is_empty() {
        let out = wp::Array::<f32>::zeros(want.len(), dev).unwrap();
        let r = no_panic("a launch over a strided array", || {
            wp::launch(k_flatten3, a.shape(), (&a, &out), dev)
        })?;
        r.map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(out.to_vec().unwrap(), want.clone());
    }
    // A fill writes exactly the layout's elements.
    no_panic("fill", || a.fill(-1.0))?.map_err(|e| TestCaseError::fail(e.to_string()))?;
    drop(a);
    for (i, v) in buffer.iter().enumerate() {
        let inside = elements.contains(&i);
        prop_assert_eq!(*v, if inside { -1.0 } else { i as f32 }, "buffer[{}]", i);
    }
    Ok(())
}

#[wp::kernel]
fn k_flatten3(a: Array<f32, 3>, out: Array<f32>) {
    let (i, j, k) = tid();
    out[(i * a.shape()[1] + j) * a.shape()[2] + k] = a[(i, j, k)];
}

#[test]
fn external_layouts_cpu() {
    run(&wp::cpu(), 128, layout(), external_property);
}

// ---------------------------------------------------------------------------------------------
// Property: launch dims against array shapes

#[wp::kernel]
fn k_mark1(out: Array<i32>) {
    let i = tid();
    out[i] = 1;
}

#[wp::kernel]
fn k_mark2(out: Array<i32, 2>) {
    let (i, j) = tid();
    out[(i, j)] = 1;
}

/// Every thread adds one to `out[0]` (atomically: plain writes would race).
#[wp::kernel]
fn k_count(out: Array<i32>) {
    atomic_add(out, 0, 1);
}

/// A launch extent: 0, small, or at and past the GPU's 32-bit limit.
fn launch_extent() -> impl Strategy<Value = usize> {
    prop_oneof![
        8 => 0usize..7,
        1 => proptest::sample::select(&[
            i32::MAX as usize, i32::MAX as usize + 1, 1 << 40, usize::MAX,
        ][..]),
    ]
}

/// What `grid_of` must say of `dims`: `Err` for a zero extent, an extent past `i32::MAX` or a
/// thread count past `usize`, else the thread count.
fn model_threads(dims: &[usize]) -> Option<usize> {
    if dims.iter().any(|&e| e == 0 || e > i32::MAX as usize) {
        return None;
    }
    dims.iter().try_fold(1usize, |a, &e| a.checked_mul(e))
}

fn dims_property(
    dev: &wp::Device,
    (ndim, dims, len, shape2): (usize, [usize; 4], usize, (usize, usize)),
) -> Result<(), TestCaseError> {
    let dims = &dims[..ndim];
    let threads = model_threads(dims);
    if threads.is_some_and(|t| t > 4096) {
        return Ok(()); // Valid and too long to run here: grid_of is covered by smaller ones.
    }
    let dim = match ndim {
        1 => wp::Dim::from(dims[0]),
        2 => wp::Dim::from((dims[0], dims[1])),
        3 => wp::Dim::from((dims[0], dims[1], dims[2])),
        _ => wp::Dim::from((dims[0], dims[1], dims[2], dims[3])),
    };
    // A 1-D kernel: valid only for a 1-D launch covering no more than `len`.
    let out = wp::Array::<i32>::zeros(len, dev).unwrap();
    let r = no_panic("launch", || wp::launch(k_mark1, dim, (&out,), dev))?;
    match (threads, ndim, r) {
        (None, _, Err(e)) => {
            prop_assert!(matches!(e, Error::InvalidDim { .. }), "{e:?}");
            prop_assert!(e.to_string().contains("k_mark1"), "{e}");
        }
        (Some(_), 2..=4, Err(e)) => prop_assert!(matches!(e, Error::TidMismatch { .. }), "{e:?}"),
        (Some(t), 1, Err(Error::Fault(f))) => {
            prop_assert!(t > len, "{f}");
            prop_assert_eq!(f.kernel, "k_mark1");
            match &f.kind {
                FaultKind::OutOfBounds { arg, index, shape } => {
                    prop_assert_eq!(*arg, "out");
                    prop_assert_eq!(shape, &vec![len]);
                    prop_assert!(index.len() == 1 && index[0] >= len as i128, "{f}");
                }
                k => return Err(TestCaseError::fail(format!("{k:?}"))),
            }
            // The array stays usable; a launch that fits works.
            if len > 0 {
                wp::launch(k_mark1, len, (&out,), dev).unwrap();
                prop_assert!(out.to_vec().unwrap().iter().all(|&v| v == 1));
            }
        }
        (Some(t), 1, Ok(())) => {
            prop_assert!(t <= len, "{t} threads over {len} elements succeeded");
            let v = out.to_vec().unwrap();
            prop_assert!(v[..t].iter().all(|&x| x == 1) && v[t..].iter().all(|&x| x == 0));
        }
        (t, n, r) => {
            return Err(TestCaseError::fail(format!(
                "{t:?} threads, {n} dims: {r:?}"
            )));
        }
    }
    // A 2-D kernel over a 2-D array of another shape.
    let out2 = wp::Array::<i32, 2>::zeros(shape2, dev).unwrap();
    let r = no_panic("launch", || wp::launch(k_mark2, dim, (&out2,), dev))?;
    let fits = ndim == 2 && dims[0] <= shape2.0 && dims[1] <= shape2.1;
    match r {
        Ok(()) => {
            prop_assert!(threads.is_some() && fits, "{dims:?} over {shape2:?}");
            let v = out2.to_vec().unwrap();
            for (f, x) in v.iter().enumerate() {
                let (i, j) = (f / shape2.1.max(1), f % shape2.1.max(1));
                prop_assert_eq!(*x, (i < dims[0] && j < dims[1]) as i32);
            }
        }
        Err(e) => {
            clear(&e)?;
            prop_assert!(threads.is_none() || !fits, "{dims:?} over {shape2:?}: {e}");
            if threads.is_some() && ndim == 2 {
                prop_assert!(
                    matches!(&e, Error::Fault(f) if f.kernel == "k_mark2"),
                    "{e}"
                );
            }
        }
    }
    // A kernel without tid(): any valid dims.
    let count = wp::Array::<i32>::zeros(len, dev).unwrap();
    let r = no_panic("launch", || wp::launch(k_count, dim, (&count,), dev))?;
    prop_assert_eq!(r.is_ok(), threads.is_some() && len > 0, "{:?}", r);
    if let (Ok(()), Some(t)) = (r, threads) {
        prop_assert_eq!(count.to_vec().unwrap()[0], t as i32);
    }
    Ok(())
}

fn dims_strategy() -> impl Strategy<Value = (usize, [usize; 4], usize, (usize, usize))> {
    (
        1usize..=4,
        [
            launch_extent(),
            launch_extent(),
            launch_extent(),
            launch_extent(),
        ],
        0usize..40,
        (0usize..8, 0usize..8),
    )
}

#[test]
fn launch_dims_cpu() {
    run(&wp::cpu(), 128, dims_strategy(), dims_property);
}

#[test]
fn launch_dims_cuda() {
    if let Some(dev) = cuda("launch_dims_cuda") {
        run(&dev, 32, dims_strategy(), dims_property);
    }
}

// ---------------------------------------------------------------------------------------------
// Property: indices inside kernels

#[wp::kernel]
fn k_gather(src: Array<f32>, idx: Array<i64>, out: Array<f32>) {
    let i = tid();
    out[i] = src[idx[i]];
}

#[wp::kernel]
fn k_gather2(src: Array<Vec3, 2>, idx: Array<i32>, out: Array<Vec3>) {
    let i = tid();
    out[i] = src[(idx[2 * i], idx[2 * i + 1])];
}

#[wp::kernel]
fn k_scatter_u(dst: Array<f64>, idx: Array<u32>) {
    let i = tid();
    dst[idx[i]] = i as f64;
}

/// An index: in range mostly, else negative, just past the end, or huge.
fn index() -> impl Strategy<Value = i64> {
    prop_oneof![
        24 => 0i64..8,
        1 => -3i64..0,
        1 => proptest::sample::select(&[
            i64::MIN, i64::MAX, i32::MAX as i64, i32::MIN as i64, u32::MAX as i64,
            1 << 40,
        ][..]),
    ]
}

fn index_property(
    dev: &wp::Device,
    (n, idx, rows, cols): (usize, Vec<i64>, usize, usize),
) -> Result<(), TestCaseError> {
    // 1-D gather with i64 indices.
    let src: Vec<f32> = (0..n).map(f32::at).collect();
    let (s, ix) = (
        wp::Array::from_slice(&src, dev).unwrap(),
        wp::Array::from_slice(&idx, dev).unwrap(),
    );
    let out = wp::Array::<f32>::zeros(idx.len(), dev).unwrap();
    let bad = idx.iter().find(|&&k| k < 0 || k as u64 >= n as u64);
    let r = no_panic("gather", || {
        wp::launch(k_gather, idx.len(), (&s, &ix, &out), dev)
    })?;
    match (bad, r) {
        (_, Err(Error::InvalidDim { .. })) if idx.is_empty() => {}
        (None, Ok(())) => {
            let want: Vec<f32> = idx.iter().map(|&k| src[k as usize]).collect();
            prop_assert_eq!(out.to_vec().unwrap(), want);
        }
        (Some(_), Err(Error::Fault(f))) => {
            prop_assert_eq!(f.kernel, "k_gather");
            let FaultKind::OutOfBounds { arg, index, shape } = &f.kind else {
                return Err(TestCaseError::fail(format!("{f}")));
            };
            prop_assert_eq!(*arg, "src");
            prop_assert_eq!(shape, &vec![n]);
            // One of the bad indices, as given (threads run in parallel: any may be first).
            prop_assert!(
                idx.iter()
                    .any(|&k| i128::from(k) == index[0] && (k < 0 || k as u64 >= n as u64)),
                "{f}"
            );
            prop_assert!(f.to_string().contains("k_gather"), "{f}");
        }
        (b, r) => return Err(TestCaseError::fail(format!("bad index {b:?}: {r:?}"))),
    }
    // 2-D gather with i32 pairs.
    let pairs: Vec<i32> = idx.iter().map(|&k| k as i32).collect();
    let m = pairs.len() / 2;
    if m > 0 {
        let grid: Vec<Vec3> = (0..rows * cols).map(Vec3::at).collect();
        let g = wp::Array::from_slice_shape(&grid, (rows, cols), dev).unwrap();
        let p = wp::Array::from_slice(&pairs, dev).unwrap();
        let o = wp::Array::<Vec3>::zeros(m, dev).unwrap();
        let ok = pairs[..2 * m].chunks(2).all(|c| {
            (0..rows as i64).contains(&(c[0] as i64)) && (0..cols as i64).contains(&(c[1] as i64))
        });
        let r = no_panic("gather2", || wp::launch(k_gather2, m, (&g, &p, &o), dev))?;
        match r {
            Ok(()) => {
                prop_assert!(ok);
                let want: Vec<Vec3> = pairs[..2 * m]
                    .chunks(2)
                    .map(|c| grid[c[0] as usize * cols + c[1] as usize])
                    .collect();
                prop_assert_eq!(o.to_vec().unwrap(), want);
            }
            Err(Error::Fault(f)) => {
                prop_assert!(!ok, "{f}");
                prop_assert!(
                    matches!(&f.kind, FaultKind::OutOfBounds { arg: "src", shape, .. } if *shape == vec![rows, cols]),
                    "{f}"
                );
            }
            Err(e) => return Err(TestCaseError::fail(e.to_string())),
        }
    }
    // Scatter with u32 indices (an i64 index read as u32 wraps: that is the index used),
    // each index once: two threads writing one element would race.
    let mut uidx: Vec<u32> = Vec::new();
    for k in idx.iter().map(|&k| k as u32) {
        if !uidx.contains(&k) {
            uidx.push(k);
        }
    }
    let d = wp::Array::<f64>::zeros(n, dev).unwrap();
    let u = wp::Array::from_slice(&uidx, dev).unwrap();
    let r = no_panic("scatter", || {
        wp::launch(k_scatter_u, uidx.len(), (&d, &u), dev)
    })?;
    let ok = uidx.iter().all(|&k| (k as usize) < n);
    match r {
        Err(Error::InvalidDim { .. }) if uidx.is_empty() => {}
        Ok(()) => prop_assert!(ok),
        Err(Error::Fault(f)) => {
            prop_assert!(!ok, "{f}");
            prop_assert!(
                matches!(f.kind, FaultKind::OutOfBounds { arg: "dst", .. }),
                "{f}"
            );
        }
        Err(e) => return Err(TestCaseError::fail(e.to_string())),
    }
    Ok(())
}

fn index_strategy() -> impl Strategy<Value = (usize, Vec<i64>, usize, usize)> {
    (
        0usize..8,
        proptest::collection::vec(index(), 0..12),
        0usize..4,
        0usize..4,
    )
}

#[test]
fn kernel_indices_cpu() {
    run(&wp::cpu(), 128, index_strategy(), index_property);
}

#[test]
fn kernel_indices_cuda() {
    if let Some(dev) = cuda("kernel_indices_cuda") {
        run(&dev, 32, index_strategy(), index_property);
    }
}

// ---------------------------------------------------------------------------------------------
// Property: the parallel primitives over views, strided arrays and random counts

/// A 1-D array of `n` elements made one of several ways: fresh; a view into the middle of a
/// larger array; a column of a row-major 2-D array (strided unless it has one column); or a
/// view of `base`'s storage starting `shift` elements in (overlapping it).
fn make_1d(
    dev: &wp::Device,
    data: &[i32],
    how: usize,
    base: &wp::Array<i32>,
    shift: usize,
) -> Option<wp::Array<i32>> {
    let n = data.len();
    Some(match how {
        0 => wp::Array::from_slice(data, dev).unwrap(),
        1 => {
            let mut padded = vec![-7; n + 3];
            padded[2..n + 2].copy_from_slice(data);
            wp::Array::from_slice(&padded, dev)
                .unwrap()
                .view(2..n + 2)
                .unwrap()
        }
        2 => {
            let mut grid = vec![-7; n * 2];
            for (i, v) in data.iter().enumerate() {
                grid[i * 2] = *v;
            }
            let g = wp::Array::from_slice_shape(&grid, (n, 2), dev).unwrap();
            g.transpose().row(0).unwrap()
        }
        _ => {
            let v = base.view(shift.min(base.len())..).ok()?;
            if v.len() < n {
                return None;
            }
            let v = v.view(..n).unwrap();
            v.copy_from(&wp::Array::from_slice(data, dev).unwrap())
                .unwrap();
            v
        }
    })
}

fn primitives_property(
    dev: &wp::Device,
    (data, out_len, how_in, how_out, shift, count): (Vec<i32>, usize, usize, usize, usize, usize),
) -> Result<(), TestCaseError> {
    let n = data.len();
    let base = wp::Array::<i32>::zeros(n + 8, dev).unwrap();
    let Some(input) = make_1d(dev, &data, how_in, &base, 0) else {
        return Ok(());
    };
    let out_data = vec![0; out_len];
    let Some(output) = make_1d(dev, &out_data, how_out, &base, shift) else {
        return Ok(());
    };
    // What the model can say of the inputs (every precondition the docs list).
    let strided = |a: &wp::Array<i32>| !a.is_contiguous();
    let (lo_i, hi_i) = (input.device_ptr(), input.device_ptr() + 4 * n as u64);
    let (lo_o, hi_o) = (
        output.device_ptr(),
        output.device_ptr() + 4 * out_len as u64,
    );
    let same = lo_i == lo_o && n == out_len;
    let overlap = input.shares_storage_with(&output) && lo_i < hi_o && lo_o < hi_i && !same;
    let data = input.to_vec().unwrap();

    // Scan: lengths equal, contiguous, no overlap but in place.
    for inclusive in [false, true] {
        let r = no_panic("array_scan", || wp::array_scan(&input, &output, inclusive))?;
        let valid = n == out_len && !strided(&input) && !strided(&output) && !overlap;
        match r {
            Ok(()) => {
                prop_assert!(valid, "scan accepted: {n} -> {out_len}");
                let mut acc = 0i32;
                let want: Vec<i32> = data
                    .iter()
                    .map(|&v| {
                        let before = acc;
                        acc = acc.wrapping_add(v);
                        if inclusive {
                            acc
                        } else {
                            before
                        }
                    })
                    .collect();
                prop_assert_eq!(output.to_vec().unwrap(), want);
                if same {
                    // In place: put the input back for the next operation.
                    input
                        .copy_from(&wp::Array::from_slice(&data, dev).unwrap())
                        .unwrap();
                }
            }
            Err(e) => {
                clear(&e)?;
                prop_assert!(!valid, "scan refused: {e}");
            }
        }
    }
    // Reductions into a 1-element output, over a count that may exceed the input.
    let one = wp::Array::<i32>::zeros(1, dev).unwrap();
    let r = no_panic("array_sum_n", || wp::array_sum_n(&input, &one, count))?;
    match r {
        Ok(()) => {
            prop_assert!(count <= n && !strided(&input), "sum of {count} of {n}");
            let want = data[..count].iter().fold(0i32, |a, &v| a.wrapping_add(v));
            prop_assert_eq!(one.to_vec().unwrap()[0], want);
        }
        Err(e) => clear(&e)?,
    }
    let r = no_panic("array_max", || wp::array_max(&input, &output))?;
    if let Err(e) = r {
        clear(&e)?;
    }
    // Sort pairs (keys and values must not overlap), a count up to past the end.
    let keys = wp::Array::from_slice(&data, dev).unwrap();
    let r = no_panic("radix_sort_pairs", || {
        wp::radix_sort_pairs(&keys, &output, count, None)
    })?;
    match r {
        Ok(()) => {
            prop_assert!(count <= n && count <= out_len && !strided(&output));
            let mut sorted = data[..count].to_vec();
            sorted.sort();
            prop_assert_eq!(&keys.to_vec().unwrap()[..count], &sorted[..]);
        }
        Err(e) => clear(&e)?,
    }
    // Compaction with flags from the data.
    let flags: Vec<i32> = data.iter().map(|v| v & 1).collect();
    let f = wp::Array::from_slice(&flags, dev).unwrap();
    let cnt = wp::Array::<i32>::zeros(1, dev).unwrap();
    let r = no_panic("compact", || wp::compact(&input, &f, &output, &cnt))?;
    match r {
        Ok(()) => {
            let kept: Vec<i32> = data.iter().copied().filter(|v| v & 1 != 0).collect();
            prop_assert_eq!(cnt.to_vec().unwrap()[0] as usize, kept.len());
            prop_assert_eq!(&output.to_vec().unwrap()[..kept.len()], &kept[..]);
        }
        Err(e) => clear(&e)?,
    }
    Ok(())
}

fn primitives_strategy() -> impl Strategy<Value = (Vec<i32>, usize, usize, usize, usize, usize)> {
    (
        proptest::collection::vec(any::<i32>(), 0..40),
        0usize..42,
        0usize..4,
        0usize..4,
        0usize..10,
        0usize..45,
    )
        .prop_map(|(d, o, hi, ho, s, c)| {
            // Outputs of the input's length most of the time.
            let o = if o % 3 == 0 { o } else { d.len() };
            (d, o, hi, ho, s, c)
        })
}

#[test]
fn primitives_cpu() {
    run(&wp::cpu(), 96, primitives_strategy(), primitives_property);
}

#[test]
fn primitives_cuda() {
    if let Some(dev) = cuda("primitives_cuda") {
        run(&dev, 24, primitives_strategy(), primitives_property);
    }
}

// ---------------------------------------------------------------------------------------------
// Regressions: what the properties found, each as a plain test (the seeds are also in
// `proptest_runtime.proptest-regressions`, which proptest replays first).

/// An empty shape whose other extents multiply past `isize::MAX` bytes was accepted
/// (`[0, 2^62, 4]` of f32: its product is 0), with row-major strides that overflowed:
/// `byte_strides` panicked, and views of its transpose reached past the allocation. Refused
/// now as too large, as NumPy does; empty shapes of sane extents stay fine.
#[test]
fn empty_shapes_with_huge_extents() {
    let dev = wp::cpu();
    for shape in [
        [0, 1 << 62, 4],
        [0, 1 << 61, 1],
        [0, usize::MAX, 2],
        [usize::MAX, 2, 0],
    ] {
        let e = wp::Array::<f32, 3>::zeros(shape, &dev).unwrap_err();
        assert!(e.to_string().contains("too large"), "{shape:?}: {e}");
    }
    let a = wp::Array::<f32, 3>::zeros([0, 1 << 20, 4], &dev).unwrap();
    let _ = a.byte_strides();
    // Reshapes are held to the same rule.
    let e = wp::Array::<f32, 2>::zeros([0, 0], &dev)
        .unwrap()
        .reshape([0, 0, 1usize << 61])
        .unwrap_err();
    assert!(e.to_string().contains("too large"), "{e}");
    // As is external memory.
    // SAFETY: an empty layout addresses nothing.
    let e = unsafe {
        wp::Array::<f32, 3>::from_host_ptr(std::ptr::null_mut(), [0, 1 << 61, 1], None, &dev, ())
    }
    .unwrap_err();
    assert!(e.to_string().contains("too large"), "{e}");
}

/// A view or row of an empty array could point past its allocation (`[0, 0, 2^48]` of u8,
/// transposed to `[2^48, 0, 0]`, then `view(1..1)`: byte offset 1 in a 0-byte allocation),
/// and an empty view one past the end of a negative stride before it. Empty views keep the
/// parent's offset now.
#[test]
fn empty_views_stay_inside_their_allocation() {
    let dev = wp::cpu();
    let a = wp::Array::<u8, 3>::zeros([0, 0, 1 << 48], &dev).unwrap();
    let v = a.transpose().view(1..1).unwrap();
    assert_eq!(v.device_ptr(), a.device_ptr());
    assert_eq!(v.to_vec().unwrap(), Vec::<u8>::new());
    let b = wp::Array::<f32, 2>::zeros([0, 5], &dev)
        .unwrap()
        .transpose();
    let r = b.row(4).unwrap();
    assert_eq!(r.device_ptr(), b.device_ptr());
    assert!(r.to_vec().unwrap().is_empty());
    // A negative stride over external memory: the empty view at the end keeps the offset.
    let mut buf = [1.0f32, 2.0, 3.0];
    // SAFETY: the layout is buf[2], buf[1], buf[0]; `buf` outlives the array.
    let rev = unsafe {
        wp::Array::<f32>::from_host_ptr(buf.as_mut_ptr().add(2), 3, Some([-4]), &dev, ())
    }
    .unwrap();
    assert_eq!(rev.to_vec().unwrap(), [3.0, 2.0, 1.0]);
    let end = rev.view(3..).unwrap();
    assert_eq!(end.device_ptr(), rev.device_ptr());
    assert!(end.to_vec().unwrap().is_empty());
    assert_eq!(rev.view(1..).unwrap().to_vec().unwrap(), [2.0, 1.0]);
}

/// External empty layouts with huge strides: views and transposes used to multiply them by
/// the other extents (overflow). An empty layout gets row-major strides.
#[test]
fn empty_external_layouts_with_huge_strides() {
    let dev = wp::cpu();
    // SAFETY: an empty layout addresses nothing.
    let a = unsafe {
        wp::Array::<f32, 3>::from_host_ptr(
            std::ptr::null_mut(),
            [5, 0, 3],
            Some([isize::MAX - 3, 4, -(1 << 60)]),
            &dev,
            (),
        )
    }
    .unwrap();
    assert_eq!(a.strides(), [0, 3, 1]);
    assert!(a.view(3..4).unwrap().to_vec().unwrap().is_empty());
    assert!(a.transpose().view(1..2).unwrap().is_empty());
}
