use warp_lang as wp;
use wp::prelude::*;

// Assertions take a plain string literal (no format arguments: a GPU fault record holds no
// text) and a bool condition; the expectations (and assert_eq!/assert_ne!, which check as they
// do) take two arguments of one type.
#[wp::kernel]
fn k(a: Array<f32>, v: Array<Vec3>, n: Array<i32>) {
    let i = tid();
    assert!(a[i] > 0.0, "a[{}] is not positive", i);
    assert!(a[i] > 0.0, "{i}");
    debug_assert!(a[i]);
    assert!(n[i] > 0, i);
    expect_near(v[i], a[i], 0.5);
    expect_near(n[i], 1, 0);
    expect_eq(a[i], n[i]);
    let ok = expect_neq(a[i], 1.0);
    assert_eq!(a[i]);
    assert_ne!(a[i], n[i]);
    assert_eq!(n[i], 1, "n[{}]", i);
}

fn main() {}
