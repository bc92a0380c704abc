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
    pub frames: String,
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
