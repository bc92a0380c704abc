//! Nothing lost, nothing silent (issue 12), in the app off-screen (egui_kittest, wgpu): opening
//! another scene over unsaved work asks first (Cancel keeps the work, "Open without saving"
//! opens), the help sheet lists every action with its shortcut, frames not yet fitted say so,
//! and LSC is the default mode.

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use endofuse::app::actions::Action;
use endofuse::app::commands::AppCommand;
use endofuse::app::confirm::Confirm;
use endofuse::app::pickers::FileRequest;
use endofuse::app::{Dialogs, EndofuseApp, NoDialogs, UnavailableDialogs};
use std::path::{Path, PathBuf};

mod common;

use common::app::{shoot, step_until};

/// The demo at 1180×700 with `dialogs`, its autosaves in `autosaves`; `setup` adjusts the app.
fn harness(
    dialogs: Box<dyn Dialogs>,
    autosaves: PathBuf,
    setup: impl FnOnce(&mut EndofuseApp) + 'static,
) -> Harness<'static, EndofuseApp> {
    Harness::builder()
        .with_size([1180.0, 700.0])
        .with_accessibility_check(false)
        .wgpu()
        .build_eframe(move |cc| {
            let mut app = EndofuseApp::new(cc, "demo", dialogs);
            app.files.autosave_dir = Some(autosaves);
            setup(&mut app);
            app
        })
}

#[test]
fn unsaved_work_is_asked_about_and_help_lists_every_action() {
    let mut h = harness(
        Box::new(NoDialogs),
        Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("endofuse-app-safety-{}", std::process::id())),
        |_| {},
    );
    step_until(&mut h, "the demo to load", |a| a.doc.scene.is_some());
    assert_eq!(
        h.state().doc.settings.mode,
        "LSC",
        "LSC is the default mode"
    );
    assert!(!h.state().doc.unsaved());
    // The status bar says what to do next: the demo comes with seeds, so train.
    let hint = endofuse::app::panels::menu::next_step(&h.state().doc);
    assert!(hint.contains("train the forest"), "{hint}");

    // Some work: a setting changed (a session keeps it).
    let mut settings = h.state().doc.settings.clone();
    settings.trees = 31;
    h.state().send(AppCommand::SetSettings(settings));
    h.run_steps(2);
    assert!(h.state().doc.unsaved());

    // Open the demo again: asked, and Cancel keeps the work.
    h.state().send(AppCommand::Action(Action::OpenDemo));
    h.run_steps(3);
    assert_eq!(h.state().confirm, Some(Confirm::Open("demo".into())));
    assert!(
        h.state().status.busy.is_none(),
        "nothing is loading while the question is open"
    );
    shoot(&mut h, "app_unsaved_prompt");
    h.get_by_label("Cancel").click();
    h.run_steps(2);
    assert!(h.state().confirm.is_none());
    assert_eq!(h.state().doc.settings.trees, 31);
    assert!(h.state().doc.unsaved());

    // Asked again; this time open without saving.
    h.state().send(AppCommand::Action(Action::OpenDemo));
    h.run_steps(3);
    h.get_by_label("Open without saving").click();
    step_until(&mut h, "the demo to load again", |a| {
        a.confirm.is_none() && a.status.busy.is_none() && !a.doc.unsaved()
    });

    // F1: the help sheet, generated from the action table: each action's label appears once
    // more than without it.
    let actions = [
        Action::Track,
        Action::NewScene,
        Action::PickClass(0),
        Action::Pan,
        Action::Help,
    ];
    let count =
        |h: &Harness<'_, EndofuseApp>, a: Action| h.query_all_by_label_contains(a.label()).count();
    let before: Vec<usize> = actions.iter().map(|&a| count(&h, a)).collect();
    h.key_press(egui::Key::F1);
    h.run_steps(3);
    assert!(h.state().view.show_help);
    for (a, b) in actions.iter().zip(before) {
        assert!(count(&h, *a) > b, "the help sheet lists {a:?}");
    }
    shoot(&mut h, "app_help_sheet");
}

/// Where no system file dialog can open (no xdg-desktop-portal), every file action still works:
/// the app says so once and picks in its built-in browser instead.
#[test]
fn file_actions_fall_back_to_the_built_in_browser() {
    // A fixed path: the snapshot shows it.
    let dir = std::env::temp_dir().join("endofuse-app-browser");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let folder = dir.clone();
    let mut h = harness(
        Box::new(UnavailableDialogs),
        dir.join("autosaves"),
        move |app| app.files.last_folder = Some(folder),
    );
    step_until(&mut h, "the demo to load", |a| a.doc.scene.is_some());
    let mut settings = h.state().doc.settings.clone();
    settings.trees = 29;
    h.state().send(AppCommand::SetSettings(settings));
    h.run_steps(2);

    // Save session: the system dialog fails, the browser opens in its place and says why.
    h.state().send(AppCommand::Action(Action::SaveSession));
    h.run_steps(3);
    assert!(
        h.state().screen.browser.is_some(),
        "the built-in browser opens"
    );
    let notice = h.state().status.notice.clone().unwrap_or_default();
    assert!(
        notice.contains("No system file dialog could open"),
        "{notice}"
    );
    assert!(
        h.state().prefs.builtin_file_browser,
        "the File menu's preference says what the app now does"
    );
    shoot(&mut h, "app_file_browser");
    h.get_by_label("Save").click();
    h.run_steps(3);
    let saved = dir.join("session.endofuse.json");
    assert!(
        saved.is_file(),
        "the session is written where the browser said"
    );
    assert!(h.state().screen.browser.is_none());
    assert!(!h.state().doc.unsaved());

    // Load session: straight to the browser (the system dialog is not tried again).
    let mut settings = h.state().doc.settings.clone();
    settings.trees = 7;
    h.state().send(AppCommand::SetSettings(settings));
    h.run_steps(2);
    h.state().send(AppCommand::Action(Action::LoadSession));
    h.run_steps(3);
    h.get_by_label("session.endofuse.json").click();
    h.run_steps(2);
    h.get_by_label("Open").click();
    h.run_steps(3);
    // Unsaved work: asked first, as with the system dialog.
    assert_eq!(h.state().confirm, Some(Confirm::LoadSession(saved.clone())));
    h.get_by_label_contains("without saving").click();
    step_until(&mut h, "the session to load", |a| {
        a.doc.settings.trees == 29
    });

    // Saving the session over a file that is not one is refused, and nothing is written.
    let scene_like = dir.join("scene.json");
    std::fs::write(&scene_like, "{\"cameras\": []}").unwrap();
    let ctx = h.ctx.clone();
    h.state_mut().path_chosen(
        FileRequest::SaveSession { then: None },
        scene_like.clone(),
        &ctx,
    );
    h.run_steps(2);
    assert_eq!(
        std::fs::read_to_string(&scene_like).unwrap(),
        "{\"cameras\": []}"
    );
    let error = h.state().status.error.clone().unwrap_or_default();
    assert!(error.contains("not an endofuse session"), "{error}");

    // Save seeds of the demo: a folder picked in the browser.
    h.state().send(AppCommand::Action(Action::SaveSeeds));
    h.run_steps(3);
    assert!(h.state().screen.browser.is_some());
    h.get_by_label("Use this folder").click();
    h.run_steps(3);
    let notice = h.state().status.notice.clone().unwrap_or_default();
    assert!(notice.contains("seed PNGs"), "{notice}");
    let pngs = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter(|e| e.path().is_dir())
        .flat_map(|d| std::fs::read_dir(d.path()).unwrap().flatten())
        .filter(|f| f.path().extension().is_some_and(|x| x == "png"))
        .count();
    assert!(
        pngs > 0,
        "the seed PNGs are written under the folder picked"
    );
}
