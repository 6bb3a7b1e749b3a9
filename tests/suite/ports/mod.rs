//! Ports of NVIDIA Warp's own test files: one module per Warp file, named after it, each
//! exercising a feature as Warp users write it (the module's docs name the Warp file, what was
//! ported, what was not and why). The tests run on every backend like the rest of the suite.

mod test_assert;
mod test_fixedarray;
mod test_func;
mod test_generics;
mod test_grad_customs;
mod test_lerp;
mod test_mat_linalg;
mod test_ref;
mod test_smoothstep;
mod test_spatial;
mod test_struct;
mod test_tuple;
