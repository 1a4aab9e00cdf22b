//! Opaque panel images (the CT slices, the scout) made at the size they are shown and drawn
//! pixel for pixel by `voyage_render::PixelImages` inside egui's render pass; an egui
//! texture where the window has no wgpu renderer.
//!
//! egui draws its images as filtered, alpha-blended quads, which on a CPU Vulkan driver cost
//! the navigator's slices and scout about a fifth of each frame (measured: BENCHMARKS.md,
//! "The navigator window").
//!
//! [`WindowGpu`] holds what the window's own wgpu renderer draws besides egui: the
//! endoscopic view's renderer and the panels' pixel images.

use std::sync::Arc;

use eframe::egui_wgpu;
use egui::{Color32, ColorImage, Pos2, Rect, TextureHandle, TextureOptions, Vec2};
use voyage_render::{GpuRenderer, PixelImages};
use voyage_view::Rgba;

/// Kept in egui-wgpu's callback resources, so that paint callbacks reach it while egui
/// records the window's render pass.
pub struct WindowGpu {
    pub renderer: GpuRenderer,
    pub images: PixelImages,
}

impl WindowGpu {
    /// Puts one into `render_state`'s callback resources.
    pub fn install(render_state: &egui_wgpu::RenderState) {
        let (device, queue) = (render_state.device.clone(), render_state.queue.clone());
        let renderer =
            GpuRenderer::for_pass(device.clone(), queue.clone(), render_state.target_format);
        let images = PixelImages::new(
            device,
            queue,
            render_state.target_format,
            Some(voyage_render::DEPTH_FORMAT),
        );
        render_state
            .renderer
            .write()
            .callback_resources
            .insert(WindowGpu { renderer, images });
    }
}

/// One image slot of the window. `key` names it among the window's [`PixelImages`].
pub struct PanelImage {
    key: u64,
    name: &'static str,
    /// The window's renderer holds a [`PixelImages`] (else an egui texture shows the image).
    gpu: bool,
    size: [usize; 2],
    /// Pixels the GPU has not had yet: handed to the next paint callback.
    pending: Option<Arc<Rgba>>,
    fallback: Option<TextureHandle>,
}

impl PanelImage {
    pub fn new(key: u64, name: &'static str, gpu: bool) -> Self {
        PanelImage {
            key,
            name,
            gpu,
            size: [0, 0],
            pending: None,
            fallback: None,
        }
    }

    /// The image shown from now on.
    pub fn set(&mut self, image: Rgba) {
        self.size = image.size;
        self.pending = Some(Arc::new(image));
        self.fallback = None;
    }

    /// Draws the image with its top-left corner at `at` (points), one image pixel per
    /// physical pixel, clipped to the painter's clip rectangle.
    pub fn paint(&mut self, painter: &egui::Painter, at: Pos2) {
        if self.size[0] == 0 || self.size[1] == 0 {
            return;
        }
        let ppp = painter.ctx().pixels_per_point();
        let rect = Rect::from_min_size(
            at,
            Vec2::new(self.size[0] as f32, self.size[1] as f32) / ppp,
        );
        if self.gpu {
            let callback = PixelsCallback {
                key: self.key,
                upload: self.pending.take(),
            };
            painter.add(egui_wgpu::Callback::new_paint_callback(rect, callback));
            return;
        }
        if let Some(image) = self.pending.take() {
            let color = ColorImage::from_rgba_unmultiplied(image.size, &image.bytes);
            match &mut self.fallback {
                Some(t) => t.set(color, TextureOptions::NEAREST),
                None => {
                    self.fallback = Some(painter.ctx().load_texture(
                        self.name,
                        color,
                        TextureOptions::NEAREST,
                    ))
                }
            }
        }
        if let Some(t) = &self.fallback {
            painter.image(
                t.id(),
                rect,
                Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
                Color32::WHITE,
            );
        }
    }
}

struct PixelsCallback {
    key: u64,
    upload: Option<Arc<Rgba>>,
}

impl egui_wgpu::CallbackTrait for PixelsCallback {
    fn prepare(
        &self,
        _device: &wgpu::Device,
        _queue: &wgpu::Queue,
        _screen: &egui_wgpu::ScreenDescriptor,
        _encoder: &mut wgpu::CommandEncoder,
        resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        if let (Some(image), Some(WindowGpu { images, .. })) =
            (&self.upload, resources.get_mut::<WindowGpu>())
        {
            // A size the device refuses leaves the panel empty rather than stopping the window.
            if images
                .set(
                    self.key,
                    [image.size[0] as u32, image.size[1] as u32],
                    &image.bytes,
                )
                .is_err()
            {
                images.remove(self.key);
            }
        }
        Vec::new()
    }

    fn paint(
        &self,
        info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        if let Some(gpu) = resources.get::<WindowGpu>() {
            gpu.images.draw_in_pass(pass, self.key, top_left_px(&info));
        }
    }
}

/// The target pixel of a paint callback's top-left corner.
fn top_left_px(info: &egui::PaintCallbackInfo) -> [f32; 2] {
    let at = info.viewport.min * info.pixels_per_point;
    [at.x.round(), at.y.round()]
}
