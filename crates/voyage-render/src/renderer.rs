//! [`GpuRenderer`]: the endoscopic view on a GPU. It owns the device handles, the pipeline
//! and the uploaded surface, and draws any list of cells either into textures the caller
//! owns ([`GpuRenderer::draw`], for the GUI) or into a cached offscreen target that it reads
//! back ([`GpuRenderer::render`], for tests and image export) or only times
//! ([`GpuRenderer::time_frames`], for `voyage bench render`).

use std::time::Instant;

use voyage_nav::Camera;
use voyage_view::{CellMesh, Drawn, Lighting, View};

use crate::{
    device,
    error::RenderError,
    mesh::{Frustum, GpuMesh},
    pipeline::EndoscopePipeline,
    target::OffscreenTarget,
    uniforms::Uniforms,
};

/// One frame's draws ([`GpuRenderer::draw_list`]): index ranges into the uploaded mesh.
#[derive(Clone, Debug, Default)]
pub struct DrawList {
    ranges: Vec<std::ops::Range<u32>>,
}

impl DrawList {
    /// Triangles the list draws.
    pub fn triangles(&self) -> usize {
        self.ranges.iter().map(|r| r.len() / 3).sum()
    }
}

/// Frames rendered before timing starts: the first frames pay for pipeline compilation,
/// first-touch allocation and (on lavapipe) thread start-up.
pub const WARM_UP_FRAMES: usize = 3;

pub struct GpuRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: EndoscopePipeline,
    mesh: Option<GpuMesh>,
    target: Option<OffscreenTarget>,
    /// Leave out the chunks of a cell that lie wholly outside the view (on by default; the
    /// image is the same either way).
    chunk_culling: bool,
}

/// What [`GpuRenderer::time_frames`] measured: wall time from recording a frame to the GPU
/// having finished it, per frame, after [`WARM_UP_FRAMES`] untimed frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameTimes {
    pub frames: usize,
    pub mean_ms: f64,
    pub min_ms: f64,
    pub max_ms: f64,
    /// 1000 / mean_ms.
    pub fps: f64,
}

impl GpuRenderer {
    /// Opens a device of its own without a window: Vulkan (a GPU, or lavapipe on machines
    /// without one), else GL. Fails with [`RenderError::NoAdapter`] when neither exists.
    pub fn new_headless() -> Result<Self, RenderError> {
        let (device, queue) = device::open_headless()?;
        Ok(Self::from_device(device, queue))
    }

    /// Uses a device someone else opened (the GUI's, so that the view can be drawn into a
    /// texture the GUI shows). The device must allow the texture sizes and buffer sizes used.
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue) -> Self {
        Self::for_pass(device, queue, crate::COLOR_FORMAT)
    }

    /// Uses a device someone else opened to draw inside their render passes
    /// ([`Self::draw_in_pass`]), whose colour target has `color_format` (not sRGB: the shader
    /// applies the display gamma) and whose depth attachment is [`crate::DEPTH_FORMAT`].
    /// This is how the GUI draws the view straight into the window, with no texture between.
    pub fn for_pass(
        device: wgpu::Device,
        queue: wgpu::Queue,
        color_format: wgpu::TextureFormat,
    ) -> Self {
        let pipeline = EndoscopePipeline::with_format(&device, color_format);
        GpuRenderer {
            device,
            queue,
            pipeline,
            mesh: None,
            target: None,
            chunk_culling: true,
        }
    }

    /// Writes the camera and lighting for a following [`Self::draw_in_pass`] of a
    /// `width × height` viewport (through the queue: call it before the pass is submitted).
    pub fn prepare(
        &self,
        camera: &Camera,
        width: u32,
        height: u32,
        lighting: &Lighting,
    ) -> Result<(), RenderError> {
        self.check_size(width, height)?;
        let uniforms = Uniforms::new(camera, width, height, lighting);
        self.queue
            .write_buffer(&self.pipeline.uniforms, 0, bytemuck::bytes_of(&uniforms));
        Ok(())
    }

    /// What one frame of `cells` seen by `camera` at `width × height` draws: the cells'
    /// index ranges less their chunks outside the view (if chunk culling is on). Made once
    /// per frame, for [`Self::draw_in_pass`] and for the frame's statistics.
    pub fn draw_list(
        &self,
        cells: &[u32],
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<DrawList, RenderError> {
        let mesh = self.mesh.as_ref().ok_or(RenderError::NoMesh)?;
        Ok(DrawList {
            ranges: self.ranges(mesh, cells, camera, width, height)?,
        })
    }

    /// [`Self::draw_list`] of what a visibility pass chose (`drawn.cells`), each cell also
    /// without its chunks that lie wholly outside the window its portals leave open
    /// (`drawn.rects`): exact for the same reason as the cells themselves.
    pub fn draw_list_within(
        &self,
        drawn: &Drawn,
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<DrawList, RenderError> {
        if !self.chunk_culling || drawn.rects.len() != drawn.cells.len() {
            return self.draw_list(&drawn.cells, camera, width, height);
        }
        let mesh = self.mesh.as_ref().ok_or(RenderError::NoMesh)?;
        Ok(DrawList {
            ranges: mesh.draw_ranges_within(
                &drawn.cells,
                &drawn.rects,
                &Frustum::new(camera, width, height),
                &View::new(camera, width, height),
            )?,
        })
    }

    /// Draws `list` into a render pass someone else began (viewport and scissor set by
    /// them), with the uniforms of the last [`Self::prepare`].
    pub fn draw_in_pass(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        list: &DrawList,
    ) -> Result<(), RenderError> {
        let mesh = self.mesh.as_ref().ok_or(RenderError::NoMesh)?;
        record(&self.pipeline, mesh, pass, list.ranges.clone());
        Ok(())
    }

    /// Turns the leaving out of chunks outside the view on or off (for tests and benchmarks:
    /// the image must not change).
    pub fn set_chunk_culling(&mut self, on: bool) {
        self.chunk_culling = on;
    }

    fn ranges(
        &self,
        mesh: &GpuMesh,
        cells: &[u32],
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<Vec<std::ops::Range<u32>>, RenderError> {
        if self.chunk_culling {
            mesh.draw_ranges_in(cells, &Frustum::new(camera, width, height))
        } else {
            mesh.draw_ranges(cells)
        }
    }

    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// Name, backend, device type and driver of the adapter, e.g.
    /// `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu, llvmpipe Mesa 22.3.6 (LLVM 15.0.6))`.
    pub fn adapter_summary(&self) -> String {
        device::summary(&self.device)
    }

    /// Uploads the surface (replacing any earlier one). Fails if the mesh is inconsistent or
    /// too large for one buffer of this device.
    pub fn upload(&mut self, mesh: &CellMesh) -> Result<(), RenderError> {
        let gpu = self.scoped(|| GpuMesh::new(&self.device, mesh))?;
        self.mesh = Some(gpu);
        Ok(())
    }

    /// Number of cells of the uploaded mesh (0 before [`Self::upload`]).
    pub fn cells(&self) -> usize {
        self.mesh.as_ref().map_or(0, |m| m.cell_indices.len())
    }

    /// Records the endoscopic view of `cells` into `color` ([`crate::COLOR_FORMAT`]) and
    /// `depth` ([`crate::DEPTH_FORMAT`]), both `width × height`, clearing them first (black,
    /// depth 1). The uniforms are written through the queue, so a caller drawing twice must
    /// submit between the draws.
    #[allow(clippy::too_many_arguments)]
    pub fn draw(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        camera: &Camera,
        cells: &[u32],
        width: u32,
        height: u32,
        lighting: &Lighting,
    ) -> Result<(), RenderError> {
        let mesh = self.mesh.as_ref().ok_or(RenderError::NoMesh)?;
        self.check_size(width, height)?;
        let ranges = self.ranges(mesh, cells, camera, width, height)?;
        self.draw_ranges(
            encoder, color, depth, camera, ranges, width, height, lighting,
        )
    }

    /// [`Self::draw`] of index ranges already chosen.
    #[allow(clippy::too_many_arguments)]
    fn draw_ranges(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        camera: &Camera,
        ranges: Vec<std::ops::Range<u32>>,
        width: u32,
        height: u32,
        lighting: &Lighting,
    ) -> Result<(), RenderError> {
        let mesh = self.mesh.as_ref().ok_or(RenderError::NoMesh)?;
        let uniforms = Uniforms::new(camera, width, height, lighting);
        self.queue
            .write_buffer(&self.pipeline.uniforms, 0, bytemuck::bytes_of(&uniforms));
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("voyage endoscope"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        record(&self.pipeline, mesh, &mut pass, ranges);
        Ok(())
    }

    /// Renders `cells` seen by `camera` into a `width × height` image and returns it as
    /// tightly packed RGBA8, top row first (the CPU renderer's layout).
    pub fn render(
        &mut self,
        camera: &Camera,
        cells: &[u32],
        width: u32,
        height: u32,
        lighting: &Lighting,
    ) -> Result<Vec<u8>, RenderError> {
        let list = self.draw_list(cells, camera, width, height)?;
        self.render_list(camera, &list, width, height, lighting)
    }

    /// [`Self::render`] of a draw list made before ([`Self::draw_list`],
    /// [`Self::draw_list_within`]).
    pub fn render_list(
        &mut self,
        camera: &Camera,
        list: &DrawList,
        width: u32,
        height: u32,
        lighting: &Lighting,
    ) -> Result<Vec<u8>, RenderError> {
        self.check_size(width, height)?;
        self.ensure_target(width, height);
        let this = &*self;
        this.scoped(|| {
            let target = this.target.as_ref().expect("target was just made");
            let mut encoder =
                this.encode_frame(camera, list.ranges.clone(), width, height, lighting)?;
            target.encode_readback(&mut encoder);
            this.queue.submit([encoder.finish()]);
            target.read(&this.device).map_err(RenderError::Gpu)
        })
    }

    /// Records one frame into the cached offscreen target (made by `ensure_target`).
    fn encode_frame(
        &self,
        camera: &Camera,
        ranges: Vec<std::ops::Range<u32>>,
        width: u32,
        height: u32,
        lighting: &Lighting,
    ) -> Result<wgpu::CommandEncoder, RenderError> {
        let target = self.target.as_ref().expect("target was just made");
        let mut encoder = self.device.create_command_encoder(&Default::default());
        self.draw_ranges(
            &mut encoder,
            &target.color_view,
            &target.depth_view,
            camera,
            ranges,
            width,
            height,
            lighting,
        )?;
        Ok(encoder)
    }

    /// Renders every frame (no readback), each submitted and waited for, after
    /// [`WARM_UP_FRAMES`] untimed frames taken from the start of `frames`. This is what
    /// `voyage bench render` reports as GPU frames/s. An empty list times nothing (zero
    /// frames, 0 frames/s).
    pub fn time_frames(
        &mut self,
        frames: &[(Camera, Vec<u32>)],
        width: u32,
        height: u32,
        lighting: &Lighting,
    ) -> Result<FrameTimes, RenderError> {
        if frames.is_empty() {
            return Ok(FrameTimes {
                frames: 0,
                mean_ms: 0.0,
                min_ms: 0.0,
                max_ms: 0.0,
                fps: 0.0,
            });
        }
        self.check_size(width, height)?;
        self.ensure_target(width, height);
        let this = &*self;
        this.scoped(|| {
            let frame = |camera: &Camera, cells: &[u32]| -> Result<f64, RenderError> {
                let t0 = Instant::now();
                let list = this.draw_list(cells, camera, width, height)?;
                let encoder = this.encode_frame(camera, list.ranges, width, height, lighting)?;
                let index = this.queue.submit([encoder.finish()]);
                this.device
                    .poll(wgpu::PollType::Wait {
                        submission_index: Some(index),
                        timeout: None,
                    })
                    .map_err(|e| RenderError::Gpu(e.to_string()))?;
                Ok(t0.elapsed().as_secs_f64() * 1e3)
            };
            for (camera, cells) in frames.iter().cycle().take(WARM_UP_FRAMES) {
                frame(camera, cells)?;
            }
            let (mut sum, mut min, mut max) = (0.0, f64::INFINITY, 0.0f64);
            for (camera, cells) in frames {
                let ms = frame(camera, cells)?;
                sum += ms;
                min = min.min(ms);
                max = max.max(ms);
            }
            let mean_ms = sum / frames.len() as f64;
            Ok(FrameTimes {
                frames: frames.len(),
                mean_ms,
                min_ms: min,
                max_ms: max,
                fps: 1e3 / mean_ms,
            })
        })
    }

    fn check_size(&self, width: u32, height: u32) -> Result<(), RenderError> {
        let max = self.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > max || height > max {
            return Err(RenderError::BadSize { width, height, max });
        }
        Ok(())
    }

    /// The cached offscreen target, rebuilt when the size changes.
    fn ensure_target(&mut self, width: u32, height: u32) {
        if self
            .target
            .as_ref()
            .is_none_or(|t| t.width != width || t.height != height)
        {
            self.target = Some(OffscreenTarget::new(&self.device, width, height));
        }
    }

    /// Runs `f` inside error scopes, so that a wgpu validation, out-of-memory or internal
    /// error comes back as [`RenderError::Gpu`] instead of reaching the device's uncaptured
    /// error handler (which panics by default).
    fn scoped<T>(&self, f: impl FnOnce() -> Result<T, RenderError>) -> Result<T, RenderError> {
        let internal = self.device.push_error_scope(wgpu::ErrorFilter::Internal);
        let memory = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = f();
        let errors = [validation.pop(), memory.pop(), internal.pop()]
            .map(|scope| pollster::block_on(scope).map(|e| e.to_string()));
        match (result, errors.into_iter().flatten().next()) {
            (_, Some(e)) => Err(RenderError::Gpu(e)),
            (result, None) => result,
        }
    }
}

/// The draw calls of one frame: the cells' index ranges with the endoscope pipeline.
fn record(
    pipeline: &EndoscopePipeline,
    mesh: &GpuMesh,
    pass: &mut wgpu::RenderPass<'_>,
    ranges: Vec<std::ops::Range<u32>>,
) {
    pass.set_pipeline(&pipeline.pipeline);
    pass.set_bind_group(0, &pipeline.bind_group, &[]);
    pass.set_vertex_buffer(0, mesh.vertices.slice(..));
    pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
    for r in ranges {
        pass.draw_indexed(r, 0, 0..1);
    }
}
