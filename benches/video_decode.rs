//! Benchmark: what scrubbing a 1080p video costs through `endofuse::video::VideoReader`.
//! Encodes a 300-frame 1920×1080 clip (FFmpeg's testsrc2, libx264 yuv420p) with a keyframe
//! every 30 frames and with x264's default GOP of 250 into a temp folder, then measures
//! sequential decoding, random seeks, the next frame after a seek (decode-ahead should make
//! it a cache hit), a step back, and the process's peak memory.
//!
//!     cargo run --no-default-features --release --bench video_decode

use endofuse::rng::Rng;
use endofuse::video::VideoReader;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const FRAMES: usize = 300;
const SEEKS: usize = 30;

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let v = f();
    (v, ms(t.elapsed()))
}

fn encode(path: &Path, gop: &[&str]) {
    let status = Command::new("ffmpeg")
        .args(["-nostdin", "-v", "error", "-y", "-f", "lavfi", "-i"])
        .arg("testsrc2=size=1920x1080:rate=30")
        .args(["-frames:v", &FRAMES.to_string()])
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p"])
        .args(gop)
        .arg(path)
        .status()
        .expect("ffmpeg runs");
    assert!(status.success(), "encoding {}", path.display());
}

/// ms per frame of a plain `ffmpeg … -f rawvideo -pix_fmt rgb24 -` read to the end: the
/// floor for any reader that drives the program.
fn plain_pipe(path: &Path) -> f64 {
    let t = Instant::now();
    let mut child = Command::new("ffmpeg")
        .args(["-nostdin", "-v", "error", "-i"])
        .arg(path)
        .args([
            "-map",
            "0:V:0",
            "-fps_mode",
            "passthrough",
            "-f",
            "rawvideo",
        ])
        .args(["-pix_fmt", "rgb24", "-"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("ffmpeg runs");
    let mut out = child.stdout.take().expect("stdout");
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0usize;
    loop {
        match out.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => total += n,
        }
    }
    let _ = child.wait();
    assert_eq!(total, FRAMES * 1920 * 1080 * 3);
    ms(t.elapsed()) / FRAMES as f64
}

fn median_p95(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.95))
}

/// The measurements of one clip, as (label, value) rows.
fn measure(path: &Path) -> Vec<(String, String)> {
    let mut rows = Vec::new();
    let mut row = |k: &str, v: String| rows.push((k.to_string(), v));
    let pipe = plain_pipe(path);
    row("plain ffmpeg pipe, ms/frame", format!("{pipe:.1}"));

    let (video, open_ms) = timed(|| VideoReader::open(path).expect("opens"));
    row("open (probe + frame 0), ms", format!("{open_ms:.0}"));
    let (_, seq) = timed(|| {
        for i in 0..FRAMES {
            video.frame(i).expect("frame");
        }
    });
    row(
        "sequential frame(0..300), ms/frame",
        format!("{:.1}", seq / FRAMES as f64),
    );
    row(
        "resident memory after it, MB",
        format!("{:.0}", rss_mb("VmRSS:")),
    );
    drop(video);

    // Random seeks, each to a frame not cached, with the decode-ahead idle before each.
    let video = VideoReader::open(path).expect("opens");
    let mut rng = Rng::new(1);
    let (mut seek, mut next, mut back, mut back_after) = (vec![], vec![], vec![], vec![]);
    for _ in 0..SEEKS {
        let i = loop {
            let i = 1 + rng.below(FRAMES - 3);
            if !(i - 1..=i + 1).any(|j| video.is_cached(j)) {
                break i;
            }
        };
        std::thread::sleep(Duration::from_millis(300));
        seek.push(timed(|| video.frame(i).expect("seek")).1);
        // One frame's time at 30 fps, as a player would wait.
        std::thread::sleep(Duration::from_millis(33));
        next.push(timed(|| video.frame(i + 1).expect("next")).1);
        back.push(timed(|| video.frame(i).expect("back")).1);
        std::thread::sleep(Duration::from_millis(300));
        back_after.push(timed(|| video.frame(i - 1).expect("back past the seek")).1);
    }
    let (m, p) = median_p95(seek);
    row("random seek, ms (median / p95)", format!("{m:.0} / {p:.0}"));
    let (m, p) = median_p95(next);
    row(
        "next frame 33 ms after a seek, ms",
        format!("{m:.2} / {p:.2}"),
    );
    let (m, p) = median_p95(back);
    row(
        "step back to the sought frame, ms",
        format!("{m:.2} / {p:.2}"),
    );
    let (m, p) = median_p95(back_after);
    row(
        "step back before it, 0.3 s later, ms",
        format!("{m:.2} / {p:.2}"),
    );

    // The next frame asked for at once, and seeks back to back (scrubbing).
    let (mut at_once, mut scrub) = (vec![], vec![]);
    for _ in 0..SEEKS {
        let i = loop {
            let i = rng.below(FRAMES - 1);
            if !video.is_cached(i) && !video.is_cached(i + 1) {
                break i;
            }
        };
        scrub.push(timed(|| video.frame(i).expect("seek")).1);
        at_once.push(timed(|| video.frame(i + 1).expect("next")).1);
    }
    let (m, p) = median_p95(scrub);
    row(
        "back-to-back seeks (scrubbing), ms",
        format!("{m:.0} / {p:.0}"),
    );
    let (m, p) = median_p95(at_once);
    row(
        "next frame at once after a seek, ms",
        format!("{m:.1} / {p:.1}"),
    );
    row(
        "cache held at the end, MB",
        format!("{:.0}", video.cached_bytes() as f64 / 1e6),
    );
    row(
        "resident memory at the end, MB",
        format!("{:.0}", rss_mb("VmRSS:")),
    );
    rows
}

/// The process's resident memory (`VmRSS:`) or its peak (`VmHWM:`) in MB, from Linux's
/// /proc (0 elsewhere).
fn rss_mb(field: &str) -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let kb = status
        .lines()
        .find(|l| l.starts_with(field))
        .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok());
    kb.unwrap_or(0.0) / 1e3
}

fn main() {
    let dir: PathBuf =
        std::env::temp_dir().join(format!("endofuse-video-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp folder");
    let clips = [("-g 30", vec!["-g", "30"]), ("GOP 250 (default)", vec![])];
    let mut columns = Vec::new();
    for (label, gop) in &clips {
        let path = dir.join(format!("clip-{}.mp4", columns.len()));
        let (_, enc) = timed(|| encode(&path, gop));
        eprintln!("encoded {label} in {:.0} s", enc / 1e3);
        columns.push(measure(&path));
    }
    let _ = std::fs::remove_dir_all(&dir);

    println!(
        "\nVideoReader on a 1920×1080 libx264 yuv420p clip, {FRAMES} frames (testsrc2), {SEEKS} seeks"
    );
    println!("{:<40} {:>16} {:>18}", "", clips[0].0, clips[1].0);
    for (k, row) in columns[0].iter().enumerate() {
        println!("{:<40} {:>16} {:>18}", row.0, row.1, columns[1][k].1);
    }
    println!(
        "peak resident memory of the process: {:.0} MB",
        rss_mb("VmHWM:")
    );
}
