//! `endofuse experiments` (CONTRACT §5): the paper's synthetic experiments (§IV-A) rerun, with
//! our figures beside the paper's: Table IV (pose-recovery range against number of views),
//! Fig. 4 (Dice against noise, ours against Chan–Vese), Fig. 6 (tolerable shape perturbation),
//! Fig. 7 (camera parameters through a zoom) and Fig. 10b (the four modes on the project's
//! stereo phantoms). Each writes its CSV and PNG as soon as it ends, then report.md gathers
//! them. Deterministic for a seed; parallel over trials (rayon).
//!
//! The parts: [`rig`] (the virtual kidney, its cameras, eq. 10 images with noise and their
//! probabilities), [`chan_vese`] (the baseline), one module per experiment, [`plot`] and
//! [`report`].

pub mod camera;
pub mod chan_vese;
pub mod modes;
pub mod noise;
pub mod plot;
pub mod pose_range;
pub mod report;
pub mod rig;
pub mod shape;

use crate::error::Error;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// What to run.
#[derive(Debug, Clone)]
pub struct ExperimentOptions {
    pub out: PathBuf,
    /// The reduced grid (under 5 minutes on 2 cores) instead of the paper's.
    pub quick: bool,
    /// Seed of every noise image and random draw.
    pub seed: u64,
}

/// The settings of every experiment, full or quick.
#[derive(Debug, Clone)]
pub struct Grid {
    pub pose: pose_range::PoseRangeSetup,
    pub noise: noise::NoiseSetup,
    pub shape: shape::ShapeSetup,
    pub camera: camera::CameraSetup,
    pub modes: modes::ModesSetup,
}

impl Grid {
    pub fn new(quick: bool, seed: u64) -> Grid {
        use pose_range::Param;
        let sigmas: Vec<f64> = (1..=7).map(|i| 0.25 * i as f64).collect();
        let cv = chan_vese::ChanVeseParams::default();
        if quick {
            Grid {
                pose: pose_range::PoseRangeSetup {
                    views: vec![1, 4],
                    params: vec![
                        Param::ThetaX,
                        Param::ThetaY,
                        Param::ThetaZ,
                        Param::Sx,
                        Param::Sy,
                    ],
                    sigma: 0.75,
                    trials: 1,
                    bisections: 1,
                    quick: true,
                    seed,
                },
                noise: noise::NoiseSetup {
                    sigmas: vec![0.25, 1.0, 1.75],
                    views: vec![4],
                    trials: 1,
                    chan_vese: cv,
                    seed,
                },
                shape: shape::ShapeSetup {
                    sigmas: vec![0.75],
                    views: vec![1, 4],
                    perturbations_sd: vec![1.0, 2.0, 3.0],
                    trials: 1,
                    seed,
                },
                camera: camera::CameraSetup {
                    views: 4,
                    frames: 12,
                    sigma: 0.25,
                    seed,
                },
                modes: modes::ModesSetup {
                    seeds: vec![seed],
                    frames: 8,
                    width: 320,
                    height: 180,
                    noise: 0.02,
                },
            }
        } else {
            Grid {
                pose: pose_range::PoseRangeSetup {
                    views: vec![1, 4, 7, 14],
                    params: Param::ALL.to_vec(),
                    sigma: 0.75,
                    trials: 3,
                    bisections: 3,
                    quick: false,
                    seed,
                },
                noise: noise::NoiseSetup {
                    sigmas: sigmas.clone(),
                    views: vec![1, 4, 14],
                    trials: 3,
                    chan_vese: cv,
                    seed,
                },
                shape: shape::ShapeSetup {
                    sigmas: vec![0.25, 0.75, 1.25, 1.75],
                    views: vec![1, 2, 4, 7, 14],
                    perturbations_sd: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
                    trials: 3,
                    seed,
                },
                camera: camera::CameraSetup {
                    views: 4,
                    frames: 40,
                    sigma: 0.25,
                    seed,
                },
                modes: modes::ModesSetup {
                    seeds: vec![seed, seed + 1, seed + 2],
                    frames: 30,
                    width: 480,
                    height: 270,
                    noise: 0.02,
                },
            }
        }
    }
}

/// Progress on stderr: the stage, how many of its tasks are done, and the time left at the
/// pace so far (at most one line every two seconds, and one at each stage's end).
pub struct Progress {
    stage: Mutex<(String, usize, Instant, Instant)>,
    done: AtomicUsize,
    stages: AtomicUsize,
    total_stages: usize,
}

impl Progress {
    pub fn new(total_stages: usize) -> Progress {
        Progress {
            stage: Mutex::new((String::new(), 0, Instant::now(), Instant::now())),
            done: AtomicUsize::new(0),
            stages: AtomicUsize::new(0),
            total_stages,
        }
    }

    pub fn stage(&self, name: &str, tasks: usize) {
        let k = self.stages.fetch_add(1, Ordering::SeqCst) + 1;
        self.done.store(0, Ordering::SeqCst);
        if let Ok(mut s) = self.stage.lock() {
            *s = (name.to_string(), tasks, Instant::now(), Instant::now());
        }
        eprintln!(
            "experiments: [{k}/{}] {name}: {tasks} tasks",
            self.total_stages
        );
    }

    pub fn done(&self, n: usize) {
        let done = self.done.fetch_add(n, Ordering::SeqCst) + n;
        let Ok(mut s) = self.stage.lock() else {
            return;
        };
        let (name, total, started, last) = &mut *s;
        if done < *total && last.elapsed().as_secs_f64() < 2.0 {
            return;
        }
        *last = Instant::now();
        let spent = started.elapsed().as_secs_f64();
        let left = spent / done.max(1) as f64 * total.saturating_sub(done) as f64;
        eprintln!(
            "experiments: {name}: {done}/{total} done, {:.0} s spent, about {:.0} s left",
            spent, left
        );
    }
}

/// Writes `text` to `dir/name` (through a temporary file, so a reader never sees half of it).
fn write_text(dir: &Path, name: &str, text: &str) -> Result<(), Error> {
    let path = dir.join(name);
    let wrap = |source: std::io::Error| Error::Write {
        path: path.clone(),
        source,
    };
    let tmp = dir.join(format!(".{name}.tmp"));
    std::fs::write(&tmp, text).map_err(wrap)?;
    std::fs::rename(&tmp, &path).map_err(wrap)
}

fn fmt(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.6}")
    } else {
        "nan".into()
    }
}

pub fn pose_csv(rows: &[pose_range::Range]) -> String {
    let mut s = String::from(
        "views,parameter,low,high,trials,unit,low_capped,high_capped,silhouette_low,silhouette_high\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{}",
            r.views,
            r.param.name(),
            fmt(r.low),
            fmt(r.high),
            r.trials,
            r.param.unit(),
            r.low_capped as u8,
            r.high_capped as u8,
            fmt(r.silhouette_low),
            fmt(r.silhouette_high)
        );
    }
    s
}

pub fn noise_csv(rows: &[noise::NoiseRow]) -> String {
    let mut s = String::from("sigma,views,method,dice_mean,dice_std,trials\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{}",
            fmt(r.sigma),
            r.views,
            r.method,
            fmt(r.dice_mean),
            fmt(r.dice_std),
            r.trials
        );
    }
    s
}

pub fn shape_csv(rows: &[shape::ShapeRow]) -> String {
    let mut s = String::from(
        "sigma,views,perturbation_sd,recovered,vertex_rmse_mm,start_rmse_mm,floor_mm,trials\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{}",
            fmt(r.sigma),
            r.views,
            fmt(r.perturbation_sd),
            r.recovered as u8,
            fmt(r.vertex_rmse_mm),
            fmt(r.start_rmse_mm),
            fmt(r.floor_mm),
            r.trials
        );
    }
    s
}

pub fn camera_csv(rows: &[camera::CameraRow]) -> String {
    let mut s = String::from(
        "frame,camera,fx_true,fx_est,cx_true,cx_est,k1_true,k1_est,fy_true,fy_est,cy_true,cy_est\n",
    );
    for r in rows {
        let (t, e) = (&r.truth, &r.estimate);
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            r.frame,
            r.camera,
            fmt(t.fx),
            fmt(e.fx),
            fmt(t.cx),
            fmt(e.cx),
            fmt(t.k1),
            fmt(e.k1),
            fmt(t.fy),
            fmt(e.fy),
            fmt(t.cy),
            fmt(e.cy)
        );
    }
    s
}

pub fn modes_csv(rows: &[modes::ModeRow]) -> String {
    let mut s = String::from("scene,mode,dice_mean,dice_p25,dice_p75,hidden_centroid_mm\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{}",
            r.scene,
            r.mode.name(),
            fmt(r.dice_mean),
            fmt(r.dice_p25),
            fmt(r.dice_p75),
            fmt(r.hidden_centroid_mm)
        );
    }
    s
}

/// Everything the report needs.
pub struct Results {
    pub grid: Grid,
    pub pose: Vec<pose_range::Range>,
    pub noise: Vec<noise::NoiseRow>,
    pub shape: Vec<shape::ShapeRow>,
    pub camera: Vec<camera::CameraRow>,
    pub modes: Vec<modes::ModeRow>,
    pub seconds: f64,
    pub quick: bool,
    pub seed: u64,
}

/// Runs every experiment, writing each CSV and plot as it ends, then report.md.
pub fn run(options: &ExperimentOptions) -> Result<Results, Error> {
    let out = &options.out;
    if out.exists() && !out.is_dir() {
        return Err(
            crate::error::InputError::new(out, "--out names a file; it must be a folder").into(),
        );
    }
    std::fs::create_dir_all(out).map_err(|source| Error::Write {
        path: out.clone(),
        source,
    })?;
    let started = Instant::now();
    let grid = Grid::new(options.quick, options.seed);
    let progress = Progress::new(5);

    let pose = pose_range::run(&grid.pose, &progress);
    write_text(out, "pose_range.csv", &pose_csv(&pose))?;
    plot::pose_range(&out.join("pose_range.png"), &pose)?;

    let noise = noise::run(&grid.noise, &progress);
    write_text(out, "noise.csv", &noise_csv(&noise))?;
    plot::noise(&out.join("noise.png"), &noise)?;

    let shape = shape::run(&grid.shape, &progress);
    write_text(out, "shape.csv", &shape_csv(&shape))?;
    plot::shape(&out.join("shape.png"), &shape)?;

    let camera = camera::run(&grid.camera, &progress);
    write_text(out, "camera.csv", &camera_csv(&camera))?;
    plot::camera(&out.join("camera.png"), &camera)?;

    let work = out.join(".modes-work");
    let modes = modes::run(&grid.modes, &work, &progress)?;
    let _ = std::fs::remove_dir_all(&work);
    write_text(out, "modes.csv", &modes_csv(&modes))?;
    plot::modes(&out.join("modes.png"), &modes)?;

    let results = Results {
        grid,
        pose,
        noise,
        shape,
        camera,
        modes,
        seconds: started.elapsed().as_secs_f64(),
        quick: options.quick,
        seed: options.seed,
    };
    write_text(out, "report.md", &report::markdown(&results))?;
    Ok(results)
}
