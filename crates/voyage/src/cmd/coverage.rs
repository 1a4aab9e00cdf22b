//! `voyage coverage INPUT`: how much of the mucosa the automatic reading shows: one way,
//! both ways, then after a review of every unseen patch. An exam scanned supine and prone
//! is read in both positions, and coverage over both counts mucosa seen in either.

use std::io::IsTerminal;

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::{Value, json};
use voyage_core::Study;
use voyage_nav::{Camera, FlightOptions};
use voyage_view::{
    BothCoverage, CellMesh, CoverageOptions, Link, MucosaMap, Patch, READING_FOV_DEG, Reading,
    ReadingProgress, Visit, both_readings, read_both_ways,
};

use super::prep::load_and_prepare_exam;
use crate::open::{InputArgs, Prepared, position_of};

#[derive(Args, Debug)]
pub struct CoverageArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// A triangle farther than this from the eye is not counted as seen (mm).
    #[arg(long, default_value_t = CoverageOptions::default().reading_distance_mm)]
    pub reading_distance: f64,
    /// A triangle seen more obliquely than this is not counted (degrees from its normal).
    #[arg(long, default_value_t = CoverageOptions::default().max_angle_deg)]
    pub max_angle: f64,
    /// Unseen patches smaller than this are not listed (mm²).
    #[arg(long, default_value_t = CoverageOptions::default().min_patch_mm2)]
    pub min_patch: f64,
    /// The review also visits unseen bits down to this area (mm²; default: under a third of a
    /// 3 mm polyp's footprint).
    #[arg(long, default_value_t = CoverageOptions::default().review_min_mm2)]
    pub review_min: f64,
    /// Side of the square frames the coverage is measured on (pixels).
    #[arg(long, default_value_t = 256)]
    pub size: u32,
    /// The reading lens's field of view (degrees; the frames are square), 120° as in the
    /// reading studies the coverage is compared with.
    #[arg(long, default_value_t = READING_FOV_DEG)]
    pub fov: f64,
    /// Read as the paper's camera looks, straight along the flight: no glances around
    /// (every 7 mm the reading otherwise tries turning 65° eight ways around its view, one
    /// way a frame, and glances the way that shows most unseen mucosa, ≥ 100 mm²).
    #[arg(long)]
    pub no_glances: bool,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

impl CoverageArgs {
    fn options(&self) -> Result<CoverageOptions> {
        anyhow::ensure!(
            self.reading_distance.is_finite() && self.reading_distance > 0.0,
            "--reading-distance must be a positive number of mm, not {}",
            self.reading_distance
        );
        anyhow::ensure!(
            self.max_angle.is_finite() && self.max_angle > 0.0 && self.max_angle <= 90.0,
            "--max-angle must lie in (0, 90] degrees, not {}",
            self.max_angle
        );
        anyhow::ensure!(
            self.min_patch.is_finite() && self.min_patch >= 0.0,
            "--min-patch must be a number of mm² ≥ 0, not {}",
            self.min_patch
        );
        anyhow::ensure!(
            (16..=2048).contains(&self.size),
            "--size must lie in 16..2048 pixels, not {}",
            self.size
        );
        anyhow::ensure!(
            self.fov.is_finite() && self.fov >= 10.0 && self.fov <= Camera::MAX_FOV_DEG,
            "--fov must lie in 10..{} degrees, not {}",
            Camera::MAX_FOV_DEG,
            self.fov
        );
        anyhow::ensure!(
            self.review_min.is_finite() && self.review_min > 0.0,
            "--review-min must be a positive number of mm², not {}",
            self.review_min
        );
        Ok(CoverageOptions {
            reading_distance_mm: self.reading_distance,
            max_angle_deg: self.max_angle,
            min_patch_mm2: self.min_patch,
            review_min_mm2: self.review_min,
            look_around: !self.no_glances,
        })
    }
}

pub fn run(a: &CoverageArgs) -> Result<()> {
    let options = a.options()?;
    let min_wall = FlightOptions::default().safety.min_wall_mm;
    let positions = load_and_prepare_exam(&a.input, Some(min_wall))?;
    let read: Vec<Read> = positions
        .iter()
        .map(|p| read_position(a, options, p, positions.len() > 1))
        .collect::<Result<_>>()?;
    let link = (read.len() >= 2).then(|| Link::between(&positions[0].study, &positions[1].study));
    let both = link.as_ref().map(|link| {
        let (x, y) = (&read[0], &read[1]);
        both_readings(
            link,
            (x.study, &x.map, &x.reading),
            (y.study, &y.map, &y.reading),
        )
    });
    if a.json {
        let mut out: Vec<Value> = read.iter().map(|r| position_json(r, options, a)).collect();
        let out = match (&link, both) {
            (Some(link), Some([one_way, two_way, after_review])) => json!({
                "positions": out,
                "link": link_json(link, &read),
                "both_positions": {
                    "a": read[0].position,
                    "b": read[1].position,
                    "one_way": one_way,
                    "two_way": two_way,
                    "after_review": after_review,
                },
            }),
            _ => out.remove(0),
        };
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        for r in &read {
            if read.len() > 1 {
                println!("{}:", r.position);
            }
            print_position(r, options);
        }
        if let (Some(link), Some([one_way, two_way, after_review])) = (&link, both) {
            print_both(link, &read, [one_way, two_way, after_review]);
        }
    }
    Ok(())
}

/// One position read both ways and reviewed.
struct Read<'a> {
    /// "supine", "prone" ...
    position: &'static str,
    study: &'a Study,
    mesh: CellMesh,
    map: MucosaMap,
    reading: Reading,
}

fn read_position<'a>(
    a: &CoverageArgs,
    options: CoverageOptions,
    p: &'a Prepared,
    several: bool,
) -> Result<Read<'a>> {
    let study = &p.study;
    let position = position_of(study);
    let name = if several {
        format!("{} ({position})", a.input.input.display())
    } else {
        a.input.input.display().to_string()
    };
    let mut mesh = CellMesh::new(&study.surface, &study.cells);
    mesh.index_cells();
    let reading = read_with_bar(study, &mesh, options, Camera::lens(a.fov), a.size, &name)?;
    for f in &reading.flights {
        if !f.reached {
            eprintln!(
                "warning: {name}: the {} flight did not reach its goal ({:.0} mm short); coverage counts what it showed",
                f.direction.name(),
                f.final_dt_mm
            );
        }
    }
    let without_pose = reading.patches.iter().filter(|v| v.pose.is_none()).count();
    if without_pose > 0 {
        eprintln!(
            "warning: {name}: {without_pose} unseen patch(es) have no viewpoint in the lumen that sees them"
        );
    }
    let map = if several {
        MucosaMap::of(study, &mesh)
    } else {
        MucosaMap::default()
    };
    Ok(Read {
        position,
        study,
        mesh,
        map,
        reading,
    })
}

fn position_json(r: &Read, options: CoverageOptions, a: &CoverageArgs) -> Value {
    let (study, reading) = (r.study, &r.reading);
    let geometry = study.ct.geometry();
    let place_json = |p: &Patch| {
        json!({
            "area_mm2": p.area_mm2,
            "across_mm": p.across_mm,
            "center_lps_mm": geometry.local_to_patient(p.center_mm).to_array(),
            "arc_mm": p.arc_mm(study),
            "segment": study.segment_at(p.center_mm),
        })
    };
    let patch_json = |v: &Visit| {
        let mut j = place_json(&v.patch);
        j["pose"] = json!(v.pose.map(|p| {
            let mut a = p.to_array();
            a[..3].copy_from_slice(&geometry.local_to_patient(p.position).to_array());
            a
        }));
        j
    };
    let left = reading.after_review.patches(&r.mesh);
    let [one_way, two_way, after_review] =
        [&reading.one_way, &reading.two_way, &reading.after_review].map(|c| c.percent());
    json!({
        "position": r.position,
        "one_way_pct": one_way,
        "two_way_pct": two_way,
        "after_review_pct": after_review,
        "surface_mm2": reading.after_review.total_mm2(),
        "flights_reached": {
            "forward": reading.flights[0].reached,
            "backward": reading.flights[1].reached,
        },
        "options": options,
        "frame_px": a.size,
        "fov_deg": a.fov,
        "unseen_patches": reading.patches.iter().map(patch_json).collect::<Vec<Value>>(),
        "glances": reading.glances,
        "review_visits": reading.visits,
        "patches_left_after_review": left.len(),
        "left_after_review": left.iter().map(place_json).collect::<Vec<Value>>(),
    })
}

fn print_position(r: &Read, options: CoverageOptions) {
    let reading = &r.reading;
    let left = reading.after_review.patches(&r.mesh).len();
    let [one_way, two_way, after_review] =
        [&reading.one_way, &reading.two_way, &reading.after_review].map(|c| c.percent());
    println!(
        "coverage of the mucosa ({:.0} mm², seen within {:.0} mm and {:.0}°):",
        reading.after_review.total_mm2(),
        options.reading_distance_mm,
        options.max_angle_deg
    );
    println!("  one way (rectum → cecum)   {one_way:5.1} %");
    println!("  both ways                  {two_way:5.1} %");
    println!(
        "  after the review           {after_review:5.1} %  ({} patches ≥ {:.0} mm² visited, {} visits, {} left)",
        reading.patches.len(),
        options.min_patch_mm2,
        reading.visits,
        left
    );
    if options.look_around {
        let [forward, backward] = reading.glances;
        println!("  glances around             {forward} forward, {backward} backward");
    }
}

/// What the link says of the two positions: their lengths, whether the flexures anchored
/// it, how far the colon moved.
fn link_json(link: &Link, read: &[Read]) -> Value {
    json!({
        "positions": [read[0].position, read[1].position],
        "centerline_mm": [read[0].study.centerline.length_mm, read[1].study.centerline.length_mm],
        "anchored_at_flexures": link.anchored,
        "mean_moved_mm": link.mean_moved_mm,
    })
}

fn print_both(link: &Link, read: &[Read], [one_way, two_way, after]: [BothCoverage; 3]) {
    let (a, b) = (read[0].position, read[1].position);
    println!(
        "{a} and {b} linked along the colon ({:.0} and {:.0} mm; {}; the colon moved {:.0} mm on average between them)",
        read[0].study.centerline.length_mm,
        read[1].study.centerline.length_mm,
        if link.anchored {
            "anchored at the ends and flexures"
        } else {
            "anchored at the ends only: the flexures did not agree"
        },
        link.mean_moved_mm
    );
    println!("coverage over both positions (mucosa unseen in one, seen in the other, counts):");
    for (what, c) in [
        ("one way", one_way),
        ("both ways", two_way),
        ("after the reviews", after),
    ] {
        println!(
            "  {what:<18} {a} {:5.1} % → {:5.1} %, {b} {:5.1} % → {:5.1} %, together {:5.1} %",
            c.a_pct, c.a_with_b_pct, c.b_pct, c.b_with_a_pct, c.combined_pct
        );
    }
}

/// The two-way reading of `study` (named `name` in errors), with a bar on a terminal.
pub(super) fn read_with_bar(
    study: &Study,
    mesh: &CellMesh,
    options: CoverageOptions,
    camera: Camera,
    size: u32,
    name: &str,
) -> Result<Reading> {
    let bar = reading_bar();
    let reading = read_both_ways(study, mesh, options, camera, size, |p| {
        show_reading(&bar, p)
    })
    .with_context(|| format!("{name}: the two-way reading"))?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    Ok(reading)
}

/// A bar for the two-way reading on a terminal (None elsewhere), for [`show_reading`].
fn reading_bar() -> Option<ProgressBar> {
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let b = ProgressBar::new(0);
    b.set_style(ProgressStyle::with_template("{bar:24} {pos}/{len} {msg} ({elapsed})").ok()?);
    Some(b)
}

/// The reading's step and its frames or patches on the bar.
fn show_reading(bar: &Option<ProgressBar>, p: ReadingProgress) {
    let Some(b) = bar else {
        return;
    };
    if b.length() != Some(p.total as u64) || p.done == 0 {
        b.set_message(p.step.describe());
        b.set_length(p.total as u64);
    }
    b.set_position(p.done as u64);
}
