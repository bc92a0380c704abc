//! The checks every calibration format shares, so that a camera is refused for the same reason
//! with the same words whichever tool wrote it: numbers (finite), distortion vectors (OpenCV's
//! 4, 5, 8, 12 or 14 terms, of which the model keeps k1, k2, p1, p2, k3), camera matrices
//! (pinhole, no skew), rotations (orthonormal within 1e-3, determinant +1), baselines (a warning
//! outside 0.5–200 mm) and image sizes; and, for the writers, a calibration re-expressed relative
//! to its first camera.

use glam::{DMat3, DVec3};

use super::{CalibError, Calibration};
use crate::geometry::{Extrinsics, Intrinsics};

/// OpenCV's distortion vector, in its order.
const DISTORTION_NAMES: [&str; 14] = [
    "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "τx", "τy",
];

/// Tolerance of a rotation (the scene validator's, so a file that loads also validates).
const ROTATION_TOL: f64 = 1e-3;

/// A number of `key`. `.Inf`/`.Nan` (how OpenCV's YAML writes them), `inf`, `NaN` and numbers
/// beyond f64 are refused as non-finite rather than as "not a number", which would puzzle.
pub(crate) fn number(key: &str, text: &str) -> Result<f64, CalibError> {
    let t = text.trim();
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(CalibError::NonFinite {
            key: key.into(),
            text: t.into(),
        }),
        Err(_) => {
            let lower = t.to_ascii_lowercase();
            if lower.contains("inf") || lower.contains("nan") {
                Err(CalibError::NonFinite {
                    key: key.into(),
                    text: t.into(),
                })
            } else {
                Err(CalibError::NotANumber {
                    key: key.into(),
                    text: t.chars().take(40).collect(),
                })
            }
        }
    }
}

/// k1, k2, p1, p2, k3 of an OpenCV distortion vector; every further term must be zero.
pub(crate) fn distortion(key: &str, d: &[f64]) -> Result<[f64; 5], CalibError> {
    if ![4, 5, 8, 12, 14].contains(&d.len()) {
        return Err(CalibError::DistortionLength {
            key: key.into(),
            len: d.len(),
        });
    }
    if let Some((i, &value)) = d.iter().enumerate().skip(5).find(|&(_, &v)| v != 0.0) {
        return Err(CalibError::UnsupportedDistortion {
            key: key.into(),
            name: DISTORTION_NAMES[i],
            value,
        });
    }
    Ok([d[0], d[1], d[2], d[3], d.get(4).copied().unwrap_or(0.0)])
}

/// Refuses a skew the model cannot represent (more than 1e-6·fx pixels).
pub(crate) fn no_skew(key: &str, skew: f64, fx: f64) -> Result<(), CalibError> {
    let limit = 1e-6 * fx.abs();
    if skew.abs() > limit {
        return Err(CalibError::Skew {
            key: key.into(),
            skew,
            limit,
        });
    }
    Ok(())
}

/// (fx, fy, cx, cy) of a row-major 3×3 camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]].
/// The zeros and the one are required (to 1e-9): anything else is another camera model.
pub(crate) fn pinhole(key: &str, k: &[f64; 9]) -> Result<(f64, f64, f64, f64), CalibError> {
    for (index, expected) in [(3, 0.0), (6, 0.0), (7, 0.0), (8, 1.0)] {
        let value = k[index];
        if (value - expected).abs() > 1e-9 {
            return Err(CalibError::NotPinhole {
                key: key.into(),
                row: index / 3,
                col: index % 3,
                value,
                expected,
            });
        }
    }
    no_skew(key, k[1], k[0])?;
    Ok((k[0], k[4], k[2], k[5]))
}

/// Intrinsics from (fx, fy, cx, cy) and k1, k2, p1, p2, k3.
pub(crate) fn intrinsics(f: (f64, f64, f64, f64), d: [f64; 5]) -> Intrinsics {
    Intrinsics {
        fx: f.0,
        fy: f.1,
        cx: f.2,
        cy: f.3,
        k1: d[0],
        k2: d[1],
        p1: d[2],
        p2: d[3],
        k3: d[4],
    }
}

/// A row-major 3×3 matrix as a glam (column-major) matrix.
pub(crate) fn mat3_from_rows(m: &[f64; 9]) -> DMat3 {
    DMat3::from_cols_array(m).transpose()
}

/// `r` if it is a proper rotation; else the largest deviation of RᵀR from I, or the determinant.
pub(crate) fn rotation(key: &str, r: DMat3) -> Result<DMat3, CalibError> {
    let e = r.transpose() * r - DMat3::IDENTITY;
    let deviation = [e.x_axis, e.y_axis, e.z_axis]
        .iter()
        .map(|c| c.abs().max_element())
        .fold(0.0_f64, f64::max);
    if !deviation.is_finite() || deviation > ROTATION_TOL {
        return Err(CalibError::NotOrthonormal {
            key: key.into(),
            deviation,
        });
    }
    if !crate::geometry::pose::is_rotation(r, ROTATION_TOL) {
        return Err(CalibError::Determinant {
            key: key.into(),
            det: r.determinant(),
        });
    }
    Ok(r)
}

/// The warning (not a refusal) for a baseline that is not a few millimetres: the file may be in
/// metres or centimetres, and the fused overlay would then sit at the wrong depth.
pub(crate) fn baseline_warning(key: &str, t: DVec3) -> Option<String> {
    let b = t.length();
    (!(0.5..=200.0).contains(&b)).then(|| {
        format!(
            "{key}: baseline |T| = {b} is outside 0.5–200; millimetres are expected (is the file in metres or centimetres?)"
        )
    })
}

/// An image size in pixels: a whole number in 1..=100000.
pub(crate) fn size(key: &str, v: f64) -> Result<u32, CalibError> {
    if v.fract() == 0.0 && (1.0..=100_000.0).contains(&v) {
        Ok(v as u32)
    } else {
        Err(CalibError::BadSize {
            key: key.into(),
            value: v.to_string(),
        })
    }
}

/// A stereo (two-camera) or monocular calibration named "left", "right" / "left".
pub(crate) fn rig(
    format: super::CalibFormat,
    image_size: Option<(u32, u32)>,
    left: Intrinsics,
    right: Option<(Intrinsics, Extrinsics)>,
) -> Calibration {
    let mut cameras = vec![super::CalibCamera {
        name: "left".into(),
        intrinsics: left,
        extrinsics: Extrinsics::default(),
    }];
    if let Some((intrinsics, extrinsics)) = right {
        cameras.push(super::CalibCamera {
            name: "right".into(),
            intrinsics,
            extrinsics,
        });
    }
    Calibration {
        format,
        image_size,
        cameras,
        warnings: Vec::new(),
    }
}

/// `e` (camera 0 → this camera) re-expressed so that `first` becomes the identity:
/// X = R_e R_fᵀ (X_f − T_f) + T_e.
pub(crate) fn relative_to(first: &Extrinsics, e: &Extrinsics) -> Extrinsics {
    let rotation = e.rotation * first.rotation.transpose();
    Extrinsics {
        rotation,
        translation_mm: e.translation_mm - rotation * first.translation_mm,
    }
}

/// What the two-camera writers need: the first camera's intrinsics and, for a stereo pair, the
/// second's with its extrinsics relative to the first. Refuses more than two cameras and
/// non-finite numbers (a file that cannot be read back is worse than no file).
pub(crate) fn for_writing(
    cal: &Calibration,
    format: &str,
) -> std::io::Result<(Intrinsics, Option<(Intrinsics, Extrinsics)>)> {
    use std::io::{Error, ErrorKind};
    let [first, rest @ ..] = cal.cameras.as_slice() else {
        return Err(Error::new(ErrorKind::InvalidInput, "no cameras to write"));
    };
    if rest.len() > 1 {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!(
                "{format} holds one or two cameras, this calibration has {}",
                cal.cameras.len()
            ),
        ));
    }
    let finite = |i: &Intrinsics| {
        [i.fx, i.fy, i.cx, i.cy, i.k1, i.k2, i.p1, i.p2, i.k3]
            .iter()
            .all(|v| v.is_finite())
    };
    let second = rest
        .first()
        .map(|c| (c.intrinsics, relative_to(&first.extrinsics, &c.extrinsics)));
    let ok = finite(&first.intrinsics)
        && second.as_ref().is_none_or(|(i, e)| {
            finite(i) && e.rotation.is_finite() && e.translation_mm.is_finite()
        });
    if !ok {
        return Err(Error::new(
            ErrorKind::InvalidData,
            "the calibration holds non-finite numbers",
        ));
    }
    Ok((first.intrinsics, second))
}

/// The rotation vector of `r` (Rodrigues), accurate for the small angles of stereo rigs: the
/// angle from atan2(|sin θ·k|, cos θ) rather than acos(cos θ), which loses half the digits near 0.
pub(crate) fn rotation_vector(r: DMat3) -> DVec3 {
    let v = DVec3::new(
        r.y_axis.z - r.z_axis.y,
        r.z_axis.x - r.x_axis.z,
        r.x_axis.y - r.y_axis.x,
    ) * 0.5;
    let cos = (r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) * 0.5;
    let sin = v.length();
    let theta = sin.atan2(cos);
    if theta > std::f64::consts::FRAC_PI_2 {
        // Far from 0 the axis from the skew part loses accuracy near π: the general log map.
        return crate::geometry::pose::rotation_to_vector(r);
    }
    if sin < 1e-300 {
        return DVec3::ZERO;
    }
    v * (theta / sin)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose::rotation_from_vector;

    #[test]
    fn numbers_as_opencv_writes_them() {
        for (text, v) in [
            ("0.", 0.0),
            ("1.0e+03", 1000.0),
            ("-4.3499e+00", -4.3499),
            ("7", 7.0),
        ] {
            assert_eq!(number("x", text), Ok(v));
        }
        for bad in [".Inf", "-.Inf", ".Nan", "nan", "1e999"] {
            assert!(
                matches!(number("x", bad), Err(CalibError::NonFinite { .. })),
                "{bad}"
            );
        }
        assert!(matches!(
            number("x", "1,5"),
            Err(CalibError::NotANumber { .. })
        ));
    }

    #[test]
    fn distortion_lengths_and_extra_terms() {
        assert_eq!(
            distortion("D", &[1.0, 2.0, 3.0, 4.0]),
            Ok([1.0, 2.0, 3.0, 4.0, 0.0])
        );
        let mut d14 = [0.0; 14];
        d14[4] = 0.5;
        assert_eq!(distortion("D", &d14), Ok([0.0, 0.0, 0.0, 0.0, 0.5]));
        d14[12] = 1e-3;
        let e = distortion("D", &d14).unwrap_err().to_string();
        assert!(
            e.contains("τx") && e.contains("k1, k2, p1, p2, k3 only"),
            "{e}"
        );
        assert!(matches!(
            distortion("D", &[0.0; 6]),
            Err(CalibError::DistortionLength { len: 6, .. })
        ));
    }

    #[test]
    fn camera_matrix_checks() {
        let k = [1000.0, 0.0, 640.0, 0.0, 990.0, 512.0, 0.0, 0.0, 1.0];
        assert_eq!(pinhole("K1", &k), Ok((1000.0, 990.0, 640.0, 512.0)));
        let mut skewed = k;
        skewed[1] = 0.5;
        assert!(matches!(
            pinhole("K1", &skewed),
            Err(CalibError::Skew { .. })
        ));
        let mut last = k;
        last[8] = 2.0;
        let e = pinhole("K1", &last).unwrap_err().to_string();
        assert!(e.contains("[2][2] is 2"), "{e}");
    }

    #[test]
    fn rotation_checks_and_vector() {
        let r = rotation_from_vector(DVec3::new(0.01, -0.03, 0.02));
        assert!(rotation("R", r).is_ok());
        let e = rotation("R", r * 1.1).unwrap_err().to_string();
        assert!(e.contains("deviates") && e.contains("2.100e-1"), "{e}");
        let flip = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
        assert!(matches!(
            rotation("R", flip),
            Err(CalibError::Determinant { .. })
        ));
        for w in [
            DVec3::new(-1.5e-5, -1.18e-3, -1.6e-5),
            DVec3::new(0.3, -0.2, 0.1),
            DVec3::new(0.0, 3.1, 0.2),
            DVec3::ZERO,
        ] {
            let back = rotation_vector(rotation_from_vector(w));
            assert!((back - w).length() <= 1e-12, "{w} → {back}");
        }
    }

    #[test]
    fn relative_extrinsics_compose() {
        let a = Extrinsics {
            rotation: rotation_from_vector(DVec3::new(0.1, 0.2, -0.1)),
            translation_mm: DVec3::new(1.0, 2.0, 3.0),
        };
        let b = Extrinsics {
            rotation: rotation_from_vector(DVec3::new(-0.05, 0.1, 0.3)),
            translation_mm: DVec3::new(-4.0, 0.5, 1.0),
        };
        let rel = relative_to(&a, &b);
        let p = DVec3::new(3.0, -7.0, 90.0);
        assert!((rel.apply(a.apply(p)) - b.apply(p)).length() < 1e-12);
    }
}
