//! Helpers shared by the tests on real colons and phantoms (each test file uses some).
#![allow(dead_code)]

use glam::DVec3;
use voyage_core::{COLON_SEGMENTS, OFF_WALL_MM, Segmentation, Study};

/// How much nearer one centerline point must be to a marker than another for the marker to
/// lie at the one and not at the other: a voxel, about.
const TIE_MM: f64 = 1.0;

/// Markers dropped on the wall every `step_mm` of the centerline's arc, as a reader drops
/// them, and read back: for each, where it lies along the colon and [`Study::arc_at`]'s
/// answer. A marker lies where a ray from the centerline point across the centerline meets
/// the wall (of 8 directions, the nearest wall), moved back [`OFF_WALL_MM`] into the lumen,
/// as findings and coverage patches are read. Where it lies is the arc of the centerline
/// point nearest it within 50 mm of arc of the one it was dropped from: in a haustrum or by
/// the cecal pole that is not quite the point it was dropped from, and it is never a loop
/// beside this one. Points as near it as the nearest to within [`TIE_MM`] are all where it
/// lies: in a wide chamber, where the centerline bends round a marker 20 mm off it, points
/// 30 mm apart in arc were 17.8 and 18.0 mm from it.
pub fn markers_read_back(study: &Study, step_mm: f64) -> Vec<(f64, f64)> {
    let cl = &study.centerline;
    let lumen = &study.segmentation.lumen;
    let g = lumen.geometry();
    let inside = |p: DVec3| {
        let q = g.local_to_index(p).round();
        g.contains_index(q) && lumen.get(q.x as usize, q.y as usize, q.z as usize) != 0
    };
    let point = |i: usize| DVec3::from_array(cl.points_mm[i]);
    let at_arc = |a: f64| {
        cl.arc_mm
            .partition_point(|&x| x < a)
            .min(cl.arc_mm.len() - 1)
    };
    let mut out = Vec::new();
    let mut arc = step_mm;
    while arc < cl.length_mm - step_mm / 2.0 {
        let i = at_arc(arc);
        let (a, b) = (point(at_arc(arc - 5.0)), point(at_arc(arc + 5.0)));
        let t = (b - a).normalize_or(DVec3::Z);
        let u = t.any_orthonormal_vector();
        let v = t.cross(u);
        let wall = (0..8)
            .map(|k| {
                let phi = k as f64 * std::f64::consts::FRAC_PI_4;
                let dir = u * phi.cos() + v * phi.sin();
                let mut r = 0.0;
                while r < 150.0 && inside(point(i) + dir * (r + 0.25)) {
                    r += 0.25;
                }
                (r, dir)
            })
            .min_by(|x, y| x.0.total_cmp(&y.0));
        if let Some((r, dir)) = wall
            && r > OFF_WALL_MM
        {
            let marker = point(i) + dir * (r - OFF_WALL_MM);
            let span = at_arc(arc - 50.0)..=at_arc(arc + 50.0);
            let d = |x: usize| (point(x) - marker).length();
            let nearest = span.clone().map(d).fold(f64::INFINITY, f64::min);
            if let Some(read) = study.arc_at(marker) {
                // Where the centerline bends round the marker, stretches of it far apart in
                // arc can lie as near it (to a voxel): it lies at each of them.
                let here = span
                    .filter(|&x| d(x) <= nearest + TIE_MM)
                    .min_by(|&x, &y| {
                        (cl.arc_mm[x] - read)
                            .abs()
                            .total_cmp(&(cl.arc_mm[y] - read).abs())
                    })
                    .unwrap_or(i);
                out.push((cl.arc_mm[here], read));
            }
        }
        arc += step_mm;
    }
    out
}

/// Asserts that markers every 100 mm read back within 15 mm of where they lie along the
/// colon, and in order.
pub fn assert_markers_read_back(study: &Study, what: &str) {
    let read = markers_read_back(study, 100.0);
    let worst = read.iter().map(|(a, r)| (r - a).abs()).fold(0.0, f64::max);
    eprintln!(
        "{what}: {} markers, worst arc error {worst:.1} mm: {:?}",
        read.len(),
        read.iter()
            .map(|(a, r)| format!("{a:.0}→{r:.0}"))
            .collect::<Vec<_>>()
    );
    assert!(read.len() >= 8, "{what}: {} markers", read.len());
    for (a, r) in &read {
        assert!(
            (r - a).abs() <= 15.0,
            "{what}: a marker at arc {a:.0} mm reads {r:.0} mm"
        );
    }
    assert!(
        read.windows(2).all(|w| w[0].1 < w[1].1),
        "{what}: markers read out of order"
    );
}

/// The colon's segments, in their order along the chain, are named by landmarks in the
/// colon's order (rectum first, cecum last), and a segment's middle name is the landmark
/// halfway along the colon between its ends: not the one nearest its centroid, which for a
/// U-shaped compartment lies in the middle of the abdomen (it named the phantom's
/// splenic-flexure-to-cecum compartment "splenic flexure–ascending–cecum").
pub fn assert_labelled_in_anatomical_order(seg: &Segmentation) {
    let mut chained: Vec<(usize, &str)> = seg
        .segments
        .iter()
        .filter_map(|x| Some((x.order?, x.label.as_str())))
        .collect();
    chained.sort();
    let labels: Vec<&str> = chained.iter().map(|&(_, l)| l).collect();
    let index = |name: &str| {
        COLON_SEGMENTS
            .iter()
            .position(|&n| n == name)
            .unwrap_or_else(|| panic!("{name} is no landmark: {labels:?}"))
    };
    let mut last = 0;
    for label in &labels {
        let names: Vec<usize> = label.split('–').map(index).collect();
        assert!(
            names.windows(2).all(|w| w[0] < w[1]) && names[0] >= last,
            "out of order: {labels:?}"
        );
        if let [a, mid, b] = names[..] {
            let halfway = 0.5 * (a + b) as f64;
            assert!(
                (mid as f64 - halfway).abs() <= 0.5,
                "{label}: its middle is not halfway along the colon"
            );
        }
        last = *names.last().unwrap();
    }
    assert!(
        labels.first().is_some_and(|l| l.starts_with("rectum")),
        "{labels:?}"
    );
    assert!(
        labels.last().is_some_and(|l| l.ends_with("cecum")),
        "{labels:?}"
    );
}
