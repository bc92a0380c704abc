//! The menu bar (every action of the action table, grouped) and the status bar (the worker's
//! progress with Cancel, the last error until dismissed, or the last notice).

use super::{action_button, menu_item, menu_item_if};
use crate::app::Shown;
use crate::app::actions::Action;
use crate::app::commands::AppCommand;
use egui::{Color32, RichText};

pub fn menu_bar(shown: &Shown, ui: &mut egui::Ui) {
    egui::Panel::top("menu").show(ui, |ui| {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                menu_item(shown, ui, Action::NewScene);
                menu_item(shown, ui, Action::OpenScene);
                menu_item(shown, ui, Action::OpenDemo);
                let recent = &shown.prefs.recent;
                ui.add_enabled_ui(!recent.is_empty(), |ui| {
                    ui.menu_button("Open recent", |ui| {
                        for r in recent {
                            if ui.button(r).clicked() {
                                shown.commands.send(AppCommand::OpenScene(r.clone()));
                                ui.close();
                            }
                        }
                    });
                });
                ui.separator();
                menu_item(shown, ui, Action::LoadSession);
                menu_item(shown, ui, Action::SaveSession);
                menu_item(shown, ui, Action::SaveSeeds);
                let tracked = if shown.doc.results.is_empty() {
                    Err("Track some frames first")
                } else {
                    Ok(())
                };
                menu_item_if(shown, ui, Action::Export, tracked);
                ui.separator();
                let mut builtin = shown.prefs.builtin_file_browser;
                if ui
                    .checkbox(&mut builtin, "Use the built-in file browser")
                    .on_hover_text(
                        "Pick files inside the app instead of the system's dialog (chosen by \
                         itself when the system dialog cannot open)",
                    )
                    .changed()
                {
                    let mut prefs = shown.prefs.clone();
                    prefs.builtin_file_browser = builtin;
                    shown.commands.send(AppCommand::SetPrefs(prefs));
                }
            });
            ui.menu_button("Edit", |ui| {
                menu_item(shown, ui, Action::Undo);
                menu_item(shown, ui, Action::Redo);
                ui.separator();
                menu_item(shown, ui, Action::Brush);
                menu_item(shown, ui, Action::Eraser);
                menu_item(shown, ui, Action::Place);
                menu_item(shown, ui, Action::BrushSmaller);
                menu_item(shown, ui, Action::BrushBigger);
            });
            ui.menu_button("View", |ui| {
                menu_item(shown, ui, Action::ShowImage);
                menu_item(shown, ui, Action::ShowProbability);
                menu_item(shown, ui, Action::ShowUncertainty);
                menu_item(shown, ui, Action::ResetView);
                menu_item(shown, ui, Action::HiddenRegion);
                menu_item(shown, ui, Action::Review);
            });
            ui.menu_button("Fit", |ui| {
                menu_item(shown, ui, Action::Train);
                menu_item(shown, ui, Action::Initialise);
                menu_item(shown, ui, Action::FitFrame);
                menu_item(shown, ui, Action::Track);
                menu_item(shown, ui, Action::Cancel);
            });
            ui.menu_button("Play", |ui| {
                menu_item(shown, ui, Action::PlayPause);
                menu_item(shown, ui, Action::StepBack);
                menu_item(shown, ui, Action::StepForward);
                menu_item(shown, ui, Action::FirstFrame);
                menu_item(shown, ui, Action::LastFrame);
            });
            ui.menu_button("Help", |ui| {
                menu_item(shown, ui, Action::Help);
            });
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                let spec = &shown.doc.spec;
                let name = if spec == crate::open::DEMO {
                    "built-in demo"
                } else {
                    spec.as_str()
                };
                let dirty = if shown.doc.unsaved() { " •" } else { "" };
                ui.label(RichText::new(format!("{name}{dirty}")).weak());
            });
        });
    });
}

pub fn status_bar(shown: &Shown, ui: &mut egui::Ui) {
    egui::Panel::bottom("status").show(ui, |ui| {
        ui.horizontal(|ui| {
            if let Some(b) = &shown.status.busy {
                ui.spinner();
                ui.label(&b.what);
                if b.total > 0 {
                    ui.add(
                        egui::ProgressBar::new(b.done as f32 / b.total as f32)
                            .desired_width(220.0)
                            .text(format!("{}/{}", b.done, b.total)),
                    );
                }
                action_button(shown, ui, Action::Cancel, true);
            } else {
                ui.label(RichText::new(next_step(shown.doc)).weak());
            }
            // Long messages end in "…" where the window ends, whole on hover; the dismiss
            // button comes first so that it never falls off the edge.
            if let Some(e) = &shown.status.error {
                ui.separator();
                if ui.small_button("x").on_hover_text("Dismiss").clicked() {
                    shown.commands.send(AppCommand::DismissError);
                }
                ui.add(
                    egui::Label::new(
                        RichText::new(format!("Error: {e}"))
                            .color(Color32::from_rgb(255, 110, 110)),
                    )
                    .truncate(),
                );
            } else if let Some(n) = &shown.status.notice {
                ui.separator();
                ui.add(egui::Label::new(n).truncate());
            }
        });
    });
}

/// What to do next, following the workflow (the first-run hint of the status bar).
pub fn next_step(doc: &crate::app::Document) -> &'static str {
    let Some(scene) = doc.scene.as_ref() else {
        return "Ready. Next: open a scene (File > Open or File > New scene).";
    };
    let painted = doc.editor.counts();
    let classes = scene.visible_structures().count() + 1;
    if painted.len() < classes {
        return "Next: paint seeds on the first frames: 1 background and tools, 2, 3, ... each visible structure (B brush).";
    }
    if doc.appearance.is_none() {
        return "Next: train the forest (T), then check the probability view (P).";
    }
    if doc.results.is_empty() {
        if doc.placement.is_some() {
            return "Next: check the placed model, then fit this frame (F).";
        }
        return "Next: place the model (M or Place automatically) and fit this frame (F).";
    }
    // Fits that found nothing: tracking on from them would hold a pose never found.
    if doc.results.values().all(|r| r.lost) {
        return "Next: the fit lost the organ: place the model again, closer (M, or Place automatically), and fit (F).";
    }
    if doc.results.len() < scene.frame_count {
        return "Next: track (Ctrl+T); frames not fitted yet say so in the views.";
    }
    "Next: review the plots (View > Review plots), export (Ctrl+E) and save the session (Ctrl+S)."
}
