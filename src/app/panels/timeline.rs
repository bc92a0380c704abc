//! The timeline: one bar per frame (height = confidence, lost frames red; per pixel column,
//! its worst frame, when a long video has more frames than columns), blue ticks on seeded
//! frames, the tracking range and the current frame; click or drag to scrub. Below it the play
//! buttons, the frame and range fields and the current frame's figures.

use super::action_button;
use crate::app::Shown;
use crate::app::actions::Action;
use crate::app::commands::AppCommand;
use crate::app::views::Layout;
use egui::{Color32, Sense, Stroke, pos2, vec2};

pub fn timeline(shown: &Shown, layout: &mut Layout, ui: &mut egui::Ui) {
    let Some(scene) = &shown.doc.scene else {
        return;
    };
    let (doc, view) = (shown.doc, shown.view);
    let send = |c: AppCommand| shown.commands.send(c);
    let n = scene.frame_count.max(1);
    egui::Panel::bottom("timeline").show(ui, |ui| {
        ui.add_space(4.0);
        let (rect, response) =
            ui.allocate_exact_size(vec2(ui.available_width(), 46.0), Sense::click_and_drag());
        layout.timeline = Some(rect);
        let painter = ui.painter_at(rect);
        // Darker than the panel, so the timeline's own end is visible.
        painter.rect_filled(rect, 3.0, Color32::from_gray(14));
        let w = rect.width() / n as f32;
        // One cell per frame, or per pixel column when frames outnumber columns (a long
        // video): a column shows its worst frame (lost, then the lowest confidence) and a tick
        // if any of its frames is seeded, so nothing is hidden and the cost does not grow
        // with the video's length.
        let cells = n.min(rect.width().max(1.0) as usize).max(1);
        for k in 0..cells {
            let frames = k * n / cells..((k + 1) * n / cells).max(k * n / cells + 1);
            let cell = egui::Rect::from_min_max(
                pos2(rect.left() + frames.start as f32 * w, rect.top()),
                pos2(
                    (rect.left() + frames.end as f32 * w)
                        .max(rect.left() + frames.start as f32 * w + 1.0),
                    rect.bottom(),
                ),
            );
            if doc.editor.any_seeded_in(frames.clone()) {
                painter.rect_filled(
                    egui::Rect::from_min_max(cell.left_top(), pos2(cell.right(), cell.top() + 4.0)),
                    0.0,
                    Color32::from_rgb(90, 140, 255),
                );
            }
            let worst = doc
                .results
                .range(frames.clone())
                .map(|(_, r)| r)
                .min_by(|a, b| {
                    b.lost
                        .cmp(&a.lost)
                        .then(a.confidence.total_cmp(&b.confidence))
                });
            let warned =
                |r: &crate::session::FrameResult| r.confidence < 0.5 || r.depth_explains_zoom;
            if let Some(r) = worst {
                let h = (r.confidence.clamp(0.0, 1.0) as f32) * (rect.height() - 8.0);
                let col = if r.lost {
                    Color32::from_rgb(230, 60, 60)
                } else if doc.results.range(frames).any(|(_, r)| warned(r)) {
                    Color32::from_rgb(230, 180, 50)
                } else {
                    Color32::from_rgb(70, 200, 110)
                };
                let top = if r.lost {
                    rect.top() + 6.0
                } else {
                    rect.bottom() - h
                };
                let bar = egui::Rect::from_min_max(pos2(cell.left(), top), cell.right_bottom());
                let cw = cell.width();
                painter.rect_filled(bar.shrink2(vec2((cw * 0.1).min(1.0), 0.0)), 0.0, col);
            }
        }
        // Frame numbers at a step that leaves ~70 px between labels (1, 2, 5 × 10^k), and the
        // last frame, so the range outline does not read as the video's end.
        let step = [1usize, 2, 5]
            .iter()
            .flat_map(|&m| (0..7).map(move |k| m * 10usize.pow(k)))
            .filter(|&s| s as f32 * w >= 70.0)
            .min()
            .unwrap_or(n);
        let label = |t: usize| {
            let x = rect.left() + (t as f32 + 0.5) * w;
            painter.text(
                pos2(x, rect.top() + 6.0),
                egui::Align2::CENTER_TOP,
                t.to_string(),
                egui::FontId::proportional(10.0),
                Color32::from_gray(150),
            );
        };
        for t in (0..n).step_by(step.max(1)) {
            if n - 1 - t >= step / 2 || t == 0 {
                label(t);
            }
        }
        label(n - 1);
        let (a, b) = view.track_range;
        let xa = rect.left() + a as f32 * w;
        let xb = rect.left() + (b + 1) as f32 * w;
        painter.rect_stroke(
            egui::Rect::from_min_max(pos2(xa, rect.top()), pos2(xb, rect.bottom())),
            0.0,
            Stroke::new(1.0, Color32::from_gray(120)),
            egui::StrokeKind::Inside,
        );
        let x = rect.left() + (view.frame as f32 + 0.5) * w;
        painter.line_segment(
            [pos2(x, rect.top()), pos2(x, rect.bottom())],
            Stroke::new(2.0, Color32::WHITE),
        );
        if let Some(p) = response.interact_pointer_pos()
            && (response.clicked() || response.dragged())
        {
            let t = (((p.x - rect.left()) / w).floor().max(0.0) as usize).min(n - 1);
            send(AppCommand::SetFrame(t));
        }
        // No tooltip: it opened under the pointer, over the buttons below the strip, whenever
        // the pointer crossed it. What the strip shows is in the Help sheet's first steps.
        ui.horizontal(|ui| {
            let ctx = ui.ctx().clone();
            for (a, icon) in [
                (Action::FirstFrame, "|<"),
                (Action::StepBack, "<"),
                (
                    Action::PlayPause,
                    if view.playing { "Pause" } else { "Play" },
                ),
                (Action::StepForward, ">"),
                (Action::LastFrame, ">|"),
            ] {
                if ui.button(icon).on_hover_text(a.hint(&ctx)).clicked() {
                    shown.commands.act(a);
                }
            }
            let mut f = view.frame;
            if ui
                .add(
                    egui::DragValue::new(&mut f)
                        .range(0..=n - 1)
                        .prefix("frame "),
                )
                .changed()
            {
                send(AppCommand::SetFrame(f));
            }
            ui.label(format!("/ {}", n - 1));
            ui.separator();
            ui.label("track frames");
            let (mut a, mut b) = view.track_range;
            let first = ui.add(egui::DragValue::new(&mut a).range(0..=n - 1));
            ui.label("to");
            let last = ui.add(egui::DragValue::new(&mut b).range(0..=n - 1));
            if first.changed() || last.changed() {
                send(AppCommand::SetTrackRange(a, b));
            }
            let idle = shown.status.busy.is_none();
            action_button(shown, ui, Action::Track, idle && doc.appearance.is_some());
            if let Some(r) = doc.results.get(&view.frame) {
                ui.separator();
                ui.label(format!(
                    "confidence {:.2}{}  ·  {:.0} ms",
                    r.confidence,
                    if r.lost && r.refused.iter().any(|w| w == "placement_refused") {
                        " (lost; a far placement refused)"
                    } else if r.lost {
                        " (lost)"
                    } else if r.depth_explains_zoom {
                        " (zoom followed by depth)"
                    } else if !r.refused.is_empty() {
                        " (camera correction refused)"
                    } else {
                        ""
                    },
                    r.ms
                ))
                .on_hover_text(if r.depth_explains_zoom {
                    "The image zoomed with the cameras fixed: only the depth could follow, so \
                     the hidden structures may be off. LSC corrects the cameras."
                } else {
                    "How well the fitted contours separate the tissues"
                });
                if !r.dice.is_empty() {
                    let mean = r.dice.iter().map(|(_, d)| d).sum::<f64>() / r.dice.len() as f64;
                    ui.label(format!("Dice {mean:.3}"));
                }
                // Where each hidden structure could be, beside the frame it belongs to: the
                // side panel's section may be scrolled out of sight.
                for (name, region) in &r.hidden_region {
                    ui.separator();
                    let depth = match region.margin95_mm {
                        Some(m) if m < 0.05 => ", may reach the surface".to_string(),
                        Some(m) => format!(", ≥ {m:.1} mm deep"),
                        None => String::new(),
                    };
                    ui.label(format!(
                        "{name} within {:.1} mm (95 %){depth}",
                        region.radius95_mm
                    ))
                    .on_hover_text(
                        "The true centre lies within this distance of the fitted one in 95 % of \
                         frames (calibrated on phantoms with truth); and the least depth under \
                         the visible surface, along the first camera's line of sight, that the \
                         region allows.",
                    );
                }
            }
        });
        ui.add_space(2.0);
    });
}
