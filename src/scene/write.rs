//! Writing scene files and JSON outputs. JSON is written to a temporary file and renamed into
//! place, so a reader never sees half a file and a crash never leaves one.

use crate::error::Error;
use serde::Serialize;
use std::path::Path;

/// Writes `value` as pretty JSON to `path` atomically, creating parent folders.
pub fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), Error> {
    let wrap = |source: std::io::Error| Error::Write {
        path: path.to_path_buf(),
        source,
    };
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(wrap)?;
    }
    let text = serde_json::to_string_pretty(value).map_err(|e| wrap(std::io::Error::other(e)))?;
    // A name of its own per write: two writers of one file (an autosave still running when
    // the next starts) never share a half-written temporary.
    static WRITES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = WRITES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("json.tmp-{}-{n}", std::process::id()));
    let written = (|| {
        use std::io::Write;
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.write_all(b"\n")?;
        // On disk before it takes the name: a crash after the rename finds the whole file.
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written.map_err(wrap)
}

/// Writes an RGB frame (PNG or JPEG by extension), creating parent folders.
pub fn write_rgb(path: &Path, img: &image::RgbImage) -> Result<(), Error> {
    let wrap = |source: std::io::Error| Error::Write {
        path: path.to_path_buf(),
        source,
    };
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(wrap)?;
    }
    save_image(path, img).map_err(wrap)
}

/// Encodes an image in memory (PNG or JPEG by extension) and writes the bytes unbuffered, so
/// that every write error reaches the caller: `image`'s own `save` drops a buffered writer
/// whose final flush failed (a full disk) and reports success, leaving an empty file.
pub fn save_image<P, C>(path: &Path, img: &image::ImageBuffer<P, C>) -> std::io::Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    let format = image::ImageFormat::from_path(path).map_err(std::io::Error::other)?;
    let mut bytes = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut bytes), format)
        .map_err(std::io::Error::other)?;
    std::fs::write(path, bytes)
}

/// Writes a label PNG, mapping the I/O error to [`Error::Write`].
pub fn write_labels(path: &Path, labels: &crate::plane::LabelImage) -> Result<(), Error> {
    super::labels::write_label_png(path, labels).map_err(|source| Error::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes a mask as a label PNG: 255 inside, 0 outside (hidden structures' projections).
pub fn write_mask(path: &Path, mask: &crate::plane::Mask) -> Result<(), Error> {
    write_labels(path, &mask.map(|&b| if b { 255 } else { 0 }))
}
