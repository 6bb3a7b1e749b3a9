//! Rust printer of the adjoint IR (`middle::adjoint`, which holds the scheme, its decisions
//! and its docs): the body of a kernel's CPU adjoint thread, or of a func's `__wp_adj`.
//!
//! The stack is the thread's [`AdStack`](warp_core::AdStack) (`__stack`, `push` faults when
//! full); library calls are `warp_core::adjoint`'s (`adj_<op>(inputs.., &mut adj_inputs..,
//! adj_ret)` accumulate; arrays by reference); array gradients are `GradView`s
//! (`adj_<array>`). Variables whose type the macro cannot see are declared without one: rustc
//! infers it from their assignments.

use super::rust::{member_tokens, ty_tokens, RustEmitter};
use crate::ir::*;
use crate::middle::adjoint::*;
use crate::types::Ty;
use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote, quote_spanned, ToTokens};

/// Emits the adjoint body of kernel or func `f`, or why it cannot yet. In scope: the forward
/// parameters, `adj_<param>` gradient views for array parameters, `__stack`, and for a kernel
/// `__tid` and `__FAST`; for a func also `__adj_ret` (the adjoint of its result) and
/// `__adj_out<k>` (`&mut` adjoints of its value parameters).
pub fn emit(f: &Function) -> Result<TokenStream, String> {
    print(&build(f, Policy::CPU)?)
}

/// The adjoint body of a func with custom gradients `grads` (see `middle::adjoint::custom`).
pub fn emit_custom(f: &Function, grads: &[(syn::Ident, syn::Path)]) -> Result<TokenStream, String> {
    print(&custom(f, grads)?)
}

fn print(adj: &Adjoint) -> Result<TokenStream, String> {
    let mut fwd = RustEmitter::new(&adj.f);
    // User funcs are called through their replays.
    fwd.replay = true;
    let p = Printer {
        fwd,
        adj,
        per_lane: Vec::new(),
    };
    // A tiled kernel's block (`back::rust_tile_adjoint`).
    if adj.f.tiled.is_some() {
        return p.tiled_body();
    }
    let mut out = p.declarations();
    out.extend(p.block(&adj.body)?);
    Ok(out)
}

pub(super) struct Printer<'a> {
    pub(super) fwd: RustEmitter<'a>,
    pub(super) adj: &'a Adjoint,
    /// A tiled kernel's variables kept per lane (`back::rust_tile_adjoint`); empty otherwise.
    pub(super) per_lane: Vec<bool>,
}

impl Printer<'_> {
    pub(super) fn f(&self) -> &Function {
        &self.adj.f
    }

    pub(super) fn var(&self, v: VarId) -> syn::Ident {
        self.fwd.var(v)
    }

    fn callee(&self, k: Callee) -> Result<&syn::Path, String> {
        self.f()
            .callees
            .get(k)
            .ok_or_else(|| "internal: no such callee".into())
    }

    pub(super) fn adj(&self, v: VarId) -> syn::Ident {
        format_ident!("adj_{}", self.var(v))
    }

    /// The variables and their adjoints, zero.
    pub(super) fn declarations(&self) -> TokenStream {
        let mut out = TokenStream::new();
        for d in &self.adj.decls {
            let x = self.var(d.var);
            let ty = self.f().ty(d.var);
            out.extend(match ty_tokens(ty) {
                Some(t) => quote!(let mut #x: #t = __wp::adjoint::zero();),
                // A statement's unit result (`tile_store`'s): named, since nothing may use it to
                // infer its type (a store of a tile that needs no adjoint, an integer one).
                None if *ty == crate::types::Ty::Unit => {
                    quote!(let mut #x: () = __wp::adjoint::zero();)
                }
                None => quote!(let mut #x = __wp::adjoint::zero();),
            });
        }
        for &v in &self.adj.adjs {
            let (x, a) = (self.var(v), self.adj(v));
            out.extend(quote!(let mut #a = __wp::zero_like(&#x);));
        }
        out
    }

    pub(super) fn block(&self, b: &[AStmt]) -> Result<TokenStream, String> {
        b.iter().map(|s| self.stmt(s)).collect()
    }

    pub(super) fn stmt(&self, s: &AStmt) -> Result<TokenStream, String> {
        // The user's location, but the macro's hygiene: the generated locals (`__stack`, `__r`,
        // `__tid`) resolve where the macro declared them even when the user's tokens came from
        // another expansion (a func call passed to a `macro_rules!` that writes the kernel).
        let sp = Span::call_site().located_at(s.span);
        Ok(match &s.kind {
            AKind::Assign { dst, value } => {
                let x = self.var(*dst);
                let rhs = match value {
                    Value::Op(op) => self.fwd.op_tokens(op, self.f().ty(*dst), sp),
                    // The type comes from the declaration.
                    Value::Zero { .. } => quote!(__wp::adjoint::zero()),
                };
                quote_spanned!(sp=> #x = #rhs;)
            }
            AKind::SetMember { var, path, value } => {
                let (x, val, path) = (self.var(*var), self.var(*value), members(path));
                quote_spanned!(sp=> #x #path = #val;)
            }
            AKind::SetElem { var, index, value } => {
                let (var, index, value) = (*var, *index, *value);
                let set = StmtKind::SetElem { var, index, value };
                self.fwd.stmt_tokens(&Stmt {
                    kind: set,
                    span: sp,
                })
            }
            AKind::ClearAdjElem { var, index } => {
                let e = self.adj_elem(*var, *index);
                quote_spanned!(sp=> *#e = __wp::adjoint::zero();)
            }
            AKind::Push { var, line } => {
                let x = self.var(*var);
                quote_spanned!(sp=> __stack.push(#x, #line)?;)
            }
            AKind::Loop {
                range,
                exit,
                body,
                line,
            } => {
                let range = range.as_ref().map(|r| self.range_tokens(r));
                let (exit, body) = (self.exit(exit), self.block(body)?);
                counted_loop(range, exit, body, quote!(__stack), *line, sp)
            }
            AKind::StepVar { var, end } => {
                let v = self.var(*var);
                let value = match ty_tokens(self.f().ty(*var)) {
                    Some(t) => quote!(__range.at(__n) as #t),
                    None => {
                        let end = self.var(*end);
                        quote!(__wp::ops::int_like(&#end, __range.at(__n)))
                    }
                };
                quote_spanned!(sp=> #v = #value;)
            }
            AKind::If { cond, then, els } => {
                let c = match cond {
                    Cond::Var(c) => self.var(*c).into_token_stream(),
                    Cond::Popped => quote!(__stack.pop::<bool>()),
                    Cond::Fast => quote!(__FAST),
                };
                let (t, e) = (self.block(then)?, self.block(els)?);
                quote_spanned!(sp=> if #c { #t } else { #e })
            }
            AKind::Scope(b) => {
                let b = self.block(b)?;
                quote_spanned!(sp=> { #b })
            }
            AKind::Seed(from) => {
                let g = self.grad(from)?;
                quote_spanned!(sp=> let __r = #g;)
            }
            AKind::ClearAdj { var, path } => {
                let (a, x, path) = (self.adj(*var), self.var(*var), members(path));
                quote_spanned!(sp=> #a #path = __wp::zero_like(&#x #path);)
            }
            AKind::Pop { var } => {
                let x = self.var(*var);
                quote_spanned!(sp=> #x = __stack.pop();)
            }
            AKind::Accum { to, from } => {
                let to = match to {
                    AdjOf::Var { var, path } => {
                        let (a, path) = (self.adj(*var), members(path));
                        quote!(&mut #a #path)
                    }
                    AdjOf::Out(k) => format_ident!("__adj_out{}", k).into_token_stream(),
                    AdjOf::Elem { var, index } => self.adj_elem(*var, *index),
                };
                let g = self.grad(from)?;
                quote_spanned!(sp=> __wp::adjoint::Adjoint::adj_accum(#to, #g);)
            }
            AKind::ZeroTemp { k, like } => {
                let (g, x) = match like {
                    TempLike::Var(v) | TempLike::Param { arg: v, .. } => (temp(*k), self.var(*v)),
                };
                quote_spanned!(sp=> let mut #g = __wp::zero_like(&#x);)
            }
            AKind::AdjCall {
                func,
                values,
                grads,
                faults,
            } if func.starts_with("adj_tile") => {
                self.tile_adj_call(func, values, grads, *faults, sp)
            }
            AKind::TileMapAdj {
                f,
                values,
                grads,
                dst,
            } => self.tile_map_adj(*f, values, grads, *dst, sp),
            AKind::LaneAdj { func, lanes, tile } => self.lane_adj(func, *lanes, *tile, sp),
            AKind::AdjCall {
                func,
                values,
                grads,
                faults,
            } => {
                let f = format_ident!("{}", func);
                let xs = values.iter().map(|a| match a {
                    Arg::Value(v) => self.var(*v).into_token_stream(),
                    Arg::Array(v) => {
                        let x = self.var(*v);
                        quote!(&#x)
                    }
                });
                // A gradient view is passed as a `&mut` copy (it accumulates through shared
                // memory).
                let gs = grads.iter().map(|g| match g {
                    GradArg::ArrayGrad(a) => {
                        let a = self.adj(*a);
                        quote!(&mut #a.clone())
                    }
                    g => self.grad_arg(g),
                });
                // An adjoint that reads an object's buffers (`adj_mesh_query_point`) returns a
                // `KResult`, as its forward call does.
                let q = if *faults { quote!(?) } else { quote!() };
                quote_spanned!(sp=> __wp::adjoint::#f(#(#xs,)* #(#gs,)* __r)#q;)
            }
            AKind::FuncAdj {
                func,
                values,
                grads,
            } => {
                let path = self.callee(*func)?;
                let xs = values.iter().map(|v| self.var(*v));
                let gs = grads.iter().map(|g| self.grad_arg(g));
                quote_spanned!(sp=> #path::__wp_adj(#(#xs,)* #(#gs,)* __r, __stack)?;)
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
                    // Recorded for the launch's ordered reduction, on the fast path too, so
                    // that both paths add in one order (warp-runtime's cpu/deterministic.rs).
                    quote_spanned!(sp=> __wp::deterministic::grad_add(&#g, #idx, #v, __flat)?;)
                } else if *own {
                    // SAFETY (of the generated code): under __FAST the array covers the grid,
                    // so the index is in bounds, only this thread touches the element, and no
                    // other adjoint launch runs (the runtime turns __FAST off otherwise).
                    quote_spanned!(sp=> unsafe { #g.accumulate_own(#idx, #v) })
                } else {
                    quote_spanned!(sp=> #g.accumulate(#idx, #v)?;)
                }
            }
            AKind::GradClearOwn { .. } => {
                return Err("internal: the CPU adjoint has no deferred gradient clear".into())
            }
            AKind::RevLoop { body } => reversed_loop(self.block(body)?, quote!(__stack), sp),
        })
    }

    /// `&mut adj_<var>[index]` of a local array's adjoint (the index was checked by the
    /// replay; `at_mut` keeps the access in bounds regardless).
    fn adj_elem(&self, var: VarId, index: VarId) -> TokenStream {
        let (a, i) = (self.adj(var), self.var(index));
        let at = match self.f().ty(var) {
            Ty::Matrix(..) => quote!(col_at_mut),
            _ => quote!(at_mut),
        };
        quote!(__wp::local_array::#at(&mut #a, #i))
    }

    /// A temporary or an adjoint as a `&mut` argument; an array's gradient view by value.
    pub(super) fn grad_arg(&self, g: &GradArg) -> TokenStream {
        match g {
            GradArg::Temp(k) => {
                let g = temp(*k);
                quote!(&mut #g)
            }
            GradArg::Adj(v) => {
                let a = self.adj(*v);
                quote!(&mut #a)
            }
            GradArg::ArrayGrad(v) => self.adj(*v).into_token_stream(),
        }
    }

    /// An array index: one variable, a tuple of them, or the thread index.
    fn index(&self, index: &Index) -> TokenStream {
        match index {
            Index::At(vs) => self.fwd.index_tokens(vs),
            Index::Thread(1) => quote!(__tid[0]),
            Index::Thread(n) => {
                let ks = 0..*n as usize;
                quote!((#(__tid[#ks]),*))
            }
        }
    }

    /// A loop's exit check (before anything of the iteration runs).
    fn exit(&self, flags: &[VarId]) -> TokenStream {
        if flags.is_empty() {
            return TokenStream::new();
        }
        let fs = flags.iter().map(|v| self.var(*v));
        quote!(if false #(|| #fs)* { break; })
    }

    /// The progression of a `for`.
    pub(super) fn range_tokens(&self, range: &RangeSpec) -> TokenStream {
        let start = self.var(range.start);
        let end = self.var(range.end);
        let incl = range.inclusive;
        let name = proc_macro2::Literal::string(&self.f().name);
        let adapters = range.adapters.iter().map(|a| match a {
            RangeAdapter::Rev => quote!(.rev()),
            RangeAdapter::StepBy(k) => {
                let k = self.var(*k);
                quote!(.step_by(#k as i64, #name)?)
            }
        });
        quote!(__wp::RangeProg::new(#start as i64, #end as i64, #incl) #(#adapters)*)
    }

    fn grad(&self, g: &GradSrc) -> Result<TokenStream, String> {
        Ok(match g {
            GradSrc::Seed => quote!(__r),
            GradSrc::SeedLane(l) => {
                let l = member_tokens(l);
                quote!(__r.#l)
            }
            GradSrc::LaneSum(lanes) => {
                let ls = lanes.iter().map(|l| format_ident!("{}", l));
                quote!(0.0 #(+ __r.#ls)*)
            }
            GradSrc::Diagonal { vector, entries } => {
                let vt = ty_tokens(vector).ok_or("internal: a diagonal of no vector type")?;
                let parts = entries.iter().map(|(c, l)| {
                    let (c, l) = (format_ident!("{}", c), format_ident!("{}", l));
                    quote!(__r.#c.#l)
                });
                quote!(#vt::new(#(#parts),*))
            }
            GradSrc::Temp(k) => temp(*k).into_token_stream(),
            GradSrc::AdjRet => quote!(__adj_ret),
            GradSrc::Adj { var, path } => {
                let (a, path) = (self.adj(*var), members(path));
                quote!(#a #path)
            }
            GradSrc::Zero(like) => {
                let x = self.var(*like);
                quote!(__wp::zero_like(&#x))
            }
            GradSrc::AdjElem { var, index } => {
                let e = self.adj_elem(*var, *index);
                quote!(*#e)
            }
            GradSrc::SeedElem(k) => {
                let k = proc_macro2::Literal::usize_unsuffixed(*k);
                quote!(__r[#k])
            }
            GradSrc::ElemSum => quote!(__wp::local_array::sum(&__r)),
            GradSrc::Take { array, index, like } | GradSrc::Get { array, index, like } => {
                let (a, idx, v) = (self.adj(*array), self.index(index), self.var(*like));
                let f = match g {
                    GradSrc::Take { .. } => quote!(take),
                    _ => quote!(get),
                };
                quote!(#a.#f(#idx, __wp::zero_like(&#v))?)
            }
            GradSrc::Custom { func, args } => {
                let (path, args) = (self.callee(*func)?, args.iter().map(|v| self.var(*v)));
                quote!(#path::__wp_cpu(#(#args,)* __adj_ret)?)
            }
        })
    }
}

/// `.a.b` (tuple elements by position).
fn members(path: &[String]) -> TokenStream {
    let path = path.iter().map(|m| member_tokens(m));
    quote!(#(.#path)*)
}

/// The temporary `__g<k>`.
pub(super) fn temp(k: usize) -> syn::Ident {
    format_ident!("__g{}", k)
}

/// The replay of a loop: `body` (after the `exit` check) over the progression `range` (a `for`)
/// or until it leaves (`None`: a `loop`), counting the iterations, whose count then goes on
/// `stack`.
pub(super) fn counted_loop(
    range: Option<TokenStream>,
    exit: TokenStream,
    body: TokenStream,
    stack: TokenStream,
    line: u32,
    sp: Span,
) -> TokenStream {
    let (range, head) = match range {
        Some(r) => (r, quote!(for __n in 0..__range.count)),
        None => (quote!(()), quote!(loop)),
    };
    quote_spanned! {sp=>
        {
            let __range = #range;
            let mut __count: i64 = 0;
            #head {
                #exit
                #body
                __count += 1;
            }
            #stack.push(__count, #line)?;
        }
    }
}

/// The reverse of a loop: `body` as many times as the count popped from `stack`.
pub(super) fn reversed_loop(body: TokenStream, stack: TokenStream, sp: Span) -> TokenStream {
    quote_spanned! {sp=>
        {
            let __count: i64 = #stack.pop();
            for _ in 0..__count {
                #body
            }
        }
    }
}
