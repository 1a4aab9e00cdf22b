//! The rectal catheter: from the rectum out through the perineum into the air outside.

use glam::DVec3;

use crate::{
    axis::{Axis, Knot},
    frame::Frame,
    tube::{Balloon, Blob, Canal, Catheter, Tube},
};
use voyage_core::{Error, Result};

/// Full-size height (z, mm) of the perineum's skin when the body has one (rectal tube): the
/// rectum's wall ends ≈ 10.5 mm above the first slice, so this keeps ≥ 5 mm of tissue.
pub(super) const FLOOR_Z: f64 = 4.0;
/// Where (full-size arc, mm) and how far off the axis (fraction of the radius) the rectal
/// catheter's tip lies, and its plastic's HU.
const CATHETER_TIP_ARC: f64 = 35.0;
const CATHETER_OFFSET: f64 = 0.6;
pub(super) const CATHETER_HU: f64 = 100.0;
/// How much lower (full size, mm) the perineum lies when the catheter's way out is an anal
/// canal held open by gas (`ColonOptions::anal_canal`): the canal is this long, plus the few
/// mm of pelvic floor the catheter crosses otherwise.
pub const CANAL_MM: f64 = 35.0;
/// Width (full size, mm) of the canal's gas round the catheter's plastic.
const CANAL_GAS_MM: f64 = 2.5;
/// A retention balloon (full size, mm): from this far up the rectum, this long along it,
/// this much wider than the lumen (it presses into the wall, so no gas passes it), its skin
/// this thick. About 23 ml of air, as a balloon inflated with 20–40 ml. The catheter's tip
/// then lies higher, above it.
const BALLOON_FROM_ARC: f64 = 8.0;
const BALLOON_LENGTH: f64 = 24.0;
const BALLOON_PRESS_MM: f64 = 1.0;
const BALLOON_SKIN_MM: f64 = 1.0;
const BALLOON_TIP_ARC: f64 = 39.0;

/// The rectal catheter (full size: air channel 3 mm in radius, 1 mm plastic wall; kept ≥ a
/// voxel in the small phantom). Its open tip lies `CATHETER_TIP_ARC` mm up the rectum,
/// `CATHETER_OFFSET` of the radius off the axis (so the true centerline stays in the
/// lumen), on the side (posterior first, then left, right, anterior) that keeps clear of
/// the polyps; it runs down beside the axis to the rectum's lower end, bends there and runs
/// on inferiorly and a little posteriorly (like the anal canal) through the pelvic floor to
/// its open end half a slice below the perineum's skin, in the outside air. With `canal`, gas
/// round it below the rectum down to the skin holds its anal canal open; with `balloon`, a
/// retention balloon round it fills the rectum's lowest stretch wall to wall.
pub(super) fn make_catheter(
    frame: &Frame,
    tube: &Tube,
    polyps: &[Blob],
    floor: f64,
    canal: bool,
    balloon: bool,
) -> Result<Catheter> {
    let s = frame.scale;
    let ax = &tube.axis;
    let inner = frame.thin(3.0, 1.1);
    let wall = frame.thin(1.0, 0.75);
    let tip_arc = if balloon {
        BALLOON_TIP_ARC
    } else {
        CATHETER_TIP_ARC
    } * s;
    let low_arc = 5.0 * s;
    let balloon = balloon.then(|| make_balloon(frame, ax));
    let end_z = floor - 0.5 * frame.geom.spacing[2];
    let sides = [DVec3::Y, DVec3::X, DVec3::NEG_X, DVec3::NEG_Y];
    for side in sides {
        let off = |arc: f64| {
            let t = ax.tangent[ax.vertex_at(arc)];
            (side - t * side.dot(t)).normalize_or_zero() * CATHETER_OFFSET * ax.radius_at(arc)
        };
        let tip = ax.point_at(tip_arc) + off(tip_arc);
        let low = ax.point_at(low_arc) + off(low_arc);
        // Below the rectum: inferior and a little posterior.
        let dir = DVec3::new(0.0, 0.25, -1.0).normalize();
        let exit = low + dir * ((low.z - end_z) / -dir.z);
        let mid = low + dir * (0.5 * (low.z - end_z) / -dir.z);
        let knots = [tip, low, mid, exit].map(|pos| Knot { pos, radius: inner });
        let path = Axis::through(&knots, 1.0 * s)?;
        let c = Catheter {
            points: path.points,
            inner_radius: inner,
            wall_mm: wall,
            hu: CATHETER_HU,
            canal: canal.then(|| Canal {
                radius: inner + wall + frame.thin(CANAL_GAS_MM, 1.5),
                floor,
                top: low.z,
            }),
            balloon,
        };
        let clear = polyps
            .iter()
            .all(|b| c.clearance(b.center) - b.reach() >= frame.max_spacing());
        if clear {
            return Ok(c);
        }
    }
    Err(Error::invalid(
        "colon phantom: no room for the rectal catheter beside the rectal polyp",
    ))
}

/// The retention balloon: round the rectum's axis from [`BALLOON_FROM_ARC`] up, pressing
/// into the wall all round its middle.
fn make_balloon(frame: &Frame, ax: &Axis) -> Balloon {
    let s = frame.scale;
    let mid = (BALLOON_FROM_ARC + 0.5 * BALLOON_LENGTH) * s;
    Balloon {
        center: ax.point_at(mid),
        axis: ax.tangent[ax.vertex_at(mid)],
        radius: ax.radius_at(mid) + frame.thin(BALLOON_PRESS_MM, 0.75),
        half_length: 0.5 * BALLOON_LENGTH * s,
        wall_mm: frame.thin(BALLOON_SKIN_MM, 0.75),
    }
}
