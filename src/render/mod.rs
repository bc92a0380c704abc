//! The fit renderer on the CPU: rasterised silhouettes, depth and triangle ids per view, and
//! the distance maps the energy is built on.

pub mod distance;
pub mod raster;

pub use distance::{signed_distance, squared_edt};
pub use raster::{RasterOptions, RenderObject, ViewRaster, rasterize};
