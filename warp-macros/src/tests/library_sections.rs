//! The CUDA library sections the macros name are rows of the library's table.
//!
//! A kernel unit includes the sections its builtins and types name, looked up in
//! `warp_cuda::library::SECTIONS` (warp-runtime's `cuda/source.rs`): a name that is no kernel
//! row there would leave its builtins undefined on a GPU alone, and the CPU tests would not
//! notice. The names come from the builtin table's rows, the object kinds' rows (`OBJECTS`),
//! and those the CUDA emitter adds itself (`back/cuda.rs`: a transform value's and
//! `print`'s; `back/cuda_tile.rs`: the tile sections). A proc-macro crate cannot depend on
//! warp-cuda; its tests can, so the check is here.

use crate::builtins::BUILTINS;
use crate::types::OBJECTS;
use std::collections::BTreeSet;

/// The section names that `back/cuda.rs` and `back/cuda_tile.rs` pass to `Emitter::section`
/// as string literals.
fn emitter_literals() -> Vec<&'static str> {
    [
        include_str!("../back/cuda.rs"),
        include_str!("../back/cuda_tile.rs"),
    ]
    .into_iter()
    .flat_map(|text| {
        text.match_indices(".section(\"").map(move |(i, m)| {
            let rest = &text[i + m.len()..];
            &rest[..rest.find('"').expect("a closing quote")]
        })
    })
    .collect()
}

#[test]
fn every_section_the_macros_name_is_a_kernel_row_of_the_library() {
    let emitted = emitter_literals();
    // The scan finds the emitter's own (else it would check nothing).
    assert!(emitted.contains(&"transform") && emitted.contains(&"print"));
    assert!(emitted.contains(&"tile_mma"));
    let named = BUILTINS
        .iter()
        .map(|b| (b.section, format!("builtin `{}`", b.name)))
        .chain(
            OBJECTS
                .iter()
                .map(|o| (o.section, format!("object kind `{}`", o.name))),
        )
        .chain(emitted.iter().map(|s| (*s, "the CUDA emitter".to_string())));
    let mut used = BTreeSet::new();
    for (section, by) in named {
        let row = warp_cuda::library::find(section);
        assert!(
            row.is_some_and(|r| r.kernel),
            "{by} names the section \"{section}\", which is no kernel section of \
             warp_cuda::library::SECTIONS"
        );
        used.insert(section);
    }
    // And no kernel row is dead: each is named by something here.
    for row in warp_cuda::library::SECTIONS.iter().filter(|r| r.kernel) {
        assert!(
            used.contains(row.name),
            "no builtin, object kind or emitter names the kernel section \"{}\"",
            row.name
        );
    }
}
