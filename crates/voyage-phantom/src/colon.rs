//! A synthetic colon at a real scan's size, with haustral folds, polyps of known size and
//! the things that make real CT colonography hard (tagged fluid, collapsed and fluid-filled
//! stretches, small-bowel gas and opacified small bowel, lung bases, a prone patient, a
//! rectal catheter, quantised grey levels; see [`ColonOptions`]).
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
//!
//! Options (all combine):
//! - prone: gravity −y; tagged fluid pools in the sigmoid's and transverse colon's anterior
//!   loops and at the caecal pole instead of posteriorly in the rectum, descending and
//!   ascending colon. Each pool is anchored at its segment's most dependent point, so its
//!   level is flat and gas remains above it.
//! - collapsed: 30 mm of the sigmoid (55 % along), descending (60 %) and/or transverse (50 %)
//!   down to a tissue cord.
//! - fluid-filled: 40–60 mm of a segment filled to the brim (+400..+700 HU), 20–35 % along
//!   it (65–80 % if that meets a collapse).
//! - opacified small bowel: see [`super::small_bowel`]; it brings its own caecal pool.
//! - rectal tube: a catheter from 35 mm up the rectum out through a perineum, which the body
//!   gets only then (4 mm above the first slice, full size): the rectum's end stays ≥ 5 mm
//!   from its skin, its muscle wraps the rectum's end as the pelvic floor does.
//! - table: a CT table (carbon-fibre shell, foam core) under the patient on the dependent
//!   side, the skin pressed flat on it over a contact strip (see [`super::skin`]).
//! - skin folds: 4–8 thin crevices of outside air cut into the skin, on the dependent side
//!   and low in the scan (perineal beside the catheter, or gluteal), some closed over by skin
//!   in part of their length (see [`super::skin`]).
//! - quantise: the CT rounded to multiples of a step after the noise.

use glam::{DVec2, DVec3};

use super::{
    Phantom, arr,
    axis::{Axis, Knot},
    body::{self, Body, Lung, Spine},
    frame::Frame,
    label, label_counts,
    polyp::{PolypSpec, place},
    posture::{dependent_angle, pair_collapsed, supine_knot},
    raster::{Materials, Scene},
    rng::{Rng, stream_key},
    skin::{self, Obstacles},
    small_bowel::{self, Valve},
    truth::{
        COORDINATES_NOTE, CollapsedTruth, DistractorTruth, FilledTruth, FoldTruth, GapTruth,
        PolypTruth, PoolTruth, RectalTubeTruth, RoiTruth, SegmentTruth, StoolTruth, Truth,
    },
    tube::{
        Blob, BlobKind, Catheter, Collapse, Ends, Filled, Fold, FoldSector, Pool, Tube,
        segment_distance,
    },
};
use voyage_core::{Error, Result};

pub use super::frame::{FULL_DIMS, FULL_SPACING, SMALL_DIMS, SMALL_SCALE, SMALL_SPACING};

/// What colon to make.
#[derive(Clone, Debug)]
pub struct ColonOptions {
    pub seed: u64,
    /// ≈128³ at 1.5–1.6 mm with the anatomy scaled by ½, for fast tests.
    pub small: bool,
    /// Pools of tagged fluid (+400..+700 HU) with flat air–fluid levels in the dependent
    /// parts of the colon: the rectum, descending and ascending colon supine (posterior);
    /// the sigmoid, transverse colon and caecum prone (anterior).
    pub tagged_fluid: bool,
    /// The patient lies face down (DICOM "HFP"): gravity points anterior (−y), so tagged
    /// fluid pools anteriorly. The volume's geometry does not change.
    pub prone: bool,
    /// Segments (sigmoid, descending, transverse; each at most once) in which a 30 mm
    /// stretch (full size) is collapsed to a tissue cord: N collapses leave the gas in N + 1
    /// pieces.
    pub collapsed: Vec<String>,
    /// Segments (rectum, sigmoid, descending, transverse, ascending, caecum; each at most
    /// once) with a 40–60 mm stretch (full size) filled to the brim with tagged fluid: lumen,
    /// but no gas, so the gas is split there while the lumen goes on.
    pub fluid_filled: Vec<String>,
    /// Segments (sigmoid, descending, transverse; each at most once) with a neck 30 % of
    /// the way along: over 10 mm (full size) the gas narrows to a thread [`NECK_RADIUS_MM`]
    /// in radius, joined but narrower than the camera's distance from the wall allows (a
    /// real sigmoid's spasm).
    pub narrowed: Vec<String>,
    /// Loops of small bowel filled with oral contrast (+300..+600 HU, no gas) in the right
    /// and central lower abdomen and pelvis, some touching the colon near the descending
    /// colon, the terminal ileum opening into the caecum under the level of a caecal pool
    /// (made even without `tagged_fluid`): one bright region with the caecal fluid.
    pub opacified_small_bowel: bool,
    /// A rectal catheter from the lower rectum out of the body through a perineum (the body
    /// then ends 4 mm above the first slice): colon gas joins the air outside in 3D.
    pub rectal_tube: bool,
    /// Lumps of tagged stool (+500..+900 HU, 4–9 mm at full size) on the wall, two in each
    /// of the rectum, sigmoid, descending, transverse and ascending colon, one of each two
    /// mottled with air: colon content, labelled 11, in the truth's `stool`.
    pub tagged_stool: bool,
    /// A CT table under the patient on the dependent side (posterior supine, anterior prone):
    /// a 2.5 mm shell (+350 HU) round a foam core (−935 HU), 45 mm thick at full size, in
    /// every slice, running out of the field of view on both sides as on a real exam; the
    /// skin lies flat on it over a contact strip, with a wedge of outside air beside it. Not
    /// the patient: label 0, the air round it 1.
    pub table: bool,
    /// 4–8 skin folds: crevices of outside air (label 1) 1–2 mm wide, 15–40 mm deep and
    /// 30–80 mm long at full size, 3–6 on the dependent side beside the table's contact and
    /// 1–2 low in the scan (rising from the perineum beside the rectal catheter's exit, or
    /// without one in the gluteal cleft off the scan's inferior edge); most closed over by skin
    /// in part of their length, where axial slices hold their air enclosed in the body.
    pub skin_folds: bool,
    /// A few separate small-bowel gas pockets (not colon).
    pub small_bowel_gas: bool,
    /// The bases of both lungs in the top slices (not colon).
    pub lung_bases: bool,
    /// Standard deviation of the CT noise (HU).
    pub noise_hu: f64,
    /// Round the CT (after the noise) to multiples of this many HU, as a windowed 8-bit
    /// export leaves it.
    pub quantize_hu: Option<f64>,
    /// One position of a supine–prone pair (`colon_pair`): supine, the transverse
    /// colon and the sigmoid's anterior loop sag posteriorly by centimetres while folds and
    /// polyps keep their places on the wall (the same place along the colon, the same side of
    /// it in the patient's frame); in either position tagged stool lies on the dependent side.
    pub pair_member: bool,
}

impl Default for ColonOptions {
    fn default() -> Self {
        ColonOptions {
            seed: 1,
            small: false,
            tagged_fluid: false,
            prone: false,
            collapsed: Vec::new(),
            fluid_filled: Vec::new(),
            narrowed: Vec::new(),
            opacified_small_bowel: false,
            rectal_tube: false,
            tagged_stool: false,
            table: false,
            skin_folds: false,
            small_bowel_gas: true,
            lung_bases: true,
            noise_hu: 20.0,
            quantize_hu: None,
            pair_member: false,
        }
    }
}

/// Segments that `ColonOptions::collapsed` may name.
pub const COLLAPSIBLE: &[&str] = &["sigmoid", "descending", "transverse"];
/// Segments that `ColonOptions::fluid_filled` may name.
pub const FILLABLE: &[&str] = &[
    "rectum",
    "sigmoid",
    "descending",
    "transverse",
    "ascending",
    "cecum",
];

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
// Streams of the newer options: drawn only when the option is on, so the older phantoms
// stay bit for bit what they were.
const STREAM_FILLED: u64 = 0xC010_0006;
const STREAM_VALVE_POOL: u64 = 0xC010_0008;
const STREAM_STOOL: u64 = 0xC010_0009;
// 0xC010_0007 and 0xC010_000A: the small bowel's and the skin folds' (frame.rs).

/// Full-size height (z, mm) of the perineum's skin when the body has one (rectal tube): the
/// rectum's wall ends ≈ 10.5 mm above the first slice, so this keeps ≥ 5 mm of tissue.
const FLOOR_Z: f64 = 4.0;
/// Where (full-size arc, mm) and how far off the axis (fraction of the radius) the rectal
/// catheter's tip lies, and its plastic's HU.
const CATHETER_TIP_ARC: f64 = 35.0;
const CATHETER_OFFSET: f64 = 0.6;
const CATHETER_HU: f64 = 100.0;

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

/// Segments where tagged fluid pools: the posterior, dependent ones for a supine patient,
/// and for a prone one the anterior ones (the sigmoid's and transverse colon's anterior
/// loops and the caecal pole), each of which is a local low point under gravity, so its pool
/// has a flat level and leaves gas above it.
const POOL_SEGMENTS: &[&str] = &["rectum", "descending", "ascending"];
const PRONE_POOL_SEGMENTS: &[&str] = &["sigmoid", "transverse", "cecum"];

/// Makes the colon phantom.
pub fn colon(opts: &ColonOptions) -> Result<Phantom> {
    check_options(opts)?;
    let frame = Frame::new(opts.small)?;
    let floor = opts.rectal_tube.then(|| frame.pos([0.0, 0.0, FLOOR_Z]).z);
    let gravity = if opts.prone { DVec3::NEG_Y } else { DVec3::Y };
    let mut body = make_body(&frame, opts.lung_bases, floor);
    if opts.table {
        body.table = Some(skin::make_table(&frame, &body, gravity));
    }
    let axis = make_axis(&frame, false)?;
    let mut segments = segments(&axis);
    check_anatomy(&frame, &axis, &body)?;
    let mut tube = Tube::new(axis, frame.thin(WALL, 1.0), Ends::Round);
    let necks = make_necks(&frame, &segments, &opts.narrowed)?;
    let (collapsed, placing) = if opts.pair_member {
        // Folds and polyps keep clear of both positions' collapses, so they are the same in
        // both.
        (
            pair_collapsed(&opts.collapsed, Some(opts.prone)),
            pair_collapsed(&opts.collapsed, None),
        )
    } else {
        (opts.collapsed.clone(), opts.collapsed.clone())
    };
    let collapses = make_collapses(&frame, &segments, &collapsed)?;
    tube.collapse = make_collapses(&frame, &segments, &placing)?
        .into_iter()
        .map(|(c, _)| c)
        .chain(necks.iter().cloned())
        .collect();
    let folds = make_folds(&frame, &tube, &segments, opts.seed);
    tube.set_folds(folds);
    let mut polyp_specs = make_polyps(&frame, &mut tube, &segments, opts.seed)?;
    tube.collapse = collapses.iter().map(|(c, _)| c.clone()).collect();
    tube.collapse.extend(necks);
    let mut filled = make_filled(&frame, &tube, &segments, &opts.fluid_filled, opts.seed)?;
    tube.filled = filled.iter().map(|(f, _)| f.clone()).collect();
    let mut collapses = collapses;
    if opts.pair_member && !opts.prone {
        // Everything along the colon was placed on the prone shape; it keeps its place on
        // the wall as the loops sag.
        let mut moved = make_axis(&frame, true)?;
        moved.reframe_like(&tube.axis);
        check_anatomy(&frame, &moved, &body)?;
        let at = |s: f64| tube.axis.arc_on(&moved, s);
        polyp_specs.iter_mut().for_each(|p| p.arc = at(p.arc));
        for (_, t) in &mut collapses {
            (t.start_arc_mm, t.end_arc_mm) = (at(t.start_arc_mm), at(t.end_arc_mm));
        }
        for (_, t) in &mut filled {
            (t.start_arc_mm, t.end_arc_mm) = (at(t.start_arc_mm), at(t.end_arc_mm));
        }
        tube = tube.moved_to(moved);
        segments = self::segments(&tube.axis);
    }
    let (mut blobs, polyps): (Vec<Blob>, Vec<PolypTruth>) =
        polyp_specs.iter().map(|sp| place(&tube, sp)).unzip();
    let catheter = if opts.rectal_tube {
        Some(make_catheter(&frame, &tube, &blobs, floor.unwrap_or(0.0))?)
    } else {
        None
    };
    let bowel = if opts.opacified_small_bowel {
        Some(small_bowel::make(
            &frame,
            &tube,
            &body,
            &segments,
            gravity,
            &blobs,
            catheter.as_ref(),
            opts.seed,
        )?)
    } else {
        None
    };
    let pools = make_pools(
        &tube,
        &segments,
        opts,
        gravity,
        bowel.as_ref().map(|b| &b.valve),
    );
    let stool = if opts.tagged_stool {
        let dependent = opts.pair_member.then_some(gravity);
        make_stool(&frame, &tube, &segments, &polyps, dependent, opts.seed)?
    } else {
        Vec::new()
    };
    blobs.extend(stool.iter().map(|(b, _)| b.clone()));
    tube.pools = pools.iter().map(|(p, _)| p.clone()).collect();
    // Pockets keep clear of the loops and the catheter as they do of the colon; without
    // either the list is empty and they land where they always did.
    let mut obstacles: Vec<(DVec3, DVec3, f64)> = Vec::new();
    if let Some(b) = &bowel {
        obstacles.extend(
            b.blobs
                .iter()
                .filter_map(|l| l.stalk.map(|(p, q, r)| (p, q, r + l.wall_mm))),
        );
    }
    if let Some(c) = &catheter {
        obstacles.extend(c.points.windows(2).map(|w| (w[0], w[1], c.outer_radius())));
    }
    let mut distractors = Vec::new();
    if opts.small_bowel_gas {
        let pockets = make_pockets(&frame, &tube, &body, &obstacles, opts.seed);
        distractors.extend(pockets.iter().map(|b| DistractorTruth {
            kind: "small_bowel_gas".into(),
            center_mm: arr(b.center),
            semi_axes_mm: [b.radius; 3],
            hu: body::AIR,
        }));
        blobs.extend(pockets);
    }
    if let Some(b) = &bowel {
        distractors.extend(b.loops.iter().map(|l| {
            let (lo, hi) = l.axis_mm.iter().fold(
                ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
                |(lo, hi), p| {
                    (
                        [0, 1, 2].map(|a| lo[a].min(p[a])),
                        [0, 1, 2].map(|a| hi[a].max(p[a])),
                    )
                },
            );
            DistractorTruth {
                kind: "opacified_small_bowel".into(),
                center_mm: [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a])),
                semi_axes_mm: [0, 1, 2].map(|a| 0.5 * (hi[a] - lo[a]) + l.radius_mm + l.wall_mm),
                hu: l.hu,
            }
        }));
        blobs.extend(b.blobs.iter().cloned());
    }
    let skin_folds = if opts.skin_folds {
        let near = Obstacles {
            tube: &tube,
            blobs: &blobs,
            catheter: catheter.as_ref(),
        };
        skin::make_folds(&frame, &body, gravity, &near, opts.seed)
    } else {
        Vec::new()
    };
    body.folds = skin_folds.iter().map(|(f, _)| f.clone()).collect();
    distractors.extend(body.lungs.iter().map(|l| DistractorTruth {
        kind: "lung".into(),
        center_mm: [
            l.center.x,
            l.center.y,
            0.5 * (l.recess + frame.geom.extent_mm().z),
        ],
        semi_axes_mm: [
            l.semi.x,
            l.semi.y,
            0.5 * (frame.geom.extent_mm().z - l.recess),
        ],
        hu: body::LUNG,
    }));
    let noise_roi = fat_roi(&frame, &tube, &blobs, &body, catheter.as_ref());
    let scene = Scene {
        geom: frame.geom.clone(),
        tube: &tube,
        blobs: &blobs,
        catheter: catheter.as_ref(),
        materials: Materials {
            lumen_air: body::AIR,
            wall: body::SOFT_TISSUE,
            polyp: body::SOFT_TISSUE,
            pocket_air: body::AIR,
        },
        background: &body,
        noise_sigma: opts.noise_hu,
        noise_key: stream_key(opts.seed, STREAM_NOISE),
        quantize: opts.quantize_hu,
    };
    let r = scene.render()?;
    let counts = label_counts(&r.labels);
    let ax = &tube.axis;
    let inset = END_INSET * frame.scale;
    let (source_arc, target_arc) = (inset, ax.length - inset);
    let collapsed: Vec<CollapsedTruth> = collapses.into_iter().map(|(_, t)| t).collect();
    let fluid_filled: Vec<FilledTruth> = filled.into_iter().map(|(_, t)| t).collect();
    let mut gas_gaps: Vec<GapTruth> = collapsed
        .iter()
        .map(|c| GapTruth {
            kind: "collapsed".into(),
            segment: c.segment.clone(),
            start_arc_mm: c.start_arc_mm,
            end_arc_mm: c.end_arc_mm,
        })
        .chain(fluid_filled.iter().map(|f| GapTruth {
            kind: "fluid_filled".into(),
            segment: f.segment.clone(),
            start_arc_mm: f.start_arc_mm,
            end_arc_mm: f.end_arc_mm,
        }))
        .collect();
    gas_gaps.sort_by(|a, b| a.start_arc_mm.total_cmp(&b.start_arc_mm));
    let truth = Truth {
        kind: "colon".into(),
        seed: opts.seed,
        coordinates: COORDINATES_NOTE.into(),
        position: if opts.prone { "HFP" } else { "HFS" }.into(),
        gravity_lps: arr(gravity),
        dims: frame.geom.dims,
        spacing_mm: frame.geom.spacing,
        origin_lps_mm: frame.geom.origin,
        direction: frame.geom.direction,
        scale: frame.scale,
        noise_hu: opts.noise_hu,
        quantize_hu: opts.quantize_hu,
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
        lumen_voxels: counts[label::LUMEN_AIR as usize]
            + counts[label::LUMEN_FLUID as usize]
            + counts[label::STOOL as usize],
        folds: tube.folds.len(),
        fold_list: fold_truth(&tube, &segments),
        segments: segments.clone(),
        fluid_pools: pools.into_iter().map(|(_, t)| t).collect(),
        fluid_voxels: counts[label::LUMEN_FLUID as usize],
        collapsed,
        fluid_filled,
        gas_gaps,
        distractors,
        small_bowel_loops: bowel.as_ref().map_or_else(Vec::new, |b| b.loops.clone()),
        ileocecal_valve_mm: bowel.as_ref().map(|b| arr(b.valve.point)),
        stool: stool.into_iter().map(|(_, t)| t).collect(),
        rectal_tube: catheter.as_ref().map(|c| RectalTubeTruth {
            tip_mm: arr(c.points[0]),
            exit_mm: arr(c.points[c.points.len() - 1]),
            inner_radius_mm: c.inner_radius,
            outer_radius_mm: c.outer_radius(),
            wall_hu: c.hu,
        }),
        body_floor_z_mm: floor,
        table: body.table.as_ref().map(|t| skin::table_truth(t, &body)),
        skin_folds: skin_folds.into_iter().map(|(_, t)| t).collect(),
        noise_roi,
        materials_hu: materials(opts),
        labels: label::legend(),
    };
    Ok(Phantom {
        ct: r.ct,
        lumen: r.lumen,
        labels: r.labels,
        truth,
    })
}

/// Refuses options that cannot make a phantom, with a message that says why.
fn check_options(opts: &ColonOptions) -> Result<()> {
    if !(opts.noise_hu >= 0.0 && opts.noise_hu.is_finite()) {
        return Err(Error::invalid(format!(
            "noise {} HU is not a non-negative number",
            opts.noise_hu
        )));
    }
    if let Some(q) = opts.quantize_hu
        && !(q > 0.0 && q.is_finite())
    {
        return Err(Error::invalid(format!(
            "quantisation step {q} HU is not a positive number"
        )));
    }
    let names = |what: &str, list: &[String], allowed: &[&str]| -> Result<()> {
        for (i, n) in list.iter().enumerate() {
            if !allowed.contains(&n.as_str()) {
                return Err(Error::invalid(format!(
                    "{what} segment '{n}': choose from {}",
                    allowed.join(", ")
                )));
            }
            if list[..i].contains(n) {
                return Err(Error::invalid(format!("{what} segment '{n}' named twice")));
            }
        }
        Ok(())
    };
    names("collapsed", &opts.collapsed, COLLAPSIBLE)?;
    names("narrowed", &opts.narrowed, COLLAPSIBLE)?;
    names("fluid-filled", &opts.fluid_filled, FILLABLE)
}

fn materials(opts: &ColonOptions) -> Vec<(String, f64)> {
    let mut m: Vec<(String, f64)> = [
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
    .collect();
    if opts.rectal_tube {
        m.push(("catheter_plastic".into(), CATHETER_HU));
    }
    if opts.table {
        m.push(("table_shell".into(), body::TABLE_SHELL));
        m.push(("table_foam".into(), body::TABLE_FOAM));
    }
    m
}

/// The abdomen: a 340×260 mm ellipse (full size) with a 10 mm rim, the spine posteriorly
/// and, optionally, the lung bases in the top 24 slices and a perineum at height `floor`.
fn make_body(frame: &Frame, lungs: bool, floor: Option<f64>) -> Body {
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
fn make_axis(frame: &Frame, supine_pair: bool) -> Result<Axis> {
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
fn segments(axis: &Axis) -> Vec<SegmentTruth> {
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

fn segment<'a>(segments: &'a [SegmentTruth], name: &str) -> Result<&'a SegmentTruth> {
    segments
        .iter()
        .find(|s| s.name == name)
        .ok_or_else(|| Error::invalid(format!("colon has no segment {name}")))
}

fn segment_name(segments: &[SegmentTruth], s: f64) -> String {
    segments
        .iter()
        .find(|g| s >= g.start_arc_mm && s <= g.end_arc_mm)
        .map_or_else(String::new, |g| g.name.clone())
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

/// 30 mm (full size) of each named segment collapses to a tissue cord: the descending colon
/// 60 % of the way up (where it always did), the sigmoid at 55 % of its length (the top of
/// its anterior loop), the transverse colon at half its length. Sorted along the colon.
fn make_collapses(
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
fn make_necks(frame: &Frame, segments: &[SegmentTruth], names: &[String]) -> Result<Vec<Collapse>> {
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
fn near_collapse(tube: &Tube, s: f64, margin: f64) -> bool {
    tube.collapse
        .iter()
        .any(|c| s > c.start - c.taper - margin && s < c.end + c.taper + margin)
}

/// A 40–60 mm stretch (full size) of each named segment filled to the brim with tagged
/// fluid (+400..+700 HU), centred 20–35 % of the way along the segment (or 65–80 % if that
/// would meet a collapse), clear of the colon's ends. Sorted along the colon.
fn make_filled(
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

/// Haustral folds every 20–30 mm from the sigmoid to the cecal pole (none in the rectum,
/// nor in a collapsed stretch): three crescents between the taeniae, 3–8 mm deep.
fn make_folds(frame: &Frame, tube: &Tube, segments: &[SegmentTruth], seed: u64) -> Vec<Fold> {
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
fn make_polyps(
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
            let clear_collapse = tube
                .collapse
                .iter()
                .all(|c| at + d < c.start - c.taper || at - d > c.end + c.taper);
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

/// Segments that get tagged stool, two lumps each; the lumps' diameters (full size) and HU.
const STOOL_SEGMENTS: &[&str] = &["rectum", "sigmoid", "descending", "transverse", "ascending"];
const STOOL_DIAMETER: (f64, f64) = (4.0, 9.0);
const STOOL_HU: (f64, f64) = (500.0, 900.0);

/// Lumps of tagged stool on the wall, sessile like polyps, between folds, clear of the polyps
/// (15 mm along the colon), of each other, of collapsed and fluid-filled stretches; the
/// second of each segment's two is mottled with air.
fn make_stool(
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
                    && tube
                        .collapse
                        .iter()
                        .all(|c| at + d < c.start - c.taper || at - d > c.end + c.taper)
                    && tube
                        .filled
                        .iter()
                        .all(|f| at + d < f.start || at - d > f.end);
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

/// The fold nearest to `arc`.
fn nearest_fold(tube: &Tube, arc: f64) -> Result<usize> {
    (0..tube.folds.len())
        .min_by(|&a, &b| {
            (tube.folds[a].arc - arc)
                .abs()
                .total_cmp(&(tube.folds[b].arc - arc).abs())
        })
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
/// most dependent point of its segment (largest `p · gravity + radius`: posterior supine,
/// anterior prone); its level lies 30–50 % of the radius above the lumen's floor there,
/// and it extends along the colon as long as the lumen's floor is below the level — where
/// the colon rises above the level, the pool ends by itself, so the level is flat and the
/// fluid physically plausible.
///
/// With opacified small bowel a pool also fills the caecum's dependent side around the
/// ileocaecal valve, deep enough to cover the valve's opening (even without tagged fluid);
/// it comes first, and the usual pool of that part of the colon (ascending supine, caecum
/// prone), which it would overlap, is left out.
fn make_pools(
    tube: &Tube,
    segments: &[SegmentTruth],
    opts: &ColonOptions,
    gravity: DVec3,
    valve: Option<&Valve>,
) -> Vec<(Pool, PoolTruth)> {
    let ax = &tube.axis;
    let floor = |i: usize| ax.points[i].dot(gravity) + ax.radius[i];
    let mut pools: Vec<(Pool, PoolTruth)> = Vec::new();
    if let Some(v) = valve {
        let mut rng = Rng::new(opts.seed, STREAM_VALVE_POOL);
        let depth = (rng.range(0.35, 0.5) * ax.radius[v.vertex]).max(v.min_depth);
        let hu = rng.range(400.0, 700.0);
        let name = segment_name(segments, ax.arc[v.vertex]);
        if let Some(p) = pool_from(tube, v.vertex, floor(v.vertex) - depth, gravity, hu, &name) {
            pools.push(p);
        }
    }
    if opts.tagged_fluid {
        let mut rng = Rng::new(opts.seed, STREAM_POOLS);
        for &name in if opts.prone {
            PRONE_POOL_SEGMENTS
        } else {
            POOL_SEGMENTS
        } {
            let Ok(seg) = segment(segments, name) else {
                continue;
            };
            let (a, b) = (ax.vertex_at(seg.start_arc_mm), ax.vertex_at(seg.end_arc_mm));
            let open = |i: &usize| !near_collapse(tube, ax.arc[*i], 0.0);
            let Some(anchor) = (a..=b)
                .filter(open)
                .max_by(|&i, &j| floor(i).total_cmp(&floor(j)))
            else {
                continue;
            };
            let depth = rng.range(0.3, 0.5) * ax.radius[anchor];
            let hu = rng.range(400.0, 700.0);
            let Some(p) = pool_from(tube, anchor, floor(anchor) - depth, gravity, hu, name) else {
                continue;
            };
            if pools
                .iter()
                .any(|(q, _)| p.0.start < q.end && p.0.end > q.start)
            {
                continue;
            }
            pools.push(p);
        }
    }
    pools.sort_by(|x, y| x.0.start.total_cmp(&y.0.start));
    pools
}

/// The pool with level `level` (along `gravity`) around axis vertex `anchor`: as far along
/// the colon both ways as the lumen's floor lies below the level, never across a collapsed
/// cord (the anchor's side is kept).
fn pool_from(
    tube: &Tube,
    anchor: usize,
    level: f64,
    gravity: DVec3,
    hu: f64,
    name: &str,
) -> Option<(Pool, PoolTruth)> {
    let ax = &tube.axis;
    let floor = |i: usize| ax.points[i].dot(gravity) + ax.radius[i];
    let mut lo = anchor;
    while lo > 0 && floor(lo - 1) > level {
        lo -= 1;
    }
    let mut hi = anchor;
    while hi + 1 < ax.len() && floor(hi + 1) > level {
        hi += 1;
    }
    let (mut start, mut end) = (ax.arc[lo] - ax.radius[lo], ax.arc[hi] + ax.radius[hi]);
    for c in &tube.collapse {
        if start < c.end + c.taper && end > c.start - c.taper {
            // Fluid does not cross the collapsed cord: keep the anchor's side.
            if ax.arc[anchor] < c.start {
                end = end.min(c.start - c.taper);
            } else {
                start = start.max(c.end + c.taper);
            }
        }
    }
    if start >= end {
        return None;
    }
    let pool = Pool {
        start,
        end,
        gravity,
        level,
        hu,
    };
    // The level is the plane y = level·g_y (gravity is ±y).
    let truth = PoolTruth {
        segment: name.into(),
        start_arc_mm: start,
        end_arc_mm: end,
        level_y_mm: level * gravity.y,
        gravity_lps: arr(gravity),
        hu,
    };
    Some((pool, truth))
}

/// A few small-bowel gas pockets (10–20 mm) in the central abdomen, each at least 10 mm
/// (full size) from the colon's lumen, the spine, the lungs, the abdominal wall, each
/// other and the `obstacles` (capsules: ends and radius; opacified loops, the catheter).
/// Rejection sampling with a fixed number of tries and draws: deterministic, and where they
/// always were when there are no obstacles.
fn make_pockets(
    frame: &Frame,
    tube: &Tube,
    body: &Body,
    obstacles: &[(DVec3, DVec3, f64)],
    seed: u64,
) -> Vec<Blob> {
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
        let c = frame.pos([
            rng.range(110.0, 274.0),
            rng.range(100.0, 260.0),
            rng.range(60.0, 330.0),
        ]);
        let colon_ok = ax
            .points
            .iter()
            .zip(&ax.radius)
            .step_by(2)
            .all(|(p, rc)| p.distance(c) - rc - r - wall - tube.wall_mm >= clear);
        let body_ok = body.skin_sdf(c) + r + wall + clear <= -body.rim
            && body.spine.sdf_xy(c) >= r + wall + clear
            && body.lungs.iter().all(|l| l.sdf(c) >= r + wall + clear);
        let apart = pockets
            .iter()
            .all(|o| o.center.distance(c) - o.radius - r - 2.0 * wall >= clear);
        let free = obstacles
            .iter()
            .all(|&(a, b, ro)| segment_distance(c, a, b) - ro - r - wall >= clear);
        if colon_ok && body_ok && apart && free {
            pockets.push(Blob {
                kind: BlobKind::Pocket,
                center: c,
                radius: r,
                stalk: None,
                wall_mm: wall,
                content_hu: 0.0,
            });
        }
    }
    pockets
}

/// The rectal catheter (full size: air channel 3 mm in radius, 1 mm plastic wall; kept ≥ a
/// voxel in the small phantom). Its open tip lies `CATHETER_TIP_ARC` mm up the rectum,
/// `CATHETER_OFFSET` of the radius off the axis (so the true centerline stays in the
/// lumen), on the side (posterior first, then left, right, anterior) that keeps clear of
/// the polyps; it runs down beside the axis to the rectum's lower end, bends there and runs
/// on inferiorly and a little posteriorly (like the anal canal) through the pelvic floor to
/// its open end half a slice below the perineum's skin, in the outside air.
fn make_catheter(frame: &Frame, tube: &Tube, polyps: &[Blob], floor: f64) -> Result<Catheter> {
    let s = frame.scale;
    let ax = &tube.axis;
    let inner = frame.thin(3.0, 1.1);
    let wall = frame.thin(1.0, 0.75);
    let (tip_arc, low_arc) = (CATHETER_TIP_ARC * s, 5.0 * s);
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
        };
        let clear = polyps
            .iter()
            .all(|b| c.distance(b.center) - c.outer_radius() - b.reach() >= frame.max_spacing());
        if clear {
            return Ok(c);
        }
    }
    Err(Error::invalid(
        "colon phantom: no room for the rectal catheter beside the rectal polyp",
    ))
}

/// A 12-voxel box of pure fat (far from colon, pockets, loops, catheter, spine, lungs, skin
/// folds and the rim) for
/// measuring the noise, found by a fixed scan.
fn fat_roi(
    frame: &Frame,
    tube: &Tube,
    blobs: &[Blob],
    body: &Body,
    catheter: Option<&Catheter>,
) -> Option<RoiTruth> {
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
                    && ax
                        .points
                        .iter()
                        .zip(&ax.radius)
                        .all(|(p, r)| p.distance(c) - r - tube.wall_mm >= margin)
                    && blobs
                        .iter()
                        .all(|b| b.center.distance(c) - b.reach() >= margin)
                    && catheter.is_none_or(|t| t.distance(c) - t.outer_radius() >= margin)
                    && body
                        .folds
                        .iter()
                        .all(|f| f.plane_distance(c) - f.half_width - f.lining >= margin);
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
    let axis = make_axis(&frame, false)?;
    let wall = frame.thin(WALL, 1.0);
    let (bend, at) = axis.min_bend_ratio(wall);
    let (gap, i, j) = axis.min_part_gap(wall, 2);
    let mut out = format!(
        "length {:.0} mm; tightest bend {bend:.2} × (radius + wall) at arc {:.0}; loops closest ({gap:.1} mm) at arcs {:.0} and {:.0}\n",
        axis.length, axis.arc[at], axis.arc[i], axis.arc[j]
    );
    for g in segments(&axis) {
        out += &format!(
            "  {:<16} {:6.0} .. {:6.0} mm ({:.0} mm)\n",
            g.name,
            g.start_arc_mm,
            g.end_arc_mm,
            g.end_arc_mm - g.start_arc_mm
        );
    }
    let verdict = check_anatomy(&frame, &axis, &make_body(&frame, true, None))
        .map_or_else(|e| e.to_string(), |_| "checks pass".into());
    Ok(out + &verdict + "\n")
}

/// Development aid (for placing the small-bowel loops): for axial levels every 10 mm, a map
/// (full-size mm, 6 mm cells) of the room around each point: the distance to the colon's
/// outer wall, the spine, the lungs and the muscle under the skin, in 4 mm steps (0–9);
/// `#` the colon itself, ` ` outside the body's fat.
#[doc(hidden)]
pub fn free_space_map(z_from: f64, z_to: f64) -> Result<String> {
    let frame = Frame::new(false)?;
    let axis = make_axis(&frame, false)?;
    let body = make_body(&frame, true, None);
    let wall = frame.thin(WALL, 1.0);
    let mut out = String::new();
    let mut z = z_from;
    while z <= z_to {
        out += &format!("z = {z:.0}   x 60..330 →, y 70..330 ↓ (digit = room / 4 mm)\n");
        let mut y = 70.0;
        while y <= 330.0 {
            let mut row = format!("{y:4.0} ");
            let mut x = 60.0;
            while x <= 330.0 {
                let p = DVec3::new(x, y, z);
                let colon = axis
                    .points
                    .iter()
                    .zip(&axis.radius)
                    .map(|(a, r)| a.distance(p) - r - wall)
                    .fold(f64::INFINITY, f64::min);
                let skin = -body.skin_sdf(p) - body.rim;
                let room = colon.min(skin).min(body.spine.sdf_xy(p)).min(
                    body.lungs
                        .iter()
                        .map(|l| l.sdf(p))
                        .fold(f64::INFINITY, f64::min),
                );
                row.push(if colon < 0.0 {
                    '#'
                } else if skin < 0.0 {
                    ' '
                } else {
                    char::from(b'0' + (room / 4.0).clamp(0.0, 9.0) as u8)
                });
                x += 6.0;
            }
            out += &row;
            out.push('\n');
            y += 6.0;
        }
        z += 10.0;
    }
    Ok(out)
}

/// Development aid (for placing the small-bowel loops): for a loop of radius `r` (plus a
/// 1.5 mm wall) through full-size `knots`, the smallest room left between its wall and the
/// colon's outer wall / the rim under the skin / the spine / the lungs along each span.
#[doc(hidden)]
pub fn loop_room_report(knots: &[[f64; 3]], r: f64) -> Result<String> {
    let frame = Frame::new(false)?;
    let axis = make_axis(&frame, false)?;
    let body = make_body(&frame, true, None);
    let wall = frame.thin(WALL, 1.0);
    let ks: Vec<Knot> = knots
        .iter()
        .map(|k| Knot {
            pos: DVec3::from_array(*k),
            radius: r,
        })
        .collect();
    let path = Axis::through(&ks, 1.0)?;
    let reach = r + 1.5;
    let mut out = format!(
        "length {:.0} mm, tightest bend {:.2}\n",
        path.length,
        path.min_bend_ratio(1.5).0
    );
    for span in 0..ks.len() - 1 {
        let (a, b) = (path.knot_arc[span], path.knot_arc[span + 1]);
        let mut worst = (f64::INFINITY, "", 0.0, DVec3::ZERO);
        let mut bend = f64::INFINITY;
        for (i, (p, s)) in path
            .points
            .iter()
            .zip(&path.arc)
            .enumerate()
            .filter(|(_, (_, s))| **s >= a && **s <= b)
        {
            if i >= 3 && i + 3 < path.len() {
                let turn = path.tangent[i - 3].angle_between(path.tangent[i + 3]);
                let ds = path.arc[i + 3] - path.arc[i - 3];
                bend = bend.min(if turn > 1e-9 {
                    ds / turn / (r + 1.5)
                } else {
                    f64::INFINITY
                });
            }
            let (colon, at) = axis
                .points
                .iter()
                .zip(&axis.radius)
                .zip(&axis.arc)
                .map(|((c, rc), arc)| (c.distance(*p) - rc - wall, *arc))
                .fold((f64::INFINITY, 0.0), |x, y| if y.0 < x.0 { y } else { x });
            let cands = [
                (colon - reach, "colon"),
                (-body.skin_sdf(*p) - body.rim - reach, "skin"),
                (body.spine.sdf_xy(*p) - reach, "spine"),
                (
                    body.lungs
                        .iter()
                        .map(|l| l.sdf(*p))
                        .fold(f64::INFINITY, f64::min)
                        - reach,
                    "lung",
                ),
            ];
            for (v, what) in cands {
                if v < worst.0 {
                    worst = (v, what, if what == "colon" { at } else { *s }, *p);
                }
            }
        }
        out += &format!(
            "  {:?} -> {:?}: room {:.1} mm ({} at {:.0}, near {:.0?}), bend {bend:.2}\n",
            knots[span],
            knots[span + 1],
            worst.0,
            worst.1,
            worst.2,
            worst.3.to_array()
        );
    }
    Ok(out)
}

/// The colon's axis as it lies supine and as it lies prone in a pair (`pair_member`).
pub(crate) fn pair_axes(small: bool) -> Result<(Axis, Axis)> {
    let frame = Frame::new(small)?;
    let prone = make_axis(&frame, false)?;
    let mut supine = make_axis(&frame, true)?;
    supine.reframe_like(&prone);
    Ok((supine, prone))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Background;

    /// The body with a table and skin folds as [`colon`] makes it (folds clear of the colon
    /// and, with `catheter`, of a rectal catheter leaving through a perineum).
    fn body_on_table(small: bool, prone: bool, catheter: bool) -> Body {
        let frame = Frame::new(small).expect("frame");
        let gravity = if prone { DVec3::NEG_Y } else { DVec3::Y };
        let floor = catheter.then(|| frame.pos([0.0, 0.0, FLOOR_Z]).z);
        let mut body = make_body(&frame, true, floor);
        body.table = Some(skin::make_table(&frame, &body, gravity));
        let tube = Tube::new(
            make_axis(&frame, false).expect("axis"),
            frame.thin(WALL, 1.0),
            Ends::Round,
        );
        let cath = floor.map(|f| make_catheter(&frame, &tube, &[], f).expect("catheter"));
        let near = Obstacles {
            tube: &tube,
            blobs: &[],
            catheter: cath.as_ref(),
        };
        body.folds = skin::make_folds(&frame, &body, gravity, &near, 1)
            .into_iter()
            .map(|(f, _)| f)
            .collect();
        body
    }

    /// The rows' shortcuts (plain air, table, fat) give exactly what [`Background::sample`]
    /// gives, next to the table, the contact strip, the wedge and every skin fold.
    #[test]
    fn rows_with_the_table_and_folds_are_what_sample_gives() {
        for (small, prone, catheter) in [
            (true, true, true),
            (true, false, false),
            (false, true, true),
            (false, false, false),
        ] {
            let frame = Frame::new(small).expect("frame");
            let body = body_on_table(small, prone, catheter);
            assert!(body.folds.len() >= 4, "{} folds", body.folds.len());
            let g = &frame.geom;
            let [nx, ny, nz] = g.dims;
            let [sx, sy, sz] = g.spacing;
            // Every slice of the small phantom; at full size the first ones (perineum, the
            // gluteal folds) and those through each fold's middle.
            let slices: Vec<usize> = if small {
                (0..nz).collect()
            } else {
                (0..8)
                    .chain(body.folds.iter().map(|f| {
                        let mid = f.mouth + f.along * 0.5 * (f.span.0 + f.span.1);
                        ((mid.z / sz).round().max(0.0) as usize).min(nz - 1)
                    }))
                    .collect()
            };
            let (mut hu, mut lab) = (vec![0.0; nx], vec![0u8; nx]);
            for k in slices {
                let z = k as f64 * sz;
                for j in 0..ny {
                    let y = j as f64 * sy;
                    body.fill_row(y, z, sx, &mut hu, &mut lab);
                    for i in 0..nx {
                        let want = body.sample(DVec3::new(i as f64 * sx, y, z));
                        assert!(
                            (hu[i], lab[i]) == want,
                            "small {small} prone {prone}: voxel ({i}, {j}, {k}) row {:?}, sample {want:?}",
                            (hu[i], lab[i])
                        );
                    }
                }
            }
        }
    }
}
