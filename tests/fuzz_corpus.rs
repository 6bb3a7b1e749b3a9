//! The fuzz corpus as a regression suite on stable: every input under fuzz/corpus/<target>/
//! (valid files, broken ones, and each crash the fuzzer found, kept after its fix) replayed
//! through the same harness the cargo-fuzz targets run (fuzz/src/lib.rs, included here). A
//! reader that panics or breaks an invariant on any of them fails this test, naming the file.

#[allow(dead_code)]
#[path = "../fuzz/src/lib.rs"]
mod harness;

use std::path::{Path, PathBuf};

/// The corpus files of `target`, sorted (a failure names the same file every run).
fn corpus(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    assert!(
        files.len() >= 4,
        "{}: a corpus of valid and broken inputs",
        dir.display()
    );
    files
}

/// Every file of `target`'s corpus through `run`: none may panic, and a file named `valid_*`
/// must be accepted, one named `broken_*` refused (each an `Err`, not a crash); any other
/// (the fuzzer's finds, `found_*`, and inputs whose outcome depends on the machine, such as
/// `any_cuda_device`: refused without a GPU, imported with one) only must not fail.
fn replay(target: &str, run: fn(&[u8]) -> bool) {
    for file in corpus(target) {
        let bytes = std::fs::read(&file).unwrap();
        let name = file.file_name().unwrap().to_string_lossy().into_owned();
        let outcome = std::panic::catch_unwind(|| run(&bytes));
        if let Ok(accepted) = outcome {
            if name.starts_with("valid_") {
                assert!(
                    accepted,
                    "`{target}` refuses the valid input {}",
                    file.display()
                );
            }
            if name.starts_with("broken_") {
                assert!(
                    !accepted,
                    "`{target}` accepts the broken input {}",
                    file.display()
                );
            }
        }
        assert!(
            outcome.is_ok(),
            "fuzz target `{target}` fails on {} (replay it: cd fuzz && cargo +nightly fuzz run \
             {target} {})",
            file.display(),
            file.strip_prefix(Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz"))
                .unwrap()
                .display()
        );
    }
}

#[test]
fn nvdb_corpus() {
    replay("nvdb", harness::nvdb);
}

#[test]
fn obj_corpus() {
    replay("obj", harness::obj);
}

#[test]
fn dlpack_corpus() {
    replay("dlpack", harness::dlpack);
}
