//! The constants warp-core shares with the CUDA library's headers (`warp-cuda/cuda/`), checked
//! equal: each is written in both languages (a Rust constant and a C++ `#define`, `constexpr`
//! or enum), and a GPU result agrees with the CPU's only while they are. The host C++ tests
//! compare results; this compares the numbers themselves, so a drift names the constant.
//!
//! (The marching cubes tables are written once, in the header, and read by warp-runtime at
//! compile time; the records passed to the GPU assert their sizes on both sides.)

use crate::builtins::svd::DecompFloat;
use crate::objects::{bvh, geometry, nanovdb, volume};

const BVH: &str = include_str!("../../warp-cuda/cuda/wp_bvh.h");
const GEOMETRY: &str = include_str!("../../warp-cuda/cuda/wp_geometry.h");
const VOLUME: &str = include_str!("../../warp-cuda/cuda/wp_volume.h");
const VOLUME_BUILD: &str = include_str!("../../warp-cuda/cuda/wp_volume_build.h");
const RAND: &str = include_str!("../../warp-cuda/cuda/wp_rand.h");
const SVD: &str = include_str!("../../warp-cuda/cuda/wp_svd.h");

/// The first `n` numeric literals in `header` after the successive `anchors` (each searched
/// from the end of the one before), their suffixes (`u`, `ull`, `f`) dropped.
fn literals_after<'a>(header: &'a str, anchors: &[&str], n: usize) -> Vec<&'a str> {
    let mut at = 0;
    for a in anchors {
        at += header[at..]
            .find(a)
            .unwrap_or_else(|| panic!("`{a}` is not in the header"))
            + a.len();
    }
    let mut out = Vec::new();
    let bytes = header.as_bytes();
    while out.len() < n {
        while at < bytes.len() && !bytes[at].is_ascii_digit() {
            at += 1;
        }
        let start = at;
        while at < bytes.len()
            && (bytes[at].is_ascii_alphanumeric()
                || bytes[at] == b'.'
                || ((bytes[at] == b'-' || bytes[at] == b'+')
                    && matches!(bytes[at - 1], b'e' | b'E')))
        {
            at += 1;
        }
        out.push(header[start..at].trim_end_matches(['u', 'U', 'l', 'L', 'f', 'F']));
    }
    out
}

/// The one numeric literal after `anchors`, parsed as `T`.
fn value<T: std::str::FromStr>(header: &str, anchors: &[&str]) -> T
where
    T::Err: std::fmt::Debug,
{
    let text = literals_after(header, anchors, 1)[0];
    text.parse()
        .unwrap_or_else(|e| panic!("{anchors:?}: `{text}` is not a number: {e:?}"))
}

#[test]
fn geometry_constants() {
    assert_eq!(
        geometry::SLIVER_RATIO,
        value::<f32>(GEOMETRY, &["#define WP_SLIVER_RATIO"])
    );
    assert_eq!(
        geometry::TRI_TRI_EPS,
        value::<f32>(GEOMETRY, &["#define WP_TRI_TRI_EPS"])
    );
    assert_eq!(
        bvh::ORDERED_STACK,
        value::<usize>(BVH, &["#define WP_BVH_ORDERED_STACK"])
    );
}

/// The NanoVDB layout facts the sampling and the build read (offsets into a grid's nodes),
/// and the sampling modes.
#[test]
fn volume_constants() {
    let v = |name: &str| value::<usize>(VOLUME, &[name, "="]);
    assert_eq!(nanovdb::UPPER_CHILD_MASK, v("VOL_UPPER_CHILD_MASK"));
    assert_eq!(nanovdb::LOWER_CHILD_MASK, v("VOL_LOWER_CHILD_MASK"));
    assert_eq!(nanovdb::LEAF_VALUE_MASK, v("VOL_LEAF_MASK"));
    assert_eq!(volume::INDEX_PREFIX_SUM as usize, v("VOL_PREFIX_SUM"));
    assert_eq!(nanovdb::MAP, v("VOL_MAP"));
    assert_eq!(
        volume::CLOSEST,
        value::<i32>(VOLUME, &["VOLUME_CLOSEST", "="])
    );
    assert_eq!(
        volume::LINEAR,
        value::<i32>(VOLUME, &["VOLUME_LINEAR", "="])
    );
    let b = |name: &str| value::<usize>(VOLUME_BUILD, &[name, "="]);
    assert_eq!(nanovdb::UPPER_CHILD_MASK, b("vb_upper_child_mask"));
    assert_eq!(nanovdb::LOWER_CHILD_MASK, b("vb_lower_child_mask"));
    assert_eq!(nanovdb::LEAF_VALUE_MASK, b("vb_leaf_value_mask"));
    assert_eq!(nanovdb::LEAF_BBOX_DIF, b("vb_leaf_bbox_dif"));
    assert_eq!(nanovdb::grid::WORLD_BBOX, b("vb_world_bbox"));
}

/// The random number generator's and the noise's constants.
#[test]
fn rand_constants() {
    use crate::builtins::rand;
    assert_eq!(
        rand::RANDN_EPSILON,
        value::<f32>(RAND, &["RANDN_EPSILON", "="])
    );
    assert_eq!(
        rand::POISSON_MAX_DRAWS,
        value::<u32>(RAND, &["POISSON_MAX_DRAWS", "="])
    );
    // `rand_unit`: the top 24 bits over 2^24.
    assert_eq!(
        rand::UNIT,
        1.0 / value::<f32>(RAND, &["f32 rand_unit(", "(1.0f /"])
    );
    let primes: Vec<u32> = literals_after(RAND, &["primes[4] = {"], 4)
        .iter()
        .map(|p| p.parse().unwrap())
        .collect();
    assert_eq!(crate::builtins::noise::PRIMES[..], primes[..]);
}

/// The decompositions' tolerances, sweeps and rotation constants, per precision.
#[test]
fn svd_constants() {
    fn check<S>(cfg: &str, from_f64: fn(f64) -> S)
    where
        S: DecompFloat + std::str::FromStr + PartialEq + std::fmt::Debug,
        S::Err: std::fmt::Debug,
    {
        assert_eq!(S::EPS, value::<S>(SVD, &[cfg, "eps()"]), "{cfg}");
        assert_eq!(S::SWEEPS, value::<usize>(SVD, &[cfg, "sweeps()"]), "{cfg}");
        // `(S)5.828...`: a double literal rounded to `S`, as the Rust `5.828..._f64 as S`.
        let cast = |f: &str| from_f64(value::<f64>(SVD, &[f, "(S)"]));
        assert_eq!(S::GAMMA, cast("S gamma()"));
        assert_eq!(S::CSTAR, cast("S cstar()"));
        assert_eq!(S::SSTAR, cast("S sstar()"));
        assert_eq!(S::SQRT1_2, cast("S sqrt1_2()"));
    }
    check::<f32>("struct cfg<f32>", |x| x as f32);
    check::<f64>("struct cfg<f64>", |x| x);
}

/// The reader finds what it is asked for and fails loudly where it is not there.
#[test]
fn literals_after_reads_suffixed_literals() {
    let h = "#define A 12u\nconstexpr f32 B = 5.96e-8f; int c[2] = {7u, 0x1};";
    assert_eq!(value::<u32>(h, &["#define A"]), 12);
    assert_eq!(value::<f32>(h, &["B", "="]), 5.96e-8);
    assert_eq!(literals_after(h, &["c[2] = {"], 1), ["7"]);
    assert!(std::panic::catch_unwind(|| value::<u32>(h, &["#define Z"])).is_err());
}
