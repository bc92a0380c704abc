//! Decoded frames kept for reuse, least recently used out first, bounded in bytes (a 1080p RGB
//! frame is 6.2 MB: the default 256 MB holds about 40). A frame larger than the bound is not
//! kept at all, so the bound holds for any size.

use image::RgbImage;
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

pub(crate) struct FrameCache {
    limit: usize,
    bytes: usize,
    clock: u64,
    /// Frame index → (frame, last use).
    frames: HashMap<usize, (Arc<RgbImage>, u64)>,
    /// Last use → frame index: the oldest first.
    by_use: BTreeMap<u64, usize>,
}

fn size(img: &RgbImage) -> usize {
    img.as_raw().len()
}

impl FrameCache {
    pub(crate) fn new(limit: usize) -> FrameCache {
        FrameCache {
            limit,
            bytes: 0,
            clock: 0,
            frames: HashMap::new(),
            by_use: BTreeMap::new(),
        }
    }

    pub(crate) fn limit(&self) -> usize {
        self.limit
    }

    /// Bytes of pixels held.
    pub(crate) fn bytes(&self) -> usize {
        self.bytes
    }

    pub(crate) fn contains(&self, index: usize) -> bool {
        self.frames.contains_key(&index)
    }

    /// Frame `index`, now the most recently used.
    pub(crate) fn get(&mut self, index: usize) -> Option<Arc<RgbImage>> {
        self.clock += 1;
        let (img, used) = self.frames.get_mut(&index)?;
        self.by_use.remove(used);
        *used = self.clock;
        self.by_use.insert(self.clock, index);
        Some(img.clone())
    }

    pub(crate) fn insert(&mut self, index: usize, img: Arc<RgbImage>) {
        self.remove(index);
        let bytes = size(&img);
        if bytes > self.limit {
            return;
        }
        self.shrink_to(self.limit - bytes);
        self.clock += 1;
        self.by_use.insert(self.clock, index);
        self.frames.insert(index, (img, self.clock));
        self.bytes += bytes;
    }

    /// Memory for the next frame of `bytes`: where inserting it would evict the least recently
    /// used frame, that frame goes now and its pixels' memory is reused (unless a caller still
    /// holds it). Keeps the process's memory at the bound rather than the bound plus what the
    /// allocator keeps of freed frames.
    pub(crate) fn buffer(&mut self, bytes: usize) -> Vec<u8> {
        if bytes <= self.limit
            && self.bytes + bytes > self.limit
            && let Some((_, index)) = self.by_use.pop_first()
            && let Some((img, _)) = self.frames.remove(&index)
        {
            self.bytes -= size(&img);
            if let Ok(img) = Arc::try_unwrap(img) {
                return img.into_raw();
            }
        }
        Vec::with_capacity(bytes)
    }

    pub(crate) fn set_limit(&mut self, limit: usize) {
        self.limit = limit;
        self.shrink_to(limit);
    }

    fn remove(&mut self, index: usize) {
        if let Some((img, used)) = self.frames.remove(&index) {
            self.by_use.remove(&used);
            self.bytes -= size(&img);
        }
    }

    fn shrink_to(&mut self, bytes: usize) {
        while self.bytes > bytes {
            let Some((_, index)) = self.by_use.pop_first() else {
                break;
            };
            if let Some((img, _)) = self.frames.remove(&index) {
                self.bytes -= size(&img);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(v: u8) -> Arc<RgbImage> {
        Arc::new(RgbImage::from_pixel(10, 10, image::Rgb([v, v, v])))
    }

    #[test]
    fn least_recently_used_goes_first_and_the_bound_holds() {
        let mut c = FrameCache::new(3 * 300);
        for i in 0..3 {
            c.insert(i, frame(i as u8));
        }
        assert_eq!(c.bytes(), 900);
        assert!(c.get(0).is_some()); // 1 is now the oldest
        c.insert(3, frame(3));
        assert!(c.contains(0) && !c.contains(1) && c.contains(2) && c.contains(3));
        assert_eq!(c.bytes(), 900);
        c.insert(3, frame(9)); // replacing counts once
        assert_eq!(c.bytes(), 900);
        assert_eq!(c.get(3).unwrap().get_pixel(0, 0).0, [9, 9, 9]);
        c.set_limit(400);
        assert_eq!(c.bytes(), 300);
        assert!(c.contains(3));
    }

    #[test]
    fn a_full_cache_lends_its_oldest_frame_for_the_next() {
        let mut c = FrameCache::new(2 * 300);
        c.insert(0, frame(0));
        assert_eq!(c.buffer(300).capacity(), 300); // room left: a new buffer
        assert!(c.contains(0));
        c.insert(1, frame(1));
        let held = c.get(0).unwrap(); // 1 is now the oldest
        let buf = c.buffer(300);
        assert!(!c.contains(1) && c.contains(0));
        assert_eq!((buf.len(), c.bytes()), (300, 300));
        c.insert(2, frame(2));
        drop(held);
        // The oldest (0) is still held by nobody now: its memory is reused.
        let _ = c.get(2);
        assert_eq!(c.buffer(300).len(), 300);
        assert!(!c.contains(0));
    }

    #[test]
    fn a_frame_larger_than_the_bound_is_not_kept() {
        let mut c = FrameCache::new(299);
        c.insert(0, frame(0));
        assert_eq!(c.bytes(), 0);
        assert!(c.get(0).is_none());
    }
}
