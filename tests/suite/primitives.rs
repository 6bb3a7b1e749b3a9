//! The parallel primitives (`wp::array_scan`, the reductions, `wp::radix_sort_pairs`,
//! `wp::compact`) against serial references on random data: sizes 0, 1, non-powers of two,
//! more than one GPU tile (2048) and more than one CPU chunk (65536), duplicate keys
//! (stability), negative and special float keys, partial key bits, counts on the device;
//! and every bad input an `Err` naming the function and the argument.
//!
//! Data is integer-valued wherever sums are compared, so that every summation order gives
//! the same result and the comparison is exact on both backends; fractional float sums are
//! compared within the bound of any summation order.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::primitives::SortKey;
use wp::Error;

backend_tests!(
    scan_all_types_and_sizes,
    scan_in_place_and_counts,
    scan_float_fractional_within_rounding,
    scan_onepass_kernel,
    scan_threepass_kernel,
    reductions_all_types,
    reductions_nan_and_empty,
    sort_u32_stable_with_duplicates,
    sort_i32_and_f32_keys,
    sort_key_bits,
    sort_counts,
    sort_every_kernel_config,
    workspace_reuse_across_sizes_types_and_streams,
    compact_types_and_counts,
    device_counts_chain_without_host_reads,
    bad_inputs_are_errors,
    bad_device_counts,
);

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// Sizes: empty, tiny, around a GPU tile (2048), and past a CPU chunk (65536).
const SIZES: [usize; 8] = [0, 1, 2, 37, 2047, 2049, 5000, 70001];

#[path = "../common/primitives_data.rs"]
mod primitives_data;
use primitives_data::{serial_scan, Elem, F32_SPECIALS};

fn scan_type<T: Elem>(dev: &wp::Device) {
    let mut rng = Rng(11 + T::CUDA.len() as u64);
    for n in SIZES {
        let x: Vec<T> = (0..n).map(|_| T::small(rng.next())).collect();
        let input = arr(&x, dev);
        for inclusive in [false, true] {
            let out = zeros::<T, 1>(n, dev);
            wp::array_scan(&input, &out, inclusive).unwrap();
            assert_eq!(
                host(&out),
                serial_scan(&x, inclusive),
                "{} n {n} inclusive {inclusive}",
                T::CUDA
            );
        }
        assert_eq!(host(&input), x, "the input is left alone");
    }
}

fn scan_all_types_and_sizes(dev: &wp::Device) {
    scan_type::<i32>(dev);
    scan_type::<u32>(dev);
    scan_type::<i64>(dev);
    scan_type::<u64>(dev);
    scan_type::<f32>(dev);
    scan_type::<f64>(dev);
}

fn scan_in_place_and_counts(dev: &wp::Device) {
    let mut rng = Rng(5);
    let x: Vec<i32> = (0..5000).map(|_| i32::small(rng.next())).collect();
    // In place.
    let a = arr(&x, dev);
    wp::array_scan(&a, &a, true).unwrap();
    assert_eq!(host(&a), serial_scan(&x, true));
    // The first 3000 of a longer input into a longer output: the rest stays.
    let out = wp::Array::full(6000, -1, dev).unwrap();
    let input = arr(&x, dev);
    wp::array_scan_n(&input, &out, 3000, false).unwrap();
    let got = host(&out);
    assert_eq!(got[..3000], serial_scan(&x[..3000], false)[..]);
    assert!(got[3000..].iter().all(|&v| v == -1));
    // Counts on the device, including 0 and the whole capacity.
    for c in [0, 1, 2048, 4999, 5000] {
        let count = arr(&[c], dev);
        let a = arr(&x, dev);
        wp::array_scan_n(&a, &a, &count, true).unwrap();
        let got = host(&a);
        let c = c as usize;
        assert_eq!(got[..c], serial_scan(&x[..c], true)[..], "device count {c}");
        assert_eq!(got[c..], x[c..], "device count {c}: past the count");
    }
}

/// An inclusive scan of `n` fractional f32 values in [-1, 1], checked within the bound of any
/// summation order (any order of k additions is within 2 k eps sum |x| of the exact prefix);
/// the input and the result.
fn fractional_scan_within_rounding(dev: &wp::Device, n: usize) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Rng(99);
    let x: Vec<f32> = (0..n)
        .map(|_| (rng.below(2_000_001) as f32 - 1e6) * 1e-6)
        .collect();
    let out = zeros::<f32, 1>(n, dev);
    wp::array_scan(&arr(&x, dev), &out, true).unwrap();
    let got = host(&out);
    let (mut exact, mut abs) = (0f64, 0f64);
    for (k, (&g, &v)) in got.iter().zip(&x).enumerate() {
        exact += v as f64;
        abs += v.abs() as f64;
        let bound = 2.0 * (k + 1) as f64 * f32::EPSILON as f64 * abs;
        assert!(
            (g as f64 - exact).abs() <= bound,
            "prefix {k}: {g} vs {exact}"
        );
    }
    (x, got)
}

fn scan_float_fractional_within_rounding(dev: &wp::Device) {
    let n = 70001;
    let (x, got) = fractional_scan_within_rounding(dev, n);
    // Deterministic: the same again.
    let again = zeros::<f32, 1>(n, dev);
    wp::array_scan(&arr(&x, dev), &again, true).unwrap();
    assert_eq!(
        host(&again).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        got.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
}

/// The GPU's single-pass scan (decoupled look-back, `plan::ScanAlgorithm::OnePass`, the
/// integers' and f32's default), whatever the default: see `scan_by`.
fn scan_onepass_kernel(dev: &wp::Device) {
    scan_by(dev, wp::primitives::plan::ScanAlgorithm::OnePass);
}

/// The GPU's three-phase scan (`plan::ScanAlgorithm::ThreePass`, the default of f64, f16 and
/// bf16), whatever the default: see `scan_by`.
fn scan_threepass_kernel(dev: &wp::Device) {
    scan_by(dev, wp::primitives::plan::ScanAlgorithm::ThreePass);
}

/// Every scan through one GPU algorithm, for every element type: the checks of
/// `scan_all_types_and_sizes` and `scan_in_place_and_counts`, fractional floats within
/// rounding and the same bits in five runs (which tiles a look-back finds published depends
/// on timing; the float sums' order must not), and inputs of thousands of tiles, where blocks
/// run at once and look-backs meet tiles that have published only their aggregate. On the CPU the algorithm plays no part, and is left alone (the CPU instances run
/// beside the GPU's): the same checks run once.
fn scan_by(dev: &wp::Device, algorithm: wp::primitives::plan::ScanAlgorithm) {
    use wp::primitives::plan;
    /// Puts the default back however the test ends (the GPU instances run one at a time: no
    /// other scan sees the choice).
    struct Restore;
    impl Drop for Restore {
        fn drop(&mut self) {
            plan::set_gpu_scan_algorithm(None);
        }
    }
    let _restore = dev.is_cuda().then(|| {
        plan::set_gpu_scan_algorithm(Some(algorithm));
        Restore
    });
    scan_all_types_and_sizes(dev);
    scan_in_place_and_counts(dev);
    let (x, first) = fractional_scan_within_rounding(dev, 1 << 20);
    let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for run in 1..5 {
        let again = zeros::<f32, 1>(x.len(), dev);
        wp::array_scan(&arr(&x, dev), &again, true).unwrap();
        assert!(
            bits(&host(&again)) == bits(&first),
            "{algorithm:?}: run {run} of a fractional f32 scan gives other bits than run 0"
        );
    }
    let mut rng = Rng(41);
    for n in [1 << 20, (1 << 22) + 5] {
        let x: Vec<i32> = (0..n).map(|_| i32::small(rng.next())).collect();
        let a = arr(&x, dev);
        let out = zeros::<i32, 1>(n, dev);
        wp::array_scan(&a, &out, true).unwrap();
        assert_eq!(host(&out), serial_scan(&x, true), "i32 n {n}");
        wp::array_scan(&a, &a, false).unwrap();
        assert_eq!(host(&a), serial_scan(&x, false), "i32 in place n {n}");
        // 8-byte elements: flags and values apart, ordered by fences.
        let y: Vec<u64> = (0..n).map(|_| u64::small(rng.next())).collect();
        let out = zeros::<u64, 1>(n, dev);
        wp::array_scan(&arr(&y, dev), &out, true).unwrap();
        assert_eq!(host(&out), serial_scan(&y, true), "u64 n {n}");
        let z: Vec<f64> = (0..n).map(|_| f64::small(rng.next())).collect();
        let count = arr(&[(n - 7) as i32], dev);
        let out = wp::Array::full(n, -0.5f64, dev).unwrap();
        wp::array_scan_n(&arr(&z, dev), &out, &count, false).unwrap();
        let got = host(&out);
        assert_eq!(
            got[..n - 7],
            serial_scan(&z[..n - 7], false)[..],
            "f64 n {n}"
        );
        assert!(
            got[n - 7..].iter().all(|&v| v == -0.5),
            "f64 n {n}: past the count"
        );
    }
}

fn reduce_type<T: Elem>(dev: &wp::Device) {
    let mut rng = Rng(3 + T::CUDA.len() as u64);
    for n in SIZES {
        let x: Vec<T> = (0..n).map(|_| T::small(rng.next())).collect();
        let a = arr(&x, dev);
        let out = zeros::<T, 1>(1, dev);
        wp::array_sum(&a, &out).unwrap();
        assert_eq!(
            host(&out)[0],
            x.iter().fold(T::ZERO, |s, &v| s.add(v)),
            "sum {n}"
        );
        wp::array_min(&a, &out).unwrap();
        assert_eq!(
            host(&out)[0],
            x.iter().fold(T::MIN_IDENTITY, |s, &v| s.min_of(v)),
            "min {n}"
        );
        wp::array_max(&a, &out).unwrap();
        assert_eq!(
            host(&out)[0],
            x.iter().fold(T::MAX_IDENTITY, |s, &v| s.max_of(v)),
            "max {n}"
        );
        // The first half, with a host and a device count.
        let h = n / 2;
        let want = x[..h].iter().fold(T::ZERO, |s, &v| s.add(v));
        wp::array_sum_n(&a, &out, h).unwrap();
        assert_eq!(host(&out)[0], want, "sum of {h}");
        let count = arr(&[h as i32], dev);
        out.fill(T::small(1)).unwrap();
        wp::array_sum_n(&a, &out, &count).unwrap();
        assert_eq!(host(&out)[0], want, "sum of a device count {h}");
        wp::array_max_n(&a, &out, &count).unwrap();
        let want = x[..h].iter().fold(T::MAX_IDENTITY, |s, &v| s.max_of(v));
        assert_eq!(host(&out)[0], want, "max of a device count {h}");
        wp::array_min_n(&a, &out, &count).unwrap();
        let want = x[..h].iter().fold(T::MIN_IDENTITY, |s, &v| s.min_of(v));
        assert_eq!(host(&out)[0], want, "min of a device count {h}");
    }
}

fn reductions_all_types(dev: &wp::Device) {
    reduce_type::<i32>(dev);
    reduce_type::<u32>(dev);
    reduce_type::<i64>(dev);
    reduce_type::<u64>(dev);
    reduce_type::<f32>(dev);
    reduce_type::<f64>(dev);
}

fn reductions_nan_and_empty(dev: &wp::Device) {
    let nan = f32::NAN;
    let mut x: Vec<f32> = (0..5000).map(|i| (i % 97) as f32 - 40.0).collect();
    for i in (0..5000).step_by(13) {
        x[i] = nan;
    }
    let (a, out) = (arr(&x, dev), zeros::<f32, 1>(1, dev));
    wp::array_min(&a, &out).unwrap();
    assert_eq!(host(&out), [-40.0], "NaN ignored by min");
    wp::array_max(&a, &out).unwrap();
    assert_eq!(host(&out), [56.0], "NaN ignored by max");
    wp::array_sum(&a, &out).unwrap();
    assert!(host(&out)[0].is_nan(), "a sum with NaN is NaN");
    let all_nan = arr(&[nan; 300], dev);
    wp::array_min(&all_nan, &out).unwrap();
    assert_eq!(host(&out), [f32::INFINITY], "all NaN: the identity");
    let inf = arr(&[1.0, f32::INFINITY, -f32::INFINITY], dev);
    wp::array_max(&inf, &out).unwrap();
    assert_eq!(host(&out), [f32::INFINITY]);
    wp::array_min(&inf, &out).unwrap();
    assert_eq!(host(&out), [f32::NEG_INFINITY]);
    let empty = zeros::<f64, 1>(0, dev);
    let out = wp::Array::full(1, 5.0f64, dev).unwrap();
    wp::array_sum(&empty, &out).unwrap();
    assert_eq!(host(&out), [0.0]);
    wp::array_min(&empty, &out).unwrap();
    assert_eq!(host(&out), [f64::INFINITY]);
    let out = wp::Array::full(1, 5i32, dev).unwrap();
    wp::array_max(&zeros::<i32, 1>(0, dev), &out).unwrap();
    assert_eq!(host(&out), [i32::MIN]);
}

/// The reference: a stable sort of the pairs by the low `bits` bits of the keys' images.
fn sort_reference<K: SortKey>(keys: &[K], values: &[u32], bits: u32) -> (Vec<K>, Vec<u32>) {
    let mask = if bits == 32 {
        u32::MAX
    } else {
        (1 << bits) - 1
    };
    let mut pairs: Vec<(K, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    pairs.sort_by_key(|(k, _)| k.to_radix() & mask);
    pairs.into_iter().unzip()
}

/// Sorts `keys` (values: their positions, so stability shows) on `dev` and compares keys
/// bit for bit and values exactly.
#[track_caller]
fn check_sort<K: SortKey + std::fmt::Debug>(
    dev: &wp::Device,
    keys: &[K],
    bits: Option<u32>,
    what: &str,
) {
    let n = keys.len();
    let values: Vec<u32> = (0..n as u32).collect();
    let (k, v) = (arr(keys, dev), arr(&values, dev));
    wp::radix_sort_pairs(&k, &v, n, bits).unwrap();
    let (wk, wv) = sort_reference(keys, &values, bits.unwrap_or(32));
    let gk = host(&k);
    assert_eq!(
        bytemuck::cast_slice::<K, u32>(&gk),
        bytemuck::cast_slice::<K, u32>(&wk),
        "{what}: keys"
    );
    assert_eq!(host(&v), wv, "{what}: values (stability)");
}

fn sort_u32_stable_with_duplicates(dev: &wp::Device) {
    let mut rng = Rng(21);
    for n in SIZES {
        // 37 distinct keys spread over every byte: long runs of equal keys in every pass.
        let keys: Vec<u32> = (0..n).map(|_| rng.below(37) as u32 * 0x0101_0101).collect();
        check_sort(dev, &keys, None, &format!("u32 duplicates n {n}"));
        let keys: Vec<u32> = (0..n).map(|_| rng.next() as u32).collect();
        check_sort(dev, &keys, None, &format!("u32 random n {n}"));
    }
    check_sort(dev, &[u32::MAX, 0, u32::MAX, 1, 0], None, "u32 extremes");
}

fn sort_i32_and_f32_keys(dev: &wp::Device) {
    let mut rng = Rng(22);
    for n in SIZES {
        let keys: Vec<i32> = (0..n).map(|_| rng.below(2001) as i32 - 1000).collect();
        check_sort(dev, &keys, None, &format!("i32 n {n}"));
        let keys: Vec<f32> = (0..n)
            .map(|_| (rng.below(81) as f32 - 40.0) * 0.25)
            .collect();
        check_sort(dev, &keys, None, &format!("f32 n {n}"));
    }
    check_sort(
        dev,
        &[i32::MIN, i32::MAX, -1, 0, 1, i32::MIN],
        None,
        "i32 extremes",
    );
    // The float order is f32::total_cmp's: -NaN < -inf < .. < -0.0 < +0.0 < .. < inf < NaN.
    let specials = F32_SPECIALS;
    check_sort(dev, &specials, None, "f32 specials");
    let (k, v) = (arr(&specials, dev), arr(&[0u32; 14], dev));
    wp::radix_sort_pairs(&k, &v, 14, None).unwrap();
    let got = host(&k);
    assert!(got[0].is_nan() && got[0].is_sign_negative());
    assert_eq!(got[1], f32::NEG_INFINITY);
    assert!(got[5] == 0.0 && got[5].is_sign_negative() && got[6].is_sign_negative());
    assert!(got[7] == 0.0 && got[7].is_sign_positive());
    assert!(got[13].is_nan() && got[13].is_sign_positive());
    // Values of every 4-byte type move with their keys.
    let (k, v) = (arr(&[3u32, 1, 2], dev), arr(&[30.5f32, 10.5, 20.5], dev));
    wp::radix_sort_pairs(&k, &v, 3, None).unwrap();
    assert_eq!(host(&v), [10.5, 20.5, 30.5]);
    let (k, v) = (arr(&[3i32, -1, 2], dev), arr(&[3i32, -1, 2], dev));
    wp::radix_sort_pairs(&k, &v, 3, None).unwrap();
    assert_eq!(host(&v), [-1, 2, 3]);
}

fn sort_key_bits(dev: &wp::Device) {
    let mut rng = Rng(23);
    for bits in [1, 4, 5, 9, 16, 31] {
        for n in [1000, 70001] {
            // High bits set too: only the low `bits` bits may order.
            let keys: Vec<u32> = (0..n).map(|_| rng.next() as u32).collect();
            check_sort(dev, &keys, Some(bits), &format!("u32 {bits} bits n {n}"));
            let keys: Vec<i32> = (0..n).map(|_| rng.next() as i32).collect();
            check_sort(dev, &keys, Some(bits), &format!("i32 {bits} bits n {n}"));
        }
    }
}

/// Every GPU sort kernel and block shape the bench compares gives the default's results (the
/// stable order, bit for bit), with more tiles than the GPU holds at once (long look-back
/// chains) and a partial last tile; a block of one warp of 4 keys makes tiles of 128. On the
/// CPU the configuration plays no part, and is left alone (the CPU instances run beside the
/// GPU's): the same checks run once.
fn sort_every_kernel_config(dev: &wp::Device) {
    use wp::primitives::plan::{self, SortConfig, SortVariant, Tile};
    /// Puts the default configuration back however the test ends (the GPU instances run one
    /// at a time: no other sort sees the choice).
    struct Restore;
    impl Drop for Restore {
        fn drop(&mut self) {
            plan::set_gpu_sort_config(None).unwrap();
        }
    }
    let _restore = dev.is_cuda().then_some(Restore);
    let with = |variant, threads, items, min_blocks| SortConfig {
        variant,
        tile: Tile { threads, items },
        min_blocks,
    };
    let configs = [
        with(SortVariant::MatchAny, 256, 16, 3),
        with(SortVariant::Ballot, 384, 12, 2),
        with(SortVariant::Ballot, 512, 8, 2),
        with(SortVariant::Ballot, 256, 12, 4),
        with(SortVariant::Ballot, 128, 16, 6),
        with(SortVariant::Nibbles, 256, 16, 4),
        with(SortVariant::Ballot, 32, 4, 1),
    ];
    let runs = if dev.is_cuda() {
        &configs[..]
    } else {
        &configs[..1]
    };
    let mut rng = Rng(25);
    for &c in runs {
        if dev.is_cuda() {
            plan::set_gpu_sort_config(Some(c)).unwrap();
        }
        for n in [1, 5000, 300_001] {
            let keys: Vec<u32> = (0..n).map(|_| rng.next() as u32).collect();
            check_sort(dev, &keys, None, &format!("{c:?} random n {n}"));
            let keys: Vec<u32> = (0..n).map(|_| rng.below(37) as u32 * 0x0101_0101).collect();
            check_sort(dev, &keys, None, &format!("{c:?} duplicates n {n}"));
            let keys: Vec<u32> = (0..n).map(|_| rng.below(1 << 21) as u32).collect();
            check_sort(dev, &keys, Some(21), &format!("{c:?} 21 bits n {n}"));
        }
        // A count on the device that ends inside a tile.
        let keys: Vec<u32> = (0..9000).map(|_| rng.below(500) as u32).collect();
        let values: Vec<u32> = (0..9000).collect();
        let (k, v, count) = (arr(&keys, dev), arr(&values, dev), arr(&[6001i32], dev));
        wp::radix_sort_pairs(&k, &v, &count, None).unwrap();
        let (mut wk, mut wv) = sort_reference(&keys[..6001], &values[..6001], 32);
        wk.extend_from_slice(&keys[6001..]);
        wv.extend_from_slice(&values[6001..]);
        assert_eq!(host(&k), wk, "{c:?} device count");
        assert_eq!(host(&v), wv, "{c:?} device count");
    }
}

fn sort_counts(dev: &wp::Device) {
    let mut rng = Rng(24);
    let n = 5000;
    let keys: Vec<u32> = (0..n).map(|_| rng.below(100) as u32).collect();
    let values: Vec<u32> = (0..n as u32).collect();
    for c in [0usize, 1, 2, 2048, 3001, n] {
        for device in [false, true] {
            let (k, v) = (arr(&keys, dev), arr(&values, dev));
            let count = arr(&[c as i32], dev);
            if device {
                wp::radix_sort_pairs(&k, &v, &count, None).unwrap();
            } else {
                wp::radix_sort_pairs(&k, &v, c, None).unwrap();
            }
            let (mut wk, mut wv) = sort_reference(&keys[..c], &values[..c], 32);
            wk.extend_from_slice(&keys[c..]);
            wv.extend_from_slice(&values[c..]);
            assert_eq!(host(&k), wk, "count {c} on the device: {device}");
            assert_eq!(host(&v), wv, "count {c} on the device: {device}");
        }
    }
    // Warp's convention of 2n-element arrays works too: the second half is left alone.
    let (k, v) = (
        arr(&[5u32, 4, 3, 9, 9, 9], dev),
        arr(&[0u32, 1, 2, 7, 7, 7], dev),
    );
    wp::radix_sort_pairs(&k, &v, 3, None).unwrap();
    assert_eq!(host(&k), [3, 4, 5, 9, 9, 9]);
    assert_eq!(host(&v), [2, 1, 0, 7, 7, 7]);
}

/// The serial reference of compaction.
fn kept<T: Copy>(values: &[T], flags: &[i32]) -> Vec<T> {
    values
        .iter()
        .zip(flags)
        .filter(|(_, &f)| f != 0)
        .map(|(v, _)| *v)
        .collect()
}

fn check_compact<T: wp::Element + PartialEq + std::fmt::Debug>(
    dev: &wp::Device,
    values: &[T],
    flags: &[i32],
    fill: T,
) {
    let n = values.len();
    let out = wp::Array::full(n + 1, fill, dev).unwrap();
    let count = arr(&[-9], dev);
    wp::compact(&arr(values, dev), &arr(flags, dev), &out, &count).unwrap();
    let want = kept(values, flags);
    let got = host(&out);
    assert_eq!(
        host(&count),
        [want.len() as i32],
        "{} n {n}: count",
        T::TYPE_NAME
    );
    assert_eq!(&got[..want.len()], &want[..], "{} n {n}", T::TYPE_NAME);
    assert!(
        got[want.len()..].iter().all(|v| *v == fill),
        "past the count"
    );
}

fn compact_types_and_counts(dev: &wp::Device) {
    use wp::glam::{DVec2, Vec3};
    let mut rng = Rng(31);
    for n in SIZES {
        let flags: Vec<i32> = (0..n)
            .map(|_| {
                if rng.below(3) == 0 {
                    rng.below(9) as i32 - 4
                } else {
                    0
                }
            })
            .collect();
        let f: Vec<f32> = (0..n).map(|i| i as f32 * 0.5).collect();
        check_compact(dev, &f, &flags, -1.0);
        let b: Vec<u8> = (0..n).map(|i| i as u8).collect();
        check_compact(dev, &b, &flags, 255);
        let h: Vec<wp::f16> = (0..n)
            .map(|i| wp::f16::from_f32((i % 1000) as f32))
            .collect();
        check_compact(dev, &h, &flags, wp::f16::from_f32(-1.0));
        let v: Vec<Vec3> = (0..n).map(|i| Vec3::splat(i as f32)).collect();
        check_compact(dev, &v, &flags, Vec3::new(-1.0, -2.0, -3.0));
        let d: Vec<DVec2> = (0..n).map(|i| DVec2::new(i as f64, -(i as f64))).collect();
        check_compact(dev, &d, &flags, DVec2::splat(-1.0));
        // Keep everything, keep nothing.
        check_compact(dev, &f, &vec![1; n], -1.0);
        check_compact(dev, &f, &vec![0; n], -1.0);
    }
    // A count (host or device) over part of the arrays.
    let values: Vec<i64> = (0..5000).collect();
    let flags: Vec<i32> = (0..5000).map(|i| (i % 3 == 0) as i32).collect();
    for c in [0usize, 1, 2500, 5000] {
        for device in [false, true] {
            let out = wp::Array::full(5000, -1i64, dev).unwrap();
            let n_out = zeros::<i32, 1>(1, dev);
            let (v, f) = (arr(&values, dev), arr(&flags, dev));
            if device {
                wp::compact_n(&v, &f, &out, &n_out, &arr(&[c as i32], dev)).unwrap();
            } else {
                wp::compact_n(&v, &f, &out, &n_out, c).unwrap();
            }
            let want = kept(&values[..c], &flags[..c]);
            assert_eq!(host(&n_out), [want.len() as i32]);
            assert_eq!(host(&out)[..want.len()], want[..]);
        }
    }
}

/// A pipeline whose lengths stay on the device: compact the positive values, sort the kept
/// ones by key with the count `compact` wrote, then sum the first of them, all with that
/// count. On a GPU nothing here reads the count on the host.
fn device_counts_chain_without_host_reads(dev: &wp::Device) {
    let mut rng = Rng(41);
    let n = 10_000;
    let x: Vec<i32> = (0..n).map(|_| rng.below(2001) as i32 - 1000).collect();
    let flags: Vec<i32> = x.iter().map(|&v| (v > 0) as i32).collect();
    let (xs, fl) = (arr(&x, dev), arr(&flags, dev));
    let kept_keys = zeros::<i32, 1>(n, dev);
    let count = zeros::<i32, 1>(1, dev);
    wp::compact(&xs, &fl, &kept_keys, &count).unwrap();
    let idx: Vec<u32> = (0..n as u32).collect();
    let values = arr(&idx, dev);
    wp::radix_sort_pairs(&kept_keys, &values, &count, None).unwrap();
    let sum = zeros::<i32, 1>(1, dev);
    wp::array_sum_n(&kept_keys, &sum, &count).unwrap();
    let prefix = zeros::<i32, 1>(n, dev);
    wp::array_scan_n(&kept_keys, &prefix, &count, true).unwrap();

    let kept_in_order: Vec<i32> = x.iter().copied().filter(|&v| v > 0).collect();
    let m = kept_in_order.len();
    let (want, want_values) = sort_reference(&kept_in_order, &idx[..m], 32);
    assert_eq!(host(&count), [m as i32]);
    assert_eq!(host(&kept_keys)[..m], want[..]);
    let got_values = host(&values);
    assert_eq!(
        got_values[..m],
        want_values[..],
        "values moved with their keys, stably"
    );
    assert_eq!(got_values[m..], idx[m..], "past the count");
    assert_eq!(host(&sum), [want.iter().sum::<i32>()]);
    assert_eq!(host(&prefix)[..m], serial_scan(&want, true)[..]);
}

/// The message of an `Err`, or a panic naming what came instead.
#[track_caller]
fn err(r: wp::Result<()>) -> String {
    match r {
        Err(e) => e.to_string(),
        Ok(()) => panic!("expected an error"),
    }
}

fn bad_inputs_are_errors(dev: &wp::Device) {
    let a = arr(&[1i32, 2, 3, 4], dev);
    let b = zeros::<i32, 1>(3, dev);
    assert_eq!(
        err(wp::array_scan(&a, &b, true)),
        "invalid argument: array_scan: `output` has 3 elements but `input` has 4"
    );
    assert_eq!(
        err(wp::array_scan_n(&a, &b, 4, true)),
        "invalid argument: array_scan_n: count 4 is larger than `output` (3 elements)"
    );
    // Not contiguous: every other element of a 2-D array's column.
    let m = wp::Array::<i32, 2>::zeros((4, 2), dev).unwrap();
    let col = m.transpose().row(0).unwrap();
    assert_eq!(
        err(wp::array_scan(&col, &a, true)),
        "invalid argument: array_scan: `input` is not contiguous (shape [4], strides [2]); \
         copy it into a new array first"
    );
    // Partly overlapping views of one array.
    let big = zeros::<i32, 1>(8, dev);
    let (lo, hi) = (big.view(0..4).unwrap(), big.view(2..6).unwrap());
    assert_eq!(
        err(wp::array_scan(&lo, &hi, true)),
        "invalid argument: array_scan: `output` and `input` overlap without being the same \
         elements (in place is allowed, partly overlapping is not)"
    );
    // Disjoint views of one array are fine.
    wp::array_scan(&big.view(0..4).unwrap(), &big.view(4..8).unwrap(), true).unwrap();
    // Reductions.
    let out2 = zeros::<i32, 1>(2, dev);
    assert_eq!(
        err(wp::array_sum(&a, &out2)),
        "invalid argument: array_sum: `out` must be a 1-element array, got shape [2]"
    );
    assert_eq!(
        err(wp::array_max(&a, &a.view(1..2).unwrap())),
        "invalid argument: array_max: `out` and `values` share memory (an output must not \
         overlap the other arrays)"
    );
    assert_eq!(
        err(wp::array_min_n(&a, &b.view(0..1).unwrap(), 5)),
        "invalid argument: array_min_n: count 5 is larger than `values` (4 elements)"
    );
    // Counts on the device: one element, on the arrays' device.
    let two = arr(&[1, 1], dev);
    assert_eq!(
        err(wp::array_sum_n(&a, &b.view(0..1).unwrap(), &two)),
        "invalid argument: array_sum_n: `count` must be a 1-element array, got shape [2]"
    );
    if !dev.is_cpu() {
        let host_count = arr(&[1], &wp::cpu());
        assert_eq!(
            err(wp::array_sum_n(&a, &b.view(0..1).unwrap(), &host_count)),
            format!(
                "kernel `array_sum_n`: argument `count` is on device \"cpu\" but the launch is \
                 on device \"{}\"",
                dev.alias()
            )
        );
        let on_cpu = arr(&[1i32, 2, 3], &wp::cpu());
        assert!(matches!(
            wp::array_scan(&on_cpu, &b, true),
            Err(Error::DeviceMismatch {
                kernel: "array_scan",
                arg: "output",
                ..
            })
        ));
    }
    // Sort.
    let keys = arr(&[3u32, 1, 2], dev);
    let vals = zeros::<u32, 1>(2, dev);
    assert_eq!(
        err(wp::radix_sort_pairs(&keys, &vals, 3, None)),
        "invalid argument: radix_sort_pairs: count 3 is larger than `values` (2 elements)"
    );
    let vals = zeros::<u32, 1>(3, dev);
    assert_eq!(
        err(wp::radix_sort_pairs(&keys, &vals, 3, Some(0))),
        "invalid argument: radix_sort_pairs: `key_bits` is 0; it must be 1 to 32"
    );
    assert_eq!(
        err(wp::radix_sort_pairs(&keys, &vals, 3, Some(33))),
        "invalid argument: radix_sort_pairs: `key_bits` is 33; it must be 1 to 32"
    );
    let fkeys = arr(&[1.0f32, 0.5, 2.0], dev);
    assert_eq!(
        err(wp::radix_sort_pairs(&fkeys, &vals, 3, Some(16))),
        "invalid argument: radix_sort_pairs: `key_bits` is 16, but f32 keys are sorted by all \
         32 bits (their low bits alone have no order)"
    );
    let same = zeros::<u32, 1>(6, dev);
    assert_eq!(
        err(wp::radix_sort_pairs(
            &same.view(0..3).unwrap(),
            &same.view(2..5).unwrap(),
            3,
            None
        )),
        "invalid argument: radix_sort_pairs: `values` and `keys` share memory (an output must \
         not overlap the other arrays)"
    );
    // Compaction.
    let v = arr(&[1.0f32, 2.0, 3.0], dev);
    let (f2, f3) = (arr(&[1, 0], dev), arr(&[1, 0, 1], dev));
    let (o2, o3, c1) = (
        zeros::<f32, 1>(2, dev),
        zeros::<f32, 1>(3, dev),
        zeros::<i32, 1>(1, dev),
    );
    assert_eq!(
        err(wp::compact(&v, &f2, &o3, &c1)),
        "invalid argument: compact: `flags` has 2 elements but `values` has 3"
    );
    assert_eq!(
        err(wp::compact(&v, &f3, &o2, &c1)),
        "invalid argument: compact: `out` has 2 elements, fewer than `values` (3): every \
         element may be kept"
    );
    assert_eq!(
        err(wp::compact(&v, &f3, &o3, &zeros::<i32, 1>(2, dev))),
        "invalid argument: compact: `out_count` must be a 1-element array, got shape [2]"
    );
    assert_eq!(
        err(wp::compact_n(&v, &f3, &o3, &c1, 4)),
        "invalid argument: compact_n: count 4 is larger than `values` (3 elements)"
    );
    assert_eq!(
        err(wp::compact_n(&v, &f3, &o3, &c1, &c1)),
        "invalid argument: compact_n: `out_count` and `count` share memory (an output must not \
         overlap the other arrays)"
    );
}

/// A device count outside 0..=capacity: an `Err` on the CPU before anything is written; on a
/// GPU a fault at the next synchronisation (debug mode: at once), and nothing written.
fn bad_device_counts(dev: &wp::Device) {
    let a = arr(&[1i32, 2, 3, 4], dev);
    let out = wp::Array::full(4, -1i32, dev).unwrap();
    for bad in [5, -1] {
        let count = arr(&[bad], dev);
        let r = wp::array_scan_n(&a, &out, &count, true);
        if dev.is_cpu() {
            assert_eq!(
                err(r),
                format!(
                    "invalid argument: array_scan_n: the `count` array holds {bad}, outside \
                     0..=4 (`input` has 4 elements)"
                )
            );
        } else {
            // The suite runs GPU tests in debug mode: the fault comes back from the call, and
            // names the primitive's launch.
            let launch = wp::last_launch_id().expect("the primitive is a launch");
            assert_eq!(
                err(r),
                format!(
                    "kernel `array_scan_n`: index [{bad}] is out of bounds for argument \
                     `count` of shape [5] ({launch})"
                )
            );
        }
        assert_eq!(host(&out), [-1; 4], "nothing written for count {bad}");
        let (k, v) = (arr(&[4u32, 3, 2, 1], dev), arr(&[0u32, 1, 2, 3], dev));
        assert!(wp::radix_sort_pairs(&k, &v, &count, None).is_err());
        assert_eq!(host(&k), [4, 3, 2, 1]);
        let n = arr(&[-7], dev);
        assert!(wp::compact_n(&a, &a, &out, &n, &count).is_err());
        assert_eq!(host(&out), [-1; 4]);
    }
    // The device is usable afterwards.
    let s = zeros::<i32, 1>(1, dev);
    wp::array_sum(&a, &s).unwrap();
    assert_eq!(host(&s), [10]);
}

/// The GPU keeps one scratch workspace per device, grown to the largest need: calls of
/// different sizes (large, then small, then larger), key types, key bits and primitives use
/// it one after another without synchronising, and on two user streams in turn (each waits
/// for the workspace's last user). Results are read only at the end.
fn workspace_reuse_across_sizes_types_and_streams(dev: &wp::Device) {
    let mut rng = Rng(77);
    let sizes = [70_001usize, 37, 5000, 150_000, 1];
    let mut pending = Vec::new();
    let streams = if dev.is_cuda() {
        vec![wp::Stream::new(dev).unwrap(), wp::Stream::new(dev).unwrap()]
    } else {
        vec![]
    };
    for (c, &n) in sizes.iter().enumerate() {
        let _scope = streams
            .get(c % 2)
            .map(|s| wp::ScopedStream::new(s).unwrap());
        let ku: Vec<u32> = (0..n).map(|_| rng.next() as u32).collect();
        let kf: Vec<f32> = (0..n)
            .map(|_| (rng.below(41) as f32 - 20.0) * 0.25)
            .collect();
        let values: Vec<u32> = (0..n as u32).collect();
        let (a, av) = (arr(&ku, dev), arr(&values, dev));
        wp::radix_sort_pairs(&a, &av, n, Some(21)).unwrap();
        let (b, bv) = (arr(&kf, dev), arr(&values, dev));
        wp::radix_sort_pairs(&b, &bv, n, None).unwrap();
        let x: Vec<i32> = (0..n).map(|_| rng.below(200) as i32 - 100).collect();
        let (xa, prefix, total) = (
            arr(&x, dev),
            zeros::<i32, 1>(n, dev),
            zeros::<i32, 1>(1, dev),
        );
        wp::array_scan(&xa, &prefix, true).unwrap();
        wp::array_sum(&xa, &total).unwrap();
        pending.push((ku, kf, values, x, a, av, b, bv, prefix, total));
    }
    for (ku, kf, values, x, a, av, b, bv, prefix, total) in pending {
        let n = ku.len();
        let (wk, wv) = sort_reference(&ku, &values, 21);
        assert_eq!(host(&a), wk, "u32 keys, 21 bits, n {n}");
        assert_eq!(host(&av), wv, "u32 values, n {n}");
        let (wk, wv) = sort_reference(&kf, &values, 32);
        assert_eq!(host(&b), wk, "f32 keys, n {n}");
        assert_eq!(host(&bv), wv, "f32 values, n {n}");
        let mut acc = 0i32;
        let want: Vec<i32> = x
            .iter()
            .map(|&v| {
                acc += v;
                acc
            })
            .collect();
        assert_eq!(host(&prefix), want, "scan, n {n}");
        assert_eq!(host(&total), [acc], "sum, n {n}");
    }
}
