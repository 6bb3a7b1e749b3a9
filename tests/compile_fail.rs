//! The language's compile-time errors: constructs outside the kernel subset, type errors and
//! wrong launch arguments fail at `cargo build`, pointing at the user's own code.
//! Regenerate the expected output with `TRYBUILD=overwrite cargo test --test compile_fail`.

#[test]
fn compile_fail() {
    let t = trybuild::TestCases::new();
    t.compile_fail("tests/ui/*.rs");
}
