//! The camera views: the frame, the probability or uncertainty layer, the seeds, the fitted
//! overlay and the brush cursor, in a grid with one shared zoom and pan. Painting, erasing and
//! placing the model happen here; what they change lives in the app state.

use super::overlay3d::{self, CameraUniform, OverlayCallback, StyleUniform, Vertex};
use super::view::{ViewTransform, grid};
use super::{EndofuseApp, Layer, Tool};
use crate::geometry::Affine;
use crate::overlay::{BACKGROUND_SEED_COLOUR, structure_colour};
use crate::scene::{SEED_BACKGROUND, SEED_NONE};
use crate::strokes::Dab;
use eframe::egui_wgpu;
use egui::{
    Color32, ColorImage, Pos2, Rect, Sense, Stroke, TextureHandle, TextureOptions, Vec2, pos2, vec2,
};
use glam::{DMat3, DVec3};
use std::sync::Arc;

/// Textures of what the views show, re-uploaded only when what they show changes.
#[derive(Default)]
pub struct Textures {
    frames: Vec<Option<((usize, usize), TextureHandle)>>,
    /// Frame asked of the loader per camera, not yet arrived.
    requested: Vec<Option<usize>>,
    seeds: Vec<Option<((usize, u64), TextureHandle)>>,
    probability: Vec<Option<TextureHandle>>,
    pub probability_key: Option<(usize, Layer)>,
    overlay_cpu: Vec<Option<(usize, TextureHandle)>>,
}

/// The stroke in progress: which view, and the last image point painted.
#[derive(Default)]
pub struct StrokeState {
    last: Option<(usize, Pos2)>,
    /// Space held and a pan happened (so Space does not also toggle play).
    panned_with_space: bool,
}

fn slot<T>(v: &mut Vec<Option<T>>, i: usize) -> &mut Option<T> {
    if v.len() <= i {
        v.resize_with(i + 1, || None);
    }
    &mut v[i]
}

/// An RGBA (unmultiplied) texture of `size` pixels.
fn rgba_texture(
    ctx: &egui::Context,
    name: String,
    size: [usize; 2],
    rgba: &[u8],
    options: TextureOptions,
) -> TextureHandle {
    ctx.load_texture(
        name,
        ColorImage::from_rgba_unmultiplied(size, rgba),
        options,
    )
}

fn colour32(c: [u8; 3], a: u8) -> Color32 {
    Color32::from_rgba_unmultiplied(c[0], c[1], c[2], a)
}

/// Colour of forest class `k` (0 = background/tools) for seeds and probability maps.
pub fn class_colour(app: &EndofuseApp, k: usize) -> [u8; 3] {
    if k == 0 {
        return BACKGROUND_SEED_COLOUR;
    }
    let (Some(classes), Some(scene)) = (&app.classes, &app.scene) else {
        return [255, 255, 255];
    };
    let label = classes.labels.get(k).copied().unwrap_or(0);
    let i = scene
        .structures
        .iter()
        .position(|s| s.label == label)
        .unwrap_or(k);
    structure_colour(i)
}

/// Seed value painted for forest class `k`.
pub fn seed_value(app: &EndofuseApp, k: usize) -> u8 {
    if k == 0 {
        return SEED_BACKGROUND;
    }
    app.classes
        .as_ref()
        .and_then(|c| c.labels.get(k).copied())
        .unwrap_or(SEED_BACKGROUND)
}

/// The current frame's texture of camera `c`; while a new frame decodes on the loader
/// thread, the last one shown stays up.
fn frame_texture(app: &mut EndofuseApp, c: usize) -> Option<TextureHandle> {
    let scene = app.scene.clone()?;
    let key = (c, app.frame);
    let current = slot(&mut app.textures.frames, c).clone();
    if current.as_ref().is_none_or(|(k, _)| *k != key)
        && *slot(&mut app.textures.requested, c) != Some(app.frame)
    {
        app.loader.request(&scene, c, app.frame);
        *slot(&mut app.textures.requested, c) = Some(app.frame);
    }
    current.map(|(_, t)| t)
}

/// Uploads frames the loader finished (those still wanted).
pub fn receive_frames(app: &mut EndofuseApp, ctx: &egui::Context) {
    for l in app.loader.drain() {
        if *slot(&mut app.textures.requested, l.camera) == Some(l.frame) {
            *slot(&mut app.textures.requested, l.camera) = None;
        }
        if l.frame != app.frame {
            continue;
        }
        match l.image {
            Ok(img) => {
                let image = ColorImage::from_rgb(
                    [img.width() as usize, img.height() as usize],
                    img.as_raw(),
                );
                let tex =
                    ctx.load_texture(format!("frame-{}", l.camera), image, TextureOptions::LINEAR);
                *slot(&mut app.textures.frames, l.camera) = Some(((l.camera, l.frame), tex));
                ctx.request_repaint();
            }
            Err(e) => {
                app.error = Some(e);
                app.playing = false;
            }
        }
    }
}

/// True when every view shows the current frame.
pub fn frames_ready(app: &EndofuseApp) -> bool {
    let Some(scene) = &app.scene else {
        return false;
    };
    (0..scene.cameras.len()).all(|c| {
        app.textures
            .frames
            .get(c)
            .and_then(|f| f.as_ref())
            .is_some_and(|(k, _)| *k == (c, app.frame))
    })
}

fn seeds_texture(app: &mut EndofuseApp, ctx: &egui::Context, c: usize) -> Option<TextureHandle> {
    let key = (app.frame, app.editor.revision);
    if let Some((k, tex)) = slot(&mut app.textures.seeds, c)
        && *k == key
    {
        return Some(tex.clone());
    }
    let layer = app.editor.layer(c, app.frame)?.clone();
    let classes = app.classes.clone()?;
    let colours: Vec<(u8, [u8; 3])> = (0..classes.len())
        .map(|k| (seed_value(app, k), class_colour(app, k)))
        .collect();
    let mut rgba = vec![0u8; layer.data.len() * 4];
    for (px, &v) in rgba.chunks_exact_mut(4).zip(&layer.data) {
        if v == SEED_NONE {
            continue;
        }
        if let Some((_, c)) = colours.iter().find(|(s, _)| *s == v) {
            px.copy_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    let tex = rgba_texture(
        ctx,
        format!("seeds-{c}"),
        [layer.width, layer.height],
        &rgba,
        TextureOptions::NEAREST,
    );
    *slot(&mut app.textures.seeds, c) = Some((key, tex.clone()));
    Some(tex)
}

/// Probability of the chosen class (in its colour) or uncertainty (dark → bright orange).
fn probability_texture(
    app: &mut EndofuseApp,
    ctx: &egui::Context,
    c: usize,
) -> Option<TextureHandle> {
    if app.layer == Layer::Image {
        return None;
    }
    let maps = app.probabilities.get(&app.frame)?.clone();
    let key = (app.frame, app.layer);
    if app.textures.probability_key != Some(key) {
        app.textures.probability.clear();
        app.textures.probability_key = Some(key);
    }
    if let Some(tex) = slot(&mut app.textures.probability, c) {
        return Some(tex.clone());
    }
    let m = maps.get(c)?;
    let rgba: Vec<u8> = match app.layer {
        Layer::Probability(k) => {
            let col = class_colour(app, k);
            m.class_plane(k.min(m.classes - 1))
                .data
                .iter()
                .flat_map(|&p| [col[0], col[1], col[2], (p.clamp(0.0, 1.0) * 255.0) as u8])
                .collect()
        }
        _ => m
            .uncertainty()
            .data
            .iter()
            .flat_map(|&u| {
                let u = u.clamp(0.0, 1.0);
                [
                    255,
                    (80.0 + 175.0 * u) as u8,
                    (40.0 * (1.0 - u)) as u8,
                    (u * 255.0) as u8,
                ]
            })
            .collect(),
    };
    let tex = rgba_texture(
        ctx,
        format!("prob-{c}"),
        [m.width, m.height],
        &rgba,
        TextureOptions::LINEAR,
    );
    *slot(&mut app.textures.probability, c) = Some(tex.clone());
    Some(tex)
}

/// Without wgpu: the tracked labels drawn on the CPU (the same look, from the fit's masks).
fn overlay_cpu_texture(
    app: &mut EndofuseApp,
    ctx: &egui::Context,
    c: usize,
) -> Option<TextureHandle> {
    let t = app.frame;
    if let Some((k, tex)) = slot(&mut app.textures.overlay_cpu, c)
        && *k == t
    {
        return Some(tex.clone());
    }
    let (scene, model) = (app.scene.clone()?, app.model.clone()?);
    let state = app.state_at(t)?;
    let rendered = crate::fit::tracker::render_state(&scene, &model, &state);
    let cam = &scene.cameras[c];
    let mut img = image::RgbImage::new(cam.width, cam.height);
    crate::overlay::draw_fit(&mut img, &scene, &rendered.labels, &rendered.hidden, c, 1.0);
    let rgba: Vec<u8> = img
        .pixels()
        .flat_map(|p| {
            let a = if p.0 == [0, 0, 0] { 0 } else { 150 };
            [p.0[0], p.0[1], p.0[2], a]
        })
        .collect();
    let size = [cam.width as usize, cam.height as usize];
    let tex = rgba_texture(
        ctx,
        format!("overlay-{c}"),
        size,
        &rgba,
        TextureOptions::LINEAR,
    );
    *slot(&mut app.textures.overlay_cpu, c) = Some((t, tex.clone()));
    Some(tex)
}

/// The wgpu overlay of camera `c` in `rect`, from the state at the current frame.
fn overlay_callback(
    app: &EndofuseApp,
    ctx: &egui::Context,
    c: usize,
    rect: Rect,
    image_rect: Rect,
) -> Option<egui::Shape> {
    let (scene, model) = (app.scene.as_ref()?, app.model.as_ref()?);
    let state = app.state_at(app.frame)?;
    let cam = scene.cameras.get(c)?;
    let intr = state.intrinsics.get(c)?;
    let deformed = model.deformed(&state.shape);
    let posed = model.posed(&state.affine, &deformed);
    let mut vertices = Vec::new();
    let (mut visible, mut hidden) = (Vec::new(), Vec::new());
    let (mut near, mut far) = (f64::INFINITY, 0f64);
    for (i, (s, pts)) in model.structures.iter().zip(&posed).enumerate() {
        let base = vertices.len() as u32;
        let id = (s.part + 1) as f32;
        for &p in pts {
            let q = cam.extrinsics.apply(p);
            near = near.min(q.z);
            far = far.max(q.z);
            vertices.push(Vertex {
                position_mm: [q.x as f32, q.y as f32, q.z as f32],
                id,
            });
        }
        let list = if model.structures[i].visible {
            &mut visible
        } else {
            &mut hidden
        };
        for f in &s.faces {
            list.extend(f.iter().map(|&v| base + v));
        }
    }
    if vertices.is_empty() || !near.is_finite() {
        return None;
    }
    let ppp = ctx.pixels_per_point();
    let target_px = [
        (rect.width() * ppp).round().max(1.0) as u32,
        (rect.height() * ppp).round().max(1.0) as u32,
    ];
    let scale = image_rect.width() / cam.width as f32 * ppp;
    let origin = (image_rect.min - rect.min) * ppp;
    let mut style = StyleUniform::default();
    for (i, s) in scene
        .structures
        .iter()
        .enumerate()
        .take(overlay3d::MAX_STRUCTURES)
    {
        let col = structure_colour(i);
        let st = app.styles.get(i).copied().unwrap_or(super::StructureStyle {
            shown: true,
            opacity: 0.3,
        });
        let opacity = if s.visible {
            st.opacity
        } else {
            st.opacity.max(0.15)
        };
        style.colours[i] = [
            col[0] as f32 / 255.0,
            col[1] as f32 / 255.0,
            col[2] as f32 / 255.0,
            opacity,
        ];
        style.shown[i] = [
            if st.shown && app.prefs.show_overlay {
                1.0
            } else {
                0.0
            },
            1.0,
            0.0,
            0.0,
        ];
    }
    let callback = OverlayCallback {
        key: egui::Id::unique(("overlay", c)).value(),
        target_px,
        camera: CameraUniform {
            k: [
                intr.fx as f32,
                intr.fy as f32,
                intr.cx as f32,
                intr.cy as f32,
            ],
            distortion: [
                intr.k1 as f32,
                intr.k2 as f32,
                intr.p1 as f32,
                intr.p2 as f32,
            ],
            // The camera's pixel centres are integers; the texture's pixel i spans [i, i + 1).
            view: [scale, origin.x + 0.5 * scale, origin.y + 0.5 * scale, 0.0],
            target: [
                target_px[0] as f32,
                target_px[1] as f32,
                (near * 0.5) as f32,
                (far * 1.5 + 1.0) as f32,
            ],
        },
        style,
        vertices: Arc::new(vertices),
        visible_indices: Arc::new(visible),
        hidden_indices: Arc::new(hidden),
    };
    Some(egui::Shape::Callback(
        egui_wgpu::Callback::new_paint_callback(rect, callback),
    ))
}

/// Moves the placed model: `pan_px` in the view plane of camera `c`, `rotate` (radians about
/// the camera's y and x axes, around the model's centre), `depth_mm` along the view ray.
fn move_model(app: &mut EndofuseApp, c: usize, pan_px: Vec2, rotate: Vec2, depth_mm: f64) {
    let (Some(scene), Some(model)) = (app.scene.clone(), app.model.clone()) else {
        return;
    };
    let Some(state) = app.state_at(app.frame) else {
        return;
    };
    let cam = &scene.cameras[c];
    let deformed = model.deformed(&state.shape);
    let posed = model.posed(&state.affine, &deformed);
    let anchor = &posed[model.anchor];
    let centre = crate::geometry::mesh::vertex_mean(anchor);
    let centre_cam = cam.extrinsics.apply(centre);
    let to_ref = cam.extrinsics.rotation.transpose();
    let intr = state.intrinsics.get(c).copied().unwrap_or(cam.intrinsics);
    let z = centre_cam.z.max(1.0);
    let shift_cam = DVec3::new(
        pan_px.x as f64 * z / intr.fx,
        pan_px.y as f64 * z / intr.fy,
        0.0,
    ) + centre_cam.normalize_or_zero() * depth_mm;
    let shift = to_ref * shift_cam;
    let r_cam = crate::geometry::pose::rotation_from_vector(DVec3::new(
        -(rotate.y as f64),
        rotate.x as f64,
        0.0,
    ));
    let r: DMat3 = to_ref * r_cam * cam.extrinsics.rotation;
    let linear = r * state.affine.linear();
    let t = r * (state.affine.translation_mm() - centre) + centre + shift;
    let moved = Affine::from_linear_translation(linear, t);
    if moved.is_finite() {
        app.placement = Some(moved);
        // A manual move replaces this frame's fit: the user will fit again from here.
        app.results.remove(&app.frame);
        app.textures.overlay_cpu.clear();
    }
}

/// Draws every view and handles painting, panning, zooming and placing.
pub fn views(app: &mut EndofuseApp, ui: &mut egui::Ui) {
    let Some(scene) = app.scene.clone() else {
        ui.centered_and_justified(|ui| {
            if app.busy.is_some() {
                ui.spinner();
            } else {
                ui.label("Open a scene (Ctrl+O), drop a scene folder here, or open the demo.");
            }
        });
        return;
    };
    let ctx = ui.ctx().clone();
    let cams = scene.cameras.len();
    let image_size = vec2(
        scene.cameras[0].width as f32,
        scene.cameras[0].height as f32,
    );
    let transform = *app.transform.get_or_insert(ViewTransform::fit(image_size));
    let rects = grid(ui.available_rect_before_wrap(), cams, 6.0);
    app.layout.views = rects.clone();
    let space = ctx.input(|i| i.key_down(egui::Key::Space));
    if !space {
        app.stroke.panned_with_space = false;
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
        if let Some(tex) = frame_texture(app, c) {
            painter.image(tex.id(), image_rect, uv, Color32::WHITE);
        }
        if let Some(tex) = probability_texture(app, &ctx, c) {
            let a = (app.prefs.probability_opacity * 255.0) as u8;
            painter.image(tex.id(), image_rect, uv, Color32::from_white_alpha(a));
        }
        if app.prefs.show_overlay {
            if app.gpu_overlay {
                if let Some(shape) = overlay_callback(app, &ctx, c, rect, image_rect) {
                    painter.add(shape);
                }
            } else if let Some(tex) = overlay_cpu_texture(app, &ctx, c) {
                painter.image(tex.id(), image_rect, uv, Color32::WHITE);
            }
        }
        if app.prefs.show_seeds
            && let Some(tex) = seeds_texture(app, &ctx, c)
        {
            let a = (app.prefs.seed_opacity * 255.0) as u8;
            painter.image(tex.id(), image_rect, uv, Color32::from_white_alpha(a));
        }
        painter.text(
            rect.left_top() + vec2(6.0, 4.0),
            egui::Align2::LEFT_TOP,
            format!("{}  ·  frame {}", scene.cameras[c].name, app.frame),
            egui::FontId::proportional(13.0),
            Color32::from_gray(230),
        );
        if let Some(r) = app.results.get(&app.frame)
            && r.lost
        {
            painter.text(
                rect.right_top() + vec2(-6.0, 4.0),
                egui::Align2::RIGHT_TOP,
                "LOST: holding the last good pose",
                egui::FontId::proportional(13.0),
                Color32::from_rgb(255, 90, 90),
            );
        }
        interact(app, &ctx, &response, c, rect, cam_size, space);
        // Brush cursor: a black-and-white double ring, unlike any painted seed.
        if let Some(p) = response.hover_pos()
            && matches!(app.tool, Tool::Brush | Tool::Eraser)
        {
            let r_px = if app.tool == Tool::Eraser {
                app.prefs.eraser_px
            } else {
                app.prefs.brush_px
            };
            let r = r_px * transform.scale(rect, cam_size);
            painter.circle_stroke(p, r + 1.0, Stroke::new(1.0, Color32::BLACK));
            painter.circle_stroke(p, r, Stroke::new(1.0, Color32::WHITE));
            if app.tool == Tool::Brush {
                let col = class_colour(app, app.class);
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

fn interact(
    app: &mut EndofuseApp,
    ctx: &egui::Context,
    response: &egui::Response,
    c: usize,
    rect: Rect,
    cam_size: Vec2,
    space: bool,
) {
    let Some(mut transform) = app.transform else {
        return;
    };
    let (middle, primary, secondary, modifiers) = ctx.input(|i| {
        (
            i.pointer.button_down(egui::PointerButton::Middle),
            i.pointer.primary_down(),
            i.pointer.secondary_down(),
            i.modifiers,
        )
    });
    // Pan: middle drag, or Space + drag.
    if response.dragged() && (middle || space) {
        transform.pan(rect, cam_size, response.drag_delta());
        app.transform = Some(transform);
        if space && !app.stroke.panned_with_space {
            app.stroke.panned_with_space = true;
            // The Space press that started this pan also toggled playing: take that back.
            app.playing = !app.playing;
        }
        return;
    }
    // Wheel: zoom about the cursor; Shift+wheel: brush size; in Place mode, depth.
    if response.hovered() {
        let scroll = ctx.input(|i| i.smooth_scroll_delta);
        let amount = scroll.x + scroll.y;
        if amount != 0.0 {
            if modifiers.shift {
                app.resize_brush(if amount > 0.0 { 1.1 } else { 1.0 / 1.1 });
            } else if app.tool == Tool::Place && app.placement.is_some() {
                move_model(app, c, Vec2::ZERO, Vec2::ZERO, -(amount as f64) * 0.05);
            } else if let Some(p) = response.hover_pos() {
                transform.zoom_about(rect, cam_size, p, (amount * 0.002).exp());
                app.transform = Some(transform);
            }
        }
    }
    let Some(pointer) = response.interact_pointer_pos().or(response.hover_pos()) else {
        return;
    };
    let image_pt = transform.to_image(rect, cam_size, pointer);
    match app.tool {
        Tool::Brush | Tool::Eraser => {
            let painting = (response.dragged() || response.drag_started() || response.clicked())
                && primary | response.clicked()
                && !middle
                && !space;
            if painting {
                let dab = if app.tool == Tool::Eraser {
                    Dab::Erase
                } else {
                    Dab::Paint {
                        value: seed_value(app, app.class),
                        overwrite: app.overwrite,
                    }
                };
                let r = if app.tool == Tool::Eraser {
                    app.prefs.eraser_px
                } else {
                    app.prefs.brush_px
                };
                if !app.editor.in_stroke() {
                    app.editor.begin_stroke();
                    app.stroke.last = None;
                }
                let from = match app.stroke.last {
                    Some((view, p)) if view == c => p,
                    _ => image_pt,
                };
                app.editor.line(
                    c,
                    app.frame,
                    (from.x - 0.5, from.y - 0.5),
                    (image_pt.x - 0.5, image_pt.y - 0.5),
                    r,
                    dab,
                );
                app.stroke.last = Some((c, image_pt));
            }
            if (response.drag_stopped() || response.clicked() || !primary) && app.editor.in_stroke()
            {
                app.editor.end_stroke();
                app.stroke.last = None;
            }
        }
        Tool::Place => {
            if response.dragged() && app.placement.is_some() {
                let d = response.drag_delta() / transform.scale(rect, cam_size);
                if secondary || modifiers.command {
                    move_model(app, c, Vec2::ZERO, d * 0.01, 0.0);
                } else if primary {
                    move_model(app, c, d, Vec2::ZERO, 0.0);
                }
            }
        }
    }
}
