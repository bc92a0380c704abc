//! endofuse core: fuses preoperative CT models with stereo endoscopic video (Nosrati et al.,
//! multi-structure segmentation and non-rigid pose estimation). Knows nothing of the GUI; the
//! app and the CLI are two faces over these functions.

#[cfg(feature = "gui")]
pub mod app;
pub mod appearance;
pub mod calib;
pub mod classify;
pub mod cpu;
pub mod ctimport;
pub mod error;
pub mod experiments;
pub mod export;
pub mod fit;
pub mod geometry;
pub mod info;
pub mod newscene;
pub mod open;
pub mod overlay;
pub mod plane;
pub mod pool;
pub mod render;
pub mod results_dir;
pub mod rng;
pub mod scene;
pub mod session;
pub mod shape;
pub mod strokes;
pub mod synth;
pub mod track;
pub mod video;
pub mod worker;

pub use error::{Error, InputError, Result};
pub use scene::Scene;
