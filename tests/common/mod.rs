//! Helpers the end-to-end tests share: scratch folders, the hand-made fixture, and running
//! the binary.
#![allow(dead_code)]

#[cfg(feature = "app-tests")]
pub mod app;
pub mod strace;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh scratch folder for this test process, named after `tag`.
pub fn scratch_dir(tag: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("endofuse-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

pub fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/handmade_scene")
}

/// A private copy of the hand-made fixture scene.
pub fn fixture_copy(tag: &str) -> PathBuf {
    let dir = scratch_dir(tag);
    copy_dir(&fixture(), &dir);
    dir
}

/// Runs `endofuse ARGS` and asserts that it succeeded.
pub fn run_ok<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `endofuse synth --out <scratch> ARGS`, asserting success.
pub fn synth(tag: &str, args: &[&str]) -> PathBuf {
    let dir = scratch_dir(tag);
    let mut all: Vec<std::ffi::OsString> = vec!["synth".into(), "--out".into(), dir.clone().into()];
    all.extend(args.iter().map(|a| a.into()));
    run_ok(&all);
    dir
}

/// Rewrites `dir/scene.json` after `f` changed its JSON.
pub fn edit_json(dir: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let p = dir.join("scene.json");
    let mut v = read_json(&p);
    f(&mut v);
    std::fs::write(p, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

pub fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}
