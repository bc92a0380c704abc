//! Which configurations the fit can work with. A configuration read back with
//! `track --config` is user input: a non-finite or negative weight, an empty range or a
//! pyramid level beyond [`MAX_LEVEL`] is refused with the key's path, before any fit runs.

use super::FitConfig;
use std::fmt::Display;
use std::ops::RangeInclusive;

/// A configuration value outside what the fit can work with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} is {value}, but {expected}")]
pub struct ConfigError {
    /// The key's path in the configuration, e.g. `stereo.half_window`.
    pub field: &'static str,
    pub value: String,
    pub expected: String,
}

/// Pyramid levels a configuration may name (each halves the image).
pub const MAX_LEVEL: usize = 8;

fn check(
    field: &'static str,
    ok: bool,
    value: impl Display,
    expected: impl Into<String>,
) -> Result<(), ConfigError> {
    if ok {
        return Ok(());
    }
    Err(ConfigError {
        field,
        value: value.to_string(),
        expected: expected.into(),
    })
}

/// A finite number at least zero.
fn non_negative(field: &'static str, v: f64) -> Result<(), ConfigError> {
    check(
        field,
        v.is_finite() && v >= 0.0,
        v,
        "it must be a finite number ≥ 0",
    )
}

/// A finite number above zero.
fn positive(field: &'static str, v: f64) -> Result<(), ConfigError> {
    check(
        field,
        v.is_finite() && v > 0.0,
        v,
        "it must be a finite number > 0",
    )
}

/// A value inside `range` (integers, or numbers that must not be NaN).
fn within<T: PartialOrd + Display>(
    field: &'static str,
    v: T,
    range: RangeInclusive<T>,
) -> Result<(), ConfigError> {
    let expected = format!("it must lie in {}..={}", range.start(), range.end());
    check(field, range.contains(&v), v, expected)
}

impl FitConfig {
    /// Refuses values the fit cannot work with, naming the first one's key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let s = &self.solver;
        non_negative("solver.lm", s.lm)?;
        positive("solver.lm_floor", s.lm_floor)?;
        within("solver.target_tries", s.target_tries, 1..=30)?;
        within("solver.newton_tries", s.newton_tries, 0..=30)?;
        within("solver.rigid_from_level", s.rigid_from_level, 0..=MAX_LEVEL)?;

        let e = &self.energy;
        within("energy.half_length", e.half_length, 2..=64)?;
        positive("energy.heaviside_px", e.heaviside_px)?;
        within("energy.probability_floor", e.probability_floor, 1e-6..=0.49)?;
        positive(
            "energy.saturated_line_variance_px2",
            e.saturated_line_variance_px2,
        )?;
        non_negative(
            "energy.parabola_below_variance_px2",
            e.parabola_below_variance_px2,
        )?;
        let [lo, hi] = e.parabola_variance_px2;
        check(
            "energy.parabola_variance_px2",
            lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi,
            format!("[{lo}, {hi}]"),
            "it must be [low, high] with 0 < low ≤ high",
        )?;
        positive(
            "energy.min_softmin_variance_px2",
            e.min_softmin_variance_px2,
        )?;
        non_negative("energy.rim_check_px", e.rim_check_px)?;
        positive("energy.rim_depth_tolerance", e.rim_depth_tolerance)?;
        within("energy.line_cell_px", e.line_cell_px, 0.5..=64.0)?;
        // 0 means no limit. Fewer than `tracking.min_lines` would lose every frame where one
        // structure shows in one view, and a handful could not hold a pose.
        let fewest = self.tracking.min_lines.max(8);
        check(
            "energy.max_lines_per_structure",
            e.max_lines_per_structure == 0
                || (fewest..=1_000_000).contains(&e.max_lines_per_structure),
            e.max_lines_per_structure,
            format!(
                "it must be 0 (no limit) or lie in {fewest}..=1000000 (at least tracking.min_lines)"
            ),
        )?;
        non_negative("energy.confidence_band_px", e.confidence_band_px)?;

        let p = &self.priors;
        for (field, v) in [
            ("priors.pose_damping", p.pose_damping),
            ("priors.pose_damping_depth", p.pose_damping_depth),
            ("priors.strain", p.strain),
            ("priors.strain_scale", p.strain_scale),
            ("priors.shape", p.shape),
            ("priors.shape_damping", p.shape_damping),
            ("priors.camera_damping", p.camera_damping),
        ]
        .into_iter()
        .chain(p.camera_relative.map(|v| ("priors.camera_relative", v)))
        {
            non_negative(field, v)?;
        }

        let st = &self.stereo;
        non_negative("stereo.weight", st.weight)?;
        within("stereo.max_points", st.max_points, 1..=100_000)?;
        within("stereo.half_window", st.half_window, 1..=32)?;
        // A binomial kernel of 2·radius + 1 taps over each whole view: beyond 16 px it only
        // blurs the texture away, and a huge one ran for minutes.
        within("stereo.smooth_radius", st.smooth_radius, 0..=16)?;
        within("stereo.search_px", st.search_px, 1..=64)?;
        within("stereo.min_ncc", st.min_ncc, -1.0..=1.0)?;
        positive("stereo.sigma_px", st.sigma_px)?;
        positive("stereo.huber", st.huber)?;
        within(
            "stereo.max_partner_angle_deg",
            st.max_partner_angle_deg,
            0.0..=180.0,
        )?;

        let f = &self.first_frame;
        within("first_frame.coarser_levels", f.coarser_levels, 0..=4)?;
        within("first_frame.rounds", f.rounds, 1..=50)?;
        within("first_frame.steps", f.steps, 1..=100)?;
        within("first_frame.rebuild_every", f.rebuild_every, 1..=1000)?;
        non_negative("first_frame.pose_damping", f.pose_damping)?;
        within("first_frame.stereo_search_px", f.stereo_search_px, 1..=64)?;

        let t = &self.tracked_frame;
        within("tracked_frame.rounds", t.rounds, 1..=50)?;
        within("tracked_frame.steps", t.steps, 1..=100)?;
        within("tracked_frame.rebuild_every", t.rebuild_every, 1..=1000)?;
        non_negative("tracked_frame.shape_prior", t.shape_prior)?;

        let z = &self.zoom;
        non_negative(
            "zoom.cameras_pose_damping_factor",
            z.cameras_pose_damping_factor,
        )?;
        non_negative("zoom.cameras_shape_damping", z.cameras_shape_damping)?;
        non_negative(
            "zoom.cameras_stereo_weight_factor",
            z.cameras_stereo_weight_factor,
        )?;
        within("zoom.cameras_min_rounds", z.cameras_min_rounds, 0..=50)?;
        within(
            "zoom.cameras_rebuild_every",
            z.cameras_rebuild_every,
            1..=1000,
        )?;
        within(
            "zoom.cameras_coarser_levels",
            z.cameras_coarser_levels,
            0..=4,
        )?;
        non_negative("zoom.camera_damping_factor", z.camera_damping_factor)?;
        non_negative("zoom.pose_only_damping_factor", z.pose_only_damping_factor)?;
        within("zoom.settle_frames", z.settle_frames, 0..=1000)?;
        within("zoom.onset_frames", z.onset_frames, 0..=100)?;
        positive("zoom.detector.rate_two_frames", z.detector.rate_two_frames)?;
        positive("zoom.detector.rate_one_frame", z.detector.rate_one_frame)?;
        positive("zoom.detector.calm_rate", z.detector.calm_rate)?;
        within(
            "zoom.detector.calm_frames",
            z.detector.calm_frames,
            1..=1000,
        )?;
        within(
            "zoom.detector.warmup_frames",
            z.detector.warmup_frames,
            0..=1000,
        )?;
        within(
            "zoom.motion.history_frames",
            z.motion.history_frames,
            3..=1000,
        )?;

        let k = &self.tracking;
        within("tracking.fit_width_px", k.fit_width_px, 16..=16_384)?;
        within("tracking.max_fit_level", k.max_fit_level, 0..=4)?;
        within("tracking.lost_confidence", k.lost_confidence, 0.0..=1.0)?;
        within(
            "tracking.depth_zoom_confidence",
            k.depth_zoom_confidence,
            0.0..=1.0,
        )?;
        within(
            "tracking.reinit_after_lost",
            k.reinit_after_lost,
            1..=10_000,
        )?;
        non_negative("tracking.occluder_margin_px", k.occluder_margin_px as f64)?;
        non_negative("tracking.reinit_max_jump_mm", k.reinit_max_jump_mm)?;
        within("tracking.max_zoom_factor", k.max_zoom_factor, 1.0..=100.0)?;
        within("tracking.max_aspect_change", k.max_aspect_change, 0.0..=1.0)?;
        within(
            "tracking.occluder_background",
            k.occluder_background,
            0.0..=1.0,
        )?;

        let pl = &self.placement;
        within("placement.score_level", pl.score_level, 0..=4)?;
        within("placement.directions", pl.directions, 1..=10_000)?;
        within("placement.rolls", pl.rolls, 1..=360)?;
        within("placement.refined", pl.refined, 1..=1000)?;
        within("placement.polish_deg", pl.polish_deg, 0.0..=90.0)?;
        within(
            "placement.silhouette_centring",
            pl.silhouette_centring,
            0.0..=1.0,
        )?;
        within(
            "placement.initial_polish_deg",
            pl.initial_polish_deg,
            0.0..=90.0,
        )?;
        non_negative("placement.min_area_px", pl.min_area_px)?;
        positive("placement.reference_depth_mm", pl.reference_depth_mm)?;
        check(
            "placement.levels",
            !pl.levels.is_empty() && pl.levels.iter().all(|&l| l <= MAX_LEVEL),
            format!("{:?}", pl.levels),
            format!("it must list 1 or more levels, each 0 to {MAX_LEVEL}"),
        )?;
        within("placement.rounds", pl.rounds, 1..=50)?;
        within("placement.steps", pl.steps, 1..=100)?;
        within("placement.rebuild_every", pl.rebuild_every, 1..=1000)?;
        non_negative("placement.pose_damping", pl.pose_damping)?;

        let h = &self.hidden_region;
        non_negative("hidden_region.covariance_scale", h.covariance_scale)?;
        non_negative("hidden_region.model_error_mm", h.model_error_mm)?;
        non_negative(
            "hidden_region.model_error_per_rim_residual",
            h.model_error_per_rim_residual,
        )?;
        non_negative(
            "hidden_region.rim_residual_floor_mm",
            h.rim_residual_floor_mm,
        )?;
        non_negative(
            "hidden_region.model_error_per_confidence_shortfall",
            h.model_error_per_confidence_shortfall,
        )?;
        within(
            "hidden_region.confidence_full",
            h.confidence_full,
            0.0..=1.0,
        )?;
        positive("hidden_region.focal_sd", h.focal_sd)?;
        positive("hidden_region.principal_sd_px", h.principal_sd_px)?;
        non_negative(
            "hidden_region.zoom_depth_sd_corrected",
            h.zoom_depth_sd_corrected,
        )?;
        non_negative(
            "hidden_region.zoom_depth_sd_uncorrected",
            h.zoom_depth_sd_uncorrected,
        )?;
        non_negative(
            "hidden_region.zoom_depth_per_depth_change",
            h.zoom_depth_per_depth_change,
        )?;
        within("hidden_region.probability", h.probability, 0.5..=0.999)?;
        non_negative(
            "hidden_region.lost_growth_mm_per_frame",
            h.lost_growth_mm_per_frame,
        )
    }
}
