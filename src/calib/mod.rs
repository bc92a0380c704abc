//! Stereo calibration files other tools wrote, read into the camera model of
//! [`crate::geometry::camera`]: OpenCV FileStorage YAML and XML (as `cv::FileStorage` writes them
//! after `cv::stereoCalibrate` or `cv::calibrateCamera`), the da Vinci / EndoVis
//! `camera_calibration.txt`, and the `cameras` of a scene.json. This module holds the types, the
//! format detection (from the content; the extension only breaks ties) and the checks every format
//! shares: a distortion vector the model can represent (k1, k2, p1, p2, k3), a pinhole camera
//! matrix without skew, a proper rotation, finite numbers, and a baseline that looks like
//! millimetres. The baseline is only a warning (|T| < 0.5 or > 200, in `Calibration::warnings`,
//! which [`read`] says as `log::warn!` lines naming the file): a file in metres or centimetres
//! still loads, and the log says why the overlay then looks wrong.
//!
//! Conventions: camera 0 is the left/reference camera, with identity extrinsics; camera m's
//! extrinsics map camera-0 coordinates into camera m, X_m = R·X_0 + T (eq. 11), which is exactly
//! OpenCV's `stereoCalibrate` R, T. Millimetres and pixels.

mod checks;
mod endovis;
mod opencv;
mod scene_json;
mod xml;
mod yaml;

use std::io::Read;
use std::path::Path;

use crate::error::InputError;
use crate::geometry::camera::IntrinsicsError;
use crate::geometry::{Camera, Extrinsics, Intrinsics};

/// The file formats [`read`] understands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CalibFormat {
    OpenCvYaml,
    OpenCvXml,
    EndoVisText,
    SceneJson,
}

impl std::fmt::Display for CalibFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            CalibFormat::OpenCvYaml => "OpenCV FileStorage YAML",
            CalibFormat::OpenCvXml => "OpenCV FileStorage XML",
            CalibFormat::EndoVisText => "da Vinci/EndoVis camera_calibration.txt",
            CalibFormat::SceneJson => "scene.json (cameras)",
        })
    }
}

/// One camera of a calibration file.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibCamera {
    pub name: String,
    pub intrinsics: Intrinsics,
    /// Camera-0 coordinates into this camera (identity for camera 0).
    pub extrinsics: Extrinsics,
}

/// What a calibration file holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    pub format: CalibFormat,
    /// Image size the file states (width, height), if it states one.
    pub image_size: Option<(u32, u32)>,
    /// 2 for a stereo file, 1 for a monocular one; index 0 = left/reference.
    pub cameras: Vec<CalibCamera>,
    /// What was doubtful but not wrong (lines skipped, a baseline not in millimetres), each
    /// without the file's name: [`read`] says them as warnings naming the file.
    pub warnings: Vec<String>,
}

/// What is wrong with a calibration file, with the key and the values at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibError {
    #[error("the file is empty")]
    Empty,
    #[error("not a text file: byte {offset} is neither UTF-8 text nor a line break or tab")]
    NotText { offset: usize },
    #[error("the file is {bytes} bytes; a calibration file is a few kilobytes")]
    TooLarge { bytes: u64 },
    #[error(
        "not a calibration file this reader knows (OpenCV FileStorage YAML or XML, a da Vinci/EndoVis camera_calibration.txt, or a scene.json); it starts with {start:?}"
    )]
    UnknownFormat { start: String },
    #[error("line {line}: {problem}")]
    Syntax { line: usize, problem: String },
    #[error("{key} appears twice (lines {first} and {second})")]
    DuplicateKey {
        key: String,
        first: usize,
        second: usize,
    },
    #[error("missing {key}: {purpose}")]
    MissingKey { key: String, purpose: String },
    #[error("{key} (line {line}): {problem}")]
    BadValue {
        key: String,
        line: usize,
        problem: String,
    },
    #[error("{key}: {text:?} is not a number")]
    NotANumber { key: String, text: String },
    #[error("{key}: {text} is not a finite number")]
    NonFinite { key: String, text: String },
    #[error("{key} has {len} numbers, expected {expected} ({what})")]
    Count {
        key: String,
        len: usize,
        expected: usize,
        what: &'static str,
    },
    #[error("{key} is {rows}×{cols}, expected {expected}")]
    Shape {
        key: String,
        rows: usize,
        cols: usize,
        expected: &'static str,
    },
    #[error("{key}: rows × cols = {rows} × {cols} = {product}, but data holds {len} numbers")]
    DataLength {
        key: String,
        rows: usize,
        cols: usize,
        product: usize,
        len: usize,
    },
    #[error("{key} has {len} distortion coefficients; OpenCV writes 4, 5, 8, 12 or 14")]
    DistortionLength { key: String, len: usize },
    #[error(
        "{key}: distortion coefficient {name} = {value} is not zero, but the camera model has k1, k2, p1, p2, k3 only (OpenCV's rational k4–k6, thin-prism s1–s4 and tilt τx, τy terms are not supported)"
    )]
    UnsupportedDistortion {
        key: String,
        name: &'static str,
        value: f64,
    },
    #[error(
        "{key}: skew {skew} is not zero (limit 1e-6·fx = {limit:e}); the camera model has no skew"
    )]
    Skew { key: String, skew: f64, limit: f64 },
    #[error(
        "{key}: element [{row}][{col}] is {value}, expected {expected} in a camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
    )]
    NotPinhole {
        key: String,
        row: usize,
        col: usize,
        value: f64,
        expected: f64,
    },
    #[error(
        "{key} is not a rotation: RᵀR deviates from the identity by up to {deviation:.3e} (tolerance 1e-3)"
    )]
    NotOrthonormal { key: String, deviation: f64 },
    #[error("{key} is not a proper rotation: its determinant is {det} (expected +1)")]
    Determinant { key: String, det: f64 },
    #[error("{key}: image size {value} is not a whole number of pixels between 1 and 100000")]
    BadSize { key: String, value: String },
    #[error("cameras have different image sizes ({first}: {w0}×{h0}, {other}: {w1}×{h1})")]
    MixedSizes {
        first: String,
        w0: u32,
        h0: u32,
        other: String,
        w1: u32,
        h1: u32,
    },
    #[error("{0}")]
    Json(String),
    #[error("the file states {file_w}×{file_h} images, but the images are {width}×{height}")]
    SizeMismatch {
        file_w: u32,
        file_h: u32,
        width: u32,
        height: u32,
    },
    #[error("camera {camera}: {source}")]
    Intrinsics {
        camera: String,
        source: IntrinsicsError,
    },
}

impl Calibration {
    /// Cameras for an image of `width`×`height` (checks plausibility, and that a size the
    /// file states equals it: otherwise an error saying both sizes).
    pub fn cameras(&self, width: u32, height: u32) -> Result<Vec<Camera>, CalibError> {
        if let Some((file_w, file_h)) = self.image_size
            && (file_w, file_h) != (width, height)
        {
            return Err(CalibError::SizeMismatch {
                file_w,
                file_h,
                width,
                height,
            });
        }
        self.cameras
            .iter()
            .map(|c| {
                c.intrinsics
                    .check_plausible(width, height)
                    .map_err(|source| CalibError::Intrinsics {
                        camera: c.name.clone(),
                        source,
                    })?;
                Ok(Camera {
                    name: c.name.clone(),
                    width,
                    height,
                    intrinsics: c.intrinsics,
                    extrinsics: c.extrinsics,
                })
            })
            .collect()
    }
}

/// Files larger than this are not calibration files (and are not read whole into memory).
const MAX_BYTES: u64 = 16 << 20;

/// Reads a calibration file of any known format (detected from the content; see [`parse`]).
/// Errors name the file and say the problem in one line.
pub fn read(path: &Path) -> Result<Calibration, InputError> {
    let fail = |problem: String| InputError::new(path, problem);
    crate::error::regular_file(path).map_err(|e| fail(format!("cannot read: {e}")))?;
    let file = std::fs::File::open(path).map_err(|e| fail(format!("cannot read: {e}")))?;
    let mut bytes = Vec::new();
    file.take(MAX_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| fail(format!("cannot read: {e}")))?;
    if bytes.len() as u64 > MAX_BYTES {
        let size = std::fs::metadata(path)
            .map(|m| m.len())
            .unwrap_or(MAX_BYTES + 1);
        return Err(fail(CalibError::TooLarge { bytes: size }.to_string()));
    }
    let extension = path.extension().and_then(|e| e.to_str());
    let text = text_of(&bytes).map_err(|e| fail(e.to_string()))?;
    let format = detect(text, extension).map_err(|e| fail(e.to_string()))?;
    let cal = parse_as(format, text).map_err(|e| fail(format!("{format}: {e}")))?;
    for w in &cal.warnings {
        log::warn!("{}: {w}", path.display());
    }
    Ok(cal)
}

/// Parses the bytes of a calibration file; `extension` (without the dot) only breaks ties the
/// content leaves open.
pub fn parse(bytes: &[u8], extension: Option<&str>) -> Result<Calibration, CalibError> {
    let text = text_of(bytes)?;
    parse_as(detect(text, extension)?, text)
}

/// Parses `text` as `format` (a UTF-8 byte-order mark already removed), then checks the
/// intrinsics against the image size the file states, so that an impossible camera is refused
/// when the file is read rather than when it is first used.
pub fn parse_as(format: CalibFormat, text: &str) -> Result<Calibration, CalibError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let cal = match format {
        CalibFormat::OpenCvYaml => opencv::to_calibration(&yaml::parse(text)?, format)?,
        CalibFormat::OpenCvXml => opencv::to_calibration(&xml::parse(text)?, format)?,
        CalibFormat::EndoVisText => endovis::parse(text)?,
        CalibFormat::SceneJson => scene_json::parse(text)?,
    };
    if let Some((w, h)) = cal.image_size {
        cal.cameras(w, h)?;
    }
    Ok(cal)
}

/// The text of a file: UTF-8, byte-order mark removed, no control characters but line breaks
/// and tabs (binary garbage is refused here, before any parser sees it).
fn text_of(bytes: &[u8]) -> Result<&str, CalibError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let text = std::str::from_utf8(bytes).map_err(|e| CalibError::NotText {
        offset: e.valid_up_to(),
    })?;
    if let Some((offset, _)) = text
        .char_indices()
        .find(|&(_, c)| c.is_control() && !matches!(c, '\n' | '\r' | '\t'))
    {
        return Err(CalibError::NotText { offset });
    }
    if text.trim().is_empty() {
        return Err(CalibError::Empty);
    }
    Ok(text)
}

/// The format of `text`, from its content: a `%YAML` directive or `---`, an XML declaration or
/// `<opencv_storage>`, a JSON object, EndoVis `Camera-0-…`/`Extrinsic-…` keys, or else
/// `key: value` lines (a FileStorage YAML without directive). `extension` decides only when the
/// content fits none of these.
pub fn detect(text: &str, extension: Option<&str>) -> Result<CalibFormat, CalibError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let start = text.trim_start();
    if start.is_empty() {
        return Err(CalibError::Empty);
    }
    if start.starts_with("%YAML") || start.starts_with("---") {
        return Ok(CalibFormat::OpenCvYaml);
    }
    if start.starts_with('<') {
        return Ok(CalibFormat::OpenCvXml);
    }
    if start.starts_with('{') {
        return Ok(CalibFormat::SceneJson);
    }
    let endovis = text.lines().any(|l| {
        let l = l.trim_start();
        l.starts_with("Camera-0-") || l.starts_with("Camera-1-") || l.starts_with("Extrinsic-")
    });
    if endovis {
        return Ok(CalibFormat::EndoVisText);
    }
    let first = start.lines().next().unwrap_or("");
    if text.contains("!!opencv-matrix") || looks_like_key_value(first) {
        return Ok(CalibFormat::OpenCvYaml);
    }
    match extension.map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("yml" | "yaml") => Ok(CalibFormat::OpenCvYaml),
        Some("xml") => Ok(CalibFormat::OpenCvXml),
        Some("json") => Ok(CalibFormat::SceneJson),
        Some("txt") => Ok(CalibFormat::EndoVisText),
        _ => Err(CalibError::UnknownFormat {
            start: first.chars().take(40).collect(),
        }),
    }
}

/// `identifier: …` (a FileStorage key starts with a letter or `_`).
fn looks_like_key_value(line: &str) -> bool {
    let Some((key, _)) = line.split_once(':') else {
        return false;
    };
    let mut chars = key.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// Writes `cal` as OpenCV FileStorage YAML (K1, D1[, K2, D2, R, T], imageSize), which OpenCV's
/// `FileStorage` and [`read`] both read back exactly (numbers printed shortest round-trip).
pub fn write_opencv_yaml(cal: &Calibration, path: &Path) -> std::io::Result<()> {
    std::fs::write(path, yaml::write(cal)?)
}

/// Writes `cal` as OpenCV FileStorage XML (same keys as [`write_opencv_yaml`]).
pub fn write_opencv_xml(cal: &Calibration, path: &Path) -> std::io::Result<()> {
    std::fs::write(path, xml::write(cal)?)
}

/// Writes `cal` as a da Vinci/EndoVis `camera_calibration.txt` (rotation as a Rodrigues vector).
pub fn write_endovis_text(cal: &Calibration, path: &Path) -> std::io::Result<()> {
    std::fs::write(path, endovis::write(cal)?)
}
