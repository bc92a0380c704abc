//! `trajectory.json` (CONTRACT §3): the per-frame pose, shape, cameras and structure centroids.
//! The same type is the ground truth that `synth` writes and the result that `track` writes;
//! fields only the tracker knows are optional. Readers ignore unknown keys.

use crate::geometry::Intrinsics;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
pub struct Trajectory {
    pub frames: Vec<TrajectoryFrame>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TrajectoryFrame {
    pub frame: u32,
    /// q1…q12 of eq. 2.
    pub affine: Vec<f64>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub shape: BTreeMap<String, Vec<f64>>,
    #[serde(default)]
    pub cameras: Vec<Intrinsics>,
    /// Vertex means of each structure's deformed mesh in camera-0 coordinates, mm.
    #[serde(default)]
    pub centroids: BTreeMap<String, [f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub energy: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ms: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lost: Option<bool>,
}

impl Trajectory {
    /// Checks what later stages rely on; the message names the frame entry.
    pub fn validate(&self, frame_count: usize, camera_count: usize) -> Result<(), String> {
        for (i, f) in self.frames.iter().enumerate() {
            if f.affine.len() != 12 || f.affine.iter().any(|v| !v.is_finite()) {
                return Err(format!(
                    "frames[{i}] (frame {}): 'affine' must be 12 finite numbers",
                    f.frame
                ));
            }
            if f.frame as usize >= frame_count {
                return Err(format!(
                    "frames[{i}]: frame {} is beyond the scene's {} frames",
                    f.frame, frame_count
                ));
            }
            if !f.cameras.is_empty() && f.cameras.len() != camera_count {
                return Err(format!(
                    "frames[{i}] (frame {}): {} cameras listed, the scene has {}",
                    f.frame,
                    f.cameras.len(),
                    camera_count
                ));
            }
            if f.centroids.values().flatten().any(|v| !v.is_finite()) {
                return Err(format!(
                    "frames[{i}] (frame {}): non-finite centroid",
                    f.frame
                ));
            }
        }
        Ok(())
    }

    pub fn get(&self, frame: usize) -> Option<&TrajectoryFrame> {
        self.frames.iter().find(|f| f.frame as usize == frame)
    }
}
