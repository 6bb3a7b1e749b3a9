//! Geometric tests on triangles, rays and boxes, in f32: what the BVH and mesh queries are
//! built from ([`super::bvh`], [`super::mesh`]), and kernel helpers in their own right
//! (Warp's `closest_point_to_triangle`, `intersect_tri_tri`, its ray-triangle test).
//!
//! # Barycentric convention
//!
//! Warp's: a point of triangle `(a, b, c)` is `u * a + v * b + w * c` with `w = 1 - u - v`.
//! [`closest_point_triangle`] and [`intersect_ray_triangle`] return `u` and `v` (and `w`
//! where useful) in that convention, so mesh queries return the same numbers as Warp's.
//!
//! # Scale
//!
//! The predicates multiply coordinates together (up to the fourth power in the closest point
//! test), which in f32 overflows from about 1e10 and underflows below about 1e-10. Each test
//! therefore first translates its inputs to one of its points and multiplies them by a power
//! of two that brings the largest coordinate into `[1, 2)` ([`pow2_scale`]). Scaling by a
//! power of two is exact, and barycentrics, signs and intersection tests do not change under
//! a uniform scale, so the results are those of the unscaled problem, for coordinates from
//! about 1e-30 to 1e30 alike. (Only the translation rounds; that is the accuracy f32 has.)
//!
//! # NaN
//!
//! Every accepting comparison is written so that NaN fails it: a NaN input never makes a hit
//! or an overlap. Results computed from NaN inputs are otherwise unspecified (never a panic).

// `!(x > t)` is true when `x` is NaN: the negated comparisons below are how NaN takes the
// rejecting branch, on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::Vec3;

/// The sliver threshold: a triangle whose `|(b - a) x (c - a)|` is below this fraction of the
/// sum of its squared edge lengths (the sine of its smallest angle, up to a factor of about
/// 3) is treated as degenerate: a segment or a point (Warp skips such triangles in its mesh
/// queries with the same test; here they still count, through their edges).
pub const SLIVER_RATIO: f32 = 1e-6;

/// A power of two `s` such that `m * s` lies in `[1, 2)` (for a normal, finite, positive
/// `m`; clamped to `2^±126` for denormal `m`), or 1 when `m` is 0, infinite or NaN. Multiplying
/// by it is exact.
#[inline(always)]
pub fn pow2_scale(m: f32) -> f32 {
    if !(m > 0.0 && m <= f32::MAX) {
        return 1.0;
    }
    let e = ((m.to_bits() >> 23) & 0xff) as i32 - 127;
    let k = (-e).clamp(-126, 126);
    f32::from_bits(((k + 127) as u32) << 23)
}

/// The largest absolute component of some vectors.
#[inline(always)]
fn max_abs(vs: &[Vec3]) -> f32 {
    let mut m = 0.0f32;
    for v in vs {
        m = m.max(v.abs().max_element());
    }
    m
}

/// The part of a triangle `(a, b, c)` its closest point to a query lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[repr(i32)]
pub enum TriFeature {
    /// The interior of the face.
    #[default]
    Face = 0,
    /// Vertex `a` (`u = 1`).
    VertexA = 1,
    /// Vertex `b` (`v = 1`).
    VertexB = 2,
    /// Vertex `c` (`w = 1`).
    VertexC = 3,
    /// The open edge from `a` to `b` (`w = 0`).
    EdgeAB = 4,
    /// The open edge from `b` to `c` (`u = 0`).
    EdgeBC = 5,
    /// The open edge from `c` to `a` (`v = 0`).
    EdgeCA = 6,
}

/// The closest point of a triangle to a query point, as barycentrics `u * a + v * b + w * c`
/// (all in `[0, 1]`, `w = 1 - u - v` up to rounding), and the feature it lies on.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[repr(C)]
pub struct TriangleClosestPoint {
    /// The weight of `a`.
    pub u: f32,
    /// The weight of `b`.
    pub v: f32,
    /// The weight of `c`.
    pub w: f32,
    /// The feature (vertex, edge or face interior).
    pub feature: TriFeature,
}

impl TriangleClosestPoint {
    /// The point `u * a + v * b + w * c`.
    #[inline(always)]
    pub fn position(&self, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
        a * self.u + b * self.v + c * self.w
    }
}

/// Barycentrics for the point at parameter `t` along edge `feature` (an edge of the triangle;
/// `t = 0` at its first vertex). `t` of exactly 0 or 1 reports the vertex.
#[inline(always)]
fn on_edge(edge: TriFeature, t: f32) -> TriangleClosestPoint {
    let (u, v, w, f) = match edge {
        TriFeature::EdgeAB => (1.0 - t, t, 0.0, edge),
        TriFeature::EdgeBC => (0.0, 1.0 - t, t, edge),
        _ => (t, 0.0, 1.0 - t, TriFeature::EdgeCA),
    };
    let feature = if t <= 0.0 {
        match f {
            TriFeature::EdgeAB => TriFeature::VertexA,
            TriFeature::EdgeBC => TriFeature::VertexB,
            _ => TriFeature::VertexC,
        }
    } else if t >= 1.0 {
        match f {
            TriFeature::EdgeAB => TriFeature::VertexB,
            TriFeature::EdgeBC => TriFeature::VertexC,
            _ => TriFeature::VertexA,
        }
    } else {
        f
    };
    TriangleClosestPoint { u, v, w, feature }
}

/// The parameter in `[0, 1]` of the point of segment `s0 + t * d` closest to `q` (0 for a
/// zero-length segment or NaN).
#[inline(always)]
fn segment_param(s0: Vec3, d: Vec3, q: Vec3) -> f32 {
    let dd = d.dot(d);
    let t = (q - s0).dot(d) / dd;
    if dd > 0.0 && t > 0.0 {
        t.min(1.0)
    } else {
        0.0
    }
}

/// The closest point of triangle `(a, b, c)` to `p` (Ericson, *Real-Time Collision
/// Detection*, 5.1.5: Voronoi regions of the vertices, then the edges, then the face), with
/// its barycentrics in Warp's convention and the feature it lies on.
///
/// Robust where the textbook version is not: inputs are translated to `a` and scaled by a
/// power of two first (see the module docs: any magnitude from 1e-30 to 1e30), a degenerate
/// triangle (collinear or coincident vertices, or a sliver below [`SLIVER_RATIO`]) is treated
/// as its three edges (the closest of the three segments wins, ties to `ab`, `bc`, `ca` in
/// that order), and every quotient is clamped so that the barycentrics always describe a point
/// of the triangle (never NaN for finite inputs).
#[inline]
pub fn closest_point_triangle(a: Vec3, b: Vec3, c: Vec3, p: Vec3) -> TriangleClosestPoint {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let s = pow2_scale(max_abs(&[ab, ac, ap]));
    closest_point_triangle_scaled(ab * s, ac * s, ap * s)
}

/// [`closest_point_triangle`] on the triangle already translated to `a` and scaled by a power
/// of two `s` of the caller's choosing: `ab = (b - a) * s`, `ac = (c - a) * s`,
/// `ap = (p - a) * s`. Every quantity it compares or divides is a homogeneous polynomial of
/// those (degree 2 for the sliver test's two sides, 4 for the sub-areas), so the result is the
/// same, bit for bit, for every `s` under which no intermediate leaves the normal range; the
/// mesh's closest-point search passes its own unit here instead of computing a scale per
/// triangle (see `mesh::Closest::visit`).
#[inline(always)]
pub(crate) fn closest_point_triangle_scaled(ab: Vec3, ac: Vec3, ap: Vec3) -> TriangleClosestPoint {
    let bc = ac - ab;
    let n = ab.cross(ac);
    let edges = ab.length_squared() + ac.length_squared() + bc.length_squared();
    if !(n.length() > SLIVER_RATIO * edges) {
        return closest_point_segments(ab, ac, ap);
    }

    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return on_edge(TriFeature::EdgeAB, 0.0);
    }
    let bp = ap - ab;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return on_edge(TriFeature::EdgeAB, 1.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return on_edge(TriFeature::EdgeAB, ratio(d1, d1 - d3));
    }
    let cp = ap - ac;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return on_edge(TriFeature::EdgeBC, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        // On edge ca at 1 - t from c, where t runs from a to c.
        return on_edge(TriFeature::EdgeCA, 1.0 - ratio(d2, d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return on_edge(TriFeature::EdgeBC, ratio(d4 - d3, (d4 - d3) + (d5 - d6)));
    }
    // Inside the face: the weights are the (nonnegative, up to rounding) sub-areas.
    let (va, vb, vc) = (va.max(0.0), vb.max(0.0), vc.max(0.0));
    let sum = va + vb + vc;
    if !(sum > 0.0) {
        return closest_point_segments(ab, ac, ap);
    }
    let v = vb / sum;
    let w = vc / sum;
    TriangleClosestPoint {
        u: (1.0 - v - w).max(0.0),
        v,
        w,
        feature: TriFeature::Face,
    }
}

/// `num / den` clamped to `[0, 1]` (0 when the quotient is NaN).
#[inline(always)]
fn ratio(num: f32, den: f32) -> f32 {
    let t = num / den;
    if t > 0.0 {
        t.min(1.0)
    } else {
        0.0
    }
}

/// The closest point to `ap` of the three edges of the triangle `(0, ab, ac)` (translated to
/// `a`): the degenerate case of [`closest_point_triangle`].
#[inline(never)]
fn closest_point_segments(ab: Vec3, ac: Vec3, ap: Vec3) -> TriangleClosestPoint {
    let t_ab = segment_param(Vec3::ZERO, ab, ap);
    let t_bc = segment_param(ab, ac - ab, ap);
    let t_ca = segment_param(ac, -ac, ap);
    let d_ab = (ab * t_ab - ap).length_squared();
    let d_bc = (ab + (ac - ab) * t_bc - ap).length_squared();
    let d_ca = (ac - ac * t_ca - ap).length_squared();
    if !(d_bc < d_ab) && !(d_ca < d_ab) {
        on_edge(TriFeature::EdgeAB, t_ab)
    } else if !(d_ca < d_bc) {
        on_edge(TriFeature::EdgeBC, t_bc)
    } else {
        on_edge(TriFeature::EdgeCA, t_ca)
    }
}

/// The derivative of the closest point's barycentrics with respect to the query point, for
/// the feature the forward pass found: rows `du/dp`, `dv/dp`, `dw/dp` (zero at a vertex,
/// where the closest point does not move). Computed on the translated, scaled triangle and
/// scaled back (the barycentrics are a function of `s * (p - a)`).
fn closest_point_triangle_jacobian(
    a: Vec3,
    b: Vec3,
    c: Vec3,
    p: Vec3,
    feature: TriFeature,
) -> [Vec3; 3] {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let s = pow2_scale(max_abs(&[ab, ac, ap]));
    let (ab, ac) = (ab * s, ac * s);
    // d t / d p for t = (q - e0) . d / |d|^2, scaled back by s.
    let edge = |d: Vec3| {
        let dd = d.dot(d);
        if dd > 0.0 {
            d * (s / dd)
        } else {
            Vec3::ZERO
        }
    };
    match feature {
        TriFeature::VertexA | TriFeature::VertexB | TriFeature::VertexC => [Vec3::ZERO; 3],
        TriFeature::EdgeAB => {
            let dt = edge(ab);
            [-dt, dt, Vec3::ZERO]
        }
        TriFeature::EdgeBC => {
            let dt = edge(ac - ab);
            [Vec3::ZERO, -dt, dt]
        }
        TriFeature::EdgeCA => {
            // u = t, w = 1 - t for t running from c to a.
            let dt = edge(-ac);
            [dt, Vec3::ZERO, -dt]
        }
        TriFeature::Face => {
            // [v, w] = G^-1 [ab . ap, ac . ap], with G the Gram matrix of (ab, ac).
            let (g00, g01, g11) = (ab.dot(ab), ab.dot(ac), ac.dot(ac));
            let det = g00 * g11 - g01 * g01;
            if !(det > 0.0) {
                return [Vec3::ZERO; 3];
            }
            let k = s / det;
            let dv = (ab * g11 - ac * g01) * k;
            let dw = (ac * g00 - ab * g01) * k;
            [-(dv + dw), dv, dw]
        }
    }
}

/// Adjoint of [`closest_point_triangle`] with respect to the query point `p`: `adj_p +=
/// adj_ret.u * du/dp + adj_ret.v * dv/dp + adj_ret.w * dw/dp`, where the derivatives are those
/// of the feature the forward pass finds (zero at a vertex; along the edge on an edge; the
/// projection onto the plane inside the face). The vertex adjoints `adj_a`, `adj_b`, `adj_c`
/// are left unchanged (the gradient with respect to the triangle is not provided).
#[allow(clippy::too_many_arguments)]
pub fn adj_closest_point_triangle(
    a: Vec3,
    b: Vec3,
    c: Vec3,
    p: Vec3,
    _adj_a: &mut Vec3,
    _adj_b: &mut Vec3,
    _adj_c: &mut Vec3,
    adj_p: &mut Vec3,
    adj_ret: TriangleClosestPoint,
) {
    let f = closest_point_triangle(a, b, c, p).feature;
    let [du, dv, dw] = closest_point_triangle_jacobian(a, b, c, p, f);
    *adj_p += du * adj_ret.u + dv * adj_ret.v + dw * adj_ret.w;
}

/// The result of [`intersect_ray_triangle`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[repr(C)]
pub struct RayTriangleHit {
    /// Whether the ray hits the triangle at some `t >= 0`.
    pub result: bool,
    /// The hit's ray parameter: the point is `start + t * dir`.
    pub t: f32,
    /// The weight of `a` at the hit point (Warp's convention, see the module docs).
    pub u: f32,
    /// The weight of `b` at the hit point.
    pub v: f32,
    /// `1.0` when the ray hits the front face (the side `(b - a) x (c - a)` points to, so
    /// `dir . n < 0`), `-1.0` when it hits the back face.
    pub sign: f32,
}

/// Whether, where and from which side the ray `start + t * dir`, `t >= 0`, hits triangle
/// `(a, b, c)`.
///
/// Woop, Benthin and Wald's *watertight* test (JCGT 2013), the one Warp's `mesh_query_ray`
/// uses, rather than Möller–Trumbore: the triangle is sheared into the ray's frame and the
/// hit decided by the signs of three 2D edge functions, computed here from exact products
/// (f32 values multiplied in f64) so that their signs are exact. Two triangles sharing an
/// edge therefore evaluate that edge's function identically (up to its sign), and a ray
/// through the edge hits at least one of them: a closed mesh has no cracks, which the parity
/// and inside tests rely on. Möller–Trumbore computes each triangle's barycentrics with its
/// own roundings and lets rays slip between neighbours.
///
/// A ray parallel to the triangle's plane never hits it: the test rejects rays with
/// `|dir . n| <= 1e-6 |dir| |b - a| |c - a|` (the rounding noise of that product, so that
/// exactly parallel rays, whose sheared triangle is degenerate only up to rounding, never
/// produce a far-away spurious hit). A zero or non-finite `dir`, a degenerate triangle and
/// NaN anywhere never hit. Inputs are translated to `start` and scaled by a power of two
/// first (module docs), so the test works at any magnitude from 1e-30 to 1e30; `t` is scaled
/// back exactly.
#[inline]
pub fn intersect_ray_triangle(start: Vec3, dir: Vec3, a: Vec3, b: Vec3, c: Vec3) -> RayTriangleHit {
    let hit =
        RayFrame::new(dir).and_then(|fr| intersect_ray_triangle_in_frame(&fr, start, dir, a, b, c));
    match hit {
        Some(h) => RayTriangleHit {
            result: true,
            t: h.t,
            u: h.u(),
            v: h.v(),
            sign: h.sign,
        },
        None => RayTriangleHit::default(),
    }
}

/// The part of the watertight tests' shear that depends on the ray's direction only, made
/// once per ray by a search over many faces (two divisions per face saved): the direction's
/// dominant axis `kz`, which becomes z, with x and y following cyclically (`kx`, `ky`,
/// swapped when z points backwards to keep the winding), and the shear `sx = dir[kx] /
/// dir[kz]`, `sy = dir[ky] / dir[kz]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayFrame {
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
}

impl RayFrame {
    /// The frame of the ray along `dir`; `None` for a zero or non-finite direction (which
    /// hits and crosses nothing).
    #[inline(always)]
    pub(crate) fn new(dir: Vec3) -> Option<RayFrame> {
        let ad = dir.abs();
        let kz = if ad.x >= ad.y && ad.x >= ad.z {
            0
        } else if ad.y >= ad.z {
            1
        } else {
            2
        };
        let dz = dir[kz];
        if !(dz != 0.0 && dir.is_finite()) {
            return None;
        }
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if dz < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Some(RayFrame {
            kx,
            ky,
            kz,
            sx: dir[kx] / dz,
            sy: dir[ky] / dz,
        })
    }
}

/// A hit of [`intersect_ray_triangle`] before its barycentrics are divided out: a search for
/// the nearest hit compares `t` with its bound first and divides only for a nearer one.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayTriangleCandidate {
    /// The hit's ray parameter.
    pub(crate) t: f32,
    /// `1.0` for the front face, `-1.0` for the back face.
    pub(crate) sign: f32,
    uu: f64,
    vv: f64,
    det: f64,
}

impl RayTriangleCandidate {
    /// The weight of `a` at the hit.
    #[inline(always)]
    pub(crate) fn u(&self) -> f32 {
        (self.uu / self.det) as f32
    }
    /// The weight of `b` at the hit.
    #[inline(always)]
    pub(crate) fn v(&self) -> f32 {
        (self.vv / self.det) as f32
    }
}

/// [`intersect_ray_triangle`] in the frame `fr` of the ray along `dir`: the same hits, `t`
/// and sign, the barycentrics left to the caller.
#[inline(always)]
pub(crate) fn intersect_ray_triangle_in_frame(
    fr: &RayFrame,
    start: Vec3,
    dir: Vec3,
    a: Vec3,
    b: Vec3,
    c: Vec3,
) -> Option<RayTriangleCandidate> {
    let sh = shear_triangle(fr, start, a, b, c);
    // A hit is the conjunction of side-effect-free tests, so their order is free: the cheap
    // sign test of the edge functions (most faces fail it) comes before the parallel test's
    // cross product and square roots.
    let [uu, vv, ww] = sh.e;
    let inside = (uu >= 0.0 && vv >= 0.0 && ww >= 0.0) || (uu <= 0.0 && vv <= 0.0 && ww <= 0.0);
    let det = uu + vv + ww;
    if !(inside && det != 0.0) {
        return None;
    }
    // Parallel rays (and degenerate triangles) never hit.
    let [aa, bb, cc] = sh.q;
    let (ab, ac) = (bb - aa, cc - aa);
    let dn = dir.dot(ab.cross(ac));
    if !(dn.abs() > 1e-6 * dir.length() * ab.length() * ac.length()) {
        return None;
    }
    let t = (sh.depth(dir) / det) as f32 / sh.s;
    if !(t >= 0.0 && t.is_finite()) {
        return None;
    }
    Some(RayTriangleCandidate {
        t,
        sign: if dn < 0.0 { 1.0 } else { -1.0 },
        uu,
        vv,
        det,
    })
}

/// A triangle in a ray's frame, as the watertight tests see it: the frame's `kz`, the
/// vertices translated to the ray's start and scaled by the power of two `s` (`q`), their
/// sheared 2D positions (`xy`: the ray is the origin), and the three edge functions `e`
/// (`e[0]` of the edge `b c`, `e[1]` of `c a`, `e[2]` of `a b`; twice the signed areas of the
/// origin with each edge, exact in sign).
struct Sheared {
    kz: usize,
    s: f32,
    q: [Vec3; 3],
    xy: [(f32, f32); 3],
    e: [f64; 3],
}

impl Sheared {
    /// The hit's depth times `det = e[0] + e[1] + e[2]`, in units of `1 / s` (the depths
    /// of the vertices weighted by their edge functions), for the ray along `dir`.
    #[inline(always)]
    fn depth(&self, dir: Vec3) -> f64 {
        let [uu, vv, ww] = self.e;
        let sz = 1.0 / dir[self.kz];
        let z = self.q.map(|q| (sz * q[self.kz]) as f64);
        uu * z[0] + vv * z[1] + ww * z[2]
    }
}

/// The shear of [`intersect_ray_triangle`] and [`ray_crosses_triangle`] in the ray's frame.
#[inline(always)]
fn shear_triangle(fr: &RayFrame, start: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Sheared {
    let RayFrame { kx, ky, kz, sx, sy } = *fr;
    let (aa, bb, cc) = (a - start, b - start, c - start);
    let s = pow2_scale(max_abs(&[aa, bb, cc]));
    let q = [aa * s, bb * s, cc * s];

    let xy = q.map(|q| (q[kx] - sx * q[kz], q[ky] - sy * q[kz]));
    let [(ax, ay), (bx, by), (cx, cy)] = xy;
    // Edge functions: exact products, one rounding each, so exact signs.
    let det2 = |p: f32, q: f32, r: f32, t: f32| p as f64 * q as f64 - r as f64 * t as f64;
    let e = [
        det2(cx, by, cy, bx),
        det2(ax, cy, ay, cx),
        det2(bx, ay, by, ax),
    ];
    Sheared { kz, s, q, xy, e }
}

/// Whether the ray `start + t * dir`, `t >= 0`, crosses triangle `(a, b, c)`, counted so that
/// the number of faces of a closed mesh the ray crosses has the parity of the number of times
/// it passes through the surface: the test of `mesh_query_point_sign_parity`.
///
/// [`intersect_ray_triangle`]'s sheared edge functions (exact in sign), with two differences:
///
/// - **Ties are broken.** [`intersect_ray_triangle`] counts a point of an edge as inside, so a
///   ray through an edge hits both faces sharing it and one through a vertex every face
///   around it: watertight, but a parity counted with it would be wrong there. Here an edge
///   function that is exactly zero takes the sign it has once the ray's origin is moved by
///   `(ε, ε²)` in the sheared plane (Edelsbrunner and Mücke's simulation of simplicity): the
///   sign of its derivative along x, or along y when that is zero. That is a real
///   displacement, the same for every face, so the faces counted are exactly those a ray
///   infinitesimally beside it crosses, in general position: through an edge, one of the two
///   faces when the ray passes through the surface there and none or both when it grazes it;
///   through a vertex, likewise. A face whose sheared edge is a point (or whose projection
///   is degenerate) is never crossed, as in general position.
/// - **No parallel rejection.** A face nearly parallel to the ray is tested as its
///   neighbours are (dropping it would leave its neighbours' count unbalanced). Its depth is
///   a weighted mean of its vertices' with weights of one sign, so free of cancellation.
///
/// A crossing at `t = 0` (the start on the face) counts: the start is taken as a point just
/// behind it along `-dir`. NaN anywhere, a zero or non-finite `dir` never cross. Inputs are
/// translated and scaled as [`intersect_ray_triangle`]'s (consistent between faces sharing a
/// vertex unless the scaled coordinates underflow, below 1e-38 of the face's extent).
#[inline]
pub fn ray_crosses_triangle(start: Vec3, dir: Vec3, a: Vec3, b: Vec3, c: Vec3) -> bool {
    RayFrame::new(dir).is_some_and(|fr| ray_crosses_triangle_in_frame(&fr, start, dir, a, b, c))
}

/// [`ray_crosses_triangle`] in the frame `fr` of the ray along `dir`.
#[inline(always)]
pub(crate) fn ray_crosses_triangle_in_frame(
    fr: &RayFrame,
    start: Vec3,
    dir: Vec3,
    a: Vec3,
    b: Vec3,
    c: Vec3,
) -> bool {
    let sh = shear_triangle(fr, start, a, b, c);
    let [pa, pb, pc] = sh.xy;
    let [uu, vv, ww] = sh.e;
    let (su, sv, sw) = (
        tie_broken_side(uu, pc, pb),
        tie_broken_side(vv, pa, pc),
        tie_broken_side(ww, pb, pa),
    );
    if !(su != 0 && su == sv && sv == sw) {
        return false;
    }
    let det = uu + vv + ww;
    if det == 0.0 {
        return false;
    }
    let t = sh.depth(dir) / det;
    t >= 0.0 && t.is_finite()
}

/// The sign (`-1`, `0`, `1`) of the edge function `e = p.x * q.y - p.y * q.x` once the origin
/// moves by `(ε, ε²)`: its own when nonzero, else that of its derivative along x
/// (`p.y - q.y`), else along y (`q.x - p.x`); 0 for NaN or an edge that is a point.
#[inline(always)]
fn tie_broken_side(e: f64, p: (f32, f32), q: (f32, f32)) -> i32 {
    let sign = |x: f32| {
        if x > 0.0 {
            1
        } else if x < 0.0 {
            -1
        } else {
            0
        }
    };
    if e > 0.0 {
        1
    } else if e < 0.0 {
        -1
    } else if e == 0.0 {
        match sign(p.1 - q.1) {
            0 => sign(q.0 - p.0),
            s => s,
        }
    } else {
        0
    }
}

/// Whether boxes `[a_lower, a_upper]` and `[b_lower, b_upper]` overlap, touching included
/// (Warp's `intersect_aabb_aabb`). An inverted box (some `lower > upper`) or NaN overlaps
/// nothing.
#[inline(always)]
pub fn aabb_overlap(a_lower: Vec3, a_upper: Vec3, b_lower: Vec3, b_upper: Vec3) -> bool {
    a_lower.x <= b_upper.x
        && a_lower.y <= b_upper.y
        && a_lower.z <= b_upper.z
        && b_lower.x <= a_upper.x
        && b_lower.y <= a_upper.y
        && b_lower.z <= a_upper.z
        && a_lower.x <= a_upper.x
        && a_lower.y <= a_upper.y
        && a_lower.z <= a_upper.z
}

/// The ray `start + t * dir` against box `[lower, upper]` by the slab test, given
/// `inv_dir = 1 / dir` componentwise: `Some(t_enter)` when the ray meets the box at some
/// `t >= 0` (`t_enter` is where it enters the box, negative when `start` is inside), `None`
/// otherwise. Touching counts.
///
/// Robust where the plain slab test is not: a zero direction component (`inv_dir` infinite,
/// which `1 / ±0` gives) makes the ray parallel to that slab, tested as `lower <= start <=
/// upper` instead of computing `0 * inf`; an inverted box misses; and NaN anywhere (a NaN
/// box, a NaN ray) misses rather than slipping through a `min`/`max` that drops it.
#[inline(always)]
pub fn intersect_ray_aabb(start: Vec3, inv_dir: Vec3, lower: Vec3, upper: Vec3) -> Option<f32> {
    let mut t0 = f32::NEG_INFINITY;
    let mut t1 = f32::INFINITY;
    for k in 0..3 {
        let (o, inv, lo, hi) = (start[k], inv_dir[k], lower[k], upper[k]);
        if inv.is_infinite() {
            if !(lo <= o && o <= hi) {
                return None;
            }
        } else {
            let (ta, tb) = ((lo - o) * inv, (hi - o) * inv);
            // Choosing by the sign of the direction keeps an inverted box inverted (near >
            // far), which min/max would silently repair.
            let (near, far) = if inv >= 0.0 { (ta, tb) } else { (tb, ta) };
            if !(near <= far) {
                return None; // inverted box, or NaN
            }
            if near > t0 {
                t0 = near;
            }
            if far < t1 {
                t1 = far;
            }
        }
    }
    if t0 <= t1 && t1 >= 0.0 {
        Some(t0)
    } else {
        None
    }
}

/// [`intersect_ray_aabb`] for an `inv_dir` with no infinite component (a direction with no
/// zero component; NaN allowed), without a branch: per axis the same two products, the same
/// choice of near and far by the sign of `inv`, the same updates of `t0` and `t1`, with the
/// early `None` of an inverted slab folded into `ok`. While `ok` holds every step is the
/// branching version's; once it fails, that version returns `None` and so does this one: the
/// same result, bit for bit. (The GPU's slab test of a ray's walk, where branches diverge.)
#[inline(always)]
pub(crate) fn intersect_ray_aabb_finite(
    start: Vec3,
    inv_dir: Vec3,
    lower: Vec3,
    upper: Vec3,
) -> Option<f32> {
    let mut t0 = f32::NEG_INFINITY;
    let mut t1 = f32::INFINITY;
    let mut ok = true;
    for k in 0..3 {
        let (o, inv) = (start[k], inv_dir[k]);
        let (ta, tb) = ((lower[k] - o) * inv, (upper[k] - o) * inv);
        let pos = inv >= 0.0;
        let near = if pos { ta } else { tb };
        let far = if pos { tb } else { ta };
        ok = ok && near <= far;
        t0 = if near > t0 { near } else { t0 };
        t1 = if far < t1 { far } else { t1 };
    }
    (ok && t0 <= t1 && t1 >= 0.0).then_some(t0)
}

/// Whether [`intersect_ray_aabb_finite`] serves `inv_dir` (no component infinite).
#[inline(always)]
pub(crate) fn ray_inv_dir_finite(inv_dir: Vec3) -> bool {
    !(inv_dir.x.is_infinite() || inv_dir.y.is_infinite() || inv_dir.z.is_infinite())
}

/// The componentwise `1 / dir` that [`intersect_ray_aabb`] takes (`±inf` for zero
/// components, by IEEE division).
#[inline(always)]
pub fn ray_inv_dir(dir: Vec3) -> Vec3 {
    Vec3::ONE / dir
}

/// Squared distance from `p` to the box `[lower, upper]` (0 inside).
#[inline(always)]
pub fn aabb_distance_sq(p: Vec3, lower: Vec3, upper: Vec3) -> f32 {
    let d = p.clamp_nan_safe(lower, upper) - p;
    d.length_squared()
}

/// Squared distance from `p` to the box `[lower, upper]` in units of `1 / s`, for a power of
/// two `s`: `|(clamp(p, lower, upper) - p) * s|^2` (0 inside). The offset is taken unscaled
/// and scaled once (three products where `aabb_distance_sq(p * s, lower * s, upper * s)` takes
/// nine), and the two are the same bits whenever none of those nine products under- or
/// overflows: clamping only selects, a power-of-two product is exact in the normal range, and
/// a difference is rounded alike before or after such a product. Where one does (a point
/// far from the origin beside a box of tiny extent, whose `p * s` overflows), this one is the
/// right one. The mesh's closest-point search keys its boxes and triangles with it.
#[inline(always)]
pub fn aabb_distance_sq_scaled(p: Vec3, lower: Vec3, upper: Vec3, s: f32) -> f32 {
    ((p.clamp_nan_safe(lower, upper) - p) * s).length_squared()
}

trait ClampNanSafe {
    fn clamp_nan_safe(self, lo: Self, hi: Self) -> Self;
}

impl ClampNanSafe for Vec3 {
    /// `max(lo, min(hi, self))` by comparisons, without glam's debug assertion that
    /// `lo <= hi` (the empty tree's inverted box has `lo > hi`).
    #[inline(always)]
    fn clamp_nan_safe(self, lo: Vec3, hi: Vec3) -> Vec3 {
        let c = |x: f32, l: f32, h: f32| {
            let y = if x > h { h } else { x };
            if y < l {
                l
            } else {
                y
            }
        };
        Vec3::new(
            c(self.x, lo.x, hi.x),
            c(self.y, lo.y, hi.y),
            c(self.z, lo.z, hi.z),
        )
    }
}

/// Whether triangles `(v0, v1, v2)` and `(u0, u1, u2)` intersect, touching included
/// (Warp's `intersect_tri_tri`).
///
/// Möller's interval-overlap test (*A Fast Triangle-Triangle Intersection Test*, 1997),
/// written from the paper: each triangle's vertices are classified against the other's plane
/// (all on one side: no intersection); otherwise both triangles cut the line where the planes
/// meet in an interval, and they intersect when the intervals overlap. Coplanar triangles
/// (every signed distance within the tolerance below) are projected onto the axis plane the
/// normal is most aligned with and tested in 2D: an edge of one crossing an edge of the other,
/// or one containing a vertex of the other.
///
/// Robustness: both triangles are translated to `v0` and scaled by a power of two first
/// (module docs); a signed distance below `1e-6 |n|` (about a millionth of the scaled extent)
/// counts as zero, so touching and nearly coplanar triangles are decided consistently. A
/// degenerate triangle (a sliver below [`SLIVER_RATIO`], a segment or a point) is tested as
/// its three edges against the other triangle; two degenerate triangles as segments against
/// segments. NaN anywhere gives `false`.
pub fn intersect_tri_tri(v0: Vec3, v1: Vec3, v2: Vec3, u0: Vec3, u1: Vec3, u2: Vec3) -> bool {
    let o = v0;
    let (a, b) = ([v0 - o, v1 - o, v2 - o], [u0 - o, u1 - o, u2 - o]);
    let s = pow2_scale(max_abs(&[a[0], a[1], a[2], b[0], b[1], b[2]]));
    let a = a.map(|x| x * s);
    let b = b.map(|x| x * s);
    if !a.iter().chain(b.iter()).all(|x| x.is_finite()) {
        return false;
    }
    match (degenerate(&a), degenerate(&b)) {
        (false, false) => tri_tri(&a, &b),
        (true, false) => edges(&a).iter().any(|e| segment_triangle(e[0], e[1], &b)),
        (false, true) => edges(&b).iter().any(|e| segment_triangle(e[0], e[1], &a)),
        (true, true) => edges(&a).iter().any(|e| {
            edges(&b)
                .iter()
                .any(|f| segments_touch(e[0], e[1], f[0], f[1]))
        }),
    }
}

/// The distance tolerance of [`intersect_tri_tri`], relative to `|n|` in scaled units.
pub(crate) const TRI_TRI_EPS: f32 = 1e-6;

fn degenerate(t: &[Vec3; 3]) -> bool {
    let (e0, e1, e2) = (t[1] - t[0], t[2] - t[0], t[2] - t[1]);
    let sum = e0.length_squared() + e1.length_squared() + e2.length_squared();
    !(e0.cross(e1).length() > SLIVER_RATIO * sum)
}

fn edges(t: &[Vec3; 3]) -> [[Vec3; 2]; 3] {
    [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]]
}

/// Signed distances (times `|n|`) of `pts` from the plane of `t`, snapped to 0 within the
/// tolerance; and the plane normal.
fn plane_distances(t: &[Vec3; 3], pts: &[Vec3; 3]) -> ([f32; 3], Vec3) {
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    let eps = TRI_TRI_EPS * n.length();
    let d = pts.map(|p| {
        let x = n.dot(p - t[0]);
        if x.abs() <= eps {
            0.0
        } else {
            x
        }
    });
    (d, n)
}

fn same_side(d: &[f32; 3]) -> bool {
    (d[0] > 0.0 && d[1] > 0.0 && d[2] > 0.0) || (d[0] < 0.0 && d[1] < 0.0 && d[2] < 0.0)
}

/// Möller's test for two non-degenerate triangles (translated and scaled).
fn tri_tri(a: &[Vec3; 3], b: &[Vec3; 3]) -> bool {
    let (da, nb) = plane_distances(b, a);
    if same_side(&da) {
        return false;
    }
    let (db, na) = plane_distances(a, b);
    if same_side(&db) {
        return false;
    }
    if da == [0.0; 3] || db == [0.0; 3] {
        return coplanar_tri_tri(na, a, b);
    }
    // The line of the planes' intersection, projected onto its dominant axis (the interval
    // order along the line is preserved).
    let dir = na.cross(nb).abs();
    let k = if dir.x >= dir.y && dir.x >= dir.z {
        0
    } else if dir.y >= dir.z {
        1
    } else {
        2
    };
    let (Some(ia), Some(ib)) = (interval(a.map(|p| p[k]), da), interval(b.map(|p| p[k]), db))
    else {
        return coplanar_tri_tri(na, a, b);
    };
    ia.0 <= ib.1 && ib.0 <= ia.1
}

/// The interval the triangle with projections `p` and signed distances `d` (not all of one
/// sign) covers on the planes' line: between the points where its two edges from the vertex
/// alone on its side cross the plane. `None` when every distance is zero.
fn interval(p: [f32; 3], d: [f32; 3]) -> Option<(f32, f32)> {
    let lone = if d[0] * d[1] > 0.0 {
        2
    } else if d[0] * d[2] > 0.0 {
        1
    } else if d[1] * d[2] > 0.0 || d[0] != 0.0 {
        0
    } else if d[1] != 0.0 {
        1
    } else if d[2] != 0.0 {
        2
    } else {
        return None;
    };
    let (i, j) = ((lone + 1) % 3, (lone + 2) % 3);
    // d[lone] != 0 and the others are zero or of the other sign: the denominators are nonzero.
    let cut = |o: usize| p[lone] + (p[o] - p[lone]) * (d[lone] / (d[lone] - d[o]));
    let (t0, t1) = (cut(i), cut(j));
    Some(if t0 <= t1 { (t0, t1) } else { (t1, t0) })
}

/// The two axes of the plane a normal is least aligned with (drop its dominant axis).
fn projection_axes(n: Vec3) -> (usize, usize) {
    let m = n.abs();
    if m.x >= m.y && m.x >= m.z {
        (1, 2)
    } else if m.y >= m.z {
        (0, 2)
    } else {
        (0, 1)
    }
}

/// Twice the signed area of the 2D triangle `(p, q, r)`.
fn orient2(p: (f32, f32), q: (f32, f32), r: (f32, f32)) -> f32 {
    (q.0 - p.0) * (r.1 - p.1) - (q.1 - p.1) * (r.0 - p.0)
}

/// Whether 2D segments `pq` and `rs` intersect, touching and collinear overlap included.
fn segments_2d(p: (f32, f32), q: (f32, f32), r: (f32, f32), s: (f32, f32)) -> bool {
    let (o1, o2) = (orient2(p, q, r), orient2(p, q, s));
    let (o3, o4) = (orient2(r, s, p), orient2(r, s, q));
    let between = |a: (f32, f32), b: (f32, f32), c: (f32, f32)| {
        c.0 >= a.0.min(b.0) && c.0 <= a.0.max(b.0) && c.1 >= a.1.min(b.1) && c.1 <= a.1.max(b.1)
    };
    if ((o1 > 0.0 && o2 < 0.0) || (o1 < 0.0 && o2 > 0.0))
        && ((o3 > 0.0 && o4 < 0.0) || (o3 < 0.0 && o4 > 0.0))
    {
        return true;
    }
    (o1 == 0.0 && between(p, q, r))
        || (o2 == 0.0 && between(p, q, s))
        || (o3 == 0.0 && between(r, s, p))
        || (o4 == 0.0 && between(r, s, q))
}

/// Whether 2D point `x` lies in triangle `t` (boundary included), either winding.
fn in_triangle_2d(x: (f32, f32), t: [(f32, f32); 3]) -> bool {
    let (o0, o1, o2) = (
        orient2(t[0], t[1], x),
        orient2(t[1], t[2], x),
        orient2(t[2], t[0], x),
    );
    (o0 >= 0.0 && o1 >= 0.0 && o2 >= 0.0) || (o0 <= 0.0 && o1 <= 0.0 && o2 <= 0.0)
}

/// Coplanar triangles, tested in the axis plane their normal `n` is most aligned with.
fn coplanar_tri_tri(n: Vec3, a: &[Vec3; 3], b: &[Vec3; 3]) -> bool {
    let (i, j) = projection_axes(n);
    let pa = a.map(|p| (p[i], p[j]));
    let pb = b.map(|p| (p[i], p[j]));
    for e in 0..3 {
        for f in 0..3 {
            if segments_2d(pa[e], pa[(e + 1) % 3], pb[f], pb[(f + 1) % 3]) {
                return true;
            }
        }
    }
    in_triangle_2d(pa[0], pb) || in_triangle_2d(pb[0], pa)
}

/// Whether segment `pq` meets the non-degenerate triangle `t` (all translated and scaled).
fn segment_triangle(p: Vec3, q: Vec3, t: &[Vec3; 3]) -> bool {
    let (d, n) = plane_distances(t, &[p, q, p]);
    let (dp, dq) = (d[0], d[1]);
    if (dp > 0.0 && dq > 0.0) || (dp < 0.0 && dq < 0.0) {
        return false;
    }
    let (i, j) = projection_axes(n);
    let proj = |x: Vec3| (x[i], x[j]);
    let pt = t.map(proj);
    if dp == 0.0 && dq == 0.0 {
        // In the plane: a 2D segment against a 2D triangle.
        let (a, b) = (proj(p), proj(q));
        return in_triangle_2d(a, pt) || (0..3).any(|e| segments_2d(a, b, pt[e], pt[(e + 1) % 3]));
    }
    // The crossing point (dp and dq of opposite signs or one zero: dp - dq != 0).
    let x = p + (q - p) * (dp / (dp - dq));
    in_triangle_2d(proj(x), pt)
}

/// Whether two 3D segments come within the tri-tri tolerance of each other (for two
/// degenerate triangles).
fn segments_touch(p0: Vec3, p1: Vec3, q0: Vec3, q1: Vec3) -> bool {
    // Closest points of two segments (Ericson 5.1.9), clamped; then their distance.
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.dot(d1), d2.dot(d2), d2.dot(r));
    let (s, t) = if a <= 0.0 && e <= 0.0 {
        (0.0, 0.0)
    } else if a <= 0.0 {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(r);
        if e <= 0.0 {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(d2);
            let den = a * e - b * b;
            let mut s = if den > 0.0 {
                ((b * f - c * e) / den).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    let gap = (p0 + d1 * s) - (q0 + d2 * t);
    gap.length() <= TRI_TRI_EPS * 4.0
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// xorshift64*, seeded: deterministic test inputs with no dependency.
    pub(crate) struct Rng(pub u64);

    impl Rng {
        pub fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }
        /// Uniform in `[lo, hi)`.
        pub fn f(&mut self, lo: f32, hi: f32) -> f32 {
            let u = (self.next() >> 40) as f32 / (1u64 << 24) as f32;
            lo + (hi - lo) * u
        }
        pub fn v(&mut self, lo: f32, hi: f32) -> Vec3 {
            Vec3::new(self.f(lo, hi), self.f(lo, hi), self.f(lo, hi))
        }
        pub fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }
    }

    /// Brute-force closest point of a triangle: the best of a fine barycentric grid, then of
    /// the edges sampled finely (a reference, in f64, for distances only).
    fn brute_closest_dist(a: Vec3, b: Vec3, c: Vec3, p: Vec3) -> f64 {
        let (a, b, c, p) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3(), p.as_dvec3());
        let seg = |s0: glam::DVec3, s1: glam::DVec3| {
            let d = s1 - s0;
            let dd = d.dot(d);
            let t = if dd > 0.0 {
                ((p - s0).dot(d) / dd).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (s0 + d * t - p).length()
        };
        let mut best = seg(a, b).min(seg(b, c)).min(seg(c, a));
        // The plane projection, if inside.
        let n = (b - a).cross(c - a);
        let nn = n.dot(n);
        if nn > 0.0 {
            let q = p - n * ((p - a).dot(n) / nn);
            let inside = |x: glam::DVec3, y: glam::DVec3| (y - x).cross(q - x).dot(n) >= 0.0;
            if inside(a, b) && inside(b, c) && inside(c, a) {
                best = best.min((q - p).length());
            }
        }
        best
    }

    fn check_closest(a: Vec3, b: Vec3, c: Vec3, p: Vec3, rel: f64) {
        let r = closest_point_triangle(a, b, c, p);
        for x in [r.u, r.v, r.w] {
            assert!((0.0..=1.0).contains(&x), "{r:?} for {a} {b} {c} {p}");
        }
        assert!(((r.u + r.v + r.w) - 1.0).abs() <= 1e-6, "{r:?}");
        let got = (r.position(a, b, c).as_dvec3() - p.as_dvec3()).length();
        let want = brute_closest_dist(a, b, c, p);
        let scale = (a.abs().max(b.abs()).max(c.abs()).max(p.abs()))
            .max_element()
            .max(f32::MIN_POSITIVE) as f64;
        assert!(
            (got - want).abs() <= rel * scale,
            "distance {got} vs {want} ({r:?}) for {a} {b} {c} {p}"
        );
    }

    /// Tolerance: the closest point's distance against an f64 reference, within `4e-6`
    /// of the largest coordinate: a handful of f32 roundings (2^-24 = 6e-8 each) of the
    /// translated inputs, the products and the final interpolation, with margin.
    #[test]
    fn closest_point_matches_brute_force() {
        let mut rng = Rng(0x1234_5678);
        for _ in 0..20000 {
            let (a, b, c) = (rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0));
            let p = rng.v(-2.0, 2.0);
            check_closest(a, b, c, p, 4e-6);
        }
    }

    #[test]
    fn closest_point_features_and_convention() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let r = closest_point_triangle(a, b, c, Vec3::new(0.25, 0.25, 1.0));
        assert_eq!(r.feature, TriFeature::Face);
        // Warp's convention: position = u a + v b + w c.
        assert!((r.position(a, b, c) - Vec3::new(0.25, 0.25, 0.0)).length() < 1e-6);
        assert!((r.v - 0.25).abs() < 1e-6 && (r.w - 0.25).abs() < 1e-6);
        let cases = [
            (
                Vec3::new(-1.0, -1.0, 0.0),
                TriFeature::VertexA,
                [1.0, 0.0, 0.0],
            ),
            (
                Vec3::new(2.0, -0.5, 0.3),
                TriFeature::VertexB,
                [0.0, 1.0, 0.0],
            ),
            (
                Vec3::new(-0.5, 3.0, 0.0),
                TriFeature::VertexC,
                [0.0, 0.0, 1.0],
            ),
            (
                Vec3::new(0.5, -1.0, 0.0),
                TriFeature::EdgeAB,
                [0.5, 0.5, 0.0],
            ),
            (
                Vec3::new(1.0, 1.0, 0.0),
                TriFeature::EdgeBC,
                [0.0, 0.5, 0.5],
            ),
            (
                Vec3::new(-1.0, 0.25, 0.0),
                TriFeature::EdgeCA,
                [0.75, 0.0, 0.25],
            ),
            // Exactly on a vertex and on an edge.
            (Vec3::X, TriFeature::VertexB, [0.0, 1.0, 0.0]),
            (
                Vec3::new(0.5, 0.0, 0.0),
                TriFeature::EdgeAB,
                [0.5, 0.5, 0.0],
            ),
            (
                Vec3::new(0.5, 0.5, 0.0),
                TriFeature::EdgeBC,
                [0.0, 0.5, 0.5],
            ),
        ];
        for (p, f, uvw) in cases {
            let r = closest_point_triangle(a, b, c, p);
            assert_eq!(r.feature, f, "{p}");
            for (x, y) in [r.u, r.v, r.w].into_iter().zip(uvw) {
                assert!((x - y).abs() < 1e-6, "{p}: {r:?}");
            }
        }
    }

    #[test]
    fn closest_point_degenerate_and_extreme() {
        let mut rng = Rng(99);
        for _ in 0..2000 {
            let a = rng.v(-1.0, 1.0);
            let d = rng.v(-1.0, 1.0);
            let p = rng.v(-2.0, 2.0);
            // Collinear, a repeated vertex, all coincident, a sliver.
            check_closest(a, a + d, a + d * rng.f(-2.0, 2.0), p, 4e-6);
            check_closest(a, a, a + d, p, 4e-6);
            check_closest(a, a, a, p, 4e-6);
            check_closest(
                a,
                a + d,
                a + d * 0.5 + d.any_orthogonal_vector() * 1e-7,
                p,
                4e-6,
            );
        }
        // All coincident: the vertex.
        let r = closest_point_triangle(Vec3::ONE, Vec3::ONE, Vec3::ONE, Vec3::ZERO);
        assert_eq!(
            (r.u, r.v, r.w, r.feature),
            (1.0, 0.0, 0.0, TriFeature::VertexA)
        );
        // Huge and tiny: the same barycentrics as at unit scale (exact power-of-two scales).
        for (k, s) in [(1e30f32, 0), (1e-30, 1), (1e20, 2)] {
            let _ = s;
            let mut rng = Rng(7);
            for _ in 0..500 {
                let (a, b, c, p) = (
                    rng.v(-1.0, 1.0),
                    rng.v(-1.0, 1.0),
                    rng.v(-1.0, 1.0),
                    rng.v(-2.0, 2.0),
                );
                check_closest(a * k, b * k, c * k, p * k, 4e-6);
            }
        }
        // NaN: no panic, anything back.
        let _ = closest_point_triangle(Vec3::NAN, Vec3::ONE, Vec3::ZERO, Vec3::X);
    }

    /// Gradcheck of [`adj_closest_point_triangle`] against central differences of the f32
    /// forward. The barycentrics are affine in `p` within a feature's region, so the
    /// difference has no truncation error as long as `p ± h` stays in the region (points too
    /// near a region boundary are skipped); its rounding error is about
    /// `2 * 2^-24 * |uvw| / (2h) ≈ 6e-6` for `h = 0.01` and a unit-size triangle. Tolerance
    /// `1e-4 * max(1, |derivative|)`: far above that, far below any formula error.
    #[test]
    fn closest_point_gradcheck() {
        let mut rng = Rng(4242);
        let mut checked = [0usize; 7];
        for _ in 0..4000 {
            let (a, b, c) = (rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0));
            let p = rng.v(-1.5, 1.5);
            let g = TriangleClosestPoint {
                u: rng.f(-1.0, 1.0),
                v: rng.f(-1.0, 1.0),
                w: rng.f(-1.0, 1.0),
                feature: TriFeature::Face,
            };
            let f0 = closest_point_triangle(a, b, c, p).feature;
            let h = 0.01;
            let mut ok = true;
            let mut num = Vec3::ZERO;
            for k in 0..3 {
                let mut e = Vec3::ZERO;
                e[k] = h;
                let (rp, rm) = (
                    closest_point_triangle(a, b, c, p + e),
                    closest_point_triangle(a, b, c, p - e),
                );
                ok &= rp.feature == f0 && rm.feature == f0;
                let l = |r: TriangleClosestPoint| g.u * r.u + g.v * r.v + g.w * r.w;
                num[k] = (l(rp) - l(rm)) / (2.0 * h);
            }
            // Also skip near-degenerate triangles (the Jacobian is ill-conditioned there).
            if !ok || a.distance(b).min(b.distance(c)).min(c.distance(a)) < 0.2 {
                continue;
            }
            let n = (b - a).cross(c - a).length();
            if n < 0.1 {
                continue;
            }
            let mut ana = Vec3::ZERO;
            let (mut x, mut y, mut z) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
            adj_closest_point_triangle(a, b, c, p, &mut x, &mut y, &mut z, &mut ana, g);
            for k in 0..3 {
                assert!(
                    (num[k] - ana[k]).abs() <= 1e-4 * ana[k].abs().max(1.0),
                    "{f0:?}: numeric {num} vs adjoint {ana}"
                );
            }
            checked[f0 as usize] += 1;
        }
        assert!(
            checked.iter().all(|n| *n > 20),
            "features covered: {checked:?}"
        );
    }

    fn brute_ray_tri(o: Vec3, d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<(f64, f64, f64)> {
        // Cramer's rule in f64: o + t d = a + v (b - a) + w (c - a).
        let (o, d, a, b, c) = (
            o.as_dvec3(),
            d.as_dvec3(),
            a.as_dvec3(),
            b.as_dvec3(),
            c.as_dvec3(),
        );
        let (e1, e2) = (b - a, c - a);
        let m = glam::DMat3::from_cols(-d, e1, e2);
        let det = m.determinant();
        if det.abs() < 1e-12 {
            return None;
        }
        let x = m.inverse() * (o - a);
        let (t, v, w) = (x.x, x.y, x.z);
        (t >= 0.0 && v >= 0.0 && w >= 0.0 && v + w <= 1.0).then_some((t, 1.0 - v - w, v))
    }

    /// Against f64 Cramer: hits and misses agree except within 1e-4 of an edge (where
    /// either answer is right for f32 inputs), and t, u, v agree within 1e-4 (relative to
    /// the scene's unit scale: a few f32 roundings through conditioning of about 100 for
    /// the random triangles kept).
    #[test]
    fn ray_triangle_matches_brute_force() {
        let mut rng = Rng(31337);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..20000 {
            let (a, b, c) = (rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0));
            let o = rng.v(-3.0, 3.0);
            // Half the rays aimed near the triangle, so that both answers are common.
            let d = if rng.below(2) == 0 {
                rng.v(-1.0, 1.0)
            } else {
                let (x, y) = (rng.f(-0.2, 1.0), rng.f(-0.2, 1.0));
                (a + (b - a) * x + (c - a) * (y * (1.0 - x))) - o
            };
            let n = (b - a).cross(c - a);
            // Skip thin triangles and grazing rays (badly conditioned in f32).
            if n.length() < 0.05
                || d.length() < 0.1
                || d.normalize().dot(n.normalize()).abs() < 0.05
            {
                continue;
            }
            let got = intersect_ray_triangle(o, d, a, b, c);
            let want = brute_ray_tri(o, d, a, b, c);
            match want {
                Some((t, u, v)) => {
                    let w = 1.0 - u - v;
                    let margin = u.min(v).min(w);
                    if margin > 1e-4 {
                        assert!(got.result, "missed {o} {d} {a} {b} {c}");
                        assert!((got.t as f64 - t).abs() <= 1e-4 * t.max(1.0));
                        assert!(
                            (got.u as f64 - u).abs() <= 1e-4 && (got.v as f64 - v).abs() <= 1e-4
                        );
                        let n = (b - a).cross(c - a);
                        assert_eq!(got.sign, if d.dot(n) < 0.0 { 1.0 } else { -1.0 });
                        hits += 1;
                    }
                }
                None => {
                    // Miss by Cramer: a hit is only allowed on the boundary.
                    if got.result {
                        let w = 1.0 - got.u - got.v;
                        assert!(got.u.min(got.v).min(w) < 1e-4 || got.t < 1e-4);
                    } else {
                        misses += 1;
                    }
                }
            }
        }
        assert!(hits > 1000 && misses > 1000, "{hits} {misses}");
    }

    #[test]
    fn ray_triangle_edge_cases() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        // Front and back.
        let h = intersect_ray_triangle(Vec3::new(0.2, 0.3, 1.0), -Vec3::Z, a, b, c);
        assert!(h.result && h.sign == 1.0 && (h.t - 1.0).abs() < 1e-6);
        assert!(
            (h.u - 0.5).abs() < 1e-6 && (h.v - 0.2).abs() < 1e-6,
            "{h:?}"
        );
        let h = intersect_ray_triangle(Vec3::new(0.2, 0.3, -1.0), Vec3::Z, a, b, c);
        assert!(h.result && h.sign == -1.0);
        // Behind the start: no hit.
        assert!(!intersect_ray_triangle(Vec3::new(0.2, 0.3, -1.0), -Vec3::Z, a, b, c).result);
        // Parallel: in the plane, and above it, crossing the triangle's footprint.
        for o in [
            Vec3::new(-1.0, 0.2, 0.0),
            Vec3::new(-1.0, 0.2, 1e-3),
            Vec3::new(-1.0, 0.2, -1e-30),
        ] {
            for d in [Vec3::X, Vec3::new(1.0, 0.1, 0.0), Vec3::new(3.0, 0.0, 0.0)] {
                assert!(!intersect_ray_triangle(o, d, a, b, c).result, "{o} {d}");
            }
        }
        // Zero and NaN directions, NaN vertices.
        assert!(!intersect_ray_triangle(Vec3::Z, Vec3::ZERO, a, b, c).result);
        assert!(!intersect_ray_triangle(Vec3::Z, Vec3::NAN, a, b, c).result);
        assert!(!intersect_ray_triangle(Vec3::Z, -Vec3::Z, Vec3::NAN, b, c).result);
        // Degenerate triangle.
        assert!(!intersect_ray_triangle(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, a, b, b * 2.0).result);
        // Through a shared edge and a shared vertex of a fan: watertight, at least one hit.
        let fan = [Vec3::X, Vec3::Y, -Vec3::X, -Vec3::Y];
        for o in [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.5, 0.5, 1.0),
            Vec3::new(0.25, 0.0, 1.0),
        ] {
            let n = (0..4)
                .filter(|i| {
                    intersect_ray_triangle(o, -Vec3::Z, Vec3::ZERO, fan[*i], fan[(i + 1) % 4])
                        .result
                })
                .count();
            assert!(n >= 1, "{o}: {n}");
        }
        // Huge and tiny scenes: the same hit scaled.
        for k in [1e30f32, 1e-30] {
            let h =
                intersect_ray_triangle(Vec3::new(0.2, 0.3, 1.0) * k, -Vec3::Z, a * k, b * k, c * k);
            assert!(
                h.result && (h.t / k - 1.0).abs() < 1e-6 && (h.u - 0.5).abs() < 1e-6,
                "{k}: {h:?}"
            );
        }
    }

    /// A shared edge of random quads split in two: every ray through the quad hits at least
    /// one half (no crack), including rays aimed exactly at points of the diagonal.
    #[test]
    fn ray_triangle_is_watertight() {
        let mut rng = Rng(5);
        for _ in 0..20000 {
            let (p0, p1, p2, p3) = (
                rng.v(-1.0, 1.0),
                rng.v(-1.0, 1.0),
                rng.v(-1.0, 1.0),
                rng.v(-1.0, 1.0),
            );
            let o = rng.v(-3.0, 3.0) + Vec3::Z * 5.0;
            let t = rng.f(0.0, 1.0);
            let target = p0 + (p2 - p0) * t; // on the diagonal p0-p2
            let d = target - o;
            let h1 = intersect_ray_triangle(o, d, p0, p1, p2);
            let h2 = intersect_ray_triangle(o, d, p0, p2, p3);
            let n1 = (p1 - p0).cross(p2 - p0);
            let n2 = (p2 - p0).cross(p3 - p0);
            // Only where the ray sees both halves from the same side (not a silhouette edge,
            // where missing both is right) and neither half is near-parallel to the ray.
            let par = |n: Vec3| d.normalize().dot(n.normalize()).abs() < 1e-2;
            if d.dot(n1) * d.dot(n2) <= 0.0
                || par(n1)
                || par(n2)
                || n1.length() < 0.05
                || n2.length() < 0.05
            {
                continue;
            }
            assert!(h1.result || h2.result, "crack at {target}");
        }
    }

    /// The branch-free slab test against the branching one, bit for bit (no tolerance: it
    /// claims the same result and the same entry parameter), on every ray whose inv_dir has
    /// no infinite component: random rays and boxes with special values mixed in (signed
    /// zeros, infinities and NaN in the box and the start, infinite direction components, whose
    /// inv is a signed zero, NaN directions, inverted boxes, starts on the slab boundaries).
    #[test]
    fn ray_aabb_finite_matches_the_branching_test() {
        let specials = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            1e-30,
            1e30,
        ];
        let mut rng = Rng(4242);
        let (mut some, mut none, mut checked) = (0, 0, 0);
        let pick = |rng: &mut Rng, lo: f32, hi: f32| {
            if rng.below(6) == 0 {
                specials[rng.below(specials.len())]
            } else {
                rng.f(lo, hi)
            }
        };
        for _ in 0..200_000 {
            let o = Vec3::new(
                pick(&mut rng, -3.0, 3.0),
                pick(&mut rng, -3.0, 3.0),
                pick(&mut rng, -3.0, 3.0),
            );
            let d = Vec3::new(
                pick(&mut rng, -1.0, 1.0),
                pick(&mut rng, -1.0, 1.0),
                pick(&mut rng, -1.0, 1.0),
            );
            let (mut l, mut h) = (rng.v(-1.0, 0.0), rng.v(0.0, 1.0));
            // Half of the rays aimed at a point of the box, so that both outcomes are common.
            let d = if rng.below(2) == 0 {
                rng.v(-0.5, 0.5) - o
            } else {
                d
            };
            match rng.below(8) {
                0 => std::mem::swap(&mut l, &mut h),
                1 => l[rng.below(3)] = specials[rng.below(specials.len())],
                2 => h[rng.below(3)] = specials[rng.below(specials.len())],
                3 => l[rng.below(3)] = o[rng.below(3)],
                _ => {}
            }
            let inv = ray_inv_dir(d);
            if !ray_inv_dir_finite(inv) {
                continue;
            }
            checked += 1;
            let want = intersect_ray_aabb(o, inv, l, h);
            let got = intersect_ray_aabb_finite(o, inv, l, h);
            assert_eq!(
                got.map(f32::to_bits),
                want.map(f32::to_bits),
                "{o} {d} {l} {h}"
            );
            if want.is_some() {
                some += 1;
            } else {
                none += 1;
            }
        }
        // Both outcomes exercised, on most of the cases.
        assert!(
            checked > 100_000 && some > 10_000 && none > 10_000,
            "{checked} {some} {none}"
        );
    }

    #[test]
    fn ray_aabb_slabs() {
        let (lo, hi) = (Vec3::ZERO, Vec3::ONE);
        let hit = |o: Vec3, d: Vec3| intersect_ray_aabb(o, ray_inv_dir(d), lo, hi);
        assert_eq!(hit(Vec3::new(-1.0, 0.5, 0.5), Vec3::X), Some(1.0));
        assert_eq!(hit(Vec3::new(0.5, 0.5, 0.5), Vec3::X), Some(-0.5));
        assert_eq!(hit(Vec3::new(2.0, 0.5, 0.5), Vec3::X), None);
        // Zero components: parallel to those slabs, inside them or not; on a face (touching).
        assert_eq!(hit(Vec3::new(-1.0, 1.0, 0.0), Vec3::X), Some(1.0));
        assert_eq!(hit(Vec3::new(-1.0, 1.0 + 1e-6, 0.5), Vec3::X), None);
        assert_eq!(
            hit(Vec3::new(-1.0, 0.5, 0.5), Vec3::new(1.0, -0.0, 0.0)),
            Some(1.0)
        );
        // Origin on the slab boundary with a zero component: 0 * inf must not make NaN.
        assert_eq!(hit(Vec3::new(0.0, 0.0, -1.0), Vec3::Z), Some(1.0));
        // A zero direction: a point test.
        assert!(hit(Vec3::splat(0.5), Vec3::ZERO).is_some());
        assert!(hit(Vec3::splat(2.0), Vec3::ZERO).is_none());
        // NaN boxes, NaN rays, inverted boxes never hit.
        assert!(
            intersect_ray_aabb(Vec3::splat(-1.0), ray_inv_dir(Vec3::ONE), Vec3::NAN, hi).is_none()
        );
        assert!(
            intersect_ray_aabb(Vec3::splat(-1.0), ray_inv_dir(Vec3::ONE), lo, Vec3::NAN).is_none()
        );
        assert!(intersect_ray_aabb(Vec3::NAN, ray_inv_dir(Vec3::ONE), lo, hi).is_none());
        assert!(intersect_ray_aabb(Vec3::splat(-1.0), ray_inv_dir(Vec3::NAN), lo, hi).is_none());
        let inf = Vec3::splat(f32::INFINITY);
        assert!(intersect_ray_aabb(Vec3::splat(-1.0), ray_inv_dir(Vec3::ONE), inf, -inf).is_none());
        assert!(intersect_ray_aabb(Vec3::splat(-1.0), ray_inv_dir(Vec3::X), inf, -inf).is_none());
        // Random rays against brute force sampling of the segment parameter.
        let mut rng = Rng(77);
        for _ in 0..5000 {
            let (l, h) = (rng.v(-1.0, 0.0), rng.v(0.0, 1.0));
            let o = rng.v(-3.0, 3.0);
            let mut d = rng.v(-1.0, 1.0);
            if rng.below(4) == 0 {
                d[rng.below(3)] = 0.0;
            }
            let got = intersect_ray_aabb(o, ray_inv_dir(d), l, h);
            // Reference: the clipped interval in f64.
            let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
            let mut ok = true;
            for k in 0..3 {
                let (o, d, l, h) = (o[k] as f64, d[k] as f64, l[k] as f64, h[k] as f64);
                if d == 0.0 {
                    ok &= l <= o && o <= h;
                } else {
                    let (a, b) = ((l - o) / d, (h - o) / d);
                    t0 = t0.max(a.min(b));
                    t1 = t1.min(a.max(b));
                }
            }
            let want = ok && t0 <= t1 && t1 >= 0.0;
            // Only where the answer is not within rounding of the boundary.
            if want && t1 - t0.max(0.0) > 1e-4 {
                assert!(got.is_some(), "{o} {d} {l} {h}");
                assert!((got.unwrap() as f64 - t0).abs() <= 1e-5 * t0.abs().max(1.0));
            } else if !want && (!ok || t0 - t1 > 1e-4 || t1 < -1e-4) {
                assert!(got.is_none(), "{o} {d} {l} {h}");
            }
        }
    }

    #[test]
    fn aabb_overlap_cases() {
        let (lo, hi) = (Vec3::ZERO, Vec3::ONE);
        assert!(aabb_overlap(lo, hi, Vec3::splat(0.5), Vec3::splat(2.0)));
        assert!(aabb_overlap(lo, hi, Vec3::ONE, Vec3::splat(2.0))); // touching
        assert!(!aabb_overlap(
            lo,
            hi,
            Vec3::new(1.01, 0.0, 0.0),
            Vec3::splat(2.0)
        ));
        assert!(!aabb_overlap(lo, hi, Vec3::NAN, Vec3::splat(2.0)));
        let inf = Vec3::splat(f32::INFINITY);
        assert!(
            !aabb_overlap(inf, -inf, -inf, inf),
            "an inverted box overlaps nothing"
        );
        assert!(aabb_overlap(lo, hi, -inf, inf));
        assert_eq!(aabb_distance_sq(Vec3::new(2.0, 0.5, -1.0), lo, hi), 2.0);
        assert_eq!(aabb_distance_sq(Vec3::splat(0.5), lo, hi), 0.0);
    }

    /// Brute force for triangle-triangle: sample points on each triangle's edges and test
    /// them against the other triangle by the segment test... instead, a simple independent
    /// reference: two triangles intersect iff some edge of one crosses the other (f64, exact
    /// enough away from touching cases).
    fn brute_tri_tri(a: [Vec3; 3], b: [Vec3; 3]) -> bool {
        let seg_tri = |p: Vec3, q: Vec3, t: [Vec3; 3]| {
            let d = q - p;
            match brute_ray_tri(p, d, t[0], t[1], t[2]) {
                Some((s, _, _)) => s <= 1.0,
                None => false,
            }
        };
        (0..3).any(|i| seg_tri(a[i], a[(i + 1) % 3], b))
            || (0..3).any(|i| seg_tri(b[i], b[(i + 1) % 3], a))
    }

    #[test]
    fn tri_tri_matches_brute_force() {
        let mut rng = Rng(2024);
        let (mut yes, mut no) = (0, 0);
        for _ in 0..20000 {
            let a = [rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0)];
            let off = rng.v(-0.8, 0.8);
            let b = [
                rng.v(-1.0, 1.0) + off,
                rng.v(-1.0, 1.0) + off,
                rng.v(-1.0, 1.0) + off,
            ];
            let got = intersect_tri_tri(a[0], a[1], a[2], b[0], b[1], b[2]);
            let want = brute_tri_tri(a, b);
            // Skip near-touching configurations: perturbing b by 1e-4 must not change the
            // brute-force answer.
            let e = Vec3::splat(1e-4);
            let stable = brute_tri_tri(a, b.map(|x| x + e)) == want
                && brute_tri_tri(a, b.map(|x| x - e)) == want;
            if stable {
                assert_eq!(got, want, "{a:?} {b:?}");
                if want {
                    yes += 1
                } else {
                    no += 1
                }
            }
            // Symmetric.
            assert_eq!(
                got,
                intersect_tri_tri(b[0], b[1], b[2], a[0], a[1], a[2]),
                "{a:?} {b:?}"
            );
        }
        assert!(yes > 1000 && no > 1000, "{yes} {no}");
    }

    #[test]
    fn tri_tri_special_cases() {
        let t =
            |a: [f32; 3], b: [f32; 3], c: [f32; 3]| [Vec3::from(a), Vec3::from(b), Vec3::from(c)];
        let f = |a: [Vec3; 3], b: [Vec3; 3]| intersect_tri_tri(a[0], a[1], a[2], b[0], b[1], b[2]);
        let base = t([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        // Coplanar: overlapping, contained, disjoint, touching at an edge and a vertex.
        assert!(f(
            base,
            t([0.2, 0.2, 0.0], [2.0, 0.2, 0.0], [0.2, 2.0, 0.0])
        ));
        assert!(f(
            base,
            t([0.1, 0.1, 0.0], [0.2, 0.1, 0.0], [0.1, 0.2, 0.0])
        ));
        assert!(f(
            t([0.1, 0.1, 0.0], [0.2, 0.1, 0.0], [0.1, 0.2, 0.0]),
            base
        ));
        assert!(!f(
            base,
            t([1.0, 1.0, 0.0], [2.0, 1.0, 0.0], [1.0, 2.0, 0.0])
        ));
        assert!(f(
            base,
            t([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0])
        ));
        assert!(f(
            base,
            t([1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0])
        ));
        // Crossing, piercing, touching at a vertex from above, separated.
        assert!(f(
            base,
            t([0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [0.5, 2.0, 0.0])
        ));
        assert!(f(
            base,
            t([0.2, 0.2, 0.0], [0.2, 0.3, 1.0], [0.3, 0.2, 1.0])
        ));
        assert!(!f(
            base,
            t([0.2, 0.2, 0.01], [0.2, 0.3, 1.0], [0.3, 0.2, 1.0])
        ));
        // Degenerate: a segment piercing the triangle, a point on it, a point off it.
        assert!(f(
            base,
            t([0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [0.2, 0.2, 0.0])
        ));
        assert!(f(
            base,
            t([0.2, 0.2, 0.0], [0.2, 0.2, 0.0], [0.2, 0.2, 0.0])
        ));
        assert!(!f(
            base,
            t([0.2, 0.2, 0.1], [0.2, 0.2, 0.1], [0.2, 0.2, 0.1])
        ));
        // Two degenerate: crossing segments, disjoint segments.
        let s1 = t([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]);
        assert!(f(s1, t([0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0])));
        assert!(!f(
            s1,
            t([0.0, -1.0, 0.5], [0.0, 1.0, 0.5], [0.0, 1.0, 0.5])
        ));
        // Huge and tiny, and NaN.
        for k in [1e30f32, 1e-30] {
            let s = |x: [Vec3; 3]| x.map(|v| v * k);
            assert!(
                f(
                    s(base),
                    s(t([0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [0.5, 2.0, 0.0]))
                ),
                "{k}"
            );
            assert!(
                !f(
                    s(base),
                    s(t([0.2, 0.2, 0.01], [0.2, 0.3, 1.0], [0.3, 0.2, 1.0]))
                ),
                "{k}"
            );
        }
        assert!(!f(
            base,
            t([f32::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        ));
    }

    /// The parity test: through a fan's centre vertex, a shared edge (spoke) and a face,
    /// exactly one of the four faces covering the square is crossed, where the hit test finds
    /// four, two and one (the directions are dyadic, so the rays meet those points exactly);
    /// elsewhere, away from edges and from parallel faces, it agrees with the hit test.
    #[test]
    fn ray_crossing_counts_one_face() {
        let fan = [Vec3::X, Vec3::Y, -Vec3::X, -Vec3::Y];
        for d in [-Vec3::Z, Vec3::new(0.25, -0.5, -1.0)] {
            for (target, hits) in [
                (Vec3::ZERO, 4),
                (Vec3::new(0.25, 0.0, 0.0), 2),
                (Vec3::new(0.0, -0.5, 0.0), 2),
                (Vec3::new(0.1, 0.2, 0.0), 1),
            ] {
                let o = target - d;
                let count = |f: &dyn Fn(usize) -> bool| (0..4).filter(|i| f(*i)).count();
                let n =
                    count(&|i| ray_crosses_triangle(o, d, Vec3::ZERO, fan[i], fan[(i + 1) % 4]));
                assert_eq!(n, 1, "{o} {d}");
                let h = count(&|i| {
                    intersect_ray_triangle(o, d, Vec3::ZERO, fan[i], fan[(i + 1) % 4]).result
                });
                assert_eq!(h, hits, "{o} {d}");
            }
        }
        let mut rng = Rng(12);
        let mut crossed = 0;
        for _ in 0..20000 {
            let (a, b, c) = (rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0));
            // Aimed near the triangle, so that about half the rays hit it.
            let (u, v) = (rng.f(-0.2, 1.0), rng.f(-0.2, 1.0));
            let o = rng.v(-3.0, 3.0);
            let d = a * u + b * v + c * (1.0 - u - v) - o;
            let n = (b - a).cross(c - a);
            if d.normalize().dot(n.normalize()).abs() < 1e-3 {
                continue;
            }
            let h = intersect_ray_triangle(o, d, a, b, c).result;
            assert_eq!(ray_crosses_triangle(o, d, a, b, c), h, "{o} {d}");
            crossed += h as usize;
        }
        assert!(crossed > 5000, "{crossed}");
        // NaN and a zero direction never cross.
        let (a, b, c) = (Vec3::X, Vec3::Y, -Vec3::X - Vec3::Y);
        assert!(!ray_crosses_triangle(Vec3::Z, Vec3::ZERO, a, b, c));
        assert!(!ray_crosses_triangle(Vec3::Z, Vec3::NAN, a, b, c));
        assert!(!ray_crosses_triangle(Vec3::NAN, -Vec3::Z, a, b, c));
        assert!(!ray_crosses_triangle(Vec3::Z, -Vec3::Z, Vec3::NAN, b, c));
        assert!(ray_crosses_triangle(Vec3::Z, -Vec3::Z, a, b, c));
        assert!(!ray_crosses_triangle(Vec3::Z, Vec3::Z, a, b, c));
    }

    /// Whether `x * s` is exact: zero, or finite and normal (a power-of-two product rounds only
    /// where it leaves the normal range).
    fn exact_product(x: f32, s: f32) -> bool {
        let y = x * s;
        x == 0.0 || (y.is_normal() && y / s == x)
    }

    /// `aabb_distance_sq_scaled` is the nine-product form `aabb_distance_sq(p * s, lo * s,
    /// hi * s)`, bit for bit, wherever no product under- or overflows (checked case by case;
    /// the cases span 1e-30 to 1e30 and scales up to 2^±120, so that many do leave the
    /// range), and is right where the nine-product form overflows.
    #[test]
    fn aabb_distance_sq_scaled_is_the_scaled_key() {
        let mut rng = Rng(77);
        let (mut same, mut skipped) = (0, 0);
        for _ in 0..200_000 {
            let m = 10f32.powi(rng.below(61) as i32 - 30);
            let (a, b) = (rng.v(-1.0, 1.0) * m, rng.v(-1.0, 1.0) * m);
            let (lo, hi) = (a.min(b), a.max(b));
            // Points inside, on and around the box, sometimes exactly on a face.
            let mut p = rng.v(-2.0, 2.0) * m;
            if rng.below(4) == 0 {
                p.x = lo.x;
            }
            let s = 2f32.powi(rng.below(241) as i32 - 120);
            let d = p.clamp_nan_safe(lo, hi) - p;
            let exact = [p, lo, hi, d]
                .iter()
                .all(|v| v.to_array().iter().all(|&x| exact_product(x, s)));
            let got = aabb_distance_sq_scaled(p, lo, hi, s);
            if exact {
                let want = aabb_distance_sq(p * s, lo * s, hi * s);
                assert_eq!(got.to_bits(), want.to_bits(), "{p} {lo} {hi} {s}");
                same += 1;
            } else {
                skipped += 1;
            }
        }
        assert!(same > 50_000 && skipped > 10_000, "{same} {skipped}");
        // A point on a box of extent 1e-20 at x = 1e20, in the unit a mesh query would pick
        // (the extent brought to [1, 2)): p * s overflows, so the nine-product form is NaN.
        let lo = Vec3::new(1e20, 0.0, 0.0);
        let hi = Vec3::new(1e20, 1e-20, 1e-20);
        let p = Vec3::new(1e20, 5e-21, 2e-20);
        let s = pow2_scale(1e-20);
        assert!(aabb_distance_sq(p * s, lo * s, hi * s).is_nan());
        let want = (((2e-20f64 - 1e-20f32 as f64) * s as f64).powi(2)) as f32;
        let got = aabb_distance_sq_scaled(p, lo, hi, s);
        assert!((got - want).abs() <= 1e-6 * want, "{got} vs {want}");
        assert_eq!(
            aabb_distance_sq_scaled(Vec3::new(1e20, 5e-21, 0.0), lo, hi, s),
            0.0
        );
        // NaN: a NaN point is never near; a NaN bound is passed over (as by the clamp).
        assert!(aabb_distance_sq_scaled(Vec3::NAN, lo, hi, s).is_nan());
        let nan_lo = Vec3::new(f32::NAN, 0.0, 0.0);
        assert_eq!(
            aabb_distance_sq_scaled(Vec3::new(2.0, 0.5, 0.5), nan_lo, Vec3::ONE, 1.0),
            1.0
        );
    }

    /// `closest_point_triangle_scaled` gives the same bits at any power-of-two scale under
    /// which its intermediates stay normal: here the triangle's own scale times `2^j` for
    /// `|j| <= 20` (the scaled coordinates below 2^21, so the degree-4 sub-areas stay far
    /// inside the range, and above 2^-20 for triangles not thinner than 1e-3 of their size).
    #[test]
    fn closest_point_triangle_scaled_is_scale_free() {
        let mut rng = Rng(31);
        for i in 0..20_000 {
            let m = 10f32.powi(rng.below(41) as i32 - 20);
            let (a, b, c) = (
                rng.v(-1.0, 1.0) * m,
                rng.v(-1.0, 1.0) * m,
                rng.v(-1.0, 1.0) * m,
            );
            let p = rng.v(-2.0, 2.0) * m;
            let (ab, ac, ap) = (b - a, c - a, p - a);
            if ab.cross(ac).length() < 1e-3 * ab.length_squared().max(ac.length_squared()) {
                continue;
            }
            let want = closest_point_triangle(a, b, c, p);
            let s = pow2_scale(max_abs(&[ab, ac, ap])) * 2f32.powi(i % 41 - 20);
            let got = closest_point_triangle_scaled(ab * s, ac * s, ap * s);
            assert_eq!(
                (
                    got.u.to_bits(),
                    got.v.to_bits(),
                    got.w.to_bits(),
                    got.feature
                ),
                (
                    want.u.to_bits(),
                    want.v.to_bits(),
                    want.w.to_bits(),
                    want.feature
                ),
                "{a} {b} {c} {p} at {s}"
            );
        }
    }
}
