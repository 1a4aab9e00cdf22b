//! The GPU image against the CPU reference renderer (`voyage_view::render_rgba`) on
//! a real scene: the paper's pipe phantom, prepared by voyage-core, seen from points of its
//! centerline looking along it, every cell drawn.
//!
//! The two renderers cannot agree bit for bit: the GPU interpolates the eye-relative position
//! and the normal in f32 and rasterizes with its own fixed-point edge rules, the CPU in f64
//! with its own tie rules, so pixels on silhouettes (a fold or polyp in front of the wall
//! behind) may take different triangles, and interior pixels may round the other way.
//!
//! Measured on lavapipe (Mesa 22.3.6, Vulkan) and on Mesa's GL (`WGPU_BACKEND=gl`), 256×256,
//! seven views (536 276 triangles): 880 to 1 210 of 65 536 pixels (1.3–1.8 %) differ, by one
//! unit (two at worst: the CPU shades through lookup tables for the two powers), none by more
//! than 8/255; mean |diff| at most 0.0062/255. (With the CPU evaluating powf exactly, 6 to 26
//! pixels differed, the worst by 5 on a silhouette.) The limits below (the brief's) leave
//! room for other drivers' rasterizers.
//!
//! Set `VOYAGE_RENDER_DUMP=<dir>` to write each view as `gpu-N.ppm`, `cpu-N.ppm` and a
//! difference image `diff-N.ppm` (|gpu − cpu| × 16).

use std::sync::OnceLock;

use glam::DVec3;
use voyage_core::{PrepOptions, Study, prepare};
use voyage_nav::{Camera, Pose};
use voyage_phantom as phantom;
use voyage_render::GpuRenderer;
use voyage_view::{CellMesh, Lighting, Strategy, View, Visibility, render_rgba};

/// Share of pixels that may have a channel differing by more than 8/255.
const MAX_FAR_OFF: f64 = 0.01;
/// Mean absolute difference over all channel values, in 1/255.
const MAX_MEAN_DIFF: f64 = 1.5;

fn pipe() -> &'static (Study, CellMesh) {
    static P: OnceLock<(Study, CellMesh)> = OnceLock::new();
    P.get_or_init(|| {
        let p = phantom::pipe(1).expect("pipe phantom");
        let study = prepare(p.ct, &PrepOptions::default(), |_| {}).expect("prepare the pipe");
        let mesh = CellMesh::new(&study.surface, &study.cells);
        (study, mesh)
    })
}

/// A headless renderer with `mesh` uploaded, and the list of all its cells.
fn uploaded(mesh: &CellMesh) -> (GpuRenderer, Vec<u32>) {
    let mut gpu = GpuRenderer::new_headless().unwrap_or_else(|e| panic!("{e}"));
    gpu.upload(mesh).unwrap();
    (gpu, (0..mesh.cells() as u32).collect())
}

/// Cameras at fractions of the centerline, looking along it.
fn views(study: &Study, fractions: &[f64]) -> Vec<Camera> {
    let pts: Vec<DVec3> = study
        .centerline
        .points_mm
        .iter()
        .map(|&p| DVec3::from_array(p))
        .collect();
    fractions
        .iter()
        .map(|&f| {
            let i = ((pts.len() - 1) as f64 * f).round() as usize;
            let (a, b) = (pts[i.saturating_sub(3)], pts[(i + 3).min(pts.len() - 1)]);
            Camera::new(Pose::looking(pts[i], b - a, DVec3::Z))
        })
        .collect()
}

/// RGBA pixels that differ between two images of the same size.
fn pixels_differing(a: &[u8], b: &[u8]) -> usize {
    a.chunks(4).zip(b.chunks(4)).filter(|(x, y)| x != y).count()
}

fn write_ppm(path: &std::path::Path, rgba: &[u8], w: u32, h: u32) {
    let mut out = format!("P6\n{w} {h}\n255\n").into_bytes();
    for px in rgba.chunks(4) {
        out.extend_from_slice(&px[..3]);
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn gpu_matches_the_cpu_renderer_on_the_pipe() {
    let (study, mesh) = pipe();
    let (mut gpu, all) = uploaded(mesh);
    let lighting = Lighting::default();
    let (w, h) = (256, 256);
    let dump = std::env::var_os("VOYAGE_RENDER_DUMP").map(std::path::PathBuf::from);
    let mut cameras = views(study, &[0.15, 0.4, 0.5, 0.6, 0.85]);
    // A wide endoscope, and a view across the pipe toward its wall from near it.
    cameras.push(views(study, &[0.45])[0].with_fov(120.0));
    cameras.push({
        let c = views(study, &[0.55])[0];
        let side = c.pose.y_body();
        Camera::new(Pose::looking(
            c.pose.position - 12.0 * side,
            side + 0.3 * c.pose.z_body(),
            c.pose.z_body(),
        ))
    });
    for (k, cam) in cameras.iter().enumerate() {
        let g = gpu.render(cam, &all, w, h, &lighting).unwrap();
        let c = render_rgba(mesh, cam, &all, w, h, &lighting);
        assert_eq!(g.len(), c.len());
        let (mut far_off, mut differ, mut sum, mut worst) = (0usize, 0usize, 0u64, 0u8);
        for (pg, pc) in g.chunks(4).zip(c.chunks(4)) {
            assert_eq!(pg[3], 255);
            let d = [0, 1, 2].map(|ch| pg[ch].abs_diff(pc[ch]));
            let most = d.into_iter().max().unwrap();
            far_off += (most > 8) as usize;
            differ += (most > 0) as usize;
            sum += d.iter().map(|&v| v as u64).sum::<u64>();
            worst = worst.max(most);
        }
        let n = (w * h) as usize;
        let lit = g.chunks(4).filter(|p| p[..3] != [0, 0, 0]).count();
        let (far, mean) = (far_off as f64 / n as f64, sum as f64 / (3 * n) as f64);
        eprintln!(
            "view {k}: {lit} lit pixels; {differ} pixels differ, {far_off} by more than 8 ({:.4} %); mean |diff| {mean:.5}/255, worst {worst}",
            100.0 * far
        );
        if let Some(dir) = &dump {
            std::fs::create_dir_all(dir).unwrap();
            write_ppm(&dir.join(format!("gpu-{k}.ppm")), &g, w, h);
            write_ppm(&dir.join(format!("cpu-{k}.ppm")), &c, w, h);
            let diff: Vec<u8> = g
                .iter()
                .zip(&c)
                .map(|(a, b)| a.abs_diff(*b).saturating_mul(16))
                .collect();
            write_ppm(&dir.join(format!("diff-{k}.ppm")), &diff, w, h);
        }
        assert!(
            lit > (w * h) as usize / 2,
            "view {k}: the wall fills the view ({lit} lit pixels)"
        );
        assert!(
            far <= MAX_FAR_OFF,
            "view {k}: {:.3} % of pixels differ by more than 8",
            100.0 * far
        );
        assert!(
            mean <= MAX_MEAN_DIFF,
            "view {k}: mean difference {mean:.3}/255"
        );
    }
}

/// Frames are timed (the figures are printed; run with `--nocapture`).
#[test]
fn frames_are_timed_on_the_pipe() {
    let (study, mesh) = pipe();
    let (mut gpu, all) = uploaded(mesh);
    let frames: Vec<(Camera, Vec<u32>)> = views(study, &[0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
        .into_iter()
        .map(|c| (c, all.clone()))
        .collect();
    let size = std::env::var("VOYAGE_RENDER_TIME_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(128);
    let t = gpu
        .time_frames(&frames, size, size, &Lighting::default())
        .unwrap();
    eprintln!(
        "{}: {} triangles, {size}²: {} frames, mean {:.2} ms, min {:.2} ms, max {:.2} ms, {:.1} frames/s",
        gpu.adapter_summary(),
        mesh.triangles.len(),
        t.frames,
        t.mean_ms,
        t.min_ms,
        t.max_ms,
        t.fps
    );
    assert_eq!(t.frames, frames.len());
    assert!(t.mean_ms > 0.0 && t.min_ms <= t.mean_ms && t.mean_ms <= t.max_ms && t.fps > 0.0);
}

/// Leaving out the chunks outside the view changes no pixel (the GPU against itself, bit for
/// bit), and it does leave some out: views along the pipe, a wide one, one across it, one
/// looking back and one from a corner, every cell drawn.
#[test]
fn chunks_outside_the_view_change_nothing() {
    let (study, mesh) = pipe();
    let (mut gpu, all) = uploaded(mesh);
    let lighting = Lighting::default();
    let (w, h) = (200, 150);
    let mut cameras = views(study, &[0.05, 0.3, 0.5, 0.7, 0.95]);
    cameras.push(views(study, &[0.4])[0].with_fov(140.0));
    let c = views(study, &[0.6])[0];
    cameras.push(Camera::new(Pose::looking(
        c.pose.position,
        c.pose.y_body(),
        c.pose.z_body(),
    )));
    cameras.push(Camera::new(Pose::looking(
        c.pose.position,
        -c.pose.z_body(),
        DVec3::Z,
    )));
    let (mut kept, mut total) = (0, 0);
    for (k, cam) in cameras.iter().enumerate() {
        gpu.set_chunk_culling(false);
        let whole = gpu.render(cam, &all, w, h, &lighting).unwrap();
        total += gpu.draw_list(&all, cam, w, h).unwrap().triangles();
        gpu.set_chunk_culling(true);
        let culled = gpu.render(cam, &all, w, h, &lighting).unwrap();
        kept += gpu.draw_list(&all, cam, w, h).unwrap().triangles();
        assert!(
            whole == culled,
            "view {k}: {} pixels differ",
            pixels_differing(&whole, &culled)
        );
    }
    eprintln!("chunk culling kept {kept} of {total} triangles");
    assert_eq!(total, cameras.len() * mesh.triangles.len());
    assert!(
        kept < total / 2,
        "most of the pipe lies outside each view: kept {kept} of {total}"
    );
}

/// The cells the portals let through, each without its chunks outside the window the portals
/// leave open, give the same image as the cells whole (the GPU against itself, bit for bit),
/// and leave chunks out: views along the pipe at 19 places.
#[test]
fn chunks_outside_the_portals_window_change_nothing() {
    let (study, mesh) = pipe();
    let (mut gpu, _) = uploaded(mesh);
    let lighting = Lighting::default();
    let (w, h) = (200, 150);
    let mut vis = Visibility::new(&study.cells, Strategy::Ours);
    let (mut kept, mut whole_tris) = (0, 0);
    let fractions: Vec<f64> = (1..20).map(|k| k as f64 / 20.0).collect();
    for (k, cam) in views(study, &fractions).iter().enumerate() {
        let drawn = vis.select(&study.cells, &View::new(cam, w, h));
        assert_eq!(drawn.rects.len(), drawn.cells.len());
        let cells = gpu.draw_list(&drawn.cells, cam, w, h).unwrap();
        let within = gpu.draw_list_within(&drawn, cam, w, h).unwrap();
        whole_tris += cells.triangles();
        kept += within.triangles();
        let a = gpu.render_list(cam, &cells, w, h, &lighting).unwrap();
        let b = gpu.render_list(cam, &within, w, h, &lighting).unwrap();
        assert!(
            a == b,
            "view {k}: {} pixels differ",
            pixels_differing(&a, &b)
        );
    }
    eprintln!("the portals' windows kept {kept} of {whole_tris} triangles");
    assert!(kept < whole_tris, "no chunk was left out");
}
