//! The colon's course (its knots, their radii, the segments they start) and the body it lies
//! in, with the checks that keep the two apart and the loops from touching.

use glam::DVec2;

use crate::{
    axis::{Axis, Knot},
    body::{Body, Lung, Spine},
    frame::Frame,
    posture::supine_knot,
    truth::SegmentTruth,
};
use voyage_core::{Error, Result};

/// Colon wall thickness at full size.
pub(super) const WALL: f64 = 2.5;
/// Lumen-to-lumen tissue that different parts of the colon must keep (full size).
pub const MIN_PART_GAP: f64 = 6.0;
/// Source and target lie this far along the centerline from its ends (full size).
pub(super) const END_INSET: f64 = 15.0;

/// The colon's course at full size, in volume-local mm of the 384×384×400 mm volume:
/// (x, y, z), radius, and the name of the segment that starts at the knot.
const KNOTS: &[([f64; 3], f64, &str)] = &[
    ([192.0, 218.0, 30.0], 17.0, "rectum"),
    ([192.0, 228.0, 58.0], 22.0, ""),
    ([191.0, 226.0, 90.0], 23.0, ""),
    ([186.0, 212.0, 118.0], 20.0, ""),
    ([170.0, 190.0, 140.0], 15.0, "sigmoid"),
    ([146.0, 168.0, 150.0], 13.0, ""),
    ([124.0, 140.0, 144.0], 13.0, ""),
    ([128.0, 124.0, 112.0], 13.0, ""),
    ([160.0, 132.0, 82.0], 13.0, ""),
    ([204.0, 132.0, 80.0], 13.0, ""),
    ([236.0, 122.0, 108.0], 13.0, ""),
    ([232.0, 116.0, 148.0], 13.0, ""),
    ([206.0, 114.0, 178.0], 13.0, ""),
    ([176.0, 115.0, 191.0], 13.0, ""),
    ([157.0, 123.0, 195.0], 13.0, ""),
    ([149.0, 142.0, 198.0], 13.0, ""),
    ([157.0, 161.0, 201.0], 13.0, ""),
    ([176.0, 169.0, 202.0], 13.0, ""),
    ([220.0, 172.0, 190.0], 13.0, ""),
    ([260.0, 172.0, 160.0], 12.0, ""),
    ([280.0, 190.0, 136.0], 12.0, ""),
    ([294.0, 206.0, 126.0], 12.0, ""),
    ([307.0, 222.0, 130.0], 12.0, "descending"),
    ([312.0, 232.0, 150.0], 12.0, ""),
    ([308.0, 234.0, 184.0], 12.0, ""),
    ([304.0, 236.0, 232.0], 13.0, ""),
    ([306.0, 230.0, 280.0], 14.0, ""),
    ([296.0, 214.0, 322.0], 16.0, "splenic_flexure"),
    ([280.0, 186.0, 342.0], 18.0, ""),
    ([260.0, 154.0, 340.0], 19.0, ""),
    ([244.0, 128.0, 318.0], 20.0, "transverse"),
    ([228.0, 116.0, 280.0], 20.0, ""),
    ([202.0, 114.0, 250.0], 20.0, ""),
    ([172.0, 116.0, 248.0], 20.0, ""),
    ([148.0, 122.0, 270.0], 20.0, ""),
    ([134.0, 132.0, 300.0], 21.0, ""),
    ([114.0, 150.0, 322.0], 22.0, "hepatic_flexure"),
    ([94.0, 180.0, 324.0], 23.0, ""),
    ([82.0, 208.0, 296.0], 24.0, "ascending"),
    ([78.0, 214.0, 250.0], 25.0, ""),
    ([82.0, 208.0, 204.0], 27.0, ""),
    ([88.0, 196.0, 166.0], 29.0, "cecum"),
    ([94.0, 186.0, 132.0], 30.0, ""),
    ([100.0, 178.0, 104.0], 30.0, ""),
];

/// The abdomen: a 340×260 mm ellipse (full size) with a 10 mm rim, the spine posteriorly
/// and, optionally, the lung bases in the top 24 slices and a perineum at height `floor`.
pub(super) fn make_body(frame: &Frame, lungs: bool, floor: Option<f64>) -> Body {
    let s = frame.scale;
    let c = |x: f64, y: f64| {
        let p = frame.pos([x, y, 0.0]);
        DVec2::new(p.x, p.y)
    };
    let lung = |x: f64| Lung {
        center: c(x, 222.0),
        semi: DVec2::new(55.0, 68.0) * s,
        dome_top: frame.pos([0.0, 0.0, 396.0]).z,
        recess: frame.pos([0.0, 0.0, 376.0]).z,
    };
    Body {
        center: c(192.0, 200.0),
        semi: DVec2::new(170.0, 130.0) * s,
        rim: 10.0 * s,
        spine: Spine {
            center: c(192.0, 284.0),
            radius: 19.0 * s,
            cortex: frame.thin(2.0, 1.0),
            period: 34.0 * s,
            disc: 7.0 * s,
            arch_center: c(192.0, 312.0),
            arch_inner: 7.0 * s,
            arch_outer: 11.0 * s,
        },
        lungs: if lungs {
            vec![lung(192.0 - 88.0), lung(192.0 + 88.0)]
        } else {
            Vec::new()
        },
        floor,
        table: None,
        folds: Vec::new(),
        inv_w: 3.0 / frame.geom.spacing.iter().sum::<f64>(),
    }
}

/// The colon's axis; `supine_pair`: as it lies supine in a supine–prone pair.
pub(super) fn make_axis(frame: &Frame, supine_pair: bool) -> Result<Axis> {
    let knots: Vec<Knot> = KNOTS
        .iter()
        .enumerate()
        .map(|(i, (p, r, _))| Knot {
            pos: frame.pos(if supine_pair { supine_knot(i, *p) } else { *p }),
            radius: r * frame.scale,
        })
        .collect();
    Axis::through(&knots, 1.0)
}

/// Named arc ranges from the knots that start each segment.
pub(super) fn segments(axis: &Axis) -> Vec<SegmentTruth> {
    let starts: Vec<(usize, &str)> = KNOTS
        .iter()
        .enumerate()
        .filter(|(_, k)| !k.2.is_empty())
        .map(|(i, k)| (i, k.2))
        .collect();
    starts
        .iter()
        .enumerate()
        .map(|(n, &(i, name))| SegmentTruth {
            name: name.to_string(),
            start_arc_mm: axis.knot_arc[i],
            end_arc_mm: starts
                .get(n + 1)
                .map_or(axis.length, |&(j, _)| axis.knot_arc[j]),
        })
        .collect()
}

pub(super) fn segment<'a>(segments: &'a [SegmentTruth], name: &str) -> Result<&'a SegmentTruth> {
    segments
        .iter()
        .find(|s| s.name == name)
        .ok_or_else(|| Error::invalid(format!("colon has no segment {name}")))
}

pub(super) fn segment_name(segments: &[SegmentTruth], s: f64) -> String {
    segments
        .iter()
        .find(|g| s >= g.start_arc_mm && s <= g.end_arc_mm)
        .map_or_else(String::new, |g| g.name.clone())
}

/// The checks that make the truth trustworthy: length, bends, separation of the loops,
/// and room around the colon inside the body, away from spine and lungs.
pub(super) fn check_anatomy(frame: &Frame, axis: &Axis, body: &Body) -> Result<()> {
    let s = frame.scale;
    let wall = frame.thin(WALL, 1.0);
    let bad = |what: String| Err(Error::invalid(format!("colon phantom: {what}")));
    if !(1300.0 * s..=1700.0 * s).contains(&axis.length) {
        return bad(format!("centerline {:.0} mm long", axis.length));
    }
    let (bend, at) = axis.min_bend_ratio(wall);
    if bend < 1.05 {
        return bad(format!(
            "bend too tight at arc {:.0} mm (ratio {bend:.2})",
            axis.arc[at]
        ));
    }
    let (gap, i, j) = axis.min_part_gap(wall, 2);
    if gap < MIN_PART_GAP * s {
        return bad(format!(
            "loops at arcs {:.0} and {:.0} mm only {gap:.1} mm apart",
            axis.arc[i], axis.arc[j]
        ));
    }
    let ext = frame.geom.extent_mm() - frame.geom.spacing_vec();
    for (p, r) in axis.points.iter().zip(&axis.radius) {
        let reach = r + wall;
        if (0..3).any(|a| p[a] - reach < 3.0 * s || p[a] + reach > ext[a] - 3.0 * s) {
            return bad(format!("colon at {p:?} touches the volume border"));
        }
        if body.side_sdf(*p) + reach + 5.0 * s > -body.rim {
            return bad(format!("colon at {p:?} reaches the abdominal wall"));
        }
        // The perineum's muscle may wrap the rectum's end (it does in life), its skin not.
        if let Some(f) = body.floor
            && p.z - reach - f < 5.0 * s
        {
            return bad(format!("colon at {p:?} within 5 mm of the perineum"));
        }
        if body.spine.sdf_xy(*p) < reach + 5.0 * s {
            return bad(format!("colon at {p:?} touches the spine"));
        }
        if let Some(l) = body.lungs.iter().find(|l| l.sdf(*p) < reach + 10.0 * s) {
            return bad(format!(
                "colon at {p:?} within 10 mm of the lung at {:?}",
                l.center
            ));
        }
    }
    Ok(())
}

/// The colon's axis as it lies supine and as it lies prone in a pair (`pair_member`).
pub(crate) fn pair_axes(small: bool) -> Result<(Axis, Axis)> {
    let frame = Frame::new(small)?;
    let prone = make_axis(&frame, false)?;
    let mut supine = make_axis(&frame, true)?;
    supine.reframe_like(&prone);
    Ok((supine, prone))
}
