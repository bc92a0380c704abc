//! The camera model of the paper's eq. 10–11 (OpenCV convention: k1, k2 radial, p1, p2
//! decentering; pixel centres at integer coordinates), with analytic Jacobians of a projected
//! point with respect to the 3D point and to the five intrinsics the fit corrects under zoom
//! (fx, fy, cx, cy, k1; the paper's Table III).

use glam::{DMat3, DVec2, DVec3};

/// Points closer to the camera plane than this (mm) are not projected.
pub const NEAR_MM: f64 = 1e-3;

/// The eight intrinsics of eq. 10, in pixels (focal lengths, principal point) and unitless
/// (distortion).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    /// Third radial coefficient (OpenCV's k3, r⁶ term). Absent in older scenes and outputs
    /// (read as 0, not written when 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub k3: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// Intrinsics no real camera of the given image size has (a typo, a unit slip, a file of
/// another tool's convention). Bounds are wide: a field of view between ~0.1° and ~178°, a
/// principal point within one image size of the image, distortion of real lenses.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IntrinsicsError {
    #[error("intrinsics must be finite numbers")]
    NonFinite,
    #[error("focal lengths must be positive, got fx={fx_px} fy={fy_px}")]
    NonPositiveFocal { fx_px: f64, fy_px: f64 },
    #[error(
        "focal length {focal_px:e} px is implausible for a {size_px} px wide image (expected {min_px:.0}–{max_px:.0} px)"
    )]
    FocalOutOfRange {
        focal_px: f64,
        size_px: u32,
        min_px: f64,
        max_px: f64,
    },
    #[error(
        "principal point ({cx_px}, {cy_px}) px lies far outside the {width_px}×{height_px} image"
    )]
    PrincipalPoint {
        cx_px: f64,
        cy_px: f64,
        width_px: u32,
        height_px: u32,
    },
    #[error("distortion coefficient {name} = {value} is beyond any real lens (|{name}| ≤ {limit})")]
    Distortion {
        name: &'static str,
        value: f64,
        limit: f64,
    },
}

impl Intrinsics {
    /// Checks that these intrinsics can belong to a real camera of `width`×`height` pixels.
    pub fn check_plausible(&self, width: u32, height: u32) -> Result<(), IntrinsicsError> {
        let all = [
            self.fx, self.fy, self.cx, self.cy, self.k1, self.k2, self.p1, self.p2, self.k3,
        ];
        if all.iter().any(|v| !v.is_finite()) {
            return Err(IntrinsicsError::NonFinite);
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(IntrinsicsError::NonPositiveFocal {
                fx_px: self.fx,
                fy_px: self.fy,
            });
        }
        let size = width.max(height).max(1);
        let (min_px, max_px) = (0.02 * size as f64, 1000.0 * size as f64);
        for focal_px in [self.fx, self.fy] {
            if !(min_px..=max_px).contains(&focal_px) {
                return Err(IntrinsicsError::FocalOutOfRange {
                    focal_px,
                    size_px: size,
                    min_px,
                    max_px,
                });
            }
        }
        let (w, h) = (width as f64, height as f64);
        if !(-w..=2.0 * w).contains(&self.cx) || !(-h..=2.0 * h).contains(&self.cy) {
            return Err(IntrinsicsError::PrincipalPoint {
                cx_px: self.cx,
                cy_px: self.cy,
                width_px: width,
                height_px: height,
            });
        }
        for (name, value, limit) in [
            ("k1", self.k1, 1e3),
            ("k2", self.k2, 1e3),
            ("k3", self.k3, 1e3),
            ("p1", self.p1, 1.0),
            ("p2", self.p2, 1.0),
        ] {
            if value.abs() > limit {
                return Err(IntrinsicsError::Distortion { name, value, limit });
            }
        }
        Ok(())
    }
}

/// Which intrinsics the fit may correct, in this order (the paper's π_m).
pub const CORRECTED_INTRINSICS: [&str; 5] = ["fx", "fy", "cx", "cy", "k1"];

/// Rigid map from camera-0 (reference) coordinates into this camera, eq. 11, millimetres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extrinsics {
    pub rotation: DMat3,
    pub translation_mm: DVec3,
}

impl Default for Extrinsics {
    fn default() -> Self {
        Self {
            rotation: DMat3::IDENTITY,
            translation_mm: DVec3::ZERO,
        }
    }
}

/// One camera of the rig: image size, intrinsics and extrinsics.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub intrinsics: Intrinsics,
    pub extrinsics: Extrinsics,
}

/// Scale of pyramid level `level` relative to full resolution (each level halves the image).
pub fn level_scale(level: usize) -> f64 {
    1.0 / (1u32 << level) as f64
}

/// A full-resolution pixel position in an image scaled by `s`. Pixel centres lie at integer
/// coordinates at every scale, so the map is (p + ½)·s − ½.
pub fn pixel_at_scale(p: DVec2, s: f64) -> DVec2 {
    (p + DVec2::splat(0.5)) * s - DVec2::splat(0.5)
}

/// The inverse of [`pixel_at_scale`]: a pixel of the image scaled by `s` at full resolution.
pub fn pixel_from_scale(p: DVec2, s: f64) -> DVec2 {
    (p + DVec2::splat(0.5)) / s - DVec2::splat(0.5)
}

/// Intermediate values of a projection, shared by the projection and its Jacobians.
struct Distorted {
    xn: f64,
    yn: f64,
    r2: f64,
    radial: f64,
    xd: f64,
    yd: f64,
}

impl Intrinsics {
    pub fn pinhole(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self {
            fx,
            fy,
            cx,
            cy,
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        }
    }

    pub fn has_distortion(&self) -> bool {
        self.k1 != 0.0 || self.k2 != 0.0 || self.p1 != 0.0 || self.p2 != 0.0 || self.k3 != 0.0
    }

    /// Whether a point at normalised radius² `r2` lies inside the lens model's fold: the
    /// distorted radius r·(1 + k1 r² + k2 r⁴ + k3 r⁶) grows with r from the centre up to its
    /// first turning point, and beyond it the polynomial folds back. With k1 and k2 both
    /// negative (k1 −0.04, k2 −0.007, as drawn for the widened phantoms) that is r ≈ 2, 64°
    /// off the axis: a point there would land back inside the image, and the phantom drew a
    /// tool's far shaft as black wedges across the organ. Such points are not imaged.
    ///
    /// Exact: the derivative d(s) = 1 + 3k1 s + 5k2 s² + 7k3 s³ of the distorted radius (s = r²)
    /// is 1 at the centre, and it stays positive on [0, r2] exactly when it is positive at r2
    /// and at its own turning points inside (the roots of 3k1 + 10k2 s + 21k3 s²).
    fn inside_fold(&self, r2: f64) -> bool {
        let (k1, k2, k3) = (self.k1, self.k2, self.k3);
        // Most calls are well inside the view: a bound that needs no roots.
        if r2 * (3.0 * k1.abs() + r2 * (5.0 * k2.abs() + r2 * 7.0 * k3.abs())) < 1.0 {
            return true;
        }
        let d = |s: f64| 1.0 + s * (3.0 * k1 + s * (5.0 * k2 + s * 7.0 * k3));
        let at_r2 = d(r2);
        if at_r2.is_nan() || at_r2 <= 0.0 {
            return false;
        }
        let (a, b, c) = (21.0 * k3, 10.0 * k2, 3.0 * k1);
        let mut turning = [f64::NAN; 2];
        if a != 0.0 {
            let disc = b * b - 4.0 * a * c;
            if disc >= 0.0 {
                let root = disc.sqrt();
                turning = [(-b - root) / (2.0 * a), (-b + root) / (2.0 * a)];
            }
        } else if b != 0.0 {
            turning[0] = -c / b;
        }
        turning
            .iter()
            .filter(|&&s| s > 0.0 && s < r2)
            .all(|&s| d(s) > 0.0)
    }

    /// d(radial factor)/d(r²) at r².
    fn radial_slope(&self, r2: f64) -> f64 {
        self.k1 + 2.0 * self.k2 * r2 + 3.0 * self.k3 * r2 * r2
    }

    fn distort_parts(&self, xn: f64, yn: f64) -> Distorted {
        let r2 = xn * xn + yn * yn;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let xd = xn * radial + 2.0 * self.p1 * xn * yn + self.p2 * (r2 + 2.0 * xn * xn);
        let yd = yn * radial + self.p1 * (r2 + 2.0 * yn * yn) + 2.0 * self.p2 * xn * yn;
        Distorted {
            xn,
            yn,
            r2,
            radial,
            xd,
            yd,
        }
    }

    /// Distorts normalised coordinates (x', y') into (x'', y'') of eq. 10.
    pub fn distort(&self, normalized: DVec2) -> DVec2 {
        let d = self.distort_parts(normalized.x, normalized.y);
        DVec2::new(d.xd, d.yd)
    }

    /// Projects a point given in this camera's coordinates (mm) to pixels, or `None` when it
    /// lies behind the camera or beyond the lens model's fold ([`Intrinsics::inside_fold`]).
    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        if p.z <= NEAR_MM {
            return None;
        }
        let d = self.distort_parts(p.x / p.z, p.y / p.z);
        if !self.inside_fold(d.r2) {
            return None;
        }
        Some(DVec2::new(
            self.fx * d.xd + self.cx,
            self.fy * d.yd + self.cy,
        ))
    }

    /// Jacobian of the pixel with respect to the camera-frame point, rows (u, v), columns
    /// (X, Y, Z). `None` where [`Intrinsics::project`] is.
    pub fn jacobian_point(&self, p: DVec3) -> Option<[[f64; 3]; 2]> {
        if p.z <= NEAR_MM {
            return None;
        }
        let inv_z = 1.0 / p.z;
        let d = self.distort_parts(p.x * inv_z, p.y * inv_z);
        if !self.inside_fold(d.r2) {
            return None;
        }
        let (x, y) = (d.xn, d.yn);
        // Derivative of the radial factor with respect to r², then the 2×2 distortion Jacobian.
        let dradial = self.radial_slope(d.r2);
        let dxd_dx = d.radial + 2.0 * x * x * dradial + 2.0 * self.p1 * y + 6.0 * self.p2 * x;
        let dxd_dy = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let dyd_dx = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let dyd_dy = d.radial + 2.0 * y * y * dradial + 6.0 * self.p1 * y + 2.0 * self.p2 * x;
        // x' = X/Z, y' = Y/Z.
        let dn = [[inv_z, 0.0, -x * inv_z], [0.0, inv_z, -y * inv_z]];
        let mut j = [[0.0; 3]; 2];
        for c in 0..3 {
            j[0][c] = self.fx * (dxd_dx * dn[0][c] + dxd_dy * dn[1][c]);
            j[1][c] = self.fy * (dyd_dx * dn[0][c] + dyd_dy * dn[1][c]);
        }
        Some(j)
    }

    /// Jacobian of the pixel with respect to (fx, fy, cx, cy, k1), the paper's Table III.
    pub fn jacobian_intrinsics(&self, p: DVec3) -> Option<[[f64; 5]; 2]> {
        if p.z <= NEAR_MM {
            return None;
        }
        let d = self.distort_parts(p.x / p.z, p.y / p.z);
        if !self.inside_fold(d.r2) {
            return None;
        }
        Some([
            [d.xd, 0.0, 1.0, 0.0, self.fx * d.xn * d.r2],
            [0.0, d.yd, 0.0, 1.0, self.fy * d.yn * d.r2],
        ])
    }

    /// Inverts the distortion: the normalised coordinates (x', y') whose projection is
    /// `pixel`. Newton iterations on eq. 10; exact to ~1e-12 for the distortions of real
    /// endoscopes.
    pub fn unproject(&self, pixel: DVec2) -> DVec2 {
        let target = DVec2::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy);
        if !self.has_distortion() {
            return target;
        }
        let mut n = target;
        for _ in 0..20 {
            let d = self.distort_parts(n.x, n.y);
            let residual = DVec2::new(d.xd, d.yd) - target;
            if residual.length_squared() < 1e-26 {
                break;
            }
            // Jacobian of (x'', y'') with respect to (x', y') at n.
            let dradial = self.radial_slope(d.r2);
            let a =
                d.radial + 2.0 * n.x * n.x * dradial + 2.0 * self.p1 * n.y + 6.0 * self.p2 * n.x;
            let b = 2.0 * n.x * n.y * dradial + 2.0 * self.p1 * n.x + 2.0 * self.p2 * n.y;
            let c = b;
            let e =
                d.radial + 2.0 * n.y * n.y * dradial + 6.0 * self.p1 * n.y + 2.0 * self.p2 * n.x;
            let det = a * e - b * c;
            if det.abs() < 1e-12 {
                break;
            }
            n -= DVec2::new(
                e * residual.x - b * residual.y,
                -c * residual.x + a * residual.y,
            ) / det;
        }
        n
    }

    /// These intrinsics for the image scaled by `s` ([`pixel_at_scale`]: focal lengths scale,
    /// the principal point keeps its pixel-centre convention; distortion acts on normalised
    /// coordinates and does not change).
    pub fn scaled(&self, s: f64) -> Intrinsics {
        Intrinsics {
            fx: self.fx * s,
            fy: self.fy * s,
            cx: (self.cx + 0.5) * s - 0.5,
            cy: (self.cy + 0.5) * s - 0.5,
            ..*self
        }
    }

    /// Parameters as an array in [`CORRECTED_INTRINSICS`] order.
    pub fn corrected(&self) -> [f64; 5] {
        [self.fx, self.fy, self.cx, self.cy, self.k1]
    }

    pub fn with_corrected(mut self, v: [f64; 5]) -> Self {
        [self.fx, self.fy, self.cx, self.cy, self.k1] = v;
        self
    }
}

impl Extrinsics {
    pub fn apply(&self, p_ref: DVec3) -> DVec3 {
        self.rotation * p_ref + self.translation_mm
    }

    /// The camera centre in reference (camera-0) coordinates, mm.
    pub fn center_mm(&self) -> DVec3 {
        -(self.rotation.transpose() * self.translation_mm)
    }
}

impl Camera {
    /// Maps a reference-frame (camera-0) point into this camera's frame (eq. 11).
    pub fn to_camera(&self, p_ref: DVec3) -> DVec3 {
        self.extrinsics.apply(p_ref)
    }

    /// Projects a reference-frame point to this camera's pixels (eq. 10–11).
    pub fn project(&self, p_ref: DVec3) -> Option<DVec2> {
        self.intrinsics.project(self.to_camera(p_ref))
    }

    /// Jacobian of the pixel with respect to the reference-frame point: J_proj · R_m.
    pub fn jacobian_ref_point(&self, p_ref: DVec3) -> Option<[[f64; 3]; 2]> {
        self.jacobian_ref_point_with(&self.intrinsics, p_ref)
    }

    /// [`Camera::jacobian_ref_point`] under other intrinsics (those a fit is correcting).
    pub fn jacobian_ref_point_with(
        &self,
        intrinsics: &Intrinsics,
        p_ref: DVec3,
    ) -> Option<[[f64; 3]; 2]> {
        let j = intrinsics.jacobian_point(self.to_camera(p_ref))?;
        let r = self.extrinsics.rotation;
        let mut out = [[0.0; 3]; 2];
        for (row, jr) in out.iter_mut().zip(j.iter()) {
            for (c, o) in row.iter_mut().enumerate() {
                // Column c of R is its c-th column vector; (J R)[row][c] = Σ_k J[row][k] R[k][c].
                let col = r.col(c);
                *o = jr[0] * col.x + jr[1] * col.y + jr[2] * col.z;
            }
        }
        Some(out)
    }

    /// This camera with `intrinsics` (those a fit is correcting) at pyramid level `level`,
    /// whose image is `size` pixels.
    pub fn at_level(&self, intrinsics: &Intrinsics, level: usize, size: (usize, usize)) -> Camera {
        Camera {
            intrinsics: intrinsics.scaled(level_scale(level)),
            width: size.0 as u32,
            height: size.1 as u32,
            ..self.clone()
        }
    }

    /// Unit ray direction (camera-0 coordinates) and origin through a pixel.
    pub fn pixel_ray(&self, pixel: DVec2) -> (DVec3, DVec3) {
        self.pixel_ray_with(&self.intrinsics, pixel)
    }

    /// [`Camera::pixel_ray`] under other intrinsics (those a fit is correcting).
    pub fn pixel_ray_with(&self, intrinsics: &Intrinsics, pixel: DVec2) -> (DVec3, DVec3) {
        let n = intrinsics.unproject(pixel);
        let dir_cam = DVec3::new(n.x, n.y, 1.0).normalize();
        let rt = self.extrinsics.rotation.transpose();
        (self.extrinsics.center_mm(), rt * dir_cam)
    }

    /// Distance between this camera's centre and camera 0's, mm.
    pub fn baseline_mm(&self) -> f64 {
        self.extrinsics.center_mm().length()
    }

    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn random_camera(rng: &mut Rng) -> Camera {
        let fx = rng.range(600.0, 1400.0);
        let intr = Intrinsics {
            fx,
            fy: fx * rng.range(0.95, 1.05),
            cx: rng.range(300.0, 500.0),
            cy: rng.range(200.0, 300.0),
            k1: rng.range(-0.2, 0.2),
            k2: rng.range(-0.05, 0.05),
            p1: rng.range(-0.005, 0.005),
            p2: rng.range(-0.005, 0.005),
            k3: rng.range(-0.02, 0.02),
        };
        let rot =
            crate::geometry::pose::rotation_from_vector(rng.unit_vector() * rng.range(0.0, 0.2));
        Camera {
            name: "c".into(),
            width: 960,
            height: 540,
            intrinsics: intr,
            extrinsics: Extrinsics {
                rotation: rot,
                translation_mm: DVec3::new(
                    rng.range(-5.0, 5.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                ),
            },
        }
    }

    fn random_point(rng: &mut Rng) -> DVec3 {
        DVec3::new(
            rng.range(-40.0, 40.0),
            rng.range(-30.0, 30.0),
            rng.range(80.0, 250.0),
        )
    }

    #[test]
    fn point_jacobian_matches_central_differences() {
        let mut rng = Rng::new(11);
        for _ in 0..200 {
            let cam = random_camera(&mut rng);
            let p = random_point(&mut rng);
            let j = cam.jacobian_ref_point(p).unwrap();
            for c in 0..3 {
                let h = 1e-4;
                let mut e = DVec3::ZERO;
                e[c] = h;
                let fd = (cam.project(p + e).unwrap() - cam.project(p - e).unwrap()) / (2.0 * h);
                for (r, fdv) in [fd.x, fd.y].iter().enumerate() {
                    let err = (j[r][c] - fdv).abs();
                    assert!(
                        err < 1e-5 * (1.0 + fdv.abs()),
                        "d{r}/dP{c}: {} vs {fdv}",
                        j[r][c]
                    );
                }
            }
        }
    }

    #[test]
    fn intrinsics_jacobian_matches_central_differences() {
        let mut rng = Rng::new(12);
        for _ in 0..200 {
            let cam = random_camera(&mut rng);
            let p = cam.to_camera(random_point(&mut rng));
            let j = cam.intrinsics.jacobian_intrinsics(p).unwrap();
            for k in 0..5 {
                let h = [1e-3, 1e-3, 1e-3, 1e-3, 1e-6][k];
                let mut plus = cam.intrinsics.corrected();
                let mut minus = plus;
                plus[k] += h;
                minus[k] -= h;
                let a = cam.intrinsics.with_corrected(plus).project(p).unwrap();
                let b = cam.intrinsics.with_corrected(minus).project(p).unwrap();
                let fd = (a - b) / (2.0 * h);
                for (r, fdv) in [fd.x, fd.y].iter().enumerate() {
                    let err = (j[r][k] - fdv).abs();
                    assert!(
                        err < 1e-5 * (1.0 + fdv.abs()),
                        "d{r}/d{}: {} vs {fdv}",
                        CORRECTED_INTRINSICS[k],
                        j[r][k]
                    );
                }
            }
        }
    }

    #[test]
    fn unproject_inverts_project() {
        let mut rng = Rng::new(13);
        for _ in 0..200 {
            let cam = random_camera(&mut rng);
            let p = cam.to_camera(random_point(&mut rng));
            let px = cam.intrinsics.project(p).unwrap();
            let n = cam.intrinsics.unproject(px);
            assert!((n - DVec2::new(p.x / p.z, p.y / p.z)).length() < 1e-9);
        }
    }

    #[test]
    fn behind_the_camera_is_not_projected() {
        let cam = Intrinsics::pinhole(1000.0, 1000.0, 480.0, 270.0);
        assert!(cam.project(DVec3::new(0.0, 0.0, -5.0)).is_none());
        assert!(cam.jacobian_point(DVec3::new(1.0, 0.0, 0.0)).is_none());
    }

    /// Beyond the radial polynomial's fold a point is not imaged: with k1 and k2 both
    /// negative, a point 70° off the axis would otherwise land back inside the image. Checked
    /// against a brute-force walk outwards along the ray's radius, for lenses of both signs
    /// and with k3.
    #[test]
    fn points_beyond_the_lens_fold_are_not_projected() {
        let mut cam = Intrinsics::pinhole(504.0, 504.0, 239.5, 134.5);
        cam.k1 = -0.0366;
        cam.k2 = -0.0066;
        // 70° off the axis: r = tan 70° = 2.75, past the fold at r ≈ 2.02.
        let far = DVec3::new(70f64.to_radians().tan() * 100.0, 0.0, 100.0);
        let wrapped = cam.distort(DVec2::new(far.x / far.z, 0.0));
        assert!(wrapped.x < 1.0, "the polynomial folds back ({wrapped})");
        assert!(cam.project(far).is_none());
        assert!(cam.jacobian_point(far).is_none());
        assert!(cam.jacobian_intrinsics(far).is_none());
        // The image's corner is well inside.
        assert!(
            cam.project(DVec3::new(0.5 * 150.0, 0.3 * 150.0, 150.0))
                .is_some()
        );
        // Brute force: the first r at which the distorted radius stops growing, against the
        // first r at which a point is refused, for lenses of every sign.
        let mut rng = Rng::new(17);
        for _ in 0..300 {
            let mut c = Intrinsics::pinhole(500.0, 500.0, 240.0, 135.0);
            c.k1 = rng.range(-0.5, 0.3);
            c.k2 = rng.range(-0.2, 0.2);
            c.k3 = if rng.range(0.0, 1.0) < 0.5 {
                0.0
            } else {
                rng.range(-0.05, 0.05)
            };
            let radius = |r: f64| r * (1.0 + r * r * (c.k1 + r * r * (c.k2 + r * r * c.k3)));
            let step = 1e-3;
            let mut fold = None;
            let mut refused = None;
            for i in 1..4000 {
                let r = i as f64 * step;
                if fold.is_none() && radius(r) <= radius(r - step) {
                    fold = Some(r);
                }
                if refused.is_none() && c.project(DVec3::new(r, 0.0, 1.0)).is_none() {
                    refused = Some(r);
                }
            }
            match (fold, refused) {
                (None, None) => {}
                (Some(f), Some(r)) => assert!(
                    (f - r).abs() <= 2.0 * step,
                    "{c:?}: the radius turns at r = {f}, refused from {r}"
                ),
                other => panic!("{c:?}: fold and refusal disagree: {other:?}"),
            }
        }
    }
}
