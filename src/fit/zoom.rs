//! Zoom detection for LSC where the scene marks no zoom change (CONTRACT §1: camera correction
//! "may switch itself on … where the tracker detects one").
//!
//! With the intrinsics fixed, a zoom can only be explained by the organ growing or coming
//! closer: its apparent size (the affine's scale × fx / depth of its centre) then changes by
//! percents a frame, frame after frame in one direction. Breathing and drift change it by a
//! few tenths of a percent a frame at video rate, and fit jitter (tools crossing the rim) by
//! up to ±1 % but back and forth (measured on phantoms without zoom). So camera correction
//! switches on when two frames in a row grow (or shrink) by `rate_two_frames` together, or one
//! frame by `rate_one_frame`, and stays on until the fitted focal length holds still for
//! `calm_frames` frames ([`ZoomDetectorConfig`]).

use super::config::ZoomDetectorConfig;
use super::state::FitState;
use glam::DVec3;

/// Apparent size of the organ whose preoperative centre is `centre` under `state`:
/// cbrt|det A| · fx / z, in pixels per millimetre.
pub fn apparent_size(state: &FitState, centre: DVec3) -> Option<f64> {
    let z = state.affine.apply(centre).z;
    let fx = state.intrinsics.first()?.fx;
    let scale = state.affine.linear().determinant().abs().cbrt();
    (z > 0.0 && scale.is_finite()).then(|| scale * fx / z)
}

/// Whether the tracker believes the intrinsics are changing.
#[derive(Debug, Clone, Default)]
pub struct ZoomDetector {
    config: ZoomDetectorConfig,
    active: bool,
    calm: usize,
    /// The previous fixed-intrinsics frame's relative change of apparent size.
    last_change: Option<f64>,
}

impl ZoomDetector {
    pub fn new(config: ZoomDetectorConfig) -> Self {
        Self {
            config,
            ..Self::default()
        }
    }

    pub fn active(&self) -> bool {
        self.active
    }

    /// A frame fitted with fixed intrinsics, from `before` (the last good state) to `after`:
    /// true when its apparent size changed fast enough to be a zoom (correction turns on).
    pub fn fires(&mut self, before: &FitState, after: &FitState, centre: DVec3) -> bool {
        if self.changes_like_a_zoom(before, after, centre) {
            self.active = true;
            self.calm = 0;
            self.last_change = None;
        }
        self.active
    }

    /// True when this frame's change of apparent size (with the intrinsics fixed) is as fast
    /// and as steady as a zoom's; nothing is switched on. Modes without camera correction ask
    /// this to say when depth alone explained a zoom (their confidence falls).
    pub fn changes_like_a_zoom(
        &mut self,
        before: &FitState,
        after: &FitState,
        centre: DVec3,
    ) -> bool {
        let (Some(a), Some(b)) = (apparent_size(before, centre), apparent_size(after, centre))
        else {
            return false;
        };
        let change = b / a - 1.0;
        let sustained = self
            .last_change
            .is_some_and(|c| c * change > 0.0 && (c + change).abs() > self.config.rate_two_frames);
        self.last_change = Some(change);
        sustained || change.abs() > self.config.rate_one_frame
    }

    /// A frame fitted with camera correction while a detected zoom is on: the zoom ends after
    /// `calm_frames` frames whose focal length barely moved.
    pub fn corrected(&mut self, before: &FitState, after: &FitState) {
        let (Some(a), Some(b)) = (before.intrinsics.first(), after.intrinsics.first()) else {
            return;
        };
        if (b.fx / a.fx - 1.0).abs() < self.config.calm_rate {
            self.calm += 1;
            if self.calm >= self.config.calm_frames {
                self.active = false;
                self.calm = 0;
            }
        } else {
            self.calm = 0;
        }
    }

    /// Forgets a zoom in progress (tracking lost, or a marked zoom change takes over).
    pub fn reset(&mut self) {
        *self = Self::new(self.config);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Affine, Intrinsics};

    fn state(z_mm: f64, fx: f64) -> FitState {
        FitState {
            affine: Affine::from_linear_translation(glam::DMat3::IDENTITY, DVec3::Z * z_mm),
            shape: Vec::new(),
            intrinsics: vec![Intrinsics {
                fx,
                fy: fx,
                cx: 480.0,
                cy: 270.0,
                k1: 0.0,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0,
            }],
        }
    }

    #[test]
    fn breathing_and_jitter_do_not_fire_and_a_zoom_does_until_the_optics_settle() {
        let mut d = ZoomDetector::default();
        let fires = |d: &mut ZoomDetector, z0: f64, z1: f64| {
            d.fires(&state(z0, 1000.0), &state(z1, 1000.0), DVec3::ZERO)
        };
        // 0.3 mm closer at 190 mm: breathing.
        assert!(!fires(&mut d, 190.0, 189.7));
        // ±1 % back and forth: jitter.
        assert!(!fires(&mut d, 190.0, 188.1));
        assert!(!fires(&mut d, 188.1, 190.0));
        assert!(!fires(&mut d, 190.0, 188.1));
        assert!(!fires(&mut d, 188.1, 190.0));
        // The organ "comes" 0.6 % closer, then 1.1 %: with the intrinsics fixed, a zoom.
        assert!(!fires(&mut d, 190.0, 188.9));
        assert!(fires(&mut d, 188.9, 186.8));
        assert!(d.active());
        // While correcting, fx still moving keeps it on; two calm frames end it.
        d.corrected(&state(190.0, 1000.0), &state(190.0, 1020.0));
        assert!(d.active());
        d.corrected(&state(190.0, 1020.0), &state(190.0, 1021.0));
        assert!(d.active());
        d.corrected(&state(190.0, 1021.0), &state(190.0, 1021.5));
        assert!(!d.active());
        // A fast zoom fires in one frame.
        assert!(fires(&mut d, 190.0, 184.0));
    }
}
