//! Stretches of the colon where the gas stops or narrows: collapsed to a tissue cord,
//! narrowed to a neck, or filled to the brim with tagged fluid.

use super::{
    anatomy::{END_INSET, WALL, segment},
    streams::STREAM_FILLED,
};
use crate::{
    frame::Frame,
    rng::Rng,
    truth::{CollapsedTruth, FilledTruth, SegmentTruth},
    tube::{Collapse, Filled, Tube},
};
use voyage_core::{Error, Result};

/// 30 mm (full size) of each named segment collapses to a tissue cord: the descending colon
/// 60 % of the way up (where it always did), the sigmoid at 55 % of its length (the top of
/// its anterior loop), the transverse colon at half its length. Sorted along the colon.
pub(super) fn make_collapses(
    frame: &Frame,
    segments: &[SegmentTruth],
    names: &[String],
) -> Result<Vec<(Collapse, CollapsedTruth)>> {
    let s = frame.scale;
    let mut out = Vec::new();
    for name in names {
        let g = segment(segments, name)?;
        let frac = match name.as_str() {
            "sigmoid" => 0.55,
            "transverse" => 0.5,
            _ => 0.6,
        };
        let (a, b) = (g.start_arc_mm, g.end_arc_mm);
        let mid = a + frac * (b - a);
        let half = 15.0 * s;
        let taper = 8.0 * s;
        let c = Collapse {
            start: mid - half,
            end: mid + half,
            taper,
            cord_radius: 2.0 * frame.thin(WALL, 1.0),
            neck_radius: 0.0,
        };
        let t = CollapsedTruth {
            segment: name.clone(),
            start_arc_mm: c.start,
            end_arc_mm: c.end,
            taper_mm: taper,
        };
        out.push((c, t));
    }
    out.sort_by(|x, y| x.0.start.total_cmp(&y.0.start));
    Ok(out)
}

/// The gas thread's radius in a neck (mm, any size): under the camera's 1 mm from the wall.
pub const NECK_RADIUS_MM: f64 = 0.9;

/// A neck 30 % of the way along each named segment: 10 mm (full size) where the lumen is
/// a thread [`NECK_RADIUS_MM`] in radius, tapering over 8 mm on each side.
pub(super) fn make_necks(
    frame: &Frame,
    segments: &[SegmentTruth],
    names: &[String],
) -> Result<Vec<Collapse>> {
    let s = frame.scale;
    names
        .iter()
        .map(|name| {
            let g = segment(segments, name)?;
            let mid = g.start_arc_mm + 0.3 * (g.end_arc_mm - g.start_arc_mm);
            Ok(Collapse {
                start: mid - 5.0 * s,
                end: mid + 5.0 * s,
                taper: 8.0 * s,
                cord_radius: 0.0,
                neck_radius: NECK_RADIUS_MM,
            })
        })
        .collect()
}

/// Whether arc `s` lies within `margin` of a collapsed stretch (tapers included).
pub(super) fn near_collapse(tube: &Tube, s: f64, margin: f64) -> bool {
    tube.collapse
        .iter()
        .any(|c| s > c.start - c.taper - margin && s < c.end + c.taper + margin)
}

/// A 40–60 mm stretch (full size) of each named segment filled to the brim with tagged
/// fluid (+400..+700 HU), centred 20–35 % of the way along the segment (or 65–80 % if that
/// would meet a collapse), clear of the colon's ends. Sorted along the colon.
pub(super) fn make_filled(
    frame: &Frame,
    tube: &Tube,
    segments: &[SegmentTruth],
    names: &[String],
    seed: u64,
) -> Result<Vec<(Filled, FilledTruth)>> {
    let s = frame.scale;
    let mut rng = Rng::new(seed, STREAM_FILLED);
    let mut out: Vec<(Filled, FilledTruth)> = Vec::new();
    for name in names {
        let g = segment(segments, name)?;
        let len = rng.range(40.0, 60.0) * s;
        let hu = rng.range(400.0, 700.0);
        let early = rng.range(0.2, 0.35);
        let late = rng.range(0.65, 0.8);
        let (a, b) = (g.start_arc_mm, g.end_arc_mm);
        let margin = 10.0 * s;
        let fits = |mid: f64| {
            let (lo, hi) = (mid - 0.5 * len, mid + 0.5 * len);
            lo >= (END_INSET + 5.0) * s
                && hi <= tube.axis.length - (END_INSET + 5.0) * s
                && !tube
                    .collapse
                    .iter()
                    .any(|c| lo < c.end + c.taper + margin && hi > c.start - c.taper - margin)
                && !out
                    .iter()
                    .any(|(f, _)| lo < f.end + margin && hi > f.start - margin)
        };
        let mid = [early, late, 0.5]
            .into_iter()
            .map(|f| a + f * (b - a))
            .find(|&m| fits(m));
        let Some(mid) = mid else {
            return Err(Error::invalid(format!(
                "colon phantom: no room for a fluid-filled stretch in the {name}"
            )));
        };
        let f = Filled {
            start: mid - 0.5 * len,
            end: mid + 0.5 * len,
            hu,
        };
        let t = FilledTruth {
            segment: name.clone(),
            start_arc_mm: f.start,
            end_arc_mm: f.end,
            hu,
        };
        out.push((f, t));
    }
    out.sort_by(|x, y| x.0.start.total_cmp(&y.0.start));
    Ok(out)
}
