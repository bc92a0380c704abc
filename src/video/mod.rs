//! Video files as frame sources: frame `i` of a camera is the `i`-th decoded frame of the
//! file's first video stream in presentation order, the same pixels whether it is reached by
//! playing forward or by seeking. The FFmpeg programs do the decoding (`ffprobe` lists the
//! packets, `ffmpeg` decodes to raw RGB on a pipe), so a plain `cargo build` needs no system
//! libraries; a missing FFmpeg is an ordinary error that says what to install.
//!
//! The pieces: [`probe`](probe()) reads the stream's frame table, [`VideoReader`] keeps one
//! running decoder, a bounded cache and a decode-ahead thread so that scrubbing and playing a
//! 1080p video neither stalls nor grows memory with the video's length.

mod ahead;
mod cache;
mod probe;
mod reader;
mod stream;
mod timeline;
mod tools;

pub use reader::{DEFAULT_CACHE_BYTES, VideoReader};
pub use tools::Tools;

use std::path::{Path, PathBuf};

/// What ffprobe says about the first video stream (cover art excluded), with the frame count
/// taken from its packets rather than from the container's header.
#[derive(Clone, Debug, PartialEq)]
pub struct VideoInfo {
    pub width: u32,
    pub height: u32,
    /// Frames that can be read: `0..frame_count`.
    pub frame_count: usize,
    /// Frames per second as the container states it (the average rate), or as the frame
    /// timestamps imply where it states none.
    pub fps: f64,
    /// FFmpeg's codec name, e.g. `h264`, `ffv1`.
    pub codec: String,
    /// Frame 0's presentation time in seconds (not 0 in files cut from a longer recording).
    pub start_time: f64,
}

/// A rectangle of a frame in pixels: one view of a side-by-side stereo video.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Crop {
    /// The left and right halves of a side-by-side frame `width` × `height` (an odd width
    /// leaves the middle column out of both).
    pub fn side_by_side(width: u32, height: u32) -> (Crop, Crop) {
        let half = width / 2;
        let left = Crop {
            x: 0,
            y: 0,
            width: half,
            height,
        };
        let right = Crop {
            x: width - half,
            ..left
        };
        (left, right)
    }
}

/// Everything reading a video can fail with. Each message names the file and says the problem
/// in one line.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    #[error("{}: file not found", path.display())]
    NotFound { path: PathBuf },
    /// `ffmpeg` or `ffprobe` could not be started because it is not there.
    #[error(
        "{}: cannot read the video: {program} not found; install FFmpeg: apt install ffmpeg / brew install ffmpeg / https://ffmpeg.org/download.html",
        path.display()
    )]
    ToolMissing { path: PathBuf, program: String },
    /// `ffmpeg` or `ffprobe` is there but could not be run (permissions, odd output).
    #[error("{}: {program} failed: {message}", path.display())]
    Tool {
        path: PathBuf,
        program: String,
        message: String,
    },
    /// ffprobe cannot open the file: not a media file, or too damaged to find its streams.
    #[error("{}: not a readable video: {message}", path.display())]
    Unreadable { path: PathBuf, message: String },
    #[error("{}: no video stream (audio only, or not a video file)", path.display())]
    NoVideoStream { path: PathBuf },
    #[error("{}: the video stream has no frames", path.display())]
    NoFrames { path: PathBuf },
    #[error("{}: frame {index} does not exist (the video has {count} frames)", path.display())]
    OutOfRange {
        path: PathBuf,
        index: usize,
        count: usize,
    },
    /// The decoder stopped or failed before producing the frame: a truncated or damaged file.
    #[error("{}: frame {index} cannot be decoded: {message}", path.display())]
    Decode {
        path: PathBuf,
        index: usize,
        message: String,
    },
    #[error(
        "{}: crop {}×{} at ({}, {}) does not fit the {width}×{height} frame",
        path.display(), crop.width, crop.height, crop.x, crop.y
    )]
    BadCrop {
        path: PathBuf,
        crop: Crop,
        width: u32,
        height: u32,
    },
}

impl VideoError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            VideoError::NotFound { path }
            | VideoError::ToolMissing { path, .. }
            | VideoError::Tool { path, .. }
            | VideoError::Unreadable { path, .. }
            | VideoError::NoVideoStream { path }
            | VideoError::NoFrames { path }
            | VideoError::OutOfRange { path, .. }
            | VideoError::Decode { path, .. }
            | VideoError::BadCrop { path, .. } => path,
        }
    }
}

/// What ffprobe says about `path`'s first video stream, with the FFmpeg programs found as
/// [`Tools::from_env`] says.
pub fn probe(path: &Path) -> Result<VideoInfo, VideoError> {
    probe_with(path, &Tools::from_env())
}

/// [`probe()`] with the FFmpeg programs at the given paths.
pub fn probe_with(path: &Path, tools: &Tools) -> Result<VideoInfo, VideoError> {
    probe::probe(path, tools).map(|p| p.info)
}

/// Whether `path` names a video file by its extension (mp4 m4v mov avi mkv webm, any case):
/// how a folder of frames is told from a video.
pub fn is_video_path(path: &Path) -> bool {
    const EXTENSIONS: [&str; 6] = ["mp4", "m4v", "mov", "avi", "mkv", "webm"];
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| EXTENSIONS.iter().any(|v| e.eq_ignore_ascii_case(v)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn video_paths_by_extension_in_any_case() {
        for p in ["a.mp4", "b.M4V", "c.MoV", "d.avi", "e.mkv", "dir.x/f.WEBM"] {
            assert!(is_video_path(Path::new(p)), "{p}");
        }
        for p in ["a.png", "mp4", "a.mp4.txt", "frames/", "a.", ""] {
            assert!(!is_video_path(Path::new(p)), "{p}");
        }
    }

    #[test]
    fn side_by_side_halves() {
        let (l, r) = Crop::side_by_side(640, 240);
        assert_eq!(
            l,
            Crop {
                x: 0,
                y: 0,
                width: 320,
                height: 240
            }
        );
        assert_eq!(r.x, 320);
        assert_eq!(r.width, 320);
        let (l, r) = Crop::side_by_side(641, 2);
        assert_eq!((l.width, r.x, r.width), (320, 321, 320));
    }

    #[test]
    fn messages_name_the_file_in_one_line() {
        let path = PathBuf::from("/videos/case 3.mp4");
        let errors = [
            VideoError::NotFound { path: path.clone() },
            VideoError::ToolMissing {
                path: path.clone(),
                program: "/opt/ffmpeg".into(),
            },
            VideoError::Decode {
                path: path.clone(),
                index: 17,
                message: "the decoder stopped".into(),
            },
            VideoError::BadCrop {
                path: path.clone(),
                crop: Crop {
                    x: 1,
                    y: 2,
                    width: 3,
                    height: 4,
                },
                width: 2,
                height: 2,
            },
        ];
        for e in &errors {
            let m = e.to_string();
            assert!(m.starts_with("/videos/case 3.mp4: "), "{m}");
            assert!(!m.contains('\n'), "{m}");
            assert_eq!(e.path(), path);
        }
        assert!(
            errors[1]
                .to_string()
                .contains("install FFmpeg: apt install ffmpeg")
        );
        assert!(errors[2].to_string().contains("frame 17"));
    }
}
