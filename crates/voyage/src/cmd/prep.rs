//! `voyage prep INPUT --out DIR`: the whole preprocessing, with its exports. An exam
//! scanned supine and prone: each position's exports in a folder of its name, and the link
//! of their centerlines.

use std::{io::IsTerminal, path::PathBuf};

use anyhow::Result;
use clap::Args;
use glam::DVec3;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use voyage_core::{Geometry, Stage, Study};
use voyage_export::study::{StudyExports, check_out_dir, write_study};
use voyage_io::write_atomic;
use voyage_view::Link;

use crate::open::{InputArgs, Prepared, open_exam, open_study, position_of};

#[derive(Args, Debug)]
pub struct PrepArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Folder for the exports (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Print one JSON object with counts and timings.
    #[arg(long)]
    pub json: bool,
    /// Also write surface.stl (about twice the PLY's size; 3D printing, older tools).
    #[arg(long)]
    pub stl: bool,
}

/// Opens the input ([`open_study`]) with a progress bar on a terminal, and prints the
/// study's warnings.
pub fn load_and_prepare(a: &InputArgs, nav_min_wall_mm: Option<f64>) -> Result<Prepared> {
    let bar = progress_bar();
    let prepared = open_study(a, nav_min_wall_mm, |o| {
        if let Some(b) = &bar {
            b.set_message(o.what.to_string());
            b.set_position(o.step as u64);
        }
    });
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let prepared = prepared?;
    for w in &prepared.study.segmentation.warnings {
        eprintln!("warning: {}: {w}", a.input.display());
    }
    Ok(prepared)
}

/// [`load_and_prepare`] for every position of the exam (see [`crate::open::open_exam`]).
pub fn load_and_prepare_exam(a: &InputArgs, nav_min_wall_mm: Option<f64>) -> Result<Vec<Prepared>> {
    let bar = progress_bar();
    let positions = open_exam(a, nav_min_wall_mm, |i, n, o| {
        if let Some(b) = &bar {
            let of = if n > 1 {
                format!("position {} of {n}: ", i + 1)
            } else {
                String::new()
            };
            b.set_message(format!("{of}{}", o.what));
            b.set_position(o.step as u64);
        }
    });
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let positions = positions?;
    for p in &positions {
        let name = match positions.len() {
            1 => a.input.display().to_string(),
            _ => format!("{} ({})", a.input.display(), position_of(&p.study)),
        };
        for w in &p.study.segmentation.warnings {
            eprintln!("warning: {name}: {w}");
        }
    }
    Ok(positions)
}

pub fn run(a: &PrepArgs) -> Result<()> {
    check_out_dir(&a.out)?;
    let mut positions = load_and_prepare_exam(&a.input, None)?;
    if positions.len() >= 2 {
        return both_positions(a, &positions[..2]);
    }
    let Prepared { study, load_ms, .. } = positions.remove(0);
    let g = study.ct.geometry();
    let written = write_study(&a.out, &study, StudyExports { stl: a.stl })?;
    let summary = summary(&study, g, load_ms);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_text(&study, g, load_ms);
        for p in written {
            println!("  wrote {}", p.display());
        }
    }
    Ok(())
}

/// An exam of two positions: each one's exports in a folder of its name, and `link.json`,
/// the correspondence of their centerlines.
fn both_positions(a: &PrepArgs, positions: &[Prepared]) -> Result<()> {
    let link = Link::between(&positions[0].study, &positions[1].study);
    let mut summaries = Vec::new();
    let mut written = Vec::new();
    for p in positions {
        let name = position_of(&p.study);
        let g = p.study.ct.geometry();
        written.extend(write_study(
            &a.out.join(name),
            &p.study,
            StudyExports { stl: a.stl },
        )?);
        let mut s = summary(&p.study, g, p.load_ms);
        s["position"] = json!(name);
        summaries.push(s);
        if !a.json {
            println!("{name}:");
            print_text(&p.study, g, p.load_ms);
        }
    }
    let (from, to) = link.arcs();
    let link_json = json!({
        "positions": positions.iter().map(|p| position_of(&p.study)).collect::<Vec<_>>(),
        "note": "arc_mm[0][i] along the first position's centerline (centerline.json) is the same place of the colon as arc_mm[1][i] along the second's",
        "arc_mm": [from, to],
        "anchored_at_flexures": link.anchored,
        "mean_moved_mm": link.mean_moved_mm,
    });
    let path = a.out.join("link.json");
    write_atomic(&path, |w| {
        w.write_all((serde_json::to_string_pretty(&link_json)? + "\n").as_bytes())
    })?;
    written.push(path);
    if a.json {
        let out = json!({
            "positions": summaries,
            "link": {
                "anchored_at_flexures": link.anchored,
                "mean_moved_mm": link.mean_moved_mm,
            },
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "linked: {} ({})",
            if link.anchored {
                "anchored at the ends and flexures"
            } else {
                "anchored at the ends only"
            },
            format_args!("the colon moved {:.0} mm on average", link.mean_moved_mm)
        );
        for p in written {
            println!("  wrote {}", p.display());
        }
    }
    Ok(())
}

fn progress_bar() -> Option<ProgressBar> {
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let b = ProgressBar::new(crate::open::OPEN_STEPS as u64);
    b.set_style(ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}").ok()?);
    Some(b)
}

fn summary(s: &Study, g: &Geometry, load_ms: f64) -> serde_json::Value {
    let t = &s.timings;
    let mut timings_ms = json!(t);
    timings_ms["load"] = json!(load_ms);
    json!({
        "lumen_voxels": s.segmentation.lumen_voxels,
        "from_mask": s.segmentation.from_mask,
        "components": s.segmentation.components.iter().map(|c| c.voxels).collect::<Vec<_>>(),
        "component_details": s.segmentation.components,
        "source_mm": s.source_mm().to_array(),
        "target_mm": s.target_mm().to_array(),
        "source_lps_mm": g.local_to_patient(s.source_mm()).to_array(),
        "target_lps_mm": g.local_to_patient(s.target_mm()).to_array(),
        "centerline_length_mm": s.centerline.length_mm,
        "position": s.segmentation.orientation.position.code(),
        "position_source": s.segmentation.orientation.source,
        "gravity_lps": s.segmentation.orientation.gravity_lps,
        "segments": s.segmentation.segments,
        "gaps": gaps(s),
        "warnings": s.segmentation.warnings,
        "contact_voxels": s.contact_voxels,
        "cells": s.cells.cells.len(),
        "triangles": s.surface.mesh.triangles.len(),
        "cleanse": cleanse_summary(s),
        "surface_roughness": roughness(s).map(|(air, fluid)| json!({"air_deg": air, "fluid_deg": fluid})),
        "timings_ms": timings_ms,
        "peak_rss_mb": peak_rss_mb(),
    })
}

/// What electronic cleansing changed; null when it did not run or found no tagged material.
fn cleanse_summary(s: &Study) -> serde_json::Value {
    let c = &s.cleansing;
    if c.is_empty() {
        return serde_json::Value::Null;
    }
    json!({"voxels_changed": c.len(), "tagged_voxels": c.tagged_voxels, "left_lumen": c.left_lumen, "stool_lumps": c.stool_lumps, "stool_voxels": c.stool_voxels, "joined_lumen": c.joined_lumen})
}

/// The surface's mean angle between neighbouring triangles (degrees) away from and near
/// tagged material of the original CT (within 2 mm; None without any); None for a mask.
fn roughness(s: &Study) -> Option<(Option<f64>, Option<f64>)> {
    (!s.segmentation.from_mask).then(|| {
        voyage_core::roughness(
            &s.surface.mesh,
            &s.ct,
            voyage_core::SegmentOptions::default()
                .fluid_hu
                .unwrap_or(200),
            2.0,
        )
    })
}

/// Each bridged gap with its span on the centerline.
fn gaps(s: &Study) -> Vec<serde_json::Value> {
    s.segmentation
        .gaps
        .iter()
        .enumerate()
        .map(|(i, g)| {
            let span = s.gap_spans[i];
            json!({
                "between": g.between,
                "length_mm": g.length_mm,
                "from_lps_mm": g.from_lps_mm,
                "to_lps_mm": g.to_lps_mm,
                "mean_cost": g.mean_cost,
                "fluid_filled": g.fluid_filled,
                "at_edge": g.at_edge(),
                "centerline_arc_mm": span,
            })
        })
        .collect()
}

fn print_text(s: &Study, g: &Geometry, load_ms: f64) {
    let seg = &s.segmentation;
    // The colon's gas, every segment kept, as the report counts it.
    let colon_ml: f64 = seg
        .segments
        .iter()
        .filter(|s| s.kept)
        .map(|s| s.gas_ml)
        .sum();
    println!(
        "lumen       {} voxels ({colon_ml:.0} ml of gas{}){}",
        seg.lumen_voxels,
        if seg.fluid_voxels > 0 {
            format!(", {} voxels of tagged fluid", seg.fluid_voxels)
        } else {
            String::new()
        },
        if seg.from_mask { ", from a mask" } else { "" }
    );
    for c in &seg.components {
        println!(
            "  gas       {:>9} voxels {:>8.1} ml  {}",
            c.voxels,
            c.volume_ml,
            c.kind.name()
        );
    }
    if seg.small_components > 0 {
        println!("  gas       {} smaller pockets", seg.small_components);
    }
    let o = &seg.orientation;
    println!(
        "position    {} ({}; {})",
        o.position.code(),
        o.position.describe(),
        o.source.describe()
    );
    for (i, sg) in seg.segments.iter().filter(|x| x.kept).enumerate() {
        println!(
            "  colon     {}. {:<36} {:>7.1} ml gas {:>7.1} ml fluid",
            i + 1,
            sg.label,
            sg.gas_ml,
            sg.fluid_ml
        );
    }
    for (gap, span) in seg.gaps.iter().zip(&s.gap_spans) {
        let at = span.map_or(String::new(), |a| {
            format!(", centerline {:.0}–{:.0} mm", a[0], a[1])
        });
        println!(
            "  gap       {}→{}: {:.0} mm bridged{at}",
            gap.between[0] + 1,
            gap.between[1] + 1,
            gap.length_mm
        );
    }
    for sg in seg.segments.iter().filter(|x| !x.kept && x.gas_ml >= 5.0) {
        println!(
            "  left out  {:<36} {:>7.1} ml gas: {}",
            sg.label,
            sg.gas_ml,
            sg.reason.as_deref().unwrap_or("")
        );
    }
    let lps = |p: DVec3| g.local_to_patient(p);
    println!(
        "source      {:.1?} mm LPS (rectum)",
        lps(s.source_mm()).to_array()
    );
    println!(
        "target      {:.1?} mm LPS (cecum)",
        lps(s.target_mm()).to_array()
    );
    let canal = match s.centerline.canal_mm {
        c if c > 0.0 => {
            format!("; its first {c:.0} mm, down to the colon's lowest gas, too narrow to fly")
        }
        _ => String::new(),
    };
    println!(
        "centerline  {:.0} mm, {} points{canal}",
        s.centerline.length_mm,
        s.centerline.points_mm.len()
    );
    println!(
        "surface     {} triangles, {} vertices",
        s.surface.mesh.triangles.len(),
        s.surface.mesh.positions.len()
    );
    println!("cells       {}", s.cells.cells.len());
    if !s.cleansing.is_empty() {
        let r = roughness(s).map_or(String::new(), |(air, fluid)| {
            let deg = |x: Option<f64>| x.map_or("-".to_string(), |d| format!("{d:.1}°"));
            format!(
                "; surface roughness {} in air, {} where fluid lay",
                deg(air),
                deg(fluid)
            )
        });
        let c = &s.cleansing;
        let stool = if c.stool_lumps > 0 {
            format!(
                ", {} lumps of tagged stool ({} voxels)",
                c.stool_lumps, c.stool_voxels
            )
        } else {
            String::new()
        };
        println!(
            "cleansing   {} voxels of tagged fluid made air{stool}, {} voxels changed{r}",
            c.tagged_voxels,
            c.len()
        );
    }
    if s.contact_voxels > 0 {
        println!(
            "contacts    {} lumen voxels made wall where loops of the colon touch",
            s.contact_voxels
        );
    }
    let t = &s.timings;
    let stages: Vec<String> = Stage::ALL
        .iter()
        .map(|&stage| format!("{} {:.0}", stage.name(), t[stage]))
        .collect();
    println!(
        "time        load {load_ms:.0} ms; {}; total after load {:.0} ms",
        stages.join(", "),
        t.total_after_load
    );
    if let Some(mb) = peak_rss_mb() {
        println!("memory      peak {mb:.0} MB");
    }
}

/// Peak resident memory of this process (Linux), MB.
pub fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}
