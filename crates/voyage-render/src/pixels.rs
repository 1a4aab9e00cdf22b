//! [`PixelImages`]: opaque images (CT slices, the scout) drawn pixel for pixel into a render
//! pass someone else began, as the GUI's panels need them.
//!
//! A GUI toolkit draws an image as a filtered, alpha-blended textured quad. On a CPU Vulkan
//! driver that costs every pixel a bilinear fetch and a read-modify-write of the target; the
//! navigator's slices and scout paid about a fifth of the window's frame for it. These images
//! are made at the size they are shown, so one unfiltered fetch per pixel suffices.

use std::collections::HashMap;

use crate::error::RenderError;

/// The pixel format of [`PixelImages::set`]'s bytes: RGBA, 8 bits each, display values (the
/// target's colour format must not be sRGB, as for the endoscope).
pub const PIXEL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

struct Slot {
    texture: wgpu::Texture,
    bind_group: wgpu::BindGroup,
    size: [u32; 2],
}

/// Images by key, each in a texture of its own, and the pipeline that copies one into the
/// viewport.
pub struct PixelImages {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    images: HashMap<u64, Slot>,
}

impl PixelImages {
    /// For render passes whose colour target has `color_format` and whose depth attachment,
    /// if any, has `depth_format` (the depth is neither tested nor written).
    pub fn new(
        device: wgpu::Device,
        queue: wgpu::Queue,
        color_format: wgpu::TextureFormat,
        depth_format: Option<wgpu::TextureFormat>,
    ) -> Self {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("voyage pixels.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("pixels.wgsl").into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("voyage pixel image"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("voyage pixel image"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("voyage pixel image"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: depth_format.map(|format| wgpu::DepthStencilState {
                format,
                depth_write_enabled: Some(false),
                depth_compare: Some(wgpu::CompareFunction::Always),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: color_format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        PixelImages {
            device,
            queue,
            pipeline,
            layout,
            images: HashMap::new(),
        }
    }

    /// Sets image `key` to `rgba` (`size[0] × size[1]` pixels, 4 bytes each, rows top to
    /// bottom). The texture is kept while the size stays; the bytes go through the queue, so
    /// call this before the pass that draws the image is submitted.
    pub fn set(&mut self, key: u64, size: [u32; 2], rgba: &[u8]) -> Result<(), RenderError> {
        let max = self.device.limits().max_texture_dimension_2d;
        let [w, h] = size;
        if w == 0 || h == 0 || w > max || h > max {
            return Err(RenderError::BadSize {
                width: w,
                height: h,
                max,
            });
        }
        if rgba.len() != w as usize * h as usize * 4 {
            return Err(RenderError::Gpu(format!(
                "a {w}×{h} image needs {} bytes, got {}",
                w as usize * h as usize * 4,
                rgba.len()
            )));
        }
        if self.images.get(&key).is_none_or(|s| s.size != size) {
            let texture = self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("voyage pixel image"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: PIXEL_FORMAT,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            });
            let bind_group = self.bind(&texture.create_view(&Default::default()));
            self.images.insert(
                key,
                Slot {
                    texture,
                    bind_group,
                    size,
                },
            );
        }
        if let Some(Slot { texture, .. }) = self.images.get(&key) {
            self.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                rgba,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * w),
                    rows_per_image: Some(h),
                },
                wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
            );
        }
        Ok(())
    }

    fn bind(&self, view: &wgpu::TextureView) -> wgpu::BindGroup {
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("voyage pixel image"),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(view),
            }],
        })
    }

    /// Forgets image `key` (its texture is freed).
    pub fn remove(&mut self, key: u64) {
        self.images.remove(&key);
    }

    /// The size of image `key`, if it is set.
    pub fn size(&self, key: u64) -> Option<[u32; 2]> {
        self.images.get(&key).map(|s| s.size)
    }

    /// Draws image `key` with its top-left pixel at `at` (target pixels), one texel per pixel;
    /// the pass's scissor rectangle still clips it. Nothing is drawn for an unknown key.
    pub fn draw_in_pass(&self, pass: &mut wgpu::RenderPass<'_>, key: u64, at: [f32; 2]) {
        let Some(slot) = self.images.get(&key) else {
            return;
        };
        pass.set_viewport(
            at[0],
            at[1],
            slot.size[0] as f32,
            slot.size[1] as f32,
            0.0,
            1.0,
        );
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &slot.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}
