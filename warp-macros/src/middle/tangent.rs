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
//! The derivative rules are one table, [`Tx::builtin`] (builtins) with [`Tx::binary`]
//! (operators). What it does not cover (a builtin without a rule, a user func given a
//! differentiated argument, transforms, min/max atomics on differentiated arrays) is an error
//! naming the construct and its line; the macro stores it in the kernel's `Forward` impl and
//! `wp::jvp` returns it at the first use, so the user's crate still compiles.

use crate::builtins::{self, ArgTy, Grad};
use crate::ir::*;
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
        Ty::Matrix(..) | Ty::Quat(_) | Ty::Deferred => true,
        _ => false,
    }
}

/// Whether an array's elements have tangents.
fn tangent_array(t: &Ty) -> bool {
    matches!(t, Ty::Array(e, _) if !e.is_deferred() && tangent_type(e))
}

/// Whether a value of this type holds floats that forward mode cannot follow yet.
fn untracked_float(t: &Ty) -> bool {
    matches!(t, Ty::Transform(_) | Ty::Tuple(_))
}

/// The tangent kernel of `f`, or why there is none (a sentence after "it": "calls `quat_rotate`
/// (line 12), which forward mode does not differentiate yet").
pub fn build(f: &Function) -> Result<Function, String> {
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
    })
}

/// Whether an operation can give its result a tangent (given a differentiated operand).
fn carries(op: &Op) -> bool {
    match op {
        Op::Lit(_)
        | Op::LitLike(..)
        | Op::Tid(_)
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
                StmtKind::SetMember { var, value, .. } => (*var, active[*value]),
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
            None => self.tmp(Ty::Deferred, Op::LitLike(Lit::Float(x), like)),
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
        Ok(match &ty {
            Ty::Scalar(_) => self.tmp(ty.clone(), Op::Lit(Lit::Float(0.0))),
            Ty::Vector(..) | Ty::Matrix(..) => self.tmp(
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
            Ty::Deferred => self.tmp(Ty::Deferred, Op::LitLike(Lit::Float(0.0), like)),
            other => {
                return Err(format!(
                    "computes a `{other}` from differentiated values (line {}), which forward mode does not handle yet",
                    self.line()
                ))
            }
        })
    }

    fn bin(&mut self, op: BinOp, a: VarId, b: VarId) -> Result<VarId, String> {
        let ty = crate::front::lower::typing::binary_result(op, &self.ty(a), &self.ty(b))?;
        Ok(self.tmp(ty, Op::Binary(op, a, b)))
    }

    fn neg(&mut self, a: VarId) -> VarId {
        let ty = self.ty(a);
        self.tmp(ty, Op::Unary(UnOp::Neg, a))
    }

    /// A call of builtin `name`, typed by its signature.
    fn call(&mut self, name: &str, args: &[VarId]) -> Result<VarId, String> {
        let b = builtins::lookup(name).expect("a rule names a builtin of the table");
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

    /// `f(t, other..)` for a builtin linear in its first argument, or nothing.
    fn lin1(
        &mut self,
        name: &str,
        t: Option<VarId>,
        rest: &[VarId],
    ) -> Result<Option<VarId>, String> {
        let Some(t) = t else { return Ok(None) };
        let mut args = vec![t];
        args.extend_from_slice(rest);
        Some(self.call(name, &args)).transpose()
    }

    /// `f(a, t) + f(t_a, b)` for a builtin linear in each argument (dot, cross, outer, ..).
    fn bilinear(
        &mut self,
        name: &str,
        a: VarId,
        b: VarId,
        da: Option<VarId>,
        db: Option<VarId>,
    ) -> Result<Option<VarId>, String> {
        let l = match da {
            Some(da) => Some(self.call(name, &[da, b])?),
            None => None,
        };
        let r = match db {
            Some(db) => Some(self.call(name, &[a, db])?),
            None => None,
        };
        self.add(l, r)
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
            | Op::Tid(_)
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
                self.builtin(builtin.name, args, &dargs, d)?
            }
            Op::Func { path, args } => {
                if args.iter().any(|v| self.active[*v]) {
                    let name = path
                        .segments
                        .iter()
                        .map(|s| s.ident.to_string())
                        .collect::<Vec<_>>()
                        .join("::");
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
            Op::Member(v, m) => match self.dot[*v] {
                Some(t) if tangent_type(&self.ty(d)) => {
                    let ty = self.ty(d);
                    Some(self.tmp(ty, Op::Member(t, m.clone())))
                }
                _ => None,
            },
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

    /// The builtins' rules: `args` the primal arguments, `dargs` their tangents (at least one
    /// given), `d` the primal result.
    fn builtin(
        &mut self,
        name: &str,
        args: &[VarId],
        dargs: &[Option<VarId>],
        d: VarId,
    ) -> Result<Option<VarId>, String> {
        let a = args[0];
        let da = dargs[0];
        let b = args.get(1).copied();
        let db = dargs.get(1).copied().flatten();
        // For a unary function: `f'(a) a'` (the scale first).
        macro_rules! chain {
            ($scale:expr) => {{
                let s: VarId = $scale;
                self.mul_l(s, da)?
            }};
        }
        Ok(match name {
            "sqrt" => {
                let two_d = self.bin(BinOp::Add, d, d)?;
                self.div_r(da, two_d)?
            }
            "cbrt" => {
                let dd = self.bin(BinOp::Mul, d, d)?;
                let three = self.lit(d, 3.0);
                let den = self.bin(BinOp::Mul, three, dd)?;
                self.div_r(da, den)?
            }
            "exp" => chain!(d),
            "exp2" => {
                let ln2 = self.lit(d, std::f64::consts::LN_2);
                let s = self.bin(BinOp::Mul, d, ln2)?;
                chain!(s)
            }
            "log" => self.div_r(da, a)?,
            "log2" | "log10" => {
                let c = if name == "log2" {
                    std::f64::consts::LN_2
                } else {
                    std::f64::consts::LN_10
                };
                let c = self.lit(a, c);
                let den = self.bin(BinOp::Mul, a, c)?;
                self.div_r(da, den)?
            }
            "sin" => {
                let c = self.call("cos", &[a])?;
                chain!(c)
            }
            "cos" => {
                let s = self.call("sin", &[a])?;
                let t = self.mul_l(s, da)?;
                t.map(|t| self.neg(t))
            }
            "tan" => {
                let one = self.lit(d, 1.0);
                let dd = self.bin(BinOp::Mul, d, d)?;
                let s = self.bin(BinOp::Add, one, dd)?;
                chain!(s)
            }
            "asin" | "acos" => {
                let one = self.lit(a, 1.0);
                let aa = self.bin(BinOp::Mul, a, a)?;
                let r = self.bin(BinOp::Sub, one, aa)?;
                let r = self.call("sqrt", &[r])?;
                let t = self.div_r(da, r)?;
                if name == "acos" {
                    t.map(|t| self.neg(t))
                } else {
                    t
                }
            }
            "atan" => {
                let one = self.lit(a, 1.0);
                let aa = self.bin(BinOp::Mul, a, a)?;
                let den = self.bin(BinOp::Add, one, aa)?;
                self.div_r(da, den)?
            }
            "sinh" => {
                let c = self.call("cosh", &[a])?;
                chain!(c)
            }
            "cosh" => {
                let s = self.call("sinh", &[a])?;
                chain!(s)
            }
            "tanh" => {
                let one = self.lit(d, 1.0);
                let dd = self.bin(BinOp::Mul, d, d)?;
                let s = self.bin(BinOp::Sub, one, dd)?;
                chain!(s)
            }
            // atan2(y, x)' = (x y' - y x') / (x^2 + y^2)
            "atan2" => {
                let (y, x) = (a, b.expect("atan2 has two arguments"));
                let l = self.mul_l(x, da)?;
                let r = self.mul_l(y, db)?;
                let num = self.sub(l, r)?;
                let xx = self.bin(BinOp::Mul, x, x)?;
                let yy = self.bin(BinOp::Mul, y, y)?;
                let den = self.bin(BinOp::Add, xx, yy)?;
                self.div_r(num, den)?
            }
            // pow(a, b)' = b a^(b-1) a' + a^b ln(a) b' (the second term only where b varies).
            "pow" => {
                let b = b.expect("pow has two arguments");
                let l = match da {
                    Some(da) => {
                        let one = self.lit(b, 1.0);
                        let bm1 = self.bin(BinOp::Sub, b, one)?;
                        let p = self.call("pow", &[a, bm1])?;
                        let s = self.bin(BinOp::Mul, b, p)?;
                        Some(self.bin(BinOp::Mul, s, da)?)
                    }
                    None => None,
                };
                let r = match db {
                    Some(db) => {
                        let ln = self.call("log", &[a])?;
                        let s = self.bin(BinOp::Mul, d, ln)?;
                        Some(self.bin(BinOp::Mul, s, db)?)
                    }
                    None => None,
                };
                self.add(l, r)?
            }
            "erf" | "erfc" => {
                let aa = self.bin(BinOp::Mul, a, a)?;
                let naa = self.neg(aa);
                let e = self.call("exp", &[naa])?;
                let c = self.lit(a, std::f64::consts::FRAC_2_SQRT_PI);
                let s = self.bin(BinOp::Mul, c, e)?;
                let t = chain!(s);
                if name == "erfc" {
                    t.map(|t| self.neg(t))
                } else {
                    t
                }
            }
            "degrees" | "radians" => {
                let c = if name == "degrees" {
                    180.0 / std::f64::consts::PI
                } else {
                    std::f64::consts::PI / 180.0
                };
                let c = self.lit(a, c);
                chain!(c)
            }
            "frac" => da,
            "abs" => {
                let s = self.call("sign", &[a])?;
                chain!(s)
            }
            "min" | "max" | "clamp" => self.lifted(name, args, dargs)?,
            "dot" | "cross" | "outer" | "ddot" | "cw_mul" => {
                self.bilinear(name, a, b.expect("two arguments"), da, db)?
            }
            "cw_div" => {
                let b = b.expect("two arguments");
                let l = self.lin1("cw_div", da, &[b])?;
                let q = self.lin1("cw_div", db, &[b])?;
                let r = match q {
                    Some(q) => Some(self.call("cw_mul", &[d, q])?),
                    None => None,
                };
                self.sub(l, r)?
            }
            "transpose" | "trace" | "diag" | "skew" | "get_diag" => self.lin1(name, da, &[])?,
            // |a|' = (a / |a|) . a' (zero at a = 0, where normalize gives zero).
            "length" | "norm_l2" => {
                let n = self.call("normalize", &[a])?;
                self.lin1("dot", da, &[n])?
            }
            "length_sq" => {
                let t = self.lin1("dot", da, &[a])?;
                self.add(t, t)?
            }
            // normalize(a)' = (a' - n (n . a')) / |a|, and zero at a = 0 (where normalize
            // gives zero, and so does reverse mode): the division is by
            // |a| + (1 - nonzero(|a|)) and the quotient is scaled by nonzero(|a|), both exact
            // where |a| != 0.
            "normalize" if matches!(self.ty(a), Ty::Vector(..)) => {
                let Some(da) = da else { return Ok(None) };
                let nd = self.call("dot", &[d, da])?;
                let p = self.bin(BinOp::Mul, d, nd)?;
                let num = self.bin(BinOp::Sub, da, p)?;
                let l = self.call("length", &[a])?;
                let nz = self.call("nonzero", &[l])?;
                let one = self.lit(l, 1.0);
                let gap = self.bin(BinOp::Sub, one, nz)?;
                let den = self.bin(BinOp::Add, l, gap)?;
                let q = self.bin(BinOp::Div, num, den)?;
                Some(self.bin(BinOp::Mul, q, nz)?)
            }
            // inverse(A)' = -A^-1 A' A^-1
            "inverse" if matches!(self.ty(a), Ty::Matrix(..)) => {
                let Some(da) = da else { return Ok(None) };
                let l = self.bin(BinOp::Mul, d, da)?;
                let p = self.bin(BinOp::Mul, l, d)?;
                Some(self.neg(p))
            }
            // det(A)' = det(A) tr(A^-1 A')
            "determinant" => {
                let Some(da) = da else { return Ok(None) };
                let inv = self.call("inverse", &[a])?;
                let p = self.bin(BinOp::Mul, inv, da)?;
                let tr = self.call("trace", &[p])?;
                Some(self.bin(BinOp::Mul, d, tr)?)
            }
            // lerp(a, b, t) = a + t (b - a)
            "lerp" if tangent_type(&self.ty(a)) => {
                let (b, t) = (b.expect("three arguments"), args[2]);
                let dt = dargs[2];
                let diff = self.sub(db, da)?;
                let l = self.mul_l(t, diff)?;
                let l = self.add(da, l)?;
                let r = match dt {
                    Some(dt) => {
                        let bma = self.bin(BinOp::Sub, b, a)?;
                        Some(self.bin(BinOp::Mul, bma, dt)?)
                    }
                    None => None,
                };
                self.add(l, r)?
            }
            "atomic_add" | "atomic_sub" => {
                let Some(ta) = da else { return Ok(None) };
                let value = *args.last().expect("an atomic has a value");
                let tv = self.or_zero(dargs[args.len() - 1], value)?;
                let mut targs = args.to_vec();
                targs[0] = ta;
                *targs.last_mut().expect("a value") = tv;
                let ty = self.ty(d);
                let builtin = builtins::lookup(name).expect("atomics are builtins");
                Some(self.tmp(
                    ty,
                    Op::Builtin {
                        builtin,
                        args: targs,
                    },
                ))
            }
            other => {
                return Err(self.unsupported(&format!("calls `{other}` on differentiated values")))
            }
        })
    }

    /// `min`, `max` and `clamp`: by the primal's decisions (the operand returned carries its
    /// tangent, ties as the adjoint breaks them), lane by lane for vectors.
    fn lifted(
        &mut self,
        name: &str,
        args: &[VarId],
        dargs: &[Option<VarId>],
    ) -> Result<Option<VarId>, String> {
        let ty = self.ty(args[0]);
        let Ty::Vector(s, n) = ty else {
            return self.select(name, args, dargs);
        };
        let mut lanes = Vec::new();
        for lane in &LANES[..n as usize] {
            let mut la = Vec::new();
            let mut lda = Vec::new();
            for (v, t) in args.iter().zip(dargs) {
                la.push(self.tmp(Ty::Scalar(s), Op::Member(*v, lane.to_string())));
                lda.push(t.map(|t| self.tmp(Ty::Scalar(s), Op::Member(t, lane.to_string()))));
            }
            let t = self.select(name, &la, &lda)?;
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
        name: &str,
        args: &[VarId],
        dargs: &[Option<VarId>],
    ) -> Result<Option<VarId>, String> {
        let pick = |tx: &mut Self,
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
        match name {
            "min" => pick(self, true, args[0], args[1], dargs[0], dargs[1]),
            "max" => pick(self, false, args[0], args[1], dargs[0], dargs[1]),
            _ => {
                let m = self.call("max", &[args[0], args[1]])?;
                let dm = pick(self, false, args[0], args[1], dargs[0], dargs[1])?;
                pick(self, true, m, args[2], dm, dargs[2])
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use syn::parse_quote;

    fn kernel(item: syn::ItemFn) -> Function {
        crate::front::lower::lower_fn(&item, FnKind::Kernel).unwrap()
    }

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
}
