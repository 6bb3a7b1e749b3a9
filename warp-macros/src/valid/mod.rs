//! The validator: checks a lowered function as a whole, between the front end and the back
//! ends (naga's `valid/`).
//!
//! The front end checks what one expression or statement can decide (types, the language
//! subset) as it lowers. What needs the whole function is here, run on the IR the front end
//! produced and before anything is printed:
//!
//! - `wellformed`: every variable read is defined before, in an enclosing block (a view used
//!   as a value is the one way user code gets this wrong: a view is a name that lowering
//!   rewrites away, never defined); `break` and `continue` are inside a loop.
//! - `options`: the macro's options against the lowered signature (`same_shape` names array
//!   parameters, `grad(x = ..)` names value parameters).
//! - `uniformity`: which values are the same in every thread and which statements run under
//!   thread-dependent control flow; a block-cooperative builtin call (a row with the
//!   `cooperative` fact: the tile operations) under such control flow is an error, and so is
//!   a tile operation's scalar argument (an offset) that differs between the block's threads.
//! - `capabilities`: what the code needs of its target beyond the core language (an f64
//!   atomic add, a 64-bit integer atomic minimum, ...), by the names of warp-core's capability
//!   table, for the `requires` field of `KernelInfo` and `FuncInfo`, which the runtime checks
//!   against a GPU's architecture when it loads the kernel.
//!
//! - `deterministic`: what a `#[kernel(deterministic)]` kernel may not do (use an
//!   accumulation's old value, exchange floats), and its per-thread record limit.
//!
//! Errors are gathered with the user's spans, all at once, like the front end's; the expansion
//! turns them into compile errors.

mod capabilities;
pub mod deterministic;
mod options;
mod uniformity;
mod wellformed;

#[cfg(test)]
mod tests;

use crate::ir::Function;

pub use capabilities::{required_capabilities, Capability};
pub use uniformity::Uniformity;

/// What a function is validated against besides its body: its macro's options.
pub enum Options<'a> {
    /// `#[kernel(same_shape(a, b, dim))]` groups, as written.
    Kernel { same_shape: &'a [Vec<syn::Ident>] },
    /// `#[func(grad(x = dfdx))]`: the parameters given custom gradients, and their funcs.
    Func { grad: &'a [(syn::Ident, syn::Path)] },
}

/// What validation established about a valid function, for the back ends.
#[derive(Debug)]
pub struct Valid {
    /// A kernel's `same_shape` groups as parameter indices (`usize::MAX` stands for the launch
    /// dimensions); empty for a func.
    pub same_shape: Vec<Vec<usize>>,
    /// The capabilities its code needs of its target, forward and adjoint.
    pub requires: Vec<Capability>,
}

/// Validates a lowered function; all errors found are returned together.
pub fn validate(f: &Function, options: Options) -> Result<Valid, Vec<syn::Error>> {
    let mut errors = Vec::new();
    wellformed::check(f, &mut errors);
    let same_shape = options::check(f, &options, &mut errors);
    uniformity::check_cooperative(f, &mut errors);
    if errors.is_empty() {
        Ok(Valid {
            same_shape,
            requires: required_capabilities(f),
        })
    } else {
        Err(errors)
    }
}
