//! Fig. 10b: the four settings R, L, LS and LSC on the project's stereo phantoms with tools and
//! a zoom, tracked end to end as `endofuse track` does (forest trained on the synth's strokes,
//! the scene's initial pose): Dice of the visible structures per frame (box plot) and the
//! hidden tumour's centroid error per mode. The paper's own Fig. 10b is on ex vivo lamb
//! kidneys; these phantoms stand in for them (we have no such video).

use super::Progress;
use crate::error::Error;
use crate::fit::Mode;
use crate::fit::config::FitConfig;
use crate::synth::{SynthOptions, memory_scene};
use std::path::Path;

/// One row of modes.csv.
#[derive(Debug, Clone)]
pub struct ModeRow {
    pub scene: String,
    pub mode: Mode,
    pub dice_mean: f64,
    pub dice_p25: f64,
    pub dice_p75: f64,
    pub hidden_centroid_mm: f64,
    /// Every frame's Dice (for the box plot).
    pub per_frame: Vec<f64>,
}

#[derive(Debug, Clone)]
pub struct ModesSetup {
    pub seeds: Vec<u64>,
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub noise: f64,
}

pub const MODES: [Mode; 4] = [Mode::R, Mode::L, Mode::LS, Mode::LSC];

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return f64::NAN;
    }
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// Tracks every phantom in every mode; `work` holds the tracker's outputs meanwhile (removed
/// after each run).
pub fn run(setup: &ModesSetup, work: &Path, progress: &Progress) -> Result<Vec<ModeRow>, Error> {
    progress.stage(
        "modes R/L/LS/LSC (Fig. 10b)",
        setup.seeds.len() * MODES.len(),
    );
    let mut rows = Vec::new();
    for &seed in &setup.seeds {
        let scene = memory_scene(&SynthOptions {
            frames: setup.frames,
            seed,
            noise: setup.noise,
            width: setup.width,
            height: setup.height,
            tools: true,
            zoom: true,
            smoke: false,
            ..SynthOptions::default()
        })?;
        let name = format!("phantom-seed{seed}");
        for mode in MODES {
            let out = work.join(format!("{name}-{}", mode.name()));
            let m = crate::track::run(
                &scene,
                &out,
                mode,
                (0, setup.frames - 1),
                &FitConfig::default(),
                None,
                &|_, _| {},
            )?;
            // Best effort: the outputs are only the means to the figures.
            let _ = std::fs::remove_dir_all(&out);
            let per_frame = m
                .dice
                .as_ref()
                .map(|d| d.per_frame.clone())
                .unwrap_or_default();
            let hidden = m
                .hidden
                .values()
                .map(|h| h.centroid_error_mm_mean)
                .next()
                .unwrap_or(f64::NAN);
            rows.push(ModeRow {
                scene: name.clone(),
                mode,
                dice_mean: m.dice.as_ref().map_or(f64::NAN, |d| d.mean),
                dice_p25: quantile(&per_frame, 0.25),
                dice_p75: quantile(&per_frame, 0.75),
                hidden_centroid_mm: hidden,
                per_frame,
            });
            progress.done(1);
        }
    }
    Ok(rows)
}
