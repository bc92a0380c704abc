//! Rendering one phantom frame: the posed anatomy, instruments and backdrop rasterised in
//! every view, shaded (textured tissue under a headlight with specular highlights, vignetting,
//! smoke, noise), with the frame's ground truth: labels, tool masks, hidden structures'
//! projections and the true pose, cameras and centroids.

use super::{KIDNEY_DEPTH_MM, Phantom, TOOL_RADIUS_MM, TOOL_TIP_MM};
use crate::geometry::mesh::vertex_normals;
use crate::geometry::{Affine, Camera, Mesh};
use crate::plane::{LabelImage, Mask};
use crate::render::raster::{
    NO_OBJECT, RasterOptions, RenderObject, ViewRaster, coverage, rasterize, rasterize_objects,
};
use crate::rng::Rng;
use crate::scene::TrajectoryFrame;
use crate::synth::texture::{Material, albedo, fbm};
use glam::{DVec3, Vec3};
use image::RgbImage;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// What one frame of the phantom holds.
pub struct FrameTruth {
    pub images: Vec<RgbImage>,
    /// Ground-truth labels per camera (front-most visible structure; tools and background 0).
    pub labels: Vec<LabelImage>,
    /// Tool pixels per camera (they are background/tools for seeds).
    pub tools: Vec<Mask>,
    /// Hidden structures' projections per (hidden structure, camera), occlusion ignored.
    pub hidden: Vec<(String, Vec<Mask>)>,
    pub trajectory: TrajectoryFrame,
}

/// One object drawn in the appearance raster.
struct Drawn {
    posed: Vec<DVec3>,
    normals: Vec<DVec3>,
    /// Tissue-fixed coordinates for the texture.
    texture_coords: Vec<DVec3>,
    faces: Vec<[u32; 3]>,
    kind: DrawnKind,
}

#[derive(Clone, Copy, PartialEq)]
enum DrawnKind {
    Structure(usize),
    Tool,
    Background,
}

impl Phantom {
    /// The posed objects of frame t, with the anatomy first (index = structure index).
    fn drawn(&self, t: usize, deformed: &[Vec<DVec3>], pose: &Affine) -> Vec<Drawn> {
        let mut out: Vec<Drawn> = self
            .structures
            .iter()
            .zip(deformed)
            .enumerate()
            .map(|(i, ((_, _, _, mesh), verts))| {
                let posed: Vec<DVec3> = verts.iter().map(|&p| pose.apply(p)).collect();
                Drawn {
                    normals: vertex_normals(&posed, &mesh.faces),
                    posed,
                    texture_coords: mesh.vertices.clone(),
                    faces: mesh.faces.clone(),
                    kind: DrawnKind::Structure(i),
                }
            })
            .collect();
        for tool in &self.tools {
            let (entry, tip) = self.tool_axis(tool, t);
            let (mesh, coords) = cylinder(entry, tip, TOOL_RADIUS_MM, 20);
            out.push(Drawn {
                normals: mesh.vertex_normals(),
                posed: mesh.vertices,
                texture_coords: coords,
                faces: mesh.faces,
                kind: DrawnKind::Tool,
            });
        }
        // The background moves with half the breathing.
        let shift = self.rigid_offset(t) * 0.5;
        let posed: Vec<DVec3> = self
            .background
            .vertices
            .iter()
            .map(|&p| p + shift)
            .collect();
        out.push(Drawn {
            normals: self.background.vertex_normals(),
            posed,
            texture_coords: self.background.vertices.clone(),
            faces: self.background.faces.clone(),
            kind: DrawnKind::Background,
        });
        out
    }

    /// Renders frame t in every view with its ground truth.
    pub fn render(&self, t: usize) -> FrameTruth {
        let pose = self.pose(t);
        let deformed = self.deformed(t);
        let cameras = self.cameras(t);
        let drawn = self.drawn(t, &deformed, &pose);
        // Hidden structures are inside the kidney: leave them out of the appearance raster.
        let shown: Vec<usize> = (0..drawn.len())
            .filter(|&i| match drawn[i].kind {
                DrawnKind::Structure(s) => self.structures[s].2,
                _ => true,
            })
            .collect();
        let objects: Vec<RenderObject> = shown
            .iter()
            .map(|&i| RenderObject {
                vertices: &drawn[i].posed,
                faces: &drawn[i].faces,
                closed: false,
            })
            .collect();
        let mut images = Vec::new();
        let mut labels = Vec::new();
        let mut tools = Vec::new();
        for (m, cam) in cameras.iter().enumerate() {
            let raster = rasterize(cam, &objects, &RasterOptions::default());
            let kinds: Vec<DrawnKind> = shown.iter().map(|&i| drawn[i].kind).collect();
            let label_of: Vec<u8> = kinds
                .iter()
                .map(|k| match k {
                    DrawnKind::Structure(s) => self.structures[*s].1,
                    _ => 0,
                })
                .collect();
            labels.push(raster.label_image(&label_of));
            tools.push(
                raster
                    .object
                    .map(|&o| o != NO_OBJECT && kinds[o as usize] == DrawnKind::Tool),
            );
            images.push(self.shade(t, m, cam, &raster, &shown, &drawn));
        }
        let mut hidden = Vec::new();
        for (s, (name, _, visible, mesh)) in self.structures.iter().enumerate() {
            if *visible {
                continue;
            }
            let obj = [RenderObject {
                vertices: &drawn[s].posed,
                faces: &mesh.faces,
                closed: false,
            }];
            hidden.push((
                name.to_string(),
                cameras
                    .iter()
                    .map(|c| coverage(&rasterize_objects(c, &obj, &RasterOptions::default())))
                    .collect(),
            ));
        }
        let centroids: BTreeMap<String, [f64; 3]> = self
            .structures
            .iter()
            .zip(&drawn)
            .map(|((name, ..), d)| {
                (
                    name.to_string(),
                    crate::geometry::mesh::vertex_mean(&d.posed).to_array(),
                )
            })
            .collect();
        FrameTruth {
            images,
            labels,
            tools,
            hidden,
            trajectory: TrajectoryFrame {
                frame: t as u32,
                affine: pose.q.to_vec(),
                shape: BTreeMap::new(),
                cameras: cameras.iter().map(|c| c.intrinsics).collect(),
                centroids,
                energy: None,
                iterations: None,
                ms: None,
                confidence: None,
                lost: None,
                warnings: Vec::new(),
                hidden_region: BTreeMap::new(),
            },
        }
    }

    /// Shades one view: headlight diffuse + specular, inverse-square falloff, vignetting,
    /// smoke haze and Gaussian noise.
    fn shade(
        &self,
        t: usize,
        m: usize,
        cam: &Camera,
        raster: &ViewRaster,
        shown: &[usize],
        drawn: &[Drawn],
    ) -> RgbImage {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let light = self.lights[m];
        let look = self.look;
        let eye = cam.extrinsics.center_mm();
        let noise = self.options.noise;
        let smoke = if self.options.smoke {
            0.12 + 0.10 * (t as f64 / 45.0).sin().abs()
        } else {
            0.0
        };
        let diag2 = (w as f64 * 0.5).powi(2) + (h as f64 * 0.5).powi(2);
        let rows: Vec<Vec<u8>> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut rng = Rng::fork(
                    self.options.seed ^ 0x5EED,
                    ((t * 64 + m) * 65536 + y) as u64,
                );
                let mut row = Vec::with_capacity(w * 3);
                for x in 0..w {
                    let i = y * w + x;
                    let o = raster.object.data[i];
                    let mut c = if o == NO_OBJECT {
                        Vec3::new(0.02, 0.01, 0.01)
                    } else {
                        let d = &drawn[shown[o as usize]];
                        let f = d.faces[raster.triangle.data[i] as usize];
                        let [b1, b2] = raster.barycentric.data[i].map(|b| b as f64);
                        let b0 = 1.0 - b1 - b2;
                        let lerp3 = |v: &[DVec3]| {
                            v[f[0] as usize] * b0 + v[f[1] as usize] * b1 + v[f[2] as usize] * b2
                        };
                        let p = lerp3(&d.posed);
                        let tex = lerp3(&d.texture_coords) / look.texture_scale;
                        let mut n = lerp3(&d.normals).normalize_or(DVec3::NEG_Z);
                        let v = (eye - p).normalize_or(DVec3::NEG_Z);
                        if n.dot(v) < 0.0 {
                            n = -n;
                        }
                        let material = match d.kind {
                            DrawnKind::Structure(0) => Material::Kidney,
                            DrawnKind::Structure(_) => Material::Tumour,
                            DrawnKind::Tool if tex.x < TOOL_TIP_MM => Material::ToolMetal,
                            DrawnKind::Tool => Material::ToolShaft,
                            DrawnKind::Background => Material::Fat,
                        };
                        // Bumpy tissue: perturb the normal with the texture's noise.
                        if matches!(material, Material::Fat | Material::Kidney) {
                            let bump = DVec3::new(
                                fbm(tex / 6.0, 2, 91),
                                fbm(tex / 6.0, 2, 92),
                                fbm(tex / 6.0, 2, 93),
                            );
                            n = (n + bump * 0.25).normalize_or(n);
                        }
                        let (mut albedo, ks, shininess) = albedo(material, tex);
                        match material {
                            Material::Kidney => albedo *= look.kidney_tint,
                            // Blood-like patches on the surrounding tissue: close to the
                            // kidney's colour.
                            Material::Fat if look.blood > 0.0 => {
                                let patch = ((fbm(tex / 14.0, 3, 55) as f32 + 0.5
                                    - (1.0 - look.blood))
                                    * 4.0)
                                    .clamp(0.0, 1.0);
                                albedo = albedo.lerp(Vec3::new(0.42, 0.07, 0.06), patch);
                            }
                            _ => {}
                        }
                        let ks = ks * look.specular;
                        let to_light = light - p;
                        let dist = to_light.length().max(1.0);
                        let l = to_light / dist;
                        let diffuse = n.dot(l).max(0.0);
                        let half = (l + v).normalize_or(l);
                        let spec = (n.dot(half).max(0.0)).powf(shininess as f64) * ks as f64;
                        let falloff = (KIDNEY_DEPTH_MM / dist).powi(2).min(2.0);
                        (albedo * (0.10 + 0.95 * diffuse as f32) + Vec3::splat(spec as f32))
                            * falloff as f32
                            * look.gain
                            * look.light_rgb
                    };
                    let r2 = ((x as f64 - cam.intrinsics.cx).powi(2)
                        + (y as f64 - cam.intrinsics.cy).powi(2))
                        / diag2;
                    c *= (1.0 - 0.45 * r2).max(0.2) as f32;
                    if smoke > 0.0 {
                        let haze = smoke
                            * (0.6
                                + 0.4
                                    * fbm(
                                        DVec3::new(
                                            x as f64 / 150.0,
                                            y as f64 / 150.0,
                                            t as f64 * 0.02,
                                        ),
                                        3,
                                        77,
                                    ));
                        c = c.lerp(Vec3::new(0.80, 0.76, 0.74), haze as f32);
                    }
                    for k in 0..3 {
                        let v = c[k] as f64 + noise * rng.normal();
                        row.push((v.clamp(0.0, 1.0) * 255.0).round() as u8);
                    }
                }
                row
            })
            .collect();
        let image = RgbImage::from_raw(w as u32, h as u32, rows.concat()).unwrap_or_default();
        if look.blur_px > 0.05 {
            image::imageops::blur(&image, look.blur_px)
        } else {
            image
        }
    }
}

/// A capped cylinder from `a` to `b`; texture coordinates are (distance from b, angle, 0).
/// The shaft is cut into rings at most 4 mm apart: its far end lies well outside the view
/// (beyond the lens model's fold, where nothing is projected), and one triangle from there
/// to the tip would drop the whole visible shaft with it.
fn cylinder(a: DVec3, b: DVec3, radius: f64, segments: usize) -> (Mesh, Vec<DVec3>) {
    let axis = (b - a).normalize_or(DVec3::Z);
    let u = axis.any_orthonormal_vector();
    let v = axis.cross(u);
    let len = (b - a).length();
    let shaft = (len - TOOL_TIP_MM).max(0.0);
    let pieces = (shaft / 4.0).ceil().max(1.0) as usize;
    let mut rings: Vec<f64> = (0..=pieces)
        .map(|i| shaft * i as f64 / pieces as f64)
        .collect();
    rings.push(len);
    let mut verts = Vec::new();
    let mut coords = Vec::new();
    for &s in &rings {
        for k in 0..segments {
            let ang = k as f64 / segments as f64 * std::f64::consts::TAU;
            verts.push(a + axis * s + (u * ang.cos() + v * ang.sin()) * radius);
            coords.push(DVec3::new(len - s, ang, 0.0));
        }
    }
    verts.push(b);
    coords.push(DVec3::ZERO);
    let tip = (verts.len() - 1) as u32;
    let mut faces = Vec::new();
    let seg = segments as u32;
    let last = (rings.len() - 1) as u32;
    for r in 0..last {
        for k in 0..seg {
            let (i0, i1) = (r * seg + k, r * seg + (k + 1) % seg);
            faces.push([i0, i1, i1 + seg]);
            faces.push([i0, i1 + seg, i0 + seg]);
        }
    }
    for k in 0..seg {
        faces.push([last * seg + k, last * seg + (k + 1) % seg, tip]);
    }
    (Mesh::new(verts, faces), coords)
}
