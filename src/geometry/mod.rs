//! Geometry: the camera model (eq. 10–11), poses (eq. 2), triangle meshes and their files.

pub mod camera;
pub mod mesh;
pub mod mesh_io;
pub mod pose;

pub use camera::{Camera, Extrinsics, Intrinsics};
pub use mesh::Mesh;
pub use pose::{Affine, RigidPose};
