//! Rendering without a GPU: the reference rasterizer (depth and triangle-id buffers), the
//! endoscope shading both renderers share, the surface laid out by cell, and the visibility
//! strategies that choose which cells to draw (paper §4.3).

pub mod mesh;
pub mod shading;

pub use mesh::CellMesh;
pub use shading::Lighting;
