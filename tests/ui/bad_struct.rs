use warp_lang as wp;
use wp::prelude::*;

// Kernel structs need #[repr(C)].
#[derive(Clone, Copy, wp::Struct)]
struct NoRepr {
    a: f32,
}

// Padding between a u8 and an f32.
#[derive(Clone, Copy, wp::Struct)]
#[repr(C)]
struct Padded {
    flag: u8,
    value: f32,
}

fn main() {}
