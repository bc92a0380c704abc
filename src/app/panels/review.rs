//! The review window: Dice per structure, confidence and the corrected focal lengths over
//! time (the paper's Figs. 7, 10a and 12a), with the export.

use super::action_button;
use crate::app::Shown;
use crate::app::actions::Action;
use crate::app::commands::AppCommand;

/// Dice per structure, confidence and the corrected focal lengths over time (the paper's
/// Figs. 7, 10a and 12a), with the export.
pub fn review_window(shown: &Shown, ctx: &egui::Context) {
    use egui_plot::{Legend, Line, Plot, PlotPoints, VLine};
    let mut open = shown.view.show_review;
    let (doc, scene) = (shown.doc, shown.doc.scene.as_ref());
    egui::Window::new("Review")
        .open(&mut open)
        .default_size([520.0, 520.0])
        .show(ctx, |ui| {
            if doc.results.is_empty() {
                ui.label("Track some frames to see plots here.");
                return;
            }
            let frame = shown.view.frame as f64;
            ui.label("Dice per structure (against ground truth)");
            let mut by_name: std::collections::BTreeMap<String, Vec<[f64; 2]>> = Default::default();
            for r in doc.results.values() {
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
            let conf: Vec<[f64; 2]> = doc
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
            let mut hidden: std::collections::BTreeMap<String, Vec<[f64; 2]>> = Default::default();
            for r in doc.results.values() {
                for (name, e) in &r.hidden_error_mm {
                    hidden
                        .entry(name.clone())
                        .or_default()
                        .push([r.frame as f64, *e]);
                }
            }
            if !hidden.is_empty() {
                ui.label("Hidden structures: centroid error against ground truth (mm)");
                Plot::new("hidden")
                    .height(110.0)
                    .legend(Legend::default().position(egui_plot::Corner::LeftTop))
                    .include_y(0.0)
                    .show(ui, |p| {
                        for (name, pts) in &hidden {
                            p.line(Line::new(name.clone(), PlotPoints::from(pts.clone())));
                        }
                        p.vline(VLine::new("frame", frame));
                    });
            }
            ui.label("Focal length fx per camera (px); dashed: ground truth");
            Plot::new("fx")
                .height(130.0)
                .legend(Legend::default())
                .show(ui, |p| {
                    let cams = scene.map(|s| s.cameras.as_slice()).unwrap_or_default();
                    for (c, cam) in cams.iter().enumerate() {
                        let pts: Vec<[f64; 2]> = doc
                            .results
                            .values()
                            .filter_map(|r| {
                                r.state.intrinsics.get(c).map(|i| [r.frame as f64, i.fx])
                            })
                            .collect();
                        p.line(Line::new(format!("{} fx", cam.name), PlotPoints::from(pts)));
                        if let Some(truth) = scene.and_then(|s| s.ground_truth.trajectory.as_ref())
                        {
                            let gt: Vec<[f64; 2]> = doc
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
                action_button(shown, ui, Action::Export, shown.status.busy.is_none());
            });
        });
    if open != shown.view.show_review {
        shown.commands.send(AppCommand::SetReviewShown(open));
    }
}
