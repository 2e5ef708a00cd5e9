//! The medit reader: any bytes give a mesh or an error with file and line; an accepted mesh has
//! indices in range and positively oriented tets, and builds a scene.
#![no_main]
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::element::signed_volume;
use bevy_soft_body::core::fem::mesh::TetMesh;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(m) = TetMesh::from_medit("fuzz.mesh", text) {
        for t in &m.tets {
            assert!(t.iter().all(|&i| (i as usize) < m.vertices.len()));
            let x = t.map(|i| glam_free(m.vertices[i as usize]));
            assert!(signed_volume(x) > 0.0);
        }
        let _ = m.to_scene("fuzz", NeoHookean::default()).build();
    }
});

fn glam_free(p: [f64; 3]) -> bevy_soft_body::core::fem::element::DVec3 {
    bevy_soft_body::core::fem::element::DVec3::from_array(p)
}
