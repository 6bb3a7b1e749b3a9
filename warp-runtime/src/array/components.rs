//! The element types as array libraries see them: a scalar type and trailing axes (NumPy's
//! view of Warp's vector and matrix arrays), shared by the ndarray views, DLPack and ops (their
//! arrays' elements and value parameters).

use super::Element;

/// An element type as NumPy sees it in Warp: scalars of type `Scalar` on trailing axes of
/// shape `SHAPE` (none for a scalar, `[K]` for a vector or quaternion, `[rows, columns]`
/// for a matrix), at element strides `STRIDES` within one element.
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a numeric scalar, vector, quaternion or matrix type",
    note = "array interop (ndarray views, DLPack) and ops (their arrays' elements and value \
            parameters) take the numeric scalars and glam's vectors, quaternions and matrices of \
            them; for an op, wrap a kernel that takes structs, meshes or other objects in an \
            Op::computation and build those inside the body"
)]
pub trait NdComponents: Element {
    /// The scalar type of the components.
    type Scalar: Element;
    /// The extents of the trailing axes.
    const SHAPE: &'static [usize];
    /// The strides of the trailing axes, in scalars.
    const STRIDES: &'static [isize];
}

macro_rules! nd_scalars {
    ($($t:ty),*) => {$(
        impl NdComponents for $t {
            type Scalar = $t;
            const SHAPE: &'static [usize] = &[];
            const STRIDES: &'static [isize] = &[];
        }
    )*};
}
nd_scalars!(
    i8,
    i16,
    i32,
    i64,
    u8,
    u16,
    u32,
    u64,
    f32,
    f64,
    warp_core::f16,
    warp_core::bf16
);

macro_rules! nd_vectors {
    ($($t:ty => $s:ty, $k:literal);* $(;)?) => {$(
        impl NdComponents for $t {
            type Scalar = $s;
            const SHAPE: &'static [usize] = &[$k];
            const STRIDES: &'static [isize] = &[1];
        }
    )*};
}
nd_vectors!(
    glam::Vec2 => f32, 2; glam::Vec3 => f32, 3; glam::Vec4 => f32, 4;
    glam::DVec2 => f64, 2; glam::DVec3 => f64, 3; glam::DVec4 => f64, 4;
    glam::IVec2 => i32, 2; glam::IVec3 => i32, 3; glam::IVec4 => i32, 4;
    glam::UVec2 => u32, 2; glam::UVec3 => u32, 3; glam::UVec4 => u32, 4;
    glam::Quat => f32, 4; glam::DQuat => f64, 4;
);

// glam stores matrices by column: entry (row i, column j) is scalar j * K + i, so the
// trailing axes [i, j] have strides [1, K] (a row-major index, as Warp's NumPy view).
macro_rules! nd_matrices {
    ($($t:ty => $s:ty, $k:literal);* $(;)?) => {$(
        impl NdComponents for $t {
            type Scalar = $s;
            const SHAPE: &'static [usize] = &[$k, $k];
            const STRIDES: &'static [isize] = &[1, $k];
        }
    )*};
}
nd_matrices!(
    glam::Mat2 => f32, 2; glam::Mat3 => f32, 3; glam::Mat4 => f32, 4;
    glam::DMat2 => f64, 2; glam::DMat3 => f64, 3; glam::DMat4 => f64, 4;
);

// The layouts the ndarray views and DLPack share.
#[cfg(any(feature = "ndarray", feature = "dlpack"))]
impl<T: NdComponents, const N: usize> super::Array<T, N> {
    /// The number of scalars in one element.
    pub(crate) fn components_per_element() -> usize {
        std::mem::size_of::<T>() / std::mem::size_of::<T::Scalar>()
    }

    /// The shape and strides (in scalars) of the array's scalars: the array's own axes, then
    /// the element type's trailing component axes.
    pub(crate) fn component_shape_strides(&self) -> (Vec<usize>, Vec<isize>) {
        let k = Self::components_per_element() as isize;
        let shape = self.shape.iter().chain(T::SHAPE).copied().collect();
        let strides = self
            .strides
            .iter()
            .map(|s| s * k)
            .chain(T::STRIDES.iter().copied())
            .collect();
        (shape, strides)
    }
}
