//! The CUDA tile conversions (`wp_tile.h`'s `tile_full`, `tile_astype`, `tile_reshape`,
//! `tile_diag_add`, and `wp_adjoint_tile.h`'s `adj_tile_reshape`, `adj_tile_diag_add`,
//! `adj_tile_astype`, `adj_tile_full`), checked
//! without a GPU against warp-core bit for bit: a driver
//! (`warp-cuda/cuda/tests/wp_tile_convert_driver.cpp`) runs them in one block under the block
//! emulator for block sizes 1, 5, 32 and 256. The values test `as`'s meaning in `tile_astype`
//! (NaN to 0, saturation at the i32 range, truncation toward zero) and `-0.0` off the diagonal
//! of `tile_diag_add`. What only hardware shows (NVRTC's acceptance) is the suite's
//! `tile_convert` tests' on a GPU.
//!
//! Skipped, saying so, without g++.

#[path = "common/host_cpp.rs"]
mod host_cpp;

use std::process::Command;
use warp_core::tile::{self, adjoint, Tile, Tile1, Tile2};

fn bytes<X: Tile>(t: &X) -> Vec<u8>
where
    X::Elem: bytemuck::Pod,
{
    bytemuck::cast_slice(t.as_flat()).to_vec()
}

#[test]
fn conversions_match_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_tile_convert_host: no g++ on this machine");
        return;
    }
    let mut xd: [f32; 24] = std::array::from_fn(|k| k as f32 * 0.75 - 7.3);
    xd[1] = f32::NAN;
    xd[2] = 3e9;
    xd[3] = -3e9;
    xd[8] = -0.0;
    let x = Tile2::<f32, 4, 6> {
        data: std::array::from_fn(|i| std::array::from_fn(|j| xd[i * 6 + j])),
    };
    let d = Tile1::<f32, 4> {
        data: [1.5, -2.0, 0.25, 1e-3],
    };
    let sqr = Tile2::<f32, 4, 4> {
        data: std::array::from_fn(|i| std::array::from_fn(|j| x.data[i][j])),
    };
    let row = Tile2::<f32, 1, 6> { data: [x.data[1]] };
    let (mut adj_re, mut adj_a, mut adj_d) = (
        Tile2::<f32, 6, 4>::zeros(),
        Tile2::<f32, 4, 4>::zeros(),
        Tile1::<f32, 4>::zeros(),
    );
    let re: Tile2<f32, 6, 4> = tile::reshape22(&x);
    // `tile_astype`'s adjoint from the f64 tile converts back; from the integer one, nothing.
    let (mut adj_w, mut adj_i) = (Tile2::<f32, 4, 6>::zeros(), Tile2::<f32, 4, 6>::zeros());
    adjoint::adj_tile_astype(&x, &mut adj_w, &x.map(|v| v as f64), 1);
    adjoint::adj_tile_astype(&x, &mut adj_i, &x.map(|v| v as i32), 1);
    adjoint::adj_tile_reshape(&re, &mut adj_re, &x, 1);
    adjoint::adj_tile_diag_add(&sqr, &d, &mut adj_a, &mut adj_d, &sqr, 1);
    let want = [
        bytes(&Tile2::<f32, 4, 6>::splat(2.5)),
        bytes(&x.map(|v| v as i32)),
        bytes(&x.map(|v| v as f64)),
        bytes(&re),
        bytes(&tile::reshape21::<f32, 1, 6, 6>(&row)),
        bytes(&tile::diag_add(&sqr, &d)),
        bytes(&adj_re),
        bytes(&adj_a),
        bytes(&adj_d),
        bytes(&adj_w),
        bytes(&adj_i),
    ]
    .concat();
    let mut input = bytes(&x);
    input.extend(bytes(&d));
    let hex: String = input.iter().map(|b| format!("{b:02x}")).collect();
    for bd in [1, 5, 32, 256] {
        // `tile_full`'s value: a block total, in the order for this block size.
        let mut gx = 0.25f32;
        adjoint::adj_tile_full(2.5f32, &mut gx, &d, bd);
        let mut want = want.clone();
        want.extend(gx.to_ne_bytes());
        let (dir, exe) = host_cpp::compile_driver(
            &format!("tile_convert_{bd}"),
            include_str!("../warp-cuda/cuda/tests/wp_tile_convert_driver.cpp"),
            &[&format!("WP_TILE_BLOCK_DIM={bd}")],
        );
        let path = dir.join("script.txt");
        std::fs::write(&path, format!("run convert {hex}\n")).unwrap();
        let out = Command::new(&exe).arg(&path).output().unwrap();
        assert!(
            out.status.success(),
            "driver (block size {bd}): {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).unwrap();
        let line = text.trim().strip_prefix("out ").expect("an out line");
        let got: Vec<u8> = (0..line.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&line[i..i + 2], 16).unwrap())
            .collect();
        assert_eq!(got.len(), want.len(), "block size {bd}: output length");
        assert!(
            got == want,
            "block size {bd}: the CUDA conversions differ from warp-core"
        );
    }
}
