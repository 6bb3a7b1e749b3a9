//! Scalar builtins (section "scalar" of the CUDA library, warp-core `builtins::math`).

use super::*;

/// The scalar functions, `mod` and `lerp`.
pub(super) const ROWS: &[Builtin] = rows! {
    "min":        NUM_OR_VEC,     (T, T) -> T,              "scalar", Adjoint,
        tangent(Tangent::Select(Pick::Min)), method;
    "max":        NUM_OR_VEC,     (T, T) -> T,              "scalar", Adjoint,
        tangent(Tangent::Select(Pick::Max)), method;
    "abs":        SIGNED,         (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Call("sign", &[A0]))), method;
    "sign":       SIGNED,         (T) -> T,                 "scalar", Zero;
    "clamp":      NUM_OR_VEC,     (T, T, T) -> T,           "scalar", Adjoint,
        tangent(Tangent::Select(Pick::Clamp)), method;
    "floor":      FLOAT,          (T) -> T,                 "scalar", Zero, method;
    "ceil":       FLOAT,          (T) -> T,                 "scalar", Zero, method;
    // a' / (2 sqrt(a))
    "sqrt":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(quotient(&Add(&OUT, &OUT))), method;
    "exp":        FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&OUT)), method;
    // pow(a, b)' = b a^(b-1) a' + a^b ln(a) b' (the second term only where b varies).
    "pow":        FLOAT,          (T, T) -> T,              "scalar", Adjoint,
        tangent(Tangent::Rule(Add(
            &Mul(&Mul(&A1, &Call("pow", &[A0, Sub(&A1, &Const(1.0))])), &D0),
            &Mul(&Mul(&OUT, &Call("log", &[A0])), &D1),
        ))),
        aliases(&["powf"]);
    "log":        FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(quotient(&A0)), aliases(&["ln"]);
    "sin":        FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Call("cos", &[A0]))), method;
    "cos":        FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(Tangent::Rule(Neg(&Mul(&Call("sin", &[A0]), &D0)))), method;
    "tan":        FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Add(&Const(1.0), &Mul(&OUT, &OUT)))), method;
    // atan2(y, x)' = (x y' - y x') / (x^2 + y^2)
    "atan2":      FLOAT,          (T, T) -> T,              "scalar", Adjoint,
        tangent(Tangent::Rule(Div(
            &Sub(&Mul(&A1, &D0), &Mul(&A0, &D1)),
            &Add(&Mul(&A1, &A1), &Mul(&A0, &A0)),
        ))),
        method;
    "asin":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(quotient(&Call("sqrt", &[Sub(&Const(1.0), &Mul(&A0, &A0))]))), method;
    "acos":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(Tangent::Rule(Neg(&Div(
            &D0,
            &Call("sqrt", &[Sub(&Const(1.0), &Mul(&A0, &A0))]),
        )))),
        method;
    "atan":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(quotient(&Add(&Const(1.0), &Mul(&A0, &A0)))), method;
    "sinh":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Call("cosh", &[A0]))), method;
    "cosh":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Call("sinh", &[A0]))), method;
    "tanh":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Sub(&Const(1.0), &Mul(&OUT, &OUT)))), method;
    "exp2":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Mul(&OUT, &Const(LN_2)))), method, extension;
    "log2":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(quotient(&Mul(&A0, &Const(LN_2)))), method;
    "log10":      FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(quotient(&Mul(&A0, &Const(LN_10)))), method;
    // a' / (3 cbrt(a)^2)
    "cbrt":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(quotient(&Mul(&Const(3.0), &Mul(&OUT, &OUT)))), method;
    // erf(a)' = 2/sqrt(pi) exp(-a^2) a'
    "erf":        FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&ERF_SCALE));
    "erfc":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(Tangent::Rule(Neg(&Mul(&ERF_SCALE, &D0))));
    "erfinv":     FLOAT,          (T) -> T,                 "scalar", Adjoint, no_tangent;
    "erfcinv":    FLOAT,          (T) -> T,                 "scalar", Adjoint, no_tangent;
    "round":      FLOAT,          (T) -> T,                 "scalar", Zero, method;
    "rint":       FLOAT,          (T) -> T, "scalar", Zero, aliases(&["round_ties_even"]);
    "trunc":      FLOAT,          (T) -> T,                 "scalar", Zero, method;
    "frac":       FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(Tangent::Rule(D0)), aliases(&["fract"]);
    "step":       NUMBER,         (T) -> T,                 "scalar", Zero;
    "smoothstep": FLOAT,          (T, T, T) -> T,           "scalar", Adjoint, no_tangent;
    "degrees":    FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Const(DEGREES_PER_RADIAN))), aliases(&["to_degrees"]);
    "radians":    FLOAT,          (T) -> T,                 "scalar", Adjoint,
        tangent(chain(&Const(RADIANS_PER_DEGREE))), aliases(&["to_radians"]);
    "isfinite":   CLASSIFY,       (T) -> Bool,              "scalar", Zero, aliases(&["is_finite"]);
    "isnan":      CLASSIFY,       (T) -> Bool,              "scalar", Zero, aliases(&["is_nan"]);
    "isinf":      CLASSIFY,       (T) -> Bool, "scalar", Zero, aliases(&["is_infinite"]);
    // `mod(a, b)` (`r#mod` in Rust source, as `mod` is a keyword) is lowered to the `%`
    // operator: truncated remainder for integers (a fault on zero), C `fmod` for floats, and
    // `%`'s adjoint and tangent.
    "mod":        NUMBER,         (T, T) -> T,              "scalar", Adjoint, operator(BinOp::Rem);
    // lerp takes transforms too (wp_transform.h: the emitter adds the section where a value
    // is a transform); matrices, quaternions and spatial types lane by lane (wp_scalar.h, whose
    // core header defines those types). lerp(a, b, t) = a (1 - t) + b t, whose tangent is
    // a' + (b' - a') t + (b - a) t' (the scalar on the right: quaternions have `q * s` only).
    "lerp":       LERP,           (T, T, ScalarOfT) -> T,   "scalar", Adjoint,
        tangent(Tangent::Rule(Add(
            &Add(&D0, &Mul(&Sub(&D1, &D0), &A2)),
            &Mul(&Sub(&A1, &A0), &D2),
        ))),
        method;
};

/// `erf`'s derivative, `2/sqrt(pi) exp(-a^2)` (`erfc`'s is its negation).
const ERF_SCALE: Dx = Mul(&Const(FRAC_2_SQRT_PI), &Call("exp", &[Neg(&Mul(&A0, &A0))]));
const DEGREES_PER_RADIAN: f64 = 180.0 / std::f64::consts::PI;
const RADIANS_PER_DEGREE: f64 = std::f64::consts::PI / 180.0;
