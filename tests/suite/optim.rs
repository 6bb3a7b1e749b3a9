//! Optimizers (`wp::optim`): updates against their closed forms for a constant gradient, and
//! convergence on a quadratic bowl through a tape, with scalar and vector parameters, on every
//! backend.

use crate::{arr, zeros};
use warp_lang as wp;
use wp::optim::{Adam, Optimizer, Sgd};
use wp::prelude::*;

backend_tests!(
    constant_gradient_updates,
    quadratic_bowl_converges,
    parameters_need_gradients,
    optimizers_debug_their_settings,
);

/// Sets every component of `a`'s gradient to `c`.
fn set_grad<T: wp::Element>(a: &wp::Array<T>, c: T) {
    a.grad().unwrap().fill(c).unwrap();
}

/// With the gradient held at a constant g: SGD moves each component by lr g a step; Adam's
/// bias-corrected moments are g and g^2, so it moves by lr g / (|g| + eps) a step; SGD with
/// momentum mu (no dampening) has the buffer g (1 - mu^t) / (1 - mu) at step t.
fn constant_gradient_updates(dev: &wp::Device) {
    let steps = 20;
    let (lr, g) = (0.01f64, 0.5f64);
    // f64 parameters: the closed forms to 1e-12 (20 steps of O(1) arithmetic in f64, and
    // on a GPU FMA contraction: a few ulps each).
    let x = arr(&[1.0f64, -2.0, 3.0], dev).with_grad().unwrap();
    let mut sgd = Sgd::new(lr);
    sgd.add(&x).unwrap();
    for _ in 0..steps {
        set_grad(&x, g);
        sgd.step().unwrap();
    }
    let want = |x0: f64, per_step: f64| x0 - steps as f64 * per_step;
    for (got, x0) in x.to_vec().unwrap().iter().zip([1.0, -2.0, 3.0]) {
        assert!((got - want(x0, lr * g)).abs() < 1e-12, "{got}");
    }
    let y = arr(&[1.0f64, -2.0], dev).with_grad().unwrap();
    let mut adam = Adam::new(lr);
    adam.add(&y).unwrap();
    for _ in 0..steps {
        set_grad(&y, g);
        adam.step().unwrap();
    }
    assert_eq!(adam.steps(), steps as u64);
    for (got, x0) in y.to_vec().unwrap().iter().zip([1.0, -2.0]) {
        let w = want(x0, lr * g / (g + 1e-8));
        assert!((got - w).abs() < 1e-12, "{got} vs {w}");
    }
    let mu = 0.9f64;
    let z = arr(&[0.0f64], dev).with_grad().unwrap();
    let mut heavy = Sgd::new(lr).momentum(mu);
    heavy.add(&z).unwrap();
    let mut expect = 0.0f64;
    for t in 1..=steps {
        set_grad(&z, g);
        heavy.step().unwrap();
        expect -= lr * g * (1.0 - mu.powi(t)) / (1.0 - mu);
    }
    assert!((z.to_vec().unwrap()[0] - expect).abs() < 1e-12);
}

/// loss = sum |x_i - target_i|^2, one atomic add per element.
#[wp::kernel]
fn bowl_scalar(x: Array<f32>, target: Array<f32>, loss: Array<f32>) {
    let i = tid();
    let d = x[i] - target[i];
    atomic_add(loss, 0, d * d);
}

#[wp::kernel]
fn bowl_vec3(x: Array<Vec3>, target: Array<Vec3>, loss: Array<f32>) {
    let i = tid();
    let d = x[i] - target[i];
    atomic_add(loss, 0, d.dot(d));
}

/// Adam, SGD and Nesterov SGD minimise a quadratic bowl over a scalar and a Vec3 parameter
/// array at once (the gradient from a tape each step); the tolerances are stated per
/// optimizer from its contraction: SGD at lr 0.1 contracts the distance by 0.8 a step, so
/// 100 steps leave 1e-9 of the start (f32 rounding, ~1e-6, dominates); Adam at lr 0.02 walks
/// about lr a step and then oscillates within ~lr of the minimum, so 400 steps end within 2e-2.
fn quadratic_bowl_converges(dev: &wp::Device) {
    let n = 64;
    let targets: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
    let vtargets: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(i as f32 * 0.01, -0.5, (i as f32).cos()))
        .collect();
    let (t1, t3) = (arr(&targets, dev), arr(&vtargets, dev));
    let cases: [(&str, usize, f32); 3] = [
        ("sgd", 100, 1e-5),
        ("nesterov", 100, 1e-5),
        ("adam", 400, 2e-2),
    ];
    for (name, steps, tol) in cases {
        let x = zeros::<f32, 1>(n, dev).with_grad().unwrap();
        let v = zeros::<Vec3, 1>(n, dev).with_grad().unwrap();
        let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
        let mut opt: Box<dyn Optimizer> = match name {
            "adam" => {
                let mut o = Adam::new(0.02);
                o.add(&x).unwrap();
                o.add(&v).unwrap();
                Box::new(o)
            }
            _ => {
                let nesterov = name == "nesterov";
                let mut o = Sgd::new(0.1)
                    .momentum(if nesterov { 0.5 } else { 0.0 })
                    .nesterov(nesterov);
                o.add(&x).unwrap();
                o.add(&v).unwrap();
                Box::new(o)
            }
        };
        for _ in 0..steps {
            opt.zero_grad().unwrap();
            loss.fill(0.0).unwrap();
            let tape = wp::Tape::new();
            {
                let _rec = tape.record();
                wp::launch(bowl_scalar, n, (&x, &t1, &loss), dev).unwrap();
                wp::launch(bowl_vec3, n, (&v, &t3, &loss), dev).unwrap();
            }
            tape.backward(&loss).unwrap();
            opt.step().unwrap();
        }
        let xs = x.to_vec().unwrap();
        let vs = v.to_vec().unwrap();
        let worst = xs
            .iter()
            .zip(&targets)
            .map(|(a, b)| (a - b).abs())
            .chain(
                vs.iter()
                    .zip(&vtargets)
                    .map(|(a, b)| (*a - *b).abs().max_element()),
            )
            .fold(0.0f32, f32::max);
        assert!(worst < tol, "{name}: {worst} after {steps} steps");
    }
}

/// A parameter without a gradient, or a strided one, is an error naming the optimizer.
fn parameters_need_gradients(dev: &wp::Device) {
    let x = zeros::<f32, 1>(4, dev);
    let e = Adam::new(0.1).add(&x).unwrap_err().to_string();
    assert!(e.contains("Adam") && e.contains("no gradient"), "{e}");
    let m = zeros::<f32, 2>((3, 4), dev).with_grad().unwrap();
    let e = Sgd::new(0.1).add(&m.transpose()).unwrap_err().to_string();
    assert!(e.contains("not contiguous"), "{e}");
}

/// `Debug` shows an optimizer's settings and progress (a user logging it sees its learning
/// rate, betas or momentum, how many parameters it updates and how many steps it took).
fn optimizers_debug_their_settings(dev: &wp::Device) {
    let x = zeros::<f32, 1>(4, dev).with_grad().unwrap();
    let mut adam = Adam::new(0.25);
    adam.add(&x).unwrap();
    adam.step().unwrap();
    let d = format!("{adam:?}");
    assert!(
        d.starts_with("Adam")
            && d.contains("parameters: 1")
            && d.contains("lr: 0.25")
            && d.contains("step: 1")
            && d.contains("beta1: 0.9"),
        "{d}"
    );
    let sgd = Sgd::new(0.5).momentum(0.75);
    let d = format!("{sgd:?}");
    assert!(
        d.starts_with("Sgd") && d.contains("momentum: 0.75") && d.contains("parameters: 0"),
        "{d}"
    );
}
