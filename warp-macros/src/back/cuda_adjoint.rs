//! CUDA printer of the adjoint IR (`middle::adjoint`, which holds the scheme and its docs):
//! C++ templates over `warp-cuda/cuda/wp_adjoint.h` for a kernel's adjoint thread function
//! (`@@SELF@@_adj`) and entry (`@@ENTRY@@_adj`), or a func's replay (`@@SELF@@_replay`) and
//! adjoint (`@@SELF@@_adj`).
//!
//! The stack is a `wp::adstack_t` in per-thread local memory (`WP_ADSTACK_BYTES`); `adj_<array>`
//! parameters are the arrays' gradients (`data == nullptr`: none). A variable whose type the
//! macro cannot see is declared with the type of its first definition
//! (`remove_cvref<decltype(..)>` of the same expression over variables declared before it,
//! which `middle::adjoint` guarantees), or of its loop's end bound.

use super::cuda::{cpp_member, cpp_type, Emitter};
use crate::ir::*;
use crate::middle::adjoint::*;
use crate::types::Ty;

/// The adjoint templates of kernel or func `f`.
pub struct CudaAdjoint {
    /// The adjoint thread function (and, for kernels, the `@@ENTRY@@_adj` entry point); for
    /// funcs, preceded by the replay function.
    pub source: String,
    /// Whether anything is pushed on the adjoint stack (the entry then reserves
    /// `WP_ADSTACK_BYTES` of per-thread local memory).
    pub uses_stack: bool,
}

/// Emits the CUDA adjoint of `f`, or why it cannot.
pub fn emit(f: &Function, file: &str) -> Result<CudaAdjoint, String> {
    let adj = build(f, Policy::CUDA)?;
    let replay = match f.kind {
        FnKind::Func => func_replay(f, file)?,
        FnKind::Kernel => String::new(),
    };
    let text = Printer::new(&adj, file, &adj.f.callees).function()?;
    Ok(CudaAdjoint {
        source: format!("{replay}{text}"),
        uses_stack: adj.uses_stack,
    })
}

/// The CUDA replay and adjoint of a func with custom gradients `grads` (parameter, gradient
/// func): the adjoint calls the gradient funcs, which are appended to `callees` (their
/// `@@F<k>@@` indices follow the body's callees).
pub fn emit_custom(
    f: &Function,
    file: &str,
    grads: &[(syn::Ident, syn::Path)],
    callees: &mut Vec<syn::Path>,
) -> Result<String, String> {
    let adj = custom(f, grads)?;
    for (_, gf) in grads {
        if !callees.contains(gf) {
            callees.push(gf.clone());
        }
    }
    let replay = func_replay(f, file)?;
    let text = Printer::new(&adj, file, callees).function()?;
    Ok(format!("{replay}{text}"))
}

/// A func's replay (`@@SELF@@_replay`): its forward code as `replay_of` strips it, atomics
/// not redone, funcs called through their replays.
fn func_replay(f: &Function, file: &str) -> Result<String, String> {
    let stripped = replay_of(f);
    let mut r = Emitter::new(&stripped, file);
    r.replay = true;
    let text = r.function_text()?;
    if matches!(f.ret, Ty::Unit) {
        // A unit func's replay returns `wp::unit_t`, so that callers can assign its result
        // like any other (the declared variable is a `wp::unit_t`).
        let text = text
            .replacen(
                "static WP_FN void @@SELF@@(",
                "static WP_FN wp::unit_t @@SELF@@_replay(",
                1,
            )
            .replace("return;", "return wp::unit_t{};");
        let body_end = text.rfind('}').ok_or("replay text")?;
        return Ok(format!(
            "{}    return wp::unit_t{{}};\n{}",
            &text[..body_end],
            &text[body_end..]
        ));
    }
    Ok(text.replacen("@@SELF@@(", "@@SELF@@_replay(", 1))
}

struct Printer<'a> {
    e: Emitter<'a>,
    adj: &'a Adjoint,
    /// The callees by `@@F<k>@@` index (a custom adjoint's gradient funcs follow the body's).
    callees: &'a [syn::Path],
}

impl<'a> Printer<'a> {
    fn new(adj: &'a Adjoint, file: &str, callees: &'a [syn::Path]) -> Self {
        let mut e = Emitter::new(&adj.f, file);
        // User funcs are called through their replays.
        e.replay = true;
        Printer { e, adj, callees }
    }

    fn f(&self) -> &'a Function {
        &self.adj.f
    }
    fn var(&self, v: VarId) -> String {
        self.e.var(v)
    }
    fn adj(&self, v: VarId) -> String {
        format!("adj_{}", self.e.var(v))
    }
    fn is_array(&self, v: VarId) -> bool {
        matches!(self.f().ty(v), Ty::Array(..))
    }
    fn line(&mut self, sp: proc_macro2::Span, text: &str) {
        self.e.line(sp, text);
    }
    fn callee(&self, path: &syn::Path) -> Result<usize, String> {
        self.callees
            .iter()
            .position(|p| p == path)
            .ok_or_else(|| "callee not recorded".to_string())
    }

    /// The thread index, one component per array dimension.
    fn tid_index(&self, array: VarId) -> Result<String, String> {
        match self.f().ty(array) {
            Ty::Array(_, n) => Ok((0..*n as usize)
                .map(|d| format!("__tid[{d}]"))
                .collect::<Vec<_>>()
                .join(", ")),
            _ => Err("internal: a thread-owned array that is no array".into()),
        }
    }

    /// The parameter list: forward parameters, then gradients of arrays (kernels and funcs)
    /// and `&` adjoints of value parameters (funcs).
    fn params(&self) -> Result<Vec<String>, String> {
        let mut ps = Vec::new();
        for p in &self.f().params {
            ps.push(format!(
                "{} {}",
                cpp_type(&p.ty).ok_or("parameter type")?,
                self.var(p.var)
            ));
        }
        for (k, p) in self.f().params.iter().enumerate() {
            let t = cpp_type(&p.ty).ok_or("parameter type")?;
            if self.is_array(p.var) {
                ps.push(format!("{t} {}", self.adj(p.var)));
            } else if self.f().kind == FnKind::Func {
                ps.push(format!("{t}& __adj_out{k}"));
            }
        }
        Ok(ps)
    }

    /// The C++ type of a declared variable: its own where the macro can spell it, else that of
    /// its definition (see `middle::adjoint::Decl`).
    fn decl_type(&mut self, d: &Decl) -> Result<String, String> {
        let ty = self.f().ty(d.var);
        if matches!(ty, Ty::Unit) {
            return Ok("wp::unit_t".into());
        }
        if let Some(t) = cpp_type(ty) {
            return Ok(t);
        }
        match &d.def {
            Some(TypeOf::Var(w)) => Ok(format!("decltype({})", self.var(*w))),
            Some(TypeOf::Value(value)) => Ok(format!(
                "typename wp::detail::remove_cvref<decltype({})>::type",
                self.value(value, d.var)?
            )),
            None => Err(format!(
                "internal: `{}` is never assigned and has no type",
                self.var(d.var)
            )),
        }
    }

    fn value(&mut self, value: &Value, dst: VarId) -> Result<String, String> {
        match value {
            Value::Op(op) => self.e.op(op, dst),
            Value::Zero { like } => Ok(format!("wp::zero_like({})", self.var(*like))),
        }
    }

    fn function(mut self) -> Result<String, String> {
        let mut ps = self.params()?;
        let kernel = self.f().kind == FnKind::Kernel;
        if kernel {
            ps.push("const wp::launch_t& __launch".into());
            ps.push("wp::i64 __flat".into());
        } else {
            let ret = match &self.f().ret {
                Ty::Unit => "wp::unit_t".to_string(),
                t => cpp_type(t).ok_or("the func's return type has no CUDA type")?,
            };
            ps.push(format!("{ret} __adj_ret"));
        }
        ps.push("wp::ctx_t* __ctx".into());
        ps.push("wp::adstack_t* __stack".into());
        if !kernel {
            // The types of the value parameters' adjoints, for the temporaries of callers
            // (an argument may have another type, such as a literal's `int` for a `usize`).
            for (k, p) in self.f().params.iter().enumerate() {
                if !self.is_array(p.var) {
                    let t = cpp_type(&p.ty).ok_or("parameter type")?;
                    self.e
                        .out
                        .push_str(&format!("typedef {t} @@SELF@@_adj_arg{k};\n"));
                }
            }
        }
        self.e.out.push_str(&format!(
            "static WP_FN void @@SELF@@_adj({}) {{\n",
            ps.join(", ")
        ));
        if kernel {
            self.e
                .out
                .push_str("    const bool __FAST = __launch.fast != 0;\n");
            if let Some(n) = self.f().tid_ndim {
                self.e.out.push_str(&format!(
                    "    wp::i64 __tid[4];\n    wp::unflatten(__launch, __flat, __tid, {n});\n"
                ));
            }
        }
        let adj = self.adj;
        for d in &adj.decls {
            let t = self.decl_type(d)?;
            let x = self.var(d.var);
            self.e.out.push_str(&format!("    {t} {x}{{}};\n"));
        }
        for &v in &self.adj.adjs {
            let (a, x) = (self.adj(v), self.var(v));
            self.e
                .out
                .push_str(&format!("    auto {a} = wp::zero_like({x});\n"));
        }
        for &arr in &self.adj.gathered {
            if let Ty::Array(elem, _) = self.f().ty(arr) {
                let t = cpp_type(elem).ok_or("element type")?;
                let v = self.var(arr);
                self.e.out.push_str(&format!("    {t} __acc_{v}{{}};\n"));
            }
        }
        self.block(&adj.body)?;
        self.e.out.push_str("}\n");
        if kernel {
            self.entry()?;
        }
        Ok(self.e.out)
    }

    /// `@@ENTRY@@_adj`: the grid-stride loop over threads, each with an empty stack in
    /// per-thread local memory.
    fn entry(&mut self) -> Result<(), String> {
        let mut decl = vec![
            "wp::launch_t __launch".to_string(),
            "wp::ctx_t __ctx_value".into(),
        ];
        let mut call = Vec::new();
        for p in &self.f().params {
            decl.push(format!(
                "{} {}",
                cpp_type(&p.ty).ok_or("type")?,
                self.var(p.var)
            ));
            call.push(self.var(p.var));
        }
        for p in &self.f().params {
            if self.is_array(p.var) {
                decl.push(format!(
                    "{} {}",
                    cpp_type(&p.ty).ok_or("type")?,
                    self.adj(p.var)
                ));
                call.push(self.adj(p.var));
            }
        }
        call.extend([
            "__launch".into(),
            "__flat".into(),
            "&__ctx_value".into(),
            "&__st".into(),
        ]);
        let bytes = if self.adj.uses_stack {
            "WP_ADSTACK_BYTES"
        } else {
            "0"
        };
        self.e.out.push_str(&format!(
            "#ifdef __CUDACC__\nextern \"C\" __global__ void @@ENTRY@@_adj({}) {{\n    \
             char __buf[{bytes} > 0 ? {bytes} : 1];\n    \
             wp::adstack_t __st = wp::adstack_new(__buf, {bytes});\n    \
             const wp::i64 __stride = (wp::i64)blockDim.x * gridDim.x;\n    \
             for (wp::i64 __flat = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x; __flat < __launch.total; __flat += __stride) {{\n        \
             __st.top = 0;\n        @@SELF@@_adj({});\n    }}\n}}\n#endif\n",
            decl.join(", "),
            call.join(", ")
        ));
        Ok(())
    }

    fn block(&mut self, b: &[AStmt]) -> Result<(), String> {
        for s in b {
            self.stmt(s)?;
        }
        Ok(())
    }

    fn nested(&mut self, b: &[AStmt]) -> Result<(), String> {
        self.e.indent += 1;
        let r = self.block(b);
        self.e.indent -= 1;
        r
    }

    fn stmt(&mut self, s: &AStmt) -> Result<(), String> {
        let sp = s.span;
        match &s.kind {
            AKind::Assign { dst, value } => {
                let rhs = self.value(value, *dst)?;
                if matches!(self.f().ty(*dst), Ty::Unit) {
                    self.line(sp, &format!("{rhs};"));
                } else {
                    let x = self.var(*dst);
                    self.line(sp, &format!("{x} = {rhs};"));
                }
            }
            AKind::SetMember { var, path, value } => {
                let (x, v) = (self.var(*var), self.var(*value));
                self.line(sp, &format!("{x}.{} = {v};", member_path(path)));
            }
            AKind::Push { var, line } => {
                let x = self.var(*var);
                self.line(
                    sp,
                    &format!("wp::adstack_push(__stack, {x}, {line}, __ctx);"),
                );
            }
            AKind::If {
                cond,
                then,
                els,
                record,
            } => {
                let c = self.var(*cond);
                self.line(sp, &format!("{{ const bool __c = {c}; if (__c) {{"));
                self.nested(then)?;
                self.line(sp, "} else {");
                self.nested(els)?;
                if *record {
                    self.line(sp, "} wp::adstack_push(__stack, __c, 0, __ctx); }");
                } else {
                    self.line(sp, "} }");
                }
            }
            AKind::For {
                range,
                exit,
                body,
                line,
            } => {
                let (s0, e0) = (self.var(range.start), self.var(range.end));
                self.line(sp, "{");
                self.e.indent += 1;
                self.line(
                    sp,
                    &format!(
                        "wp::range_t __r = wp::range_new((wp::i64)({s0}), (wp::i64)({e0}), {});",
                        range.inclusive
                    ),
                );
                for a in &range.adapters {
                    match a {
                        RangeAdapter::Rev => self.line(sp, "__r = wp::range_rev(__r);"),
                        RangeAdapter::StepBy(k) => {
                            let k = self.var(*k);
                            self.line(
                                sp,
                                &format!("__r = wp::range_step_by(__r, (wp::i64)({k}), __ctx);"),
                            );
                        }
                    }
                }
                self.line(sp, "wp::i64 __count = 0;");
                self.line(sp, "for (wp::i64 __n = 0; __n < __r.count; ++__n) {");
                self.e.indent += 1;
                self.exit(exit, sp);
                self.block(body)?;
                self.line(sp, "++__count;");
                self.e.indent -= 1;
                self.line(sp, "}");
                self.line(
                    sp,
                    &format!("wp::adstack_push(__stack, __count, {line}, __ctx);"),
                );
                self.e.indent -= 1;
                self.line(sp, "}");
            }
            AKind::Loop { exit, body, line } => {
                self.line(sp, "{ wp::i64 __count = 0; for (;;) {");
                self.e.indent += 1;
                self.exit(exit, sp);
                self.block(body)?;
                self.line(sp, "++__count;");
                self.e.indent -= 1;
                self.line(
                    sp,
                    &format!("}} wp::adstack_push(__stack, __count, {line}, __ctx); }}"),
                );
            }
            AKind::StepVar { var, .. } => {
                let v = self.var(*var);
                self.line(
                    sp,
                    &format!("{v} = wp::cast<decltype({v})>(wp::range_at(__r, __n));"),
                );
            }
            AKind::Scope(b) => {
                self.line(sp, "{");
                self.nested(b)?;
                self.line(sp, "}");
            }
            AKind::Seed { var } => {
                let (a, x) = (self.adj(*var), self.var(*var));
                self.line(sp, &format!("auto __r = {a}; {a} = wp::zero_like({x});"));
            }
            AKind::SeedMember { var, path } => {
                let (a, p) = (self.adj(*var), member_path(path));
                self.line(
                    sp,
                    &format!("auto __r = {a}.{p}; {a}.{p} = wp::zero_like(__r);"),
                );
            }
            AKind::SeedZero { like } => {
                let x = self.var(*like);
                self.line(sp, &format!("auto __r = wp::zero_like({x});"));
            }
            AKind::ClearAdj { var } => {
                let (a, x) = (self.adj(*var), self.var(*var));
                self.line(sp, &format!("{a} = wp::zero_like({x});"));
            }
            AKind::Pop { var } => {
                let x = self.var(*var);
                self.line(
                    sp,
                    &format!("{x} = wp::adstack_pop<decltype({x})>(__stack);"),
                );
            }
            AKind::Accum { var, member, from } => {
                let mut a = self.adj(*var);
                if let Some(m) = member {
                    a = format!("{a}.{}", cpp_member(m));
                }
                let g = self.grad(from)?;
                self.line(sp, &format!("wp::adj_accum({a}, {g});"));
            }
            AKind::AdjCall {
                func,
                inputs,
                faults,
            } => {
                let xs: Vec<String> = inputs.iter().map(|v| self.var(*v)).collect();
                // An array input's adjoint is the array's gradient; the others' zeroed
                // temporaries.
                let mut gs = Vec::new();
                for (k, (x, v)) in xs.iter().zip(inputs).enumerate() {
                    if matches!(self.f().ty(*v), crate::types::Ty::Array(..)) {
                        gs.push(self.adj(*v));
                    } else {
                        self.line(sp, &format!("auto __g{k} = wp::zero_like({x});"));
                        gs.push(format!("__g{k}"));
                    }
                }
                // An adjoint that reads an object's buffers (`adj_mesh_query_point`) takes the
                // fault context last, as its forward call does.
                let ctx = if *faults { ", __ctx" } else { "" };
                self.line(
                    sp,
                    &format!(
                        "wp::{func}({}, {}, __r{ctx});",
                        xs.join(", "),
                        gs.join(", ")
                    ),
                );
            }
            AKind::AdjCast { from } => {
                let x = self.var(*from);
                self.line(
                    sp,
                    &format!("auto __g0 = wp::zero_like({x}); wp::adj_cast(__g0, __r);"),
                );
            }
            AKind::FuncAdj { path, args } => {
                let k = self.callee(path)?;
                let mut pass: Vec<String> = args.iter().map(|(a, _)| self.var(*a)).collect();
                for (j, (a, how)) in args.iter().enumerate() {
                    match how {
                        FuncArgAdj::ArrayGrad => pass.push(self.adj(*a)),
                        FuncArgAdj::Temp => {
                            self.line(
                                sp,
                                &format!("auto __g{j} = wp::adj_zero<@@F{k}@@_adj_arg{j}>();"),
                            );
                            pass.push(format!("__g{j}"));
                        }
                    }
                }
                pass.extend(["__r".into(), "__ctx".into(), "__stack".into()]);
                self.line(sp, &format!("@@F{k}@@_adj({});", pass.join(", ")));
            }
            AKind::AtomicAdj {
                kind,
                array,
                index,
                value,
            } => {
                let (g, idx, x, av) = (
                    self.adj(*array),
                    self.e.index(index),
                    self.var(*value),
                    self.adj(*value),
                );
                self.line(
                    sp,
                    &format!("auto __grad = wp::grad_get({g}, {idx}, wp::zero_like({x}), __ctx);"),
                );
                let text = match kind {
                    AtomicKind::Sub => format!("wp::adj_neg({x}, {av}, __grad);"),
                    AtomicKind::Add => format!("wp::adj_accum({av}, __grad);"),
                    AtomicKind::Extreme => {
                        let a = self.var(*array);
                        format!("wp::adj_atomic_extreme(wp::load({a}, {idx}, __ctx), {x}, {av}, __grad);")
                    }
                };
                self.line(sp, &text);
            }
            AKind::GradAccum { array, index, mode } => {
                let (g, idx) = (self.adj(*array), self.e.index(index));
                let atomic = format!("wp::grad_accum({g}, {idx}, __r, __ctx);");
                let text = match mode {
                    AccumMode::Atomic => atomic,
                    AccumMode::OwnWhenFast => {
                        format!("if (__FAST) wp::grad_accum_own({g}, {idx}, __r); else {atomic}")
                    }
                    AccumMode::GatherWhenFast => {
                        let v = self.var(*array);
                        format!("if (__FAST) wp::adj_accum(__acc_{v}, __r); else {atomic}")
                    }
                };
                self.line(sp, &text);
            }
            AKind::RevIf { cond, then, els } => {
                let c = match cond {
                    Some(c) => self.var(*c),
                    None => "wp::adstack_pop<bool>(__stack)".to_string(),
                };
                self.line(sp, &format!("if ({c}) {{"));
                self.nested(then)?;
                self.line(sp, "} else {");
                self.nested(els)?;
                self.line(sp, "}");
            }
            AKind::RevLoop { body } => {
                self.line(
                    sp,
                    "{ const wp::i64 __count = wp::adstack_pop<wp::i64>(__stack);",
                );
                self.line(sp, "for (wp::i64 __k = 0; __k < __count; ++__k) {");
                self.nested(body)?;
                self.line(sp, "} }");
            }
            AKind::FlushGathered { array } => {
                let (g, v, idx) = (self.adj(*array), self.var(*array), self.tid_index(*array)?);
                self.line(
                    sp,
                    &format!("if (__FAST) wp::grad_accum_own({g}, {idx}, __acc_{v});"),
                );
            }
            AKind::ClearOwn { array } => {
                let (g, idx) = (self.adj(*array), self.tid_index(*array)?);
                self.line(sp, &format!("if (__FAST) wp::grad_clear_own({g}, {idx});"));
            }
            AKind::AccumOut { k, var } => {
                let a = self.adj(*var);
                self.line(sp, &format!("wp::adj_accum(__adj_out{k}, {a});"));
            }
            AKind::CustomGrad { k, func } => {
                let j = self.callee(func)?;
                let args: Vec<String> = self.f().params.iter().map(|p| self.var(p.var)).collect();
                self.line(
                    sp,
                    &format!(
                        "wp::adj_accum(__adj_out{k}, @@F{j}@@({}, __adj_ret, __ctx));",
                        args.join(", ")
                    ),
                );
            }
        }
        Ok(())
    }

    /// A loop's exit check (before anything of the iteration runs).
    fn exit(&mut self, flags: &[VarId], sp: proc_macro2::Span) {
        if !flags.is_empty() {
            let fs: Vec<String> = flags.iter().map(|v| self.var(*v)).collect();
            self.line(sp, &format!("if ({}) break;", fs.join(" || ")));
        }
    }

    fn grad(&self, g: &GradSrc) -> Result<String, String> {
        Ok(match g {
            GradSrc::Seed => "__r".into(),
            GradSrc::SeedLane(l) => format!("__r.{l}"),
            GradSrc::LaneSum(lanes) => lanes
                .iter()
                .map(|l| format!("__r.{l}"))
                .collect::<Vec<_>>()
                .join(" + "),
            GradSrc::Diagonal { vector, entries } => {
                let name = vector
                    .glam_name()
                    .ok_or("internal: a diagonal of no vector type")?;
                let parts: Vec<String> = entries
                    .iter()
                    .map(|(c, l)| format!("__r.{c}.{l}"))
                    .collect();
                format!("wp::{name}_new({})", parts.join(", "))
            }
            GradSrc::Temp(k) => format!("__g{k}"),
            GradSrc::AdjRet => "__adj_ret".into(),
            GradSrc::Take {
                array,
                index,
                like,
                mode,
            } => {
                let (g, idx, v) = (self.adj(*array), self.e.index(index), self.var(*like));
                let take = format!("wp::grad_take({g}, {idx}, wp::zero_like({v}), __ctx)");
                match mode {
                    TakeMode::Take => take,
                    TakeMode::GetWhenFast => format!(
                        "__FAST ? wp::grad_get({g}, {idx}, wp::zero_like({v}), __ctx) : {take}"
                    ),
                }
            }
        })
    }
}

/// `a.b.c` in C++ (tuple elements are `f<k>`).
fn member_path(path: &[String]) -> String {
    path.iter()
        .map(|m| cpp_member(m))
        .collect::<Vec<_>>()
        .join(".")
}

#[cfg(test)]
mod tests {
    use syn::parse_quote;

    /// Variables the macro cannot type (a loop over a const, a nested loop over that loop's
    /// variable, a func's result) are declared with the type of their definitions.
    #[test]
    fn untyped_variables_are_declared_by_their_definitions() {
        let item: syn::ItemFn = parse_quote! {
            fn k(x: Array<f64>, out: Array<f64>) {
                let mut p: f64 = 1.0;
                for i in 0..N {
                    for j in 0..i {
                        p = p * x[j] * helper(x[j]);
                    }
                }
                out[0] = p;
            }
        };
        let f = crate::front::lower::lower_fn(&item, crate::ir::FnKind::Kernel).unwrap();
        let src = super::emit(&f, "k.rs").unwrap().source;
        let decl = |what: &str| {
            src.lines()
                .find(|l| l.trim_end().ends_with(&format!(" {what}{{}};")))
                .unwrap_or_else(|| panic!("no declaration of {what}:\n{src}"))
                .trim()
                .to_string()
        };
        let end = decl("t4").replace(" t4{};", "");
        assert!(end.contains("decltype(@@K0@@)"), "{end}");
        assert_eq!(decl("i_6"), "decltype(t4) i_6{};");
        assert_eq!(decl("j_8"), "decltype(i_6) j_8{};");
        assert!(
            decl("t12").contains("decltype(@@F0@@_replay(t11, __ctx))"),
            "{src}"
        );
    }
}
