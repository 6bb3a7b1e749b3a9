//! The parts of a tiled kernel's `Kernel` impl: its `TileInfo` (the block's shared memory and
//! CPU frame, the width its `tile(x)` fixes) and its CPU entry, which runs whole blocks.

use crate::back::rust::ty_tokens;
use crate::back::rust_tile::BlockPrinter;
use crate::ir::Function;
use crate::middle::lanes::Storage;
use proc_macro2::TokenStream;
use quote::quote;

/// Bytes assumed per lane for a per-lane value whose type only rustc knows (a func's result):
/// the frame estimate must not fall short, and kernel values are at most a 4x4 f64 matrix.
const DEFERRED_LANE_BYTES: usize = 128;

/// A tiled kernel's block printer (its lane plan), made once for the parts below; why there is
/// none when the plan refuses the kernel.
pub(super) type Block<'a> = Result<BlockPrinter<'a>, String>;

/// `KernelInfo::tile`: `None` for an ordinary kernel (`block` is `None` then).
pub(super) fn info(f: &Function, block: Option<&Block>) -> TokenStream {
    let (Some(tiled), Some(block)) = (&f.tiled, block) else {
        return quote!(::core::option::Option::None);
    };
    let width = match &tiled.width {
        Some(d) => {
            let d = d.rust_tokens();
            quote!(::core::option::Option::Some(#d))
        }
        None => quote!(::core::option::Option::None),
    };
    // One 16-byte aligned slot per tile variable, in variable order: the rule of the CUDA
    // emitter's slots (`wp::tile_slot_end`), so this is the dynamic shared memory it uses.
    let tiles: Vec<TokenStream> = f
        .tile_vars()
        .into_iter()
        .map(|v| ty_tokens(f.ty(v)).expect("a tile type"))
        .collect();
    // The adjoint's slots: the forward's, then an adjoint tile for each tile that has one
    // (`middle::adjoint::adjoint_tiles`, the CUDA adjoint's order).
    let adj_tiles: Vec<TokenStream> = crate::middle::adjoint::adjoint_tiles(f)
        .into_iter()
        .map(|v| ty_tokens(f.ty(v)).expect("a tile type"))
        .collect();
    // The extra stages the forward kernel's pipelined GEMM k-loops may use (the CUDA emitter
    // prints exactly these loops pipelined).
    let pipes: Vec<TokenStream> = crate::back::cuda_tile_pipe::gemm_loop_tiles(f)
        .into_iter()
        .map(|(acc, a, b)| {
            let [acc, a, b] = [acc, a, b].map(|v| ty_tokens(f.ty(v)).expect("a tile type"));
            quote!(__wp::TileInfo::pipe_extra_for(
                ::core::mem::size_of::<#acc>(),
                ::core::mem::size_of::<#a>(),
                ::core::mem::size_of::<#b>(),
            ))
        })
        .collect();
    let per_lane: Vec<TokenStream> = match block {
        Ok(p) => (0..f.vars.len())
            .filter(|v| p.plan.storage[*v] == Storage::PerLane)
            .map(|v| match ty_tokens(&f.vars[v].ty) {
                Some(t) => quote!(::core::mem::size_of::<__wp::block::PerLane<#t>>()),
                None => quote!(#DEFERRED_LANE_BYTES * __wp::block::MAX_BLOCK_DIM),
            })
            .collect(),
        Err(_) => Vec::new(),
    };
    quote! {
        ::core::option::Option::Some(__wp::TileInfo {
            width: #width,
            shared_bytes: {
                let mut __o = 0usize;
                #( __o = (__o + ::core::mem::size_of::<#tiles>()).div_ceil(16) * 16; )*
                __o
            },
            adjoint_shared_bytes: {
                let mut __o = 0usize;
                #( __o = (__o + ::core::mem::size_of::<#tiles>()).div_ceil(16) * 16; )*
                #( __o = (__o + ::core::mem::size_of::<#adj_tiles>()).div_ceil(16) * 16; )*
                __o
            },
            cpu_frame_bytes: 0usize #( + ::core::mem::size_of::<#tiles>() )* #( + #per_lane )*,
            pipe_extra_bytes: {
                let mut __x = 0usize;
                #( let __p = #pipes; if __p > __x { __x = __p; } )*
                __x
            },
        })
    }
}

/// The tile shape rules only rustc can decide, each a `const` assertion spanned at its call:
/// `cargo check` evaluates it, so a mismatch of named consts is an error there with the
/// macro's message.
pub(super) fn shape_checks(f: &Function) -> TokenStream {
    f.shape_obligations
        .iter()
        .map(|o| {
            let (l, r) = (o.lhs.rust_tokens(), o.rhs.rust_tokens());
            // `assert!`'s message is a format string.
            let msg = o.msg.replace('{', "{{").replace('}', "}}");
            if o.pow2 {
                quote::quote_spanned! {o.span=>
                    const _: () = ::core::assert!((#l).is_power_of_two(), #msg);
                }
            } else if o.or_one {
                quote::quote_spanned! {o.span=>
                    const _: () = ::core::assert!(#l == #r || #l == 1, #msg);
                }
            } else {
                quote::quote_spanned! {o.span=>
                    const _: () = ::core::assert!(#l == #r, #msg);
                }
            }
        })
        .collect()
}

/// `Kernel::run_cpu` of a tiled kernel: `__range` is a range of blocks, each run whole by
/// `__block` (the lane plan's body).
pub(super) fn run_cpu(
    f: &Function,
    block: &Block,
    pvars: &[TokenStream],
    pnames: &[syn::Ident],
    tys: &[&syn::Type],
    tid_setup: Option<&TokenStream>,
) -> TokenStream {
    let body = match block {
        Ok(p) => p.body(),
        Err(why) => {
            let msg = format!("`{}`: {why}", f.name);
            quote!(::core::compile_error!(#msg);)
        }
    };
    quote! {
        fn run_cpu(
            __params: &__wp::CpuParamsOf<Self>,
            __grid: &__wp::Grid,
            __range: ::core::ops::Range<usize>,
        ) -> __wp::KResult<()> {
            // One block: its tile operations once, its lane code in loops over the lanes
            // (`middle::lanes`). Parameters by value, as `run_cpu`'s thread function.
            #[inline(always)]
            #[allow(unused_variables, unused_mut, unused_assignments, unused_parens, unused_labels, non_snake_case, unreachable_code, clippy::all)]
            fn __block(
                #( #pvars: <#tys as __wp::KernelArg>::CpuView, )*
                __grid: &__wp::Grid,
                __flat: usize,
            ) -> __wp::KResult<()> {
                #tid_setup
                #body
                ::core::result::Result::Ok(())
            }
            let ( #(#pnames,)* ) = *__params;
            let __grid = *__grid;
            for __flat in __range {
                __block( #(#pnames,)* &__grid, __flat)?;
            }
            ::core::result::Result::Ok(())
        }
    }
}
