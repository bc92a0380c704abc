//! Placing the model by hand in a view: a drag moves it in the view plane, a right- or
//! Ctrl-drag turns it about its centre, a Shift+right-drag rolls it in the image plane, the
//! wheel moves it along the view ray.

use crate::app::state::Document;
use crate::geometry::Affine;
use egui::Vec2;
use glam::{DMat3, DVec3};

/// The model drawn at the current frame moved by hand: `pan_px` in the view plane of camera
/// `c`, `turn_rad` (a rotation vector in camera `c`'s axes, radians, around the model's centre),
/// `depth_mm` along the view ray. None without a model to move, or for a move that would not be
/// finite.
pub fn moved_placement(
    doc: &Document,
    frame: usize,
    c: usize,
    pan_px: Vec2,
    turn_rad: DVec3,
    depth_mm: f64,
) -> Option<Affine> {
    let (scene, model) = (doc.scene.as_ref()?, doc.model.as_ref()?);
    let state = doc.state_at(frame)?;
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
    let r_cam = crate::geometry::pose::rotation_from_vector(turn_rad);
    let r: DMat3 = to_ref * r_cam * cam.extrinsics.rotation;
    let linear = r * state.affine.linear();
    let t = r * (state.affine.translation_mm() - centre) + centre + shift;
    let moved = Affine::from_linear_translation(linear, t);
    moved.is_finite().then_some(moved)
}
