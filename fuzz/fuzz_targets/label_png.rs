//! Label and seed PNGs (8 and 16 bit, grey, palette, RGB, truncated chunks) decoded into a
//! label image. As in a scene, the size read from the header is checked before the pixels are
//! decoded; here any size up to 640×480 passes (a scene takes only its camera's), so the
//! decoder runs on most inputs without each one zeroing a buffer its header claims.
#![no_main]

use endofuse::error::InputError;
use std::path::Path;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let name = Path::new("label.png");
    let _ = endofuse::scene::labels::decode_label_png(name, data, |w, h| {
        if w <= 640 && h <= 480 {
            Ok(())
        } else {
            Err(InputError::new(name, "larger than the camera"))
        }
    });
});
