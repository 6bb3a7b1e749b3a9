//! Forward mode as one pass: a lowered kernel to its *tangent kernel*, an ordinary kernel IR.
//!
//! The tangent kernel takes the kernel's parameters followed by one tangent parameter per
//! parameter, of the same type (`x_dot` for `x`): the tangent of a float value, or an array
//! of the tangents of a float array's elements. Integer, bool, struct and object parameters get
//! one too, so that a launch passes `(args, tangents)` as two tuples of the kernel's own
//! parameter types, but it is never read: those are held constant.
//!
//! Every statement runs as in the kernel and is followed by the statements that compute the
//! tangent of what it defined, from primal and tangent values, with operations the IR already
//! has: `d = a * b` is followed by `d_dot = a_dot * b + a * b_dot`, a load `d = a[i]` by
//! `d_dot = a_dot[i]`, a store `a[i] = v` by `a_dot[i] = v_dot`, an `atomic_add` by the same
//! atomic on the tangent array. Control flow is kept as it is: the tangent runs alongside the
//! primal, so branches and loops take the primal's decisions. Since the result is an ordinary
//! kernel, both back ends emit it unchanged, and the adjoint pass differentiates it again
//! (reverse over forward), which gives Hessian-vector products.
//!
//! A value whose tangent is zero has none (`None`), so integer and constant computations add
//! nothing; a variable assigned more than once that may carry a tangent (an *active* one, found
//! by a fixpoint over the body) gets a mutable tangent variable, assigned wherever the variable
//! is (with zero where the value assigned is constant).
//!
//! A builtin's derivative rule is a fact of its row in the builtin table, beside its adjoint
//! rule ([`Tangent`]: an expression in the arguments, the result and the arguments' tangents,
//! which [`Tx::expand`] writes out as operations, or a shape written once here: the selections
//! of `min`/`max`/`clamp`, the atomics); the operators' rules are [`Tx::binary`]'s. What they
//! do not cover (a builtin whose row has no rule, a user func given a differentiated argument,
//! transforms, min/max atomics on differentiated arrays) is an error naming the construct and
//! its line; the macro stores it in the kernel's `Forward` impl and
//! `wp::jvp` returns it at the first use, so the user's crate still compiles.

use crate::builtins::{self, ArgTy, Builtin, Dx, Grad, Pick, Tangent};
use crate::ir::*;
use crate::operators::binary_result;
use crate::types::Ty;
use proc_macro2::Span;

/// The most parameters a launch takes (warp-runtime's `MAX_PARAMS`): the tangent kernel has
/// twice the kernel's.
const MAX_PARAMS: usize = 32;

/// Whether values of this type have a tangent of the same type (`Deferred`: a value the macro
/// cannot type, taken to be a float where it meets differentiated values).
fn tangent_type(t: &Ty) -> bool {
    match t {
        Ty::Scalar(s) | Ty::Vector(s, _) => s.is_float(),
        Ty::Matrix(..)
        | Ty::Quat(_)
        | Ty::SpatialVector(_)
        | Ty::SpatialMatrix(_)
        | Ty::MatRC(..)
        | Ty::Deferred => true,
        // A local array's tangent is a local array of its elements' tangents.
        Ty::LocalArray(e, _) => !e.is_deferred() && tangent_type(e),
        // A tuple's is a tuple: its elements' tangents, or their values where they have none.
        Ty::Tuple(ts) => ts.iter().any(tangent_type),
        _ => false,
    }
}

/// Whether an array's elements have tangents.
fn tangent_array(t: &Ty) -> bool {
    matches!(t, Ty::Array(e, _) if !e.is_deferred() && tangent_type(e))
}

/// Whether a value of this type holds floats that forward mode cannot follow yet. A user
/// struct's fields are invisible to the macro (an integer field's tangent could not be told
/// from a float's), so a struct computed from differentiated values is refused too.
fn untracked_float(t: &Ty) -> bool {
    matches!(t, Ty::Transform(_) | Ty::Struct(_))
}

/// The tangent kernel of `f`, or why there is none (a sentence after "it": "calls `quat_rotate`
/// (line 12), which forward mode does not differentiate yet").
pub fn build(f: &Function) -> Result<Function, String> {
    // Tile operations have no tangents yet; the rules' arms for them are never reached.
    if f.tiled.is_some() {
        return Err(crate::middle::adjoint::TILE_TANGENT.into());
    }
    if f.params.len() * 2 > MAX_PARAMS {
        return Err(format!(
            "has {} parameters: its tangent kernel would take {}, more than the {MAX_PARAMS} a kernel may take",
            f.params.len(),
            f.params.len() * 2
        ));
    }
    let active = activity(f);
    let mut tx = Tx {
        vars: f.vars.clone(),
        dot: vec![None; f.vars.len()],
        active,
        out: Vec::new(),
        span: Span::call_site(),
    };
    let mut params = f.params.clone();
    for p in &f.params {
        let v = tx.new_var(
            Some(format!("{}_dot", p.name.trim_start_matches("r#"))),
            p.ty.clone(),
            f.vars[p.var].mutable,
        );
        params.push(Param {
            name: format!("{}_dot", p.name.trim_start_matches("r#")),
            var: v,
            ty: p.ty.clone(),
            syn_ty: p.syn_ty.clone(),
            by_ref: false,
        });
        if tx.active[p.var] {
            tx.dot[p.var] = Some(v);
        }
    }
    // Variables assigned more than once keep one tangent variable.
    for v in 0..f.vars.len() {
        let var = &f.vars[v];
        let is_param = f.params.iter().any(|p| p.var == v);
        if tx.active[v] && var.mutable && !is_param {
            let name = var
                .name
                .as_ref()
                .map(|n| format!("{}_dot", n.trim_start_matches("r#")));
            tx.dot[v] = Some(tx.new_var(name, var.ty.clone(), true));
        }
    }
    let body = tx.block(&f.body)?;
    Ok(Function {
        kind: f.kind,
        name: format!("{}_jvp", f.name),
        params,
        ret: f.ret.clone(),
        ret_syn: f.ret_syn.clone(),
        vars: tx.vars,
        body,
        tid_ndim: f.tid_ndim,
        callees: f.callees.clone(),
        consts: f.consts.clone(),
        tiled: f.tiled.clone(),
        shape_obligations: Vec::new(),
        // The tangent kernel of a deterministic kernel records its primal's accumulations
        // and their tangents' (one each per primal call).
        deterministic: f.deterministic.map(|n| n.saturating_mul(2)),
        // The primal's calls are the same calls, checked with the primal.
        call_checks: Vec::new(),
        custom_replay: f.custom_replay,
    })
}

/// Whether an operation can give its result a tangent (given a differentiated operand).
fn carries(op: &Op) -> bool {
    match op {
        Op::Lit(_)
        | Op::LitLike(..)
        | Op::ZeroLike(_)
        | Op::Tid(_)
        | Op::Lane
        | Op::DebugMode
        | Op::TileMap { .. }
        | Op::TileReduce { .. }
        | Op::Extent(..)
        | Op::Len(_)
        | Op::Const(_)
        | Op::ViewCheck { .. } => false,
        Op::Binary(b, ..) => !b.is_comparison(),
        Op::Builtin { builtin, .. } => builtin.grad != Grad::Zero,
        _ => true,
    }
}

/// The variables that may carry a tangent: float (or array of float) parameters, and every
/// variable assigned from one through an operation that carries it (a fixpoint, for loops).
fn activity(f: &Function) -> Vec<bool> {
    let mut active = vec![false; f.vars.len()];
    for p in &f.params {
        active[p.var] = tangent_type(&p.ty) || tangent_array(&p.ty);
    }
    loop {
        let mut changed = false;
        walk_stmts(&f.body, &mut |s| {
            let (dst, reads_active) = match &s.kind {
                StmtKind::Assign { dst, op, .. } => {
                    let mut any = false;
                    if carries(op) {
                        op.for_each_read(&mut |v| any |= active[v]);
                    }
                    (*dst, any)
                }
                StmtKind::SetMember { var, value, .. } | StmtKind::SetElem { var, value, .. } => {
                    (*var, active[*value])
                }
                _ => return,
            };
            let t = &f.vars[dst].ty;
            if reads_active
                && !active[dst]
                && (tangent_type(t) || tangent_array(t) || untracked_float(t))
            {
                active[dst] = true;
                changed = true;
            }
        });
        if !changed {
            return active;
        }
    }
}

/// The transform's state.
struct Tx {
    /// The tangent function's variables: the kernel's, then the new ones.
    vars: Vec<Var>,
    /// The tangent of each of the kernel's variables where it has one: fixed for parameters and
    /// mutable variables, the latest definition's for the others.
    dot: Vec<Option<VarId>>,
    active: Vec<bool>,
    /// The block being written.
    out: Block,
    /// The span of the statement being differentiated.
    span: Span,
}

const LANES: [&str; 4] = ["x", "y", "z", "w"];

impl Tx {
    fn new_var(&mut self, name: Option<String>, ty: Ty, mutable: bool) -> VarId {
        self.vars.push(Var { name, ty, mutable });
        self.vars.len() - 1
    }

    fn ty(&self, v: VarId) -> Ty {
        self.vars[v].ty.clone()
    }

    fn line(&self) -> usize {
        self.span.start().line
    }

    fn push(&mut self, kind: StmtKind) {
        self.out.push(Stmt {
            kind,
            span: self.span,
        });
    }

    /// A new temporary `t: ty = op`.
    fn tmp(&mut self, ty: Ty, op: Op) -> VarId {
        let v = self.new_var(None, ty, false);
        self.push(StmtKind::Assign {
            dst: v,
            op,
            define: true,
        });
        v
    }

    /// The literal `x` of the scalar `like` is made of.
    fn lit(&mut self, like: VarId, x: f64) -> VarId {
        match self.ty(like).scalar() {
            Some(s) => self.tmp(Ty::Scalar(s), Op::Lit(Lit::Float(x))),
            None => self.tmp(Ty::Deferred, Op::LitLike(Lit::Float(x), like, Like::Value)),
        }
    }

    /// The tangent `t`, or zero of `like`'s type where there is none (a constant value).
    fn or_zero(&mut self, t: Option<VarId>, like: VarId) -> Result<VarId, String> {
        match t {
            Some(t) => Ok(t),
            None => self.zero(like),
        }
    }

    /// Zero of `like`'s type.
    fn zero(&mut self, like: VarId) -> Result<VarId, String> {
        let ty = self.ty(like);
        self.zero_of(ty, like)
    }

    /// Zero of type `ty` (`like`: a value of that type, for a type the macro cannot see).
    fn zero_of(&mut self, ty: Ty, like: VarId) -> Result<VarId, String> {
        Ok(match &ty {
            Ty::LocalArray(e, _) => {
                let z = self.zero_of((**e).clone(), like)?;
                let (ctor, args) = (Ctor::Splat, vec![z]);
                self.tmp(ty.clone(), Op::Construct { ty, ctor, args })
            }
            Ty::Scalar(_) => self.tmp(ty.clone(), Op::Lit(Lit::Float(0.0))),
            Ty::Vector(..)
            | Ty::Matrix(..)
            | Ty::SpatialVector(_)
            | Ty::SpatialMatrix(_)
            | Ty::MatRC(..) => self.tmp(
                ty.clone(),
                Op::Construct {
                    ty: ty.clone(),
                    ctor: Ctor::Const("ZERO".into()),
                    args: vec![],
                },
            ),
            Ty::Quat(s) => {
                let z = self.tmp(Ty::Scalar(*s), Op::Lit(Lit::Float(0.0)));
                self.tmp(
                    ty.clone(),
                    Op::Construct {
                        ty: ty.clone(),
                        ctor: Ctor::Components,
                        args: vec![z; 4],
                    },
                )
            }
            // Any type (a struct's matrix or quaternion field, a func's result): `zero_like`,
            // since a literal splats only into scalars and vectors.
            Ty::Deferred => self.tmp(Ty::Deferred, Op::ZeroLike(like)),
            // A tuple of its elements' zeros; an element without a tangent keeps `like`'s value
            // (see `Op::Tuple`'s rule).
            Ty::Tuple(ts) => {
                let mut zs = Vec::new();
                for (k, t) in ts.iter().enumerate() {
                    let m = self.tmp(t.clone(), Op::Member(like, k.to_string()));
                    zs.push(match tangent_type(t) {
                        true => self.zero_of(t.clone(), m)?,
                        false => m,
                    });
                }
                self.tmp(ty.clone(), Op::Tuple(zs))
            }
            other => {
                return Err(format!(
                    "computes a `{other}` from differentiated values (line {}), which forward mode does not handle yet",
                    self.line()
                ))
            }
        })
    }

    fn bin(&mut self, op: BinOp, a: VarId, b: VarId) -> Result<VarId, String> {
        let ty = binary_result(op, &self.ty(a), &self.ty(b))?;
        Ok(self.tmp(ty, Op::Binary(op, a, b)))
    }

    fn neg(&mut self, a: VarId) -> VarId {
        let ty = self.ty(a);
        self.tmp(ty, Op::Unary(UnOp::Neg, a))
    }

    /// A call of builtin `name`, typed by its signature.
    fn call(&mut self, name: &str, args: &[VarId]) -> Result<VarId, String> {
        let b = builtins::lookup(name)
            .ok_or_else(|| format!("names `{name}`, which is not a builtin (a rule's mistake)"))?;
        self.call_row(b, args)
    }

    /// A call of the builtin `b`, typed by its signature.
    fn call_row(&mut self, b: &'static Builtin, args: &[VarId]) -> Result<VarId, String> {
        let tys: Vec<ArgTy> = args.iter().map(|v| ArgTy::Known(self.ty(*v))).collect();
        let ret = b.resolve(&tys)?.ret;
        Ok(self.tmp(
            ret,
            Op::Builtin {
                builtin: b,
                args: args.to_vec(),
            },
        ))
    }

    fn add(&mut self, a: Option<VarId>, b: Option<VarId>) -> Result<Option<VarId>, String> {
        Ok(match (a, b) {
            (Some(a), Some(b)) => Some(self.bin(BinOp::Add, a, b)?),
            (a, None) => a,
            (None, b) => b,
        })
    }

    fn sub(&mut self, a: Option<VarId>, b: Option<VarId>) -> Result<Option<VarId>, String> {
        Ok(match (a, b) {
            (Some(a), Some(b)) => Some(self.bin(BinOp::Sub, a, b)?),
            (a, None) => a,
            (None, Some(b)) => Some(self.neg(b)),
        })
    }

    /// `a * t` (in that order: matrices do not commute), or nothing when `t` is zero.
    fn mul_l(&mut self, a: VarId, t: Option<VarId>) -> Result<Option<VarId>, String> {
        t.map(|t| self.bin(BinOp::Mul, a, t)).transpose()
    }

    /// `t * a`.
    fn mul_r(&mut self, t: Option<VarId>, a: VarId) -> Result<Option<VarId>, String> {
        t.map(|t| self.bin(BinOp::Mul, t, a)).transpose()
    }

    /// `t / a`.
    fn div_r(&mut self, t: Option<VarId>, a: VarId) -> Result<Option<VarId>, String> {
        t.map(|t| self.bin(BinOp::Div, t, a)).transpose()
    }

    fn unsupported(&self, what: &str) -> String {
        format!(
            "{what} (line {}), which forward mode does not differentiate yet",
            self.line()
        )
    }

    /// The block with every statement followed by its tangent statements.
    fn block(&mut self, b: &Block) -> Result<Block, String> {
        let saved = std::mem::take(&mut self.out);
        for s in b {
            self.stmt(s)?;
        }
        Ok(std::mem::replace(&mut self.out, saved))
    }

    fn stmt(&mut self, s: &Stmt) -> Result<(), String> {
        self.span = s.span;
        match &s.kind {
            StmtKind::Assign { dst, op, define } => self.assign(s, *dst, op, *define)?,
            StmtKind::Declare { var } => {
                self.out.push(s.clone());
                if let (true, Some(t)) = (self.vars[*var].mutable, self.dot[*var]) {
                    self.push(StmtKind::Declare { var: t });
                }
            }
            StmtKind::Store {
                array,
                index,
                value,
            } => {
                self.out.push(s.clone());
                if let Some(ta) = self.dot[*array] {
                    let tv = self.or_zero(self.dot[*value], *value)?;
                    self.push(StmtKind::Store {
                        array: ta,
                        index: index.clone(),
                        value: tv,
                    });
                }
            }
            StmtKind::SetElem { var, index, value } => {
                self.out.push(s.clone());
                if let Some(t) = self.dot[*var] {
                    let tv = self.or_zero(self.dot[*value], *value)?;
                    self.push(StmtKind::SetElem {
                        var: t,
                        index: *index,
                        value: tv,
                    });
                }
            }
            StmtKind::SetMember { var, path, value } => {
                self.out.push(s.clone());
                if let Some(t) = self.dot[*var] {
                    let tv = self.or_zero(self.dot[*value], *value)?;
                    self.push(StmtKind::SetMember {
                        var: t,
                        path: path.clone(),
                        value: tv,
                    });
                }
            }
            StmtKind::If { cond, then, els } => {
                let then = self.block(then)?;
                let els = self.block(els)?;
                self.span = s.span;
                self.push(StmtKind::If {
                    cond: *cond,
                    then,
                    els,
                });
            }
            StmtKind::For { var, range, body } => {
                let body = self.block(body)?;
                self.span = s.span;
                self.push(StmtKind::For {
                    var: *var,
                    range: range.clone(),
                    body,
                });
            }
            StmtKind::Loop { body } => {
                let body = self.block(body)?;
                self.span = s.span;
                self.push(StmtKind::Loop { body });
            }
            StmtKind::Break
            | StmtKind::Continue
            | StmtKind::Return { .. }
            | StmtKind::ExitIf { .. }
            | StmtKind::Print { .. } => self.out.push(s.clone()),
            // Dropped: the tangent kernel runs after (or instead of) the forward launch, which
            // checks the assertion; a tangent kernel that faulted on it would report the
            // hidden kernel's name.
            StmtKind::Assert { .. } => {}
        }
        Ok(())
    }

    fn assign(&mut self, s: &Stmt, dst: VarId, op: &Op, define: bool) -> Result<(), String> {
        if !self.active[dst] {
            self.out.push(s.clone());
            return Ok(());
        }
        if untracked_float(&self.vars[dst].ty) {
            return Err(format!(
                "computes a `{}` from differentiated values (line {}), which forward mode does not handle yet",
                self.vars[dst].ty,
                self.line()
            ));
        }
        let mutable = self.vars[dst].mutable;
        let mut reads_self = false;
        op.for_each_read(&mut |v| reads_self |= v == dst);
        // The result of the primal operation: `dst` itself, unless the operation reads `dst`
        // (`acc = acc * x`): then a temporary, so the rule still sees the operands' old values.
        let result = if reads_self {
            let ty = self.ty(dst);
            self.tmp(ty, op.clone())
        } else {
            self.out.push(s.clone());
            dst
        };
        let t = self.rule(op, result)?;
        if reads_self {
            self.push(StmtKind::Assign {
                dst,
                op: Op::Copy(result),
                define,
            });
        }
        if mutable {
            let td = self.dot[dst].expect("active mutable variables have a tangent");
            let value = self.or_zero(t, dst)?;
            self.push(StmtKind::Assign {
                dst: td,
                op: Op::Copy(value),
                define,
            });
        } else {
            self.dot[dst] = t;
        }
        Ok(())
    }

    /// The tangent of `op`'s value `d` (already computed), or `None` when it is zero.
    fn rule(&mut self, op: &Op, d: VarId) -> Result<Option<VarId>, String> {
        Ok(match op {
            Op::Lit(_)
            | Op::LitLike(..)
            | Op::ZeroLike(_)
            | Op::Tid(_)
            | Op::Lane
            | Op::DebugMode
            | Op::TileMap { .. }
            | Op::TileReduce { .. }
            | Op::Extent(..)
            | Op::Len(_)
            | Op::Const(_)
            | Op::ViewCheck { .. } => None,
            Op::Copy(v) => self.dot[*v],
            Op::Unary(UnOp::Neg, v) => self.dot[*v].map(|t| self.neg(t)),
            Op::Unary(UnOp::Not, _) => None,
            Op::Binary(b, l, r) => {
                let (dl, dr) = (self.dot[*l], self.dot[*r]);
                self.binary(*b, *l, *r, dl, dr, d)?
            }
            Op::Cast(v, to) => match (self.dot[*v], to) {
                (Some(t), Ty::Scalar(s)) if s.is_float() => {
                    Some(self.tmp(to.clone(), Op::Cast(t, to.clone())))
                }
                _ => None,
            },
            Op::Builtin { builtin, args } => {
                let dargs: Vec<Option<VarId>> = args.iter().map(|v| self.dot[*v]).collect();
                if builtin.grad == Grad::Zero || dargs.iter().all(Option::is_none) {
                    return Ok(None);
                }
                self.builtin(builtin, args, &dargs, d)?
            }
            Op::Func { path, args } => {
                if args.iter().any(|v| self.active[*v]) {
                    let name = crate::front::lower::resolve::callee_name(path);
                    return Err(self.unsupported(&format!(
                        "calls the func `{name}` with a differentiated argument"
                    )));
                }
                None
            }
            Op::Load { array, index } => match self.dot[*array] {
                Some(ta) => {
                    let ty = self.ty(d);
                    Some(self.tmp(
                        ty,
                        Op::Load {
                            array: ta,
                            index: index.clone(),
                        },
                    ))
                }
                None => None,
            },
            Op::Index { array, index } => match self.dot[*array] {
                Some(ta) if tangent_type(&self.ty(d)) => {
                    let (ty, index) = (self.ty(d), *index);
                    Some(self.tmp(ty, Op::Index { array: ta, index }))
                }
                _ => None,
            },
            Op::Member(v, m) => match self.dot[*v] {
                Some(t) if tangent_type(&self.ty(d)) => {
                    let ty = self.ty(d);
                    Some(self.tmp(ty, Op::Member(t, m.clone())))
                }
                _ => None,
            },
            // A tuple's tangent is the tuple of its elements' tangents; an element without one
            // (an integer, a `bool`) keeps its value there, which no member read takes as a
            // tangent (`tangent_type` of its type is false).
            Op::Tuple(args) if args.iter().any(|v| self.dot[*v].is_some()) => {
                let mut targs = Vec::new();
                for &v in args {
                    targs.push(match self.dot[v] {
                        Some(t) => t,
                        None if tangent_type(&self.ty(v)) => self.zero(v)?,
                        None => v,
                    });
                }
                Some(self.tmp(self.ty(d), Op::Tuple(targs)))
            }
            Op::Tuple(_) => None,
            Op::Construct { ty, ctor, args } => match ctor {
                Ctor::Const(_) => None,
                _ if args.iter().all(|v| self.dot[*v].is_none()) => None,
                _ => {
                    let mut targs = Vec::new();
                    for v in args {
                        targs.push(self.or_zero(self.dot[*v], *v)?);
                    }
                    Some(self.tmp(
                        ty.clone(),
                        Op::Construct {
                            ty: ty.clone(),
                            ctor: ctor.clone(),
                            args: targs,
                        },
                    ))
                }
            },
        })
    }

    /// The operators' rules.
    fn binary(
        &mut self,
        op: BinOp,
        a: VarId,
        b: VarId,
        da: Option<VarId>,
        db: Option<VarId>,
        d: VarId,
    ) -> Result<Option<VarId>, String> {
        if da.is_none() && db.is_none() {
            return Ok(None);
        }
        match op {
            BinOp::Add => self.add(da, db),
            BinOp::Sub => self.sub(da, db),
            // (a b)' = a' b + a b'
            BinOp::Mul => {
                let l = self.mul_r(da, b)?;
                let r = self.mul_l(a, db)?;
                self.add(l, r)
            }
            // (a / b)' = a' / b - (a / b) (b' / b)
            BinOp::Div => {
                let l = self.div_r(da, b)?;
                let q = self.div_r(db, b)?;
                let r = self.mul_l(d, q)?;
                self.sub(l, r)
            }
            // fmod: a - trunc(a / b) b, so a' - trunc(a / b) b' (float scalars).
            BinOp::Rem
                if matches!(self.ty(a), Ty::Scalar(_)) && matches!(self.ty(b), Ty::Scalar(_)) =>
            {
                let r = match db {
                    Some(db) => {
                        let q = self.bin(BinOp::Div, a, b)?;
                        let tq = self.call("trunc", &[q])?;
                        Some(self.bin(BinOp::Mul, tq, db)?)
                    }
                    None => None,
                };
                self.sub(da, r)
            }
            _ => Err(self.unsupported(&format!(
                "applies `{}` to differentiated values",
                op.symbol()
            ))),
        }
    }

    /// A builtin's rule, its row's [`Tangent`]: `args` the primal arguments, `dargs` their
    /// tangents (at least one given), `d` the primal result.
    fn builtin(
        &mut self,
        b: &'static Builtin,
        args: &[VarId],
        dargs: &[Option<VarId>],
        d: VarId,
    ) -> Result<Option<VarId>, String> {
        let mut site = Site {
            builtin: b,
            args,
            dargs,
            out: d,
            done: Vec::new(),
        };
        match &b.tangent {
            Some(Tangent::Rule(dx)) => self.expand(&mut site, dx),
            Some(Tangent::RuleFor(classes, dx))
                if args
                    .first()
                    .is_some_and(|a| classes.iter().any(|c| c.admits(&self.ty(*a)))) =>
            {
                self.expand(&mut site, dx)
            }
            Some(Tangent::Select(pick)) => self.lifted(*pick, args, dargs),
            Some(Tangent::Atomic) => self.atomic(b, args, dargs, d),
            Some(Tangent::RuleFor(..) | Tangent::NoRule) | None => {
                Err(self.unsupported(&format!("calls `{}` on differentiated values", b.name)))
            }
        }
    }

    /// The operations that compute a rule's expression at a call site, or `None` where its
    /// tangents are absent (see [`Dx`]).
    fn expand(&mut self, site: &mut Site, dx: &'static Dx) -> Result<Option<VarId>, String> {
        let dargs = site.dargs;
        let given = |i: usize| dargs.get(i).copied().flatten().is_some();
        if dx.present(&given) == Some(false) {
            return Ok(None);
        }
        if let Some((_, v)) = site.done.iter().find(|(e, _)| *e == dx) {
            return Ok(*v);
        }
        let malformed = || {
            format!(
                "has a call of `{}`, whose forward-mode rule is malformed (a bug of warp-lang)",
                site.builtin.name
            )
        };
        let v = match dx {
            Dx::Arg(i) => Some(*site.args.get(*i).ok_or_else(malformed)?),
            Dx::Out => Some(site.out),
            Dx::Dot(i) => site.dargs.get(*i).copied().flatten(),
            Dx::Const(_) => return Err(malformed()),
            Dx::Neg(x) => self.expand(site, x)?.map(|t| self.neg(t)),
            Dx::Add(l, r) => {
                let (l, r) = self.operands(site, l, r)?;
                self.add(l, r)?
            }
            Dx::Sub(l, r) => {
                let (l, r) = self.operands(site, l, r)?;
                self.sub(l, r)?
            }
            Dx::Mul(l, r) | Dx::Div(l, r) => {
                let op = if matches!(dx, Dx::Mul(..)) {
                    BinOp::Mul
                } else {
                    BinOp::Div
                };
                match self.operands(site, l, r)? {
                    (Some(l), Some(r)) => Some(self.bin(op, l, r)?),
                    _ => None,
                }
            }
            Dx::Call(name, args) => {
                let b = builtins::lookup(name).ok_or_else(malformed)?;
                self.expand_call(site, b, args)?
            }
            Dx::This(args) => {
                let b = site.builtin;
                self.expand_call(site, b, args)?
            }
        };
        site.done.push((dx, v));
        Ok(v)
    }

    /// The operands of a binary operation of a rule: a constant is typed by the operand it
    /// meets (the literal rule), which is computed first.
    fn operands(
        &mut self,
        site: &mut Site,
        l: &'static Dx,
        r: &'static Dx,
    ) -> Result<(Option<VarId>, Option<VarId>), String> {
        Ok(match (l, r) {
            (Dx::Const(c), r) => {
                let r = self.expand(site, r)?;
                (r.map(|r| self.lit(r, *c)), r)
            }
            (l, Dx::Const(c)) => {
                let l = self.expand(site, l)?;
                (l, l.map(|l| self.lit(l, *c)))
            }
            (l, r) => (self.expand(site, l)?, self.expand(site, r)?),
        })
    }

    /// A call in a rule, or `None` where its tangent argument is absent.
    fn expand_call(
        &mut self,
        site: &mut Site,
        b: &'static Builtin,
        args: &'static [Dx],
    ) -> Result<Option<VarId>, String> {
        let mut vals = Vec::with_capacity(args.len());
        for a in args {
            match self.expand(site, a)? {
                Some(v) => vals.push(v),
                None => return Ok(None),
            }
        }
        Some(self.call_row(b, &vals)).transpose()
    }

    /// [`Tangent::Atomic`]: the same atomic on the tangent array with the value's tangent
    /// (an array without tangents: nothing).
    fn atomic(
        &mut self,
        b: &'static Builtin,
        args: &[VarId],
        dargs: &[Option<VarId>],
        d: VarId,
    ) -> Result<Option<VarId>, String> {
        let (Some(ta), Some(&value)) = (dargs[0], args.last()) else {
            return Ok(None);
        };
        let tv = self.or_zero(dargs[args.len() - 1], value)?;
        let mut targs = args.to_vec();
        targs[0] = ta;
        targs[args.len() - 1] = tv;
        let ty = self.ty(d);
        Ok(Some(self.tmp(
            ty,
            Op::Builtin {
                builtin: b,
                args: targs,
            },
        )))
    }

    /// [`Tangent::Select`]: by the primal's decisions (the operand returned carries its
    /// tangent, ties as the adjoint breaks them), lane by lane for vectors.
    fn lifted(
        &mut self,
        pick: Pick,
        args: &[VarId],
        dargs: &[Option<VarId>],
    ) -> Result<Option<VarId>, String> {
        let ty = self.ty(args[0]);
        let Ty::Vector(s, n) = ty else {
            return self.select(pick, args, dargs);
        };
        let mut lanes = Vec::new();
        for lane in &LANES[..n as usize] {
            let mut la = Vec::new();
            let mut lda = Vec::new();
            for (v, t) in args.iter().zip(dargs) {
                la.push(self.tmp(Ty::Scalar(s), Op::Member(*v, lane.to_string())));
                lda.push(t.map(|t| self.tmp(Ty::Scalar(s), Op::Member(t, lane.to_string()))));
            }
            let t = self.select(pick, &la, &lda)?;
            let t = self.or_zero(t, la[0])?;
            lanes.push(t);
        }
        Ok(Some(self.tmp(
            ty.clone(),
            Op::Construct {
                ty,
                ctor: Ctor::Components,
                args: lanes,
            },
        )))
    }

    /// The scalar rule of [`Tx::lifted`], with `step(x)` (1 where `x < 0`) as the weight of
    /// the operand not returned on a tie: `min(a, b)' = a' + step(b - a) (b' - a')`,
    /// `max(a, b)' = a' + step(a - b) (b' - a')`, `clamp(x, lo, hi) = min(max(x, lo), hi)`.
    fn select(
        &mut self,
        pick: Pick,
        args: &[VarId],
        dargs: &[Option<VarId>],
    ) -> Result<Option<VarId>, String> {
        let choose = |tx: &mut Self,
                      min: bool,
                      a: VarId,
                      b: VarId,
                      da: Option<VarId>,
                      db: Option<VarId>|
         -> Result<Option<VarId>, String> {
            let diff = tx.sub(db, da)?;
            let Some(diff) = diff else { return Ok(da) };
            let x = if min {
                tx.bin(BinOp::Sub, b, a)?
            } else {
                tx.bin(BinOp::Sub, a, b)?
            };
            let w = tx.call("step", &[x])?;
            let r = tx.bin(BinOp::Mul, w, diff)?;
            tx.add(da, Some(r))
        };
        match pick {
            Pick::Min => choose(self, true, args[0], args[1], dargs[0], dargs[1]),
            Pick::Max => choose(self, false, args[0], args[1], dargs[0], dargs[1]),
            Pick::Clamp => {
                let m = self.call("max", &[args[0], args[1]])?;
                let dm = choose(self, false, args[0], args[1], dargs[0], dargs[1])?;
                choose(self, true, m, args[2], dm, dargs[2])
            }
        }
    }
}

/// A call whose rule [`Tx::expand`] writes out: the row, the primal arguments, their
/// tangents and result, and the rule's subexpressions already computed (each once).
struct Site<'a> {
    builtin: &'static Builtin,
    args: &'a [VarId],
    dargs: &'a [Option<VarId>],
    out: VarId,
    done: Vec<(&'static Dx, Option<VarId>)>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::kernel;
    use syn::parse_quote;

    /// The tangent kernel's statements that write a variable named `name`.
    fn writes_of(g: &Function, name: &str) -> usize {
        let mut n = 0;
        walk_stmts(&g.body, &mut |s| {
            if let StmtKind::Assign { dst, .. } = &s.kind {
                if g.vars[*dst].name.as_deref() == Some(name) {
                    n += 1;
                }
            }
        });
        n
    }

    #[test]
    fn tangent_parameters_follow_the_parameters() {
        let f = kernel(parse_quote! {
            fn k(x: Array<f32>, n: i32, s: f32, y: Array<f32>) {
                let i = tid();
                y[i] = x[i] * s + (n as f32);
            }
        });
        let g = build(&f).unwrap();
        let names: Vec<&str> = g.params.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(
            names,
            ["x", "n", "s", "y", "x_dot", "n_dot", "s_dot", "y_dot"]
        );
        assert_eq!(g.name, "k_jvp");
        // One store into y and one into its tangent.
        let mut stores = Vec::new();
        walk_stmts(&g.body, &mut |s| {
            if let StmtKind::Store { array, .. } = &s.kind {
                stores.push(g.vars[*array].name.clone().unwrap());
            }
        });
        assert_eq!(stores, ["y", "y_dot"]);
    }

    #[test]
    fn mutable_accumulators_get_one_tangent_variable() {
        let f = kernel(parse_quote! {
            fn k(x: Array<f64>, n: i32, y: Array<f64>) {
                let i = tid();
                let mut acc: f64 = 1.0;
                let mut count = 0;
                for _k in 0..n {
                    acc = acc * x[i];
                    count += 1;
                }
                y[i] = acc + (count as f64);
            }
        });
        let g = build(&f).unwrap();
        // Defined once, assigned in the loop; the integer counter has no tangent.
        assert_eq!(writes_of(&g, "acc_dot"), 2);
        assert_eq!(writes_of(&g, "count_dot"), 0);
    }

    #[test]
    fn refusals_name_the_construct_and_the_line() {
        let f = kernel(parse_quote! {
            fn k(q: Array<Quat>, v: Array<Vec3>, out: Array<Vec3>) {
                let i = tid();
                out[i] = quat_rotate(q[i], v[i]);
            }
        });
        let why = build(&f).unwrap_err();
        assert!(
            why.starts_with("calls `quat_rotate` on differentiated values (line"),
            "{why}"
        );

        let f = kernel(parse_quote! {
            fn k(x: Array<f32>) {
                atomic_max(x, 0, 1.0);
            }
        });
        assert!(build(&f).unwrap_err().contains("`atomic_max`"));

        // Integer atomics and zero-gradient builtins are fine.
        let f = kernel(parse_quote! {
            fn k(x: Array<f32>, c: Array<i32>) {
                let i = tid();
                atomic_max(c, 0, 1);
                x[i] = x[i].floor() + x[i].sin();
            }
        });
        build(&f).unwrap();
    }

    #[test]
    fn too_many_parameters_for_the_tangent_kernel() {
        let params: Vec<syn::FnArg> = (0..17usize)
            .map(|k| {
                let id = quote::format_ident!("p{}", k);
                parse_quote!(#id: f32)
            })
            .collect();
        let f = kernel(parse_quote! { fn k(#(#params),*) {} });
        let why = build(&f).unwrap_err();
        assert!(why.contains("would take 34"), "{why}");
    }

    #[test]
    fn element_stores_get_tangent_element_stores() {
        let f = kernel(parse_quote! {
            fn k(x: Array<f64>, y: Array<f64>) {
                let i = tid();
                let mut a = [0.0f64; 3];
                for j in 0..3 {
                    a[j] = x[i] * a[(j + 2) % 3] + x[i];
                }
                y[i] = a[1];
            }
        });
        let g = build(&f).unwrap();
        let a_dot = g
            .vars
            .iter()
            .position(|v| v.name.as_deref() == Some("a_dot"))
            .expect("the array has a tangent variable");
        let (mut sets, mut reads) = (0, 0);
        walk_stmts(&g.body, &mut |s| match &s.kind {
            StmtKind::SetElem { var, .. } if *var == a_dot => sets += 1,
            StmtKind::Assign {
                op: Op::Index { array, .. },
                ..
            } if *array == a_dot => reads += 1,
            _ => {}
        });
        // The store's, and the reads of `a[(j + 2) % 3]` and `a[1]`.
        assert_eq!((sets, reads), (1, 2));
        // The tangent of the constant `[0.0; 3]`: a repeat of zero.
        assert_eq!(g.vars[a_dot].ty.to_string(), "[f64; 3]");
    }

    #[test]
    fn tuples_carry_their_elements_tangents() {
        let f = kernel(parse_quote! {
            fn k(x: Array<f32>, y: Array<f32>) {
                let i = tid();
                let t = (x[i] * x[i], 3);
                let u = if x[i] > 0.0 { t } else { (1.0, 2) };
                let (a, b) = (u.0 * 2.0, x[i]);
                y[i] = a + b * u.1 as f32;
            }
        });
        let g = build(&f).unwrap();
        // The primal's three literals, then three tangents: `t`'s, the constant branch's
        // zeros (the `if`'s result has a tangent) and the destructured pair's.
        let mut tuples = 0;
        walk_stmts(&g.body, &mut |s| {
            if let StmtKind::Assign {
                op: Op::Tuple(_), ..
            } = &s.kind
            {
                tuples += 1;
            }
        });
        assert_eq!(tuples, 6);
    }
}
