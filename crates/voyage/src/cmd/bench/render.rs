//! `voyage bench render`: the paper's Table 1 and more. Along both automatic flights (and
//! random look-around views), per visibility strategy: triangles per frame, the ratio to
//! drawing everything, whether the image stayed exactly the same, the CPU renderer's frames/s
//! on one core including the physics, and the GPU renderer's frames/s drawing the same cells.

use std::{path::PathBuf, time::Instant};

use anyhow::{Result, bail};
use serde_json::{Map, Value, json};
use voyage_core::{PrepOptions, Study, Volume, prepare};
use voyage_io::{self as io, LoadOptions};
use voyage_nav::{Camera, Direction, FlightOptions, Pose, fly, potential_field};
use voyage_phantom::{self as phantom, ColonOptions};
use voyage_render::GpuRenderer;
use voyage_view::{
    CellMesh, Coverage, CoverageOptions, Frame, Lighting, Rasterizer, Reader, Shading, Strategy,
    Survey, View, Visibility, look_around, survey,
};

use super::common::Common;

/// What `bench render` was asked for.
pub struct Plan {
    pub inputs: Vec<PathBuf>,
    pub pipe: bool,
    pub colon: bool,
    pub size: u32,
    pub frames_per_flight: usize,
    pub random: usize,
    pub gpu: bool,
}

pub fn run(plan: &Plan, common: &Common) -> Result<()> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(common.threads)
        .build_global()
        .ok();
    let mut cases: Vec<(String, Volume<i16>)> = Vec::new();
    if plan.pipe {
        cases.push(("pipe phantom".into(), phantom::pipe(1)?.ct));
    }
    if plan.colon || (plan.inputs.is_empty() && !plan.pipe) {
        cases.push((
            "colon phantom".into(),
            phantom::colon(&ColonOptions::default())?.ct,
        ));
    }
    for p in &plan.inputs {
        cases.push((
            p.display().to_string(),
            io::load(p, &LoadOptions::default())?.volume,
        ));
    }
    let mut gpu = if plan.gpu {
        match GpuRenderer::new_headless() {
            Ok(g) => Some(g),
            Err(e) => {
                eprintln!("no GPU figures: {e}");
                None
            }
        }
    } else {
        None
    };
    let mut out = Vec::new();
    for (name, ct) in cases {
        eprintln!("{name}: preprocessing ...");
        let study = prepare(ct, &PrepOptions::default(), |_| {})?;
        out.push(measure(&name, &study, plan, gpu.as_mut())?);
    }
    if common.json {
        let v = if out.len() == 1 {
            out.remove(0)
        } else {
            Value::Array(out)
        };
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        for c in &out {
            print_case(c);
        }
    }
    Ok(())
}

fn measure(name: &str, study: &Study, plan: &Plan, gpu: Option<&mut GpuRenderer>) -> Result<Value> {
    let opts = FlightOptions::for_study(study);
    let field = potential_field(study, opts.safety.min_wall_mm)?;
    let mut cameras: Vec<Camera> = Vec::new();
    let mut all_poses: Vec<Pose> = Vec::new();
    let mut physics_ns = Vec::new();
    let mut reached = Vec::new();
    for dir in [Direction::Forward, Direction::Backward] {
        let f = fly(&field, &study.centerline, dir, &opts)?;
        physics_ns.push(f.step_ns);
        reached.push(f.reached);
        let n = f.poses.len();
        if n == 0 {
            bail!("{name}: the {} flight has no frames", dir.name());
        }
        let take = plan.frames_per_flight.min(n).max(1);
        cameras.extend((0..take).map(|i| Camera::new(f.poses[i * n / take])));
        all_poses.extend(f.poses);
    }
    cameras.extend(
        look_around(&all_poses, plan.random, 11)
            .into_iter()
            .map(Camera::new),
    );
    let mesh = CellMesh::new(&study.surface, &study.cells);
    eprintln!(
        "{name}: {} frames × {} strategies at {}² ...",
        cameras.len(),
        Strategy::ALL.len(),
        plan.size
    );
    let s = survey(
        &mesh,
        &study.cells,
        &cameras,
        plan.size,
        plan.size,
        &Strategy::ALL,
        gpu.is_some(),
    );
    let physics_ms = physics_ns.iter().sum::<f64>() / physics_ns.len() as f64 / 1e6;
    let coverage = coverage_cost(&mesh, study, &cameras, plan.size);
    let gpu_times = match gpu {
        Some(g) => Some(gpu_figures(g, &mesh, &cameras, &s)?),
        None => None,
    };
    let mut out = report(name, study, &mesh, &s, physics_ms, &reached, gpu_times);
    out["coverage"] = coverage;
    Ok(out)
}

/// Window sizes of the coverage pass [`coverage_cost`] times on its own (the window marks
/// coverage on a small CPU frame of the same view).
const COVERAGE_SIDES: [u32; 2] = [96, 128];

/// What coverage costs per frame, one thread: marking the id buffer of a frame drawn at
/// `size`² (what a renderer's own id buffer would cost), and a whole coverage pass (exact
/// culling, drawing, marking) at the small sizes the window uses.
fn coverage_cost(mesh: &CellMesh, study: &Study, cameras: &[Camera], size: u32) -> Value {
    let mut indexed = mesh.clone();
    indexed.index_cells();
    let shading = Shading::new(&Lighting::default());
    let mut vis = Visibility::new(&study.cells, Strategy::Ours);
    let mut frame = Frame::new(size, size);
    let mut seen = Coverage::new(&indexed, CoverageOptions::default());
    let mut mark_ms = 0.0;
    for camera in cameras {
        let view = View::new(camera, size, size);
        frame.clear();
        vis.draw(
            &mut frame,
            &Rasterizer::new(&indexed, view, &shading),
            &study.cells,
        );
        let t = Instant::now();
        seen.mark(&frame, &view, &indexed);
        mark_ms += t.elapsed().as_secs_f64() * 1e3;
    }
    let n = cameras.len().max(1) as f64;
    let mut passes = Map::new();
    for side in COVERAGE_SIDES {
        let mut reader = Reader::new(&study.cells, Camera::new(cameras[0].pose), side, side);
        let mut seen = Coverage::new(&indexed, CoverageOptions::default());
        let t = Instant::now();
        for camera in cameras {
            reader.show(&indexed, &study.cells, camera.pose, &mut seen);
        }
        passes.insert(side.to_string(), json!(t.elapsed().as_secs_f64() * 1e3 / n));
    }
    json!({ "mark_ms": mark_ms / n, "pass_ms": passes })
}

/// Per strategy, GPU frames/s at 512² and 1024² drawing the cells the strategy chose.
struct GpuTimes {
    adapter: String,
    fps: Vec<(Strategy, f64, f64)>,
}

fn gpu_figures(
    g: &mut GpuRenderer,
    mesh: &CellMesh,
    cameras: &[Camera],
    s: &Survey,
) -> Result<GpuTimes> {
    g.upload(mesh)?;
    let lighting = Lighting::default();
    let mut fps = Vec::new();
    for st in &s.strategies {
        let frames: Vec<(Camera, Vec<u32>)> = cameras
            .iter()
            .copied()
            .zip(st.cell_lists.iter().cloned())
            .collect();
        // Every frame at 512²; a third of them at 1024² (the CPU driver is slow there).
        let small = g.time_frames(&frames, 512, 512, &lighting)?;
        let sparse: Vec<(Camera, Vec<u32>)> = frames.iter().step_by(3).cloned().collect();
        let large = g.time_frames(&sparse, 1024, 1024, &lighting)?;
        eprintln!(
            "  GPU {}: {:.1} frames/s at 512², {:.1} at 1024²",
            st.strategy.name(),
            small.fps,
            large.fps
        );
        fps.push((st.strategy, small.fps, large.fps));
    }
    Ok(GpuTimes {
        adapter: g.adapter_summary(),
        fps,
    })
}

fn report(
    name: &str,
    study: &Study,
    mesh: &CellMesh,
    s: &Survey,
    physics_ms: f64,
    reached: &[bool],
    gpu: Option<GpuTimes>,
) -> Value {
    let mut strategies = Map::new();
    for st in &s.strategies {
        let cpu_ms = st.draw_ms_mean + s.shade_ms_mean + physics_ms;
        let (g512, g1024) = gpu
            .as_ref()
            .and_then(|g| g.fps.iter().find(|f| f.0 == st.strategy))
            .map(|f| (Some(f.1), Some(f.2)))
            .unwrap_or((None, None));
        strategies.insert(
            st.strategy.name().into(),
            json!({
                "mean_triangles": st.mean_triangles.round(),
                "max_triangles": st.max_triangles,
                "mean_cells": st.mean_cells,
                "ratio_to_all": st.ratio_to_all,
                "inexact_frames": st.inexact_frames,
                "differing_pixels": st.differing_pixels,
                "depth_pixels_read": st.depth_pixels_read.round(),
                "cpu_draw_ms": st.draw_ms_mean,
                "cpu_draw_ms_max": st.draw_ms_max,
                "cpu_frame_ms": cpu_ms,
                "cpu_fps": 1e3 / cpu_ms,
                "gpu_fps_512": g512,
                "gpu_fps_1024": g1024,
            }),
        );
    }
    json!({
        "case": name,
        "triangles": mesh.triangles.len(),
        "cells": mesh.cells(),
        "centerline_length_mm": study.centerline.length_mm,
        "flights_reached": reached,
        "size": s.width,
        "frames": s.frames,
        "exact": s.exact,
        "shade_ms": s.shade_ms_mean,
        "physics_ms": physics_ms,
        "gpu_adapter": gpu.as_ref().map(|g| g.adapter.clone()),
        "strategies": strategies,
    })
}

fn print_case(c: &Value) {
    println!(
        "\n{} — {} triangles in {} cells; {} frames at {}² (both flights + look-around); exact: {}",
        c["case"].as_str().unwrap_or("?"),
        c["triangles"],
        c["cells"],
        c["frames"],
        c["size"],
        c["exact"]
    );
    println!(
        "  shading {:.2} ms/frame, physics {:.4} ms/frame",
        c["shade_ms"].as_f64().unwrap_or(0.0),
        c["physics_ms"].as_f64().unwrap_or(0.0)
    );
    if let Some(a) = c["gpu_adapter"].as_str() {
        println!("  GPU: {a}");
    }
    println!(
        "  {:<6} {:>11} {:>9} {:>7} {:>8} {:>10} {:>9} {:>10} {:>11}",
        "", "tris/frame", "max", "MC:x", "inexact", "CPU ms", "CPU fps", "GPU 512²", "GPU 1024²"
    );
    let cov = &c["coverage"];
    println!(
        "  coverage: marking a {}² frame's id buffer {:.2} ms/frame; a whole coverage pass (culling, drawing, marking) {:.2} ms at 96², {:.2} ms at 128²",
        c["size"],
        cov["mark_ms"].as_f64().unwrap_or(f64::NAN),
        cov["pass_ms"]["96"].as_f64().unwrap_or(f64::NAN),
        cov["pass_ms"]["128"].as_f64().unwrap_or(f64::NAN)
    );
    for s in Strategy::ALL {
        let v = &c["strategies"][s.name()];
        let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        let g = |k: &str| {
            v[k].as_f64()
                .map(|x| format!("{x:.1}"))
                .unwrap_or_else(|| "-".into())
        };
        println!(
            "  {:<6} {:>11.0} {:>9.0} {:>7.1} {:>8} {:>10.2} {:>9.1} {:>10} {:>11}",
            s.name(),
            f("mean_triangles"),
            f("max_triangles"),
            f("ratio_to_all"),
            v["inexact_frames"],
            f("cpu_frame_ms"),
            f("cpu_fps"),
            g("gpu_fps_512"),
            g("gpu_fps_1024")
        );
    }
}
