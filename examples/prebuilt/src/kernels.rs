//! The kernels of the prebuilt example: the autodiff example's (`examples/common/seed_ad.rs`:
//! the seed function, and the particle program's step and loss), included both by the build
//! script, which compiles them to cubins, and by the binary, which launches them. The same
//! file gives the same generated CUDA, so the same ahead-of-time keys, on both sides (a unit
//! names the module below the crate, `kernels::seed_ad`, and the file, never the crate).

#[path = "../../common/seed_ad.rs"]
pub mod seed_ad;

use warp_lang as wp;

/// Every kernel the binary launches (the build script compiles these, with their adjoints).
#[allow(dead_code)] // not called by the binary unless it checks its cubins
pub fn all() -> Vec<&'static wp::KernelInfo> {
    vec![
        wp::kernel_info(seed_ad::seed),
        wp::kernel_info(seed_ad::step),
        wp::kernel_info(seed_ad::sum_sq),
    ]
}
