//! The app without a GPU (egui_kittest, no renderer: the overlay falls back to the CPU):
//! placing the model by dragging, a session saved and loaded back, and the autosave written
//! after a stroke. The same session run again under strace: the app opens no socket, runs no
//! program and writes only the session, its autosaves and the folder the user picked.

use egui::{Event, Modifiers, PointerButton, Pos2, vec2};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use endofuse::app::actions::Action;
use endofuse::app::{Dialogs, EndofuseApp, Picked, Picker, Tool};
use std::path::{Path, PathBuf};

mod common;

use common::app::step_until;

/// Dialogs that answer with fixed paths.
struct Scripted(PathBuf);

impl Dialogs for Scripted {
    fn pick(&mut self, picker: &Picker) -> Picked {
        Picked::Chosen(match picker {
            Picker::Folder { .. } => self.0.with_extension("export"),
            _ => self.0.clone(),
        })
    }
}

/// The test's folder; the strace check names it through ENDOFUSE_APP_SCRATCH.
fn scratch() -> PathBuf {
    let d = std::env::var_os("ENDOFUSE_APP_SCRATCH")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_TARGET_TMPDIR"))
                .join(format!("endofuse-app-session-{}", std::process::id()))
        });
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn drag(h: &mut Harness<'_, EndofuseApp>, from: Pos2, to: Pos2) {
    h.event(Event::PointerMoved(from));
    h.step();
    h.event(Event::PointerButton {
        pos: from,
        button: PointerButton::Primary,
        pressed: true,
        modifiers: Modifiers::NONE,
    });
    h.step();
    for i in 1..=5 {
        h.event(Event::PointerMoved(from + (to - from) * (i as f32 / 5.0)));
        h.step();
    }
    h.event(Event::PointerButton {
        pos: to,
        button: PointerButton::Primary,
        pressed: false,
        modifiers: Modifiers::NONE,
    });
    h.step();
}

#[test]
fn place_by_dragging_save_and_load_a_session_and_autosave() {
    let dir = scratch();
    let session = dir.join("s.endofuse.json");
    let mut h = Harness::builder()
        .with_size([1100.0, 680.0])
        .with_accessibility_check(false)
        .build_eframe(|cc| {
            let mut app = EndofuseApp::new(cc, "demo", Box::new(Scripted(session.clone())));
            app.files.autosave_dir = Some(dir.join("autosave"));
            app
        });
    step_until(&mut h, "the demo", |a| {
        a.doc.scene.is_some() && a.frames_ready()
    });

    // Place tool: a drag to the right moves the model along camera 0's x axis only.
    h.key_press(egui::Key::M);
    h.step();
    assert_eq!(h.state().view.tool, Tool::Place);
    let before = h
        .state()
        .doc
        .placement
        .expect("the demo has an initial pose");
    let v = h.state().screen.layout.views[0];
    drag(&mut h, v.center(), v.center() + vec2(40.0, 0.0));
    let after = h.state().doc.placement.unwrap();
    let (t0, t1) = (before.translation_mm(), after.translation_mm());
    assert!(t1.x - t0.x > 1.0, "moved right: {t0} → {t1}");
    assert!((t1.y - t0.y).abs() < 0.2 * (t1.x - t0.x) && (t1.z - t0.z).abs() < 0.2 * (t1.x - t0.x));
    // A second drag is a step of its own: Ctrl+Z takes it back and leaves the first.
    drag(&mut h, v.center(), v.center() + vec2(0.0, 30.0));
    assert_ne!(
        h.state().doc.placement,
        Some(after),
        "the second drag moved the model"
    );
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.step();
    assert_eq!(
        h.state().doc.placement,
        Some(after),
        "Undo took back the second drag only"
    );
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.step();
    assert_eq!(h.state().doc.placement, Some(before), "and then the first");
    drag(&mut h, v.center(), v.center() + vec2(40.0, 0.0));
    let after = h.state().doc.placement.unwrap();
    assert!(after.translation_mm().x - t0.x > 1.0, "moved right again");

    // Space, both the play key and (held) the pan key of the action table: a press plays and
    // pauses; held for a drag it pans the views and leaves playing alone.
    h.key_press(egui::Key::Space);
    h.step();
    assert!(h.state().view.playing, "Space plays");
    h.key_press(egui::Key::Space);
    h.step();
    assert!(!h.state().view.playing, "Space pauses");
    let space = |pressed| Event::Key {
        key: egui::Key::Space,
        physical_key: None,
        pressed,
        repeat: false,
        modifiers: Modifiers::NONE,
    };
    let zoom_before = h.state().view.transform;
    h.event(space(true));
    h.step();
    let v = h.state().screen.layout.views[0];
    drag(&mut h, v.center(), v.center() + vec2(25.0, 15.0));
    h.event(space(false));
    h.step();
    assert!(!h.state().view.playing, "a Space drag does not play");
    assert_ne!(h.state().view.transform, zoom_before, "a Space drag pans");
    h.key_press(egui::Key::R);
    h.step();

    // A stroke, then the autosave appears within a few seconds of app time.
    h.key_press(egui::Key::B);
    let v = h.state().screen.layout.views[1];
    drag(
        &mut h,
        v.center() - vec2(30.0, 0.0),
        v.center() + vec2(30.0, 10.0),
    );
    assert!(h.state().doc.unsaved());
    let painted = h.state().doc.editor.counts();
    let autosaves = dir.join("autosave");
    step_until(&mut h, "the autosave", |_| {
        std::fs::read_dir(&autosaves)
            .map(|d| d.count() > 0)
            .unwrap_or(false)
    });

    // Save, undo the stroke, load the session: the stroke and the placement are back.
    let ctx = h.ctx.clone();
    h.state_mut().do_action(Action::SaveSession, &ctx);
    assert!(
        session.is_file() && !h.state().doc.unsaved(),
        "{:?}",
        h.state().status.error
    );
    h.state_mut().do_action(Action::Undo, &ctx);
    h.state_mut().doc.placement = None;
    assert_ne!(h.state().doc.editor.counts(), painted);
    // Loading over unsaved work (the undo) asks first.
    h.state_mut().do_action(Action::LoadSession, &ctx);
    assert!(matches!(
        h.state().confirm,
        Some(endofuse::app::confirm::Confirm::LoadSession(_))
    ));
    h.run_steps(2);
    h.get_by_label("Load without saving").click();
    h.run_steps(2);
    assert_eq!(
        h.state().doc.editor.counts(),
        painted,
        "{:?}",
        h.state().status.error
    );
    assert_eq!(h.state().doc.placement, Some(after));

    // Seeds as the contract's label PNGs (the demo lives in memory: into a picked folder).
    h.state_mut().do_action(Action::SaveSeeds, &ctx);
    let seeds_dir = session.with_extension("export");
    let written = endofuse::scene::labels::read_label_png(&seeds_dir.join("right/000000.png"))
        .expect("seed PNG of the painted view and frame");
    assert!(written.data.contains(&1), "kidney seeds in the PNG");

    // A damaged session file is one message in the window; nothing is lost.
    std::fs::write(&session, "{ not json").unwrap();
    h.state_mut().do_action(Action::LoadSession, &ctx);
    let err = h.state().status.error.clone().unwrap_or_default();
    assert!(err.contains("s.endofuse.json"), "{err}");
    assert_eq!(h.state().doc.editor.counts(), painted);
    if std::env::var_os("ENDOFUSE_APP_SCRATCH").is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// The session above (open the demo, place, paint, autosave, save, load, export seeds) run by
/// this test binary again, under strace: no socket or connection, no program run, and every
/// write inside the test's folder (session, autosave folder, picked export folder). Mesa's
/// shader cache is switched off: the driver's cache is the driver's, not the app's.
#[test]
fn the_app_opens_no_socket_runs_no_program_and_writes_only_what_the_user_chose() {
    if !common::strace::available() {
        return;
    }
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("endofuse-app-traced-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut cmd = std::process::Command::new(std::env::current_exe().unwrap());
    cmd.args([
        "--exact",
        "place_by_dragging_save_and_load_a_session_and_autosave",
        "--test-threads=1",
    ])
    .env("ENDOFUSE_APP_SCRATCH", &dir)
    .env("MESA_SHADER_CACHE_DISABLE", "true");
    let log = dir.with_extension("strace");
    let (out, text) = common::strace::run(&cmd, &log);
    assert!(
        out.status.success(),
        "the traced session failed: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    let bad = common::strace::violations(&text, |p| p.starts_with(&dir));
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    // The trace saw the writes it judged: the session and the autosave.
    assert!(common::strace::wrote(&text, &dir.join("s.endofuse.json")));
    assert!(common::strace::wrote(&text, &dir.join("autosave")));
    // And the rule can fail: judged against another folder, the same writes break it.
    let elsewhere = common::strace::violations(&text, |p| p.starts_with(dir.join("autosave")));
    assert!(
        !elsewhere.is_empty(),
        "writes outside the autosave folder went unseen"
    );
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(&log);
}
