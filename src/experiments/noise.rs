//! Fig. 4: Dice against the noise's σ, ours against Chan–Vese (ACWOE) on the same images.
//! Ours: mode LS (affine + shape), started 10° and 10 mm from the truth in a random direction
//! per trial (the experiment is about noise, not the start). ACWOE segments each view's
//! image on its own, as it can only. Dice is per view against the noise-free silhouette.

use super::Progress;
use super::chan_vese::{ChanVeseParams, segment};
use super::rig::{Rig, noisy_images};
use crate::fit::config::{Phase, Zoom};
use crate::fit::{FitState, Mode};
use crate::geometry::Affine;
use crate::plane::dice;
use crate::rng::Rng;
use glam::{DMat3, DQuat};
use rayon::prelude::*;

/// Start offset of our fit from the truth.
pub const START_OFFSET_DEG: f64 = 10.0;
pub const START_OFFSET_MM: f64 = 10.0;

/// One row of noise.csv.
#[derive(Debug, Clone)]
pub struct NoiseRow {
    pub sigma: f64,
    pub views: usize,
    /// "ours" or "chan_vese".
    pub method: &'static str,
    pub dice_mean: f64,
    pub dice_std: f64,
    pub trials: usize,
}

#[derive(Debug, Clone)]
pub struct NoiseSetup {
    pub sigmas: Vec<f64>,
    pub views: Vec<usize>,
    pub trials: usize,
    pub chan_vese: ChanVeseParams,
    pub seed: u64,
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len().max(1) as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n;
    (m, var.sqrt())
}

/// The start of trial `trial`: the truth turned by [`START_OFFSET_DEG`] about a random axis
/// through the kidney's centre and moved [`START_OFFSET_MM`] in a random direction.
pub fn offset_start(rig: &Rig, seed: u64, trial: u64) -> FitState {
    let mut rng = Rng::fork(seed, 0x5_7A27 + trial);
    let axis = rng.unit_vector();
    let shift = rng.unit_vector() * START_OFFSET_MM;
    let turn = DMat3::from_quat(DQuat::from_axis_angle(axis, START_OFFSET_DEG.to_radians()));
    let t = &rig.truth.affine;
    FitState {
        affine: Affine::from_linear_translation(
            turn * t.linear(),
            turn * (t.translation_mm() - rig.centre_mm) + rig.centre_mm + shift,
        ),
        ..rig.truth.clone()
    }
}

pub fn run(setup: &NoiseSetup, progress: &Progress) -> Vec<NoiseRow> {
    let tasks: Vec<(usize, f64)> = setup
        .views
        .iter()
        .flat_map(|&v| setup.sigmas.iter().map(move |&s| (v, s)))
        .collect();
    progress.stage("Dice vs noise (Fig. 4)", tasks.len());
    let rigs: Vec<Rig> = setup.views.iter().map(|&v| Rig::new(v, &[])).collect();
    let config = super::rig::experiment_config();
    tasks
        .par_iter()
        .flat_map(|&(views, sigma)| {
            let rig = &rigs[setup.views.iter().position(|&v| v == views).unwrap_or(0)];
            let truths = rig.silhouettes(&rig.truth);
            let params = rig.params(Mode::LS, Phase::FirstFrame, Zoom::Off, &config);
            let (mut ours, mut theirs) = (Vec::new(), Vec::new());
            for trial in 0..setup.trials as u64 {
                let images = noisy_images(&truths, sigma, setup.seed, trial);
                let fit = rig.fit(&images, &offset_start(rig, setup.seed, trial), &params);
                let fitted = rig.silhouettes(&fit);
                for (f, t) in fitted.iter().zip(&truths) {
                    ours.push(dice(f, t).unwrap_or(1.0));
                }
                for (img, t) in images.iter().zip(&truths) {
                    let seg = segment(&img.intensity, img.width, img.height, &setup.chan_vese);
                    log::debug!(
                        "chan-vese σ {sigma}: {} iterations, c {:.3}/{:.3}",
                        seg.iterations,
                        seg.c_inside,
                        seg.c_outside
                    );
                    theirs.push(dice(&seg.brighter(), t).unwrap_or(1.0));
                }
            }
            progress.done(1);
            let (om, os) = mean_std(&ours);
            let (cm, cs) = mean_std(&theirs);
            vec![
                NoiseRow {
                    sigma,
                    views,
                    method: "ours",
                    dice_mean: om,
                    dice_std: os,
                    trials: setup.trials,
                },
                NoiseRow {
                    sigma,
                    views,
                    method: "chan_vese",
                    dice_mean: cm,
                    dice_std: cs,
                    trials: setup.trials,
                },
            ]
        })
        .collect()
}
