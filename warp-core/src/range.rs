//! Range loops as arithmetic progressions.
//!
//! `for i in (a..b).rev().step_by(k)` is lowered by the macro to a count and an affine map
//! `i = first + n * step`, so that both backends (and the adjoint, which must replay loops
//! backwards) run exactly the same iterations. The rules below reproduce Rust's iterator
//! semantics for `Range`, `RangeInclusive`, `rev` and `step_by`, in any order.

use crate::fault::{Fault, FaultKind, KResult};

/// An arithmetic progression of `count` values starting at `first`, `step` apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RangeProg {
    /// First value.
    pub first: i64,
    /// Distance between consecutive values (negative after `rev`).
    pub step: i64,
    /// Number of values (never negative).
    pub count: i64,
}

impl RangeProg {
    /// `start..end`, or `start..=end` when `inclusive`.
    #[inline(always)]
    pub fn new(start: i64, end: i64, inclusive: bool) -> Self {
        let count = if inclusive {
            end as i128 - start as i128 + 1
        } else {
            end as i128 - start as i128
        };
        RangeProg {
            first: start,
            step: 1,
            count: count.clamp(0, i64::MAX as i128) as i64,
        }
    }

    /// `.rev()`: the same values, last first.
    #[inline(always)]
    pub fn rev(self) -> Self {
        if self.count == 0 {
            return self;
        }
        RangeProg {
            first: self.first + self.step * (self.count - 1),
            step: -self.step,
            count: self.count,
        }
    }

    /// `.step_by(k)`: every `k`-th value, starting with the first. `k <= 0` is a fault (Rust
    /// panics at 0; a kernel reports it).
    #[inline(always)]
    pub fn step_by(self, k: i64, kernel: &'static str) -> KResult<Self> {
        if k <= 0 {
            return Err(Fault::new(kernel, FaultKind::BadStep { step: k }));
        }
        Ok(RangeProg {
            first: self.first,
            step: self.step * k,
            count: (self.count + k - 1) / k,
        })
    }

    /// The `n`-th value.
    #[inline(always)]
    pub fn at(&self, n: i64) -> i64 {
        self.first + n * self.step
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(p: RangeProg) -> Vec<i32> {
        (0..p.count).map(|n| p.at(n) as i32).collect()
    }

    #[test]
    fn matches_rust_iterators_in_every_order() {
        for (a, b) in [(0i32, 11i32), (3, 3), (5, 2), (-4, 7)] {
            for k in 1..5usize {
                let r = RangeProg::new(a as i64, b as i64, false);
                assert_eq!(values(r), (a..b).collect::<Vec<_>>());
                assert_eq!(values(r.rev()), (a..b).rev().collect::<Vec<_>>());
                assert_eq!(
                    values(r.step_by(k as i64, "t").unwrap()),
                    (a..b).step_by(k).collect::<Vec<_>>()
                );
                assert_eq!(
                    values(r.rev().step_by(k as i64, "t").unwrap()),
                    (a..b).rev().step_by(k).collect::<Vec<_>>()
                );
                assert_eq!(
                    values(r.step_by(k as i64, "t").unwrap().rev()),
                    (a..b).step_by(k).rev().collect::<Vec<_>>()
                );
                let ri = RangeProg::new(a as i64, b as i64, true);
                assert_eq!(values(ri), (a..=b).collect::<Vec<_>>());
                // std has no `.rev()` after `step_by` on inclusive ranges; reversing the sequence is the meaning.
                let mut want: Vec<i32> = (a..=b).step_by(k).collect();
                want.reverse();
                assert_eq!(values(ri.step_by(k as i64, "t").unwrap().rev()), want);
            }
        }
    }

    #[test]
    fn zero_step_is_a_fault() {
        assert_eq!(
            RangeProg::new(0, 4, false)
                .step_by(0, "k")
                .unwrap_err()
                .kind,
            FaultKind::BadStep { step: 0 }
        );
        assert_eq!(
            RangeProg::new(0, 4, false)
                .step_by(-2, "k")
                .unwrap_err()
                .kind,
            FaultKind::BadStep { step: -2 }
        );
    }
}
