//! `voyage report INPUT --findings findings.json --out DIR`: the reading's report from the
//! findings the window exported: each marker's view drawn again, its segment and distance
//! from the rectum end, the C-RADS category, and the coverage of a two-way reading with
//! review, as `report.html` beside the findings' files.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use voyage_export::{ReportCoverage, export_reading, read_findings};
use voyage_nav::{Camera, FlightOptions};
use voyage_view::{
    CellMesh, CoverageOptions, Lighting, READING_FOV_DEG, Strategy, View, Visibility,
    read_both_ways, render_rgba,
};

use super::prep::load_and_prepare;
use crate::open::{InputArgs, Prepared};

#[derive(Args, Debug)]
pub struct ReportArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// The findings.json the window's Export wrote for this study.
    #[arg(long)]
    pub findings: PathBuf,
    /// Folder to write into: report.html, findings.json and .mrk.json, a PNG per marker.
    #[arg(long)]
    pub out: PathBuf,
    /// Leave out the coverage (the two-way reading with review takes some seconds).
    #[arg(long)]
    pub no_coverage: bool,
    /// The snapshots' vertical field of view (degrees).
    #[arg(long, default_value_t = 90.0)]
    pub fov: f64,
}

/// Side of the snapshots (pixels), as the window's export.
const SNAPSHOT_PX: u32 = 512;

pub fn run(a: &ReportArgs) -> Result<()> {
    voyage_export::study::check_out_dir(&a.out)?;
    let min_wall = FlightOptions::default().safety.min_wall_mm;
    let Prepared { study, exam, .. } = load_and_prepare(&a.input, Some(min_wall))?;
    let findings = read_findings(&a.findings, study.ct.geometry())?;
    let mut mesh = CellMesh::new(&study.surface, &study.cells);
    mesh.index_cells();
    let coverage = if a.no_coverage {
        ReportCoverage::default()
    } else {
        // The same reading as `voyage coverage` with its defaults, not the snapshots' lens.
        let lens = Camera::lens(READING_FOV_DEG);
        let bar = super::coverage::reading_bar();
        let r = read_both_ways(&study, &mesh, CoverageOptions::default(), lens, 256, |p| {
            super::coverage::show_reading(&bar, p)
        })
        .with_context(|| format!("{}: the two-way reading", a.input.input.display()))?;
        if let Some(b) = bar {
            b.finish_and_clear();
        }
        ReportCoverage {
            session_pct: None,
            one_way_pct: Some(r.one_way.percent()),
            two_way_pct: Some(r.two_way.percent()),
            after_review_pct: Some(r.after_review.percent()),
            patches_left: Some(r.after_review.patches(&mesh).len()),
            by_segment: r.after_review.by_segment(&mesh, &study),
        }
    };
    let files = export_reading(&a.out, &findings, &study, &exam, coverage, |_, m| {
        let camera = Camera::new(m.view).with_fov(a.fov);
        let view = View::new(&camera, SNAPSHOT_PX, SNAPSHOT_PX);
        let cells = Visibility::new(&study.cells, Strategy::Lg)
            .select(&study.cells, &view)
            .cells;
        let rgba = render_rgba(
            &mesh,
            &camera,
            &cells,
            SNAPSHOT_PX,
            SNAPSHOT_PX,
            &Lighting::default(),
        );
        Ok((SNAPSHOT_PX, SNAPSHOT_PX, rgba))
    })?;
    println!(
        "wrote {} files to {} (report.html: {} findings)",
        files.len(),
        a.out.display(),
        findings.markers.len()
    );
    Ok(())
}
