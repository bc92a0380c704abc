//! What an OpenCV FileStorage holds, whichever syntax (YAML or XML) it came in, and how a
//! `stereoCalibrate` or `calibrateCamera` output becomes a [`Calibration`]. The YAML and XML
//! readers produce a [`Storage`] of top-level nodes; values they cannot read become
//! [`Node::Bad`] and are an error only if a key this module needs holds one, so another tool's
//! extra keys never stop a file from loading. Keys: the camera matrices under the names OpenCV's
//! samples and common tools use (`K1`, `M1`, `cameraMatrix1`, `camera_matrix_left`, …;
//! `camera_matrix` for a monocular file), distortion `D1`, `distCoeffs1`, …, `R` and `T` as
//! `stereoCalibrate` defines them (X_2 = R·X_1 + T), and the image size as `imageSize: [w, h]`,
//! `image_width`/`image_height` or `width`/`height`.

use glam::DVec3;

use super::checks;
use super::{CalibError, CalibFormat, Calibration};
use crate::geometry::{Extrinsics, Intrinsics};

/// A `!!opencv-matrix` / `type_id="opencv-matrix"` node, its numbers still text (so that the
/// messages about them name the key).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Matrix {
    pub rows: usize,
    pub cols: usize,
    pub dt: String,
    pub data: Vec<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Node {
    Scalar(String),
    Seq(Vec<String>),
    Matrix(Matrix),
    /// Something this reader does not interpret (a nested mapping, a sequence of mappings).
    Other(&'static str),
    /// A value that could not be read, and why.
    Bad(String),
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Entry {
    pub key: String,
    pub line: usize,
    pub node: Node,
}

/// The top-level nodes of a FileStorage, keys unique.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Storage {
    entries: Vec<Entry>,
}

impl Storage {
    /// Refuses a key that appears twice (OpenCV would read one of them silently).
    pub fn new(entries: Vec<Entry>) -> Result<Self, CalibError> {
        for (i, e) in entries.iter().enumerate() {
            if let Some(first) = entries[..i].iter().find(|f| f.key == e.key) {
                return Err(CalibError::DuplicateKey {
                    key: e.key.clone(),
                    first: first.line,
                    second: e.line,
                });
            }
        }
        Ok(Self { entries })
    }

    /// The first of `aliases` present.
    fn get(&self, aliases: &[&str]) -> Option<&Entry> {
        aliases
            .iter()
            .find_map(|a| self.entries.iter().find(|e| e.key == *a))
    }
}

// Key names (the first present is used): OpenCV's samples, its docs and common tools.
#[rustfmt::skip]
const LEFT_K: &[&str] = &[
    "K1", "M1", "cameraMatrix1", "camera_matrix1", "camera_matrix_left",
    "cameraMatrixLeft", "cameraMatrixL", "K_left", "left_camera_matrix",
];
#[rustfmt::skip]
const LEFT_D: &[&str] = &[
    "D1", "distCoeffs1", "dist_coeffs1", "distortion_coefficients1",
    "distortion_coefficients_left", "dist_coeffs_left", "distCoeffsLeft", "distCoeffsL",
    "D_left", "left_distortion_coefficients",
];
const MONO_K: &[&str] = &["camera_matrix", "cameraMatrix", "K", "M"];
const MONO_D: &[&str] = &["distortion_coefficients", "distCoeffs", "dist_coeffs", "D"];
#[rustfmt::skip]
const RIGHT_K: &[&str] = &[
    "K2", "M2", "cameraMatrix2", "camera_matrix2", "camera_matrix_right",
    "cameraMatrixRight", "cameraMatrixR", "K_right", "right_camera_matrix",
];
#[rustfmt::skip]
const RIGHT_D: &[&str] = &[
    "D2", "distCoeffs2", "dist_coeffs2", "distortion_coefficients2",
    "distortion_coefficients_right", "dist_coeffs_right", "distCoeffsRight", "distCoeffsR",
    "D_right", "right_distortion_coefficients",
];
const SIZE_KEYS: &[&str] = &["imageSize", "image_size", "ImageSize", "imgSize"];
const SIZE_PAIRS: &[(&str, &str)] = &[
    ("image_width", "image_height"),
    ("imageWidth", "imageHeight"),
    ("width", "height"),
];

fn missing(key: &str, purpose: impl Into<String>) -> CalibError {
    CalibError::MissingKey {
        key: key.into(),
        purpose: purpose.into(),
    }
}

/// The numbers of a node and its shape (a flow sequence is a 1×n row).
fn numbers(e: &Entry) -> Result<(usize, usize, Vec<f64>), CalibError> {
    let bad = |problem: String| CalibError::BadValue {
        key: e.key.clone(),
        line: e.line,
        problem,
    };
    let parse = |items: &[String]| -> Result<Vec<f64>, CalibError> {
        items.iter().map(|t| checks::number(&e.key, t)).collect()
    };
    match &e.node {
        Node::Matrix(m) => {
            // One channel only: "d", "f", "i", … optionally with the count 1 ("1d").
            let dt = m.dt.trim_matches(|c| c == '"' || c == '\'');
            let single = dt.strip_prefix('1').unwrap_or(dt);
            if single.len() != 1 || !"ucwsifdh".contains(single) {
                return Err(bad(format!(
                    "dt {dt:?} is not a one-channel matrix type (d, f, i, …)"
                )));
            }
            let product = m.rows.saturating_mul(m.cols);
            if product != m.data.len() {
                return Err(CalibError::DataLength {
                    key: e.key.clone(),
                    rows: m.rows,
                    cols: m.cols,
                    product,
                    len: m.data.len(),
                });
            }
            Ok((m.rows, m.cols, parse(&m.data)?))
        }
        Node::Seq(items) => Ok((1, items.len(), parse(items)?)),
        Node::Scalar(s) => Ok((1, 1, vec![checks::number(&e.key, s)?])),
        Node::Other(what) => Err(bad(format!("is {what}, expected numbers"))),
        Node::Bad(why) => Err(bad(why.clone())),
    }
}

/// A row-major 3×3 matrix (a 9-number flow sequence is taken row-major too).
fn matrix3(e: &Entry) -> Result<[f64; 9], CalibError> {
    let (rows, cols, v) = numbers(e)?;
    let shape_ok = (rows, cols) == (3, 3) || (rows == 1 && matches!(e.node, Node::Seq(_)));
    match <[f64; 9]>::try_from(v.as_slice()) {
        Ok(m) if shape_ok => Ok(m),
        _ => Err(CalibError::Shape {
            key: e.key.clone(),
            rows,
            cols,
            expected: "3×3",
        }),
    }
}

/// A vector: a 1×n or n×1 matrix.
fn vector(e: &Entry) -> Result<Vec<f64>, CalibError> {
    let (rows, cols, v) = numbers(e)?;
    if rows == 1 || cols == 1 {
        Ok(v)
    } else {
        Err(CalibError::Shape {
            key: e.key.clone(),
            rows,
            cols,
            expected: "1×n or n×1",
        })
    }
}

fn camera(k: &Entry, d: &Entry) -> Result<Intrinsics, CalibError> {
    let f = checks::pinhole(&k.key, &matrix3(k)?)?;
    let d = checks::distortion(&d.key, &vector(d)?)?;
    Ok(checks::intrinsics(f, d))
}

fn image_size(st: &Storage) -> Result<Option<(u32, u32)>, CalibError> {
    if let Some(e) = st.get(SIZE_KEYS) {
        let v = vector(e)?;
        let [w, h] = v[..] else {
            return Err(CalibError::Count {
                key: e.key.clone(),
                len: v.len(),
                expected: 2,
                what: "width, height",
            });
        };
        return Ok(Some((checks::size(&e.key, w)?, checks::size(&e.key, h)?)));
    }
    for (wk, hk) in SIZE_PAIRS {
        let one = |key: &str| -> Result<Option<u32>, CalibError> {
            st.get(&[key])
                .map(|e| match vector(e)?[..] {
                    [v] => checks::size(key, v),
                    ref v => Err(CalibError::Count {
                        key: key.into(),
                        len: v.len(),
                        expected: 1,
                        what: "pixels",
                    }),
                })
                .transpose()
        };
        match (one(wk)?, one(hk)?) {
            (Some(w), Some(h)) => return Ok(Some((w, h))),
            (Some(_), None) => {
                return Err(missing(hk, format!("image height (the file has {wk})")));
            }
            (None, Some(_)) => return Err(missing(wk, format!("image width (the file has {hk})"))),
            (None, None) => {}
        }
    }
    Ok(None)
}

/// The calibration a `stereoCalibrate` (two cameras) or `calibrateCamera` (one) output holds.
pub(crate) fn to_calibration(st: &Storage, format: CalibFormat) -> Result<Calibration, CalibError> {
    let image_size = image_size(st)?;
    let k0 = st.get(LEFT_K).or_else(|| st.get(MONO_K)).ok_or_else(|| {
        missing(
            "K1",
            "the left (or only) camera matrix (also looked for M1, cameraMatrix1, camera_matrix_left, camera_matrix)",
        )
    })?;
    let d0 = st.get(LEFT_D).or_else(|| st.get(MONO_D)).ok_or_else(|| {
        missing(
            "D1",
            "the left (or only) camera's distortion coefficients (also looked for distCoeffs1, distortion_coefficients)",
        )
    })?;
    let left = camera(k0, d0)?;
    let (r, t) = (st.get(&["R"]), st.get(&["T"]));
    let Some(k1) = st.get(RIGHT_K) else {
        if let Some(e) = st.get(RIGHT_D).or(r).or(t) {
            let why = format!(
                "the right camera matrix (the file has {}, so it describes a stereo pair)",
                e.key
            );
            return Err(missing("K2", why));
        }
        return Ok(checks::rig(format, image_size, left, None));
    };
    let d1 = st.get(RIGHT_D).ok_or_else(|| {
        missing(
            "D2",
            "the right camera's distortion coefficients (also looked for distCoeffs2)",
        )
    })?;
    let right = camera(k1, d1)?;
    const EXTRINSICS_ELSEWHERE: &str = "a file of intrinsics only? OpenCV's stereo_calib sample writes R and T to a separate extrinsics.yml";
    let r = r.ok_or_else(|| {
        missing(
            "R",
            format!("the rotation from the left to the right camera ({EXTRINSICS_ELSEWHERE})"),
        )
    })?;
    let t = t.ok_or_else(|| {
        missing(
            "T",
            format!(
                "the translation from the left to the right camera, mm ({EXTRINSICS_ELSEWHERE})"
            ),
        )
    })?;
    let rotation = checks::rotation(&r.key, checks::mat3_from_rows(&matrix3(r)?))?;
    let tv = vector(t)?;
    let [tx, ty, tz] = tv[..] else {
        return Err(CalibError::Count {
            key: t.key.clone(),
            len: tv.len(),
            expected: 3,
            what: "Tx, Ty, Tz",
        });
    };
    let translation_mm = DVec3::new(tx, ty, tz);
    let extrinsics = Extrinsics {
        rotation,
        translation_mm,
    };
    let mut cal = checks::rig(format, image_size, left, Some((right, extrinsics)));
    cal.warnings
        .extend(checks::baseline_warning(&t.key, translation_mm));
    Ok(cal)
}

/// A matrix to write: key, rows, cols, row-major numbers.
pub(crate) type Written = (&'static str, usize, usize, Vec<f64>);

/// The matrices the writers put in a file, in order: K1, D1[, K2, D2, R, T].
pub(crate) fn matrices(cal: &Calibration, format: &str) -> std::io::Result<Vec<Written>> {
    let (left, right) = checks::for_writing(cal, format)?;
    let k = |i: &Intrinsics| vec![i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0];
    let d = |i: &Intrinsics| vec![i.k1, i.k2, i.p1, i.p2, i.k3];
    let mut out = vec![("K1", 3, 3, k(&left)), ("D1", 1, 5, d(&left))];
    if let Some((i, e)) = right {
        let r = e.rotation.transpose().to_cols_array().to_vec(); // row-major
        out.push(("K2", 3, 3, k(&i)));
        out.push(("D2", 1, 5, d(&i)));
        out.push(("R", 3, 3, r));
        out.push(("T", 3, 1, e.translation_mm.to_array().to_vec()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(key: &str, node: Node) -> Entry {
        Entry {
            key: key.into(),
            line: 1,
            node,
        }
    }

    fn mat(rows: usize, cols: usize, data: &[&str]) -> Node {
        Node::Matrix(Matrix {
            rows,
            cols,
            dt: "d".into(),
            data: data.iter().map(|s| s.to_string()).collect(),
        })
    }

    const K: &[&str] = &["800", "0", "320", "0", "801", "240", "0", "0", "1"];

    #[test]
    fn monocular_aliases_and_sizes() {
        let st = Storage::new(vec![
            entry("image_width", Node::Scalar("640".into())),
            entry("image_height", Node::Scalar("480".into())),
            entry("camera_matrix", mat(3, 3, K)),
            entry(
                "distortion_coefficients",
                mat(4, 1, &["0.1", "0", "0", "0"]),
            ),
        ])
        .unwrap();
        let cal = to_calibration(&st, CalibFormat::OpenCvYaml).unwrap();
        assert_eq!((cal.image_size, cal.cameras.len()), (Some((640, 480)), 1));
        assert_eq!(cal.cameras[0].intrinsics.fy, 801.0);
    }

    #[test]
    fn shapes_types_and_half_sizes_are_refused() {
        let base = |k: Node| {
            Storage::new(vec![
                entry("M1", k),
                entry("D1", Node::Seq(vec!["0".into(); 5])),
            ])
            .unwrap()
        };
        let e = to_calibration(&base(mat(3, 2, &K[..6])), CalibFormat::OpenCvXml).unwrap_err();
        assert!(e.to_string().contains("M1 is 3×2, expected 3×3"), "{e}");
        let e = to_calibration(&base(mat(3, 3, &K[..8])), CalibFormat::OpenCvXml).unwrap_err();
        assert!(e.to_string().contains("= 9, but data holds 8"), "{e}");
        let mut two_channel = mat(3, 3, K);
        if let Node::Matrix(m) = &mut two_channel {
            m.dt = "2d".into();
        }
        let e = to_calibration(&base(two_channel), CalibFormat::OpenCvXml).unwrap_err();
        assert!(e.to_string().contains("\"2d\""), "{e}");
        let e =
            to_calibration(&base(Node::Other("a mapping")), CalibFormat::OpenCvXml).unwrap_err();
        assert!(e.to_string().contains("is a mapping"), "{e}");
        let st = Storage::new(vec![
            entry("width", Node::Scalar("640".into())),
            entry("K1", mat(3, 3, K)),
        ])
        .unwrap();
        let e = to_calibration(&st, CalibFormat::OpenCvYaml).unwrap_err();
        assert!(e.to_string().contains("missing height"), "{e}");
        let st = Storage::new(vec![entry(
            "imageSize",
            Node::Seq(vec!["640.5".into(), "480".into()]),
        )])
        .unwrap();
        let e = to_calibration(&st, CalibFormat::OpenCvYaml).unwrap_err();
        assert!(e.to_string().contains("image size 640.5"), "{e}");
    }
}
