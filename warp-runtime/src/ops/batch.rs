//! Batched calls (JAX's `vmap` with `vmap_method="expand_dims"`): every array operand arrives
//! with `b` leading batch axes in front of the op's own, an unbatched one with extent 1 there
//! (never tiled). [`Vmap::Loop`] runs the op once per batch index on views (a size-1 axis
//! always read at index 0: no copy); [`Vmap::Fold`] folds one batch axis into the first
//! array axis and launches once, when that is the same computation.

use super::args::CallArg;
use super::buffer::Buffer;
use super::exec::Exec;
use super::spec::{ArgKind, OpSpec};
use super::Op;
use crate::error::{Error, Result};

/// How an op runs a batched call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Vmap {
    /// Once per batch index, on views (always correct).
    #[default]
    Loop,
    /// One launch with the batch axis folded into every array's first axis and the first
    /// launch dimension (NVIDIA Warp's behaviour), when the call has one batch axis, every
    /// array operand is batched (no extent-1 batch axis) and contiguous across the fold, and
    /// the shape rules accept the folded shapes; else as `Loop`. Correct only for kernels
    /// whose thread `i` touches row `i` of every array and nothing else (no reduction into a
    /// shared element, no neighbour reads across rows): the caller's promise.
    Fold,
}

/// The batch rank and shape of a call, after checking every array operand's leading axes.
fn batch_of(
    spec: &OpSpec,
    args: &[CallArg<'_>],
    grads: &[Option<&Buffer>],
) -> Result<(usize, Vec<usize>)> {
    let mut b: Option<(usize, &str)> = None;
    let operands = spec
        .params
        .iter()
        .zip(args)
        .enumerate()
        .flat_map(|(k, (p, a))| {
            let g = grads.get(k).copied().flatten().map(|g| (p, g));
            let a = match a {
                CallArg::Buffer(buf) => Some((p, *buf)),
                _ => None,
            };
            a.into_iter().chain(g)
        });
    let operands: Vec<_> = operands.collect();
    for (p, buf) in &operands {
        let ArgKind::Array { rank, element, .. } = p.kind else {
            continue;
        };
        let own = rank + element.len();
        let extra = buf.dims.len().checked_sub(own).ok_or_else(|| {
            Error::invalid(format!(
                "{}: argument '{}': shape {:?} has fewer axes than {}",
                spec.name,
                p.name,
                buf.dims,
                p.kind.describe()
            ))
        })?;
        match b {
            None => b = Some((extra, p.name)),
            Some((e, first)) if e != extra => {
                return Err(Error::invalid(format!(
                    "{}: batched call: '{first}' has {e} leading batch axes and '{}' has {extra}",
                    spec.name, p.name
                )))
            }
            _ => {}
        }
    }
    let b = b.map_or(0, |(e, _)| e);
    let mut shape = vec![1usize; b];
    for (_, buf) in &operands {
        for (s, &e) in shape.iter_mut().zip(&buf.dims) {
            *s = (*s).max(e);
        }
    }
    for (p, buf) in &operands {
        if let Some(d) = (0..b).find(|&d| buf.dims[d] != 1 && buf.dims[d] != shape[d]) {
            return Err(Error::invalid(format!(
                "{}: batched call: '{}' has extent {} on batch axis {d}; the batch has {} (or \
                 1, unbatched)",
                spec.name, p.name, buf.dims[d], shape[d]
            )));
        }
    }
    Ok((b, shape))
}

/// `buf` at batch index `idx` (its first `idx.len()` axes dropped; extent-1 axes read at 0).
fn slice(buf: &Buffer, idx: &[usize]) -> Buffer {
    let strides = buf.byte_strides_or_row_major();
    let mut ptr = buf.ptr as i64;
    for (d, &i) in idx.iter().enumerate() {
        if buf.dims[d] != 1 {
            ptr += i as i64 * strides[d] as i64;
        }
    }
    Buffer {
        ptr: ptr as u64,
        dims: buf.dims[idx.len()..].to_vec(),
        byte_strides: Some(strides[idx.len()..].to_vec()),
        dtype: buf.dtype,
    }
}

/// `buf` with its batch axis folded into its first own axis, if the memory allows.
fn fold(buf: &Buffer) -> Option<Buffer> {
    let s = buf.byte_strides_or_row_major();
    if buf.dims.len() < 2 || s[0] != s[1] * buf.dims[1] as isize {
        return None;
    }
    let mut dims = vec![buf.dims[0] * buf.dims[1]];
    dims.extend(&buf.dims[2..]);
    let mut strides = vec![s[1]];
    strides.extend(&s[2..]);
    Some(Buffer {
        ptr: buf.ptr,
        dims,
        byte_strides: Some(strides),
        dtype: buf.dtype,
    })
}

impl Op {
    /// [`forward`](Self::forward) of a call whose array operands may carry leading batch axes
    /// (see the module's text), run as the op's [`Vmap`] says ([`KernelOp::vmap`]).
    ///
    /// [`KernelOp::vmap`]: super::KernelOp::vmap
    ///
    /// # Safety
    /// As [`forward`](Self::forward).
    ///
    /// # Errors
    /// As [`forward`](Self::forward); operands whose batch ranks differ, or whose batch
    /// extents are neither 1 nor the batch's.
    pub unsafe fn forward_batched(&self, args: &[CallArg<'_>], exec: &Exec<'_>) -> Result<()> {
        // SAFETY: forwarded contract.
        unsafe { self.batched(args, None, exec) }
    }

    /// [`backward`](Self::backward) of a batched call: every gradient buffer carries the batch
    /// axes too (an unbatched input's gradient per batch element: the framework sums them).
    ///
    /// # Safety
    /// As [`backward`](Self::backward).
    ///
    /// # Errors
    /// As [`forward_batched`](Self::forward_batched).
    pub unsafe fn backward_batched(
        &self,
        args: &[CallArg<'_>],
        grads: &[Option<&Buffer>],
        exec: &Exec<'_>,
    ) -> Result<()> {
        // SAFETY: forwarded contract.
        unsafe { self.batched(args, Some(grads), exec) }
    }

    unsafe fn batched(
        &self,
        args: &[CallArg<'_>],
        grads: Option<&[Option<&Buffer>]>,
        exec: &Exec<'_>,
    ) -> Result<()> {
        let spec = self.spec();
        let no_grads = vec![None; args.len()];
        let g = grads.unwrap_or(&no_grads);
        if g.len() != args.len() {
            // The per-call check words it.
            // SAFETY: refused before any buffer is used.
            return unsafe { self.backward(args, g, exec) };
        }
        let (b, shape) = batch_of(spec, args, g)?;
        // SAFETY (of every call below): forwarded contract; the views stay inside the buffers.
        let call = |a: &[CallArg<'_>], gr: &[Option<&Buffer>]| match grads {
            None => unsafe { self.forward(a, exec) },
            Some(_) => unsafe { self.backward(a, gr, exec) },
        };
        if b == 0 {
            return call(args, g);
        }
        let every_batched = args
            .iter()
            .filter_map(|a| match a {
                CallArg::Buffer(x) => Some(*x),
                _ => None,
            })
            .chain(g.iter().flatten().copied())
            .all(|x| x.dims[0] == shape[0]);
        if self.vmap() == Vmap::Fold && b == 1 && every_batched {
            let folded_args: Vec<Option<Buffer>> = args
                .iter()
                .map(|a| match a {
                    CallArg::Buffer(x) => fold(x),
                    _ => None,
                })
                .collect();
            let folded_grads: Vec<Option<Buffer>> = g.iter().map(|x| x.and_then(fold)).collect();
            let all_fold = args
                .iter()
                .zip(&folded_args)
                .all(|(a, f)| !matches!(a, CallArg::Buffer(_)) || f.is_some())
                && g.iter()
                    .zip(&folded_grads)
                    .all(|(x, f)| x.is_none() || f.is_some());
            if all_fold {
                let fa: Vec<CallArg<'_>> = args
                    .iter()
                    .zip(&folded_args)
                    .map(|(a, f)| match f {
                        Some(f) => CallArg::Buffer(f),
                        None => *a,
                    })
                    .collect();
                let fg: Vec<Option<&Buffer>> = folded_grads.iter().map(|f| f.as_ref()).collect();
                // The rules must accept the folded shapes (a Fixed output does not).
                if self.shapes(&fa).is_ok() {
                    return call(&fa, &fg);
                }
            }
        }
        let total: usize = shape.iter().product();
        let mut idx = vec![0usize; b];
        for n in 0..total {
            let mut rest = n;
            for d in (0..b).rev() {
                idx[d] = rest % shape[d];
                rest /= shape[d];
            }
            let sa: Vec<Option<Buffer>> = args
                .iter()
                .map(|a| match a {
                    CallArg::Buffer(x) => Some(slice(x, &idx)),
                    _ => None,
                })
                .collect();
            let sg: Vec<Option<Buffer>> = g.iter().map(|x| x.map(|x| slice(x, &idx))).collect();
            let ca: Vec<CallArg<'_>> = args
                .iter()
                .zip(&sa)
                .map(|(a, s)| match s {
                    Some(s) => CallArg::Buffer(s),
                    None => *a,
                })
                .collect();
            let cg: Vec<Option<&Buffer>> = sg.iter().map(|s| s.as_ref()).collect();
            call(&ca, &cg)?;
        }
        Ok(())
    }
}
