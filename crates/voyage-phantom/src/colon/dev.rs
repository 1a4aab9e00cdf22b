//! Development aids for tuning the anatomy (`examples/phantom_look.rs`): reports and maps of
//! the room around the colon. Nothing a phantom is made with.

use glam::DVec3;

use super::anatomy::{WALL, check_anatomy, make_axis, make_body, segments};
use crate::{
    axis::{Axis, Knot},
    frame::Frame,
};
use voyage_core::Result;

/// Development aid (for tuning [`KNOTS`](super::anatomy::KNOTS)): the axis's length,
/// per-segment lengths, the tightest bend, the closest loops and what [`check_anatomy`] says.
#[doc(hidden)]
pub fn anatomy_report(small: bool) -> Result<String> {
    let frame = Frame::new(small)?;
    let axis = make_axis(&frame, false)?;
    let wall = frame.thin(WALL, 1.0);
    let (bend, at) = axis.min_bend_ratio(wall);
    let (gap, i, j) = axis.min_part_gap(wall, 2);
    let mut out = format!(
        "length {:.0} mm; tightest bend {bend:.2} × (radius + wall) at arc {:.0}; loops closest ({gap:.1} mm) at arcs {:.0} and {:.0}\n",
        axis.length, axis.arc[at], axis.arc[i], axis.arc[j]
    );
    for g in segments(&axis) {
        out += &format!(
            "  {:<16} {:6.0} .. {:6.0} mm ({:.0} mm)\n",
            g.name,
            g.start_arc_mm,
            g.end_arc_mm,
            g.end_arc_mm - g.start_arc_mm
        );
    }
    let verdict = check_anatomy(&frame, &axis, &make_body(&frame, true, None))
        .map_or_else(|e| e.to_string(), |_| "checks pass".into());
    Ok(out + &verdict + "\n")
}

/// Development aid (for placing the small-bowel loops): for axial levels every 10 mm, a map
/// (full-size mm, 6 mm cells) of the room around each point: the distance to the colon's
/// outer wall, the spine, the lungs and the muscle under the skin, in 4 mm steps (0–9);
/// `#` the colon itself, ` ` outside the body's fat.
#[doc(hidden)]
pub fn free_space_map(z_from: f64, z_to: f64) -> Result<String> {
    let frame = Frame::new(false)?;
    let axis = make_axis(&frame, false)?;
    let body = make_body(&frame, true, None);
    let wall = frame.thin(WALL, 1.0);
    let mut out = String::new();
    let mut z = z_from;
    while z <= z_to {
        out += &format!("z = {z:.0}   x 60..330 →, y 70..330 ↓ (digit = room / 4 mm)\n");
        let mut y = 70.0;
        while y <= 330.0 {
            let mut row = format!("{y:4.0} ");
            let mut x = 60.0;
            while x <= 330.0 {
                let p = DVec3::new(x, y, z);
                let colon = axis
                    .points
                    .iter()
                    .zip(&axis.radius)
                    .map(|(a, r)| a.distance(p) - r - wall)
                    .fold(f64::INFINITY, f64::min);
                let skin = -body.skin_sdf(p) - body.rim;
                let room = colon.min(skin).min(body.spine.sdf_xy(p)).min(
                    body.lungs
                        .iter()
                        .map(|l| l.sdf(p))
                        .fold(f64::INFINITY, f64::min),
                );
                row.push(if colon < 0.0 {
                    '#'
                } else if skin < 0.0 {
                    ' '
                } else {
                    char::from(b'0' + (room / 4.0).clamp(0.0, 9.0) as u8)
                });
                x += 6.0;
            }
            out += &row;
            out.push('\n');
            y += 6.0;
        }
        z += 10.0;
    }
    Ok(out)
}

/// Development aid (for placing the small-bowel loops): for a loop of radius `r` (plus a
/// 1.5 mm wall) through full-size `knots`, the smallest room left between its wall and the
/// colon's outer wall / the rim under the skin / the spine / the lungs along each span.
#[doc(hidden)]
pub fn loop_room_report(knots: &[[f64; 3]], r: f64) -> Result<String> {
    let frame = Frame::new(false)?;
    let axis = make_axis(&frame, false)?;
    let body = make_body(&frame, true, None);
    let wall = frame.thin(WALL, 1.0);
    let ks: Vec<Knot> = knots
        .iter()
        .map(|k| Knot {
            pos: DVec3::from_array(*k),
            radius: r,
        })
        .collect();
    let path = Axis::through(&ks, 1.0)?;
    let reach = r + 1.5;
    let mut out = format!(
        "length {:.0} mm, tightest bend {:.2}\n",
        path.length,
        path.min_bend_ratio(1.5).0
    );
    for span in 0..ks.len() - 1 {
        let (a, b) = (path.knot_arc[span], path.knot_arc[span + 1]);
        let mut worst = (f64::INFINITY, "", 0.0, DVec3::ZERO);
        let mut bend = f64::INFINITY;
        for (i, (p, s)) in path
            .points
            .iter()
            .zip(&path.arc)
            .enumerate()
            .filter(|(_, (_, s))| **s >= a && **s <= b)
        {
            if i >= 3 && i + 3 < path.len() {
                let turn = path.tangent[i - 3].angle_between(path.tangent[i + 3]);
                let ds = path.arc[i + 3] - path.arc[i - 3];
                bend = bend.min(if turn > 1e-9 {
                    ds / turn / (r + 1.5)
                } else {
                    f64::INFINITY
                });
            }
            let (colon, at) = axis
                .points
                .iter()
                .zip(&axis.radius)
                .zip(&axis.arc)
                .map(|((c, rc), arc)| (c.distance(*p) - rc - wall, *arc))
                .fold((f64::INFINITY, 0.0), |x, y| if y.0 < x.0 { y } else { x });
            let cands = [
                (colon - reach, "colon"),
                (-body.skin_sdf(*p) - body.rim - reach, "skin"),
                (body.spine.sdf_xy(*p) - reach, "spine"),
                (
                    body.lungs
                        .iter()
                        .map(|l| l.sdf(*p))
                        .fold(f64::INFINITY, f64::min)
                        - reach,
                    "lung",
                ),
            ];
            for (v, what) in cands {
                if v < worst.0 {
                    worst = (v, what, if what == "colon" { at } else { *s }, *p);
                }
            }
        }
        out += &format!(
            "  {:?} -> {:?}: room {:.1} mm ({} at {:.0}, near {:.0?}), bend {bend:.2}\n",
            knots[span],
            knots[span + 1],
            worst.0,
            worst.1,
            worst.2,
            worst.3.to_array()
        );
    }
    Ok(out)
}
