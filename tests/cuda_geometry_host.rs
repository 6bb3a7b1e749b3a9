//! The CUDA geometry, BVH and mesh queries (`warp-cuda/cuda/wp_geometry.h`, `wp_bvh.h`,
//! `wp_mesh.h` and their adjoint parts) against warp-core's, bit for bit, on the host.
//!
//! One C++ driver (below, `DRIVER`) reads a stream of cases (u32 words: an op code and its
//! inputs as bit patterns) and prints one line per case; the same cases run through
//! warp-core's functions here and print the same line format, and the two are compared as
//! text. Floats are printed as their bits (any NaN as `nan`), so "equal" means bit for bit.
//! The driver is built with `g++ -std=c++17 -O1 -ffp-contract=off -Wall -Wextra -Werror
//! -Wdouble-promotion` (no FMA contraction: the runtime compiles kernels with `--fmad=false`
//! where bit-exact results matter). Skipped, saying so, without g++.
//!
//! Cases: every geometric test on random inputs with degenerate ones mixed in (repeated and
//! collinear vertices, slivers, points on vertices and edges, axis-aligned rays, zero
//! direction components, huge and tiny scales, NaN and infinities); the BVH box and ray queries
//! over trees from warp-runtime's SAH builder (empty, one box, up to 5000 boxes, past its
//! parallel threshold) and a hand-built 1500-level caterpillar; every mesh query on a triangle
//! soup with degenerate faces, a sphere, a torus, an open patch and a sphere at 1e30, with and
//! without velocities; the adjoints; and corrupt trees and meshes (hand-made corruptions and
//! random ones), which must fault at the same read with the same index, or end after the same
//! items, on both sides.
//!
//! A second test checks that NVRTC accepts the headers (every function instantiated in a
//! kernel) for sm_90 and sm_80 with `--fmad=false`; skipped, saying so, without libnvrtc.

use std::fmt::Write as _;
use std::process::Command;

use warp_core::glam::{Vec3, Vec4};
use warp_core::objects::bvh::{
    bvh_query_aabb, bvh_query_aabb_done, bvh_query_aabb_item, bvh_query_aabb_next, bvh_query_ray,
    bvh_query_ray_done, bvh_query_ray_item, bvh_query_ray_next, preorder_escapes, BvhNode,
    BvhQueryAabb, BvhQueryRay, BvhTree, BvhView,
};
use warp_core::objects::geometry::{
    aabb_distance_sq, aabb_distance_sq_scaled, aabb_overlap, adj_closest_point_triangle,
    closest_point_triangle, intersect_ray_aabb, intersect_ray_triangle, intersect_tri_tri,
    pow2_scale, ray_crosses_triangle, ray_inv_dir, RayTriangleHit, TriFeature,
    TriangleClosestPoint,
};
use warp_core::objects::mesh::{
    adj_mesh_eval_position, adj_mesh_eval_velocity, adj_mesh_query_point,
    adj_mesh_query_point_no_sign, adj_mesh_query_point_sign_normal,
    adj_mesh_query_point_sign_parity, mesh_eval_face_normal, mesh_eval_position,
    mesh_eval_velocity, mesh_query_aabb, mesh_query_aabb_done, mesh_query_aabb_item,
    mesh_query_aabb_next, mesh_query_furthest_point_no_sign, mesh_query_point,
    mesh_query_point_no_sign, mesh_query_point_sign_normal, mesh_query_point_sign_parity,
    mesh_query_ray, MeshQueryAabb, MeshQueryPoint, MeshQueryRay, MeshView, PARITY_DIR,
};
use warp_core::{Fault, FaultKind, KResult};
use warp_runtime::objects::bvh_build::{build_sah, check_layout, leaf_triangles};

#[path = "common/host_cpp.rs"]
mod host_cpp;

/// The fault argument index the driver gives its objects, and the name Rust faults carry.
const ARG: i32 = 7;
const ARG_NAME: &str = "geom";
/// The most items an iterating query may yield before both sides stop listing them.
const MAX_ITEMS: usize = 100_000;

// ------------------------------------------------------------------------------------------
// The C++ driver
// ------------------------------------------------------------------------------------------

const DRIVER: &str = r#"
#include <cstdio>
#include <cstring>
#include <cstddef>
#include <vector>
#include "wp_adjoint_mesh.h"
using namespace wp;

static std::vector<u32> in;
static size_t at = 0;
static u32 w() { return in[at++]; }
static i32 wi() { return (i32)w(); }
static f32 wf() { f32 x; u32 u = w(); memcpy(&x, &u, 4); return x; }
static Vec3 wv() { f32 x = wf(); f32 y = wf(); f32 z = wf(); return Vec3_new(x, y, z); }
static void pf(f32 x) { if (x != x) printf(" nan"); else { u32 u; memcpy(&u, &x, 4); printf(" %08x", u); } }
static void pv(Vec3 v) { pf(v.x); pf(v.y); pf(v.z); }
static fault_t fault;
static u32 flag;
static launch_ctx_t rec;
static ctx_t fresh() {
  memset(&fault, 0, sizeof fault);
  flag = 0;
  rec = launch_ctx_make(&fault, &flag);
  return ctx_make(&rec);
}
static bool pfault(const ctx_t& c) {
  if (!c.raised) return false;
  printf(" F %d %lld %lld", fault.arg, (long long)fault.index[0], (long long)fault.shape[0]);
  return true;
}

static std::vector<bvh_node_t> nodes;
static std::vector<i32> parents, prim_ids, indices;
static std::vector<Vec3> lowers, uppers, points, velocities;
static std::vector<f32> leaf_tris;
static bvh_tree_t read_tree() {
  const i32 nn = wi();
  nodes.resize(nn);
  for (i32 i = 0; i < nn; ++i) {
    for (int k = 0; k < 3; ++k) nodes[i].lower[k] = wf();
    nodes[i].left = wi();
    for (int k = 0; k < 3; ++k) nodes[i].upper[k] = wf();
    nodes[i].right = wi();
  }
  parents.resize(2 * (size_t)nn);  // the links: parents, then escapes
  for (i32 i = 0; i < 2 * nn; ++i) parents[i] = wi();
  const i32 np = wi();
  prim_ids.resize(np);
  for (i32 i = 0; i < np; ++i) prim_ids[i] = wi();
  bvh_tree_t t;
  t.nodes = nodes.data();
  t.parents = parents.data();
  t.prim_ids = prim_ids.data();
  t.num_nodes = nn;
  t.num_prims = np;
  t.arg = 7;
  t.pad = 0;
  return t;
}

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  FILE* f = fopen(argv[1], "rb");
  if (!f) return 2;
  u32 word;
  while (fread(&word, 4, 1, f) == 1) in.push_back(word);
  fclose(f);
  bvh_t bvh{};
  mesh_t mesh{};
  while (at < in.size()) {
    const u32 op = w();
    switch (op) {
      case 0: {
        printf("layout %zu %zu %zu %zu %zu %zu %zu %zu %zu %zu %zu %zu %zu %zu", sizeof(bvh_node_t),
               sizeof(bvh_query_aabb_t), sizeof(bvh_query_ray_t), sizeof(mesh_query_aabb_t),
               sizeof(triangle_closest_point_t), sizeof(ray_triangle_hit_t),
               sizeof(mesh_query_point_t), offsetof(mesh_query_point_t, face),
               offsetof(mesh_query_point_t, v), sizeof(mesh_query_ray_t),
               offsetof(mesh_query_ray_t, t), offsetof(mesh_query_ray_t, normal),
               offsetof(ray_triangle_hit_t, sign), offsetof(triangle_closest_point_t, feature));
        break;
      }
      case 1: {
        const Vec3 a = wv(), b = wv(), c = wv(), p = wv();
        triangle_closest_point_t g;
        g.u = wf(); g.v = wf(); g.w = wf(); g.feature = 0;
        Vec3 ap = wv();
        const triangle_closest_point_t r = closest_point_triangle(a, b, c, p);
        Vec3 x = Vec3_ZERO(), y = Vec3_ZERO(), z = Vec3_ZERO();
        adj_closest_point_triangle(a, b, c, p, x, y, z, ap, g);
        printf("cp"); pf(r.u); pf(r.v); pf(r.w); printf(" %d", r.feature); pv(ap);
        break;
      }
      case 2: {
        const Vec3 s = wv(), d = wv(), a = wv(), b = wv(), c = wv();
        const ray_triangle_hit_t h = intersect_ray_triangle(s, d, a, b, c);
        printf("rt %d", (int)h.result); pf(h.t); pf(h.u); pf(h.v); pf(h.sign);
        printf(" x%d", (int)ray_crosses_triangle(s, d, a, b, c));
        break;
      }
      case 3: {
        const Vec3 a = wv(), b = wv(), c = wv(), d = wv(), e = wv(), g = wv();
        printf("tt %d", (int)intersect_tri_tri(a, b, c, d, e, g));
        break;
      }
      case 4: {
        const Vec3 s = wv(), d = wv(), lo = wv(), hi = wv();
        f32 t = 0.0f;
        const bool hit = intersect_ray_aabb(s, ray_inv_dir(d), lo, hi, &t);
        printf("ra %d", (int)hit); if (hit) pf(t);
        break;
      }
      case 5: {
        const Vec3 al = wv(), au = wv(), bl = wv(), bu = wv(), p = wv();
        printf("bx %d", (int)aabb_overlap(al, au, bl, bu)); pf(aabb_distance_sq(p, al, au));
        pf(aabb_distance_sq_scaled(p, al, au, pow2_scale(::fabsf(bl.x))));
        break;
      }
      case 6: { printf("p2"); pf(pow2_scale(wf())); break; }
      case 10: {
        bvh.tree = read_tree();
        const i32 np = bvh.tree.num_prims;
        lowers.resize(np); uppers.resize(np);
        for (i32 i = 0; i < np; ++i) lowers[i] = wv();
        for (i32 i = 0; i < np; ++i) uppers[i] = wv();
        bvh.lowers = lowers.data(); bvh.uppers = uppers.data();
        printf("bvh");
        break;
      }
      case 11: case 12: {
        const Vec3 x = wv(), y = wv();
        ctx_t c = fresh();
        printf(op == 11 ? "qa" : "qr");
        size_t n = 0;
        if (op == 11) {
          bvh_query_aabb_t q = bvh_query_aabb(bvh, x, y, &c);
          for (;;) {
            q = bvh_query_aabb_next(bvh, q, &c);
            // A GPU thread goes on after a fault: the walk must have ended (Rust never
            // prints this, so the line would not match).
            if (c.raised && !bvh_query_aabb_done(q)) printf(" not-ended");
            if (c.raised || bvh_query_aabb_done(q) || n >= 100000) break;
            printf(" %d", bvh_query_aabb_item(q)); ++n;
          }
          if (!c.raised && n < 100000) {
            q = bvh_query_aabb_next(bvh, q, &c);
            if (!c.raised) printf(" done%d", (int)bvh_query_aabb_done(q));
          }
        } else {
          bvh_query_ray_t q = bvh_query_ray(bvh, x, y, &c);
          for (;;) {
            q = bvh_query_ray_next(bvh, q, &c);
            if (c.raised && !bvh_query_ray_done(q)) printf(" not-ended");
            if (c.raised || bvh_query_ray_done(q) || n >= 100000) break;
            printf(" %d", bvh_query_ray_item(q)); ++n;
          }
          if (!c.raised && n < 100000) {
            q = bvh_query_ray_next(bvh, q, &c);
            if (!c.raised) printf(" done%d", (int)bvh_query_ray_done(q));
          }
        }
        pfault(c);
        break;
      }
      case 20: {
        mesh.tree = read_tree();
        const i32 npts = wi();
        points.resize(npts);
        for (i32 i = 0; i < npts; ++i) points[i] = wv();
        const bool has_vel = wi() != 0;
        velocities.resize(has_vel ? npts : 0);
        for (size_t i = 0; i < velocities.size(); ++i) velocities[i] = wv();
        indices.resize(3 * (size_t)mesh.tree.num_prims);
        for (size_t i = 0; i < indices.size(); ++i) indices[i] = wi();
        leaf_tris.resize(12 * (size_t)mesh.tree.num_prims);
        for (size_t i = 0; i < leaf_tris.size(); ++i) leaf_tris[i] = wf();
        mesh.leaf_tris = leaf_tris.data();
        mesh.points = points.data();
        mesh.velocities = has_vel ? velocities.data() : nullptr;
        mesh.indices = indices.data();
        mesh.num_points = npts;
        mesh.pad = 0;
        printf("mesh");
        break;
      }
      case 21: case 22: case 23: case 27: case 28: {
        const Vec3 p = wv();
        const f32 d = wf();
        mesh_query_point_t g{};
        g.u = wf(); g.v = wf();
        Vec3 ap = wv();
        ctx_t c = fresh();
        const mesh_query_point_t r =
            op == 21   ? mesh_query_point(mesh, p, d, &c)
            : op == 22 ? mesh_query_point_no_sign(mesh, p, d, &c)
            : op == 27 ? mesh_query_point_sign_normal(mesh, p, d, &c)
            : op == 28 ? mesh_query_point_sign_parity(mesh, p, d, &c)
                       : mesh_query_furthest_point_no_sign(mesh, p, d, &c);
        printf(op == 21 ? "mp" : op == 22 ? "mn" : op == 27 ? "ms" : op == 28 ? "mq" : "mf");
        if (pfault(c)) break;
        printf(" %d", (int)r.result); pf(r.sign); printf(" %d", r.face); pf(r.u); pf(r.v);
        mesh_t am{};
        f32 ad = 0.0f;
        c = fresh();
        if (op == 21) adj_mesh_query_point(mesh, p, d, am, ap, ad, g, &c);
        else if (op == 22) adj_mesh_query_point_no_sign(mesh, p, d, am, ap, ad, g, &c);
        else if (op == 27) adj_mesh_query_point_sign_normal(mesh, p, d, am, ap, ad, g, &c);
        else if (op == 28) {
          // The tuple overload, as generated code calls it.
          const mesh_query_point_tuple_t gt = g;
          adj_mesh_query_point_sign_parity(mesh, p, d, am, ap, ad, gt, &c);
        }
        else adj_mesh_query_furthest_point_no_sign(mesh, p, d, am, ap, ad, g, &c);
        printf(" |"); if (!pfault(c)) pv(ap);
        break;
      }
      case 24: {
        const Vec3 s = wv(), d = wv();
        const f32 mt = wf();
        ctx_t c = fresh();
        const mesh_query_ray_t r = mesh_query_ray(mesh, s, d, mt, &c);
        printf("mr");
        if (pfault(c)) break;
        printf(" %d", (int)r.result); pf(r.sign); printf(" %d", r.face); pf(r.t); pf(r.u); pf(r.v);
        pv(r.normal);
        break;
      }
      case 25: {
        const Vec3 x = wv(), y = wv();
        ctx_t c = fresh();
        printf("ma");
        size_t n = 0;
        mesh_query_aabb_t q = mesh_query_aabb(mesh, x, y, &c);
        for (;;) {
          q = mesh_query_aabb_next(mesh, q, &c);
          if (c.raised && !mesh_query_aabb_done(q)) printf(" not-ended");
          if (c.raised || mesh_query_aabb_done(q) || n >= 100000) break;
          printf(" %d", mesh_query_aabb_item(q)); ++n;
        }
        pfault(c);
        break;
      }
      case 26: {
        const i32 face = wi();
        const f32 u = wf(), v = wf();
        const Vec3 g = wv();
        const f32 au0 = wf(), av0 = wf();
        printf("me");
        ctx_t c = fresh();
        const Vec3 pos = mesh_eval_position(mesh, face, u, v, &c);
        if (!pfault(c)) pv(pos);
        c = fresh();
        const Vec3 vel = mesh_eval_velocity(mesh, face, u, v, &c);
        printf(" |"); if (!pfault(c)) pv(vel);
        c = fresh();
        const Vec3 nrm = mesh_eval_face_normal(mesh, face, &c);
        printf(" |"); if (!pfault(c)) pv(nrm);
        mesh_t am{};
        i32 af = 0;
        f32 au = au0, av = av0;
        c = fresh();
        adj_mesh_eval_position(mesh, face, u, v, am, af, au, av, g, &c);
        printf(" |"); if (!pfault(c)) { pf(au); pf(av); }
        au = au0; av = av0;
        c = fresh();
        adj_mesh_eval_velocity(mesh, face, u, v, am, af, au, av, g, &c);
        printf(" |"); if (!pfault(c)) { pf(au); pf(av); }
        break;
      }
      default:
        fprintf(stderr, "bad op %u at word %zu\n", op, at - 1);
        return 3;
    }
    printf("\n");
  }
  return 0;
}
"#;

// ------------------------------------------------------------------------------------------
// Cases: the words the driver reads and the lines warp-core gives
// ------------------------------------------------------------------------------------------

/// xorshift64*, seeded (warp-core's test generator).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn f(&mut self, lo: f32, hi: f32) -> f32 {
        let u = (self.next() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * u
    }
    fn v(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.f(lo, hi), self.f(lo, hi), self.f(lo, hi))
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// A float as the driver prints it.
fn hf(x: f32) -> String {
    if x.is_nan() {
        " nan".into()
    } else {
        format!(" {:08x}", x.to_bits())
    }
}

fn hv(v: Vec3) -> String {
    format!("{}{}{}", hf(v.x), hf(v.y), hf(v.z))
}

/// A fault as the driver prints it (`F arg index shape`).
fn hfault(e: &Fault) -> String {
    match &e.kind {
        FaultKind::OutOfBounds { arg, index, shape } => {
            assert_eq!(*arg, ARG_NAME, "{e}");
            format!(" F {ARG} {} {}", index[0], shape[0])
        }
        k => panic!("unexpected fault kind {k:?}"),
    }
}

/// The case stream and the expected output.
#[derive(Default)]
struct Cases {
    words: Vec<u32>,
    want: Vec<String>,
    /// What each case is (for failure messages).
    what: Vec<String>,
    label: String,
}

impl Cases {
    fn op(&mut self, op: u32) -> &mut Self {
        self.words.push(op);
        self
    }
    fn i(&mut self, x: i32) -> &mut Self {
        self.words.push(x as u32);
        self
    }
    fn f(&mut self, x: f32) -> &mut Self {
        self.words.push(x.to_bits());
        self
    }
    fn v(&mut self, v: Vec3) -> &mut Self {
        self.f(v.x).f(v.y).f(v.z)
    }
    fn expect(&mut self, line: String) {
        self.want.push(line);
        self.what.push(self.label.clone());
    }
    fn tree(&mut self, t: &Tree) {
        self.i(t.nodes.len() as i32);
        for n in &t.nodes {
            self.v(n.lower()).i(n.left).v(n.upper()).i(n.right);
        }
        for p in &t.parents {
            self.i(*p);
        }
        self.i(t.prim_ids.len() as i32);
        for p in &t.prim_ids {
            self.i(*p);
        }
    }
}

/// A tree in the shared layout (possibly corrupt).
#[derive(Clone)]
struct Tree {
    nodes: Vec<BvhNode>,
    parents: Vec<i32>,
    prim_ids: Vec<i32>,
}

impl Tree {
    fn sah(lowers: &[Vec3], uppers: &[Vec3]) -> Tree {
        let b = build_sah(lowers, uppers);
        check_layout(&b.nodes, &b.parents, &b.prim_ids, lowers, uppers).unwrap();
        Tree {
            nodes: b.nodes,
            parents: b.parents,
            prim_ids: b.prim_ids,
        }
    }
    /// The tree's view (the buffers must outlive it).
    fn view(&self) -> BvhTree {
        // SAFETY: the vectors hold that many elements and are not touched while the tree is
        // used (every use is within the caller's borrow of `self`).
        unsafe {
            BvhTree::from_raw(
                self.nodes.as_ptr(),
                self.parents.as_ptr(),
                self.nodes.len() as i32,
                self.prim_ids.as_ptr(),
                self.prim_ids.len() as i32,
                "driver",
                ARG_NAME,
            )
        }
    }
}

// ----- geometry -----

fn closest_case(c: &mut Cases, a: Vec3, b: Vec3, cc: Vec3, p: Vec3, rng: &mut Rng) {
    let g = TriangleClosestPoint {
        u: rng.f(-1.0, 1.0),
        v: rng.f(-1.0, 1.0),
        w: rng.f(-1.0, 1.0),
        feature: TriFeature::Face,
    };
    let mut ap = rng.v(-1.0, 1.0);
    c.op(1).v(a).v(b).v(cc).v(p).f(g.u).f(g.v).f(g.w).v(ap);
    let r = closest_point_triangle(a, b, cc, p);
    let (mut x, mut y, mut z) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    adj_closest_point_triangle(a, b, cc, p, &mut x, &mut y, &mut z, &mut ap, g);
    c.expect(format!(
        "cp{}{}{} {}{}",
        hf(r.u),
        hf(r.v),
        hf(r.w),
        r.feature as i32,
        hv(ap)
    ));
}

fn ray_tri_case(c: &mut Cases, s: Vec3, d: Vec3, a: Vec3, b: Vec3, cc: Vec3) {
    c.op(2).v(s).v(d).v(a).v(b).v(cc);
    let h: RayTriangleHit = intersect_ray_triangle(s, d, a, b, cc);
    c.expect(format!(
        "rt {}{}{}{}{} x{}",
        h.result as i32,
        hf(h.t),
        hf(h.u),
        hf(h.v),
        hf(h.sign),
        ray_crosses_triangle(s, d, a, b, cc) as i32
    ));
}

fn tri_tri_case(c: &mut Cases, t: [Vec3; 6]) {
    c.op(3);
    for v in t {
        c.v(v);
    }
    let r = intersect_tri_tri(t[0], t[1], t[2], t[3], t[4], t[5]);
    c.expect(format!("tt {}", r as i32));
}

fn ray_aabb_case(c: &mut Cases, s: Vec3, d: Vec3, lo: Vec3, hi: Vec3) {
    c.op(4).v(s).v(d).v(lo).v(hi);
    let r = intersect_ray_aabb(s, ray_inv_dir(d), lo, hi);
    c.expect(match r {
        Some(t) => format!("ra 1{}", hf(t)),
        None => "ra 0".into(),
    });
}

fn boxes_case(c: &mut Cases, al: Vec3, au: Vec3, bl: Vec3, bu: Vec3, p: Vec3) {
    c.op(5).v(al).v(au).v(bl).v(bu).v(p);
    // The scaled distance at a power of two from the inputs (up to 2^±126 for the huge and
    // tiny ones, so that products leave the normal range).
    c.expect(format!(
        "bx {}{}{}",
        aabb_overlap(al, au, bl, bu) as i32,
        hf(aabb_distance_sq(p, al, au)),
        hf(aabb_distance_sq_scaled(p, al, au, pow2_scale(bl.x.abs())))
    ));
}

/// A random vector with special values mixed in (zeros, NaN, infinities, huge, tiny).
fn odd_vec(rng: &mut Rng) -> Vec3 {
    let mut v = rng.v(-1.0, 1.0);
    for k in 0..3 {
        match rng.below(12) {
            0 => v[k] = 0.0,
            1 => v[k] = -0.0,
            2 => v[k] = f32::NAN,
            3 => v[k] = f32::INFINITY,
            4 => v[k] = f32::NEG_INFINITY,
            5 => v[k] *= 1e30,
            6 => v[k] *= 1e-30,
            _ => {}
        }
    }
    v
}

fn geometry_cases(c: &mut Cases) {
    let mut rng = Rng(0x5eed_0001);
    c.label = "closest_point_triangle".into();
    for i in 0..20000 {
        let (a, b, cc) = (rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0));
        let mut p = rng.v(-2.0, 2.0);
        let (a, b, cc) = match i % 10 {
            // Degenerate: collinear, repeated, coincident, a sliver.
            0 => (a, b, a + (b - a) * rng.f(-2.0, 2.0)),
            1 => (a, a, b),
            2 => (a, a, a),
            3 => (
                a,
                b,
                a + (b - a) * 0.5 + (b - a).any_orthogonal_vector() * 1e-7,
            ),
            // Exactly on a vertex, on an edge, in the face; axis-aligned inputs.
            4 => {
                p = [a, b, cc][rng.below(3)];
                (a, b, cc)
            }
            5 => {
                p = a + (b - a) * 0.5;
                (a, b, cc)
            }
            6 => {
                let q = |v: Vec3| (v * 4.0).round() * 0.25;
                p = q(p);
                (q(a), q(b), q(cc))
            }
            7 => {
                let k = [1e30f32, 1e-30, 1e20, 1e-20][rng.below(4)];
                p *= k;
                (a * k, b * k, cc * k)
            }
            _ => (a, b, cc),
        };
        closest_case(c, a, b, cc, p, &mut rng);
    }
    for _ in 0..2000 {
        let (a, b, cc, p) = (
            odd_vec(&mut rng),
            odd_vec(&mut rng),
            odd_vec(&mut rng),
            odd_vec(&mut rng),
        );
        closest_case(c, a, b, cc, p, &mut rng);
    }

    c.label = "intersect_ray_triangle".into();
    for i in 0..20000 {
        let (a, b, cc) = (rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0));
        let o = rng.v(-3.0, 3.0);
        let mut d = if rng.below(2) == 0 {
            rng.v(-1.0, 1.0)
        } else {
            let (x, y) = (rng.f(-0.2, 1.0), rng.f(-0.2, 1.0));
            (a + (b - a) * x + (cc - a) * (y * (1.0 - x))) - o
        };
        match i % 8 {
            0 => d[rng.below(3)] = 0.0,
            1 => d = [a, b, cc][rng.below(3)] - o, // through a vertex
            2 => d = a + (b - a) * 0.5 - o,        // through an edge
            3 => {
                let k = [1e30f32, 1e-30][rng.below(2)];
                ray_tri_case(c, o * k, d, a * k, b * k, cc * k);
                continue;
            }
            4 => {
                ray_tri_case(c, o, d, a, a, b); // degenerate
                continue;
            }
            _ => {}
        }
        ray_tri_case(c, o, d, a, b, cc);
    }
    for _ in 0..2000 {
        let v: Vec<Vec3> = (0..5).map(|_| odd_vec(&mut rng)).collect();
        ray_tri_case(c, v[0], v[1], v[2], v[3], v[4]);
    }
    // Watertightness cases: rays at points of a shared diagonal.
    for _ in 0..2000 {
        let p: Vec<Vec3> = (0..4).map(|_| rng.v(-1.0, 1.0)).collect();
        let o = rng.v(-3.0, 3.0) + Vec3::Z * 5.0;
        let d = p[0] + (p[2] - p[0]) * rng.f(0.0, 1.0) - o;
        ray_tri_case(c, o, d, p[0], p[1], p[2]);
        ray_tri_case(c, o, d, p[0], p[2], p[3]);
    }
    // The crossing's ties: dyadic rays exactly through a fan's centre, its spokes, its rim.
    let fan = [Vec3::X, Vec3::Y, -Vec3::X, -Vec3::Y];
    for d in [
        -Vec3::Z,
        Vec3::new(0.25, -0.5, -1.0),
        Vec3::new(0.9375, 0.75, 1.0),
        Vec3::new(-1.0, 0.5, 0.25),
    ] {
        for t in [
            Vec3::ZERO,
            Vec3::new(0.25, 0.0, 0.0),
            Vec3::new(0.0, -0.5, 0.0),
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::X,
        ] {
            for i in 0..4 {
                ray_tri_case(c, t - d, d, Vec3::ZERO, fan[i], fan[(i + 1) % 4]);
                ray_tri_case(c, t - d, d, Vec3::ZERO, fan[(i + 1) % 4], fan[i]);
            }
        }
    }

    c.label = "intersect_tri_tri".into();
    for i in 0..20000 {
        let a = [rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0)];
        let off = rng.v(-0.8, 0.8);
        let mut b = [
            rng.v(-1.0, 1.0) + off,
            rng.v(-1.0, 1.0) + off,
            rng.v(-1.0, 1.0) + off,
        ];
        let mut a2 = a;
        match i % 10 {
            // Coplanar (z = 0 for both), touching at a vertex, degenerate on one or both sides.
            0 => {
                for v in a2.iter_mut().chain(b.iter_mut()) {
                    v.z = 0.0;
                }
            }
            1 => b[0] = a[rng.below(3)],
            2 => b[2] = b[0] + (b[1] - b[0]) * 0.5,
            3 => {
                a2[2] = a2[0];
                b[2] = b[1];
            }
            4 => {
                let k = [1e30f32, 1e-30][rng.below(2)];
                a2 = a2.map(|v| v * k);
                b = b.map(|v| v * k);
            }
            5 => {
                let q = |v: Vec3| (v * 2.0).round() * 0.5;
                a2 = a2.map(q);
                b = b.map(q);
            }
            _ => {}
        }
        tri_tri_case(c, [a2[0], a2[1], a2[2], b[0], b[1], b[2]]);
    }
    for _ in 0..1000 {
        let t: Vec<Vec3> = (0..6).map(|_| odd_vec(&mut rng)).collect();
        tri_tri_case(c, [t[0], t[1], t[2], t[3], t[4], t[5]]);
    }

    c.label = "intersect_ray_aabb / aabb_overlap / aabb_distance_sq(_scaled)".into();
    for _ in 0..10000 {
        let (l, h) = (rng.v(-1.0, 0.0), rng.v(0.0, 1.0));
        let o = rng.v(-3.0, 3.0);
        let mut d = rng.v(-1.0, 1.0);
        if rng.below(3) == 0 {
            d[rng.below(3)] = if rng.below(2) == 0 { 0.0 } else { -0.0 };
        }
        ray_aabb_case(c, o, d, l, h);
        let (bl, bh) = (rng.v(-1.5, 0.5), rng.v(-0.5, 1.5));
        boxes_case(c, l, h, bl, bh, o);
    }
    for _ in 0..2000 {
        let v: Vec<Vec3> = (0..5).map(|_| odd_vec(&mut rng)).collect();
        ray_aabb_case(c, v[0], v[1], v[2], v[3]);
        boxes_case(c, v[0], v[1], v[2], v[3], v[4]);
    }
    let inf = Vec3::splat(f32::INFINITY);
    ray_aabb_case(c, Vec3::splat(-1.0), Vec3::ONE, inf, -inf);
    boxes_case(c, inf, -inf, -inf, inf, Vec3::ZERO);

    c.label = "pow2_scale".into();
    let mut specials = vec![
        0.0f32,
        -0.0,
        1.0,
        f32::MAX,
        f32::MIN_POSITIVE,
        1e-45,
        1e-40,
        f32::INFINITY,
        f32::NAN,
        -1.0,
    ];
    specials.extend((0..2000).map(|_| f32::from_bits(rng.next() as u32)));
    for m in specials {
        c.op(6).f(m);
        c.expect(format!("p2{}", hf(pow2_scale(m))));
    }
}

// ----- BVH -----

fn random_boxes(rng: &mut Rng, n: usize, extent: f32, size: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    let (mut lo, mut hi) = (Vec::new(), Vec::new());
    for _ in 0..n {
        let c = rng.v(-extent, extent);
        let h = rng.v(0.0, size);
        lo.push(c - h);
        hi.push(c + h);
    }
    (lo, hi)
}

fn bvh_load(c: &mut Cases, t: &Tree, lowers: &[Vec3], uppers: &[Vec3]) {
    c.op(10);
    c.tree(t);
    for v in lowers.iter().chain(uppers) {
        c.v(*v);
    }
    c.expect("bvh".into());
}

/// Runs an iterating query to its end (or a fault) the way the driver does, into a line.
fn iterate<Q: Copy>(
    tag: &str,
    mut q: Q,
    next: impl Fn(Q) -> KResult<Q>,
    done: impl Fn(Q) -> bool,
    item: impl Fn(Q) -> i32,
    check_done: bool,
) -> String {
    let mut s = tag.to_string();
    let mut n = 0;
    loop {
        match next(q) {
            Err(e) => {
                s += &hfault(&e);
                return s;
            }
            Ok(nq) => q = nq,
        }
        if done(q) || n >= MAX_ITEMS {
            break;
        }
        write!(s, " {}", item(q)).unwrap();
        n += 1;
    }
    if check_done && n < MAX_ITEMS {
        match next(q) {
            Err(e) => s += &hfault(&e),
            Ok(q) => write!(s, " done{}", done(q) as i32).unwrap(),
        }
    }
    s
}

fn bvh_queries(c: &mut Cases, v: BvhView, rng: &mut Rng, n: usize, extent: f32) {
    for k in 0..n {
        let (lo, hi) = match k % 8 {
            0 => (Vec3::splat(f32::NEG_INFINITY), Vec3::splat(f32::INFINITY)),
            1 => (Vec3::NAN, Vec3::ONE),
            2 => (Vec3::ONE, -Vec3::ONE),
            _ => {
                let ctr = rng.v(-extent, extent);
                let h = rng.v(0.0, extent * 0.3);
                (ctr - h, ctr + h)
            }
        };
        c.op(11).v(lo).v(hi);
        let line = iterate(
            "qa",
            bvh_query_aabb(v, lo, hi).unwrap(),
            |q: BvhQueryAabb| bvh_query_aabb_next(v, q),
            bvh_query_aabb_done,
            bvh_query_aabb_item,
            true,
        );
        c.expect(line);
        let o = rng.v(-1.5 * extent, 1.5 * extent);
        let mut d = rng.v(-1.0, 1.0);
        match k % 6 {
            0 => d[rng.below(3)] = 0.0,
            1 => d = Vec3::ZERO,
            2 => d = Vec3::NAN,
            _ => {}
        }
        c.op(12).v(o).v(d);
        let line = iterate(
            "qr",
            bvh_query_ray(v, o, d).unwrap(),
            |q: BvhQueryRay| bvh_query_ray_next(v, q),
            bvh_query_ray_done,
            bvh_query_ray_item,
            true,
        );
        c.expect(line);
    }
}

fn bvh_view<'a>(t: &'a Tree, lowers: &'a [Vec3], uppers: &'a [Vec3]) -> BvhView {
    // SAFETY: the boxes hold one entry per primitive of `t`, alive for the caller's borrow.
    unsafe { BvhView::from_raw(t.view(), lowers.as_ptr(), uppers.as_ptr()) }
}

/// A corruption of a tree: one word of its buffers changed.
fn corrupt(t: &Tree, rng: &mut Rng) -> Tree {
    let mut t = t.clone();
    let nn = t.nodes.len() as i32;
    let np = t.prim_ids.len() as i32;
    let val = |rng: &mut Rng, n: i32| match rng.below(5) {
        0 => -1 - rng.below(3) as i32,
        1 => n + rng.below(3) as i32,
        _ => rng.below(n.max(1) as usize) as i32,
    };
    match rng.below(5) {
        0 => {
            let i = rng.below(t.nodes.len());
            t.nodes[i].left = val(rng, nn);
        }
        1 => {
            let i = rng.below(t.nodes.len());
            t.nodes[i].right = if t.nodes[i].left < 0 {
                val(rng, np + 1)
            } else {
                val(rng, nn)
            };
        }
        2 => {
            let i = rng.below(t.parents.len());
            t.parents[i] = val(rng, nn);
        }
        3 if np > 0 => {
            let i = rng.below(t.prim_ids.len());
            t.prim_ids[i] = val(rng, np);
        }
        _ => {
            let i = rng.below(t.nodes.len());
            let j = rng.below(t.nodes.len());
            t.nodes[i] = t.nodes[j];
        }
    }
    t
}

fn bvh_cases(c: &mut Cases) {
    let mut rng = Rng(0x5eed_0002);
    for (n, extent, size) in [
        (0usize, 10.0f32, 1.0f32),
        (1, 10.0, 1.0),
        (2, 10.0, 1.0),
        (7, 10.0, 1.0),
        (100, 10.0, 1.0),
        (1000, 10.0, 0.5),
        (5000, 20.0, 0.5),
        (300, 1e30, 1e29),
        (300, 1e-30, 1e-31),
    ] {
        c.label = format!("bvh of {n} boxes at {extent}");
        let (lo, hi) = random_boxes(&mut rng, n, extent, size);
        let t = Tree::sah(&lo, &hi);
        bvh_load(c, &t, &lo, &hi);
        bvh_queries(c, bvh_view(&t, &lo, &hi), &mut rng, 200, extent);
    }
    // Duplicate boxes (the builder's median fallback).
    c.label = "bvh of duplicate boxes".into();
    let (lo, hi) = (vec![Vec3::ZERO; 50], vec![Vec3::ONE; 50]);
    let t = Tree::sah(&lo, &hi);
    bvh_load(c, &t, &lo, &hi);
    bvh_queries(c, bvh_view(&t, &lo, &hi), &mut rng, 20, 1.0);

    // A caterpillar deeper than any fixed stack.
    c.label = "deep bvh".into();
    let n = 1500;
    let lo: Vec<Vec3> = (0..n).map(|i| Vec3::splat(i as f32)).collect();
    let hi: Vec<Vec3> = lo.iter().map(|x| *x + 0.5).collect();
    let deep = caterpillar(&lo, &hi);
    bvh_load(c, &deep, &lo, &hi);
    bvh_queries(c, bvh_view(&deep, &lo, &hi), &mut rng, 30, 1500.0);

    // Corrupt trees: the hand-made ones of warp-core's tests, then random ones.
    let (lo, hi) = random_boxes(&mut rng, 64, 10.0, 1.0);
    let base = Tree::sah(&lo, &hi);
    let mut bad: Vec<Tree> = Vec::new();
    let mut t = base.clone();
    t.nodes[0].right = 10_000;
    bad.push(t);
    let mut t = base.clone();
    let leaf = t.nodes.iter().position(|n| n.is_leaf()).unwrap();
    t.nodes[leaf].right = 65;
    bad.push(t);
    for id in [64, -1] {
        let mut t = base.clone();
        t.prim_ids[3] = id;
        bad.push(t);
    }
    let mut t = base.clone();
    let internal = t.nodes.iter().rposition(|n| !n.is_leaf()).unwrap();
    t.nodes[internal].left = 0;
    bad.push(t);
    // Links: every parent the root, every escape the root, the last node escaping to
    // itself, an escape outside the nodes.
    let nn = base.nodes.len();
    let mut t = base.clone();
    for p in t.parents[..nn].iter_mut().skip(1) {
        *p = 0;
    }
    bad.push(t);
    let mut t = base.clone();
    for e in t.parents[nn..].iter_mut() {
        *e = 0;
    }
    bad.push(t);
    let mut t = base.clone();
    t.parents[2 * nn - 1] = nn as i32 - 1;
    bad.push(t);
    let mut t = base.clone();
    let leaf = t.nodes.iter().position(|n| n.is_leaf()).unwrap();
    t.parents[nn + leaf] = 10_000;
    bad.push(t);
    let mut t = base.clone();
    let root = t.nodes[0];
    t.nodes.iter_mut().for_each(|n| *n = root);
    bad.push(t);
    for _ in 0..300 {
        let mut t = corrupt(&base, &mut rng);
        if rng.below(3) == 0 {
            t = corrupt(&t, &mut rng);
        }
        bad.push(t);
    }
    for (k, t) in bad.iter().enumerate() {
        c.label = format!("corrupt bvh {k}");
        bvh_load(c, t, &lo, &hi);
        bvh_queries(c, bvh_view(t, &lo, &hi), &mut rng, 6, 10.0);
    }
}

/// A caterpillar over the boxes, deeper than any fixed stack: node 2k is internal with
/// children 2k+1 (the leaf of box k) and 2k+2 (the rest); the last node is a leaf.
fn caterpillar(lo: &[Vec3], hi: &[Vec3]) -> Tree {
    let n = lo.len();
    let (mut rest_lo, mut rest_hi) = (lo.to_vec(), hi.to_vec());
    for k in (0..n.saturating_sub(1)).rev() {
        rest_lo[k] = rest_lo[k].min(rest_lo[k + 1]);
        rest_hi[k] = rest_hi[k].max(rest_hi[k + 1]);
    }
    let (mut nodes, mut parents) = (Vec::new(), Vec::new());
    for k in 0..n {
        if k + 1 < n {
            nodes.push(BvhNode::internal(
                rest_lo[k],
                rest_hi[k],
                2 * k as i32 + 1,
                2 * k as i32 + 2,
            ));
            nodes.push(BvhNode::leaf(lo[k], hi[k], k as i32, k as i32 + 1));
            parents.push(if k == 0 { -1 } else { 2 * k as i32 - 2 });
            parents.push(2 * k as i32);
        } else {
            nodes.push(BvhNode::leaf(lo[k], hi[k], k as i32, k as i32 + 1));
            parents.push(2 * k as i32 - 2);
        }
    }
    parents.extend(preorder_escapes(&nodes));
    Tree {
        nodes,
        parents,
        prim_ids: (0..n as i32).collect(),
    }
}

// ----- meshes -----

struct Mesh {
    points: Vec<Vec3>,
    velocities: Option<Vec<Vec3>>,
    indices: Vec<i32>,
    tree: Tree,
    /// The triangles in leaf order (`leaf_triangles`), as a build or refit writes them; NaN
    /// corners for a corrupt mesh's bad ids and indices. Remade by `soup` after a change.
    leaf_tris: Vec<Vec4>,
}

impl Mesh {
    fn new(points: Vec<Vec3>, indices: Vec<i32>, with_velocities: bool) -> Mesh {
        let (mut lo, mut hi) = (Vec::new(), Vec::new());
        for t in indices.chunks(3) {
            let [a, b, c] = [0, 1, 2].map(|k| points[t[k] as usize]);
            lo.push(a.min(b).min(c));
            hi.push(a.max(b).max(c));
        }
        let velocities = with_velocities.then(|| {
            points
                .iter()
                .map(|p| Vec3::new(p.y, -p.x, 2.0 * p.z))
                .collect()
        });
        let mut m = Mesh {
            tree: Tree::sah(&lo, &hi),
            points,
            velocities,
            indices,
            leaf_tris: Vec::new(),
        };
        m.soup();
        m
    }
    /// Remakes the leaf-ordered triangles from the tree, indices and points.
    fn soup(&mut self) {
        self.leaf_tris = leaf_triangles(&self.tree.prim_ids, &self.indices, &self.points);
    }
    fn view(&self) -> MeshView {
        let vel = self
            .velocities
            .as_ref()
            .map_or(std::ptr::null(), |v| v.as_ptr());
        // SAFETY: the buffers hold what the tree and the points need (indices: three per
        // face), alive for the caller's borrow of `self`.
        unsafe {
            MeshView::from_raw(
                self.tree.view(),
                self.points.as_ptr(),
                vel,
                self.points.len() as i32,
                self.indices.as_ptr(),
                self.leaf_tris.as_ptr(),
            )
        }
    }
    fn load(&self, c: &mut Cases) {
        c.op(20);
        c.tree(&self.tree);
        c.i(self.points.len() as i32);
        for p in &self.points {
            c.v(*p);
        }
        match &self.velocities {
            Some(v) => {
                c.i(1);
                for x in v {
                    c.v(*x);
                }
            }
            None => {
                c.i(0);
            }
        }
        for i in &self.indices {
            c.i(*i);
        }
        assert_eq!(self.leaf_tris.len(), self.indices.len());
        for t in &self.leaf_tris {
            for x in t.to_array() {
                c.f(x);
            }
        }
        c.expect("mesh".into());
    }
}

fn sphere(r: f32, rings: usize, segs: usize) -> (Vec<Vec3>, Vec<i32>) {
    let mut pts = vec![Vec3::new(0.0, 0.0, r)];
    for i in 1..rings {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segs {
            let ph = 2.0 * std::f32::consts::PI * j as f32 / segs as f32;
            pts.push(Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r);
        }
    }
    pts.push(Vec3::new(0.0, 0.0, -r));
    let south = pts.len() as i32 - 1;
    let at = |i: usize, j: usize| (1 + (i - 1) * segs + j % segs) as i32;
    let mut ix = Vec::new();
    for j in 0..segs {
        ix.extend([0, at(1, j), at(1, j + 1)]);
        ix.extend([south, at(rings - 1, j + 1), at(rings - 1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segs {
            ix.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            ix.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    (pts, ix)
}

fn torus(big: f32, small: f32, n: usize, m: usize) -> (Vec<Vec3>, Vec<i32>) {
    let mut pts = Vec::new();
    for i in 0..n {
        let a = 2.0 * std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..m {
            let b = 2.0 * std::f32::consts::PI * j as f32 / m as f32;
            let rr = big + small * b.cos();
            pts.push(Vec3::new(rr * a.cos(), rr * a.sin(), small * b.sin()));
        }
    }
    let at = |i: usize, j: usize| ((i % n) * m + j % m) as i32;
    let mut ix = Vec::new();
    for i in 0..n {
        for j in 0..m {
            ix.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            ix.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    (pts, ix)
}

fn patch(k: usize) -> (Vec<Vec3>, Vec<i32>) {
    let mut pts = Vec::new();
    for i in 0..=k {
        for j in 0..=k {
            pts.push(Vec3::new(
                -1.0 + 2.0 * j as f32 / k as f32,
                -1.0 + 2.0 * i as f32 / k as f32,
                0.0,
            ));
        }
    }
    let at = |i: usize, j: usize| (i * (k + 1) + j) as i32;
    let mut ix = Vec::new();
    for i in 0..k {
        for j in 0..k {
            ix.extend([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
            ix.extend([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
        }
    }
    (pts, ix)
}

fn soup(rng: &mut Rng, n: usize) -> (Vec<Vec3>, Vec<i32>) {
    let mut pts = Vec::new();
    let mut ix = Vec::new();
    for f in 0..n {
        let ctr = rng.v(-5.0, 5.0);
        for _ in 0..3 {
            pts.push(ctr + rng.v(-1.0, 1.0));
        }
        ix.extend([3 * f as i32, 3 * f as i32 + 1, 3 * f as i32 + 2]);
    }
    if n > 4 {
        pts[4] = pts[3];
        pts[8] = pts[6] + (pts[7] - pts[6]) * 0.25;
    }
    (pts, ix)
}

fn point_line(tag: &str, r: KResult<MeshQueryPoint>, adj: KResult<Vec3>) -> String {
    match r {
        Err(e) => format!("{tag}{}", hfault(&e)),
        Ok(r) => format!(
            "{tag} {}{} {}{}{} |{}",
            r.result as i32,
            hf(r.sign),
            r.face,
            hf(r.u),
            hf(r.v),
            match adj {
                Ok(v) => hv(v),
                Err(e) => hfault(&e),
            }
        ),
    }
}

fn mesh_queries(c: &mut Cases, m: &Mesh, rng: &mut Rng, n: usize, scale: f32) {
    let v = m.view();
    let npts = m.points.len();
    let nfaces = m.indices.len() / 3;
    for k in 0..n {
        // Points: random around the mesh, near and exactly on vertices, on edges.
        let p = match k % 8 {
            0 if npts > 0 => m.points[rng.below(npts)],
            1 if npts > 0 => m.points[rng.below(npts)] * 1.1,
            // Near a vertex, off in any direction: the vertex pseudonormal decides the sign
            // where the offset is nearly tangent.
            3 | 4 if npts > 0 => m.points[rng.below(npts)] + rng.v(-0.05, 0.05) * scale,
            2 if nfaces > 0 && npts > 0 => {
                let f = rng.below(nfaces);
                // Clamped: a corrupt mesh's indices may be out of range.
                let at = |k: usize| m.points[(m.indices[k].max(0) as usize).min(npts - 1)];
                let (a, b) = (at(3 * f), at(3 * f + 1));
                (a + (b - a) * 0.5) * rng.f(0.8, 1.2)
            }
            _ => rng.v(-1.5, 1.5) * scale,
        };
        let d = match k % 7 {
            0 => f32::MAX,
            1 => 0.0,
            2 => -1.0,
            3 => f32::NAN,
            4 => f32::INFINITY,
            _ => rng.f(0.0, 1.0) * scale,
        };
        let g = MeshQueryPoint {
            u: rng.f(-1.0, 1.0),
            v: rng.f(-1.0, 1.0),
            ..Default::default()
        };
        let ap0 = rng.v(-1.0, 1.0);
        type Forward = fn(MeshView, Vec3, f32) -> KResult<MeshQueryPoint>;
        type Backward = fn(
            MeshView,
            Vec3,
            f32,
            &mut MeshView,
            &mut Vec3,
            &mut f32,
            MeshQueryPoint,
        ) -> KResult<()>;
        let furthest_adj: Backward = |_, _, _, _, _, _, _| Ok(());
        // The signed queries after the furthest point's, whose rng draw the others follow.
        let queries: [(u32, &str, Forward, Backward); 5] = [
            (21, "mp", mesh_query_point, adj_mesh_query_point),
            (
                22,
                "mn",
                mesh_query_point_no_sign,
                adj_mesh_query_point_no_sign,
            ),
            (23, "mf", mesh_query_furthest_point_no_sign, furthest_adj),
            (
                27,
                "ms",
                mesh_query_point_sign_normal,
                adj_mesh_query_point_sign_normal,
            ),
            (
                28,
                "mq",
                mesh_query_point_sign_parity,
                adj_mesh_query_point_sign_parity,
            ),
        ];
        for (op, tag, fwd, bwd) in queries {
            let d = if op == 23 && k % 2 == 0 {
                rng.f(0.0, 2.0) * scale
            } else {
                d
            };
            c.op(op).v(p).f(d).f(g.u).f(g.v).v(ap0);
            let r = fwd(v, p, d);
            let adj = r.as_ref().ok().map(|_| {
                let (mut am, mut ap, mut ad) = (MeshView::empty(), ap0, 0.0f32);
                bwd(v, p, d, &mut am, &mut ap, &mut ad, g).map(|_| ap)
            });
            c.expect(point_line(tag, r, adj.unwrap_or(Ok(ap0))));
        }

        // Rays: from outside towards the mesh, through vertices, axis-aligned.
        let o = rng.v(-2.0, 2.0) * scale;
        let mut dir = match k % 5 {
            0 if npts > 0 => m.points[rng.below(npts)] - o,
            1 => {
                let mut d = Vec3::ZERO;
                d[rng.below(3)] = if rng.below(2) == 0 { 1.0 } else { -1.0 };
                d
            }
            _ => rng.v(-1.0, 1.0) * scale - o,
        };
        if k % 11 == 0 {
            dir = Vec3::ZERO;
        }
        let max_t = match k % 4 {
            0 => f32::INFINITY,
            1 => rng.f(0.0, 2.0),
            2 => f32::NAN,
            _ => f32::MAX,
        };
        c.op(24).v(o).v(dir).f(max_t);
        c.expect(match mesh_query_ray(v, o, dir, max_t) {
            Err(e) => format!("mr{}", hfault(&e)),
            Ok(r) => {
                let r: MeshQueryRay = r;
                format!(
                    "mr {}{} {}{}{}{}{}",
                    r.result as i32,
                    hf(r.sign),
                    r.face,
                    hf(r.t),
                    hf(r.u),
                    hf(r.v),
                    hv(r.normal)
                )
            }
        });

        // Boxes.
        let ctr = rng.v(-1.2, 1.2) * scale;
        let h = rng.v(0.0, 0.4) * scale;
        let (lo, hi) = if k % 9 == 0 {
            (Vec3::splat(f32::NEG_INFINITY), Vec3::splat(f32::INFINITY))
        } else {
            (ctr - h, ctr + h)
        };
        c.op(25).v(lo).v(hi);
        let line = iterate(
            "ma",
            mesh_query_aabb(v, lo, hi).unwrap(),
            |q: MeshQueryAabb| mesh_query_aabb_next(v, q),
            mesh_query_aabb_done,
            mesh_query_aabb_item,
            false,
        );
        c.expect(line);

        // Evaluation, valid and invalid faces.
        let face = match k % 8 {
            0 => -1,
            1 => nfaces as i32,
            2 => nfaces as i32 + 3,
            _ => rng.below(nfaces.max(1)) as i32,
        };
        let (u, w) = (rng.f(-0.2, 1.0), rng.f(-0.2, 1.0));
        let gr = rng.v(-1.0, 1.0);
        let (au0, av0) = (rng.f(-1.0, 1.0), rng.f(-1.0, 1.0));
        c.op(26).i(face).f(u).f(w).v(gr).f(au0).f(av0);
        let opt = |r: KResult<Vec3>| match r {
            Ok(x) => hv(x),
            Err(e) => hfault(&e),
        };
        type Adj = fn(
            MeshView,
            i32,
            f32,
            f32,
            &mut MeshView,
            &mut i32,
            &mut f32,
            &mut f32,
            Vec3,
        ) -> KResult<()>;
        let adj = |f: Adj| {
            let (mut am, mut af, mut au, mut av) = (MeshView::empty(), 0i32, au0, av0);
            match f(v, face, u, w, &mut am, &mut af, &mut au, &mut av, gr) {
                Ok(()) => format!("{}{}", hf(au), hf(av)),
                Err(e) => hfault(&e),
            }
        };
        c.expect(format!(
            "me{} |{} |{} |{} |{}",
            opt(mesh_eval_position(v, face, u, w)),
            opt(mesh_eval_velocity(v, face, u, w)),
            opt(mesh_eval_face_normal(v, face)),
            adj(adj_mesh_eval_position::<i32>),
            adj(adj_mesh_eval_velocity::<i32>),
        ));
    }
    // The parity's ray along the edges and through the vertices: starts a little back from a
    // vertex or an edge's midpoint along the ray's direction.
    let mut prng = Rng(0x5eed_0005 ^ n as u64);
    for k in 0..n / 2 {
        if npts == 0 || nfaces == 0 {
            break;
        }
        let f = prng.below(nfaces);
        let at = |k: usize| m.points[(m.indices[k].max(0) as usize).min(npts - 1)];
        let (a, b) = (at(3 * f), at(3 * f + 1));
        let target = if k % 2 == 0 { a } else { a + (b - a) * 0.5 };
        let p = target - PARITY_DIR * (prng.f(0.0, 2.0) * scale);
        c.op(28).v(p).f(f32::MAX).f(0.5).f(-0.5).v(Vec3::ZERO);
        let g = MeshQueryPoint {
            u: 0.5,
            v: -0.5,
            ..Default::default()
        };
        let r = mesh_query_point_sign_parity(v, p, f32::MAX);
        let adj = r.as_ref().ok().map(|_| {
            let (mut am, mut ap, mut ad) = (MeshView::empty(), Vec3::ZERO, 0.0f32);
            adj_mesh_query_point_sign_parity(v, p, f32::MAX, &mut am, &mut ap, &mut ad, g)
                .map(|_| ap)
        });
        c.expect(point_line("mq", r, adj.unwrap_or(Ok(Vec3::ZERO))));
    }
}

fn mesh_cases(c: &mut Cases) {
    let mut rng = Rng(0x5eed_0003);
    let mut meshes: Vec<(String, Mesh, f32)> = Vec::new();
    for (n, vel) in [(1usize, true), (5, false), (300, true)] {
        let (p, ix) = soup(&mut rng, n);
        meshes.push((format!("soup of {n}"), Mesh::new(p, ix, vel), 6.0));
    }
    let (p, ix) = sphere(1.0, 24, 32);
    meshes.push(("sphere".into(), Mesh::new(p, ix, true), 1.0));
    let (p, ix) = torus(1.0, 0.3, 40, 16);
    meshes.push(("torus".into(), Mesh::new(p, ix, false), 1.3));
    let (p, ix) = patch(8);
    meshes.push(("patch".into(), Mesh::new(p, ix, true), 1.0));
    let (p, ix) = sphere(1e30, 12, 16);
    meshes.push(("sphere at 1e30".into(), Mesh::new(p, ix, false), 1e30));
    let (p, ix) = sphere(1e-30, 12, 16);
    meshes.push(("sphere at 1e-30".into(), Mesh::new(p, ix, false), 1e-30));
    meshes.push((
        "empty mesh".into(),
        Mesh::new(Vec::new(), Vec::new(), true),
        1.0,
    ));
    // A strip of 120 triangles along the diagonal under a caterpillar tree: the ordered
    // walks' stack overflows and the dropped entries are found by climbing.
    let mut p = Vec::new();
    for k in 0..120 {
        let a = Vec3::splat(k as f32 * 0.02 - 1.2);
        p.extend([
            a,
            a + Vec3::new(0.015, 0.0, 0.0),
            a + Vec3::new(0.0, 0.015, 0.005),
        ]);
    }
    let ix: Vec<i32> = (0..p.len() as i32).collect();
    let mut deep = Mesh::new(p, ix, false);
    let (lo, hi): (Vec<Vec3>, Vec<Vec3>) = deep
        .indices
        .chunks(3)
        .map(|t| {
            let [a, b, cc] = [0, 1, 2].map(|k| deep.points[t[k] as usize]);
            (a.min(b).min(cc), a.max(b).max(cc))
        })
        .unzip();
    deep.tree = caterpillar(&lo, &hi);
    deep.soup();
    meshes.push(("deep strip".into(), deep, 1.3));
    for (name, m, scale) in &meshes {
        c.label = format!("mesh {name}");
        m.load(c);
        mesh_queries(c, m, &mut rng, 300, *scale);
    }

    // Corrupt meshes: bad vertex indices, then corrupt trees.
    let (p, ix) = sphere(1.0, 8, 8);
    let base = Mesh::new(p, ix, true);
    for k in 0..60 {
        c.label = format!("corrupt mesh {k}");
        let mut m = Mesh {
            points: base.points.clone(),
            velocities: base.velocities.clone(),
            indices: base.indices.clone(),
            tree: base.tree.clone(),
            leaf_tris: Vec::new(),
        };
        if k % 2 == 0 {
            let i = rng.below(m.indices.len());
            m.indices[i] = if rng.below(2) == 0 {
                -1
            } else {
                m.points.len() as i32 + rng.below(3) as i32
            };
        } else {
            m.tree = corrupt(&m.tree, &mut rng);
        }
        // As a refit would write it (the runtime refuses a bad index at a CPU refit; a GPU's
        // writes NaN corners): the walks read the copy, the box query and evaluations the
        // indices.
        m.soup();
        m.load(c);
        mesh_queries(c, &m, &mut rng, 12, 1.0);
    }
}

fn layout_case(c: &mut Cases) {
    use std::mem::{offset_of, size_of};
    c.label = "layout".into();
    c.op(0);
    c.expect(format!(
        "layout {} {} {} {} {} {} {} {} {} {} {} {} {} {}",
        size_of::<BvhNode>(),
        size_of::<BvhQueryAabb>(),
        size_of::<BvhQueryRay>(),
        size_of::<MeshQueryAabb>(),
        size_of::<TriangleClosestPoint>(),
        size_of::<RayTriangleHit>(),
        size_of::<MeshQueryPoint>(),
        offset_of!(MeshQueryPoint, face),
        offset_of!(MeshQueryPoint, v),
        size_of::<MeshQueryRay>(),
        offset_of!(MeshQueryRay, t),
        offset_of!(MeshQueryRay, normal),
        offset_of!(RayTriangleHit, sign),
        offset_of!(TriangleClosestPoint, feature),
    ));
}

#[test]
fn cuda_geometry_bvh_mesh_match_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_geometry_bvh_mesh_match_warp_core_bit_for_bit: no g++");
        return;
    }
    let mut c = Cases::default();
    layout_case(&mut c);
    geometry_cases(&mut c);
    bvh_cases(&mut c);
    mesh_cases(&mut c);

    let (dir, exe) = host_cpp::compile_driver("cuda_geometry", DRIVER, &[]);
    let input = dir.join("cases.bin");
    let bytes: Vec<u8> = c.words.iter().flat_map(|w| w.to_le_bytes()).collect();
    std::fs::write(&input, bytes).unwrap();
    let run = Command::new(&exe).arg(&input).output().unwrap();
    assert!(
        run.status.success(),
        "driver: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = String::from_utf8(run.stdout).unwrap();
    let got: Vec<&str> = text.lines().collect();
    assert_eq!(got.len(), c.want.len(), "one line per case");
    let mut bad = Vec::new();
    for (k, (g, w)) in got.iter().zip(&c.want).enumerate() {
        if g != w {
            bad.push(format!(
                "case {k} ({}):\n  C++:  {}\n  Rust: {}",
                c.what[k],
                &g[..g.len().min(400)],
                &w[..w.len().min(400)]
            ));
        }
    }
    let faults = c.want.iter().filter(|l| l.contains(" F ")).count();
    eprintln!(
        "{} cases ({} with a fault), {} mismatches",
        c.want.len(),
        faults,
        bad.len()
    );
    assert!(
        bad.is_empty(),
        "{} of {} cases differ:\n{}",
        bad.len(),
        c.want.len(),
        bad[..bad.len().min(20)].join("\n")
    );
    assert!(faults > 200, "too few fault cases: {faults}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// NVRTC accepts the headers, every function instantiated in a kernel (forward and adjoint),
/// for sm_90 and sm_80 with `--fmad=false`: needs libnvrtc, no GPU; skipped, saying so,
/// without it.
#[test]
fn nvrtc_compiles_the_geometry_headers() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED nvrtc_compiles_the_geometry_headers: {e}");
        return;
    }
    let source = r#"
#define WP_ADJOINT_UNIT 1
#include "wp_core.h"
#include "wp_scalar.h"
#include "wp_vector.h"
#include "wp_geometry.h"
#include "wp_bvh.h"
#include "wp_mesh.h"
#include "wp_adjoint_core.h"
#include "wp_adjoint_geometry.h"
#include "wp_adjoint_mesh.h"
extern "C" __global__ void geometry_all(wp::bvh_t bvh, wp::mesh_t mesh, wp::Vec3* out,
                                        wp::i32* iout, wp::fault_t* fault, wp::u32* flag) {
  using namespace wp;
  launch_ctx_t rec = launch_ctx_make(fault, flag);
  ctx_t c = ctx_make(&rec);
  const Vec3 p = out[threadIdx.x], d = out[threadIdx.x + 1];
  triangle_closest_point_t r = closest_point_triangle(p, d, p + d, d - p);
  const triangle_closest_point_t rs = closest_point_triangle_scaled(p, d, d - p);
  ray_triangle_hit_t h = intersect_ray_triangle(p, d, p, d, p + d);
  f32 t = 0.0f;
  bool b = intersect_tri_tri(p, d, p, d, p, d) && aabb_overlap(p, d, p, d) &&
           intersect_ray_aabb(p, ray_inv_dir(d), p, d, &t);
  Vec3 ap = Vec3_ZERO(), aa = ap, ab = ap, ac = ap;
  adj_closest_point_triangle(p, d, p, d, aa, ab, ac, ap, r);
  i32 n = 0;
  bvh_query_aabb_t qa = bvh_query_aabb(bvh, p, d, &c);
  for (qa = bvh_query_aabb_next(bvh, qa, &c); !bvh_query_aabb_done(qa) && !c.raised;
       qa = bvh_query_aabb_next(bvh, qa, &c))
    n += bvh_query_aabb_item(qa);
  bvh_query_ray_t qr = bvh_query_ray(bvh, p, d, &c);
  for (qr = bvh_query_ray_next(bvh, qr, &c); !bvh_query_ray_done(qr) && !c.raised;
       qr = bvh_query_ray_next(bvh, qr, &c))
    n += bvh_query_ray_item(qr);
  mesh_query_aabb_t qm = mesh_query_aabb(mesh, p, d, &c);
  for (qm = mesh_query_aabb_next(mesh, qm, &c); !mesh_query_aabb_done(qm) && !c.raised;
       qm = mesh_query_aabb_next(mesh, qm, &c))
    n += mesh_query_aabb_item(qm);
  mesh_query_point_t m1 = mesh_query_point(mesh, p, 1.0f, &c);
  mesh_query_point_t m2 = mesh_query_point_no_sign(mesh, p, 1.0f, &c);
  mesh_query_point_t m3 = mesh_query_furthest_point_no_sign(mesh, p, 0.0f, &c);
  mesh_query_ray_t mr = mesh_query_ray(mesh, p, d, 1e30f, &c);
  Vec3 e = mesh_eval_position(mesh, n, 0.25f, 0.5f, &c) + mesh_eval_velocity(mesh, (u64)n, 0.25f, 0.5f, &c) +
           mesh_eval_face_normal(mesh, (i64)n, &c);
  mesh_t am = adj_zero<mesh_t>();
  f32 ad = 0.0f, au = 0.0f, av = 0.0f;
  i32 af = 0;
  adj_mesh_query_point(mesh, p, 1.0f, am, ap, ad, m1, &c);
  adj_mesh_query_point_no_sign(mesh, p, 1.0f, am, ap, ad, m2, &c);
  adj_mesh_query_furthest_point_no_sign(mesh, p, 1.0f, am, ap, ad, m3, &c);
  adj_mesh_eval_position(mesh, n, 0.25f, 0.5f, am, af, au, av, e, &c);
  adj_mesh_eval_velocity(mesh, n, 0.25f, 0.5f, am, af, au, av, e, &c);
  mesh_query_point_t zm = adj_zero<mesh_query_point_t>();
  adj_accum(zm, m1);
  mesh_query_ray_t zr = zero_like(mr);
  adj_accum(zr, mr);
  triangle_closest_point_t zt = adj_zero<triangle_closest_point_t>();
  adj_accum(zt, r);
  bvh_query_aabb_t zq = adj_zero<bvh_query_aabb_t>();
  adj_accum(zq, qa);
  out[threadIdx.x] = e + ap + mr.normal + Vec3_splat(h.t + t + zm.u + zr.t + zt.u + au + av + ad +
                                                     rs.v + aabb_distance_sq_scaled(p, d, e, 2.0f));
  iout[threadIdx.x] = n + (int)b + zq.walk.item;
}
"#;
    let headers: Vec<(&str, &str)> = warp_cuda::HEADERS.to_vec();
    for arch in [90, 80] {
        let opts = warp_cuda::CompileOptions {
            fmad: false,
            headers: &headers,
            ..Default::default()
        };
        let c = warp_cuda::compile(source, "geometry_all.cu", &opts, arch)
            .unwrap_or_else(|e| panic!("sm_{arch}: {e}"));
        assert!(!c.cubin.is_empty());
        assert!(!c.log.contains("warning"), "sm_{arch}: {}", c.log);
    }
}
