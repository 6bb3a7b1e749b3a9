//! Rust's inference for a `let` of an unsuffixed literal, `let mut acc = 1.0;`: rustc types
//! `acc` by its later uses (`acc *= x` with `x: f64` makes it an f64; `n += i` with `i` a
//! `usize` a usize), where one pass over the body must type it at the `let` (f32, i32).
//!
//! The lowering types such a `let` by the literal's default and remembers the variable. When
//! an operation later meets it with a scalar of the same kind (float and float, integer and
//! integer) of another type, that is Rust's answer: the type is noted and the function is
//! lowered again with the `let` typed so ([`Defaults::given`], keyed by the order in which
//! the lowering meets such `let`s, which is the same on every pass). A mismatch with nothing
//! to learn from stays the error it was.

use super::places::Place;
use super::*;
use std::collections::hash_map::Entry;

/// What the passes over one function know about its literal `let`s.
#[derive(Default)]
pub(super) struct Defaults {
    /// The types earlier passes found for the literal `let`s (by their order).
    pub given: HashMap<usize, Ty>,
    /// Literal `let`s met on this pass.
    met: usize,
    /// The variables they bound, with their `let`'s key.
    vars: HashMap<VarId, usize>,
    /// Types this pass's uses asked for, not yet in `given`.
    pub found: HashMap<usize, Ty>,
}

impl Defaults {
    /// A pass that knows the types in `given`.
    pub fn new(given: HashMap<usize, Ty>) -> Self {
        Defaults {
            given,
            ..Default::default()
        }
    }

    /// At an unannotated `let` of an unsuffixed literal: its key, and the type an earlier
    /// pass found for it.
    pub fn meet(&mut self) -> (usize, Option<Ty>) {
        let key = self.met;
        self.met += 1;
        (key, self.given.get(&key).cloned())
    }

    pub fn bound(&mut self, var: VarId, key: usize) {
        self.vars.insert(var, key);
    }
}

impl Lowerer {
    /// `var` (of type `have`) met a value of type `other` where the two had to agree: if
    /// `var` is a literal `let`'s and `other`'s scalar is of the same kind, note it for the
    /// next pass.
    pub(super) fn learn_literal_type(&mut self, var: VarId, other: &Ty) {
        let Some(&key) = self.defaults.vars.get(&var) else {
            return;
        };
        let (Ty::Scalar(have), Some(want)) = (self.ty(var), other.scalar()) else {
            return;
        };
        let same_kind = (have.is_float() && want.is_float()) || (have.is_int() && want.is_int());
        if !same_kind || have == want || self.defaults.given.contains_key(&key) {
            return;
        }
        if let Entry::Vacant(e) = self.defaults.found.entry(key) {
            e.insert(Ty::Scalar(want));
        }
    }

    /// A place met a value of type `other`: learned if the place is a literal `let`'s
    /// variable itself (not a field or lane of it).
    pub(super) fn learn_for_place(&mut self, place: &Place, other: &Ty) {
        if let Place::Local { var, path } = place {
            if path.is_empty() {
                self.learn_literal_type(*var, other);
            }
        }
    }

    /// Both directions of [`learn_literal_type`](Self::learn_literal_type) for two operands.
    pub(super) fn learn_from_pair(&mut self, a: VarId, b: VarId) {
        let (ta, tb) = (self.ty(a), self.ty(b));
        self.learn_literal_type(a, &tb);
        self.learn_literal_type(b, &ta);
    }
}
