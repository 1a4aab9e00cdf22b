//! Lumps of tagged stool on the wall, placed as sessile polyps are, some mottled with air.

use glam::DVec3;

use super::{anatomy::segment, folds::folds_around, polyps::fit_diameter, streams::STREAM_STOOL};
use crate::{
    frame::Frame,
    polyp::{PolypSpec, place},
    posture::dependent_angle,
    rng::Rng,
    truth::{PolypTruth, SegmentTruth, StoolTruth},
    tube::{Blob, BlobKind, Tube},
};
use voyage_core::{Error, Result};

/// Segments that get tagged stool, two lumps each; the lumps' diameters (full size) and HU.
const STOOL_SEGMENTS: &[&str] = &["rectum", "sigmoid", "descending", "transverse", "ascending"];
const STOOL_DIAMETER: (f64, f64) = (4.0, 9.0);
const STOOL_HU: (f64, f64) = (500.0, 900.0);

/// Lumps of tagged stool on the wall, sessile like polyps, between folds, clear of the polyps
/// (15 mm along the colon), of each other, of collapsed and fluid-filled stretches; the
/// second of each segment's two is mottled with air.
pub(super) fn make_stool(
    frame: &Frame,
    tube: &Tube,
    segments: &[SegmentTruth],
    polyps: &[PolypTruth],
    dependent: Option<DVec3>,
    seed: u64,
) -> Result<Vec<(Blob, StoolTruth)>> {
    let s = frame.scale;
    let mut rng = Rng::new(seed, STREAM_STOOL);
    let mut out: Vec<(Blob, StoolTruth)> = Vec::new();
    for &name in STOOL_SEGMENTS {
        let seg = segment(segments, name)?;
        for n in 0..2 {
            let wanted = rng.range(STOOL_DIAMETER.0, STOOL_DIAMETER.1) * s;
            let hu = rng.range(STOOL_HU.0, STOOL_HU.1);
            let mut spec = None;
            for _ in 0..16 {
                let arc =
                    seg.start_arc_mm + rng.range(0.1, 0.9) * (seg.end_arc_mm - seg.start_arc_mm);
                let angle = rng.range(0.0, std::f64::consts::TAU);
                let at = folds_around(tube, arc).map_or(arc, |(a, b)| 0.5 * (a + b));
                // Stool sinks: within ±30° of the bottom of the lumen.
                let angle = dependent.map_or(angle, |g| {
                    dependent_angle(&tube.axis, at, g) + (angle / std::f64::consts::TAU - 0.5)
                });
                let d = fit_diameter(wanted, None, tube.axis.radius_at(at))
                    .max(2.0 * frame.max_spacing());
                let clear = polyps.iter().all(|p| (p.arc_mm - at).abs() > 15.0 * s)
                    && out.iter().all(|(_, t)| (t.arc_mm - at).abs() > 10.0 * s)
                    && tube.clear_of_stretches(at, d);
                if clear && at > seg.start_arc_mm && at < seg.end_arc_mm {
                    spec = Some(PolypSpec {
                        arc: at,
                        angle,
                        diameter: d,
                        stalk: None,
                        segment: name.into(),
                        behind_fold: false,
                    });
                    break;
                }
            }
            let spec = spec.ok_or_else(|| {
                Error::invalid(format!(
                    "colon phantom: no room for tagged stool in the {name}"
                ))
            })?;
            let (mut blob, t) = place(tube, &spec);
            let mottled = n == 1;
            blob.kind = BlobKind::Stool { mottled };
            blob.content_hu = hu;
            out.push((
                blob,
                StoolTruth {
                    center_mm: t.center_mm,
                    diameter_mm: spec.diameter,
                    segment: name.into(),
                    arc_mm: spec.arc,
                    hu,
                    mottled,
                },
            ));
        }
    }
    Ok(out)
}
