//! The adjoint of `atomic_min`/`atomic_max`: the gradient at the updated element goes to the
//! value that won.

/// Element types of `atomic_min`/`atomic_max` whose adjoint routes the gradient to the value
/// that won (componentwise for vectors).
pub trait AtomicExtreme: Copy {
    /// `adj_v += grad` where `v` equals `cur` (the array's value after the launch), per
    /// component; nothing for integer types.
    fn adj_extreme(cur: Self, v: Self, adj_v: &mut Self, grad: Self);
}

macro_rules! extreme_float {
    ($($t:ty),*) => {$(
        impl AtomicExtreme for $t {
            #[inline(always)]
            fn adj_extreme(cur: Self, v: Self, adj_v: &mut Self, grad: Self) {
                if cur == v {
                    *adj_v += grad;
                }
            }
        }
    )*};
}
extreme_float!(f32, f64, half::f16, half::bf16);

macro_rules! extreme_vec {
    ($($t:ty => $n:expr),*) => {$(
        impl AtomicExtreme for $t {
            #[inline(always)]
            fn adj_extreme(cur: Self, v: Self, adj_v: &mut Self, grad: Self) {
                for k in 0..$n {
                    if cur[k] == v[k] {
                        adj_v[k] += grad[k];
                    }
                }
            }
        }
    )*};
}
extreme_vec!(glam::Vec2 => 2, glam::Vec3 => 3, glam::Vec4 => 4, glam::DVec2 => 2, glam::DVec3 => 3, glam::DVec4 => 4);

macro_rules! extreme_none {
    ($($t:ty),*) => {$(
        impl AtomicExtreme for $t {
            #[inline(always)]
            fn adj_extreme(_: Self, _: Self, _: &mut Self, _: Self) {}
        }
    )*};
}
extreme_none!(i32, u32, i64, u64);

/// The adjoint of `atomic_min(a, idx, v)` / `atomic_max(a, idx, v)`: the gradient at `idx`
/// goes to `v` if `v` is the value the array holds after the launch (every tied thread gets
/// it, as in NVIDIA Warp).
#[inline(always)]
pub fn adj_atomic_extreme<T: AtomicExtreme>(cur: T, v: T, adj_v: &mut T, grad: T) {
    T::adj_extreme(cur, v, adj_v, grad)
}
