//! The reverse sweep: each statement's adjoint, last statement first.

use super::replay::split_exit;
use super::{
    at, if_fast, pop, AKind, AStmt, AdjOf, Arg, Cond, Cx, GradArg, GradSrc, Index, TempLike,
};
use super::{TypeOf, Value};
use crate::builtins::Grad;
use crate::ir::*;
use crate::types::Ty;
use proc_macro2::Span;

/// `__r = adj_var.path; adj_var.path = 0`: the seed of a scope, taken from an adjoint.
pub(super) fn seed_from(var: VarId, path: Vec<String>, sp: Span) -> [AStmt; 2] {
    let from = GradSrc::Adj {
        var,
        path: path.clone(),
    };
    [
        at(AKind::Seed(from), sp),
        at(AKind::ClearAdj { var, path }, sp),
    ]
}

impl Cx<'_> {
    /// The reverse sweep of `b`.
    pub(super) fn reverse(&mut self, b: &[Stmt], in_loop: bool) -> Vec<AStmt> {
        let mut out = Vec::new();
        for s in b.iter().rev() {
            let sp = s.span;
            match &s.kind {
                StmtKind::Assign { dst, op, .. } => self.reverse_assign(&mut out, *dst, op, sp),
                StmtKind::Store {
                    array,
                    index,
                    value,
                } => {
                    if !self.diff(*value) {
                        continue;
                    }
                    let (array, like) = (*array, *value);
                    let take = |get: bool| {
                        let index = Index::At(index.clone());
                        let from = if get {
                            GradSrc::Get { array, index, like }
                        } else {
                            GradSrc::Take { array, index, like }
                        };
                        let mut b = Vec::new();
                        self.accum(&mut b, like, Vec::new(), from, sp);
                        b
                    };
                    // A deferred clear (`Policy::defer_write_only_clear`) only reads the
                    // gradient of the element the thread owns.
                    if self.deferred_clear.contains(&array) && self.tid_access(array, index) {
                        out.push(at(if_fast(take(true), take(false)), sp));
                    } else {
                        out.extend(take(false));
                    }
                }
                StmtKind::SetMember { var, path, value } => {
                    let mut b = seed_from(*var, path.clone(), sp).to_vec();
                    self.accum(&mut b, *value, Vec::new(), GradSrc::Seed, sp);
                    b.push(pop(*var, sp));
                    out.push(at(AKind::Scope(b), sp));
                }
                // `var = var with element index set to value`: the element's adjoint goes to
                // the value and is cleared (the store replaced it), then the old array is
                // restored.
                StmtKind::SetElem { var, index, value } => {
                    let (var, index) = (*var, *index);
                    let mut b = Vec::new();
                    if self.diff(var) {
                        b.push(at(AKind::Seed(GradSrc::AdjElem { var, index }), sp));
                        b.push(at(AKind::ClearAdjElem { var, index }, sp));
                        self.accum(&mut b, *value, Vec::new(), GradSrc::Seed, sp);
                    }
                    b.push(pop(var, sp));
                    out.push(at(AKind::Scope(b), sp));
                }
                StmtKind::If { cond, then, els } => {
                    let cond = match self.records(*cond, in_loop) {
                        true => Cond::Popped,
                        false => Cond::Var(*cond),
                    };
                    let (then, els) = (self.reverse(then, in_loop), self.reverse(els, in_loop));
                    out.push(at(AKind::If { cond, then, els }, sp));
                }
                StmtKind::For { body, .. } | StmtKind::Loop { body } => {
                    let (_, body) = split_exit(body);
                    let mut b = self.recomputed(body);
                    b.extend(self.reverse(body, true));
                    // A `for` restores its variable after each reversed iteration.
                    if let StmtKind::For { var, .. } = &s.kind {
                        b.push(pop(*var, sp));
                    }
                    out.push(at(AKind::RevLoop { body: b }, sp));
                }
                _ => {}
            }
        }
        out
    }

    /// Reverse of `dst = op`: take `dst`'s adjoint, restore `dst`'s old value, accumulate the
    /// operands' adjoints.
    fn reverse_assign(&mut self, out: &mut Vec<AStmt>, dst: VarId, op: &Op, sp: Span) {
        if self.f.tiled.is_some() {
            if let Some(b) = self.reverse_tile(dst, op, sp) {
                out.extend(b);
                return;
            }
        }
        let restore = self.overwritten[dst].then(|| pop(dst, sp));
        if let Op::Func { path, args } = op {
            let func = self.callee(path);
            // The func's adjoint runs even when its result carries no gradient: it may have
            // read arrays.
            let mut b = if self.diff(dst) {
                seed_from(dst, Vec::new(), sp).to_vec()
            } else {
                vec![at(AKind::Seed(GradSrc::Zero(dst)), sp)]
            };
            b.extend(restore);
            // A value argument's adjoint goes to a temporary of the func's parameter type.
            let mut grads = Vec::new();
            for (k, &arg) in args.iter().enumerate() {
                if self.is_array(arg) {
                    grads.push(GradArg::ArrayGrad(arg));
                } else {
                    let like = TempLike::Param { func, k, arg };
                    b.push(at(AKind::ZeroTemp { k, like }, sp));
                    grads.push(GradArg::Temp(k));
                }
            }
            let values = args.clone();
            b.push(at(
                AKind::FuncAdj {
                    func,
                    values,
                    grads,
                },
                sp,
            ));
            for (k, a) in args.iter().enumerate() {
                self.accum(&mut b, *a, Vec::new(), GradSrc::Temp(k), sp);
            }
            out.push(at(AKind::Scope(b), sp));
            return;
        }
        if !self.diff(dst) {
            out.extend(restore);
            return;
        }
        // `S { a: x, ..base }`: each named field's adjoint goes to its value and is cleared,
        // then what is left (the fields copied) goes to the base.
        if let Op::Construct {
            ctor: Ctor::Fields {
                names, base: true, ..
            },
            args,
            ..
        } = op
        {
            let mut b = Vec::new();
            for (name, v) in names.iter().zip(args) {
                let path = vec![name.to_string()];
                let from = GradSrc::Adj {
                    var: dst,
                    path: path.clone(),
                };
                self.accum(&mut b, *v, Vec::new(), from, sp);
                b.push(at(AKind::ClearAdj { var: dst, path }, sp));
            }
            b.extend(seed_from(dst, Vec::new(), sp));
            b.extend(restore);
            self.accum(&mut b, args[names.len()], Vec::new(), GradSrc::Seed, sp);
            out.push(at(AKind::Scope(b), sp));
            return;
        }
        let acc = self.accumulate(op, sp);
        if acc.is_empty() {
            let path = Vec::new();
            out.push(at(AKind::ClearAdj { var: dst, path }, sp));
            out.extend(restore);
            return;
        }
        let mut b = seed_from(dst, Vec::new(), sp).to_vec();
        b.extend(restore);
        b.extend(acc);
        out.push(at(AKind::Scope(b), sp));
    }

    fn tid_access(&self, array: VarId, index: &[VarId]) -> bool {
        crate::analysis::is_tid_access(self.f, &self.tid, array, index)
    }

    /// `adj_<func>(inputs.., __g.., __r)` (an array input's gradient in place of its
    /// temporary), then each temporary into its input's adjoint; `faults`: see
    /// [`AKind::AdjCall`].
    fn call(&self, out: &mut Vec<AStmt>, func: &str, inputs: &[VarId], faults: bool, sp: Span) {
        let (mut values, mut grads) = (Vec::new(), Vec::new());
        for (k, &v) in inputs.iter().enumerate() {
            if self.is_array(v) {
                values.push(Arg::Array(v));
                grads.push(GradArg::ArrayGrad(v));
            } else {
                let like = TempLike::Var(v);
                out.push(at(AKind::ZeroTemp { k, like }, sp));
                values.push(Arg::Value(v));
                grads.push(GradArg::Temp(k));
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
        for (k, v) in inputs.iter().enumerate() {
            self.accum(out, *v, Vec::new(), GradSrc::Temp(k), sp);
        }
    }

    /// The adjoint of `atomic_<op>(array, index.., value)`: the gradient at the index is the
    /// seed of the value's adjoint.
    fn atomic(&mut self, out: &mut Vec<AStmt>, name: &str, args: &[VarId], sp: Span) {
        let (array, value) = (args[0], args[args.len() - 1]);
        if !self.diff(value) {
            return;
        }
        let index = args[1..args.len() - 1].to_vec();
        let (at_index, like) = (Index::At(index.clone()), value);
        let mut b = vec![at(
            AKind::Seed(GradSrc::Get {
                array,
                index: at_index,
                like,
            }),
            sp,
        )];
        let (faults, grads) = (false, vec![GradArg::Adj(value)]);
        let call = |func: &str, values| AKind::AdjCall {
            func: func.into(),
            values,
            grads: grads.clone(),
            faults,
        };
        match name {
            "atomic_add" => self.accum(&mut b, value, Vec::new(), GradSrc::Seed, sp),
            "atomic_sub" => b.push(at(call("adj_neg", vec![Arg::Value(value)]), sp)),
            // atomic_min/atomic_max: to the value if it won, that is, if it is what the array
            // holds after the launch.
            _ => {
                let Ty::Array(elem, _) = self.f.ty(array).clone() else {
                    self.error = Some("internal: an atomic update of no array".into());
                    return;
                };
                let load = Value::Op(Op::Load { array, index });
                let cur = self.fresh(*elem, Some(TypeOf::Value(load.clone())));
                b.push(at(
                    AKind::Assign {
                        dst: cur,
                        value: load,
                    },
                    sp,
                ));
                let values = vec![Arg::Value(cur), Arg::Value(value)];
                b.push(at(call("adj_atomic_extreme", values), sp));
            }
        }
        out.push(at(AKind::Scope(b), sp));
    }

    /// Adds the seed (the adjoint of `op`'s result) into the adjoints of `op`'s operands.
    fn accumulate(&mut self, op: &Op, sp: Span) -> Vec<AStmt> {
        let mut out = Vec::new();
        let seed = |out: &mut Vec<AStmt>, v: VarId, from: GradSrc| {
            self.accum(out, v, Vec::new(), from, sp);
        };
        match op {
            Op::Copy(a) => seed(&mut out, *a, GradSrc::Seed),
            Op::Unary(UnOp::Neg, a) => self.call(&mut out, "adj_neg", &[*a], false, sp),
            Op::Binary(o, a, b) => {
                if let Some(f) = o.adjoint_fn() {
                    self.call(&mut out, f, &[*a, *b], false, sp);
                }
            }
            Op::Cast(a, _) => {
                if self.diff(*a) {
                    let like = TempLike::Var(*a);
                    out.push(at(AKind::ZeroTemp { k: 0, like }, sp));
                    let (func, values) = ("adj_cast".into(), Vec::new());
                    let (grads, faults) = (vec![GradArg::Temp(0)], false);
                    let call = AKind::AdjCall {
                        func,
                        values,
                        grads,
                        faults,
                    };
                    out.push(at(call, sp));
                    seed(&mut out, *a, GradSrc::Temp(0));
                }
            }
            Op::Builtin { builtin, args } => match builtin.grad {
                // AtomicNone: only integer updates whose result is unused get here
                // (`analysis::atomic_without_adjoint`): nothing to propagate.
                Grad::Zero | Grad::AtomicNone | Grad::Effect => {}
                Grad::Adjoint => {
                    let func = format!("adj_{}", builtin.name);
                    self.call(&mut out, &func, args, builtin.faults(), sp)
                }
                Grad::Atomic => self.atomic(&mut out, builtin.name, args, sp),
                Grad::NotYet => {
                    unreachable!("`build` refuses a kernel that calls `{}`", builtin.name)
                }
            },
            Op::Load { array, index } => out.push(at(self.load(*array, index, sp), sp)),
            Op::Member(v, m) => self.accum(&mut out, *v, vec![m.clone()], GradSrc::Seed, sp),
            Op::Index { array, index } => {
                if self.diff(*array) {
                    let (var, index) = (*array, *index);
                    let to = AdjOf::Elem { var, index };
                    out.push(at(
                        AKind::Accum {
                            to,
                            from: GradSrc::Seed,
                        },
                        sp,
                    ));
                }
            }
            // A tuple: element k of the seed to the k-th value.
            Op::Tuple(args) => {
                for (k, v) in args.iter().enumerate() {
                    seed(&mut out, *v, GradSrc::SeedLane(k.to_string()));
                }
            }
            // A local array's literal: element k of the seed to the k-th value; a repeat: the
            // sum of the seed's elements to the repeated value.
            Op::Construct {
                ty: Ty::LocalArray(..),
                ctor,
                args,
            } => match ctor {
                Ctor::Splat => seed(&mut out, args[0], GradSrc::ElemSum),
                _ => {
                    for (k, v) in args.iter().enumerate() {
                        seed(&mut out, *v, GradSrc::SeedElem(k));
                    }
                }
            },
            // A struct literal (its `..base` form is `reverse_assign`'s): field k of the
            // seed to the k-th value.
            Op::Construct {
                ctor: Ctor::Fields { names, .. },
                args,
                ..
            } => {
                for (name, v) in names.iter().zip(args) {
                    seed(&mut out, *v, GradSrc::SeedLane(name.to_string()));
                }
            }
            Op::Construct { ty, ctor, args } => {
                let lanes: &[&str] = match ty {
                    Ty::Vector(..) | Ty::Quat(_) => &["x", "y", "z", "w"],
                    Ty::Matrix(..) => &["x_axis", "y_axis", "z_axis", "w_axis"],
                    Ty::SpatialMatrix(_) | Ty::MatRC(..) => &["0", "1", "2", "3", "4", "5"],
                    _ => &[],
                };
                match (ctor, ty) {
                    (Ctor::Components, _) => {
                        for (v, l) in args.iter().zip(lanes) {
                            seed(&mut out, *v, GradSrc::SeedLane(l.to_string()));
                        }
                    }
                    // from_diagonal(v): the diagonal of the adjoint.
                    (Ctor::Splat, Ty::Matrix(_, n)) => {
                        let s = args[0];
                        if matches!(self.f.ty(s), Ty::Vector(..)) {
                            let comps = ["x", "y", "z", "w"];
                            let entries = (0..*n as usize)
                                .map(|k| (lanes[k].to_string(), comps[k].to_string()))
                                .collect();
                            let vector = self.f.ty(s).clone();
                            seed(&mut out, s, GradSrc::Diagonal { vector, entries });
                        }
                    }
                    // splat(s): the sum of the adjoint's lanes.
                    (Ctor::Splat, Ty::Vector(_, n)) => {
                        let sum = lanes[..*n as usize].iter().map(|l| l.to_string()).collect();
                        seed(&mut out, args[0], GradSrc::LaneSum(sum));
                    }
                    _ => {}
                }
            }
            Op::Lit(_)
            | Op::LitLike(..)
            | Op::ZeroLike(_)
            | Op::Unary(UnOp::Not, _)
            | Op::Tid(_)
            | Op::Lane
            | Op::DebugMode
            | Op::TileMap { .. }
            | Op::TileReduce { .. }
            | Op::Extent(..)
            | Op::Len(_)
            | Op::ViewCheck { .. }
            | Op::Const(_)
            | Op::Func { .. } => {}
        }
        out
    }

    /// The reverse of a read of `array[index]`: the seed into the gradient there. A
    /// thread-owned array's gradient under `__FAST` is gathered in a register
    /// (`Policy::gather_read_only`) or updated as the element's only user; atomically
    /// otherwise.
    fn load(&self, array: VarId, index: &[VarId], sp: Span) -> AKind {
        let accum = |own| AKind::GradAccum {
            array,
            index: Index::At(index.to_vec()),
            from: GradSrc::Seed,
            own,
        };
        let tid_access = self.tid_access(array, index);
        let reg = self.registers.iter().find(|r| r.0 == array);
        if let Some(&(_, var)) = reg.filter(|_| tid_access) {
            let (to, from) = (AdjOf::Var { var, path: vec![] }, GradSrc::Seed);
            let gather = AKind::Accum { to, from };
            if_fast(vec![at(gather, sp)], vec![at(accum(false), sp)])
        } else if self.own.contains(&array) && tid_access {
            if_fast(vec![at(accum(true), sp)], vec![at(accum(false), sp)])
        } else {
            accum(false)
        }
    }
}
