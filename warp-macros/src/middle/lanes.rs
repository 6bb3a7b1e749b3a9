//! Lanes: how a tiled kernel's block runs as one CPU task.
//!
//! On a GPU every thread of a block runs the whole body, and the cooperative statements (tile
//! operations) are where the threads meet. On the CPU one task runs the block: it runs each
//! cooperative statement once for the block, and each run of other statements between them
//! (a *lane region*) in a loop over the block's lanes. That is the same program: the
//! validator has made sure that cooperative statements are only under control flow every
//! thread of a block takes alike, so lifting that control flow out of the lane loops changes
//! nothing.
//!
//! This pass classifies statements (*block-level*: cooperative, or control flow around a
//! cooperative statement, or an exit all lanes take together; the rest *lane-level*), numbers
//! the regions, and gives each variable its storage: a block-level value (tiles, parameters,
//! loop variables of block-level loops), one value per lane kept between regions
//! ([`Storage::PerLane`]), or a local of one region. The Rust back end (`back::rust_tile`)
//! prints from this plan; the CUDA back end needs none of it.

use crate::ir::*;
use crate::valid::Uniformity;
use std::collections::HashSet;

/// Where a variable of a tiled kernel lives on the CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// One value for the block: tiles, parameters, values only block-level statements set.
    Block,
    /// One value per lane, kept between lane regions (`warp_core::block::PerLane`).
    PerLane,
    /// A local of the one lane region that uses it.
    Local,
}

/// The plan of a tiled kernel's CPU block.
#[derive(Debug)]
pub struct LanePlan {
    block_level: HashSet<*const Stmt>,
    /// Per variable.
    pub storage: Vec<Storage>,
    /// Every lane of a region computes and stores the same thing (no `lane()`, no per-lane
    /// tile rows, no atomics, prints or func calls): one lane per region does it for all.
    pub lane_invariant: bool,
    /// Some lane may return while others go on: later regions skip the lanes that returned.
    pub lane_returns: bool,
}

impl LanePlan {
    /// Whether `s` (a statement of the planned function) runs once for the block.
    pub fn is_block_level(&self, s: &Stmt) -> bool {
        self.block_level.contains(&(s as *const Stmt))
    }

    /// Plans `f`, a tiled kernel the validator accepted.
    pub fn of(f: &Function) -> Result<LanePlan, String> {
        let u = Uniformity::of(f);
        let mut p = Planner {
            f,
            u: &u,
            block_level: HashSet::new(),
            homes: vec![HashSet::new(); f.vars.len()],
            lane_set: vec![false; f.vars.len()],
            block_set: vec![false; f.vars.len()],
            per_lane_results: vec![false; f.vars.len()],
            next_region: 0,
            lane_returns: false,
            lane_invariant: true,
        };
        p.classify(&f.body);
        p.exits(&f.body, false);
        p.list(&f.body);
        let mut storage = Vec::with_capacity(f.vars.len());
        for v in 0..f.vars.len() {
            let is_param = f.params.iter().any(|q| q.var == v);
            let s = if is_param || f.vars[v].ty.is_tile() {
                Storage::Block
            } else if p.per_lane_results[v] {
                Storage::PerLane
            } else if p.lane_set[v] && p.block_set[v] {
                return Err(format!(
                    "`{}` is set both by the whole block and by single threads; give the per-thread value its own variable",
                    f.vars[v].name.as_deref().unwrap_or("a temporary")
                ));
            } else if p.block_set[v] {
                Storage::Block
            } else if p.homes[v].len() <= 1 && !p.homes[v].contains(&BLOCK) {
                Storage::Local
            } else {
                Storage::PerLane
            };
            storage.push(s);
        }
        Ok(LanePlan {
            block_level: p.block_level,
            storage,
            lane_invariant: p.lane_invariant && !p.lane_returns,
            lane_returns: p.lane_returns,
        })
    }
}

/// The home of a variable occurrence in a block-level statement.
const BLOCK: usize = usize::MAX;

struct Planner<'a> {
    f: &'a Function,
    u: &'a Uniformity,
    block_level: HashSet<*const Stmt>,
    /// Per variable: the regions it occurs in ([`BLOCK`] for block-level statements).
    homes: Vec<HashSet<usize>>,
    /// Per variable: assigned by a lane-level statement.
    lane_set: Vec<bool>,
    /// Per variable: assigned by a block-level statement.
    block_set: Vec<bool>,
    /// Per variable: the per-lane result of a block-level statement (`untile`).
    per_lane_results: Vec<bool>,
    next_region: usize,
    lane_returns: bool,
    lane_invariant: bool,
}

impl Planner<'_> {
    /// Marks the block-level statements of `b` (and returns whether there is one).
    fn classify(&mut self, b: &Block) -> bool {
        let mut any = false;
        for s in b {
            let nested = match &s.kind {
                StmtKind::If { then, els, .. } => {
                    let a = self.classify(then);
                    self.classify(els) || a
                }
                StmtKind::For { body, .. } | StmtKind::Loop { body } => self.classify(body),
                _ => false,
            };
            let own = match &s.kind {
                StmtKind::Return { .. } => self.u.divergence(s).is_none(),
                _ => self.f.is_cooperative(s),
            };
            if nested || own {
                self.block_level.insert(s as *const Stmt);
                any = true;
            }
        }
        any
    }

    /// Marks a `break` or `continue` of a block-level loop block-level (it leaves the loop for
    /// the whole block; the validator made it uniform), and the control flow around it inside
    /// the loop; `block_loop`: whether the innermost loop around `b` is block-level.
    fn exits(&mut self, b: &Block, block_loop: bool) -> bool {
        let mut any = false;
        for s in b {
            let hit = match &s.kind {
                StmtKind::Break | StmtKind::Continue => block_loop,
                StmtKind::If { then, els, .. } => {
                    let a = self.exits(then, block_loop);
                    self.exits(els, block_loop) || a
                }
                StmtKind::For { body, .. } | StmtKind::Loop { body } => {
                    let inner = self.is_block(s);
                    self.exits(body, inner);
                    false
                }
                _ => false,
            };
            if hit {
                self.block_level.insert(s as *const Stmt);
                any = true;
            }
        }
        any
    }

    fn is_block(&self, s: &Stmt) -> bool {
        self.block_level.contains(&(s as *const Stmt))
    }

    /// Numbers the regions of `b` and records where variables occur.
    fn list(&mut self, b: &Block) {
        let mut region: Option<usize> = None;
        for s in b {
            if self.is_block(s) {
                region = None;
                self.block_stmt(s);
            } else {
                let r = *region.get_or_insert_with(|| {
                    self.next_region += 1;
                    self.next_region
                });
                self.lane_stmt(s, r);
            }
        }
    }

    fn block_stmt(&mut self, s: &Stmt) {
        s.kind.for_each_read(&mut |v| {
            self.homes[v].insert(BLOCK);
        });
        match &s.kind {
            StmtKind::Assign { dst, op, .. } => {
                self.homes[*dst].insert(BLOCK);
                let per_lane = matches!(op, Op::Builtin { builtin, .. } if builtin.lanes)
                    && !self.f.vars[*dst].ty.is_tile();
                if per_lane {
                    self.per_lane_results[*dst] = true;
                } else {
                    self.block_set[*dst] = true;
                }
            }
            StmtKind::If { then, els, .. } => {
                self.list(then);
                self.list(els);
            }
            StmtKind::For { var, body, .. } => {
                self.block_set[*var] = true;
                self.homes[*var].insert(BLOCK);
                self.list(body);
            }
            StmtKind::Loop { body } => self.list(body),
            _ => {}
        }
    }

    fn lane_stmt(&mut self, s: &Stmt, r: usize) {
        let mut reads = Vec::new();
        s.kind.for_each_read(&mut |v| reads.push(v));
        for v in reads {
            self.homes[v].insert(r);
        }
        match &s.kind {
            StmtKind::Assign { dst, op, .. } => {
                self.homes[*dst].insert(r);
                self.lane_set[*dst] = true;
                let varies = match op {
                    Op::Lane | Op::Func { .. } => true,
                    Op::Builtin { builtin, .. } => {
                        builtin.is_atomic()
                            || builtin.lanes
                            || builtin.name == "block_dim"
                            || builtin.grad == crate::builtins::Grad::Effect
                    }
                    _ => false,
                };
                if varies {
                    self.lane_invariant = false;
                }
            }
            StmtKind::Declare { var } => {
                self.homes[*var].insert(r);
                self.lane_set[*var] = true;
            }
            StmtKind::SetMember { var, .. } | StmtKind::SetElem { var, .. } => {
                self.homes[*var].insert(r);
                self.lane_set[*var] = true;
            }
            StmtKind::Print { .. } | StmtKind::Assert { .. } => self.lane_invariant = false,
            StmtKind::Return { .. } => self.lane_returns = true,
            StmtKind::If { then, els, .. } => {
                self.lane_block(then, r);
                self.lane_block(els, r);
            }
            StmtKind::For { var, body, .. } => {
                self.homes[*var].insert(r);
                self.lane_set[*var] = true;
                self.lane_block(body, r);
            }
            StmtKind::Loop { body } => self.lane_block(body, r),
            _ => {}
        }
    }

    fn lane_block(&mut self, b: &Block, r: usize) {
        for s in b {
            self.lane_stmt(s, r);
        }
    }
}

/// The variables the statements of a lane region read or assign (nested blocks included), in
/// first-occurrence order, and which of them it assigns.
pub fn region_vars(b: &[&Stmt]) -> (Vec<VarId>, HashSet<VarId>) {
    let mut order = Vec::new();
    let mut seen = HashSet::new();
    let mut set = HashSet::new();
    let mut note = |v: VarId, order: &mut Vec<VarId>| {
        if seen.insert(v) {
            order.push(v);
        }
    };
    let mut visit = |s: &Stmt| {
        s.kind.for_each_read(&mut |v| note(v, &mut order));
        match &s.kind {
            StmtKind::Assign { dst: v, .. }
            | StmtKind::Declare { var: v }
            | StmtKind::SetMember { var: v, .. }
            | StmtKind::SetElem { var: v, .. }
            | StmtKind::For { var: v, .. } => {
                note(*v, &mut order);
                set.insert(*v);
            }
            _ => {}
        }
    };
    for s in b {
        walk_stmts(std::slice::from_ref(*s), &mut visit);
    }
    (order, set)
}
