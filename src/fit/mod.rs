//! The fit (paper §II-B, II-C): the global affine T, the joint shape weights W and the cameras'
//! intrinsics π that minimise eq. 4 in every view, frame after frame.
//!
//! Every tuning constant is in [`config`]. The parts, in the order the data flow: [`model`] (structures and joint shape model),
//! [`state`] (what is estimated, and its parameter blocks), [`context`] (a frame's cameras and
//! classes, and how blocks move model points), the image terms [`lines`] and [`stereo`] and the
//! [`priors`], combined through [`objective`] by the [`optimizer`]; [`information`] and
//! [`hidden_region`] say how sure the fit is of each hidden structure's place; [`init`] places the model
//! when the scene gives no pose, and [`tracker`] carries the fit from frame to frame (with
//! [`motion`] and [`zoom`]). [`probability`] evaluates the forest lazily where the lines look.

pub mod config;
pub mod context;
pub mod depth_margin;
pub mod hidden_region;
pub mod information;
pub mod init;
pub mod lines;
pub mod model;
pub mod motion;
pub mod objective;
pub mod optimizer;
pub mod priors;
pub mod probability;
pub mod profile;
pub mod state;
pub mod stereo;
pub mod tracker;
pub mod zoom;

pub use config::{FitConfig, FitParams, Mode, Phase, Zoom};
pub use context::FrameContext;
pub use lines::EnergyParams;
pub use model::Model;
pub use optimizer::{FrameFit, fit_frame};
pub use state::{Block, FitState};
