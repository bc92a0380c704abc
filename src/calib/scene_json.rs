//! The `cameras` of a scene.json (`endofuse-scene/1`, CONTRACT §2): name, width, height, fx, fy,
//! cx, cy, k1, k2, p1, p2, optional k3, `rotation` (rows) and `translation` (mm), mapping
//! camera-0 coordinates into each camera (eq. 11). Everything else in the file, and keys inside a
//! camera this reader does not need (`frames`, …), is ignored: the file is read for its cameras
//! only, with a local serde struct so that this module does not depend on the scene reader. A
//! scene whose first camera is not the identity is re-expressed relative to it (the same rig in
//! the frame [`super::Calibration`] promises); all cameras must share one image size.

use glam::DVec3;
use serde::Deserialize;

use super::checks;
use super::{CalibCamera, CalibError, CalibFormat, Calibration};
use crate::geometry::{Extrinsics, Intrinsics};

#[derive(Deserialize)]
struct SceneFile {
    format: Option<serde_json::Value>,
    cameras: Option<Vec<CameraEntry>>,
}

fn identity() -> [[f64; 3]; 3] {
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
}

#[derive(Deserialize)]
struct CameraEntry {
    name: String,
    width: f64,
    height: f64,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    #[serde(default)]
    k1: f64,
    #[serde(default)]
    k2: f64,
    #[serde(default)]
    p1: f64,
    #[serde(default)]
    p2: f64,
    #[serde(default)]
    k3: f64,
    #[serde(default = "identity")]
    rotation: [[f64; 3]; 3],
    #[serde(default)]
    translation: [f64; 3],
}

pub(crate) fn parse(text: &str) -> Result<Calibration, CalibError> {
    let file: SceneFile =
        serde_json::from_str(text).map_err(|e| CalibError::Json(e.to_string()))?;
    if let Some(f) = file
        .format
        .as_ref()
        .filter(|f| f.as_str() != Some("endofuse-scene/1"))
    {
        log::warn!("scene.json format is {f}, not endofuse-scene/1: reading its cameras anyway");
    }
    let entries = file.cameras.ok_or_else(|| CalibError::MissingKey {
        key: "cameras".into(),
        purpose: "the scene's camera list".into(),
    })?;
    let mut cameras = Vec::with_capacity(entries.len());
    let mut sizes = Vec::with_capacity(entries.len());
    for (i, c) in entries.iter().enumerate() {
        let key = |k: &str| format!("cameras[{i}].{k}");
        sizes.push((
            checks::size(&key("width"), c.width)?,
            checks::size(&key("height"), c.height)?,
        ));
        let rows: [f64; 9] = std::array::from_fn(|k| c.rotation[k / 3][k % 3]);
        let numbers = [c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, c.p1, c.p2, c.k3];
        // serde_json refuses numbers beyond f64, but be explicit: the rule is finite numbers.
        if let Some(v) = numbers
            .iter()
            .chain(&rows)
            .chain(&c.translation)
            .find(|v| !v.is_finite())
        {
            return Err(CalibError::NonFinite {
                key: key("…"),
                text: v.to_string(),
            });
        }
        let rotation = checks::rotation(&key("rotation"), checks::mat3_from_rows(&rows))?;
        cameras.push(CalibCamera {
            name: c.name.clone(),
            intrinsics: Intrinsics {
                fx: c.fx,
                fy: c.fy,
                cx: c.cx,
                cy: c.cy,
                k1: c.k1,
                k2: c.k2,
                p1: c.p1,
                p2: c.p2,
                k3: c.k3,
            },
            extrinsics: Extrinsics {
                rotation,
                translation_mm: DVec3::from_array(c.translation),
            },
        });
    }
    let Some(first) = cameras.first().map(|c| c.extrinsics) else {
        return Err(CalibError::MissingKey {
            key: "cameras".into(),
            purpose: "at least one camera (the list is empty)".into(),
        });
    };
    if first != Extrinsics::default() {
        log::info!(
            "scene.json: camera 0 is not at the origin; cameras re-expressed relative to it"
        );
    }
    let mut warnings = Vec::new();
    for (i, c) in cameras.iter_mut().enumerate() {
        c.extrinsics = if i == 0 {
            Extrinsics::default()
        } else {
            checks::relative_to(&first, &c.extrinsics)
        };
        if i > 0 {
            warnings.extend(checks::baseline_warning(
                &format!("cameras[{i}].translation"),
                c.extrinsics.translation_mm,
            ));
        }
    }
    if let Some(i) = sizes.iter().position(|s| *s != sizes[0]) {
        return Err(CalibError::MixedSizes {
            first: cameras[0].name.clone(),
            w0: sizes[0].0,
            h0: sizes[0].1,
            other: cameras[i].name.clone(),
            w1: sizes[i].0,
            h1: sizes[i].1,
        });
    }
    Ok(Calibration {
        format: CalibFormat::SceneJson,
        image_size: sizes.first().copied(),
        cameras,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose::rotation_from_vector;

    fn camera(name: &str, w: u32, rotation: [[f64; 3]; 3], t: [f64; 3]) -> serde_json::Value {
        serde_json::json!({"name": name, "frames": "x/{frame:06}.png", "width": w, "height": 540,
            "fx": 1000.0, "fy": 1000.0, "cx": 480.0, "cy": 270.0, "k1": 0.01,
            "rotation": rotation, "translation": t})
    }

    fn rows(m: glam::DMat3) -> [[f64; 3]; 3] {
        m.transpose().to_cols_array_2d()
    }

    #[test]
    fn cameras_only_and_relative_to_the_first() {
        let r0 = rotation_from_vector(DVec3::new(0.1, -0.2, 0.05));
        let r1 = rotation_from_vector(DVec3::new(0.12, -0.18, 0.04));
        let text = serde_json::json!({"format": "endofuse-scene/1", "whatever": [1, {"a": null}],
            "cameras": [camera("a", 960, rows(r0), [1.0, 2.0, 3.0]), camera("b", 960, rows(r1), [-3.0, 2.0, 3.0])]})
        .to_string();
        let cal = parse(&text).unwrap();
        assert_eq!(cal.image_size, Some((960, 540)));
        assert_eq!(cal.cameras[0].extrinsics, Extrinsics::default());
        assert_eq!(cal.cameras[1].name, "b");
        assert_eq!(cal.cameras[0].intrinsics.k2, 0.0);
        // A world point maps to the same camera-b point either way.
        let p = DVec3::new(5.0, -3.0, 120.0);
        let in_a = r0 * p + DVec3::new(1.0, 2.0, 3.0);
        let in_b = r1 * p + DVec3::new(-3.0, 2.0, 3.0);
        assert!((cal.cameras[1].extrinsics.apply(in_a) - in_b).length() < 1e-12);
    }

    #[test]
    fn refuses_what_a_calibration_cannot_be() {
        let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mixed = serde_json::json!({"cameras": [camera("a", 960, id, [0.0; 3]), camera("b", 640, id, [-4.0, 0.0, 0.0])]});
        let e = parse(&mixed.to_string()).unwrap_err().to_string();
        assert!(e.contains("a: 960×540") && e.contains("b: 640×540"), "{e}");
        let scaled = [[1.1, 0.0, 0.0], [0.0, 1.1, 0.0], [0.0, 0.0, 1.1]];
        let bad = serde_json::json!({"cameras": [camera("a", 960, scaled, [0.0; 3])]});
        let e = parse(&bad.to_string()).unwrap_err().to_string();
        assert!(e.contains("cameras[0].rotation is not a rotation"), "{e}");
        let e = parse("{\"fps\": 30}").unwrap_err().to_string();
        assert!(e.contains("missing cameras"), "{e}");
        assert!(
            parse("{\"cameras\": []}")
                .unwrap_err()
                .to_string()
                .contains("empty")
        );
        let e = parse("{\"cameras\": [{\"name\": \"a\"}]}")
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field `width`"), "{e}");
    }
}
