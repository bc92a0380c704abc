//! Where the FFmpeg programs are and what running them says: the paths (overridable so a test
//! can point at a program that is not there, and a user at an FFmpeg outside `PATH`), which
//! option keeps every frame (`-fps_mode` arrived in 5.1, older releases know only `-vsync`),
//! and the first line of what a program wrote to stderr, which is what an error message quotes.

use super::VideoError;
use std::ffi::OsString;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{ChildStderr, Command, Stdio};
use std::thread::JoinHandle;

/// The FFmpeg programs to run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Tools {
    pub ffmpeg: PathBuf,
    pub ffprobe: PathBuf,
}

impl Default for Tools {
    /// `ffmpeg` and `ffprobe` as `PATH` finds them.
    fn default() -> Self {
        Tools {
            ffmpeg: "ffmpeg".into(),
            ffprobe: "ffprobe".into(),
        }
    }
}

impl Tools {
    /// Environment variable naming the `ffmpeg` program to use instead of `PATH`'s.
    pub const FFMPEG_ENV: &'static str = "ENDOFUSE_FFMPEG";
    /// Environment variable naming the `ffprobe` program to use instead of `PATH`'s.
    pub const FFPROBE_ENV: &'static str = "ENDOFUSE_FFPROBE";

    /// The programs named by `ENDOFUSE_FFMPEG` / `ENDOFUSE_FFPROBE` where set, else `PATH`'s.
    pub fn from_env() -> Tools {
        let pick = |var: &str, default: &str| {
            std::env::var_os(var)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
                .unwrap_or_else(|| default.into())
        };
        Tools {
            ffmpeg: pick(Self::FFMPEG_ENV, "ffmpeg"),
            ffprobe: pick(Self::FFPROBE_ENV, "ffprobe"),
        }
    }
}

/// The option that makes ffmpeg pass every decoded frame through, neither duplicating nor
/// dropping any (its default for raw output may do either to reach a constant rate). Asking
/// `ffmpeg -version` once per opened file also tells early, at open, that ffmpeg is missing.
pub(crate) fn passthrough_option(ffmpeg: &Path, video: &Path) -> Result<&'static str, VideoError> {
    let out = Command::new(ffmpeg)
        .args(["-hide_banner", "-version"])
        .stdin(Stdio::null())
        .output()
        .map_err(|e| spawn_error(ffmpeg, video, e))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let first = text.lines().next().unwrap_or("");
    if !out.status.success() || !first.contains("version") {
        return Err(VideoError::Tool {
            path: video.to_path_buf(),
            program: ffmpeg.display().to_string(),
            message: format!(
                "`-version` did not answer like FFmpeg ({})",
                first_line(&out.stderr, video).unwrap_or_else(|| out.status.to_string())
            ),
        });
    }
    Ok(if knows_fps_mode(first) {
        "-fps_mode"
    } else {
        "-vsync"
    })
}

/// Whether the `ffmpeg -version` first line names a release with `-fps_mode` (5.1 or later).
/// Builds from git say `N-…` or a hash: they are newer than any release that lacks it.
fn knows_fps_mode(version_line: &str) -> bool {
    let Some(word) = version_line
        .split_whitespace()
        .skip_while(|w| *w != "version")
        .nth(1)
    else {
        return true;
    };
    let word = word.trim_start_matches('n');
    let mut numbers = word.split(|c: char| !c.is_ascii_digit());
    let major = numbers.next().and_then(|n| n.parse::<u32>().ok());
    let minor = numbers
        .next()
        .and_then(|n| n.parse::<u32>().ok())
        .unwrap_or(0);
    match major {
        Some(major) => (major, minor) >= (5, 1),
        None => true,
    }
}

/// A program that could not be started: missing (the "install FFmpeg" error) or not runnable.
pub(crate) fn spawn_error(program: &Path, video: &Path, err: std::io::Error) -> VideoError {
    if err.kind() == std::io::ErrorKind::NotFound {
        VideoError::ToolMissing {
            path: video.to_path_buf(),
            program: program.display().to_string(),
        }
    } else {
        VideoError::Tool {
            path: video.to_path_buf(),
            program: program.display().to_string(),
            message: err.to_string(),
        }
    }
}

/// `path` as an FFmpeg input URL: the `file:` prefix keeps a name that starts with `-` or
/// holds a `:` (which FFmpeg would take for an option or a protocol) a plain file.
pub(crate) fn input_url(path: &Path) -> OsString {
    let mut url = OsString::from("file:");
    url.push(path.as_os_str());
    url
}

/// The first non-empty line of a program's stderr, without the `file:…: ` that FFmpeg puts in
/// front of messages about `video` (the error names the file already).
pub(crate) fn first_line(stderr: &[u8], video: &Path) -> Option<String> {
    let text = String::from_utf8_lossy(stderr);
    let line = text.lines().map(str::trim).find(|l| !l.is_empty())?;
    let prefix = format!("{}: ", input_url(video).to_string_lossy());
    let line = line.strip_prefix(&prefix).unwrap_or(line);
    // `[h264 @ 0x55d7f11c4140] ` says which of FFmpeg's parts spoke, at which address.
    let line = match line.split_once("] ") {
        Some((part, rest)) if part.starts_with('[') && part.contains(" @ 0x") => rest,
        _ => line,
    };
    Some(line.to_string())
}

/// Drains a child's stderr on a thread, keeping the first few kilobytes: a child whose stderr
/// pipe fills would block, and a damaged file can make a decoder write a line per frame.
pub(crate) struct StderrCollector {
    thread: Option<JoinHandle<Vec<u8>>>,
}

impl StderrCollector {
    const KEEP: usize = 8 * 1024;

    pub(crate) fn start(stderr: Option<ChildStderr>) -> StderrCollector {
        let thread = stderr.and_then(|mut pipe| {
            std::thread::Builder::new()
                .name("ffmpeg-stderr".into())
                .spawn(move || {
                    let mut kept = Vec::new();
                    let mut chunk = [0u8; 4096];
                    loop {
                        match pipe.read(&mut chunk) {
                            Ok(0) | Err(_) => break,
                            Ok(n) => {
                                let room = Self::KEEP.saturating_sub(kept.len());
                                kept.extend_from_slice(&chunk[..n.min(room)]);
                            }
                        }
                    }
                    kept
                })
                .ok()
        });
        StderrCollector { thread }
    }

    /// What the child wrote, once its stderr has closed (call after the child has exited).
    pub(crate) fn finish(&mut self) -> Vec<u8> {
        self.thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fps_mode_from_version_5_1_on() {
        let cases = [
            (
                "ffmpeg version 5.1.9-0+deb12u1 Copyright (c) 2000-2026",
                true,
            ),
            ("ffmpeg version 4.4.2-0ubuntu0.22.04.1 Copyright", false),
            ("ffmpeg version n5.0.3 Copyright", false),
            ("ffmpeg version 6.1 Copyright", true),
            (
                "ffmpeg version 7.0.2-static https://johnvansickle.com",
                true,
            ),
            ("ffmpeg version N-113207-g8d24a28d06 Copyright", true),
            ("ffmpeg version 5 Copyright", false),
            ("something else", true),
        ];
        for (line, expected) in cases {
            assert_eq!(knows_fps_mode(line), expected, "{line}");
        }
    }

    #[test]
    fn first_line_drops_the_input_name() {
        let video = Path::new("/tmp/a: b.mp4");
        assert_eq!(
            first_line(
                b"\n  file:/tmp/a: b.mp4: Invalid data found when processing input\nmore\n",
                video
            )
            .as_deref(),
            Some("Invalid data found when processing input")
        );
        assert_eq!(
            first_line(
                b"[h264 @ 0x55] Invalid NAL unit size (5527 > 2725).\n",
                video
            )
            .as_deref(),
            Some("Invalid NAL unit size (5527 > 2725).")
        );
        assert_eq!(first_line(b" \n\n", video), None);
    }

    #[test]
    fn input_urls_keep_odd_names_files() {
        assert_eq!(
            input_url(Path::new("-x:y.mp4")),
            OsString::from("file:-x:y.mp4")
        );
    }

    #[test]
    fn a_missing_program_says_what_to_install() {
        let e = passthrough_option(Path::new("/nonexistent/ffmpeg"), Path::new("v.mp4"));
        match e {
            Err(e @ VideoError::ToolMissing { .. }) => {
                assert!(e.to_string().contains("install FFmpeg"), "{e}")
            }
            other => panic!("expected ToolMissing, got {other:?}"),
        }
    }
}
