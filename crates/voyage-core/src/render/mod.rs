//! Rendering without a GPU: the reference rasterizer (depth and triangle-id buffers), the
//! endoscope shading both renderers share, the surface laid out by cell, and the visibility
//! strategies that choose which cells to draw (paper §4.3).

pub mod mesh;
pub mod raster;
pub mod shading;
pub mod survey;
pub mod visibility;

pub use mesh::CellMesh;
pub use raster::{Frame, NO_TRIANGLE, Rasterizer, View, render_rgba, shade};
pub use shading::Lighting;
pub use survey::{StrategyStats, Survey, look_around, survey};
pub use visibility::{Drawn, Strategy, Visibility};
