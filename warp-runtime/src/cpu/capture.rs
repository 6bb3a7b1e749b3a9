//! Graph capture on the CPU: what recording means here (`backend.rs`). While the calling
//! thread captures, each operation it enqueues is kept as an [`Op`] instead of run; a replay
//! runs them in order. A conditional's bodies are recorded into frames of their own and
//! replayed by one operation that reads the flag.

use crate::backend::{Conditional, Op};
use crate::error::{Error, Result};
use std::cell::RefCell;

thread_local! {
    /// The calling thread's recording: the graph's operations, then one list per open
    /// conditional body (innermost last). Empty when the thread is not capturing on the CPU.
    static FRAMES: RefCell<Vec<Vec<Op>>> = const { RefCell::new(Vec::new()) };
}

/// What a CPU graph replays.
pub(crate) struct CpuGraph {
    ops: Vec<Op>,
}

impl CpuGraph {
    /// The recorded operations.
    pub(crate) fn node_count(&self) -> usize {
        self.ops.len()
    }

    /// Runs the recorded operations in order; the first error stops the replay.
    pub(crate) fn replay(&self) -> Result<()> {
        run_ops(&self.ops)
    }
}

/// Starts recording the calling thread's CPU work.
pub(crate) fn begin() {
    FRAMES.with(|f| *f.borrow_mut() = vec![Vec::new()]);
}

/// Ends the recording and returns its graph.
pub(crate) fn end() -> Result<CpuGraph> {
    let mut frames = FRAMES.with(|f| std::mem::take(&mut *f.borrow_mut()));
    match frames.len() {
        1 => Ok(CpuGraph {
            ops: frames.swap_remove(0),
        }),
        0 => Err(Error::Capture {
            what: "the capture was already ended".into(),
        }),
        _ => Err(Error::Capture {
            what: "a conditional body is still open at the end of the capture".into(),
        }),
    }
}

/// Ends the recording and drops it.
pub(crate) fn abort() {
    FRAMES.with(|f| f.borrow_mut().clear());
}

/// Records `op` into the innermost open frame; false when the thread is not recording.
pub(crate) fn record(op: Op) -> bool {
    FRAMES.with(|f| match f.borrow_mut().last_mut() {
        Some(frame) => {
            frame.push(op);
            true
        }
        None => false,
    })
}

/// Runs `body` with a new frame open, and returns what it recorded there.
fn record_frame(body: &mut dyn FnMut() -> Result<()>) -> Result<Vec<Op>> {
    FRAMES.with(|f| f.borrow_mut().push(Vec::new()));
    let ran = body();
    let ops = FRAMES.with(|f| f.borrow_mut().pop().expect("the frame pushed above"));
    ran.map(|()| ops)
}

/// A conditional on the `i32` at host address `cond`: its bodies recorded into frames of
/// their own, replayed by one operation that reads the flag (before each iteration, for a
/// loop).
pub(crate) fn conditional(
    kind: Conditional,
    cond: u64,
    then: &mut dyn FnMut() -> Result<()>,
    otherwise: Option<&mut dyn FnMut() -> Result<()>>,
) -> Result<()> {
    let then_ops = record_frame(then)?;
    let else_ops = match otherwise {
        Some(body) => record_frame(body)?,
        None => Vec::new(),
    };
    let flag = Flag(cond as usize as *const i32);
    let op: Op = match kind {
        Conditional::While => Box::new(move || {
            while flag.read() != 0 {
                run_ops(&then_ops)?;
            }
            Ok(())
        }),
        Conditional::If => Box::new(move || {
            if flag.read() != 0 {
                run_ops(&then_ops)
            } else {
                run_ops(&else_ops)
            }
        }),
    };
    record(op);
    Ok(())
}

/// A condition flag in host memory, read between the operations of a replay.
#[derive(Clone, Copy)]
struct Flag(*const i32);

// SAFETY: the flag is an element of an array that the graph keeps alive (`Backend::
// capture_conditional`'s contract); it is read on the replaying thread between operations,
// when no kernel runs (CPU operations have finished when they return).
unsafe impl Send for Flag {}

impl Flag {
    fn read(self) -> i32 {
        // SAFETY: see the `Send` impl: live, aligned (an `i32` array's element), not written
        // while the replay reads it.
        unsafe { self.0.read() }
    }
}

fn run_ops(ops: &[Op]) -> Result<()> {
    for op in ops {
        op()?;
    }
    Ok(())
}
