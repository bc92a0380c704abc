//! CPU rasteriser of the fit: projects posed meshes through a camera (eq. 10–11, distortion
//! included) and keeps, per pixel, the front-most surface's camera depth, object, triangle and
//! perspective-correct barycentrics — so the fit can find the 3D point behind any pixel.
//!
//! Distortion bends straight edges, so a triangle whose projected edges bow by more than a
//! tolerance is split into four in 3D (recursively) and each piece rasterised; barycentrics
//! always refer to the original triangle. Pixels are sampled at their centres (integer
//! coordinates, OpenCV's convention). Triangles reaching behind the near plane are skipped.

use crate::geometry::Camera;
use crate::geometry::camera::NEAR_MM;
use crate::plane::{LabelImage, Mask, Plane};
use glam::{DVec2, DVec3};

/// Marks a pixel no surface covers.
pub const NO_OBJECT: u8 = u8::MAX;
pub const NO_TRIANGLE: u32 = u32::MAX;

/// One posed mesh to draw: vertices in camera-0 (reference) coordinates, mm.
#[derive(Debug, Clone, Copy)]
pub struct RenderObject<'a> {
    pub vertices: &'a [DVec3],
    pub faces: &'a [[u32; 3]],
    /// Closed and edge-manifold: every edge shared by exactly two faces, so a back face is
    /// never the nearest surface and [`RasterOptions::cull_back_faces`] may skip it.
    pub closed: bool,
}

#[derive(Debug, Clone, Copy)]
pub struct RasterOptions {
    /// Largest bow (px) of a projected edge before the triangle is split. Keep it far above
    /// rounding (the fit uses 0.2 px): triangles the straightness bound proves within half of
    /// it skip the measured test, whose rounding must not reach the other half.
    pub tolerance_px: f64,
    /// How many times a triangle may be split in four.
    pub max_subdivision: u32,
    /// Skip the back faces of closed objects: exact (a ray meets a closed surface's front
    /// face before any back face of it), and half the triangles (the fit's visibility raster).
    pub cull_back_faces: bool,
}

impl Default for RasterOptions {
    fn default() -> Self {
        Self {
            tolerance_px: 0.2,
            max_subdivision: 5,
            cull_back_faces: false,
        }
    }
}

/// What one view sees of a set of objects, front-most surface per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewRaster {
    /// Camera-frame depth Z (mm) of the front-most surface; ∞ where nothing is drawn.
    pub depth_mm: Plane<f32>,
    /// Index of the object drawn, [`NO_OBJECT`] where none.
    pub object: Plane<u8>,
    /// Face index within that object, [`NO_TRIANGLE`] where none.
    pub triangle: Plane<u32>,
    /// Barycentric weights of the face's vertices 1 and 2 (vertex 0 gets the rest).
    pub barycentric: Plane<[f32; 2]>,
}

impl ViewRaster {
    fn empty(width: usize, height: usize) -> Self {
        Self {
            depth_mm: Plane::filled(width, height, f32::INFINITY),
            object: Plane::filled(width, height, NO_OBJECT),
            triangle: Plane::filled(width, height, NO_TRIANGLE),
            barycentric: Plane::filled(width, height, [0.0; 2]),
        }
    }

    pub fn width(&self) -> usize {
        self.object.width
    }

    pub fn height(&self) -> usize {
        self.object.height
    }

    /// Pixels where `object` is the front-most surface.
    pub fn visible_mask(&self, object: u8) -> Mask {
        self.object.map(|&o| o == object)
    }

    /// Pixels covered by anything.
    pub fn coverage(&self) -> Mask {
        coverage(&self.object)
    }

    /// Label image: `labels[object]` where an object is front-most, 0 elsewhere.
    pub fn label_image(&self, labels: &[u8]) -> LabelImage {
        label_image(&self.object, labels)
    }

    /// The reference-frame surface point behind pixel `i`, if any.
    pub fn surface_point(&self, objects: &[RenderObject], i: usize) -> Option<DVec3> {
        let o = *self.object.data.get(i)?;
        let obj = objects.get(o as usize)?;
        let f = obj.faces.get(self.triangle.data[i] as usize)?;
        let [b1, b2] = self.barycentric.data[i].map(|b| b as f64);
        let [a, b, c] = f.map(|k| obj.vertices[k as usize]);
        Some(a * (1.0 - b1 - b2) + b * b1 + c * b2)
    }
}

/// Pixels an object plane (`ViewRaster::object`, [`rasterize_objects`]) covers.
pub fn coverage(object: &Plane<u8>) -> Mask {
    object.map(|&o| o != NO_OBJECT)
}

/// An object plane as a label image: `labels[object]` where an object is front-most, 0
/// elsewhere.
pub fn label_image(object: &Plane<u8>, labels: &[u8]) -> LabelImage {
    object.map(|&o| labels.get(o as usize).copied().unwrap_or(0))
}

/// A projected vertex: pixel, camera depth, and where it lies in the original triangle.
#[derive(Clone, Copy)]
struct Corner {
    cam: DVec3,
    px: DVec2,
    bary: DVec2,
    /// 1 / `cam.z`, and `cam`'s normalised coordinates (x/z, y/z): once per vertex, not once
    /// per triangle sharing it.
    inv_z: f64,
    normalized: DVec2,
}

impl Corner {
    fn new(cam: DVec3, px: DVec2, bary: DVec2) -> Self {
        Self {
            cam,
            px,
            bary,
            inv_z: 1.0 / cam.z,
            normalized: DVec2::new(cam.x / cam.z, cam.y / cam.z),
        }
    }
}

/// Rasterises `objects` (at most 254) into one view of `camera`.
pub fn rasterize(camera: &Camera, objects: &[RenderObject], options: &RasterOptions) -> ViewRaster {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut out = ViewRaster::empty(w, h);
    draw(camera, objects, options, &mut out);
    out
}

/// The front-most object of every pixel ([`NO_OBJECT`] where none): [`rasterize`]'s `object`
/// plane, equal to it pixel for pixel (the same triangles, depths and tests), without the
/// triangle and barycentric planes the fit reads. What output masks need, at a third of the
/// memory a full-resolution [`ViewRaster`] fills.
pub fn rasterize_objects(
    camera: &Camera,
    objects: &[RenderObject],
    options: &RasterOptions,
) -> Plane<u8> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut out = ObjectRaster {
        depth_mm: Plane::filled(w, h, f32::INFINITY),
        object: Plane::filled(w, h, NO_OBJECT),
    };
    draw(camera, objects, options, &mut out);
    out.object
}

/// Where [`fill_triangle`] writes the front-most surface of each pixel.
trait Sink {
    fn width(&self) -> usize;
    fn height(&self) -> usize;
    /// The depth (mm) drawn at pixel `i` so far.
    fn depth(&self, i: usize) -> f32;
    /// Pixel `i` is now `object`'s face `triangle` at depth `z`; `bary` gives the face's
    /// barycentrics, for sinks that keep them.
    fn put(&mut self, i: usize, z: f32, object: u8, triangle: u32, bary: impl FnOnce() -> [f32; 2]);
}

impl Sink for ViewRaster {
    fn width(&self) -> usize {
        self.object.width
    }
    fn height(&self) -> usize {
        self.object.height
    }
    #[inline]
    fn depth(&self, i: usize) -> f32 {
        self.depth_mm.data[i]
    }
    #[inline]
    fn put(
        &mut self,
        i: usize,
        z: f32,
        object: u8,
        triangle: u32,
        bary: impl FnOnce() -> [f32; 2],
    ) {
        self.depth_mm.data[i] = z;
        self.object.data[i] = object;
        self.triangle.data[i] = triangle;
        self.barycentric.data[i] = bary();
    }
}

/// Depth and object only ([`rasterize_objects`]).
struct ObjectRaster {
    depth_mm: Plane<f32>,
    object: Plane<u8>,
}

impl Sink for ObjectRaster {
    fn width(&self) -> usize {
        self.object.width
    }
    fn height(&self) -> usize {
        self.object.height
    }
    #[inline]
    fn depth(&self, i: usize) -> f32 {
        self.depth_mm.data[i]
    }
    #[inline]
    fn put(&mut self, i: usize, z: f32, object: u8, _: u32, _: impl FnOnce() -> [f32; 2]) {
        self.depth_mm.data[i] = z;
        self.object.data[i] = object;
    }
}

/// Draws `objects` into `out`, front-most surface per pixel.
fn draw(camera: &Camera, objects: &[RenderObject], options: &RasterOptions, out: &mut impl Sink) {
    let straight = StraightnessBound::new(&camera.intrinsics, options.tolerance_px);
    draw_with(camera, objects, options, &straight, out);
}

/// [`draw`] with the straightness bound given (the tests give one that proves nothing).
fn draw_with(
    camera: &Camera,
    objects: &[RenderObject],
    options: &RasterOptions,
    straight: &StraightnessBound,
    out: &mut impl Sink,
) {
    let intr = &camera.intrinsics;
    let distorted = intr.has_distortion();
    for (oi, obj) in objects.iter().enumerate().take(NO_OBJECT as usize) {
        let cam: Vec<DVec3> = obj.vertices.iter().map(|&p| camera.to_camera(p)).collect();
        let projected: Vec<Option<Corner>> = cam
            .iter()
            .map(|&p| intr.project(p).map(|px| Corner::new(p, px, DVec2::ZERO)))
            .collect();
        // Which way the faces wind (the affine may mirror the mesh): the sign of its volume.
        let winding = (options.cull_back_faces && obj.closed)
            .then(|| {
                let volume: f64 = obj
                    .faces
                    .iter()
                    .filter(|f| f.iter().all(|&k| (k as usize) < cam.len()))
                    .map(|f| {
                        let [a, b, c] = f.map(|k| cam[k as usize]);
                        a.dot(b.cross(c))
                    })
                    .sum();
                (volume.abs() > 1e-9).then_some(volume.signum())
            })
            .flatten();
        for (fi, f) in obj.faces.iter().enumerate() {
            let idx = f.map(|k| k as usize);
            if idx.iter().any(|&k| k >= cam.len()) {
                continue;
            }
            if let Some(sign) = winding {
                let [a, b, c] = idx.map(|k| cam[k]);
                // Outward normal (sign-corrected) pointing away from the camera: a back face.
                if sign * (b - a).cross(c - a).dot(a) >= 0.0 {
                    continue;
                }
            }
            let (Some(c0), Some(mut c1), Some(mut c2)) =
                (projected[idx[0]], projected[idx[1]], projected[idx[2]])
            else {
                continue;
            };
            c1.bary = DVec2::X;
            c2.bary = DVec2::Y;
            let corners = [c0, c1, c2];
            let mut target = Target {
                out: &mut *out,
                object: oi as u8,
                triangle: fi as u32,
            };
            if distorted {
                subdivide(camera, straight, &corners, options, 0, &mut target);
            } else {
                fill_triangle(&corners, &mut target);
            }
        }
    }
}

struct Target<'a, S: Sink> {
    out: &'a mut S,
    object: u8,
    triangle: u32,
}

/// Distance (px) from the projection of an edge's 3D midpoint to the straight projected edge.
fn edge_bow(camera: &Camera, a: &Corner, b: &Corner) -> f64 {
    let Some(m) = camera.intrinsics.project((a.cam + b.cam) * 0.5) else {
        return f64::INFINITY;
    };
    let e = b.px - a.px;
    let len = e.length();
    if len < 1e-9 {
        return (m - a.px).length();
    }
    (e.perp_dot(m - a.px) / len).abs()
}

/// A bound on how far the lens model bows a triangle's projected edges and centroid away from
/// the straight triangle of its corners' pixels, from the distortion polynomial's second
/// derivative; [`subdivide`] fills the triangles it proves straight enough without the four
/// projections its own test costs (most of a fine mesh's triangles, at any level), taking the
/// same branch the test would: the pixels drawn are the same.
///
/// For the distortion D of normalised coordinates u and |u| ≤ R (s = R²), the radial part
/// u·g(|u|²) with g = 1 + k1 s + k2 s² + k3 s³ has a second derivative along a unit direction
/// of at most 6R|g'| + 4R³|g''|, and the tangential part at most 10(|p1| + |p2|): call the sum
/// M. A projected edge of normalised length L then bows by at most f·M·L²/8 px (a C² curve
/// stays within max|γ''|/8 of its chord; f the larger focal length), and the projection of the
/// triangle's 3D centroid lies within f·M·Lmax²/2 of the corners' depth-weighted mean (a
/// second-order Taylor bound around it; the weighted mean of the normalised corners is the
/// pinhole projection of the centroid). The disk of radius R holds the whole triangle (it is
/// convex and holds the corners), and inside the fold's cheap bound every point projects.
struct StraightnessBound {
    /// The radial coefficients' absolute values.
    k1: f64,
    k2: f64,
    k3: f64,
    /// The tangential part's second-derivative bound, 10(|p1| + |p2|).
    tangential: f64,
    /// The larger focal length (px per normalised unit).
    focal_px: f64,
    /// Half the tolerance (px): what the bound must stay under, rounding far below the rest.
    limit_px: f64,
}

impl StraightnessBound {
    fn new(intr: &crate::geometry::Intrinsics, tolerance_px: f64) -> Self {
        let (k1, k2, k3) = (intr.k1.abs(), intr.k2.abs(), intr.k3.abs());
        Self {
            k1,
            k2,
            k3,
            tangential: 10.0 * (intr.p1.abs() + intr.p2.abs()),
            focal_px: intr.fx.abs().max(intr.fy.abs()),
            limit_px: 0.5 * tolerance_px,
        }
    }

    /// Whether the bound proves every bow of `c` (edges and centroid) within the tolerance.
    fn proves(&self, c: &[Corner; 3]) -> bool {
        self.bound_px(c).is_some_and(|b| b <= self.limit_px)
    }

    /// The bound (px) on `c`'s largest bow, edges and centroid; `None` where it does not apply
    /// (corners beyond the fold's cheap bound, or a projected edge shorter than 0.001 px).
    fn bound_px(&self, c: &[Corner; 3]) -> Option<f64> {
        let u = c.map(|k| k.normalized);
        let s = u[0]
            .length_squared()
            .max(u[1].length_squared())
            .max(u[2].length_squared());
        // Inside Intrinsics::inside_fold's cheap bound (every point of the disk projects).
        // The corners reaching here were projected, so they are finite (`f64::max` would
        // pass over a NaN); `fold` and the edge lengths are checked so that NaN fails anyway.
        let fold = s * (3.0 * self.k1 + s * (5.0 * self.k2 + s * 7.0 * self.k3));
        if fold.is_nan() || fold >= 0.5 {
            return None;
        }
        let edge2 = (u[1] - u[0])
            .length_squared()
            .max((u[2] - u[1]).length_squared())
            .max((u[0] - u[2]).length_squared());
        // Degenerate projected edges take edge_bow's other formula: leave them to the test.
        let min_edge_px2 = (c[1].px - c[0].px)
            .length_squared()
            .min((c[2].px - c[1].px).length_squared())
            .min((c[0].px - c[2].px).length_squared());
        if min_edge_px2.is_nan() || min_edge_px2 < 1e-6 {
            return None;
        }
        let r = s.sqrt();
        let slope = self.k1 + s * (2.0 * self.k2 + s * 3.0 * self.k3);
        let curve = 2.0 * self.k2 + s * 6.0 * self.k3;
        let m = 6.0 * r * slope + 4.0 * r * s * curve + self.tangential;
        // The centroid's bound (Lmax²/2) is the larger of the two.
        Some(self.focal_px * m * edge2 * 0.5)
    }
}

fn subdivide<S: Sink>(
    camera: &Camera,
    straight: &StraightnessBound,
    c: &[Corner; 3],
    options: &RasterOptions,
    level: u32,
    target: &mut Target<S>,
) {
    if straight.proves(c) {
        fill_triangle(c, target);
        return;
    }
    // Edges bow, and the interior stretches unevenly: check the centroid too.
    let centroid_shift = camera
        .intrinsics
        .project((c[0].cam + c[1].cam + c[2].cam) / 3.0)
        .map(|m| {
            // Where a pinhole puts the 3D centroid: the corners' pixels weighted by depth.
            let w = [c[0].cam.z, c[1].cam.z, c[2].cam.z];
            let affine = (c[0].px * w[0] + c[1].px * w[1] + c[2].px * w[2]) / (w[0] + w[1] + w[2]);
            (m - affine).length()
        })
        .unwrap_or(f64::INFINITY);
    let bow = edge_bow(camera, &c[0], &c[1])
        .max(edge_bow(camera, &c[1], &c[2]))
        .max(edge_bow(camera, &c[2], &c[0]))
        .max(centroid_shift);
    if bow <= options.tolerance_px || level >= options.max_subdivision {
        fill_triangle(c, target);
        return;
    }
    let mid = |a: &Corner, b: &Corner| {
        let cam = (a.cam + b.cam) * 0.5;
        camera
            .intrinsics
            .project(cam)
            .map(|px| Corner::new(cam, px, (a.bary + b.bary) * 0.5))
    };
    let (Some(m01), Some(m12), Some(m20)) =
        (mid(&c[0], &c[1]), mid(&c[1], &c[2]), mid(&c[2], &c[0]))
    else {
        return;
    };
    for sub in [
        [c[0], m01, m20],
        [m01, c[1], m12],
        [m20, m12, c[2]],
        [m01, m12, m20],
    ] {
        subdivide(camera, straight, &sub, options, level + 1, target);
    }
}

/// Scan-converts one (sub)triangle with a depth test, sampling pixel centres.
fn fill_triangle<S: Sink>(c: &[Corner; 3], target: &mut Target<S>) {
    let (w, h) = (target.out.width(), target.out.height());
    let [a, b, d] = [c[0].px, c[1].px, c[2].px];
    let area = (b - a).perp_dot(d - a);
    if area.abs() < 1e-12 || c.iter().any(|k| k.cam.z <= NEAR_MM) {
        return;
    }
    let lo = a.min(b).min(d);
    let hi = a.max(b).max(d);
    if hi.x < 0.0 || hi.y < 0.0 || lo.x > (w - 1) as f64 || lo.y > (h - 1) as f64 {
        return;
    }
    let x0 = lo.x.ceil().max(0.0) as usize;
    let y0 = lo.y.ceil().max(0.0) as usize;
    let x1 = (hi.x.floor() as i64).min(w as i64 - 1);
    let y1 = (hi.y.floor() as i64).min(h as i64 - 1);
    if x1 < x0 as i64 || y1 < y0 as i64 {
        return;
    }
    let inv_area = 1.0 / area;
    let inv_z = [c[0].inv_z, c[1].inv_z, c[2].inv_z];
    for y in y0..=y1 as usize {
        let py = y as f64;
        for x in x0..=x1 as usize {
            let p = DVec2::new(x as f64, py);
            // Normalised edge functions = screen-space barycentrics of this sub-triangle.
            let l0 = (c[2].px - c[1].px).perp_dot(p - c[1].px) * inv_area;
            let l1 = (c[0].px - c[2].px).perp_dot(p - c[2].px) * inv_area;
            let l2 = 1.0 - l0 - l1;
            // One branch instead of three (`|`, not `||`): tiny triangles' pixels fall either
            // side of their edges with no pattern a predictor learns. NaN passes, as before.
            if (l0 < 0.0) | (l1 < 0.0) | (l2 < 0.0) {
                continue;
            }
            // Perspective-correct: interpolate 1/Z and attribute/Z linearly in the image.
            let iz = l0 * inv_z[0] + l1 * inv_z[1] + l2 * inv_z[2];
            let z = 1.0 / iz;
            let i = y * w + x;
            if (z as f32) < target.out.depth(i) {
                target
                    .out
                    .put(i, z as f32, target.object, target.triangle, || {
                        let bary = (c[0].bary * (l0 * inv_z[0])
                            + c[1].bary * (l1 * inv_z[1])
                            + c[2].bary * (l2 * inv_z[2]))
                            * z;
                        [bary.x as f32, bary.y as f32]
                    });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Extrinsics, Intrinsics, Mesh};
    use crate::rng::Rng;

    /// Ray casting: every pixel's ray (undistorted exactly) against every triangle.
    fn brute_force(camera: &Camera, objects: &[RenderObject]) -> (Plane<u8>, Plane<f32>) {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mut obj = Plane::filled(w, h, NO_OBJECT);
        let mut depth = Plane::filled(w, h, f32::INFINITY);
        for y in 0..h {
            for x in 0..w {
                let n = camera.intrinsics.unproject(DVec2::new(x as f64, y as f64));
                let dir = DVec3::new(n.x, n.y, 1.0);
                for (oi, o) in objects.iter().enumerate() {
                    for f in o.faces {
                        let [a, b, c] = f.map(|k| camera.to_camera(o.vertices[k as usize]));
                        // Möller–Trumbore from the camera centre; t is the depth Z since dir.z = 1.
                        let (e1, e2) = (b - a, c - a);
                        let pv = dir.cross(e2);
                        let det = e1.dot(pv);
                        if det.abs() < 1e-12 {
                            continue;
                        }
                        let tv = -a;
                        let u = tv.dot(pv) / det;
                        let qv = tv.cross(e1);
                        let v = dir.dot(qv) / det;
                        let t = e2.dot(qv) / det;
                        if u >= 0.0
                            && v >= 0.0
                            && u + v <= 1.0
                            && t > NEAR_MM
                            && (t as f32) < *depth.get(x, y)
                        {
                            depth.set(x, y, t as f32);
                            obj.set(x, y, oi as u8);
                        }
                    }
                }
            }
        }
        (obj, depth)
    }

    /// The meshes as render objects, closed where their faces are.
    fn closed_objects(meshes: &[Mesh]) -> Vec<RenderObject<'_>> {
        meshes
            .iter()
            .map(|m| RenderObject {
                vertices: &m.vertices,
                faces: &m.faces,
                closed: crate::fit::model::is_closed(&m.faces),
            })
            .collect()
    }

    fn random_blob(rng: &mut Rng, center: DVec3, radius: f64) -> Mesh {
        let s = crate::geometry::mesh::icosphere(2);
        let axes = DVec3::new(
            rng.range(0.6, 1.4),
            rng.range(0.6, 1.4),
            rng.range(0.6, 1.4),
        ) * radius;
        let bumps = [rng.unit_vector(), rng.unit_vector()];
        let verts = s
            .vertices
            .iter()
            .map(|v| {
                let r = 1.0 + 0.2 * (3.0 * v.dot(bumps[0])).sin() * (2.0 * v.dot(bumps[1])).cos();
                center + *v * axes * r
            })
            .collect();
        Mesh::new(verts, s.faces)
    }

    fn scene(rng: &mut Rng, k1: f64) -> (Camera, Vec<Mesh>) {
        let cam = Camera {
            name: "t".into(),
            width: 96,
            height: 72,
            intrinsics: Intrinsics {
                k1,
                k2: k1 * 0.3,
                p1: k1 * 0.01,
                ..Intrinsics::pinhole(90.0, 92.0, 47.3, 35.8)
            },
            extrinsics: Extrinsics {
                rotation: crate::geometry::pose::rotation_from_vector(rng.unit_vector() * 0.05),
                translation_mm: DVec3::new(-4.5, 0.0, 0.0),
            },
        };
        let meshes = (0..3)
            .map(|_| {
                let c = DVec3::new(
                    rng.range(-30.0, 30.0),
                    rng.range(-20.0, 20.0),
                    rng.range(90.0, 140.0),
                );
                let r = rng.range(10.0, 30.0);
                random_blob(rng, c, r)
            })
            .collect();
        (cam, meshes)
    }

    fn compare(k1: f64, seed: u64, allowed_mismatch_per_pixel_of_edge: f64) {
        let mut rng = Rng::new(seed);
        for _ in 0..4 {
            let (cam, meshes) = scene(&mut rng, k1);
            let objects: Vec<RenderObject> = meshes
                .iter()
                .map(|m| RenderObject {
                    vertices: &m.vertices,
                    faces: &m.faces,
                    closed: false,
                })
                .collect();
            let fast = rasterize(&cam, &objects, &RasterOptions::default());
            let (obj, depth) = brute_force(&cam, &objects);
            let mut mismatch = 0;
            let mut boundary = 0;
            for i in 0..obj.data.len() {
                let (x, y) = (i % obj.width, i / obj.width);
                // Boundary pixels: any 4-neighbour differs in the brute-force object map.
                let edge = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
                    .iter()
                    .any(|(dx, dy)| {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        nx >= 0
                            && ny >= 0
                            && (nx as usize) < obj.width
                            && (ny as usize) < obj.height
                            && *obj.get(nx as usize, ny as usize) != obj.data[i]
                    });
                boundary += edge as usize;
                if fast.object.data[i] != obj.data[i] {
                    mismatch += 1;
                    assert!(
                        edge,
                        "interior pixel ({x},{y}) differs: {} vs {}",
                        fast.object.data[i], obj.data[i]
                    );
                } else if obj.data[i] != NO_OBJECT && !edge {
                    // Depth must be right to within half a pixel of position: allow half the
                    // largest depth step to a neighbour (steep where the surface turns away).
                    let step = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
                        .iter()
                        .filter_map(|(dx, dy)| {
                            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                            (nx >= 0
                                && ny >= 0
                                && (nx as usize) < obj.width
                                && (ny as usize) < obj.height)
                                .then(|| {
                                    (depth.get(nx as usize, ny as usize) - depth.data[i]).abs()
                                })
                        })
                        .fold(0.0f32, f32::max);
                    let (a, b) = (fast.depth_mm.data[i], depth.data[i]);
                    assert!(
                        (a - b).abs() < 0.02 + 0.5 * step,
                        "depth at ({x},{y}): {a} vs {b} (neighbour step {step})"
                    );
                }
            }
            assert!(
                (mismatch as f64) <= allowed_mismatch_per_pixel_of_edge * boundary as f64,
                "{mismatch} mismatches over {boundary} boundary pixels"
            );
            // The surface point behind a pixel lies on its ray.
            for i in (0..obj.data.len()).step_by(7) {
                if let Some(p) = fast.surface_point(&objects, i) {
                    let px = cam.project(p).unwrap();
                    let (x, y) = ((i % obj.width) as f64, (i / obj.width) as f64);
                    assert!(
                        (px - DVec2::new(x, y)).length() < 0.3,
                        "surface point reprojects {px:?} for ({x},{y})"
                    );
                }
            }
        }
    }

    #[test]
    fn pinhole_raster_matches_ray_casting() {
        compare(0.0, 61, 0.01);
    }

    #[test]
    fn distorted_raster_matches_ray_casting() {
        compare(-0.25, 62, 0.05);
        compare(0.2, 63, 0.05);
    }

    /// Culling closed objects' back faces changes nothing a raster says (object, triangle,
    /// depth), mirrored meshes included (their faces wind the other way).
    /// The object-only raster is the full raster's object plane, pixel for pixel, with and
    /// without distortion (subdivided triangles) and with back faces culled.
    #[test]
    fn object_rasters_equal_the_full_rasters_object_plane() {
        let mut rng = Rng::new(73);
        for k1 in [0.0, -0.25] {
            let (cam, meshes) = scene(&mut rng, k1);
            let objects = closed_objects(&meshes);
            for cull_back_faces in [false, true] {
                let options = RasterOptions {
                    cull_back_faces,
                    ..RasterOptions::default()
                };
                let full = rasterize(&cam, &objects, &options);
                assert!(full.coverage().data.iter().filter(|&&c| c).count() > 500);
                assert_eq!(rasterize_objects(&cam, &objects, &options), full.object);
            }
        }
    }

    #[test]
    fn culling_back_faces_of_closed_meshes_is_exact() {
        let mut rng = Rng::new(71);
        for k1 in [0.0, -0.2] {
            let (cam, mut meshes) = scene(&mut rng, k1);
            // Mirror one mesh through its centre's x: its winding flips.
            let c = meshes[1].vertex_mean();
            for v in &mut meshes[1].vertices {
                v.x = 2.0 * c.x - v.x;
            }
            let objects = closed_objects(&meshes);
            assert!(objects.iter().all(|o| o.closed));
            let all = rasterize(&cam, &objects, &RasterOptions::default());
            let culled = rasterize(
                &cam,
                &objects,
                &RasterOptions {
                    cull_back_faces: true,
                    ..RasterOptions::default()
                },
            );
            let covered = all.object.data.iter().filter(|&&o| o != NO_OBJECT).count();
            assert!(covered > 500, "the meshes cover {covered} px");
            let differ = (0..all.object.data.len())
                .filter(|&i| {
                    all.object.data[i] != culled.object.data[i]
                        || all.triangle.data[i] != culled.triangle.data[i]
                        || all.depth_mm.data[i] != culled.depth_mm.data[i]
                })
                .count();
            assert_eq!(differ, 0, "k1 {k1}: {differ} of {covered} pixels differ");
        }
    }

    /// The straightness bound never understates what `subdivide` measures (the three edges'
    /// bows and the centroid's shift, by projection): random lenses (k1 to ±0.3, k2, k3, p1,
    /// p2), triangles from a hundredth of a pixel to a third of the view across, near the axis
    /// and at the view's corners, any depths.
    #[test]
    fn straightness_bound_holds_against_measured_bows() {
        let mut rng = Rng::new(91);
        let mut applied = 0;
        for _ in 0..40 {
            let intr = Intrinsics {
                k1: rng.range(-0.3, 0.3),
                k2: rng.range(-0.1, 0.1),
                k3: rng.range(-0.05, 0.05),
                p1: rng.range(-0.01, 0.01),
                p2: rng.range(-0.01, 0.01),
                ..Intrinsics::pinhole(
                    rng.range(200.0, 1200.0),
                    rng.range(200.0, 1200.0),
                    480.0,
                    270.0,
                )
            };
            let camera = Camera {
                name: "t".into(),
                width: 960,
                height: 540,
                intrinsics: intr,
                extrinsics: Extrinsics::default(),
            };
            let bound = StraightnessBound::new(&intr, 0.2);
            for _ in 0..200 {
                let size = 10f64.powf(rng.range(-4.0, -0.5));
                let centre = DVec2::new(rng.range(-0.7, 0.7), rng.range(-0.5, 0.5));
                let corners = [0, 1, 2].map(|k| {
                    let u = centre + DVec2::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * size;
                    let z = rng.range(50.0, 300.0);
                    let cam = DVec3::new(u.x * z, u.y * z, z);
                    Corner::new(
                        cam,
                        intr.project(cam).unwrap_or(DVec2::NAN),
                        DVec2::splat(k as f64),
                    )
                });
                let Some(b) = bound.bound_px(&corners) else {
                    continue;
                };
                applied += 1;
                let measured = edge_bow(&camera, &corners[0], &corners[1])
                    .max(edge_bow(&camera, &corners[1], &corners[2]))
                    .max(edge_bow(&camera, &corners[2], &corners[0]));
                let m = intr
                    .project((corners[0].cam + corners[1].cam + corners[2].cam) / 3.0)
                    .unwrap();
                let w = corners.map(|c| c.cam.z);
                let affine = (corners[0].px * w[0] + corners[1].px * w[1] + corners[2].px * w[2])
                    / (w[0] + w[1] + w[2]);
                let measured = measured.max((m - affine).length());
                assert!(
                    measured <= b * (1.0 + 1e-9) + 1e-9,
                    "measured bow {measured} px over the bound {b} px ({intr:?})"
                );
            }
        }
        assert!(
            applied > 4000,
            "the bound applied to {applied} triangles only"
        );
    }

    /// Rasters drawn with the straightness bound equal those drawn with the projections' test
    /// on every triangle, plane for plane (the bound only skips tests that would pass). The
    /// scenes are coarse spheres through strong lenses, so that many triangles bow past the
    /// tolerance: a bound that claimed 100 times more than it proves changes pixels there.
    #[test]
    fn straightness_bound_changes_no_pixel() {
        let mut rng = Rng::new(93);
        for (k1, k2, p1) in [
            (-0.3, 0.05, 0.005),
            (0.2, -0.05, -0.005),
            (-0.04, -0.007, 0.0),
        ] {
            let cam = Camera {
                name: "t".into(),
                width: 320,
                height: 240,
                intrinsics: Intrinsics {
                    k1,
                    k2,
                    p1,
                    ..Intrinsics::pinhole(400.0, 410.0, 159.5, 119.5)
                },
                extrinsics: Extrinsics::default(),
            };
            let meshes: Vec<Mesh> = (0..3)
                .map(|_| {
                    let s = crate::geometry::mesh::icosphere(1);
                    let centre = DVec3::new(
                        rng.range(-30.0, 30.0),
                        rng.range(-20.0, 20.0),
                        rng.range(90.0, 130.0),
                    );
                    let radius = rng.range(15.0, 35.0);
                    Mesh::new(
                        s.vertices.iter().map(|v| centre + *v * radius).collect(),
                        s.faces,
                    )
                })
                .collect();
            let objects = closed_objects(&meshes);
            let options = RasterOptions::default();
            let drawn = |bound: &StraightnessBound| {
                let mut out = ViewRaster::empty(cam.width as usize, cam.height as usize);
                draw_with(&cam, &objects, &options, bound, &mut out);
                out
            };
            let bound = StraightnessBound::new(&cam.intrinsics, options.tolerance_px);
            let with_bound = rasterize(&cam, &objects, &options);
            let tested = drawn(&StraightnessBound {
                limit_px: f64::NEG_INFINITY,
                ..StraightnessBound::new(&cam.intrinsics, options.tolerance_px)
            });
            let overclaimed = drawn(&StraightnessBound {
                limit_px: bound.limit_px * 100.0,
                ..StraightnessBound::new(&cam.intrinsics, options.tolerance_px)
            });
            assert!(with_bound.coverage().data.iter().filter(|&&c| c).count() > 5000);
            assert_eq!(with_bound, tested, "k1 {k1}");
            if k1.abs() > 0.1 {
                assert_ne!(overclaimed, tested, "k1 {k1}: no triangle needed splitting");
            }
        }
    }
}
