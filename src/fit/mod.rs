//! The fit (paper §II-B, II-C): the global affine T, the joint shape weights W and the cameras'
//! intrinsics π that minimise eq. 4 in every view, frame after frame.

pub mod energy;
pub mod init;
pub mod model;
pub mod motion;
pub mod optimizer;
pub mod probability;
pub mod profile;
pub mod stereo;
pub mod tracker;
pub mod zoom;

pub use energy::{Block, EnergyParams, FitState, FrameContext};
pub use model::Model;
pub use optimizer::{FitParams, FrameFit, Mode, fit_frame};
