//! gt/trajectory.json (and a track's own output read back): parsed, then checked against a
//! scene of 4 frames and 2 cameras as `Scene::load` does.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(t) = serde_json::from_slice::<endofuse::scene::trajectory::Trajectory>(data) {
        let _ = t.validate(4, 2);
        let _ = t.get(3);
    }
});
