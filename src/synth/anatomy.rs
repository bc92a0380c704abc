//! The project's own default anatomy, made procedurally (no third-party meshes): a bean-shaped
//! kidney (≈104 × 60 × 34 mm, hilum notch on the medial side), a partly exophytic tumour on its
//! lateral-anterior surface and an endophytic tumour wholly inside it. Each is a deformed
//! icosphere, so triangles are well shaped and the vertex order is fixed. `assets/meshes/`
//! holds these meshes as OBJ files; a test keeps the two identical.
//!
//! Preoperative frame (mm): origin near the kidney's centre, +y superior, −x medial (hilum),
//! −z anterior (towards the camera in the default view).

use crate::geometry::Mesh;
use crate::geometry::mesh::icosphere;
use glam::DVec3;

/// Places each vertex direction of a unit icosphere on the zero set of `inside` (negative
/// inside), by bisection along the ray from `center`: a star-shaped surface.
fn radial_surface(
    subdivisions: u32,
    center: DVec3,
    max_radius: f64,
    inside: impl Fn(DVec3) -> f64,
) -> Mesh {
    let sphere = icosphere(subdivisions);
    let vertices = sphere
        .vertices
        .iter()
        .map(|&d| {
            let (mut lo, mut hi) = (0.0, max_radius);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if inside(center + d * mid) < 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            center + d * (0.5 * (lo + hi))
        })
        .collect();
    let mut mesh = Mesh::new(vertices, sphere.faces);
    mesh.orient_outwards();
    mesh
}

const KIDNEY_HALF_LENGTH_MM: f64 = 52.0;
const KIDNEY_HALF_WIDTH_MM: f64 = 30.0;
const KIDNEY_HALF_THICKNESS_MM: f64 = 17.0;

/// Implicit kidney: a bent ellipsoid whose medial side is notched at the hilum.
fn kidney_field(p: DVec3) -> f64 {
    let bend = 0.004 * p.y * p.y;
    let notch = if p.x < 0.0 {
        1.0 - 0.38 * (-(p.y / 16.0).powi(2) - (p.z / 14.0).powi(2)).exp()
    } else {
        1.0
    };
    let x = (p.x - bend + 6.0) / (KIDNEY_HALF_WIDTH_MM * notch);
    let y = p.y / KIDNEY_HALF_LENGTH_MM;
    let z = p.z / KIDNEY_HALF_THICKNESS_MM;
    x * x + y * y + z * z - 1.0
}

/// A roughly spherical tumour with gentle lobes.
fn tumour_field(center: DVec3, radius: f64, lobes: DVec3) -> impl Fn(DVec3) -> f64 {
    move |p: DVec3| {
        let d = p - center;
        let r = d.length();
        let dir = d / r.max(1e-9);
        let lobe = 1.0 + 0.08 * (3.0 * dir.dot(lobes)).sin() + 0.05 * (5.0 * dir.x * dir.y).cos();
        r - radius * lobe
    }
}

/// Centre of the exophytic tumour: on the lateral-anterior kidney surface, pushed out so that
/// about 60 % of it protrudes.
const TUMOUR_EXO_CENTER: DVec3 = DVec3::new(24.0, 16.0, -10.0);
const TUMOUR_EXO_RADIUS_MM: f64 = 11.0;
/// Centre of the endophytic tumour: inside, at least ~4 mm under the surface.
const TUMOUR_ENDO_CENTER: DVec3 = DVec3::new(4.0, -20.0, -3.0);
const TUMOUR_ENDO_RADIUS_MM: f64 = 8.0;

pub fn kidney() -> Mesh {
    radial_surface(4, DVec3::new(2.0, 0.0, 0.0), 120.0, kidney_field)
}

pub fn tumour_exophytic() -> Mesh {
    radial_surface(
        3,
        TUMOUR_EXO_CENTER,
        40.0,
        tumour_field(
            TUMOUR_EXO_CENTER,
            TUMOUR_EXO_RADIUS_MM,
            DVec3::new(0.6, 0.5, 0.62),
        ),
    )
}

pub fn tumour_endophytic() -> Mesh {
    radial_surface(
        3,
        TUMOUR_ENDO_CENTER,
        30.0,
        tumour_field(
            TUMOUR_ENDO_CENTER,
            TUMOUR_ENDO_RADIUS_MM,
            DVec3::new(-0.3, 0.8, 0.5),
        ),
    )
}

/// The default structures: (name, label, visible, mesh).
pub fn default_structures() -> Vec<(&'static str, u8, bool, Mesh)> {
    vec![
        ("kidney", 1, true, kidney()),
        ("tumour_exo", 2, true, tumour_exophytic()),
        ("tumour_endo", 3, false, tumour_endophytic()),
    ]
}

/// Is `p` inside the default kidney's implicit surface?
pub fn inside_kidney(p: DVec3) -> bool {
    kidney_field(p) < 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anatomy_has_the_intended_sizes_and_nesting() {
        let k = kidney();
        assert!(k.validate().is_ok());
        let (lo, hi) = k.bounding_box().unwrap();
        let size = hi - lo;
        assert!((95.0..115.0).contains(&size.y), "kidney length {}", size.y);
        assert!((45.0..70.0).contains(&size.x), "kidney width {}", size.x);
        assert!(
            (28.0..40.0).contains(&size.z),
            "kidney thickness {}",
            size.z
        );
        let endo = tumour_endophytic();
        assert!(endo.validate().is_ok());
        assert!(
            endo.vertices.iter().all(|&v| inside_kidney(v)),
            "the endophytic tumour lies wholly inside"
        );
        let exo = tumour_exophytic();
        assert!(exo.validate().is_ok());
        let outside = exo.vertices.iter().filter(|&&v| !inside_kidney(v)).count() as f64
            / exo.vertices.len() as f64;
        assert!(
            (0.4..0.85).contains(&outside),
            "exophytic share outside the kidney {outside}"
        );
    }

    #[test]
    fn assets_are_the_generated_meshes() {
        // Regenerate with: UPDATE_ASSETS=1 cargo test assets_are_the_generated_meshes
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/meshes");
        for (name, _, _, mesh) in default_structures() {
            let text = crate::geometry::mesh_io::obj_string(&mesh);
            let path = dir.join(format!("{name}.obj"));
            if std::env::var_os("UPDATE_ASSETS").is_some() {
                std::fs::create_dir_all(&dir).unwrap();
                std::fs::write(&path, &text).unwrap();
            }
            let stored = std::fs::read_to_string(&path).unwrap_or_default();
            assert!(
                stored == text,
                "{} is stale: run UPDATE_ASSETS=1 cargo test assets_are_the_generated_meshes",
                path.display()
            );
        }
    }
}
