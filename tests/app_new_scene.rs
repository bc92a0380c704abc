//! File → New scene… in the app (egui_kittest, wgpu off-screen): the form opened from the
//! menu, each input chosen with its Browse… button (scripted dialogs), checked inline (an
//! unreadable calibration is flagged before anything runs), the scene built on the worker from a
//! KiTS CT, an OpenCV YAML calibration and two MP4 videos, and opened. Dropped files fill the
//! form. Needs the `ffmpeg` program.

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use endofuse::app::panels::new_scene::Field;
use endofuse::app::{Dialogs, EndofuseApp, Picked, Picker};
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

use common::app::step_until;

/// A file dropped on the window.
#[derive(Debug)]
struct Dropped(PathBuf);

impl egui::DroppedFile for Dropped {
    fn path(&self) -> &Path {
        &self.0
    }
    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

/// Answers each picker by its title.
struct Scripted {
    calib: PathBuf,
    ct: PathBuf,
    left: PathBuf,
    right: PathBuf,
    out: PathBuf,
}

impl Dialogs for Scripted {
    fn pick(&mut self, picker: &Picker) -> Picked {
        let title = picker.title();
        let path = [
            (Field::Out, &self.out),
            (Field::Calibration, &self.calib),
            (Field::Ct, &self.ct),
            (Field::Left, &self.left),
            (Field::Right, &self.right),
        ]
        .into_iter()
        .find(|(f, _)| f.label() == title)
        .map(|(_, p)| p.clone());
        path.map_or(Picked::Cancelled, Picked::Chosen)
    }
}

/// Inputs at fixed paths (the form shows them: the snapshot must not depend on a process id).
fn inputs() -> Scripted {
    let dir = std::env::temp_dir().join("endofuse-app-new-scene");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let mut cal =
        endofuse::calib::read(&fixtures.join("calib/calib_A_seq1-2-3-4-6-7.txt")).unwrap();
    cal.image_size = Some((320, 256));
    for c in &mut cal.cameras {
        c.intrinsics = c.intrinsics.scaled(0.25);
    }
    let calib = dir.join("stereo.yml");
    endofuse::calib::write_opencv_yaml(&cal, &calib).unwrap();
    let video = |name: &str| {
        let p = dir.join(name);
        let out = Command::new("ffmpeg")
            .args(["-v", "error", "-y", "-f", "lavfi", "-i"])
            .arg("testsrc2=size=320x256:rate=25")
            .args(["-frames:v", "6", "-c:v", "libx264", "-pix_fmt", "yuv420p"])
            .arg(&p)
            .output()
            .expect("the ffmpeg program is needed for this test (apt install ffmpeg)");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        p
    };
    Scripted {
        calib,
        ct: {
            let p = dir.join("kits19_case_00010.nii.gz");
            std::fs::copy(fixtures.join("ct/kits19_case_00010_cropped.nii.gz"), &p).unwrap();
            p
        },
        left: video("left.mp4"),
        right: video("right.mp4"),
        out: dir.join("scene"),
    }
}

#[test]
fn the_new_scene_form_builds_a_scene_from_ct_calibration_and_videos_and_opens_it() {
    let scripted = inputs();
    let (out, ct, calib) = (
        scripted.out.clone(),
        scripted.ct.clone(),
        scripted.calib.clone(),
    );
    let mut h = Harness::builder()
        .with_size([1180.0, 700.0])
        .with_accessibility_check(false)
        .wgpu()
        .build_eframe(move |cc| {
            let mut app = EndofuseApp::new(cc, "demo", Box::new(scripted));
            app.files.autosave_dir =
                Some(std::env::temp_dir().join("endofuse-app-new-scene-autosave"));
            app
        });
    step_until(&mut h, "the demo to load", |a| a.doc.scene.is_some());

    // Ctrl+N opens the form; files dropped on the window fill it (here the CT and the
    // calibration; a file of another kind is left alone).
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::N);
    h.run_steps(2);
    assert!(
        h.state().screen.new_scene.is_some(),
        "Ctrl+N opens the form"
    );
    h.state_mut().screen.new_scene = None;
    for p in [&ct, &calib] {
        h.input_mut()
            .dropped_files
            .push(std::sync::Arc::new(Dropped(p.clone())));
    }
    h.run_steps(2);
    {
        let form = h
            .state()
            .screen
            .new_scene
            .as_ref()
            .expect("dropping a CT opens the form");
        assert_eq!(form.values.get(&Field::Ct), Some(&ct.display().to_string()));
        assert_eq!(
            form.values.get(&Field::Calibration),
            Some(&calib.display().to_string())
        );
    }
    h.state_mut().screen.new_scene = None;
    let mut form = endofuse::app::panels::new_scene::NewSceneForm::default();
    assert!(!form.fill_from_dropped(&[PathBuf::from("/x/notes.pdf")]));

    // From the menu, then every input through its Browse… button.
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label_contains("New scene from CT").click();
    h.run_steps(3);
    assert!(h.state().screen.new_scene.is_some());
    let buttons = h.query_all_by_label("Browse…").count();
    assert_eq!(buttons, 5, "calibration, CT, left, right, output");
    for i in 0..5 {
        h.query_all_by_label("Browse…").nth(i).unwrap().click();
        h.run_steps(2);
    }
    step_until(&mut h, "the inputs to be checked", |a| {
        a.screen
            .new_scene
            .as_ref()
            .is_some_and(|f| f.options().is_some())
    });
    h.run_steps(3);
    h.snapshot("app_new_scene_form");

    h.get_by_label("Create and open").click();
    let scene_json = out.join("scene.json");
    step_until(&mut h, "the new scene to open", |a| {
        a.doc
            .scene
            .as_ref()
            .is_some_and(|s| s.origin == scene_json.display().to_string())
    });
    let app = h.state();
    assert!(
        app.screen.new_scene.is_none(),
        "the form closes when the scene opens"
    );
    let scene = app.doc.scene.as_ref().unwrap();
    assert_eq!(scene.frame_count, 6);
    assert_eq!(
        (scene.cameras[0].width, scene.cameras[0].height),
        (320, 256)
    );
    let names: Vec<&str> = scene.structures.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["kidney", "tumour_exo"]);
    assert!(app.status.error.is_none(), "{:?}", app.status.error);
    // No guessed pose in the scene: nothing is drawn until the model is placed. Choosing the
    // Place tool (M) puts it in front of the camera, to be dragged; an undo takes it away.
    assert!(app.doc.placement.is_none());
    h.key_press(egui::Key::M);
    h.run_steps(2);
    let placed = h
        .state()
        .doc
        .placement
        .expect("M places the model in front of the camera");
    assert!(placed.translation_mm().z > 0.0, "{placed:?}");
    assert!(h.state().doc.state_at(0).is_some());
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert!(
        h.state().doc.placement.is_none(),
        "Ctrl+Z takes the start away"
    );
    let notice = h.state().status.notice.clone().unwrap_or_default();
    assert!(notice.contains("nothing placed"), "{notice}");
}
