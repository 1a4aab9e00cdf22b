//! The one error type of the renderer. Library code never prints: every failure (no adapter,
//! a device that cannot be created, a validation error caught by an error scope, a bad
//! argument) comes back to the caller as a [`RenderError`] with a message a user can act on.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum RenderError {
    /// No Vulkan or GL adapter at all: the machine has no GPU driver and no software driver.
    #[error(
        "no GPU adapter (Vulkan/GL) found; install mesa-vulkan-drivers or use the CPU renderer ({0})"
    )]
    NoAdapter(String),
    /// The adapter exists but refused to open a device with the limits we asked for.
    #[error("the GPU adapter {adapter} could not open a device: {reason}")]
    NoDevice { adapter: String, reason: String },
    /// An image size of zero or beyond the device's largest texture.
    #[error("image size {width}×{height} is not drawable on this device (1 to {max} per side)")]
    BadSize { width: u32, height: u32, max: u32 },
    /// A cell id beyond the uploaded mesh's cells.
    #[error("cell {cell} does not exist (the uploaded mesh has {cells} cells)")]
    UnknownCell { cell: u32, cells: usize },
    /// `render` or `time_frames` before `upload`.
    #[error("no mesh uploaded: call GpuRenderer::upload first")]
    NoMesh,
    /// The mesh does not fit in one buffer of this device.
    #[error("the mesh needs a {needed}-byte buffer; this device allows at most {max} bytes")]
    MeshTooLarge { needed: u64, max: u64 },
    /// A mesh whose triangles name vertices it does not have, or whose cell ranges do not tile
    /// its triangles.
    #[error("invalid mesh: {0}")]
    BadMesh(String),
    /// wgpu reported a validation, out-of-memory or internal error, or the device was lost.
    #[error("GPU error: {0}")]
    Gpu(String),
}
