//! Benchmark: how fast the worker answers Cancel while it tracks (the app's promise: within
//! 100 ms). Tracks the built-in demo phantom in the worker, cancels at random moments, and
//! reports the delay until the `Cancelled` event.
//!
//!     cargo bench --bench worker_cancel

use endofuse::appearance::ForestParams;
use endofuse::fit::Mode;
use endofuse::worker::{Command, Event, Task, Worker};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn main() {
    let scene = Arc::new(endofuse::synth::demo_scene().expect("the demo builds"));
    let frames = scene.frame_count;
    let worker = Worker::spawn();
    worker.send(Command::UseScene(scene));
    worker.send(Command::Train(ForestParams::default()));
    loop {
        match worker.wait(Duration::from_secs(60)) {
            Some(Event::Finished(Task::Train)) => break,
            Some(Event::Failed { message, .. }) => panic!("{message}"),
            None => panic!("training did not finish"),
            _ => {}
        }
    }
    let mut delays = Vec::new();
    for k in 0..10 {
        worker.send(Command::Track {
            mode: Mode::LSC,
            frames: (0, frames - 1),
            start: None,
        });
        std::thread::sleep(Duration::from_millis(150 + 37 * k));
        let asked = Instant::now();
        worker.cancel();
        loop {
            match worker.wait(Duration::from_secs(60)) {
                Some(Event::Cancelled(_)) | Some(Event::Finished(Task::Track)) => break,
                Some(_) => {}
                None => panic!("no answer to cancel"),
            }
        }
        delays.push(asked.elapsed().as_secs_f64() * 1e3);
    }
    delays.sort_by(f64::total_cmp);
    println!(
        "cancel answered after {:.1} ms (median), {:.1} ms (max) over {} cancels while tracking the demo (LSC, 480×270 stereo)",
        delays[delays.len() / 2],
        delays[delays.len() - 1],
        delays.len()
    );
}
