//! The camera views: the frame, the probability or uncertainty layer, the seeds, the fitted
//! overlay and the brush cursor, in a grid with one shared zoom and pan. Pointer input here
//! becomes commands (paint, erase, place, pan, zoom); the document is only read.

pub mod overlay;
pub mod place;
pub mod scale;
mod textures;

use super::Shown;
use super::actions::Action;
use super::commands::AppCommand;
use super::frames::FrameLoader;
use super::state::{Tool, ViewPart};
use super::view::{ViewTransform, grid};
use crate::strokes::Dab;
use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2, pos2, vec2};
use textures::Textures;

/// Screen rectangles of the last frame's views and timeline strip.
#[derive(Debug, Clone, Default)]
pub struct Layout {
    pub views: Vec<egui::Rect>,
    pub timeline: Option<egui::Rect>,
}

/// The stroke in progress: which view, and the last image point painted.
#[derive(Default)]
pub struct StrokeState {
    last: Option<(usize, Pos2)>,
    /// A stroke was begun and not yet ended.
    painting: bool,
    /// The pan key is held and a pan happened (so its release does not also press it).
    pub panned_with_key: bool,
    /// A drag of the model is under way (its later moves continue its undo step).
    placing: bool,
    /// When the wheel last moved the model (s of input time): turns within a moment of each
    /// other are one gesture, one undo step.
    wheel_placed_s: Option<f64>,
}

/// Wheel turns further apart than this (s) are separate gestures of the model.
const WHEEL_GESTURE_GAP_S: f64 = 0.6;

/// Does a wheel move of the model at `now_s` begin an undo step of its own? Not during a drag
/// (it joins the drag's), nor within [`WHEEL_GESTURE_GAP_S`] of the wheel's last move.
fn wheel_starts_step(placing: bool, last_wheel_s: Option<f64>, now_s: f64) -> bool {
    !placing && last_wheel_s.is_none_or(|t| now_s - t > WHEEL_GESTURE_GAP_S)
}

/// What the views keep between frames that is theirs alone: textures, the stroke in progress,
/// where things were drawn, the frame loader, and whether wgpu draws the overlay.
pub struct Screen {
    pub textures: Textures,
    pub stroke: StrokeState,
    /// Where the views and the timeline were drawn last frame (screen points), for tests.
    pub layout: Layout,
    pub loader: FrameLoader,
    /// True when the overlay's wgpu pipelines are registered.
    pub gpu_overlay: bool,
    /// File → New scene's form, while it is open.
    pub new_scene: Option<crate::app::panels::new_scene::NewSceneForm>,
    /// The built-in file browser, while it is open.
    pub browser: Option<crate::app::panels::browser::Browser>,
}

impl Screen {
    pub fn new(gpu_overlay: bool) -> Self {
        Self {
            textures: Textures::default(),
            stroke: StrokeState::default(),
            layout: Layout::default(),
            loader: FrameLoader::spawn(),
            gpu_overlay,
            new_scene: None,
            browser: None,
        }
    }
}

fn colour32(c: [u8; 3], a: u8) -> Color32 {
    Color32::from_rgba_unmultiplied(c[0], c[1], c[2], a)
}

/// Whether the pan key of the action table is held.
pub fn pan_key_down(ctx: &egui::Context) -> bool {
    Action::Pan
        .held_key()
        .is_some_and(|k| ctx.input(|i| i.key_down(k)))
}

/// Draws every view and turns pointer input into commands.
pub fn views(shown: &Shown, screen: &mut Screen, ui: &mut egui::Ui) {
    let Some(scene) = shown.doc.scene.clone() else {
        ui.centered_and_justified(|ui| {
            if shown.status.busy.is_some() {
                ui.spinner();
            } else {
                ui.label("Open a scene (Ctrl+O), drop a scene folder here, or open the demo.");
            }
        });
        return;
    };
    let ctx = ui.ctx().clone();
    let (view, prefs) = (shown.view, shown.prefs);
    let cams = scene.cameras.len();
    let image_size = vec2(
        scene.cameras[0].width as f32,
        scene.cameras[0].height as f32,
    );
    let transform = view.transform.unwrap_or(ViewTransform::fit(image_size));
    if view.transform.is_none() {
        shown.commands.send(AppCommand::SetTransform(transform));
    }
    let rects = grid(ui.available_rect_before_wrap(), cams, 6.0);
    screen.layout.views = rects.clone();
    let pan_key = pan_key_down(&ctx);
    if !pan_key {
        // Also where the key's release went unseen (a text field had the keyboard).
        screen.stroke.panned_with_key = false;
    }
    for (c, &rect) in rects.iter().enumerate() {
        let cam_size = vec2(
            scene.cameras[c].width as f32,
            scene.cameras[c].height as f32,
        );
        let response = ui.interact(rect, egui::Id::unique(("view", c)), Sense::click_and_drag());
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 0.0, Color32::from_gray(12));
        let image_rect = transform.image_rect(rect, cam_size);
        let uv = Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0));
        if let Some(tex) = textures::frame_texture(shown, screen, c) {
            painter.image(tex.id(), image_rect, uv, Color32::WHITE);
        }
        if let Some(tex) = textures::probability_texture(shown, screen, &ctx, c) {
            let a = (prefs.probability_opacity * 255.0) as u8;
            painter.image(tex.id(), image_rect, uv, Color32::from_white_alpha(a));
        }
        let hidden = view.hidden_in(c);
        if prefs.show_overlay && !hidden.overlay {
            if screen.gpu_overlay {
                if let Some(shape) = overlay::overlay_callback(shown, &ctx, c, rect, image_rect) {
                    painter.add(shape);
                }
            } else if let Some(tex) = overlay::overlay_cpu_texture(shown, screen, &ctx, c) {
                painter.image(tex.id(), image_rect, uv, Color32::WHITE);
            }
            if prefs.show_hidden_region
                && let Some(tex) = textures::region_texture(shown, screen, &ctx, c)
            {
                painter.image(tex.id(), image_rect, uv, Color32::WHITE);
            }
        }
        if prefs.show_seeds
            && !hidden.seeds
            && let Some(tex) = textures::seeds_texture(shown, screen, &ctx, c)
        {
            let a = (prefs.seed_opacity * 255.0) as u8;
            painter.image(tex.id(), image_rect, uv, Color32::from_white_alpha(a));
        }
        painter.text(
            rect.left_top() + vec2(6.0, 4.0),
            egui::Align2::LEFT_TOP,
            format!("{}  ·  frame {}", scene.cameras[c].name, view.frame),
            egui::FontId::proportional(13.0),
            Color32::from_gray(230),
        );
        scale::draw(shown, &painter, rect);
        if let Some(hint) = textures::stroke_hint(shown, screen, c) {
            // Where a stroke would teach the forest most: a dashed ring and a word.
            let centre = transform.to_screen(rect, cam_size, pos2(hint.x, hint.y));
            let r = hint.radius * transform.scale(rect, cam_size);
            let ring = egui::Shape::dashed_line(
                &(0..=48)
                    .map(|i| {
                        let a = i as f32 / 48.0 * std::f32::consts::TAU;
                        centre + r * vec2(a.cos(), a.sin())
                    })
                    .collect::<Vec<_>>(),
                Stroke::new(2.0, Color32::from_rgb(120, 220, 255)),
                6.0,
                4.0,
            );
            painter.extend(ring);
            painter.text(
                centre + vec2(0.0, r + 4.0),
                egui::Align2::CENTER_TOP,
                format!("paint here next? (uncertainty {:.2})", hint.uncertainty),
                egui::FontId::proportional(12.0),
                Color32::from_rgb(120, 220, 255),
            );
        }
        // What the model drawn here is, when it is not this frame's fit.
        let banner = match shown.doc.results.get(&view.frame) {
            None if shown.doc.placement.is_some() => Some((
                "NOT FITTED: showing the placed pose",
                Color32::from_rgb(255, 190, 70),
            )),
            Some(r) if r.lost => Some((
                // Before any good fit there is no good pose to hold.
                if shown
                    .doc
                    .results
                    .range(..view.frame)
                    .any(|(_, earlier)| !earlier.lost)
                {
                    "LOST: holding the last good pose"
                } else {
                    "LOST: not found from this start: place the model again (M)"
                },
                Color32::from_rgb(255, 90, 90),
            )),
            _ => None,
        };
        if let Some((text, colour)) = banner {
            painter.text(
                rect.right_top() + vec2(-6.0, 4.0),
                egui::Align2::RIGHT_TOP,
                text,
                egui::FontId::proportional(13.0),
                colour,
            );
        }
        let view_rect = ViewRect {
            camera: c,
            rect,
            cam_size,
            transform,
        };
        interact(shown, screen, &ctx, &response, &view_rect, pan_key);
        view_toggles(shown, ui, c, rect);
        // Brush cursor: a black-and-white double ring, unlike any painted seed.
        if let Some(p) = response.hover_pos()
            && matches!(view.tool, Tool::Brush | Tool::Eraser)
        {
            let r = prefs.radius_px(view.tool) * transform.scale(rect, cam_size);
            painter.circle_stroke(p, r + 1.0, Stroke::new(1.0, Color32::BLACK));
            painter.circle_stroke(p, r, Stroke::new(1.0, Color32::WHITE));
            if view.tool == Tool::Brush {
                let col = shown.doc.class_colour(view.class);
                painter.circle_filled(p, 2.5, colour32(col, 255));
            } else {
                painter.line_segment(
                    [p - vec2(3.0, 3.0), p + vec2(3.0, 3.0)],
                    Stroke::new(1.5, Color32::WHITE),
                );
                painter.line_segment(
                    [p - vec2(3.0, -3.0), p + vec2(3.0, -3.0)],
                    Stroke::new(1.5, Color32::WHITE),
                );
            }
            ctx.set_cursor_icon(egui::CursorIcon::None);
        }
    }
}

/// Under the view's title: hide this view's seeds or overlay, to see the map under them.
fn view_toggles(shown: &Shown, ui: &mut egui::Ui, camera: usize, rect: Rect) {
    let hidden = shown.view.hidden_in(camera);
    let parts = [
        (
            ViewPart::Seeds,
            "seeds",
            hidden.seeds,
            shown.prefs.show_seeds,
        ),
        (
            ViewPart::Overlay,
            "overlay",
            hidden.overlay,
            shown.prefs.show_overlay,
        ),
    ];
    let mut at = rect.left_top() + vec2(6.0, 22.0);
    for (part, label, is_hidden, globally_shown) in parts {
        let text = egui::RichText::new(label).size(11.0);
        let button = egui::Button::selectable(globally_shown && !is_hidden, text);
        let size = vec2(52.0, 18.0);
        let r = ui
            .put(Rect::from_min_size(at, size), button)
            .on_hover_text(if globally_shown {
                "Show or hide in this view only"
            } else {
                "Hidden in every view (side panel)"
            });
        if r.clicked() && globally_shown {
            shown
                .commands
                .send(AppCommand::ToggleInView { camera, part });
        }
        at.x += size.x + 4.0;
    }
}

/// One view: its camera, where it is on screen, and the shared zoom and pan.
struct ViewRect {
    camera: usize,
    rect: Rect,
    cam_size: Vec2,
    transform: ViewTransform,
}

fn interact(
    shown: &Shown,
    screen: &mut Screen,
    ctx: &egui::Context,
    response: &egui::Response,
    v: &ViewRect,
    pan_key: bool,
) {
    let send = |c: AppCommand| shown.commands.send(c);
    let (view, prefs) = (shown.view, shown.prefs);
    let (c, rect, cam_size) = (v.camera, v.rect, v.cam_size);
    let mut transform = v.transform;
    let (middle, primary, secondary, modifiers) = ctx.input(|i| {
        (
            i.pointer.button_down(egui::PointerButton::Middle),
            i.pointer.primary_down(),
            i.pointer.secondary_down(),
            i.modifiers,
        )
    });
    // Pan: middle drag, or a drag with the pan key held.
    if response.dragged() && (middle || pan_key) {
        transform.pan(rect, cam_size, response.drag_delta());
        send(AppCommand::SetTransform(transform));
        if pan_key {
            screen.stroke.panned_with_key = true;
        }
        return;
    }
    let place = |pan: Vec2, turn: glam::DVec3, depth_mm: f64, new_step: bool| {
        if let Some(moved) = place::moved_placement(shown.doc, view.frame, c, pan, turn, depth_mm) {
            send(AppCommand::Place {
                affine: moved,
                new_step,
            });
        }
    };
    let now_s = ctx.input(|i| i.time);
    // Wheel: zoom about the cursor; Shift+wheel: brush size; in Place mode, depth.
    if response.hovered() {
        let scroll = ctx.input(|i| i.smooth_scroll_delta);
        let amount = scroll.x + scroll.y;
        if amount != 0.0 {
            if modifiers.shift {
                send(AppCommand::ResizeBrush(if amount > 0.0 {
                    1.1
                } else {
                    1.0 / 1.1
                }));
            } else if view.tool == Tool::Place && shown.doc.placement.is_some() {
                // During a drag the wheel's moves join the drag's step (egui spreads a notch
                // over several frames, so they can outlast the drag's first frames too).
                let stroke = &mut screen.stroke;
                let new_step = wheel_starts_step(stroke.placing, stroke.wheel_placed_s, now_s);
                stroke.wheel_placed_s = Some(now_s);
                place(
                    Vec2::ZERO,
                    glam::DVec3::ZERO,
                    -(amount as f64) * 0.05,
                    new_step,
                );
            } else if let Some(p) = response.hover_pos() {
                transform.zoom_about(rect, cam_size, p, (amount * 0.002).exp());
                send(AppCommand::SetTransform(transform));
            }
        }
    }
    let Some(pointer) = response.interact_pointer_pos().or(response.hover_pos()) else {
        return;
    };
    let image_pt = transform.to_image(rect, cam_size, pointer);
    match view.tool {
        Tool::Brush | Tool::Eraser => {
            let painting = (response.dragged() || response.drag_started() || response.clicked())
                && primary | response.clicked()
                && !middle
                && !pan_key;
            let stroke = &mut screen.stroke;
            if painting {
                let dab = if view.tool == Tool::Eraser {
                    Dab::Erase
                } else {
                    Dab::Paint {
                        value: shown.doc.seed_value(view.class),
                        overwrite: view.overwrite,
                    }
                };
                if !stroke.painting {
                    send(AppCommand::BeginStroke);
                    stroke.painting = true;
                    stroke.last = None;
                }
                let from = match stroke.last {
                    Some((last_view, p)) if last_view == c => p,
                    _ => image_pt,
                };
                send(AppCommand::PaintLine {
                    camera: c,
                    frame: view.frame,
                    from: (from.x - 0.5, from.y - 0.5),
                    to: (image_pt.x - 0.5, image_pt.y - 0.5),
                    radius_px: prefs.radius_px(view.tool),
                    dab,
                });
                stroke.last = Some((c, image_pt));
            }
            if (response.drag_stopped() || response.clicked() || !primary) && stroke.painting {
                send(AppCommand::EndStroke);
                stroke.painting = false;
                stroke.last = None;
            }
        }
        Tool::Place => {
            // Nothing to move yet (the tool was already chosen when the scene came): the
            // first drag puts the model in front of the camera, as choosing the tool does.
            if response.drag_started() && shown.doc.state_at(view.frame).is_none() {
                shown.commands.act(Action::Place);
            }
            let stroke = &mut screen.stroke;
            if response.dragged() && shown.doc.placement.is_some() {
                let d = response.drag_delta() / transform.scale(rect, cam_size);
                // A drag that starts is a step of its own even when no frame saw the buttons
                // up between it and the last one (a release and a press in one slow frame).
                let new_step = !stroke.placing || response.drag_started();
                // Radians per screen pixel of drag: x turns about the view's vertical axis, y
                // about its horizontal one; with Shift, x rolls in the image plane (a kidney
                // lying diagonally could not be matched before).
                let (ax, ay) = (d.x as f64 * 0.01, d.y as f64 * 0.01);
                if (secondary || modifiers.command) && modifiers.shift {
                    place(Vec2::ZERO, glam::DVec3::new(0.0, 0.0, ax), 0.0, new_step);
                    stroke.placing = true;
                } else if secondary || modifiers.command {
                    place(Vec2::ZERO, glam::DVec3::new(-ay, ax, 0.0), 0.0, new_step);
                    stroke.placing = true;
                } else if primary {
                    place(d, glam::DVec3::ZERO, 0.0, new_step);
                    stroke.placing = true;
                }
                // A drag is a gesture of its own, apart from wheel turns before and after.
                stroke.wheel_placed_s = None;
            }
            // Ended with the button (every view runs this; only one is dragged).
            if !(primary || secondary) {
                stroke.placing = false;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::wheel_starts_step;

    /// A run of wheel turns is one step; a pause, or none before, begins one; during a drag
    /// the wheel never does.
    #[test]
    fn wheel_turns_are_one_step_unless_apart_and_join_a_drag() {
        assert!(wheel_starts_step(false, None, 3.0));
        assert!(!wheel_starts_step(false, Some(2.9), 3.0));
        assert!(wheel_starts_step(false, Some(2.0), 3.0));
        assert!(!wheel_starts_step(true, None, 3.0));
        assert!(!wheel_starts_step(true, Some(1.0), 3.0));
    }
}
