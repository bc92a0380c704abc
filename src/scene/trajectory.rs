//! `trajectory.json` (CONTRACT §3): the per-frame pose, shape, cameras and structure centroids.
//! The same type is the ground truth that `synth` writes and the result that `track` writes;
//! fields only the tracker knows are optional. Readers ignore unknown keys.

use crate::geometry::Intrinsics;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A trajectory entry later stages cannot use. `entry` is the position in `frames` (0-based,
/// as the messages show it), `frame` the frame number the entry gives.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TrajectoryError {
    #[error("frames[{entry}] (frame {frame}): 'affine' must be 12 finite numbers")]
    Affine { entry: usize, frame: u32 },
    #[error("frames[{entry}]: frame {frame} is beyond the scene's {frame_count} frames")]
    FrameBeyondScene {
        entry: usize,
        frame: u32,
        frame_count: usize,
    },
    #[error(
        "frames[{entry}] (frame {frame}): {listed} cameras listed, the scene has {camera_count}"
    )]
    CameraCount {
        entry: usize,
        frame: u32,
        listed: usize,
        camera_count: usize,
    },
    #[error("frames[{entry}] (frame {frame}): non-finite centroid")]
    NonFiniteCentroid { entry: usize, frame: u32 },
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
pub struct Trajectory {
    pub frames: Vec<TrajectoryFrame>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TrajectoryFrame {
    pub frame: u32,
    /// q1…q12 of eq. 2.
    pub affine: Vec<f64>,
    /// Shape weights per structure. Another tool's ground truth may use the key for its own
    /// data: whatever does not read as weights is ignored, like an unknown key.
    #[serde(
        default,
        skip_serializing_if = "BTreeMap::is_empty",
        deserialize_with = "lenient::shape"
    )]
    pub shape: BTreeMap<String, Vec<f64>>,
    #[serde(default)]
    pub cameras: Vec<Intrinsics>,
    /// Vertex means of each structure's deformed mesh in camera-0 coordinates, mm.
    #[serde(default)]
    pub centroids: BTreeMap<String, [f64; 3]>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "lenient::energy"
    )]
    pub energy: Option<f64>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "lenient::iterations"
    )]
    pub iterations: Option<u32>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "lenient::ms"
    )]
    pub ms: Option<f64>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "lenient::confidence"
    )]
    pub confidence: Option<f64>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "lenient::lost"
    )]
    pub lost: Option<bool>,
    /// What the tracker knows may be wrong in this frame although it looks right (an
    /// extension of CONTRACT §3: readers ignore it). "depth_explains_zoom": the apparent size
    /// changed as in a zoom with the cameras fixed, so the depth (and the hidden structures
    /// with it) may be off.
    #[serde(
        default,
        skip_serializing_if = "Vec::is_empty",
        deserialize_with = "lenient::warnings"
    )]
    pub warnings: Vec<String>,
    /// Where each hidden structure could be (CONTRACT §3): its centroid's covariance under the
    /// fit's posterior and the 95 % sphere's radius about the fitted centroid.
    #[serde(
        default,
        skip_serializing_if = "BTreeMap::is_empty",
        deserialize_with = "lenient::hidden_region"
    )]
    pub hidden_region: BTreeMap<String, HiddenRegionEntry>,
}

/// One hidden structure's region in trajectory.json.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct HiddenRegionEntry {
    pub centroid_cov_mm2: [[f64; 3]; 3],
    pub radius95_mm: f64,
    /// The fit's unexplained rim at the centroid's depth (mm), which widens the region.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rim_residual_mm: Option<f64>,
    /// The fit's own confidence, which widens the region where it is low (before a
    /// depth-for-zoom frame's reported confidence is halved; a lost frame keeps the last good
    /// frame's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_confidence: Option<f64>,
    /// The relative standard deviation of depth along camera 0's ray that a zoom added
    /// (absent before any zoom).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zoom_depth_sd: Option<f64>,
    /// After a zoom the pose alone followed: the relative change of the hidden structures'
    /// depth since it began.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zoom_depth_change: Option<f64>,
    /// Along camera 0's line of sight through the fitted centroid: the distance from the
    /// camera to the visible surface, from there to the fitted structure, and to the
    /// nearest point of its 95 % region (mm); absent where that line meets no visible surface.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub margin95_mm: Option<f64>,
}

/// The warning of a frame where depth alone explained a change of apparent size.
pub const DEPTH_EXPLAINS_ZOOM: &str = "depth_explains_zoom";
/// The warning of a frame whose camera correction left the plausible range (focal length far
/// from calibration, or fy/fx off the lens's aspect): the frame was fitted with the cameras as
/// before it instead.
pub const CAMERA_CORRECTION_REFUSED: &str = "camera_correction_refused";
/// The warning of a lost frame whose fresh placement landed implausibly far from the last good
/// pose: it was refused and the frame stays lost.
pub const PLACEMENT_REFUSED: &str = "placement_refused";

/// The tracker's own name for a refusal a session recorded (None for anything else).
pub fn known_warning(w: &str) -> Option<&'static str> {
    [CAMERA_CORRECTION_REFUSED, PLACEMENT_REFUSED]
        .into_iter()
        .find(|k| *k == w)
}

/// Reading a value of the expected type, or its default when the file gives something else
/// under the key (CONTRACT §3: readers ignore what they do not know, whatever its type); what
/// was ignored is counted per key, so that [`Trajectory::from_json`] says it once, not once per
/// frame with neither the file nor the key.
mod lenient {
    use serde::Deserialize;
    use std::cell::RefCell;
    use std::collections::BTreeMap;

    thread_local! {
        /// Key → (values ignored, the first one's reason), while a trajectory is read.
        pub(super) static IGNORED: RefCell<BTreeMap<&'static str, (usize, String)>> =
            const { RefCell::new(BTreeMap::new()) };
    }

    fn read<'de, D, T>(d: D, key: &'static str) -> Result<T, D::Error>
    where
        D: serde::Deserializer<'de>,
        T: serde::de::DeserializeOwned + Default,
    {
        let value = serde_json::Value::deserialize(d)?;
        Ok(serde_json::from_value(value).unwrap_or_else(|e| {
            IGNORED.with_borrow_mut(|ignored| {
                ignored.entry(key).or_insert((0, e.to_string())).0 += 1;
            });
            T::default()
        }))
    }

    macro_rules! keys {
        ($($key:ident),*) => {$(
            pub(super) fn $key<'de, D, T>(d: D) -> Result<T, D::Error>
            where
                D: serde::Deserializer<'de>,
                T: serde::de::DeserializeOwned + Default,
            {
                read(d, stringify!($key))
            }
        )*};
    }
    keys!(
        shape,
        energy,
        iterations,
        ms,
        confidence,
        lost,
        warnings,
        hidden_region
    );
}

impl Trajectory {
    /// Parses a trajectory.json; the second value says, when some were, which values of
    /// another tool's type were ignored (per key: how many, and why the first was).
    pub fn from_json(text: &str) -> Result<(Self, Option<String>), serde_json::Error> {
        lenient::IGNORED.with_borrow_mut(|i| i.clear());
        let parsed = serde_json::from_str::<Self>(text);
        let ignored = lenient::IGNORED.with_borrow_mut(std::mem::take);
        let note = (!ignored.is_empty()).then(|| {
            let keys: Vec<String> = ignored
                .iter()
                .map(|(key, (n, first))| format!("{n} under '{key}' ({first})"))
                .collect();
            format!("ignored values of another tool's type: {}", keys.join("; "))
        });
        Ok((parsed?, note))
    }

    /// Checks what later stages rely on; the error names the frame entry.
    pub fn validate(&self, frame_count: usize, camera_count: usize) -> Result<(), TrajectoryError> {
        for (entry, f) in self.frames.iter().enumerate() {
            let frame = f.frame;
            if f.affine.len() != 12 || f.affine.iter().any(|v| !v.is_finite()) {
                return Err(TrajectoryError::Affine { entry, frame });
            }
            if frame as usize >= frame_count {
                return Err(TrajectoryError::FrameBeyondScene {
                    entry,
                    frame,
                    frame_count,
                });
            }
            if !f.cameras.is_empty() && f.cameras.len() != camera_count {
                return Err(TrajectoryError::CameraCount {
                    entry,
                    frame,
                    listed: f.cameras.len(),
                    camera_count,
                });
            }
            if f.centroids.values().flatten().any(|v| !v.is_finite()) {
                return Err(TrajectoryError::NonFiniteCentroid { entry, frame });
            }
        }
        Ok(())
    }

    pub fn get(&self, frame: usize) -> Option<&TrajectoryFrame> {
        self.frames.iter().find(|f| f.frame as usize == frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Another tool's values under known keys are ignored (CONTRACT §3) and counted per key
    /// for one note; a clean file gives none; a value of the wrong type where nothing can
    /// stand in (the affine) is still an error.
    #[test]
    fn values_of_another_type_are_ignored_and_counted_once() {
        let frame = |t: u32, extra: &str| {
            format!(r#"{{"frame": {t}, "affine": [1,0,0,0,1,0,0,0,1,0,0,150]{extra}}}"#)
        };
        let text = format!(
            r#"{{"frames": [{}, {}, {}]}}"#,
            frame(0, r#", "shape": "catalog-7", "tools": [1, 2]"#),
            frame(1, r#", "shape": {"kidney": "x"}, "lost": "no""#),
            frame(2, ""),
        );
        let (traj, note) = Trajectory::from_json(&text).unwrap();
        assert_eq!(traj.frames.len(), 3);
        assert!(traj.frames[0].shape.is_empty() && traj.frames[1].lost.is_none());
        let note = note.unwrap();
        assert!(
            note.contains("2 under 'shape'") && note.contains("1 under 'lost'"),
            "{note}"
        );
        let (_, clean) =
            Trajectory::from_json(&format!(r#"{{"frames": [{}]}}"#, frame(0, ""))).unwrap();
        assert_eq!(clean, None, "the count starts afresh per file");
        assert!(Trajectory::from_json(r#"{"frames": [{"frame": 0, "affine": "I"}]}"#).is_err());
    }
}
