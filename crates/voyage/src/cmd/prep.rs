//! `voyage prep INPUT --out DIR`: the whole preprocessing, with its exports.

use std::{io::IsTerminal, path::PathBuf, time::Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use glam::DVec3;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use voyage_core::{
    ComponentKind, Geometry, PatientPosition, PositionSource, PrepOptions, Stage, Study, prepare,
};
use voyage_io::{
    self as io, LoadOptions,
    export::study::{StudyExports, check_out_dir, write_study},
};

#[derive(Clone, Copy, Debug, Default, ValueEnum)]
pub enum Frame {
    /// DICOM patient coordinates (LPS mm), as viewers show them.
    #[default]
    Lps,
    /// Volume-local mm (x = i·sx, y = j·sy, z = k·sz), as the phantoms' truth files give them.
    Local,
}

/// The input and the preprocessing choices every command that runs `prep` shares.
#[derive(Args, Debug, Clone)]
pub struct InputArgs {
    /// A CT (DICOM folder or file, NIfTI, MetaImage, NRRD) or a lumen mask (0/1 labels).
    pub input: PathBuf,
    /// Treat the input as a lumen mask, every non-zero label lumen (default: detected when it
    /// holds 0 and one other value, as 0/1 or 0/255; labels 0/1/2... need it).
    #[arg(long)]
    pub mask: bool,
    #[command(flatten)]
    pub points: PointArgs,
    /// DICOM: which series to load when the folder holds several.
    #[arg(long)]
    pub series: Option<String>,
}

/// A DICOM PatientPosition code, any case.
fn parse_position(s: &str) -> Result<PatientPosition, String> {
    PatientPosition::parse(s)
        .ok_or_else(|| format!("{s}: expected one of HFS, HFP, FFS, FFP, HFDR, HFDL, FFDR, FFDL"))
}

/// Corrections to the automatic choices: which gas is colon, where the flight starts and
/// ends, how the patient lay, whether the colon's tagged fluid is cleansed.
#[derive(Args, Debug, Clone, Default)]
pub struct PointArgs {
    /// A point in gas that is colon (mm, see --coords): its gas joins the colon. It does not
    /// move the start; --source does. Repeat it for several segments (`prep --json` lists
    /// each segment with a point in it, `anchor_lps_mm`).
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub seed: Vec<DVec3>,
    /// A point in gas that is not colon (mm, see --coords): its gas is left out, even when it
    /// is the lowest (the rectum is then the lowest of the rest). Repeatable.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub exclude: Vec<DVec3>,
    /// The rectum end of the flight (mm, see --coords).
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub source: Option<DVec3>,
    /// The cecum end of the flight (mm, see --coords).
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub target: Option<DVec3>,
    /// The coordinate frame of --seed, --source and --target.
    #[arg(long, value_enum, default_value_t = Frame::Lps)]
    pub coords: Frame,
    /// How the patient lay, as a DICOM PatientPosition code (HFS, HFP, FFS, FFP, HFDR, HFDL,
    /// FFDR, FFDL), overriding the file and the air–fluid levels: decides on which side fluid
    /// lies and which way is up in the view.
    #[arg(long, value_parser = parse_position)]
    pub position: Option<PatientPosition>,
    /// Keep the colon's tagged fluid: no electronic cleansing (on by default where the
    /// colon holds tagged fluid; the surface is then cut at the fluid's edge).
    #[arg(long)]
    pub no_cleanse: bool,
}

impl PointArgs {
    /// Puts the choices into `opts` for a volume of geometry `g` whose loader found `meta`.
    pub fn apply(&self, g: &Geometry, meta: &io::Meta, opts: &mut PrepOptions) {
        let to_local = |p: DVec3| match self.coords {
            Frame::Lps => g.patient_to_local(p),
            Frame::Local => p,
        };
        opts.segment.seeds_mm = self.seed.iter().map(|&p| to_local(p)).collect();
        opts.segment.exclude_mm = self.exclude.iter().map(|&p| to_local(p)).collect();
        opts.centerline.source_mm = self.source.map(to_local);
        opts.centerline.target_mm = self.target.map(to_local);
        opts.segment.position = match (self.position, meta.position) {
            (Some(p), _) => Some((p, PositionSource::Given)),
            (None, Some(p)) => Some((p, PositionSource::Dicom)),
            (None, None) => None,
        };
        if self.no_cleanse {
            opts.cleanse = None;
        }
    }
}

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

pub fn parse_point(s: &str) -> Result<DVec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s}: {e}"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(x, y, z)),
        _ => Err(format!("{s}: expected three numbers x,y,z")),
    }
}

/// A study ready for navigation, and what it cost to load.
pub struct Prepared {
    /// In the study storage: its local mm are read with `study.ct.geometry()`.
    pub study: Study,
    pub load_ms: f64,
}

/// Loads the input and runs the whole preprocessing (a progress bar on a terminal), with the
/// navigable core for a camera `nav_min_wall_mm` from the wall (None: no navigation).
pub fn load_and_prepare(a: &InputArgs, nav_min_wall_mm: Option<f64>) -> Result<Prepared> {
    let t0 = Instant::now();
    let loaded = io::load(
        &a.input,
        &LoadOptions {
            series_uid: a.series.clone(),
        },
    )?;
    let load_ms = t0.elapsed().as_secs_f64() * 1e3;
    let g = loaded.volume.geometry().clone();
    let mut opts = PrepOptions::default();
    a.points.apply(&g, &loaded.meta, &mut opts);
    opts.segment.mask = a.mask.then_some(true);
    opts.nav_min_wall_mm = nav_min_wall_mm;

    let bar = progress_bar();
    let mut study = prepare(loaded.volume, &opts, |stage| {
        if let Some(b) = &bar {
            b.set_message(stage.name());
            b.set_position(Stage::ALL.iter().position(|s| *s == stage).unwrap_or(0) as u64);
        }
    })
    .with_context(|| format!("{}", a.input.display()))?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    if study.centerline.points_mm.len() < 2 {
        bail!("{}: the centerline is empty", a.input.display());
    }
    study
        .segmentation
        .warnings
        .splice(0..0, loaded.meta.warnings);
    for w in &study.segmentation.warnings {
        eprintln!("warning: {}: {w}", a.input.display());
    }
    Ok(Prepared { study, load_ms })
}

pub fn run(a: &PrepArgs) -> Result<()> {
    check_out_dir(&a.out)?;
    let Prepared { study, load_ms } = load_and_prepare(&a.input, None)?;
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

fn progress_bar() -> Option<ProgressBar> {
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let b = ProgressBar::new(Stage::ALL.len() as u64);
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
                "at_edge": g.at_edge,
                "centerline_arc_mm": span,
            })
        })
        .collect()
}

fn print_text(s: &Study, g: &Geometry, load_ms: f64) {
    let seg = &s.segmentation;
    let colon_ml = seg
        .components
        .iter()
        .find(|c| c.kind == ComponentKind::Colon)
        .map_or(0.0, |c| c.volume_ml);
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
            "  gas       {:>9} voxels {:>8.1} ml  {:?}",
            c.voxels, c.volume_ml, c.kind
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
    println!(
        "centerline  {:.0} mm, {} points",
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
