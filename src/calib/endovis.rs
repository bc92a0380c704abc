//! The da Vinci / EndoVis `camera_calibration.txt` (the EndoVis 2018 challenge's per-sequence
//! files): one `Key: numbers   // comment` per line. `Width`, `Height` (pixels);
//! `Camera-N-F` = fx fy, `Camera-N-C` = cx cy (pixels), `Camera-N-Alpha` = skew (optional: some
//! files omit it), `Camera-N-K` = distortion in OpenCV's order k1 k2 p1 p2 k3 (calib_D's non-zero
//! fifth term is k3: its third and fourth, the decentering terms, are written `0.0`);
//! N = 0 left, 1 right. `Extrinsic-Omega` is the left→right rotation as a Rodrigues vector
//! (radians) and `Extrinsic-T` the left→right translation in mm, in OpenCV's convention
//! X_right = R·X_left + T: with the ~4.35 mm baseline T_x ≈ −4.35, so the right camera's centre
//! −RᵀT lies at +x in left coordinates. Alpha is refused beyond 1e-6 (as Bouguet's `alpha_c`, a
//! fraction of fx, that is 1e-6·fx pixels of skew; read as pixels it is stricter still). Lines
//! that are not `Key: …` (calib_D ends with a Python dump of a device header) are skipped with a
//! warning; keys this reader does not know are ignored, and only the keys it reads must hold
//! numbers. The format is a stereo pair's: a file without the right camera is refused as
//! truncated (and the writer refuses a monocular calibration).

use std::fmt::Write as _;

use glam::DVec3;

use super::checks;
use super::{CalibError, CalibFormat, Calibration};
use crate::geometry::pose::rotation_from_vector;
use crate::geometry::{Extrinsics, Intrinsics};

struct Value<'a> {
    line: usize,
    text: &'a str,
}

struct Keys<'a> {
    values: Vec<(&'a str, Value<'a>)>,
    /// Lines (1-based) that are not `Key: numbers`.
    skipped: Vec<usize>,
}

impl Keys<'_> {
    /// The numbers of `key`, `None` when absent; exactly `expected` of them when given.
    fn get(
        &self,
        key: &str,
        expected: Option<usize>,
        what: &'static str,
    ) -> Result<Option<Vec<f64>>, CalibError> {
        let Some((_, v)) = self.values.iter().find(|(k, _)| *k == key) else {
            return Ok(None);
        };
        let numbers = v
            .text
            .split_whitespace()
            .map(|t| checks::number(key, t))
            .collect::<Result<Vec<_>, _>>()?;
        if let Some(expected) = expected.filter(|&n| n != numbers.len()) {
            return Err(CalibError::Count {
                key: key.into(),
                len: numbers.len(),
                expected,
                what,
            });
        }
        log::trace!("{key} (line {}): {numbers:?}", v.line);
        Ok(Some(numbers))
    }

    fn need(
        &self,
        key: &str,
        n: Option<usize>,
        what: &'static str,
    ) -> Result<Vec<f64>, CalibError> {
        self.get(key, n, what)?
            .ok_or_else(|| CalibError::MissingKey {
                key: key.into(),
                purpose: what.into(),
            })
    }
}

fn keys(text: &str) -> Result<Keys<'_>, CalibError> {
    let mut values: Vec<(&str, Value)> = Vec::new();
    let mut skipped = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let content = raw.split("//").next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let key_value = content.split_once(':').filter(|(k, _)| {
            !k.is_empty()
                && k.chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        });
        let Some((key, text)) = key_value else {
            skipped.push(line);
            continue;
        };
        if let Some((_, first)) = values.iter().find(|(k, _)| *k == key) {
            return Err(CalibError::DuplicateKey {
                key: key.into(),
                first: first.line,
                second: line,
            });
        }
        values.push((key, Value { line, text }));
    }
    Ok(Keys { values, skipped })
}

fn camera(keys: &Keys, n: usize) -> Result<Intrinsics, CalibError> {
    let side = if n == 0 { "left" } else { "right" };
    let key = |what: &str| format!("Camera-{n}-{what}");
    let f = keys.need(
        &key("F"),
        Some(2),
        if n == 0 {
            "left camera focal lengths fx fy in pixels"
        } else {
            "right camera focal lengths fx fy in pixels (the file describes a stereo pair: is it truncated?)"
        },
    )?;
    let c = keys.need(&key("C"), Some(2), "principal point cx cy in pixels")?;
    if let Some(alpha) = keys.get(&key("Alpha"), Some(1), "skew")? {
        checks::no_skew(&key("Alpha"), alpha[0], 1.0)?;
    }
    let k = keys.need(&key("K"), None, "distortion k1 k2 p1 p2 k3")?;
    let d = checks::distortion(&key("K"), &k)?;
    log::debug!("EndoVis {side} camera: f {f:?}, c {c:?}");
    Ok(checks::intrinsics((f[0], f[1], c[0], c[1]), d))
}

pub(crate) fn parse(text: &str) -> Result<Calibration, CalibError> {
    let keys = keys(text)?;
    let width = keys.get("Width", Some(1), "image width in pixels")?;
    let height = keys.get("Height", Some(1), "image height in pixels")?;
    let image_size = match (width, height) {
        (Some(w), Some(h)) => Some((checks::size("Width", w[0])?, checks::size("Height", h[0])?)),
        (None, None) => None,
        (Some(_), None) => {
            return Err(missing(
                "Height",
                "image height in pixels (the file has Width)",
            ));
        }
        (None, Some(_)) => {
            return Err(missing(
                "Width",
                "image width in pixels (the file has Height)",
            ));
        }
    };
    let left = camera(&keys, 0)?;
    // Always a stereo pair: a file without the right camera is a truncated one, not a
    // monocular calibration (none was ever written in this format).
    let right = camera(&keys, 1)?;
    let omega = keys.need(
        "Extrinsic-Omega",
        Some(3),
        "left to right rotation, Rodrigues vector in radians",
    )?;
    let t = keys.need(
        "Extrinsic-T",
        Some(3),
        "left to right translation in mm (X_right = R X_left + T)",
    )?;
    let rotation = checks::rotation(
        "Extrinsic-Omega",
        rotation_from_vector(DVec3::from_slice(&omega)),
    )?;
    let translation_mm = DVec3::from_slice(&t);
    let extrinsics = Extrinsics {
        rotation,
        translation_mm,
    };
    let mut cal = checks::rig(
        CalibFormat::EndoVisText,
        image_size,
        left,
        Some((right, extrinsics)),
    );
    if !keys.skipped.is_empty() {
        cal.warnings.push(format!(
            "skipped {} line(s) that are not `Key: numbers` (lines {:?})",
            keys.skipped.len(),
            keys.skipped
        ));
    }
    cal.warnings
        .extend(checks::baseline_warning("Extrinsic-T", translation_mm));
    Ok(cal)
}

fn missing(key: &str, purpose: &str) -> CalibError {
    CalibError::MissingKey {
        key: key.into(),
        purpose: purpose.into(),
    }
}

/// `cal` as a camera_calibration.txt (comments as the EndoVis files have them).
pub(crate) fn write(cal: &Calibration) -> std::io::Result<String> {
    let (left, right) = checks::for_writing(cal, "a camera_calibration.txt")?;
    let Some((right_intrinsics, e)) = right else {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "a camera_calibration.txt holds a stereo pair, this calibration has one camera",
        ));
    };
    let mut s = String::new();
    // Shortest round-trip numbers, padded so that the comments line up as in the originals.
    let mut put = |key: &str, numbers: String, comment: &str| {
        let _ = writeln!(s, "{:<58}// {comment}", format!("{key}: {numbers}"));
    };
    if let Some((w, h)) = cal.image_size {
        put("Width", w.to_string(), "width of the images in pixels");
        put("Height", h.to_string(), "height of the images in pixels");
    }
    let mut line = |key: &str, values: &[f64], comment: &str| {
        let numbers: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
        put(key, numbers.join(" "), comment);
    };
    for (n, (i, side)) in [(left, "left"), (right_intrinsics, "right")]
        .iter()
        .enumerate()
    {
        line(
            &format!("Camera-{n}-F"),
            &[i.fx, i.fy],
            &format!("{side} camera x,y focal dist in pixels"),
        );
        line(
            &format!("Camera-{n}-C"),
            &[i.cx, i.cy],
            &format!("{side} camera x,y center in pixels"),
        );
        line(
            &format!("Camera-{n}-Alpha"),
            &[0.0],
            &format!("{side} camera skew"),
        );
        line(
            &format!("Camera-{n}-K"),
            &[i.k1, i.k2, i.p1, i.p2, i.k3],
            &format!("{side} camera distortion k1 k2 p1 p2 k3"),
        );
    }
    let omega = checks::rotation_vector(e.rotation);
    line(
        "Extrinsic-Omega",
        &omega.to_array(),
        "left to right camera rotation",
    );
    line(
        "Extrinsic-T",
        &e.translation_mm.to_array(),
        "left to right camera position",
    );
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PAIR: &str = "Width: 640 // w\r\nHeight: 480\r\nCamera-0-F: 500 501\r\nCamera-0-C: 320 240\r\n\
        Camera-0-K: 0.1 0.01 0.001 0.002 0.0001\r\nCamera-1-F: 502 503\r\nCamera-1-C: 330 241\r\n\
        Camera-1-Alpha: 0.00000\r\nCamera-1-K: 0.2 0.02 0 0 0\r\nExtrinsic-Omega: 0 0.01 0\r\nExtrinsic-T: -5 0 0";

    #[test]
    fn reads_a_pair_in_opencv_order() {
        let cal = parse(PAIR).unwrap();
        assert_eq!(cal.image_size, Some((640, 480)));
        let l = cal.cameras[0].intrinsics;
        assert_eq!(
            [l.k1, l.k2, l.p1, l.p2, l.k3],
            [0.1, 0.01, 0.001, 0.002, 0.0001]
        );
        let e = cal.cameras[1].extrinsics;
        assert_eq!(e.translation_mm, DVec3::new(-5.0, 0.0, 0.0));
        assert!(e.center_mm().x > 4.9, "right camera at +x of the left one");
        assert!(cal.warnings.is_empty(), "{:?}", cal.warnings);
        // Lines that are not keys and a baseline in metres are warnings the reader says with
        // the file's name (they named a file `camera_calibration.txt` whatever it was called).
        let odd = PAIR.replace("Extrinsic-T: -5 0 0", "Extrinsic-T: -0.005 0 0\nb'\\x00'");
        let cal = parse(&odd).unwrap();
        assert_eq!(cal.warnings.len(), 2, "{:?}", cal.warnings);
        assert!(cal.warnings[0].starts_with("skipped 1 line(s)"));
        assert!(cal.warnings[1].starts_with("Extrinsic-T: baseline"));
    }

    #[test]
    fn refuses_skew_counts_and_duplicates() {
        let skewed = PAIR.replace("Camera-1-Alpha: 0.00000", "Camera-1-Alpha: 0.01");
        let e = parse(&skewed).unwrap_err().to_string();
        assert!(
            e.contains("Camera-1-Alpha") && e.contains("skew 0.01"),
            "{e}"
        );
        let short = PAIR.replace("Camera-0-F: 500 501", "Camera-0-F: 500");
        let e = parse(&short).unwrap_err().to_string();
        assert!(e.contains("Camera-0-F has 1 numbers, expected 2"), "{e}");
        let twice = format!("{PAIR}\nWidth: 640");
        assert!(matches!(
            parse(&twice),
            Err(CalibError::DuplicateKey { .. })
        ));
        let text = PAIR.replace("-5 0 0", "-5 zero 0");
        let e = parse(&text).unwrap_err().to_string();
        assert!(
            e.contains("Extrinsic-T") && e.contains("\"zero\" is not a number"),
            "{e}"
        );
    }

    #[test]
    fn writer_output_reads_back() {
        let cal = parse(PAIR).unwrap();
        let back = parse(&write(&cal).unwrap()).unwrap();
        assert_eq!(back.cameras[0], cal.cameras[0]);
        let (a, b) = (cal.cameras[1].extrinsics, back.cameras[1].extrinsics);
        assert!((a.rotation - b.rotation).abs_diff_eq(glam::DMat3::ZERO, 1e-15));
    }
}
