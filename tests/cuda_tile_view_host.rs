//! The CUDA windows of tiles (`wp_tile.h`'s `tile_view` and `tile_window`, and
//! `wp_adjoint_tile.h`'s `adj_tile_view*`, `adj_tile_assign2`, `adj_tile_add_inplace2`,
//! `adj_tile_sub_inplace2`), checked without a GPU against warp-core bit for bit: a driver
//! (`warp-cuda/cuda/tests/wp_tile_view_driver.cpp`) runs them in one block under the block
//! emulator for block sizes 1, 5, 32 and 256, including a view outside the tile (zeros and a
//! `TileIndex` fault with the same index and shape as warp-core's). What only hardware shows
//! (NVRTC's acceptance) is the suite's `tile_views` tests' on a GPU.
//!
//! Skipped, saying so, without g++.

#[path = "common/host_cpp.rs"]
mod host_cpp;

use std::process::Command;
use warp_core::tile::view::op;
use warp_core::tile::{self, adjoint, Tile, Tile1, Tile2};
use warp_core::FaultKind;

fn bytes<X: Tile>(t: &X) -> Vec<u8>
where
    X::Elem: bytemuck::Pod,
{
    bytemuck::cast_slice(t.as_flat()).to_vec()
}

#[test]
fn windows_match_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_tile_view_host: no g++ on this machine");
        return;
    }
    let x = Tile2::<f32, 4, 6> {
        data: std::array::from_fn(|i| std::array::from_fn(|j| (i * 6 + j) as f32 * 0.37 - 2.1)),
    };
    let s = Tile2::<f32, 2, 3> {
        data: [[1.5, -0.25, 3.0], [0.1, -7.5, 2.2]],
    };
    let y = Tile1::<f32, 8> {
        data: std::array::from_fn(|k| k as f32 * 1.1 - 0.3),
    };
    let ints = Tile1::<i32, 8> {
        data: std::array::from_fn(|k| k as i32 * 977 - 3000),
    };
    let j = Tile1::<i32, 3> {
        data: [0x0f0f, -1, 12345],
    };
    let k = "k";
    let v: Tile2<f32, 2, 3> = tile::view22(&x, 1, 2, k).unwrap();
    let row: Tile1<f32, 6> = tile::view21(&x, 3i64, k).unwrap();
    let v1: Tile1<f32, 3> = tile::view11(&y, 5u32, k).unwrap();
    let d = tile::window2(&x, &s, 2, 3, k, op::assign).unwrap();
    let e = tile::window2(&x, &s, 1, 0, k, op::add).unwrap();
    let e = tile::window2(&e, &s, 0, 1, k, op::sub).unwrap();
    let xi = tile::window1(&ints, &j, 4, k, op::bit_xor).unwrap();
    let fault = match tile::view22::<f32, 4, 6, 2, 3, _, _>(&x, 3, 2, k)
        .unwrap_err()
        .kind
    {
        FaultKind::TileIndex { index, shape, .. } => [
            6,
            index[0],
            index[1],
            i64::from(shape[0]),
            i64::from(shape[1]),
        ],
        other => panic!("{other:?}"),
    };
    // The adjoints, called as the generated CPU code calls them (the seed a copy).
    let seed6 = Tile1::<f32, 6> {
        data: std::array::from_fn(|k| y.data[k]),
    };
    let mut adj_x = Tile2::<f32, 4, 6>::zeros();
    let (mut a0, mut a1, mut a64) = (0i32, 0i32, 0i64);
    adjoint::adj_tile_view2(&x, 1, 2, &mut adj_x, &mut a0, &mut a1, &s, 1).unwrap();
    adjoint::adj_tile_view1(&x, 3i64, &mut adj_x, &mut a64, &seed6, 1).unwrap();
    let (mut adj_d, mut adj_s) = (x, Tile2::<f32, 2, 3>::zeros());
    let r = adj_d;
    adjoint::adj_tile_assign2(
        &d, &s, 2, 3, &mut adj_d, &mut adj_s, &mut a0, &mut a1, &r, 1,
    )
    .unwrap();
    let (mut adj_d2, mut adj_s2) = (x, Tile2::<f32, 2, 3>::zeros());
    let r = adj_d2;
    adjoint::adj_tile_sub_inplace2(
        &e,
        &s,
        0,
        1,
        &mut adj_d2,
        &mut adj_s2,
        &mut a0,
        &mut a1,
        &r,
        1,
    )
    .unwrap();
    let r = adj_d2;
    adjoint::adj_tile_add_inplace2(
        &e,
        &s,
        1,
        0,
        &mut adj_d2,
        &mut adj_s2,
        &mut a0,
        &mut a1,
        &r,
        1,
    )
    .unwrap();
    let want = [
        bytes(&v),
        bytes(&row),
        bytes(&v1),
        bytes(&d),
        bytes(&e),
        bytes(&xi),
        bytes(&Tile2::<f32, 2, 3>::zeros()),
        bytemuck::cast_slice(&fault).to_vec(),
        bytes(&adj_x),
        bytes(&adj_d),
        bytes(&adj_s),
        bytes(&adj_d2),
        bytes(&adj_s2),
    ]
    .concat();
    let input = [bytes(&x), bytes(&s), bytes(&y), bytes(&ints), bytes(&j)].concat();
    let hex: String = input.iter().map(|b| format!("{b:02x}")).collect();
    for bd in [1, 5, 32, 256] {
        let (dir, exe) = host_cpp::compile_driver(
            &format!("tile_view_{bd}"),
            include_str!("../warp-cuda/cuda/tests/wp_tile_view_driver.cpp"),
            &[&format!("WP_TILE_BLOCK_DIM={bd}")],
        );
        let path = dir.join("script.txt");
        std::fs::write(&path, format!("run view {hex}\n")).unwrap();
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
            "block size {bd}: the CUDA windows differ from warp-core"
        );
    }
}
