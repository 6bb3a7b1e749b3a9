//! cargo-fuzz target: the harness's `obj` (fuzz/src/lib.rs), which tests/fuzz_corpus.rs replays
//! over fuzz/corpus/obj/ on stable.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    warp_fuzz::obj(data);
});
