//! Lowering of the random-number builtins: Warp's functions that advance a `u32` state in
//! place (`randf(&mut state)`), and the builtins whose Warp overloads differ by arity
//! (`rand_init(seed[, offset])`, `pnoise(state, x, px[, py[, pz[, pt]]])`).
//!
//! The IR has no references. A draw is lowered into pure operations and an assignment:
//!
//! ```text
//! randf(&mut s)          pre = s; r = randf(pre); s = rand_pcg(pre)
//! randn(&mut s)          pre = s; r = randn(pre); s = rand_pcg(rand_pcg(pre))
//! randi(&mut s, lo, hi)  pre = s; t = rand_pcg(pre); s = t;
//!                        r = ((t % ((hi - lo) as u32)) + lo as u32) as i32
//! poisson(&mut s, lam)   pre = s; r = poisson(pre, lam); s = poisson_state(pre, lam)
//! ```
//!
//! where `randf(pre)` is the table row's pure function of the state *before* the draw and
//! `rand_pcg` is applied once per uniform draw the builtin consumes (the row's `draws`). The adjoint's
//! replay therefore recomputes the same draws (the state is an ordinary `u32` variable, pushed
//! on the adjoint stack where loops overwrite it), and every draw has zero gradient.
//! The state may be any assignable place of type `u32`: a `let mut` local, a field of one, or
//! an array element (`&mut states[i]`, loaded once and stored once). `randi`/`randu` with a
//! range use the language's integer operators, so an empty range (`lo == hi`) is the integer
//! remainder-by-zero fault on both backends (Warp: undefined behaviour).

use super::*;
use crate::builtins::Draw;

const U32: Ty = Ty::Scalar(Scalar::U32);
const I32: Ty = Ty::Scalar(Scalar::I32);
const F32: Ty = Ty::Scalar(Scalar::F32);

fn row(name: &str) -> &'static Builtin {
    builtins::lookup(name).expect("rand rows are in the table")
}

impl Lowerer {
    /// Lowers `name(args)` if it is one of the builtins this module handles.
    pub(super) fn rng_call(
        &mut self,
        name: &str,
        c: &syn::ExprCall,
        want: Option<&Ty>,
        span: Span,
    ) -> R<Option<VarId>> {
        let args: Vec<&Expr> = c.args.iter().collect();
        match name {
            // `rand_init(seed, offset)` is the row `rand_init_offset` (an overload by arity).
            "rand_init" => match args.len() {
                1 => self.builtin_call(row("rand_init"), &args, want, span).map(Some),
                n => err(
                    span,
                    format!("`rand_init` takes a seed and an optional offset (`rand_init(seed)`, `rand_init(seed, offset)`), found {n} argument(s)"),
                ),
            },
            "pnoise" if args.len() > 3 && args.len() <= 6 => {
                // Warp's `pnoise(state, xy, px, py)`: the periods become one integer vector.
                let ctor = format_ident(&format!("ivec{}", args.len() - 2), span);
                let periods = &args[2..];
                let packed: Expr = syn::parse_quote_spanned!(span=> #ctor(#(#periods),*));
                let given = args.len() - 2;
                self.builtin_call(row("pnoise"), &[args[0], args[1], &packed], want, span)
                    .map(Some)
                    .map_err(|e| {
                        if e.to_string().contains("argument 3") {
                            syn::Error::new(
                                span,
                                format!("`pnoise` takes one integer period per lane of its position, found {given}: {e}"),
                            )
                        } else {
                            e
                        }
                    })
            }
            // Not a row: its argument is an `Array<f32>`, which no signature position is.
            // Warp's: `lower_bound(cdf, randf(state))`, one step.
            "sample_cdf" => self
                .rng_draw(name, Draw::Steps(1), &args, span)
                .map(Some),
            _ => match builtins::lookup(name).and_then(|b| b.draw) {
                Some(draw) => self.rng_draw(name, draw, &args, span).map(Some),
                None => Ok(None),
            },
        }
    }

    /// A state-advancing draw, which advances the state as `draw` says.
    fn rng_draw(&mut self, name: &str, draw: Draw, args: &[&Expr], span: Span) -> R<VarId> {
        let Some(first) = args.first() else {
            return err(
                span,
                format!("`{name}` takes the generator state first: `{name}(&mut state)`"),
            );
        };
        let place_expr = match strip(first) {
            Expr::Reference(r) if r.mutability.is_some() => &*r.expr,
            Expr::Reference(r) => {
                return err(
                    r.span(),
                    format!("`{name}` advances the generator state in place: pass `&mut state`, not `&state`"),
                )
            }
            other => {
                return err(
                    other.span(),
                    format!("`{name}` advances the generator state in place: pass it as `&mut state` (a `u32` from `rand_init`)"),
                )
            }
        };
        if !matches!(
            strip(place_expr),
            Expr::Path(_) | Expr::Field(_) | Expr::Index(_)
        ) {
            return err(
                place_expr.span(),
                "the generator state must be a mutable variable, a field of one or an array element",
            );
        }
        // Which extra arguments, of which types.
        let cdf = [Ty::Array(Box::new(F32), 1)];
        let extra: &[Ty] = match (name, args.len() - 1) {
            ("sample_cdf", 1) => &cdf,
            ("sample_cdf", _) => {
                return err(span, "`sample_cdf` takes the state and a cumulative distribution: `sample_cdf(&mut state, cdf)` with `cdf: Array<f32>`")
            }
            ("randi", 0) | ("randu", 0) | ("randf", 0) => &[],
            ("randi", 2) => &[I32, I32],
            ("randu", 2) => &[U32, U32],
            ("randf", 2) => &[F32, F32],
            ("poisson", 1) => &[F32],
            ("randi" | "randu" | "randf", n) => {
                return err(
                    span,
                    format!("`{name}` takes the state and an optional range: `{name}(&mut state)` or `{name}(&mut state, lo, hi)`, found {n} argument(s) after the state"),
                )
            }
            ("poisson", _) => {
                return err(span, "`poisson` takes the state and the mean: `poisson(&mut state, lam)`")
            }
            (_, 0) => &[],
            _ => return err(span, format!("`{name}` takes only the state: `{name}(&mut state)`")),
        };
        // The place (its index expressions), then the other arguments, then the read: a draw
        // inside another argument happens first.
        let place = self.place(place_expr)?;
        let pty = self.place_ty(&place, place_expr.span())?;
        if !pty.is_deferred() && pty != U32 {
            return err(
                place_expr.span(),
                format!("the generator state is a `u32` (from `rand_init`), found `{pty}`"),
            );
        }
        let mut xs = Vec::new();
        for (a, want) in args[1..].iter().zip(extra) {
            let v = self.expr(a, Some(want))?;
            let t = self.ty(v);
            if !t.is_deferred() && t != *want {
                return err(
                    a.span(),
                    format!("mismatched types in `{name}`: expected `{want}`, found `{t}`"),
                );
            }
            xs.push(v);
        }
        let pre = self.read_place(&place, U32, span);
        let call = |cx: &mut Self, b: &str, args: Vec<VarId>| {
            let b = row(b);
            let ty = match b.ret {
                Pos::Fixed(s) => Ty::Scalar(s),
                Pos::FixedVec(s, n) => Ty::Vector(s, n),
                _ => Ty::Deferred,
            };
            cx.def(Op::Builtin { builtin: b, args }, ty, span)
        };
        // The state after the draw, a function of the state before it.
        let advance = |cx: &mut Self| match draw {
            Draw::Steps(k) => (0..k).fold(pre, |s, _| call(cx, "rand_pcg", vec![s])),
            Draw::NextState(r) => call(cx, r, std::iter::once(pre).chain(xs.clone()).collect()),
        };
        let (result, next) = match (name, xs.len()) {
            ("randi" | "randu", n) => {
                let t = advance(self);
                let r = if n == 0 {
                    t
                } else {
                    // Warp's `state % (hi - lo) + lo`, in u32 (wrapping), then as i32 for randi.
                    let (lo, hi) = (xs[0], xs[1]);
                    let ity = if name == "randi" { I32 } else { U32 };
                    let d = self.def(Op::Binary(BinOp::Sub, hi, lo), ity.clone(), span);
                    let (du, lou) = if name == "randi" {
                        (
                            self.def(Op::Cast(d, U32), U32, span),
                            self.def(Op::Cast(lo, U32), U32, span),
                        )
                    } else {
                        (d, lo)
                    };
                    let m = self.def(Op::Binary(BinOp::Rem, t, du), U32, span);
                    self.def(Op::Binary(BinOp::Add, m, lou), U32, span)
                };
                let r = if name == "randi" {
                    self.def(Op::Cast(r, I32), I32, span)
                } else {
                    r
                };
                (r, t)
            }
            ("sample_cdf", _) => {
                // Warp's: `lower_bound(cdf, randf(state))`, one step.
                if self.is_view(xs[0]) {
                    return err(
                        args[1].span(),
                        "`sample_cdf` searches an array, not a view: pass the array",
                    );
                }
                let u = call(self, "randf", vec![pre]);
                let r = self.def(
                    Op::Builtin {
                        builtin: row("lower_bound"),
                        args: vec![xs[0], u],
                    },
                    I32,
                    span,
                );
                (r, advance(self))
            }
            ("poisson", _) => {
                let r = call(self, "poisson", vec![pre, xs[0]]);
                (r, advance(self))
            }
            ("randf", 2) => {
                let r = call(self, "randf_range", vec![pre, xs[0], xs[1]]);
                (r, advance(self))
            }
            _ => {
                let r = call(self, name, vec![pre]);
                (r, advance(self))
            }
        };
        self.write_place(place, next, span);
        Ok(result)
    }
}

fn format_ident(name: &str, span: Span) -> syn::Ident {
    syn::Ident::new(name, span)
}

#[cfg(test)]
mod tests {
    use crate::builtins::{Draw, BUILTINS};

    #[test]
    fn draw_counts_match_warp_core() {
        // warp-core states the same counts for its functions (this crate cannot depend on it):
        // compare the text of its `DRAWS` with the table's `draws`.
        let core = include_str!("../../../../warp-core/src/builtins/rand.rs");
        let block = core
            .split("pub const DRAWS: &[(&str, u32)] = &[")
            .nth(1)
            .and_then(|rest| rest.split("];").next())
            .expect("warp-core's DRAWS table");
        let mut rows = 0;
        for b in BUILTINS {
            if let Some(Draw::Steps(k)) = b.draw {
                let name = b.name;
                assert!(
                    block.contains(&format!("(\"{name}\", {k}),")),
                    "{name}: {k} draws in the table, not in warp-core's DRAWS"
                );
                rows += 1;
            }
        }
        // And no row there that is missing here.
        assert_eq!(
            block.matches("(\"").count(),
            rows,
            "rows in warp-core's DRAWS"
        );
    }
}
