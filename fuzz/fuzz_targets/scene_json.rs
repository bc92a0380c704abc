//! scene.json with the scene validator: the fuzzed file replaces the fixture's scene.json, so
//! a valid mutation reaches the meshes, seed PNGs and frames it names, as `info` does.
#![no_main]
#[path = "scratch.rs"]
mod scratch;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let p = scratch::file("scene.json", data);
    if let Ok(scene) = endofuse::scene::Scene::load(&p) {
        let _ = scene.seeds.seeded_frames();
        let _ = scene.seeds.pixel_counts();
        let _ = scene.ground_truth_frames();
    }
});
