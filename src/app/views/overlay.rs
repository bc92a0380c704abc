//! The fitted overlay of one view: drawn by wgpu (the meshes projected with the camera's own
//! distortion, hidden structures through the kidney), or on the CPU from the fit's label
//! images where no wgpu renderer runs.

use super::Screen;
use super::textures::{rgba_texture, slot};
use crate::app::Shown;
use crate::app::overlay3d::{self, CameraUniform, OverlayCallback, StyleUniform, Vertex};
use crate::app::state::StructureStyle;
use crate::overlay::structure_colour;
use eframe::egui_wgpu;
use egui::{Rect, TextureHandle, TextureOptions};
use std::sync::Arc;

/// Without wgpu: the tracked labels drawn on the CPU (the same look, from the fit's masks).
pub(super) fn overlay_cpu_texture(
    shown: &Shown,
    screen: &mut Screen,
    ctx: &egui::Context,
    c: usize,
) -> Option<TextureHandle> {
    let t = shown.view.frame;
    if let Some((k, tex)) = slot(&mut screen.textures.overlay_cpu, c)
        && *k == t
    {
        return Some(tex.clone());
    }
    let (scene, model) = (shown.doc.scene.as_ref()?, shown.doc.model.as_ref()?);
    let state = shown.doc.state_at(t)?;
    let rendered = crate::fit::tracker::render_state(scene, model, &state);
    let cam = &scene.cameras[c];
    let mut img = image::RgbImage::new(cam.width, cam.height);
    crate::overlay::draw_fit(&mut img, scene, &rendered.labels, &rendered.hidden, c, 1.0);
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
    *slot(&mut screen.textures.overlay_cpu, c) = Some((t, tex.clone()));
    Some(tex)
}

/// The wgpu overlay of camera `c` in `rect`, from the state at the current frame.
pub(super) fn overlay_callback(
    shown: &Shown,
    ctx: &egui::Context,
    c: usize,
    rect: Rect,
    image_rect: Rect,
) -> Option<egui::Shape> {
    let (scene, model) = (shown.doc.scene.as_ref()?, shown.doc.model.as_ref()?);
    let state = shown.doc.state_at(shown.view.frame)?;
    let cam = scene.cameras.get(c)?;
    let ppp = ctx.pixels_per_point();
    let target_px = [
        (rect.width() * ppp).round().max(1.0) as u32,
        (rect.height() * ppp).round().max(1.0) as u32,
    ];
    let placement = TargetPlacement {
        target_px,
        scale: image_rect.width() / cam.width as f32 * ppp,
        origin_px: ((image_rect.min - rect.min) * ppp).to_pos2(),
    };
    let mut style = StyleUniform::default();
    for (i, s) in scene
        .structures
        .iter()
        .enumerate()
        .take(overlay3d::MAX_STRUCTURES)
    {
        let col = structure_colour(i);
        let st = shown.view.styles.get(i).copied().unwrap_or(StructureStyle {
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
            if st.shown && shown.prefs.show_overlay {
                1.0
            } else {
                0.0
            },
            1.0,
            0.0,
            0.0,
        ];
    }
    let key = egui::Id::unique(("overlay", c)).value();
    let callback = mesh_callback(scene, model, &state, c, &placement, style, key)?;
    Some(egui::Shape::Callback(
        egui_wgpu::Callback::new_paint_callback(rect, callback),
    ))
}

/// Where camera pixels land in the overlay's off-screen target: the target's size, target
/// pixels per camera pixel, and the target position of the camera image's corner (0, 0).
#[derive(Debug, Clone, Copy)]
pub struct TargetPlacement {
    pub target_px: [u32; 2],
    pub scale: f32,
    pub origin_px: egui::Pos2,
}

/// The overlay of camera `c` for a fitted state: every structure's posed mesh in the camera's
/// frame, the camera's intrinsics for the shader's projection (the same eq. 10 as
/// `Intrinsics::project`, in f32) and where its image sits in the target.
pub fn mesh_callback(
    scene: &crate::scene::Scene,
    model: &crate::fit::Model,
    state: &crate::fit::FitState,
    c: usize,
    placement: &TargetPlacement,
    style: StyleUniform,
    key: u64,
) -> Option<OverlayCallback> {
    let cam = scene.cameras.get(c)?;
    let intr = state.intrinsics.get(c)?;
    let deformed = model.deformed(&state.shape);
    let posed = model.posed(&state.affine, &deformed);
    let mut vertices = Vec::new();
    let (mut visible, mut hidden) = (Vec::new(), Vec::new());
    let (mut near, mut far) = (f64::INFINITY, 0f64);
    for (s, pts) in model.structures.iter().zip(&posed) {
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
        let list = if s.visible { &mut visible } else { &mut hidden };
        for f in &s.faces {
            list.extend(f.iter().map(|&v| base + v));
        }
    }
    if vertices.is_empty() || !near.is_finite() {
        return None;
    }
    let (scale, origin, target_px) = (placement.scale, placement.origin_px, placement.target_px);
    Some(OverlayCallback {
        key,
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
    })
}
