//! The reverse sweep of tile operations (tiled kernels), and which adjoint statements the
//! whole block runs together.
//!
//! A tile's adjoint is a tile of the same shape, held where the tile is (a block value on the
//! CPU, a shared-memory slot on CUDA). A tile operation's adjoint is a library call
//! (`adj_tile_<op>` in warp-core's `tile::adjoint` and wp_adjoint_tile.h) that every thread of
//! the block makes together, like the operation itself: it accumulates into the adjoints of
//! the tile operands directly ([`GradArg::Adj`]; no temporaries, which on CUDA would need slots
//! of their own), and into temporaries for scalar operands.
//!
//! **The uniform-operand rule.** A scalar operand of a tile operation (`s` in `t * s`) is the
//! same in every lane, and every lane computed it. Its adjoint from the whole tile is added
//! once for the block, into lane 0's adjoint: the CPU's block-level statements read and write
//! lane 0 of per-lane values, and CUDA guards the accumulation with `threadIdx.x == 0`. The
//! reverse of the lane code that computed `s` then runs in every lane, and the lanes other
//! than 0 pass on zero, so the operand's inputs receive the contribution exactly once.
//!
//! Order of a tile's adjoint statements: seed (`__r` is the tile's adjoint itself, a
//! reference on CUDA), the call, then the clear. The usual order (clear before the call) would
//! clear the seed it reads; this one is the same because a tile is never its own operand,
//! except in `tile_matmul(a, b, &mut acc)`, whose adjoint passes through uncleared.
//!
//! **Reassigned tiles** (in a loop, or `let mut`) are not pushed on the adjoint stack (a tile is
//! too large for a thread's stack). [`plan`] sorts them:
//! - a tile whose value no adjoint rule reads (an accumulator: `acc = acc + t`, lowered to
//!   `tmp = acc + t; acc = tmp`, or `tile_matmul(a, b, &mut acc)`; a tile only stored, summed,
//!   transposed) needs no history at all: the replay leaves its last value, which nothing in
//!   the sweep looks at;
//! - a tile computed once per iteration, at the top level of a loop body, from no other tile
//!   (`tile_load` from an array the kernel does not write, `tile(x)` of lane values, a constant
//!   tile), from operands that nothing later in the body reassigns, is *computed again* at the
//!   start of each reversed iteration (when the loop's variables and the lanes' values hold
//!   that iteration's values again);
//! - any other (a tile whose earlier values a product or a map needs, computed from other
//!   tiles: a layer loop's activations) is pushed before it is overwritten, each lane pushing
//!   the elements it owns on its own stack (`push_tile`, `adstack_push_tile`), and popped after
//!   its statement's adjoint.
//!
//! The accumulating `tile_matmul(a, b, &mut acc)` sets the tile it reads: the adjoint of `acc`
//! before it is the adjoint after it, so the seed is neither cleared nor accumulated into.
//! `tile_fft(&mut t)` and `tile_ifft(&mut t)` set the tile they read too: their adjoint call
//! gets the adjoint slot of `t` both as the seed and as the operand's adjoint, and replaces it
//! with the seed's adjoint transform (nothing earlier has added to the adjoint of `t` before
//! the transform, so replacing is accumulating into zero); the slot is not cleared after.
//! Being linear, they need no history of `t`: a `let mut t` that only the transforms, loads,
//! stores and sums read is never pushed.

use super::{at, AKind, AStmt, Arg, Cx, GradArg, GradSrc, TempLike};
use crate::builtins::Grad;
use crate::ir::*;
use proc_macro2::Span;

/// Whether `s` pushes or pops a tile (the whole block together).
pub fn tile_stack_op(f: &Function, s: &AStmt) -> bool {
    matches!(&s.kind, AKind::Push { var, .. } | AKind::Pop { var } if f.ty(*var).is_tile())
}

/// The tile rows with an adjoint, and what the builtins table says of each: the one list
/// the sweep (which refuses every other row that is not constant) and the docs read.
pub const TILE_ADJOINTS: &[(&str, &str)] = &[
    ("tile_load", "adjoint"),
    ("tile_store", "adjoint"),
    ("tile", "adjoint"),
    ("untile", "adjoint"),
    ("tile_extract", "adjoint"),
    ("tile_map", "adjoint"),
    (
        "tile_reduce",
        "adjoint (`add` only; Warp differentiates none)",
    ),
    ("tile_sum", "adjoint"),
    ("tile_min", "adjoint (to the first minimum)"),
    ("tile_max", "adjoint (to the first maximum)"),
    ("tile_transpose", "adjoint"),
    ("tile_broadcast", "adjoint"),
    (
        "tile_matmul",
        "adjoint (f16, bf16: adjoints of the operands' type, each an f32 chain rounded once)",
    ),
    (
        "tile_matmul_acc",
        "adjoint (f16, bf16: adjoints of the operands' type, each an f32 chain rounded once)",
    ),
    ("tile_reshape", "adjoint"),
    ("tile_squeeze", "adjoint"),
    ("tile_diag_add", "adjoint"),
    (
        "tile_lower_solve",
        "adjoint (into `L`'s lower triangle and `y`)",
    ),
    (
        "tile_upper_solve",
        "adjoint (into `U`'s upper triangle and `z`)",
    ),
    (
        "tile_cholesky_solve",
        "adjoint (into `L`'s lower triangle and `y`; Warp does not differentiate it)",
    ),
    (
        "tile_cholesky",
        "adjoint (with respect to `a`'s lower triangle, which it reads)",
    ),
    (
        "tile_scan_inclusive",
        "adjoint (suffix sums; Warp differentiates no scan)",
    ),
    (
        "tile_scan_exclusive",
        "adjoint (suffix sums; Warp differentiates no scan)",
    ),
    (
        "tile_scan_max_inclusive",
        "adjoint (to the first maximum so far; Warp differentiates no scan)",
    ),
    (
        "tile_scan_min_inclusive",
        "adjoint (to the first minimum so far; Warp differentiates no scan)",
    ),
    ("tile_view", "adjoint"),
    ("tile_assign", "adjoint"),
    ("tile_add_inplace", "adjoint"),
    ("tile_sub_inplace", "adjoint"),
    ("tile_fft", "adjoint (`tile_ifft` of the seed, in place)"),
    ("tile_ifft", "adjoint (`tile_fft` of the seed, in place)"),
    (
        "tile_full",
        "adjoint (the value gets the seed's sum; Warp drops it)",
    ),
    (
        "tile_astype",
        "adjoint (between floats; none to or from integers, as Warp)",
    ),
    (
        "tile_atomic_add",
        "adjoint (the tile gets the array's gradient over the window; the old values none, as Warp)",
    ),
];

/// What the builtins table says of tile row `name`'s gradient, `None` where backward through
/// it is refused.
pub fn tile_adjoint(name: &str) -> Option<&'static str> {
    TILE_ADJOINTS.iter().find(|r| r.0 == name).map(|r| r.1)
}

/// Whether the whole block runs `s` together (on the CPU: once for the block, outside the
/// lane loops), for a statement of the adjoint of tiled kernel `f`: a tile operation of the
/// replay, a tile adjoint call, the seeding, clearing or accumulating of a tile's adjoint, and
/// control flow around any of those.
pub fn is_block_level(f: &Function, s: &AStmt) -> bool {
    let tile = |v: &VarId| f.ty(*v).is_tile();
    match &s.kind {
        AKind::Assign {
            dst,
            value: super::Value::Op(op),
        } => f.is_cooperative_op(*dst, op),
        AKind::AdjCall { func, .. } => is_block_call(func),
        AKind::TileMapAdj { .. } | AKind::LaneAdj { .. } => true,
        AKind::Push { .. } | AKind::Pop { .. } => tile_stack_op(f, s),
        AKind::Seed(GradSrc::Adj { var, .. }) | AKind::ClearAdj { var, .. } => tile(var),
        AKind::Accum {
            to: super::AdjOf::Var { var, .. },
            ..
        } => tile(var),
        AKind::Scope(b) | AKind::RevLoop { body: b } | AKind::Loop { body: b, .. } => {
            b.iter().any(|s| is_block_level(f, s))
        }
        AKind::If { then, els, .. } => then.iter().chain(els).any(|s| is_block_level(f, s)),
        _ => false,
    }
}

/// Whether the library adjoint `func` is a tile operation's, which the block calls together
/// (every one but `t[i]`'s, which a lane calls for its own read).
pub fn is_block_call(func: &str) -> bool {
    func.starts_with("adj_tile") && !func.starts_with("adj_tile_extract")
}

/// How the sweep restores reassigned tiles (see the module docs): which tiles it computes
/// again in each reversed iteration; `overwritten` keeps only the tiles pushed on the stack.
pub(super) fn plan(f: &Function, overwritten: &mut [bool]) -> Vec<bool> {
    let mut recompute = vec![false; f.vars.len()];
    let mut assigned = vec![0usize; f.vars.len()];
    let mut needed = vec![false; f.vars.len()];
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Assign { dst, op, .. } = &s.kind {
            assigned[*dst] += 1;
            reads_value(op, *dst, &mut |v| needed[v] = true);
        }
    });
    let written = crate::analysis::written_params(f);
    let written: Vec<VarId> = written.iter().map(|k| f.params[*k].var).collect();
    let mut candidates = Vec::new();
    recomputable(f, &f.body, false, &written, &mut candidates);
    for t in f.tile_vars() {
        if !overwritten[t] {
            continue;
        }
        overwritten[t] = false;
        if !needed[t] {
            continue;
        }
        if assigned[t] == 1 && candidates.contains(&t) {
            recompute[t] = true;
            continue;
        }
        // Its history goes on the lanes' stacks.
        overwritten[t] = true;
    }
    recompute
}

/// The tile operands of `op` (the value of `dst`) whose values its adjoint reads: the
/// operands of products, quotients, maps, extrema and matmuls (not the accumulator of
/// `tile_matmul(a, b, &mut c)`); conservatively every tile operand of an operation not listed
/// as reading none.
fn reads_value(op: &Op, dst: VarId, out: &mut dyn FnMut(VarId)) {
    match op {
        Op::Binary(BinOp::Add | BinOp::Sub, ..) | Op::Unary(UnOp::Neg, _) | Op::Copy(_) => {}
        Op::TileReduce {
            f: TileFn::Op(BinOp::Add),
            ..
        } => {}
        Op::Builtin { builtin, args } => match builtin.name {
            "tile_store"
            | "tile_sum"
            | "tile_transpose"
            | "tile_broadcast"
            | "tile_extract"
            | "untile"
            | "tile_load"
            | "tile"
            | "tile_scan_inclusive"
            | "tile_scan_exclusive"
            | "tile_fft"
            | "tile_ifft"
            | "tile_full"
            | "tile_astype"
            | "tile_atomic_add" => {}
            // The windows' adjoints move adjoints around; they read no tile's value.
            "tile_view"
            | "tile_assign"
            | "tile_add_inplace"
            | "tile_sub_inplace"
            | "tile_bit_and_inplace"
            | "tile_bit_or_inplace"
            | "tile_bit_xor_inplace" => {}
            "tile_matmul_acc" => args.iter().filter(|a| **a != dst).for_each(|a| out(*a)),
            _ => args.iter().for_each(|a| out(*a)),
        },
        op => op.for_each_read(out),
    }
}

/// The tiles a loop body (`in_loop`) computes at its top level from no other tile: by a
/// `tile_load` from an array not in `written`, `tile(x)` of lane values, a constant tile; none
/// of whose operands the rest of the body reassigns, so that at the end of an iteration they
/// still hold what the tile was computed from.
fn recomputable(f: &Function, b: &[Stmt], in_loop: bool, written: &[VarId], out: &mut Vec<VarId>) {
    for (k, s) in b.iter().enumerate() {
        match &s.kind {
            StmtKind::Assign {
                dst,
                op: op @ Op::Builtin { builtin, args },
                ..
            } if in_loop && f.ty(*dst).is_tile() && !builtin.is_atomic() => {
                let mut from_tiles_or_written = false;
                op.for_each_read(&mut |v| {
                    from_tiles_or_written |= f.ty(v).is_tile() || written.contains(&v)
                });
                let mut later = Vec::new();
                walk_stmts(&b[k + 1..], &mut |s| match &s.kind {
                    StmtKind::Assign { dst, .. } => later.push(*dst),
                    StmtKind::For { var, .. } => later.push(*var),
                    StmtKind::SetMember { var, .. } | StmtKind::SetElem { var, .. } => {
                        later.push(*var)
                    }
                    _ => {}
                });
                if !from_tiles_or_written && !args.iter().any(|a| later.contains(a)) {
                    out.push(*dst);
                }
            }
            StmtKind::If { then, els, .. } => {
                recomputable(f, then, false, written, out);
                recomputable(f, els, false, written, out);
            }
            StmtKind::For { body, .. } | StmtKind::Loop { body } => {
                let (_, body) = super::replay::split_exit(body);
                recomputable(f, body, true, written, out);
            }
            _ => {}
        }
    }
}

impl Cx<'_> {
    /// The recomputations of the tiles at the top level of loop body `b` that the sweep computes again, which start each reversed
    /// iteration (see [`plan`]).
    pub(super) fn recomputed(&self, b: &[Stmt]) -> Vec<AStmt> {
        let mut out = Vec::new();
        for s in b {
            if let StmtKind::Assign { dst, op, .. } = &s.kind {
                if self.recompute[*dst] {
                    let value = super::Value::Op(op.clone());
                    out.push(at(AKind::Assign { dst: *dst, value }, s.span));
                }
            }
        }
        out
    }

    /// The reverse of `dst = op` in a tiled kernel when `op` is a tile operation (or `dst` a
    /// tile); `None` for anything else, which the ordinary rules handle. A reassigned `dst`
    /// gets its old value back after the adjoint (a tile from the lanes' stacks, see [`plan`]).
    pub(super) fn reverse_tile(&mut self, dst: VarId, op: &Op, sp: Span) -> Option<Vec<AStmt>> {
        let mut out = self.reverse_tile_op(dst, op, sp)?;
        let store = matches!(op, Op::Builtin { builtin, .. } if builtin.name == "tile_store");
        if self.overwritten[dst] && !store {
            out.push(super::pop(dst, sp));
        }
        Some(out)
    }

    fn reverse_tile_op(&mut self, dst: VarId, op: &Op, sp: Span) -> Option<Vec<AStmt>> {
        let f = self.f;
        let tile = |v: VarId| f.ty(v).is_tile();
        let tile_op = match op {
            Op::Builtin { builtin, .. } => builtin.is_tile(),
            Op::TileMap { .. } | Op::TileReduce { .. } => true,
            _ => tile(dst),
        };
        if !tile_op {
            return None;
        }
        let mut b = Vec::new();
        // The rows whose reverse is not seeded from the result's adjoint tile.
        if let Op::Builtin { builtin, args } = op {
            let name = builtin.name;
            if builtin.grad != Grad::Zero && tile_adjoint(name).is_none() {
                self.refuse(name);
                return Some(Vec::new());
            }
            // Tiles of vectors (complex values) have the adjoints of the rows made for them
            // (and of `+ -` and scaling, which are not rows); the other rules are written for
            // scalar elements.
            let vector = |v: &VarId| f.ty(*v).is_vector_tile();
            let for_vectors = matches!(
                name,
                "tile_load" | "tile_store" | "tile_extract" | "tile_fft" | "tile_ifft"
            );
            if builtin.grad != Grad::Zero
                && !for_vectors
                && (vector(&dst) || args.iter().any(vector))
            {
                self.refuse(&format!("`{name}` on tiles of vectors"));
                return Some(Vec::new());
            }
            match name {
                // The store hands each written element's gradient to the tile.
                "tile_store" => {
                    if !self.diff(args[1]) {
                        return Some(b);
                    }
                    b.push(at(AKind::Seed(GradSrc::Zero(dst)), sp));
                    let func = format!("adj_tile_store{}", args.len() - 2);
                    self.tile_call(&mut b, &func, args, true, sp);
                    return Some(vec![at(AKind::Scope(b), sp)]);
                }
                // A lane's read of one element.
                "tile_extract" => {
                    if !self.diff(dst) {
                        return Some(b);
                    }
                    b.extend(super::sweep::seed_from(dst, Vec::new(), sp));
                    let func = format!("adj_tile_extract{}", args.len() - 1);
                    self.tile_call(&mut b, &func, args, true, sp);
                    return Some(vec![at(AKind::Scope(b), sp)]);
                }
                // `c += a b`: the accumulator's adjoint passes through.
                "tile_matmul_acc" => {
                    let (a, bb, c) = (args[0], args[1], args[2]);
                    if a == c || bb == c {
                        self.refuse("a `tile_matmul` accumulating into one of its operands");
                        return Some(Vec::new());
                    }
                    if self.diff(c) {
                        let seed = GradSrc::Adj {
                            var: c,
                            path: Vec::new(),
                        };
                        b.push(at(AKind::Seed(seed), sp));
                        self.tile_call(&mut b, "adj_tile_matmul", &[a, bb], false, sp);
                    }
                    return Some(vec![at(AKind::Scope(b), sp)]);
                }
                // `d = op(d[window], s)` sets the tile it reads, as the accumulating matmul:
                // one adjoint slot is `d`'s after and before; the library call hands the
                // window's adjoint to `s` and, for `tile_assign`, clears it there.
                "tile_assign" | "tile_add_inplace" | "tile_sub_inplace" => {
                    let (d, src) = (args[0], args[1]);
                    if d == src {
                        self.refuse(&format!("a `{name}` of a tile into itself"));
                        return Some(Vec::new());
                    }
                    if self.diff(d) {
                        let seed = GradSrc::Adj {
                            var: d,
                            path: Vec::new(),
                        };
                        b.push(at(AKind::Seed(seed), sp));
                        let func = format!("adj_{name}{}", args.len() - 2);
                        self.tile_call(&mut b, &func, args, true, sp);
                    }
                    return Some(vec![at(AKind::Scope(b), sp)]);
                }
                // `t` transformed in place (`t = tile_fft(t)`): the adjoint of `t` before is
                // the adjoint transform of the adjoint after, which replaces it in its slot.
                // Linear: the value of `t` is not read (so the replay need not keep it).
                "tile_fft" | "tile_ifft" => {
                    let t = args[0];
                    if self.diff(t) {
                        let seed = GradSrc::Adj {
                            var: t,
                            path: Vec::new(),
                        };
                        b.push(at(AKind::Seed(seed), sp));
                        self.tile_call(&mut b, &format!("adj_{name}"), &[t], false, sp);
                    }
                    return Some(vec![at(AKind::Scope(b), sp)]);
                }
                "untile" => {
                    if self.diff(dst) {
                        let (lanes, tile) = (dst, args[0]);
                        let func = "adj_untile";
                        b.push(at(AKind::LaneAdj { func, lanes, tile }, sp));
                    }
                    return Some(b);
                }
                _ => {}
            }
        }
        // The rest: seeded from `dst`'s adjoint tile, which is cleared at the end.
        if !self.diff(dst) {
            return Some(b);
        }
        // The lowering gives every operation a fresh result (`acc = acc + t` is `tmp = acc + t;
        // acc = tmp`), so only the accumulating matmul (above) reads the tile it sets; another
        // one would read and clear one adjoint slot as both seed and operand.
        let mut reads_dst = false;
        op.for_each_read(&mut |v| reads_dst |= v == dst);
        if reads_dst {
            self.refuse("an operation that reads the tile it sets");
            return Some(Vec::new());
        }
        let seed = GradSrc::Adj {
            var: dst,
            path: Vec::new(),
        };
        b.push(at(AKind::Seed(seed), sp));
        match op {
            Op::Builtin { builtin, args } => {
                let name = builtin.name;
                match (name, builtin.grad) {
                    (_, Grad::Zero) => {}
                    ("tile", _) => {
                        // Kernel parameters' adjoints go nowhere.
                        let (lanes, tile) = (args[0], dst);
                        if self.diff(lanes) && !f.params.iter().any(|p| p.var == lanes) {
                            let func = "adj_tile_lanes";
                            b.push(at(AKind::LaneAdj { func, lanes, tile }, sp));
                        }
                    }
                    ("tile_load", _) => {
                        let func = format!("adj_tile_load{}", args.len() - 1);
                        self.tile_call(&mut b, &func, args, true, sp);
                    }
                    // The value tile gets the array's gradient over the window (the update
                    // added it there); the seed, the adjoint of the old values, goes nowhere,
                    // as Warp's `adj_ret` (the kernel cannot read them: see `replay`).
                    ("tile_atomic_add", _) => {
                        let func = format!("adj_tile_atomic_add{}", args.len() - 2);
                        self.tile_call(&mut b, &func, args, true, sp);
                    }
                    (
                        "tile_sum" | "tile_min" | "tile_max" | "tile_transpose" | "tile_matmul",
                        _,
                    ) => {
                        let func = format!("adj_{name}");
                        self.tile_call(&mut b, &func, args, false, sp);
                    }
                    // A reshape's adjoint is the same copy the other way.
                    ("tile_reshape" | "tile_squeeze", _) => {
                        self.tile_call(&mut b, "adj_tile_reshape", args, false, sp);
                    }
                    // A value every lane computed, or a tile whose elements convert back
                    // (nothing to do for an operand that carries no gradient, such as an
                    // integer tile or a constant; a kernel parameter's adjoint goes nowhere).
                    ("tile_full" | "tile_astype", _) => {
                        let param = f.params.iter().any(|p| p.var == args[0]);
                        if self.diff(args[0]) && !param {
                            let func = format!("adj_{name}");
                            self.tile_call(&mut b, &func, &args[..1], false, sp);
                        }
                    }
                    ("tile_diag_add", _) => {
                        self.tile_call(&mut b, "adj_tile_diag_add", args, false, sp);
                    }
                    // The linear algebra recomputes the solution or the factor it needs from
                    // its operands; the max and min scans their running extrema.
                    (
                        "tile_lower_solve"
                        | "tile_upper_solve"
                        | "tile_cholesky_solve"
                        | "tile_cholesky"
                        | "tile_scan_inclusive"
                        | "tile_scan_exclusive"
                        | "tile_scan_max_inclusive"
                        | "tile_scan_min_inclusive",
                        _,
                    ) => {
                        let func = format!("adj_{name}");
                        self.tile_call(&mut b, &func, args, false, sp);
                    }
                    // The copy of a window: its adjoint adds into the window's.
                    ("tile_view", _) => {
                        let func = format!("adj_tile_view{}", args.len() - 1);
                        self.tile_call(&mut b, &func, args, true, sp);
                    }
                    ("tile_broadcast", _) => {
                        let rank = |v: VarId| match f.ty(v) {
                            crate::types::Ty::Tile(_, d) => d.len(),
                            _ => 0,
                        };
                        let func = format!("adj_tile_broadcast{}{}", rank(args[0]), rank(dst));
                        self.tile_call(&mut b, &func, args, false, sp);
                    }
                    _ => {
                        self.refuse(name);
                        return Some(Vec::new());
                    }
                }
            }
            Op::TileMap { f: g, args } if args.iter().any(|a| !tile(*a)) => {
                if !self.tile_map_consts_adj(&mut b, *g, args, dst, sp) {
                    return Some(Vec::new());
                }
            }
            Op::TileMap { f: g, args } => match g {
                TileFn::Builtin(bi) if bi.grad == Grad::Zero => {}
                TileFn::Builtin(bi) if bi.grad != Grad::Adjoint => {
                    self.refuse(&format!("tile_map({}, ..)", bi.name));
                    return Some(Vec::new());
                }
                // A user func: its own adjoint on each element. Between float tiles only: a
                // result of integers carries no gradient (as in Warp), and an integer operand
                // beside float ones would need an adjoint tile of integers.
                TileFn::Func(_) => {
                    let float = |v: VarId| matches!(f.ty(v), crate::types::Ty::Tile(e, _) if matches!(**e, crate::types::Ty::Scalar(s) if s.is_float()));
                    if !float(dst) {
                    } else if !args.iter().all(|a| float(*a)) {
                        self.refuse("tile_map of a func over integer and float tiles together");
                        return Some(Vec::new());
                    } else {
                        let grads = args.iter().map(|a| GradArg::Adj(*a)).collect();
                        let (f, values) = (*g, args.clone());
                        b.push(at(
                            AKind::TileMapAdj {
                                f,
                                values,
                                grads,
                                dst,
                            },
                            sp,
                        ));
                    }
                }
                _ => {
                    let grads = args.iter().map(|a| GradArg::Adj(*a)).collect();
                    let (f, values) = (*g, args.clone());
                    b.push(at(
                        AKind::TileMapAdj {
                            f,
                            values,
                            grads,
                            dst,
                        },
                        sp,
                    ));
                }
            },
            // Warp differentiates no other reduction either; a silent zero would be a wrong
            // gradient.
            Op::TileReduce { f: g, arg } => {
                // Warp differentiates no `tile_reduce` of a user func either: its adjoint
                // would replay the reduction tree, keeping every partial. A result that
                // carries no gradient (integers, or values of no differentiable input) needs
                // no adjoint, so only a differentiable one is refused.
                if let TileFn::Func(k) = g {
                    if !self.diff(dst) {
                        return Some(Vec::new());
                    }
                    let name = f.callees.get(*k).map_or_else(
                        || "the func".to_string(),
                        |p| {
                            quote::ToTokens::to_token_stream(p)
                                .to_string()
                                .replace(' ', "")
                        },
                    );
                    self.refuse(&format!("`tile_reduce({name}, ..)` (a reduction with a user #[func]; Warp differentiates none: reduce with `add` or `tile_sum`, or keep it out of the differentiated kernel)"));
                    return Some(Vec::new());
                }
                if !matches!(g, TileFn::Op(BinOp::Add)) {
                    self.refuse("tile_reduce with anything but `add`");
                    return Some(Vec::new());
                }
                self.tile_call(&mut b, "adj_tile_sum", &[*arg], false, sp);
            }
            Op::Binary(o, l, r) => {
                let name = match o {
                    BinOp::Add => "add",
                    BinOp::Sub => "sub",
                    BinOp::Mul => "mul",
                    BinOp::Div => "div",
                    _ => {
                        self.refuse(&format!("`{}` on tiles", o.symbol()));
                        return Some(Vec::new());
                    }
                };
                let form = match (tile(*l), tile(*r)) {
                    (true, true) => "tt",
                    (true, false) => "ts",
                    _ => "st",
                };
                let func = format!("adj_tile_{name}_{form}");
                self.tile_call(&mut b, &func, &[*l, *r], false, sp);
            }
            Op::Unary(UnOp::Neg, a) => self.tile_call(&mut b, "adj_tile_neg", &[*a], false, sp),
            Op::Copy(a) => self.accum(&mut b, *a, Vec::new(), GradSrc::Seed, sp),
            _ => {
                self.refuse("this tile operation");
                return Some(Vec::new());
            }
        }
        let path = Vec::new();
        b.push(at(AKind::ClearAdj { var: dst, path }, sp));
        Some(vec![at(AKind::Scope(b), sp)])
    }

    /// `func(inputs.., adjoints.., __r)`: a tile input's adjoint directly, an array's gradient,
    /// a scalar's through a temporary that is then accumulated (see the uniform-operand rule).
    fn tile_call(
        &self,
        out: &mut Vec<AStmt>,
        func: &str,
        inputs: &[VarId],
        faults: bool,
        sp: Span,
    ) {
        let (mut values, mut grads) = (Vec::new(), Vec::new());
        let mut temps = Vec::new();
        for (k, &v) in inputs.iter().enumerate() {
            if self.is_array(v) {
                values.push(Arg::Array(v));
                grads.push(GradArg::ArrayGrad(v));
                continue;
            }
            values.push(Arg::Value(v));
            if self.f.ty(v).is_tile() && self.diff(v) {
                grads.push(GradArg::Adj(v));
            } else {
                let like = TempLike::Var(v);
                out.push(at(AKind::ZeroTemp { k, like }, sp));
                grads.push(GradArg::Temp(k));
                temps.push((k, v));
            }
        }
        let func = func.to_string();
        let call = AKind::AdjCall {
            func,
            values,
            grads,
            faults,
        };
        out.push(at(call, sp));
        for (k, v) in temps {
            if !self.f.ty(v).is_tile() {
                self.accum(out, v, Vec::new(), GradSrc::Temp(k), sp);
            }
        }
    }

    /// The adjoint of `tile_map` with scalar constants (broadcast to every element) into `b`;
    /// false where it is refused. The constants' adjoints are temporaries the map's adjoint
    /// fills (each element's contribution, summed in the reductions' order), then added to
    /// the constants' own. An integer constant's temporary stays zero and is dropped; a result
    /// that carries no gradient needs nothing.
    fn tile_map_consts_adj(
        &mut self,
        b: &mut Vec<AStmt>,
        g: TileFn,
        args: &[VarId],
        dst: VarId,
        sp: Span,
    ) -> bool {
        use crate::types::Ty;
        let f = self.f;
        let tile = |v: VarId| f.ty(v).is_tile();
        if !self.diff(dst) {
            return true;
        }
        let float_tile = |v: VarId| matches!(f.ty(v), Ty::Tile(e, _) if matches!(**e, Ty::Scalar(s) if s.is_float()));
        match g {
            TileFn::Builtin(bi) if bi.grad == Grad::Zero => return true,
            TileFn::Builtin(bi) if bi.grad != Grad::Adjoint => {
                self.refuse(&format!("tile_map({}, ..)", bi.name));
                return false;
            }
            // As without constants: an integer tile beside float ones would need an adjoint
            // tile of integers.
            TileFn::Func(_) if !args.iter().filter(|a| tile(**a)).all(|a| float_tile(*a)) => {
                self.refuse("tile_map of a func over integer and float tiles together");
                return false;
            }
            _ => {}
        }
        let mut grads = Vec::new();
        for (k, &a) in args.iter().enumerate() {
            if tile(a) {
                grads.push(GradArg::Adj(a));
            } else {
                let like = TempLike::Var(a);
                b.push(at(AKind::ZeroTemp { k, like }, sp));
                grads.push(GradArg::Temp(k));
            }
        }
        let values = args.to_vec();
        b.push(at(
            AKind::TileMapAdj {
                f: g,
                values,
                grads,
                dst,
            },
            sp,
        ));
        for (k, &a) in args.iter().enumerate() {
            if !tile(a) && matches!(f.ty(a), Ty::Scalar(s) if s.is_float()) {
                self.accum(b, a, Vec::new(), GradSrc::Temp(k), sp);
            }
        }
        true
    }

    /// Records that backward through `what` is not supported yet.
    fn refuse(&mut self, what: &str) {
        if self.error.is_none() {
            self.error = Some(format!(
                "uses tiles, and backward through {what} is not supported yet"
            ));
        }
    }
}
