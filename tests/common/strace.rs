//! Running a program under `strace -f` and judging the system calls it made (issue 17:
//! nothing executes, phones out or writes where it should not):
//! - no socket is opened and no connection made (no network at all);
//! - no program is executed but the first one (and FFmpeg's `ffmpeg`/`ffprobe`, by those
//!   fixed names);
//! - every file or folder created, written, renamed or removed is one the caller allows.
//!
//! Needs strace (Debian's `strace`, installed by `.ci/run`). Without it [`available`] says so
//! and the caller skips, except where ENDOFUSE_REQUIRE_STRACE is set (CI sets it).

use std::path::Path;
use std::process::{Command, Output};

const CALLS: &str = "trace=execve,execveat,socket,connect,open,openat,creat,mkdir,mkdirat,rename,renameat,renameat2,unlink,unlinkat,rmdir,link,linkat,symlink,symlinkat,truncate";

pub fn available() -> bool {
    // Tracing `true` tells both that strace is there and that this machine lets it trace.
    let works = Command::new("strace")
        .args(["-f", "-o", "/dev/null", "true"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !works {
        assert!(
            std::env::var_os("ENDOFUSE_REQUIRE_STRACE").is_none(),
            "strace is required here (ENDOFUSE_REQUIRE_STRACE) but is missing or may not trace"
        );
        eprintln!("strace missing or not allowed to trace: the system-call checks did not run");
    }
    works
}

/// Runs `command` under strace, its calls logged to `log`; returns its output and the log.
pub fn run(command: &Command, log: &Path) -> (Output, String) {
    let _ = std::fs::remove_file(log);
    let mut traced = Command::new("strace");
    traced
        .args(["-f", "-qq", "-s", "4096", "-o"])
        .arg(log)
        .args(["-e", CALLS])
        .arg(command.get_program())
        .args(command.get_args());
    for (k, v) in command.get_envs() {
        match v {
            Some(v) => traced.env(k, v),
            None => traced.env_remove(k),
        };
    }
    let out = traced.output().unwrap();
    let text = std::fs::read_to_string(log).unwrap();
    (out, text)
}

/// The quoted path arguments of one strace line (`"…"`), in order.
pub fn paths_of(line: &str) -> Vec<String> {
    line.split('"')
        .enumerate()
        .filter(|(i, _)| i % 2 == 1)
        .map(|(_, p)| p.to_string())
        .collect()
}

/// What in the strace log `text` broke the rules, given the paths the program may write.
pub fn violations(text: &str, may_write: impl Fn(&Path) -> bool) -> Vec<String> {
    let mut bad = Vec::new();
    let mut execs = 0;
    for line in text.lines() {
        // Failed calls changed nothing (a create_dir_all probing a parent that exists).
        let failed = line.contains(" = -1 ");
        let call = line
            .split_once(' ')
            .map(|(_, rest)| rest.trim_start())
            .unwrap_or(line);
        if call.starts_with("socket(") || call.starts_with("connect(") {
            bad.push(format!("network: {line}"));
        } else if call.starts_with("execve") {
            if !failed {
                execs += 1;
                let program = paths_of(line).first().cloned().unwrap_or_default();
                if execs > 1 && !program.ends_with("/ffmpeg") && !program.ends_with("/ffprobe") {
                    bad.push(format!("ran a program: {line}"));
                }
            }
        } else if !failed {
            let writes = if call.starts_with("open") {
                call.contains("O_WRONLY") || call.contains("O_RDWR") || call.contains("O_CREAT")
            } else {
                true // creat, mkdir, rename, unlink, rmdir, link, symlink, truncate
            };
            if writes {
                // Every path a writing call names (both ends of a rename) must be allowed.
                for p in paths_of(line) {
                    if !may_write(Path::new(&p)) && p != "/dev/null" && p != "/dev/tty" {
                        bad.push(format!("wrote where it may not: {line}"));
                    }
                }
            }
        }
    }
    assert!(execs >= 1, "strace saw the program start: {text}");
    bad
}

/// True when the log shows `path` opened for writing or created (the trace saw the writes).
pub fn wrote(text: &str, path: &Path) -> bool {
    let p = path.to_string_lossy();
    text.lines().any(|l| {
        !l.contains(" = -1 ")
            && paths_of(l).iter().any(|q| q.starts_with(&*p))
            && (l.contains("O_CREAT") || l.contains("O_WRONLY") || l.contains("rename"))
    })
}
