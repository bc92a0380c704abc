//! Calibration files other tools wrote (`endofuse::calib`): the EndoVis 2018 da Vinci files,
//! OpenCV 4 FileStorage YAML and XML as `stereoCalibrate`/`calibrateCamera` output them, a
//! scene.json's cameras; round trips through every writer; the left→right convention checked by
//! projection; bad input refused with a message naming the problem; no panic on any truncation.

use std::path::{Path, PathBuf};

use endofuse::calib::{self, CalibCamera, CalibFormat, Calibration};
use endofuse::geometry::pose::rotation_from_vector;
use endofuse::geometry::{Extrinsics, Intrinsics};
use glam::{DMat3, DVec3};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/calib")
        .join(name)
}

fn fixture_text(name: &str) -> String {
    std::fs::read_to_string(fixture(name)).expect("fixture")
}

/// A fresh scratch folder for this test process and test.
fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("endofuse-calib-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// The error message `parse` gives for `text` (panics if it parses).
fn problem(text: &str, ext: &str) -> String {
    match calib::parse(text.as_bytes(), Some(ext)) {
        Ok(c) => panic!("parsed but should not: {c:?}"),
        Err(e) => e.to_string(),
    }
}

fn assert_mentions(message: &str, words: &[&str]) {
    for w in words {
        assert!(message.contains(w), "{message:?} does not mention {w:?}");
    }
}

const CALIB_A: &str = "calib_A_seq1-2-3-4-6-7.txt";
const CALIB_D: &str = "calib_D_seq13-15-16.txt";

#[test]
fn endovis_calib_a_numbers_as_in_the_file() {
    let cal = calib::read(&fixture(CALIB_A)).expect("calib_A");
    assert_eq!(cal.format, CalibFormat::EndoVisText);
    assert_eq!(cal.image_size, Some((1280, 1024)));
    let [l, r] = &cal.cameras[..] else {
        panic!("{} cameras", cal.cameras.len())
    };
    assert_eq!((l.name.as_str(), r.name.as_str()), ("left", "right"));
    let want_l = Intrinsics {
        fx: 1084.21,
        fy: 1084.05,
        cx: 580.02,
        cy: 506.79,
        k1: -0.00069,
        k2: 0.00195,
        p1: 0.00018,
        p2: 0.0,
        k3: 0.0,
    };
    assert_eq!(l.intrinsics, want_l);
    assert_eq!(l.extrinsics, Extrinsics::default());
    assert_eq!(
        (r.intrinsics.fx, r.intrinsics.cx, r.intrinsics.k1),
        (1083.43, 680.91, -0.00085)
    );
    assert_eq!(
        r.extrinsics.rotation,
        rotation_from_vector(DVec3::new(-0.0002, -0.0011, -0.0))
    );
    assert_eq!(
        r.extrinsics.translation_mm,
        DVec3::new(-4.3499, 0.0333, -0.0369)
    );
}

#[test]
fn endovis_calib_d_fifth_coefficient_is_k3_and_alpha_may_be_absent() {
    let cal = calib::read(&fixture(CALIB_D)).expect("calib_D (no Camera-0-Alpha, trailing dump)");
    let [l, r] = &cal.cameras[..] else {
        panic!("{} cameras", cal.cameras.len())
    };
    let li = l.intrinsics;
    assert_eq!(
        (li.fx, li.fy, li.cx, li.cy),
        (1081.85, 1081.64, 600.38, 508.57)
    );
    assert_eq!(
        (li.k1, li.k2, li.p1, li.p2, li.k3),
        (-0.00271, 0.01359, 0.0, 0.0, -0.01585)
    );
    assert_eq!(r.intrinsics.k3, -0.00697);
    let omega = DVec3::new(-1.53345e-05, -0.00118, -1.61941e-05);
    assert_eq!(r.extrinsics.rotation, rotation_from_vector(omega));
    assert_eq!(
        r.extrinsics.translation_mm,
        DVec3::new(-4.36901, -0.03091, -0.03944)
    );
}

#[test]
fn endovis_all_five_shared_files_when_present() {
    let dir = Path::new("/work/shared/data/endovis2018-calibration");
    if !dir.is_dir() {
        eprintln!(
            "skipped: {} is not here (the two fixtures cover the format)",
            dir.display()
        );
        return;
    }
    let mut n = 0;
    for entry in std::fs::read_dir(dir).expect("dir") {
        let path = entry.expect("entry").path();
        if path.extension().and_then(|e| e.to_str()) != Some("txt") {
            continue;
        }
        let cal = calib::read(&path).unwrap_or_else(|e| panic!("{e}"));
        let cams = cal
            .cameras(1280, 1024)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(cams.len(), 2, "{}", path.display());
        let centre = cams[1].extrinsics.center_mm();
        assert!(
            (4.2..4.4).contains(&cams[1].baseline_mm()) && centre.x > 4.2,
            "{centre}"
        );
        assert!((1000.0..1100.0).contains(&cams[0].intrinsics.fx));
        n += 1;
    }
    assert_eq!(n, 5);
}

#[test]
fn endovis_right_camera_sees_a_point_to_the_left() {
    let cal = calib::read(&fixture(CALIB_A)).expect("calib_A");
    let cams = cal.cameras(1280, 1024).expect("plausible");
    let right = &cams[1];
    // The right camera's centre −RᵀT lies at +x of the left camera (T_x ≈ −4.35 mm).
    assert!(
        right.extrinsics.center_mm().x > 4.3,
        "{}",
        right.extrinsics.center_mm()
    );
    let p = DVec3::new(0.0, 0.0, 100.0);
    let mut zero_baseline = right.clone();
    zero_baseline.extrinsics.translation_mm = DVec3::ZERO;
    let u = right.project(p).expect("in front").x;
    let u0 = zero_baseline.project(p).expect("in front").x;
    let expected = -right.intrinsics.fx * 4.3499 / 100.0; // ≈ −47 px: to the left
    assert!(
        (u - u0 - expected).abs() < 0.3,
        "u − u0 = {} px, expected {expected}",
        u - u0
    );
}

/// The numbers written in opencv4_stereo.yml / .xml.
// The digits as the file has them (OpenCV's %.16e prints 17 significant digits).
#[allow(clippy::excessive_precision)]
fn opencv_fixture_cameras() -> Vec<CalibCamera> {
    let k = |fx, fy, cx, cy, d: [f64; 5]| Intrinsics {
        fx,
        fy,
        cx,
        cy,
        k1: d[0],
        k2: d[1],
        p1: d[2],
        p2: d[3],
        k3: d[4],
    };
    let r = [
        9.9999939500006296e-01,
        1.0999998854543946e-07,
        -1.0999997708333478e-03,
        1.0999998854543946e-07,
        9.9999998000000212e-01,
        1.9999995833333597e-04,
        1.0999997708333478e-03,
        -1.9999995833333597e-04,
        9.9999937500006508e-01,
    ];
    vec![
        CalibCamera {
            name: "left".into(),
            intrinsics: k(
                1084.2137,
                1084.0528,
                580.0219,
                506.7893,
                [-6.9e-4, 1.95e-3, 1.8e-4, 0.0, 2.5e-5],
            ),
            extrinsics: Extrinsics::default(),
        },
        CalibCamera {
            name: "right".into(),
            intrinsics: k(
                1083.4301,
                1083.2196,
                680.9142,
                505.8107,
                [-8.5e-4, 2.45e-3, 4e-5, -1.2e-5, 0.0],
            ),
            extrinsics: Extrinsics {
                rotation: DMat3::from_cols_array(&r).transpose(),
                translation_mm: DVec3::new(-4.3499, 0.0333, -0.0369),
            },
        },
    ]
}

#[test]
fn opencv_yaml_stereo_with_8_term_distortion() {
    let cal = calib::read(&fixture("opencv4_stereo.yml")).expect("yaml");
    assert_eq!(cal.format, CalibFormat::OpenCvYaml);
    assert_eq!(cal.image_size, Some((1280, 1024)));
    assert_eq!(cal.cameras, opencv_fixture_cameras());
}

#[test]
fn opencv_xml_stereo_with_14_and_5x1_distortion() {
    let cal = calib::read(&fixture("opencv4_stereo.xml")).expect("xml");
    assert_eq!(cal.format, CalibFormat::OpenCvXml);
    assert_eq!(cal.image_size, Some((1280, 1024)));
    assert_eq!(cal.cameras, opencv_fixture_cameras());
}

#[test]
// The digits as the file has them (OpenCV's %.16e prints 17 significant digits).
#[allow(clippy::excessive_precision)]
fn opencv_yaml_monocular_calibrate_camera_output() {
    let cal = calib::read(&fixture("opencv4_mono.yml")).expect("mono");
    assert_eq!(cal.image_size, Some((640, 480)));
    let [c] = &cal.cameras[..] else {
        panic!("{} cameras", cal.cameras.len())
    };
    assert_eq!(c.name, "left");
    assert_eq!(
        (c.intrinsics.fx, c.intrinsics.cx),
        (5.3260127250000005e+02, 3.4216546630859375e+02)
    );
    assert_eq!(
        (c.intrinsics.k1, c.intrinsics.k3),
        (-2.8087375760078431e-01, 1.5438655018806458e-01)
    );
}

#[test]
fn opencv_rational_k4_is_refused_naming_k4() {
    let path = fixture("opencv4_stereo_k4.yml");
    let e = calib::read(&path).expect_err("k4 ≠ 0");
    assert_eq!(e.path, path);
    assert_mentions(
        &e.to_string(),
        &[
            "opencv4_stereo_k4.yml",
            "D2",
            "k4 = 0.0125",
            "k1, k2, p1, p2, k3 only",
        ],
    );
}

/// A calibration with distinct non-trivial values: 4° about a skew axis, k3 ≠ 0.
fn sample() -> Calibration {
    let intr = |s: f64| Intrinsics {
        fx: 1051.6734 * s,
        fy: 1049.2218 * s,
        cx: 612.3456 * s,
        cy: 498.7654 / s,
        k1: -0.123456 * s,
        k2: 0.0456789 / s,
        p1: 0.00123 * s,
        p2: -0.00078 / s,
        k3: -0.0123 * s,
    };
    let axis = DVec3::new(0.3, -0.8, 0.5).normalize();
    Calibration {
        format: CalibFormat::OpenCvYaml,
        image_size: Some((1280, 1024)),
        cameras: vec![
            CalibCamera {
                name: "left".into(),
                intrinsics: intr(1.0),
                extrinsics: Extrinsics::default(),
            },
            CalibCamera {
                name: "right".into(),
                intrinsics: intr(1.01),
                extrinsics: Extrinsics {
                    rotation: rotation_from_vector(axis * 4f64.to_radians()),
                    translation_mm: DVec3::new(-4.4, 0.05, -0.1),
                },
            },
        ],
        warnings: Vec::new(),
    }
}

fn assert_close(a: &Calibration, b: &Calibration, what: &str) {
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * x.abs().max(y.abs());
    assert_eq!(a.image_size, b.image_size, "{what}");
    assert_eq!(a.cameras.len(), b.cameras.len(), "{what}");
    for (ca, cb) in a.cameras.iter().zip(&b.cameras) {
        assert_eq!(ca.name, cb.name, "{what}");
        let (ia, ib) = (ca.intrinsics, cb.intrinsics);
        let pairs = [
            (ia.fx, ib.fx),
            (ia.fy, ib.fy),
            (ia.cx, ib.cx),
            (ia.cy, ib.cy),
            (ia.k1, ib.k1),
            (ia.k2, ib.k2),
            (ia.p1, ib.p1),
            (ia.p2, ib.p2),
            (ia.k3, ib.k3),
        ];
        let ea = ca
            .extrinsics
            .rotation
            .to_cols_array()
            .into_iter()
            .chain(ca.extrinsics.translation_mm.to_array());
        let eb = cb
            .extrinsics
            .rotation
            .to_cols_array()
            .into_iter()
            .chain(cb.extrinsics.translation_mm.to_array());
        for (x, y) in pairs.into_iter().chain(ea.zip(eb)) {
            assert!(close(x, y), "{what}: {x} vs {y}\n{ca:?}\n{cb:?}");
        }
    }
}

#[test]
fn every_writer_round_trips() {
    let dir = scratch("round-trip");
    let cal = sample();
    type Writer = fn(&Calibration, &Path) -> std::io::Result<()>;
    let writers: [(&str, Writer, CalibFormat); 3] = [
        ("rig.yml", calib::write_opencv_yaml, CalibFormat::OpenCvYaml),
        ("rig.xml", calib::write_opencv_xml, CalibFormat::OpenCvXml),
        (
            "camera_calibration.txt",
            calib::write_endovis_text,
            CalibFormat::EndoVisText,
        ),
    ];
    for (name, write, format) in writers {
        let path = dir.join(name);
        write(&cal, &path).expect("write");
        let back = calib::read(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back.format, format);
        assert_close(&cal, &back, name);
        // A monocular calibration too (OpenCV only: camera_calibration.txt is a stereo pair's).
        let mono = Calibration {
            cameras: cal.cameras[..1].to_vec(),
            ..cal.clone()
        };
        if format == CalibFormat::EndoVisText {
            let e = write(&mono, &path).expect_err("EndoVis is stereo");
            assert_mentions(&e.to_string(), &["stereo pair"]);
        } else {
            write(&mono, &path).expect("write mono");
            assert_close(&mono, &calib::read(&path).expect("mono back"), name);
        }
    }
    // scene.json: the cameras array as the scene contract writes it (rotation rows).
    let cameras: Vec<_> = cal
        .cameras
        .iter()
        .map(|c| {
            let i = c.intrinsics;
            let r = c.extrinsics.rotation.transpose().to_cols_array_2d(); // rows
            serde_json::json!({
                "name": c.name, "frames": format!("{}/{{frame:06}}.png", c.name),
                "width": 1280, "height": 1024, "fx": i.fx, "fy": i.fy, "cx": i.cx, "cy": i.cy,
                "k1": i.k1, "k2": i.k2, "p1": i.p1, "p2": i.p2, "k3": i.k3,
                "rotation": r, "translation": c.extrinsics.translation_mm.to_array(),
            })
        })
        .collect();
    let scene = serde_json::json!({
        "format": "endofuse-scene/1", "fps": 30, "frame_count": 1, "cameras": cameras,
        "structures": [{"name": "kidney", "label": 1, "mesh": "meshes/kidney.obj"}],
    });
    let path = dir.join("scene.json");
    std::fs::write(&path, format!("\u{feff}{scene:#}")).expect("write scene");
    let back = calib::read(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back.format, CalibFormat::SceneJson);
    assert_close(&cal, &back, "scene.json");
    let _ = std::fs::remove_dir_all(dir);
}

/// The YAML fixture without the matrix `key` (its five lines and data continuation lines).
fn without_matrix(text: &str, key: &str) -> String {
    let mut out = String::new();
    let mut skipping = false;
    for line in text.lines() {
        if !line.starts_with(' ') {
            skipping = line.starts_with(&format!("{key}:"));
        }
        if !skipping {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

#[test]
fn bad_input_is_refused_with_the_problem_named() {
    let yaml = fixture_text("opencv4_stereo.yml");
    assert_mentions(
        &problem(&without_matrix(&yaml, "T"), "yml"),
        &["missing T", "translation"],
    );
    assert_mentions(
        &problem(&without_matrix(&yaml, "D2"), "yml"),
        &["missing D2", "distortion"],
    );
    let only_left = without_matrix(&without_matrix(&yaml, "K2"), "D2");
    assert_mentions(&problem(&only_left, "yml"), &["missing K2", "has R"]);
    let skewed = yaml.replacen(
        "1.0842137000000000e+03, 0.,",
        "1.0842137000000000e+03, 2.5e-01,",
        1,
    );
    assert_mentions(&problem(&skewed, "yml"), &["K1", "skew 0.25"]);
    let inf = yaml.replacen("1.0842137000000000e+03", ".Inf", 1);
    assert_mentions(
        &problem(&inf, "yml"),
        &["K1", ".Inf", "not a finite number"],
    );
    let short_t = yaml.replacen(
        "T: !!opencv-matrix\n   rows: 3",
        "T: !!opencv-matrix\n   rows: 2",
        1,
    );
    assert_mentions(&problem(&short_t, "yml"), &["T", "2 × 1 = 2", "3 numbers"]);
    let r_2x3 = yaml.replacen(
        "R: !!opencv-matrix\n   rows: 3\n   cols: 3",
        "R: !!opencv-matrix\n   rows: 1\n   cols: 9",
        1,
    );
    assert_mentions(&problem(&r_2x3, "yml"), &["R is 1×9", "3×3"]);
    // R scaled by 1.1: not orthonormal (the writer does not check; the reader must).
    let mut scaled = sample();
    scaled.cameras[1].extrinsics.rotation *= 1.1;
    let dir = scratch("bad");
    let path = dir.join("scaled.xml");
    calib::write_opencv_xml(&scaled, &path).expect("write");
    let e = calib::read(&path).expect_err("R·1.1").to_string();
    assert_mentions(&e, &["scaled.xml", "R is not a rotation", "2.100e-1"]);
    let _ = std::fs::remove_dir_all(dir);
    // Truncated files: a YAML cut inside a matrix, an EndoVis file that stops after the left camera.
    let cut = &yaml[..yaml.find("9.9999998").expect("R data")];
    assert_mentions(&problem(cut, "yml"), &["R", "never closed", "truncated"]);
    let endovis: String = fixture_text(CALIB_A)
        .lines()
        .take(6)
        .map(|l| format!("{l}\n"))
        .collect();
    assert_mentions(
        &problem(&endovis, "txt"),
        &["missing Camera-1-F", "truncated"],
    );
    let xml = fixture_text("opencv4_stereo.xml");
    assert_mentions(&problem(&xml[..xml.len() / 2], "xml"), &["truncated"]);
    // Empty, blank and binary files.
    assert_mentions(&problem("", "yml"), &["empty"]);
    assert_mentions(&problem(" \r\n\n", "txt"), &["empty"]);
    let garbage = [
        0x7f_u8, 0x45, 0x4c, 0x46, 0x02, 0x01, 0x00, 0xff, 0xfe, 0x13,
    ];
    let e = calib::parse(&garbage, Some("yml"))
        .expect_err("binary")
        .to_string();
    assert_mentions(&e, &["not a text file"]);
    assert_mentions(
        &problem("hello world\n", "dat"),
        &["not a calibration file"],
    );
    // A missing file, through `read`.
    let e = calib::read(Path::new("/nonexistent/calib.yml")).expect_err("missing");
    assert_mentions(&e.to_string(), &["/nonexistent/calib.yml", "cannot read"]);
}

#[test]
fn size_mismatch_names_both_sizes() {
    let cal = calib::read(&fixture(CALIB_A)).expect("calib_A");
    let e = cal.cameras(960, 540).expect_err("wrong size").to_string();
    assert_mentions(&e, &["1280×1024", "960×540"]);
    // Without a stated size the plausibility check still applies.
    let mut unsized_cal = cal.clone();
    unsized_cal.image_size = None;
    assert_eq!(unsized_cal.cameras(1280, 1024).expect("fits").len(), 2);
    let e = unsized_cal
        .cameras(8, 8)
        .expect_err("1084 px focal on 8 px")
        .to_string();
    assert_mentions(&e, &["camera left", "8×8"]);
}

#[test]
fn detection_reads_content_not_extension() {
    let yaml = fixture_text("opencv4_stereo.yml");
    let xml = fixture_text("opencv4_stereo.xml");
    let endovis = fixture_text(CALIB_A);
    let want = calib::parse(yaml.as_bytes(), None).expect("yaml");
    for (text, ext) in [
        (format!("\u{feff}{yaml}"), "txt"),
        (yaml.replacen("%YAML:1.0", "%YAML 1.0", 1), "xml"),
        (yaml.replacen("%YAML:1.0\n---\n", "", 1), "json"),
        (yaml.replace('\n', "\r\n"), "yml"),
    ] {
        assert_eq!(
            calib::parse(text.as_bytes(), Some(ext))
                .expect("yaml variant")
                .cameras,
            want.cameras
        );
    }
    assert_eq!(
        calib::parse(xml.as_bytes(), Some("yml"))
            .expect("xml")
            .format,
        CalibFormat::OpenCvXml
    );
    let bom = format!("\u{feff}{endovis}");
    assert_eq!(
        calib::parse(bom.as_bytes(), Some("yml"))
            .expect("endovis")
            .format,
        CalibFormat::EndoVisText
    );
}

#[test]
fn no_panic_for_any_truncation() {
    for (name, ext) in [
        ("opencv4_stereo.yml", "yml"),
        ("opencv4_mono.yml", "yml"),
        ("opencv4_stereo.xml", "xml"),
        (CALIB_D, "txt"),
    ] {
        let bytes = std::fs::read(fixture(name)).expect("fixture");
        let mut refused = 0;
        for n in 0..=bytes.len() {
            // Returning at all (Ok or Err) is the check: a panic fails the test.
            refused += usize::from(calib::parse(&bytes[..n], Some(ext)).is_err());
        }
        assert!(calib::parse(&bytes, Some(ext)).is_ok(), "{name}");
        // Most prefixes lack a key or close no bracket; only cuts in keys nobody reads may pass.
        assert!(
            refused > bytes.len() / 2,
            "{name}: only {refused} of {} prefixes refused",
            bytes.len()
        );
    }
}

#[test]
fn no_panic_for_any_single_byte_change() {
    // Characters that steer the parsers (brackets, colons, line breaks, indentation, tags).
    let swaps = *b"[]{}:\n -<>/\"#0.e\xff";
    for name in ["opencv4_stereo.yml", "opencv4_stereo.xml", CALIB_A] {
        let bytes = std::fs::read(fixture(name)).expect("fixture");
        for i in 0..bytes.len() {
            for &b in &swaps {
                let mut changed = bytes.clone();
                changed[i] = b;
                let _ = calib::parse(&changed, Some("yml"));
            }
        }
    }
}
