//! The side panel: seed tools and classes, the forest, the layers, the structures' display,
//! the fit's settings and actions, and the offer to restore an autosave. Widgets edit copies;
//! what changed goes back as a command.

use super::action_button;
use crate::app::Shown;
use crate::app::actions::Action;
use crate::app::commands::AppCommand;
use crate::app::state::{Layer, Tool};
use crate::overlay::structure_colour;
use egui::{Color32, RichText, Sense, Vec2};

pub fn side_panel(shown: &Shown, ui: &mut egui::Ui) {
    egui::Panel::left("side")
        .default_size(250.0)
        .show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| side_contents(shown, ui));
        });
}

/// A colour swatch.
fn swatch(ui: &mut egui::Ui, col: [u8; 3]) {
    let (r, _) = ui.allocate_exact_size(Vec2::splat(14.0), Sense::hover());
    ui.painter()
        .rect_filled(r, 3.0, Color32::from_rgb(col[0], col[1], col[2]));
}

fn side_contents(shown: &Shown, ui: &mut egui::Ui) {
    let send = |c: AppCommand| shown.commands.send(c);
    let Some(scene) = &shown.doc.scene else {
        ui.label("No scene loaded.");
        if ui.button(Action::OpenDemo.label()).clicked() {
            shown.commands.act(Action::OpenDemo);
        }
        return;
    };
    let (doc, view) = (shown.doc, shown.view);
    let ctx = ui.ctx().clone();
    let mut prefs = shown.prefs.clone();
    let mut settings = doc.settings.clone();

    ui.heading("Seeds");
    ui.horizontal(|ui| {
        for (t, a) in [
            (Tool::Brush, Action::Brush),
            (Tool::Eraser, Action::Eraser),
            (Tool::Place, Action::Place),
        ] {
            if ui
                .selectable_label(view.tool == t, a.label())
                .on_hover_text(a.hint(&ctx))
                .clicked()
            {
                shown.commands.act(a);
            }
        }
    });
    if let Some(classes) = &doc.classes {
        for (k, name) in classes.names.iter().enumerate() {
            let label = if k == 0 {
                "background / tools"
            } else {
                name.as_str()
            };
            ui.horizontal(|ui| {
                swatch(ui, doc.class_colour(k));
                let text = format!("{}  {label}", k + 1);
                let pick = Action::PickClass(k as u8);
                if ui
                    .selectable_label(view.class == k && view.tool == Tool::Brush, text)
                    .on_hover_text(match pick.shortcut() {
                        Some(s) => format!(
                            "Paint {label} ({})",
                            crate::app::actions::shortcut_text(&ctx, &s)
                        ),
                        None => format!("Paint {label}"),
                    })
                    .clicked()
                {
                    shown.commands.act(pick);
                }
            });
        }
    }
    ui.add(
        egui::Slider::new(&mut prefs.brush_px, 1.0..=80.0)
            .text("brush px")
            .logarithmic(true)
            .max_decimals(1),
    )
    .on_hover_text("[ and ], or Shift+wheel");
    ui.add(
        egui::Slider::new(&mut prefs.eraser_px, 1.0..=120.0)
            .text("eraser px")
            .logarithmic(true)
            .max_decimals(1),
    );
    let mut overwrite = view.overwrite;
    if ui
        .checkbox(&mut overwrite, "paint over other classes")
        .changed()
    {
        send(AppCommand::SetOverwrite(overwrite));
    }
    ui.horizontal(|ui| {
        ui.checkbox(&mut prefs.show_seeds, "seeds");
        ui.add(egui::Slider::new(&mut prefs.seed_opacity, 0.0..=1.0).text("opacity"));
    });
    ui.horizontal(|ui| {
        action_button(shown, ui, Action::Undo, doc.can_undo());
        action_button(shown, ui, Action::Redo, doc.editor.can_redo());
    });
    let counts = doc.editor.counts();
    ui.label(
        RichText::new(format!(
            "{} painted pixels on {} frames",
            counts.values().sum::<usize>(),
            doc.editor.seeded_frames().count()
        ))
        .weak(),
    );

    ui.separator();
    ui.heading("Forest");
    let idle = shown.status.busy.is_none();
    ui.horizontal(|ui| {
        ui.add(
            egui::DragValue::new(&mut settings.trees)
                .range(1..=200)
                .suffix(" trees"),
        );
        action_button(shown, ui, Action::Train, idle);
    });
    ui.checkbox(
        &mut settings.live_update,
        "live update (retrain after strokes)",
    );
    if let Some(a) = &doc.appearance {
        // The out-of-bag error only says how separable the strokes are, not how good the
        // maps are away from them: on hover, with that said.
        let check = match &a.validation {
            Some(v) => format!(
                "held-out {:.0} % (worst {:.0} %)",
                100.0 * v.balanced_accuracy,
                100.0 * v.worst_class_accuracy
            ),
            None if shown.jobs.validating => "checking…".into(),
            None => "seed a 2nd frame to check".into(),
        };
        let colour = match &a.validation {
            Some(v) if v.worst_class_accuracy < 0.8 => Color32::from_rgb(255, 190, 70),
            _ => ui.visuals().text_color(),
        };
        // Two lines, not one row: the check's words change as it runs, and a row that grows
        // widened the panel and shifted the views beside it.
        {
            ui.label(format!(
                "{} samples, {:.2} s",
                a.stats.samples, a.stats.train_s
            ))
            .on_hover_text(format!(
                "Trained on {} samples in {:.2} s: the painted pixels, and the same strokes \
                     at the coarser pyramid levels the fit also reads (so more than the painted \
                     pixels counted above). Out-of-bag error {:.2} %: how well \
                     the forest separates the painted pixels, not how good the maps are \
                     elsewhere.",
                a.stats.samples,
                a.stats.train_s,
                a.stats.oob_error * 100.0
            ));
            ui.colored_label(colour, check)
                .on_hover_text(match &a.validation {
                    Some(v) => format!(
                        "A forest that learnt every seeded {0} but one labels the left-out {0}'s \
                     strokes right this often (classes weighed equally; {1} folds): a guide to \
                     frames it never saw. Low: paint where the maps are wrong, on more frames.",
                        v.left_out, v.folds
                    ),
                    None => "With strokes on two or more frames (or views), the forest is checked \
                         on strokes it did not learn."
                        .to_string(),
                });
        }
    } else {
        // Two lines, as the trained forest's figures take: training must not push the buttons
        // below down under the pointer (a click meant for Place automatically opened the mode
        // list).
        ui.label(RichText::new("not trained yet").weak());
        ui.label(RichText::new("train (T) once every class is painted").weak());
    }
    ui.horizontal(|ui| {
        for (a, on) in [
            (Action::ShowImage, view.layer == Layer::Image),
            (
                Action::ShowProbability,
                matches!(view.layer, Layer::Probability(_)),
            ),
            (Action::ShowUncertainty, view.layer == Layer::Uncertainty),
        ] {
            if ui
                .selectable_label(on, a.label())
                .on_hover_text(a.hint(&ctx))
                .clicked()
            {
                shown.commands.act(a);
            }
        }
    });
    ui.horizontal(|ui| {
        if let (Layer::Probability(k), Some(classes)) = (view.layer, &doc.classes) {
            let mut layer = view.layer;
            egui::ComboBox::from_id_salt("probability class")
                .width(86.0)
                .selected_text(classes.names.get(k).cloned().unwrap_or_default())
                .show_ui(ui, |ui| {
                    for (i, name) in classes.names.iter().enumerate() {
                        ui.selectable_value(&mut layer, Layer::Probability(i), name);
                    }
                })
                .response
                .on_hover_text("The class whose probability is shown");
            if layer != view.layer {
                send(AppCommand::SetLayer(layer));
            }
        }
        let label = if matches!(view.layer, Layer::Probability(_)) {
            "opacity"
        } else {
            "map opacity"
        };
        ui.add(egui::Slider::new(&mut prefs.probability_opacity, 0.0..=1.0).text(label));
    });

    ui.separator();
    ui.heading("Fit");
    egui::ComboBox::from_label("mode")
        .selected_text(settings.mode.clone())
        .show_ui(ui, |ui| {
            for (m, what) in [
                ("R", "rigid pose"),
                ("L", "affine pose"),
                ("LS", "affine + shape"),
                ("LSC", "affine + shape + cameras under zoom (default)"),
            ] {
                ui.selectable_value(&mut settings.mode, m.to_string(), format!("{m}: {what}"));
            }
        })
        .response
        .on_hover_text(
            "LSC corrects the cameras only where a zoom change is marked or detected; \
             elsewhere it fits as LS.",
        );
    let trained = doc.appearance.is_some();
    ui.horizontal_wrapped(|ui| {
        action_button(shown, ui, Action::Initialise, idle && trained);
        action_button(shown, ui, Action::FitFrame, idle && trained);
    });
    if view.tool == Tool::Place {
        ui.label(
            RichText::new(
                "Place model: drag to move, right- or Ctrl-drag to turn, Shift+right-drag to \
                 roll, wheel for depth.",
            )
            .weak()
            .small(),
        );
    }
    ui.horizontal_wrapped(|ui| {
        action_button(shown, ui, Action::Track, idle && trained);
        action_button(shown, ui, Action::Review, true);
    });
    // Strokes painted or undone since the forest learned them (live update retrains by itself).
    if !settings.live_update
        && doc.appearance.is_some()
        && shown
            .jobs
            .forest_revision
            .is_some_and(|r| r != doc.editor.revision)
    {
        ui.colored_label(
            Color32::from_rgb(255, 190, 70),
            "The strokes changed since the forest was trained: train again (T) to use them.",
        );
    }
    let older = shown
        .jobs
        .fits_of_earlier_forests(doc.results.keys().copied());
    if older > 0 {
        ui.colored_label(
            Color32::from_rgb(255, 190, 70),
            format!(
                "{older} of {} fitted frames were fitted with an earlier forest: track them \
                 again to use this one.",
                doc.results.len()
            ),
        );
    }
    hidden_structures(shown, ui, &mut prefs);
    ui.separator();
    // How the overlay is drawn comes after the workflow (seeds, forest, fit): the main path
    // fits the window without scrolling.
    egui::CollapsingHeader::new(RichText::new("Structures").heading())
        .default_open(false)
        .show(ui, |ui| {
            ui.checkbox(&mut prefs.show_overlay, "show fitted overlay");
            for (i, (s, style)) in scene.structures.iter().zip(&view.styles).enumerate() {
                let mut edited = *style;
                ui.horizontal(|ui| {
                    swatch(ui, structure_colour(i));
                    let name = if s.visible {
                        s.name.clone()
                    } else {
                        format!("{} (hidden)", s.name)
                    };
                    ui.checkbox(&mut edited.shown, name);
                });
                ui.add(egui::Slider::new(&mut edited.opacity, 0.0..=1.0).text("fill"));
                if edited != *style {
                    send(AppCommand::SetStyle(i, edited));
                }
            }
        });
    if prefs != *shown.prefs {
        send(AppCommand::SetPrefs(prefs));
    }
    if settings != doc.settings {
        send(AppCommand::SetSettings(settings));
    }
}

/// Where each hidden structure could be at the current frame: its 95 % radius and how deep it
/// lies under the visible surface, with the region's toggle and opacity.
fn hidden_structures(shown: &Shown, ui: &mut egui::Ui, prefs: &mut crate::app::state::Prefs) {
    let Some(scene) = &shown.doc.scene else {
        return;
    };
    if scene.structures.iter().all(|s| s.visible) {
        return;
    }
    let ctx = ui.ctx().clone();
    ui.separator();
    ui.heading("Hidden structures");
    ui.horizontal(|ui| {
        ui.checkbox(&mut prefs.show_hidden_region, "95 % region")
            .on_hover_text(Action::HiddenRegion.hint(&ctx));
        ui.add(egui::Slider::new(&mut prefs.hidden_region_opacity, 0.0..=1.0).text("opacity"));
    });
    let result = shown.doc.results.get(&shown.view.frame);
    for (i, s) in scene.structures.iter().enumerate() {
        if s.visible {
            continue;
        }
        let entry = result.and_then(|r| r.hidden_region.get(&s.name));
        let lost = result.is_some_and(|r| r.lost);
        ui.horizontal_wrapped(|ui| {
            swatch(ui, structure_colour(i));
            ui.label(RichText::new(&s.name).strong());
            match entry {
                Some(entry) => {
                    ui.label(format!(
                        "within {:.1} mm (95 %){}",
                        entry.radius95_mm,
                        if lost { ", frame lost" } else { "" }
                    ))
                    .on_hover_text(
                        "The true centre lies inside a sphere of this radius about the fitted \
                         one in 95 % of frames: the fit's own uncertainty (what the silhouettes \
                         leave open of the pose, the shape and the cameras) plus a calibrated \
                         allowance for deformation the shape model does not span; widened on a \
                         lost frame. The halo in the views is the structure moved anywhere \
                         inside it.",
                    );
                }
                None => {
                    ui.label(RichText::new("not fitted at this frame").weak());
                }
            }
        });
        let Some(entry) = entry else {
            continue;
        };
        match (entry.depth_mm, entry.margin95_mm) {
            (Some(depth), Some(margin)) => {
                ui.label(if margin < 0.05 {
                    format!("{depth:.1} mm under the surface; its region may reach it")
                } else {
                    format!("{depth:.1} mm under the surface, at least {margin:.1} mm (95 %)")
                })
                .on_hover_text(
                    "Along the first camera's line of sight through the fitted centre: from the \
                     visible surface to the fitted structure, and to the nearest point of its \
                     95 % region. 0 mm: the region reaches the surface.",
                );
            }
            _ => {
                ui.label(RichText::new("no visible surface in front of it").weak());
            }
        }
    }
}
