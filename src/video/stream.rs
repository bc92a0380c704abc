//! One running `ffmpeg` that decodes the video from some frame on and writes raw RGB frames
//! (width × height × 3 bytes each) to a pipe, and knows which frame comes out next. A frame
//! that does not come out whole is an error naming the frame and quoting ffmpeg's stderr,
//! never a partial image; the child is killed and reaped when the stream is dropped.

use super::timeline::{Start, Timeline};
use super::tools::{StderrCollector, first_line, input_url, spawn_error};
use super::{VideoError, VideoInfo, probe::VIDEO_STREAM};
use image::RgbImage;
use std::io::Read;
use std::path::PathBuf;
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// Everything needed to start a decoder for one file.
pub(crate) struct Source {
    pub path: PathBuf,
    pub ffmpeg: PathBuf,
    /// `-fps_mode` or `-vsync` (see [`super::tools::passthrough_option`]).
    pub passthrough: &'static str,
    pub info: VideoInfo,
    pub timeline: Timeline,
}

impl Source {
    pub(crate) fn frame_bytes(&self) -> usize {
        self.info.width as usize * self.info.height as usize * 3
    }

    /// A decoder whose output reaches frame `index` (it may start a few frames before: see
    /// [`Stream::next`]).
    pub(crate) fn spawn(&self, index: usize) -> Result<Stream, VideoError> {
        self.spawn_at(self.timeline.start_for(index))
    }

    /// A decoder started as `start` says.
    pub(crate) fn spawn_at(&self, start: Start) -> Result<Stream, VideoError> {
        let mut cmd = Command::new(&self.ffmpeg);
        // -xerror: a decoding error ends the output, so a damaged frame is never skipped
        // silently (which would shift every later index) nor replaced by a concealed one.
        cmd.args(["-nostdin", "-hide_banner", "-v", "error", "-xerror"]);
        // The stream's own frames, whatever rotation its header asks a player for.
        cmd.arg("-noautorotate");
        if !start.accurate {
            cmd.arg("-noaccurate_seek");
        }
        if let Some(seek) = start.seek {
            cmd.args(["-ss", &format!("{seek:.6}")]);
        }
        cmd.arg("-i").arg(input_url(&self.path));
        cmd.args(["-map", &format!("0:{VIDEO_STREAM}"), "-an", "-sn", "-dn"]);
        cmd.args([self.passthrough, "passthrough"]);
        cmd.args(["-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"]);
        log::debug!("{}: ffmpeg from {start:?}", self.path.display());
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| spawn_error(&self.ffmpeg, &self.path, e))?;
        let stderr = StderrCollector::start(child.stderr.take());
        let Some(stdout) = child.stdout.take() else {
            let _ = child.kill();
            let _ = child.wait();
            return Err(VideoError::Tool {
                path: self.path.clone(),
                program: self.ffmpeg.display().to_string(),
                message: "no output pipe".into(),
            });
        };
        Ok(Stream {
            child: KillSwitch(Arc::new(Mutex::new(child))),
            stdout,
            stderr,
            next: start.first,
            seeked: start.seek.is_some(),
            width: self.info.width,
            height: self.info.height,
            path: self.path.clone(),
        })
    }
}

/// Stops a stream's child from another thread: a decode-ahead that a new request made
/// useless is cut off instead of finishing its seek.
#[derive(Clone)]
pub(crate) struct KillSwitch(Arc<Mutex<Child>>);

impl KillSwitch {
    pub(crate) fn kill(&self) {
        let _ = self.lock().kill();
    }

    fn lock(&self) -> MutexGuard<'_, Child> {
        self.0
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// A running decoder positioned at frame [`Stream::next`].
pub(crate) struct Stream {
    child: KillSwitch,
    stdout: ChildStdout,
    stderr: StderrCollector,
    next: usize,
    /// Started by a seek rather than at the file's first frame.
    seeked: bool,
    width: u32,
    height: u32,
    path: PathBuf,
}

impl Stream {
    /// The index of the frame the next [`Stream::read`] returns.
    pub(crate) fn next(&self) -> usize {
        self.next
    }

    pub(crate) fn seeked(&self) -> bool {
        self.seeked
    }

    pub(crate) fn kill_switch(&self) -> KillSwitch {
        self.child.clone()
    }

    /// Frame [`Stream::next`], whole, in `buf`'s memory (a frame's worth of capacity spares
    /// an allocation and its page faults). After an error the stream is spent: drop it.
    pub(crate) fn read(&mut self, mut buf: Vec<u8>) -> Result<RgbImage, VideoError> {
        let index = self.next;
        let bytes = self.width as usize * self.height as usize * 3;
        buf.clear();
        buf.reserve_exact(bytes);
        let got = (&mut self.stdout).take(bytes as u64).read_to_end(&mut buf);
        let problem = match got {
            Ok(n) if n == bytes => match RgbImage::from_raw(self.width, self.height, buf) {
                Some(img) => {
                    self.next += 1;
                    return Ok(img);
                }
                None => "the frame does not fit its size".to_string(),
            },
            Ok(n) => self.why_ended(n),
            Err(e) => format!("reading the decoder's output failed: {e}"),
        };
        Err(VideoError::Decode {
            path: self.path.clone(),
            index,
            message: problem,
        })
    }

    /// Why the output ended `got` bytes into a frame: ffmpeg's first error line, else its exit.
    fn why_ended(&mut self, got: usize) -> String {
        let status = self.wait_exit(Duration::from_secs(5));
        let stderr = self.stderr.finish();
        if let Some(line) = first_line(&stderr, &self.path) {
            return line;
        }
        let partial = if got > 0 {
            format!(" ({got} bytes of the frame came)")
        } else {
            String::new()
        };
        match status {
            Some(s) if s.success() => {
                format!("the decoder ended before this frame{partial}: the file may be truncated")
            }
            Some(s) => format!("ffmpeg stopped ({s}){partial}"),
            None => format!("ffmpeg stopped writing frames{partial}"),
        }
    }

    /// The child's exit status, waiting up to `limit` for it to exit, else killing it.
    fn wait_exit(&mut self, limit: Duration) -> Option<std::process::ExitStatus> {
        let since = Instant::now();
        let mut child = self.child.lock();
        loop {
            match child.try_wait() {
                Ok(Some(status)) => return Some(status),
                Ok(None) if since.elapsed() < limit => {}
                _ => {
                    let _ = child.kill();
                    return child.wait().ok();
                }
            }
            drop(child);
            std::thread::sleep(Duration::from_millis(5));
            child = self.child.lock();
        }
    }
}

impl Drop for Stream {
    fn drop(&mut self) {
        // Kill, then reap: no zombie ffmpeg per seek.
        {
            let mut child = self.child.lock();
            let _ = child.kill();
            let _ = child.wait();
        }
        self.stderr.finish();
    }
}
