//! `voyage bench fly`: the cost of navigation — a sample of the potential field in each
//! storage layout (the paper's sorted lumen list, bricks, the dense box), and the physics per
//! frame of the automatic flights both ways.

use std::{path::PathBuf, time::Instant};

use anyhow::{Result, bail};
use glam::DVec3;
use serde_json::{Value, json};
use voyage_core::{PrepOptions, Study, Volume, prepare};
use voyage_io::{self as io, LoadOptions};
use voyage_nav::{
    BoxStore, BrickStore, Direction, DistanceStore, FlightOptions, Looking, PotentialField,
    PotentialParams, SortedStore, fly, looking,
};
use voyage_phantom::{self as phantom, ColonOptions};

use super::common::Common;

pub fn run(inputs: &[PathBuf], phantoms: bool, samples: usize, common: &Common) -> Result<()> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(common.threads)
        .build_global()
        .ok();
    let mut cases: Vec<(String, Volume<i16>)> = Vec::new();
    if phantoms {
        eprintln!("making the phantoms ...");
        cases.push(("pipe phantom".into(), phantom::pipe(1)?.ct));
        cases.push((
            "colon phantom (512×512×400)".into(),
            phantom::colon(&ColonOptions::default())?.ct,
        ));
    }
    for p in inputs {
        cases.push((
            p.display().to_string(),
            io::load(p, &LoadOptions::default())?.volume,
        ));
    }
    if cases.is_empty() {
        bail!("nothing to measure: give an input or leave the phantoms in");
    }
    let mut out = Vec::new();
    for (name, ct) in cases {
        eprintln!("measuring {name} ...");
        let study = prepare(ct, &PrepOptions::default(), |_| {})?;
        out.push(measure(&name, &study, samples)?);
    }
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &json!({ "bench": "fly", "threads": common.threads, "cases": out })
            )?
        );
    } else {
        for c in &out {
            print_case(c);
        }
    }
    Ok(())
}

fn measure(name: &str, study: &Study, samples: usize) -> Result<Value> {
    let opts = FlightOptions::for_study(study);
    let nav = study.navigable(opts.safety.min_wall_mm)?;
    let points = phantom::fixtures::random_lumen_points(study, samples, 5);
    let g = study.ct.geometry();
    let layouts = vec![
        layout(
            "sorted list + binary search (paper)",
            &PotentialField::new(SortedStore::new(study, &nav)?, g),
            &points,
        ),
        layout(
            "8³ bricks (used)",
            &PotentialField::new(BrickStore::new(study, &nav)?, g),
            &points,
        ),
        layout(
            "dense box",
            &PotentialField::new(BoxStore::new(study, &nav)?, g),
            &points,
        ),
    ];
    let field = PotentialField::new(BrickStore::new(study, &nav)?, g);
    let mut flights = Vec::new();
    for dir in [Direction::Forward, Direction::Backward] {
        let f = fly(&field, &study.centerline, dir, &opts)?;
        let l = looking(study, dir, &f.poses);
        flights.push(json!({
            "direction": dir.name(), "reached": f.reached, "frames": f.frames, "stalls": f.stalls,
            "step_ns": f.step_ns, "substeps_per_frame": f.substeps as f64 / f.frames.max(1) as f64,
            "view_angle_deg": l.view_angle_deg, "all_wall_share": l.all_wall_share,
        }));
    }
    Ok(json!({
        "case": name,
        "lumen_voxels": study.segmentation.lumen_voxels,
        "navigable_voxels": field.store().voxels(),
        "core_mm": nav.core_mm,
        "layouts": layouts,
        "flights": flights,
        "target_step_ns": 5000.0,
    }))
}

fn layout<S: DistanceStore>(name: &str, f: &PotentialField<S>, points: &[DVec3]) -> Value {
    let p = PotentialParams::default();
    // Random order (cache-cold, a worst case), then along a path (the flight's pattern).
    let t = Instant::now();
    let mut acc = 0.0;
    for &x in points {
        acc += f.sample(x, Direction::Forward).ds;
    }
    let random_ns = t.elapsed().as_nanos() as f64 / points.len() as f64;
    let mut path: Vec<DVec3> = points.to_vec();
    path.sort_by(|a, b| {
        (a.z, a.y, a.x)
            .partial_cmp(&(b.z, b.y, b.x))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let t = Instant::now();
    for &x in &path {
        acc += f.sample(x, Direction::Forward).ds;
    }
    let coherent_ns = t.elapsed().as_nanos() as f64 / path.len() as f64;
    let t = Instant::now();
    let n = points.len().min(200_000);
    for &x in &path[..n] {
        acc += f.gradient(x, &p, Direction::Forward).x;
    }
    let gradient_ns = t.elapsed().as_nanos() as f64 / n as f64;
    std::hint::black_box(acc);
    json!({ "layout": name, "megabytes": f.store().bytes() as f64 / 1e6, "sample_ns_random": random_ns, "sample_ns_coherent": coherent_ns, "gradient_ns": gradient_ns })
}

fn print_case(c: &Value) {
    println!(
        "{}: {} lumen voxels, {} navigable (core: Ds ≥ {:.2} mm)",
        c["case"].as_str().unwrap_or(""),
        c["lumen_voxels"],
        c["navigable_voxels"],
        c["core_mm"].as_f64().unwrap_or(0.0)
    );
    println!(
        "  {:<38} {:>9} {:>14} {:>16} {:>12}",
        "layout", "MB", "sample ns", "sample ns", "∇V ns"
    );
    println!(
        "  {:<38} {:>9} {:>14} {:>16} {:>12}",
        "", "", "(random)", "(coherent)", "(coherent)"
    );
    for l in c["layouts"].as_array().into_iter().flatten() {
        let f = |k: &str| l[k].as_f64().unwrap_or(f64::NAN);
        println!(
            "  {:<38} {:>9.1} {:>14.1} {:>16.1} {:>12.1}",
            l["layout"].as_str().unwrap_or(""),
            f("megabytes"),
            f("sample_ns_random"),
            f("sample_ns_coherent"),
            f("gradient_ns")
        );
    }
    for fl in c["flights"].as_array().into_iter().flatten() {
        println!(
            "  flight {:<8} reached {:<5} {:>5} frames, {:>2} stalls, {:.1} sub-steps/frame, physics {:.2} µs/frame (target ≤ 5)",
            fl["direction"].as_str().unwrap_or(""),
            fl["reached"],
            fl["frames"],
            fl["stalls"],
            fl["substeps_per_frame"].as_f64().unwrap_or(0.0),
            fl["step_ns"].as_f64().unwrap_or(0.0) / 1e3
        );
        let looked = Looking {
            view_angle_deg: serde_json::from_value(fl["view_angle_deg"].clone())
                .unwrap_or_default(),
            all_wall_share: fl["all_wall_share"].as_f64().unwrap_or(f64::NAN),
            ..Looking::default()
        };
        println!(
            "         {} (targets ≤ 15°, ≤ 45°, ≤ 2%)",
            crate::cmd::fly::describe_looking(&looked)
        );
    }
}
