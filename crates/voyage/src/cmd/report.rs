//! `voyage report INPUT --findings findings.json --out DIR`: the reading's report from the
//! findings the window exported: each marker's view drawn again, its segment and distance
//! from the rectum end, the C-RADS category, and the coverage of a two-way reading with
//! review, as `report.html` beside the findings' files. An exam scanned supine and prone
//! gives a report over both positions (each finding once, the coverage over both) and each
//! position's own.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use voyage_core::Study;
use voyage_export::{
    PositionReading, ReportCoverage, export_pair_reading, export_reading, read_findings,
};
use voyage_nav::{Camera, FlightOptions};
use voyage_view::{
    BothCoverage, CellMesh, CoverageOptions, Findings, Lighting, Link, Marker, MucosaMap,
    READING_FOV_DEG, Reading, Strategy, View, Visibility, both_readings, render_rgba,
};

use super::prep::load_and_prepare_exam;
use crate::open::{InputArgs, Prepared, position_of};

#[derive(Args, Debug)]
pub struct ReportArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// The findings.json the window's Export wrote for this study; for an exam of two
    /// positions, the folder it exported into (a findings.json in a folder per position,
    /// e.g. supine/findings.json and prone/findings.json).
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
    // Before any work: the findings are there, and an exam of two positions reads them from
    // a folder.
    if !a.findings.exists() {
        anyhow::bail!(
            "{}: no such file or folder: give --findings the findings.json the window's Export wrote (for an exam of two positions, the folder it exported into, which holds supine/findings.json and prone/findings.json)",
            a.findings.display()
        );
    }
    if a.findings.is_file() && crate::open::exam_positions(&a.input)?.len() >= 2 {
        let folder = a
            .findings
            .parent()
            .and_then(|p| p.parent())
            .filter(|p| !p.as_os_str().is_empty())
            .map_or_else(|| "the folder".to_string(), |p| p.display().to_string());
        anyhow::bail!(
            "{}: the exam has two positions: give --findings the folder the window exported them into (e.g. {folder}, which holds supine/findings.json and prone/findings.json), not one position's file",
            a.findings.display()
        );
    }
    let min_wall = FlightOptions::default().safety.min_wall_mm;
    let mut positions = load_and_prepare_exam(&a.input, Some(min_wall))?;
    if positions.len() >= 2 {
        return both_positions(a, &positions[..2]);
    }
    let Prepared { study, exam, .. } = positions.remove(0);
    let findings = read_findings(&a.findings, study.ct.geometry())?;
    let read = read(a, &study, a.input.input.display().to_string())?;
    let files = export_reading(&a.out, &findings, &study, &exam, read.coverage, |_, m| {
        Ok(snapshot(a, &study, &read.mesh, m))
    })?;
    let n = findings.markers.len();
    println!(
        "wrote {} files to {} (report.html: {n} finding{})",
        files.len(),
        a.out.display(),
        if n == 1 { "" } else { "s" }
    );
    Ok(())
}

/// One position read for the report: its mesh, the reading (None with --no-coverage) and
/// the figures.
struct Read {
    mesh: CellMesh,
    reading: Option<Reading>,
    coverage: ReportCoverage,
}

fn read(a: &ReportArgs, study: &Study, name: String) -> Result<Read> {
    let mut mesh = CellMesh::new(&study.surface, &study.cells);
    mesh.index_cells();
    if a.no_coverage {
        return Ok(Read {
            mesh,
            reading: None,
            coverage: ReportCoverage::default(),
        });
    }
    // The same reading as `voyage coverage` with its defaults, not the snapshots' lens.
    let lens = Camera::lens(READING_FOV_DEG);
    let r =
        super::coverage::read_with_bar(study, &mesh, CoverageOptions::default(), lens, 256, &name)?;
    let coverage = ReportCoverage {
        session_pct: None,
        one_way_pct: Some(r.one_way.percent()),
        two_way_pct: Some(r.two_way.percent()),
        after_review_pct: Some(r.after_review.percent()),
        patches_left: Some(r.after_review.patches(&mesh).len()),
        by_segment: r.after_review.by_segment(&mesh, study),
    };
    Ok(Read {
        mesh,
        reading: Some(r),
        coverage,
    })
}

fn position_reading<'a>(p: &'a Prepared, findings: &'a Findings, r: &Read) -> PositionReading<'a> {
    PositionReading {
        name: position_of(&p.study),
        study: &p.study,
        exam: &p.exam,
        findings,
        coverage: r.coverage.clone(),
    }
}

/// Marker `m`'s view drawn again (RGBA, [`SNAPSHOT_PX`]²).
fn snapshot(a: &ReportArgs, study: &Study, mesh: &CellMesh, m: &Marker) -> (u32, u32, Vec<u8>) {
    let camera = Camera::new(m.view).with_fov(a.fov);
    let view = View::new(&camera, SNAPSHOT_PX, SNAPSHOT_PX);
    let cells = Visibility::new(&study.cells, Strategy::Lg)
        .select(&study.cells, &view)
        .cells;
    let rgba = render_rgba(
        mesh,
        &camera,
        &cells,
        SNAPSHOT_PX,
        SNAPSHOT_PX,
        &Lighting::default(),
    );
    (SNAPSHOT_PX, SNAPSHOT_PX, rgba)
}

/// The report of an exam read in two positions: each position's findings from the folder
/// the window exported into (a position without its findings.json has none marked), each
/// read both ways, the coverage over both, the report over both.
fn both_positions(a: &ReportArgs, positions: &[Prepared]) -> Result<()> {
    let (pa, pb) = (&positions[0], &positions[1]);
    let files: Vec<PathBuf> = [pa, pb]
        .iter()
        .map(|p| a.findings.join(position_of(&p.study)).join("findings.json"))
        .collect();
    if !files.iter().any(|f| f.exists()) {
        anyhow::bail!(
            "{}: the exam has two positions: --findings names the folder the window exported them into, with {} (neither found)",
            a.findings.display(),
            files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(" and ")
        );
    }
    let mut findings = Vec::new();
    let mut reads = Vec::new();
    for (p, file) in [pa, pb].into_iter().zip(&files) {
        let name = position_of(&p.study);
        findings.push(if file.exists() {
            read_findings(file, p.study.ct.geometry())?
        } else {
            eprintln!(
                "warning: {}: not found: the report counts no findings marked {name}",
                file.display()
            );
            Findings::default()
        });
        reads.push(read(
            a,
            &p.study,
            format!("{} ({name})", a.input.input.display()),
        )?);
    }
    let link = Link::between(&pa.study, &pb.study);
    let maps = [
        MucosaMap::of(&pa.study, &reads[0].mesh),
        MucosaMap::of(&pb.study, &reads[1].mesh),
    ];
    let stages: Vec<(&str, BothCoverage)> = match (&reads[0].reading, &reads[1].reading) {
        (Some(ra), Some(rb)) => {
            let [one_way, two_way, after_review] =
                both_readings(&link, (&pa.study, &maps[0], ra), (&pb.study, &maps[1], rb));
            vec![
                ("One way (rectum to cecum)", one_way),
                ("Both ways", two_way),
                ("After the review of unseen patches", after_review),
            ]
        }
        _ => Vec::new(),
    };
    let files = export_pair_reading(
        &a.out,
        position_reading(pa, &findings[0], &reads[0]),
        position_reading(pb, &findings[1], &reads[1]),
        &link,
        &stages,
        |p, _, m| {
            let (study, read) = if p == 0 {
                (&pa.study, &reads[0])
            } else {
                (&pb.study, &reads[1])
            };
            Ok(snapshot(a, study, &read.mesh, m))
        },
    )?;
    println!(
        "wrote {} files to {} (report.html over {} and {}: {} and {} findings)",
        files.len(),
        a.out.display(),
        position_of(&pa.study),
        position_of(&pb.study),
        findings[0].markers.len(),
        findings[1].markers.len()
    );
    Ok(())
}
