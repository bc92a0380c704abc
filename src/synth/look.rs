//! A wider set of looks than the default phantom's, drawn from the scene's seed when
//! `synth --vary-look` asks for it: the light's colour and strength, how strongly tissue
//! glints, the kidney's tint, the texture's scale, blood-like patches on the tissue around the
//! kidney (a colour close to the kidney's, the classifier's hardest neighbour on real frames)
//! and optical blur. The appearance model is judged on these (`benches/appearance_heldout.rs`)
//! rather than on the one look it was first built on. A separate random stream: without the
//! flag every phantom is exactly what it was.

use crate::rng::Rng;
use glam::Vec3;

/// How a scene looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Look {
    /// The light's colour (per-channel gain) and strength.
    pub light_rgb: Vec3,
    pub gain: f32,
    /// Specular strength multiplier.
    pub specular: f32,
    /// Multiplies the kidney's albedo.
    pub kidney_tint: Vec3,
    /// Tissue texture coordinates are divided by this (> 1: coarser texture).
    pub texture_scale: f64,
    /// Share (0–1) of the surrounding tissue turned into blood-like patches.
    pub blood: f32,
    /// Gaussian blur (px) of the rendered frame.
    pub blur_px: f32,
}

impl Look {
    /// The default phantom's look.
    pub const PLAIN: Look = Look {
        light_rgb: Vec3::ONE,
        gain: 1.0,
        specular: 1.0,
        kidney_tint: Vec3::ONE,
        texture_scale: 1.0,
        blood: 0.0,
        blur_px: 0.0,
    };

    /// A look drawn from `seed`.
    pub fn drawn(seed: u64) -> Look {
        let mut rng = Rng::fork(seed, 0x100C);
        let mut around = |spread: f64| 1.0 + rng.range(-spread, spread) as f32;
        let light_rgb = Vec3::new(around(0.15), around(0.10), around(0.15));
        let gain = around(0.35);
        let kidney_tint = Vec3::new(around(0.2), around(0.25), around(0.25));
        let mut rng = Rng::fork(seed, 0x100D);
        Look {
            light_rgb,
            gain,
            specular: rng.range(0.3, 2.5) as f32,
            kidney_tint,
            texture_scale: rng.range(0.6, 1.6),
            blood: rng.range(0.0, 0.5) as f32,
            blur_px: rng.range(0.0, 1.2) as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn looks_are_seeded_and_within_their_ranges() {
        assert_eq!(Look::drawn(3), Look::drawn(3));
        assert_ne!(Look::drawn(3), Look::drawn(4));
        for s in 0..50 {
            let l = Look::drawn(s);
            assert!((0.65..=1.35).contains(&l.gain));
            assert!((0.3..=2.5).contains(&l.specular));
            assert!((0.0..=0.5).contains(&l.blood));
            assert!((0.0..=1.2).contains(&l.blur_px));
        }
    }
}
