//! A corpus of malformed inputs (issue 17 §2), beside the scene cases of `cli_bad_input.rs`:
//! scene.json files no reader should take, broken meshes (OBJ, STL, PLY), frames and seed images
//! that are truncated, of the wrong size or depth, or not images at all, calibration files given
//! to `new-scene`, NIfTI label volumes given to `import-ct`, and video files that are no videos
//! (with or without FFmpeg on the machine). Every case runs the binary once and checks what
//! CONTRACT §1 promises for bad input: exit code 2; one line on stderr besides progress, naming
//! the offending file and saying the problem; no panic; and, for a command that takes `--out`,
//! nothing written there (the folder absent or empty, and no staging folder left beside it).
//! Each case builds its input in a scratch folder and is checked before any real work starts,
//! so the whole corpus runs in seconds.

mod common;

use common::{edit_json, fixture};
use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// One run of the binary: its arguments and the environment variables it needs.
struct Run {
    args: Vec<OsString>,
    env: Vec<(&'static str, OsString)>,
}

impl Run {
    fn new<I, S>(args: I) -> Run
    where
        I: IntoIterator<Item = S>,
        S: Into<OsString>,
    {
        Run {
            args: args.into_iter().map(Into::into).collect(),
            env: Vec::new(),
        }
    }

    fn env(mut self, key: &'static str, value: impl Into<OsString>) -> Run {
        self.env.push((key, value.into()));
        self
    }
}

/// A malformed input: `make` builds it under a scratch folder and says how to run the binary
/// on it; the error line must name `file` (a path suffix) and contain one of `says`.
struct Case {
    name: &'static str,
    file: &'static str,
    says: &'static [&'static str],
    make: Box<dyn FnOnce(&Path) -> Run>,
}

fn case(
    name: &'static str,
    file: &'static str,
    says: &'static [&'static str],
    make: impl FnOnce(&Path) -> Run + 'static,
) -> Case {
    Case {
        name,
        file,
        says,
        make: Box::new(make),
    }
}

/// Commands whose progress lines (`info: …`, `import-ct: …`) are not the error line.
const PROGRESS: [&str; 6] = [
    "info",
    "classify",
    "track",
    "import-ct",
    "new-scene",
    "synth",
];

/// The lines of stderr that are neither progress nor blank (a progress line rewritten in place
/// with `\r` counts as several lines).
fn error_lines(stderr: &str) -> Vec<String> {
    stderr
        .split(['\n', '\r'])
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .filter(|l| {
            !l.split_once(": ")
                .is_some_and(|(head, _)| PROGRESS.contains(&head))
        })
        .map(str::to_string)
        .collect()
}

/// Everything under `dir`, relative (for the message when something was written).
fn listing(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            found.push(p.strip_prefix(dir).unwrap_or(&p).display().to_string());
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
    found.sort();
    found
}

/// Runs one case; `Err` says everything that was wrong with what the binary did.
fn check(case: Case) -> Result<(), String> {
    let root = common::scratch_dir(&format!("malformed-{}", case.name));
    std::fs::create_dir_all(&root).unwrap();
    let run = (case.make)(&root);
    let out_dir = run
        .args
        .windows(2)
        .find(|w| w[0] == "--out")
        .map(|w| PathBuf::from(&w[1]));
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_endofuse"));
    cmd.args(&run.args).env_remove("RUST_LOG");
    for (k, v) in &run.env {
        cmd.env(k, v);
    }
    let output = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr).to_string();
    let mut problems = Vec::new();
    if output.status.code() != Some(2) {
        problems.push(format!("exit {:?}, expected 2", output.status.code()));
    }
    if stderr.contains("panicked") || stderr.contains("internal error") {
        problems.push("a panic".to_string());
    }
    let lines = error_lines(&stderr);
    match lines.as_slice() {
        [line] => {
            let normalised = line.replace('\\', "/");
            if !line.starts_with("endofuse: ") {
                problems.push("the error line does not start with 'endofuse: '".into());
            }
            if !normalised.contains(case.file) {
                problems.push(format!("the error line does not name {}", case.file));
            }
            let lower = line.to_lowercase();
            if !case.says.iter().any(|w| lower.contains(&w.to_lowercase())) {
                problems.push(format!("the error line says none of {:?}", case.says));
            }
        }
        _ => problems.push(format!(
            "expected one error line besides progress, got {}",
            lines.len()
        )),
    }
    if let Some(out) = &out_dir {
        let written = listing(out);
        if !written.is_empty() {
            problems.push(format!("--out holds {written:?}"));
        }
        let name = out.file_name().unwrap().to_string_lossy().to_string();
        let staged: Vec<String> = std::fs::read_dir(out.parent().unwrap())
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().to_string())
            .filter(|f| f.starts_with(&format!(".{name}.")))
            .collect();
        if !staged.is_empty() {
            problems.push(format!("staging left beside --out: {staged:?}"));
        }
    }
    if problems.is_empty() {
        let _ = std::fs::remove_dir_all(&root);
        return Ok(());
    }
    let args: Vec<String> = run
        .args
        .iter()
        .map(|a| a.to_string_lossy().to_string())
        .collect();
    Err(format!(
        "{}: {}\n    endofuse {}\n    stderr: {}",
        case.name,
        problems.join("; "),
        args.join(" "),
        stderr.trim_end()
    ))
}

/// Runs every case of a table and fails with all the cases that went wrong.
fn check_all(cases: Vec<Case>) {
    let count = cases.len();
    let failures: Vec<String> = cases.into_iter().filter_map(|c| check(c).err()).collect();
    assert!(
        failures.is_empty(),
        "{} of {count} malformed inputs were not refused as CONTRACT §1 says:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

// ---- building inputs ----------------------------------------------------------------------

/// A copy of the fixture scene at `root/scene`, changed by `edit`.
fn scene(root: &Path, edit: impl FnOnce(&Path)) -> PathBuf {
    let dir = root.join("scene");
    common::copy_dir(&fixture(), &dir);
    edit(&dir);
    dir
}

fn edit_bytes(path: &Path, f: impl FnOnce(Vec<u8>) -> Vec<u8>) {
    let bytes = std::fs::read(path).unwrap();
    std::fs::write(path, f(bytes)).unwrap();
}

/// Replaces the first `from` in a text file, which must hold it.
fn replace(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(from), "{} lacks {from:?}", path.display());
    std::fs::write(path, text.replacen(from, to, 1)).unwrap();
}

fn write(path: &Path, bytes: impl AsRef<[u8]>) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

fn info(scene: &Path) -> Run {
    Run::new([OsString::from("info"), scene.into()])
}

/// `classify SCENE --out DIR`, the folder beside the scene.
fn classify(scene: &Path) -> Run {
    let out = scene.parent().unwrap().join("out");
    Run::new([
        OsString::from("classify"),
        scene.into(),
        "--out".into(),
        out.into(),
    ])
}

/// `track SCENE --out DIR --mode R`, the folder beside the scene.
fn track(scene: &Path) -> Run {
    let out = scene.parent().unwrap().join("out");
    Run::new([
        OsString::from("track"),
        scene.into(),
        "--out".into(),
        out.into(),
        "--mode".into(),
        "R".into(),
    ])
}

/// `new-scene --out root/out` with the fixture's calibration (its scene.json) and meshes, and
/// the given views.
fn fixture_anatomy(root: &Path, views: Vec<OsString>) -> Run {
    let f = fixture();
    new_scene_with(
        root,
        &f.join("scene.json"),
        ["--meshes".into(), f.join("meshes").into()],
        views,
    )
}

/// `new-scene` with the fixture's frames as the two views and its meshes as the anatomy.
fn new_scene(root: &Path, calib: &Path) -> Run {
    let f = fixture();
    new_scene_with(
        root,
        calib,
        ["--meshes".into(), f.join("meshes").into()],
        views(&f.join("left"), &f.join("right")),
    )
}

/// `new-scene --out root/out --calib CALIB ANATOMY VIEWS`.
fn new_scene_with(root: &Path, calib: &Path, anatomy: [OsString; 2], views: Vec<OsString>) -> Run {
    let mut args: Vec<OsString> = vec![
        "new-scene".into(),
        "--out".into(),
        root.join("out").into(),
        "--calib".into(),
        calib.into(),
    ];
    args.extend(anatomy);
    args.extend(views);
    Run::new(args)
}

/// `--view =LEFT --view =RIGHT`: unnamed views in the calibration's camera order.
fn views(left: &Path, right: &Path) -> Vec<OsString> {
    let view = |p: &Path| {
        let mut v = OsString::from("=");
        v.push(p);
        v
    };
    vec!["--view".into(), view(left), "--view".into(), view(right)]
}

fn import_ct(root: &Path, labels: &Path) -> Run {
    Run::new([
        OsString::from("import-ct"),
        labels.into(),
        "--out".into(),
        root.join("out").into(),
    ])
}

fn calib_fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/calib")
        .join(name)
}

fn ct_fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/ct/kits19_case_00010_cropped.nii.gz")
}

/// A binary STL whose header claims `claimed` triangles and whose body holds `written`.
fn binary_stl(claimed: u32, written: usize) -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b.extend(claimed.to_le_bytes());
    for t in 0..written {
        let t = t as f32;
        for v in [0.0, 0.0, 0.0, t, 0.0, 0.0, t + 1.0, 1.0, 0.0, t, 1.0, 1.0] {
            b.extend(v.to_le_bytes());
        }
        b.extend([0u8; 2]);
    }
    b
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

/// A NIfTI-1 single file (.nii): the 348-byte header (dims, datatype, unit pixdim, no
/// sform/qform), 4 bytes of no extension, then `data`.
fn nifti(dims: &[i16], datatype: i16, bitpix: i16, data: &[u8]) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    let mut dim = [1i16; 8];
    dim[0] = dims.len() as i16;
    dim[1..=dims.len()].copy_from_slice(dims);
    for (i, d) in dim.iter().enumerate() {
        h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&datatype.to_le_bytes());
    h[72..74].copy_from_slice(&bitpix.to_le_bytes());
    for i in 0..8 {
        h[76 + 4 * i..80 + 4 * i].copy_from_slice(&1.0f32.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352.0f32.to_le_bytes());
    h[112..116].copy_from_slice(&1.0f32.to_le_bytes());
    h[344..348].copy_from_slice(b"n+1\0");
    h.extend_from_slice(data);
    h
}

const NIFTI_UINT8: (i16, i16) = (2, 8);
const NIFTI_FLOAT32: (i16, i16) = (16, 32);
const NIFTI_FLOAT64: (i16, i16) = (64, 64);
const NIFTI_RGB24: (i16, i16) = (128, 24);

fn png_chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut crc = flate2::Crc::new();
    crc.update(kind);
    crc.update(data);
    let mut c = (data.len() as u32).to_be_bytes().to_vec();
    c.extend(kind);
    c.extend(data);
    c.extend(crc.sum().to_be_bytes());
    c
}

/// A PNG whose header says 100000×100000 RGB, with a few bytes of pixel data.
fn png_claiming_huge_size() -> Vec<u8> {
    let mut ihdr = 100_000u32.to_be_bytes().to_vec();
    ihdr.extend(100_000u32.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    z.write_all(&[0u8; 64]).unwrap();
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(png_chunk(b"IHDR", &ihdr));
    png.extend(png_chunk(b"IDAT", &z.finish().unwrap()));
    png.extend(png_chunk(b"IEND", &[]));
    png
}

fn save_grey(path: &Path, w: u32, h: u32, value: u8) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::GrayImage::from_pixel(w, h, image::Luma([value]))
        .save(path)
        .unwrap();
}

fn save_rgb(path: &Path, w: u32, h: u32) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_pixel(w, h, image::Rgb([120, 60, 50]))
        .save(path)
        .unwrap();
}

/// A 16-bit grey PNG of the camera's size.
fn save_grey16(path: &Path) {
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(64, 48, image::Luma([255]))
        .save(path)
        .unwrap();
}

/// What a video error may say: with FFmpeg installed, what ffprobe found; without, what to
/// install. Either way the file is named and the exit code is 2.
const NOT_A_VIDEO: &[&str] = &[
    "install ffmpeg",
    "not a readable video",
    "no video stream",
    "has no frames",
];

// ---- the corpus ---------------------------------------------------------------------------

/// scene.json itself: values and encodings `cli_bad_input.rs` does not try.
#[test]
fn malformed_scene_json() {
    check_all(vec![
        case(
            "top-level-array",
            "scene/scene.json",
            &["malformed scene", "is an array, not an object"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| *v = serde_json::json!([1, 2, 3]))
                }))
            },
        ),
        case(
            "fx-nan-string",
            "scene/scene.json",
            &["malformed scene"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| v["cameras"][0]["fx"] = "NaN".into())
                }))
            },
        ),
        case(
            "fy-infinity-string",
            "scene/scene.json",
            &["malformed scene"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| v["cameras"][1]["fy"] = "Infinity".into())
                }))
            },
        ),
        case(
            "bare-nan-token",
            "scene/scene.json",
            &["malformed scene"],
            |r| {
                info(&scene(r, |s| {
                    replace(&s.join("scene.json"), "\"k1\": 0.0", "\"k1\": NaN")
                }))
            },
        ),
        case(
            "huge-frame-count",
            "scene/left/000002.png",
            &["missing frame"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| v["frame_count"] = 1_000_000_000_000_000u64.into())
                }))
            },
        ),
        case(
            "frame-count-past-u64",
            "scene/scene.json",
            &["malformed scene"],
            |r| {
                info(&scene(r, |s| {
                    replace(
                        &s.join("scene.json"),
                        "\"frame_count\": 2",
                        "\"frame_count\": 18446744073709551616",
                    )
                }))
            },
        ),
        case(
            "fps-zero",
            "scene/scene.json",
            &["fps must be positive"],
            |r| info(&scene(r, |s| edit_json(s, |v| v["fps"] = 0.into()))),
        ),
        case(
            "empty-file",
            "scene/scene.json",
            &["malformed scene"],
            |r| info(&scene(r, |s| write(&s.join("scene.json"), ""))),
        ),
        case("utf16", "scene/scene.json", &["utf-8"], |r| {
            info(&scene(r, |s| {
                edit_bytes(&s.join("scene.json"), |b| {
                    let text = String::from_utf8(b).unwrap();
                    let mut u = vec![0xff, 0xfe];
                    u.extend(text.encode_utf16().flat_map(u16::to_le_bytes));
                    u
                })
            }))
        }),
        case(
            "two-byte-order-marks",
            "scene/scene.json",
            &["malformed scene"],
            |r| {
                info(&scene(r, |s| {
                    edit_bytes(&s.join("scene.json"), |b| {
                        [b"\xef\xbb\xbf\xef\xbb\xbf".as_slice(), &b].concat()
                    })
                }))
            },
        ),
        case(
            "duplicate-key",
            "scene/scene.json",
            &["duplicate field `fx`"],
            |r| {
                info(&scene(r, |s| {
                    replace(
                        &s.join("scene.json"),
                        "\"fx\": 60.0",
                        "\"fx\": 60.0, \"fx\": 61.0",
                    )
                }))
            },
        ),
        case(
            "trailing-garbage",
            "scene/scene.json",
            &["trailing characters"],
            |r| {
                info(&scene(r, |s| {
                    edit_bytes(&s.join("scene.json"), |b| {
                        [b, b"\n}garbage".to_vec()].concat()
                    })
                }))
            },
        ),
        case("no-cameras", "scene/scene.json", &["no cameras"], |r| {
            info(&scene(r, |s| {
                edit_json(s, |v| v["cameras"] = serde_json::json!([]))
            }))
        }),
        case(
            "camera-name-path",
            "scene/scene.json",
            &["'../right'"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| v["cameras"][1]["name"] = "../right".into())
                }))
            },
        ),
        case(
            "duplicate-camera",
            "scene/scene.json",
            &["two cameras are named 'left'"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| v["cameras"][1]["name"] = "left".into())
                }))
            },
        ),
        case(
            "height-100000",
            "scene/scene.json",
            &["at most 16384"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| v["cameras"][0]["height"] = 100_000.into())
                }))
            },
        ),
        case("mirror-pose", "scene/scene.json", &["determinant"], |r| {
            info(&scene(r, |s| {
                edit_json(s, |v| {
                    v["initial_pose"]["affine"] =
                        serde_json::json!([-1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 150])
                })
            }))
        }),
        case(
            "nothing-visible",
            "scene/scene.json",
            &["no visible structure"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| {
                        for st in v["structures"].as_array_mut().unwrap() {
                            st["visible"] = false.into();
                        }
                    })
                }))
            },
        ),
        case(
            "seeds-placeholder",
            "scene/scene.json",
            &["unknown placeholder"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| v["seeds"] = "seeds/{cam}/{frame:06}.png".into())
                }))
            },
        ),
        case(
            "missing-trajectory",
            "scene/gt/trajectory.json",
            &["cannot read ground-truth trajectory"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| {
                        v["ground_truth"]["trajectory"] = "gt/trajectory.json".into()
                    })
                }))
            },
        ),
    ]);
}

/// Meshes a scene names: OBJ, STL and PLY that are truncated, lie about their size, index
/// past their vertices, hold NaN, are empty or are not what their extension says; and a
/// meshes folder given to `new-scene`.
#[test]
fn malformed_meshes() {
    let stl = "scene/meshes/tumour.stl";
    let ply = "scene/meshes/hidden.ply";
    let obj = "scene/meshes/kidney.obj";
    check_all(vec![
        case("stl-truncated", stl, &["binary STL truncated"], |r| {
            info(&scene(r, |s| {
                write(
                    &s.join("meshes/tumour.stl"),
                    &binary_stl(8, 8)[..84 + 50 * 3 + 20],
                )
            }))
        }),
        case(
            "stl-claims-4e9",
            stl,
            &["promises 4000000000 triangles"],
            |r| {
                info(&scene(r, |s| {
                    write(&s.join("meshes/tumour.stl"), binary_stl(4_000_000_000, 1))
                }))
            },
        ),
        case(
            "stl-empty",
            stl,
            &["shorter than its 84-byte header"],
            |r| info(&scene(r, |s| write(&s.join("meshes/tumour.stl"), ""))),
        ),
        case("stl-nan-vertex", stl, &["non-finite"], |r| {
            info(&scene(r, |s| {
                replace(
                    &s.join("meshes/tumour.stl"),
                    "vertex 24 0 -4",
                    "vertex nan 0 -4",
                )
            }))
        }),
        case("stl-quad-facet", stl, &["facet with 4 vertices"], |r| {
            info(&scene(r, |s| {
                replace(
                    &s.join("meshes/tumour.stl"),
                    "vertex 24 0 -4",
                    "vertex 24 0 -4\n   vertex 1 1 1",
                )
            }))
        }),
        case("obj-named-stl", stl, &["binary STL truncated"], |r| {
            info(&scene(r, |s| {
                std::fs::copy(s.join("meshes/kidney.obj"), s.join("meshes/tumour.stl")).unwrap();
            }))
        }),
        case("ply-claims-4e9-vertices", ply, &["ends early"], |r| {
            info(&scene(r, |s| {
                replace(
                    &s.join("meshes/hidden.ply"),
                    "element vertex 6",
                    "element vertex 4000000000",
                )
            }))
        }),
        case(
            "binary-ply-claims-4e9-vertices",
            ply,
            &["ends early"],
            |r| {
                info(&scene(r, |s| {
                    let mut b =
                        b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n\
                    property float x\nproperty float y\nproperty float z\nelement face 1\n\
                    property list uchar int vertex_indices\nend_header\n"
                            .to_vec();
                    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
                        b.extend(v.to_le_bytes());
                    }
                    write(&s.join("meshes/hidden.ply"), b)
                }))
            },
        ),
        case("ply-negative-index", ply, &["negative index"], |r| {
            info(&scene(r, |s| {
                replace(&s.join("meshes/hidden.ply"), "3 0 2 4\n", "3 0 2 -4\n")
            }))
        }),
        case("ply-infinite-vertex", ply, &["non-finite"], |r| {
            info(&scene(r, |s| {
                replace(&s.join("meshes/hidden.ply"), "\n-7 0 0\n", "\n-7 inf 0\n")
            }))
        }),
        case("ply-empty", ply, &["not a PLY file"], |r| {
            info(&scene(r, |s| write(&s.join("meshes/hidden.ply"), "")))
        }),
        case("ply-unknown-format", ply, &["unknown PLY format"], |r| {
            info(&scene(r, |s| {
                replace(
                    &s.join("meshes/hidden.ply"),
                    "format ascii 1.0",
                    "format binary_middle_endian 1.0",
                )
            }))
        }),
        case("obj-empty", obj, &["no vertices"], |r| {
            info(&scene(r, |s| write(&s.join("meshes/kidney.obj"), "")))
        }),
        case(
            "obj-index-out-of-range",
            obj,
            &["refers to vertex 99"],
            |r| {
                info(&scene(r, |s| {
                    replace(
                        &s.join("meshes/kidney.obj"),
                        "f 1//1 3//1 5//1",
                        "f 1//1 3//1 99//1",
                    )
                }))
            },
        ),
        case("obj-index-zero", obj, &["face index 0"], |r| {
            info(&scene(r, |s| {
                replace(&s.join("meshes/kidney.obj"), "f 1//1 3//1 5//1", "f 0 3 5")
            }))
        }),
        case("obj-degenerate-face", obj, &["degenerate"], |r| {
            info(&scene(r, |s| {
                replace(&s.join("meshes/kidney.obj"), "f 1//1 3//1 5//1", "f 1 1 5")
            }))
        }),
        case(
            "wrong-extension",
            "scene/meshes/kidney.off",
            &["unknown mesh format"],
            |r| {
                info(&scene(r, |s| {
                    std::fs::rename(s.join("meshes/kidney.obj"), s.join("meshes/kidney.off"))
                        .unwrap();
                    edit_json(s, |v| {
                        v["structures"][0]["mesh"] = "meshes/kidney.off".into()
                    });
                }))
            },
        ),
        case(
            "mesh-is-a-folder",
            "scene/meshes",
            &["cannot read mesh"],
            |r| {
                info(&scene(r, |s| {
                    edit_json(s, |v| v["structures"][0]["mesh"] = "meshes".into())
                }))
            },
        ),
        case(
            "new-scene-bad-kidney",
            "meshes/kidney.obj",
            &["refers to vertex 9"],
            |r| {
                write(
                    &r.join("meshes/kidney.obj"),
                    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 9\n",
                );
                let f = fixture();
                new_scene_with(
                    r,
                    &f.join("scene.json"),
                    ["--meshes".into(), r.join("meshes").into()],
                    views(&f.join("left"), &f.join("right")),
                )
            },
        ),
    ]);
}

/// Frames: truncated, corrupt, of the wrong size, not images, or folders; through `info`,
/// `classify` and the views of `new-scene`.
#[test]
fn malformed_frames() {
    check_all(vec![
        case(
            "png-cut-to-10-bytes",
            "scene/left/000001.png",
            &["not a readable image"],
            |r| {
                classify(&scene(r, |s| {
                    edit_bytes(&s.join("left/000001.png"), |b| b[..10].to_vec())
                }))
            },
        ),
        case(
            "png-bad-crc",
            "scene/left/000000.png",
            &["cannot decode frame"],
            |r| {
                info(&scene(r, |s| {
                    edit_bytes(&s.join("left/000000.png"), |mut b| {
                        // A byte of the image data (IEND and the IDAT checksum are the last 16).
                        let n = b.len();
                        b[n - 20] ^= 0xff;
                        b
                    })
                }))
            },
        ),
        case(
            "png-wrong-size",
            "scene/right/000001.png",
            &["128×96 but the camera is 64×48"],
            |r| {
                classify(&scene(r, |s| {
                    save_rgb(&s.join("right/000001.png"), 128, 96)
                }))
            },
        ),
        case(
            "text-named-png",
            "scene/right/000000.png",
            &["not a readable image"],
            |r| {
                classify(&scene(r, |s| {
                    write(&s.join("right/000000.png"), "hello, not a PNG\n")
                }))
            },
        ),
        case(
            "empty-png",
            "scene/right/000001.png",
            &["not a readable image"],
            |r| info(&scene(r, |s| write(&s.join("right/000001.png"), ""))),
        ),
        case(
            "png-claims-100000-square",
            "scene/left/000000.png",
            &["100000×100000", "not a readable image"],
            |r| {
                classify(&scene(r, |s| {
                    write(&s.join("left/000000.png"), png_claiming_huge_size())
                }))
            },
        ),
        case(
            "frame-is-a-folder",
            "scene/left/000001.png",
            &["is a folder, not a frame image"],
            |r| {
                info(&scene(r, |s| {
                    std::fs::remove_file(s.join("left/000001.png")).unwrap();
                    std::fs::create_dir(s.join("left/000001.png")).unwrap();
                }))
            },
        ),
        case(
            "view-numbers-jump",
            "views/left",
            &["jump from 0 to 2"],
            |r| {
                save_rgb(&r.join("views/left/000000.png"), 64, 48);
                save_rgb(&r.join("views/left/000002.png"), 64, 48);
                fixture_anatomy(r, views(&r.join("views/left"), &fixture().join("right")))
            },
        ),
        case("views-of-two-sizes", "views/right", &["128×96"], |r| {
            save_rgb(&r.join("views/right/000000.png"), 128, 96);
            save_rgb(&r.join("views/right/000001.png"), 128, 96);
            fixture_anatomy(r, views(&fixture().join("left"), &r.join("views/right")))
        }),
        case(
            "view-first-frame-text",
            "views/left/000000.png",
            &["not a readable image"],
            |r| {
                write(&r.join("views/left/000000.png"), "not a PNG");
                save_rgb(&r.join("views/left/000001.png"), 64, 48);
                fixture_anatomy(r, views(&r.join("views/left"), &fixture().join("right")))
            },
        ),
        case(
            "view-without-frames",
            "views/left",
            &["no numbered PNG or JPEG frames"],
            |r| {
                write(&r.join("views/left/notes.txt"), "nothing here");
                fixture_anatomy(r, views(&r.join("views/left"), &fixture().join("right")))
            },
        ),
        case(
            "view-neither-video-nor-folder",
            "views/left.txt",
            &["is neither a video"],
            |r| {
                write(&r.join("views/left.txt"), "frames elsewhere");
                fixture_anatomy(
                    r,
                    views(&r.join("views/left.txt"), &fixture().join("right")),
                )
            },
        ),
        // A frame whose header reads but whose pixels are cut off is found only when its turn
        // comes: the frames before it were written to a staging folder, never into --out.
        case(
            "classify-later-frame-truncated",
            "left/000001.png",
            &["cannot decode frame"],
            |r| {
                classify(&scene(r, |s| {
                    edit_bytes(&s.join("left/000001.png"), |b| b[..b.len() / 2].to_vec())
                }))
            },
        ),
        case(
            "track-later-frame-truncated",
            "left/000001.png",
            &["cannot decode frame"],
            |r| {
                track(&scene(r, |s| {
                    edit_bytes(&s.join("left/000001.png"), |b| b[..b.len() / 2].to_vec())
                }))
            },
        ),
        case(
            "classify-ground-truth-16-bit",
            "gt/left/000000.png",
            &["8-bit grey"],
            |r| classify(&scene(r, |s| save_grey16(&s.join("gt/left/000000.png")))),
        ),
        case(
            "track-ground-truth-16-bit",
            "gt/left/000000.png",
            &["8-bit grey"],
            |r| track(&scene(r, |s| save_grey16(&s.join("gt/left/000000.png")))),
        ),
    ]);
}

/// Seed images: wrong size, depth or colour, unreadable, naming no class, or no seeds at all
/// when `classify` needs them.
#[test]
fn malformed_seeds() {
    check_all(vec![
        case(
            "seeds-too-big",
            "scene/seeds/left/000000.png",
            &["128×96"],
            |r| {
                classify(&scene(r, |s| {
                    save_grey(&s.join("seeds/left/000000.png"), 128, 96, 255)
                }))
            },
        ),
        case(
            "seed-value-no-class",
            "scene/seeds/right/000000.png",
            &["seed value 3"],
            |r| {
                classify(&scene(r, |s| {
                    let p = s.join("seeds/right/000000.png");
                    let mut img = image::open(&p).unwrap().into_luma8();
                    img.put_pixel(10, 10, image::Luma([3]));
                    img.save(&p).unwrap();
                }))
            },
        ),
        case(
            "seeds-in-colour",
            "scene/seeds/left/000000.png",
            &["has colours"],
            |r| {
                classify(&scene(r, |s| {
                    let mut img = image::RgbImage::new(64, 48);
                    img.put_pixel(3, 3, image::Rgb([255, 0, 0]));
                    img.save(s.join("seeds/left/000000.png")).unwrap();
                }))
            },
        ),
        case(
            "seeds-16-bit",
            "scene/seeds/left/000000.png",
            &["8-bit grey"],
            |r| classify(&scene(r, |s| save_grey16(&s.join("seeds/left/000000.png")))),
        ),
        case(
            "seeds-text",
            "scene/seeds/right/000000.png",
            &["cannot decode label image"],
            |r| {
                classify(&scene(r, |s| {
                    write(&s.join("seeds/right/000000.png"), "not a PNG")
                }))
            },
        ),
        case(
            "seeds-truncated",
            "scene/seeds/right/000000.png",
            &["cannot decode label image"],
            |r| {
                classify(&scene(r, |s| {
                    edit_bytes(&s.join("seeds/right/000000.png"), |b| b[..60].to_vec())
                }))
            },
        ),
        case(
            "seeds-all-unpainted",
            "scene/seeds/{camera}/{frame:06}.png",
            &["no seeds"],
            |r| {
                classify(&scene(r, |s| {
                    save_grey(&s.join("seeds/left/000000.png"), 64, 48, 0);
                    save_grey(&s.join("seeds/right/000000.png"), 64, 48, 0);
                }))
            },
        ),
        case(
            "no-seed-images",
            "scene/seeds/{camera}/{frame:06}.png",
            &["no seeds"],
            |r| {
                classify(&scene(r, |s| {
                    std::fs::remove_dir_all(s.join("seeds")).unwrap()
                }))
            },
        ),
        case(
            "background-seeds-only",
            "scene/seeds/{camera}/{frame:06}.png",
            &["no seeded pixel for 'kidney'"],
            |r| {
                classify(&scene(r, |s| {
                    for cam in ["left", "right"] {
                        let p = s.join(format!("seeds/{cam}/000000.png"));
                        let mut img = image::open(&p).unwrap().into_luma8();
                        for px in img.pixels_mut() {
                            if px.0[0] != 255 {
                                px.0[0] = 0;
                            }
                        }
                        img.save(&p).unwrap();
                    }
                }))
            },
        ),
    ]);
}

/// Calibration files given to `new-scene`: truncated, wrong shapes, missing keys, impossible
/// cameras, and a size that does not match the views.
#[test]
fn malformed_calibrations() {
    let endovis = || calib_fixture("calib_A_seq1-2-3-4-6-7.txt");
    let yaml = || calib_fixture("opencv4_stereo.yml");
    let xml = || calib_fixture("opencv4_stereo.xml");
    check_all(vec![
        case(
            "yaml-truncated",
            "cut.yml",
            &["is not a number"],
            move |r| {
                let text = std::fs::read(yaml()).unwrap();
                write(&r.join("cut.yml"), &text[..600]);
                new_scene(r, &r.join("cut.yml"))
            },
        ),
        case("xml-truncated", "cut.xml", &["truncated"], move |r| {
            let text = std::fs::read(xml()).unwrap();
            write(&r.join("cut.xml"), &text[..300]);
            new_scene(r, &r.join("cut.xml"))
        }),
        case(
            "xml-2x2-camera-matrix",
            "k22.xml",
            &["cameraMatrix1 is 2×2, expected 3×3"],
            move |r| {
                let text = std::fs::read_to_string(xml()).unwrap();
                let start = text.find("<cameraMatrix1").unwrap();
                let end = text.find("</cameraMatrix1>").unwrap() + "</cameraMatrix1>".len();
                let two_by_two = "<cameraMatrix1 type_id=\"opencv-matrix\">\n  <rows>2</rows>\n  \
                <cols>2</cols>\n  <dt>d</dt>\n  <data>\n    1084.2 0. 0. 1084.0</data></cameraMatrix1>";
                write(
                    &r.join("k22.xml"),
                    format!("{}{two_by_two}{}", &text[..start], &text[end..]),
                );
                new_scene(r, &r.join("k22.xml"))
            },
        ),
        case(
            "endovis-missing-key",
            "camera_calibration.txt",
            &["missing Camera-1-F"],
            move |r| {
                let text = std::fs::read_to_string(endovis()).unwrap();
                let kept: Vec<&str> = text
                    .lines()
                    .filter(|l| !l.starts_with("Camera-1-F"))
                    .collect();
                write(&r.join("camera_calibration.txt"), kept.join("\n"));
                new_scene(r, &r.join("camera_calibration.txt"))
            },
        ),
        case(
            "endovis-negative-focal",
            "camera_calibration.txt",
            &["focal lengths must be positive"],
            move |r| {
                let text = std::fs::read_to_string(endovis()).unwrap();
                assert!(text.contains("Camera-0-F: 1084.21"));
                write(
                    &r.join("camera_calibration.txt"),
                    text.replacen("Camera-0-F: 1084.21", "Camera-0-F: -1084.21", 1),
                );
                new_scene(r, &r.join("camera_calibration.txt"))
            },
        ),
        case(
            "size-not-the-views",
            "calib_A_seq1-2-3-4-6-7.txt",
            &["1280×1024 images, but the images are 64×48"],
            move |r| new_scene(r, &endovis()),
        ),
        case("empty-calibration", "empty.yml", &["empty"], |r| {
            write(&r.join("empty.yml"), "");
            new_scene(r, &r.join("empty.yml"))
        }),
        case(
            "binary-calibration",
            "garbage.yml",
            &["not a text file"],
            |r| {
                write(
                    &r.join("garbage.yml"),
                    (0..=255u8).cycle().take(2000).collect::<Vec<u8>>(),
                );
                new_scene(r, &r.join("garbage.yml"))
            },
        ),
        case(
            "yaml-nan-focal",
            "nan.yml",
            &["not a finite number"],
            move |r| {
                let text = std::fs::read_to_string(yaml()).unwrap();
                write(
                    &r.join("nan.yml"),
                    text.replacen("1.0842137000000000e+03", ".nan", 1),
                );
                new_scene(r, &r.join("nan.yml"))
            },
        ),
        case(
            "yaml-not-a-rotation",
            "rot.yml",
            &["R is not a rotation"],
            move |r| {
                let text = std::fs::read_to_string(yaml()).unwrap();
                write(
                    &r.join("rot.yml"),
                    text.replacen("9.9999939500006296e-01", "1.9999939500006296e+00", 1),
                );
                new_scene(r, &r.join("rot.yml"))
            },
        ),
        case("yaml-skew", "skew.yml", &["skew"], move |r| {
            let text = std::fs::read_to_string(yaml()).unwrap();
            write(
                &r.join("skew.yml"),
                text.replacen(
                    "1.0842137000000000e+03, 0.,",
                    "1.0842137000000000e+03, 5.,",
                    1,
                ),
            );
            new_scene(r, &r.join("skew.yml"))
        }),
        case(
            "yaml-rational-distortion",
            "opencv4_stereo_k4.yml",
            &["k4"],
            |r| new_scene(r, &calib_fixture("opencv4_stereo_k4.yml")),
        ),
        case(
            "mono-calibration-two-views",
            "opencv4_mono.yml",
            &["1 camera(s)"],
            |r| new_scene(r, &calib_fixture("opencv4_mono.yml")),
        ),
        case(
            "scene-json-without-cameras",
            "cams.json",
            &["missing cameras"],
            |r| {
                write(
                    &r.join("cams.json"),
                    r#"{"format": "endofuse-scene/1", "cameras": []}"#,
                );
                new_scene(r, &r.join("cams.json"))
            },
        ),
    ]);
}

/// NIfTI label volumes given to `import-ct` (and one to `new-scene --ct`).
#[test]
fn malformed_label_volumes() {
    let (u8t, u8b) = NIFTI_UINT8;
    check_all(vec![
        case(
            "truncated-nii-gz",
            "half.nii.gz",
            &["cannot read NIfTI"],
            |r| {
                let b = std::fs::read(ct_fixture()).unwrap();
                write(&r.join("half.nii.gz"), &b[..b.len() / 2]);
                import_ct(r, &r.join("half.nii.gz"))
            },
        ),
        case(
            "dims-32767-cubed",
            "huge.nii",
            &["cannot read NIfTI"],
            |r| {
                let (t, b) = NIFTI_FLOAT64;
                write(
                    &r.join("huge.nii"),
                    nifti(&[32767, 32767, 32767], t, b, &[]),
                );
                import_ct(r, &r.join("huge.nii"))
            },
        ),
        case(
            "dims-32767-cubed-gz",
            "huge.nii.gz",
            &["cannot read NIfTI"],
            |r| {
                let (t, b) = NIFTI_FLOAT64;
                write(
                    &r.join("huge.nii.gz"),
                    gzip(&nifti(&[32767, 32767, 32767], t, b, &[])),
                );
                import_ct(r, &r.join("huge.nii.gz"))
            },
        ),
        case(
            "negative-dims",
            "neg.nii",
            &["dim[1] is -5", "cannot be negative"],
            move |r| {
                write(
                    &r.join("neg.nii"),
                    nifti(&[-5, 10, 10], u8t, u8b, &[1; 500]),
                );
                import_ct(r, &r.join("neg.nii"))
            },
        ),
        case(
            "float-intensities",
            "ct.nii",
            &["not whole non-negative labels"],
            |r| {
                let (t, b) = NIFTI_FLOAT32;
                let data: Vec<u8> = (0..1000)
                    .flat_map(|i| (i as f32 * 0.37).to_le_bytes())
                    .collect();
                write(&r.join("ct.nii"), nifti(&[10, 10, 10], t, b, &data));
                import_ct(r, &r.join("ct.nii"))
            },
        ),
        case(
            "text-named-nii",
            "labels.nii",
            &["cannot read NIfTI"],
            |r| {
                write(&r.join("labels.nii"), "this is not a NIfTI file\n");
                import_ct(r, &r.join("labels.nii"))
            },
        ),
        case("empty-nii", "empty.nii", &["cannot read NIfTI"], |r| {
            write(&r.join("empty.nii"), "");
            import_ct(r, &r.join("empty.nii"))
        }),
        case(
            "gz-name-not-gzip",
            "plain.nii.gz",
            &["not gzip data"],
            move |r| {
                write(
                    &r.join("plain.nii.gz"),
                    nifti(&[10, 10, 10], u8t, u8b, &[1; 1000]),
                );
                import_ct(r, &r.join("plain.nii.gz"))
            },
        ),
        case(
            "two-dimensional",
            "slice.nii",
            &["2-dimensional"],
            move |r| {
                write(&r.join("slice.nii"), nifti(&[10, 10], u8t, u8b, &[1; 100]));
                import_ct(r, &r.join("slice.nii"))
            },
        ),
        case("rgb-datatype", "rgb.nii", &["cannot hold labels"], |r| {
            let (t, b) = NIFTI_RGB24;
            write(&r.join("rgb.nii"), nifti(&[10, 10, 10], t, b, &[0; 3000]));
            import_ct(r, &r.join("rgb.nii"))
        }),
        case(
            "all-background",
            "zeros.nii",
            &["all background"],
            move |r| {
                write(
                    &r.join("zeros.nii"),
                    nifti(&[10, 10, 10], u8t, u8b, &[0; 1000]),
                );
                import_ct(r, &r.join("zeros.nii"))
            },
        ),
        case(
            "no-kidney-label",
            "fives.nii",
            &["no voxel has the kidney label"],
            move |r| {
                write(
                    &r.join("fives.nii"),
                    nifti(&[10, 10, 10], u8t, u8b, &[5; 1000]),
                );
                import_ct(r, &r.join("fives.nii"))
            },
        ),
        case(
            "voxels-missing",
            "short.nii",
            &["cannot read NIfTI"],
            move |r| {
                write(
                    &r.join("short.nii"),
                    nifti(&[10, 10, 10], u8t, u8b, &[1; 100]),
                );
                import_ct(r, &r.join("short.nii"))
            },
        ),
        case(
            "new-scene-truncated-ct",
            "half.nii.gz",
            &["cannot read NIfTI"],
            |r| {
                let b = std::fs::read(ct_fixture()).unwrap();
                write(&r.join("half.nii.gz"), &b[..b.len() / 2]);
                let f = fixture();
                new_scene_with(
                    r,
                    &f.join("scene.json"),
                    ["--ct".into(), r.join("half.nii.gz").into()],
                    views(&f.join("left"), &f.join("right")),
                )
            },
        ),
    ]);
}

/// Files named as videos that are none, through a scene and through `new-scene`; they are
/// refused the same way whether or not FFmpeg is installed.
#[test]
fn malformed_videos() {
    /// The fixture scene with camera 0's frames taken from `scene/left.mp4`.
    fn video_scene(r: &Path, bytes: Option<&[u8]>) -> PathBuf {
        scene(r, |s| {
            if let Some(b) = bytes {
                write(&s.join("left.mp4"), b);
            }
            edit_json(s, |v| v["cameras"][0]["frames"] = "left.mp4".into());
        })
    }
    check_all(vec![
        case("text-named-mp4", "scene/left.mp4", NOT_A_VIDEO, |r| {
            info(&video_scene(r, Some(&b"this is not a video\n"[..])))
        }),
        case("empty-mp4", "scene/left.mp4", NOT_A_VIDEO, |r| {
            info(&video_scene(r, Some(&b""[..])))
        }),
        case("missing-mp4", "scene/left.mp4", &["file not found"], |r| {
            info(&video_scene(r, None))
        }),
        case("side-by-side-text", "scene/stereo.mkv", NOT_A_VIDEO, |r| {
            info(&scene(r, |s| {
                write(&s.join("stereo.mkv"), "not a stereo video\n");
                edit_json(s, |v| {
                    v["cameras"][0]["frames"] =
                        serde_json::json!({"video": "stereo.mkv", "crop": [0, 0, 64, 48]});
                    v["cameras"][1]["frames"] =
                        serde_json::json!({"video": "stereo.mkv", "crop": [64, 0, 64, 48]});
                })
            }))
        }),
        case("new-scene-view-not-a-video", "fake.mp4", NOT_A_VIDEO, |r| {
            write(&r.join("fake.mp4"), "this is not a video\n");
            fixture_anatomy(r, views(&r.join("fake.mp4"), &fixture().join("right")))
        }),
        case(
            "new-scene-empty-side-by-side",
            "empty.mp4",
            NOT_A_VIDEO,
            |r| {
                write(&r.join("empty.mp4"), "");
                let f = fixture();
                let mut run = new_scene_with(
                    r,
                    &f.join("scene.json"),
                    ["--meshes".into(), f.join("meshes").into()],
                    Vec::new(),
                );
                run.args.push(OsString::from("--side-by-side"));
                run.args.push(r.join("empty.mp4").into());
                run
            },
        ),
        case(
            "ffprobe-missing",
            "scene/left.mp4",
            &["install FFmpeg"],
            |r| {
                info(&video_scene(r, Some(&b"this is not a video\n"[..])))
                    .env("ENDOFUSE_FFPROBE", r.join("no-such-ffprobe"))
            },
        ),
        case(
            "ffprobe-not-a-program",
            "scene/left.mp4",
            &["failed"],
            |r| {
                write(&r.join("ffprobe.txt"), "not a program");
                info(&video_scene(r, Some(&b"this is not a video\n"[..])))
                    .env("ENDOFUSE_FFPROBE", r.join("ffprobe.txt"))
            },
        ),
    ]);
}

/// `track --config FILE`: read before the scene, so nothing is fitted or written.
#[test]
fn malformed_fit_configs() {
    let track = |r: &Path, config: &str| {
        write(&r.join("fit.json"), config);
        Run::new([
            OsString::from("track"),
            fixture().into(),
            "--out".into(),
            r.join("out").into(),
            "--config".into(),
            r.join("fit.json").into(),
        ])
    };
    check_all(vec![
        case(
            "config-truncated",
            "fit.json",
            &["malformed fit configuration"],
            move |r| track(r, "{\"priors\": "),
        ),
        case(
            "config-wrong-length",
            "fit.json",
            &["malformed fit configuration"],
            move |r| track(r, r#"{"priors": {"camera_relative": [-1]}}"#),
        ),
        case(
            "config-too-few-lines",
            "fit.json",
            &[
                "energy.max_lines_per_structure",
                "0 (no limit) or lie in 8..=1000000",
            ],
            move |r| track(r, r#"{"energy": {"max_lines_per_structure": 3}}"#),
        ),
    ]);
}
