//! File → New scene…: the form that turns a patient's files into a scene (what `endofuse
//! new-scene` does). One row per input with a file picker; each input is checked in the
//! background as soon as it changes (a calibration parsed, a video probed, a CT's header and
//! labels read) and the result is shown under it; Create stays off until every input reads.
//! The scene is built on the worker with its stages in the status bar, and opens when done.
//! Dropping a NIfTI, a calibration and videos on the window fills the form.

use crate::app::Shown;
use crate::app::commands::AppCommand;
use crate::newscene::{Anatomy, NewSceneOptions, Views};
use crossbeam_channel::{Receiver, Sender, unbounded};
use egui::{Color32, RichText};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The form's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Field {
    Calibration,
    Ct,
    Meshes,
    Left,
    Right,
    SideBySide,
    Out,
}

impl Field {
    pub fn label(self) -> &'static str {
        match self {
            Field::Calibration => "Calibration file",
            Field::Ct => "CT label volume",
            Field::Meshes => "Meshes folder",
            Field::Left => "Left video",
            Field::Right => "Right video",
            Field::SideBySide => "Side-by-side video",
            Field::Out => "New scene folder",
        }
    }

    /// What the file picker offers.
    pub fn extensions(self) -> &'static [&'static str] {
        match self {
            Field::Calibration => &["yml", "yaml", "xml", "txt", "json"],
            Field::Ct => &["nii", "gz"],
            Field::Left | Field::Right | Field::SideBySide => {
                &["mp4", "m4v", "mov", "avi", "mkv", "webm"]
            }
            Field::Meshes | Field::Out => &[],
        }
    }

    /// Folders rather than files.
    pub fn is_folder(self) -> bool {
        matches!(self, Field::Meshes | Field::Out)
    }
}

/// The result of checking one input: a summary, or the problem.
type Check = Result<String, String>;

/// The form's state (UI-local: it lives in the screen, not in the document).
pub struct NewSceneForm {
    pub values: HashMap<Field, String>,
    /// CT (true) or meshes folder; two videos (false) or one side-by-side video.
    pub from_ct: bool,
    pub side_by_side: bool,
    pub copy_frames: bool,
    pub replace: bool,
    /// The last check of each field, with the value it checked.
    checks: HashMap<Field, (String, Check)>,
    results_tx: Sender<(Field, String, Check)>,
    results_rx: Receiver<(Field, String, Check)>,
    /// The worker's failure, shown in the form as well as in the status bar.
    pub error: Option<String>,
    pub creating: bool,
}

impl Default for NewSceneForm {
    fn default() -> Self {
        let (results_tx, results_rx) = unbounded();
        Self {
            values: HashMap::new(),
            from_ct: true,
            side_by_side: false,
            copy_frames: false,
            replace: false,
            checks: HashMap::new(),
            results_tx,
            results_rx,
            error: None,
            creating: false,
        }
    }
}

impl NewSceneForm {
    pub fn set(&mut self, field: Field, value: &Path) {
        self.values.insert(field, value.display().to_string());
    }

    fn value(&self, field: Field) -> &str {
        self.values.get(&field).map(|s| s.trim()).unwrap_or("")
    }

    /// The inputs this choice of anatomy and views needs.
    fn needed(&self) -> Vec<Field> {
        let mut f = vec![Field::Calibration];
        f.push(if self.from_ct {
            Field::Ct
        } else {
            Field::Meshes
        });
        if self.side_by_side {
            f.push(Field::SideBySide);
        } else {
            f.extend([Field::Left, Field::Right]);
        }
        f.push(Field::Out);
        f
    }

    /// Starts a background check of every field whose value changed; takes finished checks.
    pub fn refresh(&mut self, ctx: &egui::Context) {
        for (field, value, check) in self.results_rx.try_iter() {
            if self.value(field) == value {
                self.checks.insert(field, (value, check));
            }
        }
        for field in self.needed() {
            let value = self.value(field).to_string();
            if self.checks.get(&field).is_some_and(|(v, _)| *v == value) {
                continue;
            }
            self.checks
                .insert(field, (value.clone(), Err("checking…".into())));
            if value.is_empty() {
                self.checks.insert(field, (value, Err("required".into())));
                continue;
            }
            let tx = self.results_tx.clone();
            let replace = self.replace;
            let ctx = ctx.clone();
            let spawned = std::thread::Builder::new()
                .name("endofuse-check".into())
                .spawn(move || {
                    let check = check(field, Path::new(&value), replace);
                    let _ = tx.send((field, value, check));
                    ctx.request_repaint();
                });
            if spawned.is_err() {
                self.checks.insert(
                    field,
                    (self.value(field).to_string(), Err("cannot check".into())),
                );
            }
        }
    }

    fn check_of(&self, field: Field) -> Option<&Check> {
        self.checks
            .get(&field)
            .filter(|(v, _)| v == self.value(field))
            .map(|(_, c)| c)
    }

    /// Every needed input read: the options for the worker.
    pub fn options(&self) -> Option<NewSceneOptions> {
        if self
            .needed()
            .iter()
            .any(|&f| !matches!(self.check_of(f), Some(Ok(_))))
        {
            return None;
        }
        let p = |f: Field| PathBuf::from(self.value(f));
        Some(NewSceneOptions {
            out: p(Field::Out),
            calib: p(Field::Calibration),
            anatomy: if self.from_ct {
                Anatomy::Ct {
                    labels: p(Field::Ct),
                    options: Default::default(),
                }
            } else {
                Anatomy::Meshes(p(Field::Meshes))
            },
            views: if self.side_by_side {
                Views::SideBySide(p(Field::SideBySide))
            } else {
                // In the calibration's camera order, whatever it names them.
                Views::PerCamera(vec![
                    (String::new(), p(Field::Left)),
                    (String::new(), p(Field::Right)),
                ])
            },
            copy_frames: self.copy_frames,
            frames: None,
            force: self.replace,
        })
    }

    /// Files dropped on the window: a NIfTI, a calibration, one or two videos. Returns false
    /// when none of them is one of those.
    pub fn fill_from_dropped(&mut self, paths: &[PathBuf]) -> bool {
        let mut videos: Vec<&PathBuf> = Vec::new();
        let mut used = false;
        for p in paths {
            let name = p.to_string_lossy().to_ascii_lowercase();
            if name.ends_with(".nii") || name.ends_with(".nii.gz") {
                self.set(Field::Ct, p);
                self.from_ct = true;
                used = true;
            } else if crate::video::is_video_path(p) {
                videos.push(p);
            } else if [".yml", ".yaml", ".xml", ".txt"]
                .iter()
                .any(|e| name.ends_with(e))
            {
                self.set(Field::Calibration, p);
                used = true;
            }
        }
        match videos.as_slice() {
            [] => {}
            [one] => {
                self.side_by_side = true;
                self.set(Field::SideBySide, one);
                used = true;
            }
            [a, b, ..] => {
                // By file name: one that says "right" (or "left") is that camera; otherwise
                // the names' order.
                let name = |p: &PathBuf| {
                    p.file_name()
                        .map(|n| n.to_string_lossy().to_lowercase())
                        .unwrap_or_default()
                };
                let mut pair = [*a, *b];
                pair.sort_by_key(|p| name(p));
                let says = |p: &PathBuf, w: &str| name(p).contains(w);
                if (says(pair[0], "right") && !says(pair[1], "right"))
                    || (says(pair[1], "left") && !says(pair[0], "left"))
                {
                    pair.swap(0, 1);
                }
                self.side_by_side = false;
                self.set(Field::Left, pair[0]);
                self.set(Field::Right, pair[1]);
                used = true;
            }
        }
        used
    }
}

/// Reads an input as `new-scene` will (cheaply: headers, probes), for the line under it.
fn check(field: Field, path: &Path, replace: bool) -> Check {
    let shown = |e: crate::error::InputError| e.problem;
    match field {
        Field::Calibration => {
            let c = crate::calib::read(path).map_err(shown)?;
            let names: Vec<&str> = c.cameras.iter().map(|c| c.name.as_str()).collect();
            let size = c
                .image_size
                .map(|(w, h)| format!(", {w}×{h}"))
                .unwrap_or_default();
            Ok(format!(
                "{}: {} camera(s) ({}){size}",
                c.format,
                names.len(),
                names.join(", ")
            ))
        }
        Field::Ct => {
            let v = crate::ctimport::volume::read(path).map_err(|e| e.to_string())?;
            let labels = v.labels_present();
            let s = v.spacing_mm();
            if labels.is_empty() {
                return Err("the volume is all background".into());
            }
            Ok(format!(
                "{}×{}×{} voxels of {:.2}×{:.2}×{:.2} mm, labels {:?}",
                v.dims[0], v.dims[1], v.dims[2], s[0], s[1], s[2], labels
            ))
        }
        Field::Meshes => {
            let found = crate::ctimport::output::read_structures_dir(path).map_err(shown)?;
            let names: Vec<String> = found
                .iter()
                .map(|s| {
                    format!(
                        "{}{}",
                        s.entry.name,
                        if s.entry.visible { "" } else { " (hidden)" }
                    )
                })
                .collect();
            Ok(names.join(", "))
        }
        Field::Left | Field::Right | Field::SideBySide => {
            if path.is_dir() {
                return Ok("a folder of frames".into());
            }
            let i = crate::video::probe(path)
                .map_err(|e| shown(crate::scene::frames::video_input_error(e)))?;
            Ok(format!(
                "{}×{}, {} frames at {:.2} fps ({})",
                i.width, i.height, i.frame_count, i.fps, i.codec
            ))
        }
        Field::Out => {
            let non_empty = std::fs::read_dir(path).is_ok_and(|mut d| d.next().is_some());
            if non_empty && !replace {
                Err("exists and is not empty: choose another folder or tick Replace".into())
            } else if non_empty {
                // What the worker will refuse even with Replace, said here already.
                crate::ctimport::output::check_target(
                    path,
                    true,
                    &[],
                    crate::ctimport::output::Replaces::Scenes,
                )
                .map(|()| "will be replaced".to_string())
                .map_err(|e| match e {
                    crate::error::Error::Input(i) => i.problem,
                    other => other.to_string(),
                })
            } else if path.is_file() {
                Err("is a file".into())
            } else {
                Ok("will be created".into())
            }
        }
    }
}

/// The form window; `form` is None when it is closed.
pub fn window(shown: &Shown, form: &mut Option<NewSceneForm>, ctx: &egui::Context) {
    let Some(f) = form.as_mut() else {
        return;
    };
    f.refresh(ctx);
    let mut open = true;
    egui::Window::new("New scene")
        .constrain_to(shown.below_menu)
        .open(&mut open)
        .collapsible(false)
        .default_width(620.0)
        .show(ctx, |ui| {
            ui.label("A scene from a patient's files: the CT labels are meshed, the videos are referred to where they are.");
            ui.add_space(6.0);
            egui::Grid::new("new-scene-grid")
                .num_columns(3)
                .spacing([8.0, 4.0])
                .show(ui, |ui| {
                    row(shown, f, ui, Field::Calibration);
                    ui.label("Anatomy");
                    ui.horizontal(|ui| {
                        ui.radio_value(&mut f.from_ct, true, "CT labels (NIfTI)");
                        ui.radio_value(&mut f.from_ct, false, "Meshes folder");
                    });
                    ui.end_row();
                    row(shown, f, ui, if f.from_ct { Field::Ct } else { Field::Meshes });
                    ui.label("Views");
                    ui.horizontal(|ui| {
                        ui.radio_value(&mut f.side_by_side, false, "Left and right videos");
                        ui.radio_value(&mut f.side_by_side, true, "One side-by-side video");
                    });
                    ui.end_row();
                    if f.side_by_side {
                        row(shown, f, ui, Field::SideBySide);
                    } else {
                        row(shown, f, ui, Field::Left);
                        row(shown, f, ui, Field::Right);
                    }
                    row(shown, f, ui, Field::Out);
                });
            ui.horizontal(|ui| {
                ui.checkbox(&mut f.copy_frames, "Copy the videos into the scene");
                if ui.checkbox(&mut f.replace, "Replace a non-empty folder").changed() {
                    f.checks.remove(&Field::Out);
                }
            });
            if let Some(e) = &f.error {
                ui.colored_label(Color32::from_rgb(255, 110, 110), e);
            }
            ui.separator();
            ui.horizontal(|ui| {
                let options = f.options();
                let busy = shown.status.busy.is_some();
                let create = ui.add_enabled(
                    options.is_some() && !busy,
                    egui::Button::new("Create and open"),
                );
                if create.clicked()
                    && let Some(o) = options
                {
                    f.error = None;
                    f.creating = true;
                    shown.commands.send(AppCommand::CreateScene(Box::new(o)));
                }
                if f.creating {
                    ui.spinner();
                    ui.label(
                        shown
                            .status
                            .busy
                            .as_ref()
                            .map(|b| b.what.clone())
                            .unwrap_or_default(),
                    );
                }
            });
        });
    if !open {
        *form = None;
    }
}

fn row(shown: &Shown, f: &mut NewSceneForm, ui: &mut egui::Ui, field: Field) {
    let label = ui.label(field.label());
    ui.vertical(|ui| {
        let value = f.values.entry(field).or_default();
        ui.add(
            egui::TextEdit::singleline(value)
                .desired_width(420.0)
                .hint_text(if field.is_folder() { "folder" } else { "file" }),
        )
        .labelled_by(label.id);
        match f.check_of(field) {
            Some(Ok(summary)) => {
                ui.label(
                    RichText::new(summary.as_str())
                        .small()
                        .color(Color32::from_rgb(120, 200, 120)),
                );
            }
            Some(Err(problem)) => {
                ui.label(
                    RichText::new(problem.as_str())
                        .small()
                        .color(Color32::from_rgb(255, 140, 110)),
                );
            }
            None => {}
        }
    });
    if ui
        .button("Browse…")
        .on_hover_text(format!("Choose the {}", field.label().to_lowercase()))
        .clicked()
    {
        shown.commands.send(AppCommand::BrowseNewScene(field));
    }
    ui.end_row();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dropped_files_fill_the_right_fields() {
        let mut f = NewSceneForm::default();
        let p = |s: &str| PathBuf::from(s);
        // "right" in a folder name says nothing; file names decide, then their order.
        assert!(
            f.fill_from_dropped(&[p("/data/albright/right.mp4"), p("/data/albright/left.mp4")])
        );
        assert_eq!(f.value(Field::Left), "/data/albright/left.mp4");
        assert_eq!(f.value(Field::Right), "/data/albright/right.mp4");
        assert!(f.fill_from_dropped(&[p("/d/cam_b.mkv"), p("/d/cam_a.mkv")]));
        assert_eq!(f.value(Field::Left), "/d/cam_a.mkv");
        assert!(!f.side_by_side);
        assert!(f.fill_from_dropped(&[p("/d/stereo.mp4"), p("/d/case.nii.gz"), p("/d/calib.yml")]));
        assert!(f.side_by_side && f.from_ct);
        assert_eq!(f.value(Field::SideBySide), "/d/stereo.mp4");
        assert_eq!(f.value(Field::Ct), "/d/case.nii.gz");
        assert_eq!(f.value(Field::Calibration), "/d/calib.yml");
        assert!(!f.fill_from_dropped(&[p("/d/notes.pdf")]));
    }
}
