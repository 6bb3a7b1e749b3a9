use warp_lang as wp;
use wp::prelude::*;

// The misc builtins' errors: lower_bound searches a 1-D array (not a view, not 2-D), its
// arities; div_approx divides floats; inverse_approx takes matrices; quat_to_axis_angle and
// transform_decompose return tuples; argmin takes vectors; sample_cdf takes an f32 array.
#[wp::kernel]
fn k(a: Array<f32>, g: Array<f32, 2>, n: Array<i32>, q: Array<Quat>, out: Array<f32>) {
    let i = tid();
    let x = lower_bound(g, 0.5);
    let w = a.view(1..3);
    let y = lower_bound(w, 0.5);
    let z = lower_bound(a, 0, 0.5);
    let d = div_approx(n[i], 2);
    let e = inverse_approx(q[i]);
    let t: f32 = quat_to_axis_angle(q[i]);
    let k = argmin(out[i]);
    let mut s = rand_init(1, 2);
    let c = sample_cdf(&mut s, n);
    let h = norm_huber(vec3(1.0, 2.0, 3.0), 1.0, 2.0);
}

fn main() {}
