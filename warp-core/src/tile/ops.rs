//! Elementwise operations on tiles: `map` (unary and binary), the operators `+ - *` between
//! tiles of one shape and between a tile and a scalar (on either side), `/` for float tiles,
//! unary `-` (wrapping for integers, a sign flip for floats), and checked integer division.
//!
//! Each element is computed independently with the builtins' dispatch traits
//! ([`Scalar`]: IEEE for floats, wrapping for integers, as on CUDA), so the results do not
//! depend on the block size and equal the GPU's bit for bit. A shape mismatch is a type error.

use std::ops::{Add, Div, Mul, Neg, Sub};

use super::{Tile, Tile1, Tile2, Tile3, Tile4, TileFromFn};
use crate::builtins::{Float, Scalar};
use crate::fault::KResult;
use crate::ops::WrapInt;

impl<T: Copy, const N0: usize> Tile1<T, N0> {
    /// `f` applied to each element (`tile_map(f, t)`).
    #[inline(always)]
    pub fn map<U>(&self, f: impl Fn(T) -> U) -> Tile1<U, N0> {
        Tile1 {
            data: self.data.map(f),
        }
    }

    /// `f` applied to each pair of elements at the same position (`tile_map(f, a, b)`).
    #[inline(always)]
    pub fn map2<U: Copy, V>(&self, o: &Tile1<U, N0>, f: impl Fn(T, U) -> V) -> Tile1<V, N0> {
        Tile1 {
            data: std::array::from_fn(|i| f(self.data[i], o.data[i])),
        }
    }
}

impl<T: Copy, const N0: usize, const N1: usize> Tile2<T, N0, N1> {
    /// `f` applied to each element (`tile_map(f, t)`).
    #[inline(always)]
    pub fn map<U>(&self, f: impl Fn(T) -> U) -> Tile2<U, N0, N1> {
        Tile2 {
            data: self.data.map(|row| row.map(&f)),
        }
    }

    /// `f` applied to each pair of elements at the same position (`tile_map(f, a, b)`).
    #[inline(always)]
    pub fn map2<U: Copy, V>(
        &self,
        o: &Tile2<U, N0, N1>,
        f: impl Fn(T, U) -> V,
    ) -> Tile2<V, N0, N1> {
        Tile2 {
            data: std::array::from_fn(|i| {
                std::array::from_fn(|j| f(self.data[i][j], o.data[i][j]))
            }),
        }
    }
}

/// `map` and `map2` of the rank-3 and rank-4 tiles, over their row-major flattening (each
/// element is independent, so the order of the calls does not matter to the result).
macro_rules! nd_maps {
    ($tile:ident < $($n:ident),+ >) => {
        impl<T: Copy, $(const $n: usize),+> $tile<T, $($n),+> {
            /// `f` applied to each element (`tile_map(f, t)`).
            #[inline(always)]
            pub fn map<U>(&self, f: impl Fn(T) -> U) -> $tile<U, $($n),+> {
                let a = self.as_flat();
                <$tile<U, $($n),+>>::from_flat_fn(|k| f(a[k]))
            }

            /// `f` applied to each pair of elements at the same position (`tile_map(f, a, b)`).
            #[inline(always)]
            pub fn map2<U: Copy, V>(
                &self,
                o: &$tile<U, $($n),+>,
                f: impl Fn(T, U) -> V,
            ) -> $tile<V, $($n),+> {
                let (a, b) = (self.as_flat(), o.as_flat());
                <$tile<V, $($n),+>>::from_flat_fn(|k| f(a[k], b[k]))
            }
        }
    };
}

nd_maps!(Tile3<N0, N1, N2>);
nd_maps!(Tile4<N0, N1, N2, N3>);

/// `+ - *` (tile with tile, tile with scalar, scalar with tile) and `/` (float tiles) for one
/// tile type, given its const parameters.
macro_rules! tile_operators {
    ($tile:ident < $($n:ident),+ >) => {
        tile_operators!(@op $tile<$($n),+>, Add, add, s_add, Scalar);
        tile_operators!(@op $tile<$($n),+>, Sub, sub, s_sub, Scalar);
        tile_operators!(@op $tile<$($n),+>, Mul, mul, s_mul, Scalar);
        tile_operators!(@div $tile<$($n),+>);

        impl<T: Scalar, $(const $n: usize),+> Neg for $tile<T, $($n),+> {
            type Output = Self;
            /// `-t` elementwise (`tile_neg`): [`Scalar::s_neg`].
            #[inline(always)]
            fn neg(self) -> Self {
                self.map(Scalar::s_neg)
            }
        }

        impl<T: WrapInt, $(const $n: usize),+> $tile<T, $($n),+> {
            /// Integer `/` elementwise (`a / b`): wrapping on `MIN / -1`, and a division by
            /// zero in any element is a fault of `kernel` (the first in row-major order).
            pub fn div_int(&self, o: &Self, kernel: &'static str) -> KResult<Self> {
                let mut out = *self;
                for (d, &b) in
                    super::Tile::as_flat_mut(&mut out).iter_mut().zip(super::Tile::as_flat(o))
                {
                    *d = d.w_div(b, kernel)?;
                }
                Ok(out)
            }

            /// Integer `/` by a scalar elementwise (`a / s`); `s == 0` is a fault of `kernel`.
            pub fn div_int_scalar(&self, s: T, kernel: &'static str) -> KResult<Self> {
                let mut out = *self;
                for d in super::Tile::as_flat_mut(&mut out).iter_mut() {
                    *d = d.w_div(s, kernel)?;
                }
                Ok(out)
            }
        }
    };
    (@op $tile:ident < $($n:ident),+ >, $tr:ident, $m:ident, $f:ident, $bound:ident) => {
        impl<T: $bound, $(const $n: usize),+> $tr for $tile<T, $($n),+> {
            type Output = Self;
            #[inline(always)]
            fn $m(self, o: Self) -> Self {
                self.map2(&o, |a, b| a.$f(b))
            }
        }
        impl<T: $bound, $(const $n: usize),+> $tr<T> for $tile<T, $($n),+> {
            type Output = Self;
            #[inline(always)]
            fn $m(self, s: T) -> Self {
                self.map(|a| a.$f(s))
            }
        }
        tile_operators!(@left $tile [$($n),+], $tr, $m, $f;
            i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64);
    };
    (@left $tile:ident $ns:tt, $tr:ident, $m:ident, $f:ident; $($s:ty),+) => {$(
        tile_operators!(@left1 $tile $ns, $tr, $m, $f, $s);
    )+};
    (@left1 $tile:ident [$($n:ident),+], $tr:ident, $m:ident, $f:ident, $s:ty) => {
        impl<$(const $n: usize),+> $tr<$tile<$s, $($n),+>> for $s {
            type Output = $tile<$s, $($n),+>;
            #[inline(always)]
            fn $m(self, t: $tile<$s, $($n),+>) -> Self::Output {
                t.map(|a| self.$f(a))
            }
        }
    };
    (@div $tile:ident < $($n:ident),+ >) => {
        impl<T: Float + Div<Output = T>, $(const $n: usize),+> Div for $tile<T, $($n),+> {
            type Output = Self;
            #[inline(always)]
            fn div(self, o: Self) -> Self {
                self.map2(&o, |a, b| a / b)
            }
        }
        impl<T: Float + Div<Output = T>, $(const $n: usize),+> Div<T> for $tile<T, $($n),+> {
            type Output = Self;
            #[inline(always)]
            fn div(self, s: T) -> Self {
                self.map(|a| a / s)
            }
        }
        tile_operators!(@divleft $tile [$($n),+]; f32, f64);
    };
    (@divleft $tile:ident $ns:tt; $($s:ty),+) => {$(
        tile_operators!(@divleft1 $tile $ns, $s);
    )+};
    (@divleft1 $tile:ident [$($n:ident),+], $s:ty) => {
        impl<$(const $n: usize),+> Div<$tile<$s, $($n),+>> for $s {
            type Output = $tile<$s, $($n),+>;
            #[inline(always)]
            fn div(self, t: $tile<$s, $($n),+>) -> Self::Output {
                t.map(|a| self / a)
            }
        }
    };
}

tile_operators!(Tile1<N0>);
tile_operators!(Tile2<N0, N1>);
tile_operators!(Tile3<N0, N1, N2>);
tile_operators!(Tile4<N0, N1, N2, N3>);

/// Tiles of 2-vectors (`Vec2`, `DVec2`: the complex values of `tile_fft`): `+` and `-` between
/// tiles, `*` by the vector's scalar on either side. Each is glam's componentwise operator (one
/// IEEE operation per component, as CUDA's `operator+` of `wp::Vec2`).
macro_rules! vector_tile_operators {
    ($tile:ident < $($n:ident),+ >, $v:ty, $s:ty) => {
        impl<$(const $n: usize),+> Add for $tile<$v, $($n),+> {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                self.map2(&o, |a, b| a + b)
            }
        }
        impl<$(const $n: usize),+> Sub for $tile<$v, $($n),+> {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                self.map2(&o, |a, b| a - b)
            }
        }
        impl<$(const $n: usize),+> Mul<$s> for $tile<$v, $($n),+> {
            type Output = Self;
            #[inline(always)]
            fn mul(self, s: $s) -> Self {
                self.map(|a| a * s)
            }
        }
        impl<$(const $n: usize),+> Mul<$tile<$v, $($n),+>> for $s {
            type Output = $tile<$v, $($n),+>;
            #[inline(always)]
            fn mul(self, t: $tile<$v, $($n),+>) -> Self::Output {
                t.map(|a| self * a)
            }
        }
    };
}

vector_tile_operators!(Tile1<N0>, glam::Vec2, f32);
vector_tile_operators!(Tile1<N0>, glam::DVec2, f64);
vector_tile_operators!(Tile2<N0, N1>, glam::Vec2, f32);
vector_tile_operators!(Tile2<N0, N1>, glam::DVec2, f64);
vector_tile_operators!(Tile3<N0, N1, N2>, glam::Vec2, f32);
vector_tile_operators!(Tile3<N0, N1, N2>, glam::DVec2, f64);
vector_tile_operators!(Tile4<N0, N1, N2, N3>, glam::Vec2, f32);
vector_tile_operators!(Tile4<N0, N1, N2, N3>, glam::DVec2, f64);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fault::FaultKind;

    #[test]
    fn rank3_and_rank4_operators() {
        let a = Tile3::<f32, 2, 1, 3>::from_flat_fn(|k| k as f32);
        let b = Tile3::<f32, 2, 1, 3>::splat(2.0);
        assert_eq!((a + b).as_flat(), &[2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        assert_eq!((a * b - 1.0).as_flat(), &[-1.0, 1.0, 3.0, 5.0, 7.0, 9.0]);
        assert_eq!((1.0 / b).data[1][0][2], 0.5);
        assert_eq!((-a).data[1][0][1], -4.0);
        let q = Tile4::<i32, 1, 2, 1, 2>::from_flat_fn(|k| k as i32 - 1);
        assert_eq!((3 * q).as_flat(), &[-3, 0, 3, 6]);
        assert_eq!(q.map(|x| x as f64 * 0.5).as_flat(), &[-0.5, 0.0, 0.5, 1.0]);
        let d = q.div_int(&Tile4::splat(2), "k").unwrap();
        assert_eq!(d.as_flat(), &[0, 0, 0, 1]);
        assert!(q.div_int_scalar(0, "k").is_err());
    }

    #[test]
    fn operators_elementwise() {
        let a = Tile2::<f32, 2, 2> {
            data: [[1.0, 2.0], [3.0, 4.0]],
        };
        let b = Tile2::<f32, 2, 2>::ones();
        assert_eq!((a + b).data, [[2.0, 3.0], [4.0, 5.0]]);
        assert_eq!((a - b).data, [[0.0, 1.0], [2.0, 3.0]]);
        assert_eq!((a * a).data, [[1.0, 4.0], [9.0, 16.0]]);
        assert_eq!((a / (b + b)).data, [[0.5, 1.0], [1.5, 2.0]]);
        assert_eq!((a * 2.0).data, [[2.0, 4.0], [6.0, 8.0]]);
        assert_eq!((2.0 * a).data, (a * 2.0).data);
        assert_eq!((10.0 - a).data, [[9.0, 8.0], [7.0, 6.0]]);
        assert_eq!((a - 1.0).data, [[0.0, 1.0], [2.0, 3.0]]);
        assert_eq!((a / 2.0).data, [[0.5, 1.0], [1.5, 2.0]]);
        assert_eq!((4.0 / a).data, [[4.0, 2.0], [4.0 / 3.0, 1.0]]);
        let i = Tile1::<i32, 3> { data: [1, -2, 3] };
        assert_eq!((i + i * 3).data, [4, -8, 12]);
        assert_eq!((5 - i).data, [4, 7, 2]);
    }

    #[test]
    fn integer_ops_wrap_and_divide_checked() {
        let m = Tile1::<i32, 2> {
            data: [i32::MAX, i32::MIN],
        };
        assert_eq!((m + 1).data, [i32::MIN, i32::MIN + 1]);
        assert_eq!((m * 2).data, [-2, 0]);
        let d = Tile1::<i32, 2> { data: [7, -1] };
        assert_eq!(m.div_int(&d, "k").unwrap().data, [i32::MAX / 7, i32::MIN]);
        assert_eq!(
            m.div_int_scalar(2, "k").unwrap().data,
            [i32::MAX / 2, i32::MIN / 2]
        );
        let z = Tile1::<i32, 2> { data: [1, 0] };
        let e = m.div_int(&z, "k").unwrap_err();
        assert_eq!(e.kind, FaultKind::DivisionByZero);
        assert!(m.div_int_scalar(0, "k").is_err());
    }

    #[test]
    fn negation_flips_signs_and_wraps() {
        let f = Tile1::<f32, 4> {
            data: [0.0, -0.0, 1.5, f32::NAN],
        };
        let n = (-f).data.map(f32::to_bits);
        assert_eq!(n, f.data.map(|x| x.to_bits() ^ 0x8000_0000));
        let i = Tile2::<i32, 1, 3> {
            data: [[i32::MIN, 0, -7]],
        };
        assert_eq!((-i).data, [[i32::MIN, 0, 7]]);
        let u = Tile1::<u8, 2> { data: [1, 0] };
        assert_eq!((-u).data, [255, 0]);
    }

    #[test]
    fn vector_tiles() {
        use glam::{DVec2, Vec2};
        let a = Tile2::<Vec2, 1, 2> {
            data: [[Vec2::new(1.0, 2.0), Vec2::new(-3.0, 0.5)]],
        };
        let z = Tile2::<Vec2, 1, 2>::zeros();
        assert_eq!(z.data, [[Vec2::ZERO; 2]]);
        assert_eq!((a + a).data, (a * 2.0).data);
        assert_eq!((2.0 * a).data, (a * 2.0).data);
        assert_eq!((a - a).data, z.data);
        let d = Tile1::<DVec2, 2> {
            data: [DVec2::new(1.0, -1.0), DVec2::ZERO],
        };
        assert_eq!((d * 0.5).data, [DVec2::new(0.5, -0.5), DVec2::ZERO]);
        assert_eq!((d + d - d).data, d.data);
    }

    #[test]
    fn map_unary_and_binary() {
        let a = Tile1::<f32, 4>::arange(0.0, 1.0);
        assert_eq!(a.map(|x| x * x).data, [0.0, 1.0, 4.0, 9.0]);
        assert_eq!(a.map(|x| x as i32 + 1).data, [1, 2, 3, 4]);
        let b = Tile1::<i32, 4> { data: [1, 2, 3, 4] };
        assert_eq!(a.map2(&b, |x, y| x * y as f32).data, [0.0, 2.0, 6.0, 12.0]);
        let t = Tile2::<f64, 2, 3>::ones();
        let u = t.map2(&t.map(|x| x * 3.0), |x, y| x + y);
        assert_eq!(u.data, [[4.0; 3]; 2]);
    }
}

/// `tile_map` of a user func on tiles of every rank, over the row-major flattening (the order
/// the funcs run in, and fault, on every rank): `try_map_flat` (`f(e, x)` with the element's
/// index, for maps of three or more tiles, which read the others at `e`), `try_map`, `try_map2`.
macro_rules! try_maps {
    ($tile:ident, $($n:ident),+) => {
        impl<T: Copy, $(const $n: usize),+> $tile<T, $($n),+> {
            /// `f(e, x)` for each element `x` at row-major index `e`, in order, stopping at
            /// the first fault.
            #[inline(always)]
            pub fn try_map_flat<U: Copy + Default>(
                &self,
                f: impl Fn(usize, T) -> KResult<U>,
            ) -> KResult<$tile<U, $($n),+>> {
                let mut out = <$tile<U, $($n),+> as TileFromFn>::from_flat_fn(|_| U::default());
                for (e, (d, x)) in out.as_flat_mut().iter_mut().zip(self.as_flat()).enumerate() {
                    *d = f(e, *x)?;
                }
                Ok(out)
            }

            /// `f` applied to each element in row-major order, stopping at the first fault.
            #[inline(always)]
            pub fn try_map<U: Copy + Default>(
                &self,
                f: impl Fn(T) -> KResult<U>,
            ) -> KResult<$tile<U, $($n),+>> {
                self.try_map_flat(|_, x| f(x))
            }

            /// `f` applied to each pair of elements in row-major order, stopping at the first
            /// fault.
            #[inline(always)]
            pub fn try_map2<U: Copy, V: Copy + Default>(
                &self,
                o: &$tile<U, $($n),+>,
                f: impl Fn(T, U) -> KResult<V>,
            ) -> KResult<$tile<V, $($n),+>> {
                let o = o.as_flat();
                self.try_map_flat(|e, x| f(x, o[e]))
            }
        }
    };
}
try_maps!(Tile1, N0);
try_maps!(Tile2, N0, N1);
try_maps!(Tile3, N0, N1, N2);
try_maps!(Tile4, N0, N1, N2, N3);
