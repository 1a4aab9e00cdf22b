//! `voyage bench prep`: the preprocessing stage by stage, beside the reference libraries on
//! the same lumen mask in the same run.

use std::{
    path::{Path, PathBuf},
    time::Instant,
};

use anyhow::{Context, Result, bail};
use serde_json::{Value, json};
use voyage_core::{PrepOptions, Stage, Study, Timings, Volume, geodesic_distance, prepare};
use voyage_io::{self as io, LoadOptions, nifti};
use voyage_phantom::{self as phantom, ColonOptions};

use super::common::{Common, median, run_reference_script};

const PREP_REFERENCE_PY: &str = include_str!("../../../../../bench/prep_reference.py");

pub fn run(
    inputs: Vec<PathBuf>,
    phantom: bool,
    dir: &Path,
    repeats: usize,
    rounds: usize,
    reference: bool,
    common: &Common,
) -> Result<()> {
    let (threads, python, json_out) = (common.threads, common.python.as_deref(), common.json);
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()
        .ok();
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create folder", dir.display()))?;
    let mut cases: Vec<(String, Volume<i16>)> = Vec::new();
    if phantom {
        eprintln!("making the colon phantom ...");
        cases.push((
            "colon phantom (512×512×400)".into(),
            phantom::colon(&ColonOptions::default())?.ct,
        ));
    }
    for p in &inputs {
        cases.push((
            p.display().to_string(),
            io::load(p, &LoadOptions::default())?.volume,
        ));
    }
    if cases.is_empty() {
        bail!("nothing to measure: give an input or leave the phantom in");
    }
    let mut results = Vec::new();
    let rounds = rounds.max(1);
    for (i, (name, ct)) in cases.into_iter().enumerate() {
        let mut done: Vec<(Measured, Value)> = Vec::new();
        for round in 0..rounds {
            eprintln!("measuring {name} (round {} of {rounds}) ...", round + 1);
            let r = measure(&name, ct.clone(), repeats)?;
            let refs = if reference {
                let mask = dir.join(format!("case{i}-lumen.nii.gz"));
                if round == 0 {
                    nifti::save(&mask, &r.study()?.segmentation.lumen)?;
                }
                match run_reference(python, dir, &mask, r.study()?.source, repeats) {
                    Ok(v) => v,
                    Err(e) => {
                        eprintln!("reference not run: {e:#}");
                        Value::Null
                    }
                }
            } else {
                Value::Null
            };
            // Only the last round's study is reported: the others' memory goes back.
            for (earlier, _) in &mut done {
                earlier.study = None;
            }
            done.push((r, refs));
        }
        results.push(report(&done, threads));
    }
    if json_out {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &json!({"bench": "prep", "threads": threads, "repeats": repeats, "cases": results})
            )?
        );
    } else {
        for r in &results {
            print_case(r);
        }
    }
    Ok(())
}

struct Measured {
    name: String,
    /// The study of the last run (None once a later round has its own).
    study: Option<Study>,
    timings: Timings,
    dt_single_ms: f64,
    ct_mb: f64,
    peak_rss_mb: Option<f64>,
}

impl Measured {
    fn study(&self) -> Result<&Study> {
        self.study
            .as_ref()
            .context("the study of this round was already let go")
    }
}

/// Median per stage over `repeats` runs after a warm-up, and one plain Dt alone.
fn measure(name: &str, ct: Volume<i16>, repeats: usize) -> Result<Measured> {
    let ct_mb = (ct.data().len() * 2) as f64 / 1e6;
    let opts = PrepOptions::default();
    reset_peak_rss();
    let mut study = prepare(ct.clone(), &opts, |_| {})?;
    let mut runs: Vec<Timings> = Vec::new();
    for _ in 0..repeats.max(1) {
        // One study at a time, so that the peak is one run's (plus the CT the bench keeps).
        drop(study);
        study = prepare(ct.clone(), &opts, |_| {})?;
        runs.push(study.timings.clone());
    }
    let med = |f: &dyn Fn(&Timings) -> f64| median(&mut runs.iter().map(f).collect::<Vec<_>>());
    let mut timings = Timings::default();
    for stage in Stage::ALL {
        timings[stage] = med(&|t| t[stage]);
    }
    timings.total_after_load = med(&|t| t.total_after_load);
    let lumen = &study.segmentation.lumen;
    let mut single = Vec::new();
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        geodesic_distance(lumen, &study.ds.grid, study.source)?;
        single.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(Measured {
        name: name.into(),
        dt_single_ms: median(&mut single),
        study: Some(study),
        timings,
        ct_mb,
        peak_rss_mb: crate::cmd::prep::peak_rss_mb(),
    })
}

/// Starts the process's peak resident memory afresh (Linux; elsewhere nothing happens), so
/// that each case reports its own.
fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn run_reference(
    python: Option<&Path>,
    dir: &Path,
    mask: &Path,
    source: [usize; 3],
    repeats: usize,
) -> Result<Value> {
    let source = format!("{},{},{}", source[0], source[1], source[2]);
    let repeats = repeats.max(1).to_string();
    let stdout = run_reference_script(
        python,
        dir,
        ("prep_reference.py", PREP_REFERENCE_PY),
        &[mask.as_os_str(), source.as_ref(), repeats.as_ref()],
    )?;
    serde_json::from_slice(&stdout).context("reference printed no JSON")
}

/// One case's rows from its rounds: per stage the median over rounds of voyage's and the
/// reference's medians, and the median and range of the speedups paired within each round.
fn report(rounds: &[(Measured, Value)], threads: usize) -> Value {
    let Some((m, refs)) = rounds.last() else {
        return Value::Null;
    };
    let Ok(s) = m.study() else { return Value::Null };
    let row = |stage: &str,
               ours: fn(&Measured) -> f64,
               reference: &str,
               key: &str,
               target_ms: f64,
               target_ratio: Option<f64>| {
        let ours_ms = median(&mut rounds.iter().map(|(m, _)| ours(m)).collect::<Vec<_>>());
        let ref_of = |refs: &Value| refs.get(key).and_then(|v| v["ms"].as_f64());
        let mut ref_ms: Vec<f64> = rounds.iter().filter_map(|(_, r)| ref_of(r)).collect();
        let mut speedups: Vec<f64> = rounds
            .iter()
            .filter_map(|(m, r)| ref_of(r).map(|x| x / ours(m)))
            .collect();
        let (lo, hi) = speedups
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            });
        let has = !speedups.is_empty();
        json!({
            "stage": stage, "voyage_ms": ours_ms, "reference": reference,
            "reference_ms": has.then(|| median(&mut ref_ms)),
            "speedup": has.then(|| median(&mut speedups)),
            "speedup_range": has.then_some([lo, hi]),
            "rounds": rounds.len(),
            "target_ms": target_ms, "target_speedup": target_ratio,
        })
    };
    json!({
        "case": m.name,
        "threads": threads,
        "lumen_voxels": s.segmentation.lumen_voxels,
        "box": s.ds.grid.dims,
        "triangles": s.surface.mesh.triangles.len(),
        "centerline_length_mm": s.centerline.length_mm,
        "cells": s.cells.cells.len(),
        "contact_voxels": s.contact_voxels,
        "ct_mb": m.ct_mb,
        "peak_rss_mb": m.peak_rss_mb,
        "reference_triangles": refs.get("vtk_flying_edges").and_then(|v| v.get("triangles")).cloned(),
        "rows": [
            row("segment", |m| m.timings[Stage::Segment], "-", "", 60.0, None),
            row("cleanse (0 without tagged fluid)", |m| m.timings[Stage::Cleanse], "-", "", 150.0, None),
            row("ds", |m| m.timings[Stage::Ds], "edt (1 thread)", "edt", 100.0, Some(5.0)),
            row("ds", |m| m.timings[Stage::Ds], "scipy.ndimage EDT", "scipy_edt", 100.0, None),
            row("one Dt", |m| m.dt_single_ms, "dijkstra3d", "dijkstra3d", 100.0, Some(4.0)),
            row("endpoints + skeleton path", |m| m.timings[Stage::Skeleton], "-", "", 200.0, None),
            row("centerline refinement", |m| m.timings[Stage::Centerline], "-", "", 50.0, None),
            row("touching loops (on the skeleton's blocks)", |m| m.timings[Stage::Contacts], "-", "", f64::NAN, None),
            row("Dt from the source (for the cells)", |m| m.timings[Stage::Dt], "-", "", 100.0, None),
            row("navigable core: both Dt", |m| m.timings[Stage::Nav], "-", "", 200.0, None),
            row("surface", |m| m.timings[Stage::Surface], "VTK flying edges", "vtk_flying_edges", 80.0, Some(1.0)),
            row("surface", |m| m.timings[Stage::Surface], "scikit-image", "skimage_marching_cubes", 80.0, None),
            row("cells", |m| m.timings[Stage::Cells], "-", "", 50.0, None),
            row("total after load, no core (as `prep`)", |m| m.timings.total_after_load - m.timings[Stage::Nav], "-", "", 500.0, None),
            row("total after load, with core (`fly`, `view`)", |m| m.timings.total_after_load, "-", "", 500.0, None),
        ],
    })
}

/// Whether a row meets its targets: "yes", "NO", or "-" where it has none.
fn met(r: &Value) -> &'static str {
    let time = r["target_ms"]
        .as_f64()
        .filter(|&t| t > 0.0)
        .zip(r["voyage_ms"].as_f64())
        .map(|(t, ms)| ms <= t);
    let ratio = r["target_speedup"]
        .as_f64()
        .zip(r["speedup"].as_f64())
        .map(|(t, x)| x >= t);
    match (time, ratio) {
        (None, None) => "-",
        (a, b) if a.unwrap_or(true) && b.unwrap_or(true) => "yes",
        _ => "NO",
    }
}

fn print_case(c: &Value) {
    println!(
        "{}: {} lumen voxels, box {}, {} triangles, centerline {:.0} mm, {} cells; process peak {:.0} MB while it ran, for a {:.0} MB CT (the bench holds more than one prep does; `voyage prep --json` gives one run's)",
        c["case"].as_str().unwrap_or(""),
        c["lumen_voxels"],
        c["box"],
        c["triangles"],
        c["centerline_length_mm"].as_f64().unwrap_or(0.0),
        c["cells"],
        c["peak_rss_mb"].as_f64().unwrap_or(0.0),
        c["ct_mb"].as_f64().unwrap_or(0.0)
    );
    println!(
        "  {:<42} {:>10} {:<20} {:>10} {:>8} {:>13} {:>10} {:>8}  met",
        "stage", "voyage ms", "reference", "ref ms", "speedup", "(range)", "target ms", "target×"
    );
    let empty = vec![];
    for r in c["rows"].as_array().unwrap_or(&empty) {
        let f = |v: &Value, p: usize| {
            v.as_f64()
                .map(|x| format!("{x:.p$}"))
                .unwrap_or_else(|| "-".into())
        };
        let range = match r["speedup_range"].as_array() {
            Some(a) if a.len() == 2 => format!("{}–{}", f(&a[0], 2), f(&a[1], 2)),
            _ => "-".into(),
        };
        println!(
            "  {:<42} {:>10} {:<20} {:>10} {:>7}× {:>13} {:>10} {:>7}  {}",
            r["stage"].as_str().unwrap_or(""),
            f(&r["voyage_ms"], 1),
            r["reference"].as_str().unwrap_or(""),
            f(&r["reference_ms"], 1),
            f(&r["speedup"], 2),
            range,
            f(&r["target_ms"], 0),
            r["target_speedup"]
                .as_f64()
                .map(|x| format!("{x:.0}×"))
                .unwrap_or_else(|| "-".into()),
            met(r),
        );
    }
}
