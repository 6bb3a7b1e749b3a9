//! The forward-mode rule of a row: how the tangent of a builtin's result follows from its
//! arguments and their tangents, stated beside the row's adjoint rule (its
//! [`Grad`](super::Grad)), so that a builtin's derivative rules for both modes are facts of its
//! row. `middle::tangent` reads them; a row with a gradient and no rule says so (`no_tangent`),
//! and a unit test below holds every such row to stating one or the other.
//!
//! Most rules are a [`Dx`]: a small expression in the primal arguments (`A0`..), the result
//! (`OUT`) and the arguments' tangents (`D0`..), linear in the tangents, which the pass writes
//! out as IR operations (`sin`: `cos(a) a'`, written `chain(&Call("cos", &[A0]))`). A few are
//! shapes the pass implements once for every row of that shape: choosing an operand by the
//! primal's decision (`min`, `max`, `clamp`), and the same atomic on the tangent array.

use super::Class;

/// A row's forward-mode rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tangent {
    /// The tangent is this expression.
    Rule(Dx),
    /// This expression where the first argument's type is of one of these classes; forward
    /// mode refuses the others (`normalize` of a quaternion, `inverse` of a quaternion).
    RuleFor(&'static [Class], Dx),
    /// The operand the primal returns carries its tangent, lane by lane for vectors, ties
    /// broken as the adjoint breaks them.
    Select(Pick),
    /// The same atomic on the tangent array, with the value's tangent (`atomic_add`,
    /// `atomic_sub`: linear in the stored value).
    Atomic,
    /// No rule (yet): a differentiated argument makes the kernel's tangent kernel an error
    /// naming the call, which `wp::jvp` returns (`Forward::TANGENT_ERROR`).
    NoRule,
}

/// Which selection a [`Tangent::Select`] row makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pick {
    Min,
    Max,
    /// `clamp(x, lo, hi)`, as `min(max(x, lo), hi)`.
    Clamp,
}

/// An expression of a forward-mode rule. Where a tangent is absent (its argument is held
/// constant), so is every product, quotient and call it is a factor of, and a sum drops it;
/// where the whole expression is absent the result has no tangent. Identical subexpressions
/// are computed once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dx {
    /// Primal argument `i`.
    Arg(usize),
    /// The primal result.
    Out,
    /// The tangent of argument `i`.
    Dot(usize),
    /// A float constant, typed like an unsuffixed literal by the operand it meets (the
    /// literal rule): only as an operand of `Add`, `Sub`, `Mul` or `Div`.
    Const(f64),
    Add(&'static Dx, &'static Dx),
    Sub(&'static Dx, &'static Dx),
    Mul(&'static Dx, &'static Dx),
    Div(&'static Dx, &'static Dx),
    Neg(&'static Dx),
    /// A call of the named builtin, linear in its tangent argument if it has one.
    Call(&'static str, &'static [Dx]),
    /// A call of the row's own builtin (linear in its tangent argument).
    This(&'static [Dx]),
}

pub const A0: Dx = Dx::Arg(0);
pub const A1: Dx = Dx::Arg(1);
pub const A2: Dx = Dx::Arg(2);
pub const OUT: Dx = Dx::Out;
pub const D0: Dx = Dx::Dot(0);
pub const D1: Dx = Dx::Dot(1);
pub const D2: Dx = Dx::Dot(2);

/// `f'(a) a'` for a function of one argument, given the scale `f'(a)`.
pub const fn chain(scale: &'static Dx) -> Tangent {
    Tangent::Rule(Dx::Mul(scale, &D0))
}

/// `a' / q` for a function of one argument whose derivative is `1 / q`.
pub const fn quotient(q: &'static Dx) -> Tangent {
    Tangent::Rule(Dx::Div(&D0, q))
}

/// A builtin linear in its one argument (`transpose`, `trace`): `f(a')`.
pub const LINEAR: Tangent = Tangent::Rule(Dx::This(&[D0]));

/// A builtin linear in each of its two arguments (`dot`, `cross`): `f(a', b) + f(a, b')`.
pub const BILINEAR: Tangent = Tangent::Rule(Dx::Add(&Dx::This(&[D0, A1]), &Dx::This(&[A0, D1])));

impl Dx {
    /// Whether the expression carries a tangent (mentions a `Dot`), and if it does, whether
    /// it is present given which arguments have tangents: `None` for a primal expression.
    pub fn present(&self, has_dot: &dyn Fn(usize) -> bool) -> Option<bool> {
        let pair = |l: &Dx, r: &Dx| match (l.present(has_dot), r.present(has_dot)) {
            (None, None) => None,
            (l, r) => Some(l.unwrap_or(false) || r.unwrap_or(false)),
        };
        match self {
            Dx::Arg(_) | Dx::Out | Dx::Const(_) => None,
            Dx::Dot(i) => Some(has_dot(*i)),
            Dx::Neg(x) => x.present(has_dot),
            Dx::Add(l, r) | Dx::Sub(l, r) => pair(l, r),
            // Linear: one factor carries the tangent (the checks below hold rules to it).
            Dx::Mul(l, r) | Dx::Div(l, r) => pair(l, r),
            Dx::Call(_, args) | Dx::This(args) => args
                .iter()
                .filter_map(|a| a.present(has_dot))
                .reduce(|a, b| a || b),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{lookup, Builtin, Emit, Grad, Pos, BUILTINS};
    use super::*;

    /// Holds a rule to what the pass assumes: arguments and tangents within the signature,
    /// calls of rows of the table with their arity, linear in the tangents (a product or
    /// quotient has one factor that carries a tangent, a divisor none, a call at most one
    /// argument that does, a sum both terms or neither), constants only beside an operand.
    fn check(b: &Builtin, dx: &Dx) {
        let n = b.params.len();
        let any = |_: usize| true;
        let carries = |x: &Dx| x.present(&any).is_some();
        let not_const = |x: &Dx| !matches!(x, Dx::Const(_));
        match dx {
            Dx::Arg(i) | Dx::Dot(i) => assert!(*i < n, "{}: argument {i}", b.name),
            Dx::Out | Dx::Const(_) => {}
            Dx::Neg(x) => {
                assert!(
                    not_const(x),
                    "{}: a constant stands beside an operand",
                    b.name
                );
                check(b, x)
            }
            Dx::Add(l, r) | Dx::Sub(l, r) | Dx::Mul(l, r) | Dx::Div(l, r) => {
                assert!(
                    not_const(l) || not_const(r),
                    "{}: two constants: fold them",
                    b.name
                );
                let (cl, cr) = (carries(l), carries(r));
                match dx {
                    Dx::Add(..) | Dx::Sub(..) => {
                        assert_eq!(cl, cr, "{}: a sum of a tangent and a primal", b.name)
                    }
                    Dx::Mul(..) => assert!(!(cl && cr), "{}: a product of tangents", b.name),
                    _ => assert!(!cr, "{}: division by a tangent", b.name),
                }
                for x in [l, r] {
                    if not_const(x) {
                        check(b, x);
                    }
                }
            }
            Dx::Call(name, args) => {
                let row = lookup(name).unwrap_or_else(|| panic!("{}: calls `{name}`", b.name));
                assert_eq!(row.params.len(), args.len(), "{}: `{name}`'s arity", b.name);
                call_args(b, args);
            }
            Dx::This(args) => {
                assert_eq!(n, args.len(), "{}: its own arity", b.name);
                call_args(b, args);
            }
        }
        fn call_args(b: &Builtin, args: &[Dx]) {
            let any = |_: usize| true;
            let carrying = args.iter().filter(|a| a.present(&any).is_some()).count();
            assert!(carrying <= 1, "{}: a call linear in one argument", b.name);
            for a in args {
                assert!(
                    !matches!(a, Dx::Const(_)),
                    "{}: a constant argument",
                    b.name
                );
                check(b, a);
            }
        }
    }

    /// The recipe "a new builtin states both rules": every row that has a gradient (an
    /// adjoint, an atomic's, an effect's refusal) states its forward-mode rule, or that it has
    /// none; a zero-gradient row states none, as its tangent is zero whatever the arguments'.
    #[test]
    fn every_differentiable_row_states_its_forward_rule() {
        for b in BUILTINS {
            match (b.grad, b.emit, b.tangent) {
                (Grad::Zero, _, t) => assert_eq!(t, None, "{}: zero gradient", b.name),
                // `mod` is the `%` operator, whose rule is the operator's.
                (_, Emit::Operator(_), t) => assert_eq!(t, None, "{}: an operator", b.name),
                (_, _, None) => panic!(
                    "{}: a row with a gradient states its forward-mode rule, \
                     `tangent(..)`, or that it has none, `no_tangent`",
                    b.name
                ),
                (_, _, Some(Tangent::Rule(dx) | Tangent::RuleFor(_, dx))) => {
                    let any = |_: usize| true;
                    assert_eq!(dx.present(&any), Some(true), "{}: no tangent", b.name);
                    check(b, &dx);
                }
                (_, _, Some(Tangent::Select(_))) => {
                    assert!(b.params.iter().all(|p| *p == Pos::T), "{}", b.name);
                    assert!(b.ret == Pos::T, "{}", b.name)
                }
                (_, _, Some(Tangent::Atomic)) => {
                    assert!(
                        b.grad == Grad::Atomic && b.atomic_values() == 1,
                        "{}",
                        b.name
                    )
                }
                (_, _, Some(Tangent::NoRule)) => {}
            }
        }
        assert!(matches!(
            lookup("sin").unwrap().tangent,
            Some(Tangent::Rule(_))
        ));
        assert_eq!(lookup("erfinv").unwrap().tangent, Some(Tangent::NoRule));
    }

    #[test]
    fn presence_follows_the_tangents_given() {
        // pow: a' b a^(b-1) + b' a^b ln a, one term per tangent.
        let Some(Tangent::Rule(dx)) = lookup("pow").unwrap().tangent else {
            panic!("pow has a rule")
        };
        assert_eq!(dx.present(&|i| i == 0), Some(true));
        assert_eq!(dx.present(&|i| i == 1), Some(true));
        assert_eq!(dx.present(&|_| false), Some(false));
        let Dx::Add(l, r) = dx else { panic!("a sum") };
        assert_eq!(l.present(&|i| i == 1), Some(false));
        assert_eq!(r.present(&|i| i == 1), Some(true));
        assert_eq!(Dx::Call("sqrt", &[A0]).present(&|_| true), None);
    }
}
