//! Which frames a video stream has and where a decoder must start to produce frame `i`. Built
//! from ffprobe's packet list (read without decoding): frame `i`'s time is the `i`-th smallest
//! presentation timestamp. To start at frame `i`, ffmpeg is asked to seek to the point halfway
//! between frames `i − 1` and `i`: it decodes from the keyframe before that point and drops
//! what comes earlier, and half a frame of margin means no rounding can return a neighbour.
//!
//! Streams whose packets carry no presentation times (AVI) cannot be trimmed by time: there
//! frames are counted from the keyframe ffmpeg lands on, whose index the table knows (for a
//! closed GOP, as AVI's codecs write, decode order up to a keyframe is display order).

/// One packet of the video stream as ffprobe lists it, in decode order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Packet {
    pub pts: Option<i64>,
    pub dts: Option<i64>,
    pub key: bool,
    /// Decoded only to feed later frames, never shown (an edit list starts after it).
    pub discard: bool,
}

/// How the decoder's output is matched to frame indices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Indexing {
    /// ffmpeg trims by timestamp: the first frame out after a seek is the one asked for.
    ByTime,
    /// Frames are counted from a keyframe whose index is known (decode order is display
    /// order there for a closed GOP).
    ByCount,
}

/// Where to start ffmpeg for a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Start {
    /// `-ss` before `-i`, in seconds after the file's start time; `None`: from the beginning.
    pub seek: Option<f64>,
    /// Whether ffmpeg drops the frames before `seek` (its "accurate seek").
    pub accurate: bool,
    /// The index of the first frame ffmpeg will output.
    pub first: usize,
}

/// The frame table: 8 bytes per frame plus one index per keyframe.
#[derive(Clone, Debug)]
pub(crate) struct Timeline {
    /// Presentation time of each frame in seconds, ascending.
    times: Vec<f64>,
    /// Indices of the frames a decoder can start at, ascending.
    keyframes: Vec<usize>,
    /// The container's start time, from which ffmpeg counts `-ss`.
    origin: f64,
    indexing: Indexing,
    /// Whether a decoder may start at a keyframe other than the first (see
    /// [`Timeline::decode_from_start_only`]).
    seekable: bool,
}

impl Timeline {
    /// The table of `packets` (decode order) with timestamps in units of `time_base` seconds.
    /// Packets before the first keyframe, and frames shown before it, are left out: no decoder
    /// can produce them. `count`: index by counting from keyframes even where packets have
    /// presentation times (AVI, see below).
    pub(crate) fn from_packets(
        packets: &[Packet],
        time_base: f64,
        origin: f64,
        count: bool,
    ) -> Result<Timeline, String> {
        let shown: Vec<&Packet> = packets
            .iter()
            .skip_while(|p| !p.key)
            .filter(|p| !p.discard)
            .collect();
        if shown.is_empty() {
            return Err("the video stream has no keyframe".into());
        }
        if !count && shown.iter().all(|p| p.pts.is_some()) {
            let mut pts: Vec<(i64, bool)> =
                shown.iter().filter_map(|p| Some((p.pts?, p.key))).collect();
            let first_key = pts[0].0;
            pts.retain(|&(t, _)| t >= first_key);
            pts.sort_unstable();
            // Two frames at one time could not be told apart by seeking.
            if pts.windows(2).all(|w| w[0].0 < w[1].0) {
                return Ok(Self::table(&pts, time_base, origin, Indexing::ByTime));
            }
        }
        // AVI (decode times only, or presentation times copied from them): ffmpeg's accurate
        // seek mislabels the frame it lands on there (measured with FFmpeg 5.1: a seek between
        // frames 2 and 3 of an intra-only AVI returns frame 2), so frames are counted from the
        // keyframe it lands on instead.
        if shown.iter().all(|p| p.dts.is_some()) {
            let dts: Vec<(i64, bool)> =
                shown.iter().filter_map(|p| Some((p.dts?, p.key))).collect();
            if dts.windows(2).all(|w| w[0].0 < w[1].0) {
                return Ok(Self::table(&dts, time_base, origin, Indexing::ByCount));
            }
            return Err("the packets' decode times do not increase".into());
        }
        Err("the packets carry no presentation times".into())
    }

    fn table(stamps: &[(i64, bool)], time_base: f64, origin: f64, indexing: Indexing) -> Timeline {
        Timeline {
            times: stamps.iter().map(|&(t, _)| t as f64 * time_base).collect(),
            keyframes: (0..stamps.len()).filter(|&i| stamps[i].1).collect(),
            origin,
            indexing,
            seekable: true,
        }
    }

    /// Whether frames are counted from keyframes rather than trimmed by time.
    pub(crate) fn counts_frames(&self) -> bool {
        self.indexing == Indexing::ByCount
    }

    /// The keyframe after the first, if any: where a counted stream's seeking is checked.
    pub(crate) fn second_keyframe(&self) -> Option<usize> {
        self.keyframes.get(1).copied()
    }

    /// Every decode from the first frame on: for counted streams with open GOPs, whose
    /// keyframes are not the first frame out after a seek.
    pub(crate) fn decode_from_start_only(&mut self) {
        self.seekable = false;
    }

    pub(crate) fn len(&self) -> usize {
        self.times.len()
    }

    /// Frame `i`'s presentation time in seconds.
    pub(crate) fn time(&self, i: usize) -> Option<f64> {
        self.times.get(i).copied()
    }

    /// The frame interval, from the table's ends (1/25 s for a single frame).
    pub(crate) fn mean_interval(&self) -> f64 {
        match (self.times.first(), self.times.last()) {
            (Some(a), Some(b)) if self.times.len() > 1 && b > a => {
                (b - a) / (self.times.len() - 1) as f64
            }
            _ => 0.04,
        }
    }

    /// The last keyframe at or before frame `i`.
    pub(crate) fn keyframe_before(&self, i: usize) -> usize {
        match self.keyframes.binary_search(&i) {
            Ok(k) => self.keyframes[k],
            Err(0) => 0,
            Err(k) => self.keyframes[k - 1],
        }
    }

    /// Where ffmpeg must start so that its output reaches frame `i` (`i < len`).
    pub(crate) fn start_for(&self, i: usize) -> Start {
        match self.indexing {
            Indexing::ByTime => {
                let at = match i {
                    0 => self.times[0] - self.gap_after(0) / 2.0,
                    _ => (self.times[i - 1] + self.times[i]) / 2.0,
                };
                let seek = at - self.origin;
                Start {
                    seek: (seek > 0.0).then_some(seek),
                    accurate: true,
                    first: i,
                }
            }
            Indexing::ByCount => {
                let key = self.keyframe_before(i);
                if key == 0 || !self.seekable {
                    return Start {
                        seek: None,
                        accurate: false,
                        first: 0,
                    };
                }
                // Mid-way to the next keyframe: ffmpeg lands on `key` even where it first
                // backs off a little for streams that reorder (its dts heuristic, ~0.13 s).
                let next = self
                    .keyframes
                    .iter()
                    .find(|&&k| k > key)
                    .and_then(|&k| self.time(k))
                    .unwrap_or(self.times[self.times.len() - 1] + self.mean_interval());
                Start {
                    seek: Some((self.times[key] + next) / 2.0 - self.origin),
                    accurate: false,
                    first: key,
                }
            }
        }
    }

    /// Where to start for frame `i` from the GOP before its own: the second try after a decoder
    /// started at `i` lost frames (ffmpeg does, seeking into the last open GOP of a file).
    pub(crate) fn start_gop_before(&self, i: usize) -> Start {
        let key = self.keyframe_before(i);
        let earlier = match key {
            0 => 0,
            k => self.keyframe_before(k - 1),
        };
        self.start_for(earlier)
    }

    fn gap_after(&self, i: usize) -> f64 {
        match (self.time(i), self.time(i + 1)) {
            (Some(a), Some(b)) => b - a,
            _ => self.mean_interval(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packet(pts: Option<i64>, dts: Option<i64>, key: bool) -> Packet {
        Packet {
            pts,
            dts,
            key,
            discard: false,
        }
    }

    /// x264's decode order for I P B B …: presentation times 0 3 1 2 6 4 5 at 1/3 s.
    fn b_frame_packets() -> Vec<Packet> {
        [
            (0, true),
            (3, false),
            (1, false),
            (2, false),
            (6, true),
            (4, false),
            (5, false),
        ]
        .iter()
        .enumerate()
        .map(|(d, &(p, k))| packet(Some(p), Some(d as i64 - 1), k))
        .collect()
    }

    #[test]
    fn b_frames_sorted_to_presentation_order() {
        let t = Timeline::from_packets(&b_frame_packets(), 1.0 / 3.0, 0.0, false).unwrap();
        assert_eq!(t.len(), 7);
        for i in 0..7 {
            assert!((t.time(i).unwrap() - i as f64 / 3.0).abs() < 1e-12);
        }
        assert_eq!(t.keyframes, vec![0, 6]);
        assert_eq!(t.indexing, Indexing::ByTime);
    }

    #[test]
    fn seeks_halfway_between_neighbours_from_the_file_start() {
        // Video starting at 2 s, container start 1.5 s (audio begins first).
        let packets: Vec<Packet> = (0..10)
            .map(|i| packet(Some(60 + 3 * i), Some(60 + 3 * i), i % 5 == 0))
            .collect();
        let t = Timeline::from_packets(&packets, 1.0 / 30.0, 1.5, false).unwrap();
        assert!((t.time(0).unwrap() - 2.0).abs() < 1e-12);
        let s = t.start_for(4);
        assert_eq!(s.first, 4);
        assert!(s.accurate);
        // Frames 3 and 4 at 2.3 and 2.4 s: seek to 2.35 s, 0.85 s after the start.
        assert!((s.seek.unwrap() - 0.85).abs() < 1e-9, "{s:?}");
        // Frame 0 is half a frame before 2 s, after the container's start: still a seek.
        assert!((t.start_for(0).seek.unwrap() - 0.45).abs() < 1e-9);
        let t = Timeline::from_packets(&packets, 1.0 / 30.0, 2.0, false).unwrap();
        assert_eq!(t.start_for(0).seek, None);
    }

    #[test]
    fn frames_before_the_first_keyframe_and_discarded_ones_are_left_out() {
        let mut packets = b_frame_packets();
        packets.insert(0, packet(Some(-1), Some(-3), false));
        packets[2].discard = true; // pts 3
        let t = Timeline::from_packets(&packets, 1.0, 0.0, false).unwrap();
        let times: Vec<f64> = (0..t.len()).map(|i| t.time(i).unwrap()).collect();
        assert_eq!(times, vec![0.0, 1.0, 2.0, 4.0, 5.0, 6.0]);
        assert_eq!(t.keyframes, vec![0, 5]);
    }

    #[test]
    fn open_gop_leading_frames_of_the_first_keyframe_are_left_out() {
        // The first keyframe at 2, then frames 0 and 1 that need a previous GOP.
        let packets = [
            packet(Some(2), Some(0), true),
            packet(Some(0), Some(1), false),
            packet(Some(1), Some(2), false),
            packet(Some(3), Some(3), false),
        ];
        let t = Timeline::from_packets(&packets, 1.0, 0.0, false).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t.time(0), Some(2.0));
        // Frame 0 must not come out as the dropped frame 1: seek between 1.5 and 2.
        assert_eq!(t.start_for(0).seek, Some(1.5));
    }

    #[test]
    fn without_presentation_times_frames_are_counted_from_keyframes() {
        // AVI: dts only, keyframes every 10.
        let packets: Vec<Packet> = (0..30)
            .map(|i| packet(None, Some(i), i % 10 == 0))
            .collect();
        let mut t = Timeline::from_packets(&packets, 0.2, 0.0, false).unwrap();
        assert_eq!(t.indexing, Indexing::ByCount);
        let s = t.start_for(17);
        assert_eq!(s.first, 10);
        assert!(!s.accurate);
        assert!((s.seek.unwrap() - 3.0).abs() < 1e-9, "{s:?}");
        assert_eq!(t.start_for(9).seek, None);
        assert_eq!(t.start_for(9).first, 0);
        // The last GOP: mid-way to the end of the stream.
        assert!((t.start_for(29).seek.unwrap() - 5.0).abs() < 1e-9);
        assert_eq!(t.start_for(29).first, 20);
        assert_eq!(t.start_gop_before(29).first, 10);
        assert_eq!(t.start_gop_before(5).first, 0);
        t.decode_from_start_only();
        assert_eq!(t.start_for(29).seek, None);
        assert_eq!(t.start_for(29).first, 0);
        // AVI with presentation times: counted all the same.
        let packets: Vec<Packet> = (0..30)
            .map(|i| packet(Some(i), Some(i), i % 10 == 0))
            .collect();
        let t = Timeline::from_packets(&packets, 0.2, 0.0, true).unwrap();
        assert!(t.counts_frames());
        assert_eq!(t.second_keyframe(), Some(10));
        assert!(
            !Timeline::from_packets(&packets, 0.2, 0.0, false)
                .unwrap()
                .counts_frames()
        );
    }

    #[test]
    fn unusable_tables_are_refused() {
        assert!(Timeline::from_packets(&[], 1.0, 0.0, false).is_err());
        let no_key = [packet(Some(0), Some(0), false)];
        assert!(Timeline::from_packets(&no_key, 1.0, 0.0, false).is_err());
        let none = [packet(None, None, true), packet(None, None, false)];
        assert!(Timeline::from_packets(&none, 1.0, 0.0, false).is_err());
        // Equal presentation times: counted by decode time where those increase, else refused.
        let same = [
            packet(Some(0), Some(0), true),
            packet(Some(0), Some(1), false),
        ];
        let t = Timeline::from_packets(&same, 1.0, 0.0, false).unwrap();
        assert_eq!(t.indexing, Indexing::ByCount);
        let same = [
            packet(Some(0), Some(0), true),
            packet(Some(0), Some(0), false),
        ];
        assert!(Timeline::from_packets(&same, 1.0, 0.0, false).is_err());
    }

    #[test]
    fn keyframe_before() {
        let packets: Vec<Packet> = (0..30)
            .map(|i| packet(Some(i), Some(i), i % 10 == 0))
            .collect();
        let t = Timeline::from_packets(&packets, 1.0, 0.0, false).unwrap();
        assert_eq!(t.keyframe_before(0), 0);
        assert_eq!(t.keyframe_before(9), 0);
        assert_eq!(t.keyframe_before(10), 10);
        assert_eq!(t.keyframe_before(29), 20);
    }
}
