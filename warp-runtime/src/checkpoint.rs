//! Memory-bounded reverse mode for long rollouts: [`Checkpointed`].
//!
//! A [`Tape`] over `T` steps of a simulation keeps every intermediate state with its gradient
//! (`T + 1` states). A checkpointed rollout keeps the initial state (the caller's), two working
//! states with gradients and a budget of value-only snapshots. Its forward pass runs the steps
//! without recording and stores snapshots where the schedule says; its backward pass reverses
//! the steps one at a time, from `T - 1` down to `0`: it restores state `t` from the nearest
//! snapshot (recomputing forward steps), records that one step on a fresh tape and runs the
//! tape's adjoints. Every step's adjoint runs exactly once, in the same order and on the same
//! inputs as under a full tape, so the gradients are the same (bit for bit on the CPU).
//!
//! The schedule is recursive checkpointing (Griewank's binomial checkpointing, "Revolve"):
//! to reverse steps `a..b` with `c` free snapshots, advance from state `a` to a split `m`,
//! store state `m`, reverse `m..b` with `c - 1` snapshots, release it and reverse `a..m` with
//! `c`. The split minimises the recomputed forward steps: a dynamic program over
//! `cost(n, c) = min_m [m + cost(n - m, c - 1) + cost(m, c)]`, `cost(1, c) = 0`,
//! `cost(n, 0) = n (n - 1) / 2`, for small rollouts, and beyond that the same minimum found from
//! the program's closed form (`r n - C(c + 1 + r, c + 2)` with `r` the least repetition number
//! such that `C(c + 1 + r, c + 1) >= n`; the unit tests check the two agree).

use crate::array::{Array, Element};
use crate::device::Device;
use crate::error::{Error, Result};
use crate::tape::{pause_recording, Seed, Tape};
use std::fmt;

/// A state that a [`Checkpointed`] rollout can snapshot and restore: an [`Array`], or a tuple
/// of up to six states (nested tuples too), such as `(positions, velocities)`.
pub trait CheckpointState: Sized {
    /// A new zeroed state of the same layout on the same device(s), with gradients when
    /// `grad`.
    fn alloc_like(&self, grad: bool) -> Result<Self>;
    /// Copies `src`'s values (not its gradients) into this state of the same layout.
    fn copy_values_from(&self, src: &Self) -> Result<()>;
    /// Sets the gradients to zero (parts without one are left alone).
    fn zero_grads(&self) -> Result<()>;
    /// The bytes of the values (not counting gradients).
    fn value_bytes(&self) -> usize;
    /// Whether every part has a gradient.
    fn has_grads(&self) -> bool;
    /// What differs between the layouts of `self` and `other` (shapes, devices), if anything.
    fn layout_mismatch(&self, other: &Self) -> Option<String>;
    /// Appends the devices of the parts, in order.
    fn devices(&self, out: &mut Vec<Device>);
}

impl<T: Element, const N: usize> CheckpointState for Array<T, N> {
    fn alloc_like(&self, grad: bool) -> Result<Self> {
        let a = Array::zeros(self.shape(), self.device())?;
        if grad {
            a.with_grad()
        } else {
            Ok(a)
        }
    }

    fn copy_values_from(&self, src: &Self) -> Result<()> {
        self.copy_from(src)
    }

    fn zero_grads(&self) -> Result<()> {
        self.zero_grad()
    }

    fn value_bytes(&self) -> usize {
        self.len() * std::mem::size_of::<T>()
    }

    fn has_grads(&self) -> bool {
        self.requires_grad()
    }

    fn layout_mismatch(&self, other: &Self) -> Option<String> {
        if self.shape() != other.shape() {
            return Some(format!(
                "shape {:?} against {:?}",
                self.shape(),
                other.shape()
            ));
        }
        if self.device() != other.device() {
            return Some(format!(
                "device \"{}\" against \"{}\"",
                self.device(),
                other.device()
            ));
        }
        None
    }

    fn devices(&self, out: &mut Vec<Device>) {
        out.push(self.device().clone());
    }
}

/// Implements [`CheckpointState`] for a tuple whose parts all implement it.
macro_rules! tuple_state {
    ($($name:ident $idx:tt),+) => {
        impl<$($name: CheckpointState),+> CheckpointState for ($($name,)+) {
            fn alloc_like(&self, grad: bool) -> Result<Self> {
                Ok(($(self.$idx.alloc_like(grad)?,)+))
            }

            fn copy_values_from(&self, src: &Self) -> Result<()> {
                $(self.$idx.copy_values_from(&src.$idx)?;)+
                Ok(())
            }

            fn zero_grads(&self) -> Result<()> {
                $(self.$idx.zero_grads()?;)+
                Ok(())
            }

            fn value_bytes(&self) -> usize {
                0 $(+ self.$idx.value_bytes())+
            }

            fn has_grads(&self) -> bool {
                true $(&& self.$idx.has_grads())+
            }

            fn layout_mismatch(&self, other: &Self) -> Option<String> {
                $(
                    if let Some(m) = self.$idx.layout_mismatch(&other.$idx) {
                        return Some(format!("part {}: {m}", $idx));
                    }
                )+
                None
            }

            fn devices(&self, out: &mut Vec<Device>) {
                $(self.$idx.devices(out);)+
            }
        }
    };
}

tuple_state!(A 0);
tuple_state!(A 0, B 1);
tuple_state!(A 0, B 1, C 2);
tuple_state!(A 0, B 1, C 2, D 3);
tuple_state!(A 0, B 1, C 2, D 3, E 4);
tuple_state!(A 0, B 1, C 2, D 3, E 4, F 5);

// ---------------------------------------------------------------------------------------------
// The schedule.

/// Where a state that an advance starts from is kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Loc {
    /// The caller's initial state (state 0).
    Initial,
    /// A snapshot slot.
    Slot(usize),
}

/// One action of a schedule.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Action {
    /// Compute state `to` from state `from` (kept at `src`; a working state may hold it too)
    /// by `to - from` forward steps; `to == from` loads it.
    Advance { from: usize, to: usize, src: Loc },
    /// Store state `t` (the last advance's result) in a snapshot slot.
    Store { t: usize, slot: usize },
    /// The slot's state is no longer needed.
    Free { slot: usize },
    /// Reverse step `t` (state `t` to `t + 1`): record it and run its adjoints.
    Reverse { t: usize },
}

/// A whole schedule: the actions, how many of them the forward pass runs (everything before
/// the first reverse, which advances from state 0 to state `T - 1`), the most snapshot slots
/// in use at once, and the forward steps its advances take in all.
#[derive(Clone, Debug)]
pub(crate) struct Plan {
    pub(crate) actions: Vec<Action>,
    pub(crate) prefix: usize,
    pub(crate) slots: usize,
    pub(crate) advance_steps: u64,
}

/// The largest `n * n * (c + 1)` for which the dynamic program's table is built.
const DP_LIMIT: u128 = 100_000_000;

/// Chooses the splits of the schedule: by the dynamic program's table when small enough,
/// else by the closed form.
pub(crate) struct Splitter {
    /// `(cost, argmin)`, indexed by `n * (c_max + 1) + c`.
    table: Option<(Vec<u64>, Vec<u32>)>,
    c_max: usize,
}

impl Splitter {
    /// A splitter for rollouts of up to `n_max` steps with up to `c_max` snapshots; the table
    /// is built when `n_max^2 (c_max + 1)` is at most [`DP_LIMIT`] and `use_table`.
    pub(crate) fn new(n_max: usize, c_max: usize, use_table: bool) -> Splitter {
        let fits = (n_max as u128) * (n_max as u128) * (c_max as u128 + 1) <= DP_LIMIT;
        if !(use_table && fits) {
            return Splitter { table: None, c_max };
        }
        let w = c_max + 1;
        let mut cost = vec![0u64; (n_max + 1) * w];
        let mut arg = vec![0u32; (n_max + 1) * w];
        for n in 2..=n_max {
            cost[n * w] = (n as u64) * (n as u64 - 1) / 2;
            for c in 1..=c_max {
                let (mut best, mut best_m) = (u64::MAX, 1);
                for m in 1..n {
                    let v = m as u64 + cost[(n - m) * w + c - 1] + cost[m * w + c];
                    if v < best {
                        (best, best_m) = (v, m);
                    }
                }
                cost[n * w + c] = best;
                arg[n * w + c] = best_m as u32;
            }
        }
        Splitter {
            table: Some((cost, arg)),
            c_max,
        }
    }

    /// The least number of forward steps that reversing `n` steps takes with `c` free slots
    /// (state 0 of the interval kept elsewhere).
    #[cfg(test)]
    pub(crate) fn cost(&self, n: usize, c: usize) -> u64 {
        match &self.table {
            Some((cost, _)) => cost[n * (self.c_max + 1) + c],
            None => closed_form_cost(n, c),
        }
    }

    /// The split `m` (in `1..n`) of an interval of `n >= 2` steps with `c >= 1` free slots.
    pub(crate) fn split(&self, n: usize, c: usize) -> usize {
        if let Some((_, arg)) = &self.table {
            return arg[n * (self.c_max + 1) + c] as usize;
        }
        // m + cost(n - m, c - 1) + cost(m, c) is convex in m (each cost is convex in its
        // length: piecewise linear with nondecreasing slope r); the first minimiser.
        let f = |m: usize| m as u64 + closed_form_cost(n - m, c - 1) + closed_form_cost(m, c);
        let (mut lo, mut hi) = (1, n - 1);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if f(mid + 1) < f(mid) {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        lo
    }
}

/// The dynamic program's `cost(n, c)` in closed form: `r n - C(c + 1 + r, c + 2)` for the least
/// `r` with `C(c + 1 + r, c + 1) >= n` (Griewank and Walther, binomial checkpointing, with
/// `c + 1` checkpoints counting the interval's first state).
pub(crate) fn closed_form_cost(n: usize, c: usize) -> u64 {
    if n <= 1 {
        return 0;
    }
    let n128 = n as u128;
    if c == 0 {
        return (n128 * (n128 - 1) / 2) as u64;
    }
    let k = c as u128 + 1;
    // beta = C(k + r, k), from r = 0 up.
    let (mut r, mut beta) = (0u128, 1u128);
    while beta < n128 {
        beta = beta * (k + r + 1) / (r + 1);
        r += 1;
    }
    // C(k + r, k + 1) = C(k + r, k) r / (k + 1).
    let below = beta * r / (k + 1);
    (r * n128 - below) as u64
}

/// The schedule for reversing `steps` steps with at most `budget` snapshots (`splitter` built
/// for at least `steps` and `min(budget, steps - 1)`).
pub(crate) fn plan(steps: usize, budget: usize, splitter: &Splitter) -> Plan {
    enum Task {
        Reverse {
            a: usize,
            b: usize,
            free: usize,
            src: Loc,
        },
        Free(usize),
    }
    let budget = budget.min(steps.saturating_sub(1));
    let mut actions = Vec::new();
    let mut free_slots: Vec<usize> = (0..budget).rev().collect();
    let (mut in_use, mut peak, mut advance_steps) = (0usize, 0usize, 0u64);
    let mut tasks = vec![Task::Reverse {
        a: 0,
        b: steps,
        free: budget,
        src: Loc::Initial,
    }];
    while let Some(task) = tasks.pop() {
        let (a, b, free, src) = match task {
            Task::Free(slot) => {
                actions.push(Action::Free { slot });
                free_slots.push(slot);
                in_use -= 1;
                continue;
            }
            Task::Reverse { a, b, free, src } => (a, b, free, src),
        };
        let n = b - a;
        if n == 1 {
            actions.push(Action::Advance {
                from: a,
                to: a,
                src,
            });
            actions.push(Action::Reverse { t: a });
        } else if free == 0 {
            for t in (a..b).rev() {
                actions.push(Action::Advance {
                    from: a,
                    to: t,
                    src,
                });
                advance_steps += (t - a) as u64;
                actions.push(Action::Reverse { t });
            }
        } else {
            let m = a + splitter.split(n, free);
            // The free count says a slot is available (the recursion holds at most
            // `budget` at once).
            let slot = free_slots.pop().unwrap_or(budget);
            in_use += 1;
            peak = peak.max(in_use);
            actions.push(Action::Advance {
                from: a,
                to: m,
                src,
            });
            advance_steps += (m - a) as u64;
            actions.push(Action::Store { t: m, slot });
            tasks.push(Task::Reverse { a, b: m, free, src });
            tasks.push(Task::Free(slot));
            tasks.push(Task::Reverse {
                a: m,
                b,
                free: free - 1,
                src: Loc::Slot(slot),
            });
        }
    }
    let prefix = actions
        .iter()
        .position(|a| matches!(a, Action::Reverse { .. }))
        .unwrap_or(actions.len());
    // The forward pass runs the prefix: its last advance ends at state T - 1 (or, for one
    // step, the load of state 0, which the forward pass does not need).
    let prefix = actions[..prefix]
        .iter()
        .rposition(|a| !matches!(a, Action::Advance { from, to, .. } if from == to))
        .map_or(0, |k| k + 1);
    Plan {
        actions,
        prefix,
        slots: peak,
        advance_steps,
    }
}

// ---------------------------------------------------------------------------------------------
// The rollout.

/// The memory and work of a [`Checkpointed`] rollout (from its schedule), next to what a full
/// tape would hold.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CheckpointReport {
    /// The rollout's steps `T`.
    pub steps: usize,
    /// The snapshot budget asked for.
    pub budget: usize,
    /// The most value-only snapshots held at once.
    pub snapshots: usize,
    /// The states held at the peak: the initial state, two working states and the snapshots.
    pub states_held: usize,
    /// Of those, how many have gradients (the working states, and the initial state if it
    /// has one).
    pub states_with_grads: usize,
    /// The bytes of one state's values.
    pub state_bytes: usize,
    /// The bytes held at the peak (values and gradients).
    pub bytes_held: usize,
    /// The states a full tape holds: `T + 1`, each with a gradient.
    pub full_tape_states: usize,
    /// Their bytes (values and gradients).
    pub full_tape_bytes: usize,
    /// Forward steps of the forward pass (`T`).
    pub forward_steps: u64,
    /// Forward steps the backward pass recomputes to restore states (besides recording each
    /// step once, which also runs its forward).
    pub recomputed_steps: u64,
}

/// Bytes in binary units (KiB, MiB, GiB).
fn human_bytes(b: usize) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut k = 0;
    while v >= 1024.0 && k + 1 < units.len() {
        v /= 1024.0;
        k += 1;
    }
    if k == 0 {
        format!("{b} B")
    } else {
        format!("{v:.1} {}", units[k])
    }
}

impl fmt::Display for CheckpointReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "checkpointed rollout of {} steps: {} states held at the peak ({} with gradients: \
             the initial and 2 working states; {} value-only snapshots of a budget of {}), {}",
            self.steps,
            self.states_held,
            self.states_with_grads,
            self.snapshots,
            self.budget,
            human_bytes(self.bytes_held)
        )?;
        writeln!(
            f,
            "  a full tape holds {} states with gradients, {} ({:.1}x the checkpointed peak)",
            self.full_tape_states,
            human_bytes(self.full_tape_bytes),
            self.full_tape_bytes as f64 / self.bytes_held.max(1) as f64
        )?;
        write!(
            f,
            "  forward {} steps; backward recomputes {} forward steps ({:.2} per step) and \
             records each of the {} steps once",
            self.forward_steps,
            self.recomputed_steps,
            self.recomputed_steps as f64 / self.steps as f64,
            self.steps
        )
    }
}

/// Where a rollout is between its passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// No forward pass yet.
    Fresh,
    /// After a forward pass: the final state is in the working state `grad_buf`.
    Forwarded,
    /// After a backward pass.
    Spent,
    /// During a pass, and after one that failed.
    Broken,
}

/// The step function: `(t, from, to)` launches the work computing state `t + 1` into `to` from
/// state `t` in `from`.
type StepFn<'a, S> = Box<dyn FnMut(usize, &S, &S) -> Result<()> + 'a>;

/// A checkpointed rollout: `T` steps of a simulation whose gradient needs memory for about
/// `sqrt(T)` states instead of a full tape's `T + 1` (see the [module](self) documentation).
///
/// The step function `step(t, from, to)` launches the kernels that compute state `t + 1` into
/// `to` from state `t` in `from`. It must write every part of `to` from `from` and parameters
/// alone (not from `to`'s old values), and do the same work whenever it is called with the
/// same `t`: the backward pass calls it again to recompute states and to record each step
/// once. Parameters with gradients that it captures (drag, masses) accumulate their
/// gradients over the steps, as under a tape; a running loss it accumulates with atomics is
/// right after [`forward`](Self::forward) (the backward pass adds to its value again) and is
/// seeded by [`backward_seeded`](Self::backward_seeded).
///
/// ```ignore
/// let s0 = (x0.with_grad()?, v0.with_grad()?);
/// let mut roll = wp::Checkpointed::sqrt_memory(&s0, 1000, |_t, (x0, v0), (x1, v1)| {
///     wp::launch(step, n, (x0, v0, x1, v1, b, mass, gravity, dt), &dev)
/// })?;
/// let (x_t, _) = roll.forward()?;
/// let tape = wp::Tape::new();
/// {
///     let _rec = tape.record();
///     wp::launch(sum_sq, n, (x_t, &loss), &dev)?;
/// }
/// tape.backward(&loss)?; // dL/dx_T into the final state's gradient
/// roll.backward()?; // dL/dx0, dL/dv0 into s0's gradients
/// println!("{}", roll.report());
/// ```
pub struct Checkpointed<'a, S: CheckpointState> {
    s0: &'a S,
    steps: usize,
    step: StepFn<'a, S>,
    /// The two working states, with gradients.
    work: [S; 2],
    /// Which state's values each working state holds.
    vals: [Option<usize>; 2],
    /// The working state whose gradient holds dL/dx of the state after the next step to
    /// reverse (the final state's after a forward pass).
    grad_buf: usize,
    /// Snapshot slots, allocated at first use and kept for later passes.
    slots: Vec<Option<S>>,
    plan: Plan,
    phase: Phase,
    report: CheckpointReport,
    /// Forward steps the last backward pass recomputed.
    recomputed: u64,
}

/// What a rollout's `Debug` shows: its length, its snapshot slots, where it is (forward done,
/// reversed) and its report; not the states (they are arrays, and `S` need not be `Debug`) nor
/// the step closure.
impl<S: CheckpointState> std::fmt::Debug for Checkpointed<'_, S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Checkpointed")
            .field("steps", &self.steps)
            .field("slots", &self.slots.len())
            .field("phase", &self.phase)
            .field("report", &self.report)
            .finish_non_exhaustive()
    }
}

impl<'a, S: CheckpointState> Checkpointed<'a, S> {
    /// The snapshot budget of [`sqrt_memory`](Self::sqrt_memory): `floor(sqrt(steps)) - 3`
    /// (at least zero), so that the states held (initial, two working, snapshots) are at most
    /// `floor(sqrt(steps))` once `steps >= 9`.
    pub fn sqrt_budget(steps: usize) -> usize {
        steps.isqrt().saturating_sub(3)
    }

    /// A rollout of `steps` steps from `s0` (the caller's; its gradient receives dL/ds0 at the
    /// end of [`backward`](Self::backward), added to what it holds) with at most `snapshots`
    /// value-only snapshots. Allocates the two working states (with gradients); snapshots are
    /// allocated when first used.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for zero steps, an initial state whose parts are on
    /// different devices, or a state type whose `alloc_like` does not reproduce its layout.
    pub fn new(
        s0: &'a S,
        steps: usize,
        snapshots: usize,
        step: impl FnMut(usize, &S, &S) -> Result<()> + 'a,
    ) -> Result<Self> {
        if steps == 0 {
            return Err(Error::invalid(
                "Checkpointed: a rollout of zero steps (steps must be at least 1)",
            ));
        }
        let mut devices = Vec::new();
        s0.devices(&mut devices);
        if let Some(other) = devices.iter().find(|d| **d != devices[0]) {
            return Err(Error::invalid(format!(
                "Checkpointed: the initial state's parts are on different devices (\"{}\" and \
                 \"{other}\"); a step runs on one device",
                devices[0]
            )));
        }
        let work = [s0.alloc_like(true)?, s0.alloc_like(true)?];
        for w in &work {
            check_layout(s0, w, "a working state")?;
        }
        let budget = snapshots.min(steps - 1);
        let splitter = Splitter::new(steps, budget, true);
        let plan = plan(steps, budget, &splitter);
        let state_bytes = s0.value_bytes();
        let s0_grad = usize::from(s0.has_grads());
        let report = CheckpointReport {
            steps,
            budget: snapshots,
            snapshots: plan.slots,
            states_held: 3 + plan.slots,
            states_with_grads: 2 + s0_grad,
            state_bytes,
            bytes_held: state_bytes * (3 + plan.slots + 2 + s0_grad),
            full_tape_states: steps + 1,
            full_tape_bytes: state_bytes * 2 * (steps + 1),
            forward_steps: steps as u64,
            recomputed_steps: plan.advance_steps - (steps as u64 - 1),
        };
        Ok(Checkpointed {
            s0,
            steps,
            step: Box::new(step),
            work,
            vals: [None, None],
            grad_buf: 0,
            slots: Vec::new(),
            plan,
            phase: Phase::Fresh,
            report,
            recomputed: 0,
        })
    }

    /// [`new`](Self::new) with the budget [`sqrt_budget`](Self::sqrt_budget)`(steps)`: at most
    /// `floor(sqrt(steps))` states held (for `steps >= 9`; three below).
    ///
    /// # Errors
    /// As [`new`](Self::new).
    pub fn sqrt_memory(
        s0: &'a S,
        steps: usize,
        step: impl FnMut(usize, &S, &S) -> Result<()> + 'a,
    ) -> Result<Self> {
        Self::new(s0, steps, Self::sqrt_budget(steps), step)
    }

    /// The rollout's number of steps.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Memory and work of the schedule, next to a full tape's.
    pub fn report(&self) -> &CheckpointReport {
        &self.report
    }

    /// Forward steps the last backward pass recomputed (the report's `recomputed_steps` once
    /// one has run).
    pub fn recomputed(&self) -> u64 {
        self.recomputed
    }

    /// Runs the `T` steps from the initial state without recording (tapes recording on this
    /// thread are paused), storing the schedule's snapshots, and returns the final state. Its
    /// values are valid until [`backward`](Self::backward); a loss computed from it under a
    /// [`Tape`] whose backward runs before this rollout's puts dL/dx_T into its gradient
    /// (zeroed here).
    ///
    /// # Errors
    /// [`Error::Step`] naming the step whose function failed; allocation and copy errors.
    pub fn forward(&mut self) -> Result<&S> {
        let _paused = pause_recording();
        self.phase = Phase::Broken;
        for w in &self.work {
            w.zero_grads()?;
        }
        self.vals = [None, None];
        let prefix = self.plan.prefix;
        for k in 0..prefix {
            let action = self.plan.actions[k];
            self.run(action, false)?;
        }
        // The last step, from state T - 1 into the other working state.
        let last = self.steps - 1;
        let dst = if last == 0 {
            run_step(&mut self.step, 0, self.s0, &self.work[0], "forward")?;
            0
        } else {
            let Some(src) = self.vals.iter().position(|v| *v == Some(last)) else {
                return Err(internal("the forward pass did not reach the last state"));
            };
            let (from, to) = pair(&self.work, src);
            run_step(&mut self.step, last, from, to, "forward")?;
            1 - src
        };
        self.vals[dst] = Some(self.steps);
        self.grad_buf = dst;
        self.phase = Phase::Forwarded;
        Ok(&self.work[dst])
    }

    /// The final state of the last forward pass (as [`forward`](Self::forward) returned it).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when no forward pass has run since the last backward pass.
    pub fn final_state(&self) -> Result<&S> {
        match self.phase {
            Phase::Forwarded => Ok(&self.work[self.grad_buf]),
            _ => Err(Error::invalid(
                "Checkpointed::final_state: no forward pass since the last backward pass",
            )),
        }
    }

    /// Reverses the steps from `T - 1` down to `0` with the gradient of the final state as
    /// the loss's backward left it (see [`forward`](Self::forward)), recomputing states from
    /// the snapshots. dL/ds0 is added into the initial state's gradient, and parameters the
    /// step function reads accumulate theirs. Tapes recording on this thread are paused.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] before a forward pass, a second time after one, or after a
    /// failed pass;
    /// [`Error::Step`] naming the step whose function failed; an adjoint's error.
    pub fn backward(&mut self) -> Result<()> {
        match self.phase {
            Phase::Fresh => {
                return Err(Error::invalid(
                    "Checkpointed::backward before forward (run forward first)",
                ))
            }
            Phase::Spent => {
                return Err(Error::invalid(
                    "Checkpointed::backward a second time without a forward pass in between \
                     (the working states no longer hold the rollout; run forward again)",
                ))
            }
            Phase::Broken => {
                return Err(Error::invalid(
                    "Checkpointed::backward after a failed forward or backward pass (run \
                     forward again)",
                ))
            }
            Phase::Forwarded => {}
        }
        self.phase = Phase::Broken;
        let _paused = pause_recording();
        self.recomputed = 0;
        for k in self.plan.prefix..self.plan.actions.len() {
            let action = self.plan.actions[k];
            self.run(action, true)?;
        }
        self.phase = Phase::Spent;
        Ok(())
    }

    /// Seeds a running loss (accumulated by the step function) with one in every element of
    /// its gradient, as [`Tape::backward`] does, then runs [`backward`](Self::backward).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `loss` has no gradient; as [`backward`](Self::backward).
    pub fn backward_seeded<T: Seed, const N: usize>(&mut self, loss: &Array<T, N>) -> Result<()> {
        let Some(g) = loss.grad() else {
            return Err(Error::invalid(
                "Checkpointed::backward_seeded: the loss has no gradient (create it with \
                 .with_grad())",
            ));
        };
        if self.phase != Phase::Forwarded {
            // The phase error, before touching the loss.
            return self.backward();
        }
        g.fill(T::ONE)?;
        self.backward()
    }

    /// Runs one action of the schedule (`backward`: in the backward pass, where advances must
    /// end in the working state that does not hold the live gradient).
    fn run(&mut self, action: Action, backward: bool) -> Result<()> {
        match action {
            Action::Advance { from, to, src } => self.advance(from, to, src, backward),
            Action::Store { t, slot } => {
                let Some(w) = self.vals.iter().position(|v| *v == Some(t)) else {
                    return Err(internal("a snapshot of a state no working state holds"));
                };
                while self.slots.len() <= slot {
                    self.slots.push(None);
                }
                if self.slots[slot].is_none() {
                    let s = self.s0.alloc_like(false)?;
                    check_layout(self.s0, &s, "a snapshot")?;
                    self.slots[slot] = Some(s);
                }
                let s = self.slots[slot].as_ref().expect("allocated above");
                s.copy_values_from(&self.work[w])
            }
            Action::Free { .. } => Ok(()),
            Action::Reverse { t } => self.reverse(t),
        }
    }

    /// State `to` into a working state, from state `from` at `src` (or a working state holding
    /// it), by `to - from` forward steps.
    fn advance(&mut self, from: usize, to: usize, src: Loc, backward: bool) -> Result<()> {
        if to == 0 {
            // Step 0 is recorded from the initial state itself.
            return Ok(());
        }
        let target = 1 - self.grad_buf;
        let k = to - from;
        if k == 0 {
            // A load: the state to reverse from, into the working state without the live
            // gradient (recording needs its gradient).
            if self.vals[target] == Some(to) {
                return Ok(());
            }
            let Loc::Slot(slot) = src else {
                return Err(internal("a load of a state that is not a snapshot"));
            };
            let Some(Some(snap)) = self.slots.get(slot) else {
                return Err(internal("a load of a snapshot never stored"));
            };
            self.work[target].copy_values_from(snap)?;
            self.vals[target] = Some(to);
            return Ok(());
        }
        // The working state where k steps from working state s end.
        let lands = |s: usize| if k % 2 == 1 { 1 - s } else { s };
        let held =
            (0..2).find(|&s| self.vals[s] == Some(from) && (!backward || lands(s) == target));
        let pass = if backward { "recomputation" } else { "forward" };
        // The first step: on from a working state, else straight from the initial state or the
        // snapshot (no copy) into the working state where k steps end in `target`.
        let mut cur = match held {
            Some(s) => {
                let (a, b) = pair(&self.work, s);
                run_step(&mut self.step, from, a, b, pass)?;
                1 - s
            }
            None => {
                let first = if !backward || k % 2 == 1 {
                    target
                } else {
                    1 - target
                };
                let source = match src {
                    Loc::Initial => self.s0,
                    Loc::Slot(slot) => match self.slots.get(slot) {
                        Some(Some(snap)) => snap,
                        _ => return Err(internal("an advance from a snapshot never stored")),
                    },
                };
                run_step(&mut self.step, from, source, &self.work[first], pass)?;
                first
            }
        };
        self.vals[cur] = Some(from + 1);
        for t in from + 1..to {
            let (a, b) = pair(&self.work, cur);
            run_step(&mut self.step, t, a, b, pass)?;
            cur = 1 - cur;
            self.vals[cur] = Some(t + 1);
        }
        if backward {
            self.recomputed += k as u64;
        }
        Ok(())
    }

    /// Records step `t` from state `t` (in the working state without the live gradient, or the
    /// initial state) into the working state whose gradient holds dL/dx_{t+1}, and runs the
    /// recorded adjoints; the gradient of state `t` then holds dL/dx_t.
    fn reverse(&mut self, t: usize) -> Result<()> {
        let q = self.grad_buf;
        let from = if t == 0 {
            self.s0
        } else {
            let p = 1 - q;
            if self.vals[p] != Some(t) {
                return Err(internal("a reverse step without its state restored"));
            }
            self.work[p].zero_grads()?;
            &self.work[p]
        };
        let tape = Tape::new();
        {
            let _rec = tape.record();
            run_step(&mut self.step, t, from, &self.work[q], "backward")?;
        }
        tape.backward_from_grads()?;
        self.vals[q] = Some(t + 1);
        if t > 0 {
            self.grad_buf = 1 - q;
        }
        Ok(())
    }
}

/// The working states as (`work[s]`, the other).
fn pair<S>(work: &[S; 2], s: usize) -> (&S, &S) {
    (&work[s], &work[1 - s])
}

/// Calls the step function, naming the step in its error.
fn run_step<S>(
    step: &mut StepFn<'_, S>,
    t: usize,
    from: &S,
    to: &S,
    pass: &'static str,
) -> Result<()> {
    step(t, from, to).map_err(|e| Error::Step {
        step: t,
        pass,
        source: Box::new(e),
    })
}

/// An error when `made` (allocated like `s0`) has another layout.
fn check_layout<S: CheckpointState>(s0: &S, made: &S, what: &str) -> Result<()> {
    match s0.layout_mismatch(made) {
        None => Ok(()),
        Some(m) => Err(Error::invalid(format!(
            "Checkpointed: {what} allocated like the initial state differs from it ({m}); the \
             state type's alloc_like must reproduce its layout"
        ))),
    }
}

/// A broken invariant of the schedule's execution (a bug here, reported rather than a panic).
#[cold]
fn internal(what: &str) -> Error {
    Error::invalid(format!("Checkpointed (internal): {what}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dynamic program, naively (the reference for the table and the closed form).
    fn dp(n_max: usize, c_max: usize) -> Vec<Vec<u64>> {
        let mut cost = vec![vec![0u64; c_max + 1]; n_max + 1];
        for n in 2..=n_max {
            cost[n][0] = (n * (n - 1) / 2) as u64;
            for c in 1..=c_max {
                cost[n][c] = (1..n)
                    .map(|m| m as u64 + cost[n - m][c - 1] + cost[m][c])
                    .min()
                    .unwrap();
            }
        }
        cost
    }

    #[test]
    fn closed_form_matches_the_dynamic_program() {
        let cost = dp(150, 10);
        for (n, row) in cost.iter().enumerate() {
            for (c, &want) in row.iter().enumerate() {
                assert_eq!(closed_form_cost(n, c), want, "n {n} c {c}");
            }
        }
        let table = Splitter::new(150, 10, true);
        assert!(table.table.is_some());
        for (n, row) in cost.iter().enumerate() {
            for (c, &want) in row.iter().enumerate() {
                assert_eq!(table.cost(n, c), want);
            }
        }
    }

    /// Checks `plan(steps, budget)` by simulating it: slots within the budget, every advance
    /// from a state that is where it says, every snapshot of the state just computed, every
    /// step reversed once in the order T-1..0 with its state just restored, and the advances'
    /// forward steps equal to the cost; the forward pass's prefix reaches state T - 1.
    fn check_plan(steps: usize, budget: usize, splitter: &Splitter) -> Plan {
        let p = plan(steps, budget, splitter);
        let budget = budget.min(steps - 1);
        assert!(p.slots <= budget, "T {steps} c {budget}: {} slots", p.slots);
        let mut slots: Vec<Option<usize>> = vec![None; budget];
        let (mut last, mut reversed, mut steps_done) = (None::<usize>, Vec::new(), 0u64);
        for (k, a) in p.actions.iter().enumerate() {
            match *a {
                Action::Advance { from, to, src } => {
                    assert!(to >= from);
                    match src {
                        Loc::Initial => assert_eq!(from, 0),
                        Loc::Slot(s) => assert_eq!(slots[s], Some(from), "action {k}"),
                    }
                    steps_done += (to - from) as u64;
                    last = Some(to);
                }
                Action::Store { t, slot } => {
                    assert_eq!(last, Some(t));
                    assert_eq!(slots[slot], None, "slot {slot} in use");
                    slots[slot] = Some(t);
                }
                Action::Free { slot } => {
                    assert!(slots[slot].is_some());
                    slots[slot] = None;
                }
                Action::Reverse { t } => {
                    assert_eq!(last, Some(t), "reverse {t} without its state");
                    reversed.push(t);
                    assert!(k >= p.prefix);
                }
            }
            if k + 1 == p.prefix && steps > 1 {
                assert_eq!(last, Some(steps - 1), "the prefix ends at T - 1");
            }
        }
        assert_eq!(reversed, (0..steps).rev().collect::<Vec<_>>());
        assert_eq!(steps_done, p.advance_steps);
        assert_eq!(
            p.advance_steps,
            closed_form_cost(steps, budget),
            "T {steps} c {budget}"
        );
        assert!(p.actions[..p.prefix]
            .iter()
            .all(|a| !matches!(a, Action::Reverse { .. })));
        p
    }

    #[test]
    fn plans_stay_in_budget_and_reverse_every_step_once() {
        for steps in 1..=60 {
            for budget in [0, 1, 2, 3, 5, 8, 59, 100] {
                let c = budget.min(steps - 1);
                check_plan(steps, budget, &Splitter::new(steps, c, true));
                check_plan(steps, budget, &Splitter::new(steps, c, false));
            }
        }
    }

    #[test]
    fn the_sqrt_budget_of_a_thousand_steps() {
        let (steps, budget) = (1000, 28);
        assert_eq!(Checkpointed::<Array<f32>>::sqrt_budget(steps), budget);
        let table = Splitter::new(steps, budget, true);
        assert!(table.table.is_some(), "1000 x 1000 x 29 fits the table");
        let p = check_plan(steps, budget, &table);
        // The closed form's splits cost the same.
        let q = check_plan(steps, budget, &Splitter::new(steps, budget, false));
        assert_eq!(p.advance_steps, q.advance_steps);
        assert!(p.slots <= budget);
    }

    #[test]
    fn long_rollouts_plan_by_the_closed_form() {
        let (steps, budget) = (100_000, 20);
        let s = Splitter::new(steps, budget, true);
        assert!(s.table.is_none());
        check_plan(steps, budget, &s);
    }
}
