//! What each target can run: the capabilities generated code may need beyond the core
//! language, and for each target whether it has them (the CPU) or from which CUDA architecture
//! (compute capability, `major * 10 + minor`).
//!
//! This table is the one place those facts are stated. `#[kernel]` and `#[func]` record which
//! capabilities a function's code uses (`KernelInfo::requires`, [`FuncInfo::requires`],
//! computed by the macros' validator from the lowered code, by these variants' names); the
//! runtime compares them with a GPU's architecture when it loads a kernel there, and refuses
//! one the GPU cannot run with an error naming the kernel and the capability, instead of an
//! NVRTC or launch failure. The CUDA library switches between an instruction and its
//! emulation with `#if __CUDA_ARCH__ >= N`; a test of the runtime (`cuda::module`) holds those
//! `N` equal to [`CapabilityRow::cuda_native_arch`].
//!
//! [`FuncInfo::requires`]: crate::FuncInfo::requires

/// Something generated code relies on that not every target has as an instruction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[non_exhaustive]
pub enum Capability {
    /// `atomic_add` and `atomic_sub` on f64 elements (and f64 vector components), and an
    /// adjoint's gradient accumulation into f64 arrays and volumes.
    AtomicAddF64,
    /// Atomics on f16 and bf16 elements (`atomic_add`, `atomic_sub`, `atomic_min`,
    /// `atomic_max`), and an adjoint's gradient accumulation into f16 and bf16 arrays.
    AtomicF16,
    /// `atomic_min`, `atomic_max`, `atomic_and`, `atomic_or` and `atomic_xor` on 64-bit integer
    /// elements (i64, u64, isize, usize).
    AtomicMinMaxBits64,
}

/// One capability's facts, per target.
#[derive(Debug)]
pub struct CapabilityRow {
    pub capability: Capability,
    /// What it is, for messages ("f64 atomic add").
    pub what: &'static str,
    /// Whether CPU launches have it (warp-core's atomics implement every one).
    pub cpu: bool,
    /// The oldest CUDA architecture that runs it at all: a GPU below it is refused when a
    /// kernel needing it is loaded there. 0: every architecture.
    pub cuda_required_arch: u32,
    /// The oldest CUDA architecture with an instruction for it; from `cuda_required_arch` up to
    /// this one the CUDA library emulates it (as [`CapabilityRow::cuda_emulation`] says).
    pub cuda_native_arch: u32,
    /// How the CUDA library does it below `cuda_native_arch` (`None` when it does not).
    pub cuda_emulation: Option<&'static str>,
}

/// Every capability's row. The architectures are those of NVIDIA's CUDA C++ Programming Guide
/// (atomic functions) as `warp-cuda/cuda/wp_atomic.h` uses them.
pub static CAPABILITIES: &[CapabilityRow] = &[
    CapabilityRow {
        capability: Capability::AtomicAddF64,
        what: "f64 atomic add",
        cpu: true,
        cuda_required_arch: 0,
        // The double-precision atomicAdd.
        cuda_native_arch: 60,
        cuda_emulation: Some("a compare-and-swap loop on the 64-bit pattern"),
    },
    CapabilityRow {
        capability: Capability::AtomicF16,
        what: "f16 and bf16 atomics",
        cpu: true,
        cuda_required_arch: 0,
        // The 16-bit atomicCAS.
        cuda_native_arch: 70,
        cuda_emulation: Some(
            "a compare-and-swap of the aligned 32-bit word holding the element, which reads \
             the neighbouring 2 bytes (past a last element, beyond the array)",
        ),
    },
    CapabilityRow {
        capability: Capability::AtomicMinMaxBits64,
        what: "64-bit integer atomic min, max, and, or and xor",
        cpu: true,
        // atomicMin/Max/And/Or/Xor on 64-bit words: no emulation in the library.
        cuda_required_arch: 50,
        cuda_native_arch: 50,
        cuda_emulation: None,
    },
];

/// A target a kernel runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    Cpu,
    /// A GPU of this architecture (`major * 10 + minor`: 90 for an H100).
    Cuda {
        arch: u32,
    },
}

/// How a target runs a capability.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Support {
    /// With an instruction (or, on the CPU, warp-core's implementation).
    Native,
    /// Emulated, as the string says.
    Emulated(&'static str),
    /// Not at all.
    Missing,
}

impl Capability {
    /// This capability's row.
    pub fn row(self) -> &'static CapabilityRow {
        CAPABILITIES
            .iter()
            .find(|r| r.capability == self)
            .expect("every capability has a row")
    }
}

impl CapabilityRow {
    /// How `target` runs this capability.
    pub fn on(&self, target: Target) -> Support {
        match target {
            Target::Cpu if self.cpu => Support::Native,
            Target::Cpu => Support::Missing,
            Target::Cuda { arch } if arch < self.cuda_required_arch => Support::Missing,
            Target::Cuda { arch } if arch < self.cuda_native_arch => match self.cuda_emulation {
                Some(how) => Support::Emulated(how),
                None => Support::Missing,
            },
            Target::Cuda { .. } => Support::Native,
        }
    }
}

/// The first of `requires` that `target` cannot run, if any.
pub fn first_missing(requires: &[Capability], target: Target) -> Option<&'static CapabilityRow> {
    requires
        .iter()
        .map(|c| c.row())
        .find(|r| r.on(target) == Support::Missing)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_capability_has_one_row_and_consistent_archs() {
        for r in CAPABILITIES {
            let n = CAPABILITIES
                .iter()
                .filter(|o| o.capability == r.capability)
                .count();
            assert_eq!(n, 1, "{:?}", r.capability);
            assert!(r.cuda_required_arch <= r.cuda_native_arch, "{r:?}");
            // An emulation exists exactly where the required and native architectures differ.
            assert_eq!(
                r.cuda_emulation.is_some(),
                r.cuda_required_arch < r.cuda_native_arch,
                "{r:?}"
            );
        }
    }

    #[test]
    fn support_per_target() {
        let f16 = Capability::AtomicF16.row();
        assert_eq!(f16.on(Target::Cpu), Support::Native);
        assert_eq!(f16.on(Target::Cuda { arch: 90 }), Support::Native);
        assert_eq!(f16.on(Target::Cuda { arch: 70 }), Support::Native);
        assert!(matches!(
            f16.on(Target::Cuda { arch: 61 }),
            Support::Emulated(_)
        ));
        let bits = Capability::AtomicMinMaxBits64.row();
        assert_eq!(bits.on(Target::Cuda { arch: 37 }), Support::Missing);
        assert_eq!(bits.on(Target::Cuda { arch: 50 }), Support::Native);
        let needs = [Capability::AtomicAddF64, Capability::AtomicMinMaxBits64];
        assert_eq!(first_missing(&needs, Target::Cpu).map(|r| r.what), None);
        assert_eq!(
            first_missing(&needs, Target::Cuda { arch: 35 }).map(|r| r.capability),
            Some(Capability::AtomicMinMaxBits64)
        );
        assert!(first_missing(&needs, Target::Cuda { arch: 52 }).is_none());
    }
}
