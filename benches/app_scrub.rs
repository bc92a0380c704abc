//! Benchmark: the app scrubbing a long scene (issue 17: "the app scrubs it without stalls and
//! with bounded memory"). Opens the scene in the real app, driven by egui_kittest with a wgpu
//! renderer (here Mesa's software Vulkan driver), so the app takes the path it takes on a
//! user's machine (the 3D overlay drawn by wgpu, not the CPU fallback); each UI frame's
//! update is timed (the drawing is not: kittest draws only when asked). It scrubs as a user
//! does:
//!
//! 1. plays forward frame by frame, waiting for each frame to be on screen;
//! 2. jumps to random frames across the whole scene, waiting for each;
//! 3. drags the slider: a new frame every UI frame, without waiting (the loader must drop
//!    the frames the user has already passed), then waits for the last one.
//!
//! It prints, per phase, the app's update time per UI frame (median, 99th percentile, max;
//! updates over 100 ms are stalls, counted), the drawing time, the time until a frame asked
//! for is shown, and the process's resident memory (now, and the peak so far).
//!
//!     python3 benches/long_video.py        # makes target/long-video/scene (10,000 frames)
//!     WGPU_BACKEND=vulkan cargo bench --bench app_scrub [-- SCENE]
//!
//! SCENE defaults to target/long-video/scene; any scene folder works (an image sequence too).

use egui_kittest::Harness;
use endofuse::app::{EndofuseApp, NoDialogs};
use endofuse::rng::Rng;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// A UI frame longer than this is a stall the user sees.
const STALL_MS: f64 = 100.0;
const PLAY_FRAMES: usize = 300;
const JUMPS: usize = 40;
const DRAG_STEPS: usize = 300;

fn rss_mib(key: &str) -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with(key))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// UI frame times and the times until a frame asked for was shown, of one phase.
#[derive(Default)]
struct Phase {
    step_ms: Vec<f64>,
    render_ms: Vec<f64>,
    shown_ms: Vec<f64>,
}

impl Phase {
    /// One UI frame: the app's update (timed: the stalls a user feels come from it), then the
    /// drawing, timed apart (on the software Vulkan driver it measures the CPU, not a GPU).
    /// Drawing also hands the frame's texture changes to the renderer, which kittest holds
    /// until then.
    fn step(&mut self, h: &mut Harness<'_, EndofuseApp>) {
        let t = Instant::now();
        h.step();
        self.step_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        if let Err(e) = h.render() {
            eprintln!("app_scrub: drawing failed: {e}");
            std::process::exit(1);
        }
        self.render_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }

    /// Steps until both views show the current frame (the loader decodes off the UI thread).
    fn wait_shown(&mut self, h: &mut Harness<'_, EndofuseApp>, since: Instant) {
        let deadline = since + Duration::from_secs(60);
        loop {
            self.step(h);
            if h.state().frames_ready() {
                break;
            }
            assert!(Instant::now() < deadline, "a frame took over 60 s to show");
            std::thread::sleep(Duration::from_millis(2));
        }
        self.shown_ms.push(since.elapsed().as_secs_f64() * 1e3);
    }

    fn row(mut self, name: &str) {
        let stalls = self.step_ms.iter().filter(|&&m| m > STALL_MS).count();
        let ui = (
            percentile(&mut self.step_ms, 0.5),
            percentile(&mut self.step_ms, 0.99),
            self.step_ms.iter().copied().fold(f64::NAN, f64::max),
        );
        let shown = (
            percentile(&mut self.shown_ms, 0.5),
            percentile(&mut self.shown_ms, 0.99),
        );
        let render = percentile(&mut self.render_ms, 0.5);
        println!(
            "| {name} | {} | {:.1} / {:.1} / {:.1} | {stalls} | {render:.0} | {:.0} / {:.0} | {:.0} | {:.0} |",
            self.step_ms.len(),
            ui.0,
            ui.1,
            ui.2,
            shown.0,
            shown.1,
            rss_mib("VmRSS:"),
            rss_mib("VmHWM:"),
        );
    }
}

fn main() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let scene = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with('-'))
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target/long-video/scene"));
    if !scene.exists() {
        eprintln!(
            "app_scrub: {} not found; make it with `python3 benches/long_video.py` or name a scene folder",
            scene.display()
        );
        std::process::exit(1);
    }
    let spec = scene.display().to_string();
    let mut h = Harness::builder()
        .with_size([1280.0, 760.0])
        .with_accessibility_check(false)
        .wgpu()
        .build_eframe(move |cc| EndofuseApp::new(cc, &spec, Box::new(NoDialogs)));
    let t0 = Instant::now();
    let mut open = Phase::default();
    let deadline = t0 + Duration::from_secs(300);
    while h.state().doc.scene.is_none() {
        if let Some(e) = &h.state().status.error {
            eprintln!("app_scrub: the app could not open {}: {e}", scene.display());
            std::process::exit(1);
        }
        assert!(
            Instant::now() < deadline,
            "the scene took over 300 s to open"
        );
        open.step(&mut h);
        std::thread::sleep(Duration::from_millis(5));
    }
    open.wait_shown(&mut h, t0);
    let frames = h.state().doc.scene.as_ref().map_or(0, |s| s.frame_count);
    println!(
        "{}: {frames} frames, opened and first frame shown in {:.1} s\n",
        scene.display(),
        t0.elapsed().as_secs_f64()
    );
    println!(
        "| phase | UI frames | update ms median / p99 / max | updates > {STALL_MS} ms | drawing ms median | frame shown after ms, median / p99 | RSS MiB | peak RSS MiB |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    open.row("open");

    let mut play = Phase::default();
    for t in 1..PLAY_FRAMES.min(frames) {
        let asked = Instant::now();
        h.state_mut().set_frame(t);
        play.wait_shown(&mut h, asked);
    }
    play.row(&format!("play frames 1..{}", PLAY_FRAMES.min(frames) - 1));

    let mut rng = Rng::new(17);
    let mut jump = Phase::default();
    for _ in 0..JUMPS {
        let asked = Instant::now();
        h.state_mut().set_frame(rng.below(frames));
        jump.wait_shown(&mut h, asked);
    }
    jump.row(&format!("{JUMPS} random jumps"));

    // A drag sweeps the whole scene at a varying speed (1 to 40 frames per UI frame), at
    // about 60 UI frames per second, and back.
    let mut drag = Phase::default();
    let mut t = h.state().view.frame as i64;
    let mut dir = 1i64;
    for _ in 0..DRAG_STEPS {
        let speed = 1 + rng.below(40) as i64;
        t += dir * speed;
        if t >= frames as i64 - 1 || t <= 0 {
            dir = -dir;
            t = t.clamp(0, frames as i64 - 1);
        }
        h.state_mut().set_frame(t as usize);
        drag.step(&mut h);
        std::thread::sleep(Duration::from_millis(16));
    }
    let asked = Instant::now();
    drag.wait_shown(&mut h, asked);
    drag.row(&format!("drag, {DRAG_STEPS} UI frames"));
}
