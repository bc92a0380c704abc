//! Nothing executes, phones out or writes where it should not (issue 17): every command is run
//! under `strace -f` and its system calls judged by [`common::strace`] — no socket, no program
//! run but the binary itself (FFmpeg's `ffmpeg`/`ffprobe` by those fixed names, for video
//! scenes, which these runs are not), and every file or folder created, written, renamed or
//! removed inside the command's output folder or its staging folder beside it
//! (`.NAME.partial-PID`). tests/app_session.rs checks the app the same way.

mod common;

use common::strace;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `endofuse ARGS` under strace; returns what broke the rules, given the folders it may
/// write (`out` and its staging folder beside it).
fn violations(args: &[&std::ffi::OsStr], out: &Path) -> Vec<String> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_endofuse"));
    cmd.args(args);
    let (run, text) = strace::run(&cmd, &out.with_extension("strace"));
    assert!(
        run.status.success(),
        "{:?}: {}",
        args,
        String::from_utf8_lossy(&run.stderr)
    );
    let name = out.file_name().unwrap().to_string_lossy().to_string();
    let staging = out.parent().unwrap().join(format!(".{name}.partial-"));
    strace::violations(&text, |p| {
        p.starts_with(out) || p.to_string_lossy().starts_with(&*staging.to_string_lossy())
    })
}

#[test]
fn commands_open_no_socket_run_no_program_and_write_only_their_output() {
    if !strace::available() {
        return;
    }
    let base = common::scratch_dir("no-side-effects");
    std::fs::create_dir_all(&base).unwrap();
    let scene = common::fixture();
    let synth_out = base.join("synth");
    let classify_out = base.join("classify");
    let track_out = base.join("track");
    let ct_out = base.join("ct");
    let ct = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/ct/kits19_case_00010_cropped.nii.gz");
    let os = |s: &Path| s.as_os_str().to_owned();
    let runs: Vec<(Vec<std::ffi::OsString>, PathBuf)> = vec![
        (
            vec!["info".into(), os(&scene)],
            base.join("info"), // writes nothing at all
        ),
        (
            vec![
                "synth".into(),
                "--out".into(),
                os(&synth_out),
                "--frames".into(),
                "2".into(),
                "--width".into(),
                "160".into(),
                "--height".into(),
                "90".into(),
            ],
            synth_out.clone(),
        ),
        (
            vec![
                "classify".into(),
                os(&scene),
                "--out".into(),
                os(&classify_out),
            ],
            classify_out.clone(),
        ),
        (
            vec![
                "track".into(),
                os(&synth_out),
                "--out".into(),
                os(&track_out),
                "--mode".into(),
                "LS".into(),
            ],
            track_out.clone(),
        ),
        (
            vec!["import-ct".into(), os(&ct), "--out".into(), os(&ct_out)],
            ct_out.clone(),
        ),
    ];
    let mut all = Vec::new();
    for (args, out) in &runs {
        let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
        all.extend(violations(&args, out));
    }
    assert!(all.is_empty(), "{}", all.join("\n"));
    assert!(track_out.join("trajectory.json").is_file());
    assert!(ct_out.join("structures.json").is_file());
    // The check itself can fail: the same classify judged against another folder breaks it.
    let elsewhere = base.join("classify-again");
    let args = [
        "classify".as_ref(),
        scene.as_os_str(),
        "--out".as_ref(),
        elsewhere.as_os_str(),
    ];
    let judged = violations(&args, &base.join("not-the-output"));
    assert!(
        judged.iter().any(|v| v.contains("wrote where it may not")),
        "writes into another folder went unseen"
    );
}
