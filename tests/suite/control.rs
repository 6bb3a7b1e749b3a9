//! Control flow and bindings: let / let mut, shadowing, block expressions, if/else as
//! statement and as value, range loops with every adapter order, while, loop/break,
//! continue, early return, nested loops.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    let_and_shadowing,
    if_else_statement,
    if_else_expression,
    range_loops_match_rust,
    range_loop_types,
    while_loop,
    loop_break,
    continue_in_loops,
    early_return,
    nested_loops,
    loop_end_evaluated_once,
);

/// A range's end is evaluated once, before the loop (Rust's semantics): assigning the variable
/// it came from inside the body changes nothing.
#[wp::kernel]
fn k_end_once(n: i32, out: Array<i32>) {
    let i = tid();
    let mut m = n;
    let mut count = 0;
    for _j in 0..m {
        m -= 1;
        count += 1;
    }
    let mut k = 0;
    for j in k..m + 2 {
        k += j;
        count += 100;
    }
    out[i] = count + k * 10000;
}

// The host reference deliberately does what the kernel does.
#[allow(clippy::mut_range_bound)]
fn loop_end_evaluated_once(dev: &wp::Device) {
    let out = zeros::<i32, 1>(1, dev);
    wp::launch(k_end_once, 1, (6, &out), dev).unwrap();
    let (mut m, mut count) = (6, 0);
    for _j in 0..m {
        m -= 1;
        count += 1;
    }
    let mut k = 0;
    for j in k..m + 2 {
        k += j;
        count += 100;
    }
    assert_eq!(out.to_vec().unwrap(), vec![count + k * 10000]);
}

#[wp::kernel]
fn k_let(a: Array<i32>, out: Array<f32, 2>) {
    let i = tid();
    let x = a[i];
    let mut y = x;
    y += 10;
    out[(i, 0)] = y as f32;
    // Shadowing with another type.
    let x = x as f32 * 1.5;
    out[(i, 1)] = x;
    // Shadowing inside a block does not leak out of it.
    {
        let x = 100.0;
        out[(i, 2)] = x;
    }
    out[(i, 3)] = x;
    // A block as a value.
    let z = {
        let t = x * 2.0;
        t + 1.0
    };
    out[(i, 4)] = z;
    let _ = z;
    let mut w = 0.0;
    w = w + z;
    out[(i, 5)] = w;
}

fn let_and_shadowing(dev: &wp::Device) {
    let a = [1, -4, 7];
    let out = zeros::<f32, 2>((3, 6), dev);
    wp::launch(k_let, 3, (&arr(&a, dev), &out), dev).unwrap();
    let want: Vec<f32> = a
        .iter()
        .flat_map(|&x| {
            let s = x as f32 * 1.5;
            let z = s * 2.0 + 1.0;
            [(x + 10) as f32, s, 100.0, s, z, z]
        })
        .collect();
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_if_stmt(a: Array<i32>, out: Array<i32>) {
    let i = tid();
    let x = a[i];
    out[i] = 0;
    if x > 10 {
        out[i] = 3;
    } else if x > 0 {
        out[i] = 2;
    } else if x == 0 {
        out[i] = 1;
    } else {
        out[i] = -1;
    }
    if x == 42 {
        out[i] += 100;
    }
}

fn if_else_statement(dev: &wp::Device) {
    let a = [-5, 0, 3, 11, 42];
    let out = zeros::<i32, 1>(5, dev);
    wp::launch(k_if_stmt, 5, (&arr(&a, dev), &out), dev).unwrap();
    let want: Vec<i32> = a
        .iter()
        .map(|&x| {
            let mut r = if x > 10 {
                3
            } else if x > 0 {
                2
            } else if x == 0 {
                1
            } else {
                -1
            };
            if x == 42 {
                r += 100;
            }
            r
        })
        .collect();
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_if_expr(a: Array<f32>, out: Array<f32>, cls: Array<i32>) {
    let i = tid();
    let x = a[i];
    let s = if x < 0.0 {
        -1
    } else if x == 0.0 {
        0
    } else {
        1
    };
    cls[i] = s;
    let y = if x > 1.0 {
        let t = x * x;
        t + 1.0
    } else if x > 0.0 {
        if x > 0.5 {
            0.75
        } else {
            0.25
        }
    } else {
        -x
    };
    out[i] = y;
}

fn if_else_expression(dev: &wp::Device) {
    let a = [-2.0f32, 0.0, 0.3, 0.6, 3.0];
    let (out, cls) = (zeros::<f32, 1>(5, dev), zeros::<i32, 1>(5, dev));
    wp::launch(k_if_expr, 5, (&arr(&a, dev), &out, &cls), dev).unwrap();
    let f = |x: f32| {
        if x > 1.0 {
            x * x + 1.0
        } else if x > 0.0 {
            if x > 0.5 {
                0.75
            } else {
                0.25
            }
        } else {
            -x
        }
    };
    // x * x + 1.0 with x = 3 is exact even when fused.
    assert_eq!(host(&out), a.iter().map(|&x| f(x)).collect::<Vec<_>>());
    assert_eq!(host(&cls), vec![-1, 0, 1, 1, 1]);
}

// Range loops: each kernel writes the values it visits and their count; the host runs the
// same adapters on Rust's own iterators. One thread per (a, b, k) case.

#[wp::kernel]
fn k_range_plain(a: Array<i32>, b: Array<i32>, out: Array<i32, 2>, count: Array<i32>) {
    let c = tid();
    let mut n = 0;
    for j in a[c]..b[c] {
        out[(c, n)] = j;
        n += 1;
    }
    count[c] = n;
}

#[wp::kernel]
fn k_range_rev(a: Array<i32>, b: Array<i32>, out: Array<i32, 2>, count: Array<i32>) {
    let c = tid();
    let mut n = 0;
    for j in (a[c]..b[c]).rev() {
        out[(c, n)] = j;
        n += 1;
    }
    count[c] = n;
}

#[wp::kernel]
fn k_range_step(
    a: Array<i32>,
    b: Array<i32>,
    k: Array<i32>,
    out: Array<i32, 2>,
    count: Array<i32>,
) {
    let c = tid();
    let mut n = 0;
    for j in (a[c]..b[c]).step_by(k[c]) {
        out[(c, n)] = j;
        n += 1;
    }
    count[c] = n;
}

#[wp::kernel]
fn k_range_rev_step(
    a: Array<i32>,
    b: Array<i32>,
    k: Array<i32>,
    out: Array<i32, 2>,
    count: Array<i32>,
) {
    let c = tid();
    let mut n = 0;
    for j in (a[c]..b[c]).rev().step_by(k[c]) {
        out[(c, n)] = j;
        n += 1;
    }
    count[c] = n;
}

#[wp::kernel]
fn k_range_step_rev(
    a: Array<i32>,
    b: Array<i32>,
    k: Array<i32>,
    out: Array<i32, 2>,
    count: Array<i32>,
) {
    let c = tid();
    let mut n = 0;
    for j in (a[c]..b[c]).step_by(k[c]).rev() {
        out[(c, n)] = j;
        n += 1;
    }
    count[c] = n;
}

#[wp::kernel]
fn k_range_incl(a: Array<i32>, b: Array<i32>, out: Array<i32, 2>, count: Array<i32>) {
    let c = tid();
    let mut n = 0;
    for j in a[c]..=b[c] {
        out[(c, n)] = j;
        n += 1;
    }
    count[c] = n;
}

#[wp::kernel]
fn k_range_incl_rev_step(
    a: Array<i32>,
    b: Array<i32>,
    k: Array<i32>,
    out: Array<i32, 2>,
    count: Array<i32>,
) {
    let c = tid();
    let mut n = 0;
    for j in (a[c]..=b[c]).rev().step_by(k[c]) {
        out[(c, n)] = j;
        n += 1;
    }
    count[c] = n;
}

#[wp::kernel]
fn k_range_incl_step_rev(
    a: Array<i32>,
    b: Array<i32>,
    k: Array<i32>,
    out: Array<i32, 2>,
    count: Array<i32>,
) {
    let c = tid();
    let mut n = 0;
    for j in (a[c]..=b[c]).step_by(k[c]).rev() {
        out[(c, n)] = j;
        n += 1;
    }
    count[c] = n;
}

/// Launches one loop kernel on (output rows, visit counts).
type LaunchLoop<'a> = dyn Fn(&wp::Array<i32, 2>, &wp::Array<i32>) -> wp::Result<()> + 'a;

/// Widest loop of the cases below.
const MAX_VISITS: usize = 16;

/// Checks one loop kernel's rows against Rust iterators.
fn check_rows(
    what: &str,
    cases: &[(i32, i32, i32)],
    out: &wp::Array<i32, 2>,
    count: &wp::Array<i32>,
    want: impl Fn(i32, i32, usize) -> Vec<i32>,
) {
    let (out, count) = (host(out), host(count));
    for (c, &(a, b, k)) in cases.iter().enumerate() {
        let want = want(a, b, k as usize);
        let n = count[c] as usize;
        assert_eq!(
            &out[c * MAX_VISITS..c * MAX_VISITS + n],
            want.as_slice(),
            "{what} with a = {a}, b = {b}, k = {k}"
        );
        assert_eq!(n, want.len(), "{what} count with a = {a}, b = {b}, k = {k}");
    }
}

fn range_loops_match_rust(dev: &wp::Device) {
    // (start, end, step): the brief's 0..11 by 3 (where rev/step_by order matters), empty
    // ranges (3..3, 5..2), negative bounds, steps larger than the range.
    let cases = [
        (0, 11, 3),
        (0, 10, 3),
        (3, 3, 2),
        (5, 2, 1),
        (-4, 7, 2),
        (-7, -1, 4),
        (0, 1, 5),
        (2, 12, 1),
        (-3, 3, 6),
    ];
    let n = cases.len();
    let a = arr(&cases.map(|c| c.0), dev);
    let b = arr(&cases.map(|c| c.1), dev);
    let k = arr(&cases.map(|c| c.2), dev);
    let run = |what: &str, launch: &LaunchLoop, want: &dyn Fn(i32, i32, usize) -> Vec<i32>| {
        let out = wp::Array::<i32, 2>::full((n, MAX_VISITS), i32::MIN, dev).unwrap();
        let count = zeros::<i32, 1>(n, dev);
        launch(&out, &count).unwrap();
        check_rows(what, &cases, &out, &count, want);
    };
    run(
        "a..b",
        &|o, c| wp::launch(k_range_plain, n, (&a, &b, o, c), dev),
        &|a, b, _| (a..b).collect(),
    );
    run(
        "(a..b).rev()",
        &|o, c| wp::launch(k_range_rev, n, (&a, &b, o, c), dev),
        &|a, b, _| (a..b).rev().collect(),
    );
    run(
        "(a..b).step_by(k)",
        &|o, c| wp::launch(k_range_step, n, (&a, &b, &k, o, c), dev),
        &|a, b, k| (a..b).step_by(k).collect(),
    );
    run(
        "(a..b).rev().step_by(k)",
        &|o, c| wp::launch(k_range_rev_step, n, (&a, &b, &k, o, c), dev),
        &|a, b, k| (a..b).rev().step_by(k).collect(),
    );
    run(
        "(a..b).step_by(k).rev()",
        &|o, c| wp::launch(k_range_step_rev, n, (&a, &b, &k, o, c), dev),
        &|a, b, k| (a..b).step_by(k).rev().collect(),
    );
    run(
        "a..=b",
        &|o, c| wp::launch(k_range_incl, n, (&a, &b, o, c), dev),
        &|a, b, _| (a..=b).collect(),
    );
    run(
        "(a..=b).rev().step_by(k)",
        &|o, c| wp::launch(k_range_incl_rev_step, n, (&a, &b, &k, o, c), dev),
        &|a, b, k| (a..=b).rev().step_by(k).collect(),
    );
    // Rust has no `.rev()` on `(a..=b).step_by(k)` for i32 (not an ExactSizeIterator); the
    // kernel language has, with the meaning "the same values, last first".
    run(
        "(a..=b).step_by(k).rev()",
        &|o, c| wp::launch(k_range_incl_step_rev, n, (&a, &b, &k, o, c), dev),
        &|a, b, k| {
            let mut v: Vec<i32> = (a..=b).step_by(k).collect();
            v.reverse();
            v
        },
    );
    // The brief's example: the two orders differ on 0..11 by 3.
    assert_ne!(
        (0..11).rev().step_by(3).collect::<Vec<_>>(),
        (0..11).step_by(3).rev().collect::<Vec<_>>()
    );
}

/// Loop variables take the bounds' type: u8, i64 and usize ranges, with literal bounds typed
/// from the other bound, and a constant-bound loop with a literal step.
#[wp::kernel]
fn k_range_types(lo: u8, hi: i64, out: Array<i64>) {
    let mut s8 = 0;
    for j in lo..250 {
        s8 += j as i32;
    }
    out[0] = s8 as i64;
    let mut s64: i64 = 0;
    for j in (hi - 5)..hi {
        s64 += j;
    }
    for j in -3..(hi - 4_999_999_999) {
        s64 += j;
    }
    out[1] = s64;
    let mut su: usize = 0;
    for j in (0..out.len()).rev() {
        su += j;
    }
    out[2] = su as i64;
    let mut sl = 0;
    for j in (0..=20).step_by(5) {
        sl += j;
    }
    out[3] = sl as i64;
    let mut n = 0;
    for _ in 0..7 {
        n += 1;
    }
    out[4] = n as i64;
}

fn range_loop_types(dev: &wp::Device) {
    let out = zeros::<i64, 1>(5, dev);
    wp::launch(k_range_types, 1, (240u8, 5_000_000_000i64, &out), dev).unwrap();
    let want = [
        (240..250).map(i64::from).sum::<i64>(),
        (5_000_000_000i64 - 5..5_000_000_000).sum::<i64>() + (-3..1).sum::<i64>(),
        (0..5).sum::<i64>(),
        (0..=20).step_by(5).sum::<i64>(),
        7,
    ];
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_while(a: Array<i64>, steps: Array<i32>) {
    let i = tid();
    let mut x = a[i];
    let mut n = 0;
    while x != 1 && n < 1000 {
        if x % 2 == 0 {
            x /= 2;
        } else {
            x = 3 * x + 1;
        }
        n += 1;
    }
    steps[i] = n;
}

fn while_loop(dev: &wp::Device) {
    let a: Vec<i64> = (1..=30).chain([27, 97, 871]).collect();
    let steps = zeros::<i32, 1>(a.len(), dev);
    wp::launch(k_while, a.len(), (&arr(&a, dev), &steps), dev).unwrap();
    let collatz = |mut x: i64| {
        let mut n = 0;
        while x != 1 && n < 1000 {
            x = if x % 2 == 0 { x / 2 } else { 3 * x + 1 };
            n += 1;
        }
        n
    };
    assert_eq!(
        host(&steps),
        a.iter().map(|&x| collatz(x)).collect::<Vec<_>>()
    );
}

#[wp::kernel]
fn k_loop_break(a: Array<u32>, out: Array<u32>) {
    let i = tid();
    let x = a[i];
    let mut p: u32 = 1;
    loop {
        if p >= x {
            break;
        }
        p *= 2;
    }
    out[i] = p;
}

fn loop_break(dev: &wp::Device) {
    let a = [0u32, 1, 2, 3, 17, 64, 1000, 1 << 31];
    let out = zeros::<u32, 1>(a.len(), dev);
    wp::launch(k_loop_break, a.len(), (&arr(&a, dev), &out), dev).unwrap();
    assert_eq!(
        host(&out),
        a.iter()
            .map(|&x| x.max(1).next_power_of_two())
            .collect::<Vec<_>>()
    );
}

#[wp::kernel]
fn k_continue(a: Array<i32>, out: Array<i32, 2>) {
    let i = tid();
    let n = a[i];
    let mut s = 0;
    for j in 0..n {
        if j % 3 == 0 {
            continue;
        }
        if j > 20 {
            break;
        }
        s += j;
    }
    out[(i, 0)] = s;
    let mut k = 0;
    let mut t = 0;
    while k < n {
        k += 1;
        if k % 2 == 0 {
            continue;
        }
        t += k;
    }
    out[(i, 1)] = t;
}

fn continue_in_loops(dev: &wp::Device) {
    let a = [0, 1, 5, 10, 30];
    let out = zeros::<i32, 2>((5, 2), dev);
    wp::launch(k_continue, 5, (&arr(&a, dev), &out), dev).unwrap();
    let want: Vec<i32> = a
        .iter()
        .flat_map(|&n| {
            let s: i32 = (0..n).filter(|j| j % 3 != 0).take_while(|&j| j <= 20).sum();
            let t: i32 = (1..=n).filter(|k| k % 2 != 0).sum();
            [s, t]
        })
        .collect();
    assert_eq!(host(&out), want);
}

/// Threads past `n` return before touching `out`; a thread also returns early from inside a
/// loop.
#[wp::kernel]
fn k_early_return(n: usize, out: Array<i32>, touched: Array<i32>) {
    let i = tid();
    touched[i] = 1;
    if i >= n {
        return;
    }
    out[i] = 1;
    for j in 0..n {
        if j == i {
            out[i] = 2 + j as i32;
            return;
        }
    }
    out[i] = -1;
}

fn early_return(dev: &wp::Device) {
    let n = 5;
    let out = zeros::<i32, 1>(8, dev);
    let touched = zeros::<i32, 1>(8, dev);
    wp::launch(k_early_return, 8, (n, &out, &touched), dev).unwrap();
    assert_eq!(host(&touched), vec![1; 8]);
    assert_eq!(host(&out), vec![2, 3, 4, 5, 6, 0, 0, 0]);
}

#[wp::kernel]
fn k_nested(n: i32, out: Array<i32, 2>) {
    let i = tid();
    let m = i as i32;
    let mut s = 0;
    for a in 0..m {
        for b in a..n {
            if (a + b) % 5 == 4 {
                continue;
            }
            let mut c = 0;
            while c < b {
                c += 2;
                s += c;
            }
        }
    }
    out[(i, 0)] = s;
    let mut pairs = 0;
    for a in (0..=m).rev() {
        for b in (0..a).step_by(2) {
            if b * a > 12 {
                break;
            }
            pairs += 1;
        }
    }
    out[(i, 1)] = pairs;
}

fn nested_loops(dev: &wp::Device) {
    let n = 9;
    let out = zeros::<i32, 2>((7, 2), dev);
    wp::launch(k_nested, 7, (n, &out), dev).unwrap();
    let want: Vec<i32> = (0..7)
        .flat_map(|m: i32| {
            let mut s = 0;
            for a in 0..m {
                for b in a..n {
                    if (a + b) % 5 == 4 {
                        continue;
                    }
                    let mut c = 0;
                    while c < b {
                        c += 2;
                        s += c;
                    }
                }
            }
            let mut pairs = 0;
            for a in (0..=m).rev() {
                for b in (0..a).step_by(2) {
                    if b * a > 12 {
                        break;
                    }
                    pairs += 1;
                }
            }
            [s, pairs]
        })
        .collect();
    assert_eq!(host(&out), want);
}
