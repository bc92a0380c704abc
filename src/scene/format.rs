//! The on-disk `scene.json` (format `endofuse-scene/1`, CONTRACT §2) as serde types. Numbers
//! that must be positive are read as plain numbers and checked in `load`, so that the error
//! says what is wrong in words rather than in serde's type names.

use serde::{Deserialize, Serialize};

pub const FORMAT_V1: &str = "endofuse-scene/1";

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SceneFile {
    pub format: String,
    #[serde(default = "default_fps")]
    pub fps: f64,
    pub frame_count: i64,
    pub cameras: Vec<CameraEntry>,
    pub structures: Vec<StructureEntry>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_pose: Option<InitialPoseEntry>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seeds: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<GroundTruthEntry>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub zoom_changes: Vec<[i64; 2]>,
    /// An extension of CONTRACT §2, optional: the lens's k1 as a function of focal length,
    /// k1 = c₀ + c₁/f + c₂/f² with f = fx / image width (the paper's §IV-A form). With it, LSC
    /// moves each camera's calibrated k1 by the relation's change from the calibrated fx to its
    /// fx estimate; without it, LSC holds k1 at calibration (silhouettes
    /// barely see k1: left free it drifted to −1.3 on a zoom in and out, issue 14).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    /// (A list, checked in `load`, so a wrong length is named in words.)
    pub k1_vs_focal: Option<Vec<f64>>,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn default_fps() -> f64 {
    30.0
}

fn identity() -> [[f64; 3]; 3] {
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraEntry {
    pub name: String,
    pub frames: FramesEntry,
    pub width: i64,
    pub height: i64,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    #[serde(default)]
    pub k1: f64,
    #[serde(default)]
    pub k2: f64,
    #[serde(default)]
    pub p1: f64,
    #[serde(default)]
    pub p2: f64,
    /// OpenCV's third radial coefficient (r⁶); optional, written only when non-zero.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub k3: f64,
    #[serde(default = "identity")]
    pub rotation: [[f64; 3]; 3],
    #[serde(default)]
    pub translation: [f64; 3],
}

/// Where a camera's frames are (CONTRACT §2): a path template with `{frame}` (an image
/// sequence), the path of a video file, or one view of a side-by-side stereo video.
#[derive(Debug, Clone, Serialize, PartialEq)]
#[serde(untagged)]
pub enum FramesEntry {
    Path(String),
    Video {
        video: String,
        /// `[x, y, width, height]` of the view in the video's frames, pixels.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        crop: Option<[i64; 4]>,
    },
}

impl From<String> for FramesEntry {
    fn from(s: String) -> Self {
        FramesEntry::Path(s)
    }
}

impl<'de> Deserialize<'de> for FramesEntry {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        const WHAT: &str = "'frames' must be a path template like \"left/{frame:06}.png\", a video file, or {\"video\": FILE, \"crop\": [x, y, width, height]}";
        match serde_json::Value::deserialize(d)? {
            serde_json::Value::String(s) => Ok(FramesEntry::Path(s)),
            serde_json::Value::Object(map) => {
                if let Some(k) = map.keys().find(|k| *k != "video" && *k != "crop") {
                    return Err(D::Error::custom(format!(
                        "unknown key '{k}' in frames: {WHAT}"
                    )));
                }
                let video = map
                    .get("video")
                    .and_then(|v| v.as_str())
                    .ok_or_else(|| D::Error::custom(WHAT))?
                    .to_string();
                let crop = match map.get("crop") {
                    None | Some(serde_json::Value::Null) => None,
                    Some(c) => {
                        Some(serde_json::from_value::<[i64; 4]>(c.clone()).map_err(|_| {
                            D::Error::custom(
                                "frames.crop must be 4 whole numbers [x, y, width, height]",
                            )
                        })?)
                    }
                };
                Ok(FramesEntry::Video { video, crop })
            }
            _ => Err(D::Error::custom(WHAT)),
        }
    }
}

impl CameraEntry {
    /// The scene.json entry of a camera whose frames are `frames`.
    pub fn from_camera(c: &crate::geometry::Camera, frames: FramesEntry) -> Self {
        let i = &c.intrinsics;
        let r = c.extrinsics.rotation;
        CameraEntry {
            name: c.name.clone(),
            frames,
            width: c.width as i64,
            height: c.height as i64,
            fx: i.fx,
            fy: i.fy,
            cx: i.cx,
            cy: i.cy,
            k1: i.k1,
            k2: i.k2,
            p1: i.p1,
            p2: i.p2,
            k3: i.k3,
            rotation: [0, 1, 2].map(|row| [r.x_axis[row], r.y_axis[row], r.z_axis[row]]),
            translation: c.extrinsics.translation_mm.to_array(),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StructureEntry {
    pub name: String,
    pub label: i64,
    #[serde(default = "yes")]
    pub visible: bool,
    pub mesh: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub catalog: Option<String>,
}

fn yes() -> bool {
    true
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct InitialPoseEntry {
    pub affine: Vec<f64>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
pub struct GroundTruthEntry {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub labels: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<String>,
    /// Hidden structures' projections; CONTRACT §2's layout when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hidden: Option<String>,
}

/// Where hidden-structure ground truth lives when `ground_truth.hidden` is not given.
pub const DEFAULT_HIDDEN_TEMPLATE: &str = "gt/hidden/{structure}/{camera}/{frame:06}.png";
