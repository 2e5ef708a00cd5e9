//! The scene JSON reader: any bytes give a scene or an error; an accepted scene builds or
//! reports why not.
#![no_main]
use bevy_soft_body::core::scene::Scene;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(scene) = Scene::from_json(text)
    {
        let _ = scene.build();
    }
});
