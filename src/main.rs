//! The `endofuse` command line (CONTRACT §1). Thin: every command calls the core library and
//! maps its errors to exit codes (2 for bad input, with one line naming the file).

use anyhow::Result;
use clap::{Parser, Subcommand};
use endofuse::Error;
use endofuse::fit::config::RecordedRun;
use endofuse::fit::{FitConfig, Model};
use endofuse::synth::SynthOptions;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "endofuse",
    version,
    about = "Fuse preoperative CT models with stereo endoscopic video (seeded forest + non-rigid multi-structure pose)."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Open the desktop app on a scene (default: the built-in demo).
    Open { scene: Option<String> },
    /// Validate a scene and print what it holds (SCENE: folder, scene.json, or `demo`).
    Info {
        scene: String,
        /// Only read frame headers instead of decoding every frame.
        #[arg(long)]
        quick: bool,
    },
    /// Train the forest on the scene's seeds; write probability, uncertainty and label maps.
    Classify {
        scene: String,
        #[arg(long)]
        out: PathBuf,
        /// Inclusive 0-based frame range, e.g. 0..29 (default: all frames).
        #[arg(long)]
        frames: Option<String>,
        /// Number of trees (N_b), 1 to 1000.
        #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u16).range(1..=1000))]
        trees: u16,
    },
    /// Train the forest, initialise, track every frame; write masks, trajectory and metrics.
    Track {
        scene: String,
        #[arg(long)]
        out: PathBuf,
        /// R (rigid), L (affine), LS (affine + shape), LSC (+ camera intrinsics under zoom).
        /// Default: the mode a --config metrics.json recorded, else LSC (camera correction only
        /// where a zoom change is marked or detected).
        #[arg(long)]
        mode: Option<String>,
        /// Inclusive 0-based frame range, e.g. 0..29 (default: all frames).
        #[arg(long)]
        frames: Option<String>,
        /// The fit's tuning constants: a JSON FitConfig (missing keys take their defaults) or
        /// the metrics.json of an earlier run, whose configuration, mode and frames it reuses
        /// unless --mode or --frames say otherwise.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Leave each frame's time (`ms`) out of trajectory.json, so that two runs of the same
        /// input write the same bytes (timings stay in metrics.json).
        #[arg(long)]
        no_timings: bool,
    },
    /// A CT label volume (NIfTI .nii/.nii.gz) → kidney and tumour surface meshes in mm.
    ImportCt {
        labels: PathBuf,
        #[arg(long)]
        out: PathBuf,
        /// Which kidney: left, right, or auto (the one the largest tumour touches).
        #[arg(long, default_value = "auto")]
        side: String,
        /// Label numbers, e.g. kidney=1,tumour=2,cyst=3 (KiTS by default).
        #[arg(long = "labels", value_name = "MAP")]
        labels_map: Option<String>,
        /// Target vertex count of the kidney mesh, at least 100 (tumours get about a quarter,
        /// at least 100).
        #[arg(long, default_value_t = 5000)]
        vertices: usize,
        /// Replace a non-empty output folder.
        #[arg(long)]
        force: bool,
    },
    /// Write a synthetic stereo endoscopic phantom scene with ground truth.
    Synth {
        #[arg(long)]
        out: PathBuf,
        #[arg(long, default_value_t = 30)]
        frames: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Standard deviation of additive Gaussian noise on intensities in [0, 1].
        #[arg(long, default_value_t = 0.01)]
        noise: f64,
        /// Frame width in px [default: 960, or the --calib file's image size].
        #[arg(long)]
        width: Option<u32>,
        /// Frame height in px [default: 540, or the --calib file's image size].
        #[arg(long)]
        height: Option<u32>,
        #[arg(long, default_value_t = 2)]
        views: usize,
        /// No surgical instruments.
        #[arg(long)]
        no_tools: bool,
        /// No zoom change.
        #[arg(long)]
        no_zoom: bool,
        /// No smoke haze.
        #[arg(long)]
        no_smoke: bool,
        /// Draw the look from the seed: light colour and strength, glints, kidney tint, texture
        /// scale, blood-like patches beside the kidney, blur (a wider test of the classifier).
        #[arg(long)]
        vary_look: bool,
        /// Draw the rig and motion from the seed as real da Vinci data vary: toe-in 1–2°, the
        /// right principal point up to 2 px off, k2 and p1/p2, a 20 % zoom over 10–15 frames
        /// (half the scenes zoom back out) with the principal point drifting ±4 px, depth
        /// 145–165 mm, and an initial pose 8 mm and 10° off (a wider test of the fit).
        #[arg(long)]
        vary_rig: bool,
        /// Render these structures (an `import-ct` output, or kidney.obj + tumour_*.obj)
        /// instead of the built-in anatomy.
        #[arg(long)]
        meshes: Option<PathBuf>,
        /// Render through this calibration (OpenCV YAML/XML, EndoVis text, scene.json); its
        /// image size replaces --width/--height, its cameras --views.
        #[arg(long)]
        calib: Option<PathBuf>,
    },
    /// Rerun the paper's synthetic experiments (§IV-A: pose-recovery range vs views, Dice vs
    /// noise against Chan–Vese, shape recovery, camera parameters under zoom, the four modes);
    /// write CSVs, PNG plots and report.md.
    Experiments {
        #[arg(long)]
        out: PathBuf,
        /// The reduced grid (a few minutes on 2 cores) instead of the paper's.
        #[arg(long)]
        quick: bool,
        /// Seed of every noise image and random draw.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Assemble a scene folder from a patient's calibration, CT labels or meshes, and videos.
    #[command(group(clap::ArgGroup::new("anatomy").required(true).args(["ct", "meshes"])))]
    NewScene {
        #[arg(long)]
        out: PathBuf,
        /// Calibration: OpenCV FileStorage YAML/XML, da Vinci/EndoVis camera_calibration.txt,
        /// or a scene.json's cameras.
        #[arg(long)]
        calib: PathBuf,
        /// CT label volume (NIfTI), meshed as `import-ct` does.
        #[arg(long)]
        ct: Option<PathBuf>,
        /// A folder of meshes (import-ct output, or kidney.obj, tumour_exo*.obj, tumour_endo*.obj).
        #[arg(long)]
        meshes: Option<PathBuf>,
        /// One view per camera: NAME=FILE (a video file or a folder of numbered frames).
        #[arg(
            long = "view",
            value_name = "NAME=FILE",
            conflicts_with = "side_by_side"
        )]
        views: Vec<String>,
        /// One side-by-side stereo video (left half = camera 0).
        #[arg(long, value_name = "FILE")]
        side_by_side: Option<PathBuf>,
        /// Copy videos/frames into the scene instead of referring to them.
        #[arg(long)]
        copy_frames: bool,
        /// Use only the first N frames.
        #[arg(long)]
        frames: Option<usize>,
        /// Replace a non-empty output folder.
        #[arg(long)]
        force: bool,
    },
}

fn main() -> ExitCode {
    // Before anything else: a binary built for another CPU says so instead of dying on an
    // illegal instruction somewhere later.
    let missing = endofuse::cpu::missing_features();
    if !missing.is_empty() {
        eprintln!("endofuse: {}", endofuse::cpu::mismatch_message(&missing));
        return ExitCode::from(1);
    }
    // Our own warnings (a calibration's baseline not in millimetres, lines a calibration file
    // skipped, a truncated video) are shown, as `warning: …` lines: a user must not learn of
    // them only by asking. Dependencies stay quiet; diagnostics for whoever asks (RUST_LOG=info,
    // =debug, or per module). A refused input still ends with exactly one error line.
    env_logger::Builder::from_env(
        env_logger::Env::default().default_filter_or("error,endofuse=warn"),
    )
    .format(|buf, record| {
        use std::io::Write;
        match record.level() {
            log::Level::Warn => writeln!(buf, "warning: {}", record.args()),
            level => writeln!(buf, "[{level} {}] {}", record.target(), record.args()),
        }
    })
    .init();
    // Whatever happens, one line on stderr, never a backtrace.
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        eprintln!(
            "endofuse: internal error: {msg} (at {}); please report it",
            info.location().map(|l| l.to_string()).unwrap_or_default()
        );
    }));
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let bad_input = matches!(e.downcast_ref::<Error>(), Some(Error::Input(_)))
                || e.downcast_ref::<endofuse::InputError>().is_some();
            eprintln!("endofuse: {e}");
            ExitCode::from(if bad_input { 2 } else { 1 })
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        None => open_app("demo"),
        Some(Command::Open { scene }) => {
            let scene = scene.unwrap_or_else(|| "demo".into());
            if scene != endofuse::open::DEMO {
                // A scene that does not load is bad input: say so before opening a window.
                Model::build(&endofuse::open::scene(&scene)?)?;
            }
            open_app(&scene)
        }
        Some(Command::Experiments { out, quick, seed }) => {
            let r = endofuse::experiments::run(&endofuse::experiments::ExperimentOptions {
                out: out.clone(),
                quick,
                seed,
            })?;
            eprintln!(
                "experiments: done in {:.0} s; report, CSVs and plots in {}",
                r.seconds,
                out.display()
            );
            Ok(())
        }
        Some(Command::Info { scene, quick }) => {
            let scene = endofuse::open::scene(&scene)?;
            if !quick {
                scene.decode_frames(&progress_every("info: decoding", 20))?;
                scene.decode_ground_truth(&progress_every("info: ground truth", 20))?;
            }
            let model = Model::build(&scene)?;
            print!("{}", endofuse::info::summary(&scene, &model.shape));
            Ok(())
        }
        Some(Command::Classify {
            scene,
            out,
            frames,
            trees,
        }) => {
            let scene = endofuse::open::scene(&scene)?;
            let range = frame_range(frames.as_deref(), scene.frame_count)?;
            let params = endofuse::appearance::ForestParams {
                trees: trees.into(),
                ..Default::default()
            };
            let inputs: Vec<&Path> = scene.root.as_deref().into_iter().collect();
            let metrics = endofuse::results_dir::write_whole(&out, &inputs, |dir| {
                endofuse::classify::run(&scene, dir, range, &params, None, &progress("classify"))
            })?;
            eprintln!(
                "classify: forest of {} trees trained in {:.2} s on {} seeded pixels; {:.1} ms per view",
                metrics.forest.trees,
                metrics.forest.train_s,
                metrics.forest.samples,
                metrics.ms_per_view
            );
            match &metrics.forest.held_out {
                Some(v) => eprintln!(
                    "classify: strokes of a seeded {} left out: {:.1} % labelled right (classes weighed equally; worst class {:.1} %), over {} folds",
                    v.left_out,
                    100.0 * v.balanced_accuracy,
                    100.0 * v.worst_class_accuracy,
                    v.folds
                ),
                None => eprintln!(
                    "classify: one seeded image: no held-out check (seed a second frame for one)"
                ),
            }
            for (class, d) in &metrics.pixel_dice {
                eprintln!("classify: pixel Dice {class}: {d:.3}");
            }
            Ok(())
        }
        Some(Command::Track {
            scene,
            out,
            mode,
            frames,
            config,
            no_timings,
        }) => {
            let recorded = match config {
                Some(path) => read_fit_config(&path)?,
                None => RecordedRun {
                    config: FitConfig::default(),
                    mode: None,
                    frames: None,
                },
            };
            let mode = match mode {
                Some(m) => endofuse::fit::Mode::parse(&m).ok_or_else(|| {
                    endofuse::InputError::new(
                        "--mode",
                        format!("'{m}' is not one of R, L, LS, LSC"),
                    )
                })?,
                None => recorded.mode.unwrap_or(endofuse::fit::Mode::LSC),
            };
            let config = recorded.config;
            let scene = endofuse::open::scene(&scene)?;
            let recorded_frames = recorded.frames.map(|(a, b)| format!("{a}..{b}"));
            let range = frame_range(
                frames.as_deref().or(recorded_frames.as_deref()),
                scene.frame_count,
            )?;
            if mode == endofuse::fit::Mode::LSC {
                // Silhouettes barely see k1 or the principal point: say what the correction
                // does with them.
                let k1 = if scene.k1_vs_focal.is_some() {
                    "k1 follows fx by the scene's k1_vs_focal"
                } else {
                    "k1 held at calibration (the scene gives no k1_vs_focal)"
                };
                let pp = if config.priors.camera_relative[2..4]
                    .iter()
                    .all(|&r| r >= 1e3)
                {
                    "the principal point held at calibration"
                } else {
                    "the principal point estimated (the configuration frees it)"
                };
                eprintln!(
                    "track: camera correction estimates fx (fy follows at the calibrated aspect); {k1}; {pp}"
                );
            }
            let timings = if no_timings {
                endofuse::track::Timings::LeftOut
            } else {
                endofuse::track::Timings::Recorded
            };
            let inputs: Vec<&Path> = scene.root.as_deref().into_iter().collect();
            let m = endofuse::results_dir::write_whole(&out, &inputs, |dir| {
                endofuse::track::run_timed(
                    &scene,
                    dir,
                    mode,
                    range,
                    &config,
                    timings,
                    None,
                    &progress("track"),
                )
            })?;
            if let Some(r) = endofuse::fit::profile::report() {
                eprintln!("track: {r}");
            }
            eprintln!(
                "track: {} frames in mode {}, {} lost; {:.1} ms per frame (median), forest trained in {:.2} s",
                m.frames,
                m.mode,
                m.lost_frames,
                m.timing.ms_per_frame.median,
                m.timing.forest_train_s
            );
            if m.depth_explains_zoom_frames > 0 {
                eprintln!(
                    "track: warning: in {} frames the apparent size changed as in a zoom with the \
                     cameras fixed (mode {}): depth explained it, so hidden structures may be off \
                     there (confidence lowered; LSC corrects the cameras)",
                    m.depth_explains_zoom_frames, m.mode
                );
            }
            for (what, n) in &m.refused_frames {
                eprintln!(
                    "track: warning: {what} in {n} frames (see trajectory.json's warnings): {}",
                    if what == endofuse::scene::trajectory::PLACEMENT_REFUSED {
                        "a fresh placement after lost frames landed implausibly far away; the frames stay lost"
                    } else {
                        "camera correction left the plausible range; those frames were fitted with the cameras as before"
                    }
                );
            }
            if let Some(d) = &m.dice {
                let by: Vec<String> = d
                    .by_structure
                    .iter()
                    .map(|(k, v)| format!("{k} {v:.3}"))
                    .collect();
                eprintln!("track: Dice {:.3} ({})", d.mean, by.join(", "));
            }
            for (name, h) in &m.hidden {
                // A ground-truth trajectory that covers part of the run scores that part.
                let over = if h.centroid_frames < m.frames {
                    format!(
                        " over {} of {} frames (the ground-truth trajectory gives no centroid for the others)",
                        h.centroid_frames, m.frames
                    )
                } else {
                    String::new()
                };
                eprintln!(
                    "track: hidden {name}: centroid error {:.2} mm (max {:.2}){over}{}",
                    h.centroid_error_mm_mean,
                    h.centroid_error_mm_max,
                    h.dice_mean
                        .map(|d| format!(", Dice {d:.3}"))
                        .unwrap_or_default()
                );
            }
            if let Some(c) = &m.camera {
                eprintln!(
                    "track: fx error {:.2} % (max {:.2} %), cx error {:.2} px, cy error {:.2} px, k1 error max {:.3}",
                    100.0 * c.fx_rel_error_mean,
                    100.0 * c.fx_rel_error_max,
                    c.cx_error_px_mean,
                    c.cy_error_px_mean,
                    c.k1_error_max
                );
            }
            Ok(())
        }
        Some(Command::ImportCt {
            labels,
            out,
            side,
            labels_map,
            vertices,
            force,
        }) => {
            if vertices < 100 {
                log::warn!(
                    "--vertices {vertices}: a kidney mesh needs at least 100; meshing to 100"
                );
            }
            let mut options = endofuse::ctimport::ImportOptions {
                side: endofuse::ctimport::Side::parse(&side).ok_or_else(|| {
                    endofuse::InputError::new(
                        "--side",
                        format!("'{side}' is not left, right or auto"),
                    )
                })?,
                kidney_vertices: vertices.max(100),
                tumour_vertices: endofuse::ctimport::ImportOptions::tumour_vertices_for(vertices),
                force,
                ..Default::default()
            };
            if let Some(spec) = &labels_map {
                options
                    .set_labels(spec)
                    .map_err(|p| endofuse::InputError::new("--labels", p))?;
            }
            let started = std::time::Instant::now();
            let report = endofuse::ctimport::import_ct(&labels, &out, &options, &|stage| {
                eprintln!("import-ct: {stage}")
            })?;
            print!("{}", endofuse::ctimport::summary(&report));
            eprintln!(
                "import-ct: wrote {} in {:.1} s",
                out.display(),
                started.elapsed().as_secs_f64()
            );
            Ok(())
        }
        Some(Command::NewScene {
            out,
            calib,
            ct,
            meshes,
            views,
            side_by_side,
            copy_frames,
            frames,
            force,
        }) => {
            use endofuse::newscene::{Anatomy, NewSceneOptions, Views};
            let anatomy = match (ct, meshes) {
                (Some(labels), _) => Anatomy::Ct {
                    labels,
                    options: Default::default(),
                },
                (None, Some(dir)) => Anatomy::Meshes(dir),
                (None, None) => {
                    return Err(endofuse::InputError::new(
                        "--ct",
                        "give --ct LABELS or --meshes DIR",
                    )
                    .into());
                }
            };
            let views = match side_by_side {
                Some(file) => Views::SideBySide(file),
                None => {
                    if views.is_empty() {
                        return Err(endofuse::InputError::new(
                            "--view",
                            "give one --view NAME=FILE per camera, or --side-by-side FILE",
                        )
                        .into());
                    }
                    let mut list = Vec::new();
                    for v in &views {
                        let (name, file) = v.split_once('=').ok_or_else(|| {
                            endofuse::InputError::new("--view", format!("'{v}' is not NAME=FILE"))
                        })?;
                        list.push((name.to_string(), PathBuf::from(file)));
                    }
                    Views::PerCamera(list)
                }
            };
            let report = endofuse::newscene::new_scene(
                &NewSceneOptions {
                    out,
                    calib,
                    anatomy,
                    views,
                    copy_frames,
                    frames,
                    force,
                },
                &|stage| eprintln!("new-scene: {stage}"),
            )?;
            println!("{}", report.next_steps());
            Ok(())
        }
        Some(Command::Synth {
            out,
            frames,
            seed,
            noise,
            width,
            height,
            views,
            no_tools,
            no_zoom,
            no_smoke,
            vary_look,
            vary_rig,
            meshes,
            calib,
        }) => {
            let structures = match &meshes {
                Some(dir) => Some(
                    endofuse::ctimport::output::read_structures_dir(dir)?
                        .into_iter()
                        .map(|s| (s.entry.name, s.entry.label as u8, s.entry.visible, s.mesh))
                        .collect(),
                ),
                None => None,
            };
            let (cameras, width, height, views) = match &calib {
                Some(file) => {
                    let cal = endofuse::calib::read(file)?;
                    // A file without an image size (OpenCV's stereo calibration sample writes
                    // none) rendered at the default size with its principal point where the
                    // real image's was: the default now only where that point fits it.
                    let (w, h) = match (cal.image_size, width, height) {
                        (_, Some(w), Some(h)) => (w, h),
                        (Some(size), None, None) => size,
                        // One of the two alone was ignored where the file gave no size.
                        (_, Some(_), None) | (_, None, Some(_)) => {
                            return Err(endofuse::InputError::new(
                                file,
                                "give both --width and --height, or neither",
                            )
                            .into());
                        }
                        (None, None, None) => {
                            // The default size, where the principal point says the cameras
                            // could have been calibrated at it (within 15 % of its centre).
                            let (w, h) = SYNTH_DEFAULT_SIZE;
                            let near_centre = cal.cameras.iter().all(|c| {
                                let k = &c.intrinsics;
                                (k.cx - w as f64 / 2.0).abs() <= 0.15 * w as f64
                                    && (k.cy - h as f64 / 2.0).abs() <= 0.15 * h as f64
                            });
                            if !near_centre {
                                return Err(endofuse::InputError::new(
                                    file,
                                    format!("gives no image size, and its principal point (cx {:.1}, cy {:.1}) is far from the centre of the default {w}×{h}: give the frames' size the cameras were calibrated at with --width and --height", cal.cameras[0].intrinsics.cx, cal.cameras[0].intrinsics.cy),
                                )
                                .into());
                            }
                            log::warn!(
                                "{}: gives no image size: rendering at {w}×{h} (--width and --height choose another)",
                                file.display()
                            );
                            (w, h)
                        }
                    };
                    let cams = cal
                        .cameras(w, h)
                        .map_err(|e| endofuse::InputError::new(file, e.to_string()))?;
                    let n = cams.len();
                    (Some(cams), w, h, n)
                }
                None => (
                    None,
                    width.unwrap_or(SYNTH_DEFAULT_SIZE.0),
                    height.unwrap_or(SYNTH_DEFAULT_SIZE.1),
                    views,
                ),
            };
            let options = SynthOptions {
                structures,
                cameras,
                frames,
                seed,
                noise,
                width,
                height,
                views,
                tools: !no_tools,
                zoom: !no_zoom,
                smoke: !no_smoke,
                vary_look,
                vary_rig,
                ..SynthOptions::default()
            };
            // Refused before anything is written, naming the file the size came from.
            if let Err(e) = options.validate() {
                use endofuse::synth::SynthOptionsError;
                return Err(match (&calib, &e) {
                    (Some(file), SynthOptionsError::Size { .. }) => endofuse::InputError::new(
                        file,
                        format!(
                            "gives frames of {width}×{height} px, which synth cannot make: {e}"
                        ),
                    ),
                    (Some(file), SynthOptionsError::Views { .. }) => endofuse::InputError::new(
                        file,
                        format!("has {views} cameras, which synth cannot make: {e}"),
                    ),
                    _ => endofuse::InputError::new(&out, e.to_string()),
                }
                .into());
            }
            let started = std::time::Instant::now();
            // Into an empty or new folder directly; over an earlier phantom, written whole into
            // a fresh staging folder and moved onto --out (replaced, not merged with: no stale
            // frames, nothing written through links inside it); any other folder is refused.
            let inputs: Vec<&Path> = meshes.iter().chain(&calib).map(|p| p.as_path()).collect();
            endofuse::results_dir::write_whole_over(
                &out,
                &inputs,
                endofuse::results_dir::Earlier::Phantom,
                |dir| endofuse::synth::write_scene(dir, &options, &progress("synth")),
            )?;
            eprintln!(
                "synth: wrote {} in {:.1} s",
                out.display(),
                started.elapsed().as_secs_f64()
            );
            Ok(())
        }
    }
}

/// `synth`'s frame size without --width/--height (or a calibration's size).
const SYNTH_DEFAULT_SIZE: (u32, u32) = (960, 540);

/// Reads `track --config FILE`.
fn read_fit_config(path: &std::path::Path) -> Result<RecordedRun> {
    let bad = |problem: String| endofuse::InputError::new(path, problem);
    let text = endofuse::error::read_text(path).map_err(|e| bad(format!("cannot read: {e}")))?;
    let run = RecordedRun::from_json(&text).map_err(|e| bad(e.to_string()))?;
    run.config
        .validate()
        .map_err(|e| bad(format!("fit configuration: {e}")))?;
    Ok(run)
}

/// Opens the desktop app (blocks until its window closes).
#[cfg(feature = "gui")]
fn open_app(scene: &str) -> Result<()> {
    endofuse::app::run_native(scene)
}

/// A build without the `gui` feature has every command but the app.
#[cfg(not(feature = "gui"))]
fn open_app(_scene: &str) -> Result<()> {
    anyhow::bail!(
        "this endofuse was built without the desktop app (cargo feature `gui`); \
         rebuild with `cargo build --release` (default features) to open it"
    )
}

/// A progress line on stderr for frames, rewritten in place.
fn progress(what: &'static str) -> impl Fn(usize, usize) + Sync {
    progress_every(what, 1)
}

/// A progress line on stderr, `what: frame done/total`, rewritten in place every `every`
/// frames and at the last. Where stderr is not a terminal (a log file), one line per tenth of
/// the work instead.
fn progress_every(what: &'static str, every: usize) -> impl Fn(usize, usize) + Sync {
    use std::io::IsTerminal;
    let terminal = std::io::stderr().is_terminal();
    move |done, total| {
        if !terminal {
            let tenth = total.div_ceil(10).max(1);
            if done.is_multiple_of(tenth) || done == total {
                eprintln!("{what}: frame {done}/{total}");
            }
            return;
        }
        if done.is_multiple_of(every) || done == total {
            eprint!("\r{what}: frame {done}/{total}");
        }
        if done == total {
            eprintln!();
        }
    }
}

/// Parses `A..B` (inclusive, 0-based) against the scene's frame count; all frames when absent.
fn frame_range(spec: Option<&str>, frame_count: usize) -> Result<(usize, usize)> {
    let Some(spec) = spec else {
        return Ok((0, frame_count - 1));
    };
    let bad = || {
        endofuse::InputError::new(
            "--frames",
            format!("'{spec}' is not a range A..B inside 0..{}", frame_count - 1),
        )
    };
    let (a, b) = spec.split_once("..").ok_or_else(bad)?;
    let a: usize = a.trim().parse().map_err(|_| bad())?;
    let b: usize = b.trim().parse().map_err(|_| bad())?;
    if a > b || b >= frame_count {
        return Err(bad().into());
    }
    Ok((a, b))
}
