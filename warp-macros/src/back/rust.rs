//! Rust back end: the IR to the CPU forward code (what the rayon executor runs per thread).
//!
//! Each statement is emitted with the user's span, so a rustc error in generated code points
//! at the kernel source. Arithmetic follows `warp_core::ops`: integers wrap, integer division
//! by zero is a fault; every array access is checked and a failed check is a fault (`?`).

use crate::ir::*;
use crate::types::{Scalar, Ty};
use proc_macro2::{Literal, Span, TokenStream};
use quote::{format_ident, quote, quote_spanned, ToTokens};

/// Integer scalars and integer vectors: the types with wrapping arithmetic.
fn is_int(t: &Ty) -> bool {
    t.is_int_scalar() || matches!(t, Ty::Vector(s, _) if !s.is_float())
}

/// Emits Rust for one lowered function.
pub struct RustEmitter<'a> {
    pub f: &'a Function,
    /// Which thread-index component each variable holds (see `analysis::tid_components`).
    pub tid: Vec<Option<u8>>,
    /// Emit expressions for an adjoint's replay (of a body `middle::adjoint` prepared): atomics
    /// are not redone (zero) and funcs are called through their replay.
    pub replay: bool,
    /// Printing a tiled kernel's lane region (`back::rust_tile`): a `return` ends this lane's
    /// part of the block, not the block.
    pub in_lanes: std::cell::Cell<bool>,
}

impl<'a> RustEmitter<'a> {
    pub fn new(f: &'a Function) -> Self {
        RustEmitter {
            f,
            tid: crate::analysis::tid_components(f),
            replay: false,
            in_lanes: std::cell::Cell::new(false),
        }
    }

    /// Accesses indexed by the thread index skip their per-thread check when the launch has
    /// checked, once per chunk, that the array covers the grid (`__FAST`).
    fn fast(&self, array: VarId, index: &[VarId]) -> bool {
        crate::analysis::is_tid_access(self.f, &self.tid, array, index)
    }

    pub fn var(&self, v: VarId) -> syn::Ident {
        match &self.f.vars[v].name {
            Some(n) => format_ident!("{}_{}", n.trim_start_matches("r#"), v),
            None => format_ident!("__t{}", v),
        }
    }

    fn name_lit(&self) -> Literal {
        Literal::string(&self.f.name)
    }

    /// The body: statements, in order.
    pub fn block(&self, b: &Block) -> TokenStream {
        b.iter().map(|s| self.stmt(s)).collect()
    }

    fn stmt(&self, s: &Stmt) -> TokenStream {
        let sp = s.span;
        match &s.kind {
            StmtKind::Declare { var } => {
                let v = self.var(*var);
                match ty_tokens(&self.f.vars[*var].ty) {
                    Some(t) => quote_spanned!(sp=> let mut #v: #t;),
                    None => quote_spanned!(sp=> let mut #v;),
                }
            }
            StmtKind::Assign { dst, op, define } => {
                let v = self.var(*dst);
                let rhs = self.op(op, &self.f.vars[*dst].ty, sp);
                if !define {
                    return quote_spanned!(sp=> #v = #rhs;);
                }
                let m = if self.f.vars[*dst].mutable {
                    quote!(mut)
                } else {
                    quote!()
                };
                match ty_tokens(&self.f.vars[*dst].ty) {
                    Some(t) => quote_spanned!(sp=> let #m #v: #t = #rhs;),
                    None => quote_spanned!(sp=> let #m #v = #rhs;),
                }
            }
            StmtKind::Store {
                array,
                index,
                value,
            } => {
                let a = self.var(*array);
                let idx = self.index(index);
                let val = self.var(*value);
                if self.fast(*array, index) {
                    quote_spanned!(sp=> if __FAST { unsafe { #a.store_unchecked(#idx, #val) } } else { #a.store(#idx, #val)?; })
                } else {
                    quote_spanned!(sp=> #a.store(#idx, #val)?;)
                }
            }
            StmtKind::SetMember { var, path, value } => {
                let v = self.var(*var);
                let path = path.iter().map(|m| member_tokens(m));
                let val = self.var(*value);
                quote_spanned!(sp=> #v #(.#path)* = #val;)
            }
            StmtKind::SetElem { var, index, value } => {
                let (a, i, val) = (self.var(*var), self.var(*index), self.var(*value));
                let (name, line) = (self.name_lit(), line_lit(sp));
                let set = match self.f.vars[*var].ty {
                    Ty::Matrix(..) => quote!(col_set),
                    _ => quote!(set),
                };
                quote_spanned!(sp=> __wp::local_array::#set(&mut #a, #i, #val, #name, #line)?;)
            }
            StmtKind::If { cond, then, els } => {
                let c = self.var(*cond);
                let t = self.block(then);
                if els.is_empty() {
                    quote_spanned!(sp=> if #c { #t })
                } else {
                    let e = self.block(els);
                    quote_spanned!(sp=> if #c { #t } else { #e })
                }
            }
            StmtKind::For { .. } => self.for_loop(s, &|b| self.block(b)),
            StmtKind::Loop { body } => {
                let body = self.block(body);
                quote_spanned!(sp=> loop { #body })
            }
            StmtKind::ExitIf { flags } => {
                let fs = flags.iter().map(|v| self.var(*v));
                quote_spanned!(sp=> if false #(|| #fs)* { break; })
            }
            StmtKind::Break => quote_spanned!(sp=> break;),
            StmtKind::Continue => quote_spanned!(sp=> continue;),
            StmtKind::Return { value: None } if self.in_lanes.get() => {
                quote_spanned!(sp=> { __alive[__lane] = false; continue '__lanes; })
            }
            StmtKind::Return { value: None } => {
                quote_spanned!(sp=> return ::core::result::Result::Ok(());)
            }
            StmtKind::Return { value: Some(v) } => {
                let v = self.var(*v);
                quote_spanned!(sp=> return ::core::result::Result::Ok(#v);)
            }
            StmtKind::Print { pieces, newline } => {
                let mut fmt = String::new();
                let mut args = Vec::new();
                for p in pieces {
                    match p {
                        FmtPiece::Text(t) => fmt.push_str(&t.replace('{', "{{").replace('}', "}}")),
                        FmtPiece::Arg { var, debug } => {
                            fmt.push_str(if *debug { "{:?}" } else { "{}" });
                            args.push(self.var(*var));
                        }
                    }
                }
                if *newline {
                    quote_spanned!(sp=> ::std::println!(#fmt #(, #args)*);)
                } else {
                    quote_spanned!(sp=> ::std::print!(#fmt #(, #args)*);)
                }
            }
            StmtKind::Assert { cond, message } => {
                let c = self.var(*cond);
                let name = self.name_lit();
                let line = Literal::u32_unsuffixed(sp.start().line as u32);
                let message = Literal::string(message);
                // A kernel names the thread by its flat launch index; a func does not know it.
                let thread = match self.f.kind {
                    FnKind::Kernel => quote!(::core::option::Option::Some(__flat)),
                    FnKind::Func => quote!(::core::option::Option::None),
                };
                quote_spanned!(sp=> if !#c {
                    return ::core::result::Result::Err(__wp::Fault::assertion_failed(#name, #line, #message, #thread));
                })
            }
        }
    }

    /// A `for` statement, its body printed by `print_body` (the block printer of a tiled
    /// kernel prints block-level loops with its own).
    pub fn for_loop(&self, s: &Stmt, print_body: &dyn Fn(&Block) -> TokenStream) -> TokenStream {
        let sp = s.span;
        let StmtKind::For { var, range, body } = &s.kind else {
            unreachable!("a for statement")
        };
        let start = self.var(range.start);
        let end = self.var(range.end);
        let incl = range.inclusive;
        let name = self.name_lit();
        let adapters = range.adapters.iter().map(|a| match a {
            RangeAdapter::Rev => quote!(.rev()),
            RangeAdapter::StepBy(k) => {
                let k = self.var(*k);
                quote!(.step_by(#k as i64, #name)?)
            }
        });
        let v = self.var(*var);
        let m = if self.f.vars[*var].mutable {
            quote!(mut)
        } else {
            quote!()
        };
        // A loop variable whose type the macro cannot see takes the end bound's type.
        let value = match ty_tokens(&self.f.vars[*var].ty) {
            Some(t) => quote!(__range.at(__n) as #t),
            None => quote!(__wp::ops::int_like(&#end, __range.at(__n))),
        };
        let body = print_body(body);
        quote_spanned! {sp=>
            {
                let __range = __wp::RangeProg::new(#start as i64, #end as i64, #incl) #(#adapters)*;
                for __n in 0..__range.count {
                    let #m #v = #value;
                    #body
                }
            }
        }
    }

    /// One statement, as the thread's body prints it.
    pub fn stmt_tokens(&self, s: &Stmt) -> TokenStream {
        self.stmt(s)
    }

    pub fn index_tokens(&self, index: &[VarId]) -> TokenStream {
        self.index(index)
    }

    pub fn op_tokens(&self, op: &Op, ty: &Ty, sp: Span) -> TokenStream {
        self.op(op, ty, sp)
    }

    fn index(&self, index: &[VarId]) -> TokenStream {
        let vs: Vec<_> = index.iter().map(|v| self.var(*v)).collect();
        if vs.len() == 1 {
            let v = &vs[0];
            quote!(#v)
        } else {
            quote!((#(#vs),*))
        }
    }

    fn op(&self, op: &Op, ty: &Ty, sp: Span) -> TokenStream {
        let name = self.name_lit();
        match op {
            Op::Lit(l) => literal(l, ty),
            // rustc types a lane-type literal from the builtin's signature, as in the user's
            // own code.
            Op::LitLike(l, _, Like::Scalar) => literal(l, &Ty::Deferred),
            Op::LitLike(l, like, Like::Value) => {
                let like = self.var(*like);
                let v = match l {
                    Lit::Int(i) => *i as f64,
                    Lit::Float(f) => *f,
                    Lit::Bool(_) => unreachable!("bool literals are always typed"),
                };
                let v = Literal::f64_unsuffixed(v);
                quote_spanned!(sp=> __wp::ops::lit_like(&#like, #v))
            }
            Op::ZeroLike(like) => {
                let like = self.var(*like);
                quote_spanned!(sp=> __wp::zero_like(&#like))
            }
            Op::Copy(v) => {
                let v = self.var(*v);
                quote_spanned!(sp=> #v)
            }
            Op::Unary(UnOp::Neg, v) => {
                let x = self.var(*v);
                if is_int(self.f.ty(*v)) {
                    quote_spanned!(sp=> __wp::ops::WrapInt::w_neg(#x))
                } else {
                    quote_spanned!(sp=> -#x)
                }
            }
            Op::Unary(UnOp::Not, v) => {
                let x = self.var(*v);
                quote_spanned!(sp=> !#x)
            }
            Op::Binary(op, l, r) => {
                let (mut a, mut b) = (
                    self.var(*l).into_token_stream(),
                    self.var(*r).into_token_stream(),
                );
                let (lt, rt) = (self.f.ty(*l), self.f.ty(*r));
                // Integer scalars and vectors wrap and fault on division by zero (warp_core::ops);
                // a scalar meeting an integer vector is splatted first.
                let int = is_int(lt) && is_int(rt);
                if int && !op.is_comparison() && !matches!(op, BinOp::Shl | BinOp::Shr) {
                    if let (Ty::Scalar(_), v @ Ty::Vector(..)) = (lt, rt) {
                        let v = ty_tokens(v).expect("vector");
                        a = quote!(#v::splat(#a));
                    }
                    if let (v @ Ty::Vector(..), Ty::Scalar(_)) = (lt, rt) {
                        let v = ty_tokens(v).expect("vector");
                        b = quote!(#v::splat(#b));
                    }
                }
                match op {
                    BinOp::Add if int => quote_spanned!(sp=> __wp::ops::WrapInt::w_add(#a, #b)),
                    BinOp::Sub if int => quote_spanned!(sp=> __wp::ops::WrapInt::w_sub(#a, #b)),
                    BinOp::Mul if int => quote_spanned!(sp=> __wp::ops::WrapInt::w_mul(#a, #b)),
                    BinOp::Div if int => {
                        quote_spanned!(sp=> __wp::ops::WrapInt::w_div(#a, #b, #name)?)
                    }
                    BinOp::Rem if int => {
                        quote_spanned!(sp=> __wp::ops::WrapInt::w_rem(#a, #b, #name)?)
                    }
                    BinOp::Shl if int => {
                        quote_spanned!(sp=> __wp::ops::WrapInt::w_shl(#a, #b as u32))
                    }
                    BinOp::Shr if int => {
                        quote_spanned!(sp=> __wp::ops::WrapInt::w_shr(#a, #b as u32))
                    }
                    _ => {
                        let o: TokenStream = op.symbol().parse().expect("operator");
                        quote_spanned!(sp=> (#a #o #b))
                    }
                }
            }
            Op::Cast(v, t) => {
                let x = self.var(*v);
                let from = self.f.ty(*v);
                let to = ty_tokens(t).expect("casts are to scalars");
                // `as` has no f16 or bf16 (the `half` crate's types): their casts go through
                // traits with `as`'s meaning (warp_core::float16, warp_core::bfloat16).
                if *t == Ty::Scalar(Scalar::F16) {
                    quote_spanned!(sp=> __wp::ops::ToF16::to_f16(#x))
                } else if *from == Ty::Scalar(Scalar::F16) {
                    quote_spanned!(sp=> <#to as __wp::ops::FromF16>::from_f16(#x))
                } else if *t == Ty::Scalar(Scalar::BF16) {
                    quote_spanned!(sp=> __wp::ops::ToBf16::to_bf16(#x))
                } else if *from == Ty::Scalar(Scalar::BF16) {
                    quote_spanned!(sp=> <#to as __wp::ops::FromBf16>::from_bf16(#x))
                } else if from.is_deferred() {
                    // A func's result may be an f16 or a bf16.
                    quote_spanned!(sp=> __wp::ops::AsScalar::<#to>::as_scalar(#x))
                } else {
                    quote_spanned!(sp=> (#x as #to))
                }
            }
            Op::Builtin { builtin, args } if builtin.is_tile() => {
                self.tile_op(builtin, args, ty, sp)
            }
            // In a tiled kernel, the block's size (the launch's `block_dim`).
            Op::Builtin { builtin, .. }
                if builtin.name == "block_dim" && self.f.tiled.is_some() =>
            {
                quote_spanned!(sp=> (__bd as i32))
            }
            Op::TileMap { f, args } => self.tile_map(*f, args, ty, sp),
            Op::TileReduce { f, arg } => self.tile_reduce(*f, *arg, sp),
            Op::Lane => quote_spanned!(sp=> __lane),
            // One relaxed load of the runtime's setting (`wp::config::debug`).
            Op::DebugMode => quote_spanned!(sp=> __wp::debug_mode()),
            Op::Builtin { builtin, args } => {
                let f = format_ident!("{}", builtin.rust);
                if builtin.grad == crate::builtins::Grad::Effect && self.replay {
                    // A store into an object: the forward launch did it.
                    quote_spanned!(sp=> ())
                } else if builtin.is_atomic() && self.replay {
                    // Not replayed: the forward launch did it.
                    quote_spanned!(sp=> __wp::adjoint::zero())
                } else if self.f.deterministic.is_some()
                    && crate::analysis::float_accumulation(self.f, builtin, args)
                {
                    // Recorded for the launch's ordered reduction (warp-runtime's
                    // cpu/deterministic.rs); `__flat` is the thread's flat launch index.
                    let a = self.var(args[0]);
                    let idx = self.index(&args[1..args.len() - 1]);
                    let v = self.var(args[args.len() - 1]);
                    let g = if builtin.name == "atomic_sub" {
                        quote!(sub)
                    } else {
                        quote!(add)
                    };
                    quote_spanned!(sp=> __wp::deterministic::#g(&#a, #idx, #v, __flat)?)
                } else if builtin.is_atomic() {
                    let a = self.var(args[0]);
                    let vals_at = args.len() - builtin.atomic_values();
                    let idx = self.index(&args[1..vals_at]);
                    let vals = args[vals_at..].iter().map(|v| self.var(*v));
                    quote_spanned!(sp=> __wp::builtins::#f(&#a, #idx, #(#vals),*)?)
                } else if builtin.faults() {
                    // `lower_bound(&a, ..)?`, `hash_grid_query(grid, ..)?`: checked reads of
                    // the array (by reference) or of the object's buffers (its view is Copy).
                    let args = args.iter().map(|v| {
                        let x = self.var(*v);
                        if matches!(self.f.ty(*v), crate::types::Ty::Array(..)) {
                            quote!(&#x)
                        } else {
                            quote!(#x)
                        }
                    });
                    quote_spanned!(sp=> __wp::builtins::#f(#(#args),*)?)
                } else {
                    let args = args.iter().map(|v| self.var(*v));
                    quote_spanned!(sp=> __wp::builtins::#f(#(#args),*))
                }
            }
            Op::Func { path, args } => {
                let args = args.iter().map(|v| self.var(*v));
                if self.replay {
                    quote_spanned!(sp=> #path::__wp_replay(#(#args),*)?)
                } else {
                    quote_spanned!(sp=> #path::__wp_cpu(#(#args),*)?)
                }
            }
            Op::Load { array, index } => {
                let a = self.var(*array);
                let idx = self.index(index);
                if self.fast(*array, index) {
                    quote_spanned!(sp=> (if __FAST { unsafe { #a.load_unchecked(#idx) } } else { #a.load(#idx)? }))
                } else {
                    quote_spanned!(sp=> #a.load(#idx)?)
                }
            }
            Op::Member(v, m) => {
                let x = self.var(*v);
                let m = member_tokens(m);
                quote_spanned!(sp=> #x.#m)
            }
            Op::Index { array, index } => {
                let (a, i, line) = (self.var(*array), self.var(*index), line_lit(sp));
                // A glam matrix's element is a column, read by its own function: `get` takes
                // no matrix, so a struct field's matrix (`s.m[i]`, typed only by rustc) does
                // not compile, as a single index of a matrix does not (`lane_index`).
                let get = match self.f.vars[*array].ty {
                    Ty::Matrix(..) => quote!(col_get),
                    _ => quote!(get),
                };
                quote_spanned!(sp=> __wp::local_array::#get(&#a, #i, #name, #line)?)
            }
            // Printed as the user's literal, so that rustc checks its fields at their spans.
            Op::Construct {
                ctor: Ctor::Fields { path, names, base },
                args,
                ..
            } => {
                // Each value at its field's name: a mistyped field's error points there.
                let vals = names.iter().zip(args).map(|(n, v)| {
                    let mut v = self.var(*v);
                    v.set_span(n.span());
                    v
                });
                let rest = base.then(|| {
                    let b = self.var(args[names.len()]);
                    quote_spanned!(sp=> ..#b)
                });
                quote_spanned!(sp=> #path { #(#names: #vals,)* #rest })
            }
            Op::Construct {
                ty: Ty::LocalArray(_, n),
                ctor,
                args,
            } => {
                let args: Vec<_> = args.iter().map(|v| self.var(*v)).collect();
                match ctor {
                    Ctor::Splat => {
                        let (v, n) = (&args[0], n.rust_tokens());
                        quote_spanned!(sp=> [#v; #n])
                    }
                    _ => quote_spanned!(sp=> [#(#args),*]),
                }
            }
            Op::Construct { ty, ctor, args } => {
                let t = ty_tokens(ty).expect("constructed types are glam types");
                let args: Vec<_> = args.iter().map(|v| self.var(*v)).collect();
                let f = match (ty, ctor) {
                    (Ty::Vector(..), Ctor::Components) => format_ident!("new"),
                    (Ty::Quat(_), Ctor::Components) => format_ident!("from_xyzw"),
                    (Ty::Matrix(..), Ctor::Components) => format_ident!("from_cols"),
                    (Ty::SpatialMatrix(_) | Ty::MatRC(..), Ctor::Components) => {
                        format_ident!("from_rows")
                    }
                    (Ty::Vector(..), Ctor::Splat) => format_ident!("splat"),
                    (Ty::Matrix(..), Ctor::Splat) => format_ident!("from_diagonal"),
                    (_, Ctor::Const(c)) => {
                        let c = format_ident!("{}", c);
                        return quote_spanned!(sp=> #t::#c);
                    }
                    _ => unreachable!("constructor checked by the front end"),
                };
                quote_spanned!(sp=> #t::#f(#(#args),*))
            }
            Op::Tid(k) => {
                let k = *k as usize;
                quote_spanned!(sp=> __tid[#k])
            }
            Op::Extent(a, k) => {
                let a = self.var(*a);
                let k = *k as usize;
                quote_spanned!(sp=> #a.shape()[#k])
            }
            Op::Len(a) => {
                let a = self.var(*a);
                quote_spanned!(sp=> #a.len())
            }
            Op::Const(p) => quote_spanned!(sp=> #p),
            Op::Tuple(args) => {
                let args = args.iter().map(|v| self.var(*v));
                quote_spanned!(sp=> (#(#args,)*))
            }
            Op::ViewCheck {
                array,
                index,
                bound,
                inclusive,
            } => {
                let (a, i, b) = (self.var(*array), self.var(*index), self.var(*bound));
                quote_spanned!(sp=> #a.view_check(#i, #b, #inclusive)?)
            }
        }
    }
}

/// A member's name: a field (`x`, `x_axis`) or a tuple index (`0`, of a decomposition's
/// result).
pub(crate) fn member_tokens(m: &str) -> TokenStream {
    match m.parse::<usize>() {
        Ok(k) => syn::Index::from(k).into_token_stream(),
        Err(_) => format_ident!("{}", m).into_token_stream(),
    }
}

/// The user's line at `sp`, which a local array's index fault names.
fn line_lit(sp: Span) -> Literal {
    Literal::u32_unsuffixed(sp.start().line as u32)
}

/// The Rust type of a value, where the macro knows it.
pub fn ty_tokens(t: &Ty) -> Option<TokenStream> {
    match t {
        Ty::LocalArray(e, n) => {
            let (e, n) = (ty_tokens(e)?, n.rust_tokens());
            Some(quote!([#e; #n]))
        }
        // An element the macro cannot see (of a func's result) is rustc's to infer: `(_, _)`
        // still states the tuple's length, which rustc then checks.
        Ty::Tuple(ts) => {
            let elem = |t: &Ty| match t {
                Ty::Deferred => Some(quote!(_)),
                t => ty_tokens(t),
            };
            let ts: Option<Vec<TokenStream>> = ts.iter().map(elem).collect();
            let ts = ts?;
            Some(quote!((#(#ts),*)))
        }
        // The `half` crate's type, by the facade's path (the user's `f16` may be any import).
        Ty::Scalar(Scalar::F16) => Some(quote!(__wp::f16)),
        Ty::Scalar(Scalar::BF16) => Some(quote!(__wp::bf16)),
        Ty::Scalar(s) => {
            let id = format_ident!("{}", s.name());
            Some(quote!(#id))
        }
        Ty::Vector(..) | Ty::Matrix(..) | Ty::Quat(_) => {
            let id = format_ident!("{}", t.glam_name()?);
            Some(quote!(__wp::glam::#id))
        }
        // warp-core's transforms and spatial types, re-exported next to glam.
        Ty::Transform(_) | Ty::SpatialVector(_) | Ty::SpatialMatrix(_) | Ty::MatRC(..) => {
            let id = format_ident!("{}", t.glam_name()?);
            Some(quote!(__wp::#id))
        }
        // warp-core's tiles, their dims as const generics.
        Ty::Tile(e, dims) => {
            let e = ty_tokens(e)?;
            let id = format_ident!("Tile{}", dims.len());
            let dims = dims.iter().map(|d| d.rust_tokens());
            Some(quote!(__wp::tile::#id<#e, #(#dims),*>))
        }
        // An object's view or a query state (warp-core's `objects`).
        Ty::Object(k) => {
            let id = format_ident!("{}", k.row().rust);
            match k.elem() {
                // `VolumeView<T>`: the element is part of the view's type.
                Some(e) => {
                    let t = match e.ty() {
                        Some(t) => ty_tokens(&t)?,
                        None => quote!(__wp::objects::VoxelIndex),
                    };
                    Some(quote!(__wp::objects::#id<#t>))
                }
                None => Some(quote!(__wp::objects::#id)),
            }
        }
        _ => None,
    }
}

/// A literal with its type written out (unsuffixed only where the type is deferred).
fn literal(l: &Lit, ty: &Ty) -> TokenStream {
    match (l, ty) {
        (Lit::Bool(b), _) => quote!(#b),
        (Lit::Int(v), Ty::Scalar(s)) if s.is_int() => {
            let lit = match s {
                Scalar::I8 => Literal::i8_suffixed(*v as i8),
                Scalar::I16 => Literal::i16_suffixed(*v as i16),
                Scalar::I32 => Literal::i32_suffixed(*v as i32),
                Scalar::I64 => Literal::i64_suffixed(*v as i64),
                Scalar::Isize => Literal::isize_suffixed(*v as isize),
                Scalar::U8 => Literal::u8_suffixed(*v as u8),
                Scalar::U16 => Literal::u16_suffixed(*v as u16),
                Scalar::U32 => Literal::u32_suffixed(*v as u32),
                Scalar::U64 => Literal::u64_suffixed(*v as u64),
                _ => Literal::usize_suffixed(*v as usize),
            };
            quote!(#lit)
        }
        (Lit::Int(v), _) => {
            let lit = Literal::i128_unsuffixed(*v);
            quote!(#lit)
        }
        // f16: the literal rounded once to f16 (ties to even), by its bit pattern.
        (Lit::Float(v), Ty::Scalar(Scalar::F16)) => {
            let bits = Literal::u16_suffixed(crate::types::f16_bits(*v));
            quote!(__wp::f16::from_bits(#bits))
        }
        // bf16 likewise (warp_core::bfloat16::bf16_from_f64's rounding).
        (Lit::Float(v), Ty::Scalar(Scalar::BF16)) => {
            let bits = Literal::u16_suffixed(crate::types::bf16_bits(*v));
            quote!(__wp::bf16::from_bits(#bits))
        }
        (Lit::Float(v), Ty::Scalar(s)) if s.is_float() => {
            let t = format_ident!("{}", s.name());
            if v.is_nan() {
                quote!(#t::NAN)
            } else if v.is_infinite() {
                if *v > 0.0 {
                    quote!(#t::INFINITY)
                } else {
                    quote!(#t::NEG_INFINITY)
                }
            } else if *s == Scalar::F32 {
                let lit = Literal::f32_suffixed(*v as f32);
                quote!(#lit)
            } else {
                let lit = Literal::f64_suffixed(*v);
                quote!(#lit)
            }
        }
        (Lit::Float(v), _) => {
            let lit = Literal::f64_unsuffixed(*v);
            quote!(#lit)
        }
    }
}
