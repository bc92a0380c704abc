//! Video frames of each camera: image sequences on disk (PNG, JPEG) behind a bounded cache of
//! decoded frames, a video file (or one view of a side-by-side video) read by
//! [`crate::video::VideoReader`] with its own cache and decode-ahead, or frames held in memory
//! (the built-in demo). Shared between threads.

use super::template::PathTemplate;
use crate::error::InputError;
use crate::video::{Crop, VideoError, VideoReader};
use image::RgbImage;
use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Decoded frames kept at most (across cameras): ~190 MB at 960×540, enough to scrub back and
/// forth without decoding again.
pub const DEFAULT_CACHE_FRAMES: usize = 128;
/// And at most this many bytes of decoded pixels: 128 frames of 1080p took 800 MB, and the
/// app scrubbing a long 1080p image sequence passed 1 GiB (as the video reader's cache).
pub const DEFAULT_CACHE_BYTES: usize = 256 << 20;

/// Where one camera's frames come from.
#[derive(Clone)]
pub enum FrameSource {
    Files {
        root: PathBuf,
        template: PathTemplate,
        camera: String,
    },
    /// A video file; cameras of one side-by-side video share its reader.
    Video {
        reader: Arc<VideoReader>,
        crop: Option<Crop>,
    },
    Memory(Arc<Vec<Arc<RgbImage>>>),
}

impl std::fmt::Debug for FrameSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Files { root, template, .. } => {
                write!(f, "Files({}, {template:?})", root.display())
            }
            Self::Video { reader, crop } => {
                write!(f, "Video({}, {crop:?})", reader.path().display())
            }
            Self::Memory(frames) => write!(f, "Memory({} frames)", frames.len()),
        }
    }
}

/// A video error as the one-line input error the scene reports (the path once).
pub fn video_input_error(e: VideoError) -> InputError {
    let path = e.path().to_path_buf();
    let text = e.to_string();
    let prefix = format!("{}: ", path.display());
    let problem = text.strip_prefix(&prefix).unwrap_or(&text).to_string();
    InputError::new(path, problem)
}

impl FrameSource {
    /// The file of frame `t`, when frames are files.
    pub fn path(&self, t: usize) -> Option<PathBuf> {
        match self {
            Self::Files {
                root,
                template,
                camera,
            } => Some(root.join(template.expand(t, camera, ""))),
            Self::Video { .. } | Self::Memory(_) => None,
        }
    }
}

/// The video readers of one scene, one per file: the two views of a side-by-side video share
/// one decoder.
#[derive(Default)]
pub struct VideoReaders {
    open: Vec<(PathBuf, Arc<VideoReader>)>,
}

impl VideoReaders {
    /// The frame source of `camera` from `path` (cropped), after checking the video against the
    /// camera: its size (or the crop's fit) and that it has the scene's frames.
    pub fn source(
        &mut self,
        path: &Path,
        crop: Option<Crop>,
        camera: &crate::geometry::Camera,
        frame_count: usize,
    ) -> Result<FrameSource, InputError> {
        let reader = match self.open.iter().find(|(p, _)| p == path) {
            Some((_, r)) => r.clone(),
            None => {
                let r = Arc::new(VideoReader::open(path).map_err(video_input_error)?);
                self.open.push((path.to_path_buf(), r.clone()));
                r
            }
        };
        let info = reader.info();
        let (w, h) = (info.width, info.height);
        match crop {
            None if (w, h) != (camera.width, camera.height) => {
                return Err(InputError::new(
                    path,
                    format!(
                        "video is {w}×{h} but camera '{}' is {}×{} (one view of a side-by-side video needs \"crop\")",
                        camera.name, camera.width, camera.height
                    ),
                ));
            }
            Some(c) if c.x + c.width > w || c.y + c.height > h => {
                return Err(InputError::new(
                    path,
                    format!(
                        "camera '{}': crop {}×{} at ({}, {}) does not fit the {w}×{h} video",
                        camera.name, c.width, c.height, c.x, c.y
                    ),
                ));
            }
            _ => {}
        }
        if info.frame_count < frame_count {
            return Err(InputError::new(
                path,
                format!(
                    "video has {} frames but the scene's frame_count is {frame_count}",
                    info.frame_count
                ),
            ));
        }
        Ok(FrameSource::Video { reader, crop })
    }
}

/// A least-recently-used cache of decoded frames, keyed by (camera, frame), bounded in
/// frames and in bytes (the newest frame always stays).
#[derive(Debug)]
pub struct FrameCache {
    capacity: usize,
    capacity_bytes: usize,
    inner: Mutex<CacheInner>,
}

#[derive(Debug, Default)]
struct CacheInner {
    map: HashMap<(usize, usize), Arc<RgbImage>>,
    order: VecDeque<(usize, usize)>,
    bytes: usize,
}

impl FrameCache {
    /// At most `capacity` frames and [`DEFAULT_CACHE_BYTES`].
    pub fn new(capacity: usize) -> Self {
        Self::bounded(capacity, DEFAULT_CACHE_BYTES)
    }

    pub fn bounded(capacity: usize, capacity_bytes: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            capacity_bytes,
            inner: Mutex::new(CacheInner::default()),
        }
    }

    /// Frame `t` of camera `c` from `source`, decoding on a miss. Checks the size.
    pub fn get(
        &self,
        c: usize,
        t: usize,
        source: &FrameSource,
        size: (u32, u32),
    ) -> Result<Arc<RgbImage>, InputError> {
        let path = match source {
            FrameSource::Memory(frames) => {
                return frames
                    .get(t)
                    .cloned()
                    .ok_or_else(|| InputError::new("demo", format!("frame {t} does not exist")));
            }
            FrameSource::Video { reader, crop } => {
                // The reader caches and decodes ahead itself.
                return match crop {
                    None => reader.frame(t),
                    Some(c) => reader.frame_cropped(t, *c).map(Arc::new),
                }
                .map_err(video_input_error);
            }
            FrameSource::Files { .. } => source.path(t).unwrap_or_default(),
        };
        if let Some(img) = self.lock().map.get(&(c, t)).cloned() {
            return Ok(img);
        }
        let img = Arc::new(decode_frame(&path, size)?);
        let mut inner = self.lock();
        if let Some(old) = inner.map.insert((c, t), img.clone()) {
            inner.bytes -= old.as_raw().len();
        }
        inner.bytes += img.as_raw().len();
        inner.order.retain(|k| *k != (c, t));
        inner.order.push_back((c, t));
        while inner.order.len() > 1
            && (inner.order.len() > self.capacity || inner.bytes > self.capacity_bytes)
        {
            if let Some(old) = inner.order.pop_front()
                && let Some(gone) = inner.map.remove(&old)
            {
                inner.bytes -= gone.as_raw().len();
            }
        }
        Ok(img)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        // A panic elsewhere while holding the lock leaves a valid cache: recover it.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn len(&self) -> usize {
        self.lock().map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

fn missing(path: &Path) -> Result<(), InputError> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(()),
        Ok(m) if m.is_dir() => Err(InputError::new(path, "is a folder, not a frame image")),
        Ok(_) => Err(InputError::new(
            path,
            "is not a regular file (a pipe or a device), not a frame image",
        )),
        Err(_) => Err(InputError::new(
            path,
            "missing frame (the camera's frames template names it, and the scene's frame_count includes it)",
        )),
    }
}

/// Decodes a PNG or JPEG frame to RGB and checks its size against the camera's.
pub fn decode_frame(path: &Path, size: (u32, u32)) -> Result<RgbImage, InputError> {
    missing(path)?;
    let img = image::ImageReader::open(path)
        .map_err(|e| InputError::new(path, format!("cannot open frame: {e}")))?
        .with_guessed_format()
        .map_err(|e| InputError::new(path, format!("cannot read frame: {e}")))?
        .decode()
        .map_err(|e| {
            InputError::new(
                path,
                format!("cannot decode frame (truncated or not an image?): {e}"),
            )
        })?;
    if (img.width(), img.height()) != size {
        return Err(InputError::new(
            path,
            format!(
                "frame is {}×{} but the camera is {}×{}",
                img.width(),
                img.height(),
                size.0,
                size.1
            ),
        ));
    }
    Ok(img.into_rgb8())
}

/// Reads only the header: the frame exists, is an image, and has the camera's size.
pub fn check_frame_header(path: &Path, size: (u32, u32)) -> Result<(), InputError> {
    missing(path)?;
    check_image_header(path, size, "frame")
}

/// Reads only the header of an existing image (`what` names it in messages) and checks its
/// size against the camera's.
pub fn check_image_header(path: &Path, size: (u32, u32), what: &str) -> Result<(), InputError> {
    let dims = image::ImageReader::open(path)
        .map_err(|e| InputError::new(path, format!("cannot open {what}: {e}")))?
        .with_guessed_format()
        .map_err(|e| InputError::new(path, format!("cannot read {what}: {e}")))?
        .into_dimensions()
        .map_err(|e| InputError::new(path, format!("not a readable image: {e}")))?;
    if dims != size {
        return Err(InputError::new(
            path,
            format!(
                "{what} is {}×{} but the camera is {}×{}",
                dims.0, dims.1, size.0, size.1
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cache_is_bounded_and_checks_sizes() {
        let dir = std::env::temp_dir().join(format!("endofuse-frames-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for t in 0..5 {
            RgbImage::from_pixel(8, 6, image::Rgb([t as u8, 0, 0]))
                .save(dir.join(format!("{t}.png")))
                .unwrap();
        }
        let src = FrameSource::Files {
            root: dir.clone(),
            template: PathTemplate::parse("{frame}.png").unwrap(),
            camera: "left".into(),
        };
        let cache = FrameCache::new(3);
        for t in 0..5 {
            assert_eq!(
                cache.get(0, t, &src, (8, 6)).unwrap().get_pixel(0, 0).0[0],
                t as u8
            );
        }
        assert_eq!(cache.len(), 3);
        // Bounded in bytes too: 8×6 RGB frames are 144 bytes; 400 bytes hold two.
        let small = FrameCache::bounded(100, 400);
        for t in 0..5 {
            small.get(0, t, &src, (8, 6)).unwrap();
        }
        assert_eq!(small.len(), 2);
        assert_eq!(
            small.get(0, 4, &src, (8, 6)).unwrap().get_pixel(0, 0).0[0],
            4
        );
        let err = cache.get(0, 9, &src, (8, 6)).unwrap_err();
        assert!(err.path.ends_with("9.png"));
        assert!(
            cache
                .get(1, 1, &src, (9, 6))
                .unwrap_err()
                .problem
                .contains("8×6 but the camera is 9×6")
        );
        std::fs::write(dir.join("bad.png"), b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR").unwrap();
        assert!(decode_frame(&dir.join("bad.png"), (8, 6)).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
