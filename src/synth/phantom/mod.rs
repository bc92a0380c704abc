//! The stereo endoscopic phantom: anatomy posed by smooth breathing-like rigid motion and
//! deformed non-rigidly over time (fields drawn like the catalog's, so the truth is near but
//! not inside its span), seen by a da Vinci-like rig whose zoom ramps focal length and drifts
//! the principal point with k1 following the paper's polynomial. This module holds the fixed
//! parts and their motion over time; `render` draws a frame from them with textured tissue,
//! a headlight with specular highlights, vignetting, optional instruments, smoke and noise.

mod render;

pub use render::FrameTruth;

use super::SynthOptions;
use super::anatomy;
use super::texture::fbm;
use crate::geometry::pose::rotation_from_vector;
use crate::geometry::{Affine, Camera, Extrinsics, Intrinsics, Mesh, RigidPose};
use crate::rng::Rng;
use crate::shape::{DeformationField, DeformationSpread};
use glam::{DMat3, DVec2, DVec3};

/// Stereo baseline of the default rig (da Vinci Xi calibrations: 4.35 mm), mm.
pub const BASELINE_MM: f64 = 4.5;
/// Focal length at zoom 1, in image widths.
pub const FOCAL_WIDTHS: f64 = 1.05;
/// Distance of the kidney's centre from the camera, mm.
const KIDNEY_DEPTH_MM: f64 = 190.0;
/// How much the zoom change multiplies the focal length.
const ZOOM_FACTOR: f64 = 1.2;

/// The paper's k1(f) = 0.226 − 0.0719/f − 0.214/f², with f the focal length in image widths
/// (f = fx / width): k1 = −0.037 at f = 1.05, +0.012 at f = 1.26.
pub fn k1_for_focal(fx_px: f64, width_px: f64) -> f64 {
    let inv = width_px / fx_px;
    let [c0, c1, c2] = K1_VS_FOCAL;
    c0 + c1 * inv + c2 * inv * inv
}

/// The coefficients of [`k1_for_focal`] in 1/f.
pub const K1_VS_FOCAL: [f64; 3] = [0.226, -0.0719, -0.214];

/// What `SynthOptions::vary_rig` draws from the seed (its own random stream: the plain phantom
/// is unchanged): the variations of real da Vinci data the fit must carry over to (issue 14).
#[derive(Debug, Clone, PartialEq)]
pub struct RigDraw {
    /// Kidney depth, mm.
    pub depth_mm: f64,
    /// The right camera's toe-in about y, and its small turns about x and z (degrees).
    pub toe_in_deg: [f64; 3],
    /// The right principal point's offset from the left's (px).
    pub right_pp_px: [f64; 2],
    /// Per camera: k2, p1, p2.
    pub distortion: Vec<[f64; 3]>,
    /// Principal point drift at full zoom (px at 960 wide).
    pub pp_drift_px: [f64; 2],
    /// Frames the zoom takes, and whether it goes back out after.
    pub zoom_frames: usize,
    pub zoom_back: bool,
}

impl RigDraw {
    pub fn drawn(seed: u64, views: usize) -> Self {
        let mut rng = Rng::fork(seed, 0x0716_0014);
        let sign = |rng: &mut Rng| if rng.below(2) == 0 { -1.0 } else { 1.0 };
        Self {
            depth_mm: rng.range(145.0, 165.0),
            toe_in_deg: [
                rng.range(1.0, 2.0),
                rng.range(-0.15, 0.15),
                rng.range(-0.15, 0.15),
            ],
            right_pp_px: [rng.range(-2.0, 2.0), rng.range(-1.0, 1.0)],
            distortion: (0..views)
                .map(|_| {
                    [
                        rng.range(-0.01, 0.01),
                        rng.range(-3e-4, 3e-4),
                        rng.range(-3e-4, 3e-4),
                    ]
                })
                .collect(),
            pp_drift_px: [sign(&mut rng) * rng.range(1.0, 4.0), rng.range(-4.0, 4.0)],
            zoom_frames: 10 + rng.below(6),
            zoom_back: rng.below(2) == 0,
        }
    }
}

/// A surgical instrument: a shaft from outside the view to a tip sweeping over the kidney.
#[derive(Debug, Clone)]
struct Tool {
    entry: DVec3,
    tip: DVec3,
    sweep: DVec3,
    period_frames: f64,
    phase: f64,
}

/// A tool's shaft radius (mm).
pub const TOOL_RADIUS_MM: f64 = 4.0;

/// The length of a tool's bare metal tip (mm); the rest of the shaft is dark.
const TOOL_TIP_MM: f64 = 14.0;

/// The phantom's fixed parts; frames are rendered on demand.
pub struct Phantom {
    pub options: SynthOptions,
    pub structures: Vec<(String, u8, bool, Mesh)>,
    /// The rig came from a real calibration: its distortion stays as measured under zoom.
    calibrated: bool,
    /// Given meshes keep their own frame (so the scene's meshes are the files given); this
    /// moves them where the built-in anatomy sits before the phantom's pose applies.
    mesh_to_model: Affine,
    rest_cameras: Vec<Camera>,
    /// Light position (mm, camera-0 frame) per camera: the endoscope tip for the stereo pair.
    lights: Vec<DVec3>,
    base_pose: RigidPose,
    breathing_dir: DVec3,
    drift_dir: DVec3,
    wobble_axis: DVec3,
    fields: Vec<(DeformationField, f64, f64)>,
    tools: Vec<Tool>,
    background: Mesh,
    /// Frame ranges of zoom changes: in, and (when the rig draw says so) back out.
    pub zoom_ranges: Vec<(usize, usize)>,
    look: crate::synth::look::Look,
    pub rig: Option<RigDraw>,
}

impl Phantom {
    pub fn new(options: SynthOptions) -> Self {
        let mut rng = Rng::new(options.seed);
        let (structures, mesh_to_model) = match &options.structures {
            Some(given) => (given.clone(), facing_transform(given)),
            None => (
                anatomy::default_structures()
                    .into_iter()
                    .map(|(n, l, v, m)| (n.to_string(), l, v, m))
                    .collect(),
                Affine::IDENTITY,
            ),
        };
        let (w, h) = (options.width as f64, options.height as f64);
        let f = FOCAL_WIDTHS * w;
        let intr = Intrinsics {
            k1: k1_for_focal(f, w),
            ..Intrinsics::pinhole(f, f, (w - 1.0) * 0.5, (h - 1.0) * 0.5)
        };
        let rig = options
            .vary_rig
            .then(|| RigDraw::drawn(options.seed, options.views.max(1)));
        let depth_mm = rig.as_ref().map_or(KIDNEY_DEPTH_MM, |r| r.depth_mm);
        let target = DVec3::new(0.0, 0.0, depth_mm);
        let mut rest_cameras = Vec::new();
        let mut lights = Vec::new();
        for m in 0..options.views.max(1) {
            let (name, extrinsics, light) = match m {
                0 => (
                    "left".to_string(),
                    Extrinsics::default(),
                    DVec3::new(BASELINE_MM * 0.5, 0.0, 0.0),
                ),
                1 => (
                    "right".to_string(),
                    Extrinsics {
                        rotation: DMat3::IDENTITY,
                        translation_mm: DVec3::new(-BASELINE_MM, 0.0, 0.0),
                    },
                    DVec3::new(BASELINE_MM * 0.5, 0.0, 0.0),
                ),
                _ => {
                    // Further views orbit the kidney: ±15°, ±30°, … about the vertical axis.
                    let k = (m - 1).div_ceil(2) as f64;
                    let sign = if m % 2 == 0 { 1.0 } else { -1.0 };
                    let orbit = rotation_from_vector(DVec3::Y * (sign * k * 15f64.to_radians()));
                    let center = target + orbit * (-target);
                    let rotation = orbit.transpose();
                    (
                        format!("view{m}"),
                        Extrinsics {
                            rotation,
                            translation_mm: -(rotation * center),
                        },
                        center,
                    )
                }
            };
            let mut camera = Camera {
                name,
                width: options.width,
                height: options.height,
                intrinsics: intr,
                extrinsics,
            };
            if let Some(r) = &rig {
                let i = &mut camera.intrinsics;
                [i.k2, i.p1, i.p2] = r.distortion[m];
                if m == 1 {
                    // Toe-in: the right camera turned towards the left one's axis, converging
                    // near the organ; its principal point a little off the left's.
                    let [y, x, z] = r.toe_in_deg.map(f64::to_radians);
                    let turn = rotation_from_vector(DVec3::Y * y)
                        * rotation_from_vector(DVec3::X * x)
                        * rotation_from_vector(DVec3::Z * z);
                    let centre = camera.extrinsics.center_mm();
                    camera.extrinsics.rotation = turn;
                    camera.extrinsics.translation_mm = -(turn * centre);
                    i.cx += r.right_pp_px[0];
                    i.cy += r.right_pp_px[1];
                }
            }
            rest_cameras.push(camera);
            lights.push(light);
        }
        if let Some(given) = options.cameras.clone().filter(|c| !c.is_empty()) {
            // The light sits between the first two camera centres, as on an endoscope's tip.
            let centres: Vec<DVec3> = given.iter().map(|c| c.extrinsics.center_mm()).collect();
            let tip = (centres[0] + centres[centres.len().min(2) - 1]) * 0.5;
            lights = vec![tip; given.len()];
            rest_cameras = given;
        }
        // The kidney seen from its anterior side, long axis tilted across the view.
        let base_pose = RigidPose {
            rotation_vector: {
                let r = rotation_from_vector(DVec3::Z * rng.range(1.05, 1.35))
                    * rotation_from_vector(DVec3::new(
                        rng.range(-0.25, 0.25),
                        rng.range(-0.25, 0.25),
                        0.0,
                    ));
                crate::geometry::pose::rotation_to_vector(r)
            },
            translation_mm: target
                + DVec3::new(
                    rng.range(-8.0, 8.0),
                    rng.range(-5.0, 5.0),
                    rng.range(-10.0, 10.0),
                ),
            log_scale: 0.0,
        };
        let kidney = &structures[0].3;
        let normals = kidney.vertex_normals();
        let spread = DeformationSpread {
            forces: (2, 3),
            amplitude_mm: (3.0, 6.0),
            ..DeformationSpread::default()
        };
        let fields = (0..2)
            .map(|_| {
                (
                    DeformationField::random(&mut rng, kidney, &normals, &spread),
                    rng.range(60.0, 140.0),
                    rng.range(0.0, std::f64::consts::TAU),
                )
            })
            .collect();
        let frames = options.frames;
        let zoom_ranges = match &rig {
            _ if !options.zoom || frames < 8 => Vec::new(),
            None => vec![(
                (frames as f64 * 0.4).round() as usize,
                ((frames as f64 * 0.7).round() as usize).min(frames - 1),
            )],
            Some(r) => {
                let a = (frames as f64 * 0.3).round() as usize;
                let b = (a + r.zoom_frames).min(frames - 1);
                let mut v = vec![(a, b)];
                // Back out after a short hold, where the video is long enough.
                let (c, d) = (b + 4, b + 4 + r.zoom_frames);
                if r.zoom_back && d < frames {
                    v.push((c, d));
                }
                v
            }
        };
        let tools = if options.tools {
            (0..2)
                .map(|i| {
                    let side = if i == 0 { -1.0 } else { 1.0 };
                    Tool {
                        entry: DVec3::new(
                            side * rng.range(140.0, 180.0),
                            rng.range(-90.0, 90.0),
                            rng.range(40.0, 80.0),
                        ),
                        tip: target
                            + DVec3::new(
                                side * rng.range(5.0, 30.0),
                                rng.range(-25.0, 25.0),
                                -rng.range(25.0, 35.0),
                            ),
                        sweep: DVec3::new(
                            side * rng.range(15.0, 30.0),
                            rng.range(-15.0, 15.0),
                            rng.range(-3.0, 3.0),
                        ),
                        period_frames: rng.range(50.0, 90.0),
                        phase: rng.range(0.0, std::f64::consts::TAU),
                    }
                })
                .collect()
        } else {
            Vec::new()
        };
        let look = if options.vary_look {
            crate::synth::look::Look::drawn(options.seed)
        } else {
            crate::synth::look::Look::PLAIN
        };
        Self {
            background: background_sheet(&mut rng, depth_mm),
            calibrated: options.cameras.as_ref().is_some_and(|c| !c.is_empty()),
            mesh_to_model,
            options,
            structures,
            rest_cameras,
            lights,
            base_pose,
            breathing_dir: rng.unit_vector(),
            drift_dir: rng.unit_vector(),
            wobble_axis: rng.unit_vector(),
            fields,
            tools,
            zoom_ranges,
            look,
            rig,
        }
    }

    fn seconds(&self, t: usize) -> f64 {
        t as f64 / 30.0
    }

    /// The true rigid pose at frame t: breathing (5 mm, 3.5 s), a slow drift and a ±4° wobble.
    pub fn pose(&self, t: usize) -> Affine {
        RigidPose {
            rotation_vector: self.base_pose.rotation_vector,
            translation_mm: self.base_pose.translation_mm + self.rigid_offset(t),
            log_scale: 0.0,
        }
        .to_affine()
        .compose(&Affine::from_linear_translation(
            self.wobble(t),
            DVec3::ZERO,
        ))
        .compose(&self.mesh_to_model)
    }

    fn rigid_offset(&self, t: usize) -> DVec3 {
        let s = self.seconds(t);
        self.breathing_dir * (5.0 * (std::f64::consts::TAU * s / 3.5).sin())
            + self.drift_dir * (3.0 * (s / 4.0).min(1.0))
    }

    fn wobble(&self, t: usize) -> DMat3 {
        let s = self.seconds(t);
        rotation_from_vector(
            self.wobble_axis * (4f64.to_radians() * (std::f64::consts::TAU * s / 5.0).sin()),
        )
    }

    /// True deformed vertices of every structure at frame t, preoperative frame.
    pub fn deformed(&self, t: usize) -> Vec<Vec<DVec3>> {
        let fields: Vec<DeformationField> = self
            .fields
            .iter()
            .map(|(f, period, phase)| {
                f.scaled(0.6 + 0.4 * (std::f64::consts::TAU * t as f64 / period + phase).sin())
            })
            .collect();
        self.structures
            .iter()
            .map(|(_, _, _, m)| {
                m.vertices
                    .iter()
                    .map(|&p| p + fields.iter().map(|f| f.displacement(p)).sum::<DVec3>())
                    .collect()
            })
            .collect()
    }

    /// Zoom progress in [0, 1] at frame t: smoothstep up across the first zoom range, down
    /// across the second (a zoom back out).
    fn zoom(&self, t: usize) -> f64 {
        let ramp = |&(a, b): &(usize, usize)| {
            if b <= a {
                return 0.0;
            }
            let u = ((t as f64 - a as f64) / (b - a) as f64).clamp(0.0, 1.0);
            u * u * (3.0 - 2.0 * u)
        };
        let mut ranges = self.zoom_ranges.iter();
        let up = ranges.next().map_or(0.0, ramp);
        up - ranges.next().map_or(0.0, ramp)
    }

    /// Cameras at frame t: focal length and principal point follow the zoom, k1 the polynomial.
    pub fn cameras(&self, t: usize) -> Vec<Camera> {
        let z = self.zoom(t);
        let scale = self.options.width as f64 / 960.0;
        self.rest_cameras
            .iter()
            .map(|c| {
                let mut c = c.clone();
                let i = &mut c.intrinsics;
                i.fx *= 1.0 + (ZOOM_FACTOR - 1.0) * z;
                i.fy *= 1.0 + (ZOOM_FACTOR - 1.0) * z;
                let drift = self.rig.as_ref().map_or([10.0, -6.0], |r| r.pp_drift_px);
                i.cx += drift[0] * scale * z;
                i.cy += drift[1] * scale * z;
                if !self.calibrated {
                    i.k1 = k1_for_focal(i.fx, c.width as f64);
                }
                c
            })
            .collect()
    }

    /// Each tool's axis at frame t, from where it enters to its tip (mm, camera-0 frame); the
    /// shaft is a cylinder of [`TOOL_RADIUS_MM`] about it.
    pub fn tool_axes(&self, t: usize) -> Vec<(DVec3, DVec3)> {
        self.tools
            .iter()
            .map(|tool| self.tool_axis(tool, t))
            .collect()
    }

    fn tool_axis(&self, tool: &Tool, t: usize) -> (DVec3, DVec3) {
        let tip = tool.tip
            + tool.sweep
                * (std::f64::consts::TAU * t as f64 / tool.period_frames + tool.phase).sin();
        (tool.entry, tip)
    }

    pub fn initial_cameras(&self) -> Vec<Camera> {
        self.cameras(0)
    }

    /// The lens's k1-vs-focal relation the phantom renders with (the paper's polynomial), as
    /// scene.json's `k1_vs_focal`; none for a real calibration's rig (its k1 stays as measured).
    pub fn k1_vs_focal(&self) -> Option<[f64; 3]> {
        (!self.calibrated).then_some(K1_VS_FOCAL)
    }

    /// The scene's initial pose: the truth at frame 0 perturbed as the options say (8 mm and
    /// 10° with `vary_rig`, the independent scenes' start).
    pub fn initial_pose(&self) -> Affine {
        let (mm, degrees) = if self.options.vary_rig {
            (8.0, 10.0)
        } else {
            (
                self.options.initial_offset_mm,
                self.options.initial_offset_deg,
            )
        };
        self.perturbed_initial_pose(mm, degrees)
    }

    /// The truth at frame 0 perturbed by `mm` millimetres and `degrees` about a random axis.
    pub fn perturbed_initial_pose(&self, mm: f64, degrees: f64) -> Affine {
        let mut rng = Rng::fork(self.options.seed, 0x1417);
        let truth = self.pose(0);
        let rot = rotation_from_vector(rng.unit_vector() * degrees.to_radians());
        let centre = crate::geometry::mesh::vertex_mean(&self.structures[0].3.vertices);
        // Rotate about the kidney's centre, then shift.
        let c = truth.apply(centre);
        let about = Affine::from_linear_translation(rot, c - rot * c + rng.unit_vector() * mm);
        about.compose(&truth)
    }
}

/// The map that puts given structures where the built-in anatomy sits: the kidney's vertex mean
/// at the origin, and the largest visible tumour turned towards the cameras (−z), as a surgeon
/// exposes it — a patient's tumour on the far side would leave nothing to segment.
fn facing_transform(given: &[(String, u8, bool, Mesh)]) -> Affine {
    let centre = given
        .first()
        .map(|s| s.3.vertex_mean())
        .unwrap_or(DVec3::ZERO);
    let facing = given
        .iter()
        .skip(1)
        .filter(|s| s.2)
        .max_by(|a, b| {
            a.3.signed_volume()
                .abs()
                .total_cmp(&b.3.signed_volume().abs())
        })
        .map(|s| (s.3.vertex_mean() - centre).normalize_or_zero())
        .filter(|d| *d != DVec3::ZERO);
    let turn = match facing {
        Some(d) => DMat3::from_quat(glam::DQuat::from_rotation_arc(d, DVec3::NEG_Z)),
        None => DMat3::IDENTITY,
    };
    Affine::from_linear_translation(turn, -(turn * centre))
}

/// The retroperitoneal backdrop: a wide bumpy sheet 40–60 mm behind the kidney.
fn background_sheet(rng: &mut Rng, depth_mm: f64) -> Mesh {
    let n = 48;
    let half = 420.0;
    let tilt = DVec2::new(rng.range(-0.15, 0.15), rng.range(-0.15, 0.15));
    let seed = rng.next_u64() % 1000;
    let mut verts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let x = -half + 2.0 * half * i as f64 / n as f64;
            let y = -half + 2.0 * half * j as f64 / n as f64;
            let bump = 10.0 * fbm(DVec3::new(x / 60.0, y / 60.0, 0.5), 3, seed);
            verts.push(DVec3::new(
                x,
                y,
                depth_mm + 50.0 + tilt.x * x + tilt.y * y + bump,
            ));
        }
    }
    let mut faces = Vec::new();
    let row = (n + 1) as u32;
    for j in 0..n as u32 {
        for i in 0..n as u32 {
            let a = j * row + i;
            faces.push([a, a + 1, a + row + 1]);
            faces.push([a, a + row + 1, a + row]);
        }
    }
    Mesh::new(verts, faces)
}
