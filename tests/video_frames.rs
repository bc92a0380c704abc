//! `endofuse::video` against videos made here: synthetic frames whose pixels encode their index
//! (six black/white blocks, readable through lossy coding) over colour gradients that move
//! with the index (so neighbours differ everywhere), encoded by the ffmpeg program. Lossless
//! files must give back the source frames bit for bit, lossy ones the frames a plain
//! sequential decode gives, whatever order the frames are asked in.

use endofuse::rng::Rng;
use endofuse::video::{Crop, Tools, VideoError, VideoReader};
use image::RgbImage;
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

const W: u32 = 320;
const H: u32 = 240;
const N: usize = 64;
const FRAME_BYTES: usize = (W * H * 3) as usize;

/// Source frame `i` (`view` tells the two halves of a stereo pair apart).
fn source(i: usize, view: u32) -> RgbImage {
    let i = i as u32;
    let mut img = RgbImage::from_fn(W, H, |x, y| {
        image::Rgb([
            ((x * 2 + i * 7 + view * 90) % 256) as u8,
            ((y * 3 + i * 11) % 256) as u8,
            ((x + y + i * 13 + view * 40) % 256) as u8,
        ])
    });
    for bit in 0..6 {
        let on = (i >> bit) & 1 == 1;
        let v = if on { 255 } else { 0 };
        for y in 8..40 {
            for x in 8 + bit * 48..40 + bit * 48 {
                img.put_pixel(x, y, image::Rgb([v, v, v]));
            }
        }
    }
    img
}

/// The index a frame's blocks spell (tolerant of lossy coding).
fn index_of(img: &RgbImage) -> usize {
    (0..6)
        .map(|bit| {
            let mut sum = 0u32;
            for y in 16..32 {
                for x in 16 + bit * 48..32 + bit * 48 {
                    sum += img.get_pixel(x, y).0.iter().map(|&c| c as u32).sum::<u32>();
                }
            }
            let on = sum / (16 * 16 * 3) > 128;
            (on as usize) << bit
        })
        .sum()
}

fn side_by_side(i: usize) -> RgbImage {
    let mut img = RgbImage::new(2 * W, H);
    image::imageops::replace(&mut img, &source(i, 0), 0, 0);
    image::imageops::replace(&mut img, &source(i, 1), W as i64, 0);
    img
}

fn dir() -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("video_frames");
    std::fs::create_dir_all(&d).expect("scratch folder");
    d
}

/// `N` frames for ffmpeg's stdin.
#[derive(Clone, Copy)]
struct Frames<'a> {
    width: u32,
    height: u32,
    rate: &'a str,
    frame: &'a dyn Fn(usize) -> RgbImage,
}

/// Runs ffmpeg with `frames` as rawvideo on stdin (when given), panicking with its stderr.
fn ffmpeg(args: &[&str], frames: Option<Frames>) {
    let mut cmd = Command::new("ffmpeg");
    cmd.args(["-nostdin", "-v", "error", "-y"]);
    if let Some(f) = frames {
        let size = format!("{}x{}", f.width, f.height);
        cmd.args(["-f", "rawvideo", "-pix_fmt", "rgb24", "-s", &size]);
        // -framerate, not -r: an input -r would override the timestamps (and -itsoffset).
        cmd.args(["-framerate", f.rate, "-i", "-"]);
    }
    let mut child = cmd
        .args(args)
        .stdin(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("ffmpeg runs (the video tests need FFmpeg installed)");
    let mut stdin = child.stdin.take().expect("stdin");
    if let Some(f) = frames {
        for i in 0..N {
            stdin
                .write_all((f.frame)(i).as_raw())
                .expect("feeding ffmpeg");
        }
    }
    drop(stdin);
    let out = child.wait_with_output().expect("ffmpeg ends");
    assert!(
        out.status.success(),
        "ffmpeg {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Each fixture's path once made, by name.
type Made = Mutex<HashMap<&'static str, Arc<OnceLock<PathBuf>>>>;

/// The fixture `name`, made once per test run.
fn fixture(name: &'static str) -> PathBuf {
    static MADE: OnceLock<Made> = OnceLock::new();
    let cell = MADE
        .get_or_init(Default::default)
        .lock()
        .unwrap()
        .entry(name)
        .or_default()
        .clone();
    cell.get_or_init(|| make(name)).clone()
}

fn make(name: &'static str) -> PathBuf {
    let path = dir().join(name);
    let p = path.to_str().expect("utf-8 temp path");
    let plain = Frames {
        width: W,
        height: H,
        rate: "30",
        frame: &|i| source(i, 0),
    };
    let x264rgb = ["-c:v", "libx264rgb", "-qp", "0", "-g", "30"];
    match name {
        // x264 turns B-frames off for lossless (qp 0) coding whatever -bf says: the B-frame
        // files below are lossy and checked against a sequential decode instead.
        "lossless.mp4" | "lossless.mov" => ffmpeg(&[&x264rgb[..], &[p]].concat(), Some(plain)),
        "lossless.mkv" | "lossless.avi" => ffmpeg(&["-c:v", "ffv1", p], Some(plain)),
        "bframes.mp4" => ffmpeg(
            &[
                "-c:v", "libx264", "-pix_fmt", "yuv420p", "-g", "30", "-bf", "3", p,
            ],
            Some(plain),
        ),
        // 5 frames/s, open GOPs: a frame shown before a keyframe lies 0.4 s before it, more
        // than ffmpeg's own allowance when seeking.
        "open-gop.mkv" | "bframes.avi" => ffmpeg(
            &[
                "-c:v",
                "libx264",
                "-pix_fmt",
                "yuv420p",
                "-g",
                "10",
                "-bf",
                "3",
                "-b_strategy",
                "0",
                "-sc_threshold",
                "0",
                "-x264-params",
                "open_gop=1",
                p,
            ],
            Some(Frames { rate: "5", ..plain }),
        ),
        // The same with closed GOPs: seeking to keyframes lands right.
        "closed-gop.avi" => ffmpeg(
            &[
                "-c:v",
                "libx264",
                "-pix_fmt",
                "yuv420p",
                "-g",
                "10",
                "-bf",
                "3",
                "-b_strategy",
                "0",
                "-sc_threshold",
                "0",
                p,
            ],
            Some(Frames { rate: "5", ..plain }),
        ),
        "sbs.mkv" => ffmpeg(
            &["-c:v", "ffv1", p],
            Some(Frames {
                width: 2 * W,
                frame: &side_by_side,
                ..plain
            }),
        ),
        "offset.mp4" => ffmpeg(
            &[&x264rgb[..], &["-output_ts_offset", "2", p]].concat(),
            Some(plain),
        ),
        // Audio from 0 s, video from 1.5 s: the container starts before the video.
        "late-video.mkv" => {
            let raw = dir().join("late-video.rgb");
            let mut bytes = Vec::with_capacity(N * FRAME_BYTES);
            for i in 0..N {
                bytes.extend_from_slice(source(i, 0).as_raw());
            }
            std::fs::write(&raw, bytes).expect("raw frames");
            ffmpeg(
                &[
                    "-f",
                    "lavfi",
                    "-i",
                    "sine=d=4",
                    "-itsoffset",
                    "1.5",
                    "-f",
                    "rawvideo",
                    "-pix_fmt",
                    "rgb24",
                    "-s",
                    "320x240",
                    "-framerate",
                    "30",
                    "-i",
                    raw.to_str().expect("utf-8"),
                    "-map",
                    "0:a",
                    "-map",
                    "1:v",
                    "-c:v",
                    "ffv1",
                    "-c:a",
                    "flac",
                    p,
                ],
                None,
            )
        }
        "faststart.mp4" => ffmpeg(
            &[&x264rgb[..], &["-movflags", "+faststart", p]].concat(),
            Some(plain),
        ),
        "audio.m4a" => ffmpeg(&["-f", "lavfi", "-i", "sine=d=1", "-c:a", "aac", p], None),
        "text.mp4" => std::fs::write(&path, "not a video\n").expect("text file"),
        _ if name.starts_with("cut-") => {
            let whole = std::fs::read(fixture(&name[4..])).expect("fixture");
            std::fs::write(&path, &whole[..whole.len() / 2]).expect("truncated copy");
        }
        _ => panic!("no fixture {name}"),
    }
    path
}

/// What a plain decode from the start gives: the reference for lossy files.
fn sequential_decode(path: &Path) -> Vec<RgbImage> {
    let out = Command::new("ffmpeg")
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
        .output()
        .expect("ffmpeg runs");
    assert!(out.status.success());
    assert_eq!(out.stdout.len() % FRAME_BYTES, 0);
    out.stdout
        .chunks(FRAME_BYTES)
        .map(|c| RgbImage::from_raw(W, H, c.to_vec()).expect("frame"))
        .collect()
}

fn open(path: &Path, cache_frames: usize) -> VideoReader {
    VideoReader::open(path)
        .unwrap_or_else(|e| panic!("{e}"))
        .with_cache_bytes(cache_frames * FRAME_BYTES)
}

fn assert_frame(video: &VideoReader, i: usize, want: &RgbImage) {
    let got = video.frame(i).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        got.as_raw() == want.as_raw(),
        "{}: frame {i} differs from the expected one (its blocks say {}, the expected's {})",
        video.path().display(),
        index_of(&got),
        index_of(want)
    );
}

/// Frames in order, in a random order of seeks, backwards, and from two threads at once, each
/// on a fresh reader with a small cache (so that most requests really decode).
fn check_every_order(path: &Path, expected: &(dyn Fn(usize) -> RgbImage + Sync)) {
    let video = open(path, 6);
    assert_eq!(video.info().frame_count, N, "{}", path.display());
    for i in 0..N {
        assert_frame(&video, i, &expected(i));
    }
    let video = open(path, 6);
    let mut rng = Rng::new(7);
    for _ in 0..40 {
        let i = rng.below(N);
        assert_frame(&video, i, &expected(i));
    }
    let video = open(path, 6);
    for i in (0..N)
        .rev()
        .step_by(3)
        .chain([40, 5, 63, 0, 31, 30, 29, 62])
    {
        assert_frame(&video, i, &expected(i));
    }
    let video = Arc::new(open(path, 6));
    std::thread::scope(|s| {
        let forward = s.spawn(|| (0..N).for_each(|i| assert_frame(&video, i, &expected(i))));
        let mut rng = Rng::new(11);
        for _ in 0..30 {
            let i = rng.below(N);
            assert_frame(&video, i, &expected(i));
        }
        forward.join().expect("the other thread's frames");
    });
}

#[test]
fn lossless_mp4_frames_are_the_source_frames() {
    let path = fixture("lossless.mp4");
    let info = endofuse::video::probe(&path).unwrap();
    assert_eq!((info.width, info.height, info.frame_count), (W, H, N));
    assert_eq!(info.codec, "h264");
    assert!((info.fps - 30.0).abs() < 1e-9);
    check_every_order(&path, &|i| source(i, 0));
}

#[test]
fn lossless_mov_frames_are_the_source_frames() {
    check_every_order(&fixture("lossless.mov"), &|i| source(i, 0));
}

#[test]
fn ffv1_mkv_frames_are_the_source_frames() {
    let path = fixture("lossless.mkv");
    assert_eq!(endofuse::video::probe(&path).unwrap().codec, "ffv1");
    check_every_order(&path, &|i| source(i, 0));
}

#[test]
fn ffv1_avi_frames_are_the_source_frames() {
    check_every_order(&fixture("lossless.avi"), &|i| source(i, 0));
}

/// Lossy files with B-frames: the frames of a sequential decode, which spell their index.
fn check_lossy(name: &'static str) {
    let path = fixture(name);
    let reference = sequential_decode(&path);
    assert_eq!(reference.len(), N);
    for (i, f) in reference.iter().enumerate() {
        assert_eq!(index_of(f), i, "{name}: the sequential decode's frame {i}");
    }
    check_every_order(&path, &|i| reference[i].clone());
}

#[test]
fn b_frame_mp4_frames_match_a_sequential_decode() {
    check_lossy("bframes.mp4");
}

#[test]
fn low_rate_open_gop_mkv_frames_match_a_sequential_decode() {
    check_lossy("open-gop.mkv");
}

#[test]
fn b_frame_avi_without_timestamps_matches_a_sequential_decode() {
    check_lossy("bframes.avi");
}

#[test]
fn closed_gop_b_frame_avi_matches_a_sequential_decode() {
    check_lossy("closed-gop.avi");
}

#[test]
fn side_by_side_halves_are_the_two_views() {
    let video = VideoReader::open(&fixture("sbs.mkv"))
        .unwrap()
        .with_cache_bytes(0);
    let info = video.info().clone();
    assert_eq!((info.width, info.height), (2 * W, H));
    let (left, right) = Crop::side_by_side(info.width, info.height);
    for i in [0, 1, 2, 40, 17, 63, 62] {
        assert!(
            video.frame_cropped(i, left).unwrap() == source(i, 0),
            "left {i}"
        );
        assert!(
            video.frame_cropped(i, right).unwrap() == source(i, 1),
            "right {i}"
        );
    }
    let outside = Crop { x: 600, ..right };
    match video.frame_cropped(0, outside) {
        Err(e @ VideoError::BadCrop { .. }) => assert!(e.to_string().contains("sbs.mkv")),
        other => panic!("expected BadCrop, got {other:?}"),
    }
}

#[test]
fn frame_0_is_the_first_frame_when_the_stream_starts_late() {
    for name in ["offset.mp4", "late-video.mkv"] {
        let path = fixture(name);
        let video = open(&path, 4);
        let start = if name == "offset.mp4" { 2.0 } else { 1.5 };
        assert!(
            (video.info().start_time - start).abs() < 1e-3,
            "{name}: {}",
            video.info().start_time
        );
        assert_eq!(video.info().frame_count, N, "{name}");
        assert!((video.timestamp(1).unwrap() - start - 1.0 / 30.0).abs() < 1e-3);
        assert_frame(&video, 0, &source(0, 0));
        check_every_order(&path, &|i| source(i, 0));
    }
}

#[test]
fn a_truncated_mp4_without_its_index_does_not_open() {
    let path = fixture("cut-lossless.mp4");
    let e = VideoReader::open(&path).unwrap_err();
    assert!(matches!(e, VideoError::Unreadable { .. }), "{e:?}");
    assert!(e.to_string().contains("cut-lossless.mp4"), "{e}");
}

/// Every frame of a truncated file is the source frame or an error naming it and the file.
fn check_truncated(name: &'static str) {
    let path = fixture(name);
    let video = match VideoReader::open(&path) {
        Ok(v) => v.with_cache_bytes(4 * FRAME_BYTES),
        Err(e) => panic!("{name} should open (its index is before the cut): {e}"),
    };
    let count = video.info().frame_count;
    assert!(count > 8 && count < N, "{name}: {count} frames");
    let mut rng = Rng::new(3);
    let order: Vec<usize> = (0..count)
        .chain((0..40).map(|_| rng.below(count)))
        .collect();
    let mut good = 0;
    let mut failed = 0;
    for i in order {
        match video.frame(i) {
            Ok(f) => {
                assert!(
                    f.as_raw() == source(i, 0).as_raw(),
                    "{name}: frame {i} is wrong"
                );
                good += 1;
            }
            Err(e) => {
                let m = e.to_string();
                assert!(
                    matches!(e, VideoError::Decode { index, .. } if index == i),
                    "{m}"
                );
                assert!(m.contains(name) && m.contains(&format!("frame {i}")), "{m}");
                failed += 1;
            }
        }
    }
    assert!(good > 8, "{name}: only {good} frames decoded");
    let _ = failed; // the last frames may or may not decode: both are fine
}

#[test]
fn a_truncated_faststart_mp4_gives_right_frames_or_errors() {
    check_truncated("cut-faststart.mp4");
}

#[test]
fn a_truncated_mkv_gives_right_frames_or_errors() {
    check_truncated("cut-lossless.mkv");
}

#[test]
fn bad_files_fail_with_a_message_naming_them() {
    let text = fixture("text.mp4");
    let e = VideoReader::open(&text).unwrap_err();
    assert!(matches!(e, VideoError::Unreadable { .. }), "{e:?}");
    assert!(
        e.to_string().starts_with(&format!("{}: ", text.display())),
        "{e}"
    );

    let audio = fixture("audio.m4a");
    let e = VideoReader::open(&audio).unwrap_err();
    assert!(matches!(e, VideoError::NoVideoStream { .. }), "{e:?}");
    assert!(e.to_string().contains("audio.m4a"), "{e}");

    let missing = dir().join("no such video.mp4");
    let e = VideoReader::open(&missing).unwrap_err();
    assert!(matches!(e, VideoError::NotFound { .. }), "{e:?}");
    assert!(e.to_string().contains("no such video.mp4"), "{e}");
}

#[test]
fn a_frame_past_the_end_is_an_error() {
    let video = VideoReader::open(&fixture("lossless.mkv")).unwrap();
    for i in [N, N + 1, usize::MAX] {
        match video.frame(i) {
            Err(e @ VideoError::OutOfRange { .. }) => {
                let m = e.to_string();
                assert!(
                    m.contains(&format!("frame {i}")) && m.contains("64 frames"),
                    "{m}"
                );
            }
            other => panic!("frame {i}: expected OutOfRange, got {other:?}"),
        }
    }
    assert!(video.frame(N - 1).is_ok());
}

#[test]
fn missing_ffmpeg_says_to_install_it() {
    let path = fixture("lossless.mkv");
    for tools in [
        Tools {
            ffmpeg: "/nonexistent/ffmpeg".into(),
            ..Tools::default()
        },
        Tools {
            ffprobe: "/nonexistent/ffprobe".into(),
            ..Tools::default()
        },
    ] {
        let e = VideoReader::open_with(&path, &tools).unwrap_err();
        let m = e.to_string();
        assert!(matches!(e, VideoError::ToolMissing { .. }), "{e:?}");
        assert!(m.contains("/nonexistent/"), "{m}");
        assert!(
            m.contains("install FFmpeg: apt install ffmpeg / brew install ffmpeg"),
            "{m}"
        );
        assert!(m.contains("lossless.mkv"), "{m}");
    }
}

#[test]
fn the_cache_stays_within_its_bound() {
    let bound = 5 * FRAME_BYTES + FRAME_BYTES / 2;
    let video = VideoReader::open(&fixture("lossless.mkv"))
        .unwrap()
        .with_cache_bytes(bound);
    let mut rng = Rng::new(5);
    let order: Vec<usize> = (0..N).chain((0..40).map(|_| rng.below(N))).collect();
    for i in order {
        video.frame(i).unwrap();
        assert!(
            video.cached_bytes() <= bound,
            "{} bytes cached",
            video.cached_bytes()
        );
    }
    std::thread::sleep(Duration::from_millis(300));
    assert!(video.cached_bytes() <= bound);
    assert!(video.cached_bytes() >= 2 * FRAME_BYTES, "the cache is used");
}

/// Waits up to 10 s for `ready`.
fn eventually(ready: impl Fn() -> bool) -> bool {
    let since = Instant::now();
    while since.elapsed() < Duration::from_secs(10) {
        if ready() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    false
}

#[test]
fn frames_after_and_just_before_a_request_are_decoded_ahead() {
    let video = VideoReader::open(&fixture("lossless.mp4")).unwrap();
    video.frame(40).unwrap();
    assert!(
        eventually(|| (41..=52).all(|i| video.is_cached(i))),
        "the next 12 frames were not decoded ahead: {:?}",
        (41..=52)
            .filter(|&i| !video.is_cached(i))
            .collect::<Vec<_>>()
    );
    assert!(
        eventually(|| (37..40).all(|i| video.is_cached(i))),
        "the 3 frames before were not filled"
    );
    assert!(!video.is_cached(30) && !video.is_cached(56));
    // Playing on keeps the window ahead filled.
    for i in 41..50 {
        assert_frame(&video, i, &source(i, 0));
    }
    assert!(eventually(|| (50..=61).all(|i| video.is_cached(i))));
    assert_frame(&video, 38, &source(38, 0));
}

/// The ffmpeg children of this process whose command line names `file`.
#[cfg(target_os = "linux")]
fn children_reading(file: &str) -> Vec<u32> {
    let me = std::process::id().to_string();
    let mut pids = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let stat = std::fs::read_to_string(entry.path().join("stat")).unwrap_or_default();
        // pid (comm) state ppid …
        let ppid = stat
            .rsplit_once(") ")
            .and_then(|(_, rest)| rest.split(' ').nth(1));
        let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
        if ppid == Some(me.as_str()) && String::from_utf8_lossy(&cmdline).contains(file) {
            pids.push(pid);
        }
    }
    pids
}

#[cfg(target_os = "linux")]
#[test]
fn dropping_the_reader_ends_and_reaps_its_ffmpeg() {
    let path = dir().join("reaped.mkv");
    std::fs::copy(fixture("lossless.mkv"), &path).unwrap();
    let video = VideoReader::open(&path).unwrap();
    video.frame(30).unwrap();
    let pids = children_reading("reaped.mkv");
    assert!(!pids.is_empty(), "a decoder runs while the reader is open");
    drop(video);
    for pid in pids {
        assert!(
            !Path::new(&format!("/proc/{pid}")).exists(),
            "ffmpeg {pid} is still there (running or a zombie) after the reader was dropped"
        );
    }
}
