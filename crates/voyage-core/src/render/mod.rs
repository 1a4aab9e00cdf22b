//! Rendering without a GPU: the reference rasterizer (depth and triangle-id buffers), the
//! endoscope shading both renderers share, the surface laid out by cell, and the visibility
//! strategies that choose which cells to draw (paper §4.3); close-up volume rendering of
//! the CT in a small box (paper Fig. 9); and the translucency view, the surface coloured by
//! what lies beneath it.

pub mod closeup;
pub mod mesh;
pub mod raster;
pub mod shading;
pub mod survey;
pub mod translucency;
pub mod visibility;

pub use closeup::{CloseupBox, TfPoint, TransferFunction, render_closeup};
pub use mesh::CellMesh;
pub use raster::{Frame, NO_TRIANGLE, Pixel, Rasterizer, View, render_rgba, shade};
pub use shading::Lighting;
pub use survey::{StrategyStats, Survey, look_around, survey};
pub use translucency::{
    Material, Translucency, TranslucencyOptions, render_translucency, surface_point,
};
pub use visibility::{Drawn, Strategy, Visibility};
