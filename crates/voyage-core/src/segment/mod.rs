//! Segmentation of the colon's air (paper §3.2: "the voxels inside the colon are easily
//! extracted with a region growing method"), made to hold on real CT colonography exams: the
//! colon in several gas segments, tagged fluid, opacified small bowel, any patient position
//! and any storage order.
//!
//! Everything starts on *runs*: maximal stretches of air along x in one row. A CT of
//! 512×512×400 voxels holds a few hundred thousand air runs, so connected components,
//! outside-air removal and region growing cost a pass over the HU values plus work on the runs.
//!
//! 1. Threshold: air is HU < `air_hu` (−500, midway between air and soft tissue, where the
//!    partial-volume boundary lies).
//! 2. Outside air: in each *axial* slice (the patient frame's, whatever the storage order),
//!    air connected (4-neighbours) to the slice's border lies outside the body. Slice by slice
//!    and not in 3D, because a rectal tube carries air from the colon out of the body.
//! 3. Components: the remaining air, 6-connected in 3D (diagonal contact through a thin wall
//!    does not join two loops of the colon).
//! 4. Lungs: large components whose air is not dark enough to be gas (lung parenchyma lies
//!    around −850 HU, bowel gas at −1000). A rectal tube (a thin tube of air from outside
//!    air into a component) is taken out of its component ([`tube`]): the rectum starts at
//!    its tip.
//! 5. Gravity: DICOM PatientPosition or `--position`; else from the air–fluid levels; else
//!    supine, assumed and said ([`crate::anatomy`]).
//! 6. Tagged fluid: bright voxels in the column under a gas region's air, across the level
//!    ([`fluid`]); gas regions and their pools form *compartments* (air split by a level
//!    stays one compartment). Once the colon is chosen, its pools are made whole: the
//!    tagged fluid beside the columns (haustral pockets, pools wider than their air, the
//!    floor of a deep pool) reached through fluid within [`fluid::POOL_REACH_MM`].
//! 7. The colon: a chain of compartments from the rectum (the lowest gas in the patient
//!    frame) to the cecum, end to end, each gap bridged by the cheapest path through the CT
//!    ([`chain`], [`bridge`]). What is left out is listed with the reason.
//!
//! A lumen mask (0/1 labels from another segmenter) skips steps 1, 2, 4 and 6; its pieces are
//! chained like gas segments.

mod bridge;
mod chain;
mod course;
mod fluid;
mod tube;
mod work;

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::{
    Error, Result, Volume,
    anatomy::{Orientation, PatientFrame, PatientPosition, PositionSource},
    simd::{self, Test},
};
use chain::{Chain, ChainOptions, Coarse, Compartment, Left, Role};
use course::Course;
use work::{BRIDGE, Bbox, GAS, LAYER, POOL};

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
}

/// One stretch of lumen candidates along x: voxels x0..x1 of row (j, k).
#[derive(Clone, Copy, Debug)]
struct Run {
    x0: u32,
    x1: u32,
}

/// All runs, row by row: the runs of row r = j + ny*k are `runs[row_start[r]..row_start[r+1]]`.
struct Runs {
    runs: Vec<Run>,
    row_start: Vec<u32>,
    /// Per run: sum of HU and count of voxels below −950 (zero for masks).
    hu_sum: Vec<i64>,
    dark: Vec<u32>,
    ny: usize,
}

impl Runs {
    fn row(&self, j: usize, k: usize) -> std::ops::Range<usize> {
        let r = j + self.ny * k;
        self.row_start[r] as usize..self.row_start[r + 1] as usize
    }

    /// The runs where `keep(run)`, in the same rows.
    fn filtered(&self, keep: impl Fn(usize) -> bool) -> Runs {
        let mut out = Runs {
            runs: Vec::new(),
            row_start: Vec::with_capacity(self.row_start.len()),
            hu_sum: Vec::new(),
            dark: Vec::new(),
            ny: self.ny,
        };
        out.row_start.push(0);
        for row in 0..self.row_start.len() - 1 {
            for r in self.row_start[row] as usize..self.row_start[row + 1] as usize {
                if keep(r) {
                    out.runs.push(self.runs[r]);
                    out.hu_sum.push(self.hu_sum[r]);
                    out.dark.push(self.dark[r]);
                }
            }
            out.row_start.push(out.runs.len() as u32);
        }
        out
    }

    /// The run holding voxel v, if any.
    fn at(&self, v: [usize; 3]) -> Option<usize> {
        let row = self.row(v[1], v[2]);
        let rs = &self.runs[row.clone()];
        let p = rs.partition_point(|r| (r.x1 as usize) <= v[0]);
        (p < rs.len() && rs[p].x0 as usize <= v[0]).then_some(row.start + p)
    }
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
    let (perm, flip) = canonical_storage(vol.geometry());
    if perm == [0, 1, 2] && flip == [false; 3] {
        return segment_axial(vol, opts, false);
    }
    let stored = vol.reoriented(perm, flip)?;
    let canon = Canonical {
        perm,
        flip,
        dims: stored.dims(),
        spacing: stored.spacing(),
    };
    let o = SegmentOptions {
        seeds_mm: opts.seeds_mm.iter().map(|&p| canon.mm_in(p)).collect(),
        exclude_mm: opts.exclude_mm.iter().map(|&p| canon.mm_in(p)).collect(),
        ..opts.clone()
    };
    let s = segment_axial(&stored, &o, false)?;
    s.stored_back(&canon, vol.geometry())
}

/// The storage every scan is segmented in: its axes permuted and flipped to run along the
/// patient's x (left), y (posterior) and z (superior), so that no result depends on how the
/// scan was stored (coarse blocks, ties between equal distances). Where the axes do not
/// match the patient's one to one (very oblique), only the axial axis is put last.
fn canonical_storage(g: &crate::Geometry) -> ([usize; 3], [bool; 3]) {
    let frame = PatientFrame::of(g);
    let mut perm = [0; 3];
    let mut flip = [false; 3];
    for (b, dir) in [DVec3::X, DVec3::Y, DVec3::Z].into_iter().enumerate() {
        let (a, sign) = frame.nearest_axis(dir);
        perm[b] = a;
        flip[b] = sign < 0;
    }
    let mut sorted = perm;
    sorted.sort_unstable();
    if sorted == [0, 1, 2] {
        return (perm, flip);
    }
    let (axial, _) = frame.nearest_axis(DVec3::Z);
    let mut perm = [0, 1, 2];
    perm.swap(axial, 2);
    (perm, [false; 3])
}

/// A scan's canonical storage ([`canonical_storage`]): `reoriented(perm, flip)` of the
/// original, of `dims` and `spacing`.
struct Canonical {
    perm: [usize; 3],
    flip: [bool; 3],
    dims: [usize; 3],
    spacing: [f64; 3],
}

impl Canonical {
    /// Original volume-local mm to canonical.
    fn mm_in(&self, p: DVec3) -> DVec3 {
        DVec3::from_array([0, 1, 2].map(|a| {
            let x = p[self.perm[a]];
            if self.flip[a] {
                (self.dims[a] - 1) as f64 * self.spacing[a] - x
            } else {
                x
            }
        }))
    }
    /// Canonical volume-local mm to original.
    fn mm_back(&self, p: [f64; 3]) -> [f64; 3] {
        let mut o = [0.0; 3];
        for a in 0..3 {
            o[self.perm[a]] = if self.flip[a] {
                (self.dims[a] - 1) as f64 * self.spacing[a] - p[a]
            } else {
                p[a]
            };
        }
        o
    }
    /// Canonical voxel to original.
    fn voxel_back(&self, v: [usize; 3]) -> [usize; 3] {
        let mut o = [0; 3];
        for a in 0..3 {
            o[self.perm[a]] = if self.flip[a] {
                self.dims[a] - 1 - v[a]
            } else {
                v[a]
            };
        }
        o
    }
    /// A canonical box (both corners inside) in the original storage.
    fn box_back(&self, lo: [usize; 3], hi: [usize; 3]) -> ([usize; 3], [usize; 3]) {
        let (a, b) = (self.voxel_back(lo), self.voxel_back(hi));
        (
            [0, 1, 2].map(|i| a[i].min(b[i])),
            [0, 1, 2].map(|i| a[i].max(b[i])),
        )
    }
    /// The (perm, flip) of `reoriented` that undoes this one.
    fn inverse(&self) -> ([usize; 3], [bool; 3]) {
        let mut inv = [0; 3];
        for a in 0..3 {
            inv[self.perm[a]] = a;
        }
        (inv, [0, 1, 2].map(|b| self.flip[inv[b]]))
    }
}

impl Segmentation {
    /// The largest gas region left out of the colon automatically (ml of gas), if any holds
    /// at least `min_ml`: the flight's end is then doubtful (not the user's choice).
    pub fn largest_left_out(&self, min_ml: f64) -> Option<&SegmentReport> {
        self.segments
            .iter()
            .filter(|s| !s.kept && s.gas_ml >= min_ml && s.reason.as_deref() != Some(EXCLUDED))
            .max_by(|a, b| a.gas_ml.total_cmp(&b.gas_ml))
    }

    /// The segmentation of a scan in its canonical storage `canon`, in the original storage
    /// (of geometry `geom`).
    fn stored_back(mut self, canon: &Canonical, geom: &crate::Geometry) -> Result<Segmentation> {
        let (inv, iflip) = canon.inverse();
        let mut lumen = self.lumen.reoriented(inv, iflip)?;
        *lumen.geometry_mut() = geom.clone();
        self.lumen = lumen;
        self.seed_voxel = canon.voxel_back(self.seed_voxel);
        self.cecum_voxel = self.cecum_voxel.map(|v| canon.voxel_back(v));
        let (lo, hi) = canon.box_back(self.extent[0], self.extent[1]);
        self.extent = [lo, hi];
        for c in &mut self.components {
            c.centroid_mm = canon.mm_back(c.centroid_mm);
            (c.bbox_lo, c.bbox_hi) = canon.box_back(c.bbox_lo, c.bbox_hi);
        }
        let back = |voxels: &[usize]| {
            let mut out: Vec<usize> = voxels
                .iter()
                .map(|&i| {
                    let v = canon.voxel_back(crate::volume::grid_ijk(canon.dims, i));
                    geom.index(v[0], v[1], v[2])
                })
                .collect();
            out.sort_unstable();
            out
        };
        for g in &mut self.gaps {
            g.voxels = back(&g.voxels);
        }
        self.pools_grown = back(&self.pools_grown);
        Ok(self)
    }
}

fn segment_axial(
    vol: &Volume<i16>,
    opts: &SegmentOptions,
    from_mask: bool,
) -> Result<Segmentation> {
    let fluid_hu = opts.fluid_hu.filter(|_| !from_mask);
    // Air, its statistics and the bright runs of tagged fluid, all in one pass over the values.
    let (runs, bright) = if from_mask {
        extract_runs(vol, Test::NonZero, None)
    } else {
        extract_runs(vol, Test::Below(opts.air_hu), fluid_hu)
    };
    let inside = if from_mask {
        vec![true; runs.runs.len()]
    } else {
        inside_body(&runs, vol.dims())
    };
    let mut labels = UnionFind::new(runs.runs.len());
    connect_3d(&runs, &inside, vol.dims(), &mut labels);
    let (mut comps, mut run_comp) = component_stats(&runs, &inside, vol, &mut labels, from_mask);
    classify_lungs(&mut comps, from_mask);
    let voxel_ml = vol.spacing().iter().product::<f64>() / 1000.0;
    let tubes = if from_mask {
        Vec::new()
    } else {
        let mut tubes = tube::find(
            &runs,
            &inside,
            &run_comp,
            |c| c != u32::MAX && comps[c as usize].kind != ComponentKind::Lung,
            vol.dims(),
            vol.spacing(),
            inferior_slice(vol),
        );
        // A tube opens into the rectum: a colon segment's gas beyond its tip.
        tubes.retain(|t| {
            let beyond = comps[t.comp as usize]
                .voxels
                .saturating_sub(run_voxels(&runs, &t.runs));
            beyond as f64 * voxel_ml >= opts.chain.min_segment_ml
        });
        tubes
    };
    for t in &tubes {
        // Its air is the outside's, carried in.
        t.runs.iter().for_each(|&r| run_comp[r] = u32::MAX);
    }
    let gas_at =
        |what: &str, mm: &DVec3| gas_component(&comps, &runs, &run_comp, vol, *mm, what, opts);
    let seed_comps = opts
        .seeds_mm
        .iter()
        .map(|mm| gas_at("the seed", mm))
        .collect::<Result<Vec<_>>>()?;
    let exclude_comps = opts
        .exclude_mm
        .iter()
        .map(|mm| gas_at("the point to exclude", mm))
        .collect::<Result<Vec<_>>>()?;
    let mut warnings = Vec::new();

    // Working labels in the volume that becomes the lumen.
    let mut work = Volume::filled(vol.geometry().clone(), 0u8)?;
    let is_gas = |c: u32| c != u32::MAX && comps[c as usize].kind != ComponentKind::Lung;
    paint(&mut work, &runs, |r| is_gas(run_comp[r]).then_some(GAS));
    let Some(gas_box) = runs_box(&runs, vol.dims(), |r| is_gas(run_comp[r])) else {
        return Err(no_colon(&comps, opts, from_mask));
    };
    let mut orientation = match opts.position {
        Some((p, src)) => Orientation::new(p, src),
        None => Orientation::new(PatientPosition::Hfs, PositionSource::Assumed),
    };
    // Fluid lies below the gas, at most a pool's depth away: everything from here on happens
    // in this box.
    let cbox = match bright {
        Some(_) => gas_box.grown(
            vol.spacing()
                .map(|s| (fluid::MAX_DEPTH_MM / s).ceil() as usize + 2),
            vol.dims(),
        ),
        None => gas_box,
    };
    let mut pooled = 0;
    let mut pool_rows = Vec::new();
    if let Some(bright) = &bright {
        let rows = label_rows(
            &runs,
            |r| is_gas(run_comp[r]),
            bright,
            &cbox,
            vol.dims()[0],
            |_, _, _| true,
        );
        // A level lies within a layer's thickness of gas: only gas near bright runs and bright
        // runs near gas (not bone, most of them) are looked at for it.
        let all = |_: usize| true;
        let near_gas = |x: (u32, u32), j: usize, k: usize| {
            runs_near(&runs, &|r| is_gas(run_comp[r]), x, j, k, 3)
        };
        let gas_near_bright = |r: usize| {
            is_gas(run_comp[r]) && {
                let (j, k) = row_of(&runs, r);
                runs_near(bright, &all, (runs.runs[r].x0, runs.runs[r].x1), j, k, 3)
            }
        };
        let near = || {
            label_rows(
                &runs,
                gas_near_bright,
                bright,
                &cbox,
                vol.dims()[0],
                near_gas,
            )
        };
        if opts.position.is_none()
            && let Some(g) = fluid::gravity_from_levels(&near(), vol.geometry(), &cbox)
        {
            orientation = Orientation::new(
                PatientPosition::from_gravity(g),
                PositionSource::AirFluidLevels,
            );
        }
        let threshold = fluid_hu.unwrap_or(i16::MAX);
        let marks = fluid::pools(&rows, vol.geometry(), &cbox, orientation.gravity(), |v| {
            vol.data()[v] >= threshold
        });
        pooled = marks.len();
        pool_rows = vec![false; vol.dims()[1] * vol.dims()[2]];
        let nx = vol.dims()[0];
        for (idx, label) in marks {
            work.data_mut()[idx] = label;
            pool_rows[idx / nx] = true;
        }
    }
    if orientation.source == PositionSource::Assumed {
        warnings.push(if from_mask {
            "patient position unknown (a mask has no fluid levels): supine assumed; give --position if not".to_string()
        } else {
            "patient position unknown (no PatientPosition, no air–fluid level seen): supine assumed; give --position if not".to_string()
        });
    }

    // Compartments: gas with its pools and layers.
    // Without pools they are the gas components, from their runs; with pools, from the labels.
    let cruns = if pooled > 0 {
        let scan = |j: usize, k: usize| {
            pool_rows[j + vol.dims()[1] * k] || runs.row(j, k).any(|r| is_gas(run_comp[r]))
        };
        work_runs(&work, &cbox, scan, |x| x == GAS || x == POOL || x == LAYER)
    } else {
        runs.filtered(|r| is_gas(run_comp[r]))
    };
    let mut cuf = UnionFind::new(cruns.runs.len());
    connect_3d(&cruns, &vec![true; cruns.runs.len()], vol.dims(), &mut cuf);
    let frame = PatientFrame::of(vol.geometry());
    let (compartments, crun_comp) = compartment_stats(
        &cruns,
        (pooled > 0).then_some(&work),
        &mut cuf,
        vol.geometry(),
        frame.inferior(),
    );
    let comp_at = |v: [usize; 3]| cruns.at(v).map(|r| crun_comp[r]).filter(|&c| c != u32::MAX);
    // Every gas component's compartment.
    let mut gas_compartment: Vec<Option<u32>> = vec![None; comps.len()];
    for (r, &c) in run_comp.iter().enumerate() {
        if is_gas(c) && gas_compartment[c as usize].is_none() {
            let (j, k) = row_of(&runs, r);
            gas_compartment[c as usize] = comp_at([runs.runs[r].x0 as usize, j, k]);
        }
    }
    let seeded: Vec<u32> = seed_comps
        .iter()
        .filter_map(|&c| gas_compartment[c])
        .collect();
    let excluded: Vec<u32> = exclude_comps
        .iter()
        .filter_map(|&c| gas_compartment[c])
        .collect();
    if let Some(i) = seeded.iter().position(|c| excluded.contains(c)) {
        return Err(Error::invalid(format!(
            "the seed {} lies in gas also excluded (by another point)",
            vol.geometry().describe_point(opts.seeds_mm[i])
        )));
    }
    // Crevices: gas thin all over, a skin fold's (closed over at the skin in every axial
    // slice, it is not found as outside air), not bowel.
    let crevice: Vec<bool> = compartments
        .iter()
        .enumerate()
        .map(|(c, comp)| {
            let ml = comp.gas_voxels as f64 * voxel_ml;
            (opts.chain.min_segment_ml..=CREVICE_MAX_ML).contains(&ml)
                && inscribed_radius_mm(&cruns, &crun_comp, c as u32, &comp.bbox, vol.spacing())
                    < CREVICE_MM
        })
        .collect();
    // A segment: big enough and no crevice, or seeded; never excluded.
    let candidate = |c: u32| {
        !excluded.contains(&c)
            && ((compartments[c as usize].gas_voxels as f64 * voxel_ml
                >= opts.chain.min_segment_ml
                && !crevice[c as usize])
                || seeded.contains(&c))
    };
    // The rectum: the candidate holding the lowest voxel in the patient frame (a seed makes
    // its gas a candidate; where it lies, not the seed, decides the rectum).
    let rectum = (0..compartments.len() as u32)
        .filter(|&c| candidate(c))
        .max_by(|&a, &b| {
            compartments[a as usize]
                .lowest_height
                .total_cmp(&compartments[b as usize].lowest_height)
                .then(b.cmp(&a))
        })
        .ok_or_else(|| no_colon(&comps, opts, from_mask))?;

    let mut coarse = Coarse::new(vol.dims(), vol.spacing());
    for k in cbox.lo[2]..=cbox.hi[2] {
        for j in cbox.lo[1]..=cbox.hi[1] {
            for r in cruns.row(j, k) {
                let c = crun_comp[r];
                if c == rectum || candidate(c) {
                    coarse.mark_run(
                        cruns.runs[r].x0 as usize,
                        cruns.runs[r].x1 as usize,
                        j,
                        k,
                        c,
                    );
                }
            }
        }
    }
    let dims = vol.dims();
    let ct = (!from_mask).then_some(vol);
    // The voxel of compartment c nearest block b's middle (of its gas only, with `gas`).
    let voxel_of_comp = |block: usize, c: u32, gas: bool| {
        let bx = coarse.voxels_of(block, dims);
        let mid = [0, 1, 2].map(|a| (bx.lo[a] + bx.hi[a]) / 2);
        let mut best: Option<(usize, [usize; 3])> = None;
        for k in bx.lo[2]..=bx.hi[2] {
            for j in bx.lo[1]..=bx.hi[1] {
                for i in bx.lo[0]..=bx.hi[0] {
                    if (!gas || work.get(i, j, k) == GAS) && comp_at([i, j, k]) == Some(c) {
                        let d = (0..3)
                            .map(|a| mid[a].abs_diff([i, j, k][a]).pow(2))
                            .sum::<usize>();
                        if best.is_none_or(|b| d < b.0) {
                            best = Some((d, [i, j, k]));
                        }
                    }
                }
            }
        }
        best.map(|b| b.1)
    };
    let voxel_in = |block: usize, c: u32| voxel_of_comp(block, c, false);
    let bridge = |from: usize, to: usize, a: u32, b: u32| {
        let (va, vb) = (voxel_in(from, a)?, voxel_in(to, b)?);
        let own = |v: [usize; 3]| comp_at(v).is_some_and(|c| c == a || c == b);
        let other =
            |v: [usize; 3]| matches!(work.get(v[0], v[1], v[2]), GAS | POOL | LAYER) && !own(v);
        bridge::cheapest_path(ct, dims, vol.spacing(), va, vb, own, other)
    };
    let roles = roles(&compartments, rectum, candidate, vol.geometry(), voxel_ml);
    let course = Course::new(
        vol.geometry(),
        colon_box(
            &compartments,
            rectum,
            |c| roles[c as usize] == Role::Major,
            vol.geometry(),
        ),
    );
    let mut ch: Chain = chain::chain(
        &coarse,
        &compartments,
        rectum,
        &roles,
        &course,
        &opts.chain,
        &bridge,
    );
    // The pole of the cecum's gas: fluid may lie lower, and is cleansed or cut away.
    let cecum_voxel = ch.cecum.as_ref().and_then(|c| {
        c.blocks
            .iter()
            .find_map(|&b| voxel_of_comp(b, c.comp, true))
    });
    // A seed's gas is colon, wherever the chain went: joined at the chain's end.
    for &s in &seeded {
        if ch.links.iter().any(|l| l.comp == s) {
            continue;
        }
        let last = ch.links.last().map_or(0, |l| l.exit);
        let at = coarse.centre_mm(last);
        let entry = [coarse.block_of(compartments[s as usize].lowest)]
            .into_iter()
            .chain([coarse
                .farthest(s, coarse.block_of(compartments[s as usize].lowest))
                .0])
            .min_by(|&x, &y| {
                coarse
                    .centre_mm(x)
                    .distance(at)
                    .total_cmp(&coarse.centre_mm(y).distance(at))
            })
            .unwrap_or(0);
        let from = ch.links.last().map(|l| l.comp).unwrap_or(rectum);
        if let Some(p) = bridge(last, entry, from, s) {
            warnings.push(format!("the seed's gas was not joined to the colon by itself: joined to its end through {:.0} mm of tissue", p.length_mm));
            ch.links.push(chain::Link {
                comp: s,
                entry,
                exit: coarse.farthest(s, entry).0,
            });
            ch.gaps.push(p);
            ch.left.retain(|(c, _)| *c != s);
        } else {
            warnings.push(format!("the seed's gas ({:.0} ml) could not be joined to the colon: no way to it through the CT", compartments[s as usize].gas_voxels as f64 * voxel_ml));
        }
    }

    for (c, why) in &mut ch.left {
        if excluded.contains(c) {
            *why = Left::Excluded;
        }
    }

    let colon_gas_ml: f64 = ch
        .links
        .iter()
        .map(|l| compartments[l.comp as usize].gas_voxels as f64 * voxel_ml)
        .sum();
    if seeded.is_empty() && colon_gas_ml < opts.min_colon_ml {
        return Err(no_colon(&comps, opts, from_mask));
    }

    // The lumen: chained compartments, bridges and the fluid filling the stretches they cross.
    let geom = vol.geometry().clone();
    let bridge_radius_mm = 3.0f64.max(1.5 * vol.spacing().iter().cloned().fold(0.0, f64::max));
    let mut added = Vec::new();
    let mut gap_voxels: Vec<Vec<usize>> = Vec::new();
    for p in &ch.gaps {
        let from = added.len();
        if let (Some(ct), Some(t)) = (ct, fluid_hu) {
            fill_fluid(
                &mut work,
                &p.voxels,
                FILL_MM,
                |i| ct.data()[i] >= t,
                &mut added,
            );
        }
        lay_bridge(&mut work, &p.voxels, bridge_radius_mm, &mut added);
        let mut v = added[from..].to_vec();
        v.sort_unstable();
        gap_voxels.push(v);
    }
    let in_colon: Vec<bool> = {
        let mut v = vec![false; compartments.len()];
        ch.links.iter().for_each(|l| v[l.comp as usize] = true);
        v
    };
    // A compartment's voxels that are not gas are its pool and layer.
    let colon = || ch.links.iter().map(|l| &compartments[l.comp as usize]);
    let mut fluid_voxels: usize = colon().map(|c| c.voxels - c.gas_voxels).sum();
    let colon_voxels: usize = colon().map(|c| c.voxels).sum();
    let mut lumen_box: Option<Bbox> = colon().map(|c| c.bbox).reduce(|a, b| a.union(&b));
    for &v in &added {
        let ijk = geom.ijk(v);
        let b = Bbox { lo: ijk, hi: ijk };
        lumen_box = Some(lumen_box.map_or(b, |x| x.union(&b)));
    }
    let bridge_voxels = added.len();
    if ct.is_some() {
        fluid_voxels += added
            .iter()
            .filter(|&&v| vol.data()[v] >= fluid_hu.unwrap_or(i16::MAX))
            .count();
    }
    // Back to 0/1: every label lies in a compartment's runs, or on a bridge.
    let kept = |r: usize| crun_comp[r] != u32::MAX && in_colon[crun_comp[r] as usize];
    paint(&mut work, &cruns, |r| Some(kept(r) as u8));
    for &v in &added {
        work.data_mut()[v] = 1;
    }
    // Whole pools: the colon's fluid beyond the columns under its air.
    let grown = match (ct, fluid_hu) {
        (Some(ct), Some(t)) => whole_pools(
            &mut work,
            ct,
            lumen_box,
            (opts.air_hu, t),
            orientation.gravity(),
        ),
        _ => Vec::new(),
    };
    for &v in &grown {
        let ijk = geom.ijk(v);
        lumen_box = lumen_box.map(|x| x.union(&Bbox { lo: ijk, hi: ijk }));
    }
    fluid_voxels += grown.len();
    let lumen = work;
    let lumen_box = lumen_box.ok_or_else(|| Error::invalid("the colon holds no voxels"))?;

    // The source side: the middle of the rectum's lowest 2 mm.
    let seed_voxel = lowest_middle(
        &cruns,
        &crun_comp,
        &compartments[rectum as usize],
        rectum,
        &geom,
        frame.inferior(),
    );

    // Reports.
    let order_of = |c: u32| ch.links.iter().position(|l| l.comp == c);
    let colon_lps = colon_box(&compartments, rectum, |c| order_of(c).is_some(), &geom);
    let mut classes = vec![ComponentKind::Other; compartments.len()];
    for (c, comp) in compartments.iter().enumerate() {
        classes[c] = if order_of(c as u32).is_some() {
            ComponentKind::Colon
        } else {
            classify(comp, &geom, &colon_lps, voxel_ml)
        };
    }
    let mut segments: Vec<SegmentReport> = Vec::new();
    // Named by where they lie along the whole colon's course.
    let named = Course::new(&geom, colon_lps);
    for (i, l) in ch.links.iter().enumerate() {
        let comp = &compartments[l.comp as usize];
        let names: Vec<&str> = [
            coarse.centre_mm(l.entry),
            comp.centroid_mm(),
            coarse.centre_mm(l.exit),
        ]
        .iter()
        .map(|&p| named.name(p))
        .fold(Vec::new(), |mut v, n| {
            if v.last() != Some(&n) {
                v.push(n);
            }
            v
        });
        segments.push(segment_report(
            comp,
            &geom,
            names.join("–"),
            ComponentKind::Colon,
            Some(i),
            None,
            voxel_ml,
        ));
    }
    let mut others: Vec<(u32, Left)> = ch.left.clone();
    others.sort_by(|a, b| {
        compartments[b.0 as usize]
            .gas_voxels
            .cmp(&compartments[a.0 as usize].gas_voxels)
            .then(a.0.cmp(&b.0))
    });
    for (c, why) in others {
        let comp = &compartments[c as usize];
        if (comp.gas_voxels as f64 * voxel_ml) < opts.min_report_ml {
            continue;
        }
        let kind = classes[c as usize];
        let reason = match why {
            Left::TooSmall if crevice[c as usize] => format!(
                "{:.1} ml of gas in a crevice less than {:.0} mm across (a skin fold), not bowel",
                comp.gas_voxels as f64 * voxel_ml,
                2.0 * CREVICE_MM
            ),
            Left::TooSmall => format!(
                "{:.1} ml of gas, less than a colon segment's {} ml",
                comp.gas_voxels as f64 * voxel_ml,
                opts.chain.min_segment_ml
            ),
            Left::TooFar(d) if d.is_finite() => format!(
                "its nearest end is {d:.0} mm from the colon's end (more than {:.0} mm)",
                opts.chain.max_gap_mm
            ),
            Left::TooFar(_) => "not reached from the colon's end".to_string(),
            Left::BridgeTooDear { gap_mm, cost } => format!(
                "the way to it ({gap_mm:.0} mm) crosses fat or bone, not collapsed bowel (cost {cost:.1} per mm)"
            ),
            Left::Excluded => EXCLUDED.to_string(),
        };
        let label = match kind {
            ComponentKind::SmallBowel => "small bowel",
            ComponentKind::Stomach => "stomach",
            _ => "other",
        };
        segments.push(segment_report(
            comp,
            &geom,
            label.to_string(),
            kind,
            None,
            Some(reason),
            voxel_ml,
        ));
    }
    for t in &tubes {
        segments.push(tube_report(t, &runs, &geom, voxel_ml));
    }
    let mut gaps = Vec::new();
    for (i, p) in ch.gaps.iter().enumerate() {
        let ends = (p.voxels[0], p.voxels[p.voxels.len() - 1]);
        let lps = |v: [usize; 3]| {
            geom.index_to_patient(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
                .to_array()
        };
        let voxels = std::mem::take(&mut gap_voxels[i]);
        gaps.push(Gap {
            between: [i, i + 1],
            length_mm: p.length_mm,
            from_lps_mm: lps(ends.0),
            to_lps_mm: lps(ends.1),
            mean_cost: p.mean_cost,
            voxels,
        });
        warnings.push(format!(
            "collapsed or fluid-filled stretch bridged: {:.0} mm between the {} and the {} segment, from LPS ({:.0}, {:.0}, {:.0})",
            p.length_mm,
            segments[i].label,
            segments[i + 1].label,
            lps(ends.0)[0],
            lps(ends.0)[1],
            lps(ends.0)[2]
        ));
    }
    for s in segments
        .iter()
        .filter(|s| !s.kept && s.gas_ml >= LARGE_LEFT_ML && s.reason.as_deref() != Some(EXCLUDED))
    {
        warnings.push(format!(
            "{:.0} ml of gas ({}) left out of the colon: {}",
            s.gas_ml,
            s.label,
            s.reason.as_deref().unwrap_or("")
        ));
    }
    // Gas components, labelled by their compartment.
    for (c, comp) in comps.iter_mut().enumerate() {
        if comp.kind == ComponentKind::Lung {
            continue;
        }
        comp.kind = gas_compartment[c].map_or(ComponentKind::Other, |x| classes[x as usize]);
    }
    let lumen_voxels = colon_voxels + bridge_voxels + grown.len();
    let mut pools_grown = grown;
    pools_grown.sort_unstable();
    let (components, small) = report(comps, opts.min_report_ml);
    Ok(Segmentation {
        lumen,
        lumen_voxels,
        components,
        small_components: small,
        fluid_voxels,
        from_mask,
        seed_voxel,
        extent: [lumen_box.lo, lumen_box.hi],
        orientation,
        segments,
        gaps,
        warnings,
        bridge_radius_mm,
        cecum_voxel,
        pools_grown,
    })
}

/// Gas from this size on (ml) that is neither lung nor stomach is colon, wherever it lies: in
/// an insufflated exam the colon's compartments are the largest gas below the diaphragm.
const MAJOR_ML: f64 = 200.0;

/// Each compartment's role in the chain: major (colon, [`MAJOR_ML`] of gas or more, unless
/// it lies where the stomach does), minor (a candidate segment) or out.
fn roles(
    comps: &[Compartment],
    rectum: u32,
    candidate: impl Fn(u32) -> bool,
    geom: &crate::Geometry,
    voxel_ml: f64,
) -> Vec<Role> {
    let big = |c: u32| {
        c != rectum && candidate(c) && comps[c as usize].gas_voxels as f64 * voxel_ml >= MAJOR_ML
    };
    let all = colon_box(comps, rectum, big, geom);
    (0..comps.len() as u32)
        .map(|c| {
            if !candidate(c) && c != rectum {
                Role::Out
            } else if big(c)
                && !stomach_like(&comps[c as usize], geom, &all)
                && !flat(&comps[c as usize], geom)
            {
                Role::Major
            } else {
                Role::Minor
            }
        })
        .collect()
}

/// All of its gas in the top 40 % of the large gas's box, its middle on the patient's left:
/// where the stomach lies under the left diaphragm (a splenic flexure alone in its own
/// compartment would look the same, and is then given back by a seed).
fn stomach_like(comp: &Compartment, geom: &crate::Geometry, all: &[DVec3; 2]) -> bool {
    let b = lps_box(geom, &comp.bbox);
    let c = geom.local_to_patient(comp.centroid_mm());
    let span = all[1] - all[0];
    b[0].z > all[0].z + 0.6 * span.z && c.x > all[0].x + 0.5 * span.x
}

/// Thinner than [`MIN_BOX_MM`] along some axis of the patient frame: a sheet of gas (air over
/// the water of a phantom's tank, under a prone patient's skin folds), not a bowel.
fn flat(comp: &Compartment, geom: &crate::Geometry) -> bool {
    let b = lps_box(geom, &comp.bbox);
    (b[1] - b[0]).min_element() < MIN_BOX_MM
}

/// A colon compartment's box is at least this wide along every axis (mm).
const MIN_BOX_MM: f64 = 15.0;

/// The LPS box of the rectum's compartment and those where `with(c)`.
fn colon_box(
    comps: &[Compartment],
    rectum: u32,
    with: impl Fn(u32) -> bool,
    geom: &crate::Geometry,
) -> [DVec3; 2] {
    let b = (0..comps.len() as u32)
        .filter(|&c| with(c))
        .fold(comps[rectum as usize].bbox, |a, c| {
            a.union(&comps[c as usize].bbox)
        });
    lps_box(geom, &b)
}

/// Gas of a compartment (up to [`CREVICE_MAX_ML`]) whose widest inscribed ball is narrower
/// than this radius (mm) lies in a crevice: a skin fold (1–2 mm), not a bowel, whose gas
/// even collapsed holds bubbles wider than 5 mm.
const CREVICE_MM: f64 = 2.5;
const CREVICE_MAX_ML: f64 = 50.0;

/// The radius (mm) of the widest ball inside compartment `c` (its runs in `runs`, within
/// `bbox`).
fn inscribed_radius_mm(
    runs: &Runs,
    run_comp: &[u32],
    c: u32,
    bbox: &Bbox,
    spacing: [f64; 3],
) -> f64 {
    // One voxel of margin: the wall all round.
    let dims = bbox.widths().map(|w| w + 2);
    let Ok(g) = crate::Geometry::new(dims, spacing, [0.0; 3]) else {
        return f64::INFINITY;
    };
    let Ok(mut mask) = Volume::filled(g, 0u8) else {
        return f64::INFINITY;
    };
    for k in bbox.lo[2]..=bbox.hi[2] {
        for j in bbox.lo[1]..=bbox.hi[1] {
            for r in runs.row(j, k).filter(|&r| run_comp[r] == c) {
                let Run { x0, x1 } = runs.runs[r];
                let row = mask
                    .geometry()
                    .index(0, j - bbox.lo[1] + 1, k - bbox.lo[2] + 1);
                let from = row + x0 as usize - bbox.lo[0] + 1;
                mask.data_mut()[from..from + (x1 - x0) as usize].fill(1);
            }
        }
    }
    let grid = crate::grid::BoxGrid::around([[0; 3], dims.map(|d| d - 1)], 0, dims);
    let ds = crate::distance::distance_to_wall_in(&mask, grid);
    ds.data.iter().cloned().fold(0.0f32, f32::max) as f64
}

/// Why a segment the user excluded is not in the colon.
const EXCLUDED: &str = "excluded by the user";
/// Gas left out of the colon from this size on (ml) gets a warning.
const LARGE_LEFT_ML: f64 = 20.0;
/// Soft tissue's HU: the bowel wall between two pools.
const TISSUE_HU: i16 = 40;
/// Fluid filling a bridged stretch is taken this far (mm) from the bridge's path.
const FILL_MM: f64 = 25.0;

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

/// The runs of `test` (the air, with HU statistics when it is `Below`) and, with `bright`, the
/// runs at or above it, from one read of the values.
fn extract_runs(vol: &Volume<i16>, test: Test, bright: Option<i16>) -> (Runs, Option<Runs>) {
    let [nx, ny, nz] = vol.dims();
    let stats = matches!(test, Test::Below(_));
    // One task per slice; concatenated in slice order so the result is thread-independent.
    let per_slice: Vec<(SliceRuns, Option<SliceRuns>)> = (0..nz)
        .into_par_iter()
        .map_init(
            || (vec![0u64; nx.div_ceil(64)], vec![0u64; nx.div_ceil(64)]),
            |words, k| {
                let slice = vol.slice_k(k);
                let mut air = SliceRuns::with_rows(ny);
                let mut fluid = bright.map(|_| SliceRuns::with_rows(ny));
                for row in slice.chunks_exact(nx) {
                    let tests = (test, bright.map(Test::AtLeast));
                    row_bits(row, tests, words);
                    air.add_row(
                        &words.0,
                        |x0, x1| if stats { run_stats(row, x0, x1) } else { None },
                    );
                    if let Some(f) = &mut fluid {
                        f.add_row(&words.1, |_, _| None);
                    }
                }
                (air, fluid)
            },
        )
        .collect();
    let (air, fluid): (Vec<SliceRuns>, Vec<Option<SliceRuns>>) = per_slice.into_iter().unzip();
    let fluid = bright.map(|_| Runs::concat(fluid.into_iter().flatten(), ny));
    (Runs::concat(air, ny), fluid)
}

/// One slice's runs, row by row.
struct SliceRuns {
    runs: Vec<Run>,
    counts: Vec<u32>,
    hu_sum: Vec<i64>,
    dark: Vec<u32>,
}

impl SliceRuns {
    fn with_rows(ny: usize) -> Self {
        SliceRuns {
            runs: Vec::new(),
            counts: Vec::with_capacity(ny),
            hu_sum: Vec::new(),
            dark: Vec::new(),
        }
    }

    /// The runs of one row's bits, each with `stats(x0, x1)` ((0, 0) where it gives none).
    fn add_row(&mut self, words: &[u64], stats: impl Fn(u32, u32) -> Option<(i64, u32)>) {
        let before = self.runs.len();
        runs_of_bits(words, |x0, x1| {
            self.runs.push(Run { x0, x1 });
            let (sum, dark) = stats(x0, x1).unwrap_or((0, 0));
            self.hu_sum.push(sum);
            self.dark.push(dark);
        });
        self.counts.push((self.runs.len() - before) as u32);
    }
}

impl Runs {
    fn concat(slices: impl IntoIterator<Item = SliceRuns>, ny: usize) -> Runs {
        let mut out = Runs {
            runs: Vec::new(),
            row_start: vec![0],
            hu_sum: Vec::new(),
            dark: Vec::new(),
            ny,
        };
        for s in slices {
            for c in s.counts {
                let last = *out.row_start.last().unwrap_or(&0);
                out.row_start.push(last + c);
            }
            out.runs.extend(s.runs);
            out.hu_sum.extend(s.hu_sum);
            out.dark.extend(s.dark);
        }
        out
    }
}

/// HU sum and count of voxels darker than −950 HU of an air run, for telling bowel gas from
/// lung. Runs reaching the row's ends lie outside the body (step 2 drops them) and the air
/// outside is most of a scan's air: they get none.
fn run_stats(row: &[i16], x0: u32, x1: u32) -> Option<(i64, u32)> {
    if x0 == 0 || x1 as usize == row.len() {
        return None;
    }
    let seg = &row[x0 as usize..x1 as usize];
    // i32 holds the sum of a row (at most 65 536 values of magnitude ≤ 32 768).
    let sum: i32 = seg.iter().map(|&v| v as i32).sum();
    let dark = seg.iter().map(|&v| (v < -950) as u32).sum();
    Some((sum as i64, dark))
}

/// Bit x % 64 of word x / 64 of `words.0`: whether `tests.0` holds for `row[x]`; the same of
/// `words.1` for `tests.1`, if any (one read of the row for both); bits past the row are 0.
fn row_bits(row: &[i16], tests: (Test, Option<Test>), words: &mut (Vec<u64>, Vec<u64>)) {
    let (chunks, rest) = row.as_chunks::<64>();
    let (a, b) = (&mut words.0, &mut words.1);
    match tests {
        (t, None) => a
            .iter_mut()
            .zip(chunks)
            .for_each(|(w, c)| *w = simd::mask64(c, t)),
        (t, Some(u)) => {
            for ((wa, wb), c) in a.iter_mut().zip(b.iter_mut()).zip(chunks) {
                (*wa, *wb) = (simd::mask64(c, t), simd::mask64(c, u));
            }
        }
    }
    if !rest.is_empty() {
        let bits = |t: Test| {
            rest.iter()
                .enumerate()
                .fold(0u64, |w, (i, &v)| w | (t.holds(v) as u64) << i)
        };
        a[row.len() / 64] = bits(tests.0);
        if let Some(u) = tests.1 {
            b[row.len() / 64] = bits(u);
        }
    }
}

/// Calls `f(x0, x1)` for each run [x0, x1) of set bits, in order.
fn runs_of_bits(words: &[u64], mut f: impl FnMut(u32, u32)) {
    let (mut carry, mut start) = (0u64, 0u32);
    for (w, &word) in words.iter().enumerate() {
        // A bit of `edges` marks where the row changes: a run starts or ends there.
        let mut edges = word ^ (word << 1 | carry);
        carry = word >> 63;
        while edges != 0 {
            let b = edges.trailing_zeros();
            edges &= edges - 1;
            let x = 64 * w as u32 + b;
            if word >> b & 1 == 1 {
                start = x;
            } else {
                f(start, x);
            }
        }
    }
    if carry == 1 {
        f(start, 64 * words.len() as u32);
    }
}

/// Calls `f(a, b)` for every pair of runs, one in row `ra` and one in row `rb`, that share an x.
fn for_overlaps(
    runs: &Runs,
    ra: std::ops::Range<usize>,
    rb: std::ops::Range<usize>,
    mut f: impl FnMut(usize, usize),
) {
    let (mut a, mut b) = (ra.start, rb.start);
    while a < ra.end && b < rb.end {
        let (p, q) = (runs.runs[a], runs.runs[b]);
        if p.x0 < q.x1 && q.x0 < p.x1 {
            f(a, b);
        }
        if p.x1 < q.x1 {
            a += 1;
        } else {
            b += 1;
        }
    }
}

/// Step 2: per slice, runs 4-connected to the slice's border are outside air.
fn inside_body(runs: &Runs, dims: [usize; 3]) -> Vec<bool> {
    let [nx, ny, nz] = dims;
    let per_slice: Vec<Vec<bool>> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let first = runs.row(0, k).start;
            let last = runs.row(ny - 1, k).end;
            let mut uf = UnionFind::new(last - first);
            for j in 1..ny {
                for_overlaps(runs, runs.row(j - 1, k), runs.row(j, k), |a, b| {
                    uf.union(a - first, b - first)
                });
            }
            let mut outside = vec![false; last - first];
            for j in 0..ny {
                for r in runs.row(j, k) {
                    let run = runs.runs[r];
                    if j == 0 || j == ny - 1 || run.x0 == 0 || run.x1 as usize == nx {
                        let root = uf.find(r - first);
                        outside[root] = true;
                    }
                }
            }
            (0..last - first).map(|r| !outside[uf.find(r)]).collect()
        })
        .collect();
    per_slice.into_iter().flatten().collect()
}

/// Step 3: 6-connected components of the inside runs.
fn connect_3d(runs: &Runs, inside: &[bool], dims: [usize; 3], uf: &mut UnionFind) {
    let [_, ny, nz] = dims;
    for k in 0..nz {
        for j in 0..ny {
            let here = runs.row(j, k);
            if here.is_empty() {
                continue;
            }
            if j > 0 {
                for_overlaps(runs, runs.row(j - 1, k), here.clone(), |a, b| {
                    if inside[a] && inside[b] {
                        uf.union(a, b)
                    }
                });
            }
            if k > 0 {
                for_overlaps(runs, runs.row(j, k - 1), here.clone(), |a, b| {
                    if inside[a] && inside[b] {
                        uf.union(a, b)
                    }
                });
            }
        }
    }
}

/// Per component statistics; returns the components and, per run, its component (or MAX).
fn component_stats(
    runs: &Runs,
    inside: &[bool],
    vol: &Volume<i16>,
    uf: &mut UnionFind,
    from_mask: bool,
) -> (Vec<Component>, Vec<u32>) {
    let [_, ny, nz] = vol.dims();
    let sp = vol.spacing();
    let mut comp_of_root = vec![u32::MAX; runs.runs.len()];
    let mut run_comp = vec![u32::MAX; runs.runs.len()];
    #[derive(Default, Clone)]
    struct Acc {
        n: usize,
        sum: [f64; 3],
        lo: [usize; 3],
        hi: [usize; 3],
        hu: i64,
        dark: u64,
    }
    let mut acc: Vec<Acc> = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                if !inside[r] {
                    continue;
                }
                let root = uf.find(r);
                if comp_of_root[root] == u32::MAX {
                    comp_of_root[root] = acc.len() as u32;
                    acc.push(Acc {
                        lo: [usize::MAX; 3],
                        ..Default::default()
                    });
                }
                let c = comp_of_root[root];
                run_comp[r] = c;
                let a = &mut acc[c as usize];
                let run = runs.runs[r];
                let len = (run.x1 - run.x0) as usize;
                a.n += len;
                a.sum[0] += (run.x0 as f64 + run.x1 as f64 - 1.0) * 0.5 * len as f64;
                a.sum[1] += (j * len) as f64;
                a.sum[2] += (k * len) as f64;
                a.lo = [a.lo[0].min(run.x0 as usize), a.lo[1].min(j), a.lo[2].min(k)];
                a.hi = [
                    a.hi[0].max(run.x1 as usize - 1),
                    a.hi[1].max(j),
                    a.hi[2].max(k),
                ];
                a.hu += runs.hu_sum[r];
                a.dark += runs.dark[r] as u64;
            }
        }
    }
    let voxel_ml = sp[0] * sp[1] * sp[2] / 1000.0;
    let comps = acc
        .into_iter()
        .map(|a| {
            let n = a.n as f64;
            Component {
                voxels: a.n,
                volume_ml: n * voxel_ml,
                centroid_mm: [
                    a.sum[0] / n * sp[0],
                    a.sum[1] / n * sp[1],
                    a.sum[2] / n * sp[2],
                ],
                bbox_lo: a.lo,
                bbox_hi: a.hi,
                mean_hu: (!from_mask).then(|| a.hu as f64 / n),
                dark_fraction: (!from_mask).then(|| a.dark as f64 / n),
                kind: ComponentKind::Other,
            }
        })
        .collect();
    (comps, run_comp)
}

/// Step 4: lung parenchyma is air mixed with tissue; bowel gas is nearly pure air.
fn classify_lungs(comps: &mut [Component], from_mask: bool) {
    if from_mask {
        return;
    }
    for c in comps.iter_mut() {
        if c.volume_ml > 1.0 && c.dark_fraction.unwrap_or(1.0) < 0.3 {
            c.kind = ComponentKind::Lung;
        }
    }
}

/// The gas component holding a point the user gave (`what`: "the seed", ...), or an error
/// that says why there is none.
fn gas_component(
    comps: &[Component],
    runs: &Runs,
    run_comp: &[u32],
    vol: &Volume<i16>,
    mm: DVec3,
    what: &str,
    opts: &SegmentOptions,
) -> Result<usize> {
    let at = vol.geometry().describe_point(mm);
    let [i, j, k] = voxel_of(vol, mm)
        .ok_or_else(|| Error::invalid(format!("{what} {at} lies outside the volume")))?;
    match runs.at([i, j, k]).map(|r| run_comp[r]) {
        Some(c) if c != u32::MAX && comps[c as usize].kind != ComponentKind::Lung => Ok(c as usize),
        Some(c) if c != u32::MAX => Err(Error::invalid(format!(
            "{what} {at} lies in a lung, not in the bowel"
        ))),
        Some(_) => Err(Error::invalid(format!(
            "{what} {at} lies in air outside the body"
        ))),
        None => Err(Error::invalid(format!(
            "{what} {at} is not in gas (HU {} ≥ {})",
            vol.get(i, j, k),
            opts.air_hu
        ))),
    }
}

/// The error when no gas is big enough to be a colon.
fn no_colon(comps: &[Component], opts: &SegmentOptions, from_mask: bool) -> Error {
    let biggest = comps
        .iter()
        .filter(|c| c.kind != ComponentKind::Lung)
        .map(|c| c.volume_ml)
        .fold(0.0, f64::max);
    if from_mask {
        return Error::invalid(if comps.is_empty() {
            "the mask holds no lumen: every voxel is 0".to_string()
        } else {
            format!(
                "the mask's largest lumen region is {biggest:.1} ml, too small for a colon (at least {} ml expected)",
                opts.min_colon_ml
            )
        });
    }
    Error::invalid(format!(
        "no colon lumen found: the largest gas inside the body, lungs left out, is {biggest:.1} ml (at least {} ml expected; is this a CT colonography? a --seed picks any gas)",
        opts.min_colon_ml
    ))
}

fn voxel_of(vol: &Volume<i16>, mm: DVec3) -> Option<[usize; 3]> {
    let ijk = vol.geometry().local_to_index(mm).round();
    vol.geometry()
        .contains_index(ijk)
        .then_some([ijk.x as usize, ijk.y as usize, ijk.z as usize])
}

/// (j, k) of run `r`'s row.
fn row_of(runs: &Runs, r: usize) -> (usize, usize) {
    let row = runs.row_start.partition_point(|&s| s as usize <= r) - 1;
    (row % runs.ny, row / runs.ny)
}

/// Writes `value(run)` over each run that has one, slice by slice in parallel.
fn paint(work: &mut Volume<u8>, runs: &Runs, value: impl Fn(usize) -> Option<u8> + Sync) {
    let [nx, ny, _] = work.dims();
    work.data_mut()
        .par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, slab)| {
            for j in 0..ny {
                for r in runs.row(j, k) {
                    if let Some(v) = value(r) {
                        let run = runs.runs[r];
                        slab[j * nx + run.x0 as usize..j * nx + run.x1 as usize].fill(v);
                    }
                }
            }
        });
}

/// The gas runs (where `gas(run)`) and the bright runs inside `bx`, merged row by row in x
/// order, for the fluid's line walks.
/// Bright runs only where `keep_bright((x0, x1), j, k)`.
fn label_rows(
    runs: &Runs,
    gas: impl Fn(usize) -> bool + Sync,
    bright: &Runs,
    bx: &Bbox,
    nx: usize,
    keep_bright: impl Fn((u32, u32), usize, usize) -> bool + Sync,
) -> fluid::LabelRows {
    let ny = runs.ny;
    let nz = (runs.row_start.len() - 1) / ny;
    let per_slice: Vec<(Vec<fluid::LabelRun>, Vec<u32>)> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let (mut out, mut counts) = (Vec::new(), Vec::with_capacity(ny));
            for j in 0..ny {
                let before = out.len();
                if (bx.lo[1]..=bx.hi[1]).contains(&j) && (bx.lo[2]..=bx.hi[2]).contains(&k) {
                    let g = runs
                        .row(j, k)
                        .filter(|&r| gas(r))
                        .map(|r| (runs.runs[r].x0, runs.runs[r].x1, GAS));
                    let b = bright
                        .row(j, k)
                        .map(|r| (bright.runs[r].x0, bright.runs[r].x1, fluid::BRIGHT))
                        .filter(|r| keep_bright((r.0, r.1), j, k));
                    out.extend(g.chain(b));
                    out[before..].sort_unstable_by_key(|r| r.0);
                }
                counts.push((out.len() - before) as u32);
            }
            (out, counts)
        })
        .collect();
    let mut rows = fluid::LabelRows {
        runs: Vec::new(),
        row_start: vec![0],
        dims: [nx, ny, nz],
    };
    for (r, c) in per_slice {
        for n in c {
            let last = *rows.row_start.last().unwrap_or(&0);
            rows.row_start.push(last + n);
        }
        rows.runs.extend(r);
    }
    rows
}

/// Whether a run where `keep(run)` lies within `d` voxels of x range `x` in row (j, k) or a
/// row up to `d` steps away along y or z.
fn runs_near(
    runs: &Runs,
    keep: &(impl Fn(usize) -> bool + Sync),
    x: (u32, u32),
    j: usize,
    k: usize,
    d: usize,
) -> bool {
    let nz = (runs.row_start.len() - 1) / runs.ny;
    let near = |b: usize, c: usize| {
        runs.row(b, c).any(|r| {
            keep(r) && runs.runs[r].x0 < x.1 + d as u32 && runs.runs[r].x1 + d as u32 > x.0
        })
    };
    (0..=d).any(|s| {
        let rows = [
            (j.wrapping_sub(s), k),
            (j + s, k),
            (j, k.wrapping_sub(s)),
            (j, k + s),
        ];
        rows.iter()
            .any(|&(b, c)| b < runs.ny && c < nz && near(b, c))
    })
}

/// The box of the runs where `keep(run)`.
fn runs_box(runs: &Runs, dims: [usize; 3], keep: impl Fn(usize) -> bool) -> Option<Bbox> {
    let [_, ny, nz] = dims;
    let mut b: Option<Bbox> = None;
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k).filter(|&r| keep(r)) {
                let run = runs.runs[r];
                let x = Bbox {
                    lo: [run.x0 as usize, j, k],
                    hi: [run.x1 as usize - 1, j, k],
                };
                b = Some(b.map_or(x, |y| y.union(&x)));
            }
        }
    }
    b
}

/// Runs of the working labels where `keep(label)`, inside `bx` (rows outside it are empty).
/// Only rows where `scan(j, k)` are read.
fn work_runs(
    work: &Volume<u8>,
    bx: &Bbox,
    scan: impl Fn(usize, usize) -> bool + Sync,
    keep: impl Fn(u8) -> bool + Sync,
) -> Runs {
    let [nx, ny, nz] = work.dims();
    let per_slice: Vec<SliceRuns> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let mut s = SliceRuns::with_rows(ny);
            for j in 0..ny {
                let before = s.runs.len();
                if (bx.lo[1]..=bx.hi[1]).contains(&j)
                    && (bx.lo[2]..=bx.hi[2]).contains(&k)
                    && scan(j, k)
                {
                    let row = &work.data()[nx * (j + ny * k)..nx * (j + ny * k + 1)];
                    for r in crate::volume::runs_where(&row[bx.lo[0]..=bx.hi[0]], &keep) {
                        s.runs.push(Run {
                            x0: (r.start + bx.lo[0]) as u32,
                            x1: (r.end + bx.lo[0]) as u32,
                        });
                        s.hu_sum.push(0);
                        s.dark.push(0);
                    }
                }
                s.counts.push((s.runs.len() - before) as u32);
            }
            s
        })
        .collect();
    Runs::concat(per_slice, ny)
}

/// Compartments (6-connected runs of gas, pool and layer) with their statistics, and each
/// run's compartment.
/// `work`: the labels, to count gas among pools (None: every voxel is gas).
fn compartment_stats(
    runs: &Runs,
    work: Option<&Volume<u8>>,
    uf: &mut UnionFind,
    geom: &crate::Geometry,
    inferior: DVec3,
) -> (Vec<Compartment>, Vec<u32>) {
    let [nx, ny, nz] = geom.dims;
    let sp = geom.spacing;
    let mut of_root = vec![u32::MAX; runs.runs.len()];
    let mut run_comp = vec![u32::MAX; runs.runs.len()];
    let mut out: Vec<Compartment> = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                let root = uf.find(r);
                if of_root[root] == u32::MAX {
                    of_root[root] = out.len() as u32;
                    out.push(Compartment {
                        voxels: 0,
                        gas_voxels: 0,
                        sum_mm: DVec3::ZERO,
                        bbox: Bbox {
                            lo: [usize::MAX; 3],
                            hi: [0; 3],
                        },
                        lowest: [0; 3],
                        lowest_height: f64::NEG_INFINITY,
                    });
                }
                let c = of_root[root];
                run_comp[r] = c;
                let run = runs.runs[r];
                let (x0, x1) = (run.x0 as usize, run.x1 as usize);
                let cm = &mut out[c as usize];
                let n = x1 - x0;
                cm.voxels += n;
                cm.gas_voxels += work.map_or(n, |w| {
                    w.data()[nx * (j + ny * k) + x0..nx * (j + ny * k) + x1]
                        .iter()
                        .filter(|&&x| x == GAS)
                        .count()
                });
                cm.sum_mm += DVec3::new(
                    (x0 + x1 - 1) as f64 * 0.5 * sp[0] * n as f64,
                    (j * n) as f64 * sp[1],
                    (k * n) as f64 * sp[2],
                );
                cm.bbox = Bbox {
                    lo: [
                        cm.bbox.lo[0].min(x0),
                        cm.bbox.lo[1].min(j),
                        cm.bbox.lo[2].min(k),
                    ],
                    hi: [
                        cm.bbox.hi[0].max(x1 - 1),
                        cm.bbox.hi[1].max(j),
                        cm.bbox.hi[2].max(k),
                    ],
                };
                // The lowest voxel of the run lies at one of its ends.
                for x in [x0, x1 - 1] {
                    let h = chain::height(
                        inferior,
                        geom.index_to_local(DVec3::new(x as f64, j as f64, k as f64)),
                    );
                    if h > cm.lowest_height {
                        cm.lowest_height = h;
                        cm.lowest = [x, j, k];
                    }
                }
            }
        }
    }
    (out, run_comp)
}

/// The voxel of compartment `c` nearest the middle of its lowest 2 mm (patient frame): the
/// same place whatever the storage order, where the lowest single voxel would be picked by
/// ties.
fn lowest_middle(
    runs: &Runs,
    run_comp: &[u32],
    comp: &Compartment,
    c: u32,
    geom: &crate::Geometry,
    inferior: DVec3,
) -> [usize; 3] {
    const SLAB_MM: f64 = 2.0;
    let floor = comp.lowest_height - SLAB_MM;
    let mut voxels = Vec::new();
    // The height along a row changes by inferior.x·sx per voxel: a row whose highest
    // possible value is below the slab is passed over.
    let (x_lo, x_hi) = (
        comp.bbox.lo[0] as f64 * geom.spacing[0],
        comp.bbox.hi[0] as f64 * geom.spacing[0],
    );
    let best_x = (inferior.x * x_lo).max(inferior.x * x_hi);
    for k in comp.bbox.lo[2]..=comp.bbox.hi[2] {
        for j in comp.bbox.lo[1]..=comp.bbox.hi[1] {
            if best_x
                + inferior.y * j as f64 * geom.spacing[1]
                + inferior.z * k as f64 * geom.spacing[2]
                < floor
            {
                continue;
            }
            for r in runs.row(j, k).filter(|&r| run_comp[r] == c) {
                let run = runs.runs[r];
                for x in run.x0 as usize..run.x1 as usize {
                    if chain::height(
                        inferior,
                        geom.index_to_local(DVec3::new(x as f64, j as f64, k as f64)),
                    ) >= floor
                    {
                        voxels.push([x, j, k]);
                    }
                }
            }
        }
    }
    let mm = |v: [usize; 3]| geom.index_to_local(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64));
    let mid = voxels.iter().map(|&v| mm(v)).sum::<DVec3>() / voxels.len().max(1) as f64;
    voxels
        .into_iter()
        .min_by(|&a, &b| {
            mm(a)
                .distance(mid)
                .total_cmp(&mm(b).distance(mid))
                .then_with(|| {
                    let (p, q) = (
                        geom.index_to_patient(DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64)),
                        geom.index_to_patient(DVec3::new(b[0] as f64, b[1] as f64, b[2] as f64)),
                    );
                    p.x.total_cmp(&q.x)
                        .then(p.y.total_cmp(&q.y))
                        .then(p.z.total_cmp(&q.z))
                })
        })
        .unwrap_or(comp.lowest)
}

/// A tube of `radius_mm` around a bridge's path: BRIDGE where there is neither gas nor a pool.
fn lay_bridge(work: &mut Volume<u8>, path: &[[usize; 3]], radius_mm: f64, added: &mut Vec<usize>) {
    let g = work.geometry().clone();
    let r = g.spacing.map(|s| (radius_mm / s).floor() as i64);
    let mut ball = Vec::new();
    for dz in -r[2]..=r[2] {
        for dy in -r[1]..=r[1] {
            for dx in -r[0]..=r[0] {
                let d2 = (dx as f64 * g.spacing[0]).powi(2)
                    + (dy as f64 * g.spacing[1]).powi(2)
                    + (dz as f64 * g.spacing[2]).powi(2);
                if d2 <= radius_mm * radius_mm {
                    ball.push([dx, dy, dz]);
                }
            }
        }
    }
    for v in path {
        for o in &ball {
            let q = [v[0] as i64 + o[0], v[1] as i64 + o[1], v[2] as i64 + o[2]];
            if (0..3).any(|a| q[a] < 0 || q[a] >= g.dims[a] as i64) {
                continue;
            }
            let i = g.index(q[0] as usize, q[1] as usize, q[2] as usize);
            let x = &mut work.data_mut()[i];
            if *x == 0 {
                *x = BRIDGE;
                added.push(i);
            }
        }
    }
}

/// Fluid filling a bridged stretch: the bright voxels reached from the path's bright voxels
/// within `reach_mm`, through bright voxels.
fn fill_fluid(
    work: &mut Volume<u8>,
    path: &[[usize; 3]],
    reach_mm: f64,
    bright: impl Fn(usize) -> bool,
    added: &mut Vec<usize>,
) {
    let g = work.geometry().clone();
    let seeds: Vec<usize> = path
        .iter()
        .map(|v| g.index(v[0], v[1], v[2]))
        .filter(|&i| work.data()[i] == 0 && bright(i))
        .collect();
    fluid::grow_bright(
        work,
        seeds,
        (reach_mm, None),
        &bright,
        &bright,
        BRIDGE,
        added,
    );
}

/// The colon's tagged fluid beyond its pools' columns: bright voxels within
/// [`fluid::POOL_REACH_MM`] of the lumen's bright voxels (`lumen` is 0/1, in `lumen_box`),
/// added to the lumen. Returns them.
fn whole_pools(
    lumen: &mut Volume<u8>,
    ct: &Volume<i16>,
    lumen_box: Option<Bbox>,
    (air_hu, fluid_hu): (i16, i16),
    gravity_lps: DVec3,
) -> Vec<usize> {
    let Some(b) = lumen_box else {
        return Vec::new();
    };
    let g = lumen.geometry().clone();
    let bright = |i: usize| ct.data()[i] >= fluid_hu;
    // Only the lumen's bright voxels with a bright neighbour outside it start the growth.
    let [nx, ny, _] = g.dims;
    let seeds: Vec<usize> = (b.lo[2]..=b.hi[2])
        .into_par_iter()
        .flat_map_iter(|k| {
            let (lumen, g) = (&*lumen, &g);
            (b.lo[1]..=b.hi[1]).flat_map(move |j| {
                let row = g.index(b.lo[0], j, k);
                (row..=row + b.hi[0] - b.lo[0]).filter(move |&i| {
                    let [x, y, z] = [b.lo[0] + i - row, j, k];
                    let out = |q: usize| lumen.data()[q] == 0 && bright(q);
                    lumen.data()[i] == 1
                        && bright(i)
                        && ((x > 0 && out(i - 1))
                            || (x + 1 < nx && out(i + 1))
                            || (y > 0 && out(i - nx))
                            || (y + 1 < ny && out(i + nx))
                            || (z > 0 && out(i - nx * ny))
                            || (z + 1 < g.dims[2] && out(i + nx * ny)))
                })
            })
        })
        .collect();
    let down = PatientFrame::of(&g).nearest_axis(gravity_lps);
    // Fluid is not passed through where gas lies beside it: past the level (in the lumen
    // already) or in tagged stool mottled with gas, which cleansing's model of lumps takes.
    let by_air = |i: usize| {
        let [x, y, z] = g.ijk(i);
        [
            (x > 0).then(|| i - 1),
            (x + 1 < nx).then(|| i + 1),
            (y > 0).then(|| i - nx),
            (y + 1 < ny).then(|| i + nx),
            (z > 0).then(|| i - nx * ny),
            (z + 1 < g.dims[2]).then(|| i + nx * ny),
        ]
        .into_iter()
        .flatten()
        .any(|q| ct.data()[q] < air_hu)
    };
    // Fluid is passed through where it is wide, at least halfway to the brightest beside it
    // (not the blurred wall between two pools), with no gas beside it. Reached from there,
    // the pool's partial-volume skin (bright, under halfway) is taken too, and so is wide
    // fluid beside gas; not a tube's fluid.
    let half = |i: usize| fluid::above_half(ct.data(), i, g.dims, TISSUE_HU);
    let wide = |i: usize| fluid::wide_across(&g, i, down.0, &bright);
    let take = |i: usize| bright(i) && (!half(i) || wide(i));
    let pass = |i: usize| bright(i) && wide(i) && half(i) && !by_air(i);
    let mut grown = Vec::new();
    fluid::grow_bright(
        lumen,
        seeds,
        (fluid::POOL_REACH_MM, Some(down)),
        take,
        pass,
        1,
        &mut grown,
    );
    grown
}

/// The LPS box of a voxel box (all eight corners: the direction may turn the axes).
fn lps_box(geom: &crate::Geometry, b: &Bbox) -> [DVec3; 2] {
    geom.patient_box(b.lo, b.hi)
}

/// The anatomical region of a volume-local point within the colon's LPS box.
pub(crate) fn region_of(geom: &crate::Geometry, p: DVec3, colon: &[DVec3; 2]) -> &'static str {
    let q = geom.local_to_patient(p);
    let span = (colon[1] - colon[0]).max(DVec3::splat(1.0));
    let u = (q.x - colon[0].x) / span.x;
    let v = (q.z - colon[0].z) / span.z;
    chain::region(u, v)
}

/// Gas left out of the colon: stomach (high on the left), small bowel (small or narrow), or
/// other.
fn classify(
    comp: &Compartment,
    geom: &crate::Geometry,
    colon: &[DVec3; 2],
    voxel_ml: f64,
) -> ComponentKind {
    let ml = comp.gas_voxels as f64 * voxel_ml;
    let c = geom.local_to_patient(comp.centroid_mm());
    let span = colon[1] - colon[0];
    let high_left = c.z > colon[0].z + 0.7 * span.z && c.x > colon[0].x + 0.5 * span.x;
    if high_left && ml >= LARGE_LEFT_ML {
        return ComponentKind::Stomach;
    }
    // Its length from its box's diagonal; narrow when the mean cross-section is under 25 mm.
    let b = lps_box(geom, &comp.bbox);
    let length = (b[1] - b[0]).length().max(1.0);
    let width = 2.0 * (ml * 1000.0 / (std::f64::consts::PI * length)).sqrt();
    if ml < LARGE_LEFT_ML || width <= 25.0 {
        ComponentKind::SmallBowel
    } else {
        ComponentKind::Other
    }
}

fn segment_report(
    comp: &Compartment,
    geom: &crate::Geometry,
    label: String,
    kind: ComponentKind,
    order: Option<usize>,
    reason: Option<String>,
    voxel_ml: f64,
) -> SegmentReport {
    let b = lps_box(geom, &comp.bbox);
    SegmentReport {
        label,
        kind,
        order,
        gas_ml: comp.gas_voxels as f64 * voxel_ml,
        fluid_ml: (comp.voxels - comp.gas_voxels) as f64 * voxel_ml,
        extent_lps_mm: [b[0].to_array(), b[1].to_array()],
        anchor_lps_mm: geom
            .index_to_patient(DVec3::from_array(comp.lowest.map(|x| x as f64)))
            .to_array(),
        kept: order.is_some(),
        reason,
    }
}

/// The scan's inferior axial slice (k is axial): 0 or the last, whichever lies lower in the
/// patient; None when the slices do not run along the body.
fn inferior_slice(vol: &Volume<i16>) -> Option<usize> {
    let g = vol.geometry();
    let nz = vol.dims()[2];
    let first = g.index_to_patient(DVec3::ZERO);
    let last = g.index_to_patient(DVec3::new(0.0, 0.0, nz.saturating_sub(1) as f64));
    let along = last - first;
    if along.length() < 1e-9 || along.z.abs() < 0.7 * along.length() {
        return None;
    }
    Some(if along.z < 0.0 { nz - 1 } else { 0 })
}

/// Voxels in some runs.
fn run_voxels(runs: &Runs, rs: &[usize]) -> usize {
    rs.iter()
        .map(|&r| (runs.runs[r].x1 - runs.runs[r].x0) as usize)
        .sum()
}

/// A rectal tube as a gas region left out of the colon.
fn tube_report(
    t: &tube::Tube,
    runs: &Runs,
    geom: &crate::Geometry,
    voxel_ml: f64,
) -> SegmentReport {
    let mut bbox: Option<Bbox> = None;
    let voxels = run_voxels(runs, &t.runs);
    for &r in &t.runs {
        let (j, k) = row_of(runs, r);
        let run = runs.runs[r];
        let b = Bbox {
            lo: [run.x0 as usize, j, k],
            hi: [run.x1 as usize - 1, j, k],
        };
        bbox = Some(bbox.map_or(b, |x| x.union(&b)));
    }
    let b = bbox.map_or([DVec3::ZERO; 2], |b| lps_box(geom, &b));
    let lps = |v: [f64; 3]| geom.index_to_patient(DVec3::from_array(v)).to_array();
    let tip = lps(t.tip);
    SegmentReport {
        label: "rectal tube".into(),
        kind: ComponentKind::RectalTube,
        order: None,
        gas_ml: voxels as f64 * voxel_ml,
        fluid_ml: 0.0,
        extent_lps_mm: [b[0].to_array(), b[1].to_array()],
        anchor_lps_mm: lps(t.entry),
        kept: false,
        reason: Some(format!(
            "a rectal tube, {:.0} mm from {} to its tip at LPS ({:.0}, {:.0}, {:.0}): its air is not colon; the rectum starts at its tip",
            t.length_mm,
            if t.from_edge {
                "the scan's edge"
            } else {
                "the skin"
            },
            tip[0],
            tip[1],
            tip[2]
        )),
    }
}

/// Largest first; tiny components are only counted.
fn report(comps: Vec<Component>, min_ml: f64) -> (Vec<Component>, usize) {
    let mut listed: Vec<Component> = Vec::new();
    let mut small = 0;
    for c in comps {
        if c.kind == ComponentKind::Colon || c.volume_ml >= min_ml {
            listed.push(c);
        } else {
            small += 1;
        }
    }
    listed.sort_by_key(|c| std::cmp::Reverse(c.voxels));
    (listed, small)
}

/// Union-find over run indices, with path halving and union by size.
struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }
    fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] as usize != x {
            let p = self.parent[x] as usize;
            self.parent[x] = self.parent[p];
            x = p;
        }
        x
    }
    fn union(&mut self, a: usize, b: usize) {
        let (mut ra, mut rb) = (self.find(a), self.find(b));
        if ra == rb {
            return;
        }
        if self.size[ra] < self.size[rb] {
            std::mem::swap(&mut ra, &mut rb);
        }
        self.parent[rb] = ra as u32;
        self.size[ra] += self.size[rb];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;

    /// The runs of one row found through its bits, for both tests at once, are the runs of the
    /// plain per-voxel test: rows of many lengths (whole words and a remainder), runs at both
    /// ends and across word boundaries, values at and beside the thresholds.
    #[test]
    fn row_bits_give_the_runs_of_each_test() {
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let values = [
            -1000i16,
            -501,
            -500,
            -499,
            0,
            1,
            199,
            200,
            201,
            1500,
            i16::MIN,
            i16::MAX,
        ];
        for len in [1usize, 5, 63, 64, 65, 127, 128, 130, 200, 512, 517] {
            for _ in 0..20 {
                // Stretches of one value, so that runs are long enough to cross words.
                let mut row = Vec::with_capacity(len);
                while row.len() < len {
                    let v = values[(next() % values.len() as u64) as usize];
                    let n = 1 + (next() % 90) as usize;
                    row.extend(std::iter::repeat_n(v, n.min(len - row.len())));
                }
                for tests in [
                    (Test::Below(-500), Some(Test::AtLeast(200))),
                    (Test::NonZero, None),
                    (Test::AtLeast(-500), Some(Test::NonZero)),
                ] {
                    let mut words = (
                        vec![u64::MAX; len.div_ceil(64)],
                        vec![u64::MAX; len.div_ceil(64)],
                    );
                    row_bits(&row, tests, &mut words);
                    let found = |w: &[u64]| {
                        let mut v = Vec::new();
                        runs_of_bits(w, |a, b| v.push(a as usize..b as usize));
                        v
                    };
                    let want = |t: Test| {
                        crate::volume::runs_where(&row, |v| t.holds(v)).collect::<Vec<_>>()
                    };
                    assert_eq!(found(&words.0), want(tests.0), "{tests:?} {row:?}");
                    if let Some(u) = tests.1 {
                        assert_eq!(found(&words.1), want(u), "{tests:?} {row:?}");
                    }
                }
            }
        }
    }

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
