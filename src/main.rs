//! The `endofuse` command line (CONTRACT §1). Thin: every command calls the core library and
//! maps its errors to exit codes (2 for bad input, with one line naming the file).

use anyhow::Result;
use clap::{Parser, Subcommand};
use endofuse::scene::FrameCheck;
use endofuse::synth::SynthOptions;
use endofuse::{Error, Scene};
use std::path::PathBuf;
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
    /// Validate a scene and print what it holds (SCENE: folder, scene.json, or `demo`).
    Info {
        scene: String,
        /// Only read frame headers instead of decoding every frame.
        #[arg(long)]
        quick: bool,
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
        #[arg(long, default_value_t = 960)]
        width: u32,
        #[arg(long, default_value_t = 540)]
        height: u32,
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
    },
}

fn main() -> ExitCode {
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
        None => {
            // The desktop app arrives with its issue; until then say what the binary offers.
            use clap::CommandFactory;
            Cli::command().print_help()?;
            println!(
                "\n\nThe desktop app is not part of this build yet; the commands above work headless."
            );
            Ok(())
        }
        Some(Command::Info { scene, quick }) => {
            let check = if quick {
                FrameCheck::Headers
            } else {
                FrameCheck::Decode
            };
            let scene = Scene::open(&scene, check)?;
            print!("{}", endofuse::info::summary(&scene));
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
        }) => {
            let options = SynthOptions {
                frames,
                seed,
                noise,
                width,
                height,
                views,
                tools: !no_tools,
                zoom: !no_zoom,
                smoke: !no_smoke,
                ..SynthOptions::default()
            };
            let started = std::time::Instant::now();
            endofuse::synth::write_scene(&out, &options, &|done, total| {
                eprint!("\rsynth: frame {done}/{total}");
                if done == total {
                    eprintln!();
                }
            })?;
            eprintln!(
                "synth: wrote {} in {:.1} s",
                out.display(),
                started.elapsed().as_secs_f64()
            );
            Ok(())
        }
    }
}
