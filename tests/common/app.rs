//! Driving the app in egui_kittest: step until a condition holds (the worker and the frame
//! loader run on their own threads), then until every view shows its frame.

use egui_kittest::Harness;
use endofuse::app::EndofuseApp;
use std::time::{Duration, Instant};

/// Steps the app until `done` holds and the current frames are on screen.
pub fn step_until(
    h: &mut Harness<'_, EndofuseApp>,
    what: &str,
    done: impl Fn(&EndofuseApp) -> bool,
) {
    let deadline = Instant::now() + Duration::from_secs(240);
    let wait = |h: &mut Harness<'_, EndofuseApp>, what: &str, ok: &dyn Fn(&EndofuseApp) -> bool| {
        while !ok(h.state()) {
            assert!(
                Instant::now() < deadline,
                "timed out waiting for {what}; error: {:?}",
                h.state().status.error
            );
            h.step();
            std::thread::sleep(Duration::from_millis(10));
        }
    };
    wait(h, what, &done);
    h.run_steps(2);
    wait(h, "the frames", &|a| a.frames_ready());
    h.run_steps(2);
}

/// Once every view shows its frame, compares the app with its snapshot `name`; with UPDATE_SCREENSHOTS set, also writes it as
/// the README's `screenshots/{name}.png`.
pub fn shoot(h: &mut Harness<'_, EndofuseApp>, name: &str) {
    step_until(h, "the frames", |_| true);
    if std::env::var_os("UPDATE_SCREENSHOTS").is_some() {
        let img = h.render().expect("render");
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join(format!("screenshots/{name}.png"));
        img.save(&path).expect("write screenshot");
    }
    h.snapshot(name);
}
