//! Segmentation of the colon's air (paper §3.2: "the voxels inside the colon are easily
//! extracted with a region growing method"), made to hold on real CT colonography exams: the
//! colon in several gas segments, tagged fluid, opacified small bowel, any patient position
//! and any storage order.
//!
//! Everything starts on *runs*: maximal stretches of air along x in one row. A CT of
//! 512×512×400 voxels holds a few hundred thousand air runs, so connected components,
//! outside-air removal and region growing cost a pass over the HU values plus work on the runs.
//!
//! Each step is a call in [`segment_axial`] that takes the values the steps before returned.
//!
//! 1. Threshold: air is HU < `air_hu` (−500, midway between air and soft tissue, where the
//!    partial-volume boundary lies); its runs and the bright runs, in one read ([`runs`]).
//! 2. Outside air: in each *axial* slice (the patient frame's, whatever the storage order),
//!    air connected (4-neighbours) to the slice's border lies outside the body. Slice by slice
//!    and not in 3D, because a rectal tube carries air from the colon out of the body
//!    ([`components`], as are steps 3 and 4).
//! 3. Components: the remaining air, 6-connected in 3D (diagonal contact through a thin wall
//!    does not join two loops of the colon).
//! 4. Lungs: large components whose air is not dark enough to be gas (lung parenchyma lies
//!    around −850 HU, bowel gas at −1000); where thick slices join a lung base to bowel gas,
//!    its parenchyma (air farther than 3 mm from any dark voxel, 100 ml of it or more) is
//!    kept apart first. A rectal tube (a thin tube of air from outside
//!    air into a component) is taken out of its component ([`tube`]): the rectum starts at
//!    its tip.
//! 5. Gravity: DICOM PatientPosition or `--position`; else from the air–fluid levels; else
//!    supine, assumed and said ([`crate::anatomy`], [`fluid`]).
//! 6. Tagged fluid: bright voxels in the column under a gas region's air, across the level
//!    ([`fluid`]); gas regions and their pools form *compartments* (air split by a level
//!    stays one compartment), of which the segment candidates and the rectum are chosen
//!    ([`compartments`]).
//! 7. The colon: a chain of compartments from the rectum (the lowest gas in the patient
//!    frame) to the cecum, end to end, each gap bridged by the cheapest path through the CT
//!    ([`chain`], [`bridge`]; the course it follows: [`course`]).
//! 8. The lumen: the chained compartments, the bridges and the fluid filling the stretches
//!    they cross; the colon's pools made whole: the tagged fluid beside the columns
//!    (haustral pockets, pools wider than their air, the floor of a deep pool) reached
//!    through fluid within [`fluid::POOL_REACH_MM`] ([`lumen`]).
//! 9. The report: every gas region, kept or left out with the reason, the gaps bridged, and
//!    what the user must hear of ([`report`]).
//!
//! The working labels and boxes all steps share are in [`work`].
//!
//! A lumen mask (0/1 labels from another segmenter) skips steps 1, 2, 4 and 6; its pieces are
//! chained like gas segments.

mod bridge;
mod chain;
mod coarse;
mod compartments;
mod components;
mod course;
mod fluid;
mod lumen;
mod report;
mod runs;
mod tube;
mod work;

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::{
    Error, Result, Storage, Volume,
    anatomy::{Orientation, PatientPosition, PositionSource},
};
use chain::ChainOptions;
use compartments::{Candidates, Compartments};
pub use course::COLON_SEGMENTS;
pub(crate) use course::Course;
pub(crate) use report::region_of;

#[derive(Clone, Debug)]
pub struct SegmentOptions {
    /// Air is HU below this.
    pub air_hu: i16,
    /// Points in gas that is colon (volume-local mm): their regions join the colon even if
    /// the automatic chain would leave them out. None of them is the source.
    pub seeds_mm: Vec<DVec3>,
    /// Points in gas that is not colon (volume-local mm): their regions are left out of the
    /// colon, even the lowest (the rectum is then the lowest of the rest).
    pub exclude_mm: Vec<DVec3>,
    /// Treat the input as a lumen mask (non-zero = lumen). None: detect (values only 0 and 1).
    pub mask: Option<bool>,
    /// Components smaller than this (ml) are not reported one by one.
    pub min_report_ml: f64,
    /// Without a seed, the colon must hold at least this much gas (ml): a few millilitres
    /// of gas are bowel gas or noise, not a colon to fly through.
    pub min_colon_ml: f64,
    /// Tagged fluid is HU at or above this; None: no fluid is added to the lumen.
    pub fluid_hu: Option<i16>,
    /// The patient's position and where it came from (DICOM, the user); None: inferred.
    pub position: Option<(PatientPosition, PositionSource)>,
    /// How gas segments are chained into one colon.
    pub chain: ChainOptions,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions {
            air_hu: -500,
            seeds_mm: Vec::new(),
            exclude_mm: Vec::new(),
            mask: None,
            min_report_ml: 0.5,
            min_colon_ml: 10.0,
            fluid_hu: Some(200),
            position: None,
            chain: ChainOptions::default(),
        }
    }
}

/// What a gas component is taken to be.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ComponentKind {
    Colon,
    Lung,
    /// Narrow or small gas not joined to the colon.
    SmallBowel,
    /// Large gas high on the patient's left, not joined to the colon.
    Stomach,
    /// The air in a rectal tube, from outside the body into the rectum (`segment/tube.rs`).
    RectalTube,
    Other,
}

impl ComponentKind {
    /// In words, as a reader would say it.
    pub fn name(self) -> &'static str {
        match self {
            ComponentKind::Colon => "colon",
            ComponentKind::Lung => "lung",
            ComponentKind::SmallBowel => "small bowel",
            ComponentKind::Stomach => "stomach",
            ComponentKind::RectalTube => "rectal tube",
            ComponentKind::Other => "other",
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Component {
    pub voxels: usize,
    pub volume_ml: f64,
    /// Mean position, volume-local mm.
    pub centroid_mm: [f64; 3],
    pub bbox_lo: [usize; 3],
    pub bbox_hi: [usize; 3],
    /// Mean HU (None for mask input).
    pub mean_hu: Option<f64>,
    /// Fraction of voxels darker than −950 HU: bowel gas is mostly that dark, lung is not.
    pub dark_fraction: Option<f64>,
    pub kind: ComponentKind,
}

/// A gas region with the tagged fluid under its level, as the report lists it.
#[derive(Clone, Debug, Serialize)]
pub struct SegmentReport {
    /// Where it lies ("rectosigmoid", "descending–splenic flexure", ...) for colon segments;
    /// the class for the rest ("small bowel", "stomach", "other").
    pub label: String,
    pub kind: ComponentKind,
    /// Position in the colon, rectum first (None: not colon).
    pub order: Option<usize>,
    pub gas_ml: f64,
    pub fluid_ml: f64,
    /// Bounding box in patient LPS mm.
    pub extent_lps_mm: [[f64; 3]; 2],
    /// A point in its gas (its lowest gas voxel, patient LPS mm): give it to `--seed` to
    /// take the segment in, to `--exclude` to leave it out.
    pub anchor_lps_mm: [f64; 3],
    pub kept: bool,
    /// Why it was left out.
    pub reason: Option<String>,
}

/// A gap between two consecutive colon segments, bridged through the CT.
#[derive(Clone, Debug, Serialize)]
pub struct Gap {
    /// Indices into the colon order (`SegmentReport::order`): from `between[0]` to `between[1]`.
    pub between: [usize; 2],
    pub length_mm: f64,
    pub from_lps_mm: [f64; 3],
    pub to_lps_mm: [f64; 3],
    /// Mean cost per mm of the path (1: soft tissue, i.e. collapsed bowel, all the way).
    pub mean_cost: f64,
    /// Filled with tagged fluid, not collapsed: most of what the bridge added was fluid
    /// (cleansing makes it air, so the stretch is open lumen in the view).
    pub fluid_filled: bool,
    /// Where an end lies at the side of the scanned volume, that side of the patient ("left",
    /// "head end", ...): the colon leaves the scan there, and the bridge joins its two ends
    /// inside (what lies beyond is not read).
    pub edge_side: Option<&'static str>,
    /// It lies along a rectal catheter inside the body: what kept the gas apart is the
    /// catheter's retention balloon or the anal canal closed round it, not collapsed bowel.
    pub at_catheter: bool,
    /// The lumen voxels (volume indices, sorted) the bridge added: its tube and the fluid
    /// filling the stretch it crosses.
    #[serde(skip)]
    pub voxels: Vec<usize>,
}

#[derive(Clone, Debug)]
pub struct Segmentation {
    /// 1 = colon lumen.
    pub lumen: Volume<u8>,
    pub lumen_voxels: usize,
    /// Internal gas components, largest first (those above `min_report_ml`).
    pub components: Vec<Component>,
    /// Smaller components not listed one by one.
    pub small_components: usize,
    /// Voxels of tagged fluid (and of the air–fluid interface) counted in the lumen.
    pub fluid_voxels: usize,
    /// Whether the input was taken as a mask.
    pub from_mask: bool,
    /// The colon's lowest voxel in the patient frame (middle of its lowest 2 mm): where the
    /// rectum is looked for.
    pub seed_voxel: [usize; 3],
    /// The lumen's first and last voxel along each axis (its bounding box, both ends inside).
    pub extent: [[usize; 3]; 2],
    pub orientation: Orientation,
    /// Gas regions (with their fluid): the colon's in order, then the rest.
    pub segments: Vec<SegmentReport>,
    /// Gaps bridged between consecutive colon segments.
    pub gaps: Vec<Gap>,
    /// Doubtful results the user must hear of (an assumed position, a bridged gap, large gas
    /// left out, ...).
    pub warnings: Vec<String>,
    /// Radius (mm) of the tube laid along each bridge.
    pub bridge_radius_mm: f64,
    /// The cecal pole, where the colon's course ends (a voxel of the last segment), when the
    /// colon was ordered by its large compartments' anatomy; None: the centerline's longest
    /// path decides.
    pub cecum_voxel: Option<[usize; 3]>,
    /// The voxels of tagged fluid the lumen took in beyond its pools' columns ([`fluid`]'s
    /// whole pools; volume indices, ascending).
    pub pools_grown: Vec<usize>,
    /// What names the last colon segment again from the centerline's end.
    pub(crate) last_segment: Option<report::LastSegment>,
}

/// Segments the colon lumen from a CT (or takes it from a mask).
///
/// Outside air is found in axial slices: when the scan's axial planes are not its k slices
/// (a coronal or sagittal stack, or a volume stored another way round), the scan is first
/// stored with its axial planes as slices, and the result stored back.
pub fn segment(vol: &Volume<i16>, opts: &SegmentOptions) -> Result<Segmentation> {
    // A 0/1 mask is told at once; other label-like values (0/255, 0/1/2) are looked at only
    // then, so neither a CT nor a 0/1 mask pays for the look.
    let plain_mask = opts.mask != Some(false) && is_mask(vol);
    let labels = (opts.mask != Some(false) && !plain_mask)
        .then(|| label_values(vol))
        .flatten()
        .filter(|l| l.len() >= 2);
    let from_mask = opts
        .mask
        .unwrap_or(plain_mask || labels.as_ref().is_some_and(|l| l.len() == 2));
    if from_mask {
        let mut seg = segment_mask(vol, opts)?;
        if let Some(l) = labels.filter(|l| l.len() > 2) {
            seg.warnings.push(format!(
                "mask labels {} merged as the lumen (0 is outside)",
                join(&l[1..])
            ));
        }
        return Ok(seg);
    }
    if let Some(l) = labels {
        return Err(Error::invalid(format!(
            "this looks like a label mask, not a CT (its only values are {}): give --mask to take every non-zero label as the lumen",
            join(&l)
        )));
    }
    let storage = Storage::of(vol.geometry());
    if storage.is_identity() {
        return segment_axial(vol, opts, false);
    }
    let stored = storage.to_study(vol)?;
    let s = segment_axial(&stored, &opts.in_storage(&storage), false)?;
    s.stored_back(&storage)
}

impl SegmentOptions {
    /// These options with their points (input volume-local mm) in the study storage.
    pub(crate) fn in_storage(&self, storage: &Storage) -> SegmentOptions {
        SegmentOptions {
            seeds_mm: self.seeds_mm.iter().map(|&p| storage.mm_in(p)).collect(),
            exclude_mm: self.exclude_mm.iter().map(|&p| storage.mm_in(p)).collect(),
            ..self.clone()
        }
    }
}

impl Gap {
    /// The colon leaves the scan at this gap ([`Gap::edge_side`]).
    pub fn at_edge(&self) -> bool {
        self.edge_side.is_some()
    }
}

/// Gas left out of the colon from this size on (ml) makes a reading of the rest doubtful: a
/// reached goal is not the colon's end, and a negative reading no negative exam.
pub const LEFT_OUT_DOUBT_ML: f64 = 100.0;

impl Segmentation {
    /// The largest gas region left out of the colon automatically (ml of gas), if any holds
    /// at least `min_ml`: the flight's end is then doubtful (not the user's choice).
    pub fn largest_left_out(&self, min_ml: f64) -> Option<&SegmentReport> {
        self.left_out(min_ml)
            .max_by(|a, b| a.gas_ml.total_cmp(&b.gas_ml))
    }

    /// The gas regions of at least `min_ml` left out of the colon automatically (not by the
    /// user).
    pub fn left_out(&self, min_ml: f64) -> impl Iterator<Item = &SegmentReport> {
        self.segments
            .iter()
            .filter(move |s| !s.kept && s.gas_ml >= min_ml && s.reason.as_deref() != Some(EXCLUDED))
    }

    /// The segmentation of a scan in its study storage, in the input storage.
    fn stored_back(mut self, storage: &Storage) -> Result<Segmentation> {
        self.lumen = storage.to_input(&self.lumen)?;
        self.seed_voxel = storage.voxel_back(self.seed_voxel);
        self.cecum_voxel = self.cecum_voxel.map(|v| storage.voxel_back(v));
        let (lo, hi) = storage.box_back(self.extent[0], self.extent[1]);
        self.extent = [lo, hi];
        for c in &mut self.components {
            c.centroid_mm = storage.mm_back(c.centroid_mm);
            (c.bbox_lo, c.bbox_hi) = storage.box_back(c.bbox_lo, c.bbox_hi);
        }
        for g in &mut self.gaps {
            g.voxels = storage.indices_back(&g.voxels);
        }
        self.pools_grown = storage.indices_back(&self.pools_grown);
        Ok(self)
    }
}

/// The module's steps 1–9 on a scan whose axial planes are its k slices (or on a mask,
/// `from_mask`).
fn segment_axial(
    vol: &Volume<i16>,
    opts: &SegmentOptions,
    from_mask: bool,
) -> Result<Segmentation> {
    let fluid_hu = opts.fluid_hu.filter(|_| !from_mask);
    let ct = (!from_mask).then_some(vol);
    let found = components::find(vol, opts, fluid_hu, from_mask);
    let points = found.user_points(vol, opts)?;
    let pooled = fluid::pool(vol, opts, &found, fluid_hu, from_mask)?;
    let mut warnings: Vec<String> = pooled.position_warning(from_mask).into_iter().collect();
    let parts = Compartments::new(vol, &found, &pooled);
    let cand = Candidates::choose(&parts, &points, vol, opts, &found, from_mask)?;
    let mut chained = chain::colon(&parts, &cand, &pooled, ct, &opts.chain);
    warnings.append(&mut chained.warnings);
    // A few millilitres of gas are no colon to fly through, unless the user says so.
    if cand.seeded.is_empty() && chained.gas_ml(&parts) < opts.min_colon_ml {
        return Err(found.no_colon(opts, from_mask));
    }
    let orientation = pooled.orientation;
    let lumen = lumen::lumen(
        pooled.work,
        &parts,
        &chained,
        ct,
        (opts.air_hu, fluid_hu),
        orientation.gravity(),
    )?;
    // The source side: the middle of the rectum's lowest 2 mm.
    let seed_voxel = parts.lowest_middle(cand.rectum, vol.geometry());
    let report = report::report(
        found,
        &parts,
        &cand,
        &chained,
        lumen.gap_voxels,
        vol.geometry(),
        opts,
    );
    warnings.extend(report.warnings);
    Ok(Segmentation {
        lumen: lumen.mask,
        lumen_voxels: lumen.voxels,
        components: report.components,
        small_components: report.small_components,
        fluid_voxels: lumen.fluid_voxels,
        from_mask,
        seed_voxel,
        extent: [lumen.extent.lo, lumen.extent.hi],
        orientation,
        segments: report.segments,
        gaps: report.gaps,
        warnings,
        bridge_radius_mm: lumen.bridge_radius_mm,
        cecum_voxel: chained.cecum_voxel,
        pools_grown: lumen.pools_grown,
        last_segment: report.last_segment,
    })
}

/// Millilitres per voxel.
fn voxel_ml(vol: &Volume<i16>) -> f64 {
    vol.spacing().iter().product::<f64>() / 1000.0
}

/// Why a segment the user excluded is not in the colon.
const EXCLUDED: &str = "excluded by the user";

/// A mask is segmented as stored (it has no outside air to find in axial slices).
fn segment_mask(vol: &Volume<i16>, opts: &SegmentOptions) -> Result<Segmentation> {
    segment_axial(vol, opts, true)
}

/// The values of a volume that holds only a few in 0..=255 (a label or 0/255 mask), sorted;
/// None for anything else (a CT: its first negative value ends the look).
pub fn label_values(vol: &Volume<i16>) -> Option<Vec<i16>> {
    let seen = vol
        .data()
        .par_chunks(1 << 14)
        .map(|c| {
            let mut bits = [0u64; 4];
            for &v in c {
                if !(0..=255).contains(&v) {
                    return None;
                }
                bits[v as usize >> 6] |= 1 << (v as usize & 63);
            }
            Some(bits)
        })
        .try_reduce(|| [0u64; 4], |a, b| Some([0, 1, 2, 3].map(|i| a[i] | b[i])))?;
    let values: Vec<i16> = (0..256i16)
        .filter(|&v| seen[v as usize >> 6] >> (v as usize & 63) & 1 == 1)
        .collect();
    (values.len() <= MAX_LABELS).then_some(values)
}

/// More distinct values than this is no label mask.
const MAX_LABELS: usize = 16;

fn join(values: &[i16]) -> String {
    values
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A volume holding only 0 and 1 is a mask, not a CT.
pub fn is_mask(vol: &Volume<i16>) -> bool {
    // Chunks tested without an early exit inside (vector code); a CT fails on its first chunk.
    let chunks = || vol.data().par_chunks(1 << 14);
    chunks().all(|c| c.iter().fold(true, |a, &v| a & (v as u16 <= 1)))
        && chunks().any(|c| c.iter().fold(false, |a, &v| a | (v == 1)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;

    /// A body of tissue (40 HU) in outside air, with a big gas tube, a small gas pocket, and
    /// a "lung" of −850 HU.
    fn toy() -> Volume<i16> {
        let g = Geometry::new([60, 50, 40], [1.0, 1.0, 1.5], [0.0; 3]).unwrap();
        let mut v = Volume::filled(g, -1000i16).unwrap();
        for k in 0..40 {
            for j in 0..50 {
                for i in 0..60 {
                    let body = ((i as f64 - 30.0) / 27.0).powi(2)
                        + ((j as f64 - 25.0) / 22.0).powi(2)
                        < 1.0;
                    if !body {
                        continue;
                    }
                    let tube = (i as f64 - 20.0).powi(2) + (j as f64 - 25.0).powi(2) < 36.0
                        && (3..37).contains(&k);
                    let pocket = (i as f64 - 40.0).powi(2)
                        + (j as f64 - 20.0).powi(2)
                        + (k as f64 - 10.0).powi(2)
                        < 6.0;
                    let lung =
                        (i as f64 - 40.0).powi(2) + (j as f64 - 30.0).powi(2) < 30.0 && k >= 30;
                    let hu = if tube || pocket {
                        -1000
                    } else if lung {
                        -850
                    } else {
                        40
                    };
                    v.set(i, j, k, hu);
                }
            }
        }
        v
    }

    /// The toy's tube holds 5.6 ml of gas: below the default minimum for a colon.
    fn toy_options() -> SegmentOptions {
        SegmentOptions {
            min_colon_ml: 1.0,
            ..Default::default()
        }
    }

    #[test]
    fn too_little_gas_is_no_colon() {
        let e = segment(&toy(), &SegmentOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("no colon lumen") && e.contains("5.6 ml"), "{e}");
    }

    /// Thick slices (3 mm) that average a diaphragm away: a lung base (−800 HU, 137 ml)
    /// lies on bowel gas (72 ml) and reaches 10 mm past its side. Joined, the two passed for
    /// bowel (0.38 of it dark) and the lung was taken into the colon; its parenchyma is kept
    /// apart and is lung. So is the lung in the slice on the gas where it reaches past the
    /// gas's rim: counted by whole runs along x, that slice stayed bowel to the lung's edge
    /// (`ctc/prone-tagged` in 2.5 mm slices: 63 ml of the lung base kept, now 10).
    #[test]
    fn a_lung_base_on_the_gas_is_kept_apart() {
        let g = Geometry::new([100, 100, 24], [1.0, 1.0, 3.0], [0.0; 3]).unwrap();
        let mut v = Volume::filled(g, -1000i16).unwrap();
        for k in 0..24 {
            for j in 0..100 {
                for i in 0..100 {
                    let body = ((i as f64 - 50.0) / 48.0).powi(2)
                        + ((j as f64 - 50.0) / 48.0).powi(2)
                        < 1.0;
                    if !body {
                        continue;
                    }
                    let inner = (20..80).contains(&i) && (25..75).contains(&j);
                    let wider = (20..90).contains(&i) && (25..75).contains(&j);
                    let hu = match k {
                        2..10 if inner => -1000,
                        10..23 if wider => -800,
                        _ => 40,
                    };
                    v.set(i, j, k, hu);
                }
            }
        }
        let s = segment(&v, &toy_options()).unwrap();
        assert_eq!(s.lumen.get(50, 50, 5), 1, "the bowel gas");
        assert_eq!(s.lumen.get(50, 50, 16), 0, "the lung");
        assert_eq!(s.lumen.get(50, 50, 10), 1, "the gas's rim");
        assert_eq!(s.lumen.get(87, 50, 10), 0, "the lung past the gas's rim");
        assert!(
            s.components
                .iter()
                .any(|c| c.kind == ComponentKind::Lung && c.volume_ml >= 100.0),
            "{:?}",
            s.components
        );
    }

    #[test]
    fn finds_the_tube_not_the_pocket_lung_or_outside() {
        let v = toy();
        let s = segment(&v, &toy_options()).unwrap();
        assert!(!s.from_mask);
        assert_eq!(s.lumen.get(20, 25, 20), 1);
        assert_eq!(s.lumen.get(40, 20, 10), 0, "small pocket taken");
        assert_eq!(s.lumen.get(40, 30, 35), 0, "lung taken");
        assert_eq!(s.lumen.get(0, 0, 0), 0, "outside air taken");
        assert_eq!(
            s.lumen_voxels,
            s.lumen.data().iter().filter(|&&m| m == 1).count()
        );
        assert!(s.components.iter().any(|c| c.kind == ComponentKind::Lung));
        assert_eq!(s.components[0].kind, ComponentKind::Colon);
        assert_eq!(
            s.seed_voxel[2], 3,
            "automatic seed at the lowest slice of the colon"
        );
    }

    #[test]
    fn seed_makes_its_gas_colon_and_bad_seeds_fail() {
        let v = toy();
        // Without a seed the small pocket is left out (and the tube is too small alone).
        let s = segment(&v, &toy_options()).unwrap();
        assert_eq!(s.lumen.get(40, 20, 10), 0);
        // A seed in the pocket says it is colon: it joins, and so does the tube beside it
        // (a segment big enough, within reach), bridged, with a warning; the rectum side is
        // still the lowest colon gas, not the seed.
        let seeded = SegmentOptions {
            seeds_mm: vec![DVec3::new(40.0, 20.0, 15.0)],
            ..Default::default()
        };
        let s = segment(&v, &seeded).unwrap();
        assert_eq!(s.lumen.get(40, 20, 10), 1);
        assert_eq!(s.lumen.get(20, 25, 20), 1);
        assert_eq!(s.gaps.len(), 1);
        assert!(
            s.warnings.iter().any(|w| w.contains("bridged")),
            "{:?}",
            s.warnings
        );
        assert_eq!(
            s.seed_voxel[2], 3,
            "the source side is the lowest colon gas, not the seed"
        );
        let in_tissue = SegmentOptions {
            seeds_mm: vec![DVec3::new(30.0, 10.0, 30.0)],
            ..Default::default()
        };
        assert!(
            segment(&v, &in_tissue)
                .unwrap_err()
                .to_string()
                .contains("not in gas")
        );
        let outside = SegmentOptions {
            seeds_mm: vec![DVec3::new(0.0, 0.0, 0.0)],
            ..Default::default()
        };
        assert!(
            segment(&v, &outside)
                .unwrap_err()
                .to_string()
                .contains("outside the body")
        );
        let beyond = SegmentOptions {
            seeds_mm: vec![DVec3::new(500.0, 0.0, 0.0)],
            ..Default::default()
        };
        assert!(segment(&v, &beyond).is_err());
    }

    /// The last segment takes its end's name from where the centerline ends, and the gap
    /// warning before it says the new name.
    #[test]
    fn the_last_segment_is_named_where_the_centerline_ends() {
        let seeded = SegmentOptions {
            seeds_mm: vec![DVec3::new(40.0, 20.0, 15.0)],
            ..Default::default()
        };
        let mut s = segment(&toy(), &seeded).unwrap();
        let last = |s: &Segmentation| {
            let g = s.segments.iter().max_by_key(|g| g.order).unwrap();
            g.label.clone()
        };
        // An end outside the last segment's gas leaves its name.
        let named = last(&s);
        s.name_last_segment(DVec3::new(0.0, 25.0, 0.0));
        assert_eq!(last(&s), named);
        // The last segment (the small pocket) made as large as the body, so that ends far
        // apart in the colon's box name it differently.
        let i = (0..s.segments.len())
            .max_by_key(|&i| s.segments[i].order)
            .unwrap();
        s.segments[i].extent_lps_mm = [[-1e3; 3], [1e3; 3]];
        // The toy's LPS is its index frame at 1 × 1 × 1.5 mm: the patient's right is small i,
        // the head end large k.
        for (end, name) in [
            (DVec3::new(0.0, 25.0, 0.0), "cecum"),
            (DVec3::new(59.0, 25.0, 58.5), "splenic flexure"),
        ] {
            s.name_last_segment(end);
            let label = last(&s);
            assert!(label.ends_with(name), "{label}");
            let saying = format!("and the {label} segment");
            let bridged: Vec<&String> = s
                .warnings
                .iter()
                .filter(|w| w.contains("bridged"))
                .collect();
            assert!(
                bridged.len() == 1 && bridged[0].contains(&saying),
                "{:?}",
                s.warnings
            );
        }
    }

    #[test]
    fn mask_input_is_detected_and_used() {
        let v = toy();
        let s = segment(&v, &toy_options()).unwrap();
        let mask = s.lumen.map(|m| m as i16);
        let again = segment(&mask, &toy_options()).unwrap();
        assert!(again.from_mask);
        assert_eq!(again.lumen, s.lumen);
    }

    #[test]
    fn no_gas_is_an_error() {
        let g = Geometry::new([10, 10, 10], [1.0; 3], [0.0; 3]).unwrap();
        let v = Volume::filled(g, 40i16).unwrap();
        assert!(
            segment(&v, &SegmentOptions::default())
                .unwrap_err()
                .to_string()
                .contains("no colon")
        );
    }
}
