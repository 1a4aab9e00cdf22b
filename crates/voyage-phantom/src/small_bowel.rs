//! Opacified small bowel: loops of ileum full of oral contrast, the bright distractor of a
//! real CT colonography with fluid tagging.
//!
//! One continuous stretch of small bowel in three tubes of different calibre (full size:
//! radius 8–10.5 mm, 1.5 mm wall of soft tissue, content +300..+600 HU each, no gas, so no
//! air–fluid level), about 0.8 m in all, joined end to end so that their contrast is one:
//!
//! - a loop meandering in the central abdomen in front of the spine, under the transverse
//!   colon, up to the left;
//! - a loop down the left flank lying against the descending colon's medial wall (wall to
//!   wall) and on past the sigmoid's end into the pelvis;
//! - the terminal ileum, across the pelvis in front of the rectum, up the right side and into
//!   the caecum through the ileocaecal valve.
//!
//! The valve is on the caecum's dependent side (posterior supine, where the caecum meets the
//! ascending colon; prone, near the caecal pole, 30° below straight anterior, as the ileum
//! comes up from the pelvis: there is no room in front of the caecum) and the caecal pool's
//! level (see `make_pools` in [`super::colon`]) is set above its opening, so the caecal
//! fluid and the loops form one bright region as on a real exam. Along the contact the
//! lumens stay a voxel apart at least (tissue only); everywhere else the loops keep ≥ 3 mm
//! (full size; a voxel small) of tissue from the colon, skin, spine and lungs, and their
//! lumens stay two walls apart where the bowel passes itself.
//!
//! The course is hand-placed on a map of the free room (`free_space_map`, `loop_room_report`
//! in [`super::colon`]), its knots jittered by a few mm from the seed; a jittered course
//! that fails the checks is drawn again (a fixed number of times, then the hand-placed
//! course is used), so the result is deterministic.

use glam::DVec3;

use super::{
    arr,
    axis::{Axis, Knot},
    body::Body,
    frame::Frame,
    rng::Rng,
    truth::{LoopTruth, SegmentTruth},
    tube::{Blob, BlobKind, Catheter, Tube},
};
use voyage_core::{Error, Result};

/// Where the terminal ileum opens into the caecum.
#[derive(Clone, Debug)]
pub struct Valve {
    /// The colon's axis vertex the valve sits beside.
    pub vertex: usize,
    /// Centre of the opening, on the lumen's nominal surface on the dependent side.
    pub point: DVec3,
    /// Outward unit normal of the caecal wall there: the terminal ileum's direction.
    pub normal: DVec3,
    /// How deep (along gravity, from the lumen's floor at `vertex`) a pool must be to cover
    /// the opening with some margin.
    pub min_depth: f64,
}

/// The loops as blobs for the rasteriser, their truth and the valve.
#[derive(Clone, Debug)]
pub struct SmallBowel {
    pub blobs: Vec<Blob>,
    pub loops: Vec<LoopTruth>,
    pub valve: Valve,
}

/// A knot of a loop's course.
#[derive(Clone, Copy, Debug)]
enum Spec {
    /// A full-size position (jittered).
    At([f64; 3]),
    /// Against the colon's outer wall at full-size arc `arc`, on the side `side` points to
    /// (full-size, made perpendicular to the axis): wall to wall.
    Contact { arc: f64, side: [f64; 3] },
}

use Spec::{At, Contact};

/// Full-size radius range of each tube (central, descending, terminal ileum).
const RADII: [(f64, f64); 3] = [(9.0, 10.5), (8.0, 10.0), (8.0, 9.5)];
const WALL: f64 = 1.5;
const HU: (f64, f64) = (300.0, 600.0);
/// Jitter of the hand-placed knots (full-size mm, each axis).
const JITTER: f64 = 4.0;
const TRIES: usize = 12;

/// The course, central loop first, and the indices of the knots where the second and the
/// third tube begin. The valve's own knots are added at the end.
fn course(prone: bool) -> (Vec<Spec>, [usize; 2]) {
    let side = [-1.0, 0.0, 0.0];
    let mut v = vec![
        // Central loop.
        At([150.0, 238.0, 170.0]),
        At([196.0, 214.0, 178.0]),
        At([244.0, 230.0, 196.0]),
        At([254.0, 206.0, 226.0]),
        At([226.0, 200.0, 250.0]),
        At([218.0, 218.0, 270.0]),
        At([246.0, 234.0, 282.0]),
        // Against the descending colon, then past the sigmoid's end into the pelvis.
        Contact { arc: 875.0, side },
        Contact { arc: 850.0, side },
        Contact { arc: 825.0, side },
        Contact { arc: 800.0, side },
        At([268.0, 228.0, 140.0]),
        At([262.0, 212.0, 95.0]),
        // Terminal ileum.
        At([240.0, 200.0, 50.0]),
        At([192.0, 175.0, 45.0]),
    ];
    if prone {
        // Up the right side to the caecal pole's anterior face, from below (in front of the
        // caecum there is no room between the sigmoid and the abdominal wall).
        v.extend([
            At([160.0, 185.0, 42.0]),
            At([130.0, 172.0, 45.0]),
            At([112.0, 148.0, 56.0]),
            At([100.0, 134.0, 70.0]),
            At([96.0, 133.0, 86.0]),
        ]);
    } else {
        // Up the right side behind the caecum, round to its posterior face.
        v.extend([
            At([150.0, 200.0, 50.0]),
            At([137.0, 235.0, 80.0]),
            At([140.0, 245.0, 112.0]),
            At([120.0, 266.0, 132.0]),
            At([101.0, 273.0, 144.0]),
            At([91.0, 262.0, 153.0]),
        ]);
    }
    (v, [6, 12])
}

/// Makes the loops. `polyps` and `catheter` are kept clear of; `gravity` decides the
/// valve's side.
#[allow(clippy::too_many_arguments)]
pub(super) fn make(
    frame: &Frame,
    tube: &Tube,
    body: &Body,
    segments: &[SegmentTruth],
    gravity: DVec3,
    polyps: &[Blob],
    catheter: Option<&Catheter>,
    seed: u64,
) -> Result<SmallBowel> {
    let s = frame.scale;
    let prone = gravity.y < 0.0;
    let mut rng = Rng::new(seed, super::frame::STREAM_BOWEL);
    let wall = frame.thin(WALL, 0.7);
    let cecum = segments
        .iter()
        .find(|g| g.name == "cecum")
        .ok_or_else(|| Error::invalid("colon has no cecum"))?;
    let (specs, starts) = course(prone);
    // Draws: radii, contents, then the jitter of every knot per try: a fixed number, so the
    // result depends on the seed only.
    let radii: Vec<f64> = RADII.iter().map(|&(a, b)| rng.range(a, b) * s).collect();
    let hus: Vec<f64> = (0..3).map(|_| rng.range(HU.0, HU.1)).collect();
    let r_ileum = radii[2];
    let valve = place_valve(frame, tube, cecum, gravity, r_ileum, wall, polyps)?;
    let mut chosen = None;
    for attempt in 0..=TRIES {
        let jitter = attempt < TRIES;
        let mut knots: Vec<DVec3> = Vec::with_capacity(specs.len() + 3);
        for (i, k) in specs.iter().enumerate() {
            let d = DVec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ) * JITTER
                * s;
            let d = if jitter { d } else { DVec3::ZERO };
            let r = radii[tube_of(i, starts)];
            knots.push(match *k {
                At(p) => frame.pos(p) + d,
                Contact { arc, side } => contact(tube, arc * s, DVec3::from_array(side), r, wall),
            });
        }
        // Into the caecum through the valve, straight across its wall.
        knots.push(valve.point + valve.normal * (tube.wall_mm + r_ileum + 6.0 * s));
        knots.push(valve.point);
        knots.push(valve.point - valve.normal * (0.9 * r_ileum));
        // (The axis's radius is the widest tube's: it only enters the bend check.)
        let rmax = radii.iter().cloned().fold(0.0, f64::max);
        let ks: Vec<Knot> = knots
            .iter()
            .map(|&pos| Knot { pos, radius: rmax })
            .collect();
        let axis = Axis::through(&ks, 1.0 * s)?;
        match check(
            frame, tube, body, &axis, &specs, starts, &radii, wall, catheter,
        ) {
            Ok(()) => {
                chosen = Some(axis);
                break;
            }
            Err(e) if !jitter => return Err(e),
            Err(_) => {}
        }
    }
    let axis =
        chosen.ok_or_else(|| Error::invalid("colon phantom: no room for the small-bowel loops"))?;
    // Split the one smooth course into its tubes at the joining knots.
    let bounds = [
        0,
        axis.vertex_at(axis.knot_arc[starts[0]]),
        axis.vertex_at(axis.knot_arc[starts[1]]),
        axis.len() - 1,
    ];
    let mut blobs = Vec::new();
    let mut loops = Vec::new();
    for n in 0..3 {
        let (first, last) = (bounds[n], bounds[n + 1]);
        // Capsules between every few axis vertices: equal radii, so their union is the tube.
        let mut i = first;
        while i < last {
            let j = (i + 3).min(last);
            let (a, b) = (axis.points[i], axis.points[j]);
            blobs.push(Blob {
                kind: BlobKind::Loop,
                center: (a + b) * 0.5,
                radius: radii[n],
                stalk: Some((a, b, radii[n])),
                wall_mm: wall,
                content_hu: hus[n],
            });
            i = j;
        }
        let range = if n == 0 {
            0..starts[0]
        } else if n == 1 {
            starts[0]..starts[1]
        } else {
            starts[1]..specs.len()
        };
        loops.push(LoopTruth {
            axis_mm: axis.points[first..=last].iter().map(|p| arr(*p)).collect(),
            radius_mm: radii[n],
            wall_mm: wall,
            hu: hus[n],
            length_mm: axis.arc[last] - axis.arc[first],
            enters_cecum: n == 2,
            touches_colon: specs[range].iter().any(|k| matches!(k, Contact { .. })),
        });
    }
    Ok(SmallBowel {
        blobs,
        loops,
        valve,
    })
}

impl SmallBowel {
    /// The same loops full of gas instead of contrast (their truth's `hu` says so).
    pub fn filled_with_gas(mut self) -> SmallBowel {
        for b in &mut self.blobs {
            b.content_hu = super::body::AIR;
        }
        for l in &mut self.loops {
            l.hu = super::body::AIR;
        }
        self
    }

    /// The terminal ileum stopped short of the caecum: its lumen and wall end `margin` mm
    /// outside the colon's wall (`colon_wall` mm thick) at the valve, so that its content is
    /// apart from the caecum's (a competent valve).
    pub fn closed_at_the_valve(mut self, colon_wall: f64, margin: f64) -> SmallBowel {
        let v = self.valve.point;
        let ileum = self.loops.last().expect("the terminal ileum");
        let keep_out = ileum.radius_mm + ileum.wall_mm + colon_wall + margin;
        self.blobs.retain(|b| {
            b.kind != BlobKind::Loop
                || b.stalk
                    .is_none_or(|(a, c, _)| super::tube::segment_distance(v, a, c) >= keep_out)
        });
        let ileum = self.loops.last_mut().expect("the terminal ileum");
        while ileum
            .axis_mm
            .last()
            .is_some_and(|&p| DVec3::from_array(p).distance(v) < keep_out)
        {
            ileum.axis_mm.pop();
        }
        ileum.length_mm = ileum
            .axis_mm
            .windows(2)
            .map(|w| DVec3::from_array(w[0]).distance(DVec3::from_array(w[1])))
            .sum();
        ileum.enters_cecum = false;
        self
    }
}

/// Which tube knot `i` belongs to.
fn tube_of(i: usize, starts: [usize; 2]) -> usize {
    if i < starts[0] {
        0
    } else if i < starts[1] {
        1
    } else {
        2
    }
}

/// The valve: beside the caecum's axis vertex 12 mm (full size) into the caecum supine
/// (where it meets the ascending colon), 20 mm before the caecal pole prone, moved along the
/// caecum if a polyp is in the way; on the lumen's surface in the direction of gravity
/// supine, 30° below it prone (the terminal ileum comes up from the pelvis there: in front of
/// the caecum there is no room for it).
fn place_valve(
    frame: &Frame,
    tube: &Tube,
    cecum: &SegmentTruth,
    gravity: DVec3,
    r: f64,
    wall: f64,
    polyps: &[Blob],
) -> Result<Valve> {
    let s = frame.scale;
    let ax = &tube.axis;
    let prone = gravity.y < 0.0;
    let base = if prone {
        cecum.end_arc_mm - 20.0 * s
    } else {
        cecum.start_arc_mm + 12.0 * s
    };
    let normal = if prone {
        (gravity - DVec3::Z * 30f64.to_radians().tan()).normalize()
    } else {
        gravity
    };
    for shift in [0.0, 8.0, -8.0, 16.0, -16.0] {
        let arc =
            (base + shift * s).clamp(cecum.start_arc_mm + 4.0 * s, cecum.end_arc_mm - 12.0 * s);
        let v = ax.vertex_at(arc);
        let point = ax.points[v] + normal * ax.radius[v];
        let clear = polyps
            .iter()
            .all(|b| b.center.distance(point) - b.reach() >= r + wall + 2.0 * s);
        if clear {
            // The opening's rim reaches angle tilt + asin(r / R) from straight down, on the
            // wall's outer surface of radius R; then a margin of 3 mm (2 voxels).
            let big = ax.radius[v] + tube.wall_mm;
            let tilt = normal.angle_between(gravity);
            let rim = (tilt + (r / big).min(1.0).asin()).min(std::f64::consts::FRAC_PI_2);
            let min_depth = big * (1.0 - rim.cos()) + (3.0 * s).max(2.0 * frame.max_spacing());
            return Ok(Valve {
                vertex: v,
                point,
                normal,
                min_depth,
            });
        }
    }
    Err(Error::invalid(
        "colon phantom: no room for the ileocaecal valve beside the caecal polyp",
    ))
}

/// A knot against the colon's outer wall at `arc`, towards `side`: the two walls touch
/// (between knots the course runs a little closer or farther).
fn contact(tube: &Tube, arc: f64, side: DVec3, r: f64, wall: f64) -> DVec3 {
    let ax = &tube.axis;
    let t = ax.tangent[ax.vertex_at(arc)];
    let n = (side - t * side.dot(t)).normalize_or_zero();
    let d = ax.radius_at(arc) + tube.wall_mm + r + wall;
    ax.point_at(arc) + n * d
}

/// Checks the course's room (see the module's notes). Within a contact knot's stretch the
/// bowel may touch the colon, and from a little before the valve's knots on it may join it.
#[allow(clippy::too_many_arguments)]
fn check(
    frame: &Frame,
    tube: &Tube,
    body: &Body,
    ax: &Axis,
    specs: &[Spec],
    starts: [usize; 2],
    radii: &[f64],
    wall: f64,
    catheter: Option<&Catheter>,
) -> Result<()> {
    let s = frame.scale;
    let gap = (3.0 * s).max(frame.max_spacing());
    let bad = |what: String| Err(Error::invalid(format!("colon phantom: small bowel {what}")));
    let col = &tube.axis;
    // Radius at each vertex (that of its tube).
    let bound = [ax.knot_arc[starts[0]], ax.knot_arc[starts[1]]];
    let radius = |a: f64| {
        radii[if a < bound[0] {
            0
        } else if a < bound[1] {
            1
        } else {
            2
        }]
    };
    let rmax = radii.iter().cloned().fold(0.0, f64::max);
    // Relative to the full-size wall (scaled), so small and full size agree; below 1 the
    // tube would fold into itself on the inside of the bend.
    let (bend, at) = ax.min_bend_ratio(WALL * s);
    if bend < 1.0 {
        return bad(format!(
            "bends too tightly ({bend:.2}) at {:.0?}",
            ax.points[at].to_array()
        ));
    }
    let touch: Vec<(f64, f64)> = specs
        .iter()
        .enumerate()
        .filter(|(_, k)| matches!(k, Contact { .. }))
        .map(|(i, _)| {
            (
                ax.knot_arc[i] - 3.5 * (rmax + wall),
                ax.knot_arc[i] + 3.5 * (rmax + wall),
            )
        })
        .collect();
    let valve_from = ax.knot_arc[specs.len()] - 2.0 * (rmax + wall);
    for (p, a) in ax.points.iter().zip(&ax.arc) {
        let reach = radius(*a) + wall;
        let colon = col
            .points
            .iter()
            .zip(&col.radius)
            .map(|(c, rc)| c.distance(*p) - rc - tube.wall_mm)
            .fold(f64::INFINITY, f64::min)
            - reach;
        let touching = touch.iter().any(|&(lo, hi)| *a >= lo && *a <= hi);
        // Touching: the lumens stay a voxel apart at least, so there is tissue between them.
        let need = if touching {
            frame.max_spacing() - wall - tube.wall_mm
        } else {
            gap
        };
        if colon < need && *a < valve_from {
            return bad(format!(
                "at {:.0?} only {colon:.1} mm from the colon",
                p.to_array()
            ));
        }
        if -body.skin_sdf(*p) - body.rim - reach < gap {
            return bad(format!(
                "at {:.0?} reaches the abdominal wall",
                p.to_array()
            ));
        }
        if body.spine.sdf_xy(*p) - reach < gap {
            return bad(format!("at {:.0?} touches the spine", p.to_array()));
        }
        if body.lungs.iter().any(|l| l.sdf(*p) - reach < 10.0 * s) {
            return bad(format!("at {:.0?} near a lung", p.to_array()));
        }
        if let Some(c) = catheter
            && c.distance(*p) - c.outer_radius() - reach < gap
        {
            return bad(format!("at {:.0?} touches the rectal tube", p.to_array()));
        }
        // Where the bowel passes itself: walls may touch, lumens not.
        let far = std::f64::consts::PI * 2.0 * (rmax + wall);
        for (q, b) in ax.points.iter().zip(&ax.arc).step_by(2) {
            if (a - b).abs() > far && p.distance(*q) - radius(*a) - radius(*b) < 2.0 * wall {
                return bad(format!(
                    "at {:.0?} runs into itself at {:.0?}",
                    p.to_array(),
                    q.to_array()
                ));
            }
        }
    }
    Ok(())
}
