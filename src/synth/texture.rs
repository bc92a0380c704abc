//! Procedural solid textures for the phantom: lattice value noise, fractal sums and ridged
//! "vessel" lines, evaluated at preoperative (tissue-fixed) coordinates so the texture moves
//! and deforms with the tissue and is the same in every view.

use glam::{DVec3, Vec3};

fn hash(x: i64, y: i64, z: i64, seed: u64) -> f64 {
    let mut h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (z as u64).wrapping_mul(0x1656_67B1_9E37_79F9)
        ^ seed.wrapping_mul(0x27D4_EB2F_1656_67C5);
    h ^= h >> 29;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 32;
    (h >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

/// Smooth value noise in [−1, 1].
pub fn value_noise(p: DVec3, seed: u64) -> f64 {
    let f = p.floor();
    let (x, y, z) = (f.x as i64, f.y as i64, f.z as i64);
    let t = p - f;
    let s = t * t * (DVec3::splat(3.0) - 2.0 * t);
    let lerp = |a: f64, b: f64, u: f64| a + (b - a) * u;
    let c = |dx, dy, dz| hash(x + dx, y + dy, z + dz, seed);
    let x00 = lerp(c(0, 0, 0), c(1, 0, 0), s.x);
    let x10 = lerp(c(0, 1, 0), c(1, 1, 0), s.x);
    let x01 = lerp(c(0, 0, 1), c(1, 0, 1), s.x);
    let x11 = lerp(c(0, 1, 1), c(1, 1, 1), s.x);
    lerp(lerp(x00, x10, s.y), lerp(x01, x11, s.y), s.z)
}

/// Fractal sum of `octaves` value noises, roughly in [−1, 1].
pub fn fbm(p: DVec3, octaves: u32, seed: u64) -> f64 {
    let (mut sum, mut amp, mut norm, mut q) = (0.0, 1.0, 0.0, p);
    for o in 0..octaves {
        sum += amp * value_noise(q, seed.wrapping_add(o as u64));
        norm += amp;
        amp *= 0.5;
        q = q * 2.03 + DVec3::new(1.7, 9.2, 3.1);
    }
    sum / norm
}

/// Thin branching lines (1 on a line, 0 away from it): where noise crosses zero.
pub fn vessels(p: DVec3, width: f64, seed: u64) -> f64 {
    let n = fbm(p, 3, seed).abs();
    (1.0 - n / width).clamp(0.0, 1.0).powi(2)
}

/// Tissue kinds of the phantom and their look.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Material {
    Kidney,
    Tumour,
    Fat,
    ToolShaft,
    ToolMetal,
}

/// Surface colour (linear-ish RGB in [0, 1]) and specular strength/shininess at tissue
/// coordinate `p` (mm).
pub fn albedo(material: Material, p: DVec3) -> (Vec3, f32, f32) {
    match material {
        Material::Kidney => {
            let base = Vec3::new(0.50, 0.15, 0.11);
            let mottle = 0.82 + 0.32 * fbm(p / 9.0, 4, 11) as f32;
            let v = vessels(p / 22.0, 0.06, 12) as f32;
            let c = base * mottle;
            (c.lerp(Vec3::new(0.30, 0.04, 0.05), 0.7 * v), 0.30, 45.0)
        }
        Material::Tumour => {
            let base = Vec3::new(0.86, 0.63, 0.46);
            let mottle = 0.86 + 0.24 * fbm(p / 4.0, 4, 21) as f32;
            let spots = ((fbm(p / 2.5, 2, 22) - 0.45) * 4.0).clamp(0.0, 1.0) as f32;
            (
                (base * mottle).lerp(Vec3::new(0.78, 0.38, 0.30), 0.5 * spots),
                0.25,
                35.0,
            )
        }
        Material::Fat => {
            let fat = Vec3::new(0.86, 0.70, 0.34);
            let tissue = Vec3::new(0.66, 0.36, 0.28);
            let m = ((fbm(p / 25.0, 4, 31) + 0.35) * 2.5).clamp(0.0, 1.0) as f32;
            let lobules = 0.9 + 0.2 * fbm(p / 3.0, 3, 33) as f32;
            let v = vessels(p / 35.0, 0.035, 32) as f32;
            (
                (tissue.lerp(fat, m) * lobules).lerp(Vec3::new(0.50, 0.07, 0.06), 0.8 * v),
                0.18,
                30.0,
            )
        }
        Material::ToolShaft => (Vec3::new(0.10, 0.10, 0.11), 0.5, 30.0),
        Material::ToolMetal => {
            let brushed = 0.92 + 0.08 * value_noise(p * DVec3::new(0.2, 0.2, 3.0), 41) as f32;
            (Vec3::new(0.62, 0.64, 0.68) * brushed, 0.9, 70.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_continuous_and_seeded() {
        let mut prev = value_noise(DVec3::new(0.0, 0.3, -0.2), 1);
        for i in 1..2000 {
            let p = DVec3::new(i as f64 * 0.01, 0.3, -0.2);
            let v = value_noise(p, 1);
            assert!((-1.0..=1.0).contains(&v));
            assert!((v - prev).abs() < 0.1, "jump at {i}");
            prev = v;
        }
        assert_ne!(
            value_noise(DVec3::splat(0.5), 1),
            value_noise(DVec3::splat(0.5), 2)
        );
        let (k, _, _) = albedo(Material::Kidney, DVec3::new(3.0, 1.0, 2.0));
        let (t, _, _) = albedo(Material::Tumour, DVec3::new(3.0, 1.0, 2.0));
        assert!(t.length() > k.length(), "tumour is paler than kidney");
    }
}
