//! Rust printer of the adjoint IR (`middle::adjoint`, which holds the scheme and its docs):
//! the body of a kernel's CPU adjoint thread, or of a func's `__wp_adj`.
//!
//! The stack is the thread's [`AdStack`](warp_core::AdStack) (`__stack`, `push` faults when
//! full); library calls are `warp_core::adjoint`'s (`adj_<op>(inputs.., &mut adj_inputs..,
//! adj_ret)` accumulate); array gradients are `GradView`s (`adj_<array>`). Variables whose
//! type the macro cannot see are declared without one: rustc infers it from their
//! assignments.

use super::rust::{member_tokens, ty_tokens, RustEmitter};
use crate::ir::*;
use crate::middle::adjoint::*;
use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote, quote_spanned};

/// Emits the adjoint body of kernel or func `f`, or why it cannot yet. In scope: the forward
/// parameters, `adj_<param>` gradient views for array parameters, `__stack`, and for a kernel
/// `__tid` and `__FAST`; for a func also `__adj_ret` (the adjoint of its result) and
/// `__adj_out<k>` (`&mut` adjoints of its value parameters, accumulated into at the end).
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
    let p = Printer { fwd, adj };
    let mut out = p.declarations()?;
    out.extend(p.block(&adj.body)?);
    Ok(out)
}

struct Printer<'a> {
    fwd: RustEmitter<'a>,
    adj: &'a Adjoint,
}

impl Printer<'_> {
    fn f(&self) -> &Function {
        &self.adj.f
    }

    fn var(&self, v: VarId) -> syn::Ident {
        self.fwd.var(v)
    }

    fn adj(&self, v: VarId) -> syn::Ident {
        format_ident!("adj_{}", self.var(v))
    }

    fn gather(&self, v: VarId) -> syn::Ident {
        format_ident!("__acc_{}", self.var(v))
    }

    /// The variables, their adjoints and the gathering registers, zero.
    fn declarations(&self) -> Result<TokenStream, String> {
        let mut out = TokenStream::new();
        for d in &self.adj.decls {
            let x = self.var(d.var);
            out.extend(match ty_tokens(self.f().ty(d.var)) {
                Some(t) => quote!(let mut #x: #t = __wp::adjoint::zero();),
                None => quote!(let mut #x = __wp::adjoint::zero();),
            });
        }
        for &v in &self.adj.adjs {
            let (x, a) = (self.var(v), self.adj(v));
            out.extend(quote!(let mut #a = __wp::zero_like(&#x);));
        }
        for &a in &self.adj.gathered {
            let acc = self.gather(a);
            out.extend(quote!(let mut #acc = __wp::adjoint::zero();));
        }
        Ok(out)
    }

    fn block(&self, b: &[AStmt]) -> Result<TokenStream, String> {
        let mut out = TokenStream::new();
        for s in b {
            out.extend(self.stmt(s)?);
        }
        Ok(out)
    }

    fn stmt(&self, s: &AStmt) -> Result<TokenStream, String> {
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
                let (x, val) = (self.var(*var), self.var(*value));
                let path = path.iter().map(|m| member_tokens(m));
                quote_spanned!(sp=> #x #(.#path)* = #val;)
            }
            AKind::Push { var, line } => {
                let x = self.var(*var);
                quote_spanned!(sp=> __stack.push(#x, #line)?;)
            }
            AKind::If {
                cond,
                then,
                els,
                record,
            } => {
                let c = self.var(*cond);
                let (t, e) = (self.block(then)?, self.block(els)?);
                if *record {
                    quote_spanned!(sp=>
                        let __c = #c;
                        if __c { #t } else { #e }
                        __stack.push(__c, 0)?;
                    )
                } else {
                    quote_spanned!(sp=> if #c { #t } else { #e })
                }
            }
            AKind::For {
                range,
                exit,
                body,
                line,
            } => {
                let range = self.range(range);
                let (exit, body) = (self.exit(exit), self.block(body)?);
                quote_spanned! {sp=>
                    {
                        let __range = #range;
                        let mut __count: i64 = 0;
                        for __n in 0..__range.count {
                            #exit
                            #body
                            __count += 1;
                        }
                        __stack.push(__count, #line)?;
                    }
                }
            }
            AKind::Loop { exit, body, line } => {
                let (exit, body) = (self.exit(exit), self.block(body)?);
                quote_spanned! {sp=>
                    {
                        let mut __count: i64 = 0;
                        loop {
                            #exit
                            #body
                            __count += 1;
                        }
                        __stack.push(__count, #line)?;
                    }
                }
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
            AKind::Scope(b) => {
                let b = self.block(b)?;
                quote_spanned!(sp=> { #b })
            }
            AKind::Seed { var } => {
                let (a, x) = (self.adj(*var), self.var(*var));
                quote_spanned!(sp=> let __r = #a; #a = __wp::zero_like(&#x);)
            }
            AKind::SeedMember { var, path } => {
                let a = self.adj(*var);
                let path: Vec<_> = path.iter().map(|m| member_tokens(m)).collect();
                quote_spanned!(sp=>
                    let __r = #a #(.#path)*;
                    #a #(.#path)* = __wp::zero_like(&__r);
                )
            }
            AKind::SeedZero { like } => {
                let x = self.var(*like);
                quote_spanned!(sp=> let __r = __wp::zero_like(&#x);)
            }
            AKind::ClearAdj { var } => {
                let (a, x) = (self.adj(*var), self.var(*var));
                quote_spanned!(sp=> #a = __wp::zero_like(&#x);)
            }
            AKind::Pop { var } => {
                let x = self.var(*var);
                quote_spanned!(sp=> #x = __stack.pop();)
            }
            AKind::Accum { var, member, from } => {
                let a = self.adj(*var);
                let g = self.grad(from)?;
                match member {
                    Some(m) => {
                        let m = member_tokens(m);
                        quote_spanned!(sp=> __wp::adjoint::Adjoint::adj_accum(&mut #a.#m, #g);)
                    }
                    None => quote_spanned!(sp=> __wp::adjoint::Adjoint::adj_accum(&mut #a, #g);),
                }
            }
            AKind::AdjCall {
                func,
                inputs,
                faults,
            } => {
                let f = format_ident!("{}", func);
                // An array input (`volume_sample_index`'s data) is passed by reference, and its
                // adjoint is the array's gradient view; every other input's a zeroed temporary.
                let is_array = |v: VarId| matches!(self.f().ty(v), crate::types::Ty::Array(..));
                let mut temps = TokenStream::new();
                let mut xs = Vec::new();
                let mut gs = Vec::new();
                for (k, v) in inputs.iter().enumerate() {
                    let x = self.var(*v);
                    if is_array(*v) {
                        // A copy of the view (it accumulates through shared memory).
                        let (a, g) = (self.adj(*v), temp(k));
                        temps.extend(quote_spanned!(sp=> let mut #g = #a;));
                        xs.push(quote!(&#x));
                        gs.push(quote!(&mut #g));
                    } else {
                        let g = temp(k);
                        temps.extend(quote_spanned!(sp=> let mut #g = __wp::zero_like(&#x);));
                        xs.push(quote!(#x));
                        gs.push(quote!(&mut #g));
                    }
                }
                // An adjoint that reads an object's buffers (`adj_mesh_query_point`) returns a
                // `KResult`, as its forward call does.
                let q = if *faults { quote!(?) } else { quote!() };
                quote_spanned!(sp=>
                    #temps
                    __wp::adjoint::#f(#(#xs,)* #(#gs,)* __r)#q;
                )
            }
            AKind::AdjCast { from } => {
                let x = self.var(*from);
                quote_spanned!(sp=>
                    let mut __g0 = __wp::zero_like(&#x);
                    __wp::adjoint::adj_cast(&mut __g0, __r);
                )
            }
            AKind::FuncAdj { path, args } => {
                let mut temps = TokenStream::new();
                let mut pass = Vec::new();
                for (k, (a, how)) in args.iter().enumerate() {
                    match how {
                        FuncArgAdj::ArrayGrad => {
                            let g = self.adj(*a);
                            pass.push(quote!(#g));
                        }
                        FuncArgAdj::Temp => {
                            let (g, v) = (temp(k), self.var(*a));
                            temps.extend(quote_spanned!(sp=> let mut #g = __wp::zero_like(&#v);));
                            pass.push(quote!(&mut #g));
                        }
                    }
                }
                let xs = args.iter().map(|(a, _)| self.var(*a));
                quote_spanned!(sp=>
                    #temps
                    #path::__wp_adj(#(#xs,)* #(#pass,)* __r, __stack)?;
                )
            }
            AKind::AtomicAdj {
                kind,
                array,
                index,
                value,
            } => {
                let g = self.adj(*array);
                let idx = self.fwd.index_tokens(index);
                let (x, av, arr) = (self.var(*value), self.adj(*value), self.var(*array));
                let to_value = match kind {
                    AtomicKind::Sub => quote!(__wp::adjoint::adj_neg(#x, &mut #av, __grad)),
                    AtomicKind::Add => quote!(__wp::adjoint::Adjoint::adj_accum(&mut #av, __grad)),
                    AtomicKind::Extreme => {
                        quote!(__wp::adj_atomic_extreme(#arr.load(#idx)?, #x, &mut #av, __grad))
                    }
                };
                quote_spanned!(sp=>
                    let __grad = #g.get(#idx, __wp::zero_like(&#x))?;
                    #to_value;
                )
            }
            AKind::GradAccum { array, index, mode } => {
                let g = self.adj(*array);
                let idx = self.fwd.index_tokens(index);
                match mode {
                    AccumMode::Atomic => quote_spanned!(sp=> #g.accumulate(#idx, __r)?;),
                    // SAFETY (of the generated code): under __FAST the array covers the grid,
                    // so the index is in bounds, only this thread touches the element, and no
                    // other adjoint launch runs (the runtime turns __FAST off otherwise).
                    AccumMode::OwnWhenFast => quote_spanned!(sp=>
                        if __FAST { unsafe { #g.accumulate_own(#idx, __r) } } else { #g.accumulate(#idx, __r)?; }
                    ),
                    AccumMode::GatherWhenFast => {
                        let acc = self.gather(*array);
                        quote_spanned!(sp=>
                            if __FAST { __wp::adjoint::Adjoint::adj_accum(&mut #acc, __r) } else { #g.accumulate(#idx, __r)?; }
                        )
                    }
                }
            }
            AKind::RevIf { cond, then, els } => {
                let (t, e) = (self.block(then)?, self.block(els)?);
                let c = match cond {
                    Some(c) => {
                        let c = self.var(*c);
                        quote!(#c)
                    }
                    None => quote!(__stack.pop::<bool>()),
                };
                quote_spanned!(sp=> if #c { #t } else { #e })
            }
            AKind::RevLoop { body } => {
                let body = self.block(body)?;
                quote_spanned! {sp=>
                    {
                        let __count: i64 = __stack.pop();
                        for _ in 0..__count {
                            #body
                        }
                    }
                }
            }
            AKind::FlushGathered { array } => {
                let (g, acc, idx) = (self.adj(*array), self.gather(*array), self.tid_index()?);
                // SAFETY (of the generated code): as for `accumulate_own` above.
                quote_spanned!(sp=> if __FAST { unsafe { #g.accumulate_own(#idx, #acc) } })
            }
            AKind::ClearOwn { .. } => {
                return Err("internal: the CPU adjoint has no deferred gradient clear".into())
            }
            AKind::AccumOut { k, var } => {
                let (a, out) = (self.adj(*var), format_ident!("__adj_out{}", k));
                quote_spanned!(sp=> __wp::adjoint::Adjoint::adj_accum(#out, #a);)
            }
            AKind::CustomGrad { k, func } => {
                let out = format_ident!("__adj_out{}", k);
                let args = self.f().params.iter().map(|p| self.var(p.var));
                quote_spanned!(sp=>
                    __wp::adjoint::Adjoint::adj_accum(#out, #func::__wp_cpu(#(#args,)* __adj_ret)?);
                )
            }
        })
    }

    /// The thread index as an array index (`__tid[0]`, or a tuple of components).
    fn tid_index(&self) -> Result<TokenStream, String> {
        let n = self
            .f()
            .tid_ndim
            .ok_or("internal: a thread-owned array without tid()")? as usize;
        let ks = 0..n;
        Ok(if n == 1 {
            quote!(__tid[0])
        } else {
            quote!((#(__tid[#ks]),*))
        })
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
    fn range(&self, range: &RangeSpec) -> TokenStream {
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
                let l = format_ident!("{}", l);
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
            GradSrc::Temp(k) => {
                let g = temp(*k);
                quote!(#g)
            }
            GradSrc::AdjRet => quote!(__adj_ret),
            GradSrc::Take {
                array,
                index,
                like,
                mode,
            } => {
                let g = self.adj(*array);
                let idx = self.fwd.index_tokens(index);
                let v = self.var(*like);
                match mode {
                    TakeMode::Take => quote!(#g.take(#idx, __wp::zero_like(&#v))?),
                    TakeMode::GetWhenFast => {
                        return Err(
                            "internal: the CPU adjoint has no deferred gradient clear".into()
                        )
                    }
                }
            }
        })
    }
}

/// The temporary `__g<k>`.
fn temp(k: usize) -> syn::Ident {
    format_ident!("__g{}", k)
}
