//! Diverticula: pouches of the colon's gas through its wall, each on a narrow neck, where
//! diverticulosis puts them (the sigmoid most, then the descending colon).

use glam::DVec3;

use super::{anatomy::segment, streams::STREAM_DIVERTICULA};
use crate::{
    frame::Frame,
    posture::dependent_angle,
    rng::Rng,
    truth::{DiverticulumTruth, PolypTruth, SegmentTruth},
    tube::{Blob, BlobKind, Tube, segment_distance},
};
use voyage_core::{Error, Result};

/// Segments with diverticula, and how many each.
const DIVERTICULA: &[(&str, usize)] = &[("sigmoid", 6), ("descending", 4)];
/// A pouch's radius and its neck's (full size, mm): real ones are 5–10 mm across, opening
/// through a gap in the muscle 2–5 mm wide.
const POUCH_RADIUS: (f64, f64) = (2.5, 5.0);
const NECK_RADIUS: (f64, f64) = (1.0, 2.0);
/// Room (full size, mm) between a pouch's wall and any other loop of the colon, and along
/// the colon between pouches and from a polyp.
const CLEAR_MM: f64 = 4.0;
const APART_MM: f64 = 12.0;
const FROM_POLYP_MM: f64 = 15.0;

/// Gas-filled diverticula in the sigmoid and descending colon: each a sphere of the colon's
/// gas with its own thin wall, outside the colon's wall on the side away from gravity (gas
/// rises into them; fluid lies on the other side), joined to the lumen by a neck through
/// the wall; clear of the other loops, the polyps, each other, collapsed and fluid-filled
/// stretches and `obstacles` (capsules: ends and radius). At least a voxel and a half
/// across, and the neck at least a voxel, so that each is joined in the scan.
pub(super) fn make_diverticula(
    frame: &Frame,
    tube: &Tube,
    segments: &[SegmentTruth],
    polyps: &[PolypTruth],
    gravity: DVec3,
    obstacles: &[(DVec3, DVec3, f64)],
    seed: u64,
) -> Result<Vec<(Blob, DiverticulumTruth)>> {
    let s = frame.scale;
    let mut rng = Rng::new(seed, STREAM_DIVERTICULA);
    let ax = &tube.axis;
    let wall = tube.wall_mm;
    let mut out: Vec<(Blob, DiverticulumTruth)> = Vec::new();
    for &(name, count) in DIVERTICULA {
        let seg = segment(segments, name)?;
        for _ in 0..count {
            let radius = frame.thin(rng.range(POUCH_RADIUS.0, POUCH_RADIUS.1), 1.5);
            let neck = frame.thin(rng.range(NECK_RADIUS.0, NECK_RADIUS.1), 1.0);
            let mut placed = None;
            for _ in 0..64 {
                let arc =
                    seg.start_arc_mm + rng.range(0.05, 0.95) * (seg.end_arc_mm - seg.start_arc_mm);
                // Within ±70° of the top of the lumen.
                let angle =
                    dependent_angle(ax, arc, gravity) + std::f64::consts::PI + rng.range(-1.2, 1.2);
                let q = ax.point_at(arc);
                let outward = ax.radial_at(arc, angle);
                let wall_r = ax.radius_at(arc);
                let center = q + outward * (wall_r + wall + 0.6 * radius);
                let reach = radius + wall;
                let other_loops = ax
                    .points
                    .iter()
                    .zip(&ax.radius)
                    .zip(&ax.arc)
                    .filter(|&(_, &a)| (a - arc).abs() > 3.0 * (wall_r + reach))
                    .all(|((p, &r), _)| p.distance(center) - r - wall - reach >= CLEAR_MM * s);
                let along = |a: f64, d: f64| (a - arc).abs() > d * s;
                let clear = other_loops
                    && polyps.iter().all(|p| along(p.arc_mm, FROM_POLYP_MM))
                    && out.iter().all(|(_, t)| along(t.arc_mm, APART_MM))
                    && tube.clear_of_stretches(arc, reach)
                    && obstacles.iter().all(|&(a, b, r)| {
                        segment_distance(center, a, b) - r - reach >= CLEAR_MM * s
                    });
                if clear {
                    placed = Some((arc, q, outward, wall_r, center));
                    break;
                }
            }
            let (arc, q, outward, wall_r, center) = placed.ok_or_else(|| {
                Error::invalid(format!(
                    "colon phantom: no room for a diverticulum in the {name}"
                ))
            })?;
            // The neck starts inside the lumen, so that it opens into it, and ends in the pouch.
            let mouth = q + outward * (wall_r - neck);
            let blob = Blob {
                kind: BlobKind::Diverticulum,
                center,
                radius,
                stalk: Some((mouth, center, neck)),
                wall_mm: wall,
                content_hu: 0.0,
            };
            let truth = DiverticulumTruth {
                segment: name.into(),
                arc_mm: arc,
                center_mm: center.to_array(),
                radius_mm: radius,
                neck_radius_mm: neck,
                mouth_mm: (q + outward * wall_r).to_array(),
            };
            out.push((blob, truth));
        }
    }
    Ok(out)
}
