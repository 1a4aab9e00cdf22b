//! The polyps: where each goes (between folds, or hidden just behind one), and how large it
//! may be so that the lumen stays open.

use super::{
    anatomy::segment,
    folds::{FOLD_DEPTH, FOLD_MAX_FRACTION, folds_around, nearest_fold},
    streams::STREAM_POLYPS,
};
use crate::{frame::Frame, polyp::PolypSpec, rng::Rng, truth::SegmentTruth, tube::Tube};
use voyage_core::{Error, Result};

/// The polyps at full size: (segment, diameter mm, behind a fold, stalk length for a
/// pedunculated one).
const POLYPS: &[(&str, f64, bool, Option<f64>)] = &[
    ("rectum", 6.0, false, None),
    ("sigmoid", 8.0, false, None),
    ("sigmoid", 4.0, true, None),
    ("descending", 3.0, true, None),
    ("transverse", 12.0, false, None),
    ("transverse", 5.0, true, None),
    ("ascending", 10.0, false, Some(4.0)),
    ("cecum", 7.0, false, None),
];

/// Places the polyps of [`POLYPS`]: between two folds (or anywhere in the fold-free
/// rectum), or just behind a fold (on its cecal side) in the middle of one of its crescents,
/// which is deepened if needed so that it hides the polyp from the rectal side.
///
/// A polyp never reaches in further than [`MAX_PROTRUSION`] of the local radius (the
/// diameter is reduced if needed), so the lumen stays open around the centerline. In the
/// small phantom a diameter d becomes d/2 + 2.5 mm (3–12 mm → 4–8.5 mm: at least about three
/// voxels, so the centre voxel is solid tissue) and every polyp is sessile.
pub(super) fn make_polyps(
    frame: &Frame,
    tube: &mut Tube,
    segments: &[SegmentTruth],
    seed: u64,
) -> Result<Vec<PolypSpec>> {
    let s = frame.scale;
    let small = s < 1.0;
    let mut rng = Rng::new(seed, STREAM_POLYPS);
    let mut specs: Vec<PolypSpec> = Vec::new();
    for &(seg_name, diameter, behind, stalk) in POLYPS {
        let seg = segment(segments, seg_name)?;
        let stalk = if small { None } else { stalk };
        let wanted = if small {
            0.5 * diameter + 2.5
        } else {
            diameter
        };
        let mut arc = seg.start_arc_mm + rng.range(0.3, 0.7) * (seg.end_arc_mm - seg.start_arc_mm);
        let mut angle = rng.range(0.0, std::f64::consts::TAU);
        let k = ((rng.uniform() * 3.0) as usize).min(2);
        let mut spec = None;
        // Try a few places along the segment until one is clear of the collapse and of the
        // other polyps.
        for _ in 0..8 {
            let d = fit_diameter(wanted, stalk, tube.axis.radius_at(arc));
            let mut at = arc;
            if behind {
                let fi = nearest_fold(tube, arc)?;
                let f = &tube.folds[fi];
                at = f.arc + f.sectors[k].offset + f.half_width + d / 2.0 + 1.5 * s;
                angle = f.sector_mid_angle(k);
            } else if let Some((a, b)) = folds_around(tube, arc) {
                at = 0.5 * (a + b);
            }
            let d = fit_diameter(wanted, stalk, tube.axis.radius_at(at));
            let clear_collapse = tube.clear_of_collapses(at, d);
            let clear_polyps = specs.iter().all(|o| (o.arc - at).abs() > 20.0 * s);
            if clear_collapse && clear_polyps && at > seg.start_arc_mm && at < seg.end_arc_mm {
                spec = Some(PolypSpec {
                    arc: at,
                    angle,
                    diameter: d,
                    stalk,
                    segment: seg_name.into(),
                    behind_fold: behind,
                });
                break;
            }
            arc = seg.start_arc_mm + rng.range(0.1, 0.9) * (seg.end_arc_mm - seg.start_arc_mm);
        }
        let spec = spec.ok_or_else(|| {
            Error::invalid(format!(
                "colon phantom: no room for a polyp in the {seg_name}"
            ))
        })?;
        if behind {
            deepen_fold_before(tube, &spec, k, frame);
        }
        specs.push(spec);
    }
    // Re-index folds after any deepening (the reach of a fold does not change).
    let folds = std::mem::take(&mut tube.folds);
    tube.set_folds(folds);
    Ok(specs)
}

/// A polyp reaches in at most this fraction of the local lumen radius.
pub const MAX_PROTRUSION: f64 = 0.55;

/// How far a polyp of diameter `d` reaches in from the wall.
fn protrusion(d: f64, stalk: Option<f64>) -> f64 {
    match stalk {
        None => (1.0 + crate::polyp::SESSILE_INSET) * d / 2.0,
        Some(len) => len + d,
    }
}

/// `wanted`, or less so that the polyp leaves the middle of the lumen free.
pub(super) fn fit_diameter(wanted: f64, stalk: Option<f64>, radius: f64) -> f64 {
    let limit = MAX_PROTRUSION * radius;
    if protrusion(wanted, stalk) <= limit {
        return wanted;
    }
    match stalk {
        None => limit * 2.0 / (1.0 + crate::polyp::SESSILE_INSET),
        Some(len) => (limit - len).max(0.0),
    }
}

/// Makes crescent `k` of the fold just before a behind-fold polyp deep enough to hide it.
fn deepen_fold_before(tube: &mut Tube, spec: &PolypSpec, k: usize, frame: &Frame) {
    let Ok(fi) = nearest_fold(tube, spec.arc) else {
        return;
    };
    let r = tube.axis.radius_at(tube.folds[fi].arc);
    let need = (protrusion(spec.diameter, spec.stalk) + 1.0 * frame.scale)
        .min(FOLD_MAX_FRACTION * r)
        .min(FOLD_DEPTH.1 * frame.scale);
    let sector = &mut tube.folds[fi].sectors[k];
    sector.depth = sector.depth.max(need);
}
