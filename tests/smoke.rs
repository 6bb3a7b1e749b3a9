use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
    let i = tid();
    let a = -b * v[i] / mass + gravity;
    v[i] += a * dt;
    x[i] += v[i] * dt;
}

#[wp::func]
fn sq(x: f32) -> f32 {
    x * x
}

#[wp::kernel]
fn use_func(a: Array<f32>) {
    let i = tid();
    a[i] = sq(a[i]) + 1.0;
}

#[test]
fn smoke() {
    let dev = wp::cpu();
    let x = wp::Array::from_slice(&[Vec3::ZERO; 4], &dev).unwrap();
    let v = wp::Array::from_slice(&[Vec3::X; 4], &dev).unwrap();
    wp::launch(integrate, 4, (&x, &v, 0.05, 0.1, Vec3::new(0.0, 0.0, -9.81), 0.01), &dev).unwrap();
    println!("{:?}", x.to_vec().unwrap());
    let a = wp::Array::from_slice(&[1.0f32, 2.0, 3.0], &dev).unwrap();
    wp::launch(use_func, 3, (&a,), &dev).unwrap();
    assert_eq!(a.to_vec().unwrap(), vec![2.0, 5.0, 10.0]);
}
