//! Crash safety of the session file and the autosave (issue 17): a process killed with
//! SIGKILL at random points while it saves, again and again, never leaves a broken file, and
//! the file on disk is never older than the last save that returned (an autosave is at most
//! one interval old). Both go through `Session::save` (write to a temporary of its own, sync,
//! rename), which the app's Save and its autosave thread call.
//!
//! The writer is this test binary itself, re-run with ENDOFUSE_CRASH_WRITER set: it saves
//! sessions of ~2 MB numbered 1, 2, 3… and prints each number once `save` has returned.

use endofuse::session::{SESSION_FORMAT, SeedLayer, Session};
use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};

/// A session whose `scene` names its number and whose seeds make it a few megabytes, so a
/// kill lands inside the write often.
fn numbered_session(n: u64) -> Session {
    let runs: Vec<(u32, u8)> = (0..200_000u32)
        .map(|i| (1 + (i + n as u32) % 7, (i % 3) as u8))
        .collect();
    let pixels: u32 = runs.iter().map(|r| r.0).sum();
    Session {
        format: SESSION_FORMAT.into(),
        scene: format!("save-{n}"),
        seeds: vec![SeedLayer {
            camera: 0,
            frame: 0,
            width: pixels as usize,
            height: 1,
            runs,
        }],
        settings: Default::default(),
        placement: None,
        forest: None,
        results: Vec::new(),
    }
}

/// The writer half: runs only when the kill test starts this binary with the variable set.
#[test]
fn writer_for_the_kill_test() {
    let Some(path) = std::env::var_os("ENDOFUSE_CRASH_WRITER") else {
        return;
    };
    let path = Path::new(&path);
    for n in 1.. {
        numbered_session(n).save(path).expect("save");
        println!("saved {n}");
    }
}

fn number_of(s: &Session) -> u64 {
    s.scene
        .strip_prefix("save-")
        .and_then(|n| n.parse().ok())
        .expect("a numbered session")
}

#[test]
fn a_session_killed_while_saving_is_whole_and_never_older_than_the_last_save() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("crash-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("autosave-0123.json");
    let exe = std::env::current_exe().unwrap();
    // A fixed sequence of kill times (ms after start), spread over the first saves and the
    // steady state.
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut kills_inside_a_write = 0;
    let mut ever_saved = false;
    // At least 30 rounds, and more (up to 120) until three kills have landed inside a write:
    // on a loaded machine the writers start late and fewer kills find one mid-write.
    let mut rounds = 0;
    for round in 0..120 {
        if round >= 30 && kills_inside_a_write >= 3 {
            break;
        }
        rounds = round + 1;
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let delay_ms = 20 + (state >> 33) % 180;
        let mut child = Command::new(&exe)
            .args([
                "--exact",
                "writer_for_the_kill_test",
                "--nocapture",
                "--test-threads=1",
            ])
            .env("ENDOFUSE_CRASH_WRITER", &path)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        let mut out = String::new();
        child
            .stdout
            .take()
            .unwrap()
            .read_to_string(&mut out)
            .unwrap();
        let last_returned = out
            .lines()
            .filter_map(|l| l.strip_prefix("saved "))
            .filter_map(|n| n.parse::<u64>().ok())
            .max();
        // A temporary left by the kill is never the file itself.
        let temporaries = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
            .count();
        kills_inside_a_write += (temporaries > 0) as usize;
        if !path.exists() {
            // Only before any save ever returned (on a loaded machine the first rounds' writers
            // may be killed before their first save ends).
            assert!(
                last_returned.is_none() && !ever_saved,
                "round {round}: the session vanished after save {last_returned:?}"
            );
            continue;
        }
        ever_saved = true;
        let on_disk = Session::load(&path).unwrap_or_else(|e| {
            panic!("round {round} (killed at {delay_ms} ms): broken file: {e}")
        });
        let n = number_of(&on_disk);
        assert_eq!(
            on_disk,
            numbered_session(n),
            "round {round}: save {n} is not whole"
        );
        if let Some(last) = last_returned {
            // The rename of save last+1 may have happened before the kill, its print not.
            assert!(
                n == last || n == last + 1,
                "round {round}: file holds save {n}, the last save that returned was {last}"
            );
        }
        for e in std::fs::read_dir(&dir).unwrap().flatten() {
            if e.file_name().to_string_lossy().contains(".tmp-") {
                std::fs::remove_file(e.path()).unwrap();
            }
        }
    }
    assert!(
        kills_inside_a_write >= 3,
        "only {kills_inside_a_write} of {rounds} kills landed inside a write: the test shows nothing"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A disk that takes no more bytes (simulated by a file-size limit of 0 with SIGXFSZ ignored,
/// so every write fails as on a full disk): `classify` and `track` exit 1 with one line naming
/// the file they could not write, and leave neither `--out` nor a staging folder behind.
#[test]
fn a_full_disk_gives_exit_1_naming_the_file_and_leaves_nothing_half_written() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("full-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/handmade_scene");
    for command in ["classify", "track"] {
        let out = dir.join(command);
        let run = Command::new("sh")
            .arg("-c")
            .arg("ulimit -f 0 && trap '' XFSZ && exec \"$0\" \"$@\"")
            .arg(env!("CARGO_BIN_EXE_endofuse"))
            .arg(command)
            .arg(&scene)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{command}: {stderr}");
        let last = stderr
            .lines()
            .filter(|l| l.starts_with("endofuse:"))
            .collect::<Vec<_>>();
        assert_eq!(last.len(), 1, "{command}: one error line: {stderr}");
        // The first file either writes is a PNG (a map or a mask), named under --out.
        assert!(
            last[0].contains("cannot write")
                && last[0].contains(&*out.to_string_lossy())
                && last[0].contains(".png")
                && !last[0].contains(".partial-"),
            "{command}: names the file it could not write: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert!(left.is_empty(), "{command} left {left:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
