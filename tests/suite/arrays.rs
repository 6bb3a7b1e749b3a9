//! Arrays: 1- to 4-dimensional arrays and launches, `tid()` in every arity with row-major
//! order, index types, `len()` and `shape()`, element fields, views and strided arrays.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    tid_1d,
    tid_2d_row_major,
    tid_3d_row_major,
    tid_4d_row_major,
    read_nd_arrays,
    index_types,
    len_and_shape,
    vector_element_fields,
    matrix_element_columns,
    local_fields,
    views_and_strides,
    usize_builtins,
    every_element_type_round_trips,
);

#[wp::kernel]
fn k_tid_1d(out: Array<u64>) {
    // `wp::tid()` is `tid()`.
    let i = wp::tid();
    out[i] = i as u64 * 3 + 1;
}

fn tid_1d(dev: &wp::Device) {
    let out = zeros::<u64, 1>(37, dev);
    wp::launch(k_tid_1d, 37, (&out,), dev).unwrap();
    assert_eq!(
        host(&out),
        (0..37u64).map(|i| i * 3 + 1).collect::<Vec<_>>()
    );
}

/// Checks the launch order recorded by an atomic counter: every thread ran once and, on the
/// CPU (whose small launches run serially in flat order), in row-major order. On a GPU the
/// order is unspecified; only "each once" is checked there.
fn check_order(dev: &wp::Device, order: Vec<i32>) {
    let mut sorted = order.clone();
    sorted.sort_unstable();
    assert_eq!(
        sorted,
        (0..order.len() as i32).collect::<Vec<_>>(),
        "every thread runs exactly once"
    );
    if dev.is_cpu() {
        assert_eq!(
            order,
            (0..order.len() as i32).collect::<Vec<_>>(),
            "row-major: the last index varies fastest"
        );
    }
}

#[wp::kernel]
fn k_tid_2d(out: Array<i32, 2>, order: Array<i32, 2>, counter: Array<i32>) {
    let (i, j) = wp::tid();
    out[(i, j)] = (i * 1000 + j) as i32;
    order[(i, j)] = atomic_add(counter, 0, 1);
}

fn tid_2d_row_major(dev: &wp::Device) {
    let (rows, cols) = (3usize, 5usize);
    let out = zeros::<i32, 2>((rows, cols), dev);
    let order = zeros::<i32, 2>((rows, cols), dev);
    let counter = zeros::<i32, 1>(1, dev);
    wp::launch(k_tid_2d, (rows, cols), (&out, &order, &counter), dev).unwrap();
    let want: Vec<i32> = (0..rows)
        .flat_map(|i| (0..cols).map(move |j| (i * 1000 + j) as i32))
        .collect();
    assert_eq!(host(&out), want, "i runs over dim 0, j over dim 1");
    check_order(dev, host(&order));
}

#[wp::kernel]
fn k_tid_3d(out: Array<i32, 3>, order: Array<i32, 3>, counter: Array<i32>) {
    let (i, j, k) = tid();
    out[(i, j, k)] = (i * 100 + j * 10 + k) as i32;
    order[(i, j, k)] = atomic_add(counter, 0, 1);
}

fn tid_3d_row_major(dev: &wp::Device) {
    let dims = (2usize, 3usize, 4usize);
    let out = zeros::<i32, 3>(dims, dev);
    let order = zeros::<i32, 3>(dims, dev);
    let counter = zeros::<i32, 1>(1, dev);
    wp::launch(k_tid_3d, dims, (&out, &order, &counter), dev).unwrap();
    let mut want = Vec::new();
    for i in 0..dims.0 {
        for j in 0..dims.1 {
            for k in 0..dims.2 {
                want.push((i * 100 + j * 10 + k) as i32);
            }
        }
    }
    assert_eq!(host(&out), want);
    check_order(dev, host(&order));
}

#[wp::kernel]
fn k_tid_4d(out: Array<i32, 4>, order: Array<i32, 4>, counter: Array<i32>) {
    let (i, j, k, l) = tid();
    out[(i, j, k, l)] = (i * 1000 + j * 100 + k * 10 + l) as i32;
    order[(i, j, k, l)] = atomic_add(counter, 0, 1);
}

fn tid_4d_row_major(dev: &wp::Device) {
    let dims = (2usize, 3usize, 2usize, 3usize);
    let out = zeros::<i32, 4>(dims, dev);
    let order = zeros::<i32, 4>(dims, dev);
    let counter = zeros::<i32, 1>(1, dev);
    wp::launch(k_tid_4d, dims, (&out, &order, &counter), dev).unwrap();
    let mut want = Vec::new();
    for i in 0..dims.0 {
        for j in 0..dims.1 {
            for k in 0..dims.2 {
                for l in 0..dims.3 {
                    want.push((i * 1000 + j * 100 + k * 10 + l) as i32);
                }
            }
        }
    }
    assert_eq!(host(&out), want);
    check_order(dev, host(&order));
}

/// Reads arrays of 1 to 4 dimensions over a 1-D launch, summing along the last axes.
#[wp::kernel]
fn k_read_nd(
    a1: Array<f64>,
    a2: Array<f64, 2>,
    a3: Array<f64, 3>,
    a4: Array<f64, 4>,
    out: Array<f64, 2>,
) {
    let i = tid();
    out[(i, 0)] = a1[i];
    let mut s2: f64 = 0.0;
    for j in 0..a2.shape()[1] {
        s2 += a2[(i, j)];
    }
    out[(i, 1)] = s2;
    let mut s3: f64 = 0.0;
    for j in 0..a3.shape()[1] {
        for k in 0..a3.shape()[2] {
            s3 += a3[(i, j, k)];
        }
    }
    out[(i, 2)] = s3;
    let mut s4: f64 = 0.0;
    for j in 0..a4.shape()[1] {
        for k in 0..a4.shape()[2] {
            for l in 0..a4.shape()[3] {
                s4 += a4[(i, j, k, l)] * (l + 1) as f64;
            }
        }
    }
    out[(i, 3)] = s4;
}

fn read_nd_arrays(dev: &wp::Device) {
    let n = 3;
    let data = |len: usize| (0..len).map(|k| k as f64 * 0.5 - 2.0).collect::<Vec<f64>>();
    let a1 = arr(&data(n), dev);
    let d2 = data(n * 4);
    let d3 = data(n * 2 * 5);
    let d4 = data(n * 2 * 3 * 2);
    let a2 = wp::Array::from_slice_shape(&d2, (n, 4), dev).unwrap();
    let a3 = wp::Array::from_slice_shape(&d3, (n, 2, 5), dev).unwrap();
    let a4 = wp::Array::from_slice_shape(&d4, (n, 2, 3, 2), dev).unwrap();
    let out = zeros::<f64, 2>((n, 4), dev);
    wp::launch(k_read_nd, n, (&a1, &a2, &a3, &a4, &out), dev).unwrap();
    let mut want = Vec::new();
    for i in 0..n {
        want.push(host(&a1)[i]);
        let mut s2 = 0.0;
        for j in 0..4 {
            s2 += d2[i * 4 + j];
        }
        want.push(s2);
        let mut s3 = 0.0;
        for j in 0..2 {
            for k in 0..5 {
                s3 += d3[(i * 2 + j) * 5 + k];
            }
        }
        want.push(s3);
        let mut s4 = 0.0;
        for j in 0..2 {
            for k in 0..3 {
                for l in 0..2 {
                    s4 += d4[((i * 2 + j) * 3 + k) * 2 + l] * (l + 1) as f64;
                }
            }
        }
        want.push(s4);
    }
    // Halves and small integers: every partial sum is exact, fused or not.
    assert_eq!(host(&out), want);
}

/// Any integer type indexes an array, alone or mixed in a tuple.
#[wp::kernel]
fn k_index_types(a: Array<i32>, m: Array<i32, 2>, out: Array<i32, 2>) {
    let i = tid();
    let j = i as i32;
    let n = a.len() as i32;
    out[(i, 0)] = a[j];
    out[(j, 1)] = a[(n - 1 - j) as usize];
    let k = i as i64;
    let b = i as u8;
    out[(k, 2)] = a[b] + a[i as u16];
    out[(i, 3)] = m[(j, 1usize)];
    out[(b, 4)] = m[(i as u32, 0)];
}

fn index_types(dev: &wp::Device) {
    let a = [10, 20, 30, 40];
    let m: Vec<i32> = (0..8).map(|k| k * k).collect();
    let out = zeros::<i32, 2>((4, 5), dev);
    wp::launch(
        k_index_types,
        4,
        (
            &arr(&a, dev),
            &wp::Array::from_slice_shape(&m, (4, 2), dev).unwrap(),
            &out,
        ),
        dev,
    )
    .unwrap();
    let want: Vec<i32> = (0..4)
        .flat_map(|i| [a[i], a[3 - i], 2 * a[i], m[i * 2 + 1], m[i * 2]])
        .collect();
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_shape(a: Array<f32, 3>, b: Array<i32>, c: Array<Vec3, 2>, e: Array<f64, 2>, out: Array<u64>) {
    out[8] = e.len() as u64;
    out[9] = e.shape()[1] as u64;
    out[0] = a.len() as u64;
    out[1] = a.shape()[0] as u64;
    out[2] = a.shape()[1] as u64;
    out[3] = a.shape()[2] as u64;
    out[4] = b.len() as u64;
    out[5] = b.shape()[0] as u64;
    out[6] = c.shape()[1] as u64;
    out[7] = c.len() as u64;
}

fn len_and_shape(dev: &wp::Device) {
    let a = zeros::<f32, 3>((2, 3, 5), dev);
    let b = zeros::<i32, 1>(7, dev);
    let c = zeros::<Vec3, 2>((4, 6), dev);
    let e = zeros::<f64, 2>((0, 3), dev);
    let out = zeros::<u64, 1>(10, dev);
    wp::launch(k_shape, 1, (&a, &b, &c, &e, &out), dev).unwrap();
    assert_eq!(
        host(&out),
        vec![30, 2, 3, 5, 7, 7, 6, 24, 0, 3],
        "an empty array has length 0"
    );
}

/// Fields of array elements: read, assign, compound-assign.
#[wp::kernel]
fn k_vec_fields(v: Array<Vec3>, w: Array<DVec4>, out: Array<f32>) {
    let i = tid();
    out[i] = v[i].x + v[i].y * v[i].z;
    v[i].x = 5.0;
    v[i].y += 1.5;
    v[i].z *= -2.0;
    w[i].w -= 0.1;
    w[i].x = w[i].y;
}

fn vector_element_fields(dev: &wp::Device) {
    let v0 = [vec3(1.0, 2.0, 3.0), vec3(-0.5, 0.25, 8.0)];
    let w0 = [dvec4(1.0, 2.0, 3.0, 4.0), dvec4(0.1, 0.2, 0.3, 0.4)];
    let (v, w) = (arr(&v0, dev), arr(&w0, dev));
    let out = zeros::<f32, 1>(2, dev);
    wp::launch(k_vec_fields, 2, (&v, &w, &out), dev).unwrap();
    // y * z is exact for these values, so a fused multiply-add cannot change the sum.
    assert_eq!(
        host(&out),
        v0.iter().map(|p| p.x + p.y * p.z).collect::<Vec<_>>()
    );
    assert_eq!(
        host(&v),
        v0.iter()
            .map(|p| vec3(5.0, p.y + 1.5, p.z * -2.0))
            .collect::<Vec<_>>()
    );
    assert_eq!(
        host(&w),
        w0.iter()
            .map(|p| dvec4(p.y, p.y, p.z, p.w - 0.1))
            .collect::<Vec<_>>()
    );
}

#[wp::kernel]
fn k_mat_cols(m: Array<Mat3>, out: Array<Vec3>) {
    let i = tid();
    out[i] = m[i].z_axis;
    m[i].x_axis = Vec3::ONE;
    m[i].y_axis.z += 10.0;
    m[i].z_axis *= 2.0;
}

fn matrix_element_columns(dev: &wp::Device) {
    let m0 = [
        Mat3::from_cols_array(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]),
        Mat3::IDENTITY,
    ];
    let m = arr(&m0, dev);
    let out = zeros::<Vec3, 1>(2, dev);
    wp::launch(k_mat_cols, 2, (&m, &out), dev).unwrap();
    assert_eq!(host(&out), m0.iter().map(|m| m.z_axis).collect::<Vec<_>>());
    let want: Vec<Mat3> = m0
        .iter()
        .map(|m| {
            let mut m = *m;
            m.x_axis = Vec3::ONE;
            m.y_axis.z += 10.0;
            m.z_axis *= 2.0;
            m
        })
        .collect();
    assert_eq!(host(&m), want);
}

/// Fields of locals: `p.x += 1.0`, `p.y = ..`, and of a local matrix and quaternion.
#[wp::kernel]
fn k_local_fields(v: Array<Vec3>, out: Array<Vec3>, q: Array<Quat>) {
    let i = tid();
    let mut p = v[i];
    p.x += 1.0;
    p.y = p.x * 2.0;
    p.z -= p.y;
    out[i] = p;
    let mut m = Mat3::IDENTITY;
    m.z_axis.x = p.z;
    out[i] += m * Vec3::Z;
    let mut r = Quat::IDENTITY;
    r.w = 0.5;
    r.x += p.x;
    q[i] = r;
}

fn local_fields(dev: &wp::Device) {
    let v0 = [vec3(1.0, 2.0, 3.0), vec3(-4.0, 0.5, 0.25)];
    let (out, q) = (zeros::<Vec3, 1>(2, dev), zeros::<Quat, 1>(2, dev));
    wp::launch(k_local_fields, 2, (&arr(&v0, dev), &out, &q), dev).unwrap();
    let mut want = Vec::new();
    let mut want_q = Vec::new();
    for v in v0 {
        let mut p = v;
        p.x += 1.0;
        p.y = p.x * 2.0;
        p.z -= p.y;
        let mut m = Mat3::IDENTITY;
        m.z_axis.x = p.z;
        want.push(p + m * Vec3::Z);
        want_q.push(Quat::from_xyzw(p.x, 0.0, 0.0, 0.5));
    }
    // Small integers and halves: exact with or without FMA.
    assert_eq!(host(&out), want);
    assert_eq!(host(&q), want_q);
}

#[wp::kernel]
fn k_scale(a: Array<f32>, s: f32) {
    let i = tid();
    a[i] *= s;
}

#[wp::kernel]
fn k_copy_2d(src: Array<f32, 2>, dst: Array<f32, 2>) {
    let (i, j) = tid();
    dst[(i, j)] = src[(i, j)];
}

/// Views share memory with their parent; transposed (strided) arrays are indexed through
/// their strides.
fn views_and_strides(dev: &wp::Device) {
    let base: Vec<f32> = (0..10).map(|k| k as f32).collect();
    let a = arr(&base, dev);
    let mid = a.view(3..7).unwrap();
    wp::launch(k_scale, 4, (&mid, 10.0), dev).unwrap();
    let want: Vec<f32> = base
        .iter()
        .enumerate()
        .map(|(k, &x)| if (3..7).contains(&k) { x * 10.0 } else { x })
        .collect();
    assert_eq!(host(&a), want);

    let m: Vec<f32> = (0..6).map(|k| k as f32).collect();
    let src = wp::Array::from_slice_shape(&m, (2, 3), dev).unwrap();
    let t = src.transpose();
    let dst = zeros::<f32, 2>((3, 2), dev);
    wp::launch(k_copy_2d, (3, 2), (&t, &dst), dev).unwrap();
    let want: Vec<f32> = (0..3).flat_map(|i| [m[i], m[3 + i]]).collect();
    assert_eq!(host(&dst), want);

    let row = src.row(1).unwrap();
    wp::launch(k_scale, 3, (&row, -1.0), dev).unwrap();
    assert_eq!(host(&src), vec![0.0, 1.0, 2.0, -3.0, -4.0, -5.0]);
}

/// Builtins on `usize`, the type of `tid()`: a clamped window around each thread.
#[wp::kernel]
fn k_usize_window(a: Array<f32>, out: Array<f32>, radius: usize) {
    let i = tid();
    let lo = max(i, radius) - radius;
    let hi = min(i + radius + 1, a.len());
    let mut s = 0.0;
    for j in lo..hi {
        s += a[j];
    }
    out[i] = s;
}

fn usize_builtins(dev: &wp::Device) {
    let data: Vec<f32> = (0..10).map(|k| k as f32).collect();
    let a = crate::arr(&data, dev);
    let out = crate::zeros::<f32, 1>(10, dev);
    wp::launch(k_usize_window, 10, (&a, &out, 2), dev).expect("launch");
    let want: Vec<f32> = (0..10usize)
        .map(|i| data[i.saturating_sub(2)..(i + 3).min(10)].iter().sum())
        .collect();
    // Sums of small integers: exact in f32 on every backend.
    assert_eq!(crate::host(&out), want);
}

/// Arbitrary bit patterns of `len` elements of `T` (NaN payloads included for floats).
fn patterned<T: wp::Element>(len: usize, seed: u8) -> Vec<T> {
    let mut v = vec![<T as wp::__private::bytemuck::Zeroable>::zeroed(); len];
    let bytes: &mut [u8] = wp::__private::bytemuck::cast_slice_mut(&mut v);
    for (k, b) in bytes.iter_mut().enumerate() {
        *b = (k as u8).wrapping_mul(31).wrapping_add(seed);
    }
    v
}

fn same_bits<T: wp::Element>(a: &[T], b: &[T]) -> bool {
    let a: &[u8] = wp::__private::bytemuck::cast_slice(a);
    let b: &[u8] = wp::__private::bytemuck::cast_slice(b);
    a == b
}

/// from_vec, to_vec, fill, copy to and from the CPU, and strided copies, bit for bit.
fn round_trip<T: wp::Element>(dev: &wp::Device) {
    let cpu = wp::cpu();
    let data = patterned::<T>(37, 7);
    let a = wp::Array::from_vec(data.clone(), dev).unwrap();
    assert!(
        same_bits(&a.to_vec().unwrap(), &data),
        "{}: to_vec",
        T::TYPE_NAME
    );
    // Across devices, both ways.
    let c = wp::Array::<T>::zeros(37, &cpu).unwrap();
    wp::copy(&c, &a).unwrap();
    assert!(
        same_bits(&c.to_vec().unwrap(), &data),
        "{}: to cpu",
        T::TYPE_NAME
    );
    let back = wp::Array::<T>::zeros(37, dev).unwrap();
    wp::copy(&back, &c).unwrap();
    assert!(
        same_bits(&back.to_vec().unwrap(), &data),
        "{}: from cpu",
        T::TYPE_NAME
    );
    // A strided view (every other element of a 2-D array's transpose) into a contiguous one.
    let g = wp::Array::from_vec(patterned::<T>(6, 99), dev)
        .unwrap()
        .reshape::<2>([2, 3])
        .unwrap();
    let t = g.transpose();
    let dst = wp::Array::<T, 2>::zeros([3, 2], &cpu).unwrap();
    dst.copy_from(&t).unwrap();
    let gh = g.to_vec().unwrap();
    let want: Vec<T> = (0..3).flat_map(|i| [gh[i], gh[3 + i]]).collect();
    assert!(
        same_bits(&dst.to_vec().unwrap(), &want),
        "{}: strided",
        T::TYPE_NAME
    );
    // Fill.
    let one = patterned::<T>(1, 3)[0];
    a.fill(one).unwrap();
    assert!(
        same_bits(&a.to_vec().unwrap(), &[one; 37]),
        "{}: fill",
        T::TYPE_NAME
    );
}

#[derive(Clone, Copy, Debug, Default, wp::Struct)]
#[repr(C)]
struct Particle {
    pos: Vec3,
    id: u32,
}

fn every_element_type_round_trips(dev: &wp::Device) {
    macro_rules! all {
        ($($t:ty),*) => {$( round_trip::<$t>(dev); )*};
    }
    all!(i8, i16, i32, i64, u8, u16, u32, u64, f32, f64);
    all!(IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);
    all!(Vec2, Vec3, Vec4, DVec2, DVec3, DVec4, Mat2, Mat3, Mat4, DMat2, DMat3, DMat4);
    all!(Quat, DQuat, Particle);
}
