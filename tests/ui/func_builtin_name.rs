// A func named like a builtin would be shadowed by it in every kernel: refused at its name.
use warp_lang as wp;

#[wp::func]
fn sign(x: f32) -> f32 {
    if x < 0.0 {
        -2.0
    } else {
        2.0
    }
}

fn main() {}
