//! Label and seed PNGs (8 and 16 bit, grey, palette, RGB, truncated chunks) decoded into a
//! label image.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = endofuse::scene::labels::decode_label_png(std::path::Path::new("label.png"), data);
});
