//! `endofuse classify` end to end: outputs exactly as CONTRACT §3, the forest learns from seeds
//! of the first frames what later frames hold, and bad seeds are refused with exit 2.

mod common;

use std::ffi::OsStr;

use std::path::{Path, PathBuf};
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    common::scratch_dir(&format!("classify-{name}"))
}

#[test]
fn classify_writes_the_contract_outputs_and_segments_later_frames() {
    let scene = common::synth(
        "classify-scene",
        &[
            "--frames", "8", "--seed", "2", "--width", "320", "--height", "180", "--noise", "0.03",
        ],
    );
    let dir = tmp("out");
    common::run_ok(&[
        OsStr::new("classify"),
        scene.as_os_str(),
        OsStr::new("--out"),
        dir.as_os_str(),
        OsStr::new("--frames"),
        OsStr::new("2..7"),
    ]);
    for cam in ["left", "right"] {
        for class in ["background", "kidney", "tumour_exo"] {
            assert!(
                dir.join(format!("prob/{class}/{cam}/000007.png")).exists(),
                "{class} {cam}"
            );
        }
        assert!(dir.join(format!("uncertainty/{cam}/000002.png")).exists());
        assert!(dir.join(format!("labels/{cam}/000005.png")).exists());
        assert!(
            !dir.join(format!("labels/{cam}/000001.png")).exists(),
            "outside --frames"
        );
    }
    let prob = image::open(dir.join("prob/kidney/left/000006.png")).unwrap();
    assert_eq!((prob.width(), prob.height()), (320, 180));
    assert!(matches!(prob.color(), image::ColorType::L8));
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["forest"]["trees"], 20);
    assert!(metrics["forest"]["train_s"].as_f64().unwrap() > 0.0);
    assert!(metrics["forest"]["oob_error"].as_f64().unwrap() < 0.05);
    // Frames 3..7 were never seeded: the forest still finds kidney and tumour there.
    let unseeded = &metrics["pixel_dice_unseeded"];
    assert!(unseeded["kidney"].as_f64().unwrap() > 0.9, "{metrics}");
    assert!(unseeded["tumour_exo"].as_f64().unwrap() > 0.7, "{metrics}");
    assert!(metrics["pixel_dice"]["background"].as_f64().unwrap() > 0.95);
    let _ = std::fs::remove_dir_all(&scene);
    let _ = std::fs::remove_dir_all(&dir);
}

fn fixture_copy(name: &str) -> PathBuf {
    common::fixture_copy(&format!("classify-{name}"))
}

fn expect_exit_2(scene: &Path, words: &str) {
    let out_dir = tmp("unused");
    let out = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .arg("classify")
        .arg(scene)
        .arg("--out")
        .arg(&out_dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains(words), "expected '{words}' in: {err}");
    assert!(!err.contains("panicked"));
}

#[test]
fn the_handmade_scene_classifies() {
    let dir = tmp("handmade");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/handmade_scene");
    common::run_ok(&[
        OsStr::new("classify"),
        scene.as_os_str(),
        OsStr::new("--out"),
        dir.as_os_str(),
    ]);
    assert!(dir.join("prob/tumour/right/000001.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_seeds_are_refused_naming_the_class() {
    let d = fixture_copy("noseeds");
    for cam in ["left", "right"] {
        std::fs::remove_file(d.join(format!("seeds/{cam}/000000.png"))).unwrap();
    }
    expect_exit_2(&d, "no seeds");

    let d = fixture_copy("notumour");
    for cam in ["left", "right"] {
        let p = d.join(format!("seeds/{cam}/000000.png"));
        let mut img = image::open(&p).unwrap().into_luma8();
        for px in img.pixels_mut() {
            if px.0[0] == 2 {
                px.0[0] = 0;
            }
        }
        img.save(&p).unwrap();
    }
    expect_exit_2(&d, "no seeded pixel for 'tumour' (label 2)");

    let d = fixture_copy("range");
    let out = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .arg("classify")
        .arg(&d)
        .arg("--out")
        .arg(tmp("r"))
        .args(["--frames", "1..5"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--frames"));
}

/// The app's live loop reads again only the image a stroke changed: the cached collection must
/// give exactly the samples a cold one gives, before and after the stroke, and the coarse first
/// map must agree with the full one almost everywhere.
#[test]
fn the_live_loop_cache_and_coarse_map_match_a_cold_run() {
    use endofuse::appearance::{Appearance, ForestParams, SampleCache, TrainingSet};
    use endofuse::scene::SEED_BACKGROUND;
    let scene = endofuse::synth::memory_scene(&endofuse::synth::SynthOptions {
        frames: 4,
        width: 240,
        height: 136,
        ..Default::default()
    })
    .unwrap();
    let cache = SampleCache::default();
    let before = TrainingSet::collect(&scene, None, None).unwrap();
    let warm = TrainingSet::collect(&scene, None, Some(&cache)).unwrap();
    assert_eq!(before.samples.features, warm.samples.features);
    // A background stroke on frame 1 of the right view.
    let mut seeds = scene.seeds.clone();
    let s = seeds.by_camera[1].get_mut(&1).unwrap();
    for x in 5..40 {
        s.data[4 * s.width + x] = SEED_BACKGROUND;
    }
    let stroked = scene.with_seeds(seeds);
    let cold = TrainingSet::collect(&stroked, None, None).unwrap();
    let warm = TrainingSet::collect(&stroked, None, Some(&cache)).unwrap();
    assert!(
        cold.samples.len() > before.samples.len(),
        "the stroke adds samples"
    );
    assert_eq!(cold.samples.features, warm.samples.features);
    assert_eq!(cold.samples.classes, warm.samples.classes);

    let a = Appearance::fit(
        &warm,
        &ForestParams {
            trees: 8,
            ..Default::default()
        },
    )
    .unwrap();
    let frame = stroked.frame(0, 3).unwrap();
    let (full, coarse) = (a.classify_frame(&frame), a.classify_coarse(&frame));
    assert_eq!((coarse.width, coarse.height), (full.width, full.height));
    let (lf, lc) = (
        full.argmax_labels(&a.classes).data,
        coarse.argmax_labels(&a.classes).data,
    );
    let agree = lf.iter().zip(&lc).filter(|(x, y)| x == y).count() as f64 / lf.len() as f64;
    assert!(
        agree > 0.9,
        "coarse and full maps agree on {agree:.3} of the pixels"
    );
}
