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
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text + "\n").map_err(wrap)?;
    std::fs::rename(&tmp, path).map_err(wrap)
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
    img.save(path).map_err(|e| wrap(std::io::Error::other(e)))
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
