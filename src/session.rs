//! The session file (`endofuse-session/1`, JSON): which scene, the painted seeds, the fit
//! settings, the placed pose, the trained forest and the tracking results. Written atomically
//! (temporary file, then rename), both when the user saves and by the autosave, so a crash
//! loses at most the strokes since the last autosave and never leaves half a file.

use crate::appearance::Appearance;
use crate::error::{Error, InputError};
use crate::fit::FitState;
use crate::geometry::Affine;
use crate::plane::Plane;
use crate::scene::Seeds;
use crate::scene::write::write_json_atomic;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub const SESSION_FORMAT: &str = "endofuse-session/1";

/// Fit settings the side panel edits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FitSettings {
    /// R, L, LS or LSC. LSC by default: it corrects the cameras only where a zoom change is
    /// marked or detected, so without a zoom it gives LS's result, and through one it keeps a
    /// hidden tumour where LS would put it centimetres off. (Sessions of earlier versions
    /// also carry `camera_correction`: ignored, the mode says it.)
    pub mode: String,
    pub trees: usize,
    /// Retrain shortly after the strokes change.
    pub live_update: bool,
    /// Each tree's draws in that live retrain (0: all of them), so the maps follow a stroke at
    /// once ([`crate::appearance::LIVE_PREVIEW_SAMPLES_PER_TREE`]); tracking and placing
    /// retrain on all first.
    pub live_preview_samples: usize,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self {
            mode: "LSC".into(),
            trees: 20,
            live_update: false,
            live_preview_samples: crate::appearance::LIVE_PREVIEW_SAMPLES_PER_TREE,
        }
    }
}

/// One tracked frame as the session keeps it (labels are re-rendered from the state).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameResult {
    pub frame: usize,
    pub state: FitState,
    pub energy: f64,
    pub confidence: f64,
    pub lost: bool,
    pub ms: f64,
    /// Dice per visible structure and camera against ground truth, when it exists.
    #[serde(default)]
    pub dice: Vec<(String, f64)>,
    /// Distance of each hidden structure's fitted centroid from the true one (mm), when the
    /// scene has a ground-truth trajectory: what a good Dice cannot show.
    #[serde(default)]
    pub hidden_error_mm: Vec<(String, f64)>,
    /// The apparent size changed as in a zoom with the cameras fixed (see
    /// [`crate::fit::tracker::TrackedFrame::depth_explains_zoom`]).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub depth_explains_zoom: bool,
    /// What the tracker refused in this frame (`camera_correction_refused`,
    /// `placement_refused`; see [`crate::fit::tracker::TrackedFrame::refused`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub refused: Vec<String>,
    /// Where each hidden structure could be (as trajectory.json's `hidden_region`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub hidden_region: BTreeMap<String, crate::scene::trajectory::HiddenRegionEntry>,
}

impl FrameResult {
    /// The hidden regions of this result about the centroids of its state (`centroids` as
    /// [`crate::fit::tracker::render_state`] gives them).
    pub fn hidden_regions(
        &self,
        centroids: &[(String, glam::DVec3)],
    ) -> Vec<crate::fit::hidden_region::HiddenRegion> {
        self.hidden_region
            .iter()
            .filter_map(|(name, e)| {
                let (_, c) = centroids.iter().find(|(n, _)| n == name)?;
                Some(crate::fit::hidden_region::HiddenRegion {
                    structure: name.clone(),
                    centroid_mm: *c,
                    covariance_mm2: e.centroid_cov_mm2,
                    radius_mm: e.radius95_mm,
                    rim_residual_mm: e.rim_residual_mm.unwrap_or(0.0),
                    fit_confidence: e.fit_confidence.unwrap_or(1.0),
                    zoom_depth_sd: e.zoom_depth_sd.unwrap_or(0.0),
                    zoom_depth_change: e.zoom_depth_change,
                    margin: match (e.surface_mm, e.depth_mm, e.margin95_mm) {
                        (Some(surface_mm), Some(fitted_mm), Some(region_mm)) => {
                            Some(crate::fit::depth_margin::DepthMargin {
                                surface_mm,
                                fitted_mm,
                                region_mm,
                            })
                        }
                        _ => None,
                    },
                })
            })
            .collect()
    }
}

/// One painted view and frame, run-length coded: (run length, seed value).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeedLayer {
    pub camera: usize,
    pub frame: usize,
    pub width: usize,
    pub height: usize,
    pub runs: Vec<(u32, u8)>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Session {
    pub format: String,
    /// The scene as opened: a folder, a scene.json, or "demo".
    pub scene: String,
    pub seeds: Vec<SeedLayer>,
    #[serde(default)]
    pub settings: FitSettings,
    #[serde(default)]
    pub placement: Option<Affine>,
    #[serde(default)]
    pub forest: Option<Appearance>,
    #[serde(default)]
    pub results: Vec<FrameResult>,
}

pub fn encode_seeds(seeds: &Seeds) -> Vec<SeedLayer> {
    let mut out = Vec::new();
    for (camera, frames) in seeds.by_camera.iter().enumerate() {
        for (&frame, img) in frames {
            let mut runs: Vec<(u32, u8)> = Vec::new();
            for &v in &img.data {
                match runs.last_mut() {
                    Some((n, last)) if *last == v => *n += 1,
                    _ => runs.push((1, v)),
                }
            }
            out.push(SeedLayer {
                camera,
                frame,
                width: img.width,
                height: img.height,
                runs,
            });
        }
    }
    out
}

/// Decodes seed layers for cameras of `sizes`; a layer of the wrong size or length is an
/// error naming `origin`.
pub fn decode_seeds(
    layers: &[SeedLayer],
    sizes: &[(usize, usize)],
    origin: &Path,
) -> Result<Seeds, InputError> {
    let mut by_camera = vec![BTreeMap::new(); sizes.len()];
    for l in layers {
        let Some(&(w, h)) = sizes.get(l.camera) else {
            return Err(InputError::new(
                origin,
                format!(
                    "seeds name camera {}, the scene has {}",
                    l.camera,
                    sizes.len()
                ),
            ));
        };
        if (l.width, l.height) != (w, h) {
            return Err(InputError::new(
                origin,
                format!(
                    "seeds of camera {} frame {} are {}×{}, the camera is {w}×{h}",
                    l.camera, l.frame, l.width, l.height
                ),
            ));
        }
        let mut data = Vec::with_capacity(w * h);
        for &(n, v) in &l.runs {
            if data.len() + n as usize > w * h {
                break;
            }
            data.extend(std::iter::repeat_n(v, n as usize));
        }
        if data.len() != w * h {
            return Err(InputError::new(
                origin,
                format!(
                    "seeds of camera {} frame {} hold {} pixels, not {}",
                    l.camera,
                    l.frame,
                    data.len(),
                    w * h
                ),
            ));
        }
        by_camera[l.camera].insert(l.frame, Plane::from_vec(w, h, data).expect("sized above"));
    }
    Ok(Seeds { by_camera })
}

impl Session {
    pub fn save(&self, path: &Path) -> Result<(), Error> {
        write_json_atomic(path, self)
    }

    /// Reads and checks a session file.
    pub fn load(path: &Path) -> Result<Session, InputError> {
        let text = crate::error::read_text(path)
            .map_err(|e| InputError::new(path, format!("cannot read: {e}")))?;
        let session: Session = serde_json::from_str(&text)
            .map_err(|e| InputError::new(path, format!("not a session file: {e}")))?;
        if session.format != SESSION_FORMAT {
            return Err(InputError::new(
                path,
                format!(
                    "format is \"{}\", this version reads \"{SESSION_FORMAT}\"",
                    session.format
                ),
            ));
        }
        Ok(session)
    }
}

/// Where the autosave of a scene lives in the folder of autosaves `dir`: one file per scene.
pub fn autosave_path(dir: &Path, scene: &str) -> PathBuf {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for b in scene.bytes() {
        hash = (hash ^ b as u64).wrapping_mul(0x0100_0000_01b3);
    }
    dir.join(format!("autosave-{hash:016x}.json"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_round_trip_and_bad_layers_are_refused() {
        let mut img = Plane::filled(7, 5, 0u8);
        img.data[3] = 255;
        img.data[10..14].fill(1);
        let seeds = Seeds {
            by_camera: vec![BTreeMap::from([(2, img)]), BTreeMap::new()],
        };
        let layers = encode_seeds(&seeds);
        assert_eq!(layers.len(), 1);
        let back = decode_seeds(&layers, &[(7, 5), (7, 5)], Path::new("s.json")).unwrap();
        assert_eq!(back, seeds);
        let e = decode_seeds(&layers, &[(8, 5), (8, 5)], Path::new("s.json")).unwrap_err();
        assert!(
            e.to_string().contains("s.json") && e.to_string().contains("7×5"),
            "{e}"
        );
        let mut short = layers.clone();
        short[0].runs.pop();
        assert!(decode_seeds(&short, &[(7, 5)], Path::new("s.json")).is_err());
    }

    #[test]
    fn sessions_save_atomically_and_refuse_other_formats() {
        let dir = std::env::temp_dir().join(format!("endofuse-session-{}", std::process::id()));
        let path = dir.join("a.endofuse.json");
        let s = Session {
            format: SESSION_FORMAT.into(),
            scene: "demo".into(),
            seeds: Vec::new(),
            settings: FitSettings::default(),
            placement: None,
            forest: None,
            results: Vec::new(),
        };
        s.save(&path).unwrap();
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "temporary left behind: {leftovers:?}");
        assert_eq!(Session::load(&path).unwrap(), s);
        std::fs::write(
            &path,
            "{\"format\": \"other/9\", \"scene\": \"demo\", \"seeds\": []}",
        )
        .unwrap();
        assert!(
            Session::load(&path)
                .unwrap_err()
                .to_string()
                .contains("other/9")
        );
        std::fs::write(&path, "{").unwrap();
        assert!(Session::load(&path).is_err());
        let _ = std::fs::remove_dir_all(dir);
    }
}
