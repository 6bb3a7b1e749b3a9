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

use super::cuda::{cpp_member, cpp_type, fill_lengths, Emitter};
use crate::ir::*;
use crate::middle::adjoint::*;
use crate::types::Ty;
use std::fmt::Write as _;

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
    emit_with_replay(f, file, None)
}

/// As [`emit`], for a func whose replay is the func at `replay` in its callees
/// (`#[func(replay = r)]`), if one is given.
pub fn emit_with_replay(
    f: &Function,
    file: &str,
    replay: Option<usize>,
) -> Result<CudaAdjoint, String> {
    // A deterministic kernel's adjoint has the CPU's structure (no gradients gathered in
    // registers), so that both backends record the same accumulations in the same order.
    let policy = match f.deterministic {
        Some(_) => Policy::CPU,
        None => Policy::CUDA,
    };
    let adj = build(f, policy)?;
    let replay = match f.kind {
        FnKind::Func => func_replay(f, file, replay)?,
        FnKind::Kernel => String::new(),
    };
    let text = Printer::new(&adj, file).function()?;
    Ok(CudaAdjoint {
        source: fill_lengths(&adj.f, format!("{replay}{text}"))?,
        uses_stack: adj.uses_stack,
    })
}

/// The CUDA replay and adjoint of a func with custom gradients `grads` (parameter, gradient
/// func): the adjoint calls the gradient funcs, which `middle::adjoint::custom` appends to
/// the callees (their `@@F<k>@@` indices follow the body's); `callees` becomes that list.
pub fn emit_custom(
    f: &Function,
    file: &str,
    grads: &[(syn::Ident, syn::Path)],
    callees: &mut Vec<syn::Path>,
    replay: Option<&syn::Path>,
) -> Result<String, String> {
    let adj = custom(f, grads)?;
    callees.clone_from(&adj.f.callees);
    let replay = replay.map(|r| crate::ir::push_callee(callees, r));
    let replay = func_replay(f, file, replay)?;
    let text = Printer::new(&adj, file).function()?;
    fill_lengths(&adj.f, format!("{replay}{text}"))
}

/// A func's replay (`@@SELF@@_replay`): its forward code as `replay_of` strips it, printed by
/// the forward emitter in replay mode (atomics not redone, funcs called through their
/// replays, a unit func returning `wp::unit_t`).
fn func_replay(f: &Function, file: &str, custom: Option<usize>) -> Result<String, String> {
    if let Some(k) = custom {
        return custom_replay(f, k);
    }
    let stripped = replay_of(f);
    let mut r = Emitter::new(&stripped, file);
    r.replay = true;
    r.function_text()
}

/// The replay of a func with a custom one (`#[func(replay = r)]`, `r` its callee `k`): a call
/// of `r`'s forward code, as Warp's replay of such a func is.
fn custom_replay(f: &Function, k: usize) -> Result<String, String> {
    let mut decl = Vec::new();
    let mut xs = Vec::new();
    for (j, p) in f.params.iter().enumerate() {
        let t =
            cpp_type(&p.ty).ok_or_else(|| format!("parameter `{}` has no CUDA type", p.name))?;
        decl.push(format!("{t} x{j}"));
        xs.push(format!("x{j}"));
    }
    decl.push("wp::ctx_t* __ctx".into());
    xs.push("__ctx".into());
    let (decl, xs) = (decl.join(", "), xs.join(", "));
    Ok(match &f.ret {
        Ty::Unit => format!(
            "static WP_FN wp::unit_t @@SELF@@_replay({decl}) {{\n    @@F{k}@@({xs});\n    return wp::unit_t{{}};\n}}\n"
        ),
        t => {
            let ret = cpp_type(t).ok_or("the func's return type has no CUDA type")?;
            format!("static WP_FN {ret} @@SELF@@_replay({decl}) {{\n    return @@F{k}@@({xs});\n}}\n")
        }
    })
}

pub(super) struct Printer<'a> {
    pub(super) e: Emitter<'a>,
    pub(super) adj: &'a Adjoint,
    /// Inside this many block-level scopes of a tiled kernel (`middle::adjoint::tiles`): an
    /// accumulation into a scalar's adjoint there is thread 0's alone.
    pub(super) block_depth: usize,
}

impl<'a> Printer<'a> {
    fn new(adj: &'a Adjoint, file: &str) -> Self {
        let mut e = Emitter::new(&adj.f, file);
        // User funcs are called through their replays.
        e.replay = true;
        Printer {
            e,
            adj,
            block_depth: 0,
        }
    }

    pub(super) fn f(&self) -> &'a Function {
        &self.adj.f
    }
    pub(super) fn var(&self, v: VarId) -> String {
        self.e.var(v)
    }
    pub(super) fn adj(&self, v: VarId) -> String {
        format!("adj_{}", self.e.var(v))
    }
    pub(super) fn line(&mut self, sp: proc_macro2::Span, text: impl AsRef<str>) {
        self.e.line(sp, text.as_ref());
    }
    fn ty(&self, v: VarId) -> Result<String, String> {
        cpp_type(self.f().ty(v)).ok_or_else(|| format!("`{}` has no CUDA type", self.var(v)))
    }

    /// The forward parameters, then the gradient parameters (`middle::adjoint::GradParam`).
    pub(super) fn params(&self) -> Result<Vec<String>, String> {
        let mut ps = Vec::new();
        for p in &self.f().params {
            ps.push(format!("{} {}", self.ty(p.var)?, self.var(p.var)));
        }
        for gp in &self.adj.grad_params {
            ps.push(match *gp {
                GradParam::Array(v) => format!("{} {}", self.ty(v)?, self.adj(v)),
                GradParam::Out { k, var } => format!("{}& __adj_out{k}", self.ty(var)?),
            });
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
            ps.extend([
                "const wp::launch_t& __launch".into(),
                "wp::i64 __flat".into(),
            ]);
        } else {
            let ret = match &self.f().ret {
                Ty::Unit => "wp::unit_t".to_string(),
                t => cpp_type(t).ok_or("the func's return type has no CUDA type")?,
            };
            ps.push(format!("{ret} __adj_ret"));
        }
        ps.extend(["wp::ctx_t* __ctx".into(), "wp::adstack_t* __stack".into()]);
        if kernel && self.f().deterministic.is_some() {
            // The thread's record slots (wp_core.h's `det_thread_t`).
            ps.push("wp::det_thread_t* __det".into());
        }
        // The types of the value parameters' adjoints, for the temporaries of callers
        // (`TempLike::Param`).
        for gp in &self.adj.grad_params {
            if let GradParam::Out { k, var } = *gp {
                let t = self.ty(var)?;
                let _ = writeln!(self.e.out, "typedef {t} @@SELF@@_adj_arg{k};");
            }
        }
        let _ = writeln!(
            self.e.out,
            "static WP_FN void @@SELF@@_adj({}) {{",
            ps.join(", ")
        );
        if kernel {
            self.e
                .out
                .push_str("    const bool __FAST = (__launch.flags & wp::LAUNCH_FAST) != 0;\n");
            if let Some(n) = self.f().tid_ndim {
                let _ = writeln!(
                    self.e.out,
                    "    wp::i64 __tid[4];\n    wp::unflatten(__launch, __flat, __tid, {n});"
                );
            }
        }
        let adj = self.adj;
        let tiled = self.f().tiled.is_some();
        // A tiled kernel's tiles and their adjoints are on slots of shared memory.
        let on_slot = |v: VarId| tiled && adj.f.ty(v).is_tile();
        for d in adj.decls.iter().filter(|d| !on_slot(d.var)) {
            let (t, x) = (self.decl_type(d)?, self.var(d.var));
            let _ = writeln!(self.e.out, "    {t} {x}{{}};");
        }
        for &v in adj.adjs.iter().filter(|v| !on_slot(**v)) {
            let (a, x) = (self.adj(v), self.var(v));
            let _ = writeln!(self.e.out, "    auto {a} = wp::zero_like({x});");
        }
        if tiled {
            self.tile_slots()?;
        }
        self.block(&adj.body)?;
        self.e.out.push_str("}\n");
        if kernel {
            self.entry()?;
        }
        Ok(self.e.out)
    }

    /// `@@ENTRY@@_adj`: the grid-stride loop over threads, each with an empty stack in
    /// per-thread local memory. (The forward entry runs one thread per element instead. The
    /// same `if` here gave wrong gradients on an H200: the suite's `lerp_overloads_gradients`,
    /// whose adjoint pushes spatial matrices, failed on CUDA alone, with and without line
    /// tables, where the loop passes; the cause is not found. The loop's 0.1 us matters little
    /// to an adjoint launch.)
    fn entry(&mut self) -> Result<(), String> {
        if self.f().tiled.is_some() {
            return self.tile_entry();
        }
        let mut decl = vec![
            "wp::launch_t __launch".into(),
            super::cuda::ENTRY_CTX_PARAM.into(),
        ];
        decl.extend(self.params()?);
        let mut call: Vec<String> = self.f().params.iter().map(|p| self.var(p.var)).collect();
        for gp in &self.adj.grad_params {
            if let GradParam::Array(v) = *gp {
                call.push(self.adj(v));
            }
        }
        call.extend(["__launch", "__flat", "&__ctx_value", "&__st"].map(String::from));
        let det = self.f().deterministic.is_some();
        if det {
            decl.insert(2, "wp::det_t __det_buf".into());
            call.push("&__dt".into());
        }
        let (begin, end) = match det {
            true => (
                "wp::det_thread_t __dt = wp::det_begin(__det_buf, __flat);\n        ",
                "\n        wp::det_end(&__dt);",
            ),
            false => ("", ""),
        };
        let bytes = if self.adj.uses_stack {
            "WP_ADSTACK_BYTES"
        } else {
            "0"
        };
        let _ = write!(
            self.e.out,
            "#ifdef __CUDACC__\nextern \"C\" __global__ void @@ENTRY@@_adj({}) {{\n    \
             char __buf[{bytes} > 0 ? {bytes} : 1];\n    \
             wp::adstack_t __st = wp::adstack_new(__buf, {bytes});\n    \
             const wp::i64 __stride = (wp::i64)blockDim.x * gridDim.x;\n    \
             for (wp::i64 __flat = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x; __flat < __launch.total; __flat += __stride) {{\n        \
             __st.top = 0;\n        {}\n        \
             {begin}@@SELF@@_adj({});{end}\n    }}\n}}\n#endif\n",
            decl.join(", "),
            super::cuda::THREAD_CTX,
            call.join(", ")
        );
        if det {
            self.e.out.push_str(super::cuda::DET_ENTRIES);
        }
        Ok(())
    }

    fn block(&mut self, b: &[AStmt]) -> Result<(), String> {
        b.iter().try_for_each(|s| self.stmt(s))
    }

    pub(super) fn nested(&mut self, b: &[AStmt]) -> Result<(), String> {
        self.e.indent += 1;
        let r = self.block(b);
        self.e.indent -= 1;
        r
    }

    fn stmt(&mut self, s: &AStmt) -> Result<(), String> {
        let sp = s.span;
        self.e.stmt_line = sp.start().line;
        let tiled = self.f().tiled.is_some();
        if tiled {
            if let Some(r) = self.tile_replay(s) {
                return r;
            }
        }
        // A cooperative statement of a tiled kernel waits for lane code before it to finish
        // with the slots it is about to write.
        let coop = tiled && self.is_coop_leaf(s);
        if coop && !self.e.after_tile_op {
            self.line(sp, "__syncthreads();");
        }
        let text = match &s.kind {
            AKind::Assign { dst, value } => {
                let rhs = self.value(value, *dst)?;
                match self.f().ty(*dst) {
                    Ty::Unit => format!("{rhs};"),
                    _ => format!("{} = {rhs};", self.var(*dst)),
                }
            }
            AKind::SetMember { var, path, value } => {
                let (x, v) = (self.var(*var), self.var(*value));
                format!("{x}{} = {v};", member_path(path))
            }
            AKind::SetElem { var, index, value } => {
                let (a, i, v) = (self.var(*var), self.var(*index), self.var(*value));
                let line = sp.start().line;
                let set = match self.f().vars[*var].ty {
                    Ty::Matrix(..) => "col_set",
                    _ => "local_set",
                };
                format!("wp::{set}({a}, (wp::i64)({i}), {v}, {line}, __ctx);")
            }
            AKind::ClearAdjElem { var, index } => {
                let e = self.adj_elem(*var, *index);
                format!("{e} = wp::zero_like({e});")
            }
            AKind::Push { var, line } if coop => {
                format!(
                    "wp::adstack_push_tile(__stack, {}, {line}, __ctx);",
                    self.var(*var)
                )
            }
            AKind::Push { var, line } => {
                format!(
                    "wp::adstack_push(__stack, {}, {line}, __ctx);",
                    self.var(*var)
                )
            }
            AKind::Loop {
                range,
                exit,
                body,
                line,
            } => {
                self.line(sp, "{");
                self.e.indent += 1;
                if let Some(range) = range {
                    self.range(range, sp);
                }
                self.line(sp, "wp::i64 __count = 0;");
                self.line(
                    sp,
                    match range {
                        Some(_) => "for (wp::i64 __n = 0; __n < __r.count; ++__n) {",
                        None => "for (;;) {",
                    },
                );
                self.e.indent += 1;
                if !exit.is_empty() {
                    let fs: Vec<String> = exit.iter().map(|v| self.var(*v)).collect();
                    self.line(sp, format!("if ({}) break;", fs.join(" || ")));
                }
                // An iteration may follow lane code at the end of the one before.
                self.e.after_tile_op = false;
                self.block(body)?;
                self.line(sp, "++__count;");
                self.e.indent -= 1;
                self.line(sp, "}");
                self.line(
                    sp,
                    format!("wp::adstack_push(__stack, __count, {line}, __ctx);"),
                );
                self.e.indent -= 1;
                "}".into()
            }
            AKind::StepVar { var, .. } => {
                let v = self.var(*var);
                format!("{v} = wp::cast<decltype({v})>(wp::range_at(__r, __n));")
            }
            AKind::If { cond, then, els } => {
                let c = match cond {
                    Cond::Var(c) => self.var(*c),
                    Cond::Popped => "wp::adstack_pop<bool>(__stack)".into(),
                    Cond::Fast => "__FAST".into(),
                };
                self.line(sp, format!("if ({c}) {{"));
                self.nested(then)?;
                self.line(sp, "} else {");
                self.nested(els)?;
                "}".into()
            }
            AKind::Scope(b) => {
                let block = tiled && is_block_level(self.f(), s);
                self.block_depth += block as usize;
                self.line(sp, "{");
                let r = self.nested(b);
                self.block_depth -= block as usize;
                r?;
                "}".into()
            }
            AKind::Seed(from) => format!("auto __r = {};", self.grad(from)?),
            AKind::ClearAdj { var, .. } if coop => format!("wp::tile_zeros({});", self.adj(*var)),
            AKind::ClearAdj { var, path } => {
                let (a, x, p) = (self.adj(*var), self.var(*var), member_path(path));
                format!("{a}{p} = wp::zero_like({x}{p});")
            }
            AKind::Pop { var } if coop => {
                format!("wp::adstack_pop_tile(__stack, {});", self.var(*var))
            }
            AKind::Pop { var } => {
                let x = self.var(*var);
                format!("{x} = wp::adstack_pop<decltype({x})>(__stack);")
            }
            AKind::Accum { to, from } => {
                let to = match to {
                    AdjOf::Var { var, path } => format!("{}{}", self.adj(*var), member_path(path)),
                    AdjOf::Out(k) => format!("__adj_out{k}"),
                    AdjOf::Elem { var, index } => self.adj_elem(*var, *index),
                };
                let g = self.grad(from)?;
                if coop {
                    format!("wp::adj_tile_accum({to}, {g});")
                } else if self.block_depth > 0 {
                    // The uniform-operand rule: once for the block.
                    format!("if (threadIdx.x == 0) wp::adj_accum({to}, {g});")
                } else {
                    format!("wp::adj_accum({to}, {g});")
                }
            }
            AKind::ZeroTemp { k, like } => match like {
                TempLike::Var(v) => format!("auto __g{k} = wp::zero_like({});", self.var(*v)),
                TempLike::Param { func, k: j, .. } => {
                    format!("auto __g{k} = wp::adj_zero<@@F{func}@@_adj_arg{j}>();")
                }
            },
            AKind::AdjCall {
                func,
                values,
                grads,
                faults,
            } => {
                let mut args: Vec<String> = values
                    .iter()
                    .map(|(Arg::Value(v) | Arg::Array(v))| self.var(*v))
                    .collect();
                args.extend(grads.iter().map(|g| self.grad_arg(g)));
                args.push("__r".into());
                // An adjoint that reads an object's buffers (`adj_mesh_query_point`) takes the
                // fault context last, as its forward call does.
                if *faults {
                    args.push("__ctx".into());
                }
                format!("wp::{func}({});", args.join(", "))
            }
            AKind::FuncAdj {
                func,
                values,
                grads,
            } => {
                let mut args: Vec<String> = values.iter().map(|v| self.var(*v)).collect();
                args.extend(grads.iter().map(|g| self.grad_arg(g)));
                args.extend(["__r", "__ctx", "__stack"].map(String::from));
                format!("@@F{func}@@_adj({});", args.join(", "))
            }
            AKind::GradAccum {
                array,
                index,
                from,
                own,
            } => {
                let (g, idx, v) = (self.adj(*array), self.index(index), self.grad(from)?);
                if self.f().deterministic.is_some()
                    && self.f().kind == FnKind::Kernel
                    && !crate::analysis::stored_or_passed(self.f()).contains(array)
                {
                    // Recorded, on the fast path too, as on the CPU (back/rust_adjoint.rs):
                    // both backends add in one order.
                    format!("wp::det_grad_accum({g}, {idx}, {v}, __det, __ctx);")
                } else {
                    match own {
                    // `__launch` is the kernel's: thread-owned arrays are a kernel's (a func's
                    // accesses are never thread-owned).
                    true => format!(
                        "wp::grad_accum_own({g}, {idx}, {v}, (__launch.flags & wp::LAUNCH_ALONE) != 0);"
                    ),
                    false => format!("wp::grad_accum({g}, {idx}, {v}, __ctx);"),
                }
                }
            }
            AKind::GradClearOwn { array, index } => {
                format!(
                    "wp::grad_clear_own({}, {});",
                    self.adj(*array),
                    self.index(index)
                )
            }
            AKind::TileMapAdj {
                f,
                values,
                grads,
                dst,
            } => self.tile_map_adj(*f, values, grads, *dst, sp)?,
            AKind::LaneAdj { func, lanes, tile } => {
                let (x, t) = (self.adj(*lanes), self.adj(*tile));
                match *func {
                    "adj_tile_lanes" => format!("wp::adj_tile_lanes({x}, {t});"),
                    _ => format!("wp::adj_untile({t}, {x});"),
                }
            }
            AKind::RevLoop { body } => {
                self.line(
                    sp,
                    "{ const wp::i64 __count = wp::adstack_pop<wp::i64>(__stack);",
                );
                self.line(sp, "for (wp::i64 __k = 0; __k < __count; ++__k) {");
                self.e.after_tile_op = false;
                self.nested(body)?;
                "} }".into()
            }
        };
        self.line(sp, text);
        // After a compound statement, control may come from anywhere inside it.
        self.e.after_tile_op = coop;
        Ok(())
    }

    /// `__r`, the progression of a `for`.
    fn range(&mut self, range: &RangeSpec, sp: proc_macro2::Span) {
        let (s0, e0, incl) = (self.var(range.start), self.var(range.end), range.inclusive);
        self.line(
            sp,
            format!("wp::range_t __r = wp::range_new((wp::i64)({s0}), (wp::i64)({e0}), {incl});"),
        );
        for a in &range.adapters {
            let text = match a {
                RangeAdapter::Rev => "__r = wp::range_rev(__r);".to_string(),
                RangeAdapter::StepBy(k) => {
                    let k = self.var(*k);
                    format!("__r = wp::range_step_by(__r, (wp::i64)({k}), __ctx);")
                }
            };
            self.line(sp, text);
        }
    }

    /// An index: its variables, or the thread index, one component per dimension.
    fn index(&self, index: &Index) -> String {
        match index {
            Index::At(vs) => self.e.index(vs),
            Index::Thread(n) => {
                let ks: Vec<String> = (0..*n).map(|d| format!("__tid[{d}]")).collect();
                ks.join(", ")
            }
        }
    }

    /// `adj_<var>[index]` of a local array's adjoint (the index was checked by the replay;
    /// `local_at` keeps the access in bounds regardless, since a faulting thread goes on).
    fn adj_elem(&self, var: VarId, index: VarId) -> String {
        let (a, i) = (self.adj(var), self.var(index));
        let at = match self.f().ty(var) {
            Ty::Matrix(..) => "col_at",
            _ => "local_at",
        };
        format!("wp::{at}({a}, (wp::i64)({i}))")
    }

    pub(super) fn grad_arg(&self, g: &GradArg) -> String {
        match g {
            GradArg::Temp(k) => format!("__g{k}"),
            GradArg::Adj(v) | GradArg::ArrayGrad(v) => self.adj(*v),
        }
    }

    fn grad(&self, g: &GradSrc) -> Result<String, String> {
        Ok(match g {
            GradSrc::Seed => "__r".into(),
            GradSrc::SeedLane(l) => format!("__r.{}", cpp_member(l)),
            GradSrc::LaneSum(lanes) => {
                let ls: Vec<String> = lanes.iter().map(|l| format!("__r.{l}")).collect();
                ls.join(" + ")
            }
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
            GradSrc::Adj { var, path } => format!("{}{}", self.adj(*var), member_path(path)),
            GradSrc::Zero(like) => format!("wp::zero_like({})", self.var(*like)),
            GradSrc::AdjElem { var, index } => self.adj_elem(*var, *index),
            GradSrc::SeedElem(k) => format!("__r.data[{k}]"),
            GradSrc::ElemSum => "wp::local_sum(__r)".into(),
            GradSrc::Take { array, index, like } | GradSrc::Get { array, index, like } => {
                let f = match g {
                    // Lanes of a tiled kernel's block may have stored the same element: one
                    // of them takes its gradient (wp_adjoint_tile.h).
                    GradSrc::Take { .. } if self.f().tiled.is_some() => "take_lanes",
                    GradSrc::Take { .. } => "take",
                    _ => "get",
                };
                let (a, idx, v) = (self.adj(*array), self.index(index), self.var(*like));
                format!("wp::grad_{f}({a}, {idx}, wp::zero_like({v}), __ctx)")
            }
            GradSrc::Custom { func, args } => {
                let args: Vec<String> = args.iter().map(|v| self.var(*v)).collect();
                format!("@@F{func}@@({}, __adj_ret, __ctx)", args.join(", "))
            }
        })
    }
}

/// `.a.b.c` in C++ (tuple elements are `f<k>`).
fn member_path(path: &[String]) -> String {
    path.iter().map(|m| format!(".{}", cpp_member(m))).collect()
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
