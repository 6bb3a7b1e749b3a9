//! cargo-fuzz target: the harness's `nvdb` (fuzz/src/lib.rs), which tests/fuzz_corpus.rs replays
//! over fuzz/corpus/nvdb/ on stable.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    warp_fuzz::nvdb(data);
});
