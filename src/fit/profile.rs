//! Optional phase timers for the per-frame fit: with `ENDOFUSE_PROFILE=1`, `endofuse track`
//! prints how the fit's time splits (pyramids, visibility rasters, correspondence lines,
//! forest evaluation, Gauss–Newton steps) so speed work measures instead of guessing. Off, a
//! timer costs one relaxed load.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Frame pyramids of every view.
    Pyramid,
    /// Building correspondence lines, the two below included.
    Lines,
    /// The visibility raster inside line building.
    Raster,
    /// Features and forest for the lines' samples (the two below included).
    Probabilities,
    /// Feature planes over the region the lines need.
    Features,
    /// The forest on the lines' samples.
    Forest,
    /// Gauss–Newton / Newton steps with their energy evaluations.
    Steps,
    /// Stereo matching (its forest checks included).
    Stereo,
}

const PHASES: [(Phase, &str); 8] = [
    (Phase::Pyramid, "pyramids"),
    (Phase::Lines, "lines in all"),
    (Phase::Raster, "visibility raster"),
    (Phase::Probabilities, "features + forest"),
    (Phase::Features, "features"),
    (Phase::Forest, "forest"),
    (Phase::Steps, "steps"),
    (Phase::Stereo, "stereo matching"),
];

static NANOS: [AtomicU64; 8] = [const { AtomicU64::new(0) }; 8];

pub fn enabled() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| std::env::var_os("ENDOFUSE_PROFILE").is_some())
}

/// Runs `f`, adding its time to `phase` when profiling is on.
pub fn time<T>(phase: Phase, f: impl FnOnce() -> T) -> T {
    if !enabled() {
        return f();
    }
    let started = Instant::now();
    let r = f();
    NANOS[phase as usize].fetch_add(started.elapsed().as_nanos() as u64, Ordering::Relaxed);
    r
}

/// Milliseconds per frame of each phase over `frames` frames (None when profiling is off).
pub fn report(frames: usize) -> Option<String> {
    if !enabled() {
        return None;
    }
    let n = frames.max(1) as f64;
    let parts: Vec<String> = PHASES
        .iter()
        .map(|(p, name)| {
            let ms = NANOS[*p as usize].load(Ordering::Relaxed) as f64 / 1e6 / n;
            format!("{name} {ms:.1}")
        })
        .collect();
    Some(format!("ms per frame: {}", parts.join(", ")))
}
