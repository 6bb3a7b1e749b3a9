use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn density(grid: HashGrid, x: Array<Vec3>, r: f32, rho: Array<f32>) {
    let i = tid();
    for j in hash_grid_query(grid, x[i], r) {
        rho[i] += 1.0 - length(x[j] - x[i]) / r;
    }
}

// A query is iterated where it is made; its grid is a HashGrid, not an array.
#[wp::kernel]
fn misuse(grid: HashGrid, x: Array<Vec3>, out: Array<i32>) {
    let i = tid();
    let q = hash_grid_query(grid, x[i], 1.0);
    for j in hash_grid_query(x, x[i], 1.0) {}
    out[i] = hash_grid_point_id(grid, 0.5) as i32;
}

fn main() -> wp::Result<()> {
    let dev = wp::cpu();
    let x = wp::Array::<Vec3>::zeros(4, &dev)?;
    let rho = wp::Array::<f32>::zeros(4, &dev)?;
    let mut grid = wp::HashGrid::new(8, 8, 8, &dev)?;
    grid.build(&x, 0.5)?;
    // The points where the kernel takes the grid.
    wp::launch(density, 4, (&x, &x, 0.5, &rho), &dev)?;
    // The grid by value.
    wp::launch(density, 4, (grid, &x, 0.5, &rho), &dev)?;
    Ok(())
}
