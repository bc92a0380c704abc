//! Smooth volumetric deformations, as DeformIt simulates forces on a CT volume: a sum of
//! Gaussian push/pull displacement kernels centred on the anchor organ's surface, plus a
//! gentle bend along its long axis. The field is defined everywhere in space, so applying it to
//! **all structures jointly** moves a tumour inside the kidney with the tissue around it.

use crate::geometry::Mesh;
use crate::rng::Rng;
use glam::DVec3;

/// One push (towards the inside) or pull (outwards) force's displacement kernel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushPull {
    pub center: DVec3,
    /// Displacement at the centre, mm.
    pub displacement: DVec3,
    /// Gaussian radius of influence, mm.
    pub radius_mm: f64,
}

/// A smooth displacement field over the preoperative frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DeformationField {
    pub forces: Vec<PushPull>,
    /// Bend: displacement `bend_mm · (s/half_length)²` along `bend_direction`, where s is the
    /// coordinate along `axis` from `origin`.
    pub origin: DVec3,
    pub axis: DVec3,
    pub half_length_mm: f64,
    pub bend_direction: DVec3,
    pub bend_mm: f64,
}

/// What a random field looks like, in millimetres.
#[derive(Debug, Clone, Copy)]
pub struct DeformationSpread {
    pub forces: (usize, usize),
    pub amplitude_mm: (f64, f64),
    pub radius_mm: (f64, f64),
    pub bend_mm: f64,
}

impl Default for DeformationSpread {
    fn default() -> Self {
        Self {
            forces: (1, 3),
            amplitude_mm: (2.0, 7.0),
            radius_mm: (12.0, 28.0),
            bend_mm: 3.0,
        }
    }
}

/// Half-length of the organ the default spread is made for (an adult kidney), mm.
pub const REFERENCE_HALF_LENGTH_MM: f64 = 52.0;

impl DeformationSpread {
    /// The same relative deformation for an organ of another size: amplitudes and radii scale
    /// with the organ's half-length.
    pub fn scaled_to(&self, organ: &Mesh) -> Self {
        let half = organ
            .bounding_box()
            .map(|(lo, hi)| 0.5 * (hi - lo).max_element())
            .unwrap_or(REFERENCE_HALF_LENGTH_MM);
        let k = if half > 0.0 {
            half / REFERENCE_HALF_LENGTH_MM
        } else {
            1.0
        };
        Self {
            forces: self.forces,
            amplitude_mm: (self.amplitude_mm.0 * k, self.amplitude_mm.1 * k),
            radius_mm: (self.radius_mm.0 * k, self.radius_mm.1 * k),
            bend_mm: self.bend_mm * k,
        }
    }
}

impl DeformationField {
    pub fn displacement(&self, p: DVec3) -> DVec3 {
        let mut d = DVec3::ZERO;
        for f in &self.forces {
            let r2 = (p - f.center).length_squared();
            d += f.displacement * (-r2 / (2.0 * f.radius_mm * f.radius_mm)).exp();
        }
        if self.bend_mm != 0.0 && self.half_length_mm > 0.0 {
            let s = (p - self.origin).dot(self.axis) / self.half_length_mm;
            d += self.bend_direction * (self.bend_mm * s * s);
        }
        d
    }

    /// This field with every displacement multiplied by `k` (for smooth motion over time).
    pub fn scaled(&self, k: f64) -> Self {
        let mut out = self.clone();
        for f in &mut out.forces {
            f.displacement *= k;
        }
        out.bend_mm *= k;
        out
    }

    pub fn apply(&self, points: &[DVec3]) -> Vec<DVec3> {
        points.iter().map(|&p| p + self.displacement(p)).collect()
    }

    /// A random field of forces on `anchor`'s surface: each pushes or pulls along the surface
    /// normal with a tangential part.
    pub fn random(
        rng: &mut Rng,
        anchor: &Mesh,
        normals: &[DVec3],
        spread: &DeformationSpread,
    ) -> Self {
        let (lo, hi) = anchor.bounding_box().unwrap_or((DVec3::ZERO, DVec3::ZERO));
        let center = anchor.vertex_mean();
        let ext = hi - lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            DVec3::X
        } else if ext.y >= ext.z {
            DVec3::Y
        } else {
            DVec3::Z
        };
        let half_length_mm = 0.5 * ext.max_element();
        let count = spread.forces.0 + rng.below(spread.forces.1 - spread.forces.0 + 1);
        let forces = (0..count)
            .filter(|_| !anchor.vertices.is_empty())
            .map(|_| {
                let i = rng.below(anchor.vertices.len());
                let n = normals.get(i).copied().unwrap_or(DVec3::Z);
                let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
                let tangential = rng
                    .unit_vector()
                    .reject_from_normalized(n.normalize_or(DVec3::Z))
                    * 0.4;
                let dir = (n * sign + tangential).normalize_or_zero();
                PushPull {
                    center: anchor.vertices[i],
                    displacement: dir * rng.range(spread.amplitude_mm.0, spread.amplitude_mm.1),
                    radius_mm: rng.range(spread.radius_mm.0, spread.radius_mm.1),
                }
            })
            .collect();
        Self {
            forces,
            origin: center,
            axis,
            half_length_mm,
            bend_direction: rng
                .unit_vector()
                .reject_from_normalized(axis)
                .normalize_or_zero(),
            bend_mm: rng.range(-spread.bend_mm, spread.bend_mm),
        }
    }
}

/// Carries a deformation observed on `anchor` vertices to other points, with Gaussian-weighted
/// (Shepard) interpolation of the anchor displacements: how a structure without a catalog of its
/// own follows the organ around it.
pub fn transfer_displacements(
    anchor_rest: &[DVec3],
    anchor_deformed: &[DVec3],
    targets: &[DVec3],
    radius_mm: f64,
) -> Vec<DVec3> {
    let inv = 1.0 / (2.0 * radius_mm * radius_mm);
    targets
        .iter()
        .map(|&t| {
            let mut sum = DVec3::ZERO;
            let mut weight = 0.0;
            let mut nearest = (f64::INFINITY, DVec3::ZERO);
            for (r, d) in anchor_rest.iter().zip(anchor_deformed) {
                let d2 = (t - *r).length_squared();
                let w = (-d2 * inv).exp();
                sum += (*d - *r) * w;
                weight += w;
                if d2 < nearest.0 {
                    nearest = (d2, *d - *r);
                }
            }
            // Far from every anchor vertex the weights underflow: take the nearest displacement.
            let disp = if weight > 1e-12 {
                sum / weight
            } else {
                nearest.1
            };
            t + disp
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_is_smooth_and_moves_inner_points_with_the_surface() {
        let sphere = crate::geometry::mesh::icosphere(3);
        let sphere = Mesh::new(
            sphere.vertices.iter().map(|v| *v * 30.0).collect(),
            sphere.faces,
        );
        let normals = sphere.vertex_normals();
        let mut rng = Rng::new(41);
        let field =
            DeformationField::random(&mut rng, &sphere, &normals, &DeformationSpread::default());
        // Smoothness: displacement changes by far less than the distance moved.
        for _ in 0..200 {
            let p = rng.unit_vector() * rng.range(0.0, 35.0);
            let q = p + rng.unit_vector() * 0.5;
            let dd = (field.displacement(p) - field.displacement(q)).length();
            assert!(dd < 0.5, "field jumps by {dd} mm over 0.5 mm");
        }
        // A point just inside the surface moves almost like the surface point beside it.
        let v = sphere.vertices[0];
        let inner = v * 0.95;
        assert!((field.displacement(v) - field.displacement(inner)).length() < 1.0);
        // Transfer reproduces a smooth field at interior points.
        let deformed = field.apply(&sphere.vertices);
        let targets: Vec<DVec3> = (0..50).map(|_| rng.unit_vector() * 24.0).collect();
        let moved = transfer_displacements(&sphere.vertices, &deformed, &targets, 10.0);
        for (t, m) in targets.iter().zip(&moved) {
            let truth = *t + field.displacement(*t);
            assert!(
                (truth - *m).length() < 1.5,
                "transfer off by {}",
                (truth - *m).length()
            );
        }
    }
}
