//! `-Δu = f` with P1 finite elements on the unit square (triangles) and the unit cube (six
//! tetrahedra per cell), and with `--elasticity` linear elasticity on the tetrahedra (3 x 3
//! blocks): assembled from triplets in kernels, solved by the sparse tier's captured CG with
//! Jacobi, measured against a manufactured solution.
//!
//! ```text
//! cargo run --release --example fem_poisson -- [--device cpu|cuda:0] [--levels N]
//!     [--levels-3d N] [--elasticity] [--rtol 1e-10] [--max-iter N] [--plot-dir DIR]
//! ```
//! The exact solution is `u = Π sin(π x_i)` (elasticity: `(1, -1/2, 1/4) u` with λ = μ = 1),
//! zero on the boundary. Level `k` has `h = 1/(8·2^k)`. Each element's stiffness (3 x 3 or
//! 4 x 4 triplets, elasticity 16 blocks) and load come from a kernel; `Bsr::from_triplets`
//! sums them (triplets touching a boundary node dropped, the boundary rows the identity's,
//! so `A` stays symmetric); CG with (block) Jacobi runs as one captured graph
//! (`Mode::Graph`, on the CPU a recorded loop). Per level it prints the unknowns, the L2
//! error (quadrature per element) beside the nodal interpolant's, the observed order
//! `log2(e_h / e_{h/2})`, the CG iterations, the assembly and solve times and the solve time
//! per unknown; the plot `<plot-dir>/fem_poisson.svg` (or `fem_elasticity.svg`) is error
//! against run time. It exits with status 1 unless every solve converged and the order is at
//! least 1.9 between the three finest levels of each problem (P1's L2 order is 2).

mod common;
#[path = "common/fem.rs"]
mod fem;

use clap::Parser;
use fem::{Level, Problem};
use warp_lang as wp;
use warp_report::frame::{Frame, Lines, TriMesh};
use warp_report::{sci, Run, Sweep, Table};
// `fem` reaches the sparse tier as `super::sparse`.
use wp::sparse;

/// P1 finite elements for Poisson's equation (2-D, 3-D) and linear elasticity (3-D): L2 error,
/// observed order, CG iterations and times per level.
#[derive(Parser)]
struct Cli {
    /// 2-D levels, h = 1/8, 1/16, .. [default: 9 on a GPU (to h = 1/2048), 5 on the CPU (to 1/128)]
    #[arg(long, value_name = "N", value_parser = common::num::<u32>)]
    levels: Option<u32>,
    /// 3-D levels, h = 1/8, 1/16, .. [default: 5 on a GPU (to h = 1/128), 3 on the CPU (to 1/32)]
    #[arg(long, value_name = "N", value_parser = common::num::<u32>)]
    levels_3d: Option<u32>,
    /// Solve linear elasticity on the tetrahedra (3 x 3 blocks) instead of Poisson's equation
    #[arg(long)]
    elasticity: bool,
    /// CG's relative tolerance |r| <= rtol |b|
    #[arg(long, default_value_t = 1e-10)]
    rtol: f64,
    /// CG's iteration limit
    #[arg(long, default_value_t = 100_000, value_parser = common::num::<usize>)]
    max_iter: usize,
    #[command(flatten)]
    scene: common::SceneArgs,
}

/// The smallest order accepted between the finest three levels.
const MIN_ORDER: f64 = 1.9;

/// Runs the levels of `problem`, prints their table and returns whether the finest three
/// levels show order >= MIN_ORDER and every solve converged, and the levels.
fn run(
    problem: Problem,
    levels: u32,
    cli: &Cli,
    sweep: &mut Sweep,
    dev: &wp::Device,
) -> wp::Result<(bool, Vec<Level>)> {
    let options = fem::options(cli.rtol, cli.max_iter);
    // Warm-up (loads the kernels on a GPU) outside the timings.
    fem::solve_level(problem, 2, &options, dev)?;
    let mut rows: Vec<Level> = Vec::new();
    for k in 0..levels {
        // 8 << k, refused by solve_level long before it overflows.
        let n = 8usize.saturating_mul(1 << k.min(40));
        let level = fem::solve_level(problem, n, &options, dev)?;
        let seconds = level.assembly_s + level.solve_s;
        sweep.record(
            problem.name(),
            1.0 / n as f64,
            Run::stable(level.iterations as u64, level.error, seconds),
        );
        rows.push(level);
    }
    sweep.finish();
    let mut t = Table::new(vec![
        "h",
        "unknowns",
        "blocks",
        "L2 error",
        "interpolant's",
        "order",
        "CG iterations",
        "stop",
        "assembly (ms)",
        "solve (ms)",
        "solve ns/unknown",
    ]);
    for (i, l) in rows.iter().enumerate() {
        let ord = if i == 0 {
            "-".to_string()
        } else {
            format!("{:.3}", fem::order(rows[i - 1].error, l.error))
        };
        t.push(vec![
            format!("1/{}", l.n),
            l.unknowns.to_string(),
            l.nnz.to_string(),
            sci(l.error),
            sci(l.interp_error),
            ord,
            l.iterations.to_string(),
            format!("{:?}", l.stop),
            format!("{:.2}", l.assembly_s * 1e3),
            format!("{:.2}", l.solve_s * 1e3),
            format!("{:.1}", l.solve_s * 1e9 / l.unknowns as f64),
        ]);
    }
    println!(
        "\n{} on \"{dev}\": P1 elements, CG + Jacobi (captured) to rtol {}\n\n{t}",
        problem.name(),
        sci(cli.rtol)
    );
    let converged = rows.iter().all(|l| l.stop == sparse::Stop::Converged);
    if rows.len() < 3 {
        println!("{}: fewer than 3 levels: no order to judge", problem.name());
        return Ok((false, rows));
    }
    let finest = &rows[rows.len() - 3..];
    let orders: Vec<f64> = finest
        .windows(2)
        .map(|w| fem::order(w[0].error, w[1].error))
        .collect();
    let ok = converged && orders.iter().all(|&o| o >= MIN_ORDER);
    println!(
        "{}: order between the finest three levels {} (>= {MIN_ORDER}: {}), every solve \
         converged: {}",
        problem.name(),
        orders
            .iter()
            .map(|o| format!("{o:.3}"))
            .collect::<Vec<_>>()
            .join(", "),
        if orders.iter().all(|&o| o >= MIN_ORDER) {
            "yes"
        } else {
            "NO"
        },
        if converged { "yes" } else { "NO" }
    );
    Ok((ok, rows))
}

/// The picture: the 2-D solution as a height field over the square (Poisson), or the cube's
/// mid-plane displaced by the elastic solution (elasticity), at the finest level of at most
/// 32 (16) cells per side.
fn frame(levels: &[Level]) -> wp::Result<Option<Frame>> {
    let elastic = levels.iter().any(|l| l.problem == Problem::Elasticity);
    let (shown, most) = if elastic {
        (Problem::Elasticity, 16)
    } else {
        (Problem::Poisson2, 32)
    };
    let Some(l) = levels
        .iter()
        .filter(|l| l.problem == shown && l.n <= most)
        .max_by_key(|l| l.n)
    else {
        return Ok(None);
    };
    let (n, x) = (l.n, l.x.to_vec()?);
    let h = 1.0 / n as f64;
    if !elastic {
        let m = n + 1;
        let points: Vec<[f64; 3]> = (0..m * m)
            .map(|i| [(i % m) as f64 * h, (i / m) as f64 * h, 0.5 * x[i]])
            .collect();
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let c = i + m * j;
                tris.push([c, c + 1, c + 1 + m]);
                tris.push([c, c + 1 + m, c + m]);
            }
        }
        let camera = common::camera([0.0; 3], [1.0, 1.0, 0.5], [1.2, -1.5, 1.3], [0.0, 0.0, 1.0]);
        let frame = Frame::new(
            format!("fem_poisson: the P1 solution of -Δu = 2π² sin(πx) sin(πy), h = 1/{n}"),
            camera,
        )
        .note(format!(
            "height 0.5 u_h over the unit square; L2 error {} (the interpolant's {})",
            sci(l.error),
            sci(l.interp_error)
        ))
        .mesh(TriMesh::new(points, tris).colour([90, 140, 200]));
        return Ok(Some(frame));
    }
    // The mid-plane z = 1/2 (n is even) displaced by 0.5 u_h (|u| is at most about 1.15).
    let m = n + 1;
    let scale = 0.5;
    let k = n / 2;
    let mut points = Vec::new();
    for j in 0..m {
        for i in 0..m {
            let node = i + m * (j + m * k);
            let g = [i as f64 * h, j as f64 * h, k as f64 * h];
            points.push([
                g[0] + scale * x[3 * node],
                g[1] + scale * x[3 * node + 1],
                g[2] + scale * x[3 * node + 2],
            ]);
        }
    }
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let c = i + m * j;
            tris.push([c, c + 1, c + 1 + m]);
            tris.push([c, c + 1 + m, c + m]);
        }
    }
    let camera = common::camera([0.0; 3], [1.0; 3], [1.3, -1.6, 1.1], [0.0, 0.0, 1.0]);
    let frame = Frame::new(
        format!("fem_poisson --elasticity: the cube's mid-plane z = 1/2 displaced by 0.5 u_h, h = 1/{n}"),
        camera,
    )
    .note(format!(
        "u = (1, -1/2, 1/4) sin(πx) sin(πy) sin(πz), λ = μ = 1; L2 error {} (the interpolant's {})",
        sci(l.error),
        sci(l.interp_error)
    ))
    .lines(Lines::bounding_box([0.0; 3], [1.0; 3]).colour([150, 150, 150]))
    .mesh(TriMesh::new(points, tris).colour([200, 120, 80]));
    Ok(Some(frame))
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let gpu = dev.is_cuda();
    let levels_2d = cli.levels.unwrap_or(if gpu { 9 } else { 5 });
    let levels_3d = cli.levels_3d.unwrap_or(if gpu { 5 } else { 3 });
    let (name, problems) = if cli.elasticity {
        ("fem_elasticity", vec![(Problem::Elasticity, levels_3d)])
    } else {
        (
            "fem_poisson",
            vec![
                (Problem::Poisson2, levels_2d),
                (Problem::Poisson3, levels_3d),
            ],
        )
    };
    let mut sweep = Sweep::new(
        format!("{name}: L2 error against run time (assembly + solve) on {dev}"),
        "h",
    )
    .progress(problems.iter().map(|&(_, l)| l as u64).sum());
    let mut pass = true;
    let mut all = Vec::new();
    for &(problem, levels) in &problems {
        if levels == 0 {
            // `--levels 0` or `--levels-3d 0` leaves that problem out rather than failing it.
            println!("\n{}: no levels asked for, left out", problem.name());
            continue;
        }
        let (ok, rows) = run(problem, levels, &cli, &mut sweep, &dev)?;
        pass &= ok;
        all.extend(rows);
    }
    common::write_plot(name, |path| {
        sweep.write_svg(path).map_err(|e| e.to_string())
    });
    if let Some(frame) = frame(&all)? {
        common::write_frame(name, &frame);
        cli.scene.record_last(name, &frame);
    }
    common::print_compiled();
    println!(
        "\n{name}: {}",
        if pass {
            "pass (order >= 1.9 between the finest three levels, every solve converged)"
        } else {
            "FAIL"
        }
    );
    if !pass {
        std::process::exit(1);
    }
    Ok(())
}
