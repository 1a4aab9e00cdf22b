//! `voyage bench prep`: the preprocessing stage by stage, beside the reference libraries on
//! the same lumen mask in the same run.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};
use voyage_core::distance::geodesic_distance;
use voyage_core::io::{self, nifti, LoadOptions};
use voyage_core::phantom::{self, ColonOptions};
use voyage_core::prep::{prepare, PrepOptions, Study, Timings};
use voyage_core::Volume;

use super::bench::{find_python, median, Common};

const PREP_REFERENCE_PY: &str = include_str!("../../../../bench/prep_reference.py");

pub fn run(inputs: Vec<PathBuf>, phantom: bool, dir: &Path, repeats: usize, reference: bool, common: &Common) -> Result<()> {
    let (threads, python, json_out) = (common.threads, common.python.as_deref(), common.json);
    rayon::ThreadPoolBuilder::new().num_threads(threads).build_global().ok();
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create folder", dir.display()))?;
    let mut cases: Vec<(String, Volume<i16>)> = Vec::new();
    if phantom {
        eprintln!("making the colon phantom ...");
        cases.push(("colon phantom (512×512×400)".into(), phantom::colon(&ColonOptions::default())?.ct));
    }
    for p in &inputs {
        cases.push((p.display().to_string(), io::load(p, &LoadOptions::default())?.volume));
    }
    if cases.is_empty() {
        bail!("nothing to measure: give an input or leave the phantom in");
    }
    let mut results = Vec::new();
    for (i, (name, ct)) in cases.into_iter().enumerate() {
        eprintln!("measuring {name} ...");
        let r = measure(&name, ct, repeats)?;
        let refs = if reference {
            let mask = dir.join(format!("case{i}-lumen.nii.gz"));
            nifti::save(&mask, &r.study.segmentation.lumen)?;
            match run_reference(python, dir, &mask, r.study.source, repeats) {
                Ok(v) => v,
                Err(e) => {
                    eprintln!("reference not run: {e:#}");
                    Value::Null
                }
            }
        } else {
            Value::Null
        };
        results.push(report(&r, refs, threads));
    }
    if json_out {
        println!("{}", serde_json::to_string_pretty(&json!({"bench": "prep", "threads": threads, "repeats": repeats, "cases": results}))?);
    } else {
        for r in &results {
            print_case(r);
        }
    }
    Ok(())
}

struct Measured {
    name: String,
    study: Study,
    timings: Timings,
    dt_single_ms: f64,
    ct_mb: f64,
    peak_rss_mb: Option<f64>,
}

/// Median per stage over `repeats` runs after a warm-up, and one plain Dt alone.
fn measure(name: &str, ct: Volume<i16>, repeats: usize) -> Result<Measured> {
    let ct_mb = (ct.data().len() * 2) as f64 / 1e6;
    let opts = PrepOptions::default();
    let mut study = prepare(ct.clone(), &opts, |_| {})?;
    let mut runs: Vec<Timings> = Vec::new();
    for _ in 0..repeats.max(1) {
        study = prepare(ct.clone(), &opts, |_| {})?;
        runs.push(study.timings.clone());
    }
    let med = |f: fn(&Timings) -> f64| median(&mut runs.iter().map(f).collect::<Vec<_>>());
    let timings = Timings {
        segment: med(|t| t.segment),
        ds: med(|t| t.ds),
        skeleton: med(|t| t.skeleton),
        contacts: med(|t| t.contacts),
        dt: med(|t| t.dt),
        centerline: med(|t| t.centerline),
        surface: med(|t| t.surface),
        cells: med(|t| t.cells),
        total_after_load: med(|t| t.total_after_load),
    };
    let lumen = &study.segmentation.lumen;
    let mut single = Vec::new();
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        geodesic_distance(lumen, &study.ds.grid, study.source)?;
        single.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(Measured { name: name.into(), dt_single_ms: median(&mut single), study, timings, ct_mb, peak_rss_mb: super::prep::peak_rss_mb() })
}

fn run_reference(python: Option<&Path>, dir: &Path, mask: &Path, source: [usize; 3], repeats: usize) -> Result<Value> {
    let python = find_python(python)?;
    let script = dir.join("prep_reference.py");
    std::fs::write(&script, PREP_REFERENCE_PY).with_context(|| format!("{}: cannot write", script.display()))?;
    let out = Command::new(&python)
        .arg(&script)
        .arg(mask)
        .arg(format!("{},{},{}", source[0], source[1], source[2]))
        .arg(repeats.max(1).to_string())
        .env("OMP_NUM_THREADS", "1")
        .output()
        .with_context(|| format!("cannot run {}", python.display()))?;
    if !out.status.success() {
        bail!("{} failed: {}", script.display(), String::from_utf8_lossy(&out.stderr).trim());
    }
    serde_json::from_slice(&out.stdout).context("reference printed no JSON")
}

fn report(m: &Measured, refs: Value, threads: usize) -> Value {
    let t = &m.timings;
    let s = &m.study;
    let r = |k: &str| refs.get(k).and_then(|v| v["ms"].as_f64());
    let row = |stage: &str, ours: f64, reference: &str, ref_ms: Option<f64>, target_ms: f64, target_ratio: Option<f64>| {
        json!({
            "stage": stage, "voyage_ms": ours, "reference": reference, "reference_ms": ref_ms,
            "speedup": ref_ms.map(|x| x / ours), "target_ms": target_ms, "target_speedup": target_ratio,
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
            row("segment", t.segment, "-", None, 60.0, None),
            row("ds", t.ds, "edt (1 thread)", r("edt"), 100.0, Some(5.0)),
            row("ds", t.ds, "scipy.ndimage EDT", r("scipy_edt"), 100.0, None),
            row("one Dt", m.dt_single_ms, "dijkstra3d", r("dijkstra3d"), 100.0, Some(4.0)),
            row("endpoints + skeleton path", t.skeleton, "-", None, 200.0, None),
            row("centerline refinement", t.centerline, "-", None, 50.0, None),
            row("touching loops (on the skeleton's blocks)", t.contacts, "-", None, 0.0, None),
            row("both Dt fields", t.dt, "-", None, 200.0, None),
            row("surface", t.surface, "VTK flying edges", r("vtk_flying_edges"), 80.0, Some(1.0)),
            row("surface", t.surface, "scikit-image", r("skimage_marching_cubes"), 80.0, None),
            row("cells", t.cells, "-", None, 50.0, None),
            row("total after load", t.total_after_load, "-", None, 500.0, None),
        ],
    })
}

fn print_case(c: &Value) {
    println!(
        "{}: {} lumen voxels, box {}, {} triangles, centerline {:.0} mm, {} cells; peak {:.0} MB for a {:.0} MB CT",
        c["case"].as_str().unwrap_or(""),
        c["lumen_voxels"],
        c["box"],
        c["triangles"],
        c["centerline_length_mm"].as_f64().unwrap_or(0.0),
        c["cells"],
        c["peak_rss_mb"].as_f64().unwrap_or(0.0),
        c["ct_mb"].as_f64().unwrap_or(0.0)
    );
    println!("  {:<38} {:>10} {:<20} {:>10} {:>8} {:>10} {:>8}", "stage", "voyage ms", "reference", "ref ms", "speedup", "target ms", "target×");
    let empty = vec![];
    for r in c["rows"].as_array().unwrap_or(&empty) {
        let f = |v: &Value, p: usize| v.as_f64().map(|x| format!("{x:.p$}")).unwrap_or_else(|| "-".into());
        println!(
            "  {:<38} {:>10} {:<20} {:>10} {:>7}× {:>10} {:>7}",
            r["stage"].as_str().unwrap_or(""),
            f(&r["voyage_ms"], 1),
            r["reference"].as_str().unwrap_or(""),
            f(&r["reference_ms"], 1),
            f(&r["speedup"], 2),
            f(&r["target_ms"], 0),
            r["target_speedup"].as_f64().map(|x| format!("{x:.0}×")).unwrap_or_else(|| "-".into()),
        );
    }
}
