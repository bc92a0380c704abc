//! The panels around the views: the menu bar, the side panel (structures, seed tools, forest,
//! fit), the timeline with per-frame confidence and lost frames, the status bar with the
//! worker's progress and Cancel, and the review window with plots over time.

use super::actions::Action;
use super::views::class_colour;
use super::{EndofuseApp, Layer, Tool};
use crate::overlay::structure_colour;
use egui::{Color32, RichText, Sense, Stroke, Vec2, pos2, vec2};

/// A button for an action, with its shortcut in the tooltip.
fn action_button(app: &mut EndofuseApp, ui: &mut egui::Ui, a: Action, enabled: bool) -> bool {
    let ctx = ui.ctx().clone();
    let clicked = ui
        .add_enabled(enabled, egui::Button::new(a.label()))
        .on_hover_text(a.hint(&ctx))
        .clicked();
    if clicked {
        app.do_action(a, &ctx);
    }
    clicked
}

fn menu_item(app: &mut EndofuseApp, ui: &mut egui::Ui, a: Action) {
    let ctx = ui.ctx().clone();
    let mut button = egui::Button::new(a.label());
    if let Some(s) = a.shortcut() {
        button = button.shortcut_text(ctx.format_shortcut(&s));
    }
    if ui.add(button).clicked() {
        app.do_action(a, &ctx);
        ui.close();
    }
}

pub fn menu_bar(app: &mut EndofuseApp, ui: &mut egui::Ui) {
    egui::Panel::top("menu").show(ui, |ui| {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                menu_item(app, ui, Action::OpenScene);
                menu_item(app, ui, Action::OpenDemo);
                let recent = app.prefs.recent.clone();
                ui.add_enabled_ui(!recent.is_empty(), |ui| {
                    ui.menu_button("Open recent", |ui| {
                        for r in recent {
                            if ui.button(&r).clicked() {
                                app.open_scene(&r);
                                ui.close();
                            }
                        }
                    });
                });
                ui.separator();
                menu_item(app, ui, Action::LoadSession);
                menu_item(app, ui, Action::SaveSession);
                menu_item(app, ui, Action::SaveSeeds);
                menu_item(app, ui, Action::Export);
            });
            ui.menu_button("Edit", |ui| {
                menu_item(app, ui, Action::Undo);
                menu_item(app, ui, Action::Redo);
                ui.separator();
                menu_item(app, ui, Action::Brush);
                menu_item(app, ui, Action::Eraser);
                menu_item(app, ui, Action::Place);
                menu_item(app, ui, Action::BrushSmaller);
                menu_item(app, ui, Action::BrushBigger);
            });
            ui.menu_button("View", |ui| {
                menu_item(app, ui, Action::ShowImage);
                menu_item(app, ui, Action::ShowProbability);
                menu_item(app, ui, Action::ShowUncertainty);
                menu_item(app, ui, Action::ResetView);
                menu_item(app, ui, Action::Review);
            });
            ui.menu_button("Fit", |ui| {
                menu_item(app, ui, Action::Train);
                menu_item(app, ui, Action::Initialise);
                menu_item(app, ui, Action::FitFrame);
                menu_item(app, ui, Action::Track);
                menu_item(app, ui, Action::Cancel);
            });
            ui.menu_button("Play", |ui| {
                menu_item(app, ui, Action::PlayPause);
                menu_item(app, ui, Action::StepBack);
                menu_item(app, ui, Action::StepForward);
                menu_item(app, ui, Action::FirstFrame);
                menu_item(app, ui, Action::LastFrame);
            });
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                let name = if app.scene_spec == "demo" {
                    "built-in demo".to_string()
                } else {
                    app.scene_spec.clone()
                };
                let dirty = if app.unsaved() { " •" } else { "" };
                ui.label(RichText::new(format!("{name}{dirty}")).weak());
            });
        });
    });
}

pub fn status_bar(app: &mut EndofuseApp, ui: &mut egui::Ui) {
    egui::Panel::bottom("status").show(ui, |ui| {
        ui.horizontal(|ui| {
            if let Some(b) = app.busy.clone() {
                ui.spinner();
                ui.label(&b.what);
                if b.total > 0 {
                    ui.add(
                        egui::ProgressBar::new(b.done as f32 / b.total as f32)
                            .desired_width(220.0)
                            .text(format!("{}/{}", b.done, b.total)),
                    );
                }
                action_button(app, ui, Action::Cancel, true);
            } else {
                ui.label(RichText::new("Ready").weak());
            }
            if let Some(e) = app.error.clone() {
                ui.separator();
                ui.colored_label(Color32::from_rgb(255, 110, 110), format!("Error: {e}"));
                if ui.small_button("x").on_hover_text("Dismiss").clicked() {
                    app.error = None;
                }
            } else if let Some(n) = app.notice.clone() {
                ui.separator();
                ui.label(n);
            }
        });
    });
}

/// Confidence strip: one bar per frame (height = confidence), lost frames red, the current
/// frame a white line; click or drag to scrub.
pub fn timeline(app: &mut EndofuseApp, ui: &mut egui::Ui) {
    let Some(scene) = app.scene.clone() else {
        return;
    };
    let n = scene.frame_count.max(1);
    egui::Panel::bottom("timeline").show(ui, |ui| {
        ui.add_space(4.0);
        let (rect, response) =
            ui.allocate_exact_size(vec2(ui.available_width(), 46.0), Sense::click_and_drag());
        app.layout.timeline = Some(rect);
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 3.0, Color32::from_gray(28));
        let w = rect.width() / n as f32;
        for t in 0..n {
            let x0 = rect.left() + t as f32 * w;
            let cell = egui::Rect::from_min_max(
                pos2(x0, rect.top()),
                pos2(x0 + w.max(1.0), rect.bottom()),
            );
            if let Some(seeds) = (0..scene.cameras.len()).find_map(|c| app.editor.layer(c, t))
                && seeds.data.iter().any(|&v| v != 0)
            {
                painter.rect_filled(
                    egui::Rect::from_min_max(cell.left_top(), pos2(cell.right(), cell.top() + 4.0)),
                    0.0,
                    Color32::from_rgb(90, 140, 255),
                );
            }
            if let Some(r) = app.results.get(&t) {
                let h = (r.confidence.clamp(0.0, 1.0) as f32) * (rect.height() - 8.0);
                let col = if r.lost {
                    Color32::from_rgb(230, 60, 60)
                } else if r.confidence < 0.5 {
                    Color32::from_rgb(230, 180, 50)
                } else {
                    Color32::from_rgb(70, 200, 110)
                };
                let bar = if r.lost {
                    egui::Rect::from_min_max(
                        pos2(cell.left(), rect.top() + 6.0),
                        cell.right_bottom(),
                    )
                } else {
                    egui::Rect::from_min_max(
                        pos2(cell.left(), rect.bottom() - h),
                        cell.right_bottom(),
                    )
                };
                painter.rect_filled(bar.shrink2(vec2((w * 0.1).min(1.0), 0.0)), 0.0, col);
            }
        }
        let (a, b) = app.track_range;
        let xa = rect.left() + a as f32 * w;
        let xb = rect.left() + (b + 1) as f32 * w;
        painter.rect_stroke(
            egui::Rect::from_min_max(pos2(xa, rect.top()), pos2(xb, rect.bottom())),
            0.0,
            Stroke::new(1.0, Color32::from_gray(120)),
            egui::StrokeKind::Inside,
        );
        let x = rect.left() + (app.frame as f32 + 0.5) * w;
        painter.line_segment(
            [pos2(x, rect.top()), pos2(x, rect.bottom())],
            Stroke::new(2.0, Color32::WHITE),
        );
        if let Some(p) = response.interact_pointer_pos()
            && (response.clicked() || response.dragged())
        {
            let t = (((p.x - rect.left()) / w).floor().max(0.0) as usize).min(n - 1);
            app.set_frame(t);
            app.playing = false;
        }
        response.on_hover_text(
            "Per-frame confidence (red: lost), blue ticks: seeded frames. Click or drag to scrub.",
        );
        ui.horizontal(|ui| {
            let ctx = ui.ctx().clone();
            for (a, icon) in [
                (Action::FirstFrame, "|<"),
                (Action::StepBack, "<"),
                (
                    Action::PlayPause,
                    if app.playing { "Pause" } else { "Play" },
                ),
                (Action::StepForward, ">"),
                (Action::LastFrame, ">|"),
            ] {
                if ui.button(icon).on_hover_text(a.hint(&ctx)).clicked() {
                    app.do_action(a, &ctx);
                }
            }
            let mut f = app.frame;
            if ui
                .add(
                    egui::DragValue::new(&mut f)
                        .range(0..=n - 1)
                        .prefix("frame "),
                )
                .changed()
            {
                app.set_frame(f);
            }
            ui.label(format!("/ {}", n - 1));
            ui.separator();
            ui.label("track frames");
            let (mut a, mut b) = app.track_range;
            ui.add(egui::DragValue::new(&mut a).range(0..=n - 1));
            ui.label("to");
            ui.add(egui::DragValue::new(&mut b).range(0..=n - 1));
            app.track_range = (a.min(b), a.max(b));
            let idle = app.busy.is_none();
            action_button(app, ui, Action::Track, idle && app.appearance.is_some());
            if let Some(r) = app.results.get(&app.frame) {
                ui.separator();
                ui.label(format!(
                    "confidence {:.2}{}  ·  {:.0} ms",
                    r.confidence,
                    if r.lost { " (lost)" } else { "" },
                    r.ms
                ));
                if !r.dice.is_empty() {
                    let mean = r.dice.iter().map(|(_, d)| d).sum::<f64>() / r.dice.len() as f64;
                    ui.label(format!("Dice {mean:.3}"));
                }
            }
        });
        ui.add_space(2.0);
    });
}

pub fn side_panel(app: &mut EndofuseApp, ui: &mut egui::Ui) {
    egui::Panel::left("side")
        .default_size(250.0)
        .show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| side_contents(app, ui));
        });
}

fn side_contents(app: &mut EndofuseApp, ui: &mut egui::Ui) {
    let Some(scene) = app.scene.clone() else {
        ui.label("No scene loaded.");
        if ui.button(Action::OpenDemo.label()).clicked() {
            app.open_scene("demo");
        }
        return;
    };
    let ctx = ui.ctx().clone();
    ui.heading("Seeds");
    ui.horizontal(|ui| {
        for (t, a) in [
            (Tool::Brush, Action::Brush),
            (Tool::Eraser, Action::Eraser),
            (Tool::Place, Action::Place),
        ] {
            if ui
                .selectable_label(app.tool == t, a.label())
                .on_hover_text(a.hint(&ctx))
                .clicked()
            {
                app.tool = t;
            }
        }
    });
    let classes = app.classes.clone();
    if let Some(classes) = &classes {
        for (k, name) in classes.names.iter().enumerate() {
            let col = class_colour(app, k);
            let label = if k == 0 {
                "background / tools"
            } else {
                name.as_str()
            };
            ui.horizontal(|ui| {
                let (r, _) = ui.allocate_exact_size(Vec2::splat(14.0), Sense::hover());
                ui.painter()
                    .rect_filled(r, 3.0, Color32::from_rgb(col[0], col[1], col[2]));
                let text = format!("{}  {label}", k + 1);
                if ui
                    .selectable_label(app.class == k && app.tool == Tool::Brush, text)
                    .on_hover_text(format!("Paint {label} (key {})", k + 1))
                    .clicked()
                {
                    app.class = k;
                    app.tool = Tool::Brush;
                }
            });
        }
    }
    ui.add(
        egui::Slider::new(&mut app.prefs.brush_px, 1.0..=80.0)
            .text("brush px")
            .logarithmic(true),
    )
    .on_hover_text("[ and ], or Shift+wheel");
    ui.add(
        egui::Slider::new(&mut app.prefs.eraser_px, 1.0..=120.0)
            .text("eraser px")
            .logarithmic(true),
    );
    ui.checkbox(&mut app.overwrite, "paint over other classes");
    ui.horizontal(|ui| {
        ui.checkbox(&mut app.prefs.show_seeds, "seeds");
        ui.add(egui::Slider::new(&mut app.prefs.seed_opacity, 0.0..=1.0).text("opacity"));
    });
    ui.horizontal(|ui| {
        let (u, r) = (app.editor.can_undo(), app.editor.can_redo());
        action_button(app, ui, Action::Undo, u);
        action_button(app, ui, Action::Redo, r);
    });
    let counts = app.editor.counts();
    ui.label(
        RichText::new(format!(
            "{} painted pixels on {} frames",
            counts.values().sum::<usize>(),
            app.editor.seeds().seeded_frames().len()
        ))
        .weak(),
    );

    ui.separator();
    ui.heading("Forest");
    ui.horizontal(|ui| {
        ui.add(
            egui::DragValue::new(&mut app.settings.trees)
                .range(1..=200)
                .suffix(" trees"),
        );
        let idle = app.busy.is_none();
        action_button(app, ui, Action::Train, idle);
    });
    ui.checkbox(
        &mut app.settings.live_update,
        "live update (retrain after strokes)",
    );
    if let Some(a) = &app.appearance {
        ui.label(format!(
            "trained on {} px in {:.2} s\nout-of-bag error {:.2} %",
            a.stats.samples,
            a.stats.train_s,
            a.stats.oob_error * 100.0
        ));
    } else {
        ui.label(RichText::new("not trained yet").weak());
    }
    ui.horizontal(|ui| {
        if ui
            .selectable_label(app.layer == Layer::Image, Action::ShowImage.label())
            .on_hover_text(Action::ShowImage.hint(&ctx))
            .clicked()
        {
            app.layer = Layer::Image;
        }
        let prob = matches!(app.layer, Layer::Probability(_));
        if ui
            .selectable_label(prob, Action::ShowProbability.label())
            .on_hover_text(Action::ShowProbability.hint(&ctx))
            .clicked()
        {
            app.do_action(Action::ShowProbability, &ctx);
        }
        if ui
            .selectable_label(
                app.layer == Layer::Uncertainty,
                Action::ShowUncertainty.label(),
            )
            .on_hover_text(Action::ShowUncertainty.hint(&ctx))
            .clicked()
        {
            app.layer = Layer::Uncertainty;
        }
    });
    if let (Layer::Probability(k), Some(classes)) = (app.layer, &classes) {
        egui::ComboBox::from_label("class")
            .selected_text(classes.names.get(k).cloned().unwrap_or_default())
            .show_ui(ui, |ui| {
                for (i, name) in classes.names.iter().enumerate() {
                    ui.selectable_value(&mut app.layer, Layer::Probability(i), name);
                }
            });
    }
    ui.add(egui::Slider::new(&mut app.prefs.probability_opacity, 0.0..=1.0).text("map opacity"));

    ui.separator();
    ui.heading("Structures");
    ui.checkbox(&mut app.prefs.show_overlay, "show fitted overlay");
    for (i, s) in scene.structures.iter().enumerate() {
        if i >= app.styles.len() {
            break;
        }
        let col = structure_colour(i);
        ui.horizontal(|ui| {
            let (r, _) = ui.allocate_exact_size(Vec2::splat(14.0), Sense::hover());
            ui.painter()
                .rect_filled(r, 3.0, Color32::from_rgb(col[0], col[1], col[2]));
            let name = if s.visible {
                s.name.clone()
            } else {
                format!("{} (hidden)", s.name)
            };
            ui.checkbox(&mut app.styles[i].shown, name);
        });
        ui.add(egui::Slider::new(&mut app.styles[i].opacity, 0.0..=1.0).text("fill"));
    }

    ui.separator();
    ui.heading("Fit");
    egui::ComboBox::from_label("mode")
        .selected_text(app.settings.mode.clone())
        .show_ui(ui, |ui| {
            for (m, what) in [
                ("R", "rigid pose"),
                ("L", "affine pose"),
                ("LS", "affine + shape"),
                ("LSC", "affine + shape + cameras"),
            ] {
                ui.selectable_value(
                    &mut app.settings.mode,
                    m.to_string(),
                    format!("{m}: {what}"),
                );
            }
        });
    ui.checkbox(
        &mut app.settings.camera_correction,
        "camera correction inside zoom changes",
    );
    let idle = app.busy.is_none();
    let trained = app.appearance.is_some();
    ui.horizontal_wrapped(|ui| {
        action_button(app, ui, Action::Initialise, idle && trained);
        action_button(app, ui, Action::FitFrame, idle && trained);
    });
    ui.label(
        RichText::new("Place model: drag to move, right- or Ctrl-drag to rotate, wheel for depth.")
            .weak()
            .small(),
    );
    ui.horizontal_wrapped(|ui| {
        action_button(app, ui, Action::Track, idle && trained);
        action_button(app, ui, Action::Review, true);
    });
    if let Some(path) = app.autosave_offer.clone() {
        ui.separator();
        ui.colored_label(
            Color32::from_rgb(255, 200, 80),
            "Autosaved work from an earlier run was found.",
        );
        ui.horizontal(|ui| {
            if ui.button("Restore").clicked() {
                app.autosave_offer = None;
                app.load_session_file(&path);
            }
            if ui.button("Discard").clicked() {
                app.autosave_offer = None;
                let _ = std::fs::remove_file(&path);
            }
        });
    }
}

/// Dice per structure, confidence and the corrected focal lengths over time (the paper's
/// Figs. 7, 10a and 12a), with the export.
pub fn review_window(app: &mut EndofuseApp, ctx: &egui::Context) {
    use egui_plot::{Legend, Line, Plot, PlotPoints, VLine};
    let mut open = app.show_review;
    let scene = app.scene.clone();
    egui::Window::new("Review")
        .open(&mut open)
        .default_size([520.0, 520.0])
        .show(ctx, |ui| {
            if app.results.is_empty() {
                ui.label("Track some frames to see plots here.");
                return;
            }
            let frame = app.frame as f64;
            ui.label("Dice per structure (against ground truth)");
            let mut by_name: std::collections::BTreeMap<String, Vec<[f64; 2]>> = Default::default();
            for r in app.results.values() {
                let mut sums: std::collections::BTreeMap<&str, (f64, usize)> = Default::default();
                for (name, d) in &r.dice {
                    let e = sums.entry(name).or_default();
                    e.0 += d;
                    e.1 += 1;
                }
                for (name, (s, n)) in sums {
                    by_name
                        .entry(name.to_string())
                        .or_default()
                        .push([r.frame as f64, s / n as f64]);
                }
            }
            Plot::new("dice")
                .height(130.0)
                .legend(Legend::default())
                .include_y(1.0)
                .show(ui, |p| {
                    for (name, pts) in &by_name {
                        p.line(Line::new(name.clone(), PlotPoints::from(pts.clone())));
                    }
                    p.vline(VLine::new("frame", frame));
                });
            ui.label("Confidence (lost frames at 0)");
            let conf: Vec<[f64; 2]> = app
                .results
                .values()
                .map(|r| [r.frame as f64, if r.lost { 0.0 } else { r.confidence }])
                .collect();
            Plot::new("confidence")
                .height(110.0)
                .include_y(0.0)
                .include_y(1.0)
                .show(ui, |p| {
                    p.line(Line::new("confidence", PlotPoints::from(conf)));
                    p.vline(VLine::new("frame", frame));
                });
            ui.label("Focal length fx per camera (px); dashed: ground truth");
            Plot::new("fx")
                .height(130.0)
                .legend(Legend::default())
                .show(ui, |p| {
                    let cams = scene
                        .as_ref()
                        .map(|s| s.cameras.clone())
                        .unwrap_or_default();
                    for (c, cam) in cams.iter().enumerate() {
                        let pts: Vec<[f64; 2]> = app
                            .results
                            .values()
                            .filter_map(|r| {
                                r.state.intrinsics.get(c).map(|i| [r.frame as f64, i.fx])
                            })
                            .collect();
                        p.line(Line::new(format!("{} fx", cam.name), PlotPoints::from(pts)));
                        if let Some(truth) = scene
                            .as_ref()
                            .and_then(|s| s.ground_truth.trajectory.as_ref())
                        {
                            let gt: Vec<[f64; 2]> = app
                                .results
                                .keys()
                                .filter_map(|&t| {
                                    truth
                                        .get(t)
                                        .and_then(|f| f.cameras.get(c))
                                        .map(|i| [t as f64, i.fx])
                                })
                                .collect();
                            p.line(
                                Line::new(format!("{} fx (truth)", cam.name), PlotPoints::from(gt))
                                    .style(egui_plot::LineStyle::dashed_loose()),
                            );
                        }
                    }
                    p.vline(VLine::new("frame", frame));
                });
            ui.horizontal(|ui| {
                action_button(app, ui, Action::Export, app.busy.is_none());
            });
        });
    app.show_review = open;
}
