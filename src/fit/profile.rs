//! Optional phase timers for the per-frame fit: with `ENDOFUSE_PROFILE=1`, `endofuse track`
//! prints how the fit's time splits (pyramids, visibility rasters, correspondence lines,
//! forest evaluation, Gauss–Newton steps) so speed work measures instead of guessing. Off, a
//! timer costs one relaxed load.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
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
    /// The features of the lines' sample pixels (inside [`Phase::Forest`]'s caller).
    SparseFeatures,
    /// The rim search of line building (edges, projection, visibility checks).
    Rim,
    /// The joint information at the fitted state (hidden regions).
    Information,
    /// The whole per-frame time (`ms` of the trajectory).
    Frame,
    /// Inside the steps: the image terms' normal equations.
    NormalEquations,
    /// Inside the steps: evaluations of the objective (trial states).
    Objective,
    /// Inside stereo matching: the matching images (grey, smoothed) of every view.
    StereoImages,
    /// Inside stereo matching: the epipolar searches of every point.
    StereoSearch,
    /// After the fit, outside its per-frame time: the frame's output masks (the three below,
    /// and the hidden regions' margins).
    Outputs,
    /// Inside the outputs: the full-resolution label and hidden-structure rasters.
    OutputRasters,
    /// Inside the outputs: the hidden structures' region masks.
    RegionMasks,
    /// Inside the outputs: the occluder check of the label masks (features and forest).
    Occluders,
    /// After the outputs: what the caller does with the frame (`track` writes its PNGs and
    /// scores them against ground truth).
    Record,
}

const PHASES: [(Phase, &str); 21] = [
    (Phase::Frame, "whole frame"),
    (Phase::Pyramid, "pyramids"),
    (Phase::Lines, "lines in all"),
    (Phase::Raster, "visibility raster"),
    (Phase::Probabilities, "features + forest"),
    (Phase::Features, "features"),
    (Phase::Forest, "forest"),
    (Phase::Steps, "steps"),
    (Phase::Stereo, "stereo matching"),
    (Phase::SparseFeatures, "sample features"),
    (Phase::Rim, "rim search"),
    (Phase::Information, "information"),
    (Phase::NormalEquations, "normal equations"),
    (Phase::Objective, "objective"),
    (Phase::StereoImages, "stereo images"),
    (Phase::StereoSearch, "stereo search"),
    (Phase::Outputs, "after the fit: output masks"),
    (Phase::OutputRasters, "mask rasters"),
    (Phase::RegionMasks, "region masks"),
    (Phase::Occluders, "occluder check"),
    (Phase::Record, "recording the frame"),
];

static NANOS: [AtomicU64; PHASES.len()] = [const { AtomicU64::new(0) }; PHASES.len()];
/// Tracked frames counted since the first frame (which is left out: it fits coarse to fine).
static FRAMES: AtomicU64 = AtomicU64::new(0);

pub fn enabled() -> bool {
    requested() && !PAUSED.load(Ordering::Relaxed)
}

/// Was profiling asked for (`ENDOFUSE_PROFILE` set)?
fn requested() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| std::env::var_os("ENDOFUSE_PROFILE").is_some())
}

/// Set while work outside the per-frame fit (the output masks) runs: not counted.
static PAUSED: AtomicBool = AtomicBool::new(false);

/// Runs `f` without counting its time in any phase (work outside the fit's per-frame time).
pub fn uncounted<T>(f: impl FnOnce() -> T) -> T {
    PAUSED.store(true, Ordering::Relaxed);
    let r = f();
    PAUSED.store(false, Ordering::Relaxed);
    r
}

/// Runs `f` outside the fit's per-frame time (no phase inside it counts), adding its time to
/// `phase` when profiling is on and `counted` (a tracked frame, not the first).
pub fn outside<T>(phase: Phase, counted: bool, f: impl FnOnce() -> T) -> T {
    let started = Instant::now();
    let r = uncounted(f);
    if counted && requested() {
        add(phase, started.elapsed());
    }
    r
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

/// Adds a measured duration to `phase` (for spans that are not one closure).
pub fn add(phase: Phase, elapsed: std::time::Duration) {
    NANOS[phase as usize].fetch_add(elapsed.as_nanos() as u64, Ordering::Relaxed);
}

/// Work counted per tracked frame, beside the phases' times (what a phase's time is for).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Count {
    /// Pixels whose feature planes were prepared (the regions' areas, every view).
    FeaturePixels,
    /// Pixels the forest classified (every view).
    ClassifiedPixels,
    /// Correspondence line builds.
    LineBuilds,
}

static COUNTS: [AtomicU64; 3] = [const { AtomicU64::new(0) }; 3];

/// Adds `n` to a per-frame count when profiling is on.
pub fn count(what: Count, n: usize) {
    if enabled() {
        COUNTS[what as usize].fetch_add(n as u64, Ordering::Relaxed);
    }
}

/// CPU time (ns) of every thread of the process, from the kernel's per-thread scheduler
/// statistics (Linux; 0 elsewhere): with the wall time it says how well a frame uses the cores.
fn process_cpu_ns() -> u64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0;
    };
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

/// The process's CPU time when the current frame started.
static FRAME_CPU_START: AtomicU64 = AtomicU64::new(0);
/// CPU time of the tracked frames' fits, every thread.
static FRAME_CPU: AtomicU64 = AtomicU64::new(0);

/// Marks the start of a frame's fit (for its CPU time).
pub fn frame_started() {
    if enabled() {
        FRAME_CPU_START.store(process_cpu_ns(), Ordering::Relaxed);
    }
}

/// Correspondence lines of the tracked frames' final states (how much work a frame is: the
/// line count follows the rim's length and the mesh's density).
static LINES: AtomicU64 = AtomicU64::new(0);

/// Ends a frame that fitted `lines` correspondence lines: after the first one (coarse to fine,
/// several times a tracked frame's work) every phase starts again from zero, so the report is
/// of tracked frames only.
pub fn frame_done(first: bool, elapsed: std::time::Duration, lines: usize) {
    if first {
        for n in NANOS.iter().chain(&COUNTS) {
            n.store(0, Ordering::Relaxed);
        }
        FRAMES.store(0, Ordering::Relaxed);
        LINES.store(0, Ordering::Relaxed);
        FRAME_CPU.store(0, Ordering::Relaxed);
    } else if enabled() {
        let cpu = process_cpu_ns().saturating_sub(FRAME_CPU_START.load(Ordering::Relaxed));
        FRAME_CPU.fetch_add(cpu, Ordering::Relaxed);
        add(Phase::Frame, elapsed);
        FRAMES.fetch_add(1, Ordering::Relaxed);
        LINES.fetch_add(lines as u64, Ordering::Relaxed);
    }
}

/// Mean milliseconds per tracked frame of each phase (None when profiling is off). Phases
/// inside a per-view parallel loop add up every view's time, so they can exceed the whole.
pub fn report() -> Option<String> {
    std::env::var_os("ENDOFUSE_PROFILE")?;
    let n = FRAMES.load(Ordering::Relaxed).max(1) as f64;
    let parts: Vec<String> = PHASES
        .iter()
        .map(|(p, name)| {
            let ms = NANOS[*p as usize].load(Ordering::Relaxed) as f64 / 1e6 / n;
            format!("{name} {ms:.1}")
        })
        .collect();
    let lines = LINES.load(Ordering::Relaxed) as f64 / n;
    let per_frame = |c: Count| COUNTS[c as usize].load(Ordering::Relaxed) as f64 / n;
    Some(format!(
        "ms per tracked frame: {}, CPU of all threads {:.1}; per frame: {lines:.0} lines, {:.1} line builds, {:.0} feature \
         pixels, {:.0} classified pixels",
        parts.join(", "),
        FRAME_CPU.load(Ordering::Relaxed) as f64 / 1e6 / n,
        per_frame(Count::LineBuilds),
        per_frame(Count::FeaturePixels),
        per_frame(Count::ClassifiedPixels),
    ))
}
