//! `endofuse track` end to end on phantoms: outputs exactly as CONTRACT §3, segmentation and
//! hidden-structure accuracy against ground truth, automatic initialisation, and bad input.

mod common;

use endofuse::geometry::Affine;
use endofuse::geometry::pose::{nearest_rotation, rotation_to_vector};
use std::path::{Path, PathBuf};
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    common::scratch_dir(&format!("track-{name}"))
}

fn synth(name: &str, extra: &[&str]) -> PathBuf {
    let mut args = vec![
        "--frames",
        "6",
        "--seed",
        "4",
        "--width",
        "320",
        "--height",
        "180",
        "--noise",
        "0.02",
        "--no-zoom",
    ];
    args.extend_from_slice(extra);
    common::synth(&format!("track-{name}"), &args)
}

fn track(scene: &Path, out: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .arg("track")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .args(args)
        .output()
        .unwrap()
}

use common::read_json as json;

/// Runs `track` and insists that it succeeded.
fn track_ok(scene: &Path, out: &Path, args: &[&str]) {
    let run = track(scene, out, args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

/// Takes `key` out of the scene's scene.json.
fn drop_scene_key(scene: &Path, key: &str) {
    let p = scene.join("scene.json");
    let mut v = json(&p);
    v.as_object_mut().unwrap().remove(key);
    std::fs::write(&p, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

#[test]
fn track_writes_the_contract_outputs_and_segments_the_phantom() {
    let scene = synth("ls", &[]);
    let out = tmp("ls-out");
    track_ok(&scene, &out, &["--mode", "LS", "--frames", "0..5"]);
    for cam in ["left", "right"] {
        let mask = image::open(out.join(format!("masks/{cam}/000005.png"))).unwrap();
        assert_eq!((mask.width(), mask.height()), (320, 180));
        assert!(
            out.join(format!("hidden/tumour_endo/{cam}/000003.png"))
                .exists()
        );
    }
    let traj = json(&out.join("trajectory.json"));
    let frames = traj["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 6);
    for key in [
        "frame",
        "affine",
        "shape",
        "cameras",
        "centroids",
        "energy",
        "iterations",
        "ms",
        "confidence",
        "lost",
    ] {
        assert!(!frames[2][key].is_null(), "trajectory frames carry '{key}'");
    }
    assert_eq!(frames[0]["affine"].as_array().unwrap().len(), 12);
    assert!(
        frames[0]["centroids"]["tumour_endo"]
            .as_array()
            .unwrap()
            .len()
            == 3
    );
    let m = json(&out.join("metrics.json"));
    assert_eq!(m["mode"], "LS");
    assert_eq!(m["frames"], 6);
    let dice = m["dice"]["mean"].as_f64().unwrap();
    assert!(dice > 0.88, "LS Dice {dice}: {m}");
    assert!(m["dice"]["by_structure"]["kidney"].as_f64().unwrap() > 0.9);
    assert_eq!(m["dice"]["per_frame"].as_array().unwrap().len(), 6);
    let hidden = &m["hidden"]["tumour_endo"];
    assert!(hidden["dice_mean"].as_f64().unwrap() > 0.6, "{m}");
    // The stereo depth term pins depth: 7.4 mm on this scene without it, 2.4 mm with it.
    assert!(
        hidden["centroid_error_mm_mean"].as_f64().unwrap() < 4.0,
        "{m}"
    );
    assert!(
        m["camera"]["fx_rel_error_mean"].as_f64().unwrap() < 1e-9,
        "no zoom, no camera change"
    );
    assert!(m["timing"]["ms_per_frame"]["median"].as_f64().unwrap() > 0.0);
    assert_eq!(m["lost_frames"], 0);
    let _ = std::fs::remove_dir_all(&scene);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn without_an_initial_pose_the_model_is_placed_automatically() {
    let scene = synth("auto", &[]);
    drop_scene_key(&scene, "initial_pose");
    let out = tmp("auto-out");
    track_ok(&scene, &out, &["--frames", "0..2"]);
    let m = json(&out.join("metrics.json"));
    assert!(
        m["dice"]["by_structure"]["kidney"].as_f64().unwrap() > 0.85,
        "{m}"
    );
    assert!(
        m["dice"]["by_structure"]["tumour_exo"].as_f64().unwrap() > 0.5,
        "the tumour ends on the right side: {m}"
    );
    let _ = std::fs::remove_dir_all(&scene);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn bad_track_arguments_are_refused() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/handmade_scene");
    let out = tmp("bad");
    let run = track(&scene, &out, &["--mode", "XYZ"]);
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("--mode"));
    let run = track(&scene, &out, &["--frames", "0..9"]);
    assert_eq!(run.status.code(), Some(2));
}

#[test]
fn frames_without_the_organ_are_lost_and_tracking_recovers() {
    let scene = synth("lost", &[]);
    // Frames 2–4 show only tissue-coloured haze: the organ is out of view.
    for t in 2..=4 {
        for cam in ["left", "right"] {
            let img = image::RgbImage::from_fn(320, 180, |x, y| {
                image::Rgb([190 + (x % 7) as u8, 160 + (y % 5) as u8, 80])
            });
            img.save(scene.join(format!("{cam}/{t:06}.png"))).unwrap();
        }
    }
    let out = tmp("lost-out");
    // LSC: nothing in a lost stretch, or in finding the organ again, may pass for a zoom.
    track_ok(&scene, &out, &["--frames", "0..5", "--mode", "LSC"]);
    let traj = json(&out.join("trajectory.json"));
    let lost: Vec<bool> = traj["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["lost"].as_bool().unwrap())
        .collect();
    assert_eq!(
        lost,
        vec![false, false, true, true, true, false],
        "frames 2–4 lost, frame 5 found again"
    );
    // Lost frames hold the last good pose.
    assert_eq!(traj["frames"][3]["affine"], traj["frames"][1]["affine"]);
    let truth = json(&scene.join("gt/trajectory.json"));
    for t in 0..6 {
        assert_eq!(
            traj["frames"][t]["cameras"], truth["frames"][t]["cameras"],
            "frame {t}: the calibration is kept"
        );
    }
    let m = json(&out.join("metrics.json"));
    assert_eq!(m["lost_frames"], 3);
    let last = m["dice"]["per_frame"]
        .as_array()
        .unwrap()
        .last()
        .unwrap()
        .as_f64()
        .unwrap();
    assert!(last > 0.85, "recovered Dice {last}");
    let _ = std::fs::remove_dir_all(&scene);
    let _ = std::fs::remove_dir_all(&out);
}

/// LSC through a zoom against ground truth: the rig's focal length follows it (fx +20 %), the
/// pose keeps the motion it had before, and the principal point stays where calibration put it
/// (the default: left free it wandered 8–15 px on widened phantoms, issue 14) unless the
/// configuration frees it; freed, it follows this phantom's drift (cx +3.3 px at this size).
/// k1 follows fx by the scene's `k1_vs_focal`.
#[test]
fn a_zoom_is_followed_by_focal_length_and_principal_point() {
    let scene = common::synth(
        "track-zoom",
        &[
            "--frames", "16", "--seed", "4", "--width", "320", "--height", "180", "--noise", "0.02",
        ],
    );
    let out = tmp("zoom-out");
    // No --mode: LSC is the default (CONTRACT §1), so a zoom is followed without asking.
    track_ok(&scene, &out, &[]);
    let m = json(&out.join("metrics.json"));
    assert_eq!(m["mode"], "LSC");
    // LS explains the zoom by depth and puts the hidden tumour further off.
    let ls_out = tmp("zoom-out-ls");
    track_ok(&scene, &ls_out, &["--mode", "LS"]);
    let hidden = |m: &serde_json::Value| {
        m["hidden"]["tumour_endo"]["centroid_error_mm_mean"]
            .as_f64()
            .unwrap()
    };
    let ls = json(&ls_out.join("metrics.json"));
    assert!(
        hidden(&m) < hidden(&ls),
        "default {} mm, LS {} mm",
        hidden(&m),
        hidden(&ls)
    );
    // And says so: in LS the frames of the zoom warn that depth explained it, and their
    // confidence falls below LSC's; LSC, which corrects the cameras there, warns of nothing.
    assert_eq!(m["depth_explains_zoom_frames"], 0, "{m}");
    let warned = ls["depth_explains_zoom_frames"].as_u64().unwrap();
    assert!(warned >= 3, "LS frames warned: {warned}");
    let frames = |dir: &Path| json(&dir.join("trajectory.json"))["frames"].clone();
    let (lsc_frames, ls_frames) = (frames(&out), frames(&ls_out));
    let mut lower = 0;
    for (a, b) in lsc_frames
        .as_array()
        .unwrap()
        .iter()
        .zip(ls_frames.as_array().unwrap())
    {
        let warns = b["warnings"]
            .as_array()
            .is_some_and(|w| w.iter().any(|x| x == "depth_explains_zoom"));
        assert!(
            a.get("warnings").is_none(),
            "LSC frame {} warns",
            a["frame"]
        );
        if warns {
            assert!(
                b["confidence"].as_f64().unwrap() < a["confidence"].as_f64().unwrap(),
                "frame {}: LS confidence {} against LSC {}",
                b["frame"],
                b["confidence"],
                a["confidence"]
            );
            lower += 1;
        }
    }
    assert_eq!(lower as u64, warned);
    let cam = &m["camera"];
    assert!(cam["fx_rel_error_mean"].as_f64().unwrap() < 0.02, "{m}");
    let fitted = json(&out.join("trajectory.json"));
    let truth = json(&scene.join("gt/trajectory.json"));
    let at = |t: &serde_json::Value, f: usize, k: &str| {
        t["frames"][f]["cameras"][0][k].as_f64().unwrap()
    };
    let shift = at(&truth, 15, "cx") - at(&truth, 0, "cx");
    assert!(shift > 3.0, "the phantom's principal point moves: {shift}");
    let held = at(&fitted, 15, "cx") - at(&truth, 0, "cx");
    assert!(held.abs() < 0.01, "cx moved {held} px from calibration");
    // k1 by the relation, not free: within 0.005 of the truth at every frame.
    for f in 0..16 {
        let (a, b) = (at(&fitted, f, "k1"), at(&truth, f, "k1"));
        assert!((a - b).abs() < 0.005, "frame {f}: k1 {a} against {b}");
    }
    // A correction past what the configuration calls plausible (here fx beyond ±5 %) is
    // refused frame by frame, warned of, and counted: fx never leaves the range.
    let narrow_dir = tmp("narrow-zoom");
    std::fs::create_dir_all(&narrow_dir).unwrap();
    let narrow = narrow_dir.join("config.json");
    std::fs::write(&narrow, r#"{"tracking": {"max_zoom_factor": 1.05}}"#).unwrap();
    let refused = tmp("zoom-out-refused");
    track_ok(&scene, &refused, &["--config", narrow.to_str().unwrap()]);
    let r = json(&refused.join("trajectory.json"));
    let mut warned = 0;
    for f in r["frames"].as_array().unwrap() {
        let fx = f["cameras"][0]["fx"].as_f64().unwrap();
        assert!(
            fx <= 1.05 * at(&truth, 0, "fx") + 1e-6,
            "frame {}: fx {fx}",
            f["frame"]
        );
        warned += f["warnings"]
            .as_array()
            .is_some_and(|w| w.iter().any(|x| x == "camera_correction_refused"))
            as u64;
    }
    assert!(warned >= 3, "refused frames: {warned}");
    let rm = json(&refused.join("metrics.json"));
    assert_eq!(rm["refused_frames"]["camera_correction_refused"], warned);
    // Freed by the configuration, the principal point follows the drift.
    let free = tmp("zoom-out-free-pp");
    let config_dir = tmp("free-pp");
    std::fs::create_dir_all(&config_dir).unwrap();
    let config = config_dir.join("config.json");
    std::fs::write(
        &config,
        r#"{"priors": {"camera_relative": [1.0, 1.0, 1.0, 1.0, 100.0]}}"#,
    )
    .unwrap();
    track_ok(&scene, &free, &["--config", config.to_str().unwrap()]);
    let freed = json(&free.join("trajectory.json"));
    assert!(
        (at(&freed, 15, "cx") - at(&truth, 15, "cx")).abs() < 1.5,
        "last frame cx {} against {}",
        at(&freed, 15, "cx"),
        at(&truth, 15, "cx")
    );
    assert!(m["dice"]["mean"].as_f64().unwrap() > 0.92, "{m}");
    let hidden = m["hidden"]["tumour_endo"]["centroid_error_mm_mean"]
        .as_f64()
        .unwrap();
    assert!(hidden < 3.5, "hidden tumour {hidden} mm");

    // The same zoom, unmarked: the tracker detects it (without, fx ends 20 % off: mean 7 %).
    drop_scene_key(&scene, "zoom_changes");
    let out = tmp("zoom-unmarked-out");
    track_ok(&scene, &out, &["--mode", "LSC"]);
    let m = json(&out.join("metrics.json"));
    assert!(
        m["camera"]["fx_rel_error_mean"].as_f64().unwrap() < 0.03,
        "{m}"
    );
    assert!(m["dice"]["mean"].as_f64().unwrap() > 0.92, "{m}");
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&scene);
}

/// LSC on a scene without zoom: the detector stays quiet and the intrinsics keep their
/// calibration exactly.
#[test]
fn without_a_zoom_lsc_keeps_the_calibration() {
    let scene = synth("nozoom-lsc", &[]);
    let out = tmp("nozoom-lsc-out");
    track_ok(&scene, &out, &["--mode", "LSC"]);
    let fitted = json(&out.join("trajectory.json"));
    let truth = json(&scene.join("gt/trajectory.json"));
    for (f, g) in fitted["frames"]
        .as_array()
        .unwrap()
        .iter()
        .zip(truth["frames"].as_array().unwrap())
    {
        assert_eq!(f["cameras"], g["cameras"], "frame {}", f["frame"]);
    }
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&scene);
}

/// The README's tracking picture: the demo tracked for 10 frames (LSC), last frame of both
/// views with the fitted structures and the hidden tumour drawn through the kidney.
#[test]
fn tracking_overlay_picture() {
    let out = tmp("picture");
    track_ok(
        Path::new("demo"),
        &out,
        &["--mode", "LSC", "--frames", "0..9"],
    );
    let scene = endofuse::open::scene("demo").unwrap();
    let index = |l: u8| scene.structures.iter().position(|s| s.label == l);
    let mut views = Vec::new();
    for (c, cam) in scene.cameras.iter().enumerate() {
        let mut img = (*scene.frame(c, 9).unwrap()).clone();
        let read = |p: String| endofuse::scene::labels::read_label_png(&out.join(p)).unwrap();
        endofuse::overlay::draw_labels(
            &mut img,
            &read(format!("masks/{}/000009.png", cam.name)),
            &index,
            0.3,
        );
        endofuse::overlay::draw_hidden(
            &mut img,
            &read(format!("hidden/tumour_endo/{}/000009.png", cam.name)).map(|&v| v > 0),
            2,
        );
        views.push(img);
    }
    let sheet = endofuse::overlay::tile(&views, 2);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("screenshots/tracking_overlay.png");
    if std::env::var_os("UPDATE_SCREENSHOTS").is_some() || !path.exists() {
        sheet.save(&path).unwrap();
    }
    let m = json(&out.join("metrics.json"));
    assert!(m["dice"]["mean"].as_f64().unwrap() > 0.9, "{m}");
    let _ = std::fs::remove_dir_all(&out);
}

/// metrics.json records the fit's configuration and what it resolved to; given back with
/// `--config` it reproduces the run exactly, and a changed constant changes the fit.
#[test]
fn a_run_is_reproduced_from_its_metrics_and_its_config_is_honoured() {
    let scene = synth("config", &[]);
    let (first, again, changed) = (tmp("config-1"), tmp("config-2"), tmp("config-3"));
    let args = ["--mode", "L", "--frames", "1..3"];
    track_ok(&scene, &first, &args);
    let metrics = json(&first.join("metrics.json"));
    let config = &metrics["config"];
    assert_eq!(config["mode"], "L");
    assert_eq!(config["frames"], serde_json::json!([1, 3]));
    assert_eq!(config["fit"]["priors"]["shape"], 128.0);
    assert_eq!(
        config["resolved"]["tracked_frame"]["priors"]["shape"],
        512.0
    );
    assert!(config["resolved"]["first_frame"]["levels"].is_array());
    assert_eq!(
        metrics["forest"]["trees"], 20,
        "the forest's settings are recorded too"
    );
    // The metrics alone: configuration, mode and frames as recorded.
    let metrics_path = first.join("metrics.json");
    track_ok(
        &scene,
        &again,
        &["--config", metrics_path.to_str().unwrap()],
    );
    assert_eq!(json(&again.join("metrics.json"))["mode"], "L");
    let frames = |dir: &Path| json(&dir.join("trajectory.json"))["frames"].clone();
    let strip_ms = |mut v: serde_json::Value| {
        for f in v.as_array_mut().unwrap() {
            f.as_object_mut().unwrap().remove("ms");
        }
        v
    };
    assert_eq!(strip_ms(frames(&first)), strip_ms(frames(&again)));
    // Tracked frames damped 50 times harder are a different fit.
    let stiff = changed.with_extension("json");
    std::fs::create_dir_all(stiff.parent().unwrap()).unwrap();
    std::fs::write(&stiff, r#"{"priors": {"pose_damping": 50.0}}"#).unwrap();
    let mut stiff_args = args.to_vec();
    stiff_args.extend(["--config", stiff.to_str().unwrap()]);
    track_ok(&scene, &changed, &stiff_args);
    assert_ne!(strip_ms(frames(&first)), strip_ms(frames(&changed)));
    // A malformed configuration is bad input, named.
    std::fs::write(&stiff, r#"{"priors": {"shape": "strong"}}"#).unwrap();
    let run = track(&scene, &tmp("config-4"), &stiff_args);
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains(stiff.to_str().unwrap()) && err.contains("fit configuration"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    // So is a well-formed one the fit cannot work with.
    std::fs::write(&stiff, r#"{"placement": {"levels": [40]}}"#).unwrap();
    let run = track(&scene, &tmp("config-5"), &stiff_args);
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("placement.levels"), "{err}");
}

/// A trajectory's or scene's 12-number affine.
fn affine_of(q: &serde_json::Value) -> Affine {
    Affine {
        q: serde_json::from_value(q.clone()).unwrap(),
    }
}

/// The rotation nearest an affine's linear part: the fitted affine scales and shears a little.
fn rotation_of(q: &serde_json::Value) -> glam::DMat3 {
    nearest_rotation(affine_of(q).linear()).unwrap()
}

/// Degrees between two rotations.
fn degrees_between(a: glam::DMat3, b: glam::DMat3) -> f64 {
    rotation_to_vector(a * b.transpose()).length().to_degrees()
}

/// A given `initial_pose` 12° off about the camera's x axis (through the kidney's centre) ends
/// in a basin of its own when it is fitted as it is; refined, its refinement turned by ±10°
/// about each camera axis and refined again (`placement.initial_polish_deg`), the most
/// confident start is nearer the truth. Measured on this phantom: frame 0 6.2° from the truth
/// unpolished, 4.1° polished. (The turn is about one of the polish's own axes, its easiest
/// case; an off-axis start is not tested.)
#[test]
fn a_given_pose_in_a_wrong_basin_is_polished_towards_the_truth() {
    let scene = synth("polish", &[]);
    let truth = json(&scene.join("gt/trajectory.json"))["frames"][0].clone();
    let r_true = rotation_of(&truth["affine"]);
    let centre: [f64; 3] = serde_json::from_value(truth["centroids"]["kidney"].clone()).unwrap();
    let centre = glam::DVec3::from(centre);
    let truth_pose = affine_of(&truth["affine"]);
    let given =
        endofuse::fit::init::turned_about(&truth_pose, centre, glam::DVec3::X * 12f64.to_radians())
            .q
            .to_vec();
    common::edit_json(&scene, |s| {
        s["initial_pose"] = serde_json::json!({ "affine": given });
    });
    let frame0_error = |polish_deg: f64, tag: &str| {
        let config = tmp(&format!("polish-{tag}")).with_extension("json");
        std::fs::create_dir_all(config.parent().unwrap()).unwrap();
        std::fs::write(
            &config,
            format!(r#"{{"placement": {{"initial_polish_deg": {polish_deg}}}}}"#),
        )
        .unwrap();
        let out = tmp(&format!("polish-{tag}-out"));
        track_ok(
            &scene,
            &out,
            &["--frames", "0..0", "--config", config.to_str().unwrap()],
        );
        let fitted = json(&out.join("trajectory.json"))["frames"][0]["affine"].clone();
        let _ = std::fs::remove_dir_all(&out);
        degrees_between(rotation_of(&fitted), r_true)
    };
    let start = degrees_between(rotation_of(&serde_json::json!(given)), r_true);
    assert!((start - 12.0).abs() < 1e-6, "the start is 12° off: {start}");
    let (plain, polished) = (frame0_error(0.0, "plain"), frame0_error(10.0, "polished"));
    assert!(
        polished < plain - 1.0 && polished < 5.5,
        "frame 0 {plain:.2}° off unpolished, {polished:.2}° polished"
    );
    let _ = std::fs::remove_dir_all(&scene);
}
