//! The review window: Dice per structure, confidence, the hidden structures' centroid error,
//! their 95 % radius and depth under the surface, and the corrected focal lengths over time (the paper's Figs. 7, 10a and 12a), with the export.
//! Each plot's legend is a row above it (never over the curves), each curve keeps its
//! structure's or camera's colour, and the value axes show enough decimals to read them.

use super::action_button;
use crate::app::Shown;
use crate::app::actions::Action;
use crate::app::commands::AppCommand;
use crate::overlay::structure_colour;
use egui::{Color32, Stroke};
use std::collections::BTreeMap;

/// One curve of a plot.
struct Series {
    name: String,
    points: Vec<[f64; 2]>,
    colour: Color32,
    dashed: bool,
}

/// A plot's value axis: its fixed range (if any) and how many decimals its ticks show.
struct Axis {
    label: &'static str,
    range: Option<(f64, f64)>,
    decimals: usize,
}

/// The colours of cameras' curves.
fn camera_colour(c: usize) -> Color32 {
    const PALETTE: [Color32; 4] = [
        Color32::from_rgb(90, 170, 255),
        Color32::from_rgb(255, 150, 60),
        Color32::from_rgb(170, 120, 255),
        Color32::from_rgb(80, 220, 200),
    ];
    PALETTE[c % PALETTE.len()]
}

/// A row of line swatches and names.
fn legend(ui: &mut egui::Ui, series: &[Series]) {
    ui.horizontal_wrapped(|ui| {
        for s in series {
            let (r, _) = ui.allocate_exact_size(egui::vec2(18.0, 10.0), egui::Sense::hover());
            let y = r.center().y;
            let stroke = Stroke::new(2.0, s.colour);
            if s.dashed {
                for i in 0..3 {
                    let x = r.left() + i as f32 * 7.0;
                    ui.painter()
                        .line_segment([egui::pos2(x, y), egui::pos2(x + 4.0, y)], stroke);
                }
            } else {
                ui.painter()
                    .line_segment([egui::pos2(r.left(), y), egui::pos2(r.right(), y)], stroke);
            }
            ui.label(egui::RichText::new(&s.name).small());
            ui.add_space(6.0);
        }
    });
}

/// A titled plot of `series` against frames, with its legend above and the current frame marked.
fn plot(
    ui: &mut egui::Ui,
    id: &str,
    title: &str,
    axis: Axis,
    series: Vec<Series>,
    frame: f64,
    height: f32,
) {
    use egui_plot::{Line, Plot, PlotPoints, VLine};
    ui.label(title);
    legend(ui, &series);
    let decimals = axis.decimals;
    let mut p = Plot::new(id)
        .height(height)
        .y_axis_label(axis.label)
        .y_axis_min_width(38.0)
        // The wheel scrolls the window to the plots below, not this plot's axes (panning a
        // plot off its curve left it empty); Ctrl+wheel still zooms.
        .allow_scroll(false)
        // About three labelled ticks whatever the range (the default spacing labels only
        // powers of ten: a Dice axis from 0.9 to 1 read "1").
        .y_grid_spacer(egui_plot::uniform_grid_spacer(|input| {
            let step = nice_step((input.bounds.1 - input.bounds.0) / 3.0);
            [step / 5.0, step, step * 5.0]
        }))
        .y_axis_formatter(move |mark, _| {
            let d = decimals.max(decimals_of(mark.step_size));
            format!("{:.*}", d, mark.value)
        });
    if let Some((lo, hi)) = axis.range {
        p = p.default_y_bounds(lo, hi);
    }
    p.show(ui, |p| {
        for s in series {
            let line = Line::new(s.name, PlotPoints::from(s.points)).color(s.colour);
            p.line(if s.dashed {
                line.style(egui_plot::LineStyle::dashed_loose())
            } else {
                line
            });
        }
        p.vline(VLine::new("frame", frame).color(Color32::from_gray(160)));
    });
}

/// 1, 2, 2.5 or 5 times a power of ten, the nearest at or under `raw` (> 0).
fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let power = 10f64.powf(raw.log10().floor());
    let m = raw / power;
    let nice = if m >= 5.0 {
        5.0
    } else if m >= 2.5 {
        2.5
    } else if m >= 2.0 {
        2.0
    } else {
        1.0
    };
    nice * power
}

/// The decimals a tick step needs (0.025: 3, 0.25: 2, 5: 0), at most 4.
fn decimals_of(step: f64) -> usize {
    (0..4)
        .find(|&d| {
            let scaled = step * 10f64.powi(d as i32);
            (scaled - scaled.round()).abs() < 1e-6 * scaled.abs().max(1.0)
        })
        .unwrap_or(4)
}

/// The Dice axis: from a round value under the lowest Dice to 1, so its ticks are readable.
fn dice_range(series: &[Series]) -> (f64, f64) {
    let lowest = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p[1]))
        .fold(1.0f64, f64::min);
    let lo = ((lowest - 0.01) * 20.0).floor() / 20.0;
    (lo.clamp(0.0, 0.95), 1.0)
}

/// Per-structure curves of `values(result)` (name, value), averaged over cameras.
fn by_structure(
    shown: &Shown,
    values: impl Fn(&crate::session::FrameResult) -> &[(String, f64)],
) -> Vec<Series> {
    let mut by_name: BTreeMap<String, Vec<[f64; 2]>> = BTreeMap::new();
    for r in shown.doc.results.values() {
        let mut sums: BTreeMap<&str, (f64, usize)> = BTreeMap::new();
        for (name, v) in values(r) {
            let e = sums.entry(name).or_default();
            e.0 += v;
            e.1 += 1;
        }
        for (name, (s, n)) in sums {
            by_name
                .entry(name.to_string())
                .or_default()
                .push([r.frame as f64, s / n as f64]);
        }
    }
    let structures = shown.doc.scene.as_ref().map(|s| s.structures.as_slice());
    by_name
        .into_iter()
        .map(|(name, points)| {
            let index = structures
                .and_then(|s| s.iter().position(|st| st.name == name))
                .unwrap_or(0);
            let c = structure_colour(index);
            Series {
                name,
                points,
                colour: Color32::from_rgb(c[0], c[1], c[2]),
                dashed: false,
            }
        })
        .collect()
}

/// The corrected focal length per camera and, where the scene has it, the truth (dashed).
fn focal_lengths(shown: &Shown) -> Vec<Series> {
    let (doc, scene) = (shown.doc, shown.doc.scene.as_ref());
    let cams = scene.map(|s| s.cameras.as_slice()).unwrap_or_default();
    let truth = scene.and_then(|s| s.ground_truth.trajectory.as_ref());
    let mut series = Vec::new();
    for (c, cam) in cams.iter().enumerate() {
        series.push(Series {
            name: format!("{} fx", cam.name),
            points: doc
                .results
                .values()
                .filter_map(|r| r.state.intrinsics.get(c).map(|i| [r.frame as f64, i.fx]))
                .collect(),
            colour: camera_colour(c),
            dashed: false,
        });
        if let Some(truth) = truth {
            series.push(Series {
                name: format!("{} fx (truth)", cam.name),
                points: doc
                    .results
                    .keys()
                    .filter_map(|&t| {
                        truth
                            .get(t)
                            .and_then(|f| f.cameras.get(c))
                            .map(|i| [t as f64, i.fx])
                    })
                    .collect(),
                colour: camera_colour(c).gamma_multiply(0.7),
                dashed: true,
            });
        }
    }
    series
}

/// Per hidden structure: its 95 % radius over frames, and (dashed) the depth from the visible
/// surface to its region's nearest point.
fn hidden_region_series(shown: &Shown) -> Vec<Series> {
    let Some(scene) = shown.doc.scene.as_ref() else {
        return Vec::new();
    };
    let mut series = Vec::new();
    for (i, s) in scene.structures.iter().enumerate() {
        if s.visible {
            continue;
        }
        let entries = || {
            shown
                .doc
                .results
                .values()
                .filter_map(|r| r.hidden_region.get(&s.name).map(|e| (r.frame as f64, e)))
        };
        let radius: Vec<[f64; 2]> = entries().map(|(t, e)| [t, e.radius95_mm]).collect();
        if radius.is_empty() {
            continue;
        }
        let c = structure_colour(i);
        let colour = Color32::from_rgb(c[0], c[1], c[2]);
        series.push(Series {
            name: format!("{} radius", s.name),
            points: radius,
            colour,
            dashed: false,
        });
        let margin: Vec<[f64; 2]> = entries()
            .filter_map(|(t, e)| e.margin95_mm.map(|m| [t, m]))
            .collect();
        if !margin.is_empty() {
            series.push(Series {
                name: format!("{} depth (95 %)", s.name),
                points: margin,
                colour: colour.gamma_multiply(0.7),
                dashed: true,
            });
        }
    }
    series
}

/// Dice per structure, confidence, hidden centroid error and the focal lengths over time.
pub fn review_window(shown: &Shown, ctx: &egui::Context) {
    let mut open = shown.view.show_review;
    let doc = shown.doc;
    egui::Window::new("Review")
        .constrain_to(shown.below_menu)
        .open(&mut open)
        .default_size([540.0, 600.0])
        .show(ctx, |ui| {
            if doc.results.is_empty() {
                ui.label("Track some frames to see plots here.");
                return;
            }
            let frame = shown.view.frame as f64;
            egui::ScrollArea::vertical().show(ui, |ui| {
                let dice = by_structure(shown, |r| &r.dice);
                if !dice.is_empty() {
                    let axis = Axis {
                        label: "Dice",
                        range: Some(dice_range(&dice)),
                        decimals: 0,
                    };
                    let title = "Dice per structure (against ground truth)";
                    plot(ui, "dice", title, axis, dice, frame, 130.0);
                }
                let confidence = vec![Series {
                    name: "confidence (lost frames at 0)".into(),
                    points: doc
                        .results
                        .values()
                        .map(|r| [r.frame as f64, if r.lost { 0.0 } else { r.confidence }])
                        .collect(),
                    colour: Color32::from_rgb(120, 200, 255),
                    dashed: false,
                }];
                let axis = Axis {
                    label: "confidence",
                    range: Some((0.0, 1.0)),
                    decimals: 0,
                };
                plot(
                    ui,
                    "confidence",
                    "Confidence",
                    axis,
                    confidence,
                    frame,
                    110.0,
                );
                let hidden = by_structure(shown, |r| &r.hidden_error_mm);
                if !hidden.is_empty() {
                    // From 0: an error is read against none, not against the smallest one.
                    let worst = hidden
                        .iter()
                        .flat_map(|s| s.points.iter().map(|p| p[1]))
                        .fold(1.0f64, f64::max);
                    let axis = Axis {
                        label: "mm",
                        range: Some((0.0, worst * 1.1)),
                        decimals: 0,
                    };
                    let title = "Hidden structures: centroid error against ground truth (mm)";
                    plot(ui, "hidden", title, axis, hidden, frame, 110.0);
                }
                let regions = hidden_region_series(shown);
                if !regions.is_empty() {
                    let top = regions
                        .iter()
                        .flat_map(|s| s.points.iter().map(|p| p[1]))
                        .fold(1.0f64, f64::max);
                    let axis = Axis {
                        label: "mm",
                        range: Some((0.0, top * 1.1)),
                        decimals: 0,
                    };
                    let title = "Hidden structures: 95 % radius, and depth under the surface \
                                 at 95 % (dashed) (mm)";
                    plot(ui, "hidden region", title, axis, regions, frame, 120.0);
                }
                let axis = Axis {
                    label: "px",
                    range: None,
                    decimals: 0,
                };
                let title = "Focal length fx per camera (px)";
                plot(ui, "fx", title, axis, focal_lengths(shown), frame, 120.0);
                ui.horizontal(|ui| {
                    action_button(shown, ui, Action::Export, shown.status.busy.is_none());
                });
            });
        });
    if open != shown.view.show_review {
        shown.commands.send(AppCommand::SetReviewShown(open));
    }
}

#[cfg(test)]
mod tests {
    use super::nice_step;

    #[test]
    fn ticks_are_round_numbers() {
        assert_eq!(nice_step(0.1 / 3.0), 0.025);
        assert_eq!(nice_step(1.0 / 3.0), 0.25);
        assert_eq!(nice_step(7.0), 5.0);
        assert_eq!(nice_step(40.0 / 3.0), 10.0);
        assert_eq!(nice_step(0.0), 1.0);
        assert_eq!(nice_step(f64::NAN), 1.0);
    }

    #[test]
    fn tick_labels_show_the_step() {
        use super::decimals_of;
        assert_eq!(decimals_of(0.025), 3);
        assert_eq!(decimals_of(0.25), 2);
        assert_eq!(decimals_of(0.1), 1);
        assert_eq!(decimals_of(5.0), 0);
        assert_eq!(decimals_of(1.0 / 3.0), 4);
    }
}
