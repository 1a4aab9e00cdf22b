//! How often a view can be other than all wall (issue 36's measure: over 90% of a square 90°
//! view nearer than 15 mm, [`voyage_nav::looking`]):
//!
//! - from every second centerline point, looking straight along the way on (the centerline
//!   20 mm ahead), and at the best of 400 directions within MAX_DEG of it;
//! - from every third frame of the automatic flights, both ways: as flown, and at the best
//!   direction within MAX_DEG of the frame's own view;
//! - the share of frames whose nearest centerline point lies in lumen narrower than a round
//!   tube that is all wall even looked straight down (radius
//!   `WALL_NEAR_MM · √(4 · (1 − ALL_WALL_SHARE) / π)`, 5.35 mm): there only a flat or bending
//!   lumen leaves a view open.
//!
//! `cargo run --release -p voyage-nav --example open_views -- INPUT [MAX_DEG]`
use glam::DVec3;
use voyage_core::{PrepOptions, Study, prepare};
use voyage_nav::{
    ALL_WALL_SHARE, Direction, FlightOptions, Pose, TANGENT_MM, WALL_NEAR_MM, fly, looking,
    potential_field,
};

/// Directions spread evenly over the sphere (a Fibonacci lattice).
fn directions(n: usize) -> Vec<DVec3> {
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            let t = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            DVec3::new(r * t.cos(), y, r * t.sin())
        })
        .collect()
}

/// Whether the view from `at` along `d` is other than all wall.
fn open_at(study: &Study, at: DVec3, d: DVec3) -> bool {
    let up = if d.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let pose = Pose::looking(at, d, (up - d * d.dot(up)).normalize());
    looking(study, Direction::Forward, &[pose]).all_wall_share == 0.0
}

/// Whether any of `dirs` within `max_deg` of `axis` gives an open view from `at`.
fn any_open(study: &Study, dirs: &[DVec3], at: DVec3, axis: DVec3, max_deg: f64) -> bool {
    dirs.iter()
        .filter(|d| d.angle_between(axis).to_degrees() <= max_deg)
        .any(|&d| open_at(study, at, d))
}

fn share(n: usize, of: usize) -> f64 {
    100.0 * n as f64 / of.max(1) as f64
}

fn from_the_centerline(study: &Study, dirs: &[DVec3], max_deg: f64) {
    let cl = &study.centerline;
    let (mut points, mut straight, mut best) = (0usize, 0usize, 0usize);
    for i in (0..cl.points_mm.len()).step_by(2) {
        let Some(j) = (i..cl.points_mm.len()).find(|&j| cl.arc_mm[j] >= cl.arc_mm[i] + TANGENT_MM)
        else {
            break;
        };
        let at = DVec3::from_array(cl.points_mm[i]);
        let way = (DVec3::from_array(cl.points_mm[j]) - at).normalize();
        points += 1;
        straight += open_at(study, at, way) as usize;
        best += any_open(study, dirs, at, way, max_deg) as usize;
    }
    println!(
        "  {points} centerline points: all wall looking along the way on {:.1} %, at the best view within {max_deg}° of it {:.1} %",
        share(points - straight, points),
        share(points - best, points)
    );
}

fn from_the_flights(study: &Study, dirs: &[DVec3], max_deg: f64) {
    let opts = FlightOptions::default().fitted_to(study);
    let field = potential_field(study, opts.safety.min_wall_mm).expect("the potential field");
    let cl = &study.centerline;
    let tube_mm = WALL_NEAR_MM * (4.0 * (1.0 - ALL_WALL_SHARE) / std::f64::consts::PI).sqrt();
    for dir in [Direction::Forward, Direction::Backward] {
        let f = fly(&field, cl, dir, &opts).expect("the flight");
        let frames: Vec<&Pose> = f.poses.iter().step_by(3).collect();
        let walled: Vec<&&Pose> = frames
            .iter()
            .filter(|p| looking(study, dir, &[***p]).all_wall_share > 0.0)
            .collect();
        let still = walled
            .iter()
            .filter(|p| !any_open(study, dirs, p.position, p.z_body(), max_deg))
            .count();
        let narrow = f
            .poses
            .iter()
            .filter(|p| {
                let near = (0..cl.points_mm.len())
                    .min_by(|&a, &b| {
                        let d = |i: usize| DVec3::from_array(cl.points_mm[i]).distance(p.position);
                        d(a).total_cmp(&d(b))
                    })
                    .unwrap_or(0);
                cl.radius_mm[near] < tube_mm
            })
            .count();
        println!(
            "  {} flight, {} frames: all wall {:.1} % as flown, {:.1} % at the best view within {max_deg}° of each; {:.1} % of frames where the lumen is under {tube_mm:.2} mm in radius",
            dir.name(),
            frames.len(),
            share(walled.len(), frames.len()),
            share(still, frames.len()),
            share(narrow, f.poses.len())
        );
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: open_views INPUT [MAX_DEG]");
        std::process::exit(2);
    };
    let max_deg: f64 = args
        .next()
        .map_or(45.0, |v| v.parse().expect("MAX_DEG: degrees"));
    let ct = voyage_io::load(std::path::Path::new(&path), &Default::default())
        .unwrap_or_else(|e| panic!("{path}: {e}"))
        .volume;
    let study = prepare(ct, &PrepOptions::default(), |_| {}).unwrap_or_else(|e| panic!("{e}"));
    let dirs = directions(400);
    println!("{path}:");
    from_the_centerline(&study, &dirs, max_deg);
    from_the_flights(&study, &dirs, max_deg);
}
