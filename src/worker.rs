//! The background worker the app drives: commands in, events out, over channels (the house
//! style of rerun). The worker thread owns the heavy state (scene, forest, last fit); the UI
//! only drains events each frame and never blocks. Cancel is a shared flag checked between
//! frames and between Gauss–Newton steps; a panic inside a job becomes an error event and the
//! worker keeps serving.

use crate::appearance::{Appearance, ForestParams, ProbabilityMaps, SampleCache, TrainingSet};
use crate::error::Error;
use crate::fit::Model;
use crate::fit::config::{FitConfig, Mode};
use crate::fit::tracker::{TrackOptions, TrackedFrame, initial_state, track};
use crate::geometry::Affine;
use crate::scene::{Scene, Seeds};
use crossbeam_channel::{Receiver, Sender, unbounded};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;

/// What the UI asks for.
pub enum Command {
    /// A scene folder, its scene.json, or "demo".
    LoadScene(String),
    /// Use a scene the UI already holds (e.g. with freshly painted seeds).
    UseScene(Arc<Scene>),
    /// Replace the seeds of the scene in use (the app's painted strokes).
    SetSeeds(Seeds),
    /// Use a forest the UI already holds (a loaded session), or none (a session saved before
    /// training).
    SetAppearance(Option<Arc<Appearance>>),
    /// Train the forest (its held-out figure follows on [`Command::Validate`]).
    Train(ForestParams),
    /// The held-out figure of the forest the last Train made ([`Event::Validated`]); sent after
    /// the visible frame's maps are asked for, so the user sees them first.
    Validate,
    /// Per-class probabilities of one frame in every view: a coarse map first, then the full.
    Classify {
        frame: usize,
        /// Echoed in the maps' events: the app takes only the answer to its latest request.
        request: u64,
    },
    /// Automatic initial pose on a frame.
    Initialise {
        frame: usize,
    },
    /// Track an inclusive frame range from `start` (or the scene's/automatic initial pose).
    Track {
        mode: Mode,
        frames: (usize, usize),
        start: Option<Affine>,
    },
    /// Write tracked frames as `endofuse track` does (File → Export).
    Export(Box<crate::export::ExportJob>),
    /// Assemble a scene folder from a patient's files (File → New scene).
    NewScene(Box<crate::newscene::NewSceneOptions>),
    Shutdown,
}

/// Which long job an event is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Task {
    Load,
    Train,
    Classify,
    /// The held-out figure after a Train.
    Validate,
    Initialise,
    Track,
    Export,
    NewScene,
}

/// What the worker tells the UI.
pub enum Event {
    /// A scene and the model of its structures (the joint shape model built once, here).
    SceneLoaded {
        scene: Arc<Scene>,
        model: Arc<Model>,
    },
    Trained(Arc<Appearance>),
    /// Probabilities of `frame`, one map per camera; `coarse`: the quick first map (classified
    /// at half resolution), the full one follows.
    Probabilities {
        frame: usize,
        maps: Arc<Vec<ProbabilityMaps>>,
        coarse: bool,
        request: u64,
    },
    /// The forest `of` with its held-out figure: replaces `of` where it is still in use.
    Validated {
        of: Arc<Appearance>,
        validated: Arc<Appearance>,
    },
    Initialised(Affine),
    Progress {
        task: Task,
        done: usize,
        total: usize,
    },
    Frame(Box<TrackedFrame>),
    /// Dice per visible structure and camera of a tracked frame, where ground truth exists.
    Dice {
        frame: usize,
        dice: Vec<(String, f64)>,
    },
    /// What a long job is doing now (a stage without a count: "meshing the kidney").
    Stage {
        task: Task,
        what: String,
    },
    /// A new scene folder is ready at `scene_json`; `notes` are what the user should check
    /// (views of different lengths, an odd-width side-by-side video).
    SceneCreated {
        scene_json: std::path::PathBuf,
        notes: Vec<String>,
    },
    Finished(Task),
    Cancelled(Task),
    /// One line for the user; the worker keeps running.
    Failed {
        task: Task,
        message: String,
    },
}

/// Handle to the worker thread.
pub struct Worker {
    commands: Sender<(u64, Command)>,
    events: Receiver<Event>,
    cancel: Arc<AtomicBool>,
    /// Commands sent so far, and the last one a cancel applies to: a cancel stops every
    /// command sent before it (running or queued) and none sent after.
    sent: AtomicU64,
    cancelled_upto: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
}

struct State {
    scene: Option<Arc<Scene>>,
    /// The model of the scene's structures (seeds change the scene, never its structures).
    model: Option<Arc<Model>>,
    appearance: Option<Arc<Appearance>>,
    /// What the last Train learned from, with its parameters and forest, until validated.
    training: Option<(TrainingSet, ForestParams, Arc<Appearance>)>,
    /// The seeded images' samples of the scene in use (cleared with the scene).
    samples: SampleCache,
    /// The fit's configuration for placing and tracking.
    config: FitConfig,
}

impl Worker {
    pub fn spawn() -> Self {
        let (commands, inbox) = unbounded::<(u64, Command)>();
        let cancelled_upto = Arc::new(AtomicU64::new(0));
        let upto = cancelled_upto.clone();
        let (outbox, events) = unbounded::<Event>();
        let cancel = Arc::new(AtomicBool::new(false));
        let flag = cancel.clone();
        let thread = std::thread::Builder::new()
            .name("endofuse-worker".into())
            .spawn(move || {
                let mut state = State {
                    scene: None,
                    model: None,
                    appearance: None,
                    training: None,
                    samples: SampleCache::default(),
                    config: FitConfig::default(),
                };
                for (id, command) in inbox {
                    if matches!(command, Command::Shutdown) {
                        break;
                    }
                    flag.store(id <= upto.load(Ordering::SeqCst), Ordering::SeqCst);
                    let task = task_of(&command);
                    log::debug!("worker: {task:?} starts");
                    let event = guarded(task, || run(command, &mut state, &flag, &outbox));
                    if outbox.send(event).is_err() {
                        break;
                    }
                }
            })
            .map_err(|e| log::error!("cannot start the worker thread: {e}"))
            .ok();
        Self {
            commands,
            events,
            cancel,
            sent: AtomicU64::new(0),
            cancelled_upto,
            thread,
        }
    }

    /// Queues a command; false if the worker is gone.
    pub fn send(&self, command: Command) -> bool {
        let id = self.sent.fetch_add(1, Ordering::SeqCst) + 1;
        self.commands.send((id, command)).is_ok()
    }

    /// Stops the running job and any queued before now (answered within one Gauss–Newton
    /// step or frame).
    pub fn cancel(&self) {
        self.cancelled_upto
            .store(self.sent.load(Ordering::SeqCst), Ordering::SeqCst);
        self.cancel.store(true, Ordering::SeqCst);
    }

    /// Every event waiting now, without blocking.
    pub fn drain(&self) -> Vec<Event> {
        self.events.try_iter().collect()
    }

    /// Waits for the next event (tests and the CLI; the UI uses [`Worker::drain`]).
    pub fn wait(&self, timeout: std::time::Duration) -> Option<Event> {
        self.events.recv_timeout(timeout).ok()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.cancel();
        let _ = self.commands.send((u64::MAX, Command::Shutdown));
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Runs one job and says how it ended: finished, cancelled, failed with its error, or failed
/// with the panic's message (the worker keeps serving after a panic inside a job).
fn guarded(task: Task, job: impl FnOnce() -> Result<(), Error>) -> Event {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)) {
        Ok(Ok(())) => Event::Finished(task),
        Ok(Err(Error::Cancelled)) => Event::Cancelled(task),
        Ok(Err(e)) => {
            log::info!("worker: {task:?} failed: {e}");
            Event::Failed {
                task,
                message: e.to_string(),
            }
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            log::error!("worker: {task:?} panicked: {what}");
            Event::Failed {
                task,
                message: format!("internal error: {what}"),
            }
        }
    }
}

fn task_of(c: &Command) -> Task {
    match c {
        Command::LoadScene(_) | Command::UseScene(_) | Command::SetSeeds(_) => Task::Load,
        Command::Train(_) | Command::SetAppearance(_) => Task::Train,
        Command::Classify { .. } => Task::Classify,
        Command::Validate => Task::Validate,
        Command::Initialise { .. } => Task::Initialise,
        Command::Track { .. } => Task::Track,
        Command::Export(_) | Command::Shutdown => Task::Export,
        Command::NewScene(_) => Task::NewScene,
    }
}

/// Hands an event to the UI. When the UI has gone (the window closed) nobody is waiting for
/// the rest of the job: it stops as if cancelled.
fn emit(out: &Sender<Event>, event: Event) -> Result<(), Error> {
    out.send(event).map_err(|_| Error::Cancelled)
}

fn need_scene(state: &State) -> Result<Arc<Scene>, Error> {
    state
        .scene
        .clone()
        .ok_or_else(|| crate::error::input_err("scene", "no scene is loaded"))
}

fn need_model(state: &State) -> Result<Arc<Model>, Error> {
    state
        .model
        .clone()
        .ok_or_else(|| crate::error::input_err("scene", "no scene is loaded"))
}

fn need_appearance(state: &State) -> Result<Arc<Appearance>, Error> {
    state
        .appearance
        .clone()
        .ok_or_else(|| crate::error::input_err("seeds", "train the forest first"))
}

fn run(
    command: Command,
    state: &mut State,
    cancel: &Arc<AtomicBool>,
    out: &Sender<Event>,
) -> Result<(), Error> {
    match command {
        Command::LoadScene(spec) => {
            let scene = Arc::new(crate::open::scene(&spec)?);
            let model = Arc::new(Model::build(&scene)?);
            state.scene = Some(scene.clone());
            state.model = Some(model.clone());
            state.appearance = None;
            state.training = None;
            state.samples = SampleCache::default();
            emit(out, Event::SceneLoaded { scene, model })?;
        }
        Command::UseScene(scene) => {
            state.model = Some(Arc::new(Model::build(&scene)?));
            state.scene = Some(scene);
            state.appearance = None;
            state.training = None;
            state.samples = SampleCache::default();
        }
        Command::SetSeeds(seeds) => {
            let scene = need_scene(state)?;
            state.scene = Some(Arc::new(scene.with_seeds(seeds)));
        }
        Command::SetAppearance(a) => {
            state.appearance = a;
            state.training = None;
        }
        Command::Train(params) => {
            let scene = need_scene(state)?;
            let set = TrainingSet::collect(&scene, Some(cancel), Some(&state.samples))?;
            let model = Arc::new(Appearance::fit(&set, &params)?);
            emit(out, Event::Trained(model.clone()))?;
            state.appearance = Some(model.clone());
            state.training = Some((set, params, model));
        }
        Command::Validate => {
            // Only the forest in use, once: a later Train or a loaded forest replaced it.
            if let Some((set, params, of)) = state.training.take()
                && state
                    .appearance
                    .as_ref()
                    .is_some_and(|a| Arc::ptr_eq(a, &of))
            {
                let validated = Arc::new(Appearance {
                    validation: set.validate(&params),
                    ..(*of).clone()
                });
                state.appearance = Some(validated.clone());
                emit(out, Event::Validated { of, validated })?;
            }
        }
        Command::Classify { frame, request } => {
            let scene = need_scene(state)?;
            let appearance = need_appearance(state)?;
            for coarse in [true, false] {
                let mut maps = Vec::new();
                for c in 0..scene.cameras.len() {
                    if cancel.load(Ordering::SeqCst) {
                        return Err(Error::Cancelled);
                    }
                    let image = scene.frame(c, frame)?;
                    maps.push(if coarse {
                        appearance.classify_coarse(&image)
                    } else {
                        appearance.classify_frame(&image)
                    });
                }
                emit(
                    out,
                    Event::Probabilities {
                        frame,
                        maps: Arc::new(maps),
                        coarse,
                        request,
                    },
                )?;
            }
        }
        Command::Initialise { frame } => {
            let scene = need_scene(state)?;
            let appearance = need_appearance(state)?;
            let model = need_model(state)?;
            let affine = crate::fit::init::automatic_pose(
                &scene,
                &model,
                &appearance,
                &state.config,
                frame,
                crate::fit::init::Placing::Start,
                Some(cancel),
            )?;
            emit(out, Event::Initialised(affine))?;
        }
        Command::Track {
            mode,
            frames,
            start,
        } => {
            let scene = need_scene(state)?;
            let appearance = need_appearance(state)?;
            if frames.0 > frames.1 || frames.1 >= scene.frame_count {
                return Err(crate::error::input_err(
                    "frames",
                    format!(
                        "{}..{} is not inside 0..{}",
                        frames.0,
                        frames.1,
                        scene.frame_count - 1
                    ),
                ));
            }
            let model = need_model(state)?;
            // Ground truth checked whole first: a bad image met mid-run stopped the tracking.
            scene.decode_ground_truth_of(frames.0..=frames.1, &|_, _| {})?;
            // A fit or a placement the app passes is taken as it is; the scene's own pose
            // (the app starts from it until one replaces it) starts as `endofuse track` starts.
            let affine = match start.filter(|a| Some(*a) != scene.initial_pose) {
                Some(a) => a,
                None => crate::fit::init::starting_pose(
                    &scene,
                    &model,
                    &appearance,
                    &state.config,
                    frames.0,
                    Some(cancel),
                )?,
            };
            let options = TrackOptions::new(mode, frames, scene.cameras[0].width)
                .with_config(state.config.clone())
                .with_cancel(Some(cancel.clone()));
            let total = frames.1 + 1 - frames.0;
            let mut done = 0;
            track(
                &scene,
                &model,
                &appearance,
                initial_state(&scene, &model, affine),
                &options,
                Some(cancel),
                &mut |f| {
                    done += 1;
                    emit(
                        out,
                        Event::Progress {
                            task: Task::Track,
                            done,
                            total,
                        },
                    )?;
                    let dice = crate::track::frame_dice(&scene, &f)?;
                    let frame = f.frame;
                    emit(out, Event::Frame(Box::new(f)))?;
                    if !dice.is_empty() {
                        emit(out, Event::Dice { frame, dice })?;
                    }
                    Ok(())
                },
            )?;
        }
        Command::Export(job) => {
            let metrics = job.run()?;
            log::info!(
                "exported {} frames to {}",
                metrics.frames,
                job.dir.display()
            );
        }
        Command::NewScene(options) => {
            let report = crate::newscene::new_scene(&options, &|stage| {
                let _ = out.send(Event::Stage {
                    task: Task::NewScene,
                    what: format!("New scene: {stage}…"),
                });
            })?;
            emit(
                out,
                Event::SceneCreated {
                    notes: report.all_notes(),
                    scene_json: report.scene_json,
                },
            )?;
        }
        Command::Shutdown => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    fn until(worker: &Worker, mut want: impl FnMut(&Event) -> bool) -> Vec<Event> {
        let mut seen = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(120);
        while Instant::now() < deadline {
            if let Some(e) = worker.wait(Duration::from_millis(200)) {
                let stop = want(&e);
                seen.push(e);
                if stop {
                    return seen;
                }
            }
        }
        panic!("the worker did not answer in time");
    }

    #[test]
    fn loads_trains_tracks_streams_frames_and_survives_errors_and_panics() {
        let worker = Worker::spawn();
        // Errors are events, not a dead worker.
        worker.send(Command::Train(ForestParams::default()));
        let ev = until(&worker, |e| matches!(e, Event::Failed { .. }));
        assert!(
            matches!(ev.last(), Some(Event::Failed { task: Task::Train, message }) if message.contains("no scene"))
        );
        // A panic inside a job is a failed job, with the panic's words.
        assert!(matches!(
            guarded(Task::Track, || panic!("boom")),
            Event::Failed { task: Task::Track, message } if message.contains("boom")
        ));
        assert!(matches!(
            guarded(Task::Train, || Err(Error::Cancelled)),
            Event::Cancelled(Task::Train)
        ));
        worker.send(Command::LoadScene("/no/such/scene".into()));
        until(&worker, |e| {
            matches!(
                e,
                Event::Failed {
                    task: Task::Load,
                    ..
                }
            )
        });

        let scene = crate::synth::memory_scene(&crate::synth::SynthOptions {
            frames: 4,
            width: 240,
            height: 136,
            ..crate::synth::SynthOptions::default()
        })
        .unwrap();
        worker.send(Command::UseScene(Arc::new(scene)));
        worker.send(Command::Train(ForestParams {
            trees: 5,
            ..ForestParams::default()
        }));
        let ev = until(&worker, |e| matches!(e, Event::Finished(Task::Train)));
        let trained = ev
            .iter()
            .find_map(|e| match e {
                Event::Trained(a) => Some(a.clone()),
                _ => None,
            })
            .expect("a forest");
        assert!(trained.stats.samples > 100);
        assert!(trained.validation.is_none(), "the figure follows the maps");
        // The visible frame's maps: a coarse one first, then the full one, both full-size.
        worker.send(Command::Classify {
            frame: 3,
            request: 1,
        });
        let ev = until(&worker, |e| matches!(e, Event::Finished(Task::Classify)));
        let maps: Vec<(bool, usize, usize)> = ev
            .iter()
            .filter_map(|e| match e {
                Event::Probabilities { maps, coarse, .. } => {
                    Some((*coarse, maps[0].width, maps[0].height))
                }
                _ => None,
            })
            .collect();
        assert_eq!(maps, vec![(true, 240, 136), (false, 240, 136)]);
        // Then the held-out figure, on the same forest.
        worker.send(Command::Validate);
        let ev = until(&worker, |e| matches!(e, Event::Finished(Task::Validate)));
        let Some(Event::Validated { of, validated }) =
            ev.iter().find(|e| matches!(e, Event::Validated { .. }))
        else {
            panic!("no held-out figure");
        };
        assert!(Arc::ptr_eq(of, &trained));
        assert_eq!(validated.forest, trained.forest);
        assert!(validated.validation.as_ref().unwrap().balanced_accuracy > 0.8);
        // Once only: a second Validate has nothing left to check.
        worker.send(Command::Validate);
        let ev = until(&worker, |e| matches!(e, Event::Finished(Task::Validate)));
        assert!(!ev.iter().any(|e| matches!(e, Event::Validated { .. })));
        worker.send(Command::Track {
            mode: Mode::LS,
            frames: (0, 3),
            start: None,
        });
        let ev = until(&worker, |e| {
            matches!(e, Event::Finished(Task::Track) | Event::Failed { .. })
        });
        let frames: Vec<usize> = ev
            .iter()
            .filter_map(|e| {
                if let Event::Frame(f) = e {
                    Some(f.frame)
                } else {
                    None
                }
            })
            .collect();
        assert_eq!(frames, vec![0, 1, 2, 3], "frames stream in order");

        // Cancel: a long job stops and says so.
        worker.send(Command::Track {
            mode: Mode::LS,
            frames: (0, 3),
            start: None,
        });
        worker.cancel();
        let ev = until(&worker, |e| {
            matches!(e, Event::Cancelled(_) | Event::Finished(Task::Track))
        });
        assert!(
            matches!(ev.last(), Some(Event::Cancelled(Task::Track))),
            "cancelled, not finished"
        );
        // A command sent after the cancel runs normally.
        worker.send(Command::Track {
            mode: Mode::LS,
            frames: (0, 0),
            start: None,
        });
        let ev = until(&worker, |e| {
            matches!(
                e,
                Event::Finished(Task::Track) | Event::Cancelled(_) | Event::Failed { .. }
            )
        });
        assert!(matches!(ev.last(), Some(Event::Finished(Task::Track))));
    }
}
