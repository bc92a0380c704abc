//! The whole real-input path against ground truth (issue 11): a KiTS19 CT (cropped fixture)
//! through `import-ct`, a real da Vinci calibration (EndoVis calib_A, halved to 640×512 so the
//! test stays small) written as OpenCV YAML and as EndoVis text, a `synth` phantom of the
//! patient's shapes through that calibration, its frames encoded losslessly as MP4 (per camera)
//! and as one side-by-side MKV, and `new-scene` assembling scenes from them. Every frame read
//! from the videos, in any order, is the PNG's frame; each video scene tracks with the Dice of
//! the same scene read from the PNG frames.
//!
//! Needs the `ffmpeg` program (as CI installs it).

mod common;

use endofuse::calib::{self, Calibration};
use std::path::{Path, PathBuf};
use std::process::Command;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

fn ffmpeg(args: &[&str]) {
    let out = Command::new("ffmpeg")
        .args(["-v", "error", "-y"])
        .args(args)
        .output()
        .expect("the ffmpeg program is needed for this test (apt install ffmpeg)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// calib_A with intrinsics halved for 640×512 frames.
fn half_size_calibration(dir: &Path) -> (PathBuf, PathBuf) {
    let mut cal: Calibration =
        calib::read(&fixtures().join("calib/calib_A_seq1-2-3-4-6-7.txt")).unwrap();
    cal.image_size = Some((640, 512));
    for c in &mut cal.cameras {
        let i = &mut c.intrinsics;
        *i = i.scaled(0.5);
    }
    let yaml = dir.join("stereo.yml");
    let txt = dir.join("camera_calibration.txt");
    calib::write_opencv_yaml(&cal, &yaml).unwrap();
    calib::write_endovis_text(&cal, &txt).unwrap();
    (yaml, txt)
}

fn track(scene: &Path, out: &Path) -> serde_json::Value {
    common::run_ok(&[
        "track".as_ref(),
        scene.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--mode".as_ref(),
        "LSC".as_ref(),
    ]);
    common::read_json(&out.join("metrics.json"))
}

/// Gives a scene that `new-scene` made the phantom's seeds, ground truth, starting pose and
/// zoom marks (what a user would paint and what synth knows), and writes its PNG twin: the same
/// scene.json with frames from the phantom's PNG folders.
fn with_truth(scene: &Path, phantom: &Path) -> PathBuf {
    let truth = common::read_json(&phantom.join("scene.json"));
    let p = scene.join("scene.json");
    let mut v = common::read_json(&p);
    for key in ["initial_pose", "ground_truth", "zoom_changes", "seeds"] {
        v[key] = truth[key].clone();
    }
    common::copy_dir(&phantom.join("gt"), &scene.join("gt"));
    common::copy_dir(&phantom.join("seeds"), &scene.join("seeds"));
    std::fs::write(&p, serde_json::to_string_pretty(&v).unwrap()).unwrap();
    let mut twin = v.clone();
    for cam in twin["cameras"].as_array_mut().unwrap() {
        let name = cam["name"].as_str().unwrap().to_string();
        cam["frames"] = format!("{}/{name}/{{frame:06}}.png", phantom.display()).into();
    }
    let twin_path = scene.join("twin.json");
    std::fs::write(&twin_path, serde_json::to_string_pretty(&twin).unwrap()).unwrap();
    twin_path
}

#[test]
fn a_patient_ct_a_real_calibration_and_videos_track_like_png_frames() {
    let dir = common::scratch_dir("real-inputs");
    std::fs::create_dir_all(&dir).unwrap();
    let ct = fixtures().join("ct/kits19_case_00010_cropped.nii.gz");
    let (yaml, txt) = half_size_calibration(&dir);
    // The patient's shapes, as import-ct makes them.
    let meshes = dir.join("meshes");
    common::run_ok(&[
        "import-ct".as_ref(),
        ct.as_os_str(),
        "--out".as_ref(),
        meshes.as_os_str(),
    ]);
    // The phantom through the real calibration.
    let phantom = dir.join("phantom");
    common::run_ok(&[
        "synth".as_ref(),
        "--out".as_ref(),
        phantom.as_os_str(),
        "--frames".as_ref(),
        "8".as_ref(),
        "--seed".as_ref(),
        "4".as_ref(),
        "--meshes".as_ref(),
        meshes.as_os_str(),
        "--calib".as_ref(),
        yaml.as_os_str(),
    ]);
    let scene = endofuse::scene::Scene::open(&phantom).unwrap();
    assert_eq!(
        (scene.cameras[0].width, scene.cameras[0].height),
        (640, 512)
    );
    assert!((scene.cameras[1].baseline_mm() - 4.35).abs() < 0.01);
    // Lossless encodes: x264 RGB (B-frames, GOP 4 so that seeks cross keyframes) per camera,
    // and one side-by-side FFV1 MKV.
    for cam in ["left", "right"] {
        let pattern = phantom.join(format!("{cam}/%06d.png"));
        let mp4 = dir.join(format!("{cam}.mp4"));
        ffmpeg(&[
            "-framerate",
            "30",
            "-i",
            pattern.to_str().unwrap(),
            "-c:v",
            "libx264rgb",
            "-qp",
            "0",
            "-g",
            "4",
            mp4.to_str().unwrap(),
        ]);
    }
    let sbs = dir.join("stereo.mkv");
    ffmpeg(&[
        "-framerate",
        "30",
        "-i",
        phantom.join("left/%06d.png").to_str().unwrap(),
        "-framerate",
        "30",
        "-i",
        phantom.join("right/%06d.png").to_str().unwrap(),
        "-filter_complex",
        "hstack",
        "-c:v",
        "ffv1",
        sbs.to_str().unwrap(),
    ]);

    let make = |name: &str, calib: &Path, views: Vec<String>| {
        let out = dir.join(name);
        let mut args: Vec<std::ffi::OsString> = vec![
            "new-scene".into(),
            "--out".into(),
            out.clone().into(),
            "--calib".into(),
            calib.into(),
            "--ct".into(),
            ct.clone().into(),
        ];
        args.extend(views.into_iter().map(Into::into));
        let printed = common::run_ok(&args);
        let text = String::from_utf8_lossy(&printed.stdout);
        assert!(
            text.contains("next:") && text.contains("endofuse open"),
            "{text}"
        );
        // No guessed pose: track and the app place the model from the images.
        let written = common::read_json(&out.join("scene.json"));
        assert!(written.get("initial_pose").is_none(), "{written}");
        out
    };
    let per_camera = |calib: &Path, name: &str| {
        make(
            name,
            calib,
            vec![
                "--view".into(),
                format!("left={}", dir.join("left.mp4").display()),
                "--view".into(),
                format!("right={}", dir.join("right.mp4").display()),
            ],
        )
    };
    let from_yaml = per_camera(&yaml, "scene-yaml");
    let from_txt = per_camera(&txt, "scene-endovis");
    let side_by_side = make(
        "scene-sbs",
        &yaml,
        vec!["--side-by-side".into(), sbs.to_string_lossy().to_string()],
    );
    // An odd-width recording splits with its middle column left out, and says so.
    let odd = dir.join("stereo-odd.mkv");
    ffmpeg(&[
        "-i",
        sbs.to_str().unwrap(),
        "-vf",
        "pad=iw+1:ih",
        "-c:v",
        "ffv1",
        odd.to_str().unwrap(),
    ]);
    let printed = common::run_ok(&[
        "new-scene".as_ref(),
        "--out".as_ref(),
        dir.join("scene-odd").as_os_str(),
        "--calib".as_ref(),
        yaml.as_os_str(),
        "--meshes".as_ref(),
        from_yaml.as_os_str(),
        "--side-by-side".as_ref(),
        odd.as_os_str(),
    ]);
    let text = String::from_utf8_lossy(&printed.stdout);
    assert!(
        text.contains("note: ") && text.contains("an odd width") && text.contains("middle column"),
        "{text}"
    );

    // Frame i read from a video, reached in any order, is the PNG's frame i.
    for s in [&from_yaml, &side_by_side] {
        let video = endofuse::scene::Scene::open(s).unwrap();
        assert_eq!(video.frame_count, 8);
        for &t in &[5usize, 0, 7, 2, 3, 1, 6, 4, 4, 0] {
            for c in 0..2 {
                let png = scene.frame(c, t).unwrap();
                let from_video = video.frame(c, t).unwrap();
                assert!(
                    *png == *from_video,
                    "{}: camera {c} frame {t} differs",
                    s.display()
                );
            }
        }
    }
    // The cameras read from YAML and from EndoVis text are the same.
    let a = endofuse::scene::Scene::open(&from_yaml).unwrap();
    let b = endofuse::scene::Scene::open(&from_txt).unwrap();
    for (x, y) in a.cameras.iter().zip(&b.cameras) {
        assert!((x.intrinsics.fx - y.intrinsics.fx).abs() < 1e-9);
        assert!((x.extrinsics.translation_mm - y.extrinsics.translation_mm).length() < 1e-9);
    }

    // Each scene tracks like its PNG twin.
    for s in [&from_yaml, &from_txt, &side_by_side] {
        let twin = with_truth(s, &phantom);
        let video = track(s, &s.join("tracked"));
        let png = track(&twin, &s.join("tracked-png"));
        let (dv, dp) = (
            video["dice"]["mean"].as_f64().unwrap(),
            png["dice"]["mean"].as_f64().unwrap(),
        );
        eprintln!("{}: Dice {dv:.4} from video, {dp:.4} from PNG", s.display());
        assert!(
            (dv - dp).abs() <= 0.01,
            "{}: Dice {dv} from video, {dp} from PNG",
            s.display()
        );
        assert!(
            dp > 0.85,
            "{}: the patient phantom tracks poorly: Dice {dp}",
            s.display()
        );
    }
}

#[test]
fn bad_real_inputs_are_refused_with_one_line() {
    let dir = common::scratch_dir("real-inputs-bad");
    std::fs::create_dir_all(&dir).unwrap();
    let ct = fixtures().join("ct/kits19_case_00010_cropped.nii.gz");
    let (yaml, _) = half_size_calibration(&dir);
    // A 320×256 video: the calibration says 640×512.
    let small = dir.join("small.mp4");
    ffmpeg(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=320x256:rate=30",
        "-frames:v",
        "5",
        "-c:v",
        "libx264",
        small.to_str().unwrap(),
    ]);
    let right = dir.join("right.mp4");
    ffmpeg(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=640x512:rate=30",
        "-frames:v",
        "5",
        "-c:v",
        "libx264",
        right.to_str().unwrap(),
    ]);
    let text = dir.join("notes.mp4");
    std::fs::write(&text, "not a video").unwrap();
    let audio = dir.join("tone.mkv");
    ffmpeg(&["-f", "lavfi", "-i", "sine=d=1", audio.to_str().unwrap()]);
    let truncated = dir.join("cut.mp4");
    let bytes = std::fs::read(&right).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 3]).unwrap();

    let run = |views: &[&Path], extra: &[&str]| {
        let out = dir.join("scene");
        let mut c = Command::new(env!("CARGO_BIN_EXE_endofuse"));
        c.arg("new-scene")
            .arg("--out")
            .arg(&out)
            .arg("--calib")
            .arg(&yaml)
            .arg("--ct")
            .arg(&ct);
        for (v, name) in views.iter().zip(["left", "right"]) {
            c.arg("--view").arg(format!("{name}={}", v.display()));
        }
        c.args(extra);
        let o = c.output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr).to_string();
        let errors: Vec<&str> = stderr
            .lines()
            .filter(|l| l.starts_with("endofuse:"))
            .collect();
        if o.status.code() == Some(2) {
            assert!(!out.exists(), "nothing may be written: {stderr}");
        }
        (o.status.code(), errors.join("\n"))
    };
    let cases: Vec<(Vec<&Path>, Vec<&str>, &str, &str)> = vec![
        (vec![&small, &small], vec![], "stereo.yml", "320×256"),
        (
            vec![&small, &right],
            vec![],
            "right.mp4",
            "640×512 but camera 'left'",
        ),
        (
            vec![&text, &right],
            vec![],
            "notes.mp4",
            "not a readable video",
        ),
        (vec![&audio, &right], vec![], "tone.mkv", "no video stream"),
        (
            vec![&right, &right],
            vec!["--frames", "50"],
            "--frames",
            "only 5",
        ),
        (vec![&right], vec![], "stereo.yml", "2 camera(s)"),
    ];
    for (views, extra, file, words) in cases {
        let (code, line) = run(&views, &extra);
        assert_eq!(code, Some(2), "{file}: {line}");
        assert_eq!(line.lines().count(), 1, "{line}");
        assert!(
            line.contains(file) && line.contains(words),
            "expected {file} / {words}: {line}"
        );
    }
    // Views name calibration cameras, each once; given out of order they still land right.
    let named = |views: &[(&str, &Path)]| {
        let out = dir.join("named");
        let _ = std::fs::remove_dir_all(&out);
        let mut c = Command::new(env!("CARGO_BIN_EXE_endofuse"));
        c.arg("new-scene")
            .arg("--out")
            .arg(&out)
            .arg("--calib")
            .arg(&yaml)
            .arg("--ct")
            .arg(&ct);
        for (name, v) in views {
            c.arg("--view").arg(format!("{name}={}", v.display()));
        }
        let o = c.output().unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).to_string(),
            out,
        )
    };
    let (code, err, _) = named(&[("right", &right), ("r", &small)]);
    assert_eq!(code, Some(2));
    assert!(
        err.contains("--view") && err.contains("'r' is not a camera"),
        "{err}"
    );
    let (code, err, _) = named(&[("right", &right), ("right", &small)]);
    assert_eq!(code, Some(2));
    assert!(err.contains("given twice"), "{err}");
    // Swapped order, with the wrong-size video named: the error names that file.
    let (code, err, _) = named(&[("right", &small), ("left", &right)]);
    assert_eq!(code, Some(2));
    assert!(
        err.contains("small.mp4") && err.contains("camera 'right'"),
        "{err}"
    );
    let other = dir.join("other.mp4");
    std::fs::copy(&right, &other).unwrap();
    let (code, err, out) = named(&[("right", &right), ("left", &other)]);
    assert_eq!(code, Some(0), "{err}");
    let v = common::read_json(&out.join("scene.json"));
    assert!(
        v["cameras"][0]["frames"]
            .as_str()
            .unwrap()
            .ends_with("other.mp4"),
        "{v}"
    );
    assert!(
        v["cameras"][1]["frames"]
            .as_str()
            .unwrap()
            .ends_with("right.mp4"),
        "{v}"
    );

    // A truncated video is refused when it opens or when a frame past the cut is read; either
    // way the message names the file, never wrong pixels.
    let (code, line) = run(&[&truncated, &right], &[]);
    if code == Some(0) {
        let scene = endofuse::scene::Scene::open(&dir.join("scene")).unwrap();
        let err = (0..5).find_map(|t| scene.frame(0, t).err());
        let err = err.expect("a truncated video must fail somewhere");
        assert!(err.path.ends_with("cut.mp4"), "{err}");
    } else {
        assert_eq!(code, Some(2));
        assert!(line.contains("cut.mp4"), "{line}");
    }
}
