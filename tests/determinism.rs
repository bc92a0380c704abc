//! Same input, same output (issue 17): `track` run twice, and with one worker thread against
//! two, writes the same trajectory.json byte for byte (per-frame times left out with
//! `--no-timings`, the one thing a run's clock decides).

mod common;

use std::path::Path;
use std::process::Command;

/// `track SCENE --out OUT --no-timings ARGS` with `threads` rayon workers; the file it wrote.
fn trajectory_bytes(scene: &Path, out: &Path, threads: usize, args: &[&str]) -> Vec<u8> {
    let run = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .env("RAYON_NUM_THREADS", threads.to_string())
        .arg("track")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .arg("--no-timings")
        .args(args)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    std::fs::read(out.join("trajectory.json")).unwrap()
}

#[test]
fn track_writes_the_same_bytes_twice_and_with_one_or_two_threads() {
    // A zoom in the range, so the camera correction (LSC) and the hidden region's zoom terms
    // take part too.
    let scene = common::synth(
        "determinism",
        &[
            "--frames", "8", "--seed", "6", "--width", "320", "--height", "180", "--noise", "0.02",
        ],
    );
    let args = ["--mode", "LSC", "--frames", "0..7"];
    let two = trajectory_bytes(&scene, &common::scratch_dir("det-two"), 2, &args);
    let again = trajectory_bytes(&scene, &common::scratch_dir("det-again"), 2, &args);
    let one = trajectory_bytes(&scene, &common::scratch_dir("det-one"), 1, &args);
    let text = String::from_utf8_lossy(&two);
    assert!(text.contains("\"affine\""), "a real trajectory: {text}");
    assert!(
        !text.contains("\"ms\""),
        "--no-timings leaves the per-frame times out"
    );
    assert!(two == again, "two runs of the same input differ");
    assert!(one == two, "one thread and two threads differ");
    // The times are there by default.
    let timed = common::scratch_dir("det-timed");
    common::run_ok(&[
        "track".as_ref(),
        scene.as_os_str(),
        "--out".as_ref(),
        timed.as_os_str(),
        "--mode".as_ref(),
        "LS".as_ref(),
        "--frames".as_ref(),
        "0..1".as_ref(),
    ]);
    let timed = std::fs::read_to_string(timed.join("trajectory.json")).unwrap();
    assert!(timed.contains("\"ms\""), "{timed}");
}
