use warp_lang as wp;
use wp::prelude::*;

// A body that uses more than the bound gives: `cross` exists for 3-lane vectors only, so the
// other instances fail at the call.
#[wp::kernel(instances(V = [Vec2, Vec3]))]
fn needs_cross<V: Vector>(a: Array<V>, b: V) {
    let i = tid();
    a[i] = a[i].cross(b);
}

// An integer parameter's body may not use float builtins.
#[wp::kernel]
fn int_sqrt<I: Int>(a: Array<I>) {
    let i = tid();
    a[i] = a[i].sqrt();
}

// A list naming a type outside the bound.
#[wp::kernel(instances(I = [i32, f32]))]
fn wrong_list<I: Int>(a: Array<I>) {
    let i = tid();
    a[i] = a[i] + 1;
}

// `Element` ranges over every element type: its instances must be listed.
#[wp::kernel]
fn unlisted<T: Element>(a: Array<T>, b: Array<T>) {
    let i = tid();
    b[i] = a[i];
}

// A list for a parameter the kernel does not have.
#[wp::kernel(instances(U = [f32]))]
fn no_such_param<T: Float>(a: Array<T>) {
    let i = tid();
    a[i] = a[i] * 2.0;
}

// An overload is selected by its parameters' types: every instance needs its own.
#[wp::func(overload)]
fn shift<T: Float>(n: i32) -> T {
    n as T
}

// An overload needs a parameter.
#[wp::func(overload)]
fn nothing() -> f32 {
    1.0
}

fn main() {}
