//! Renders the pipe phantom on the GPU from a point of its centerline, looking along it, and
//! writes a PNG: a quick look at what the headless renderer draws.
//!
//! ```text
//! cargo run --release -p voyage-render --example gpu_frame -- [out.png] [fraction 0..1] [size]
//! ```

use std::error::Error;

use glam::DVec3;
use voyage_core::{PrepOptions, prepare};
use voyage_nav::{Camera, Pose};
use voyage_phantom as phantom;
use voyage_render::GpuRenderer;
use voyage_view::{CellMesh, Lighting};

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = args.first().map_or("gpu_frame.png", String::as_str);
    let fraction: f64 = args.get(1).map_or(Ok(0.5), |s| s.parse())?;
    let size: u32 = args.get(2).map_or(Ok(512), |s| s.parse())?;

    let study = prepare(phantom::pipe(1)?.ct, &PrepOptions::default(), |_| {})?;
    let mesh = CellMesh::new(&study.surface, &study.cells);
    let pts: Vec<DVec3> = study
        .centerline
        .points_mm
        .iter()
        .map(|&p| DVec3::from_array(p))
        .collect();
    let i = ((pts.len() - 1) as f64 * fraction.clamp(0.0, 1.0)).round() as usize;
    let forward = pts[(i + 3).min(pts.len() - 1)] - pts[i.saturating_sub(3)];
    let camera = Camera::new(Pose::looking(pts[i], forward, DVec3::Z));

    let mut gpu = GpuRenderer::new_headless()?;
    gpu.upload(&mesh)?;
    let cells: Vec<u32> = (0..mesh.cells() as u32).collect();
    let rgba = gpu.render(&camera, &cells, size, size, &Lighting::default())?;
    image::RgbaImage::from_raw(size, size, rgba)
        .ok_or("image size")?
        .save(out)?;
    println!(
        "{out}: {size}×{size}, {} triangles, on {}",
        mesh.triangles.len(),
        gpu.adapter_summary()
    );
    Ok(())
}
