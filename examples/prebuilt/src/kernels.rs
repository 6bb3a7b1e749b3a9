//! The kernels of the prebuilt example: the autodiff example's seed function (its value and
//! derivative by a tape), shared by the build script (which compiles them to cubins) and the
//! binary (which launches them); the same source gives the same key on both sides.

use warp_lang as wp;
use wp::prelude::*;

/// y = sin(x^2) ln x + x^3 / sqrt(1 - x^2): the seed function of the autodiff example.
#[wp::kernel]
pub fn seed(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let v = x[i];
    y[i] = sin(v * v) * log(v) + v * v * v / sqrt(1.0 - v * v);
}

/// Every kernel the binary launches (the build script compiles these).
#[allow(dead_code)] // used by build.rs, which includes this file
pub fn all() -> Vec<&'static wp::KernelInfo> {
    vec![wp::kernel_info(seed)]
}
