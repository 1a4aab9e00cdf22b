//! Where the endoscopic view is drawn offscreen: an Rgba8Unorm colour texture, a
//! Depth32Float depth texture and a buffer to read the colour back.
//!
//! Kept apart from the mesh and the pipeline so that the GUI can instead hand
//! [`crate::GpuRenderer::draw`] views of textures it owns; the headless path caches one
//! target and rebuilds it only when the image size changes.

/// The colour format the endoscope pipeline writes: plain Unorm, because the shader applies
/// the display gamma itself (as the CPU renderer's `encode` does), so an sRGB target would
/// apply it twice.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// An offscreen colour + depth pair of one size, with its readback buffer.
pub struct OffscreenTarget {
    pub width: u32,
    pub height: u32,
    pub color: wgpu::Texture,
    pub color_view: wgpu::TextureView,
    pub depth: wgpu::Texture,
    pub depth_view: wgpu::TextureView,
    /// `padded_bytes_per_row × height` bytes, MAP_READ.
    readback: wgpu::Buffer,
}

impl OffscreenTarget {
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let texture = |label, format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let color = texture(
            "voyage endoscope colour",
            COLOR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let depth = texture(
            "voyage endoscope depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("voyage endoscope readback"),
            size: padded_bytes_per_row(width) as u64 * height as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let color_view = color.create_view(&Default::default());
        let depth_view = depth.create_view(&Default::default());
        OffscreenTarget {
            width,
            height,
            color,
            color_view,
            depth,
            depth_view,
            readback,
        }
    }

    /// Records the copy of the colour texture into the readback buffer.
    pub(crate) fn encode_readback(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.copy_texture_to_buffer(
            self.color.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded_bytes_per_row(self.width)),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
    }

    /// Maps the readback buffer (after the copy was submitted), waits, and returns tightly
    /// packed RGBA8 rows, top row first (texture row 0 is the image's top).
    pub(crate) fn read(&self, device: &wgpu::Device) -> Result<Vec<u8>, String> {
        let slice = self.readback.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| e.to_string())?;
        rx.recv()
            .map_err(|e| e.to_string())?
            .map_err(|e| e.to_string())?;
        let row = self.width as usize * 4;
        let padded = padded_bytes_per_row(self.width) as usize;
        let mut out = Vec::with_capacity(row * self.height as usize);
        {
            let data = slice.get_mapped_range().map_err(|e| e.to_string())?;
            for y in 0..self.height as usize {
                out.extend_from_slice(&data[y * padded..y * padded + row]);
            }
        }
        self.readback.unmap();
        Ok(out)
    }
}

/// Bytes per row of an RGBA8 image of `width`, rounded up to wgpu's copy alignment (256).
pub fn padded_bytes_per_row(width: u32) -> u32 {
    (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
}

#[cfg(test)]
mod tests {
    #[test]
    fn rows_pad_to_256_bytes() {
        assert_eq!(super::padded_bytes_per_row(64), 256);
        assert_eq!(super::padded_bytes_per_row(65), 512);
        assert_eq!(super::padded_bytes_per_row(1024), 4096);
        assert_eq!(super::padded_bytes_per_row(1), 256);
    }
}
