//! CUDA C++ back end: the IR to a source template for one kernel or func.
//!
//! The template is C++ over the builtin library in `warp-cuda/cuda/` (namespace `wp`), with
//! two kinds of placeholder that the runtime's assembler fills in when it builds the kernel's
//! translation unit:
//! - `@@SELF@@`: this function's C++ name;
//! - `@@F<k>@@`: the C++ name of the `k`-th func in this function's callee list.
//!
//! Funcs are named by the assembler, not here, because two funcs of the same name may live in
//! different modules and the macro cannot see module paths. Every statement is preceded by a
//! `#line` directive pointing at the user's Rust file and line, so NVRTC errors and device
//! faults name Rust source lines.
//!
//! Conventions shared with the library: every function takes a trailing `wp::ctx_t* __ctx`
//! (where faults are recorded); array parameters are `wp::array_t<T, N>`; integer arithmetic
//! goes through `wp::w_*`; `as` casts through `wp::cast<T>` (Rust semantics, no C++ UB);
//! a literal beside a value the macro cannot type is `wp::lit_like<decltype(v)>(..)`.

use crate::ir::*;
use crate::types::{Scalar, Ty};
use std::fmt::Write;

/// A CUDA template and what it needs.
pub struct CudaTemplate {
    pub source: String,
    /// The C++ return type of a func (`void` for kernels).
    pub ret: String,
    /// Library sections used (`scalar`, `vector`, `atomic`), beyond the always-present core.
    pub sections: Vec<&'static str>,
}

/// Emits the CUDA template of a kernel (`kind == Kernel`) or func.
pub fn emit(f: &Function, file: &str) -> Result<CudaTemplate, String> {
    let mut e = Emitter::new(f, file);
    e.pipeline = true;
    e.function()?;
    // Transform values need wp_transform.h even where no transform builtin is called (`inverse`
    // and `lerp` are in other sections); an object's type needs its section even in a kernel
    // that only passes it on to a func.
    // A local array's elements count as values of their type (`[SpatialVector; 4]`).
    let leaf = |mut t: &Ty| {
        while let Ty::LocalArray(e, _) = t {
            t = e;
        }
        t.clone()
    };
    if f.vars
        .iter()
        .any(|v| matches!(leaf(&v.ty), Ty::Transform(_)))
    {
        e.section("transform");
    }
    // Spatial values likewise need wp_spatial.h (`transpose`, `outer` and the operators'
    // adjoints of spatial types are there).
    if f.vars
        .iter()
        .any(|v| matches!(leaf(&v.ty), Ty::SpatialVector(_) | Ty::SpatialMatrix(_)))
    {
        e.section("spatial");
    }
    // Non-square matrices: their types, operators and adjoints are wp_matrix.h's.
    if f.vars.iter().any(|v| matches!(leaf(&v.ty), Ty::MatRC(..))) {
        e.section("matrix");
    }
    for v in &f.vars {
        if let Ty::Object(k) = v.ty {
            e.section(k.row().section);
            // A matrix of non-square blocks names their type (`wp::bsr_t<wp::Mat23>`).
            if let Some(Ty::MatRC(..)) = k.elem().and_then(|e| e.ty()) {
                e.section("matrix");
            }
        }
    }
    let ret = if matches!(f.ret, Ty::Unit) {
        "void".into()
    } else {
        cpp_type(&f.ret).unwrap_or_default()
    };
    Ok(CudaTemplate {
        source: fill_lengths(f, e.out)?,
        ret: fill_lengths(f, ret)?,
        sections: e.sections,
    })
}

pub(crate) struct Emitter<'a> {
    pub(crate) f: &'a Function,
    /// Which thread-index component each variable holds.
    pub(crate) tid: Vec<Option<u8>>,
    /// Variables read somewhere (a func result nobody reads may be `void`).
    used: Vec<bool>,
    pub(crate) out: String,
    pub(crate) indent: usize,
    file: String,
    pub(crate) sections: Vec<&'static str>,
    pub(crate) tmp: usize,
    /// Emit an adjoint's replay: atomics are not redone (zero), funcs are called through their
    /// replay (`@@F<k>@@_replay`), and a func is emitted as `@@SELF@@_replay`.
    pub(crate) replay: bool,
    /// `(array, loop variable, flag)`: inside a native loop, accesses of `array` at exactly
    /// the loop variable are in bounds when `flag` (checked once before the loop) is true; an
    /// empty flag means always (the copy of the loop that runs when the check passed).
    in_range: Vec<(VarId, VarId, String)>,
    /// How many unswitched loops enclose the current statement (each doubles the code).
    unswitched: usize,
    /// The statement just printed was a tile operation (which ends in a barrier).
    pub(crate) after_tile_op: bool,
    /// Print a tiled kernel's GEMM k-loops pipelined (`back/cuda_tile_pipe.rs`): the forward
    /// kernel only, and not the plain copy printed beside a pipelined loop.
    pub(crate) pipeline: bool,
    /// Inside the loop printed beside a pipelined one: that pipe's C++ type, which its
    /// `tile_matmul` names (`wp::tile_matmul_acc_beside`).
    pub(crate) beside_pipe: Option<String>,
    /// The C++ types of the pipelined loops printed (their occupancy hint goes on the entry).
    pub(crate) pipes: Vec<String>,
    /// The user's line of the statement being printed, which a local array's index fault
    /// names.
    pub(crate) stmt_line: usize,
}

/// The entries that order and add a deterministic kernel's records after its launch
/// (`wp::det_prepare_at`, `det_high_at`, `det_apply_at` in wp_core.h; warp-runtime's
/// cuda/deterministic.rs launches them): emitted with the forward and with the adjoint, once
/// in a unit holding both.
pub(crate) const DET_ENTRIES: &str = "#if defined(__CUDACC__) && !defined(WP_DET_ENTRIES_@@ENTRY@@)\n\
#define WP_DET_ENTRIES_@@ENTRY@@\n\
extern \"C\" __global__ void @@ENTRY@@_det_prepare(wp::det_t d, wp::u32* word, wp::u32* order, wp::i64 n) {\n    \
for (wp::i64 i = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += (wp::i64)blockDim.x * gridDim.x) wp::det_prepare_at(d, word, order, i);\n}\n\
extern \"C\" __global__ void @@ENTRY@@_det_high(wp::det_t d, wp::u32* word, wp::u32* order, wp::i64 n) {\n    \
for (wp::i64 i = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += (wp::i64)blockDim.x * gridDim.x) wp::det_high_at(d, word, order, i);\n}\n\
extern \"C\" __global__ void @@ENTRY@@_det_apply(wp::det_t d, wp::u32* word, wp::u32* order, wp::i64 n) {\n    \
(void)word;\n    \
for (wp::i64 i = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += (wp::i64)blockDim.x * gridDim.x) wp::det_apply_at(d, order, n, i);\n}\n\
#endif\n";

/// An entry's parameter for the launch's fault record (`wp::launch_ctx_t`), which
/// `WP_GRID_CONST` keeps in parameter space (the library says why).
pub(crate) const ENTRY_CTX_PARAM: &str = "const WP_GRID_CONST wp::launch_ctx_t __ctx_launch";
/// The entry's line that makes a thread's context on that record (`__ctx_value`, whose address
/// the thread function takes).
pub(crate) const THREAD_CTX: &str = "wp::ctx_t __ctx_value = wp::ctx_make(&__ctx_launch);";

/// The entry's line that makes this thread's flat index in the launch (the entry then runs
/// the thread function if it is below `__launch.total`). 64-bit, so that launches over 2^31
/// threads work.
pub(crate) const ENTRY_FLAT: &str =
    "const wp::i64 __flat = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x;";

/// Unswitched loops nest at most this deep; deeper ones test their flag at each access.
const MAX_UNSWITCH_DEPTH: usize = 2;

/// The C++ spelling of a type the macro knows.
pub fn cpp_type(t: &Ty) -> Option<String> {
    Some(match t {
        Ty::Scalar(Scalar::Bool) => "bool".into(),
        Ty::Scalar(s) => format!("wp::{}", s.name()),
        Ty::Vector(..)
        | Ty::Matrix(..)
        | Ty::Quat(_)
        | Ty::Transform(_)
        | Ty::SpatialVector(_)
        | Ty::SpatialMatrix(_)
        | Ty::MatRC(..) => format!("wp::{}", t.glam_name()?),
        Ty::Array(e, n) => format!("wp::array_t<{}, {n}>", cpp_type(e)?),
        Ty::LocalArray(e, n) => format!("wp::local_array_t<{}, {}>", cpp_type(e)?, dim_cpp(n)),
        Ty::Struct(name) => name.clone(),
        // `wp::volume_t<T>`: the element a value type, or an index grid's `wp::VoxelIndex`.
        Ty::Object(k) => match k.elem() {
            Some(e) => {
                let elem = match e.ty() {
                    Some(t) => cpp_type(&t)?,
                    None => "wp::VoxelIndex".into(),
                };
                format!("{}<{elem}>", k.row().cuda)
            }
            None => k.row().cuda.into(),
        },
        // A unit value is a tuple's element only (a func with `&mut` parameters and no result).
        Ty::Unit => "wp::unit_t".into(),
        Ty::Tuple(ts) => {
            let ts: Option<Vec<String>> = ts.iter().map(cpp_type).collect();
            format!("wp::tuple_t<{}>", ts?.join(", "))
        }
        _ => return None,
    })
}

/// A local array's length in C++: a literal, or a placeholder for a const's value that
/// [`fill_lengths`] turns into the function's `@@K<k>@@` (a type is spelt without its
/// function at hand).
fn dim_cpp(n: &crate::types::Dim) -> String {
    match n {
        crate::types::Dim::Lit(n) => n.to_string(),
        crate::types::Dim::Const(p) => format!("@@LEN:{p}@@"),
    }
}

/// The template `src` of `f` with each local array length that names a const (`@@LEN:<path>@@`)
/// written as the const's value placeholder, `@@K<k>@@`.
pub(crate) fn fill_lengths(f: &Function, mut src: String) -> Result<String, String> {
    while let Some(at) = src.find("@@LEN:") {
        let rest = &src[at + 6..];
        let end = rest
            .find("@@")
            .ok_or("internal: an unterminated length placeholder")?;
        let want: syn::Path = syn::parse_str(&rest[..end]).map_err(|e| e.to_string())?;
        let k = f.consts.iter().position(|c| c == &want).ok_or_else(|| {
            format!(
                "internal: the length `{}` is not among the consts",
                &rest[..end]
            )
        })?;
        src.replace_range(at..at + 6 + end + 2, &format!("@@K{k}@@"));
    }
    Ok(src)
}

/// A member's C++ name: fields keep theirs; element `k` of a tuple (`wp::tuple_t`) is `f<k>`.
pub(crate) fn cpp_member(m: &str) -> String {
    if m.starts_with(|c: char| c.is_ascii_digit()) {
        format!("f{m}")
    } else {
        m.to_string()
    }
}

/// A float literal as C++ source of the given type, exactly (hex floats round-trip).
fn float_lit(v: f64, s: Scalar) -> String {
    if s == Scalar::F16 {
        // The literal rounded once to f16, by its bit pattern (the Rust backend's too).
        return format!("wp::f16_from_bits({:#06x})", crate::types::f16_bits(v));
    }
    if s == Scalar::BF16 {
        return format!("wp::bf16_from_bits({:#06x})", crate::types::bf16_bits(v));
    }
    let ty = if s == Scalar::F32 {
        "wp::f32"
    } else {
        "wp::f64"
    };
    if v.is_nan() {
        return format!("wp::nan<{ty}>()");
    }
    if v.is_infinite() {
        return format!("{}wp::inf<{ty}>()", if v < 0.0 { "-" } else { "" });
    }
    if s == Scalar::F32 {
        // f32 literal: the f32 value, written so that C++ parses exactly it.
        format!("{:?}f", v as f32).replace("inf", "INFINITY")
    } else {
        format!("{v:?}")
    }
}

fn int_lit(v: i128, s: Scalar) -> String {
    match s {
        Scalar::I64 | Scalar::Isize if v == i64::MIN as i128 => {
            "(-9223372036854775807LL - 1)".into()
        }
        Scalar::I32 if v == i32::MIN as i128 => "(-2147483647 - 1)".into(),
        Scalar::U64 | Scalar::Usize => format!("(wp::{})({}ULL)", s.name(), v as u64),
        Scalar::I64 | Scalar::Isize => format!("(wp::{})({}LL)", s.name(), v as i64),
        Scalar::U32 => format!("{}u", v as u32),
        Scalar::I32 => format!("{}", v as i32),
        _ => format!("(wp::{})({v})", s.name()),
    }
}

fn is_int(t: &Ty) -> bool {
    t.is_int_scalar() || matches!(t, Ty::Vector(s, _) if !s.is_float())
}

impl<'a> Emitter<'a> {
    pub(crate) fn new(f: &'a Function, file: &str) -> Self {
        Emitter {
            f,
            tid: crate::analysis::tid_components(f),
            used: used_vars(f),
            out: String::new(),
            indent: 1,
            file: file.to_string(),
            sections: Vec::new(),
            tmp: 0,
            replay: false,
            in_range: Vec::new(),
            unswitched: 0,
            after_tile_op: false,
            pipeline: false,
            beside_pipe: None,
            pipes: Vec::new(),
            stmt_line: 0,
        }
    }

    pub(crate) fn var(&self, v: VarId) -> String {
        match &self.f.vars[v].name {
            Some(n) => format!("{}_{v}", n.trim_start_matches("r#")),
            None => format!("t{v}"),
        }
    }

    /// The C++ type of a variable: its spelling when the macro knows it, else a type
    /// expression built from how the value was made (a callee's declared return type,
    /// `@@R<k>@@`, filled in by the assembler; `decltype` over `wp::declval` otherwise).
    pub(crate) fn type_expr(&self, v: VarId, depth: usize) -> Option<String> {
        if let Some(t) = cpp_type(self.f.ty(v)) {
            return Some(t);
        }
        if depth > 64 {
            return None;
        }
        let decl = |w: VarId| {
            self.type_expr(w, depth + 1)
                .map(|t| format!("wp::declval<{t}>()"))
        };
        let mut found = None;
        walk_stmts(&self.f.body, &mut |s| {
            if found.is_some() {
                return;
            }
            if let StmtKind::Assign { dst, op, .. } = &s.kind {
                if *dst == v {
                    found = Some(op.clone());
                }
            }
        });
        match found? {
            Op::Copy(w) | Op::LitLike(_, w, Like::Value) | Op::ZeroLike(w) => {
                self.type_expr(w, depth + 1)
            }
            Op::LitLike(_, w, Like::Scalar) => Some(format!(
                "wp::scalar_of_t<{}>",
                self.type_expr(w, depth + 1)?
            )),
            Op::Func { path, .. } => Some(format!(
                "@@R{}@@",
                self.f.callees.iter().position(|p| p == &path)?
            )),
            Op::Member(w, m) => Some(format!("decltype({}.{})", decl(w)?, cpp_member(&m))),
            Op::Const(p) => Some(format!(
                "decltype(@@K{}@@)",
                self.f.consts.iter().position(|c| c == &p)?
            )),
            Op::Binary(op, a, b) if op.is_comparison() => {
                let _ = (a, b);
                Some("bool".into())
            }
            Op::Binary(op, a, b) => Some(format!(
                "decltype({} {} {})",
                decl(a)?,
                op.symbol(),
                decl(b)?
            )),
            Op::Unary(UnOp::Neg, a) => Some(format!("decltype(-{})", decl(a)?)),
            Op::Builtin { builtin, args } if !builtin.is_atomic() && !builtin.faults() => {
                let args: Option<Vec<String>> = args.iter().map(|a| decl(*a)).collect();
                Some(format!("decltype({}({}))", builtin.cuda, args?.join(", ")))
            }
            _ => None,
        }
    }

    /// An access indexed exactly by the thread index: unchecked when the launch says the
    /// arrays cover the grid (`__FAST`, read once per thread from `launch_t::flags`; the branch
    /// is the same for every thread, and one function body keeps the code small).
    ///
    /// Likewise an access at exactly a native loop's variable, when a check before the loop
    /// found the loop's whole range inside the array. Returns the condition under which the
    /// access may skip its check, if any (empty: always).
    fn unchecked_when(&self, array: VarId, index: &[VarId]) -> Option<&str> {
        if crate::analysis::is_tid_access(self.f, &self.tid, array, index) {
            return Some("__FAST");
        }
        self.in_range
            .iter()
            .rev()
            .find(|(a, v, _)| *a == array && index == [*v])
            .map(|(_, _, flag)| flag.as_str())
    }

    pub(crate) fn section(&mut self, s: &'static str) {
        if !self.sections.contains(&s) {
            self.sections.push(s);
        }
    }

    pub(crate) fn line(&mut self, span: proc_macro2::Span, text: &str) {
        let line = span.start().line;
        if line > 0 {
            let _ = writeln!(self.out, "#line {line} \"{}\"", self.file);
        }
        for _ in 0..self.indent {
            self.out.push_str("    ");
        }
        self.out.push_str(text);
        self.out.push('\n');
    }

    /// The whole function (the forward template), consuming the emitter.
    pub(crate) fn function_text(mut self) -> Result<String, String> {
        self.function()?;
        Ok(self.out)
    }

    fn function(&mut self) -> Result<(), String> {
        let mut params: Vec<String> = Vec::new();
        for p in &self.f.params {
            let t = cpp_type(&p.ty)
                .ok_or_else(|| format!("parameter `{}` has no CUDA type", p.name))?;
            params.push(format!("{t} {}", self.var(p.var)));
        }
        match self.f.kind {
            FnKind::Kernel => {
                // The per-thread function; the entry point (emitted by the assembler) calls it
                // for its thread, so that `return;` ends only this thread.
                params.push("const wp::launch_t& __launch".into());
                params.push("wp::i64 __flat".into());
                params.push("wp::ctx_t* __ctx".into());
                if self.f.deterministic.is_some() {
                    // The thread's record slots (`det_entry_loop`).
                    params.push("wp::det_thread_t* __det".into());
                }
                let _ = writeln!(
                    self.out,
                    "static WP_FN void @@SELF@@({}) {{\n    const bool __FAST = (__launch.flags & wp::LAUNCH_FAST) != 0;",
                    params.join(", ")
                );
                if let Some(n) = self.f.tid_ndim {
                    let _ = writeln!(
                        self.out,
                        "    wp::i64 __tid[4];\n    wp::unflatten(__launch, __flat, __tid, {n});"
                    );
                }
                if self.f.tiled.is_some() {
                    self.section("tile");
                    self.tile_slots()?;
                }
            }
            FnKind::Func => {
                params.push("wp::ctx_t* __ctx".into());
                // A unit func's replay (`@@SELF@@_replay`) returns `wp::unit_t`, so that an
                // adjoint can assign its result like any other.
                let ret = match (&self.f.ret, self.replay) {
                    (Ty::Unit, false) => "void".to_string(),
                    (Ty::Unit, true) => "wp::unit_t".to_string(),
                    (t, _) => cpp_type(t).ok_or("the func's return type has no CUDA type")?,
                };
                let name = if self.replay { "_replay" } else { "" };
                let _ = writeln!(
                    self.out,
                    "static WP_FN {ret} @@SELF@@{name}({}) {{",
                    params.join(", ")
                );
            }
        }
        let body = self.f.body.clone();
        self.block(&body)?;
        if self.f.kind == FnKind::Func && (self.replay || !matches!(self.f.ret, Ty::Unit)) {
            // Rust proved every path returns; C++ compilers cannot always see it.
            let _ = writeln!(self.out, "    return {{}};");
        }
        self.out.push_str("}\n");
        if self.f.kind == FnKind::Kernel {
            // The entry point: one thread per element of the launch. The runtime launches
            // enough blocks to cover it (`cuda/launch.rs` refuses a launch that would need more
            // than CUDA's 2^31 - 1 blocks): a grid-stride loop cost 0.13 us a kernel in graph
            // replays of small kernels on an H200 (2,000 more instructions executed in a
            // 1024-thread launch), against 0.02 us for a 32-bit loop and none for this `if`.
            let mut decl: Vec<String> =
                vec!["wp::launch_t __launch".into(), ENTRY_CTX_PARAM.into()];
            let mut call: Vec<String> = Vec::new();
            for p in &self.f.params {
                decl.push(format!(
                    "{} {}",
                    cpp_type(&p.ty).expect("checked above"),
                    self.var(p.var)
                ));
                call.push(self.var(p.var));
            }
            call.extend(["__launch".into(), "__flat".into(), "&__ctx_value".into()]);
            if self.f.tiled.is_some() {
                let entry = self.tile_entry(&decl.join(", "), &call.join(", "));
                self.out.push_str(&entry);
                return Ok(());
            }
            let det = self.f.deterministic.is_some();
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
            let _ = write!(
                self.out,
                "#ifdef __CUDACC__\nextern \"C\" __global__ void @@ENTRY@@({}) {{\n    \
                 {ENTRY_FLAT}\n    \
                 if (__flat < __launch.total) {{\n        \
                 {THREAD_CTX}\n        {begin}@@SELF@@({1});{end}\n    }}\n}}\n#endif\n",
                decl.join(", "),
                call.join(", ")
            );
            if det {
                self.out.push_str(DET_ENTRIES);
            }
        }
        Ok(())
    }

    fn block(&mut self, b: &Block) -> Result<(), String> {
        for s in b {
            self.stmt(s)?;
        }
        Ok(())
    }

    fn nested(&mut self, b: &Block) -> Result<(), String> {
        self.indent += 1;
        let r = self.block(b);
        self.indent -= 1;
        r
    }

    pub(crate) fn close(&mut self) {
        for _ in 0..self.indent {
            self.out.push_str("    ");
        }
        self.out.push_str("}\n");
    }

    /// A loop `head { body }` whose accesses of `arrays` at exactly `var` are in bounds when
    /// `inside(array)` holds for each (printed as a C++ condition): `flag` is set to that
    /// before the loop, and the loop is emitted twice, without those accesses' checks when
    /// `flag` holds, with them otherwise. Past [`MAX_UNSWITCH_DEPTH`] nested copies (each
    /// doubles the code), one copy tests `flag` at each access instead.
    #[allow(clippy::too_many_arguments)]
    fn unswitched_loop(
        &mut self,
        sp: proc_macro2::Span,
        head: &str,
        body: &Block,
        var: VarId,
        arrays: &[VarId],
        flag: &str,
        inside: impl Fn(&str) -> String,
    ) -> Result<(), String> {
        let conds: Vec<String> = arrays.iter().map(|a| inside(&self.var(*a))).collect();
        self.line(sp, &format!("const bool {flag} = {};", conds.join(" && ")));
        if self.unswitched >= MAX_UNSWITCH_DEPTH {
            return self.native_loop(sp, head, body, var, arrays, flag);
        }
        self.unswitched += 1;
        self.line(sp, &format!("if ({flag}) {{"));
        self.indent += 1;
        let fast = self.native_loop(sp, head, body, var, arrays, "");
        self.indent -= 1;
        self.line(sp, "} else {");
        self.indent += 1;
        let checked = self.native_loop(sp, head, body, var, &[], "");
        self.indent -= 1;
        self.unswitched -= 1;
        fast.and(checked)?;
        self.close();
        Ok(())
    }

    /// A native loop `head { body }` in which accesses of `arrays` at exactly `var` skip
    /// their checks when `flag` holds (always, for an empty flag).
    fn native_loop(
        &mut self,
        sp: proc_macro2::Span,
        head: &str,
        body: &Block,
        var: VarId,
        arrays: &[VarId],
        flag: &str,
    ) -> Result<(), String> {
        for a in arrays {
            self.in_range.push((*a, var, flag.to_string()));
        }
        self.line(sp, head);
        let r = self.nested(body);
        self.in_range.truncate(self.in_range.len() - arrays.len());
        r?;
        self.close();
        Ok(())
    }

    pub(crate) fn stmt(&mut self, s: &Stmt) -> Result<(), String> {
        if self.f.tiled.is_some() && self.is_tile_stmt(s) {
            return self.tile_stmt(s);
        }
        self.after_tile_op = false;
        self.stmt_line = s.span.start().line;
        let r = self.stmt_plain(s);
        // Control may arrive after a compound statement from before it (a loop that ran no
        // iteration): no tile operation's barrier is known to precede.
        self.after_tile_op = false;
        r
    }

    fn stmt_plain(&mut self, s: &Stmt) -> Result<(), String> {
        let sp = s.span;
        if self.pipeline && self.f.tiled.is_some() {
            if let Some(g) = self.gemm_loop(s) {
                return self.gemm_pipe_loop(s, &g);
            }
        }
        match &s.kind {
            StmtKind::Declare { var } => {
                let t = self
                    .type_expr(*var, 0)
                    .ok_or("an `if` expression whose value the macro cannot type is not supported on CUDA yet: annotate the `let`")?;
                let v = self.var(*var);
                self.line(sp, &format!("{t} {v}{{}};"));
            }
            StmtKind::Assign {
                dst,
                op: op @ Op::Func { .. },
                define: true,
            } if !self.used[*dst] => {
                let call = self.op(op, *dst)?;
                self.line(sp, &format!("{call};"));
            }
            // A builtin that is a statement (`volume_store`): the call alone; not redone in an
            // adjoint's replay (the forward launch did it).
            StmtKind::Assign {
                dst,
                op: op @ Op::Builtin { builtin, .. },
                ..
            } if matches!(self.f.ty(*dst), Ty::Unit) => {
                if !(self.replay && builtin.grad == crate::builtins::Grad::Effect) {
                    let call = self.op(op, *dst)?;
                    self.line(sp, &format!("{call};"));
                }
            }
            StmtKind::Assign { dst, op, define } => {
                let rhs = self.op(op, *dst)?;
                let v = self.var(*dst);
                if *define {
                    let t = cpp_type(self.f.ty(*dst)).unwrap_or_else(|| "auto".into());
                    self.line(sp, &format!("{t} {v} = {rhs};"));
                } else {
                    self.line(sp, &format!("{v} = {rhs};"));
                }
            }
            StmtKind::Store {
                array,
                index,
                value,
            } => {
                let idx = self.index(index);
                let (a, val) = (self.var(*array), self.var(*value));
                if let Some(c) = self.unchecked_when(*array, index) {
                    let text = if c.is_empty() {
                        format!("wp::store_unchecked({a}, {idx}, {val});")
                    } else {
                        format!("if ({c}) wp::store_unchecked({a}, {idx}, {val}); else wp::store({a}, {idx}, {val}, __ctx);")
                    };
                    self.line(sp, &text);
                } else {
                    self.line(sp, &format!("wp::store({a}, {idx}, {val}, __ctx);"));
                }
            }
            StmtKind::SetMember { var, path, value } => {
                let (v, val) = (self.var(*var), self.var(*value));
                let path: Vec<String> = path.iter().map(|m| cpp_member(m)).collect();
                self.line(sp, &format!("{v}.{} = {val};", path.join(".")));
            }
            StmtKind::SetElem { var, index, value } => {
                let (a, i, val) = (self.var(*var), self.var(*index), self.var(*value));
                let line = sp.start().line;
                let set = match self.f.vars[*var].ty {
                    Ty::Matrix(..) => "col_set",
                    _ => "local_set",
                };
                self.line(
                    sp,
                    &format!("wp::{set}({a}, (wp::i64)({i}), {val}, {line}, __ctx);"),
                );
            }
            StmtKind::If { cond, then, els } => {
                let c = self.var(*cond);
                self.line(sp, &format!("if ({c}) {{"));
                self.nested(then)?;
                if !els.is_empty() {
                    self.line(sp, "} else {");
                    self.nested(els)?;
                }
                self.close();
            }
            // `a..b` with no adapters, over a type the macro knows: a native loop. `v < b`
            // before each increment means `v` never passes `b`, so no overflow, exactly Rust's
            // iteration; and no 64-bit progression arithmetic in hot loops.
            StmtKind::For { var, range, body }
                if range.adapters.is_empty()
                    && !range.inclusive
                    && !self.f.vars[*var].mutable
                    && self.f.ty(*var).is_int_scalar()
                    && self.f.ty(range.start) == self.f.ty(*var)
                    && self.f.ty(range.end) == self.f.ty(*var) =>
            {
                let t = cpp_type(self.f.ty(*var)).expect("integer");
                let (s0, e0, v) = (self.var(range.start), self.var(range.end), self.var(*var));
                self.tmp += 1;
                let k = self.tmp;
                // Rust evaluates the end once: a body that assigns the variable holding it
                // must not move it.
                let end = format!("__end{k}");
                let head = format!("for ({t} {v} = {s0}, {end} = {e0}; {v} < {end}; ++{v}) {{");
                // One check before the loop covers every access at exactly the loop variable
                // of a 1-D array parameter. The loop is emitted twice: a copy without those
                // checks, run when the range is inside every such array, and the checked one
                // (a fault, or a `break` before the end, behaves exactly as per-access checks
                // would). A flag tested at each access instead would keep the checked path in
                // the hot loop: measured 1.28x slower on the n-body benchmark.
                let arrays = crate::analysis::loop_indexed_params(self.f, body, *var);
                if arrays.is_empty() {
                    return self.native_loop(sp, &head, body, *var, &[], "");
                }
                let inside = |a: &str| format!("wp::range_inside({a}, {s0}, {e0})");
                self.unswitched_loop(sp, &head, body, *var, &arrays, &format!("__inb{k}"), inside)?;
            }
            StmtKind::For { var, range, body } => {
                self.tmp += 1;
                let r = format!("__range{}", self.tmp);
                let n = format!("__n{}", self.tmp);
                let (s0, e0) = (self.var(range.start), self.var(range.end));
                self.line(sp, "{");
                self.indent += 1;
                self.line(
                    sp,
                    &format!(
                        "wp::range_t {r} = wp::range_new((wp::i64)({s0}), (wp::i64)({e0}), {});",
                        range.inclusive
                    ),
                );
                for a in &range.adapters {
                    match a {
                        RangeAdapter::Rev => self.line(sp, &format!("{r} = wp::range_rev({r});")),
                        RangeAdapter::StepBy(k) => {
                            let k = self.var(*k);
                            self.line(
                                sp,
                                &format!("{r} = wp::range_step_by({r}, (wp::i64)({k}), __ctx);"),
                            );
                        }
                    }
                }
                let t = self
                    .type_expr(*var, 0)
                    .unwrap_or_else(|| format!("decltype({e0})"));
                let v = self.var(*var);
                self.line(
                    sp,
                    &format!("for (wp::i64 {n} = 0; {n} < {r}.count; ++{n}) {{"),
                );
                self.indent += 1;
                self.line(
                    sp,
                    &format!("{t} {v} = wp::cast<{t}>(wp::range_at({r}, {n}));"),
                );
                self.block(body)?;
                self.indent -= 1;
                self.close();
                self.indent -= 1;
                self.close();
            }
            // A query loop whose items are below a bound of the object (`next` checks each):
            // one check before the loop that each 1-D array parameter indexed by the loop
            // variable holds that many elements covers all those accesses, as a native loop's
            // range check does, and the loop is emitted twice in the same way. Forward only:
            // the adjoint's replay keeps its single, checked copy.
            StmtKind::Loop { body } => {
                let query = (!self.replay)
                    .then(|| crate::analysis::bounded_query_loop(self.f, body))
                    .flatten()
                    .map(|(object, j, bound)| {
                        let arrays = crate::analysis::loop_indexed_params(self.f, body, j);
                        (object, j, bound, arrays)
                    })
                    .filter(|(.., arrays)| !arrays.is_empty());
                let Some((object, j, bound, arrays)) = query else {
                    self.line(sp, "for (;;) {");
                    self.nested(body)?;
                    self.close();
                    return Ok(());
                };
                self.tmp += 1;
                let flag = format!("__inb{}", self.tmp);
                let n = format!("{bound}({})", self.var(object));
                let inside = |a: &str| format!("wp::range_inside({a}, (wp::i64)0, {n})");
                self.unswitched_loop(sp, "for (;;) {", body, j, &arrays, &flag, inside)?;
            }
            StmtKind::ExitIf { .. } => {
                return Err(
                    "internal: an adjoint-only statement reached the forward emitter".into(),
                )
            }
            StmtKind::Break => self.line(sp, "break;"),
            StmtKind::Continue => self.line(sp, "continue;"),
            StmtKind::Return { value: None } if self.replay => {
                self.line(sp, "return wp::unit_t{};")
            }
            StmtKind::Return { value: None } => self.line(sp, "return;"),
            StmtKind::Return { value: Some(v) } => {
                let v = self.var(*v);
                self.line(sp, &format!("return {v};"));
            }
            StmtKind::Print { pieces, newline } => {
                self.section("print");
                let mut parts = Vec::new();
                for p in pieces {
                    match p {
                        FmtPiece::Text(t) => {
                            parts.push(format!("printf(\"%s\", {});", c_string(t)))
                        }
                        FmtPiece::Arg { var, .. } => {
                            parts.push(format!("wp::print_value({});", self.var(*var)))
                        }
                    }
                }
                if *newline {
                    parts.push("printf(\"\\n\");".into());
                }
                self.line(sp, &parts.join(" "));
            }
            StmtKind::Assert { cond, .. } => {
                // The record carries the line and column, by which the host finds the message
                // in the kernel's (or a callee's) `asserts` table, and the thread's flat launch
                // index (a func does not know it: -1). A kernel's thread then ends, as the CPU's
                // stops at the fault: code after an assertion used as a guard (a loop that
                // ends only for finite values) does not run. (`return` ends this flat index
                // only: the thread function is the entry's callee.) A tiled kernel's lanes go on,
                // since its barriers need every lane, and so does a func's caller.
                let c = self.var(*cond);
                let (line, column) = (sp.start().line, sp.start().column);
                let (thread, end) = match self.f.kind {
                    FnKind::Kernel if self.f.tiled.is_none() => ("__flat", " return;"),
                    FnKind::Kernel => ("__flat", ""),
                    FnKind::Func => ("-1", ""),
                };
                self.line(
                    sp,
                    &format!(
                        "if (!{c}) {{ wp::assert_fail(__ctx, {line}, {column}, {thread});{end} }}"
                    ),
                );
            }
        }
        Ok(())
    }

    pub(crate) fn index(&self, index: &[VarId]) -> String {
        index
            .iter()
            .map(|v| format!("(wp::i64)({})", self.var(*v)))
            .collect::<Vec<_>>()
            .join(", ")
    }

    pub(crate) fn op(&mut self, op: &Op, dst: VarId) -> Result<String, String> {
        let ty = self.f.ty(dst).clone();
        Ok(match op {
            Op::Lane => "((wp::usize)threadIdx.x)".into(),
            Op::DebugMode => "wp::debug_mode(__ctx)".into(),
            Op::TileMap { .. } | Op::TileReduce { .. } => {
                return Err("`tile_map` and `tile_reduce` are tile statements".into())
            }
            Op::Lit(Lit::Bool(b)) => b.to_string(),
            Op::Lit(Lit::Int(v)) => match &ty {
                Ty::Scalar(s) if s.is_int() => int_lit(*v, *s),
                Ty::Scalar(s) if s.is_float() => float_lit(*v as f64, *s),
                // Deferred on the CPU means rustc types it; in C++ an int literal is `int`.
                _ => format!("{v}"),
            },
            Op::Lit(Lit::Float(v)) => match &ty {
                Ty::Scalar(s) if s.is_float() => float_lit(*v, *s),
                _ => format!("{v:?}"),
            },
            Op::LitLike(l, like, kind) => {
                let v = match l {
                    Lit::Int(i) => *i as f64,
                    Lit::Float(f) => *f,
                    Lit::Bool(_) => return Err("bool literal beside an untyped value".into()),
                };
                let f = match kind {
                    Like::Value => "lit_like",
                    Like::Scalar => "scalar_lit_like",
                };
                format!("wp::{f}<decltype({})>({v:?})", self.var(*like))
            }
            // Value-initialised: zero for every kernel type (the C++ types are aggregates),
            // and needs no adjoint header (a tangent kernel is a forward unit).
            Op::ZeroLike(like) => format!(
                "typename wp::detail::remove_cvref<decltype({})>::type{{}}",
                self.var(*like)
            ),
            Op::Copy(v) => self.var(*v),
            Op::Unary(UnOp::Neg, v) if is_int(self.f.ty(*v)) => {
                format!("wp::w_neg({})", self.var(*v))
            }
            Op::Unary(UnOp::Neg, v) => format!("-{}", self.var(*v)),
            Op::Unary(UnOp::Not, v) if *self.f.ty(*v) == crate::types::BOOL => {
                format!("!{}", self.var(*v))
            }
            // Rust's `!` is logical on bool and bitwise on integers; a func's result may be either.
            Op::Unary(UnOp::Not, v) if self.f.ty(*v).is_deferred() => {
                format!("wp::not_({})", self.var(*v))
            }
            Op::Unary(UnOp::Not, v) => format!("~{}", self.var(*v)),
            Op::Binary(op, l, r) => {
                let (lt, rt) = (self.f.ty(*l).clone(), self.f.ty(*r).clone());
                let (mut a, mut b) = (self.var(*l), self.var(*r));
                let int = is_int(&lt) && is_int(&rt);
                if int && !op.is_comparison() && !matches!(op, BinOp::Shl | BinOp::Shr) {
                    if let (Ty::Scalar(_), v @ Ty::Vector(..)) = (&lt, &rt) {
                        a = format!("wp::{}_splat({a})", v.glam_name().unwrap_or_default());
                    }
                    if let (v @ Ty::Vector(..), Ty::Scalar(_)) = (&lt, &rt) {
                        b = format!("wp::{}_splat({b})", v.glam_name().unwrap_or_default());
                    }
                }
                match op {
                    BinOp::Add if int => format!("wp::w_add({a}, {b})"),
                    BinOp::Sub if int => format!("wp::w_sub({a}, {b})"),
                    BinOp::Mul if int => format!("wp::w_mul({a}, {b})"),
                    BinOp::Div if int => format!("wp::w_div({a}, {b}, __ctx)"),
                    BinOp::Rem if int => format!("wp::w_rem({a}, {b}, __ctx)"),
                    BinOp::Shl if int => format!("wp::w_shl({a}, (wp::u32)({b}))"),
                    BinOp::Shr if int => format!("wp::w_shr({a}, (wp::u32)({b}))"),
                    // Float `%` is C's fmod, as in Rust.
                    BinOp::Rem if matches!(lt, Ty::Scalar(s) if s.is_float()) => {
                        format!("wp::fmod({a}, {b})")
                    }
                    _ => format!("({a} {} {b})", op.symbol()),
                }
            }
            Op::Cast(v, t) => {
                let t = cpp_type(t).ok_or("cast to a non-scalar")?;
                format!("wp::cast<{t}>({})", self.var(*v))
            }
            Op::Builtin { builtin, args } => {
                self.section(builtin.section);
                if builtin.is_atomic() && self.replay {
                    // Not redone in an adjoint's replay: the forward launch did it.
                    let val = self.var(args[args.len() - 1]);
                    format!("wp::zero_like({val})")
                } else if self.f.deterministic.is_some()
                    && crate::analysis::float_accumulation(self.f, builtin, args)
                {
                    // Recorded in the thread's slots, added after the launch in launch order
                    // (`wp::det_atomic_add`, wp_core.h).
                    let a = self.var(args[0]);
                    let idx = self.index(&args[1..args.len() - 1]);
                    let v = self.var(args[args.len() - 1]);
                    format!("wp::det_{}({a}, {idx}, {v}, __det, __ctx)", builtin.name)
                } else if builtin.is_atomic() {
                    let a = self.var(args[0]);
                    let vals_at = args.len() - builtin.atomic_values();
                    let idx = self.index(&args[1..vals_at]);
                    let vals: Vec<String> = args[vals_at..].iter().map(|v| self.var(*v)).collect();
                    format!("{}({a}, {idx}, {}, __ctx)", builtin.cuda, vals.join(", "))
                } else if builtin.faults() {
                    // `lower_bound(a, .., __ctx)`, `hash_grid_query(grid, .., __ctx)`: checked
                    // reads of the array or of the object's buffers.
                    let args: Vec<String> = args.iter().map(|v| self.var(*v)).collect();
                    format!("{}({}, __ctx)", builtin.cuda, args.join(", "))
                } else {
                    let args: Vec<String> = args.iter().map(|v| self.var(*v)).collect();
                    format!("{}({})", builtin.cuda, args.join(", "))
                }
            }
            Op::Func { path, args } => {
                let k = self
                    .f
                    .callees
                    .iter()
                    .position(|p| p == path)
                    .ok_or("callee not recorded")?;
                let mut args: Vec<String> = args.iter().map(|v| self.var(*v)).collect();
                args.push("__ctx".into());
                let suffix = if self.replay { "_replay" } else { "" };
                format!("@@F{k}@@{suffix}({})", args.join(", "))
            }
            Op::Load { array, index } if self.unchecked_when(*array, index).is_some() => {
                let c = self.unchecked_when(*array, index).expect("guarded");
                let (a, idx) = (self.var(*array), self.index(index));
                if c.is_empty() {
                    format!("wp::load_unchecked({a}, {idx})")
                } else {
                    format!("({c} ? wp::load_unchecked({a}, {idx}) : wp::load({a}, {idx}, __ctx))")
                }
            }
            Op::Load { array, index } => format!(
                "wp::load({}, {}, __ctx)",
                self.var(*array),
                self.index(index)
            ),
            Op::Member(v, m) => format!("{}.{}", self.var(*v), cpp_member(m)),
            Op::Index { array, index } => format!(
                "wp::{}({}, (wp::i64)({}), {}, __ctx)",
                match self.f.vars[*array].ty {
                    Ty::Matrix(..) => "col_get",
                    _ => "local_get",
                },
                self.var(*array),
                self.var(*index),
                self.stmt_line
            ),
            // C++ aggregate initialisation would need the fields in declaration order, which
            // the macro cannot see: a zero (or the base) value with the fields set by name.
            Op::Construct {
                ty,
                ctor: Ctor::Fields { names, base, .. },
                args,
            } => {
                let t = cpp_type(ty).ok_or("a struct literal of no struct")?;
                let mut body = match base {
                    true => format!("{t} __s = {};", self.var(args[names.len()])),
                    false => format!("{t} __s{{}};"),
                };
                for (n, v) in names.iter().zip(args) {
                    write!(body, " __s.{n} = {};", self.var(*v)).expect("a String");
                }
                format!("([&]() {{ {body} return __s; }}())")
            }
            Op::Construct {
                ty: t @ Ty::LocalArray(..),
                ctor,
                args,
            } => {
                let t = cpp_type(t).ok_or("a local array of elements without a C++ type")?;
                let args: Vec<String> = args.iter().map(|v| self.var(*v)).collect();
                match ctor {
                    Ctor::Splat => format!("{t}::splat({})", args.join(", ")),
                    _ => format!("{t}{{{{{}}}}}", args.join(", ")),
                }
            }
            Op::Construct { ty: t, ctor, args } => {
                let name = t.glam_name().ok_or("constructed types are glam types")?;
                let args: Vec<String> = args.iter().map(|v| self.var(*v)).collect();
                match (t, ctor) {
                    (Ty::Vector(..), Ctor::Components) => {
                        format!("wp::{name}_new({})", args.join(", "))
                    }
                    (Ty::Quat(_), Ctor::Components) => {
                        format!("wp::{name}_from_xyzw({})", args.join(", "))
                    }
                    (Ty::Matrix(..), Ctor::Components) => {
                        format!("wp::{name}_from_cols({})", args.join(", "))
                    }
                    (Ty::SpatialMatrix(_) | Ty::MatRC(..), Ctor::Components) => {
                        format!("wp::{name}_from_rows({})", args.join(", "))
                    }
                    (Ty::Vector(..), Ctor::Splat) => {
                        format!("wp::{name}_splat({})", args.join(", "))
                    }
                    (Ty::Matrix(..), Ctor::Splat) => {
                        format!("wp::{name}_from_diagonal({})", args.join(", "))
                    }
                    (_, Ctor::Const(c)) => format!("wp::{name}_{c}()"),
                    _ => return Err("unsupported constructor".into()),
                }
            }
            // `wp::make_tuple` deduces the elements' types (which the macro may not see).
            Op::Tuple(args) if args.is_empty() => "wp::unit_t{}".into(),
            Op::Tuple(args) => {
                let args: Vec<String> = args.iter().map(|v| self.var(*v)).collect();
                format!("wp::make_tuple({})", args.join(", "))
            }
            Op::Tid(k) => format!("(wp::usize)__tid[{k}]"),
            Op::Extent(a, k) => format!("(wp::usize)wp::extent({}, {k})", self.var(*a)),
            Op::Len(a) => format!("(wp::usize)wp::len({})", self.var(*a)),
            Op::Const(p) => format!(
                "@@K{}@@",
                self.f
                    .consts
                    .iter()
                    .position(|c| c == p)
                    .expect("a recorded const")
            ),
            Op::ViewCheck {
                array,
                index,
                bound,
                inclusive,
            } => format!(
                "wp::view_check({}, (wp::i64){}, {}, {inclusive}, __ctx)",
                self.var(*array),
                self.var(*index),
                self.var(*bound)
            ),
        })
    }
}

/// Which variables are read by some statement.
fn used_vars(f: &Function) -> Vec<bool> {
    let mut used = vec![false; f.vars.len()];
    walk_stmts(&f.body, &mut |s| {
        s.kind.for_each_read(&mut |v| used[v] = true)
    });
    used
}

/// A C string literal.
fn c_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '%' => out.push('%'),
            c if c.is_ascii() && !c.is_ascii_control() => out.push(c),
            c => {
                let mut buf = [0u8; 4];
                for b in c.encode_utf8(&mut buf).bytes() {
                    let _ = write!(out, "\\x{b:02x}\"\"");
                }
            }
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod tests;
