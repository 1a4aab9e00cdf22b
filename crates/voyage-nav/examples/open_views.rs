//! How often a view from the centerline can be other than all wall (issue 36's measure:
//! over 90% of a square 90° view nearer than 15 mm, [`voyage_nav::looking`]): from every
//! second centerline point, looking straight along the way on (the centerline 20 mm ahead),
//! and the best of 400 directions within MAX_DEG of it.
//!
//! `cargo run --release -p voyage-nav --example open_views -- INPUT [MAX_DEG]`
use glam::DVec3;
use voyage_core::{PrepOptions, prepare};
use voyage_nav::{Direction, Pose, TANGENT_MM, looking};

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
    let cl = &study.centerline;
    let dirs = directions(400);
    let open_at = |at: DVec3, d: DVec3| {
        let up = if d.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
        let pose = Pose::looking(at, d, (up - d * d.dot(up)).normalize());
        looking(&study, Direction::Forward, &[pose]).all_wall_share == 0.0
    };
    let (mut points, mut straight, mut best) = (0usize, 0usize, 0usize);
    for i in (0..cl.points_mm.len()).step_by(2) {
        let Some(j) = (i..cl.points_mm.len()).find(|&j| cl.arc_mm[j] >= cl.arc_mm[i] + TANGENT_MM)
        else {
            break;
        };
        let at = DVec3::from_array(cl.points_mm[i]);
        let way = (DVec3::from_array(cl.points_mm[j]) - at).normalize();
        points += 1;
        straight += open_at(at, way) as usize;
        best += dirs
            .iter()
            .filter(|d| d.angle_between(way).to_degrees() <= max_deg)
            .any(|&d| open_at(at, d)) as usize;
    }
    let share = |n: usize| 100.0 * (points - n) as f64 / points.max(1) as f64;
    println!(
        "{path}: {points} centerline points; all wall looking along the way on {:.1} %, at the best view within {max_deg}° of it {:.1} %",
        share(straight),
        share(best)
    );
}
