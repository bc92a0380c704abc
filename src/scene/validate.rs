//! Validation of what scene.json gives by value: camera and structure names, camera entries
//! (size, intrinsics, rotation, frames template), the initial pose's affine, and shape
//! catalog folders. Each check has its own error type carrying the offending values; the
//! scene turns them into one-line [`InputError`]s naming scene.json (or the catalog file).

use super::format::{CameraEntry, FramesEntry};
use super::template::{PathTemplate, TemplateError};
use crate::error::InputError;
use crate::geometry::camera::IntrinsicsError;
use crate::geometry::mesh_io::load_mesh;
use crate::geometry::pose::is_rotation;
use crate::geometry::{Affine, Camera, Extrinsics, Intrinsics, Mesh};
use glam::{DMat3, DVec3};
use std::path::{Path, PathBuf};

/// A camera or structure name that cannot name an output folder.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "name '{name}' must be 1–64 letters, digits, '_' or '-' (and not 'background'): it names output folders"
)]
pub struct NameError {
    pub name: String,
}

/// A camera entry that cannot be used; `index` is its position in `cameras`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cameras[{index}] ('{name}'): {problem}")]
pub struct CameraError {
    pub index: usize,
    pub name: String,
    #[source]
    pub problem: CameraProblem,
}

/// What is wrong with a camera entry.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraProblem {
    #[error(transparent)]
    Name(NameError),
    #[error("image size {width_px}×{height_px} must be positive (and at most 16384)")]
    Size { width_px: i64, height_px: i64 },
    #[error(transparent)]
    Intrinsics(IntrinsicsError),
    #[error("'rotation' is not a rotation matrix (rows must be orthonormal with determinant +1)")]
    NotRotation,
    #[error("'translation' must be finite and under 100 m (100000 mm) long")]
    NonFiniteTranslation,
    #[error("frames: {0}")]
    Frames(#[source] TemplateError),
    /// `template` as written: a camera needs one file per frame, or a video.
    #[error(
        "frames '{template}' has no {{frame}} placeholder and is not a video file (.mp4, .mov, .avi, .mkv, .m4v, .webm)"
    )]
    NoFramePlaceholder { template: String },
    #[error("frames.crop {crop:?} needs a positive width and height and a non-negative corner")]
    Crop { crop: [i64; 4] },
    #[error("frames.crop is {crop_w}×{crop_h} but the camera is {width}×{height}")]
    CropSize {
        crop_w: i64,
        crop_h: i64,
        width: i64,
        height: i64,
    },
}

/// An `affine` (q1…q12 of eq. 2) the fit cannot start from.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AffineError {
    #[error("'affine' needs 12 numbers (q1…q12 of eq. 2), got {count}")]
    Length { count: usize },
    #[error("'affine' has a non-finite number")]
    NonFinite,
    /// `determinant` of the linear part: a mirror (negative) or a collapse (near zero).
    #[error(
        "'affine' linear part has determinant {determinant:.3e}: it must preserve orientation and not collapse the model"
    )]
    Degenerate { determinant: f64 },
    #[error(
        "'affine' scales the model by more than 100× (a linear entry of {largest:.3e}): meshes and poses are in millimetres"
    )]
    Scale { largest: f64 },
    #[error("'affine' moves the model {translation_mm:.3e} mm, more than 100 m")]
    Far { translation_mm: f64 },
}

/// Cameras and structures name output folders, so their names must be safe as folder names.
pub(super) fn check_name(name: &str) -> Result<(), NameError> {
    if name.is_empty()
        || name.len() > 64
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        || name == "background"
    {
        return Err(NameError {
            name: name.to_string(),
        });
    }
    Ok(())
}

/// Where a camera's frames come from, as scene.json says it.
#[derive(Debug, Clone, PartialEq)]
pub enum FramesSpec {
    Sequence(PathTemplate),
    /// A video file (relative to scene.json) and, for one view of a side-by-side video, the
    /// rectangle of that view.
    Video {
        path: String,
        crop: Option<crate::video::Crop>,
    },
}

/// The camera entry `index` of scene.json as a [`Camera`] and its frames.
pub(super) fn validate_camera(
    c: &CameraEntry,
    index: usize,
) -> Result<(Camera, FramesSpec), CameraError> {
    let bad = |problem: CameraProblem| CameraError {
        index,
        name: c.name.clone(),
        problem,
    };
    check_name(&c.name).map_err(|e| bad(CameraProblem::Name(e)))?;
    if c.width <= 0 || c.height <= 0 || c.width > 16384 || c.height > 16384 {
        return Err(bad(CameraProblem::Size {
            width_px: c.width,
            height_px: c.height,
        }));
    }
    let intrinsics = Intrinsics {
        fx: c.fx,
        fy: c.fy,
        cx: c.cx,
        cy: c.cy,
        k1: c.k1,
        k2: c.k2,
        p1: c.p1,
        p2: c.p2,
        k3: c.k3,
    };
    intrinsics
        .check_plausible(c.width as u32, c.height as u32)
        .map_err(|e| bad(CameraProblem::Intrinsics(e)))?;
    let r = DMat3::from_cols(
        DVec3::new(c.rotation[0][0], c.rotation[1][0], c.rotation[2][0]),
        DVec3::new(c.rotation[0][1], c.rotation[1][1], c.rotation[2][1]),
        DVec3::new(c.rotation[0][2], c.rotation[1][2], c.rotation[2][2]),
    );
    if !is_rotation(r, 1e-3) {
        return Err(bad(CameraProblem::NotRotation));
    }
    let t = DVec3::from_array(c.translation);
    // Millimetres: a rig wider than 100 m is a unit or export error (a baseline of 1e300
    // printed as "inf mm").
    if !t.is_finite() || t.length() > 1e5 {
        return Err(bad(CameraProblem::NonFiniteTranslation));
    }
    let frames = match &c.frames {
        FramesEntry::Path(p) => {
            let template = PathTemplate::parse(p).map_err(|e| bad(CameraProblem::Frames(e)))?;
            if template.uses_frame() {
                FramesSpec::Sequence(template)
            } else if crate::video::is_video_path(Path::new(p)) {
                // Its braces undoubled (a video under a folder named `br{x}`); a path with
                // another placeholder was always taken as written.
                let path = template.literal().unwrap_or_else(|| p.clone());
                FramesSpec::Video { path, crop: None }
            } else {
                return Err(bad(CameraProblem::NoFramePlaceholder {
                    template: p.clone(),
                }));
            }
        }
        FramesEntry::Video { video, crop } => {
            let crop = match *crop {
                None => None,
                Some([x, y, w, h]) => {
                    if x < 0 || y < 0 || w <= 0 || h <= 0 || x.max(y).max(w).max(h) > 65536 {
                        return Err(bad(CameraProblem::Crop { crop: [x, y, w, h] }));
                    }
                    if (w, h) != (c.width, c.height) {
                        return Err(bad(CameraProblem::CropSize {
                            crop_w: w,
                            crop_h: h,
                            width: c.width,
                            height: c.height,
                        }));
                    }
                    Some(crate::video::Crop {
                        x: x as u32,
                        y: y as u32,
                        width: w as u32,
                        height: h as u32,
                    })
                }
            };
            FramesSpec::Video {
                path: video.clone(),
                crop,
            }
        }
    };
    Ok((
        Camera {
            name: c.name.clone(),
            width: c.width as u32,
            height: c.height as u32,
            intrinsics,
            extrinsics: Extrinsics {
                rotation: r,
                translation_mm: t,
            },
        },
        frames,
    ))
}

/// q1…q12 of eq. 2 as an [`Affine`] the fit can start from: finite, orientation-preserving
/// and not collapsing the model.
pub fn validate_affine(q: &[f64]) -> Result<Affine, AffineError> {
    if q.len() != 12 {
        return Err(AffineError::Length { count: q.len() });
    }
    let mut a = Affine::IDENTITY;
    a.q.copy_from_slice(q);
    if !a.is_finite() {
        return Err(AffineError::NonFinite);
    }
    let determinant = a.linear().determinant();
    if determinant <= 1e-9 {
        return Err(AffineError::Degenerate { determinant });
    }
    // A model scaled beyond 100× (10⁶ in volume) or placed beyond 100 m is not a pose the fit
    // can start from: its errors came out infinite and metrics.json null.
    let (linear_max, translation) = (
        a.q[..9].iter().fold(0.0f64, |m, v| m.max(v.abs())),
        DVec3::new(a.q[9], a.q[10], a.q[11]).length(),
    );
    if determinant > 1e6 || linear_max > 100.0 {
        return Err(AffineError::Scale {
            largest: linear_max,
        });
    }
    if translation > 1e5 {
        return Err(AffineError::Far {
            translation_mm: translation,
        });
    }
    Ok(a)
}

/// The vertex arrays of every mesh in a catalog folder, in file-name order; each must have the
/// structure mesh's vertices in the same order, since the shape model pairs them by index.
pub(super) fn load_catalog(dir: &Path, mesh: &Mesh) -> Result<Vec<Vec<DVec3>>, InputError> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| InputError::new(dir, format!("cannot read catalog folder: {e}")))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "obj" | "stl" | "ply"))
        })
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(InputError::new(
            dir,
            "catalog folder holds no meshes (.obj, .stl, .ply)",
        ));
    }
    files
        .iter()
        .map(|f| {
            let m = load_mesh(f)?;
            if m.vertices.len() != mesh.vertices.len() {
                return Err(InputError::new(
                    f,
                    format!("catalog mesh has {} vertices but the structure's mesh has {} (catalogs need the same vertices in the same order)", m.vertices.len(), mesh.vertices.len()),
                ));
            }
            Ok(m.vertices)
        })
        .collect()
}
