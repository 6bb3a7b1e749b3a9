use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn closest(mesh: Mesh, q: Array<Vec3>, out: Array<Vec3>) {
    let i = tid();
    let (found, _sign, face, u, v) = mesh_query_point(mesh, q[i], 1.0);
    if found {
        out[i] = mesh_eval_position(mesh, face, u, v);
    }
}

// A mesh query takes a Mesh, not a Bvh; a point query's result is a tuple of five; a box
// query is iterated where it is made.
#[wp::kernel]
fn misuse(mesh: Mesh, bvh: Bvh, q: Array<Vec3>, out: Array<i32>) {
    let i = tid();
    let (found, face) = mesh_query_point(mesh, q[i], 1.0);
    let r = mesh_query_point_no_sign(bvh, q[i], 1.0);
    let s = bvh_query_aabb(bvh, q[i], q[i]);
    out[i] = face;
}

fn main() -> wp::Result<()> {
    let dev = wp::cpu();
    let points = wp::Array::from_slice(&[Vec3::ZERO, Vec3::X, Vec3::Y], &dev)?;
    let indices = wp::Array::from_slice(&[0, 1, 2], &dev)?;
    let mesh = wp::Mesh::new(&points, &indices, None)?;
    let bvh = wp::Bvh::new(&points, &points)?;
    // A Bvh where the kernel takes a Mesh.
    wp::launch(closest, 1, (&bvh, &points, &points), &dev)?;
    // The mesh by value.
    wp::launch(closest, 1, (mesh, &points, &points), &dev)?;
    Ok(())
}
