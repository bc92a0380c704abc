//! One PNG per CSV, drawn with plotters into a buffer and encoded by `image` (no system fonts:
//! egui's embedded Ubuntu Light is registered as the sans-serif face). The paper's values are
//! drawn beside ours where it gives numbers (Table IV); its figures 4, 6, 7 and 10b are curves
//! without published values, so report.md quotes what they show instead.

use super::camera::CameraRow;
use super::modes::{MODES, ModeRow};
use super::noise::NoiseRow;
use super::pose_range::{Param, Range};
use super::report::paper_range;
use super::shape::{ShapeRow, tolerable};
use crate::error::Error;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

const W: u32 = 1200;
const H: u32 = 800;
const FONT: &str = "sans-serif";

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // Only fails on a malformed font file, which the embedded one is not; text would then
        // be missing from the plots, not the plots themselves.
        if plotters::style::register_font(
            FONT,
            FontStyle::Normal,
            epaint_default_fonts::UBUNTU_LIGHT,
        )
        .is_err()
        {
            log::warn!("experiments: the embedded font did not load; plots without text");
        }
    });
}

/// Colours of series: views 1, 2, 4, 7, 14 and the methods.
fn colour(i: usize) -> RGBColor {
    const C: [RGBColor; 6] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
    ];
    C[i % C.len()]
}

fn plot_error(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Write {
        path: path.to_path_buf(),
        source: std::io::Error::other(format!("plot: {e}")),
    }
}

/// Draws with `draw` on a white W×H canvas and writes it as PNG.
fn draw_png(
    path: &Path,
    draw: impl FnOnce(&DrawingArea<BitMapBackend, Shift>) -> Result<(), String>,
) -> Result<(), Error> {
    register_font();
    let mut buf = vec![255u8; (W * H * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_error(path, e))?;
        draw(&root).map_err(|e| plot_error(path, e))?;
        root.present().map_err(|e| plot_error(path, e))?;
    }
    let img =
        image::RgbImage::from_raw(W, H, buf).ok_or_else(|| plot_error(path, "buffer size"))?;
    crate::scene::write::save_image(path, &img).map_err(|e| plot_error(path, e))
}

fn s<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Table IV: one panel per kind of parameter, a row per (parameter, views): ours by Dice and
/// rotation (dark), ours by Dice alone (light), the paper's (outline).
pub fn pose_range(path: &Path, rows: &[Range]) -> Result<(), Error> {
    draw_png(path, |root| {
        let (top, rest) = root.split_vertically(40);
        top.draw(&Text::new(
            "Table IV, pose-recovery range. Dark: ours (Dice and rotation recovered); light: ours (Dice alone); outline: the paper's",
            (20, 12),
            (FONT, 17).into_font(),
        ))
        .map_err(s)?;
        let kinds: Vec<(&str, &[Param], bool)> = [
            (
                "rotation (degrees)",
                &[Param::ThetaX, Param::ThetaY, Param::ThetaZ][..],
                false,
            ),
            ("scale factor (log axis)", &[Param::Sx, Param::Sy][..], true),
            (
                "translation (mm)",
                &[Param::Tx, Param::Ty, Param::Tz][..],
                false,
            ),
        ]
        .into_iter()
        .filter(|(_, params, _)| rows.iter().any(|r| params.contains(&r.param)))
        .collect();
        let panels = rest.split_evenly((1, kinds.len().max(1)));
        for (panel, (title, params, log)) in panels.iter().zip(kinds) {
            let of: Vec<&Range> = rows.iter().filter(|r| params.contains(&r.param)).collect();
            let labels: Vec<String> = of
                .iter()
                .map(|r| format!("{} {}v", r.param.name(), r.views))
                .collect();
            let n = of.len().max(1) as f64;
            let label_of = |y: &f64| -> String {
                let i = (n - 1.0 - y.round()) as isize;
                if (y - y.round()).abs() < 1e-6 && i >= 0 && (i as usize) < labels.len() {
                    labels[i as usize].clone()
                } else {
                    String::new()
                }
            };
            // Row i at y = n − 1 − i: ours (strict) on top, ours (Dice alone), the paper's.
            let bar = |i: usize, lo: f64, hi: f64, slot: f64| -> [(f64, f64); 2] {
                let y = n - 1.0 - i as f64 + 0.27 - 0.27 * slot;
                [(lo, y - 0.12), (hi.max(lo), y + 0.12)]
            };
            let dark = colour(0);
            let light = RGBColor(158, 202, 225);
            let paper = colour(1);
            let mut b = ChartBuilder::on(panel);
            b.caption(title, (FONT, 18))
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(90);
            macro_rules! bars {
                ($chart:expr) => {
                    for (i, r) in of.iter().enumerate() {
                        $chart
                            .draw_series([
                                Rectangle::new(
                                    bar(i, r.silhouette_low, r.silhouette_high, 1.0),
                                    light.filled(),
                                ),
                                Rectangle::new(bar(i, r.low, r.high, 0.0), dark.filled()),
                            ])
                            .map_err(s)?;
                        if let Some((lo, hi)) = paper_range(r.views, r.param) {
                            $chart
                                .draw_series([Rectangle::new(
                                    bar(i, lo, hi, 2.0),
                                    paper.stroke_width(2),
                                )])
                                .map_err(s)?;
                        }
                    }
                };
            }
            if log {
                let mut chart = b
                    .build_cartesian_2d((0.005f64..20f64).log_scale(), -0.6f64..n - 0.4)
                    .map_err(s)?;
                chart
                    .configure_mesh()
                    .y_labels(of.len() * 2 + 1)
                    .y_label_formatter(&label_of)
                    .x_desc("factor")
                    .draw()
                    .map_err(s)?;
                bars!(chart);
            } else {
                let mut chart = b
                    .build_cartesian_2d(-100f64..100f64, -0.6f64..n - 0.4)
                    .map_err(s)?;
                chart
                    .configure_mesh()
                    .y_labels(of.len() * 2 + 1)
                    .y_label_formatter(&label_of)
                    .x_desc(if params.contains(&Param::Tx) {
                        "mm"
                    } else {
                        "degrees"
                    })
                    .draw()
                    .map_err(s)?;
                bars!(chart);
            }
        }
        Ok(())
    })
}

/// Fig. 4: Dice against σ, one line per method and number of views, ±1 SD bars.
pub fn noise(path: &Path, rows: &[NoiseRow]) -> Result<(), Error> {
    draw_png(path, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                "Fig. 4: Dice vs noise, ours vs Chan-Vese (ACWOE)",
                (FONT, 22),
            )
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..2f64, 0f64..1.02f64)
            .map_err(s)?;
        chart
            .configure_mesh()
            .x_desc("noise standard deviation σ (intensity contrast 1)")
            .y_desc("Dice")
            .draw()
            .map_err(s)?;
        let mut keys: Vec<(&str, usize)> = rows.iter().map(|r| (r.method, r.views)).collect();
        keys.sort();
        keys.dedup();
        for (k, (method, views)) in keys.iter().enumerate() {
            let mut pts: Vec<&NoiseRow> = rows
                .iter()
                .filter(|r| r.method == *method && r.views == *views)
                .collect();
            pts.sort_by(|a, b| a.sigma.total_cmp(&b.sigma));
            let c = colour(k);
            let style = if *method == "ours" {
                c.stroke_width(3)
            } else {
                c.stroke_width(2)
            };
            chart
                .draw_series(LineSeries::new(
                    pts.iter().map(|r| (r.sigma, r.dice_mean)),
                    style,
                ))
                .map_err(s)?
                .label(format!(
                    "{} ({} view{})",
                    if *method == "ours" {
                        "ours"
                    } else {
                        "Chan-Vese"
                    },
                    views,
                    if *views == 1 { "" } else { "s" }
                ))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3))
                });
            chart
                .draw_series(pts.iter().map(|r| {
                    PathElement::new(
                        vec![
                            (r.sigma, (r.dice_mean - r.dice_std).max(0.0)),
                            (r.sigma, (r.dice_mean + r.dice_std).min(1.02)),
                        ],
                        c.stroke_width(1),
                    )
                }))
                .map_err(s)?;
            chart
                .draw_series(
                    pts.iter()
                        .map(|r| Circle::new((r.sigma, r.dice_mean), 4, c.filled())),
                )
                .map_err(s)?;
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 16))
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(s)?;
        Ok(())
    })
}

/// Fig. 6: the tolerable perturbation (SD) against σ, one line per number of views.
pub fn shape(path: &Path, rows: &[ShapeRow]) -> Result<(), Error> {
    let tol = tolerable(rows);
    let max_sd = rows
        .iter()
        .map(|r| r.perturbation_sd)
        .fold(1.0f64, f64::max);
    draw_png(path, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                "Fig. 6: tolerable shape perturbation (pose fixed)",
                (FONT, 22),
            )
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..2f64, 0f64..max_sd + 0.5)
            .map_err(s)?;
        chart
            .configure_mesh()
            .x_desc("noise standard deviation σ")
            .y_desc("largest perturbation recovered (SD from the mean shape)")
            .draw()
            .map_err(s)?;
        let mut views: Vec<usize> = tol.iter().map(|t| t.1).collect();
        views.sort();
        views.dedup();
        for (k, v) in views.iter().enumerate() {
            let pts: Vec<(f64, f64)> = tol
                .iter()
                .filter(|t| t.1 == *v)
                .map(|t| (t.0, t.2))
                .collect();
            let c = colour(k);
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(3)))
                .map_err(s)?
                .label(format!("{v} view{}", if *v == 1 { "" } else { "s" }))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3))
                });
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 5, c.filled())))
                .map_err(s)?;
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 16))
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(s)?;
        Ok(())
    })
}

/// A series of a time-series panel: its name, the truth and the estimate, as (x, y) points.
type Series<'a> = (&'a str, Vec<(f64, f64)>, Vec<(f64, f64)>);

/// One time-series panel: truth as a line, the estimate as points.
fn series_panel(
    area: &DrawingArea<BitMapBackend, Shift>,
    title: &str,
    unit: &str,
    lines: &[Series],
) -> Result<(), String> {
    let xs = lines.iter().flat_map(|l| l.1.iter().map(|p| p.0));
    let x_max = xs.fold(1.0f64, f64::max);
    let ys: Vec<f64> = lines
        .iter()
        .flat_map(|l| l.1.iter().chain(&l.2).map(|p| p.1))
        .filter(|v| v.is_finite())
        .collect();
    let (lo, hi) = ys
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let pad = ((hi - lo) * 0.1).max(1e-3);
    let (lo, hi) = if lo.is_finite() {
        (lo - pad, hi + pad)
    } else {
        (0.0, 1.0)
    };
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..x_max, lo..hi)
        .map_err(s)?;
    chart
        .configure_mesh()
        .x_desc("frame")
        .y_desc(unit)
        .draw()
        .map_err(s)?;
    for (k, (name, truth, est)) in lines.iter().enumerate() {
        let c = colour(k);
        chart
            .draw_series(LineSeries::new(truth.clone(), c.stroke_width(2)))
            .map_err(s)?
            .label(format!("{name} true"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(est.iter().map(|&p| Cross::new(p, 5, c.stroke_width(2))))
            .map_err(s)?
            .label(format!("{name} estimated"))
            .legend(move |(x, y)| Cross::new((x + 10, y), 5, c.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 14))
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(s)?;
    Ok(())
}

/// Fig. 7: fx, fy; cx, cy; k1 of camera 0 over the zoom, truth against estimate.
pub fn camera(path: &Path, rows: &[CameraRow]) -> Result<(), Error> {
    let cam0: Vec<&CameraRow> = rows.iter().filter(|r| r.camera == 0).collect();
    let pick = |f: fn(&crate::geometry::Intrinsics) -> f64| {
        (
            cam0.iter()
                .map(|r| (r.frame as f64, f(&r.truth)))
                .collect::<Vec<_>>(),
            cam0.iter()
                .map(|r| (r.frame as f64, f(&r.estimate)))
                .collect::<Vec<_>>(),
        )
    };
    let (fx_t, fx_e) = pick(|k| k.fx);
    let (fy_t, fy_e) = pick(|k| k.fy);
    let (cx_t, cx_e) = pick(|k| k.cx);
    let (cy_t, cy_e) = pick(|k| k.cy);
    let (k1_t, k1_e) = pick(|k| k.k1);
    draw_png(path, |root| {
        let panels = root.split_evenly((1, 3));
        series_panel(
            &panels[0],
            "Fig. 7: focal length (camera 0)",
            "px",
            &[
                ("fx", fx_t.clone(), fx_e.clone()),
                ("fy", fy_t.clone(), fy_e.clone()),
            ],
        )?;
        series_panel(
            &panels[1],
            "principal point (camera 0)",
            "px",
            &[
                ("cx", cx_t.clone(), cx_e.clone()),
                ("cy", cy_t.clone(), cy_e.clone()),
            ],
        )?;
        series_panel(
            &panels[2],
            "radial distortion k1 (camera 0)",
            "k1",
            &[("k1", k1_t.clone(), k1_e.clone())],
        )?;
        Ok(())
    })
}

/// Fig. 10b: a Dice box plot per mode over every frame of every phantom, and the hidden
/// tumour's mean centroid error per mode.
pub fn modes(path: &Path, rows: &[ModeRow]) -> Result<(), Error> {
    let quantile = |v: &mut Vec<f64>, q: f64| -> f64 {
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            f64::NAN
        } else {
            v[((v.len() - 1) as f64 * q).round() as usize]
        }
    };
    let stats: Vec<(String, [f64; 5], f64)> = MODES
        .iter()
        .map(|m| {
            let mut all: Vec<f64> = rows
                .iter()
                .filter(|r| r.mode == *m)
                .flat_map(|r| r.per_frame.iter().copied())
                .filter(|v| v.is_finite())
                .collect();
            let hidden: Vec<f64> = rows
                .iter()
                .filter(|r| r.mode == *m)
                .map(|r| r.hidden_centroid_mm)
                .filter(|v| v.is_finite())
                .collect();
            let q = [0.0, 0.25, 0.5, 0.75, 1.0].map(|q| quantile(&mut all, q));
            let h = hidden.iter().sum::<f64>() / hidden.len().max(1) as f64;
            (m.name().to_string(), q, h)
        })
        .collect();
    let lo = stats
        .iter()
        .map(|s| s.1[0])
        .filter(|v| v.is_finite())
        .fold(1.0f64, f64::min);
    let h_max = stats
        .iter()
        .map(|s| s.2)
        .filter(|v| v.is_finite())
        .fold(1.0f64, f64::max);
    draw_png(path, |root| {
        let panels = root.split_evenly((1, 2));
        let names: Vec<String> = stats.iter().map(|s| s.0.clone()).collect();
        let label = |x: &f64| -> String {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
                names[i as usize].clone()
            } else {
                String::new()
            }
        };
        let mut chart = ChartBuilder::on(&panels[0])
            .caption(
                "Fig. 10b: Dice per frame by mode (phantoms, tools, zoom)",
                (FONT, 18),
            )
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.6f64..3.6f64, (lo - 0.02).max(0.0)..1.0f64)
            .map_err(s)?;
        chart
            .configure_mesh()
            .x_labels(9)
            .x_label_formatter(&label)
            .y_desc("Dice")
            .draw()
            .map_err(s)?;
        for (i, (_, q, _)) in stats.iter().enumerate() {
            if !q[2].is_finite() {
                continue;
            }
            let x = i as f64;
            let c = colour(i);
            chart
                .draw_series([
                    Rectangle::new([(x - 0.25, q[1]), (x + 0.25, q[3])], c.mix(0.35).filled()),
                    Rectangle::new([(x - 0.25, q[1]), (x + 0.25, q[3])], c.stroke_width(2)),
                ])
                .map_err(s)?;
            chart
                .draw_series([
                    PathElement::new(vec![(x - 0.25, q[2]), (x + 0.25, q[2])], c.stroke_width(3)),
                    PathElement::new(vec![(x, q[0]), (x, q[1])], c.stroke_width(1)),
                    PathElement::new(vec![(x, q[3]), (x, q[4])], c.stroke_width(1)),
                    PathElement::new(vec![(x - 0.1, q[0]), (x + 0.1, q[0])], c.stroke_width(1)),
                    PathElement::new(vec![(x - 0.1, q[4]), (x + 0.1, q[4])], c.stroke_width(1)),
                ])
                .map_err(s)?;
        }
        let mut chart = ChartBuilder::on(&panels[1])
            .caption("hidden tumour centroid error by mode", (FONT, 18))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.6f64..3.6f64, 0f64..h_max * 1.15)
            .map_err(s)?;
        chart
            .configure_mesh()
            .x_labels(9)
            .x_label_formatter(&label)
            .y_desc("mm (mean over frames and phantoms)")
            .draw()
            .map_err(s)?;
        for (i, (_, _, h)) in stats.iter().enumerate() {
            if !h.is_finite() {
                continue;
            }
            let x = i as f64;
            chart
                .draw_series([Rectangle::new(
                    [(x - 0.25, 0.0), (x + 0.25, *h)],
                    colour(i).filled(),
                )])
                .map_err(s)?;
        }
        Ok(())
    })
}
