//! Every bad input of CONTRACT §1 gets exit code 2 and one line on stderr naming the file and
//! the problem, never a panic. Each case copies the hand-made fixture scene and breaks one thing.

mod common;

use common::{edit_json, fixture};
use std::path::{Path, PathBuf};
use std::process::Command;

/// A fresh copy of the fixture in a temp folder unique to `name`.
fn scratch(name: &str) -> PathBuf {
    common::fixture_copy(&format!("bad-{name}"))
}

fn info(scene: &Path) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .arg("info")
        .arg(scene)
        .env_remove("RUST_LOG")
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

/// Runs `info` and checks exit 2 with one error line naming `file` and containing `words`.
fn expect_bad(dir: &Path, file: &str, words: &str) {
    let (code, stderr) = info(dir);
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| {
            !l.starts_with("checking frames") && !l.trim().is_empty() && !l.contains("\rchecking")
        })
        .collect();
    assert_eq!(
        code, 2,
        "expected exit 2 for {file} / {words}, got {code}: {stderr}"
    );
    assert!(
        !stderr.contains("panicked") && !stderr.contains("internal error"),
        "{stderr}"
    );
    let last = lines.last().copied().unwrap_or("");
    assert!(last.contains(file), "error should name {file}: {last}");
    assert!(
        last.to_lowercase().contains(&words.to_lowercase()),
        "error should say '{words}': {last}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// Writes the first half of `from`'s bytes to `to` (a PNG cut inside its pixel data: the
/// fixture's small images keep a whole header).
fn write_first_half(from: &Path, to: &Path) {
    let bytes = std::fs::read(from).unwrap();
    std::fs::write(to, &bytes[..bytes.len() / 2]).unwrap();
}

#[test]
fn the_fixture_itself_is_accepted() {
    let (code, stderr) = info(&fixture());
    assert_eq!(code, 0, "{stderr}");
    let out = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .args(["info"])
        .arg(fixture().join("scene.json"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("baseline 5.00 mm"), "{text}");
    assert!(text.contains("hidden"), "{text}");
    assert!(text.contains("seeds: frames 0: kidney"), "{text}");
    assert!(!text.contains("not painted yet"), "{text}");

    // A class without a stroke is said by info (track and classify refuse it).
    let d = scratch("one-class-unpainted");
    let seed = d.join("seeds/left/000000.png");
    let img = image::open(&seed).unwrap().to_luma8();
    let kidney_only = image::GrayImage::from_fn(img.width(), img.height(), |x, y| {
        let v = img.get_pixel(x, y).0[0];
        image::Luma([if v == 255 { 0 } else { v }])
    });
    kidney_only.save(&seed).unwrap();
    for other in std::fs::read_dir(d.join("seeds")).unwrap().flatten() {
        for f in std::fs::read_dir(other.path()).unwrap().flatten() {
            if f.path() != seed {
                std::fs::remove_file(f.path()).unwrap();
            }
        }
    }
    let out = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .arg("info")
        .arg(&d)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("not painted yet: background/tools (seed value 255)"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn missing_and_malformed_scene_files() {
    let missing = std::env::temp_dir().join("endofuse-no-such-scene");
    let (code, stderr) = info(&missing);
    assert_eq!(code, 2);
    assert!(stderr.contains("no such scene"), "{stderr}");

    let d = scratch("malformed");
    std::fs::write(d.join("scene.json"), "{ \"format\": ").unwrap();
    expect_bad(&d, "scene.json", "malformed");

    let d = scratch("version");
    edit_json(&d, |v| v["format"] = "endofuse-scene/9".into());
    expect_bad(&d, "scene.json", "unsupported format");

    let d = scratch("missing-key");
    edit_json(&d, |v| {
        v["cameras"][1].as_object_mut().unwrap().remove("fx");
    });
    expect_bad(&d, "scene.json", "missing field `fx`");

    let d = scratch("unknown-camera-key");
    edit_json(&d, |v| v["cameras"][0]["focal"] = 3.into());
    expect_bad(&d, "scene.json", "unknown field");
}

#[test]
fn bad_values_in_scene_json() {
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(&str, Edit, &str)> = vec![
        (
            "width",
            Box::new(|v| v["cameras"][0]["width"] = 0.into()),
            "must be positive",
        ),
        (
            "frames",
            Box::new(|v| v["frame_count"] = 0.into()),
            "frame_count must be positive",
        ),
        (
            "nostructures",
            Box::new(|v| v["structures"] = serde_json::json!([])),
            "no structures",
        ),
        (
            "dup-label",
            Box::new(|v| v["structures"][1]["label"] = 1.into()),
            "already used",
        ),
        (
            "reserved",
            Box::new(|v| v["structures"][1]["label"] = 255.into()),
            "reserved",
        ),
        (
            "rotation",
            Box::new(|v| {
                v["cameras"][1]["rotation"] = serde_json::json!([[1, 0, 0], [0, 2, 0], [0, 0, 1]])
            }),
            "not a rotation",
        ),
        (
            "far-camera",
            Box::new(|v| v["cameras"][1]["translation"] = serde_json::json!([1e300, 0, 0])),
            "under 100 m",
        ),
        (
            "huge-pose",
            Box::new(|v| {
                v["initial_pose"] = serde_json::json!({
                    "affine": [1e300, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 150]
                })
            }),
            "more than 100×",
        ),
        (
            "focal",
            Box::new(|v| v["cameras"][1]["fy"] = (-3.0).into()),
            "focal lengths must be positive",
        ),
        (
            "huge-focal",
            Box::new(|v| v["cameras"][0]["fx"] = 1e308.into()),
            "implausible",
        ),
        (
            "far-centre",
            Box::new(|v| v["cameras"][1]["cx"] = 1e6.into()),
            "principal point",
        ),
        (
            "template",
            Box::new(|v| v["cameras"][0]["frames"] = "left/{frme}.png".into()),
            "unknown placeholder",
        ),
        (
            "affine",
            Box::new(|v| v["initial_pose"]["affine"] = serde_json::json!([1, 0, 0])),
            "12 numbers",
        ),
        (
            "zoom",
            Box::new(|v| v["zoom_changes"] = serde_json::json!([[1, 5]])),
            "zoom_changes",
        ),
        (
            "dup-name",
            Box::new(|v| v["structures"][1]["name"] = "kidney".into()),
            "named 'kidney'",
        ),
        (
            "k1-relation",
            Box::new(|v| v["k1_vs_focal"] = serde_json::json!([0.2, 1e300, 0])),
            "k1_vs_focal",
        ),
        (
            "k1-relation-short",
            Box::new(|v| v["k1_vs_focal"] = serde_json::json!([0.2, -0.07])),
            "k1_vs_focal",
        ),
    ];
    for (name, edit, words) in cases {
        let d = scratch(name);
        edit_json(&d, edit);
        expect_bad(&d, "scene.json", words);
    }
}

/// Files other tools wrote (issue 11 §6): a BOM before the JSON, a ground-truth trajectory
/// whose frames carry keys of their own (of any type) are read; a ground-truth label image of
/// the wrong size is refused by `info` as `classify` would refuse it.
#[test]
fn files_other_tools_wrote() {
    let d = scratch("bom");
    let p = d.join("scene.json");
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, format!("\u{feff}{text}")).unwrap();
    let (code, stderr) = info(&d);
    assert_eq!(
        code, 0,
        "a BOM before scene.json must be accepted: {stderr}"
    );

    let d = scratch("foreign-trajectory");
    let frame = |t: u32| {
        serde_json::json!({
            "frame": t, "affine": [1,0,0, 0,1,0, 0,0,1, 0,0,150],
            "shape": {"kidney": {"modes": 3, "weights": [0.1, 0.2]}},
            "tools": [{"name": "grasper", "tip": [1, 2, 3]}],
            "energy": "n/a", "lost": 0,
            "centroids": {"kidney": [0.0, 0.0, 150.0]}
        })
    };
    std::fs::write(
        d.join("gt/trajectory.json"),
        format!(
            "\u{feff}{}",
            serde_json::json!({"frames": [frame(0), frame(1)], "creator": {"tool": "other"}})
        ),
    )
    .unwrap();
    edit_json(&d, |v| {
        v["ground_truth"]["trajectory"] = "gt/trajectory.json".into();
    });
    let (code, stderr) = info(&d);
    assert_eq!(
        code, 0,
        "foreign keys in trajectory frames must be ignored: {stderr}"
    );

    let d = scratch("gt-size");
    image::GrayImage::new(10, 10)
        .save(d.join("gt/right/000001.png"))
        .unwrap();
    expect_bad(
        &d,
        "gt/right/000001.png",
        "ground-truth label image is 10×10",
    );
}

#[test]
fn bad_frames() {
    let d = scratch("missing-frame");
    std::fs::remove_file(d.join("right/000001.png")).unwrap();
    expect_bad(&d, "right/000001.png", "missing frame");

    let d = scratch("truncated-frame");
    write_first_half(&d.join("left/000001.png"), &d.join("left/000001.png"));
    expect_bad(&d, "left/000001.png", "cannot decode");

    let d = scratch("frame-size");
    image::RgbImage::new(10, 10)
        .save(d.join("left/000000.png"))
        .unwrap();
    expect_bad(&d, "left/000000.png", "10×10 but the camera is 64×48");
}

/// Ground truth that `track` would refuse is refused by `info` already (the headers were
/// checked before; a truncated body or a 16-bit image passed until a run read them).
#[test]
fn bad_ground_truth() {
    let d = scratch("truncated-truth");
    write_first_half(
        &d.join("gt/right/000001.png"),
        &d.join("gt/right/000001.png"),
    );
    expect_bad(&d, "gt/right/000001.png", "cannot decode label image");

    let d = scratch("sixteen-bit-truth");
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(64, 48)
        .save(d.join("gt/left/000000.png"))
        .unwrap();
    expect_bad(&d, "gt/left/000000.png", "must be 8-bit grey");

    // A hidden structure's mask (the default place, `gt/hidden/{structure}/{camera}/…`).
    let d = scratch("truncated-hidden-mask");
    let mask = d.join("gt/hidden/hidden/left/000001.png");
    std::fs::create_dir_all(mask.parent().unwrap()).unwrap();
    write_first_half(&d.join("gt/left/000001.png"), &mask);
    expect_bad(
        &d,
        "gt/hidden/hidden/left/000001.png",
        "cannot decode label image",
    );

    // Values no structure has: scored, they lowered the Dice with nothing saying why.
    let d = scratch("truth-value");
    let mut img = image::GrayImage::new(64, 48);
    img.put_pixel(5, 5, image::Luma([9]));
    img.save(d.join("gt/left/000001.png")).unwrap();
    // track checks every image of its range before it starts, not at the frame that has it.
    let out = d.with_extension("track-out");
    let run = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .arg("track")
        .arg(&d)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("gt/left/000001.png") && !stderr.contains("track: frame"),
        "{stderr}"
    );
    assert!(!out.exists());
    expect_bad(
        &d,
        "gt/left/000001.png",
        "ground-truth value 9 is no structure's label",
    );

    let d = scratch("truth-seed-background");
    image::GrayImage::from_pixel(64, 48, image::Luma([255]))
        .save(d.join("gt/right/000000.png"))
        .unwrap();
    expect_bad(&d, "gt/right/000000.png", "ground-truth value 255");

    // A hidden mask is 0/255 (CONTRACT): a 0/1 mask would read as empty.
    let d = scratch("hidden-mask-value");
    let mask = d.join("gt/hidden/hidden/left/000001.png");
    std::fs::create_dir_all(mask.parent().unwrap()).unwrap();
    let mut img = image::GrayImage::new(64, 48);
    img.put_pixel(5, 5, image::Luma([1]));
    img.save(&mask).unwrap();
    expect_bad(&d, "gt/hidden/hidden/left/000001.png", "mask holds value 1");
}

#[test]
fn bad_seeds() {
    let d = scratch("seed-size");
    image::GrayImage::new(32, 48)
        .save(d.join("seeds/right/000000.png"))
        .unwrap();
    expect_bad(&d, "seeds/right/000000.png", "32×48");

    let d = scratch("seed-value");
    let mut img = image::GrayImage::new(64, 48);
    img.put_pixel(3, 3, image::Luma([9]));
    img.save(d.join("seeds/left/000000.png")).unwrap();
    expect_bad(&d, "seeds/left/000000.png", "seed value 9 is no structure");

    let d = scratch("seed-hidden");
    let mut img = image::GrayImage::new(64, 48);
    img.put_pixel(3, 3, image::Luma([7]));
    img.save(d.join("seeds/left/000000.png")).unwrap();
    expect_bad(&d, "seeds/left/000000.png", "hidden structure 'hidden'");
}

#[test]
fn bad_meshes() {
    let d = scratch("missing-mesh");
    std::fs::remove_file(d.join("meshes/tumour.stl")).unwrap();
    expect_bad(&d, "meshes/tumour.stl", "cannot read mesh");

    let d = scratch("garbage-mesh");
    std::fs::write(d.join("meshes/kidney.obj"), "v 1 2\nf 1 2 3\n").unwrap();
    expect_bad(&d, "meshes/kidney.obj", "vertex needs 3 coordinates");

    let d = scratch("nan-mesh");
    let text = std::fs::read_to_string(d.join("meshes/kidney.obj"))
        .unwrap()
        .replacen("v 20 0 0", "v nan 0 0", 1);
    std::fs::write(d.join("meshes/kidney.obj"), text).unwrap();
    expect_bad(&d, "meshes/kidney.obj", "non-finite");

    let d = scratch("index-mesh");
    let text = std::fs::read_to_string(d.join("meshes/hidden.ply"))
        .unwrap()
        .replace("3 0 2 4\n", "3 0 2 44\n");
    std::fs::write(d.join("meshes/hidden.ply"), text).unwrap();
    expect_bad(&d, "meshes/hidden.ply", "refers to vertex 45");

    let d = scratch("catalog-count");
    std::fs::create_dir_all(d.join("meshes/kidney_catalog")).unwrap();
    std::fs::copy(
        d.join("meshes/kidney.obj"),
        d.join("meshes/kidney_catalog/000.obj"),
    )
    .unwrap();
    std::fs::write(
        d.join("meshes/kidney_catalog/001.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
    edit_json(&d, |v| {
        v["structures"][0]["catalog"] = "meshes/kidney_catalog".into()
    });
    expect_bad(
        &d,
        "kidney_catalog/001.obj",
        "4 vertices but the structure's mesh has 6",
    );
}

/// A named pipe where a file should be is refused at once: reading one blocks until something
/// writes to it (`info` hung on it before).
#[cfg(unix)]
#[test]
fn a_pipe_instead_of_a_file_is_refused_not_waited_on() {
    let d = scratch("fifo-mesh");
    let mesh = d.join("meshes/kidney.obj");
    std::fs::remove_file(&mesh).unwrap();
    let made = Command::new("mkfifo").arg(&mesh).status();
    if !made.is_ok_and(|s| s.success()) {
        eprintln!("skipped: mkfifo is not available here");
        return;
    }
    expect_bad(&d, "meshes/kidney.obj", "not a regular file");

    let d = scratch("fifo-scene");
    let json = d.join("scene.json");
    std::fs::remove_file(&json).unwrap();
    assert!(
        Command::new("mkfifo")
            .arg(&json)
            .status()
            .unwrap()
            .success()
    );
    expect_bad(&d, "scene.json", "not a regular file");
}

#[test]
fn bad_synth_options_are_refused() {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("endofuse-bad-synth-{}", std::process::id()));
    let run = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .args(["synth", "--frames", "0", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("--frames"));
    let run = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .args(["synth", "--noise", "nan", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
    let run = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .args(["classify", "x", "--trees", "4294967295", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2), "a forest too large to allocate");
    assert!(String::from_utf8_lossy(&run.stderr).contains("--trees"));
    // A calibration without an image size rendered at the default 960×540 even where its
    // principal point says the cameras were calibrated at another size: then the size must be
    // given, and it is used.
    let sizeless = out.with_extension("sizeless.yml");
    let yaml = std::fs::read_to_string(common::fixture().join("../calib/opencv4_stereo.yml"))
        .unwrap()
        .replace("imageSize: [ 1280, 1024 ]\n", "");
    std::fs::write(&sizeless, yaml).unwrap();
    let synth_with = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_endofuse"))
            .args(["synth", "--frames", "1", "--calib"])
            .arg(&sizeless)
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap()
    };
    let run = synth_with(&[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("sizeless.yml") && stderr.contains("gives no image size"),
        "{stderr}"
    );
    assert!(!out.exists(), "nothing written");
    let run = synth_with(&["--width", "1280", "--height", "1024"]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let scene = common::read_json(&out.join("scene.json"));
    assert_eq!(scene["cameras"][0]["width"], 1280);
    let _ = std::fs::remove_dir_all(&out);
    // One whose principal point fits the default size renders at it, and says so.
    let matrix = |data: &str| {
        format!("!!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ {data} ]\n")
    };
    let zeros =
        "!!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ 0., 0., 0., 0., 0. ]\n";
    let centred = format!(
        "%YAML:1.0\n---\nK1: {}D1: {zeros}K2: {}D2: {zeros}R: {}T: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ -4.4, 0., 0. ]\n",
        matrix("1000., 0., 478., 0., 1000., 271., 0., 0., 1."),
        matrix("1000., 0., 482., 0., 1000., 269., 0., 0., 1."),
        matrix("1., 0., 0., 0., 1., 0., 0., 0., 1."),
    );
    std::fs::write(&sizeless, centred).unwrap();
    let run = synth_with(&[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("rendering at 960×540"), "{stderr}");
    let scene = common::read_json(&out.join("scene.json"));
    assert_eq!(scene["cameras"][0]["width"], 960);
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_file(&sizeless);
}

/// `synth --out` writes a phantom whole: an earlier phantom there is replaced (none of its
/// frames stay), a folder of anything else is refused and left as it was.
#[test]
fn synth_replaces_an_earlier_phantom_and_refuses_other_folders() {
    let base = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("endofuse-synth-out-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let synth = |out: &Path, frames: &str| {
        Command::new(env!("CARGO_BIN_EXE_endofuse"))
            .args([
                "synth", "--width", "64", "--height", "48", "--frames", frames,
            ])
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let phantom = base.join("phantom");
    assert!(synth(&phantom, "3").status.success());
    assert!(phantom.join("left/000002.png").is_file());
    let again = synth(&phantom, "2");
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    assert!(phantom.join("left/000001.png").is_file());
    assert!(
        !phantom.join("left/000002.png").exists(),
        "a frame of the earlier phantom stayed"
    );

    // A phantom the user saved something into is theirs now.
    std::fs::write(phantom.join("session.endofuse.json"), "{}").unwrap();
    let refused = synth(&phantom, "2");
    assert_eq!(refused.status.code(), Some(2));
    assert!(phantom.join("session.endofuse.json").is_file());
    assert!(phantom.join("left/000001.png").is_file());

    // An empty folder is written in place (kept, not renamed away).
    let empty = base.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert!(synth(&empty, "2").status.success());
    assert!(empty.join("scene.json").is_file());

    let user = base.join("user");
    std::fs::create_dir_all(&user).unwrap();
    std::fs::write(user.join("notes.txt"), "mine").unwrap();
    let refused = synth(&user, "2");
    assert_eq!(refused.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("user") && stderr.contains("not an earlier synth phantom"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read_to_string(user.join("notes.txt")).unwrap(),
        "mine"
    );
    assert_eq!(std::fs::read_dir(&user).unwrap().count(), 1);
    let _ = std::fs::remove_dir_all(&base);
}

/// Frames under a folder whose name has braces: scene.json's frame paths are templates, so
/// `new-scene` doubles the path's own braces, and the scene opens (the folder `br{x}` was read
/// as an unknown placeholder, reported against new-scene's hidden staging folder).
#[test]
fn braces_in_a_frames_folder_are_part_of_its_path() {
    let fixture = scratch("braces-src");
    let root = common::scratch_dir("bad-braces").join("b{r}x {frame}");
    common::copy_dir(&fixture, &root);
    let out = root.parent().unwrap().join("scene");
    let new_scene = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_endofuse"))
            .arg("new-scene")
            .arg("--out")
            .arg(&out)
            .arg("--calib")
            .arg(root.join("scene.json"))
            .arg("--meshes")
            .arg(root.join("meshes"))
            .arg("--view")
            .arg(format!("left={}", root.join("left").display()))
            .arg("--view")
            .arg(format!("right={}", root.join("right").display()))
            .args(extra)
            .env_remove("RUST_LOG")
            .output()
            .unwrap()
    };
    let run = new_scene(&[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    let scene = common::read_json(&out.join("scene.json"));
    let frames = scene["cameras"][0]["frames"].as_str().unwrap().to_string();
    assert!(frames.contains("b{{r}}x {{frame}}"), "{frames}");
    let (code, stderr) = info(&out);
    assert_eq!(code, 0, "{stderr}");

    // new-scene --force replaces the scene it made …
    let again = new_scene(&["--force"]);
    assert_eq!(
        again.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    // … but not once it holds painted seeds, or anything else it did not write.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let refused = new_scene(&["--force"]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("'notes.txt', which new-scene did not write"),
        "{stderr}"
    );
    std::fs::remove_file(out.join("notes.txt")).unwrap();
    let seed = out.join("seeds/left/000000.png");
    std::fs::create_dir_all(seed.parent().unwrap()).unwrap();
    std::fs::copy(fixture.join("seeds/left/000000.png"), &seed).unwrap();
    let again = new_scene(&["--force"]);
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert_eq!(again.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("holds painted seeds"), "{stderr}");
    assert!(seed.exists());
    let _ = std::fs::remove_dir_all(&fixture);
    let _ = std::fs::remove_dir_all(root.parent().unwrap());
}

/// A doubtful input that is not an error (a baseline of 5 µm: the calibration is in metres)
/// is said by default, as one `warning:` line naming the value, and the command goes on.
#[test]
fn doubtful_inputs_warn_on_stderr_by_default() {
    let dir = scratch("metres");
    edit_json(&dir, |j| {
        j["cameras"][1]["translation"] = serde_json::json!([-0.005, 0, 0]);
    });
    let out = common::scratch_dir("bad-metres-out").join("scene");
    let run = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .arg("new-scene")
        .arg("--out")
        .arg(&out)
        .arg("--calib")
        .arg(dir.join("scene.json"))
        .arg("--meshes")
        .arg(dir.join("meshes"))
        .arg("--view")
        .arg(format!("left={}", dir.join("left").display()))
        .arg("--view")
        .arg(format!("right={}", dir.join("right").display()))
        .env_remove("RUST_LOG")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    let warnings: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("warning:"))
        .collect();
    assert_eq!(warnings.len(), 1, "{stderr}");
    assert!(
        warnings[0].contains("translation") && warnings[0].contains("0.005"),
        "{stderr}"
    );
    assert!(
        warnings[0].contains(&dir.join("scene.json").display().to_string()),
        "the warning names the file: {stderr}"
    );
    assert!(out.join("scene.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(out.parent().unwrap());

    // Camera 0 is the reference: extrinsics of its own are used, and said.
    let dir = scratch("camera0-moved");
    edit_json(&dir, |j| {
        j["cameras"][0]["translation"] = serde_json::json!([5, 0, 0]);
    });
    let (code, stderr) = info(&dir);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr
            .lines()
            .any(|l| l.starts_with("warning:") && l.contains("camera 0")),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
