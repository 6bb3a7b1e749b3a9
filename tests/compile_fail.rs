//! The language's compile-time errors: constructs outside the kernel subset, type errors and
//! wrong launch arguments fail at `cargo build`, pointing at the user's own code.
//! Regenerate the expected output with `TRYBUILD=overwrite cargo test --test compile_fail`.

#[test]
fn compile_fail() {
    // trybuild drives cargo; a machine with the test binary but no toolchain (the GPU host)
    // cannot run it.
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    if std::process::Command::new(&cargo)
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("SKIPPED compile_fail: no cargo on this machine");
        return;
    }
    let t = trybuild::TestCases::new();
    t.compile_fail("tests/ui/*.rs");
}
