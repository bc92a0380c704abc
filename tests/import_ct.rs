//! `import-ct` (CONTRACT §4) on a real KiTS19 case (cropped fixture) and on synthetic label
//! volumes with known geometry written by hand in other NIfTI flavours (qform with a rotation,
//! big-endian int16, float32 with pixdim only, uncompressed): which kidney, which tumours are
//! visible or hidden and why, volumes against the voxels and the analytic shapes, world
//! positions through each transform, closed outward manifold meshes, the catalog, and every bad
//! input with exit 2 and one line naming the file.

mod common;

use endofuse::ctimport::volume::{LabelVolume, WorldTransform, WriteTransform, WriteType, write};
use endofuse::geometry::mesh_io::load_mesh;
use glam::{DMat3, DVec3};
use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/ct/kits19_case_00010_cropped.nii.gz")
}

/// A scratch folder that exists.
fn scratch(tag: &str) -> PathBuf {
    let d = common::scratch_dir(tag);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn import(args: &[&std::ffi::OsStr]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_endofuse"))
        .arg("import-ct")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

fn import_ok(labels: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args: Vec<&std::ffi::OsStr> =
        vec![labels.as_os_str(), "--out".as_ref(), out.as_os_str()];
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    let (code, stdout, stderr) = import(&args);
    assert_eq!(code, 0, "import-ct failed: {stderr}");
    assert!(stdout.contains("kidney"), "{stdout}");
    common::read_json(&out.join("ct.json"))
}

fn structure<'a>(ct: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    ct["structures"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap_or_else(|| panic!("no structure {name} in {ct}"))
}

/// Every written mesh is closed, outward (positive signed volume), free of self-intersections,
/// with a catalog of the same vertex count.
fn check_meshes(out: &Path, ct: &serde_json::Value) {
    for s in ct["structures"].as_array().unwrap() {
        let name = s["name"].as_str().unwrap();
        let mesh = load_mesh(&out.join(format!("meshes/{name}.obj"))).unwrap();
        let topo = endofuse::ctimport::surface::topology(&mesh);
        assert!(topo.is_closed_manifold(), "{name}: {topo:?}");
        assert_eq!(
            endofuse::ctimport::surface::self_intersections(&mesh),
            0,
            "{name}"
        );
        assert!(mesh.signed_volume() > 0.0, "{name}: normals point inwards");
        let err = s["volume_error"].as_f64().unwrap();
        assert!(
            err.abs() < 0.03,
            "{name}: mesh volume off by {:.2} %",
            100.0 * err
        );
        let cat: Vec<_> = std::fs::read_dir(out.join(format!("meshes/{name}_catalog")))
            .unwrap()
            .collect();
        assert_eq!(cat.len(), endofuse::ctimport::DEFAULT_CATALOG_SIZE);
        let first = load_mesh(&cat[0].as_ref().unwrap().path()).unwrap();
        assert_eq!(first.vertices.len(), mesh.vertices.len());
    }
}

#[test]
fn a_real_kits19_case_becomes_a_kidney_and_an_exophytic_tumour() {
    let out = common::scratch_dir("ct-kits10");
    let ct = import_ok(&fixture(), &out, &[]);
    assert_eq!(ct["kidneys_found"], 2, "{ct}");
    assert_eq!(ct["side"], "left");
    let kidney = structure(&ct, "kidney");
    let tumour = structure(&ct, "tumour_exo");
    assert_eq!(tumour["visible"], true);
    // The tumour bulges out: about two thirds of its boundary faces background (KiTS SOURCE.md
    // measured 0.72 with its own rough count).
    let share = tumour["exposure"]["exposed_share"].as_f64().unwrap();
    assert!((0.5..0.8).contains(&share), "{share}");
    // KiTS's case_00010 tumour is 15.0 ml (kits.json); the kidney ~166 ml.
    let tv = tumour["voxel_volume_mm3"].as_f64().unwrap();
    assert!((tv - 15015.0).abs() < 20.0, "{tv}");
    assert!(kidney["vertices"].as_u64().unwrap() <= 5200);
    check_meshes(&out, &ct);
    // The output is a scene's structures, ready to load: the joint model builds from them.
    let entries: serde_json::Value = common::read_json(&out.join("structures.json"));
    assert_eq!(entries.as_array().unwrap().len(), 2);
    assert_eq!(entries[0]["catalog"], "meshes/kidney_catalog");
}

/// Two ellipsoid kidneys at x = ±70 mm; the right one holds a hidden tumour at its centre and
/// carries a smaller visible one on its surface. Voxel (i, j, k) ↦ world through `linear`.
fn phantom(linear: DMat3, offset: DVec3) -> (LabelVolume, DVec3, DVec3) {
    let dims = [96, 64, 48];
    let mut labels = vec![0u16; dims.iter().product()];
    // Kidney semi-axes (mm) and centres, in world coordinates.
    let axes = DVec3::new(25.0, 20.0, 30.0);
    let right = DVec3::new(45.0, 0.0, 0.0);
    let left = DVec3::new(-45.0, 0.0, 0.0);
    let endo_centre = right + DVec3::new(0.0, 0.0, 5.0);
    let exo_centre = right + DVec3::new(0.0, 20.0, 0.0);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let w = linear * DVec3::new(i as f64, j as f64, k as f64) + offset;
                let inside = |c: DVec3| ((w - c) / axes).length_squared() <= 1.0;
                let tumour = (w - exo_centre).length() <= 9.0 || (w - endo_centre).length() <= 8.0;
                let v = if tumour {
                    2
                } else if inside(right) || inside(left) {
                    1
                } else {
                    0
                };
                labels[i + dims[0] * (j + dims[1] * k)] = v;
            }
        }
    }
    (
        LabelVolume {
            dims,
            labels,
            linear,
            offset_mm: offset,
            transform: WorldTransform::Sform,
            datatype: "uint8".into(),
        },
        endo_centre,
        exo_centre,
    )
}

#[test]
fn synthetic_volumes_in_every_nifti_flavour_give_the_same_anatomy() {
    // A grid whose axes are permuted and flipped (i → −x, j → z, k → y) as a scanner in
    // another orientation would write it: a quaternion can say that.
    let rot = DMat3::from_cols(DVec3::NEG_X, DVec3::Z, DVec3::Y);
    let spacing = [1.6f32, 1.8, 2.0];
    let linear = rot * DMat3::from_diagonal(DVec3::new(1.6, 1.8, 2.0));
    let offset = DVec3::new(76.0, -47.0, -56.0);
    let (vol, endo, exo) = phantom(linear, offset);
    let q = glam::DQuat::from_mat3(&rot);
    let q = if q.w < 0.0 { -q } else { q };
    let dir = scratch("ct-flavours");
    let flavours: Vec<(&str, WriteTransform, WriteType, bool)> = vec![
        (
            "sform_u8.nii.gz",
            WriteTransform::Sform,
            WriteType::Uint8,
            false,
        ),
        (
            "qform_i16_big.nii",
            WriteTransform::Qform {
                quaternion_bcd: [q.x as f32, q.y as f32, q.z as f32],
                qfac: 1.0,
                spacing_mm: spacing,
                offset_mm: offset.to_array().map(|v| v as f32),
            },
            WriteType::Int16,
            true,
        ),
        (
            "sform_f32.nii.gz",
            WriteTransform::Sform,
            WriteType::Float32,
            false,
        ),
        (
            "sform_u16.nii",
            WriteTransform::Sform,
            WriteType::Uint16,
            true,
        ),
    ];
    let voxel_mm3 = 1.6 * 1.8 * 2.0;
    for (name, transform, ty, big) in flavours {
        let path = dir.join(name);
        write(&path, &vol, transform, ty, big).unwrap();
        let out = dir.join(format!("out-{name}"));
        let ct = import_ok(&path, &out, &[]);
        assert_eq!(ct["side"], "right", "{name}");
        assert_eq!(ct["kidneys_found"], 2, "{name}");
        let kidney = structure(&ct, "kidney");
        let endo_s = structure(&ct, "tumour_endo");
        let exo_s = structure(&ct, "tumour_exo");
        assert_eq!(endo_s["visible"], false, "{name}");
        assert_eq!(exo_s["visible"], true, "{name}");
        assert_eq!(endo_s["exposure"]["exposed_share"].as_f64().unwrap(), 0.0);
        // Volumes against the analytic spheres (discretisation allows a few per cent).
        let sphere = |r: f64| 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
        let ev = endo_s["voxel_volume_mm3"].as_f64().unwrap();
        assert!((ev / sphere(8.0) - 1.0).abs() < 0.08, "{name}: endo {ev}");
        assert!(
            kidney["voxels"].as_f64().unwrap() * voxel_mm3 > 0.8 * sphere(1.0) * 25.0 * 20.0 * 30.0
        );
        check_meshes(&out, &ct);
        // World positions: meshes are re-centred on the kidney's vertex mean, which ct.json
        // records; adding it back gives the tumours where the phantom put them.
        let centre = DVec3::from_array(
            serde_json::from_value::<[f64; 3]>(ct["recentred_by_mm"].clone()).unwrap(),
        );
        for (s, truth) in [("tumour_endo", endo), ("tumour_exo", exo)] {
            let m = load_mesh(&out.join(format!("meshes/{s}.obj"))).unwrap();
            let c = m.vertex_mean() + centre;
            assert!(
                (c - truth).length() < 1.5,
                "{name}: {s} at {c}, expected {truth}"
            );
        }
        assert!(
            (centre - DVec3::new(45.0, 0.0, 0.0)).length() < 3.0,
            "{name}: kidney at {centre}"
        );
    }
}

#[test]
fn side_and_labels_options() {
    let (vol, _, _) = phantom(
        DMat3::from_diagonal(DVec3::splat(2.0)),
        DVec3::new(-96.0, -64.0, -48.0),
    );
    let dir = scratch("ct-side");
    let path = dir.join("v.nii.gz");
    write(&path, &vol, WriteTransform::Sform, WriteType::Uint8, false).unwrap();
    // --side right is the kidney auto picks (its tumours), --side left the other one, which
    // has none: kidney only, and ct.json says so.
    let ct = import_ok(&path, &dir.join("right"), &["--side", "right"]);
    assert_eq!(ct["side"], "right");
    assert_eq!(ct["structures"].as_array().unwrap().len(), 3);
    let ct = import_ok(&path, &dir.join("left"), &["--side", "left"]);
    assert_eq!(ct["side"], "left");
    assert_eq!(ct["structures"].as_array().unwrap().len(), 1);
    assert!(
        ct["notes"]
            .to_string()
            .contains("no tumour in the chosen kidney"),
        "{ct}"
    );
    assert!(
        ct["notes"]
            .to_string()
            .contains("outside the chosen kidney"),
        "{ct}"
    );

    // Other label numbers: without --labels the KiTS default finds no kidney.
    let relabelled = LabelVolume {
        labels: vol.labels.iter().map(|&l| [0, 5, 7][l as usize]).collect(),
        ..vol.clone()
    };
    let p57 = dir.join("v57.nii");
    write(
        &p57,
        &relabelled,
        WriteTransform::Sform,
        WriteType::Uint8,
        false,
    )
    .unwrap();
    let o = dir.join("x");
    expect_bad(
        &[p57.as_os_str(), "--out".as_ref(), o.as_os_str()],
        "v57.nii",
        "no voxel has the kidney label 1 (labels present: 5, 7)",
    );
    let ct = import_ok(
        &p57,
        &dir.join("relabel"),
        &["--labels", "kidney=5,tumor=7"],
    );
    assert_eq!(ct["structures"].as_array().unwrap().len(), 3);
    expect_bad(
        &[
            p57.as_os_str(),
            "--out".as_ref(),
            o.as_os_str(),
            "--labels".as_ref(),
            "liver=3".as_ref(),
        ],
        "--labels",
        "unknown structure",
    );

    // One kidney only (the volume cropped to the right half): its side is unknown, and
    // either --side takes it.
    let half = LabelVolume {
        labels: (0..vol.labels.len())
            .map(|n| {
                if n % vol.dims[0] >= vol.dims[0] / 2 {
                    vol.labels[n]
                } else {
                    0
                }
            })
            .collect(),
        ..vol.clone()
    };
    let p1 = dir.join("one.nii.gz");
    write(&p1, &half, WriteTransform::Sform, WriteType::Uint8, false).unwrap();
    let ct = import_ok(&p1, &dir.join("one"), &["--side", "left"]);
    assert_eq!(ct["side"], "unknown");
    assert_eq!(ct["kidneys_found"], 1);
    assert_eq!(ct["structures"].as_array().unwrap().len(), 3);
}

fn expect_bad(args: &[&std::ffi::OsStr], file: &str, words: &str) {
    let (code, _, stderr) = import(args);
    assert_eq!(code, 2, "expected exit 2 ({words}): {stderr}");
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("endofuse:"))
        .collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(lines[0].contains(file), "should name {file}: {}", lines[0]);
    assert!(
        lines[0].to_lowercase().contains(words),
        "should say '{words}': {}",
        lines[0]
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn bad_label_volumes_are_refused_with_one_line() {
    let dir = scratch("ct-bad");
    let good = std::fs::read(fixture()).unwrap();
    let out = dir.join("out");
    let o = out.as_os_str();
    let case = |name: &str, bytes: &[u8]| {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let truncated = case("truncated.nii.gz", &good[..good.len() / 2]);
    expect_bad(
        &[truncated.as_os_str(), "--out".as_ref(), o],
        "truncated.nii.gz",
        "cannot read nifti",
    );
    let not_gz = case("plain.nii.gz", b"this is not gzip at all, just text");
    expect_bad(
        &[not_gz.as_os_str(), "--out".as_ref(), o],
        "plain.nii.gz",
        "not gzip",
    );
    let garbage = case("garbage.nii", &[7u8; 600]);
    expect_bad(
        &[garbage.as_os_str(), "--out".as_ref(), o],
        "garbage.nii",
        "cannot read nifti",
    );
    let missing = dir.join("missing.nii.gz");
    expect_bad(
        &[missing.as_os_str(), "--out".as_ref(), o],
        "missing.nii.gz",
        "cannot read",
    );

    let vol = |f: &dyn Fn(usize) -> u16| LabelVolume {
        dims: [20, 20, 20],
        labels: (0..8000).map(f).collect(),
        linear: DMat3::IDENTITY,
        offset_mm: DVec3::ZERO,
        transform: WorldTransform::Sform,
        datatype: String::new(),
    };
    let empty = dir.join("empty.nii.gz");
    write(
        &empty,
        &vol(&|_| 0),
        WriteTransform::Sform,
        WriteType::Uint8,
        false,
    )
    .unwrap();
    expect_bad(
        &[empty.as_os_str(), "--out".as_ref(), o],
        "empty.nii.gz",
        "all background",
    );
    let nokidney = dir.join("nokidney.nii.gz");
    write(
        &nokidney,
        &vol(&|n| if n > 4000 { 5 } else { 0 }),
        WriteTransform::Sform,
        WriteType::Uint8,
        false,
    )
    .unwrap();
    expect_bad(
        &[nokidney.as_os_str(), "--out".as_ref(), o],
        "nokidney.nii.gz",
        "no voxel has the kidney label 1",
    );
    // A float volume that is an image, not labels.
    let mut raw = Vec::new();
    let f32_path = dir.join("image.nii");
    write(
        &f32_path,
        &vol(&|n| (n % 7) as u16),
        WriteTransform::Sform,
        WriteType::Float32,
        false,
    )
    .unwrap();
    raw.extend(std::fs::read(&f32_path).unwrap());
    raw[352..356].copy_from_slice(&0.5f32.to_le_bytes());
    std::fs::write(&f32_path, &raw).unwrap();
    expect_bad(
        &[f32_path.as_os_str(), "--out".as_ref(), o],
        "image.nii",
        "not whole non-negative labels",
    );
    // An unsupported datatype (complex64) in an otherwise valid header.
    let mut cplx = std::fs::read(&f32_path).unwrap();
    cplx[70..72].copy_from_slice(&32i16.to_le_bytes());
    cplx[72..74].copy_from_slice(&64i16.to_le_bytes());
    cplx.extend(vec![0u8; 8000 * 4]);
    let cplx_path = case("complex.nii", &cplx);
    expect_bad(
        &[cplx_path.as_os_str(), "--out".as_ref(), o],
        "complex.nii",
        "datatype",
    );

    // An output folder with something in it is kept, with or without --force, unless it is an
    // earlier output; a folder holding the input is never replaced.
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "mine").unwrap();
    let f = fixture();
    expect_bad(&[f.as_os_str(), "--out".as_ref(), o], "out", "not empty");
    expect_bad(
        &[f.as_os_str(), "--out".as_ref(), o, "--force".as_ref()],
        "out",
        "not an earlier endofuse output",
    );
    assert!(out.join("keep.txt").exists());
    let earlier = dir.join("earlier");
    import_ok(&f, &earlier, &[]);
    let ct = import_ok(&f, &earlier, &["--force"]);
    assert_eq!(ct["structures"].as_array().unwrap().len(), 2);
    let inside = earlier.join("labels.nii.gz");
    std::fs::copy(&f, &inside).unwrap();
    expect_bad(
        &[
            inside.as_os_str(),
            "--out".as_ref(),
            earlier.as_os_str(),
            "--force".as_ref(),
        ],
        "earlier",
        "holds an input",
    );
    assert!(inside.exists() && earlier.join("ct.json").exists());
    // A scene folder is never import-ct's to replace (its frames and seeds went with it).
    let scene = dir.join("a-scene");
    common::copy_dir(&common::fixture(), &scene);
    expect_bad(
        &[
            f.as_os_str(),
            "--out".as_ref(),
            scene.as_os_str(),
            "--force".as_ref(),
        ],
        "a-scene",
        "holds a scene",
    );
    assert!(scene.join("seeds").is_dir() && scene.join("scene.json").is_file());
    // Nothing half-written is left beside it.
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("partial"))
        .collect();
    assert!(leftovers.is_empty());
}
