//! Haustral folds: placed along the colon, recorded in the truth, and found again by the
//! polyps and the stool that sit beside them.

use super::{anatomy::segment_name, streams::STREAM_FOLDS, stretches::near_collapse};
use crate::{
    frame::Frame,
    rng::Rng,
    truth::{FoldTruth, SegmentTruth},
    tube::{Fold, FoldSector, Tube},
};
use voyage_core::{Error, Result};

/// Fold spacing range, depth range and half thickness (full size).
const FOLD_SPACING: (f64, f64) = (20.0, 30.0);
pub(super) const FOLD_DEPTH: (f64, f64) = (3.0, 8.0);
const FOLD_HALF_WIDTH: f64 = 2.0;
/// A crescent never reaches further in than this fraction of the radius, so the lumen
/// stays open around the centerline.
pub(super) const FOLD_MAX_FRACTION: f64 = 0.45;

/// Haustral folds every 20–30 mm from the sigmoid to the cecal pole (none in the rectum,
/// nor in a collapsed stretch): three crescents between the taeniae, 3–8 mm deep.
pub(super) fn make_folds(
    frame: &Frame,
    tube: &Tube,
    segments: &[SegmentTruth],
    seed: u64,
) -> Vec<Fold> {
    let s = frame.scale;
    let mut rng = Rng::new(seed, STREAM_FOLDS);
    let hw = frame.thin(FOLD_HALF_WIDTH, 0.9);
    let start = segments
        .iter()
        .find(|g| g.name == "sigmoid")
        .map_or(0.0, |g| g.start_arc_mm)
        + 10.0 * s;
    let end = tube.axis.length - 12.0 * s;
    let phase0 = rng.range(0.0, std::f64::consts::TAU);
    let mut folds = Vec::new();
    let mut arc = start;
    while arc < end {
        let collapsed = near_collapse(tube, arc, 3.0 * hw);
        let r = tube.axis.radius_at(arc);
        let mut sector = || FoldSector {
            offset: rng.range(-1.5, 1.5) * s,
            depth: (rng.range(FOLD_DEPTH.0, FOLD_DEPTH.1) * s).min(FOLD_MAX_FRACTION * r),
        };
        let sectors = [sector(), sector(), sector()];
        if !collapsed {
            // The taeniae twist slowly around the colon.
            folds.push(Fold {
                arc,
                phase: phase0 + 0.002 * arc / s,
                half_width: hw,
                sectors,
            });
        }
        arc += rng.range(FOLD_SPACING.0, FOLD_SPACING.1) * s;
    }
    folds
}

pub(super) fn fold_truth(tube: &Tube, segments: &[SegmentTruth]) -> Vec<FoldTruth> {
    tube.folds
        .iter()
        .map(|f| FoldTruth {
            arc_mm: f.arc,
            half_width_mm: f.half_width,
            phase_rad: f.phase,
            depth_mm: f.sectors.map(|s| s.depth),
            offset_mm: f.sectors.map(|s| s.offset),
            segment: segment_name(segments, f.arc),
        })
        .collect()
}

/// The fold nearest to `arc`.
pub(super) fn nearest_fold(tube: &Tube, arc: f64) -> Result<usize> {
    (0..tube.folds.len())
        .min_by(|&a, &b| {
            (tube.folds[a].arc - arc)
                .abs()
                .total_cmp(&(tube.folds[b].arc - arc).abs())
        })
        .ok_or_else(|| Error::invalid("colon phantom: no fold to hide a polyp behind"))
}

/// Arcs of the folds just before and after `arc`, if it lies between two folds.
pub(super) fn folds_around(tube: &Tube, arc: f64) -> Option<(f64, f64)> {
    let after = tube.folds.iter().position(|f| f.arc > arc)?;
    if after == 0 {
        return None;
    }
    Some((tube.folds[after - 1].arc, tube.folds[after].arc))
}
