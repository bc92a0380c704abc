//! Calibration files (OpenCV FileStorage YAML and XML, da Vinci/EndoVis text, scene.json
//! cameras): the first byte picks the extension the parser is told, the rest is the file.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let ext = [Some("yaml"), Some("yml"), Some("xml"), Some("txt"), Some("json"), None]
        [pick as usize % 6];
    if let Ok(c) = endofuse::calib::parse(rest, ext) {
        // What `new-scene` does next with a calibration it read.
        let _ = format!("{c:?}");
    }
});
