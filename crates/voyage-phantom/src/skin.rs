//! What lies at the colon phantom's skin: the CT table under the patient and skin folds.
//!
//! Both fool a segmentation that finds the air outside the body slice by slice, as they did
//! on a real prone exam. Where the skin rests on the table a wedge of outside air narrows to
//! nothing between them; the table's foam is nearly as dark as air, and reaches the scan's
//! edge as on that exam (the table is wider than the field of view). A skin fold is a
//! thin crevice of outside air; where skin closes over its mouth, an axial slice holds it as
//! air enclosed in the body, joined to the outside only through the next slices — which is
//! also what a rectal tube looks like. So the phantom has folds on the dependent side beside
//! the table, and low in the scan near where a rectal catheter leaves the body: in the
//! perineum when the body has one, else in the gluteal cleft, running off the scan's
//! inferior edge.
//!
//! Sizes are full-size millimetres, scaled with the anatomy; a fold is placed by rejection
//! sampling from its own random stream, clear of the colon, the other bowel, the catheter,
//! bone, lungs and the other folds.

use std::f64::consts::TAU;

use glam::{DVec2, DVec3};

use super::{
    arr,
    body::{self, Body, SkinFold, Table},
    frame::Frame,
    rng::Rng,
    truth::{SkinFoldTruth, TableTruth},
    tube::{Blob, Catheter, Tube},
};

/// The table (full size): 430 mm wide, so that, as on a real exam, it runs out of the
/// 384 mm field of view on both sides (its foam reaches the scan's edge in every slice);
/// 45 mm thick, a 2.5 mm shell.
const TABLE_HALF_WIDTH: f64 = 215.0;
const TABLE_THICKNESS: f64 = 45.0;
const TABLE_SHELL: f64 = 2.5;
/// How far the body's weight presses its skin flat against the table: a contact strip
/// ≈ 84 mm wide at full size, the spine's arch kept under the skin.
const FLATTENED: f64 = 4.0;

/// A skin fold's width, depth into the body and length (full size, mm).
const FOLD_WIDTH: (f64, f64) = (1.0, 2.0);
const FOLD_DEPTH: (f64, f64) = (15.0, 40.0);
const FOLD_LENGTH: (f64, f64) = (30.0, 80.0);
/// The skin that closes a fold's mouth over part of its length, and lines it in the fat.
const FOLD_BRIDGE: f64 = 3.0;
const FOLD_LINING: f64 = 1.5;
/// Tissue kept between a fold and anything else inside the body.
const FOLD_CLEAR: f64 = 6.0;
/// Dependent folds: their mouths lie this far from the body's dependent pole (|x − cx|),
/// beside the table's contact strip, between these heights.
const SIDE_OFFSET: (f64, f64) = (55.0, 120.0);
const SIDE_Z: (f64, f64) = (30.0, 340.0);
/// Low folds: perineal ones start this far from where the catheter leaves the body; gluteal
/// ones lie this far beside the posterior midline.
const PERINEAL_OFFSET: (f64, f64) = (12.0, 60.0);
const GLUTEAL_OFFSET: (f64, f64) = (15.0, 45.0);
/// Draws per fold before it is given up (the count stays deterministic either way).
const TRIES: usize = 400;

/// The table under the patient on the dependent side (`gravity`), the body's skin pressed
/// [`FLATTENED`] flat against its top.
pub(super) fn make_table(frame: &Frame, body: &Body, gravity: DVec3) -> Table {
    let s = frame.scale;
    let down = if gravity.y >= 0.0 { 1.0 } else { -1.0 };
    Table {
        center_x: body.center.x,
        half_width: TABLE_HALF_WIDTH * s,
        top: body.center.y + down * (body.semi.y - FLATTENED * s),
        down,
        thickness: TABLE_THICKNESS * s,
        shell: frame.thin(TABLE_SHELL, 1.2),
    }
}

pub(super) fn table_truth(t: &Table, body: &Body) -> TableTruth {
    // The ellipse reaches beyond the table's top over the contact strip.
    let dy = (t.top - body.center.y).abs() / body.semi.y;
    let half = body.semi.x * (1.0 - dy * dy).max(0.0).sqrt();
    TableTruth {
        side: if t.down > 0.0 {
            "posterior"
        } else {
            "anterior"
        }
        .into(),
        top_y_mm: t.top,
        bottom_y_mm: t.top + t.down * t.thickness,
        x_range_mm: [t.center_x - t.half_width, t.center_x + t.half_width],
        shell_mm: t.shell,
        shell_hu: body::TABLE_SHELL,
        foam_hu: body::TABLE_FOAM,
        contact_x_mm: [body.center.x - half, body.center.x + half],
    }
}

/// What a fold must keep clear of, besides the body's bone and lungs.
pub(super) struct Obstacles<'a> {
    pub tube: &'a Tube,
    /// Polyps, stool, gas pockets, opacified loops.
    pub blobs: &'a [Blob],
    pub catheter: Option<&'a Catheter>,
}

/// 3–6 folds on the dependent side (`gravity`) and 1–2 low in the scan: perineal beside the
/// catheter's exit when the body has a floor, else gluteal, off the scan's inferior edge.
pub(super) fn make_folds(
    frame: &Frame,
    body: &Body,
    gravity: DVec3,
    near: &Obstacles,
    seed: u64,
) -> Vec<(SkinFold, SkinFoldTruth)> {
    let mut rng = Rng::new(seed, super::frame::STREAM_SKIN_FOLDS);
    let sides = 3 + (rng.uniform() * 4.0) as usize;
    let lows = 1 + (rng.uniform() * 2.0) as usize;
    let dependent = if gravity.y >= 0.0 { 1.0 } else { -1.0 };
    let mut folds: Vec<(SkinFold, SkinFoldTruth)> = Vec::new();
    let mut place = |draw: &mut dyn FnMut(&mut Rng) -> (SkinFold, &'static str)| {
        for _ in 0..TRIES {
            let (f, region) = draw(&mut rng);
            let placed: Vec<&SkinFold> = folds.iter().map(|(g, _)| g).collect();
            if room_for(&f, frame, body, near, &placed, region == "perineal") {
                let t = fold_truth(&f, region);
                folds.push((f, t));
                return;
            }
        }
    };
    for n in 0..sides {
        place(&mut |rng| (dependent_fold(frame, body, dependent, n, rng), "dependent"));
    }
    for n in 0..lows {
        match (body.floor, near.catheter) {
            (Some(floor), Some(c)) => {
                place(&mut |rng| (perineal_fold(frame, c, floor, n, rng), "perineal"))
            }
            _ => place(&mut |rng| (gluteal_fold(frame, body, n, rng), "gluteal")),
        }
    }
    folds
}

/// The skin's point at `x` on the side `toward` (+1 posterior, −1 anterior) of the body, and
/// the inward normal there (flat where the skin rests on the table).
fn skin_at(body: &Body, x: f64, toward: f64) -> (DVec2, DVec2) {
    let d = x - body.center.x;
    let (a, b) = (body.semi.x, body.semi.y);
    let ey = b * (1.0 - (d / a).powi(2)).max(0.0).sqrt();
    let y = body.center.y + toward * ey;
    if let Some(t) = &body.table
        && t.beyond_top(y) > 0.0
    {
        return (DVec2::new(x, t.top), DVec2::new(0.0, -t.down));
    }
    let normal = -DVec2::new(d / (a * a), toward * ey / (b * b)).normalize();
    (DVec2::new(x, y), normal)
}

/// A fold's frame from its inward direction in the axial plane, tilted by `tilt` radians, and
/// running along z.
fn axial_frame(normal: DVec2, tilt: f64) -> (DVec3, DVec3, DVec3) {
    let n = DVec2::from_angle(tilt).rotate(normal);
    let inward = DVec3::new(n.x, n.y, 0.0);
    (inward, DVec3::Z, inward.cross(DVec3::Z))
}

/// Sizes drawn for a fold: depth, length, half-width (mm, this volume).
fn draw_size(frame: &Frame, rng: &mut Rng) -> (f64, f64, f64) {
    let s = frame.scale;
    let depth = rng.range(FOLD_DEPTH.0, FOLD_DEPTH.1) * s;
    let length = rng.range(FOLD_LENGTH.0, FOLD_LENGTH.1) * s;
    let width = frame.thin(rng.range(FOLD_WIDTH.0, FOLD_WIDTH.1), 1.2);
    (depth, length, 0.5 * width)
}

/// The n-th fold on the dependent side: every third open over its whole length, the others
/// closed over its lower or upper part (35–65 % of it), so that the axial slices there hold
/// it as air enclosed in the body.
fn dependent_fold(frame: &Frame, body: &Body, toward: f64, n: usize, rng: &mut Rng) -> SkinFold {
    let s = frame.scale;
    let side = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
    let x = body.center.x + side * rng.range(SIDE_OFFSET.0, SIDE_OFFSET.1) * s;
    let tilt = rng.range(-0.35, 0.35);
    let (depth, length, half_width) = draw_size(frame, rng);
    let (lo, hi) = (frame.pos([0.0; 3]).z, frame.pos([0.0, 0.0, SIDE_Z.1]).z);
    let z0 = rng.range(lo + SIDE_Z.0 * s, hi - length);
    let closed_part = rng.range(0.35, 0.65) * length;
    let (mouth, normal) = skin_at(body, x, toward);
    let (inward, along, across) = axial_frame(normal, tilt);
    SkinFold {
        mouth: DVec3::new(mouth.x, mouth.y, z0),
        inward,
        along,
        across,
        depth,
        half_width,
        span: (0.0, length),
        closed: match n % 3 {
            0 => None,
            1 => Some((-depth, closed_part)),
            _ => Some((length - closed_part, length + depth)),
        },
        bridge: frame.thin(FOLD_BRIDGE, 1.5),
        lining: frame.thin(FOLD_LINING, 0.5),
    }
}

/// The n-th perineal fold: a crease rising from the perineum's skin (`floor`), starting
/// beside where the catheter leaves the body and running away from it; the first is closed
/// over its far half, so its air reaches the outside only near the catheter.
fn perineal_fold(frame: &Frame, c: &Catheter, floor: f64, n: usize, rng: &mut Rng) -> SkinFold {
    let s = frame.scale;
    let exit = c.points[c.points.len() - 1];
    let dir = DVec2::from_angle(rng.range(0.0, TAU));
    let start = rng.range(PERINEAL_OFFSET.0, PERINEAL_OFFSET.1) * s;
    let (depth, length, half_width) = draw_size(frame, rng);
    let along = DVec3::new(dir.x, dir.y, 0.0);
    SkinFold {
        mouth: DVec3::new(exit.x, exit.y, floor),
        inward: DVec3::Z,
        along,
        across: DVec3::Z.cross(along),
        depth,
        half_width,
        span: (start, start + length),
        closed: (n == 0).then_some((start + 0.5 * length, start + length + depth)),
        bridge: frame.thin(FOLD_BRIDGE, 1.5),
        lining: frame.thin(FOLD_LINING, 0.5),
    }
}

/// The n-th gluteal fold: beside the posterior midline, from below the scan's first slice
/// up; the first closed over its whole length (air enclosed in every axial slice, cut by the
/// scan's edge), the second open to the skin above its lower half.
fn gluteal_fold(frame: &Frame, body: &Body, n: usize, rng: &mut Rng) -> SkinFold {
    let s = frame.scale;
    let side = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
    let x = body.center.x + side * rng.range(GLUTEAL_OFFSET.0, GLUTEAL_OFFSET.1) * s;
    let tilt = rng.range(-0.25, 0.25);
    let (depth, length, half_width) = draw_size(frame, rng);
    let (mouth, normal) = skin_at(body, x, 1.0);
    let (inward, along, across) = axial_frame(normal, tilt);
    let span = (-5.0 * s, length);
    SkinFold {
        mouth: DVec3::new(mouth.x, mouth.y, 0.0),
        inward,
        along,
        across,
        depth,
        half_width,
        span,
        closed: Some(if n == 0 {
            (span.0 - depth, span.1 + depth)
        } else {
            (span.0 - depth, 0.5 * length)
        }),
        bridge: frame.thin(FOLD_BRIDGE, 1.5),
        lining: frame.thin(FOLD_LINING, 0.5),
    }
}

/// Whether fold `f` keeps [`FOLD_CLEAR`] of tissue from the colon's outer wall, the blobs,
/// the catheter, the spine, the lungs and the folds already placed, and stays inside the
/// volume (a perineal fold also inside the body's sides, under a rim of tissue).
fn room_for(
    f: &SkinFold,
    frame: &Frame,
    body: &Body,
    near: &Obstacles,
    placed: &[&SkinFold],
    perineal: bool,
) -> bool {
    let clear = FOLD_CLEAR * frame.scale;
    let reach = f.half_width + f.lining + clear;
    let ax = &near.tube.axis;
    let colon = ax
        .points
        .iter()
        .zip(&ax.radius)
        .all(|(p, r)| f.plane_distance(*p) - r - near.tube.wall_mm >= reach);
    if !colon {
        return false;
    }
    let ext = frame.geom.extent_mm() - frame.geom.spacing_vec();
    let inside_volume =
        |q: DVec3| (0..2).all(|a| q[a] >= reach && q[a] <= ext[a] - reach) && q.z <= ext.z - reach;
    f.plane_points(2.0 * frame.scale).into_iter().all(|q| {
        inside_volume(q)
            && near.blobs.iter().all(|b| b.sdf(q) - b.wall_mm >= reach)
            && near
                .catheter
                .is_none_or(|c| c.distance(q) - c.outer_radius() >= reach)
            && body.spine.sdf_xy(q) >= reach
            && body.lungs.iter().all(|l| l.sdf(q) >= reach)
            && placed
                .iter()
                .all(|g| g.plane_distance(q) - g.half_width - g.lining >= reach)
            && (!perineal || body.side_sdf(q) <= -body.rim)
    })
}

fn fold_truth(f: &SkinFold, region: &str) -> SkinFoldTruth {
    SkinFoldTruth {
        region: region.into(),
        mouth_mm: arr(f.mouth),
        inward: arr(f.inward),
        along: arr(f.along),
        depth_mm: f.depth,
        width_mm: 2.0 * f.half_width,
        span_mm: [f.span.0, f.span.1],
        closed_mm: f.closed.map(|(a, b)| [a.max(f.span.0), b.min(f.span.1)]),
        bridge_mm: f.bridge,
    }
}
