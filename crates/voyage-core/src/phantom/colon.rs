//! A synthetic colon at a real scan's size, with haustral folds, polyps of known size and
//! the things that make real CT colonography hard (tagged fluid, a collapsed stretch,
//! small-bowel gas, lung bases).
//!
//! Full size: 512×512×400 voxels of 0.75×0.75×1.0 mm (384×384×400 mm), like a clinical
//! scan. Small (for fast tests): 128×128×125 voxels of 1.5×1.5×1.6 mm with the whole
//! anatomy scaled by ½ (lumen radius 6–15 mm, so ≥ 4 voxels); thin features are kept about
//! a voxel thick at least (wall 1.6 mm, fold half-width 1.44 mm), polyps become d/2 + 2.5 mm.
//!
//! Anatomy (identity LPS frame: +x patient left, +y posterior, +z superior), see `KNOTS`:
//! the rectum rises in the midline in front of the sacrum; the sigmoid swings right, dips
//! into the pelvis in front of the rectum, climbs on the left, makes an anterior loop under
//! the transverse colon and reaches the left iliac fossa; the descending colon climbs the
//! left flank posteriorly to the splenic flexure under the left lung; the transverse colon
//! crosses anteriorly to the right, sagging to z ≈ 250 mm; the hepatic flexure (a little
//! lower than the splenic) turns down into the ascending colon on the right, which ends in
//! the wide, blind cecum. 1562 mm long; radius 12–30 mm (rectum and cecum widest, sigmoid
//! and descending narrowest); different loops keep ≥ 10 mm of tissue between their lumens.
//!
//! Haustral folds every 20–30 mm from the sigmoid on (none in the rectum): three crescents
//! between the taeniae, each 3–8 mm deep (at most 45 % of the radius) and ≈ 2–4 mm thick
//! (see [`Fold`]). Eight polyps of 3–12 mm in six segments, three hidden just behind a fold
//! (see `POLYPS`). The truth records everything (see [`Truth`]).

use glam::{DVec2, DVec3};

use super::axis::{Axis, Knot};
use super::body::{self, Body, Lung, Spine};
use super::polyp::{PolypSpec, place};
use super::raster::{Materials, Scene};
use super::rng::{Rng, stream_key};
use super::truth::{
    COORDINATES_NOTE, CollapsedTruth, DistractorTruth, FoldTruth, PolypTruth, PoolTruth, RoiTruth, SegmentTruth,
    Truth,
};
use super::tube::{Blob, BlobKind, Collapse, Ends, Fold, FoldSector, Pool, Tube};
use super::{Phantom, arr, label, label_counts};
use crate::{Error, Geometry, Result};

/// What colon to make.
#[derive(Clone, Debug)]
pub struct ColonOptions {
    pub seed: u64,
    /// ≈128³ at 1.5–1.6 mm with the anatomy scaled by ½, for fast tests.
    pub small: bool,
    /// Pools of tagged fluid (+400..+700 HU) with flat air–fluid levels in the dependent
    /// (posterior) parts of the rectum, descending and ascending colon.
    pub tagged_fluid: bool,
    /// A 30 mm stretch of the descending colon collapsed to a tissue cord: two gas parts.
    pub collapsed_segment: bool,
    /// A few separate small-bowel gas pockets (not colon).
    pub small_bowel_gas: bool,
    /// The bases of both lungs in the top slices (not colon).
    pub lung_bases: bool,
    /// Standard deviation of the CT noise (HU).
    pub noise_hu: f64,
}

impl Default for ColonOptions {
    fn default() -> Self {
        ColonOptions {
            seed: 1,
            small: false,
            tagged_fluid: false,
            collapsed_segment: false,
            small_bowel_gas: true,
            lung_bases: true,
            noise_hu: 20.0,
        }
    }
}

pub const FULL_DIMS: [usize; 3] = [512, 512, 400];
pub const FULL_SPACING: [f64; 3] = [0.75, 0.75, 1.0];
pub const SMALL_DIMS: [usize; 3] = [128, 128, 125];
pub const SMALL_SPACING: [f64; 3] = [1.5, 1.5, 1.6];
pub const SMALL_SCALE: f64 = 0.5;

/// Colon wall thickness at full size.
const WALL: f64 = 2.5;
/// Lumen-to-lumen tissue that different parts of the colon must keep (full size).
pub const MIN_PART_GAP: f64 = 6.0;
/// Source and target lie this far along the centerline from its ends (full size).
const END_INSET: f64 = 15.0;
/// Fold spacing range, depth range and half thickness (full size).
const FOLD_SPACING: (f64, f64) = (20.0, 30.0);
const FOLD_DEPTH: (f64, f64) = (3.0, 8.0);
const FOLD_HALF_WIDTH: f64 = 2.0;
/// A crescent never reaches further in than this fraction of the radius, so the lumen
/// stays open around the centerline.
const FOLD_MAX_FRACTION: f64 = 0.45;

const STREAM_NOISE: u64 = 0xC010_0001;
const STREAM_FOLDS: u64 = 0xC010_0002;
const STREAM_POLYPS: u64 = 0xC010_0003;
const STREAM_POOLS: u64 = 0xC010_0004;
const STREAM_GAS: u64 = 0xC010_0005;

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

/// Segments where tagged fluid pools (the posterior, dependent ones for a supine patient).
const POOL_SEGMENTS: &[&str] = &["rectum", "descending", "ascending"];

/// Size, spacing and the map from full-size anatomy to this volume.
#[derive(Clone, Debug)]
struct Frame {
    geom: Geometry,
    scale: f64,
    offset: DVec3,
}

impl Frame {
    fn new(small: bool) -> Result<Frame> {
        let (dims, spacing, scale) =
            if small { (SMALL_DIMS, SMALL_SPACING, SMALL_SCALE) } else { (FULL_DIMS, FULL_SPACING, 1.0) };
        let geom = Geometry::new(dims, spacing, [0.0; 3])?;
        let full = Geometry::new(FULL_DIMS, FULL_SPACING, [0.0; 3])?;
        let ext = |g: &Geometry| g.extent_mm() - g.spacing_vec();
        let offset = (ext(&geom) - ext(&full) * scale) * 0.5;
        Ok(Frame { geom, scale, offset })
    }

    /// Full-size anatomy position → this volume's local mm.
    fn pos(&self, p: [f64; 3]) -> DVec3 {
        DVec3::from_array(p) * self.scale + self.offset
    }

    fn max_spacing(&self) -> f64 {
        self.geom.spacing.iter().cloned().fold(0.0, f64::max)
    }

    /// A full-size length scaled, but not below `voxels` voxels.
    fn thin(&self, mm: f64, voxels: f64) -> f64 {
        (mm * self.scale).max(voxels * self.max_spacing())
    }
}

/// Makes the colon phantom.
pub fn colon(opts: &ColonOptions) -> Result<Phantom> {
    if !(opts.noise_hu >= 0.0 && opts.noise_hu.is_finite()) {
        return Err(Error::invalid(format!("noise {} HU is not a non-negative number", opts.noise_hu)));
    }
    let frame = Frame::new(opts.small)?;
    let body = make_body(&frame, opts.lung_bases);
    let axis = make_axis(&frame)?;
    let segments = segments(&axis);
    check_anatomy(&frame, &axis, &body)?;
    let mut tube = Tube::new(axis, frame.thin(WALL, 1.0), Ends::Round);
    let collapse = opts.collapsed_segment.then(|| make_collapse(&frame, &segments));
    tube.collapse = collapse.as_ref().map(|(c, _)| c.clone());
    let folds = make_folds(&frame, &tube, &segments, opts.seed);
    tube.set_folds(folds);
    let (mut blobs, polyps) = make_polyps(&frame, &mut tube, &segments, opts.seed)?;
    let pools = if opts.tagged_fluid { make_pools(&tube, &segments, opts.seed) } else { Vec::new() };
    tube.pools = pools.iter().map(|(p, _)| p.clone()).collect();
    let mut distractors = Vec::new();
    if opts.small_bowel_gas {
        let pockets = make_pockets(&frame, &tube, &body, opts.seed);
        distractors.extend(pockets.iter().map(|b| DistractorTruth {
            kind: "small_bowel_gas".into(),
            center_mm: arr(b.center),
            semi_axes_mm: [b.radius; 3],
            hu: body::AIR,
        }));
        blobs.extend(pockets);
    }
    distractors.extend(body.lungs.iter().map(|l| DistractorTruth {
        kind: "lung".into(),
        center_mm: [l.center.x, l.center.y, 0.5 * (l.recess + frame.geom.extent_mm().z)],
        semi_axes_mm: [l.semi.x, l.semi.y, 0.5 * (frame.geom.extent_mm().z - l.recess)],
        hu: body::LUNG,
    }));
    let noise_roi = fat_roi(&frame, &tube, &blobs, &body);
    let scene = Scene {
        geom: frame.geom.clone(),
        tube: &tube,
        blobs: &blobs,
        materials: Materials { lumen_air: body::AIR, wall: body::SOFT_TISSUE, polyp: body::SOFT_TISSUE, pocket_air: body::AIR },
        background: &body,
        noise_sigma: opts.noise_hu,
        noise_key: stream_key(opts.seed, STREAM_NOISE),
    };
    let r = scene.render()?;
    let counts = label_counts(&r.labels);
    let ax = &tube.axis;
    let inset = END_INSET * frame.scale;
    let (source_arc, target_arc) = (inset, ax.length - inset);
    let truth = Truth {
        kind: "colon".into(),
        seed: opts.seed,
        coordinates: COORDINATES_NOTE.into(),
        dims: frame.geom.dims,
        spacing_mm: frame.geom.spacing,
        origin_lps_mm: frame.geom.origin,
        direction: frame.geom.direction,
        scale: frame.scale,
        noise_hu: opts.noise_hu,
        centerline_mm: ax.points.iter().map(|p| arr(*p)).collect(),
        centerline_arc_mm: ax.arc.clone(),
        centerline_radius_mm: ax.radius.clone(),
        centerline_length_mm: ax.length,
        source_mm: arr(ax.point_at(source_arc)),
        target_mm: arr(ax.point_at(target_arc)),
        source_arc_mm: source_arc,
        target_arc_mm: target_arc,
        wall_thickness_mm: tube.wall_mm,
        min_part_gap_mm: ax.min_part_gap(tube.wall_mm, 2).0,
        polyps,
        lumen_voxels: counts[label::LUMEN_AIR as usize] + counts[label::LUMEN_FLUID as usize],
        folds: tube.folds.len(),
        fold_list: fold_truth(&tube, &segments),
        segments: segments.clone(),
        fluid_pools: pools.into_iter().map(|(_, t)| t).collect(),
        fluid_voxels: counts[label::LUMEN_FLUID as usize],
        collapsed: collapse.map(|(_, t)| t),
        distractors,
        noise_roi,
        materials_hu: materials(),
        labels: label::legend(),
    };
    Ok(Phantom { ct: r.ct, lumen: r.lumen, labels: r.labels, truth })
}

fn materials() -> Vec<(String, f64)> {
    [
        ("air", body::AIR),
        ("fat", body::FAT),
        ("colon_wall", body::SOFT_TISSUE),
        ("polyp", body::SOFT_TISSUE),
        ("muscle_skin", body::MUSCLE),
        ("cancellous_bone", body::CANCELLOUS),
        ("cortical_bone", body::CORTEX),
        ("disc", body::DISC),
        ("lung", body::LUNG),
    ]
    .into_iter()
    .map(|(n, v)| (n.to_string(), v))
    .collect()
}

/// The abdomen: a 340×260 mm ellipse (full size) with a 10 mm rim, the spine posteriorly
/// and, optionally, the lung bases in the top 24 slices.
fn make_body(frame: &Frame, lungs: bool) -> Body {
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
        lungs: if lungs { vec![lung(192.0 - 88.0), lung(192.0 + 88.0)] } else { Vec::new() },
        inv_w: 3.0 / frame.geom.spacing.iter().sum::<f64>(),
    }
}

fn make_axis(frame: &Frame) -> Result<Axis> {
    let knots: Vec<Knot> = KNOTS.iter().map(|(p, r, _)| Knot { pos: frame.pos(*p), radius: r * frame.scale }).collect();
    Axis::through(&knots, 1.0)
}

/// Named arc ranges from the knots that start each segment.
fn segments(axis: &Axis) -> Vec<SegmentTruth> {
    let starts: Vec<(usize, &str)> =
        KNOTS.iter().enumerate().filter(|(_, k)| !k.2.is_empty()).map(|(i, k)| (i, k.2)).collect();
    starts
        .iter()
        .enumerate()
        .map(|(n, &(i, name))| SegmentTruth {
            name: name.to_string(),
            start_arc_mm: axis.knot_arc[i],
            end_arc_mm: starts.get(n + 1).map_or(axis.length, |&(j, _)| axis.knot_arc[j]),
        })
        .collect()
}

fn segment<'a>(segments: &'a [SegmentTruth], name: &str) -> Result<&'a SegmentTruth> {
    segments.iter().find(|s| s.name == name).ok_or_else(|| Error::invalid(format!("colon has no segment {name}")))
}

fn segment_name(segments: &[SegmentTruth], s: f64) -> String {
    segments.iter().find(|g| s >= g.start_arc_mm && s <= g.end_arc_mm).map_or_else(String::new, |g| g.name.clone())
}

/// The checks that make the truth trustworthy: length, bends, separation of the loops,
/// and room around the colon inside the body, away from spine and lungs.
fn check_anatomy(frame: &Frame, axis: &Axis, body: &Body) -> Result<()> {
    let s = frame.scale;
    let wall = frame.thin(WALL, 1.0);
    let bad = |what: String| Err(Error::invalid(format!("colon phantom: {what}")));
    if !(1300.0 * s..=1700.0 * s).contains(&axis.length) {
        return bad(format!("centerline {:.0} mm long", axis.length));
    }
    let (bend, at) = axis.min_bend_ratio(wall);
    if bend < 1.05 {
        return bad(format!("bend too tight at arc {:.0} mm (ratio {bend:.2})", axis.arc[at]));
    }
    let (gap, i, j) = axis.min_part_gap(wall, 2);
    if gap < MIN_PART_GAP * s {
        return bad(format!("loops at arcs {:.0} and {:.0} mm only {gap:.1} mm apart", axis.arc[i], axis.arc[j]));
    }
    let ext = frame.geom.extent_mm() - frame.geom.spacing_vec();
    for (p, r) in axis.points.iter().zip(&axis.radius) {
        let reach = r + wall;
        if (0..3).any(|a| p[a] - reach < 3.0 * s || p[a] + reach > ext[a] - 3.0 * s) {
            return bad(format!("colon at {p:?} touches the volume border"));
        }
        if body.skin_sdf(*p) + reach + 5.0 * s > -body.rim {
            return bad(format!("colon at {p:?} reaches the abdominal wall"));
        }
        if body.spine.sdf_xy(*p) < reach + 5.0 * s {
            return bad(format!("colon at {p:?} touches the spine"));
        }
        if let Some(l) = body.lungs.iter().find(|l| l.sdf(*p) < reach + 10.0 * s) {
            return bad(format!("colon at {p:?} within 10 mm of the lung at {:?}", l.center));
        }
    }
    Ok(())
}

/// 30 mm of the descending colon, 60 % of the way up, collapses to a tissue cord.
fn make_collapse(frame: &Frame, segments: &[SegmentTruth]) -> (Collapse, CollapsedTruth) {
    let s = frame.scale;
    let (a, b) = segment(segments, "descending").map_or((0.0, 0.0), |g| (g.start_arc_mm, g.end_arc_mm));
    let mid = a + 0.6 * (b - a);
    let half = 15.0 * s;
    let taper = 8.0 * s;
    let c = Collapse { start: mid - half, end: mid + half, taper, cord_radius: 2.0 * frame.thin(WALL, 1.0) };
    let t = CollapsedTruth { segment: "descending".into(), start_arc_mm: c.start, end_arc_mm: c.end, taper_mm: taper };
    (c, t)
}

/// Haustral folds every 20–30 mm from the sigmoid to the cecal pole (none in the rectum,
/// nor in a collapsed stretch): three crescents between the taeniae, 3–8 mm deep.
fn make_folds(frame: &Frame, tube: &Tube, segments: &[SegmentTruth], seed: u64) -> Vec<Fold> {
    let s = frame.scale;
    let mut rng = Rng::new(seed, STREAM_FOLDS);
    let hw = frame.thin(FOLD_HALF_WIDTH, 0.9);
    let start = segments.iter().find(|g| g.name == "sigmoid").map_or(0.0, |g| g.start_arc_mm) + 10.0 * s;
    let end = tube.axis.length - 12.0 * s;
    let phase0 = rng.range(0.0, std::f64::consts::TAU);
    let mut folds = Vec::new();
    let mut arc = start;
    while arc < end {
        let collapsed = tube.collapse.as_ref().is_some_and(|c| arc > c.start - c.taper - 3.0 * hw && arc < c.end + c.taper + 3.0 * hw);
        let r = tube.axis.radius_at(arc);
        let mut sector = || FoldSector {
            offset: rng.range(-1.5, 1.5) * s,
            depth: (rng.range(FOLD_DEPTH.0, FOLD_DEPTH.1) * s).min(FOLD_MAX_FRACTION * r),
        };
        let sectors = [sector(), sector(), sector()];
        if !collapsed {
            // The taeniae twist slowly around the colon.
            folds.push(Fold { arc, phase: phase0 + 0.002 * arc / s, half_width: hw, sectors });
        }
        arc += rng.range(FOLD_SPACING.0, FOLD_SPACING.1) * s;
    }
    folds
}

fn fold_truth(tube: &Tube, segments: &[SegmentTruth]) -> Vec<FoldTruth> {
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

/// Places the polyps of [`POLYPS`]: between two folds (or anywhere in the fold-free
/// rectum), or just behind a fold (on its cecal side) in the middle of one of its crescents,
/// which is deepened if needed so that it hides the polyp from the rectal side.
///
/// A polyp never reaches in further than [`MAX_PROTRUSION`] of the local radius (the
/// diameter is reduced if needed), so the lumen stays open around the centerline. In the
/// small phantom a diameter d becomes d/2 + 2.5 mm (3–12 mm → 4–8.5 mm: at least about three
/// voxels, so the centre voxel is solid tissue) and every polyp is sessile.
fn make_polyps(frame: &Frame, tube: &mut Tube, segments: &[SegmentTruth], seed: u64) -> Result<(Vec<Blob>, Vec<PolypTruth>)> {
    let s = frame.scale;
    let small = s < 1.0;
    let mut rng = Rng::new(seed, STREAM_POLYPS);
    let mut specs: Vec<PolypSpec> = Vec::new();
    for &(seg_name, diameter, behind, stalk) in POLYPS {
        let seg = segment(segments, seg_name)?;
        let stalk = if small { None } else { stalk };
        let wanted = if small { 0.5 * diameter + 2.5 } else { diameter };
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
            let clear_collapse = tube.collapse.as_ref().is_none_or(|c| at + d < c.start - c.taper || at - d > c.end + c.taper);
            let clear_polyps = specs.iter().all(|o| (o.arc - at).abs() > 20.0 * s);
            if clear_collapse && clear_polyps && at > seg.start_arc_mm && at < seg.end_arc_mm {
                spec = Some(PolypSpec { arc: at, angle, diameter: d, stalk, segment: seg_name.into(), behind_fold: behind });
                break;
            }
            arc = seg.start_arc_mm + rng.range(0.1, 0.9) * (seg.end_arc_mm - seg.start_arc_mm);
        }
        let spec = spec.ok_or_else(|| Error::invalid(format!("colon phantom: no room for a polyp in the {seg_name}")))?;
        if behind {
            deepen_fold_before(tube, &spec, k, frame);
        }
        specs.push(spec);
    }
    // Re-index folds after any deepening (the reach of a fold does not change).
    let folds = std::mem::take(&mut tube.folds);
    tube.set_folds(folds);
    Ok(specs.iter().map(|sp| place(tube, sp)).unzip())
}

/// A polyp reaches in at most this fraction of the local lumen radius.
pub const MAX_PROTRUSION: f64 = 0.55;

/// How far a polyp of diameter `d` reaches in from the wall.
fn protrusion(d: f64, stalk: Option<f64>) -> f64 {
    match stalk {
        None => (1.0 + super::polyp::SESSILE_INSET) * d / 2.0,
        Some(len) => len + d,
    }
}

/// `wanted`, or less so that the polyp leaves the middle of the lumen free.
fn fit_diameter(wanted: f64, stalk: Option<f64>, radius: f64) -> f64 {
    let limit = MAX_PROTRUSION * radius;
    if protrusion(wanted, stalk) <= limit {
        return wanted;
    }
    match stalk {
        None => limit * 2.0 / (1.0 + super::polyp::SESSILE_INSET),
        Some(len) => (limit - len).max(0.0),
    }
}

/// Makes crescent `k` of the fold just before a behind-fold polyp deep enough to hide it.
fn deepen_fold_before(tube: &mut Tube, spec: &PolypSpec, k: usize, frame: &Frame) {
    let Ok(fi) = nearest_fold(tube, spec.arc) else { return };
    let r = tube.axis.radius_at(tube.folds[fi].arc);
    let need = (protrusion(spec.diameter, spec.stalk) + 1.0 * frame.scale).min(FOLD_MAX_FRACTION * r).min(FOLD_DEPTH.1 * frame.scale);
    let sector = &mut tube.folds[fi].sectors[k];
    sector.depth = sector.depth.max(need);
}

/// The fold nearest to `arc`.
fn nearest_fold(tube: &Tube, arc: f64) -> Result<usize> {
    (0..tube.folds.len())
        .min_by(|&a, &b| (tube.folds[a].arc - arc).abs().total_cmp(&(tube.folds[b].arc - arc).abs()))
        .ok_or_else(|| Error::invalid("colon phantom: no fold to hide a polyp behind"))
}

/// Arcs of the folds just before and after `arc`, if it lies between two folds.
fn folds_around(tube: &Tube, arc: f64) -> Option<(f64, f64)> {
    let after = tube.folds.iter().position(|f| f.arc > arc)?;
    if after == 0 {
        return None;
    }
    Some((tube.folds[after - 1].arc, tube.folds[after].arc))
}

/// Pools of tagged fluid in the dependent parts of some segments. Each pool sits at the
/// most posterior point of its segment; its level lies 30–50 % of the radius above the
/// lumen's floor there, and it extends along the colon as long as the lumen's floor
/// (axis y + radius) is below the level — where the colon rises above the level, the pool
/// ends by itself, so the level is flat and the fluid physically plausible.
fn make_pools(tube: &Tube, segments: &[SegmentTruth], seed: u64) -> Vec<(Pool, PoolTruth)> {
    let mut rng = Rng::new(seed, STREAM_POOLS);
    let ax = &tube.axis;
    let floor = |i: usize| ax.points[i].y + ax.radius[i];
    let mut pools: Vec<(Pool, PoolTruth)> = Vec::new();
    for &name in POOL_SEGMENTS {
        let Ok(seg) = segment(segments, name) else { continue };
        let (a, b) = (ax.vertex_at(seg.start_arc_mm), ax.vertex_at(seg.end_arc_mm));
        let open = |i: &usize| tube.collapse.as_ref().is_none_or(|c| ax.arc[*i] < c.start - c.taper || ax.arc[*i] > c.end + c.taper);
        let Some(anchor) = (a..=b).filter(open).max_by(|&i, &j| floor(i).total_cmp(&floor(j))) else { continue };
        let depth = rng.range(0.3, 0.5) * ax.radius[anchor];
        let level = floor(anchor) - depth;
        let hu = rng.range(400.0, 700.0);
        let mut lo = anchor;
        while lo > 0 && floor(lo - 1) > level {
            lo -= 1;
        }
        let mut hi = anchor;
        while hi + 1 < ax.len() && floor(hi + 1) > level {
            hi += 1;
        }
        let (mut start, mut end) = (ax.arc[lo] - ax.radius[lo], ax.arc[hi] + ax.radius[hi]);
        if let Some(c) = &tube.collapse
            && start < c.end + c.taper
            && end > c.start - c.taper
        {
            // Fluid does not cross the collapsed cord: keep the anchor's side.
            if ax.arc[anchor] < c.start {
                end = end.min(c.start - c.taper);
            } else {
                start = start.max(c.end + c.taper);
            }
        }
        if pools.iter().any(|(p, _)| start < p.end && end > p.start) {
            continue;
        }
        let pool = Pool { start, end, level_y: level, hu };
        let truth = PoolTruth { segment: name.into(), start_arc_mm: start, end_arc_mm: end, level_y_mm: level, hu };
        pools.push((pool, truth));
    }
    pools
}

/// A few small-bowel gas pockets (10–20 mm) in the central abdomen, each at least 10 mm
/// (full size) from the colon's lumen, the spine, the lungs, the abdominal wall and each
/// other. Rejection sampling with a fixed number of tries: deterministic.
fn make_pockets(frame: &Frame, tube: &Tube, body: &Body, seed: u64) -> Vec<Blob> {
    let s = frame.scale;
    let mut rng = Rng::new(seed, STREAM_GAS);
    let wall = frame.thin(1.5, 0.8);
    let clear = 10.0 * s;
    let mut pockets: Vec<Blob> = Vec::new();
    let ax = &tube.axis;
    for _ in 0..400 {
        if pockets.len() == 4 {
            break;
        }
        let r = rng.range(5.0, 10.0) * s;
        let c = frame.pos([rng.range(110.0, 274.0), rng.range(100.0, 260.0), rng.range(60.0, 330.0)]);
        let colon_ok = ax
            .points
            .iter()
            .zip(&ax.radius)
            .step_by(2)
            .all(|(p, rc)| p.distance(c) - rc - r - wall - tube.wall_mm >= clear);
        let body_ok = body.skin_sdf(c) + r + wall + clear <= -body.rim
            && body.spine.sdf_xy(c) >= r + wall + clear
            && body.lungs.iter().all(|l| l.sdf(c) >= r + wall + clear);
        let apart = pockets.iter().all(|o| o.center.distance(c) - o.radius - r - 2.0 * wall >= clear);
        if colon_ok && body_ok && apart {
            pockets.push(Blob { kind: BlobKind::Pocket, center: c, radius: r, stalk: None, wall_mm: wall });
        }
    }
    pockets
}

/// A 12-voxel box of pure fat (far from colon, pockets, spine, lungs and the rim) for
/// measuring the noise, found by a fixed scan.
fn fat_roi(frame: &Frame, tube: &Tube, blobs: &[Blob], body: &Body) -> Option<RoiTruth> {
    let g = &frame.geom;
    let half_vox = 6usize;
    let half = DVec3::from_array(g.spacing) * half_vox as f64;
    let margin = half.length() + 3.0 * frame.max_spacing();
    let ax = &tube.axis;
    let step = 16usize;
    for k in (half_vox..g.dims[2] - half_vox).step_by(step) {
        for j in (half_vox..g.dims[1] - half_vox).step_by(step) {
            for i in (half_vox..g.dims[0] - half_vox).step_by(step) {
                let c = g.index_to_local(DVec3::new(i as f64, j as f64, k as f64));
                let ok = body.skin_sdf(c) + margin <= -body.rim
                    && body.spine.sdf_xy(c) >= margin
                    && body.lungs.iter().all(|l| l.sdf(c) >= margin)
                    && ax.points.iter().zip(&ax.radius).all(|(p, r)| p.distance(c) - r - tube.wall_mm >= margin)
                    && blobs.iter().all(|b| b.center.distance(c) - b.reach() >= margin);
                if ok {
                    return Some(RoiTruth {
                        min_ijk: [i - half_vox, j - half_vox, k - half_vox],
                        max_ijk: [i + half_vox, j + half_vox, k + half_vox],
                        expected_hu: body::FAT,
                    });
                }
            }
        }
    }
    None
}

/// Development aid (for tuning [`KNOTS`]): the axis's length, per-segment lengths, the
/// tightest bend, the closest loops and what [`check_anatomy`] says.
#[doc(hidden)]
pub fn anatomy_report(small: bool) -> Result<String> {
    let frame = Frame::new(small)?;
    let axis = make_axis(&frame)?;
    let wall = frame.thin(WALL, 1.0);
    let (bend, at) = axis.min_bend_ratio(wall);
    let (gap, i, j) = axis.min_part_gap(wall, 2);
    let mut out = format!(
        "length {:.0} mm; tightest bend {bend:.2} × (radius + wall) at arc {:.0}; loops closest ({gap:.1} mm) at arcs {:.0} and {:.0}\n",
        axis.length, axis.arc[at], axis.arc[i], axis.arc[j]
    );
    for g in segments(&axis) {
        out += &format!("  {:<16} {:6.0} .. {:6.0} mm ({:.0} mm)\n", g.name, g.start_arc_mm, g.end_arc_mm, g.end_arc_mm - g.start_arc_mm);
    }
    let verdict = check_anatomy(&frame, &axis, &make_body(&frame, true)).map_or_else(|e| e.to_string(), |_| "checks pass".into());
    Ok(out + &verdict + "\n")
}
