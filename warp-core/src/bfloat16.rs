//! `bf16` (Warp's `bfloat16`): a tile element for loads, stores and `tile_matmul`.
//!
//! The type is the [`half`] crate's [`bf16`](struct@half::bf16): 1 sign bit, 8 exponent bits
//! (f32's range), 7 mantissa bits. Widening to `f32` is exact (the top half of the f32 bits);
//! narrowing from `f32` rounds to nearest, ties to even, once (`half`'s `bf16::from_f32`), and
//! keeps NaNs NaN. What this slice has: the tile library's loads and stores (generic over the
//! element) and the matmul with an f32 accumulator ([`crate::tile::MatmulElem`]); the kernel
//! language does not name `bf16` yet (the tiles chapter's "Not yet" says what remains).

pub use half::bf16;
