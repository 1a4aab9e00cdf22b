//! Source (rectum) and target (cecum), found automatically or given by the user; the two Dt
//! fields of paper Eq. 2 (distance to the target for flying forward, to the source for flying
//! back); and the centerline between them (paper §4.2).
//!
//! The automatic source is the rectum: the candidate nearest the seed (the colon's lowest
//! voxel, where the rectal tube enters), by the centerline's cost. The automatic target is the
//! cecum, the colon's other end: the end of the longest simple path from the source through
//! the lumen's skeleton graph (`graph.rs`), not the point farthest from the
//! source: in real scans loops of the colon touch, often over wide contacts, and every
//! shortest path (plain or centred) cuts through the contacts, so the farthest point by any
//! distance is somewhere in the middle of the colon. Only voxels at least `min_width` of the
//! widest radius from the wall are candidates, so an end is never a crevice by the wall.

use glam::DVec3;

use super::{
    CenterlineOptions,
    graph::{SkeletonGraph, SkeletonMemory},
    refine::{Centerline, cost_weight_in, refine_points},
};
use crate::{
    Error, Result, Volume,
    distance::{
        distance_to_wall,
        geodesic::{Search as Tree, TreeStart},
    },
    grid::Blocks,
    grid::{BoxGrid, Field, PadIndex, Padded},
};

#[derive(Clone, Debug)]
pub struct Endpoints {
    pub source: [usize; 3],
    pub target: [usize; 3],
    pub centerline: Centerline,
}

/// The raw colon path from the skeleton search, before it is centred on the voxels' Ds.
pub struct Skeleton {
    /// Source → target, volume-local mm (block centres when the search ran on blocks).
    pub path_mm: Vec<DVec3>,
    pub given_source: Option<[usize; 3]>,
    pub given_target: Option<[usize; 3]>,
    /// The colon's lowest gas (volume voxel): the search's seed, where a canal too narrow for
    /// the camera may lead on below the path's start ([`canal_lead_in`]).
    pub seed: [usize; 3],
    /// The blocks the search ran on, if it did.
    pub blocks: Option<Blocks>,
    /// The search behind the path, kept for [`Skeleton::detour`] (None on a detour).
    route: Option<Route>,
}

impl Skeleton {
    /// The path with the lumen voxels `closed` (volume indices) walled off, from the graph
    /// the search kept: where the colon goes once they are plugged, without searching the
    /// lumen again (the graph's edges through them are left out; no new edge appears). None
    /// when the graph cannot say: they cut it, or the given source needs a search of its own.
    pub fn detour(
        &self,
        lumen: &Volume<u8>,
        closed: &[usize],
        opts: &CenterlineOptions,
    ) -> Option<Skeleton> {
        let route = self.route.as_ref()?;
        let g = lumen.geometry();
        let mut walled: Vec<usize> = closed
            .iter()
            .filter_map(|&v| {
                let ijk = g.ijk(v);
                let cell = match &self.blocks {
                    Some(b) => b.block_of_voxel(ijk)?,
                    None => ijk,
                };
                route.pad.index_of_global(cell).map(|i| i.0)
            })
            .collect();
        walled.sort_unstable();
        walled.dedup();
        let path = route.path(&walled, opts).ok()??;
        let path_mm = path
            .iter()
            .map(|&c| match &self.blocks {
                Some(b) => b.centre_mm(c),
                None => mm_of(lumen, c),
            })
            .collect();
        Some(Skeleton {
            path_mm,
            given_source: self.given_source,
            given_target: self.given_target,
            seed: self.seed,
            blocks: None,
            route: None,
        })
    }

    /// Lets the kept search go, handing back its arrays (a few fields over the skeleton's
    /// grid) for the next search.
    pub fn forget_route(&mut self) -> SkeletonMemory {
        let mut memory = SkeletonMemory::default();
        if let Some(route) = self.route.take() {
            route.recycle(&mut memory);
        }
        memory
    }
}

/// Whether the skeleton search runs on 2×2×2 blocks: when the lumen is large and finely
/// sampled (the path is then centred on the voxels' Ds anyway).
pub fn uses_blocks(lumen: &Volume<u8>, lumen_voxels: usize, opts: &CenterlineOptions) -> bool {
    let finest = lumen
        .spacing()
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    finest < opts.coarse_below_mm && lumen_voxels > opts.coarse_above_voxels
}

/// Finds (or checks) the endpoints and traces the raw colon path through the lumen inside
/// `grid`. On blocks ([`uses_blocks`]) the search needs only the mask (the blocks get their
/// own Ds), so it can run before the voxels' Ds; where it fails on them (a neck the blocks
/// part), and on a small lumen, it searches the voxels with `fine_ds`, computing it when not
/// given. An error is the voxels' own. The search works in `memory` where it can (an
/// earlier search's, [`Skeleton::forget_route`]).
pub fn trace_skeleton(
    lumen: &Volume<u8>,
    grid: &BoxGrid,
    lumen_voxels: usize,
    seed: [usize; 3],
    fine_ds: Option<&Field<f32>>,
    opts: &CenterlineOptions,
    mut memory: SkeletonMemory,
) -> Result<Skeleton> {
    let given_source = opts
        .source_mm
        .map(|p| lumen_voxel(lumen, p, "source"))
        .transpose()?;
    let given_target = opts
        .target_mm
        .map(|p| lumen_voxel(lumen, p, "target"))
        .transpose()?;
    if let (Some(s), Some(t)) = (given_source, given_target)
        && s == t
    {
        return Err(Error::invalid(format!(
            "the source and the target are the same voxel ({})",
            lumen.geometry().describe_point(mm_of(lumen, s))
        )));
    }
    if uses_blocks(lumen, lumen_voxels, opts) {
        // A neck about two voxels wide can part the full blocks where the voxels hold
        // together (it depends on how the blocks fall on it): then the voxels' own search,
        // slower, which fails only where the lumen itself is apart.
        let on_blocks = skeleton_on_blocks(
            lumen,
            grid,
            seed,
            given_source,
            given_target,
            opts,
            &mut memory,
        );
        if let Ok(sk) = on_blocks {
            return Ok(sk);
        }
    }
    let own;
    let ds = match fine_ds {
        Some(d) => d,
        None => {
            own = distance_to_wall(lumen)?;
            &own
        }
    };
    let (voxels, route) = skeleton_path(
        lumen,
        ds,
        seed,
        given_source,
        given_target,
        opts,
        &mut memory,
    )?;
    Ok(Skeleton {
        path_mm: voxels.iter().map(|v| mm_of(lumen, *v)).collect(),
        given_source,
        given_target,
        seed,
        blocks: None,
        route: Some(route),
    })
}

/// [`trace_skeleton`] on 2×2×2 blocks of `lumen` (those all lumen), with the blocks' own Ds.
fn skeleton_on_blocks(
    lumen: &Volume<u8>,
    grid: &BoxGrid,
    seed: [usize; 3],
    given_source: Option<[usize; 3]>,
    given_target: Option<[usize; 3]>,
    opts: &CenterlineOptions,
    memory: &mut SkeletonMemory,
) -> Result<Skeleton> {
    let blocks = Blocks::new(lumen, grid, 2)?;
    let ds = distance_to_wall(&blocks.mask)?;
    let to_block = |v: [usize; 3]| blocks.nearest_full(v);
    let (voxels, route) = skeleton_path(
        &blocks.mask,
        &ds,
        to_block(seed)?,
        given_source.map(to_block).transpose()?,
        given_target.map(to_block).transpose()?,
        opts,
        memory,
    )?;
    let path_mm = voxels.iter().map(|&v| blocks.centre_mm(v)).collect();
    Ok(Skeleton {
        path_mm,
        given_source,
        given_target,
        seed,
        blocks: Some(blocks),
        route: Some(route),
    })
}

/// The endpoints (the given ones, else the widest voxels at the raw path's ends) and the
/// centerline: the raw path centred on the voxels' Ds and smoothed (paper §4.2).
pub fn centre_skeleton(
    lumen: &Volume<u8>,
    ds: &Field<f32>,
    sk: &Skeleton,
    opts: &CenterlineOptions,
) -> Result<Endpoints> {
    let lead_in = match sk.given_source {
        Some(_) => Vec::new(),
        None => canal_lead_in(lumen, ds, sk.seed, sk.path_mm[0]),
    };
    let canal_top = (!lead_in.is_empty()).then_some(sk.path_mm[0]);
    let path_mm = &[lead_in, sk.path_mm.clone()].concat();
    let source = match sk.given_source {
        Some(v) => v,
        None => snap(lumen, ds, path_mm[0])?,
    };
    let target = match sk.given_target {
        Some(v) => v,
        None => snap(lumen, ds, path_mm[path_mm.len() - 1])?,
    };
    let mut pts: Vec<DVec3> = path_mm
        .iter()
        .map(|&p| mm_of(lumen, snap(lumen, ds, p).unwrap_or(source)))
        .collect();
    pts[0] = mm_of(lumen, source);
    let last = pts.len() - 1;
    pts[last] = mm_of(lumen, target);
    let mut centerline = refine_points(pts, ds, opts);
    if let Some(top) = canal_top {
        centerline.canal_mm = arc_nearest(&centerline, top);
    }
    Ok(Endpoints {
        source,
        target,
        centerline,
    })
}

/// The arc length of the centerline's point nearest to `p`.
pub(crate) fn arc_nearest(cl: &Centerline, p: DVec3) -> f64 {
    cl.points_mm
        .iter()
        .zip(&cl.arc_mm)
        .map(|(q, &a)| (DVec3::from_array(*q).distance_squared(p), a))
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .map_or(0.0, |(_, a)| a)
}

#[cfg(test)]
/// The skeleton search and the centring in one: endpoints and centerline of the lumen whose
/// Ds is `ds`.
pub fn find_endpoints(
    lumen: &Volume<u8>,
    ds: &Field<f32>,
    seed: [usize; 3],
    opts: &CenterlineOptions,
) -> Result<Endpoints> {
    let lumen_voxels = ds.data.iter().filter(|&&d| d > 0.0).count();
    let sk = trace_skeleton(
        lumen,
        &ds.grid,
        lumen_voxels,
        seed,
        Some(ds),
        opts,
        SkeletonMemory::default(),
    )?;
    centre_skeleton(lumen, ds, &sk, opts)
}

/// Where the colon's lowest gas lies at least this far (mm, straight) from the skeleton's
/// start, a canal too narrow for the camera leads down to it: the anal canal held open by gas
/// round a catheter is about 1 mm of gas and 30–40 mm long, and no voxel in it is wide enough
/// to start from. A rectum's own floor lies within this of its first wide voxel.
const CANAL_MM: f64 = 20.0;

/// The way from the colon's lowest gas (`seed`) up to the skeleton path's start, seed first
/// and the start left out, when the seed lies at least [`CANAL_MM`] from it: the centerline
/// then runs on down the canal, as far as the colon goes, where the camera cannot fly (a
/// flight starts at the first centerline point with room for it). Empty otherwise.
///
/// A* over the lumen's voxels (26 neighbours), each step's length weighted by 1 + 1/Ds so that
/// the way keeps to the middle of the canal's gas; the straight distance is the heuristic.
/// It searches within the straight distance plus [`CANAL_MM`] of the seed.
pub(crate) fn canal_lead_in(
    lumen: &Volume<u8>,
    ds: &Field<f32>,
    seed: [usize; 3],
    start_mm: DVec3,
) -> Vec<DVec3> {
    use std::cmp::Reverse;
    use std::collections::{BinaryHeap, HashMap};
    let seed_mm = mm_of(lumen, seed);
    let straight = seed_mm.distance(start_mm);
    if straight < CANAL_MM || lumen.get(seed[0], seed[1], seed[2]) == 0 {
        return Vec::new();
    }
    let Ok(goal) = snap(lumen, ds, start_mm) else {
        return Vec::new();
    };
    let goal_mm = mm_of(lumen, goal);
    let reach = straight + CANAL_MM;
    let dims = lumen.dims();
    let sp = lumen.spacing();
    let geom = lumen.geometry();
    let index = |v: [usize; 3]| geom.index(v[0], v[1], v[2]);
    // Best cost so far and the voxel it came from, by volume index.
    let mut best: HashMap<usize, (f64, usize)> = HashMap::new();
    let mut open = BinaryHeap::new();
    let key = |f: f64| Reverse(f.to_bits());
    best.insert(index(seed), (0.0, usize::MAX));
    open.push((key(straight), index(seed), 0.0f64.to_bits()));
    while let Some((_, u, g_bits)) = open.pop() {
        let v = geom.ijk(u);
        if v == goal {
            let mut way = Vec::new();
            let mut at = best[&u].1;
            while at != usize::MAX {
                way.push(mm_of(lumen, geom.ijk(at)));
                at = best[&at].1;
            }
            way.reverse();
            return way;
        }
        let g = best[&u].0;
        if g.to_bits() != g_bits {
            continue; // queued before the voxel was reached more cheaply
        }
        for dk in -1i64..=1 {
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    let w = [v[0] as i64 + di, v[1] as i64 + dj, v[2] as i64 + dk];
                    if (di, dj, dk) == (0, 0, 0)
                        || w.iter().zip(dims).any(|(&x, n)| x < 0 || x >= n as i64)
                    {
                        continue;
                    }
                    let w = w.map(|x| x as usize);
                    let d = ds.get_global(w, 0.0);
                    if d <= 0.0 || lumen.get(w[0], w[1], w[2]) == 0 {
                        continue;
                    }
                    let w_mm = mm_of(lumen, w);
                    if w_mm.distance(seed_mm) > reach {
                        continue;
                    }
                    let step = ((di as f64 * sp[0]).powi(2)
                        + (dj as f64 * sp[1]).powi(2)
                        + (dk as f64 * sp[2]).powi(2))
                    .sqrt();
                    let cost = g + step * (1.0 + 1.0 / d as f64);
                    let wi = index(w);
                    if best.get(&wi).is_none_or(|b| cost < b.0) {
                        best.insert(wi, (cost, u));
                        open.push((key(cost + w_mm.distance(goal_mm)), wi, cost.to_bits()));
                    }
                }
            }
        }
    }
    Vec::new()
}

/// The start is the nearest voxel to the seed at least this far from the wall (mm), or
/// `min_width` of the widest, whichever is less.
const START_WIDE_MM: f32 = 5.0;

/// The raw colon path (voxels of `lumen`, source → target) from the skeleton graph
/// ([`Route::path`]), and the search kept for detours.
fn skeleton_path(
    lumen: &Volume<u8>,
    ds: &Field<f32>,
    seed: [usize; 3],
    given_source: Option<[usize; 3]>,
    given_target: Option<[usize; 3]>,
    opts: &CenterlineOptions,
    memory: &mut SkeletonMemory,
) -> Result<(Vec<[usize; 3]>, Route)> {
    let n = Padded::shape(&ds.grid).len();
    let pad = Padded::new_in(lumen, &ds.grid, memory.u8s(n));
    let sp = lumen.spacing();
    let ds_pad = pad.pad_in(&ds.data, 0.0, memory.f32s(n));
    let weight = cost_weight_in(&ds_pad, opts, memory.f32s(n));
    let dmax = ds.data.iter().cloned().fold(0.0f32, f32::max);
    // The rectum needs room for the camera, not a share of the widest chamber: with the
    // whole colon in, a wide cecum would push the start tens of mm up the rectum.
    let floor = (opts.min_width as f32 * dmax).min(dmax).min(START_WIDE_MM);
    let start = TreeStart::new_in(&pad, &weight, memory.f32s(n + 1), memory.u8s(n));
    // The search stops at the first wide voxel it settles: the nearest.
    let wide = |v: usize| ds_pad[v] > 0.0 && ds_pad[v] >= floor;
    let (nearest, start) = start.nearest(&pad, &[pad.lumen_index(seed)?], sp, &weight, &wide);
    let rectum =
        nearest.ok_or_else(|| Error::invalid("the search from the seed settled nothing"))?;
    let tree = start.search(&pad, &[rectum], sp, &weight);
    let unreachable = |v: [usize; 3], what: &str| {
        Error::invalid(format!(
            "the {what} {} mm cannot be reached from the rectum {} mm through the lumen",
            mm_of(lumen, v),
            mm_of(lumen, pad.global_of_index(rectum))
        ))
    };
    for (v, what) in [(given_source, "source"), (given_target, "target")] {
        if let Some(v) = v
            && !tree.dist[pad.lumen_index(v)?.0].is_finite()
        {
            return Err(unreachable(v, what));
        }
    }
    let graph = SkeletonGraph::new(&pad, &tree, &ds_pad, sp, rectum, opts, memory);
    let mut route = Route {
        pad,
        ds_pad,
        weight,
        sp,
        tree,
        graph,
        from_rectum: true,
        source: given_source,
        target: given_target,
    };
    let s = match (route.path(&[], opts)?, given_source) {
        (Some(path), _) => return Ok((path, route)),
        (None, Some(s)) => route.pad.lumen_index(s)?,
        (None, None) => return Err(Error::invalid("no colon path from the rectum")),
    };
    // The given source lies off the colon's path: the longest path from it (to the target,
    // when given). Both were reached from the rectum above, so they reach each other. The
    // arrays of the search from the rectum serve the graph's.
    let n = route.pad.inside.len();
    let start = TreeStart::new_in(&route.pad, &route.weight, memory.f32s(n + 1), memory.u8s(n));
    let tree = start.search(&route.pad, &[s], sp, &route.weight);
    memory.keep_search(std::mem::replace(&mut route.tree, tree));
    let graph = SkeletonGraph::new(&route.pad, &route.tree, &route.ds_pad, sp, s, opts, memory);
    std::mem::replace(&mut route.graph, graph).recycle(memory);
    route.from_rectum = false;
    let path = route
        .path(&[], opts)?
        .ok_or_else(|| Error::invalid("no colon path from the source"))?;
    Ok((path, route))
}

/// The skeleton search kept for detours: the search over the skeleton's grid (the blocks or
/// the voxels), its graph and the given ends in that grid, so that the path with part of the
/// grid walled off is found again without searching the lumen again.
pub(crate) struct Route {
    pad: Padded,
    ds_pad: Vec<f32>,
    /// The search's cost weight (a search from a given source off the colon's path needs it
    /// again), kept for its memory after.
    weight: Vec<f32>,
    sp: [f64; 3],
    tree: Tree,
    graph: SkeletonGraph,
    /// The search ran from the rectum (else from the given source).
    from_rectum: bool,
    source: Option<[usize; 3]>,
    target: Option<[usize; 3]>,
}

impl Route {
    /// Its arrays, for the next search.
    fn recycle(self, memory: &mut SkeletonMemory) {
        memory.keep_u8s(self.pad.inside);
        memory.keep_f32s(self.ds_pad);
        memory.keep_f32s(self.weight);
        memory.keep_search(self.tree);
        self.graph.recycle(memory);
    }

    /// The raw colon path (grid voxels, source → target) with the padded voxels `closed`
    /// (sorted) walled off; None when the given source lies off the path from the rectum (the
    /// source then needs a search of its own).
    ///
    /// Given endpoints are placed on the whole colon's path (automatic rectum to cecum) and
    /// the path between them is kept: the longest simple path between two given points is not
    /// the colon between them (from a point in the middle it would wander through contacts to
    /// gain length), and neither is the shortest. Only an endpoint that lies off that path
    /// (farther from it than the lumen is wide there) falls back to the longest path from the
    /// source.
    fn path(&self, closed: &[usize], opts: &CenterlineOptions) -> Result<Option<Vec<[usize; 3]>>> {
        let Route {
            pad,
            ds_pad,
            sp,
            tree,
            graph,
            from_rectum,
            source,
            target,
            ..
        } = self;
        let grid_voxels = |p: Vec<PadIndex>| -> Vec<[usize; 3]> {
            p.iter().map(|&i| pad.global_of_index(i)).collect()
        };
        let target_index = target.map(|t| pad.lumen_index(t)).transpose()?;
        if !from_rectum {
            let path = graph.colon_path(tree, ds_pad, target_index, closed, opts)?;
            return Ok(Some(grid_voxels(path)));
        }
        let colon = grid_voxels(graph.colon_path(tree, ds_pad, None, closed, opts)?);
        let place = |v: Option<[usize; 3]>, default: usize| match v {
            None => Some(default),
            Some(v) => place_on_path(&colon, v, pad, ds_pad, *sp),
        };
        if let (Some(a), Some(b)) = (place(*source, 0), place(*target, colon.len() - 1))
            && a != b
        {
            let mut path: Vec<[usize; 3]> = if a < b {
                colon[a..=b].to_vec()
            } else {
                colon[b..=a].iter().rev().copied().collect()
            };
            // The given points themselves are the ends (the centring puts them there too).
            let last = path.len() - 1;
            path[0] = source.unwrap_or(path[0]);
            path[last] = target.unwrap_or(path[last]);
            return Ok(Some(path));
        }
        if source.is_some() {
            return Ok(None);
        }
        // The target lies off the colon's path: the longest path from the rectum to it.
        let path = graph.colon_path(tree, ds_pad, target_index, closed, opts)?;
        Ok(Some(grid_voxels(path)))
    }
}

/// The index of the point of `path` nearest to voxel `v`, if `v` lies within the lumen's
/// width of it (twice the point's Ds, plus two voxels): a point in the tube around the path.
fn place_on_path(
    path: &[[usize; 3]],
    v: [usize; 3],
    pad: &Padded,
    ds_pad: &[f32],
    sp: [f64; 3],
) -> Option<usize> {
    let dist2 = |p: &[usize; 3]| {
        (0..3)
            .map(|a| ((p[a] as f64 - v[a] as f64) * sp[a]).powi(2))
            .sum::<f64>()
    };
    let (at, d2) = path
        .iter()
        .enumerate()
        .map(|(i, p)| (i, dist2(p)))
        .min_by(|x, y| x.1.total_cmp(&y.1))?;
    let width = pad
        .index_of_global(path[at])
        .map_or(0.0, |i| ds_pad[i.0] as f64);
    let reach = 2.0 * width + 2.0 * sp.iter().map(|x| x * x).sum::<f64>().sqrt();
    (d2 <= reach * reach).then_some(at)
}

/// The lumen voxel with the largest Ds among those around a point (the 8 corners of its
/// cell, else the 64 of the next ring).
fn snap(lumen: &Volume<u8>, ds: &Field<f32>, p: DVec3) -> Result<[usize; 3]> {
    let base = lumen.geometry().local_to_index(p).floor();
    for (lo, hi) in [(0i64, 1i64), (-1, 2)] {
        let mut best: Option<(f32, [usize; 3])> = None;
        for k in lo..=hi {
            for j in lo..=hi {
                for i in lo..=hi {
                    let q = [base.x as i64 + i, base.y as i64 + j, base.z as i64 + k];
                    if q.iter()
                        .zip(lumen.dims())
                        .any(|(&x, n)| x < 0 || x >= n as i64)
                    {
                        continue;
                    }
                    let q = q.map(|x| x as usize);
                    let d = ds.get_global(q, 0.0);
                    if d > 0.0 && best.is_none_or(|b| d > b.0) {
                        best = Some((d, q));
                    }
                }
            }
        }
        if let Some(b) = best {
            return Ok(b.1);
        }
    }
    Err(Error::invalid(format!("no lumen voxel near {p} mm")))
}

fn lumen_voxel(lumen: &Volume<u8>, mm: DVec3, what: &str) -> Result<[usize; 3]> {
    let ijk = lumen.geometry().local_to_index(mm).round();
    if !lumen.geometry().contains_index(ijk) {
        return Err(Error::invalid(format!(
            "the {what} {} lies outside the volume",
            lumen.geometry().describe_point(mm)
        )));
    }
    let v = [ijk.x as usize, ijk.y as usize, ijk.z as usize];
    if lumen.get(v[0], v[1], v[2]) == 0 {
        return Err(Error::invalid(format!(
            "the {what} {} is not inside the colon lumen",
            lumen.geometry().describe_point(mm)
        )));
    }
    Ok(v)
}

pub fn mm_of(vol: &Volume<u8>, v: [usize; 3]) -> DVec3 {
    vol.geometry()
        .index_to_local(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
}
