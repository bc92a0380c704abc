//! Resolving a [`FitConfig`] into the settings of one fit ([`FitParams`]) for a mode and a
//! phase, recording what a run resolved to ([`ResolvedConfig`], in metrics.json), and reading a
//! configuration back ([`RecordedRun`]).

use super::{FitConfig, Mode, Phase, Zoom};
use super::{PriorConfig, SolverConfig};
use crate::fit::lines::EnergyParams;
use crate::fit::stereo::StereoParams;
use serde::Serialize;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// The settings of one fit, resolved from a [`FitConfig`] for a mode and phase.
#[derive(Debug, Clone, Serialize)]
pub struct FitParams {
    pub mode: Mode,
    /// Whether the π block runs (LSC inside a zoom change).
    pub correct_cameras: bool,
    /// The pose stays where it starts: only the shape (and camera) blocks move. Never set by
    /// tracking; the paper's shape-recovery experiment (§IV-A, Fig. 6) fixes the pose.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub hold_pose: bool,
    /// Pyramid levels visited, coarse to fine.
    pub levels: Vec<usize>,
    /// T → W → π rounds per level.
    pub rounds: usize,
    /// Gauss–Newton steps per block and round.
    pub steps: usize,
    /// Gauss–Newton steps taken on one set of lines before they are rebuilt.
    pub rebuild_every: usize,
    pub solver: SolverConfig,
    /// The line energy (its `level` is set per pyramid level).
    pub energy: EnergyParams,
    pub priors: PriorConfig,
    /// The stereo depth term (matched once per pyramid level).
    pub stereo: StereoParams,
    /// Raised by whoever wants the fit to stop: checked between Gauss–Newton steps, so a
    /// cancel is answered within one step (a few ms), not one frame.
    #[serde(skip)]
    pub cancel: Option<Arc<AtomicBool>>,
    /// Also take the joint information of the fitted state ([`crate::fit::FrameFit`]'s
    /// `information`), for the hidden regions: the tracker sets it; placement hypotheses and
    /// the experiments, whose fits nobody asks that of, do not pay for it.
    #[serde(skip)]
    pub information: bool,
}

impl FitParams {
    /// The line energy's settings at pyramid `level`.
    pub fn energy_at(&self, level: usize) -> EnergyParams {
        EnergyParams {
            level,
            ..self.energy
        }
    }
}

impl FitConfig {
    /// The settings of one fit in `mode` and `phase`, at tracking level `fit_level` (see
    /// [`TrackingConfig::fit_level`]), inside a zoom or not. Pure: the same inputs give the
    /// same settings.
    pub fn resolve(&self, mode: Mode, phase: Phase, zoom: Zoom, fit_level: usize) -> FitParams {
        let mut p = FitParams {
            mode,
            correct_cameras: false,
            hold_pose: false,
            levels: Vec::new(),
            rounds: 0,
            steps: 0,
            rebuild_every: 0,
            solver: self.solver,
            energy: self.energy,
            priors: self.priors,
            stereo: self.stereo,
            cancel: None,
            information: false,
        };
        match phase {
            Phase::FirstFrame => {
                let f = &self.first_frame;
                p.levels = (0..=f.coarser_levels)
                    .rev()
                    .map(|k| fit_level + k)
                    .collect();
                (p.rounds, p.steps, p.rebuild_every) = (f.rounds, f.steps, f.rebuild_every);
                p.priors.hold_pose_at(f.pose_damping);
                p.stereo.search_px = f.stereo_search_px;
            }
            Phase::Tracked => {
                let f = &self.tracked_frame;
                p.levels = vec![fit_level];
                (p.rounds, p.steps, p.rebuild_every) = (f.rounds, f.steps, f.rebuild_every);
                p.priors.shape = f.shape_prior;
            }
            Phase::Placement => {
                let f = &self.placement;
                p.mode = Mode::R;
                p.levels = f.levels.clone();
                (p.rounds, p.steps, p.rebuild_every) = (f.rounds, f.steps, f.rebuild_every);
                p.priors.hold_pose_at(f.pose_damping);
            }
        }
        let z = &self.zoom;
        match zoom {
            Zoom::Off => {}
            Zoom::PoseOnly => p.priors.scale_pose_damping(z.pose_only_damping_factor),
            Zoom::Cameras if p.mode == Mode::LSC => {
                p.correct_cameras = true;
                p.priors.scale_pose_damping(z.cameras_pose_damping_factor);
                p.priors.shape_damping = p.priors.shape_damping.max(z.cameras_shape_damping);
                p.rounds = p.rounds.max(z.cameras_min_rounds);
                p.rebuild_every = p.rebuild_every.min(z.cameras_rebuild_every);
                p.priors.camera_damping *= z.camera_damping_factor;
                p.stereo.weight *= z.cameras_stereo_weight_factor;
                if phase == Phase::Tracked {
                    p.levels = (0..=z.cameras_coarser_levels)
                        .rev()
                        .map(|k| fit_level + k)
                        .collect();
                }
            }
            // Only LSC corrects cameras.
            Zoom::Cameras => {}
        }
        p
    }
}

/// What a run used: the configuration, the tracking level, and what it resolved to in every
/// phase of the run's mode (written into `track`'s metrics.json).
#[derive(Debug, Clone, Serialize)]
pub struct ResolvedConfig {
    pub mode: Mode,
    /// The inclusive frame range the run fitted, where it was one range.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames: Option<[usize; 2]>,
    pub fit_level: usize,
    pub fit: FitConfig,
    pub resolved: std::collections::BTreeMap<&'static str, FitParams>,
}

impl FitConfig {
    /// This configuration with the settings of every phase of `mode` at tracking level
    /// `fit_level`.
    pub fn resolved(&self, mode: Mode, fit_level: usize) -> ResolvedConfig {
        let zoom = if mode == Mode::LSC {
            Zoom::Cameras
        } else {
            Zoom::PoseOnly
        };
        let resolved = [
            ("first_frame", Phase::FirstFrame, Zoom::Off),
            ("tracked_frame", Phase::Tracked, Zoom::Off),
            ("first_frame_in_zoom", Phase::FirstFrame, zoom),
            ("tracked_frame_in_zoom", Phase::Tracked, zoom),
            ("placement", Phase::Placement, Zoom::Off),
        ]
        .into_iter()
        .map(|(name, phase, zoom)| (name, self.resolve(mode, phase, zoom, fit_level)))
        .collect();
        ResolvedConfig {
            mode,
            frames: None,
            fit_level,
            fit: self.clone(),
            resolved,
        }
    }
}

/// Why a configuration file cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum ConfigFileError {
    #[error("malformed fit configuration: {0}")]
    Json(#[from] serde_json::Error),
    #[error(
        "this metrics.json records no fit configuration (it was written before runs recorded one)"
    )]
    NoConfig,
    #[error(
        "this is a `classify` metrics.json (it holds a forest, no fit): --config takes a fit configuration or a `track` run's metrics.json"
    )]
    ClassifyMetrics,
}

/// Knobs added since 2026-12-06 with a default that changes the fit, and the value that does
/// what the fit did before each existed: a run's metrics.json that lacks one ran without it,
/// so it is read as that value, not as today's default (which a configuration file of one's
/// own still gets). Knobs added earlier (e.g. `zoom.detector.warmup_frames`,
/// `tracking.reinit_max_jump_mm`) are not listed: a metrics.json from before them replays
/// with today's value. Every knob added from now on with such a default belongs here.
const BEFORE_IT_EXISTED: [(&str, &str, f64); 6] = [
    // 2026-12-06, thirteenth session.
    ("placement", "polish_deg", 0.0),
    // 2026-12-06, fourteenth session.
    ("placement", "initial_polish_deg", 0.0),
    // 2026-12-06, fifteenth session.
    ("hidden_region", "rim_residual_floor_mm", 0.0),
    // 2026-12-06, sixteenth session.
    ("hidden_region", "model_error_per_confidence_shortfall", 0.0),
    // 2026-12-07, twenty-third session.
    ("placement", "silhouette_centring", 0.0),
    // 2026-12-07, twenty-fourth session.
    ("energy", "max_lines_per_structure", 0.0),
];

/// What `track --config` reads: a configuration, and where the file is a run's metrics.json,
/// the mode and frames that run used.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedRun {
    pub config: FitConfig,
    pub mode: Option<Mode>,
    pub frames: Option<(usize, usize)>,
}

impl RecordedRun {
    pub fn from_json(text: &str) -> Result<RecordedRun, ConfigFileError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let value: serde_json::Value = serde_json::from_str(text)?;
        // A metrics file: it has timing; its configuration, if any, sits under config.
        let Some(recorded) = value.get("config") else {
            if value.get("timing").is_some() {
                return Err(ConfigFileError::NoConfig);
            }
            if value.get("forest").is_some() && value.get("fit").is_none() {
                return Err(ConfigFileError::ClassifyMetrics);
            }
            return Ok(RecordedRun {
                config: serde_json::from_value(value)?,
                mode: None,
                frames: None,
            });
        };
        let fit = recorded.get("fit").ok_or(ConfigFileError::NoConfig)?;
        let mode = recorded
            .get("mode")
            .map(|m| serde_json::from_value::<Mode>(m.clone()))
            .transpose()?;
        let frames = recorded
            .get("frames")
            .map(|f| serde_json::from_value::<[usize; 2]>(f.clone()))
            .transpose()?;
        let mut fit = fit.clone();
        if let Some(sections) = fit.as_object_mut() {
            for (section, key, before) in BEFORE_IT_EXISTED {
                let section = sections
                    .entry(section)
                    .or_insert_with(|| serde_json::json!({}));
                if let Some(keys) = section.as_object_mut() {
                    // A whole number as an integer: counts (usize) refuse 0.0, and the
                    // floating-point knobs read 0 as well as 0.0.
                    keys.entry(key).or_insert_with(|| {
                        if before.fract() == 0.0 && before.abs() < 1e15 {
                            (before as i64).into()
                        } else {
                            before.into()
                        }
                    });
                }
            }
        }
        Ok(RecordedRun {
            config: serde_json::from_value(fit)?,
            mode,
            frames: frames.map(|[a, b]| (a, b)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run recorded before a knob existed ran without it: its metrics.json reads as the
    /// knob's value then, a configuration file of one's own as today's default.
    #[test]
    fn a_recorded_run_without_a_later_knob_replays_without_it() {
        let c = FitConfig::default();
        let defaults = serde_json::to_value(&c).unwrap();
        let mut before = serde_json::to_value(c.resolved(Mode::LSC, 1)).unwrap();
        let mut own = defaults.clone();
        for (section, key, then) in BEFORE_IT_EXISTED {
            assert_ne!(
                defaults[section][key].as_f64(),
                Some(then),
                "{section}.{key}: today's default is what the fit did before"
            );
            for config in [&mut before["fit"], &mut own] {
                config[section].as_object_mut().unwrap().remove(key);
            }
        }
        let metrics = serde_json::json!({ "mode": "LSC", "timing": {}, "config": before });
        let run = RecordedRun::from_json(&metrics.to_string()).unwrap();
        assert_eq!(run.config.placement.refined, c.placement.refined);
        let replayed = serde_json::to_value(&run.config).unwrap();
        let own = RecordedRun::from_json(&own.to_string()).unwrap().config;
        let own = serde_json::to_value(&own).unwrap();
        for (section, key, then) in BEFORE_IT_EXISTED {
            assert_eq!(
                replayed[section][key].as_f64(),
                Some(then),
                "{section}.{key}"
            );
            assert_eq!(own[section][key], defaults[section][key], "{section}.{key}");
        }
    }
}
