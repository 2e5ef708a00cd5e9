//! The TetGen reader: one input holds the `.node` text, a line `===`, and the `.ele` text.
#![no_main]
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::mesh::TetMesh;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let (node, ele) = text.split_once("===\n").unwrap_or((text, ""));
    if let Ok(m) = TetMesh::from_tetgen("fuzz.node", node, "fuzz.ele", ele) {
        assert!(m.tets.iter().flatten().all(|&i| (i as usize) < m.vertices.len()));
        let _ = m.to_scene("fuzz", NeoHookean::default()).build();
    }
});
