//! `wp::Volume` (Warp's sparse NanoVDB volume) on both backends, sampled from kernels against
//! host references: a trilinear field from a dense array (at and between voxels, across leaf
//! boundaries, outside the allocation), stores and lookups through tiles that straddle
//! lower- and upper-node boundaries at negative and large coordinates, vector and double
//! grids, gradients of samples (Warp's own check, and a gradcheck), value gradients into a
//! gradient grid, transforms with a non-symmetric map, index grids, files (round trips and a
//! file Warp wrote), bad input. On a GPU every sample is also compared bit for bit with the
//! CPU backend's.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::{VolumeMap, VoxelIndex};

backend_tests!(
    dense_samples_match_the_reference,
    tiles_store_and_lookup_across_nodes,
    vector_and_double_grids,
    sample_gradient_matches_warps_check,
    transforms_follow_the_map,
    index_grids_number_their_voxels,
    position_gradients_pass_gradcheck,
    value_gradients_reach_the_gradient_grid,
    files_round_trip_and_warp_files_load,
    a_file_warp_wrote_on_a_gpu_samples_the_same,
    bad_input_is_an_error,
);

// ------------------------------------------------------------------------------------------
// Kernels
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_sample(vol: Volume<f32>, uvw: Array<Vec3>, mode: i32, out: Array<f32>) {
    let i = tid();
    out[i] = volume_sample(vol, uvw[i], mode);
}

#[wp::kernel]
fn k_sample_v3(vol: Volume<Vec3>, uvw: Array<Vec3>, out: Array<Vec3>, grad: Array<Mat3>) {
    let i = tid();
    let (v, g) = volume_sample_grad(vol, uvw[i], VOLUME_LINEAR);
    out[i] = v;
    grad[i] = g;
}

#[wp::kernel]
fn k_sample_f64(vol: Volume<f64>, uvw: Array<Vec3>, out: Array<f64>) {
    let i = tid();
    out[i] = volume_sample(vol, uvw[i], VOLUME_LINEAR);
}

#[wp::kernel]
fn k_sample_grad(vol: Volume<f32>, uvw: Array<Vec3>, out: Array<f32>, grad: Array<Vec3>) {
    let i = tid();
    let (v, g) = volume_sample_grad(vol, uvw[i], VOLUME_LINEAR);
    out[i] = v;
    grad[i] = g;
}

/// Every voxel of each tile (`tid() = (tile, voxel)`) stores `i + 100 j + 10000 k`.
#[wp::kernel]
fn k_store_tiles(vol: Volume<f32>, tiles: Array<IVec3>) {
    let (t, v) = tid();
    let o = tiles[t];
    let i = o.x + (v / 64) as i32;
    let j = o.y + (v / 8 % 8) as i32;
    let k = o.z + (v % 8) as i32;
    volume_store(vol, i, j, k, (i + 100 * j + 10000 * k) as f32);
}

#[wp::kernel]
fn k_lookup(vol: Volume<f32>, ijk: Array<IVec3>, out: Array<f32>) {
    let i = tid();
    let c = ijk[i];
    out[i] = volume_lookup(vol, c.x, c.y, c.z);
}

#[wp::kernel]
fn k_store(vol: Volume<f32>, ijk: Array<IVec3>, value: f32) {
    let i = tid();
    let c = ijk[i];
    volume_store(vol, c.x, c.y, c.z, value);
}

#[wp::kernel]
fn k_transforms(
    vol: Volume<f32>,
    p: Array<Vec3>,
    w: Array<Vec3>,
    back: Array<Vec3>,
    d: Array<Vec3>,
) {
    let i = tid();
    w[i] = volume_index_to_world(vol, p[i]);
    back[i] = volume_world_to_index(vol, w[i]);
    d[i] = volume_world_to_index_dir(vol, volume_index_to_world_dir(vol, p[i]));
}

#[wp::kernel]
fn k_index(
    vol: Volume<VoxelIndex>,
    ijk: Array<IVec3>,
    data: Array<f32>,
    idx: Array<i32>,
    val: Array<f32>,
) {
    let i = tid();
    let c = ijk[i];
    idx[i] = volume_lookup_index(vol, c.x, c.y, c.z);
    let uvw = vec3(c.x as f32, c.y as f32, c.z as f32);
    val[i] = volume_sample_index(vol, uvw, VOLUME_CLOSEST, data, -1.0);
}

#[wp::kernel]
fn k_index_linear(vol: Volume<VoxelIndex>, uvw: Array<Vec3>, data: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = volume_sample_index(vol, uvw[i], VOLUME_LINEAR, data, 0.5);
}

#[wp::kernel]
fn k_weighted(vol: Volume<f32>, uvw: Array<Vec3>, w: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = volume_sample(vol, uvw[i], VOLUME_LINEAR) * w[i];
}

// ------------------------------------------------------------------------------------------
// Helpers
// ------------------------------------------------------------------------------------------

struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A trilinear function of the index (so trilinear interpolation reproduces it).
fn field(i: f64, j: f64, k: f64) -> f64 {
    0.5 + 0.25 * i - 0.5 * j + 0.125 * k + 0.01 * i * j * k
}

const DIMS: [usize; 3] = [19, 11, 10];
const BG: f32 = -3.0;

fn dense_volume(dev: &wp::Device) -> wp::Volume<f32> {
    let mut v = Vec::new();
    for i in 0..DIMS[0] {
        for j in 0..DIMS[1] {
            for k in 0..DIMS[2] {
                v.push(field(i as f64, j as f64, k as f64) as f32);
            }
        }
    }
    let map = VolumeMap::uniform(0.5, [1.0, 2.0, 3.0]);
    wp::Volume::from_dense(&v, DIMS, BG, &map, dev).unwrap()
}

/// The stored value at a voxel of `dense_volume`: the field inside the box, the background
/// elsewhere (the leaves past the box hold it too).
fn stored(c: [i64; 3]) -> f64 {
    let inside = (0..3).all(|a| c[a] >= 0 && c[a] < DIMS[a] as i64);
    if inside {
        field(c[0] as f64, c[1] as f64, c[2] as f64) as f32 as f64
    } else {
        BG as f64
    }
}

/// Warp's CLOSEST: each coordinate rounded half away from zero.
fn closest(p: Vec3) -> [i64; 3] {
    p.to_array().map(|x| x.round() as i64)
}

/// Warp's LINEAR in f64 over `stored`.
fn trilinear(p: Vec3) -> f64 {
    let b = p.to_array().map(|x| x.floor() as i64);
    let f = [0, 1, 2].map(|a| p[a] as f64 - b[a] as f64);
    let mut s = 0.0;
    for c in 0..8 {
        let o = [(c >> 2) & 1, (c >> 1) & 1, c & 1];
        let w: f64 = (0..3)
            .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
            .product();
        s += w * stored([b[0] + o[0], b[1] + o[1], b[2] + o[2]]);
    }
    s
}

/// Runs `f` on the CPU too and compares bit for bit (on a GPU; nothing on the CPU).
fn same_on_cpu<T: PartialEq + std::fmt::Debug>(
    dev: &wp::Device,
    got: &[T],
    f: impl Fn(&wp::Device) -> Vec<T>,
) {
    if dev.is_cpu() {
        return;
    }
    let cpu = f(&wp::cpu());
    let diff = got.iter().zip(&cpu).position(|(a, b)| a != b);
    assert!(
        diff.is_none(),
        "CPU and GPU differ at {diff:?}: {:?} vs {:?}",
        got.get(diff.unwrap_or(0)),
        cpu.get(diff.unwrap_or(0))
    );
}

// ------------------------------------------------------------------------------------------
// Tests
// ------------------------------------------------------------------------------------------

fn dense_samples_match_the_reference(dev: &wp::Device) {
    let run = |dev: &wp::Device| {
        let vol = dense_volume(dev);
        let mut r = Rng(0x1234_5678_9abc);
        let mut pts: Vec<Vec3> = (0..4000)
            .map(|_| {
                Vec3::new(
                    r.unit() * 24.0 - 2.0,
                    r.unit() * 16.0 - 2.0,
                    r.unit() * 14.0 - 2.0,
                )
            })
            .collect();
        // Exactly on voxels, on the leaf boundary x = 7.5, at the halves.
        pts.extend([
            Vec3::new(7.5, 3.0, 4.0),
            Vec3::new(8.0, 10.0, 9.0),
            Vec3::new(2.5, 0.5, -0.5),
            Vec3::new(-2.5, 1.0, 1.0),
            Vec3::new(18.0, 10.0, 9.0),
            Vec3::new(18.5, 10.5, 9.5),
        ]);
        let p = arr(&pts, dev);
        let lin = zeros::<f32, 1>(pts.len(), dev);
        let near = zeros::<f32, 1>(pts.len(), dev);
        wp::launch(k_sample, pts.len(), (&vol, &p, VOLUME_LINEAR, &lin), dev).unwrap();
        wp::launch(k_sample, pts.len(), (&vol, &p, VOLUME_CLOSEST, &near), dev).unwrap();
        (pts, host(&lin), host(&near))
    };
    let (pts, lin, near) = run(dev);
    for (k, p) in pts.iter().enumerate() {
        // CLOSEST returns a stored f32 exactly.
        assert_eq!(near[k] as f64, stored(closest(*p)), "closest at {p}");
        // LINEAR: eight f32 products of values up to ~6 summed: a few ulp of 8 (2e-6), far
        // below the 1e-2 differences a wrong corner or weight makes.
        let want = trilinear(*p);
        assert!(
            (lin[k] as f64 - want).abs() <= 2e-5,
            "linear at {p}: {} vs {want}",
            lin[k]
        );
    }
    same_on_cpu(
        dev,
        &lin.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        |d| run(d).1.iter().map(|x| x.to_bits()).collect(),
    );
}

fn tiles_store_and_lookup_across_nodes(dev: &wp::Device) {
    // Leaves on both sides of lower (128) and upper (4096) node boundaries, negative too.
    let tiles = [
        IVec3::new(-4104, -8, 0),
        IVec3::new(-4096, 0, -8),
        IVec3::new(4088, 120, -136),
        IVec3::new(4096, 128, -128),
        IVec3::new(0, 0, 0),
        IVec3::new(-8, -8, -8),
        IVec3::new(127, 127, 127),
    ];
    let map = VolumeMap::uniform(1.0, [0.0; 3]);
    let vol = wp::Volume::allocate_by_tiles(&tiles, 7.5f32, &map, dev).unwrap();
    // A voxel of a tile names its leaf: 127 is in the leaf at 120.
    let origins: Vec<IVec3> = tiles.iter().map(|t| *t & IVec3::splat(!7)).collect();
    let t = arr(&origins, dev);
    wp::launch(k_store_tiles, (origins.len(), 512), (&vol, &t), dev).unwrap();
    let mut ijk = Vec::new();
    for o in &origins {
        for v in 0..512 {
            ijk.push(*o + IVec3::new(v / 64, v / 8 % 8, v % 8));
        }
    }
    let outside = [
        IVec3::new(50, 50, 50),
        IVec3::new(i32::MAX, 0, 0),
        IVec3::new(i32::MIN, i32::MIN, i32::MIN),
        IVec3::new(-4105, -8, 0),
    ];
    ijk.extend(outside);
    let c = arr(&ijk, dev);
    let out = zeros::<f32, 1>(ijk.len(), dev);
    wp::launch(k_lookup, ijk.len(), (&vol, &c, &out), dev).unwrap();
    let got = host(&out);
    for (k, p) in ijk.iter().enumerate() {
        let want = if k < ijk.len() - outside.len() {
            (p.x + 100 * p.y + 10000 * p.z) as f32
        } else {
            7.5
        };
        assert_eq!(got[k], want, "lookup at {p}");
    }
    // A store outside the leaves is dropped (Warp's rule).
    let o = arr(&outside, dev);
    wp::launch(k_store, outside.len(), (&vol, &o, 1.0f32), dev).unwrap();
    let out = zeros::<f32, 1>(outside.len(), dev);
    wp::launch(k_lookup, outside.len(), (&vol, &o, &out), dev).unwrap();
    assert_eq!(host(&out), vec![7.5; outside.len()]);
    assert_eq!(vol.voxel_count(), 7 * 512);
}

fn vector_and_double_grids(dev: &wp::Device) {
    let n = [12usize, 9, 10];
    let (mut v3, mut v64) = (Vec::new(), Vec::new());
    for i in 0..n[0] {
        for j in 0..n[1] {
            for k in 0..n[2] {
                let (a, b, c) = (i as f32, j as f32, k as f32);
                v3.push(Vec3::new(
                    a + 2.0 * b + 3.0 * c,
                    4.0 * a + 5.0 * b + 6.0 * c,
                    7.0 * a + 8.0 * b + 9.0 * c,
                ));
                v64.push(field(i as f64, j as f64, k as f64));
            }
        }
    }
    let map = VolumeMap::uniform(1.0, [0.0; 3]);
    let vol3 = wp::Volume::from_dense(&v3, n, Vec3::ZERO, &map, dev).unwrap();
    let vol64 = wp::Volume::from_dense(&v64, n, 0.0f64, &map, dev).unwrap();
    let mut r = Rng(99);
    let pts: Vec<Vec3> = (0..500)
        .map(|_| {
            Vec3::new(
                r.unit() * 10.0 + 0.2,
                r.unit() * 7.0 + 0.2,
                r.unit() * 8.0 + 0.2,
            )
        })
        .collect();
    let p = arr(&pts, dev);
    let out = zeros::<Vec3, 1>(pts.len(), dev);
    let grad = zeros::<Mat3, 1>(pts.len(), dev);
    wp::launch(k_sample_v3, pts.len(), (&vol3, &p, &out, &grad), dev).unwrap();
    let out64 = zeros::<f64, 1>(pts.len(), dev);
    wp::launch(k_sample_f64, pts.len(), (&vol64, &p, &out64), dev).unwrap();
    let (o, g, o64) = (host(&out), host(&grad), host(&out64));
    let m = Mat3::from_cols_array_2d(&[[1.0, 4.0, 7.0], [2.0, 5.0, 8.0], [3.0, 6.0, 9.0]]);
    for (k, q) in pts.iter().enumerate() {
        // A linear field: exact up to f32 rounding of sums near 200 (1e-4).
        assert!(
            (o[k] - m * *q).abs().max_element() <= 1e-4,
            "vec3 at {q}: {}",
            o[k]
        );
        // Row c of the gradient is component c's: the matrix itself (column a = d/du_a).
        assert!(
            (g[k] - m).abs_diff_eq(Mat3::ZERO, 1e-4),
            "grad at {q}: {}",
            g[k]
        );
        // f64 values, but the weights come from the f32 position in f32 (Warp's rule): each
        // weight within 1e-7 relative, values below 10: 2e-6.
        let want = {
            let b = q.to_array().map(|x| x.floor() as f64);
            let f = [0, 1, 2].map(|a| q[a] as f64 - b[a]);
            let mut s = 0.0;
            for c in 0..8 {
                let o = [(c >> 2) & 1, (c >> 1) & 1, c & 1];
                let w: f64 = (0..3)
                    .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
                    .product();
                s += w * field(b[0] + o[0] as f64, b[1] + o[1] as f64, b[2] + o[2] as f64);
            }
            s
        };
        assert!(
            (o64[k] - want).abs() <= 2e-6,
            "f64 at {q}: {} vs {want}",
            o64[k]
        );
    }
}

fn sample_gradient_matches_warps_check(dev: &wp::Device) {
    // Warp's test: v = i j k, at (1.5, 2, 3) the value 9 and the gradient (6, 4.5, 3).
    let n = [8usize, 8, 8];
    let mut v = Vec::new();
    for i in 0..n[0] {
        for j in 0..n[1] {
            for k in 0..n[2] {
                v.push((i * j * k) as f32);
            }
        }
    }
    let vol =
        wp::Volume::from_dense(&v, n, 0.0f32, &VolumeMap::uniform(1.0, [0.0; 3]), dev).unwrap();
    let p = arr(&[Vec3::new(1.5, 2.0, 3.0)], dev);
    let (out, grad) = (zeros::<f32, 1>(1, dev), zeros::<Vec3, 1>(1, dev));
    wp::launch(k_sample_grad, 1, (&vol, &p, &out, &grad), dev).unwrap();
    assert_eq!(host(&out), vec![9.0]);
    assert_eq!(host(&grad), vec![Vec3::new(6.0, 4.5, 3.0)]);
}

fn transforms_follow_the_map(dev: &wp::Device) {
    let map = VolumeMap {
        mat: [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]],
        translation: [0.5, -1.0, 2.0],
    };
    let vol = wp::Volume::allocate_by_tiles(&[IVec3::ZERO], 0.0f32, &map, dev).unwrap();
    // NanoVDB's voxel size: the matrix's row sums.
    assert_eq!(vol.voxel_size().unwrap(), [3.0, 1.0, 3.0]);
    let pts = [Vec3::new(1.0, 2.0, 3.0), Vec3::new(-0.5, 0.25, 7.0)];
    let p = arr(&pts, dev);
    let (w, back, d) = (
        zeros::<Vec3, 1>(2, dev),
        zeros::<Vec3, 1>(2, dev),
        zeros::<Vec3, 1>(2, dev),
    );
    wp::launch(k_transforms, 2, (&vol, &p, &w, &back, &d), dev).unwrap();
    let (w, back, d) = (host(&w), host(&back), host(&d));
    for (k, q) in pts.iter().enumerate() {
        let want = Vec3::new(q.x + 2.0 * q.y + 0.5, q.y - 1.0, 3.0 * q.z + 2.0);
        // Small integers and halves: the f32 map is exact here.
        assert_eq!(w[k], want);
        // Through the stored f32 inverse: a few ulp.
        assert!(
            (back[k] - *q).abs().max_element() <= 1e-5,
            "{} vs {q}",
            back[k]
        );
        assert!((d[k] - *q).abs().max_element() <= 1e-5, "{} vs {q}", d[k]);
    }
}

fn index_grids_number_their_voxels(dev: &wp::Device) {
    let mut r = Rng(7);
    let mut voxels: Vec<IVec3> = (0..300)
        .map(|_| {
            IVec3::new(
                (r.unit() * 300.0) as i32 - 150,
                (r.unit() * 40.0) as i32 - 20,
                (r.unit() * 9000.0) as i32 - 4500,
            )
        })
        .collect();
    voxels.sort_by_key(|v| v.to_array());
    voxels.dedup();
    let map = VolumeMap::uniform(1.0, [0.0; 3]);
    let vol = wp::Volume::<VoxelIndex>::allocate_by_voxels(&voxels, &map, dev).unwrap();
    assert_eq!(vol.voxel_count(), voxels.len() as u64);
    let mut q = voxels.clone();
    // Neighbours that are not listed: -1, and the index read's background.
    let extra: Vec<IVec3> = voxels
        .iter()
        .map(|v| *v + IVec3::new(0, 0, 1))
        .filter(|v| {
            voxels
                .binary_search_by_key(&v.to_array(), |x| x.to_array())
                .is_err()
        })
        .collect();
    q.extend(&extra);
    let data: Vec<f32> = (0..voxels.len()).map(|k| 2.0 * k as f32).collect();
    let (c, d) = (arr(&q, dev), arr(&data, dev));
    let (idx, val) = (zeros::<i32, 1>(q.len(), dev), zeros::<f32, 1>(q.len(), dev));
    wp::launch(k_index, q.len(), (&vol, &c, &d, &idx, &val), dev).unwrap();
    let (idx, val) = (host(&idx), host(&val));
    let mut seen: Vec<i32> = idx[..voxels.len()].to_vec();
    seen.sort();
    assert_eq!(
        seen,
        (0..voxels.len() as i32).collect::<Vec<_>>(),
        "each voxel its own index"
    );
    for k in 0..voxels.len() {
        assert_eq!(val[k], data[idx[k] as usize]);
    }
    for k in voxels.len()..q.len() {
        assert_eq!((idx[k], val[k]), (-1, -1.0), "at {}", q[k]);
    }
    // Gradients into the data array through trilinear index reads, against central
    // differences: points between listed voxels and their neighbours.
    let pts: Vec<Vec3> = voxels
        .iter()
        .take(60)
        .map(|v| v.as_vec3() + Vec3::new(0.3, 0.6, 0.45))
        .collect();
    let p = arr(&pts, dev);
    let d = arr(&data, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(pts.len(), dev).with_grad().unwrap();
    let mut forward = || wp::launch(k_index_linear, pts.len(), (&vol, &p, &d, &out), dev);
    let report = wp::gradcheck(
        &mut forward,
        &[&d],
        &[&out],
        wp::GradcheckOptions::for_type::<f32>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
}

fn position_gradients_pass_gradcheck(dev: &wp::Device) {
    let vol = dense_volume(dev);
    // Points off the integer planes (LINEAR's gradient jumps across them).
    let mut r = Rng(5);
    let mut x = Vec::new();
    for _ in 0..40 {
        for a in [17.0, 9.0, 8.0] {
            x.push((r.unit() * (a - 1.0)).floor() + 0.2 + 0.6 * r.unit());
        }
    }
    let n = x.len() / 3;
    // gradcheck perturbs scalar arrays: the positions as a flat f32 array, viewed as Vec3s
    // by the kernel's launch.
    let x = arr(&x, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(n, dev).with_grad().unwrap();
    let mut forward = || {
        let p = x.reinterpret::<Vec3>()?;
        wp::launch(k_sample, n, (&vol, &p, VOLUME_LINEAR, &out), dev)
    };
    let report = wp::gradcheck(
        &mut forward,
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f32>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
}

fn value_gradients_reach_the_gradient_grid(dev: &wp::Device) {
    let vol = dense_volume(dev).with_grad().unwrap();
    // Two points inside the leaves; one in the lower node's unallocated part (its table
    // entry's value is read); one outside every node (the root background is read).
    let pts = [
        Vec3::new(1.25, 2.5, 3.75),
        Vec3::new(1.5, 2.25, 3.0),
        Vec3::new(30.0, 0.0, 0.0),
        Vec3::new(5000.5, 0.0, 0.0),
    ];
    let w = [2.0f32, -1.0, 5.0, 3.0];
    let (p, wa) = (arr(&pts, dev), arr(&w, dev));
    let out = zeros::<f32, 1>(pts.len(), dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_weighted, pts.len(), (&vol, &p, &wa, &out), dev).unwrap();
    }
    tape.backward(&out).unwrap();
    // d(sum w_i sample_i) / d(value at corner c) = sum over samples of w_i * weight_i(c).
    let mut want = std::collections::HashMap::<[i64; 3], f64>::new();
    for (q, wi) in pts.iter().zip(w).take(2) {
        let b = q.to_array().map(|x| x.floor() as i64);
        let f = [0, 1, 2].map(|a| q[a] as f64 - b[a] as f64);
        for c in 0..8 {
            let o = [(c >> 2) & 1, (c >> 1) & 1, c & 1];
            let wt: f64 = (0..3)
                .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
                .product();
            *want
                .entry([b[0] + o[0], b[1] + o[1], b[2] + o[2]])
                .or_default() += wi as f64 * wt;
        }
    }
    let g = vol.grad_volume().unwrap().expect("a gradient grid");
    let mut ijk: Vec<IVec3> = want
        .keys()
        .map(|c| IVec3::new(c[0] as i32, c[1] as i32, c[2] as i32))
        .collect();
    ijk.sort_by_key(|v| v.to_array());
    let c = arr(&ijk, dev);
    let out = zeros::<f32, 1>(ijk.len(), dev);
    wp::launch(k_lookup, ijk.len(), (&g, &c, &out), dev).unwrap();
    for (k, v) in host(&out).iter().enumerate() {
        let e = want[&[ijk[k].x as i64, ijk[k].y as i64, ijk[k].z as i64]];
        // f32 weights and atomic sums of two terms: 1e-6.
        assert!(
            (*v as f64 - e).abs() <= 1e-6,
            "grad at {}: {v} vs {e}",
            ijk[k]
        );
    }
    // The third point's eight corners share one lower-node table entry; the fourth's are
    // the root background: each gets its weight, whole.
    let bg = arr(&[IVec3::new(30, 0, 0), IVec3::new(9000, 9000, 9000)], dev);
    let out = zeros::<f32, 1>(2, dev);
    wp::launch(k_lookup, 2, (&g, &bg, &out), dev).unwrap();
    assert_eq!(host(&out), vec![5.0, 3.0]);
    vol.zero_grad().unwrap();
    let g = vol.grad_volume().unwrap().unwrap();
    let out = zeros::<f32, 1>(ijk.len(), dev);
    wp::launch(k_lookup, ijk.len(), (&g, &c, &out), dev).unwrap();
    assert!(host(&out).iter().all(|v| *v == 0.0));
}

fn files_round_trip_and_warp_files_load(dev: &wp::Device) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/warp_sphere_f32_zip.nvdb"
    );
    let vol = wp::Volume::<f32>::load(path, dev).unwrap();
    let grid = &wp::objects::nvdb::load_nvdb(path).unwrap()[0];
    let ijk: Vec<IVec3> = (0..400)
        .map(|k| IVec3::new(k % 23 - 2, k / 23 % 23 - 2, k % 7 * 3))
        .collect();
    let c = arr(&ijk, dev);
    let out = zeros::<f32, 1>(ijk.len(), dev);
    wp::launch(k_lookup, ijk.len(), (&vol, &c, &out), dev).unwrap();
    for (k, v) in host(&out).iter().enumerate() {
        assert_eq!(
            *v,
            grid.value_f32(ijk[k].to_array()).unwrap(),
            "at {}",
            ijk[k]
        );
    }
    let e = wp::Volume::<Vec3>::load(path, dev).unwrap_err().to_string();
    assert!(e.contains("Float") && e.contains("Vec3"), "{e}");
    let dir = std::env::temp_dir().join(format!(
        "warp_lang_volume_{}_{}",
        std::process::id(),
        dev.alias().replace(':', "_")
    ));
    std::fs::create_dir_all(&dir).unwrap();
    for codec in [
        wp::objects::nvdb::Codec::None,
        wp::objects::nvdb::Codec::Zip,
    ] {
        let f = dir.join(format!("{codec:?}.nvdb"));
        vol.save(&f, codec).unwrap();
        let again = wp::Volume::<f32>::load(&f, dev).unwrap();
        // The same grid but for the checksum save stores (bytes 8..16; Warp's has none).
        let (a, b) = (again.grid_bytes().unwrap(), vol.grid_bytes().unwrap());
        assert_eq!((&a[..8], &a[16..]), (&b[..8], &b[16..]), "{codec:?}");
        // Saved again: the same file, bit for bit.
        let f2 = dir.join(format!("{codec:?}-2.nvdb"));
        again.save(&f2, codec).unwrap();
        assert_eq!(
            std::fs::read(&f).unwrap(),
            std::fs::read(&f2).unwrap(),
            "{codec:?}"
        );
        // A flipped value byte: the checksum catches it.
        if codec == wp::objects::nvdb::Codec::None {
            let mut bytes = std::fs::read(&f).unwrap();
            let n = bytes.len();
            bytes[n - 100] ^= 1;
            std::fs::write(&f2, &bytes).unwrap();
            let e = wp::Volume::<f32>::load(&f2, dev).unwrap_err().to_string();
            assert!(e.contains("checksum"), "{e}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `tests/data/warp_gpu_sphere_zip.nvdb` and `warp_gpu_sphere_samples.txt`, written by NVIDIA
/// Warp 1.19 on an H100 (`benches/py/warp_volume.py` with `OUT` set, from the bench run of
/// `cargo bench --bench volume`): a sphere SDF (radius 0.6, voxel 1/8 from -1, background
/// 0.5) allocated by tiles and filled by a Warp kernel on the GPU, saved with ZIP; then
/// Warp's own `volume_sample_f(.., LINEAR)` at 500 index-space points, one `u v w value` per
/// line. Warp's GPU code contracts multiplies and adds into FMAs, ours does not: the samples
/// agree to a few f32 ulp of values below 1.5, so 1e-6.
fn a_file_warp_wrote_on_a_gpu_samples_the_same(dev: &wp::Device) {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/");
    let vol = wp::Volume::<f32>::load(format!("{dir}warp_gpu_sphere_zip.nvdb"), dev).unwrap();
    let text = std::fs::read_to_string(format!("{dir}warp_gpu_sphere_samples.txt")).unwrap();
    let rows: Vec<[f32; 4]> = text
        .lines()
        .map(|l| {
            let v: Vec<f32> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3]]
        })
        .collect();
    assert_eq!(rows.len(), 500);
    let pts: Vec<Vec3> = rows.iter().map(|r| Vec3::new(r[0], r[1], r[2])).collect();
    let p = arr(&pts, dev);
    let out = zeros::<f32, 1>(pts.len(), dev);
    wp::launch(k_sample, pts.len(), (&vol, &p, VOLUME_LINEAR, &out), dev).unwrap();
    for (k, v) in host(&out).iter().enumerate() {
        assert!(
            (v - rows[k][3]).abs() <= 1e-6,
            "at {}: {v} vs Warp's {}",
            pts[k],
            rows[k][3]
        );
    }
}

fn bad_input_is_an_error(dev: &wp::Device) {
    let vol = dense_volume(dev);
    for bad in [
        Vec3::new(f32::NAN, 1.0, 1.0),
        Vec3::new(1.0, f32::INFINITY, 1.0),
    ] {
        let p = arr(&[Vec3::ONE, bad], dev);
        let out = zeros::<f32, 1>(2, dev);
        let e = wp::launch(k_sample, 2, (&vol, &p, VOLUME_LINEAR, &out), dev)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("k_sample") && e.contains("volume sample position"),
            "{e}"
        );
    }
    // Huge finite positions read the background.
    let p = arr(
        &[Vec3::new(3e9, 0.0, 0.0), Vec3::new(-1e30, 1e30, 0.0)],
        dev,
    );
    let out = zeros::<f32, 1>(2, dev);
    wp::launch(k_sample, 2, (&vol, &p, VOLUME_LINEAR, &out), dev).unwrap();
    assert_eq!(host(&out), vec![BG, BG]);
    let map = VolumeMap::uniform(1.0, [0.0; 3]);
    let e = wp::Volume::from_dense(&[1.0f32; 5], [2, 2, 2], 0.0, &map, dev)
        .unwrap_err()
        .to_string();
    assert!(e.contains("5 values"), "{e}");
    let singular = VolumeMap {
        mat: [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
    };
    assert!(wp::Volume::allocate_by_tiles(&[IVec3::ZERO], 0.0f32, &singular, dev).is_err());
    assert!(wp::Volume::allocate_by_tiles(&[], 0.0f32, &map, dev).is_err());
    // Truncated and corrupted grids.
    let bytes = vol.grid_bytes().unwrap();
    assert!(wp::Volume::<f32>::from_grid_bytes(&bytes[..bytes.len() - 32], dev).is_err());
    let mut bad = bytes.clone();
    bad[636] = 99; // the grid type
    assert!(wp::Volume::<f32>::from_grid_bytes(&bad, dev).is_err());
    let e = wp::Volume::<f64>::from_grid_bytes(&bytes, dev)
        .unwrap_err()
        .to_string();
    assert!(e.contains("f64"), "{e}");
    let missing = wp::Volume::<f32>::load("/nonexistent/x.nvdb", dev)
        .unwrap_err()
        .to_string();
    assert!(missing.contains("/nonexistent/x.nvdb"), "{missing}");
    // A volume on another device than the launch's.
    if !dev.is_cpu() {
        let p = arr(&[Vec3::ONE], &wp::cpu());
        let out = zeros::<f32, 1>(1, &wp::cpu());
        assert!(wp::launch(k_sample, 1, (&vol, &p, VOLUME_LINEAR, &out), &wp::cpu()).is_err());
    }
}
