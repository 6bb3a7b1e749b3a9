//! [`KernelParams`] for tuples of [`KernelArg`]s: a kernel's parameter list is the tuple of its
//! parameter types, and each conversion of launch arguments is written here once, element by
//! element, instead of once per kernel in generated code.
//!
//! Every method is a fixed sequence of per-element calls that inlines into the launch: no
//! allocation and no dynamic dispatch (the launch path costs what hand-written code would).

use crate::device::Device;
use crate::error::Result;
use crate::kernel::{ArgCtx, KernelArg, KernelInfo, KernelParams, MAX_PARAMS};
use std::ffi::c_void;
use warp_core::Grid;

/// The context of parameter `index` of the kernel `info` for a launch on `device`.
#[inline(always)]
fn ctx<'d>(info: &KernelInfo, index: usize, device: &'d Device) -> ArgCtx<'d> {
    ArgCtx {
        kernel: info.name,
        arg: info.params[index],
        index,
        device,
    }
}

/// `KernelParams` for the tuple of the type parameters `$T` (element `$k` of type `$T`).
macro_rules! tuple_params {
    ($($T:ident $k:tt),*) => {
        // The empty tuple (a kernel without parameters) leaves some arguments unused.
        #[allow(unused_variables, unused_mut, clippy::unused_unit)]
        impl<$($T: KernelArg),*> KernelParams for ($($T,)*) {
            const COUNT: usize = {
                let names: &[&str] = &[$(stringify!($T)),*];
                names.len()
            };
            type Args<'a> = ($($T::Arg<'a>,)*);
            type CpuParams = ($($T::CpuView,)*);
            type CpuGrads = ($($T::GradView,)*);
            type CudaParams = ($($T::CudaArg,)*);
            type CudaGrads = ($($T::CudaGrad,)*);
            type Owned = ($($T::Owned,)*);

            #[inline(always)]
            unsafe fn cpu_params(
                args: &Self::Args<'_>,
                info: &KernelInfo,
                device: &Device,
            ) -> Result<Self::CpuParams> {
                // SAFETY: forwarded contract: the views do not outlive `args`.
                Ok(($(unsafe { $T::cpu_view(&args.$k, &ctx(info, $k, device))? },)*))
            }

            #[inline(always)]
            unsafe fn cpu_grads(
                args: &Self::Args<'_>,
                info: &KernelInfo,
                device: &Device,
            ) -> Result<Self::CpuGrads> {
                // SAFETY: forwarded contract: the views do not outlive `args`.
                Ok(($(unsafe { $T::grad_view(&args.$k, &ctx(info, $k, device))? },)*))
            }

            #[inline(always)]
            fn cuda_params(
                args: &Self::Args<'_>,
                info: &KernelInfo,
                device: &Device,
            ) -> Result<Self::CudaParams> {
                Ok(($($T::cuda_arg(&args.$k, &ctx(info, $k, device))?,)*))
            }

            #[inline(always)]
            fn cuda_grads(
                args: &Self::Args<'_>,
                info: &KernelInfo,
                device: &Device,
            ) -> Result<Self::CudaGrads> {
                Ok(($($T::cuda_grad(&args.$k, &ctx(info, $k, device))?,)*))
            }

            #[inline(always)]
            fn cuda_param_ptrs(params: &mut Self::CudaParams, out: &mut [*mut c_void]) -> usize {
                $(out[$k] = (&mut params.$k) as *mut $T::CudaArg as *mut c_void;)*
                Self::COUNT
            }

            #[inline(always)]
            fn cuda_grad_ptrs(grads: &mut Self::CudaGrads, out: &mut [*mut c_void]) -> usize {
                let mut n = 0;
                $(
                    // A constant per element: the branch folds away.
                    if $T::HAS_CUDA_GRAD {
                        out[n] = (&mut grads.$k) as *mut $T::CudaGrad as *mut c_void;
                        n += 1;
                    }
                )*
                n
            }

            fn own(args: &Self::Args<'_>) -> Self::Owned {
                ($($T::own(&args.$k),)*)
            }

            fn borrow(owned: &Self::Owned) -> Self::Args<'_> {
                ($($T::borrow(&owned.$k),)*)
            }

            fn shapes(args: &Self::Args<'_>) -> Vec<Option<Vec<usize>>> {
                vec![$($T::shape(&args.$k)),*]
            }

            #[inline(always)]
            fn cover(args: &Self::Args<'_>, which: &[usize], grid: &Grid) -> bool {
                true $(&& (!which.contains(&$k) || $T::covers(&args.$k, &grid.dims)))*
            }

            fn grads_alias(args: &Self::Args<'_>, which: &[usize]) -> bool {
                let keys: &[Option<crate::kernel::GradKey>] = &[$($T::grad_key(&args.$k)),*];
                crate::kernel::grads_alias(keys, which)
            }

            #[inline(always)]
            fn contiguous(args: &Self::Args<'_>) -> bool {
                true $(&& $T::contiguous(&args.$k))*
            }

            fn check_finite(args: &Self::Args<'_>, info: &KernelInfo) -> Result<()> {
                $(
                    if info.written.contains(&$k) {
                        $T::check_finite(&args.$k, info.name, info.params[$k])?;
                    }
                )*
                Ok(())
            }

            fn zero_grads(args: &Self::Args<'_>) -> Result<()> {
                $($T::zero_grad(&args.$k)?;)*
                Ok(())
            }
        }
    };
}

/// `tuple_params!` for every prefix of the list: `()`, `(A0,)`, `(A0, A1)`, .. up to the whole
/// list, whose length must be [`MAX_PARAMS`].
macro_rules! tuple_params_upto {
    ($($T:ident $k:tt),*) => {
        tuple_params_upto!(@ [] $($T $k),*);
    };
    (@ [$($D:ident $dk:tt)*]) => {
        tuple_params!($($D $dk),*);
        const _: () = assert!(
            <($(tuple_params_upto!(@u8 $D),)*) as KernelParams>::COUNT == MAX_PARAMS,
            "the longest tuple implementing KernelParams must have MAX_PARAMS elements"
        );
    };
    // Some element type, to name the longest tuple.
    (@u8 $x:ident) => { u8 };
    (@ [$($D:ident $dk:tt)*] $T:ident $k:tt $(, $R:ident $rk:tt)*) => {
        tuple_params!($($D $dk),*);
        tuple_params_upto!(@ [$($D $dk)* $T $k] $($R $rk),*);
    };
}

tuple_params_upto!(
    A0 0, A1 1, A2 2, A3 3, A4 4, A5 5, A6 6, A7 7, A8 8, A9 9, A10 10, A11 11, A12 12, A13 13,
    A14 14, A15 15, A16 16, A17 17, A18 18, A19 19, A20 20, A21 21, A22 22, A23 23, A24 24,
    A25 25, A26 26, A27 27, A28 28, A29 29, A30 30, A31 31
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::array::Array;
    use crate::device::cpu;
    use crate::error::Error;

    /// `k(a: Array<f32>, s: f32, b: Array<f32, 2>)`, writing `b`, indexing `a` by `tid()`.
    const INFO: KernelInfo = KernelInfo {
        name: "k",
        module: "m",
        params: &["a", "s", "b"],
        written: &[2],
        tid_indexed: &[0],
        tid_ndim: Some(1),
        ..KernelInfo::BLANK
    };
    type P = (Array<f32>, f32, Array<f32, 2>);

    #[test]
    fn conversions_follow_the_elements() {
        let dev = cpu();
        let a = Array::<f32>::zeros(4, &dev).unwrap();
        let b = Array::<f32, 2>::zeros((2, 3), &dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let args = (&a, 2.5f32, &b);
        assert_eq!(<P as KernelParams>::COUNT, 3);
        assert_eq!(<() as KernelParams>::COUNT, 0);

        // Every parameter is a launch parameter; only arrays pass a gradient.
        let mut out = [std::ptr::null_mut::<c_void>(); 8];
        let mut params = P::cuda_params(&args, &INFO, &dev).unwrap();
        assert_eq!(P::cuda_param_ptrs(&mut params, &mut out), 3);
        assert_eq!(out[1], (&mut params.1) as *mut f32 as *mut c_void);
        assert_eq!(params.2.shape, [2, 3]);
        assert_eq!(params.2.arg, 2);
        let mut grads = P::cuda_grads(&args, &INFO, &dev).unwrap();
        assert_eq!(P::cuda_grad_ptrs(&mut grads, &mut out), 2);
        assert_eq!(out[1], (&mut grads.2) as *mut _ as *mut c_void);
        assert_eq!(grads.0.data, 0, "`a` has no gradient");
        assert_ne!(grads.2.data, 0);

        // `cover` asks only the arrays it is given.
        let grid = |n| Grid {
            dims: [n, 1, 1, 1],
            ndim: 1,
            total: n,
            block_dim: 1,
        };
        assert!(P::cover(&args, INFO.tid_indexed, &grid(4)));
        assert!(!P::cover(&args, INFO.tid_indexed, &grid(5)));
        assert!(P::cover(&args, &[], &grid(5)));
        assert!(P::contiguous(&args));
        assert!(!P::contiguous(&(&a, 2.5, &b.transpose())));
        assert_eq!(
            P::shapes(&args),
            vec![Some(vec![4]), None, Some(vec![2, 3])]
        );

        // `check_finite` reads the written arrays only.
        a.fill(f32::NAN).unwrap();
        P::check_finite(&args, &INFO).unwrap();
        b.fill(f32::INFINITY).unwrap();
        assert!(matches!(
            P::check_finite(&args, &INFO),
            Err(Error::NonFinite { arg: "b", .. })
        ));

        // What a tape keeps gives the same arguments back.
        let owned = P::own(&args);
        let back = P::borrow(&owned);
        assert!(back.0.shares_storage_with(&a) && back.2.shares_storage_with(&b));
        assert_eq!(back.1, 2.5);
        b.grad().unwrap().fill(1.0).unwrap();
        P::zero_grads(&back).unwrap();
        assert_eq!(b.grad().unwrap().to_vec().unwrap(), vec![0.0; 6]);
    }

    #[test]
    fn arguments_on_another_device_name_the_parameter() {
        let a = Array::<f32>::zeros(4, &cpu()).unwrap();
        let b = Array::<f32, 2>::zeros((2, 3), &cpu()).unwrap();
        let gpu = crate::device::Device::fake_cuda(0);
        let err = P::cuda_params(&(&a, 1.0, &b), &INFO, &gpu).unwrap_err();
        assert!(
            matches!(
                err,
                Error::DeviceMismatch {
                    kernel: "k",
                    arg: "a",
                    ..
                }
            ),
            "{err}"
        );
    }
}
