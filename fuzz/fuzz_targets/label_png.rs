//! Label and seed PNGs (8 and 16 bit, grey, palette, RGB, truncated chunks) decoded into a
//! label image.
#![no_main]
#[path = "scratch.rs"]
mod scratch;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let p = scratch::file("label.png", data);
    let _ = endofuse::scene::labels::read_label_png(&p);
});
