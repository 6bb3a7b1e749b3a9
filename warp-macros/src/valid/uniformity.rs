//! Uniformity: which values are the same in every thread of a launch, and which statements
//! only some threads of a block reach (divergent control flow). A block-cooperative builtin
//! (a row with the `cooperative` fact: the tile operations) must be called by every thread of
//! the block together, so one under divergent control flow is an error at its call.
//!
//! Values: a kernel's value parameters, literals and module consts are uniform (a func's
//! parameters are assumed uniform: its callers are checked where they call it); `tid()` is
//! varying; an operation of uniform values is uniform, except an atomic (each thread gets its
//! own old value) and a read of memory the kernel writes (an array element, an object, or
//! anything a func reads through an array or object argument: another thread may have changed
//! it), which are varying. An array element read at a varying index is varying.
//!
//! Control flow: the branches of an `if` on a varying condition are divergent; so is the body
//! of a `for` loop whose bounds or step are varying, and of any loop that some threads leave
//! or skip ahead in early (a `break`, `continue`, or `return` under divergent control flow
//! inside it), and everything after a `return` under divergent control flow. A variable
//! assigned under divergent control flow that is deeper than its definition is varying
//! afterwards (threads disagree on whether the assignment happened).
//!
//! Loops make this a fixpoint: the analysis walks the function until no value becomes varying
//! and no loop becomes divergent (both only ever grow, so it ends).

use crate::ir::*;
use crate::types::Ty;
use proc_macro2::Span;
use std::collections::hash_map::Entry;
use std::collections::HashMap;

/// The uniformity facts of a function.
pub struct Uniformity {
    /// Per variable: whether threads may hold different values.
    varying: Vec<bool>,
    /// The statements under divergent control flow (by address in the analysed function),
    /// each with the span of the outermost construct that made its control flow divergent.
    divergent: HashMap<*const Stmt, Span>,
}

impl Uniformity {
    /// Analyses `f`. The statement addresses it records are `f`'s: ask about `f` only.
    pub fn of(f: &Function) -> Uniformity {
        let mut a = Analysis {
            f,
            varying: vec![false; f.vars.len()],
            def_level: vec![0; f.vars.len()],
            copy_of: copies(f),
            written: vec![false; f.vars.len()],
            written_unknown: false,
            divergent_loops: HashMap::new(),
            divergent: HashMap::new(),
            loops: Vec::new(),
            causes: Vec::new(),
            exited: None,
            changed: false,
        };
        a.find_writes();
        loop {
            a.changed = false;
            a.divergent.clear();
            a.loops.clear();
            a.causes.clear();
            a.exited = None;
            a.block(&f.body);
            if !a.changed {
                break;
            }
        }
        Uniformity {
            varying: a.varying,
            divergent: a.divergent,
        }
    }

    /// Whether every thread holds the same value of `v` (wherever `v` is in scope).
    pub fn is_uniform(&self, v: VarId) -> bool {
        !self.varying[v]
    }

    /// Where `s` is under divergent control flow: the span of the construct (a condition, a
    /// loop, a `return`) that makes it so.
    pub fn divergence(&self, s: &Stmt) -> Option<Span> {
        self.divergent.get(&(s as *const Stmt)).copied()
    }
}

/// A block-cooperative call under divergent control flow is an error at the call, and so is
/// one whose scalar arguments differ between the block's threads ([`check_tile_arguments`]).
pub(super) fn check_cooperative(f: &Function, errors: &mut Vec<syn::Error>) {
    let mut any = false;
    walk_stmts(&f.body, &mut |s| any |= f.is_cooperative(s));
    if !any {
        return;
    }
    let u = Uniformity::of(f);
    walk_stmts(&f.body, &mut |s| {
        if !f.is_cooperative(s) {
            return;
        }
        let what = match &s.kind {
            StmtKind::Assign {
                op: Op::Builtin { builtin, .. },
                ..
            } => format!("`{}`", builtin.name),
            StmtKind::Assign {
                op: Op::TileMap { .. },
                ..
            } => "`tile_map`".to_string(),
            StmtKind::Assign {
                op: Op::TileReduce { .. },
                ..
            } => "`tile_reduce`".to_string(),
            _ => "an operation on tiles".to_string(),
        };
        if let Some(cause) = u.divergence(s) {
            let mut e = syn::Error::new(
                s.span,
                format!(
                    "{what} is block-cooperative: every thread of the block must call it \
                     together, but this call is under control flow that depends on the thread"
                ),
            );
            e.combine(syn::Error::new(
                cause,
                "the control flow depends on the thread here (on `tid()`, on a value read at a \
                 thread-dependent index or from memory the kernel writes, or on an early exit \
                 some threads take)",
            ));
            errors.push(e);
        }
    });
    if f.tiled.is_some() {
        check_tile_arguments(f, &u, errors);
    }
}

/// A tile operation's scalar arguments (offsets, `tile_arange`'s bounds, `tile_map`'s
/// constants, the scalar of `t * s`) must be the same in every thread of the block: the block
/// runs the operation once (the CPU reads lane 0's value, a CUDA thread its own, so a
/// thread-dependent one would give each backend another result). (`tile(x)` takes each
/// thread's own value.)
fn check_tile_arguments(f: &Function, u: &Uniformity, errors: &mut Vec<syn::Error>) {
    walk_stmts(&f.body, &mut |s| {
        let StmtKind::Assign { op, .. } = &s.kind else {
            return;
        };
        let (name, what, args): (String, &str, &[VarId]) = match op {
            Op::Builtin { builtin, args } if builtin.cooperative && !builtin.lanes => {
                let what = match builtin.name {
                    "tile_load" | "tile_store" => "offset",
                    _ => "argument",
                };
                (format!("`{}`", builtin.name), what, args)
            }
            Op::TileMap { args, .. } => ("`tile_map`".into(), "constant", args),
            Op::Binary(op, a, b) if f.ty(*a).is_tile() != f.ty(*b).is_tile() => (
                format!("a tile's `{}`", op.symbol()),
                "scalar operand",
                std::slice::from_ref(if f.ty(*a).is_tile() { b } else { a }),
            ),
            _ => return,
        };
        for a in args {
            let t = f.ty(*a);
            if matches!(t, Ty::Array(..) | Ty::Tile(..)) || u.is_uniform(*a) {
                continue;
            }
            errors.push(syn::Error::new(
                s.span,
                format!(
                    "the {what} of {name} must be the same in every thread of the block (it may not depend on `lane()`, on a value read from memory the kernel writes, or on control flow that depends on the thread)"
                ),
            ));
            return;
        }
    });
}

struct Analysis<'a> {
    f: &'a Function,
    varying: Vec<bool>,
    /// How many divergent constructs enclosed each variable's definition.
    def_level: Vec<usize>,
    /// For array and object variables defined as a copy of another: that one.
    copy_of: Vec<Option<VarId>>,
    /// Per parameter: whether the function writes through it (stores, atomics, object
    /// writes, or passing it to a func).
    written: Vec<bool>,
    /// Whether it writes through a variable that is no known parameter's copy.
    written_unknown: bool,
    /// Loops that some threads leave or skip ahead in early, with the construct that makes
    /// them so.
    divergent_loops: HashMap<*const Stmt, Span>,
    divergent: HashMap<*const Stmt, Span>,
    /// The enclosing loops: the statement and the divergence level of its body.
    loops: Vec<(*const Stmt, usize)>,
    /// The spans of the divergent constructs enclosing the walk, outermost first.
    causes: Vec<Span>,
    /// A `return` under divergent control flow was passed: everything after it is divergent.
    exited: Option<Span>,
    changed: bool,
}

/// For array and object variables made by copying another (`let b = a;`), that variable.
fn copies(f: &Function) -> Vec<Option<VarId>> {
    let mut out = vec![None; f.vars.len()];
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Assign {
            dst,
            op: Op::Copy(src),
            define: true,
        } = &s.kind
        {
            if matches!(f.vars[*dst].ty, Ty::Array(..) | Ty::Object(_)) {
                out[*dst] = Some(*src);
            }
        }
    });
    out
}

impl Analysis<'_> {
    /// The parameter `v` is (a copy of), if known.
    fn root(&self, mut v: VarId) -> Option<VarId> {
        for _ in 0..=self.f.vars.len() {
            if self.f.params.iter().any(|p| p.var == v) {
                return Some(v);
            }
            v = self.copy_of[v]?;
        }
        None
    }

    fn find_writes(&mut self) {
        let f = self.f;
        let mut through: Vec<VarId> = Vec::new();
        walk_stmts(&f.body, &mut |s| match &s.kind {
            StmtKind::Store { array, .. } => through.push(*array),
            StmtKind::Assign {
                op: Op::Builtin { builtin, args },
                ..
            } if builtin.is_atomic() || builtin.grad == crate::builtins::Grad::Effect => {
                through.push(args[0])
            }
            StmtKind::Assign {
                op: Op::Func { args, .. },
                ..
            } => through.extend(args.iter().copied().filter(|a| is_memory(&f.vars[*a].ty))),
            _ => {}
        });
        for v in through {
            match self.root(v) {
                Some(p) => self.written[p] = true,
                None => self.written_unknown = true,
            }
        }
    }

    /// Whether another thread may write the memory `v` (an array or object) names.
    fn may_be_written(&self, v: VarId) -> bool {
        match self.root(v) {
            Some(p) => self.written[p] || self.written_unknown,
            None => self.written_unknown || self.written.iter().any(|w| *w),
        }
    }

    fn op_varying(&self, op: &Op) -> bool {
        let mut any = false;
        op.for_each_read(&mut |v| any |= self.varying[v]);
        let reads_written = |args: &[VarId]| {
            args.iter()
                .any(|a| is_memory(&self.f.vars[*a].ty) && self.may_be_written(*a))
        };
        match op {
            // In a tiled kernel `tid()` is the block's index: the same in its threads.
            Op::Tid(_) => self.f.tiled.is_none(),
            Op::Lane => true,
            // Per-thread values out of a tile.
            Op::Builtin { builtin, .. } if builtin.lanes => true,
            // Only the type of the variable counts.
            Op::LitLike(..) | Op::ZeroLike(_) => false,
            Op::Load { array, .. } => any || self.may_be_written(*array),
            Op::Builtin { builtin, .. } if builtin.is_atomic() => true,
            Op::Builtin { args, .. } | Op::Func { args, .. } => any || reads_written(args),
            _ => any,
        }
    }

    fn set_varying(&mut self, v: VarId) {
        if !self.varying[v] {
            self.varying[v] = true;
            self.changed = true;
        }
    }

    /// The span of the outermost divergent construct enclosing the walk, if any.
    fn cause(&self) -> Option<Span> {
        self.causes.first().copied().or(self.exited)
    }

    fn level(&self) -> usize {
        self.causes.len() + usize::from(self.exited.is_some())
    }

    /// Walks `body` one divergence level deeper when `cause` is set.
    fn nested(&mut self, body: &Block, cause: Option<Span>) {
        if let Some(c) = cause {
            self.causes.push(c);
        }
        self.block(body);
        if cause.is_some() {
            self.causes.pop();
        }
    }

    /// Marks the innermost loop divergent (a `break` or `continue` only some threads take).
    fn diverge_loop(&mut self, cause: Span) {
        if let Some((l, _)) = self.loops.last() {
            self.mark_loop(*l, cause);
        }
    }

    /// Marks loop `l` divergent because of `cause` (if it is not yet).
    fn mark_loop(&mut self, l: *const Stmt, cause: Span) {
        if let Entry::Vacant(e) = self.divergent_loops.entry(l) {
            e.insert(cause);
            self.changed = true;
        }
    }

    /// Whether the walk is deeper in divergence than the innermost loop's body.
    fn divergent_in_loop(&self) -> bool {
        self.loops.last().is_some_and(|(_, l)| self.level() > *l)
    }

    fn block(&mut self, b: &Block) {
        for s in b {
            if let Some(c) = self.cause() {
                self.divergent.insert(s as *const Stmt, c);
            }
            let level = self.level();
            match &s.kind {
                StmtKind::Declare { var } => self.def_level[*var] = level,
                // A tile is one value of the whole block, whatever it was computed from.
                StmtKind::Assign { dst, define, .. } if self.f.vars[*dst].ty.is_tile() => {
                    if *define {
                        self.def_level[*dst] = level;
                    }
                }
                StmtKind::Assign { dst, op, define } => {
                    if *define {
                        self.def_level[*dst] = level;
                    }
                    if self.op_varying(op) || (!define && level > self.def_level[*dst]) {
                        self.set_varying(*dst);
                    }
                }
                StmtKind::SetMember { var, value, .. } => {
                    if self.varying[*value] || level > self.def_level[*var] {
                        self.set_varying(*var);
                    }
                }
                // An element written at a varying index varies the array, as a varying value.
                StmtKind::SetElem { var, index, value } => {
                    let varying = self.varying[*value] || self.varying[*index];
                    if varying || level > self.def_level[*var] {
                        self.set_varying(*var);
                    }
                }
                StmtKind::Store { .. } | StmtKind::Print { .. } | StmtKind::Assert { .. } => {}
                StmtKind::If { cond, then, els } => {
                    let cause = self.varying[*cond].then_some(s.span);
                    self.nested(then, cause);
                    self.nested(els, cause);
                }
                StmtKind::For { var, body, .. } => {
                    self.def_level[*var] = level;
                    // The statement's own reads: the range's bounds and step.
                    let mut bounds = false;
                    s.kind.for_each_read(&mut |v| bounds |= self.varying[v]);
                    if bounds {
                        self.set_varying(*var);
                    }
                    let cause = if bounds {
                        Some(s.span)
                    } else {
                        self.divergent_loops.get(&(s as *const Stmt)).copied()
                    };
                    self.loop_body(s, body, cause);
                }
                StmtKind::Loop { body } => {
                    let cause = self.divergent_loops.get(&(s as *const Stmt)).copied();
                    self.loop_body(s, body, cause);
                }
                StmtKind::Break | StmtKind::Continue => {
                    if self.divergent_in_loop() {
                        self.diverge_loop(s.span);
                    }
                }
                StmtKind::ExitIf { flags } => {
                    if flags.iter().any(|v| self.varying[*v]) || self.divergent_in_loop() {
                        self.diverge_loop(s.span);
                    }
                }
                StmtKind::Return { .. } => {
                    if level > 0 {
                        // Some threads leave: every enclosing loop's later iterations, and
                        // everything after, run without them.
                        let loops: Vec<*const Stmt> = self.loops.iter().map(|(l, _)| *l).collect();
                        for l in loops {
                            self.mark_loop(l, s.span);
                        }
                        if self.exited.is_none() {
                            self.exited = Some(s.span);
                        }
                    }
                }
            }
        }
    }

    fn loop_body(&mut self, s: &Stmt, body: &Block, cause: Option<Span>) {
        let level = self.level() + usize::from(cause.is_some());
        self.loops.push((s as *const Stmt, level));
        self.nested(body, cause);
        self.loops.pop();
    }
}

/// Arrays and host objects: what names memory rather than holding a value.
fn is_memory(t: &Ty) -> bool {
    matches!(t, Ty::Array(..) | Ty::Object(_))
}
