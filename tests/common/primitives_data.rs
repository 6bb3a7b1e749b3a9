//! Data of the primitives' tests, shared by the backend suite (tests/suite/primitives.rs) and
//! the host run of the GPU plans (tests/cuda_primitives_host.rs), so that both check the same
//! cases against the same reference.

use warp_lang::primitives::ScanElement;

/// An element type of the scan and reduction tests: small integer-valued data (exact in any
/// summation order) from a random word.
pub trait Elem: ScanElement + PartialEq + std::fmt::Debug {
    fn small(r: u64) -> Self;
}
macro_rules! elem {
    ($($t:ty),*) => {$(
        impl Elem for $t {
            fn small(r: u64) -> Self {
                (r % 200) as $t - 100 as $t
            }
        }
    )*};
}
elem!(i32, i64, f32, f64);
impl Elem for u32 {
    // Values with the top bit set: sums wrap.
    fn small(r: u64) -> Self {
        (r as u32) | 0x8000_0000
    }
}
impl Elem for u64 {
    fn small(r: u64) -> Self {
        r | (1 << 63)
    }
}

/// The serial scan every backend's result is compared with.
pub fn serial_scan<T: Elem>(x: &[T], inclusive: bool) -> Vec<T> {
    let mut acc = T::ZERO;
    x.iter()
        .map(|&v| {
            let before = acc;
            acc = acc.add(v);
            if inclusive {
                acc
            } else {
                before
            }
        })
        .collect()
}

/// Float keys every sort test includes: NaNs of both signs, signed zeros (twice, for
/// stability), infinities, denormals and the extremes.
pub const F32_SPECIALS: [f32; 14] = [
    f32::NAN,
    -0.0,
    0.0,
    f32::INFINITY,
    f32::NEG_INFINITY,
    -f32::NAN,
    1e-45,
    -1e-45,
    -0.0,
    0.0,
    3.5,
    -3.5,
    f32::MAX,
    f32::MIN,
];
