//! What unit tests of the passes after the front end share: lowering a kernel written in the
//! test, so that a test of the middle or the back end needs no import of the front end (whose
//! lowering is the one way to make the IR they take).

use crate::ir::{FnKind, Function};

/// The lowered kernel `item` (a test's kernel is valid: a lowering error fails the test).
pub fn kernel(item: syn::ItemFn) -> Function {
    match crate::front::lower::lower_fn(&item, FnKind::Kernel) {
        Ok(f) => f,
        Err(errors) => panic!(
            "the test's kernel does not lower: {:?}",
            errors.iter().map(|e| e.to_string()).collect::<Vec<_>>()
        ),
    }
}
