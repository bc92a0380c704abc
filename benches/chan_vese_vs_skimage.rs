//! The project's Chan–Vese (the ACWOE baseline of `experiments`, Fig. 4) against
//! scikit-image's `chan_vese` on the same images: the experiments' virtual kidney in one view
//! at several noise levels. Run: `cargo bench --bench chan_vese_vs_skimage` (needs python3 with
//! numpy and scikit-image; not part of CI).
//!
//! Printed per image: the agreement (Dice) of ours in scikit-image's own setting (no
//! reinitialisation, 500 iterations, tolerance 10⁻³) with scikit-image's mask, which should be
//! ~1; and each method's Dice against the true silhouette, ours also in the experiments'
//! setting (reset every 20 iterations, 1,000 iterations).

use endofuse::experiments::chan_vese::{ChanVeseParams, segment};
use endofuse::experiments::rig::{Rig, noisy_images};
use endofuse::plane::{Mask, dice};
use std::process::Command;

fn main() {
    let dir = std::env::temp_dir().join(format!("endofuse-cv-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a scratch folder");
    let rig = Rig::new(1, &[]);
    let truth = rig.silhouettes(&rig.truth).remove(0);
    let sigmas = [0.1, 0.25, 0.5, 1.0];
    let mut images = Vec::new();
    for (k, &sigma) in sigmas.iter().enumerate() {
        let img = noisy_images(std::slice::from_ref(&truth), sigma, 11, k as u64).remove(0);
        let name = format!("sigma{sigma:.2}");
        let bytes: Vec<u8> = img.intensity.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(dir.join(format!("{name}.f32")), bytes).expect("write image");
        std::fs::write(
            dir.join(format!("{name}.json")),
            format!("{{\"width\": {}, \"height\": {}}}", img.width, img.height),
        )
        .expect("write meta");
        images.push((name, sigma, img));
    }
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/chan_vese_skimage.py");
    let status = Command::new("python3").arg(script).arg(&dir).status();
    if !status.is_ok_and(|s| s.success()) {
        eprintln!("chan_vese_vs_skimage: python3 with numpy and scikit-image is needed");
        std::process::exit(1);
    }
    let skimage_setting = ChanVeseParams {
        max_iterations: 500,
        reinit_every: None,
        ..ChanVeseParams::default()
    };
    println!(
        "| σ | ours = scikit-image (Dice between them) | scikit-image vs truth | ours, its setting, vs truth | ours, experiments' setting, vs truth | iterations (sk / ours / ours exp.) | s (sk / ours exp.) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (name, sigma, img) in &images {
        let raw = std::fs::read(dir.join(format!("{name}.skimage.u8"))).expect("skimage mask");
        let meta = std::fs::read_to_string(dir.join(format!("{name}.skimage.json"))).expect("meta");
        let sk_iter = meta
            .split("\"iterations\": ")
            .nth(1)
            .and_then(|s| s.split([',', '}']).next())
            .unwrap_or("?")
            .trim()
            .to_string();
        let sk_s: f64 = meta
            .split("\"seconds\": ")
            .nth(1)
            .and_then(|s| s.split([',', '}']).next())
            .and_then(|s| s.trim().parse().ok())
            .unwrap_or(f64::NAN);
        let sk = Mask::from_vec(img.width, img.height, raw.iter().map(|&v| v != 0).collect())
            .expect("mask size");
        let ours = segment(&img.intensity, img.width, img.height, &skimage_setting);
        let t = std::time::Instant::now();
        let exp = segment(
            &img.intensity,
            img.width,
            img.height,
            &ChanVeseParams::default(),
        );
        let exp_s = t.elapsed().as_secs_f64();
        let agree = dice(&ours.inside, &sk).unwrap_or(1.0);
        // Which phase is the kidney depends on the start only: compare the brighter phase.
        let sk_bright = {
            let inv = sk.map(|&v| !v);
            let d1 = dice(&sk, &truth).unwrap_or(0.0);
            let d2 = dice(&inv, &truth).unwrap_or(0.0);
            d1.max(d2)
        };
        println!(
            "| {sigma:.2} | {agree:.4} | {sk_bright:.3} | {:.3} | {:.3} | {sk_iter} / {} / {} | {sk_s:.1} / {exp_s:.1} |",
            dice(&ours.brighter(), &truth).unwrap_or(0.0),
            dice(&exp.brighter(), &truth).unwrap_or(0.0),
            ours.iterations,
            exp.iterations
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
