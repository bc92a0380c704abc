//! Nothing lost, nothing silent (issue 12), in the app off-screen (egui_kittest, wgpu): opening
//! another scene over unsaved work asks first (Cancel keeps the work, "Open without saving"
//! opens), the help sheet lists every action with its shortcut, frames not yet fitted say so,
//! and LSC is the default mode.

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use endofuse::app::actions::Action;
use endofuse::app::commands::AppCommand;
use endofuse::app::confirm::Confirm;
use endofuse::app::{EndofuseApp, NoDialogs};
use std::path::Path;

mod common;

use common::app::step_until;

fn harness() -> Harness<'static, EndofuseApp> {
    Harness::builder()
        .with_size([1180.0, 700.0])
        .with_accessibility_check(false)
        .wgpu()
        .build_eframe(|cc| {
            let mut app = EndofuseApp::new(cc, "demo", Box::new(NoDialogs));
            app.files.autosave_dir = Some(
                Path::new(env!("CARGO_TARGET_TMPDIR"))
                    .join(format!("endofuse-app-safety-{}", std::process::id())),
            );
            app
        })
}

#[test]
fn unsaved_work_is_asked_about_and_help_lists_every_action() {
    let mut h = harness();
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
    h.snapshot("app_unsaved_prompt");
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
    h.snapshot("app_help_sheet");
}
