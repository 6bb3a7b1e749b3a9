//! A builtin's row: the facts it states ([`Builtin`]), the row builder that the section
//! files write them with, and what follows from them (atomic, faulting, Warp's name).

use super::{Class, Pos, Tangent};
use crate::operators::BinOp;

/// How a `for` loop iterates a query row's result (`for j in hash_grid_query(grid, p, r)`,
/// lowered by `front::lower::query`): the rows of its steps, each a pure function, every one
/// internal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Iterate {
    /// `(object, state) -> state`: the state at the next candidate, or at the end.
    pub next: &'static str,
    /// `(state) -> bool`: whether the state is at the end.
    pub done: &'static str,
    /// `(state) -> item`: the candidate the loop variable takes.
    pub item: &'static str,
    /// The CUDA function of the object (`wp::hash_grid_item_bound(grid)`) whose value every
    /// item is below, with items never negative: `next` checks each item it yields (a fault,
    /// and the end of the query, otherwise). Then one check before the loop that a 1-D array
    /// holds that many elements covers every access of it at the loop variable (the forward
    /// CUDA emitter's unswitched query loop). `None` when items are not checked so.
    pub bound: Option<&'static str>,
}

/// How a builtin is differentiated in reverse mode (used by the adjoint transform; forward
/// mode's rule is the row's [`Tangent`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grad {
    /// Through `adj_<name>` in both libraries.
    Adjoint,
    /// Piecewise constant or not a float: zero gradient (floor, ceil, sign, round, step,
    /// isnan, ...).
    Zero,
    /// Atomics: special rules in the adjoint transform.
    Atomic,
    /// A write into an object (`volume_store`): not replayed by the adjoint, and backward
    /// through a kernel that makes one is refused (the stored value's gradient would be lost;
    /// see `analysis::atomic_without_adjoint`).
    Effect,
    /// Atomics without an adjoint (cas, exch, and, or, xor; Warp has none either): not
    /// replayed, and backward through a kernel is refused where one would lose a gradient or
    /// where the replay would need the old value it returned (see
    /// `analysis::atomic_without_adjoint`).
    AtomicNone,
    /// Differentiable in Warp, but without an adjoint here yet (the tile Cholesky factor and
    /// solves): backward through a kernel that calls it is refused, naming the builtin
    /// (`middle::adjoint::build`), never a gradient silently missing.
    NotYet,
}

/// How a draw `name(&mut state, ..)` advances the generator state (`front::lower::rng`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Draw {
    /// By this many generator steps (`rand_pcg`), one per uniform draw the builtin consumes.
    /// warp-core's `builtins::rand::DRAWS` states the same counts for its functions; a test
    /// in `front::lower::rng` holds the two together.
    Steps(u32),
    /// To the value of the named row at the state before the draw (`poisson_state`: Poisson
    /// sampling consumes a variable number of draws).
    NextState(&'static str),
}

/// How a call of a builtin reaches the emitters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Emit {
    /// An `Op::Builtin`: the emitters call the row's `rust` and `cuda` functions.
    Call,
    /// The binary operator (`mod` is `%`: the same faults, float semantics and adjoint); the
    /// row's `rust` and `cuda` names are never emitted.
    Operator(BinOp),
    /// Written out by the front end in other operations (`randi`: a `rand_pcg` step and
    /// integer operators, see `front::lower::rng`); no function of that name exists.
    Lowered,
}

/// One builtin: every fact about it is a field of its row in [`BUILTINS`](super::BUILTINS).
#[derive(Clone, Copy, Debug)]
pub struct Builtin {
    pub name: &'static str,
    /// The classes `T` may belong to (any of them).
    pub classes: &'static [Class],
    pub params: &'static [Pos],
    pub ret: Pos,
    /// Method syntax allowed: `x.sqrt()`, `v.dot(w)`.
    pub method: bool,
    /// Rust method names that mean this builtin under another name (`x.powf(y)` is
    /// `pow(x, y)`), callable whatever `method` says. Each has Rust's meaning exactly:
    /// `round_ties_even` is `rint`, `fract` is `x - trunc(x)` like `frac`,
    /// `to_degrees`/`to_radians` multiply by the same constants as `degrees`/`radians`.
    /// (`signum` is not an alias of `sign`: Rust's gives NaN for NaN and -1 for -0.0, Warp's
    /// `sign` +1 for both.)
    pub aliases: &'static [&'static str],
    /// glam's constructor spelling: `(class, f)` makes `Ty::f(..)`, for a type `Ty` of
    /// `class`, this builtin (`Quat::from_axis_angle(axis, angle)`, `Transform::new(p, q)`).
    pub ctor: Option<(Class, &'static str)>,
    /// Warp's overload by arity that this row is: `(name, n)` means a call of `name` with
    /// `n` arguments is this row (`min(v)` of one vector is `min_element`). That is also the
    /// row's name in Warp ([`Builtin::warp_name`]).
    pub overload: Option<(&'static str, usize)>,
    /// A piece or an overload of another builtin (the RNG's `rand_pcg`, `lower_bound_range`):
    /// user code cannot name it.
    pub internal: bool,
    /// Warp's keyword default of the last argument, as a literal the call gets when it leaves
    /// that argument out (the norms' `delta = 1.0`).
    pub default_last: Option<&'static str>,
    /// A state-advancing draw (`randf(&mut state)`): how it advances the state.
    pub draw: Option<Draw>,
    /// The names of a tuple result's parts, in the order of Warp's output arguments, as a
    /// destructuring pattern (`"(u, sigma, v)"`); error messages and the builtin table show it.
    pub results: Option<&'static str>,
    /// Not a Warp builtin: an extension of warp-lang's (docs/book/src/builtins.md lists it there).
    pub extension: bool,
    /// A query that only a `for` loop iterates (`for j in hash_grid_query(..)`), by these
    /// steps; user code cannot bind its result otherwise.
    pub iterate: Option<Iterate>,
    pub emit: Emit,
    /// Function in `warp_core::builtins`.
    pub rust: &'static str,
    /// Function in the CUDA builtin library (namespace `wp`).
    #[allow(dead_code)] // read by the CUDA emitter
    pub cuda: &'static str,
    /// Section of the CUDA builtin library that defines it.
    #[allow(dead_code)] // read by the CUDA emitter
    pub section: &'static str,
    /// How reverse mode differentiates it (the adjoint transform).
    pub grad: Grad,
    /// How forward mode differentiates it (`middle::tangent`): stated by every row with a
    /// gradient, the rule or [`Tangent::NoRule`]; `None` where the gradient is zero.
    pub tangent: Option<Tangent>,
    /// Block-cooperative (a tile operation): every thread of the block must make the call
    /// together, so it must not be under control flow that depends on the thread (the
    /// validator's uniformity rule, `valid::uniformity`).
    pub cooperative: bool,
    /// Moves values between a tile and the block's threads (`tile(x)`, `untile(t)`): its
    /// per-thread side is each lane's own, and the tile's width is the block size.
    pub lanes: bool,
}

/// The row builder: [`Builtin::row`] gives a row every default (a user-callable builtin in
/// function syntax only, emitted as a call of the functions named after it), and each method
/// below states one fact that differs; `rows!` writes them after the row's signature.
impl Builtin {
    pub(super) const fn row(
        name: &'static str,
        cuda: &'static str,
        classes: &'static [Class],
        params: &'static [Pos],
        ret: Pos,
        section: &'static str,
        grad: Grad,
    ) -> Builtin {
        Builtin {
            name,
            classes,
            params,
            ret,
            method: false,
            aliases: &[],
            ctor: None,
            overload: None,
            internal: false,
            default_last: None,
            draw: None,
            results: None,
            extension: false,
            iterate: None,
            emit: Emit::Call,
            rust: name,
            cuda,
            section,
            grad,
            tangent: None,
            cooperative: false,
            lanes: false,
        }
    }

    pub(crate) const fn cooperative(self) -> Builtin {
        Builtin {
            cooperative: true,
            ..self
        }
    }

    pub(super) const fn lanes(self) -> Builtin {
        Builtin {
            lanes: true,
            ..self
        }
    }

    /// A tile operation (its signature mentions a tile): typed by `front::lower::tiles`.
    pub fn is_tile(&self) -> bool {
        self.section == "tile"
    }

    pub(super) const fn method(self) -> Builtin {
        Builtin {
            method: true,
            ..self
        }
    }

    pub(super) const fn aliases(self, aliases: &'static [&'static str]) -> Builtin {
        Builtin { aliases, ..self }
    }

    pub(super) const fn ctor(self, class: Class, f: &'static str) -> Builtin {
        Builtin {
            ctor: Some((class, f)),
            ..self
        }
    }

    pub(super) const fn overload(self, name: &'static str, arity: usize) -> Builtin {
        Builtin {
            overload: Some((name, arity)),
            ..self
        }
    }

    pub(super) const fn internal(self) -> Builtin {
        Builtin {
            internal: true,
            ..self
        }
    }

    pub(super) const fn default_last(self, literal: &'static str) -> Builtin {
        Builtin {
            default_last: Some(literal),
            ..self
        }
    }

    pub(super) const fn draws(self, steps: u32) -> Builtin {
        Builtin {
            draw: Some(Draw::Steps(steps)),
            ..self
        }
    }

    pub(super) const fn next_state(self, row: &'static str) -> Builtin {
        Builtin {
            draw: Some(Draw::NextState(row)),
            ..self
        }
    }

    pub(super) const fn results(self, pattern: &'static str) -> Builtin {
        Builtin {
            results: Some(pattern),
            ..self
        }
    }

    pub(super) const fn extension(self) -> Builtin {
        Builtin {
            extension: true,
            ..self
        }
    }

    pub(super) const fn iterate(
        self,
        next: &'static str,
        done: &'static str,
        item: &'static str,
    ) -> Builtin {
        Builtin {
            iterate: Some(Iterate {
                next,
                done,
                item,
                bound: None,
            }),
            ..self
        }
    }

    /// The query's items are checked against `bound` of the object ([`Iterate::bound`]);
    /// after [`iterate`](Builtin::iterate).
    pub(super) const fn item_bound(self, bound: &'static str) -> Builtin {
        let Some(it) = self.iterate else {
            panic!("item_bound: not a query row");
        };
        Builtin {
            iterate: Some(Iterate {
                bound: Some(bound),
                ..it
            }),
            ..self
        }
    }

    pub(super) const fn operator(self, op: BinOp) -> Builtin {
        Builtin {
            emit: Emit::Operator(op),
            ..self
        }
    }

    pub(super) const fn lowered(self) -> Builtin {
        Builtin {
            emit: Emit::Lowered,
            ..self
        }
    }

    /// Forward mode's rule (the row's gradient is not zero).
    pub(super) const fn tangent(self, rule: Tangent) -> Builtin {
        Builtin {
            tangent: Some(rule),
            ..self
        }
    }

    /// Forward mode has no rule: a call with a differentiated argument is refused.
    pub(super) const fn no_tangent(self) -> Builtin {
        self.tangent(Tangent::NoRule)
    }
}

impl Builtin {
    /// An atomic read-modify-write of an array element (`atomic_add`, `atomic_cas`, ...): it
    /// has a side effect, is not replayed by adjoints, and its arguments are the array, the
    /// index (one variable per dimension) and [`Builtin::atomic_values`] values.
    pub fn is_atomic(&self) -> bool {
        matches!(self.grad, Grad::Atomic | Grad::AtomicNone)
    }

    /// Whether the builtin writes its first argument, an array: the atomics (`atomic_add`,
    /// `tile_atomic_add`) and `tile_store`.
    pub fn writes_array(&self) -> bool {
        self.is_atomic() || self.name == "tile_store"
    }

    /// How many value arguments follow an atomic's index: 2 for `atomic_cas` (compare,
    /// value), 1 for the others.
    pub fn atomic_values(&self) -> usize {
        let at = self
            .params
            .iter()
            .position(|p| *p == Pos::Index)
            .unwrap_or(self.params.len());
        self.params.len().saturating_sub(at + 1)
    }

    /// Whether the builtin takes an array among its values (not an atomic): its CPU function
    /// gets the view by reference and returns a `KResult` (its reads are checked), its CUDA
    /// function takes the fault context last (`lower_bound`). Read off the signature, so no
    /// row can say otherwise.
    pub fn reads_array(&self) -> bool {
        !self.is_atomic() && self.params.contains(&Pos::ArrayOfT)
    }

    /// Whether the builtin takes a host object (`hash_grid_query(grid, ..)`): like
    /// [`Builtin::reads_array`], its CPU function returns a `KResult` (the object's buffers are
    /// read through checked views) and its CUDA function takes the fault context last; the
    /// object is passed by value (a view). Read off the signature.
    pub fn reads_object(&self) -> bool {
        self.params.iter().any(|p| {
            matches!(p, Pos::Object(k) if k.row().param)
                || matches!(
                    p,
                    Pos::VolumeOfT | Pos::AnyVolume | Pos::BsrOfT | Pos::AnyBsr
                )
        })
    }

    /// Whether a call may fault ([`Builtin::reads_array`] or [`Builtin::reads_object`]): the
    /// CPU call is followed by `?`, the CUDA call takes `__ctx`.
    pub fn faults(&self) -> bool {
        self.reads_array() || self.reads_object()
    }

    /// The builtin's name in Warp: its own, or that of the builtin it is an overload of
    /// (`min_element` is Warp's `min` of one vector). None for an extension.
    #[allow(dead_code)] // read by the docs/book/src/builtins.md check
    pub fn warp_name(&self) -> Option<&'static str> {
        if self.extension {
            return None;
        }
        Some(self.overload.map_or(self.name, |(name, _)| name))
    }
}
