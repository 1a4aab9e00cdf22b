//! The GPU renderer of voyage: the endoscopic view of the colon surface, drawn with wgpu.
//!
//! It knows nothing of the viewer. voyage-core decides *what* to draw (a [`CellMesh`] and,
//! per frame, the list of cells the visibility step kept); this crate draws exactly that,
//! lit exactly like the CPU reference renderer (`voyage_view`), so that every image
//! test can use the deterministic CPU renderer and the GPU is checked against it.
//!
//! Headless use (tests, benchmarks, export):
//!
//! ```no_run
//! # use voyage_render::GpuRenderer;
//! # fn demo(mesh: &voyage_view::CellMesh, camera: &voyage_nav::Camera) -> Result<(), voyage_render::RenderError> {
//! let mut gpu = GpuRenderer::new_headless()?;
//! gpu.upload(mesh)?;
//! let cells: Vec<u32> = (0..mesh.cells() as u32).collect();
//! let rgba = gpu.render(camera, &cells, 512, 512, &Default::default())?;
//! # Ok(()) }
//! ```
//!
//! In the GUI, [`GpuRenderer::for_pass`] takes the window's device and
//! [`GpuRenderer::draw_in_pass`] draws a frame's [`DrawList`] straight into the window's
//! render pass;
//! [`PixelImages`] copies the panels' images into the same pass pixel for pixel.
//!
//! [`CellMesh`]: voyage_view::CellMesh

mod device;
mod error;
mod mesh;
mod pipeline;
mod pixels;
mod renderer;
mod target;
mod uniforms;

pub use error::RenderError;
pub use pixels::{PIXEL_FORMAT, PixelImages};
pub use renderer::{DrawList, FrameTimes, GpuRenderer, WARM_UP_FRAMES};
pub use target::{COLOR_FORMAT, DEPTH_FORMAT, OffscreenTarget, padded_bytes_per_row};
pub use uniforms::Uniforms;
