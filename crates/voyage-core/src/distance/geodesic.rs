//! Dt: single-source shortest-path distance through the lumen (paper §3.2, "single-source
//! shortest path algorithm"), over 26-neighbours with edge lengths in mm.
//!
//! Dial's bucket queue instead of a binary heap: with bucket width equal to the shortest edge
//! (the smallest voxel spacing), no voxel can improve another in the same bucket, so buckets
//! may be emptied in any order and the result is the exact Dijkstra distance. Each voxel costs
//! a push and a pop into a `Vec`, not a heap's log n.
//!
//! **How it is made fast.** The search runs on a `Padded` copy of the lumen's box, so no
//! neighbour test needs a bounds check; a settled voxel is marked by the sign bit of its
//! distance; the nine rows of three neighbours are compared four wide (SSE, weighted or not)
//! into one mask per voxel, and the rows of the voxel 16 places ahead in the bucket are
//! prefetched. Fresh box-sized memory costs a page fault per page (up to a third of a search
//! on a VM), so the searches work in a [`SearchMemory`] their caller owns (prep's starts as Ds's box
//! array, allocated with room for the padded layout), and [`geodesic_distance_like`] writes Dt
//! straight into Ds's bricks. [`geodesic_distance`] marks the bricks holding lumen while it
//! lays out its start (`BrickMarks`), so finishing makes no pass over the box to find them.
//! `TreeStart` keeps a weighted tree search's arrays for several searches: one stopped early is
//! rewound over the neighbourhoods of the voxels it settled. Timings: BENCHMARKS.md.

use crate::{
    Error, Result, Volume,
    grid::{BoxGrid, BrickIndex, BrickMarks, Bricked, PadIndex, Padded},
};

/// Dt and what the search learned on the way.
#[derive(Clone, Debug)]
pub struct Geodesic {
    /// Distance in mm from the source through lumen voxels; +∞ where unreachable or not lumen
    /// (bricks with no reached voxel are not stored).
    pub dist: Bricked<f32>,
    /// The reachable voxel farthest from the source (volume voxel index).
    pub farthest: [usize; 3],
    pub max_mm: f32,
    /// Number of lumen voxels reached.
    pub reached: usize,
}

impl Geodesic {
    /// `dist` (the search's distances, finished) with what search `r` over `shape` learned.
    fn found(shape: &Padded, r: &Search, dist: Bricked<f32>) -> Self {
        Geodesic {
            farthest: shape.global_of_index(PadIndex(r.far)),
            max_mm: r.far_d,
            reached: r.reached,
            dist,
        }
    }
}

/// Shortest-path distances from `source` (a lumen voxel) to every lumen voxel of `mask`
/// inside `grid`.
///
/// The distances start straight from the mask (walls 0, lumen +∞: no padded copy of the mask
/// is needed, the search itself tells walls by their 0) and are finished and moved into
/// bricks in one pass.
pub fn geodesic_distance(
    mask: &Volume<u8>,
    grid: &BoxGrid,
    source: [usize; 3],
) -> Result<Geodesic> {
    let mut marks = BrickMarks::new(grid);
    let (shape, r) = search_from(mask, grid, source, Vec::new(), Some(&mut marks))?;
    let dist = shape.finish_bricked(&r.dist, mask.geometry(), marks);
    Ok(Geodesic::found(&shape, &r, dist))
}

/// The memory the searches work in, reused from one search to the next by whoever runs
/// several (`prepare`): a fresh box-sized array costs a page fault per page, which on some
/// machines costs as much as the search itself. Any length; a search grows it as it needs.
#[derive(Debug, Default)]
pub struct SearchMemory {
    dist: Vec<f32>,
}

impl From<Vec<f32>> for SearchMemory {
    /// Memory some other field is done with (prep hands over Ds's box array, allocated with
    /// room for the padded layout).
    fn from(dist: Vec<f32>) -> Self {
        SearchMemory { dist }
    }
}

/// [`geodesic_distance`] over the box of `like` and stored in the bricks it stores, which must
/// hold every lumen voxel of the box (Ds's bricks do): the finishing pass then reads those
/// bricks only. The search works in `memory`.
pub fn geodesic_distance_like<U>(
    mask: &Volume<u8>,
    like: &Bricked<U>,
    source: [usize; 3],
    memory: &mut SearchMemory,
) -> Result<Geodesic> {
    let (shape, r) = search_from(
        mask,
        &like.grid,
        source,
        std::mem::take(&mut memory.dist),
        None,
    )?;
    let dist =
        Bricked::from_rows_like(like, f32::INFINITY, |j, k| shape.row(&r.dist, j, k), finish);
    let found = Geodesic::found(&shape, &r, dist);
    memory.dist = r.dist;
    Ok(found)
}

/// Where Dt is searched and what a step costs (see `navigable.rs`).
#[derive(Clone, Copy, Debug)]
pub struct CoreSpec<'a> {
    /// Lumen voxels with Ds at least this (mm) are searched.
    pub min_ds_mm: f64,
    /// A step costs `1 + (wall_weight − 1)·(1 − Ds/ramp_mm)` per mm where Ds < `ramp_mm`,
    /// 1 beyond: Dt's ways keep off the wall where the lumen lets them.
    pub ramp_mm: f64,
    pub wall_weight: f32,
    /// Points where the lumen is narrow (volume-local mm): the lumen within `open_mm` of
    /// each is searched too, so that a neck joins the core without thinning it everywhere.
    pub narrows_mm: &'a [[f64; 3]],
    pub open_mm: f64,
}

/// Dt to both ends over the lumen's **core** (`spec`: the voxels of `mask` whose Ds — `ds`,
/// over the lumen's box, in bricks holding every lumen voxel — is at least `min_ds_mm`, and
/// the lumen around the narrows): the length (mm) of the cheapest way, a step near the wall
/// costing more (so the ways keep off it), `[to target, to source]` in `ds`'s bricks, +∞
/// outside the core. The ends are the first and the last of
/// `path_mm` (volume-local mm, source first) that lie in the core. None when no path point
/// lies in the core or the ends are not joined in it. The searches work in `memory`, one
/// after the other.
pub fn core_distances(
    mask: &Volume<u8>,
    ds: &Bricked<f32>,
    spec: &CoreSpec,
    path_mm: &[[f64; 3]],
    memory: &mut SearchMemory,
) -> Option<[Bricked<f32>; 2]> {
    let shape = Padded::shape(&ds.grid);
    let outside_core = |d: f32| (d as f64) < spec.min_ds_mm;
    let sp = mask.spacing();
    let open = opened_near(mask, spec.narrows_mm, spec.open_mm);
    let in_core = |p: &[f64; 3]| {
        let v = [0, 1, 2].map(|a| (p[a] / sp[a]).round().max(0.0) as usize);
        let i = shape.index_of_global(v)?;
        (mask.get(v[0], v[1], v[2]) != 0 && (!outside_core(ds.get(v)) || open.contains(&v)))
            .then_some(i)
    };
    let s = path_mm.iter().find_map(in_core)?;
    let t = path_mm.iter().rev().find_map(in_core)?;
    let padded = |l: [usize; 3]| shape.row_start(l[1], l[2]) + l[0];
    let local = |v: &[usize; 3]| [0, 1, 2].map(|a| v[a] - ds.grid.lo[a]);
    let mut weight = vec![1.0f32; shape.search_len()];
    for (at, &d) in ds.values().iter().enumerate() {
        let l = ds.box_voxel(BrickIndex(at));
        if (d as f64) < spec.ramp_mm && (0..3).all(|a| l[a] < ds.grid.dims[a]) {
            let t = (1.0 - d as f64 / spec.ramp_mm) as f32;
            weight[padded(l)] = 1.0 + (spec.wall_weight - 1.0) * t;
        }
    }
    let range = (1.0, spec.wall_weight.max(1.0));
    // The start from the mask with the lumen outside the core made wall (every lumen voxel
    // lies in Ds's bricks).
    let search = |from: PadIndex, memory: &mut SearchMemory| {
        let mut start = shape.start_from_mask(mask, std::mem::take(&mut memory.dist), None);
        for (at, &d) in ds.values().iter().enumerate() {
            if outside_core(d) {
                let l = ds.box_voxel(BrickIndex(at));
                if (0..3).all(|a| l[a] < ds.grid.dims[a]) {
                    start[padded(l)] = 0.0;
                }
            }
        }
        for v in &open {
            start[padded(local(v))] = f32::INFINITY;
        }
        let mut r = shape
            .search(sp)
            .start(start)
            .weighted_in(&weight, range)
            .tree_in(vec![NO_PARENT; shape.search_len()])
            .unfinished()
            .from(&[from]);
        lengths_along_tree(&mut r);
        r
    };
    let bricked = |r: Search, memory: &mut SearchMemory| {
        let dist =
            Bricked::from_rows_like(ds, f32::INFINITY, |j, k| shape.row(&r.dist, j, k), finish);
        memory.dist = r.dist;
        dist
    };
    let to_t = search(t, memory);
    if !finish(to_t.dist[s.0]).is_finite() {
        memory.dist = to_t.dist;
        return None;
    }
    let to_target = bricked(to_t, memory);
    let to_s = search(s, memory);
    Some([to_target, bricked(to_s, memory)])
}

/// Replaces a weighted tree search's costs by the lengths (mm) of its ways: each voxel's
/// way is its parent's and one step, in settling order (parents first), stored settled
/// (negated) as the search leaves its distances.
fn lengths_along_tree(r: &mut Search) {
    for i in 0..r.order.len() {
        let v = r.order[i] as usize;
        r.dist[v] = match r.parent[v] {
            NO_PARENT => -0.0,
            p => {
                let (off, len) = r.nbrs[p as usize];
                r.dist[(v as isize + off) as usize] - len
            }
        };
    }
}

/// The lumen voxels (global) of `mask` within `reach_mm` of each point (volume-local mm),
/// sorted (all in Ds's box, which holds every lumen voxel).
fn opened_near(
    mask: &Volume<u8>,
    points_mm: &[[f64; 3]],
    reach_mm: f64,
) -> std::collections::BTreeSet<[usize; 3]> {
    points_mm
        .iter()
        .flat_map(|&p| crate::volume::set_voxels_in_ball(mask, p, reach_mm))
        .collect()
}

/// The plain search from `source` over `grid`, its distances left unfinished ([`finish`]);
/// `marks`, when given, hears of the bricks that hold lumen as the mask is read.
fn search_from(
    mask: &Volume<u8>,
    grid: &BoxGrid,
    source: [usize; 3],
    scratch: Vec<f32>,
    marks: Option<&mut BrickMarks>,
) -> Result<(Padded, Search)> {
    let shape = Padded::shape(grid);
    let src = source_index(mask, &shape, source)?;
    let dist = shape.start_from_mask(mask, scratch, marks);
    let r = shape
        .search(mask.spacing())
        .start(dist)
        .unfinished()
        .from(&[src]);
    Ok((shape, r))
}

/// The padded index of `source`, which must be lumen.
fn source_index(mask: &Volume<u8>, shape: &Padded, source: [usize; 3]) -> Result<PadIndex> {
    shape
        .index_of_global(source)
        .filter(|_| mask.get(source[0], source[1], source[2]) != 0)
        .ok_or_else(|| Error::invalid(format!("the voxel {source:?} is not in the lumen")))
}

/// What a search over the padded grid found.
pub struct Search {
    pub dist: Vec<f32>,
    pub far: usize,
    pub far_d: f32,
    pub reached: usize,
    /// With `tree`: per voxel, the index into `nbrs` of the offset to its predecessor
    /// ([`NO_PARENT`] for sources and unreached voxels), and the voxels in settling order.
    pub parent: Vec<u8>,
    pub order: Vec<u32>,
    pub nbrs: Vec<(isize, f32)>,
}

pub const NO_PARENT: u8 = u8::MAX;

impl Search {
    /// The voxel `v` was reached from (needs `tree`).
    #[inline]
    pub fn parent_of(&self, v: usize) -> Option<usize> {
        let p = self.parent[v];
        (p != NO_PARENT).then(|| (v as isize + self.nbrs[p as usize].0) as usize)
    }
}

/// One search over a padded grid, set up step by step ([`Padded::search`]) and run by
/// [`SearchBuilder::from`], which picks the kernel monomorphised for what was asked. Dial's
/// algorithm: with a weight the bucket width is the shortest edge times the smallest weight,
/// which keeps the buckets exact.
#[must_use]
pub struct SearchBuilder<'a> {
    pad: &'a Padded,
    spacing: [f64; 3],
    weight: Option<&'a [f32]>,
    /// The weight's smallest and largest value over the lumen, when known.
    range: Option<(f32, f32)>,
    tree: Option<Vec<u8>>,
    stop: Option<&'a dyn Fn(usize) -> bool>,
    start: Option<Vec<f32>>,
    finish: bool,
}

impl<'a> SearchBuilder<'a> {
    /// Per-voxel cost weight (padded layout, > 0 on lumen voxels): an edge u–v costs its
    /// length times (w(u) + w(v)) / 2.
    #[cfg(test)]
    pub fn weighted(mut self, weight: &'a [f32]) -> Self {
        self.weight = Some(weight);
        self
    }

    /// [`SearchBuilder::weighted`] with the weight's smallest and largest value over the
    /// lumen already known.
    pub(crate) fn weighted_in(mut self, weight: &'a [f32], range: (f32, f32)) -> Self {
        self.weight = Some(weight);
        self.range = Some(range);
        self
    }

    /// Record predecessors and the settling order.
    #[cfg(test)]
    pub fn tree(self) -> Self {
        self.tree_reusing(Vec::new())
    }

    /// Record predecessors and the settling order, in the memory of `parent` where it is
    /// large enough.
    pub(crate) fn tree_reusing(self, parent: Vec<u8>) -> Self {
        let n = self.pad.inside.len();
        self.tree_in(crate::mem::refilled(parent, n, NO_PARENT))
    }

    /// Record predecessors and the settling order in `parent` (all [`NO_PARENT`], as long as
    /// the padded grid).
    pub(crate) fn tree_in(mut self, parent: Vec<u8>) -> Self {
        self.tree = Some(parent);
        self
    }

    /// Stop, after settling it, at the first voxel where `stop` holds.
    pub fn stop_at(mut self, stop: &'a dyn Fn(usize) -> bool) -> Self {
        self.stop = Some(stop);
        self
    }

    /// Start from these distances (see [`start_from_inside`]) instead of the grid's mask.
    pub(crate) fn start(mut self, dist: Vec<f32>) -> Self {
        self.start = Some(dist);
        self
    }

    /// Leave the distances as the search leaves them, for the caller to [`finish`].
    pub(crate) fn unfinished(mut self) -> Self {
        self.finish = false;
        self
    }

    /// Runs the search from `sources` (lumen voxels).
    pub fn from(self, sources: &[PadIndex]) -> Search {
        let sources: Vec<usize> = sources.iter().map(|s| s.0).collect();
        let pad = self.pad;
        let dist = self.start.unwrap_or_else(|| start_from_inside(pad));
        let (tree, parent) = match self.tree {
            Some(p) => (true, p),
            None => (false, Vec::new()),
        };
        let weight = self.weight.unwrap_or(&[]);
        let run = match (self.weight.is_some(), tree) {
            (true, true) => dial_impl::<true, true>,
            (true, false) => dial_impl::<true, false>,
            (false, true) => dial_impl::<false, true>,
            (false, false) => dial_impl::<false, false>,
        };
        run(
            pad,
            dist,
            parent,
            &sources,
            self.spacing,
            weight,
            self.range,
            self.stop,
            self.finish,
        )
    }
}

/// The searches' side of the padded layout.
impl Padded {
    /// A search over this grid with edge lengths from `spacing` (mm).
    pub fn search(&self, spacing: [f64; 3]) -> SearchBuilder<'_> {
        SearchBuilder {
            pad: self,
            spacing,
            weight: None,
            range: None,
            tree: None,
            stop: None,
            start: None,
            finish: true,
        }
    }

    /// A search's starting distances in the padded layout straight from the mask: 0 for walls
    /// and padding, +∞ for lumen, plus the spare wall at the end the row loads need; in
    /// `reuse`'s memory where it is large enough; `marks` hears of the bricks holding lumen.
    pub(crate) fn start_from_mask(
        &self,
        mask: &Volume<u8>,
        reuse: Vec<f32>,
        marks: Option<&mut BrickMarks>,
    ) -> Vec<f32> {
        self.lay_out_mask(
            mask,
            1,
            0.0f32,
            |m| if m != 0 { f32::INFINITY } else { 0.0 },
            reuse,
            marks,
        )
    }

    /// Unfinished search distances ([`finish`]) in bricks (+∞ outside): the bricks that hold
    /// lumen, as marked when the search's start was read from the mask (no pass over the
    /// distances to find them). Walls finish as +∞, so a brick without lumen holds nothing else.
    pub(crate) fn finish_bricked(
        &self,
        v: &[f32],
        geometry: &crate::Geometry,
        marks: BrickMarks,
    ) -> Bricked<f32> {
        Bricked::from_rows_marked(
            &self.grid,
            geometry,
            f32::INFINITY,
            marks,
            |j, k| self.row(v, j, k),
            finish,
        )
    }
}

/// The working arrays of weighted tree searches over one padded grid at their start
/// (distances as [`start_from_inside`], no predecessors) and the weight's range over the lumen,
/// which sets the buckets: made once for several searches, as a search that stops after a few
/// voxels ([`TreeStart::nearest`]) hands them back rewound in time proportional to what it
/// touched, not to the grid.
pub(crate) struct TreeStart {
    dist: Vec<f32>,
    parent: Vec<u8>,
    range: (f32, f32),
}

impl TreeStart {
    #[cfg(test)]
    pub(crate) fn new(pad: &Padded, weight: &[f32]) -> Self {
        Self::new_in(pad, weight, Vec::new(), Vec::new())
    }

    /// In the memory of `dist` and `parent` where they are large enough (a search done with).
    pub(crate) fn new_in(pad: &Padded, weight: &[f32], dist: Vec<f32>, parent: Vec<u8>) -> Self {
        let range = weight
            .iter()
            .zip(&pad.inside)
            .filter(|(_, m)| **m != 0)
            .fold((f32::INFINITY, 0.0f32), |(lo, hi), (&x, _)| {
                (lo.min(x), hi.max(x))
            });
        TreeStart {
            dist: start_from_inside_in(pad, dist),
            parent: crate::mem::refilled(parent, pad.inside.len(), NO_PARENT),
            range,
        }
    }

    /// The weighted search from `sources` to its end.
    pub(crate) fn search(
        self,
        pad: &Padded,
        sources: &[PadIndex],
        spacing: [f64; 3],
        weight: &[f32],
    ) -> Search {
        pad.search(spacing)
            .weighted_in(weight, self.range)
            .tree_in(self.parent)
            .start(self.dist)
            .from(sources)
    }

    /// The last voxel the weighted search from `sources` settles: the first where `stop` holds
    /// (else the farthest), and the arrays back at their start.
    pub(crate) fn nearest(
        self,
        pad: &Padded,
        sources: &[PadIndex],
        spacing: [f64; 3],
        weight: &[f32],
        stop: &dyn Fn(usize) -> bool,
    ) -> (Option<PadIndex>, TreeStart) {
        let range = self.range;
        let r = pad
            .search(spacing)
            .weighted_in(weight, range)
            .tree_in(self.parent)
            .start(self.dist)
            .stop_at(stop)
            .unfinished()
            .from(sources);
        let (mut dist, mut parent) = (r.dist, r.parent);
        // Every value the search wrote belongs to a voxel it settled or to one of their
        // neighbours (improved from them): walls, never written, are exactly +0.
        let rows = pad.neighbour_row_starts();
        for &u in &r.order {
            for start in rows {
                let at = (u as isize + start) as usize;
                for v in at..at + 3 {
                    if dist[v].to_bits() != 0 {
                        dist[v] = f32::INFINITY;
                        parent[v] = NO_PARENT;
                    }
                }
            }
        }
        (
            r.order.last().map(|&u| PadIndex(u as usize)),
            TreeStart {
                dist,
                parent,
                range,
            },
        )
    }
}

/// Starting distances from the padded mask: walls 0 (so that `candidate < dist[v]` is never
/// true for them and the inner loop needs no separate test of what the neighbour is), lumen
/// +∞, and one spare wall at the end: the four-wide row loads read a lane past the last
/// neighbour.
fn start_from_inside(pad: &Padded) -> Vec<f32> {
    start_from_inside_in(pad, Vec::new())
}

/// [`start_from_inside`] in the memory of `reuse` where it is large enough.
pub(crate) fn start_from_inside_in(pad: &Padded, reuse: Vec<f32>) -> Vec<f32> {
    let values = pad
        .inside
        .iter()
        .map(|&m| if m != 0 { f32::INFINITY } else { 0.0 })
        .chain([0.0]);
    crate::mem::collect_in(reuse, pad.inside.len() + 1, values)
}

/// A search's final distance from its working value: settled voxels carry their distance
/// with the sign bit set, walls 0 (→ +∞), unreached lumen +∞, and voxels reached but not
/// settled (a search stopped early) their tentative distance.
#[inline]
fn finish(d: f32) -> f32 {
    if d.is_sign_negative() {
        -d
    } else if d == 0.0 {
        f32::INFINITY
    } else {
        d
    }
}

/// `W`: weighted; `T`: record the tree. Monomorphised so the plain search pays for neither.
///
/// `dist`: the starting distances (see [`start_from_inside`]); `parent`, with `T`: all
/// [`NO_PARENT`], as long as the padded grid; `range`: the weight's smallest and largest value
/// over the lumen, when the caller knows it. With `finalize` the result's distances are
/// finished ([`finish`]) and as long as the padded grid, else left as the search leaves them
/// for the caller to finish.
#[allow(clippy::too_many_arguments)]
fn dial_impl<const W: bool, const T: bool>(
    pad: &Padded,
    mut dist: Vec<f32>,
    mut parent: Vec<u8>,
    sources: &[usize],
    spacing: [f64; 3],
    weight: &[f32],
    range: Option<(f32, f32)>,
    stop: Option<&dyn Fn(usize) -> bool>,
    finalize: bool,
) -> Search {
    let nbrs = pad.neighbours(spacing);
    let (w_min, w_max) = match range {
        _ if !W => (1.0, 1.0),
        Some(r) => r,
        None => weight
            .iter()
            .zip(&dist)
            .filter(|(_, d)| **d != 0.0)
            .fold((f32::INFINITY, 0.0f32), |(lo, hi), (&x, _)| {
                (lo.min(x), hi.max(x))
            }),
    };
    let w_min = if w_min.is_finite() {
        w_min.max(1e-6)
    } else {
        1.0
    };
    let shortest = nbrs.iter().map(|n| n.1).fold(f32::INFINITY, f32::min);
    let longest = nbrs.iter().map(|n| n.1).fold(0.0, f32::max);
    let width = shortest * w_min;
    let inv_width = 1.0 / width;
    // Buckets in a ring (a power of two, for the wrap): a relaxation never reaches more than
    // the costliest edge beyond the current bucket.
    let ring = ((longest * w_max.max(w_min) / width).ceil() as usize + 2).next_power_of_two();
    let wrap = ring - 1;
    let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); ring];
    let n = dist.len() - 1;
    // A settled voxel is never improved: within a bucket distances differ by less than the
    // bucket width, and every edge is at least that long. Settling flips the sign bit (−0.0
    // for a source), which keeps `candidate < dist[v]` false and marks the voxel done without
    // a second array.
    let rows = neighbour_rows(pad, spacing);
    let mut order = Vec::new();
    // Offsets back: parent code c of v means v + nbrs[c].0 is the predecessor.
    let back: Vec<u8> = nbrs
        .iter()
        .map(|&(off, _)| nbrs.iter().position(|&(o, _)| o == -off).unwrap_or(0) as u8)
        .collect();
    let mut pending = 0usize;
    for &s in sources {
        if dist[s] > 0.0 {
            dist[s] = 0.0;
            buckets[0].push(s as u32);
            pending += 1;
        }
    }
    let mut current = 0usize;
    let (mut far, mut far_d, mut reached) = (sources.first().copied().unwrap_or(0), 0.0f32, 0usize);
    let mut work = Vec::new();
    'outer: while pending > 0 {
        let slot = current & wrap;
        while !buckets[slot].is_empty() {
            std::mem::swap(&mut work, &mut buckets[slot]);
            pending -= work.len();
            for (i, &u) in work.iter().enumerate() {
                if let Some(&ahead) = work.get(i + PREFETCH_AHEAD) {
                    prefetch_rows(&dist, ahead as usize, &rows);
                    if W {
                        prefetch_rows(weight, ahead as usize, &rows);
                    }
                }
                let u = u as usize;
                let du = dist[u];
                if du.is_sign_negative() {
                    continue;
                }
                dist[u] = -du;
                reached += 1;
                if T {
                    order.push(u as u32);
                }
                if du > far_d {
                    far_d = du;
                    far = u;
                }
                if stop.is_some_and(|f| f(u)) {
                    break 'outer;
                }
                // Files v at its new distance dv (it was `old`), reached through neighbour code c.
                macro_rules! improve {
                    ($v:expr, $dv:expr, $old:expr, $c:expr) => {{
                        let (v, dv, old) = ($v, $dv, $old);
                        dist[v] = dv;
                        if T {
                            parent[v] = back[$c];
                        }
                        // Rounding can put dv a hair below the next bucket: never file it
                        // earlier than the one being emptied.
                        let b = ((dv * inv_width) as usize).max(current);
                        // Already waiting in that bucket (its old entry is there): it will be
                        // taken with the new distance.
                        if !(old.is_finite() && ((old * inv_width) as usize).max(current) == b) {
                            buckets[b & wrap].push(v as u32);
                            pending += 1;
                        }
                    }};
                }
                // The 26 neighbours are nine rows of three along x: each row is one four-wide
                // comparison, and the nine results are gathered into one mask before any is
                // acted on (the rows do not overlap), so that a voxel costs one loop over its
                // improved neighbours, not 26 hard-to-predict tests. Neighbours are improved
                // in the order of `nbrs`, as a loop over them would.
                let wu = if W { weight[u] } else { 0.0 };
                let mut improved = 0u64;
                for (r, row) in rows.iter().enumerate() {
                    let at = (u as isize + row.start) as usize;
                    let m = if W {
                        weighted_row_improvements(&dist, weight, at, du, wu, &row.len)
                    } else {
                        row_improvements(&dist, at, du, &row.len)
                    };
                    improved |= (m as u64) << (4 * r);
                }
                while improved != 0 {
                    let bit = improved.trailing_zeros() as usize;
                    improved &= improved - 1;
                    let (r, lane) = (bit / 4, bit % 4);
                    let v = (u as isize + rows[r].start) as usize + lane;
                    let len = rows[r].len[lane];
                    let dv = if W {
                        du + len * 0.5 * (wu + weight[v])
                    } else {
                        du + len
                    };
                    improve!(v, dv, dist[v], row_code(r, lane));
                }
            }
            work.clear();
        }
        current += 1;
    }
    if finalize {
        dist.truncate(n);
        dist.iter_mut().for_each(|d| *d = finish(*d));
    }
    Search {
        dist,
        far,
        far_d,
        reached,
        parent,
        order,
        nbrs,
    }
}

/// How many voxels of a bucket ahead the neighbour rows are fetched: the rows of the voxel
/// being settled are spread over three slices of the box, and waiting for them was a third
/// of the search's time.
const PREFETCH_AHEAD: usize = 16;

/// Asks the cache for the nine neighbour rows of voxel `u`.
#[inline(always)]
fn prefetch_rows(dist: &[f32], u: usize, rows: &[Row; 9]) {
    for row in rows {
        crate::mem::prefetch(dist, (u as isize + row.start) as usize);
    }
}

/// A row of three neighbours along x: the offset of its first (di = −1) and the four lanes'
/// edge lengths (+∞ for the fourth lane, and for the voxel itself in the middle row).
struct Row {
    start: isize,
    len: [f32; 4],
}

/// The nine rows, in the order of [`Padded::neighbours`] (dk, then dj).
fn neighbour_rows(pad: &Padded, spacing: [f64; 3]) -> [Row; 9] {
    let starts = pad.neighbour_row_starts();
    std::array::from_fn(|r| {
        let (dj, dk) = ((r % 3) as isize - 1, (r / 3) as isize - 1);
        let mut len = [f32::INFINITY; 4];
        for (lane, l) in len.iter_mut().take(3).enumerate() {
            let di = lane as isize - 1;
            if (di, dj, dk) != (0, 0, 0) {
                *l = ((di as f64 * spacing[0]).powi(2)
                    + (dj as f64 * spacing[1]).powi(2)
                    + (dk as f64 * spacing[2]).powi(2))
                .sqrt() as f32;
            }
        }
        Row {
            start: starts[r],
            len,
        }
    })
}

/// The index into [`Padded::neighbours`] of lane `lane` of row `r` (the voxel itself, index 13
/// of the 27, is not in that list).
#[inline]
fn row_code(r: usize, lane: usize) -> usize {
    let i = 3 * r + lane;
    if i > 13 { i - 1 } else { i }
}

/// Which of the four lanes at `dist[at..at + 4]` a path through the settled voxel (distance
/// `du`) improves (its candidate `du + len[lane]` is smaller), as bits.
#[inline(always)]
fn row_improvements(dist: &[f32], at: usize, du: f32, len: &[f32; 4]) -> u32 {
    crate::simd::lanes_improved(&dist[at..], du, len)
}

/// [`row_improvements`] of a weighted search: lane l's candidate is
/// `du + len[l] · 0.5 · (wu + weight[at + l])`, computed as the scalar code computes it.
#[inline(always)]
fn weighted_row_improvements(
    dist: &[f32],
    weight: &[f32],
    at: usize,
    du: f32,
    wu: f32,
    len: &[f32; 4],
) -> u32 {
    // The fourth lane (never a neighbour: its length is +∞) may lie past the weights' end.
    let w = match weight.get(at..at + 4) {
        Some(w) => [w[0], w[1], w[2], w[3]],
        None => [weight[at], weight[at + 1], weight[at + 2], 0.0],
    };
    crate::simd::weighted_lanes_improved(&dist[at..], du, wu, &w, len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Geometry, distance::distance_to_wall, grid::bounding_box};
    use std::{cmp::Reverse, collections::BinaryHeap};

    /// Textbook Dijkstra with a binary heap in f64, over the whole volume.
    fn reference(mask: &Volume<u8>, src: [usize; 3]) -> Vec<f64> {
        reference_weighted(mask, src, |_| 1.0)
    }

    /// The same with an edge u–v costing its length times (w(u) + w(v)) / 2 (volume indices).
    fn reference_weighted(
        mask: &Volume<u8>,
        src: [usize; 3],
        w: impl Fn(usize) -> f64,
    ) -> Vec<f64> {
        let g = mask.geometry();
        let [nx, ny, nz] = g.dims;
        let s = g.spacing;
        let mut d = vec![f64::INFINITY; g.len()];
        let mut heap = BinaryHeap::new();
        let si = g.index(src[0], src[1], src[2]);
        d[si] = 0.0;
        heap.push(Reverse((0u64, si)));
        while let Some(Reverse((dk, u))) = heap.pop() {
            let du = f64::from_bits(dk);
            if du > d[u] {
                continue;
            }
            let [i, j, k] = g.ijk(u);
            for dk in -1i64..=1 {
                for dj in -1i64..=1 {
                    for di in -1i64..=1 {
                        let (a, b, c) = (i as i64 + di, j as i64 + dj, k as i64 + dk);
                        if (di, dj, dk) == (0, 0, 0)
                            || a < 0
                            || b < 0
                            || c < 0
                            || a >= nx as i64
                            || b >= ny as i64
                            || c >= nz as i64
                        {
                            continue;
                        }
                        let v = g.index(a as usize, b as usize, c as usize);
                        if mask.data()[v] == 0 {
                            continue;
                        }
                        let len = ((di as f64 * s[0]).powi(2)
                            + (dj as f64 * s[1]).powi(2)
                            + (dk as f64 * s[2]).powi(2))
                        .sqrt();
                        let dv = du + len * 0.5 * (w(u) + w(v));
                        if dv < d[v] {
                            d[v] = dv;
                            heap.push(Reverse((dv.to_bits(), v)));
                        }
                    }
                }
            }
        }
        d
    }

    fn maze(dims: [usize; 3], spacing: [f64; 3], seed: u64) -> Volume<u8> {
        let g = Geometry::new(dims, spacing, [0.0; 3]).unwrap();
        let mut rng = crate::rng::Rng::new(seed, 0);
        let data = (0..g.len())
            .map(|_| (rng.next_u64() % 100 < 70) as u8)
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    #[test]
    fn matches_reference_dijkstra() {
        for seed in [3u64, 5, 8] {
            let mut m = maze([24, 19, 15], [0.82, 0.82, 1.25], seed);
            m.set(0, 0, 0, 1); // touches the volume border: padding must hold
            let grid = bounding_box(&m, 1, |v| v != 0).unwrap();
            let geo = geodesic_distance(&m, &grid, [0, 0, 0]).unwrap();
            let want = reference(&m, [0, 0, 0]);
            let got = geo.dist.to_volume().unwrap();
            // Into Ds's bricks: the same distances.
            // Into Ds's bricks, in memory left over from another search: the same distances.
            let ds = Bricked::from_field(&distance_to_wall(&m).unwrap(), 0.0);
            let mut memory = SearchMemory::from(vec![7.0; 10]);
            let fresh = geodesic_distance_like(&m, &ds, [0, 0, 0], &mut memory).unwrap();
            assert_eq!(fresh.dist.to_volume().unwrap(), got);
            let reused = geodesic_distance_like(&m, &ds, [0, 0, 0], &mut memory).unwrap();
            assert_eq!(reused.dist.to_volume().unwrap(), got);
            let mut reached = 0;
            for (idx, (&a, &b)) in got.data().iter().zip(&want).enumerate() {
                if b.is_infinite() {
                    assert!(
                        a.is_infinite(),
                        "seed {seed} voxel {idx}: reached {a}, reference unreachable"
                    );
                } else {
                    reached += 1;
                    assert!(
                        (a as f64 - b).abs() <= 1e-5 * b + 1e-4,
                        "seed {seed} voxel {idx}: {a} vs {b}"
                    );
                }
            }
            assert_eq!(geo.reached, reached);
            let far = want
                .iter()
                .cloned()
                .filter(|d| d.is_finite())
                .fold(0.0, f64::max);
            assert!((geo.max_mm as f64 - far).abs() < 1e-3);
        }
    }

    #[test]
    fn weighted_tree_search_matches_reference_dijkstra() {
        for seed in [4u64, 9] {
            let mut m = maze([22, 17, 14], [0.82, 0.82, 1.25], seed);
            m.set(0, 0, 0, 1);
            let grid = bounding_box(&m, 1, |v| v != 0).unwrap();
            let pad = Padded::new(&m, &grid);
            // Weights from 1 to 50, per volume voxel, laid out like the search.
            let w_of = |v: usize| 1.0 + ((v * 2654435761) % 50) as f32;
            let mut weight = vec![1.0f32; pad.inside.len()];
            for (i, slot) in weight.iter_mut().enumerate() {
                if pad.inside[i] != 0 {
                    let g = pad.global_of_index(PadIndex(i));
                    *slot = w_of(m.geometry().index(g[0], g[1], g[2]));
                }
            }
            let src = pad.lumen_index([0, 0, 0]).unwrap();
            let r = pad
                .search(m.spacing())
                .weighted(&weight)
                .tree()
                .from(&[src]);
            let want = reference_weighted(&m, [0, 0, 0], |v| w_of(v) as f64);
            let mut reached = 0;
            for (i, &inside) in pad.inside.iter().enumerate() {
                if inside == 0 {
                    continue;
                }
                let g = pad.global_of_index(PadIndex(i));
                let b = want[m.geometry().index(g[0], g[1], g[2])];
                let a = r.dist[i] as f64;
                if b.is_infinite() {
                    assert!(
                        a.is_infinite(),
                        "seed {seed} voxel {g:?}: reached {a}, reference unreachable"
                    );
                    continue;
                }
                reached += 1;
                assert!(
                    (a - b).abs() <= 1e-5 * b + 1e-4,
                    "seed {seed} voxel {g:?}: {a} vs {b}"
                );
                // The tree: each voxel's distance is its parent's plus the edge between them.
                if let Some(p) = r.parent_of(i) {
                    let (gp, gi) = (pad.global_of_index(PadIndex(p)), g);
                    let len = (0..3)
                        .map(|a| ((gp[a] as f64 - gi[a] as f64) * m.spacing()[a]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    let edge = len * 0.5 * (weight[p] as f64 + weight[i] as f64);
                    assert!(
                        (r.dist[p] as f64 + edge - a).abs() <= 1e-4 * a + 1e-3,
                        "seed {seed}: tree edge to {g:?}"
                    );
                } else {
                    assert_eq!(i, src.0);
                }
            }
            assert_eq!(r.reached, reached);
            // From arrays handed back by searches stopped after 1, 20 and 200 voxels: the
            // same search, bit for bit (a value left behind would change distances or tree).
            let mut start = TreeStart::new(&pad, &weight);
            for settle in [1usize, 20, 200] {
                let count = std::cell::Cell::new(0usize);
                let stop = |_: usize| {
                    count.set(count.get() + 1);
                    count.get() == settle
                };
                let (last, back) = start.nearest(&pad, &[src], m.spacing(), &weight, &stop);
                assert_eq!(
                    last,
                    Some(PadIndex(r.order[settle - 1] as usize)),
                    "seed {seed}: settled {settle}"
                );
                start = back;
            }
            let again = start.search(&pad, &[src], m.spacing(), &weight);
            assert!(
                again
                    .dist
                    .iter()
                    .zip(&r.dist)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "seed {seed}: distances"
            );
            assert_eq!(
                (again.parent, again.order),
                (r.parent.clone(), r.order.clone())
            );
        }
    }

    #[test]
    fn straight_tube_distance_is_length() {
        let g = Geometry::new([60, 5, 5], [0.7, 1.0, 1.0], [0.0; 3]).unwrap();
        let mut m = Volume::filled(g, 0u8).unwrap();
        for i in 0..60 {
            m.set(i, 2, 2, 1);
        }
        let grid = bounding_box(&m, 1, |v| v != 0).unwrap();
        let geo = geodesic_distance(&m, &grid, [0, 2, 2]).unwrap();
        assert_eq!(geo.farthest, [59, 2, 2]);
        assert!((geo.max_mm - 59.0 * 0.7).abs() < 1e-3);
    }

    #[test]
    fn source_outside_lumen_is_an_error() {
        let g = Geometry::new([4, 4, 4], [1.0; 3], [0.0; 3]).unwrap();
        let mut m = Volume::filled(g, 0u8).unwrap();
        m.set(1, 1, 1, 1);
        let grid = bounding_box(&m, 1, |v| v != 0).unwrap();
        assert!(geodesic_distance(&m, &grid, [2, 2, 2]).is_err());
    }
}
