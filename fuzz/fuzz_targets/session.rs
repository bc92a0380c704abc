//! Session files (seeds, settings, the saved forest, results) as the app's Open Session reads
//! them, down to decoding the seed layers for two 64×48 cameras.
#![no_main]
#[path = "scratch.rs"]
mod scratch;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let p = scratch::file("fuzzed.endofuse-session", data);
    if let Ok(s) = endofuse::session::Session::load(&p) {
        let _ = endofuse::session::decode_seeds(&s.seeds, &[(64, 48), (64, 48)], &p);
    }
});
