//! The endoscope render pipeline: the shader in `endoscope.wgsl`, one uniform buffer,
//! back faces culled, depth test Less.
//!
//! Culling: the surface's triangles wind so that (b − a) × (c − a) points into the lumen,
//! toward the camera, which is always inside the closed surface. Seen from the camera such a
//! triangle is counter-clockwise in NDC (y up), so the front face is `Ccw` and the wall's
//! outer side (`Back`) is never drawn; the CPU renderer keeps the same triangles.

#[cfg(doc)]
use crate::target::COLOR_FORMAT;
use crate::{mesh::Vertex, target::DEPTH_FORMAT, uniforms::Uniforms};

pub(crate) struct EndoscopePipeline {
    pub pipeline: wgpu::RenderPipeline,
    pub uniforms: wgpu::Buffer,
    pub bind_group: wgpu::BindGroup,
}

impl EndoscopePipeline {
    /// The pipeline writing a colour target of `color_format` ([`COLOR_FORMAT`] offscreen,
    /// the surface's format in a window). The shader writes display-gamma values, so the
    /// format should not be an sRGB one.
    pub fn with_format(device: &wgpu::Device, color_format: wgpu::TextureFormat) -> Self {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("voyage endoscope.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("endoscope.wgsl").into()),
        });
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("voyage endoscope uniforms"),
            size: std::mem::size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("voyage endoscope uniforms"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<Uniforms>() as u64),
                },
                count: None,
            }],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("voyage endoscope uniforms"),
            layout: &layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniforms.as_entire_binding(),
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("voyage endoscope"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("voyage endoscope"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(Vertex::layout())],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                strip_index_format: None,
                front_face: wgpu::FrontFace::Ccw,
                cull_mode: Some(wgpu::Face::Back),
                unclipped_depth: false,
                polygon_mode: wgpu::PolygonMode::Fill,
                conservative: false,
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
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
        EndoscopePipeline {
            pipeline,
            uniforms,
            bind_group,
        }
    }
}
