//! `voyage fly INPUT`: automatic flights through the colon (paper §3), no user. A flight
//! that does not reach its goal makes the command fail, after its output is written.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use glam::DVec3;
use serde_json::json;
use voyage_core::Geometry;
use voyage_export::trajectory::write_trajectory;
use voyage_nav::{
    Direction, Flight, FlightOptions, Looking, Rescue, fly, looking, potential_field,
};

use super::prep::load_and_prepare;
use crate::open::{InputArgs, Prepared};

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Directions {
    /// Rectum → cecum.
    Forward,
    /// Cecum → rectum.
    Backward,
    /// Forward, then backward.
    Both,
}

impl Directions {
    fn list(self) -> Vec<Direction> {
        match self {
            Directions::Forward => vec![Direction::Forward],
            Directions::Backward => vec![Direction::Backward],
            Directions::Both => vec![Direction::Forward, Direction::Backward],
        }
    }
}

/// The physics knobs shared by `fly`, `render` and `movie`.
#[derive(Args, Debug, Clone)]
pub struct PhysicsArgs {
    /// Ct: pull toward the goal (Eq. 2).
    #[arg(long)]
    pub ct: Option<f64>,
    /// Cs: push away from the wall (Eq. 2).
    #[arg(long)]
    pub cs: Option<f64>,
    /// ρ: reach of the wall's push, mm (Eq. 2).
    #[arg(long)]
    pub rho: Option<f64>,
    /// kf: linear friction (Eq. 3).
    #[arg(long)]
    pub kf: Option<f64>,
    /// ka: angular friction (Eq. 4).
    #[arg(long)]
    pub ka: Option<f64>,
    /// The camera never comes closer to the wall than this (mm).
    #[arg(long)]
    pub min_wall: Option<f64>,
    /// Frames per second of the trajectory.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Turn off compass mode (z_body follows −∇V).
    #[arg(long)]
    pub no_compass: bool,
    /// Turn off leveling mode (y_body toward the patient's anterior).
    #[arg(long)]
    pub no_leveling: bool,
    /// Give up after this many simulated seconds (default: length / 5 mm/s + 60 s).
    #[arg(long)]
    pub max_seconds: Option<f64>,
}

impl PhysicsArgs {
    pub fn options(&self) -> Result<FlightOptions> {
        let mut o = FlightOptions::default();
        let set = |slot: &mut f64, v: Option<f64>, name: &str, min: f64| -> Result<()> {
            if let Some(v) = v {
                anyhow::ensure!(
                    v.is_finite() && v >= min,
                    "--{name} must be a number ≥ {min}, not {v}"
                );
                *slot = v;
            }
            Ok(())
        };
        set(&mut o.potential.ct, self.ct, "ct", 0.0)?;
        set(&mut o.potential.cs, self.cs, "cs", 0.0)?;
        set(&mut o.potential.rho, self.rho, "rho", 0.0)?;
        set(&mut o.dynamics.kf, self.kf, "kf", 0.0)?;
        set(&mut o.dynamics.ka, self.ka, "ka", 0.0)?;
        set(&mut o.safety.min_wall_mm, self.min_wall, "min-wall", 0.0)?;
        anyhow::ensure!(
            self.fps.is_finite() && self.fps >= 1.0 && self.fps <= 1000.0,
            "--fps must lie in 1..1000"
        );
        o.fps = self.fps;
        o.modes.compass = !self.no_compass;
        o.modes.leveling = !self.no_leveling;
        if let Some(s) = self.max_seconds {
            anyhow::ensure!(
                s.is_finite() && s > 0.0,
                "--max-seconds must be a number of seconds > 0, not {s}"
            );
        }
        o.max_sim_s = self.max_seconds;
        Ok(o)
    }
}

#[derive(Args, Debug)]
pub struct FlyArgs {
    #[command(flatten)]
    pub input: InputArgs,
    #[arg(long, value_enum, default_value_t = Directions::Both)]
    pub direction: Directions,
    #[command(flatten)]
    pub physics: PhysicsArgs,
    /// Write the poses of every frame here (JSON).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print one JSON object per direction.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &FlyArgs) -> Result<()> {
    let opts = a.physics.options()?;
    let Prepared { study, .. } = load_and_prepare(&a.input, Some(opts.safety.min_wall_mm))?;
    let geometry = study.ct.geometry();
    let opts = opts.fitted_to(&study);
    let field = potential_field(&study, opts.safety.min_wall_mm)
        .with_context(|| format!("{}", a.input.input.display()))?;
    let mut flights: Vec<Flight> = Vec::new();
    for dir in a.direction.list() {
        let f = fly(&field, &study.centerline, dir, &opts)
            .with_context(|| format!("{}: {} flight", a.input.input.display(), dir.name()))?;
        flights.push(f);
    }
    let canal_mm = study.centerline.canal_mm;
    for f in &flights {
        let into_canal = f.direction == Direction::Backward && canal_mm > 0.0;
        if f.short_end_mm > 0.0 && into_canal {
            eprintln!(
                "note: {}: the backward flight ends {:.0} mm short of the centerline's start, above the {canal_mm:.0} mm of canal too narrow to fly",
                a.input.input.display(),
                f.short_end_mm,
            );
        } else if f.short_end_mm > 0.0 {
            eprintln!(
                "warning: {}: the last {:.0} mm to the {} flight's goal are narrower than the camera fits ({} mm from the wall): the flight ends there",
                a.input.input.display(),
                f.short_end_mm,
                f.direction.name(),
                opts.safety.min_wall_mm
            );
        }
        for r in &f.rescues {
            eprintln!(
                "warning: {}: {}",
                a.input.input.display(),
                rescue_text(f, r, geometry)
            );
        }
    }
    if let Some(out) = &a.out {
        write_trajectory(out, &flights, geometry, opts.fps)?;
    }
    let looks: Vec<Looking> = flights
        .iter()
        .map(|f| looking(&study, f.direction, &f.poses))
        .collect();
    if a.json {
        let per: serde_json::Map<String, serde_json::Value> = flights
            .iter()
            .zip(&looks)
            .map(|(f, l)| (f.direction.name().to_string(), summary(f, l, geometry)))
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(
                &json!({ "centerline_length_mm": study.centerline.length_mm, "directions": per })
            )?
        );
    } else {
        for (f, l) in flights.iter().zip(&looks) {
            println!(
                "{:<8} {} in {} frames ({:.1} s simulated), path {:.0} mm, wall distance min {:.1} / mean {:.1} mm (mean radius {:.1}), {} stalls, {} rescues, physics {:.2} µs/frame",
                f.direction.name(),
                if f.reached {
                    "reached"
                } else {
                    "did NOT reach the goal"
                },
                f.frames,
                f.sim_seconds,
                f.path_length_mm,
                f.min_wall_distance_mm,
                f.mean_wall_distance_mm,
                f.mean_local_radius_mm,
                f.stalls,
                f.rescues.len(),
                f.step_ns / 1e3
            );
            println!("         {}", describe_looking(l));
        }
        if let Some(out) = &a.out {
            println!("  wrote {}", out.display());
        }
    }
    // A flight that fell short is a failure, said on stderr (the JSON says it too), after
    // what it did was printed and written.
    let short: Vec<String> = flights
        .iter()
        .filter(|f| !f.reached)
        .map(|f| {
            format!(
                "the {} flight stopped {:.0} mm short of its goal",
                f.direction.name(),
                f.final_dt_mm
            )
        })
        .collect();
    if !short.is_empty() {
        anyhow::bail!("{}: {}", a.input.input.display(), short.join("; "));
    }
    Ok(())
}

/// What a rescue (no progress for STUCK_S s, or no move for WEDGED_S s, then a glide on) says
/// to the user.
fn rescue_text(f: &Flight, r: &Rescue, g: &Geometry) -> String {
    let p = g.local_to_patient(DVec3::from_array(r.position));
    format!(
        "the {} flight {} for {:.0} s at LPS ({:.0}, {:.0}, {:.0}), {:.0} mm along its way: the autopilot glided on along the centerline",
        f.direction.name(),
        r.cause(),
        r.stuck_s,
        p.x,
        p.y,
        p.z,
        r.arc_mm
    )
}

/// How a flight looked, in a line: the view's angle to the way on and the all-wall frames.
pub fn describe_looking(l: &Looking) -> String {
    let a = &l.view_angle_deg;
    format!(
        "view {:.0}° off the way on (median; p95 {:.0}°, {:.1}% of frames over 45°), {:.1}% of frames all wall",
        a.median,
        a.p95,
        100.0 * a.over_45_share,
        100.0 * l.all_wall_share
    )
}

fn summary(f: &Flight, l: &Looking, g: &Geometry) -> serde_json::Value {
    let rescues: Vec<serde_json::Value> = f
        .rescues
        .iter()
        .map(|r| {
            json!({
                "t_s": r.t,
                "stuck_s": r.stuck_s,
                "wedged": r.wedged,
                "arc_mm": r.arc_mm,
                "lps_mm": g.local_to_patient(DVec3::from_array(r.position)).to_array(),
            })
        })
        .collect();
    json!({
        "rescues": rescues,
        "reached": f.reached,
        "frames": f.frames,
        "sim_seconds": f.sim_seconds,
        "min_wall_distance_mm": f.min_wall_distance_mm,
        "mean_wall_distance_mm": f.mean_wall_distance_mm,
        "mean_local_radius_mm": f.mean_local_radius_mm,
        "stalls": f.stalls,
        "path_length_mm": f.path_length_mm,
        "step_ns": f.step_ns,
        "substeps": f.substeps,
        "clipped_substeps": f.clipped_substeps,
        "final_dt_mm": f.final_dt_mm,
        "short_end_mm": f.short_end_mm,
        "mean_heading_error_deg": f.mean_heading_error_deg,
        "view_angle_deg": l.view_angle_deg,
        "all_wall_share": l.all_wall_share,
    })
}
