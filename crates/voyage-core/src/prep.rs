//! Preprocessing: from a CT (or a lumen mask) to a [`Study`], everything navigation and
//! rendering need. The paper's preprocessing took "a few hours"; this takes well under a
//! second after loading.

use std::time::Instant;

use glam::DVec3;
use serde::Serialize;

use crate::{
    Result, Storage, Volume,
    cells::{CellOptions, Cells, build_cells},
    centerline::{
        self, Centerline, CenterlineOptions, centre_skeleton, trace_skeleton, uses_blocks,
    },
    cleanse::{CleanseOptions, Cleansing, Scene, cleanse},
    contacts::{
        ContactMemory, ContactOptions, Hole, cut_contacts, holes_by_descent, may_have_shortcuts,
        plug_beside, shortcut_plugs,
    },
    distance::{
        distance_to_wall_reusing,
        geodesic::{SearchMemory, geodesic_distance_like},
    },
    grid::{BoxGrid, Bricked, Field},
    navigable::{DEFAULT_MIN_WALL_MM, Navigable},
    segment::{COLON_SEGMENTS, Course, SegmentOptions, Segmentation, segment},
    surface::{Surface, extract_surface},
};

#[derive(Clone, Debug)]
pub struct PrepOptions {
    pub segment: SegmentOptions,
    /// Electronic cleansing of the colon's tagged fluid (`cleanse.rs`); None: off.
    pub cleanse: Option<CleanseOptions>,
    /// The ends (given or found), the skeleton search and the refinement.
    pub centerline: CenterlineOptions,
    pub cells: CellOptions,
    pub contacts: ContactOptions,
    /// The camera's distance from the wall the navigable core is made for (`Study::nav`);
    /// None: no navigable core (a run that only exports, as `voyage prep`).
    pub nav_min_wall_mm: Option<f64>,
}

impl Default for PrepOptions {
    fn default() -> Self {
        PrepOptions {
            segment: SegmentOptions::default(),
            cleanse: Some(CleanseOptions::default()),
            centerline: CenterlineOptions::default(),
            cells: CellOptions::default(),
            contacts: ContactOptions::default(),
            nav_min_wall_mm: Some(DEFAULT_MIN_WALL_MM),
        }
    }
}

/// The stages of [`prepare`] in the order they run: what progress hears of and what
/// [`Timings`] times (one vocabulary for both).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// The colon from the CT: gas, tagged fluid, the chain of segments, the lumen.
    Segment,
    /// Electronic cleansing (costs nothing without tagged fluid).
    Cleanse,
    /// The skeleton search: endpoints and the raw centerline path.
    Skeleton,
    /// Walls where loops touch.
    Contacts,
    Ds,
    /// The centerline centred on Ds's ridge and smoothed.
    Centerline,
    /// Dt from the source over the whole lumen (for the cells).
    Dt,
    /// Both Dt over the navigable core ([`Navigable`]).
    Nav,
    Surface,
    Cells,
}

impl Stage {
    pub const ALL: [Stage; 10] = [
        Stage::Segment,
        Stage::Cleanse,
        Stage::Skeleton,
        Stage::Contacts,
        Stage::Ds,
        Stage::Centerline,
        Stage::Dt,
        Stage::Nav,
        Stage::Surface,
        Stage::Cells,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Stage::Segment => "segment",
            Stage::Cleanse => "cleanse",
            Stage::Skeleton => "skeleton",
            Stage::Contacts => "contacts",
            Stage::Ds => "ds",
            Stage::Centerline => "centerline",
            Stage::Dt => "dt",
            Stage::Surface => "surface",
            Stage::Cells => "cells",
            Stage::Nav => "nav",
        }
    }
    /// The stage's place in [`Stage::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// Wall time per stage in ms (`timings[Stage::Ds]`), and in all after loading. As JSON: one
/// number per stage name, then `total_after_load`.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    ms: [f64; Stage::ALL.len()],
    pub total_after_load: f64,
}

impl std::ops::Index<Stage> for Timings {
    type Output = f64;
    fn index(&self, stage: Stage) -> &f64 {
        &self.ms[stage.index()]
    }
}

impl std::ops::IndexMut<Stage> for Timings {
    fn index_mut(&mut self, stage: Stage) -> &mut f64 {
        &mut self.ms[stage.index()]
    }
}

impl Serialize for Timings {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(Some(Stage::ALL.len() + 1))?;
        for stage in Stage::ALL {
            map.serialize_entry(stage.name(), &self[stage])?;
        }
        map.serialize_entry("total_after_load", &self.total_after_load)?;
        map.end()
    }
}

/// Times the stages one after another and tells `progress` as each starts.
struct Laps<F: FnMut(Stage)> {
    timings: Timings,
    running: Option<(Stage, Instant)>,
    progress: F,
}

impl<F: FnMut(Stage)> Laps<F> {
    fn new(progress: F) -> Self {
        Laps {
            timings: Timings::default(),
            running: None,
            progress,
        }
    }
    fn start(&mut self, stage: Stage) {
        self.stop();
        (self.progress)(stage);
        self.running = Some((stage, Instant::now()));
    }
    fn stop(&mut self) {
        if let Some((stage, since)) = self.running.take() {
            self.timings[stage] += since.elapsed().as_secs_f64() * 1e3;
        }
    }
}

/// Everything preprocessing produces. Geometry in the study storage's local mm.
#[derive(Clone, Debug)]
pub struct Study {
    /// The input: HU, or a mask's labels, in the study storage (its axes along the
    /// patient's L, P, S).
    pub ct: Volume<i16>,
    /// The input's storage: [`Storage::to_input`] writes a volume of the study on the input's
    /// grid.
    pub storage: Storage,
    pub segmentation: Segmentation,
    /// What electronic cleansing changed in `ct` (empty without tagged fluid, or when it is
    /// off): [`Study::cleansed_ct`] is the CT the surface was cut from.
    pub cleansing: Cleansing,
    /// Ds: distance to the wall (mm), over the lumen's box, in the bricks that hold lumen
    /// (0 elsewhere).
    pub ds: Bricked<f32>,
    /// Dt from the source over the whole lumen, mm; +∞ outside. The cells are cut on it.
    pub dt_source: Bricked<f32>,
    /// Dt to both ends over the navigable core, for the camera's default distance from the
    /// wall ([`Study::navigable`] for another).
    pub nav: Option<Navigable>,
    pub source: [usize; 3],
    pub target: [usize; 3],
    /// Lumen voxels left out of Dt where loops of the colon touch (`contacts.rs`).
    pub contact_voxels: usize,
    pub centerline: Centerline,
    /// Each bridged gap's stretch of the centerline, in the order of `segmentation.gaps`;
    /// None where the centerline does not pass through the gap (the colon is joined by
    /// lumen elsewhere too).
    pub gap_spans: Vec<Option<[f64; 2]>>,
    pub surface: Surface,
    pub cells: Cells,
    pub timings: Timings,
}

/// Along the centerline from its rectum end, the rectum reaches this far (mm; the rectum is
/// 12–15 cm long).
pub const RECTUM_MM: f64 = 150.0;

/// How far along its normal into the lumen a point on the wall is moved before
/// [`Study::arc_at`] and [`Study::segment_at`] read it (mm).
pub const OFF_WALL_MM: f64 = 1.5;

/// A point on the wall is read against the centerline of its cell and of this many cells on
/// either side (cells are 6–20 mm of centerline). Dt's level sets, which bound the cells, bow
/// in a wide chamber: by colon-a's cecal pole a marker on the wall beside the centerline
/// point at 2900 mm lay in the cell two back, and with one on either side read 2882 mm.
const CELLS_AROUND: usize = 2;

/// Dt from the source is shorter than the arc along the centerline by up to this fraction
/// (the geodesic cuts the bends).
const ARC_SLACK: f64 = 0.25;

/// The non-decreasing sequence of labels (0..n) that differs from `wanted` in the fewest
/// places (dynamic programming; ties go to the earlier label).
fn monotone_labels(wanted: &[usize], n: usize) -> Vec<usize> {
    if wanted.is_empty() {
        return Vec::new();
    }
    // cost[i][k]: fewest disagreements over 0..=i with label k at i.
    let mut cost: Vec<Vec<u32>> = Vec::with_capacity(wanted.len());
    for &w in wanted {
        // The best over labels ≤ k at the point before (none before the first point).
        let mut best_before = if cost.is_empty() { 0 } else { u32::MAX };
        let row: Vec<u32> = (0..n)
            .map(|k| {
                if let Some(prev) = cost.last() {
                    best_before = best_before.min(prev[k]);
                }
                best_before + (w != k) as u32
            })
            .collect();
        cost.push(row);
    }
    let mut labels = vec![0; wanted.len()];
    let last = wanted.len() - 1;
    let mut k = (0..n).min_by_key(|&k| (cost[last][k], k)).unwrap_or(0);
    for i in (0..wanted.len()).rev() {
        labels[i] = k;
        if i > 0 {
            k = (0..=k).min_by_key(|&j| (cost[i - 1][j], j)).unwrap_or(0);
        }
    }
    labels
}

impl Study {
    /// The CT with the colon's tagged fluid made air (a copy; the CT itself when nothing was
    /// cleansed).
    pub fn cleansed_ct(&self) -> Volume<i16> {
        self.cleansing.swapped_copy(&self.ct)
    }

    /// The patient's anterior as a volume-local unit vector: up in the endoscopic view, in
    /// any position (prone, the anterior is down).
    pub fn anterior_local(&self) -> DVec3 {
        crate::anatomy::PatientFrame::of(self.ct.geometry()).local(DVec3::new(0.0, -1.0, 0.0))
    }

    /// Stretches of the centerline (arc mm from the source, start and end) that cross a
    /// bridged gap: collapsed or fluid-filled bowel, no air. Sorted.
    pub fn collapsed_spans(&self) -> Vec<[f64; 2]> {
        let mut spans: Vec<[f64; 2]> = self.gap_spans.iter().flatten().copied().collect();
        spans.sort_by(|a, b| a[0].total_cmp(&b[0]));
        spans
    }

    /// The bridged gap whose stretch of the centerline holds arc length `arc` (mm from the
    /// source), if any.
    pub fn gap_at(&self, arc: f64) -> Option<&crate::Gap> {
        self.gap_spans
            .iter()
            .position(|s| s.is_some_and(|s| s[0] <= arc && arc <= s[1]))
            .map(|i| &self.segmentation.gaps[i])
    }

    pub fn source_mm(&self) -> DVec3 {
        self.ct.geometry().index_to_local(DVec3::new(
            self.source[0] as f64,
            self.source[1] as f64,
            self.source[2] as f64,
        ))
    }
    /// The navigable core for a camera kept `min_wall_mm` from the wall: the study's own when
    /// it was made for that distance, else made now.
    pub fn navigable(&self, min_wall_mm: f64) -> Result<std::borrow::Cow<'_, Navigable>> {
        if let Some(nav) = self.nav.as_ref().filter(|n| n.min_wall_mm == min_wall_mm) {
            return Ok(std::borrow::Cow::Borrowed(nav));
        }
        let lumen = &self.segmentation.lumen;
        let mut memory = SearchMemory::default();
        Navigable::new(lumen, &self.ds, &self.centerline, min_wall_mm, &mut memory)
            .map(std::borrow::Cow::Owned)
    }
    /// The centerline point that serves the lumen around `p` (volume-local mm): the nearest
    /// of those in the stretch of `p`'s cell and of the cells around it. The cells cut the
    /// lumen along the centerline (level sets of Dt), so where two loops lie side by side `p`
    /// is read in its own, and points along the colon read in order. Dt itself is no guide to
    /// the arc: on real colons the centerline is 1.4–1.7× as long as the geodesic, which cuts
    /// the bends. A point in no cell (outside the lumen) takes the nearest point of those as
    /// far from the source along the centerline as it is through the lumen (give or take
    /// [`ARC_SLACK`]), else of all.
    fn nearest_centerline_point(&self, p: DVec3) -> Option<usize> {
        let cl = &self.centerline;
        let d = |i: &usize| DVec3::from_array(cl.points_mm[*i]).distance_squared(p);
        let nearest = |is: &mut dyn Iterator<Item = usize>| is.min_by(|a, b| d(a).total_cmp(&d(b)));
        if let Some(span) = self
            .cells
            .cell_of_point(p)
            .and_then(|c| self.centerline_span_around(c))
        {
            return nearest(&mut (span.0..=span.1));
        }
        let dt = self.dt_source.sample(p) as f64;
        let near_dt =
            |i: &usize| !dt.is_finite() || (cl.arc_mm[*i] - dt).abs() <= (ARC_SLACK * dt).max(50.0);
        let all = 0..cl.points_mm.len();
        nearest(&mut all.clone().filter(near_dt)).or_else(|| nearest(&mut all.clone()))
    }

    /// The centerline points (first, last) in cell `c` and the [`CELLS_AROUND`] either side,
    /// None when none lies there.
    fn centerline_span_around(&self, c: usize) -> Option<(usize, usize)> {
        let cells = &self.cells.cells;
        let last = cells.len().saturating_sub(1);
        // A cell no centerline point lies in keeps the span (0, 0); only cell 0 holds point 0.
        (c.saturating_sub(CELLS_AROUND)..=(c + CELLS_AROUND).min(last))
            .filter(|&k| k == 0 || cells[k].centerline_span != (0, 0))
            .map(|k| cells[k].centerline_span)
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
    }

    /// Arc length (mm from the centerline's rectum end, about the anal verge) of the
    /// centerline point nearest `p` (volume-local mm, in the lumen: a point on the wall
    /// moved [`OFF_WALL_MM`] along its normal).
    pub fn arc_at(&self, p: DVec3) -> Option<f64> {
        self.nearest_centerline_point(p)
            .map(|i| self.centerline.arc_mm[i])
    }

    /// The colon segment `p` (volume-local mm, in the lumen) lies in: that of its centerline
    /// point (see [`Study::arc_at`], [`Study::segments_along`]).
    pub fn segment_at(&self, p: DVec3) -> &'static str {
        self.nearest_centerline_point(p)
            .map_or("colon", |i| self.segments_along()[i])
    }

    /// The segment of each centerline point, from the rectum end: the rectum for the first
    /// [`RECTUM_MM`], then the segments in their anatomical order, each where the point's
    /// place in the colon's box (patient frame) names it. The order is kept: the labels are
    /// the monotone sequence that disagrees with the fewest places (a sigmoid loop that
    /// wanders into the descending colon's corner stays sigmoid).
    pub fn segments_along(&self) -> Vec<&'static str> {
        let g = self.ct.geometry();
        let grid = &self.ds.grid;
        let hi = [0, 1, 2].map(|a| grid.lo[a] + grid.dims[a].saturating_sub(1));
        let colon = g.patient_box(grid.lo, hi);
        let cl = &self.centerline;
        let wanted: Vec<usize> = cl
            .points_mm
            .iter()
            .zip(&cl.arc_mm)
            .map(|(p, &arc)| {
                let name = if arc <= RECTUM_MM {
                    "rectum"
                } else {
                    match crate::segment::region_of(g, DVec3::from_array(*p), &colon) {
                        "rectosigmoid" => "sigmoid",
                        region => region,
                    }
                };
                Course::order_of(name).unwrap_or(0)
            })
            .collect();
        monotone_labels(&wanted, COLON_SEGMENTS.len())
            .into_iter()
            .map(|i| COLON_SEGMENTS[i])
            .collect()
    }

    /// The segment of each cell (as [`Study::segment_at`] names them): that of the middle
    /// of the centerline stretch through the cell and the cells around it.
    pub fn cell_segments(&self) -> Vec<&'static str> {
        let along = self.segments_along();
        (0..self.cells.cells.len())
            .map(|c| {
                self.centerline_span_around(c)
                    .and_then(|(a, b)| along.get((a + b) / 2).copied())
                    .unwrap_or("colon")
            })
            .collect()
    }

    /// The segment of each bridged gap, at the middle of its stretch of the centerline
    /// (None where the centerline does not cross it).
    pub fn gap_segments(&self) -> Vec<Option<&'static str>> {
        let along = self.segments_along();
        let arcs = &self.centerline.arc_mm;
        self.gap_spans
            .iter()
            .map(|&span| {
                let mid = 0.5 * (span?[0] + span?[1]);
                let i = arcs
                    .partition_point(|&a| a < mid)
                    .min(arcs.len().checked_sub(1)?);
                along.get(i).copied()
            })
            .collect()
    }

    pub fn target_mm(&self) -> DVec3 {
        self.ct.geometry().index_to_local(DVec3::new(
            self.target[0] as f64,
            self.target[1] as f64,
            self.target[2] as f64,
        ))
    }
}

/// Runs every stage. `progress` hears of each stage as it starts.
///
/// The study is made in the study storage ([`Storage`]): `ct` is turned to run along the
/// patient's axes first (the points in `opts` with it), so that no result depends on how the
/// scan was stored. Everything in the [`Study`] is in that storage; `Study::storage` goes
/// back to the input's.
pub fn prepare(ct: Volume<i16>, opts: &PrepOptions, progress: impl FnMut(Stage)) -> Result<Study> {
    let start = Instant::now();
    check_room_for_a_colon(ct.geometry())?;
    let storage = Storage::of(ct.geometry());
    if storage.is_identity() {
        return prepare_stored(ct, opts, storage, start, progress);
    }
    let study_ct = storage.to_study(&ct)?;
    // The input's copy goes now, not after preprocessing (225 MB on `ctc/prone-tagged`).
    drop(ct);
    let mut o = opts.clone();
    o.segment = opts.segment.in_storage(&storage);
    o.centerline.source_mm = opts.centerline.source_mm.map(|p| storage.mm_in(p));
    o.centerline.target_mm = opts.centerline.target_mm.map(|p| storage.mm_in(p));
    prepare_stored(study_ct, &o, storage, start, progress)
}

/// A colon needs this much room each way (mm): the narrowest stretch is 20 mm across and the
/// shortest course through a scan passes several. A thinner volume (a 3-slice series gave a
/// 124 mm centerline and a "bridged" gap) is refused.
const MIN_EXTENT_MM: f64 = 40.0;

fn check_room_for_a_colon(g: &crate::Geometry) -> Result<()> {
    for a in 0..3 {
        let across = g.dims[a] as f64 * g.spacing[a];
        if across < MIN_EXTENT_MM {
            return Err(crate::Error::invalid(format!(
                "the volume is {across:.1} mm across along its {} axis ({} voxels of {} mm): too thin to hold a colon (at least {MIN_EXTENT_MM:.0} mm each way)",
                ["i", "j", "k"][a],
                g.dims[a],
                g.spacing[a]
            )));
        }
    }
    Ok(())
}

/// [`prepare`] on a scan in the study storage.
fn prepare_stored(
    mut ct: Volume<i16>,
    opts: &PrepOptions,
    storage: Storage,
    start: Instant,
    progress: impl FnMut(Stage),
) -> Result<Study> {
    let mut laps = Laps::new(progress);

    laps.start(Stage::Segment);
    let mut seg = segment(&ct, &opts.segment)?;
    laps.start(Stage::Cleanse);
    let mut cleansing = match (&opts.cleanse, opts.segment.fluid_hu) {
        // A tagged exam: segmentation found tagged fluid in the colon (then stool on the
        // wall is cleansed too; an exam without fluid costs nothing).
        (Some(c), Some(fluid_hu)) if !seg.from_mask && seg.fluid_voxels > 0 => {
            let scene = Scene {
                ct: &ct,
                lumen: &mut seg.lumen,
                extent: seg.extent,
                gravity_lps: seg.orientation.gravity(),
                air_hu: opts.segment.air_hu,
                fluid_hu,
            };
            cleanse(scene, c)
        }
        _ => Cleansing::default(),
    };
    seg.lumen_voxels = seg.lumen_voxels + cleansing.joined_lumen - cleansing.left_lumen;
    // The centerline is traced without the fluid taken in beside the pools' columns: where two
    // loops' pools lie against one thin wall, the lumen there is one voxel from a hole, and
    // on `ctc/prone-tagged` the centerline's course through the large compartment moved by
    // up to 300 mm with them. They are lumen again for Ds, Dt and the surface.
    let mut beside: Vec<usize> = seg
        .pools_grown
        .iter()
        .copied()
        .filter(|&v| seg.lumen.data()[v] != 0)
        .collect();
    set_voxels(&mut seg.lumen, &beside, 0);
    seg.lumen_voxels -= beside.len();

    // Every Ds below is over this box: cutting contacts only takes lumen away, and a box
    // larger than the lumen's own changes no distance.
    let mut kept = TraceMemory::new(BoxGrid::around(seg.extent, 1, seg.lumen.dims()));
    // Where the segmentation placed the cecum by anatomy, the centerline ends there unless
    // the user gave the end.
    let mut cl_opts = opts.centerline.clone();
    if cl_opts.target_mm.is_none() {
        cl_opts.target_mm = seg.cecum_voxel.map(|v| centerline::mm_of(&seg.lumen, v));
    }
    let mut traced = match trace(&mut seg, &mut kept, &cl_opts, opts, &mut laps) {
        Ok(t) => t,
        // Without them the colon came apart (cleansing took wall voxels out beside them):
        // traced with them.
        Err(_) if !beside.is_empty() => {
            set_voxels(&mut seg.lumen, &beside, 1);
            seg.lumen_voxels += beside.len();
            beside.clear();
            trace(&mut seg, &mut kept, &cl_opts, opts, &mut laps)?
        }
        Err(e) => return Err(e),
    };
    let mut small_bowel: Vec<usize> = Vec::new();
    // Gas through the ileocaecal valve: the centerline ran on from the cecum into the ileum,
    // the colon's farthest gas. The ileum is cut off at the valve and left out, and the
    // centerline traced again to the cecum (unless the user placed the end).
    // The segmentation's cecum may be the ileum's gas too, where it was chained in as a
    // compartment of its own: the end is then the centerline's farthest point.
    if opts.centerline.target_mm.is_none()
        && let Some((tail, ileum)) = small_bowel_beyond(&seg, &traced)
    {
        set_voxels(&mut seg.lumen, &traced.taken, 1);
        if let Some(d) = traced.ds_box.take() {
            kept.give_back(d);
        }
        kept.skeleton = traced.sk.forget_route();
        let cecum = cl_opts.target_mm.take();
        if let Some(t) = retrace_plugged(&mut seg, &mut kept, &cl_opts, opts, &mut laps, &ileum) {
            let g = seg.lumen.geometry();
            let ml = ileum.len() as f64 * g.spacing.iter().product::<f64>() / 1000.0;
            let at = g.local_to_patient(DVec3::from_array(
                traced.ends.centerline.points_mm[tail.from],
            ));
            seg.warnings.push(format!(
                "gas in the small bowel beyond the ileocaecal valve was left out ({:.0} ml): the colon's farthest gas lay {:.0} mm along a tube at most {:.0} mm wide that leaves the cecum at LPS ({:.0}, {:.0}, {:.0}); the centerline now ends in the cecum. Give --target to end elsewhere",
                ml,
                tail.length_mm,
                2.0 * tail.tube_mm,
                at.x,
                at.y,
                at.z
            ));
            let chamber = traced.ends.centerline.points_mm[tail.chamber_at];
            seg.leave_out_beyond_the_cecum(
                &ileum,
                ml,
                seg.lumen
                    .geometry()
                    .local_to_patient(DVec3::from_array(chamber)),
                "small bowel beyond the ileocaecal valve",
            );
            seg.cecum_voxel = None;
            small_bowel = ileum;
            traced = t;
        } else {
            cl_opts.target_mm = cecum;
        }
        set_voxels(&mut seg.lumen, &traced.taken, 0);
    }
    // Holes between touching loops that the centerline went through: plugged, traced again
    // (a hole plugged can show the next).
    let mut plugged: Vec<usize> = Vec::new();
    let mut necks = Vec::new();
    let mut settled = false;
    for round in 0..=MAX_PLUG_ROUNDS {
        set_voxels(&mut seg.lumen, &traced.taken, 1);
        let c = &traced.ends.centerline;
        let (mut plugs, mut more) = (Vec::new(), Vec::new());
        if may_have_shortcuts(&c.points_mm, &c.radius_mm, &c.arc_mm, &necks) {
            // The trace's Ds (with the contacts cut) makes room: it is computed again after
            // the rounds when no trace replaces it, and two fields of fresh pages cost more.
            if let Some(d) = traced.ds_box.take() {
                kept.give_back(d);
            }
            let ds = kept.ds_of(&seg.lumen);
            plugs = shortcut_plugs(
                &seg.lumen,
                &c.points_mm,
                &c.radius_mm,
                &c.arc_mm,
                &mut necks,
                &ds,
            );
            if !plugs.is_empty() && round < MAX_PLUG_ROUNDS {
                more = holes_beyond(
                    &mut seg.lumen,
                    &ds,
                    &traced.sk,
                    &plugs,
                    &cl_opts,
                    &mut necks,
                );
            }
            kept.give_back(ds);
        }
        // With the further holes plugged too, unless they cut the colon itself: then the
        // holes of the trace alone.
        let mut tries = Vec::new();
        if !plugs.is_empty() && round < MAX_PLUG_ROUNDS {
            if !more.is_empty() {
                tries.push(plugs.iter().chain(&more).copied().collect());
            }
            tries.push(plugs.clone());
        }
        if !tries.is_empty() {
            // The skeleton search's arrays serve the next one.
            kept.skeleton = traced.sk.forget_route();
        }
        let retraced = tries.into_iter().find_map(|these: Vec<usize>| {
            retrace_plugged(&mut seg, &mut kept, &cl_opts, opts, &mut laps, &these)
                .map(|t| (t, these))
        });
        match retraced {
            Some((t, these)) => {
                plugged.extend(these);
                traced = t;
            }
            None => {
                settled = plugs.is_empty();
                set_voxels(&mut seg.lumen, &traced.taken, 0);
                break;
            }
        }
    }
    if !settled {
        seg.warnings.push(format!(
            "the centerline may still go through a hole between touching loops of the colon: {MAX_PLUG_ROUNDS} rounds of plugging did not close them all"
        ));
    }
    if !plugged.is_empty() {
        seg.warnings.push(format!(
            "the centerline went through holes between touching loops of the colon ({} voxels plugged): it now goes round",
            plugged.len()
        ));
    }
    let Traced {
        mut sk,
        mut ends,
        mut taken,
        mut ds_box,
    } = traced;
    sk.forget_route();
    // The fluid beside the columns is lumen again, but for the holes plugged and the
    // contacts cut in it.
    plugged.sort_unstable();
    beside.retain(|v| {
        plugged.binary_search(v).is_err()
            && taken.binary_search(v).is_err()
            && small_bowel.binary_search(v).is_err()
    });
    if !beside.is_empty() {
        set_voxels(&mut seg.lumen, &beside, 1);
        seg.lumen_voxels += beside.len();
        // The contacts cut again on the lumen with it: where the fluid beside the columns
        // lies across a contact, it would join the loops round the wall cut before.
        laps.start(Stage::Contacts);
        let blocks = sk
            .blocks
            .as_ref()
            .map(|_| crate::grid::Blocks::new(&seg.lumen, &kept.grid, 2))
            .transpose()?;
        taken.extend(cut_along(
            &mut seg.lumen,
            &kept.grid,
            &sk,
            blocks.as_ref(),
            opts,
            &mut kept.contacts,
        )?);
        taken.sort_unstable();
        if let Some(d) = ds_box.take() {
            kept.give_back(d);
        }
    }
    // The last cut is done: its arrays go before Dt, the surface and the cells.
    kept.contacts = ContactMemory::default();
    // Ds again where a round of plugging took the trace's, or the fluid came back.
    let ds_box = match ds_box {
        Some(d) => d,
        None => {
            laps.start(Stage::Ds);
            kept.ds_of(&seg.lumen)
        }
    };
    // Ds moves into bricks, and the Dt searches work in its box array.
    let grid = kept.grid;
    let mut ds = Bricked::from_field(&ds_box, 0.0);
    let mut memory = SearchMemory::from(ds_box.data);

    laps.start(Stage::Dt);
    let mut dt_source = geodesic_distance_like(&seg.lumen, &ds, ends.source, &mut memory)?;
    let joined =
        |dt: &crate::distance::Geodesic, target: [usize; 3]| dt.dist.get(target).is_finite();
    let mut contact_voxels = taken.len();
    if contact_voxels > 0 && !joined(&dt_source, ends.target) {
        // The walls closed the colon itself (a path across a contact): go without.
        for &v in &taken {
            seg.lumen.data_mut()[v] = 1;
        }
        contact_voxels = 0;
        let ds_box = crate::distance::distance_to_wall_in(&seg.lumen, grid.clone());
        ends = centre_skeleton(&seg.lumen, &ds_box, &sk, &cl_opts)?;
        ds = Bricked::from_field(&ds_box, 0.0);
        memory = SearchMemory::from(ds_box.data);
        dt_source = geodesic_distance_like(&seg.lumen, &ds, ends.source, &mut memory)?;
    }
    if !joined(&dt_source, ends.target) {
        return Err(crate::Error::invalid(
            "the target cannot be reached from the source through the lumen",
        ));
    }
    seg.lumen_voxels -= contact_voxels;
    let (source, target, cl) = (ends.source, ends.target, ends.centerline);
    // Holes beside the centerline, that no round of plugging looked at: plugged where Dt
    // shows them (a dip along the centerline, or its way back crossing from one loop to
    // another), unless that parts the colon.
    let mut beside_plugged: Vec<Hole> = Vec::new();
    for round in 0..=MAX_BESIDE_ROUNDS {
        let holes = holes_beside(&seg.lumen, &ds, &dt_source.dist, &cl, &cl_opts);
        if holes.is_empty() {
            break;
        }
        if round == MAX_BESIDE_ROUNDS {
            seg.warnings.push(format!(
                "the colon may hold more holes between touching loops beside the centerline: {MAX_BESIDE_ROUNDS} rounds of plugging did not close them all; the cells and the flight's pull may follow them"
            ));
            break;
        }
        // All of this round's at once; where that parts the colon, the first alone.
        let mut tries = vec![holes.clone()];
        if holes.len() > 1 {
            tries.push(holes[..1].to_vec());
        }
        let mut kept = None;
        for these in tries {
            let plugs: Vec<usize> = these.iter().flat_map(|h| h.plugs.iter().copied()).collect();
            set_voxels(&mut seg.lumen, &plugs, 0);
            laps.start(Stage::Dt);
            // Plugs only take lumen away: Ds's bricks still hold every lumen voxel.
            let dt = geodesic_distance_like(&seg.lumen, &ds, source, &mut memory)?;
            if joined(&dt, target) {
                kept = Some((dt, these, plugs));
                break;
            }
            set_voxels(&mut seg.lumen, &plugs, 1);
        }
        let Some((dt, these, plugs)) = kept else {
            break;
        };
        laps.start(Stage::Ds);
        crate::distance::add_walls(&mut ds, &plugs);
        dt_source = dt;
        seg.lumen_voxels -= plugs.len();
        beside_plugged.extend(these);
    }
    if !beside_plugged.is_empty() {
        seg.warnings
            .push(holes_warning(seg.lumen.geometry(), &beside_plugged));
    }
    if let Some((i, dip)) = shortcut_beside(&cl, &dt_source.dist) {
        let p = seg
            .lumen
            .geometry()
            .local_to_patient(DVec3::from_array(cl.points_mm[i]));
        seg.warnings.push(format!(
            "the lumen holds a way {dip:.0} mm shorter than the centerline's to LPS ({:.0}, {:.0}, {:.0}), {:.0} mm along it: likely a hole between touching loops that the centerline goes round; the cells and the flight's pull may follow that way",
            p.x, p.y, p.z, cl.arc_mm[i]
        ));
    }
    // The colon's last segment ends where the centerline does, unless the user placed the end.
    if opts.centerline.target_mm.is_none() {
        seg.name_last_segment(centerline::mm_of(&seg.lumen, target));
    }

    let nav = match opts.nav_min_wall_mm {
        Some(wall) => {
            laps.start(Stage::Nav);
            Some(Navigable::new(&seg.lumen, &ds, &cl, wall, &mut memory)?)
        }
        None => None,
    };
    drop(memory);

    laps.start(Stage::Surface);
    // The surface is cut from the cleansed CT: swapped in for it, and back.
    cleansing.swap(&mut ct);
    let iso = if seg.from_mask { None } else { Some(&ct) };
    let surface = extract_surface(&seg.lumen, iso, &ds.grid, opts.segment.air_hu as f32);
    cleansing.swap(&mut ct);
    let surface = surface?;

    laps.start(Stage::Cells);
    let cells = build_cells(&seg.lumen, &dt_source.dist, &cl, &surface, &opts.cells)?;
    laps.stop();

    let gap_spans = gap_spans(&cl, &seg);
    let fluid_hu = opts.segment.fluid_hu.filter(|_| !seg.from_mask);
    let fluid_filled: Vec<bool> = seg
        .gaps
        .iter()
        .map(|gap| fluid_filled(gap, &ct, fluid_hu))
        .collect();
    seg.measure_gaps_along(&gap_spans, &fluid_filled);
    if opts.centerline.source_mm.is_none() || opts.centerline.target_mm.is_none() {
        let w = anatomical_checks(
            &seg,
            &cl,
            source,
            target,
            opts.centerline.source_mm.is_none(),
            opts.centerline.target_mm.is_none(),
        );
        seg.warnings.extend(w);
    }
    let mut timings = laps.timings;
    timings.total_after_load = start.elapsed().as_secs_f64() * 1e3;
    Ok(Study {
        ct,
        storage,
        segmentation: seg,
        cleansing,
        ds,
        dt_source: dt_source.dist,
        nav,
        source,
        target,
        contact_voxels,
        centerline: cl,
        gap_spans,
        surface,
        cells,
        timings,
    })
}

/// The lumen's box and the memory the traces reuse. Ds over the box is computed anew each
/// time the lumen changes (each trace, each round of plugging): the memory of a field no
/// longer needed is written over by the next one instead of fresh pages (on
/// `ctc/prone-tagged`, 218 MB each time). So are the arrays of the last skeleton search and
/// of the last contact cut.
struct TraceMemory {
    grid: BoxGrid,
    spare_ds: Vec<f32>,
    skeleton: centerline::SkeletonMemory,
    contacts: ContactMemory,
}

impl TraceMemory {
    fn new(grid: BoxGrid) -> Self {
        TraceMemory {
            grid,
            spare_ds: Vec::new(),
            skeleton: Default::default(),
            contacts: Default::default(),
        }
    }
    fn ds_of(&mut self, lumen: &Volume<u8>) -> Field<f32> {
        distance_to_wall_reusing(lumen, self.grid.clone(), std::mem::take(&mut self.spare_ds))
    }
    fn give_back(&mut self, ds: Field<f32>) {
        self.spare_ds = ds.data;
    }
}

/// The centerline traced through the lumen: its ends and centred path, the contact voxels
/// cut from the lumen (sorted), and Ds over the lumen's box.
struct Traced {
    sk: centerline::Skeleton,
    ends: centerline::Endpoints,
    taken: Vec<usize>,
    /// None once a round of plugging took its memory.
    ds_box: Option<Field<f32>>,
}

/// Rounds of plugging holes between loops (each traces the centerline again). The right
/// colon of `ctc/prone-tagged`, 100 mm across, with fluid on folds between its loops, takes
/// twelve.
const MAX_PLUG_ROUNDS: usize = 16;

/// The centerline traced again with `plugs` taken out of the lumen (which holds no contacts
/// cut: they are cut along the new path); None, and the lumen as it was, when the plugs cut
/// the colon itself.
fn retrace_plugged(
    seg: &mut Segmentation,
    kept: &mut TraceMemory,
    cl_opts: &CenterlineOptions,
    opts: &PrepOptions,
    laps: &mut Laps<impl FnMut(Stage)>,
    plugs: &[usize],
) -> Option<Traced> {
    set_voxels(&mut seg.lumen, plugs, 0);
    seg.lumen_voxels -= plugs.len();
    let traced = trace(seg, kept, cl_opts, opts, laps).ok();
    if traced.is_none() {
        set_voxels(&mut seg.lumen, plugs, 1);
        seg.lumen_voxels += plugs.len();
    }
    traced
}

/// Detours searched for further holes in one round, at most.
const MAX_DETOURS: usize = 8;

/// Holes beyond `plugs`, found without tracing the centerline again: the skeleton's path
/// round them from the graph its search kept ([`centerline::Skeleton::detour`]), centred and
/// looked along for holes with them plugged, and so on while it finds more. A hole plugged
/// mostly shows the next one nearby: on `ctc/prone-tagged`, 14 whole traces found one to
/// three holes each in the right colon's folds; with detours (25 ms of graph search each) it
/// takes 3. `ds` is `lumen`'s Ds at the round's start, reused: beside the new plugs it is too
/// wide, which moves where a detour looks, not what is plugged (each plug passes the holes'
/// own test, [`shortcut_plugs`], and the whole trace that follows checks the colon holds).
/// `lumen` is without contacts cut, and is left as given; returns the further plugs.
fn holes_beyond(
    lumen: &mut Volume<u8>,
    ds: &Field<f32>,
    sk: &centerline::Skeleton,
    plugs: &[usize],
    cl_opts: &CenterlineOptions,
    necks: &mut Vec<[f64; 3]>,
) -> Vec<usize> {
    let mut closed = plugs.to_vec();
    set_voxels(lumen, plugs, 0);
    for _ in 0..MAX_DETOURS {
        closed.sort_unstable();
        let Some(detour) = sk.detour(lumen, &closed, cl_opts) else {
            break;
        };
        let Ok(ends) = centre_skeleton(lumen, ds, &detour, cl_opts) else {
            break;
        };
        let c = &ends.centerline;
        let found = shortcut_plugs(lumen, &c.points_mm, &c.radius_mm, &c.arc_mm, necks, ds);
        if found.is_empty() {
            break;
        }
        set_voxels(lumen, &found, 0);
        closed.extend(found);
    }
    set_voxels(lumen, &closed, 1);
    closed.retain(|v| plugs.binary_search(v).is_err());
    closed
}

fn set_voxels(mask: &mut Volume<u8>, voxels: &[usize], v: u8) {
    voxels.iter().for_each(|&i| mask.data_mut()[i] = v);
}

/// Stages skeleton, contacts, Ds and centerline: the skeleton's path, the contacts it shows
/// cut from `seg`'s lumen, Ds, and the path centred. The skeleton search runs on blocks with
/// their own Ds when the lumen is large, so the voxels' Ds waits until the contacts are cut;
/// on a small lumen it needs Ds first.
fn trace(
    seg: &mut Segmentation,
    kept: &mut TraceMemory,
    cl_opts: &CenterlineOptions,
    opts: &PrepOptions,
    laps: &mut Laps<impl FnMut(Stage)>,
) -> Result<Traced> {
    laps.start(Stage::Skeleton);
    let early_ds = if uses_blocks(&seg.lumen, seg.lumen_voxels, cl_opts) {
        None
    } else {
        Some(kept.ds_of(&seg.lumen))
    };
    let sk = trace_skeleton(
        &seg.lumen,
        &kept.grid,
        seg.lumen_voxels,
        seg.seed_voxel,
        early_ds.as_ref(),
        cl_opts,
        std::mem::take(&mut kept.skeleton),
    )?;
    laps.start(Stage::Contacts);
    let mut taken = cut_along(
        &mut seg.lumen,
        &kept.grid,
        &sk,
        sk.blocks.as_ref(),
        opts,
        &mut kept.contacts,
    )?;
    taken.sort_unstable();
    laps.start(Stage::Ds);
    let ds_box = match early_ds {
        Some(d) if taken.is_empty() => d,
        early => {
            if let Some(d) = early {
                kept.give_back(d);
            }
            kept.ds_of(&seg.lumen)
        }
    };
    laps.start(Stage::Centerline);
    let ends = centre_skeleton(&seg.lumen, &ds_box, &sk, cl_opts)?;
    Ok(Traced {
        sk,
        ends,
        taken,
        ds_box: Some(ds_box),
    })
}

/// Cuts the contacts between loops along the skeleton's path `sk` from `lumen` (searching on
/// `blocks` when given); returns the voxels taken. No wall at the ends: source and target
/// stay lumen.
fn cut_along(
    lumen: &mut Volume<u8>,
    grid: &BoxGrid,
    sk: &centerline::Skeleton,
    blocks: Option<&crate::grid::Blocks>,
    opts: &PrepOptions,
    memory: &mut ContactMemory,
) -> Result<Vec<usize>> {
    let keep = [
        sk.given_source
            .map(|v| centerline::mm_of(lumen, v))
            .unwrap_or(sk.path_mm[0]),
        sk.given_target
            .map(|v| centerline::mm_of(lumen, v))
            .unwrap_or(sk.path_mm[sk.path_mm.len() - 1]),
    ];
    let keep_mm = 2.0 * lumen.spacing().iter().cloned().fold(0.0, f64::max);
    cut_contacts(
        lumen,
        grid,
        &sk.path_mm,
        blocks,
        &keep,
        keep_mm,
        &opts.contacts,
        memory,
    )
}

/// Rounds of plugging holes beside the centerline, at most (each plugs what Dt shows, and Dt
/// is computed again). The real exam in 2 mm slices takes six rounds for 10 holes between the
/// splenic flexure's limbs: most show only once those beside them are plugged.
const MAX_BESIDE_ROUNDS: usize = 10;
/// Dt's way back to the source is followed from a centerline point this often (mm of arc)
/// in search of holes ([`holes_by_descent`]): the ways join soon, and a hole lies on those of
/// every point beyond it.
const DESCENT_EVERY_MM: f64 = 10.0;
/// A way back that crosses at least this much of the centerline's arc at once may have
/// crossed between loops of the colon ([`holes_by_descent`]); it did where it is as narrow
/// as a hole in a wall ([`crate::contacts::thin_hole_mm`]). On `ctc/prone-tagged` a hole of
/// 0.1 mm joins the hepatic flexure's limbs, 108 mm apart along the centerline (in 3 mm
/// slices, 2.6 mm: the flight's pull drew the camera against it), and one of 0.4 mm joins
/// stretches of the ascending colon 68 mm apart.
const HOLE_NEAR_JUMP_MM: f64 = 60.0;
/// A way back that crosses at least this much of the centerline's arc at once crossed between
/// loops of the colon where it is narrow, even as wide as a quarter of the colon's radius,
/// where a smaller jump may be a gap between folds in one wide chamber: the centerline
/// meanders about 80 mm across the cecum of `ctc/prone-tagged`, 100 mm wide, where the way
/// from its pole crosses folds 2.4–3.9 mm in radius; the splenic flexure's limbs are 260 mm
/// apart along it.
const HOLE_JUMP_MM: f64 = 150.0;

/// The holes beside the centerline that Dt shows (see [`plug_beside`]), none overlapping
/// another: where Dt dips along the centerline ([`shortcut_beside`]), and where Dt's way back
/// from a centerline point crosses between loops ([`holes_by_descent`]).
fn holes_beside(
    lumen: &Volume<u8>,
    ds: &Bricked<f32>,
    dt: &Bricked<f32>,
    cl: &Centerline,
    cl_opts: &CenterlineOptions,
) -> Vec<Hole> {
    let dip = shortcut_beside(cl, dt).map(|(i, _)| (i, [SHORTCUT_DIP_MM; 2]));
    let crossings = holes_by_descent(lumen, dt, cl, HOLE_NEAR_JUMP_MM, DESCENT_EVERY_MM)
        .into_iter()
        .map(|i| (i, [HOLE_NEAR_JUMP_MM, HOLE_JUMP_MM]));
    let mut holes: Vec<Hole> = Vec::new();
    let mut taken = std::collections::HashSet::new();
    for (i, jumps) in dip.into_iter().chain(crossings) {
        for h in plug_beside(lumen, ds, dt, cl, i, jumps, cl_opts) {
            if !h.plugs.iter().any(|v| taken.contains(v)) {
                taken.extend(h.plugs.iter().copied());
                holes.push(h);
            }
        }
    }
    holes
}

/// What the user is told of the holes plugged beside the centerline: how many, where, and
/// which stretches of the colon they joined.
fn holes_warning(g: &crate::Geometry, holes: &[Hole]) -> String {
    let places: Vec<String> = holes
        .iter()
        .map(|h| {
            let at = h
                .plugs
                .iter()
                .map(|&v| DVec3::from_array(g.ijk(v).map(|x| x as f64)))
                .sum::<DVec3>()
                / h.plugs.len() as f64;
            let p = g.index_to_patient(at);
            let [from, to] = h.arcs_mm;
            format!(
                "LPS ({:.0}, {:.0}, {:.0}), {:.1} mm in radius, joining {to:.0} to {from:.0} mm",
                p.x, p.y, p.z, h.neck_mm
            )
        })
        .collect();
    let voxels: usize = holes.iter().map(|h| h.plugs.len()).sum();
    format!(
        "{} hole{} between touching loops of the colon beside the centerline joined stretches far apart along it: plugged ({voxels} voxels), so that the cells and the flight's pull follow the colon: {}",
        holes.len(),
        if holes.len() == 1 { "" } else { "s" },
        places.join("; ")
    )
}

/// Dt from the source falling along the centerline by more than this (mm), and by more
/// than [`SHORTCUT_PER_RADIUS`] times the lumen's radius there, below its highest value so
/// far marks a shortcut ([`shortcut_beside`]). Centring moves the centerline across a wide
/// chamber, where Dt, hugging the inner side of the bends, runs ahead of it: on
/// `ctc/prone-tagged`, its 2 and 3 mm variants, `masks/colon-a` and `ct/abdomen-3mm` Dt falls
/// at most 41 mm along it (1.9 radii, in the 2 mm variant's splenic flexure).
const SHORTCUT_DIP_MM: f64 = 50.0;
const SHORTCUT_PER_RADIUS: f64 = 3.0;

/// The centerline point where Dt from the source lies deepest below its highest value at
/// the points before, when that marks a shortcut ([`SHORTCUT_DIP_MM`]): the lumen there is
/// reached by a way shorter than the centerline's, through a hole between touching loops
/// that the centerline goes round (no round of plugging looks there). Cells are bands of Dt
/// and the flight is pulled down Dt: both would follow that way. Returns the point and how
/// far Dt lies below (mm). (`ctc/prone-tagged` with a bridge costed on local means: 130 mm
/// in the ascending colon, and its last cell held 240 mm of the centerline.)
fn shortcut_beside(cl: &Centerline, dt: &Bricked<f32>) -> Option<(usize, f64)> {
    let mut high = f64::NEG_INFINITY;
    let mut deepest: Option<(usize, f64)> = None;
    for (i, p) in cl.points_mm.iter().enumerate() {
        let d = dt.sample(DVec3::from_array(*p)) as f64;
        if !d.is_finite() {
            continue;
        }
        high = high.max(d);
        let dip = high - d;
        let marks = dip > SHORTCUT_DIP_MM.max(SHORTCUT_PER_RADIUS * cl.radius_mm[i]);
        if marks && deepest.is_none_or(|(_, b)| dip > b) {
            deepest = Some((i, dip));
        }
    }
    deepest
}

/// Each bridged gap's stretch of the centerline (in the order of the gaps): the points whose
/// voxel the bridge added (its tube, or the fluid filling the stretch).
fn gap_spans(cl: &Centerline, seg: &Segmentation) -> Vec<Option<[f64; 2]>> {
    let g = seg.lumen.geometry();
    let voxel_of = |p: &[f64; 3]| {
        let v = g.local_to_index(DVec3::from_array(*p)).round();
        g.contains_index(v)
            .then(|| g.index(v.x as usize, v.y as usize, v.z as usize))
    };
    let voxels: Vec<Option<usize>> = cl.points_mm.iter().map(voxel_of).collect();
    seg.gaps
        .iter()
        .map(|gap| {
            voxels
                .iter()
                .zip(&cl.arc_mm)
                .filter(|(v, _)| v.is_some_and(|v| gap.voxels.binary_search(&v).is_ok()))
                .map(|(_, &arc)| [arc, arc])
                .reduce(|a, b| [a[0].min(b[0]), a[1].max(b[1])])
        })
        .collect()
}

/// Whether most of what `gap`'s bridge added to the lumen is tagged fluid (at or above
/// `fluid_hu` in `ct`): a fluid-filled stretch, not a collapsed one.
fn fluid_filled(gap: &crate::Gap, ct: &Volume<i16>, fluid_hu: Option<i16>) -> bool {
    let Some(t) = fluid_hu else {
        return false;
    };
    let fluid = gap.voxels.iter().filter(|&&v| ct.data()[v] >= t).count();
    !gap.voxels.is_empty() && 2 * fluid >= gap.voxels.len()
}

/// Where the automatic ends lie in the colon's box in the patient frame: the rectum low and
/// near the middle (else the rectum is collapsed, fluid-filled or out of the scan, and the
/// flight starts at the lowest segment's lower end), the cecum on the patient's right and low.
fn anatomical_checks(
    seg: &Segmentation,
    cl: &Centerline,
    source: [usize; 3],
    target: [usize; 3],
    check_source: bool,
    check_target: bool,
) -> Vec<String> {
    let g = seg.lumen.geometry();
    let [a, b] = g.patient_box(seg.extent[0], seg.extent[1]);
    let span = (b - a).max(DVec3::splat(1.0));
    // u: 0 at the patient's right of the colon's box, 1 at its left; v: 0 lowest, 1 highest.
    let place = |v: [usize; 3]| {
        let p = g.index_to_patient(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64));
        ((p.x - a.x) / span.x, (p.z - a.z) / span.z, p)
    };
    let mut out = Vec::new();
    let (u, v, p) = place(source);
    if check_source && ((u - 0.5).abs() > 0.25 || v > 0.3) {
        out.push(format!(
            "the colon's lowest gas, where the flight starts, is not low in the middle of the pelvis (LPS {:.0}, {:.0}, {:.0}): the rectum may be collapsed, fluid-filled or outside the scan; give --source to start elsewhere",
            p.x, p.y, p.z
        ));
    }
    let p = g.index_to_patient(DVec3::new(
        target[0] as f64,
        target[1] as f64,
        target[2] as f64,
    ));
    if check_target && !right_lower(seg, p) {
        out.push(format!(
            "the colon's far end (LPS {:.0}, {:.0}, {:.0}) is not in the right lower quadrant, where the cecum lies: part of the colon may be missing; give --target to end elsewhere",
            p.x, p.y, p.z
        ));
    }
    if let Some(tail) = narrow_tail(cl).filter(|_| check_target) {
        let p = g.local_to_patient(DVec3::from_array(cl.points_mm[tail.from]));
        if right_lower(seg, p) {
            out.push(format!(
                "the colon's far end may lie in small bowel: the centerline's last {:.0} mm, from LPS ({:.0}, {:.0}, {:.0}) where it leaves a chamber {:.0} mm wide low on the right (the cecum), are a tube at most {:.0} mm wide, as the ileum is beyond the ileocaecal valve with gas through it; the flight would end there. Give --target at the cecum's pole",
                tail.length_mm,
                p.x,
                p.y,
                p.z,
                2.0 * tail.chamber_mm,
                2.0 * tail.tube_mm
            ));
        }
    }
    out
}

/// A centerline's last stretch narrower than the lumen before it: see [`narrow_tail`].
#[derive(Debug)]
struct NarrowTail {
    /// The centerline point where it starts.
    from: usize,
    length_mm: f64,
    /// Its widest radius, and the widest within [`CHAMBER_MM`] before it, at point
    /// `chamber_at`.
    tube_mm: f64,
    chamber_mm: f64,
    chamber_at: usize,
}

/// Where the centerline `traced` ran on from the cecum into small bowel ([`narrow_tail`],
/// leaving a chamber low on the right): the tail, and the lumen voxels beyond its valve
/// (ascending). A ball across the tube, [`VALVE_CUT`] tube radii wide, two radii past where
/// the tail begins, cuts the lumen; what the source no longer reaches, with the ball, is
/// the small bowel. None where the cut would take more than half of the lumen.
fn small_bowel_beyond(seg: &Segmentation, traced: &Traced) -> Option<(NarrowTail, Vec<usize>)> {
    let cl = &traced.ends.centerline;
    let tail = narrow_tail(cl)?;
    let g = seg.lumen.geometry();
    let at = g.local_to_patient(DVec3::from_array(cl.points_mm[tail.from]));
    if !right_lower(seg, at) {
        return None;
    }
    let past = cl.arc_mm[tail.from] + 2.0 * tail.tube_mm;
    let k = cl
        .arc_mm
        .partition_point(|&a| a < past)
        .min(cl.arc_mm.len() - 1);
    let centre = DVec3::from_array(cl.points_mm[k]);
    let radius = VALVE_CUT * tail.tube_mm;
    let lumen = seg.lumen.data();
    // The flood works in the lumen's box: every lumen voxel lies in it.
    let [lo, hi] = seg.extent;
    let w = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
    let volume = |b: usize| {
        g.index(
            lo[0] + b % w[0],
            lo[1] + (b / w[0]) % w[1],
            lo[2] + b / (w[0] * w[1]),
        )
    };
    let open = |b: usize| {
        let v = volume(b);
        lumen[v] != 0 && centerline::mm_of(&seg.lumen, g.ijk(v)).distance(centre) > radius
    };
    // A flood of the lumen from the source, round the ball.
    let s = traced.ends.source;
    let first = (s[0] - lo[0]) + w[0] * ((s[1] - lo[1]) + w[1] * (s[2] - lo[2]));
    let mut reached = vec![false; w[0] * w[1] * w[2]];
    reached[first] = true;
    let mut queue = vec![first];
    while let Some(b) = queue.pop() {
        for n in crate::volume::face_neighbours(w, b).into_iter().flatten() {
            if !reached[n] && open(n) {
                reached[n] = true;
                queue.push(n);
            }
        }
    }
    let (mut beyond, mut kept) = (Vec::new(), 0usize);
    for (b, &r) in reached.iter().enumerate() {
        let v = volume(b);
        if r {
            kept += 1;
        } else if lumen[v] != 0 {
            beyond.push(v);
        }
    }
    beyond.sort_unstable();
    (kept > beyond.len() && !beyond.is_empty()).then_some((tail, beyond))
}

/// How wide (tube radii) the ball that cuts the small bowel off at its valve is.
const VALVE_CUT: f64 = 1.5;

/// Whether patient point `p` lies on the patient's right and low in the colon's box, where
/// the cecum lies (the automatic end, and where small bowel leaves it, are checked by it).
fn right_lower(seg: &Segmentation, p: DVec3) -> bool {
    let g = seg.lumen.geometry();
    let [a, b] = g.patient_box(seg.extent[0], seg.extent[1]);
    let span = (b - a).max(DVec3::splat(1.0));
    (p.x - a.x) / span.x <= 0.5 && (p.z - a.z) / span.z <= 0.6
}

/// A narrow tail is at least this long (mm): longer than a cecum (about 60 mm), so a
/// small-bowel loop, not the colon's narrowing end. (Prone with tagged fluid, the cecum's
/// pool meets the ileum's gas at the valve, and the centerline ran about 100 mm on into the
/// loops; at 150 mm that tail was kept.)
const TAIL_MM: f64 = 80.0;
/// ... and nowhere wider than this share of the chamber before it: the ileum (10–12 mm in
/// radius with gas) beyond the cecum (25–45 mm); the colon widens towards its end.
const TAIL_SHARE: f64 = 0.5;
/// How far before the tail the chamber it leaves is looked for (mm of arc).
const CHAMBER_MM: f64 = 100.0;
/// The centerline's last mm, where its radius falls to the wall of the end: left out.
const END_CAP_MM: f64 = 10.0;

/// The longest last stretch of the centerline, at least [`TAIL_MM`] long, whose radius stays
/// within [`TAIL_SHARE`] of the widest radius in the [`CHAMBER_MM`] before it. Where the
/// terminal ileum holds gas joined to the cecum's through the valve, the colon's farthest
/// point lies at the far end of the small bowel, and the centerline runs on into it.
fn narrow_tail(cl: &Centerline) -> Option<NarrowTail> {
    let (arc, radius) = (&cl.arc_mm, &cl.radius_mm);
    let length = *arc.last()?;
    let last = arc
        .partition_point(|&a| a <= length - END_CAP_MM)
        .checked_sub(1)?;
    let mut tube = 0.0f64;
    let mut found = None;
    for i in (0..=last).rev() {
        tube = tube.max(radius[i]);
        if length - arc[i] < TAIL_MM {
            continue;
        }
        let before = arc.partition_point(|&a| a < arc[i] - CHAMBER_MM);
        let Some((chamber_at, chamber)) = (before..i)
            .map(|n| (n, radius[n]))
            .max_by(|a, b| a.1.total_cmp(&b.1))
        else {
            continue;
        };
        if tube <= TAIL_SHARE * chamber {
            found = Some(NarrowTail {
                from: i,
                length_mm: length - arc[i],
                tube_mm: tube,
                chamber_mm: chamber,
                chamber_at,
            });
        } else if found.is_some() {
            break;
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::{Bricked, Centerline, Field, monotone_labels, shortcut_beside};

    /// Dt along a straight centerline 200 mm long: where the far half is reached by a way
    /// 100 mm shorter (a hole beside it), the shortcut is found where Dt falls; a fall of
    /// 40 mm (the centerline crossing a chamber) is not one.
    #[test]
    fn a_shortcut_beside_the_centerline_is_found_where_dt_falls() {
        use crate::{Geometry, grid::BoxGrid};
        let g = Geometry::new([201, 3, 3], [1.0; 3], [0.0; 3]).unwrap();
        let cl = Centerline {
            points_mm: (0..=200).map(|i| [i as f64, 1.0, 1.0]).collect(),
            arc_mm: (0..=200).map(|i| i as f64).collect(),
            radius_mm: vec![5.0; 201],
            length_mm: 200.0,
            canal_mm: 0.0,
        };
        let dt_of = |dt: &dyn Fn(f64) -> f64| {
            let grid = BoxGrid::around([[0, 0, 0], [200, 2, 2]], 0, g.dims);
            let mut f = Field::filled(grid, g.clone(), 0.0f32);
            for (n, v) in f.data.iter_mut().enumerate() {
                *v = dt((n % 201) as f64) as f32;
            }
            Bricked::from_field(&f, f32::INFINITY)
        };
        let hole = dt_of(&|x| if x <= 120.0 { x } else { x - 100.0 });
        let (i, dip) = shortcut_beside(&cl, &hole).expect("a shortcut");
        assert_eq!((i, dip.round()), (121, 99.0));
        let chamber = dt_of(&|x| {
            if (60.0..80.0).contains(&x) {
                x - 40.0
            } else {
                x
            }
        });
        assert_eq!(shortcut_beside(&cl, &chamber), None);
    }

    #[test]
    fn monotone_labels_keep_the_order_and_disagree_least() {
        // A stray label out of order costs one disagreement; of the equal answers the
        // earlier label wins.
        assert_eq!(
            monotone_labels(&[0, 0, 2, 1, 1, 3, 3], 4),
            [0, 0, 0, 1, 1, 3, 3]
        );
        assert_eq!(
            monotone_labels(&[0, 0, 2, 2, 1, 2, 3], 4),
            [0, 0, 2, 2, 2, 2, 3]
        );
        assert_eq!(monotone_labels(&[3, 2, 1, 0], 4), [0, 0, 0, 0]);
        assert_eq!(monotone_labels(&[0, 1, 2, 7, 3, 4], 8), [0, 1, 2, 2, 3, 4]);
        assert!(monotone_labels(&[], 8).is_empty());
    }
}
