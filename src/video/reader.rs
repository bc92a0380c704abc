//! [`VideoReader`]: frames of one video file on request, from any thread. It keeps one ffmpeg
//! running with its position (a request for the frame it is at is a pipe read; one a little
//! ahead reads forward; anything else restarts it at the frame), a byte-bounded cache, and a
//! decode-ahead thread ([`super::ahead`]) that fills the next frames and the few before the
//! last one asked for, yielding to every new request.

use super::ahead;
use super::cache::FrameCache;
use super::probe;
use super::stream::{KillSwitch, Source, Stream};
use super::tools::{self, Tools};
use super::{Crop, VideoError, VideoInfo};
use image::RgbImage;
use std::path::Path;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;

/// The cache bound unless [`VideoReader::with_cache_bytes`] sets another: ~40 1080p frames.
pub const DEFAULT_CACHE_BYTES: usize = 256 << 20;

/// How far ahead of a decoder's position a frame may be and still be reached by reading
/// forward rather than by restarting: at 1080p a read costs ~6 ms and a restart ~130–180 ms
/// with a keyframe every second (more with longer GOPs), so reading 24 frames is about even.
const FORWARD_REACH: usize = 24;
/// Frames decoded ahead of the last one asked for, at most (fewer if the cache is small).
const AHEAD: usize = 12;
/// Frames kept or filled before the last one asked for, so that a step back is a cache hit.
const BACK: usize = 3;

/// A shared, thread-safe reader of one video file with a bounded cache. Frame `i` is the
/// `i`-th decoded frame in presentation order, the same pixels however it is reached.
///
/// ```no_run
/// # fn main() -> Result<(), endofuse::video::VideoError> {
/// use endofuse::video::{Crop, VideoReader};
/// let video = VideoReader::open("case.mp4".as_ref())?;
/// let (left, right) = Crop::side_by_side(video.info().width, video.info().height);
/// let l = video.frame_cropped(10, left)?;
/// let r = video.frame_cropped(10, right)?;
/// # Ok(()) }
/// ```
pub struct VideoReader {
    shared: Arc<Shared>,
    ahead: Option<JoinHandle<()>>,
}

/// What the reader and its decode-ahead thread share.
pub(crate) struct Shared {
    pub source: Source,
    /// The decoder requests use (the decode-ahead reads on from it between requests).
    pub main: Mutex<Option<Stream>>,
    pub cache: Mutex<FrameCache>,
    pub plan: Mutex<Plan>,
    /// Signalled when the plan changes.
    pub wake: Condvar,
    /// The decode-ahead's own decoder while it has one, so that a request can stop it.
    pub helper: Mutex<Option<KillSwitch>>,
}

/// What the decode-ahead should work around, and whether it may.
#[derive(Default)]
pub(crate) struct Plan {
    /// The frame last asked for.
    pub anchor: Option<usize>,
    /// Bumped whenever the anchor moves or the cache bound changes.
    pub generation: u64,
    /// Requests decoding now: the decode-ahead waits until none is.
    pub requests: usize,
    /// The generation the decode-ahead has done (or given up on).
    pub rested: Option<u64>,
    pub shutdown: bool,
}

/// Locks, taking over a mutex that a panicking thread left: every value behind these locks
/// stays consistent between statements.
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl Shared {
    /// How many frames after and before the anchor the decode-ahead keeps cached: as many as
    /// fit beside the anchor, so filling never evicts what it just filled.
    pub(crate) fn reach(&self) -> (usize, usize) {
        let fits = lock(&self.cache).limit() / self.source.frame_bytes().max(1);
        let room = fits.saturating_sub(1);
        let ahead = AHEAD.min(room - room / 4);
        (ahead, BACK.min(room - ahead))
    }

    /// Whether `stream` gets to frame `index` by reading forward at least as cheaply as a
    /// restart would: within [`FORWARD_REACH`] frames, twice that inside `index`'s GOP (a
    /// restart would decode those frames too, only without converting them), any distance
    /// where a restart would start no later (counted streams).
    pub(crate) fn can_reach(&self, stream: &Stream, index: usize) -> bool {
        let at = stream.next();
        if at > index {
            return false;
        }
        let timeline = &self.source.timeline;
        let reach = match at >= timeline.keyframe_before(index) {
            true => 2 * FORWARD_REACH,
            false => FORWARD_REACH,
        };
        index - at <= reach || at >= timeline.start_for(index).first
    }

    /// Moves the anchor to `index`, waking the decode-ahead if it moved.
    fn point_at(&self, index: usize) {
        let mut plan = lock(&self.plan);
        if plan.anchor != Some(index) {
            plan.anchor = Some(index);
            plan.generation += 1;
            self.wake.notify_all();
        }
    }

    /// Frame `index` from the decoder in `slot`, restarting it unless it can reach the frame.
    /// Frames read on the way are cached from `BACK` before `index`.
    fn decode(&self, slot: &mut Option<Stream>, index: usize) -> Result<Arc<RgbImage>, VideoError> {
        let stream = match slot.take() {
            Some(s) if self.can_reach(&s, index) => s,
            old => {
                drop(old); // stop the old child before starting another
                self.source.spawn(index)?
            }
        };
        let seeked = stream.seeked();
        let e = match self.read_to(stream, index) {
            Ok((img, stream)) => {
                *slot = Some(stream);
                return Ok(img);
            }
            Err(e) if !seeked => return Err(stopped_before(e, index)),
            Err(e) => e,
        };
        // FFmpeg can lose frames after a seek (measured with 5.1: the last frames of a file
        // whose last GOP is open). One more try, decoding through from the GOP before.
        log::debug!(
            "{}: retrying frame {index} after: {e}",
            self.source.path.display()
        );
        let stream = self
            .source
            .spawn_at(self.source.timeline.start_gop_before(index))?;
        let (img, stream) = self
            .read_to(stream, index)
            .map_err(|e| stopped_before(e, index))?;
        *slot = Some(stream);
        Ok(img)
    }

    /// Reads `stream` on to frame `index` (the stream must be at or before it).
    fn read_to(
        &self,
        mut stream: Stream,
        index: usize,
    ) -> Result<(Arc<RgbImage>, Stream), VideoError> {
        let keep_from = index.saturating_sub(self.reach().1);
        let mut spare = None;
        loop {
            let at = stream.next();
            let buf = match spare.take() {
                Some(buf) => buf,
                None => lock(&self.cache).buffer(self.source.frame_bytes()),
            };
            let img = stream.read(buf)?;
            if at >= index {
                let img = Arc::new(img);
                lock(&self.cache).insert(at, img.clone());
                return Ok((img, stream));
            }
            if at >= keep_from {
                lock(&self.cache).insert(at, Arc::new(img));
            } else {
                spare = Some(img.into_raw()); // passed over: its memory serves the next
            }
        }
    }

    /// The next frame of `stream` into the cache (the decode-ahead's step).
    pub(crate) fn read_into_cache(&self, stream: &mut Stream) -> Result<(), VideoError> {
        let at = stream.next();
        let buf = lock(&self.cache).buffer(self.source.frame_bytes());
        let img = stream.read(buf)?;
        lock(&self.cache).insert(at, Arc::new(img));
        Ok(())
    }
}

/// Whether seeking to keyframes lands where a counted stream (AVI) expects: the first frame
/// out after a seek to the second keyframe is the one a decode from the start gives there.
/// Not so for open GOPs (a keyframe's leading frames come after it in decode order), where
/// only decoding from the start gives the right indices. One GOP speaks for the file.
fn keyframe_seeks_land(source: &Source) -> Result<bool, VideoError> {
    let Some(key) = source.timeline.second_keyframe() else {
        return Ok(true);
    };
    let mut from_start = source.spawn(0)?;
    let mut expected = from_start.read(Vec::new())?;
    while from_start.next() <= key {
        expected = from_start.read(expected.into_raw())?;
    }
    drop(from_start);
    let mut sought = source.spawn(key)?;
    if sought.next() != key {
        return Ok(true); // not a seek: nothing to check
    }
    Ok(sought.read(Vec::new())? == expected)
}

/// The error for frame `index` when the decoder failed on the way, at an earlier frame.
fn stopped_before(e: VideoError, index: usize) -> VideoError {
    match e {
        VideoError::Decode {
            path,
            index: at,
            message,
        } if at != index => VideoError::Decode {
            path,
            index,
            message: format!("the decoder stopped at frame {at}: {message}"),
        },
        e => e,
    }
}

/// A request in flight: the decode-ahead stays out of the way until it ends.
struct Request<'a>(&'a Shared);

impl<'a> Request<'a> {
    fn begin(shared: &'a Shared, index: usize) -> Request<'a> {
        lock(&shared.plan).requests += 1;
        shared.point_at(index);
        // Whatever the decode-ahead's own decoder is doing was for the old anchor.
        if let Some(helper) = lock(&shared.helper).take() {
            helper.kill();
        }
        Request(shared)
    }
}

impl Drop for Request<'_> {
    fn drop(&mut self) {
        let mut plan = lock(&self.0.plan);
        plan.requests = plan.requests.saturating_sub(1);
        self.0.wake.notify_all();
    }
}

impl VideoReader {
    /// Opens `path` with the FFmpeg programs [`Tools::from_env`] names: probes it and
    /// decodes frame 0, so a file that cannot be read fails here.
    pub fn open(path: &Path) -> Result<VideoReader, VideoError> {
        Self::open_with(path, &Tools::from_env())
    }

    /// [`VideoReader::open`] with the FFmpeg programs at the given paths.
    pub fn open_with(path: &Path, tools: &Tools) -> Result<VideoReader, VideoError> {
        let probed = probe::probe(path, tools)?;
        let passthrough = tools::passthrough_option(&tools.ffmpeg, path)?;
        let mut source = Source {
            path: path.to_path_buf(),
            ffmpeg: tools.ffmpeg.clone(),
            passthrough,
            info: probed.info,
            timeline: probed.timeline,
        };
        if probed.reorders && source.timeline.counts_frames() && !keyframe_seeks_land(&source)? {
            log::warn!(
                "{}: seeking lands off the keyframes (open GOPs without timestamps): every \
                 seek decodes from the start",
                path.display()
            );
            source.timeline.decode_from_start_only();
        }
        let shared = Arc::new(Shared {
            source,
            main: Mutex::new(None),
            cache: Mutex::new(FrameCache::new(DEFAULT_CACHE_BYTES)),
            plan: Mutex::new(Plan::default()),
            wake: Condvar::new(),
            helper: Mutex::new(None),
        });
        let worker = shared.clone();
        let ahead = std::thread::Builder::new()
            .name("video-decode-ahead".into())
            .spawn(move || ahead::run(&worker));
        let ahead = match ahead {
            Ok(handle) => Some(handle),
            Err(e) => {
                log::warn!("{}: no decode-ahead ({e})", path.display());
                None
            }
        };
        let reader = VideoReader { shared, ahead };
        reader.frame(0)?;
        Ok(reader)
    }

    /// Sets the cache bound in bytes (default [`DEFAULT_CACHE_BYTES`]); the decode-ahead
    /// fills only what fits.
    pub fn with_cache_bytes(self, bytes: usize) -> Self {
        lock(&self.shared.cache).set_limit(bytes);
        let mut plan = lock(&self.shared.plan);
        plan.generation += 1;
        self.shared.wake.notify_all();
        drop(plan);
        self
    }

    pub fn info(&self) -> &VideoInfo {
        &self.shared.source.info
    }

    pub fn path(&self) -> &Path {
        &self.shared.source.path
    }

    /// Frame `index`'s presentation time in seconds (frame 0's is [`VideoInfo::start_time`]).
    pub fn timestamp(&self, index: usize) -> Option<f64> {
        self.shared.source.timeline.time(index)
    }

    /// Frame `index`, whole.
    pub fn frame(&self, index: usize) -> Result<Arc<RgbImage>, VideoError> {
        let shared = &*self.shared;
        let count = shared.source.info.frame_count;
        if index >= count {
            return Err(VideoError::OutOfRange {
                path: shared.source.path.clone(),
                index,
                count,
            });
        }
        let hit = lock(&shared.cache).get(index);
        if let Some(img) = hit {
            shared.point_at(index);
            return Ok(img);
        }
        let _request = Request::begin(shared, index);
        let mut main = lock(&shared.main);
        // The decode-ahead may have read it while this request waited for the decoder.
        let hit = lock(&shared.cache).get(index);
        if let Some(img) = hit {
            return Ok(img);
        }
        shared.decode(&mut main, index)
    }

    /// The `crop` rectangle of frame `index`: one view of a side-by-side stereo video.
    pub fn frame_cropped(&self, index: usize, crop: Crop) -> Result<RgbImage, VideoError> {
        let (width, height) = (self.info().width, self.info().height);
        let fits = crop.width > 0
            && crop.height > 0
            && crop.x.checked_add(crop.width).is_some_and(|r| r <= width)
            && crop.y.checked_add(crop.height).is_some_and(|b| b <= height);
        if !fits {
            return Err(VideoError::BadCrop {
                path: self.path().to_path_buf(),
                crop,
                width,
                height,
            });
        }
        let full = self.frame(index)?;
        Ok(image::imageops::crop_imm(&*full, crop.x, crop.y, crop.width, crop.height).to_image())
    }

    /// Bytes of decoded frames the cache holds now (never more than its bound).
    pub fn cached_bytes(&self) -> usize {
        lock(&self.shared.cache).bytes()
    }

    /// Whether frame `index` is cached now (what a timeline can show as ready).
    pub fn is_cached(&self, index: usize) -> bool {
        lock(&self.shared.cache).contains(index)
    }
}

impl std::fmt::Debug for VideoReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VideoReader")
            .field("path", &self.shared.source.path)
            .field("info", &self.shared.source.info)
            .finish_non_exhaustive()
    }
}

impl Drop for VideoReader {
    fn drop(&mut self) {
        lock(&self.shared.plan).shutdown = true;
        self.shared.wake.notify_all();
        if let Some(helper) = lock(&self.shared.helper).take() {
            helper.kill();
        }
        if let Some(handle) = self.ahead.take() {
            let _ = handle.join();
        }
        // The main decoder goes with `shared`, killed and reaped by its drop.
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readers_can_be_shared_between_threads() {
        fn shareable<T: Send + Sync>() {}
        shareable::<VideoReader>();
    }
}
