//! Poses of the preoperative models in camera 0: the 12-parameter affine map of the paper's
//! eq. 2 with its Jacobian (Table II), and a rigid parametrisation (rotation vector,
//! translation, optional uniform log-scale) for mode R, with its exact Jacobian.

use glam::{DMat3, DVec3};

/// q1…q12 of eq. 2: a row-major 3×3 linear part, then the translation (mm).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Affine {
    pub q: [f64; 12],
}

impl Default for Affine {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Affine {
    pub const IDENTITY: Self = Self {
        q: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
    };

    pub fn from_linear_translation(linear: DMat3, translation_mm: DVec3) -> Self {
        let r = linear.transpose(); // glam is column-major: rows of `linear` are columns of r.
        let (a, b, c) = (r.x_axis, r.y_axis, r.z_axis);
        Self {
            q: [
                a.x,
                a.y,
                a.z,
                b.x,
                b.y,
                b.z,
                c.x,
                c.y,
                c.z,
                translation_mm.x,
                translation_mm.y,
                translation_mm.z,
            ],
        }
    }

    /// The 3×3 linear part (R of eq. 2, which is not necessarily a rotation).
    pub fn linear(&self) -> DMat3 {
        let q = &self.q;
        DMat3::from_cols(
            DVec3::new(q[0], q[3], q[6]),
            DVec3::new(q[1], q[4], q[7]),
            DVec3::new(q[2], q[5], q[8]),
        )
    }

    pub fn translation_mm(&self) -> DVec3 {
        DVec3::new(self.q[9], self.q[10], self.q[11])
    }

    /// P_srg = R P_pre + t (eq. 2).
    pub fn apply(&self, p: DVec3) -> DVec3 {
        let q = &self.q;
        DVec3::new(
            q[0] * p.x + q[1] * p.y + q[2] * p.z + q[9],
            q[3] * p.x + q[4] * p.y + q[5] * p.z + q[10],
            q[6] * p.x + q[7] * p.y + q[8] * p.z + q[11],
        )
    }

    /// ∂P_srg/∂q_i (Table II): column i is the derivative with respect to q_{i+1}.
    pub fn jacobian(p_pre: DVec3) -> [[f64; 12]; 3] {
        let mut j = [[0.0; 12]; 3];
        for row in 0..3 {
            j[row][3 * row] = p_pre.x;
            j[row][3 * row + 1] = p_pre.y;
            j[row][3 * row + 2] = p_pre.z;
            j[row][9 + row] = 1.0;
        }
        j
    }

    /// self ∘ other: first `other`, then `self`.
    pub fn compose(&self, other: &Affine) -> Affine {
        Affine::from_linear_translation(
            self.linear() * other.linear(),
            self.linear() * other.translation_mm() + self.translation_mm(),
        )
    }

    pub fn is_finite(&self) -> bool {
        self.q.iter().all(|v| v.is_finite())
    }

    /// Nearest rigid-with-scale pose (polar decomposition of the linear part).
    pub fn to_rigid(&self) -> Option<RigidPose> {
        let m = self.linear();
        let det = m.determinant();
        if !det.is_finite() || det <= 1e-12 {
            return None;
        }
        let scale = det.cbrt();
        let rotation = nearest_rotation(m * (1.0 / scale))?;
        Some(RigidPose {
            rotation_vector: rotation_to_vector(rotation),
            translation_mm: self.translation_mm(),
            log_scale: scale.ln(),
        })
    }
}

/// Rigid pose with optional uniform scale: P = e^s · R(ω) · P_pre + t.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigidPose {
    /// Rotation vector ω (axis × angle, radians).
    pub rotation_vector: DVec3,
    pub translation_mm: DVec3,
    /// Natural log of the uniform scale (0 = no scaling).
    pub log_scale: f64,
}

impl RigidPose {
    pub fn rotation(&self) -> DMat3 {
        rotation_from_vector(self.rotation_vector)
    }

    pub fn to_affine(&self) -> Affine {
        Affine::from_linear_translation(self.rotation() * self.log_scale.exp(), self.translation_mm)
    }

    pub fn apply(&self, p: DVec3) -> DVec3 {
        self.rotation() * p * self.log_scale.exp() + self.translation_mm
    }

    /// ∂P/∂(ω1, ω2, ω3, t1, t2, t3, s), exact, via the compact formula for the derivative of
    /// the exponential map (Gallego & Yezzi 2015): ∂R/∂ω_i = (ω_i \[ω\]× + \[ω × (I − R)e_i\]×) R / |ω|².
    pub fn jacobian(&self, p_pre: DVec3) -> [[f64; 7]; 3] {
        let w = self.rotation_vector;
        let r = self.rotation();
        let scale = self.log_scale.exp();
        let rp = r * p_pre;
        let theta2 = w.length_squared();
        let mut j = [[0.0; 7]; 3];
        for i in 0..3 {
            let mut e = DVec3::ZERO;
            e[i] = 1.0;
            let d = if theta2 < 1e-16 {
                e.cross(rp)
            } else {
                let v = w.cross(e - r * e);
                (w[i] * w.cross(rp) + v.cross(rp)) / theta2
            } * scale;
            for row in 0..3 {
                j[row][i] = d[row];
            }
        }
        for row in 0..3 {
            j[row][3 + row] = 1.0;
            j[row][6] = rp[row] * scale;
        }
        j
    }
}

/// \[v\]× such that \[v\]× x = v × x.
pub fn skew(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

/// Angle (degrees) between the rotations of two affine poses (each the nearest rotation of its
/// linear part, its uniform scale taken out); 180 where one has none.
pub fn rotation_apart_deg(a: &Affine, b: &Affine) -> f64 {
    match (a.to_rigid(), b.to_rigid()) {
        (Some(ra), Some(rb)) => {
            let r = ra.rotation() * rb.rotation().transpose();
            let cos = ((r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0);
            cos.acos().to_degrees()
        }
        _ => 180.0,
    }
}

/// Rodrigues' formula.
pub fn rotation_from_vector(w: DVec3) -> DMat3 {
    let theta = w.length();
    if theta < 1e-12 {
        return DMat3::IDENTITY + skew(w);
    }
    let k = skew(w / theta);
    DMat3::IDENTITY + k * theta.sin() + k * k * (1.0 - theta.cos())
}

/// The rotation vector of a rotation matrix (log map), angle in [0, π].
pub fn rotation_to_vector(r: DMat3) -> DVec3 {
    let cos = ((r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) * 0.5).clamp(-1.0, 1.0);
    let theta = cos.acos();
    // Skew-symmetric part: (R − Rᵀ)/2 = sinθ [k]×.
    let v = DVec3::new(
        r.y_axis.z - r.z_axis.y,
        r.z_axis.x - r.x_axis.z,
        r.x_axis.y - r.y_axis.x,
    ) * 0.5;
    if theta < 1e-6 {
        return v;
    }
    if std::f64::consts::PI - theta > 1e-6 {
        return v * (theta / theta.sin());
    }
    // Near π: the axis is the dominant column of (R + I)/2.
    let b = (r + DMat3::IDENTITY) * 0.5;
    let cols = [b.x_axis, b.y_axis, b.z_axis];
    let i = (0..3)
        .max_by(|&a, &c| cols[a][a].total_cmp(&cols[c][c]))
        .unwrap_or(0);
    let axis = cols[i].normalize_or_zero();
    let axis = if axis.dot(v) < 0.0 { -axis } else { axis };
    axis * theta
}

/// Is `r` a proper rotation within `tolerance` (orthonormal columns, determinant +1)?
pub fn is_rotation(r: DMat3, tolerance: f64) -> bool {
    let should_be_identity = r.transpose() * r - DMat3::IDENTITY;
    let off = [
        should_be_identity.x_axis,
        should_be_identity.y_axis,
        should_be_identity.z_axis,
    ]
    .iter()
    .map(|c| c.abs().max_element())
    .fold(0.0_f64, f64::max);
    off.is_finite() && off <= tolerance && (r.determinant() - 1.0).abs() <= tolerance
}

/// The rotation nearest to `m` in the Frobenius norm (SVD), `None` if `m` is singular.
pub fn nearest_rotation(m: DMat3) -> Option<DMat3> {
    let a = nalgebra::Matrix3::from_fn(|r, c| m.col(c)[r]);
    let svd = a.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = nalgebra::Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * vt;
    Some(DMat3::from_cols(
        DVec3::new(r[(0, 0)], r[(1, 0)], r[(2, 0)]),
        DVec3::new(r[(0, 1)], r[(1, 1)], r[(2, 1)]),
        DVec3::new(r[(0, 2)], r[(1, 2)], r[(2, 2)]),
    ))
}

#[cfg(test)]
mod tests {
    /// The angle between two poses' rotations (the placement's near ties are told apart by
    /// it), whatever their scale and translation: 40° about a slanted axis reads 40°, the
    /// same rotation scaled 0°.
    #[test]
    fn rotation_apart_reads_the_angle_between_poses() {
        let axis = DVec3::new(1.0, -2.0, 0.5).normalize();
        let a = rotation_from_vector(axis * 0.3);
        let b = rotation_from_vector(axis * (0.3 + 40f64.to_radians()));
        let pose = |r: DMat3, scale: f64, t: DVec3| Affine::from_linear_translation(r * scale, t);
        let apart = rotation_apart_deg(
            &pose(a, 1.0, DVec3::ZERO),
            &pose(b, 1.1, DVec3::new(5.0, 0.0, 150.0)),
        );
        assert!((apart - 40.0).abs() < 1e-6, "{apart}");
        let same = rotation_apart_deg(&pose(a, 1.0, DVec3::ZERO), &pose(a, 0.9, DVec3::X));
        assert!(same < 1e-6, "{same}");
    }

    use super::*;
    use crate::rng::Rng;

    #[test]
    #[allow(clippy::needless_range_loop)] // parameter index addresses three arrays
    fn affine_jacobian_matches_central_differences() {
        let mut rng = Rng::new(21);
        for _ in 0..50 {
            let mut a = Affine::IDENTITY;
            for v in a.q.iter_mut() {
                *v += rng.range(-0.3, 0.3);
            }
            let p = DVec3::new(
                rng.range(-50.0, 50.0),
                rng.range(-50.0, 50.0),
                rng.range(-50.0, 50.0),
            );
            let j = Affine::jacobian(p);
            for i in 0..12 {
                let h = 1e-5;
                let (mut plus, mut minus) = (a, a);
                plus.q[i] += h;
                minus.q[i] -= h;
                let fd = (plus.apply(p) - minus.apply(p)) / (2.0 * h);
                for r in 0..3 {
                    assert!((j[r][i] - fd[r]).abs() < 1e-6 * (1.0 + fd[r].abs()));
                }
            }
        }
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // parameter index addresses three arrays
    fn rigid_jacobian_matches_central_differences() {
        let mut rng = Rng::new(22);
        for k in 0..200 {
            // Include the identity and angles near π.
            let angle = match k {
                0 => 0.0,
                1 => 3.1,
                _ => rng.range(0.0, 3.0),
            };
            let pose = RigidPose {
                rotation_vector: rng.unit_vector() * angle,
                translation_mm: DVec3::new(rng.range(-9.0, 9.0), 1.0, 150.0),
                log_scale: rng.range(-0.2, 0.2),
            };
            let p = DVec3::new(
                rng.range(-50.0, 50.0),
                rng.range(-50.0, 50.0),
                rng.range(-50.0, 50.0),
            );
            let j = pose.jacobian(p);
            for i in 0..7 {
                let h = 1e-6;
                let shift = |s: f64| {
                    let mut q = pose;
                    match i {
                        0..=2 => q.rotation_vector[i] += s,
                        3..=5 => q.translation_mm[i - 3] += s,
                        _ => q.log_scale += s,
                    }
                    q.apply(p)
                };
                let fd = (shift(h) - shift(-h)) / (2.0 * h);
                for r in 0..3 {
                    assert!(
                        (j[r][i] - fd[r]).abs() < 1e-5 * (1.0 + fd[r].abs()),
                        "param {i} row {r}: {} vs {}",
                        j[r][i],
                        fd[r]
                    );
                }
            }
            // The affine form agrees with the rigid form.
            assert!((pose.to_affine().apply(p) - pose.apply(p)).length() < 1e-9);
        }
    }

    #[test]
    fn rotation_vector_round_trip_and_polar_decomposition() {
        let mut rng = Rng::new(23);
        for k in 0..200 {
            let angle = if k == 0 {
                std::f64::consts::PI - 1e-9
            } else {
                rng.range(0.0, 3.1)
            };
            let w = rng.unit_vector() * angle;
            let r = rotation_from_vector(w);
            assert!(is_rotation(r, 1e-9));
            let back = rotation_from_vector(rotation_to_vector(r));
            assert!((back - r).abs_diff_eq(DMat3::ZERO, 1e-6), "angle {angle}");
            let pose = RigidPose {
                rotation_vector: w,
                translation_mm: DVec3::new(1.0, 2.0, 3.0),
                log_scale: 0.1,
            };
            let rigid = pose.to_affine().to_rigid().unwrap();
            assert!((rigid.rotation() - r).abs_diff_eq(DMat3::ZERO, 1e-6));
            assert!((rigid.log_scale - 0.1).abs() < 1e-9);
        }
        assert!(!is_rotation(
            DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)),
            1e-3
        ));
        assert!(Affine::IDENTITY.compose(&Affine::IDENTITY) == Affine::IDENTITY);
    }
}
