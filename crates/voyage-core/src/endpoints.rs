//! Source (rectum) and target (cecum), found automatically or given by the user; the two Dt
//! fields of paper Eq. 2 (distance to the target for flying forward, to the source for flying
//! back); and the centerline between them (paper §4.2).
//!
//! The automatic source is the rectum: the candidate nearest the seed (the colon's lowest
//! voxel, where the rectal tube enters), by the centerline's cost. The automatic target is the
//! cecum, the colon's other end: the end of the longest simple path from the source through
//! the lumen's skeleton graph (see [`crate::skeleton`]), not the point farthest from the
//! source: in real scans loops of the colon touch, often over wide contacts, and every
//! shortest path (plain or centred) cuts through the contacts, so the farthest point by any
//! distance is somewhere in the middle of the colon. Only voxels at least `min_width` of the
//! widest radius from the wall are candidates, so an end is never a crevice by the wall.

use glam::DVec3;

use crate::centerline::{cost_weight, refine_points, Centerline, CenterlineOptions};
use crate::skeleton::{colon_path, tree_search, SkeletonOptions};
use crate::distance::geodesic::{dial, Geodesic, Padded, SearchOptions};
use crate::field::{BoxGrid, Field};
use crate::{Error, Result, Volume};

#[derive(Clone, Debug)]
pub struct EndpointOptions {
    /// User-given source / target, volume-local mm.
    pub source_mm: Option<DVec3>,
    pub target_mm: Option<DVec3>,
    /// Candidates for an automatic endpoint have Ds ≥ this fraction of the largest Ds.
    pub min_width: f64,
}

impl Default for EndpointOptions {
    fn default() -> Self {
        EndpointOptions { source_mm: None, target_mm: None, min_width: 0.25 }
    }
}

#[derive(Clone, Debug)]
pub struct Endpoints {
    pub source: [usize; 3],
    pub target: [usize; 3],
    pub centerline: Centerline,
    /// Wall time (ms) of the parts: the skeleton search (endpoints and raw path) and the
    /// centerline's refinement.
    pub skeleton_ms: f64,
    pub refine_ms: f64,
}

/// Finds (or checks) the endpoints and traces the centerline.
///
/// The skeleton search (every voxel of the lumen visited several times) runs on a grid of
/// 2×2×2 blocks when the lumen is large and finely sampled: a voxel of 0.8 mm is far finer
/// than the path needs, the coarse grid has an eighth of the voxels, and the path is then
/// centred on the fine Ds anyway. Dt and everything after stay at full resolution.
pub fn find_endpoints(lumen: &Volume<u8>, ds: &Field<f32>, seed: [usize; 3], opts: &EndpointOptions, cl_opts: &CenterlineOptions) -> Result<Endpoints> {
    let clock = std::time::Instant::now();
    let given_source = opts.source_mm.map(|p| lumen_voxel(lumen, p, "source")).transpose()?;
    let given_target = opts.target_mm.map(|p| lumen_voxel(lumen, p, "target")).transpose()?;
    let sp = lumen.spacing();
    let lumen_voxels = ds.data.iter().filter(|&&d| d > 0.0).count();
    let coarse = (sp.iter().cloned().fold(f64::INFINITY, f64::min) < cl_opts.coarse_below_mm && lumen_voxels > cl_opts.coarse_above_voxels)
        .then(|| Coarse::new(lumen, ds))
        .transpose()?;
    let path_mm: Vec<DVec3> = match &coarse {
        Some(c) => {
            let to_coarse = |v: [usize; 3]| c.coarse_voxel(v);
            let voxels = skeleton_path(&c.mask, &c.ds, to_coarse(seed)?, given_source.map(to_coarse).transpose()?, given_target.map(to_coarse).transpose()?, opts, cl_opts)?;
            voxels.iter().map(|&v| c.fine_mm(v)).collect()
        }
        None => {
            let voxels = skeleton_path(lumen, ds, seed, given_source, given_target, opts, cl_opts)?;
            voxels.iter().map(|v| mm_of(lumen, *v)).collect()
        }
    };
    drop(coarse);
    // The ends: the given points, else the fine lumen voxels at the path's ends.
    let source = match given_source {
        Some(v) => v,
        None => snap(lumen, ds, path_mm[0])?,
    };
    let target = match given_target {
        Some(v) => v,
        None => snap(lumen, ds, path_mm[path_mm.len() - 1])?,
    };
    let skeleton_ms = clock.elapsed().as_secs_f64() * 1e3;
    let clock = std::time::Instant::now();
    let mut pts: Vec<DVec3> = path_mm.iter().map(|&p| mm_of(lumen, snap(lumen, ds, p).unwrap_or(source))).collect();
    pts[0] = mm_of(lumen, source);
    let last = pts.len() - 1;
    pts[last] = mm_of(lumen, target);
    let centerline = refine_points(pts, ds, cl_opts);
    let refine_ms = clock.elapsed().as_secs_f64() * 1e3;
    Ok(Endpoints { source, target, centerline, skeleton_ms, refine_ms })
}

/// Dt to the target and Dt to the source over the lumen inside `grid`.
pub fn dt_fields(lumen: &Volume<u8>, grid: &BoxGrid, source: [usize; 3], target: [usize; 3]) -> Result<(Geodesic, Geodesic)> {
    let pad = Padded::new(lumen, grid);
    let sp = lumen.spacing();
    let (s, t) = (pad.lumen_index(source)?, pad.lumen_index(target)?);
    // The two fields are independent: on two cores they cost one.
    Ok(rayon::join(
        || pad.geodesic(lumen, dial(&pad, &[t], sp, &SearchOptions::default())),
        || pad.geodesic(lumen, dial(&pad, &[s], sp, &SearchOptions::default())),
    ))
}

/// The raw colon path (voxels of `lumen`, source → target) from the skeleton graph.
fn skeleton_path(lumen: &Volume<u8>, ds: &Field<f32>, seed: [usize; 3], given_source: Option<[usize; 3]>, given_target: Option<[usize; 3]>, opts: &EndpointOptions, cl_opts: &CenterlineOptions) -> Result<Vec<[usize; 3]>> {
    let pad = Padded::new(lumen, &ds.grid);
    let sp = lumen.spacing();
    let weight = cost_weight(&pad, ds, cl_opts);
    let ds_pad = pad.pad(&ds.data, 0.0);
    let dmax = ds.data.iter().cloned().fold(0.0f32, f32::max);
    let floor = (opts.min_width as f32 * dmax).min(dmax);
    let source = match given_source {
        Some(s) => s,
        None => {
            // The search stops at the first wide voxel it settles: the nearest.
            let wide = |v: usize| ds_pad[v] > 0.0 && ds_pad[v] >= floor;
            let from_seed = tree_search(&pad, &[pad.lumen_index(seed)?], sp, Some(&weight), Some(&wide as &dyn Fn(usize) -> bool));
            pad.global_of_index(*from_seed.order.last().unwrap() as usize)
        }
    };
    let s = pad.lumen_index(source)?;
    let tree = tree_search(&pad, &[s], sp, Some(&weight), None);
    let t_given = given_target.map(|t| pad.lumen_index(t)).transpose()?;
    if let (Some(t), Some(tv)) = (t_given, given_target)
        && !tree.dist[t].is_finite()
    {
        return Err(Error::invalid(format!(
            "the target {} mm cannot be reached from the source {} mm through the lumen",
            mm_of(lumen, tv),
            mm_of(lumen, source)
        )));
    }
    let sk_opts = SkeletonOptions { min_width: opts.min_width, ..cl_opts.skeleton.clone() };
    let (path, _stats) = colon_path(&pad, &tree, &ds_pad, sp, s, t_given, &sk_opts)?;
    Ok(path.iter().map(|&i| pad.global_of_index(i)).collect())
}

/// How far (in blocks) a point may be moved onto the coarse grid's lumen.
const MAX_SNAP_BLOCKS: i64 = 8;

/// The lumen's box in blocks of 2×2×2 voxels: a block is lumen only when all its voxels are,
/// so that no wall, however thin, disappears (a block half lumen, half wall would open a
/// short cut between two loops that the full grid does not have); the lumen shrinks by at most
/// a voxel, which the narrowest colon survives. With its own Ds.
struct Coarse {
    mask: Volume<u8>,
    ds: Field<f32>,
    /// Fine voxel of the first block's first voxel.
    lo: [usize; 3],
    fine_spacing: [f64; 3],
}

impl Coarse {
    fn new(lumen: &Volume<u8>, ds: &Field<f32>) -> Result<Coarse> {
        let lo = ds.grid.lo;
        let fine = ds.grid.dims;
        let dims = fine.map(|n| n.div_ceil(2));
        let sp = lumen.spacing();
        let geom = crate::Geometry::new(dims, sp.map(|s| 2.0 * s), [0.0; 3])?;
        let mut data = vec![0u8; dims[0] * dims[1] * dims[2]];
        for (idx, out) in data.iter_mut().enumerate() {
            let c = [idx % dims[0], (idx / dims[0]) % dims[1], idx / (dims[0] * dims[1])];
            let mut n = 0;
            for o in 0..8 {
                let f = [lo[0] + 2 * c[0] + (o & 1), lo[1] + 2 * c[1] + ((o >> 1) & 1), lo[2] + 2 * c[2] + ((o >> 2) & 1)];
                if f.iter().zip(lumen.dims()).all(|(&x, n)| x < n) && lumen.get(f[0], f[1], f[2]) != 0 {
                    n += 1;
                }
            }
            *out = (n == 8) as u8;
        }
        let mask = Volume::from_vec(geom, data)?;
        let ds = crate::distance::distance_to_wall(&mask)?;
        Ok(Coarse { mask, ds, lo, fine_spacing: sp })
    }

    /// The block holding fine voxel `v` when it is lumen, else the nearest lumen block (the
    /// seed, at the tip of a rectal tube, may lie where no whole block is lumen).
    fn coarse_voxel(&self, v: [usize; 3]) -> Result<[usize; 3]> {
        let c = [0, 1, 2].map(|a| (v[a].saturating_sub(self.lo[a]) / 2) as i64);
        let dims = self.mask.dims();
        for r in 0..=MAX_SNAP_BLOCKS {
            let mut best: Option<(i64, [usize; 3])> = None;
            for dk in -r..=r {
                for dj in -r..=r {
                    for di in -r..=r {
                        let q = [c[0] + di, c[1] + dj, c[2] + dk];
                        if q.iter().zip(dims).any(|(&x, n)| x < 0 || x >= n as i64) {
                            continue;
                        }
                        let q = q.map(|x| x as usize);
                        let d2 = di * di + dj * dj + dk * dk;
                        if self.mask.get(q[0], q[1], q[2]) != 0 && best.is_none_or(|b| d2 < b.0) {
                            best = Some((d2, q));
                        }
                    }
                }
            }
            if let Some(b) = best {
                return Ok(b.1);
            }
        }
        Err(Error::invalid(format!("the voxel {v:?} lies where the lumen is too narrow to follow")))
    }

    /// Fine volume-local mm of a block's centre.
    fn fine_mm(&self, c: [usize; 3]) -> DVec3 {
        DVec3::new(
            (self.lo[0] as f64 + 2.0 * c[0] as f64 + 0.5) * self.fine_spacing[0],
            (self.lo[1] as f64 + 2.0 * c[1] as f64 + 0.5) * self.fine_spacing[1],
            (self.lo[2] as f64 + 2.0 * c[2] as f64 + 0.5) * self.fine_spacing[2],
        )
    }
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
                    if q.iter().zip(lumen.dims()).any(|(&x, n)| x < 0 || x >= n as i64) {
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
        return Err(Error::invalid(format!("the {what} {mm} mm lies outside the volume")));
    }
    let v = [ijk.x as usize, ijk.y as usize, ijk.z as usize];
    if lumen.get(v[0], v[1], v[2]) == 0 {
        return Err(Error::invalid(format!("the {what} {mm} mm is not inside the colon lumen")));
    }
    Ok(v)
}

pub fn mm_of(vol: &Volume<u8>, v: [usize; 3]) -> DVec3 {
    vol.geometry().index_to_local(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
}
