//! Constant-velocity prediction of the pose from the frames tracked before a zoom.
//!
//! Within one frame, an organ moving towards the camera and a focal length growing look alike:
//! its size and its stereo disparity both scale with f/z, and a principal point shifting looks
//! like the organ sliding sideways. Holding the pose where the last frame left it hands the
//! organ's own motion (breathing moves it millimetres in a third of a second) to the
//! intrinsics. Breathing is slow against the frame rate, so the motion measured just before
//! the zoom, carried on, is where the pose is held instead. How many frames the velocity is
//! fitted over and how far it carries are [`MotionConfig`]'s.

use super::config::MotionConfig;
use crate::geometry::Affine;
use std::collections::VecDeque;

/// The last few tracked poses, with their frame numbers.
#[derive(Debug, Clone, Default)]
pub struct MotionHistory {
    config: MotionConfig,
    poses: VecDeque<(usize, Affine)>,
}

impl MotionHistory {
    pub fn new(config: MotionConfig) -> Self {
        Self {
            config,
            poses: VecDeque::new(),
        }
    }

    /// Records the pose fitted at `frame` (frames must come in increasing order).
    pub fn push(&mut self, frame: usize, pose: Affine) {
        if self.poses.back().is_some_and(|(f, _)| *f >= frame) {
            self.poses.clear();
        }
        self.poses.push_back((frame, pose));
        while self.poses.len() > self.config.history_frames {
            self.poses.pop_front();
        }
    }

    /// Drops the `n` latest poses (they may hold the onset of a zoom taken for motion).
    pub fn forget_latest(&mut self, n: usize) {
        for _ in 0..n {
            self.poses.pop_back();
        }
    }

    /// Forgets the motion (after a loss of tracking, it no longer says where the organ goes).
    pub fn clear(&mut self) {
        self.poses.clear();
    }

    /// Change of each of the 12 affine parameters per frame: the least-squares slope over the
    /// history. None with fewer than three poses.
    pub fn velocity(&self) -> Option<[f64; 12]> {
        if self.poses.len() < 3 {
            return None;
        }
        let n = self.poses.len() as f64;
        let mean_t = self.poses.iter().map(|(f, _)| *f as f64).sum::<f64>() / n;
        let var_t: f64 = self
            .poses
            .iter()
            .map(|(f, _)| (*f as f64 - mean_t).powi(2))
            .sum();
        if var_t <= 0.0 {
            return None;
        }
        Some(std::array::from_fn(|k| {
            let mean_q = self.poses.iter().map(|(_, a)| a.q[k]).sum::<f64>() / n;
            self.poses
                .iter()
                .map(|(f, a)| (*f as f64 - mean_t) * (a.q[k] - mean_q))
                .sum::<f64>()
                / var_t
        }))
    }

    /// `from` (the pose at frame `frame − frames`) carried `frames` frames on at the history's
    /// velocity; `from` itself where the history is too short to tell, or more than
    /// `carry_frames` frames old at `frame`.
    pub fn predict(&self, from: &Affine, frames: f64, frame: usize) -> Affine {
        let fresh = self
            .poses
            .back()
            .is_some_and(|(f, _)| frame.saturating_sub(*f) <= self.config.carry_frames);
        match self.velocity().filter(|_| fresh) {
            Some(v) => Affine {
                q: std::array::from_fn(|k| from.q[k] + v[k] * frames),
            },
            None => *from,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CARRY_FRAMES: usize = 12;

    #[test]
    fn the_tests_carry_as_far_as_the_default() {
        assert_eq!(MotionConfig::default().carry_frames, CARRY_FRAMES);
    }

    fn moving(t: usize) -> Affine {
        let mut a = Affine::IDENTITY;
        a.q[9] = 1.0 + 0.3 * t as f64;
        a.q[11] = 180.0 - 0.25 * t as f64;
        a.q[1] = 0.002 * t as f64;
        a
    }

    #[test]
    fn a_steady_motion_is_carried_on() {
        let mut h = MotionHistory::default();
        assert!(h.velocity().is_none());
        for t in 0..10 {
            h.push(t, moving(t));
        }
        let p = h.predict(&moving(9), 3.0, 12);
        for k in 0..12 {
            assert!((p.q[k] - moving(12).q[k]).abs() < 1e-9, "q[{k}]");
        }
    }

    #[test]
    fn motion_is_carried_only_so_far() {
        let mut h = MotionHistory::default();
        for t in 0..6 {
            h.push(t, moving(t));
        }
        let carried = h.predict(&moving(5 + CARRY_FRAMES - 1), 1.0, 5 + CARRY_FRAMES);
        assert!((carried.q[9] - moving(5 + CARRY_FRAMES).q[9]).abs() < 1e-9);
        let held = moving(5 + CARRY_FRAMES);
        assert_eq!(h.predict(&held, 1.0, 6 + CARRY_FRAMES).q, held.q);
    }

    #[test]
    fn too_short_or_cleared_histories_predict_no_motion() {
        let mut h = MotionHistory::default();
        h.push(0, moving(0));
        h.push(1, moving(1));
        assert_eq!(h.predict(&moving(1), 1.0, 2).q, moving(1).q);
        h.push(2, moving(2));
        assert!(h.velocity().is_some());
        h.clear();
        assert_eq!(h.predict(&moving(2), 1.0, 3).q, moving(2).q);
        // Going back in time (a new range) starts a new history.
        h.push(5, moving(5));
        h.push(6, moving(6));
        h.push(7, moving(7));
        h.push(3, moving(3));
        assert!(h.velocity().is_none());
    }
}
