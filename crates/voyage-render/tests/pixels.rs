//! `PixelImages`: an image lands pixel for pixel where it is drawn, clipped by the target,
//! and bad images are errors. Runs on lavapipe where there is no GPU (no adapter is a
//! failure, not a skip).

use voyage_render::{
    COLOR_FORMAT, DEPTH_FORMAT, GpuRenderer, OffscreenTarget, PixelImages, RenderError,
};

const W: u32 = 16;
const H: u32 = 12;
const CLEAR: [u8; 4] = [10, 20, 30, 255];

/// A test image whose every pixel differs: (x, y, x + y, 255) scaled.
fn image(w: u32, h: u32) -> Vec<u8> {
    (0..h)
        .flat_map(|y| {
            (0..w).flat_map(move |x| {
                [
                    (x * 16 + 1) as u8,
                    (y * 16 + 2) as u8,
                    (x + y) as u8 * 8 + 3,
                    255,
                ]
            })
        })
        .collect()
}

/// Draws image `key` at each of `at` into a cleared W × H target and reads the target back.
fn draw(images: &PixelImages, gpu: &GpuRenderer, key: u64, at: &[[f32; 2]]) -> Vec<u8> {
    let (device, queue) = (gpu.device(), gpu.queue());
    let target = OffscreenTarget::new(device, W, H);
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let c = CLEAR.map(|v| v as f64 / 255.0);
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: None,
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &target.color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: c[0],
                        g: c[1],
                        b: c[2],
                        a: c[3],
                    }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &target.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        for a in at {
            images.draw_in_pass(&mut pass, key, *a);
        }
    }
    let padded = voyage_render::padded_bytes_per_row(W);
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: (padded * H) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    encoder.copy_texture_to_buffer(
        target.color.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(H),
            },
        },
        wgpu::Extent3d {
            width: W,
            height: H,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([encoder.finish()]);
    buffer
        .slice(..)
        .map_async(wgpu::MapMode::Read, |r| r.expect("map"));
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    let data = buffer.slice(..).get_mapped_range().expect("mapped");
    (0..H as usize)
        .flat_map(|y| data[y * padded as usize..y * padded as usize + 4 * W as usize].to_vec())
        .collect()
}

fn pixel(img: &[u8], w: u32, x: u32, y: u32) -> [u8; 4] {
    let i = 4 * (y * w + x) as usize;
    [img[i], img[i + 1], img[i + 2], img[i + 3]]
}

fn setup() -> (GpuRenderer, PixelImages) {
    let gpu = GpuRenderer::new_headless().unwrap_or_else(|e| panic!("{e}"));
    let images = PixelImages::new(
        gpu.device().clone(),
        gpu.queue().clone(),
        COLOR_FORMAT,
        Some(DEPTH_FORMAT),
    );
    (gpu, images)
}

#[test]
fn images_land_pixel_for_pixel_and_are_clipped_by_the_target() {
    let (gpu, mut images) = setup();
    let (iw, ih) = (5, 4);
    let src = image(iw, ih);
    images.set(7, [iw, ih], &src).unwrap();
    assert_eq!(images.size(7), Some([iw, ih]));
    // Once inside, once hanging over the top-left corner.
    let out = draw(&images, &gpu, 7, &[[3.0, 2.0], [-2.0, -1.0]]);
    for y in 0..H {
        for x in 0..W {
            let inside = |ox: i64, oy: i64| {
                let (u, v) = (x as i64 - ox, y as i64 - oy);
                (u >= 0 && v >= 0 && u < iw as i64 && v < ih as i64)
                    .then(|| pixel(&src, iw, u as u32, v as u32))
            };
            let want = inside(-2, -1).or_else(|| inside(3, 2)).unwrap_or(CLEAR);
            assert_eq!(pixel(&out, W, x, y), want, "pixel ({x}, {y})");
        }
    }
}

#[test]
fn a_new_image_replaces_the_old_one_even_at_another_size() {
    let (gpu, mut images) = setup();
    images.set(1, [3, 3], &image(3, 3)).unwrap();
    images
        .set(1, [2, 1], &[200, 100, 50, 255, 1, 2, 3, 255])
        .unwrap();
    let out = draw(&images, &gpu, 1, &[[0.0, 0.0]]);
    assert_eq!(pixel(&out, W, 0, 0), [200, 100, 50, 255]);
    assert_eq!(pixel(&out, W, 1, 0), [1, 2, 3, 255]);
    assert_eq!(pixel(&out, W, 2, 0), CLEAR);
    assert_eq!(pixel(&out, W, 0, 1), CLEAR);
    // Unknown and removed keys draw nothing.
    images.remove(1);
    assert_eq!(images.size(1), None);
    assert!(
        draw(&images, &gpu, 1, &[[0.0, 0.0]])
            .chunks(4)
            .all(|p| p == CLEAR)
    );
}

#[test]
fn bad_images_are_errors() {
    let (_gpu, mut images) = setup();
    assert!(matches!(
        images.set(0, [0, 4], &[]),
        Err(RenderError::BadSize { .. })
    ));
    assert!(matches!(
        images.set(0, [2, 2], &[0; 15]),
        Err(RenderError::Gpu(_))
    ));
    assert_eq!(images.size(0), None);
}
