//! cargo-fuzz target: the harness's `dlpack` (fuzz/src/lib.rs), which tests/fuzz_corpus.rs replays
//! over fuzz/corpus/dlpack/ on stable.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    warp_fuzz::dlpack(data);
});
