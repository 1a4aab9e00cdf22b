//! Placing polyps on the wall of a tube.

use super::{
    PolypTruth, arr,
    tube::{Blob, BlobKind, Tube},
};

/// Where and what a polyp is, before it is placed.
#[derive(Clone, Debug)]
pub struct PolypSpec {
    pub arc: f64,
    /// Frame angle around the axis.
    pub angle: f64,
    pub diameter: f64,
    /// Pedunculated: stalk length (mm) between the wall and the head; `None` for sessile.
    pub stalk: Option<f64>,
    pub segment: String,
    pub behind_fold: bool,
}

/// Fraction of a sessile polyp's radius by which its centre lies inside the lumen: the
/// head protrudes by (1 + this)·radius = 75 % of its diameter, and its widest circle (the
/// equator) is inside the lumen, so the visible diameter is the true diameter.
pub const SESSILE_INSET: f64 = 0.5;

/// Turns a spec into a blob (for the rasteriser) and its truth.
pub fn place(tube: &Tube, spec: &PolypSpec) -> (Blob, PolypTruth) {
    let ax = &tube.axis;
    let q = ax.point_at(spec.arc);
    let out = ax.radial_at(spec.arc, spec.angle);
    let wall_r = ax.radius_at(spec.arc);
    let rp = spec.diameter / 2.0;
    let base = q + out * wall_r;
    let (center, stalk, protrusion, stalk_len) = match spec.stalk {
        None => (
            q + out * (wall_r - SESSILE_INSET * rp),
            None,
            (1.0 + SESSILE_INSET) * rp,
            0.0,
        ),
        Some(len) => {
            let center = q + out * (wall_r - len - rp);
            // The stalk starts inside the wall so that it is rooted, and ends in the head.
            let root = q + out * (wall_r + 0.5 * tube.wall_mm);
            let r_stalk = (0.3 * rp).max(1.0);
            (center, Some((root, center, r_stalk)), len + 2.0 * rp, len)
        }
    };
    let blob = Blob {
        kind: BlobKind::Polyp,
        center,
        radius: rp,
        stalk,
        wall_mm: 0.0,
        content_hu: 0.0,
    };
    let truth = PolypTruth {
        center_mm: arr(center),
        diameter_mm: spec.diameter,
        segment: spec.segment.clone(),
        behind_fold: spec.behind_fold,
        arc_mm: spec.arc,
        angle_rad: spec.angle,
        base_mm: arr(base),
        direction: arr(-out),
        protrusion_mm: protrusion,
        shape: if spec.stalk.is_some() {
            "pedunculated"
        } else {
            "sessile"
        }
        .to_string(),
        stalk_length_mm: stalk_len,
    };
    (blob, truth)
}
