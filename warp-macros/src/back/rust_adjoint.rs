//! Rust back end of the adjoint (reverse mode): the IR to the body of a kernel's CPU adjoint
//! thread.
//!
//! The scheme is Warp's, with loops made right:
//! 1. a *forward replay* runs the kernel body again without its stores and atomics; before a
//!    statement overwrites a value the reverse sweep will need (a `mut` variable, anything
//!    assigned inside a loop, a loop's own variable), it pushes the old value on the thread's
//!    [`AdStack`](warp_core::AdStack); after an `if` inside a loop it pushes the branch taken,
//!    after a loop its trip count;
//! 2. the *reverse sweep* walks the statements backwards. For `d = op(a, b)` it takes `d`'s
//!    adjoint, zeroes it, pops `d`'s old value where one was pushed, and accumulates the
//!    adjoints of `a` and `b` (through `warp_core::adjoint::adj_*`, with the operands' values
//!    as they were when the statement ran: the invariant is that when the sweep reaches a
//!    statement, every variable holds the value it had just after that statement ran).
//!
//! Jumps (`break`, `continue`, early `return`) are first rewritten into flags by
//! `adjoint_prep`, so loops only need their trip counts. A func call replays through the
//! func's `__wp_replay` and reverses through its `__wp_adj`, on the same stack.
//!
//! Reading `a[i]` accumulates into `a`'s gradient atomically; writing `a[i] = v` hands the
//! gradient at `i` to `v` and clears it; `atomic_add`/`atomic_sub` pass the gradient at the
//! index to the value (negated for sub); `atomic_min`/`atomic_max` pass it to the value that
//! won. A construct the sweep cannot handle makes [`emit`] return the reason, which backward
//! reports as an error (never a wrong gradient).

use super::rust::{ty_tokens, RustEmitter};
use crate::builtins::Grad;
use crate::ir::*;
use crate::types::Ty;
use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote, quote_spanned};

/// Emits the adjoint body of kernel or func `f`, or why it cannot yet. In scope: the forward
/// parameters, `adj_<param>` gradient views for array parameters, `__stack`, and for a kernel
/// `__tid`; for a func also `__adj_ret` (the adjoint of its result) and `__adj_out<k>`
/// (`&mut` adjoints of its value parameters, accumulated into at the end).
pub fn emit(f: &Function) -> Result<TokenStream, String> {
    if let Some(why) = crate::analysis::atomic_without_adjoint(f) {
        return Err(why);
    }
    // Jumps become flags: the reverse sweep then follows `if` decisions and trip counts only.
    let prepared = crate::adjoint_prep::without_jumps(f);
    let f = &prepared;
    let mut fwd = RustEmitter::new(f);
    fwd.replay = true;
    let own = crate::analysis::tid_only_params(f, &fwd.tid);
    let e = AdjEmitter {
        fwd,
        own,
        f,
        overwritten: overwritten_vars(f),
        params: f.params.iter().map(|p| p.var).collect(),
    };
    let (body, tail) = crate::adjoint_prep::split_tail(f);
    e.check(body)?;
    let decls = e.declarations();
    let forward = e.forward(body, false);
    let mut reverse = TokenStream::new();
    if let Some(v) = tail {
        // The func's result: its adjoint is what the caller passed.
        if e.diff(v) {
            let a = e.adj(v);
            reverse.extend(quote!(__wp::adjoint::Adjoint::adj_accum(&mut #a, __adj_ret);));
        }
    }
    reverse.extend(e.reverse(body, false));
    let mut outs = TokenStream::new();
    if f.kind == FnKind::Func {
        for (k, p) in f.params.iter().enumerate() {
            if e.is_array(p.var) || !e.diff(p.var) {
                continue;
            }
            let (a, out) = (e.adj(p.var), format_ident!("__adj_out{}", k));
            outs.extend(quote!(__wp::adjoint::Adjoint::adj_accum(#out, #a);));
        }
    }
    Ok(quote! {
        #decls
        #forward
        #reverse
        #outs
    })
}

struct AdjEmitter<'a> {
    fwd: RustEmitter<'a>,
    /// Array parameters accessed only at the thread index: when the launch's arrays cover the
    /// grid (`__FAST`), their gradients are accumulated without atomics.
    own: Vec<VarId>,
    f: &'a Function,
    /// Variables assigned more than once per thread (their old values go on the stack).
    overwritten: Vec<bool>,
    params: Vec<VarId>,
}

/// Variables that may be assigned more than once in one thread: `mut` ones and everything
/// assigned inside a loop (including loop variables).
pub(crate) fn overwritten_vars(f: &Function) -> Vec<bool> {
    let mut out: Vec<bool> = f.vars.iter().map(|v| v.mutable).collect();
    fn walk(b: &Block, in_loop: bool, out: &mut Vec<bool>) {
        for s in b {
            match &s.kind {
                StmtKind::Assign { dst, .. } if in_loop => out[*dst] = true,
                StmtKind::SetMember { var, .. } => out[*var] = true,
                StmtKind::If { then, els, .. } => {
                    walk(then, in_loop, out);
                    walk(els, in_loop, out);
                }
                StmtKind::For { var, body, .. } => {
                    out[*var] = true;
                    walk(body, true, out);
                }
                StmtKind::Loop { body } => walk(body, true, out),
                _ => {}
            }
        }
    }
    walk(&f.body, false, &mut out);
    out
}

impl<'a> AdjEmitter<'a> {
    fn var(&self, v: VarId) -> syn::Ident {
        self.fwd.var(v)
    }

    fn adj(&self, v: VarId) -> syn::Ident {
        format_ident!("adj_{}", self.var(v))
    }

    fn diff(&self, v: VarId) -> bool {
        crate::adjoint_prep::differentiable(self.f.ty(v))
    }

    fn is_array(&self, v: VarId) -> bool {
        matches!(self.f.ty(v), Ty::Array(..))
    }

    fn line(sp: Span) -> u32 {
        sp.start().line as u32
    }

    /// Rejects what the reverse sweep does not handle yet.
    fn check(&self, b: &[Stmt]) -> Result<(), String> {
        for s in b {
            match &s.kind {
                StmtKind::Break | StmtKind::Continue | StmtKind::Return { .. } => {
                    return Err("internal: a jump survived jump removal".into())
                }
                StmtKind::Loop { body } => self.check(body)?,
                StmtKind::If { then, els, .. } => {
                    self.check(then)?;
                    self.check(els)?;
                }
                StmtKind::For { body, .. } => self.check(body)?,
                _ => {}
            }
        }
        Ok(())
    }

    /// Every non-parameter variable and every adjoint, declared once at the top: the reverse
    /// sweep needs the values of all of them, whatever block assigned them.
    fn declarations(&self) -> TokenStream {
        let mut out = TokenStream::new();
        for (v, var) in self.f.vars.iter().enumerate() {
            if self.params.contains(&v) || matches!(var.ty, Ty::Array(..)) {
                continue;
            }
            let x = self.var(v);
            out.extend(match ty_tokens(&var.ty) {
                Some(t) => quote!(let mut #x: #t = __wp::adjoint::zero();),
                // The type comes from the assignments below.
                None => quote!(let mut #x = __wp::adjoint::zero();),
            });
        }
        for (v, _) in self.f.vars.iter().enumerate() {
            if self.is_array(v) || !self.diff(v) {
                continue;
            }
            let (x, a) = (self.var(v), self.adj(v));
            out.extend(quote!(let mut #a = __wp::zero_like(&#x);));
        }
        out
    }

    fn push(&self, v: VarId, sp: Span) -> TokenStream {
        let x = self.var(v);
        let line = Self::line(sp);
        quote_spanned!(sp=> __stack.push(#x, #line)?;)
    }

    fn pop(&self, v: VarId, sp: Span) -> TokenStream {
        let x = self.var(v);
        quote_spanned!(sp=> #x = __stack.pop();)
    }

    /// The forward replay of `b`: the kernel's statements without stores and atomics, with the
    /// pushes the reverse sweep pops.
    fn forward(&self, b: &[Stmt], in_loop: bool) -> TokenStream {
        let mut out = TokenStream::new();
        for s in b {
            let sp = s.span;
            match &s.kind {
                StmtKind::Assign { dst, op, .. } => {
                    if self.overwritten[*dst] {
                        out.extend(self.push(*dst, sp));
                    }
                    let x = self.var(*dst);
                    let rhs = match op {
                        // Atomics are not replayed: their effect happened in the forward launch.
                        Op::Builtin { builtin, .. } if builtin.is_atomic() => {
                            quote!(__wp::adjoint::zero())
                        }
                        _ => self.fwd.op_tokens(op, self.f.ty(*dst), sp),
                    };
                    out.extend(quote_spanned!(sp=> #x = #rhs;));
                }
                StmtKind::SetMember { var, path, value } => {
                    out.extend(self.push(*var, sp));
                    let (x, val) = (self.var(*var), self.var(*value));
                    let path = path.iter().map(|m| format_ident!("{}", m));
                    out.extend(quote_spanned!(sp=> #x #(.#path)* = #val;));
                }
                StmtKind::If { cond, then, els } => {
                    let c = self.var(*cond);
                    let (t, e) = (self.forward(then, in_loop), self.forward(els, in_loop));
                    if in_loop || self.overwritten[*cond] {
                        // The branch taken, pushed after the branch's own pushes so that the
                        // reverse sweep pops it first.
                        out.extend(quote_spanned!(sp=>
                            let __c = #c;
                            if __c { #t } else { #e }
                            __stack.push(__c, 0)?;
                        ));
                    } else {
                        out.extend(quote_spanned!(sp=> if #c { #t } else { #e }));
                    }
                }
                StmtKind::For { var, range, body } => {
                    let (range_tokens, value) = self.range(*var, range, sp);
                    let v = self.var(*var);
                    let (exit, body) = self.split_exit(body);
                    let body = self.forward(body, true);
                    let line = Self::line(sp);
                    // The trip count: iterations that ran (an exit check leaves before one).
                    out.extend(quote_spanned! {sp=>
                        {
                            let __range = #range_tokens;
                            let mut __count: i64 = 0;
                            for __n in 0..__range.count {
                                #exit
                                __stack.push(#v, #line)?;
                                #v = #value;
                                #body
                                __count += 1;
                            }
                            __stack.push(__count, #line)?;
                        }
                    });
                }
                StmtKind::Loop { body } => {
                    let (exit, body) = self.split_exit(body);
                    let body = self.forward(body, true);
                    let line = Self::line(sp);
                    out.extend(quote_spanned! {sp=>
                        {
                            let mut __count: i64 = 0;
                            loop {
                                #exit
                                #body
                                __count += 1;
                            }
                            __stack.push(__count, #line)?;
                        }
                    });
                }
                // Stores, prints and declarations do nothing in the replay.
                _ => {}
            }
        }
        out
    }

    /// A loop body's leading exit check (emitted before anything of the iteration runs, so a
    /// left iteration pushes nothing and is not counted) and the rest of the body.
    fn split_exit<'b>(&self, body: &'b [Stmt]) -> (TokenStream, &'b [Stmt]) {
        match body.first() {
            Some(Stmt {
                kind: StmtKind::ExitIf { flags },
                span,
            }) => {
                let fs = flags.iter().map(|v| self.var(*v));
                (
                    quote_spanned!(*span=> if false #(|| #fs)* { break; }),
                    &body[1..],
                )
            }
            _ => (TokenStream::new(), body),
        }
    }

    /// The range progression of a `for` and the loop variable's value at step `__n`.
    fn range(&self, var: VarId, range: &RangeSpec, sp: Span) -> (TokenStream, TokenStream) {
        let start = self.var(range.start);
        let end = self.var(range.end);
        let incl = range.inclusive;
        let name = proc_macro2::Literal::string(&self.f.name);
        let adapters = range.adapters.iter().map(|a| match a {
            RangeAdapter::Rev => quote!(.rev()),
            RangeAdapter::StepBy(k) => {
                let k = self.var(*k);
                quote!(.step_by(#k as i64, #name)?)
            }
        });
        let value = match ty_tokens(self.f.ty(var)) {
            Some(t) => quote!(__range.at(__n) as #t),
            None => quote!(__wp::ops::int_like(&#end, __range.at(__n))),
        };
        let _ = sp;
        (
            quote!(__wp::RangeProg::new(#start as i64, #end as i64, #incl) #(#adapters)*),
            value,
        )
    }

    /// The reverse sweep of `b`.
    fn reverse(&self, b: &[Stmt], in_loop: bool) -> TokenStream {
        let mut out = TokenStream::new();
        for s in b.iter().rev() {
            let sp = s.span;
            match &s.kind {
                StmtKind::Assign { dst, op, .. } => out.extend(self.reverse_assign(*dst, op, sp)),
                StmtKind::Store {
                    array,
                    index,
                    value,
                } => {
                    let g = self.adj(*array);
                    let idx = self.fwd.index_tokens(index);
                    let v = self.var(*value);
                    if self.diff(*value) {
                        let a = self.adj(*value);
                        out.extend(quote_spanned!(sp=>
                            __wp::adjoint::Adjoint::adj_accum(&mut #a, #g.take(#idx, __wp::zero_like(&#v))?);
                        ));
                    }
                }
                StmtKind::SetMember { var, path, value } => {
                    let (a, x) = (self.adj(*var), self.var(*var));
                    let path: Vec<_> = path.iter().map(|m| format_ident!("{}", m)).collect();
                    let mut t = quote_spanned!(sp=>
                        let __r = #a #(.#path)*;
                        #a #(.#path)* = __wp::zero_like(&__r);
                    );
                    if self.diff(*value) {
                        let av = self.adj(*value);
                        t.extend(
                            quote_spanned!(sp=> __wp::adjoint::Adjoint::adj_accum(&mut #av, __r);),
                        );
                    }
                    t.extend(quote_spanned!(sp=> #x = __stack.pop();));
                    out.extend(quote_spanned!(sp=> { #t }));
                }
                StmtKind::If { cond, then, els } => {
                    let c = self.var(*cond);
                    let (t, e) = (self.reverse(then, in_loop), self.reverse(els, in_loop));
                    if in_loop || self.overwritten[*cond] {
                        out.extend(quote_spanned!(sp=>
                            if __stack.pop::<bool>() { #t } else { #e }
                        ));
                    } else {
                        out.extend(quote_spanned!(sp=> if #c { #t } else { #e }));
                    }
                }
                StmtKind::For { body, .. } | StmtKind::Loop { body } => {
                    // A `for` restores its variable after each reversed iteration.
                    let restore = match &s.kind {
                        StmtKind::For { var, .. } => {
                            let v = self.var(*var);
                            quote!(#v = __stack.pop();)
                        }
                        _ => TokenStream::new(),
                    };
                    let (_, body) = self.split_exit(body);
                    let body = self.reverse(body, true);
                    out.extend(quote_spanned! {sp=>
                        {
                            let __count: i64 = __stack.pop();
                            for _ in 0..__count {
                                #body
                                #restore
                            }
                        }
                    });
                }
                _ => {}
            }
        }
        out
    }

    /// Reverse of `dst = op`: take `dst`'s adjoint, restore `dst`'s old value, accumulate the
    /// operands' adjoints.
    fn reverse_assign(&self, dst: VarId, op: &Op, sp: Span) -> TokenStream {
        let restore = if self.overwritten[dst] {
            self.pop(dst, sp)
        } else {
            TokenStream::new()
        };
        if let Op::Func { path, args } = op {
            return self.reverse_call(dst, path, args, restore, sp);
        }
        if !self.diff(dst) {
            return restore;
        }
        let ad = self.adj(dst);
        let x = self.var(dst);
        let take = quote_spanned!(sp=>
            let __r = #ad;
            #ad = __wp::zero_like(&#x);
        );
        let acc = self.accumulate(op, sp);
        if acc.is_empty() {
            return quote_spanned!(sp=> #ad = __wp::zero_like(&#x); #restore);
        }
        quote_spanned!(sp=> { #take #restore #acc })
    }

    /// Reverse of `dst = path(args)`: the func's adjoint (it replays and reverses its own body
    /// on the same stack), called even when the result carries no gradient, since the func may
    /// have read arrays.
    fn reverse_call(
        &self,
        dst: VarId,
        path: &syn::Path,
        args: &[VarId],
        restore: TokenStream,
        sp: Span,
    ) -> TokenStream {
        let x = self.var(dst);
        let take = if self.diff(dst) {
            let ad = self.adj(dst);
            quote_spanned!(sp=> let __r = #ad; #ad = __wp::zero_like(&#x);)
        } else {
            quote_spanned!(sp=> let __r = __wp::zero_like(&#x);)
        };
        let mut temps = TokenStream::new();
        let mut pass = Vec::new();
        let mut after = TokenStream::new();
        for (k, a) in args.iter().enumerate() {
            let v = self.var(*a);
            if self.is_array(*a) {
                let g = self.adj(*a);
                pass.push(quote!(#g));
                continue;
            }
            let g = format_ident!("__g{}", k);
            temps.extend(quote_spanned!(sp=> let mut #g = __wp::zero_like(&#v);));
            pass.push(quote!(&mut #g));
            if self.diff(*a) {
                let ad = self.adj(*a);
                after.extend(quote_spanned!(sp=> __wp::adjoint::Adjoint::adj_accum(&mut #ad, #g);));
            }
        }
        let xs = args.iter().map(|a| self.var(*a));
        quote_spanned!(sp=> {
            #take
            #restore
            #temps
            #path::__wp_adj(#(#xs,)* #(#pass,)* __r, __stack)?;
            #after
        })
    }

    /// Adds `__r` (the adjoint of `op`'s result) into the adjoints of `op`'s operands.
    fn accumulate(&self, op: &Op, sp: Span) -> TokenStream {
        let acc = |v: VarId, g: TokenStream| -> TokenStream {
            if !self.diff(v) || self.is_array(v) {
                return TokenStream::new();
            }
            let a = self.adj(v);
            quote_spanned!(sp=> __wp::adjoint::Adjoint::adj_accum(&mut #a, #g);)
        };
        // `adj_f(inputs.., &mut g0, &mut g1.., __r)` into fresh temporaries (an operand may
        // appear twice: `x * x`), then into the operands' adjoints.
        let call = |f: syn::Ident, inputs: &[VarId]| -> TokenStream {
            let xs: Vec<_> = inputs.iter().map(|v| self.var(*v)).collect();
            let gs: Vec<_> = (0..inputs.len())
                .map(|k| format_ident!("__g{}", k))
                .collect();
            let mut t = TokenStream::new();
            for (g, x) in gs.iter().zip(&xs) {
                t.extend(quote_spanned!(sp=> let mut #g = __wp::zero_like(&#x);));
            }
            t.extend(quote_spanned!(sp=> __wp::adjoint::#f(#(#xs,)* #(&mut #gs,)* __r);));
            for (v, g) in inputs.iter().zip(&gs) {
                t.extend(acc(*v, quote!(#g)));
            }
            t
        };
        match op {
            Op::Copy(a) => acc(*a, quote!(__r)),
            Op::Unary(UnOp::Neg, a) => call(format_ident!("adj_neg"), &[*a]),
            Op::Binary(o, a, b) => {
                let Some(f) = o.adjoint_fn() else {
                    return TokenStream::new();
                };
                call(format_ident!("{}", f), &[*a, *b])
            }
            Op::Cast(a, _) => {
                if !self.diff(*a) {
                    return TokenStream::new();
                }
                let (x, ad) = (self.var(*a), self.adj(*a));
                quote_spanned!(sp=>
                    let mut __g0 = __wp::zero_like(&#x);
                    __wp::adjoint::adj_cast(&mut __g0, __r);
                    __wp::adjoint::Adjoint::adj_accum(&mut #ad, __g0);
                )
            }
            Op::Builtin { builtin, args } => match builtin.grad {
                // AtomicNone: only integer updates whose result is unused get here
                // (`analysis::atomic_without_adjoint`): nothing to propagate.
                Grad::Zero | Grad::AtomicNone => TokenStream::new(),
                Grad::Adjoint => call(format_ident!("adj_{}", builtin.name), args),
                Grad::Atomic => {
                    // atomic_add(a, idx.., v): the value's adjoint is the gradient at idx.
                    let arr = args[0];
                    let v = args[args.len() - 1];
                    if !self.diff(v) {
                        return TokenStream::new();
                    }
                    let g = self.adj(arr);
                    let idx = self.fwd.index_tokens(&args[1..args.len() - 1]);
                    let (x, av) = (self.var(v), self.adj(v));
                    let value = self.var(arr);
                    let sign = match builtin.name {
                        "atomic_sub" => quote!(__wp::adjoint::adj_neg(#x, &mut #av, __grad)),
                        "atomic_add" => quote!(__wp::adjoint::Adjoint::adj_accum(&mut #av, __grad)),
                        // min/max: to the value that won (the array's value after the launch).
                        _ => {
                            quote!(__wp::adj_atomic_extreme(#value.load(#idx)?, #x, &mut #av, __grad))
                        }
                    };
                    quote_spanned!(sp=>
                        let __grad = #g.get(#idx, __wp::zero_like(&#x))?;
                        #sign;
                    )
                }
            },
            Op::Load { array, index } => {
                let g = self.adj(*array);
                let idx = self.fwd.index_tokens(index);
                if self.own.contains(array)
                    && crate::analysis::is_tid_access(self.f, &self.fwd.tid, *array, index)
                {
                    // SAFETY (of the generated code): under __FAST the array covers the grid,
                    // so the index is in bounds, and only this thread touches the element.
                    quote_spanned!(sp=> if __FAST { unsafe { #g.accumulate_own(#idx, __r) } } else { #g.accumulate(#idx, __r)?; })
                } else {
                    quote_spanned!(sp=> #g.accumulate(#idx, __r)?;)
                }
            }
            Op::Member(v, m) => {
                if !self.diff(*v) {
                    return TokenStream::new();
                }
                let a = self.adj(*v);
                let m = super::rust::member_tokens(m);
                quote_spanned!(sp=> __wp::adjoint::Adjoint::adj_accum(&mut #a.#m, __r);)
            }
            Op::Construct { ty, ctor, args } => {
                let lanes: &[&str] = match ty {
                    Ty::Vector(..) | Ty::Quat(_) => &["x", "y", "z", "w"],
                    Ty::Matrix(..) => &["x_axis", "y_axis", "z_axis", "w_axis"],
                    _ => &[],
                };
                match ctor {
                    Ctor::Components => args
                        .iter()
                        .zip(lanes)
                        .map(|(v, l)| {
                            let l = format_ident!("{}", l);
                            acc(*v, quote!(__r.#l))
                        })
                        .collect(),
                    Ctor::Splat => {
                        let s = args[0];
                        let n = match ty {
                            Ty::Vector(_, n) | Ty::Matrix(_, n) => *n as usize,
                            _ => 0,
                        };
                        let parts = lanes[..n].iter().map(|l| {
                            let l = format_ident!("{}", l);
                            match ty {
                                // from_diagonal(v): the diagonal of the adjoint.
                                Ty::Matrix(..) => {
                                    let k =
                                        lanes.iter().position(|x| x == &l.to_string()).unwrap_or(0);
                                    let comp = format_ident!("{}", ["x", "y", "z", "w"][k]);
                                    quote!(__r.#l.#comp)
                                }
                                _ => quote!(__r.#l),
                            }
                        });
                        match ty {
                            Ty::Matrix(..) => {
                                let vt = ty_tokens(self.f.ty(s));
                                let parts: Vec<_> = parts.collect();
                                match vt {
                                    Some(vt) => acc(s, quote!(#vt::new(#(#parts),*))),
                                    None => TokenStream::new(),
                                }
                            }
                            _ => acc(s, quote!(0.0 #(+ #parts)*)),
                        }
                    }
                    Ctor::Const(_) => TokenStream::new(),
                }
            }
            Op::Lit(_)
            | Op::LitLike(..)
            | Op::Unary(UnOp::Not, _)
            | Op::Tid(_)
            | Op::Extent(..)
            | Op::Len(_)
            | Op::ViewCheck { .. }
            | Op::Const(_)
            | Op::Func { .. } => TokenStream::new(),
        }
    }
}
