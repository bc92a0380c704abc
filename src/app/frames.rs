//! Decodes video frames off the UI thread. Scrubbing or playing a scene on disk asks for a
//! frame per view; a PNG of 960×540 takes tens of milliseconds to decode, which the window
//! must not wait for. The loader keeps only the newest request per view (older ones are
//! skipped when the user scrubs faster than frames decode) and hands decoded frames back
//! through a channel drained each UI frame.

use crate::scene::Scene;
use crossbeam_channel::{Receiver, Sender, unbounded};
use image::RgbImage;
use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex};

/// A decoded frame, or why it could not be.
pub struct Loaded {
    pub camera: usize,
    pub frame: usize,
    pub image: Result<Arc<RgbImage>, crate::error::InputError>,
}

struct Shared {
    /// Newest wanted frame per camera, and the scene it belongs to.
    wanted: HashMap<usize, (Arc<Scene>, usize)>,
    stop: bool,
}

pub struct FrameLoader {
    shared: Arc<(Mutex<Shared>, Condvar)>,
    done: Receiver<Loaded>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Default for FrameLoader {
    fn default() -> Self {
        Self::spawn()
    }
}

impl FrameLoader {
    pub fn spawn() -> Self {
        let shared = Arc::new((
            Mutex::new(Shared {
                wanted: HashMap::new(),
                stop: false,
            }),
            Condvar::new(),
        ));
        let (tx, done): (Sender<Loaded>, Receiver<Loaded>) = unbounded();
        let s = shared.clone();
        let thread = std::thread::Builder::new()
            .name("endofuse-frames".into())
            .spawn(move || {
                loop {
                    let job = {
                        let (lock, cv) = &*s;
                        let Ok(mut g) = lock.lock() else { return };
                        loop {
                            if g.stop {
                                return;
                            }
                            if let Some(&c) = g.wanted.keys().min() {
                                break g.wanted.remove(&c).map(|(scene, t)| (c, scene, t));
                            }
                            g = match cv.wait(g) {
                                Ok(g) => g,
                                Err(_) => return,
                            };
                        }
                    };
                    if let Some((camera, scene, frame)) = job {
                        let image = scene.frame(camera, frame);
                        if tx
                            .send(Loaded {
                                camera,
                                frame,
                                image,
                            })
                            .is_err()
                        {
                            return;
                        }
                    }
                }
            })
            .map_err(|e| log::error!("cannot start the frame loader thread: {e}"))
            .ok();
        Self {
            shared,
            done,
            thread,
        }
    }

    /// Whether the decoding thread runs (it may fail to start).
    pub fn running(&self) -> bool {
        self.thread.is_some()
    }

    /// Asks for frame `frame` of `camera` (replacing an older request for that camera).
    pub fn request(&self, scene: &Arc<Scene>, camera: usize, frame: usize) {
        let (lock, cv) = &*self.shared;
        if let Ok(mut g) = lock.lock() {
            g.wanted.insert(camera, (scene.clone(), frame));
            cv.notify_one();
        }
    }

    /// Frames decoded since the last call.
    pub fn drain(&self) -> Vec<Loaded> {
        self.done.try_iter().collect()
    }
}

impl Drop for FrameLoader {
    fn drop(&mut self) {
        let (lock, cv) = &*self.shared;
        if let Ok(mut g) = lock.lock() {
            g.stop = true;
            cv.notify_all();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    #[test]
    fn frames_arrive_from_the_loader_thread_and_bad_ones_say_why() {
        let scene = Arc::new(
            crate::synth::memory_scene(&crate::synth::SynthOptions {
                frames: 3,
                width: 64,
                height: 36,
                ..crate::synth::SynthOptions::default()
            })
            .unwrap(),
        );
        let loader = FrameLoader::spawn();
        loader.request(&scene, 1, 2);
        loader.request(&scene, 0, 7);
        let mut got = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(20);
        while got.len() < 2 && Instant::now() < deadline {
            got.extend(loader.drain());
            std::thread::sleep(Duration::from_millis(5));
        }
        got.sort_by_key(|l| l.camera);
        assert_eq!(got.len(), 2);
        assert!(got[0].image.is_err(), "frame 7 does not exist");
        assert_eq!(got[1].image.as_ref().unwrap().width(), 64);
    }
}
