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

use crate::centerline::{cost_weight, refine, Centerline, CenterlineOptions};
use crate::skeleton::{colon_path, tree_search, SkeletonOptions};
use crate::distance::geodesic::{dial, Geodesic, Padded, SearchOptions};
use crate::field::Field;
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
    /// Dt to the target (flying forward, rectum → cecum).
    pub to_target: Geodesic,
    /// Dt to the source (flying backward).
    pub to_source: Geodesic,
    pub centerline: Centerline,
    /// Wall time (ms) of the parts: the skeleton search (endpoints and raw path), the
    /// centerline's refinement, and the two Dt fields.
    pub skeleton_ms: f64,
    pub refine_ms: f64,
    pub dt_ms: f64,
}

/// Finds (or checks) the endpoints, traces the centerline, and computes both Dt fields.
pub fn find_endpoints(lumen: &Volume<u8>, ds: &Field<f32>, seed: [usize; 3], opts: &EndpointOptions, cl_opts: &CenterlineOptions) -> Result<Endpoints> {
    let clock = std::time::Instant::now();
    let pad = Padded::new(lumen, &ds.grid);
    let sp = lumen.spacing();
    let weight = cost_weight(&pad, ds, cl_opts);
    let ds_pad = pad.pad(&ds.data, 0.0);
    let dmax = ds.data.iter().cloned().fold(0.0f32, f32::max);
    let floor = (opts.min_width as f32 * dmax).min(dmax);
    let given_source = opts.source_mm.map(|p| lumen_voxel(lumen, p, "source")).transpose()?;
    let given_target = opts.target_mm.map(|p| lumen_voxel(lumen, p, "target")).transpose()?;
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
    if let (Some(t), Some(tv)) = (t_given, given_target) {
        if !tree.dist[t].is_finite() {
            return Err(Error::invalid(format!(
                "the target {} mm cannot be reached from the source {} mm through the lumen",
                mm_of(lumen, tv),
                mm_of(lumen, source)
            )));
        }
    }
    let sk_opts = SkeletonOptions { min_width: opts.min_width, ..cl_opts.skeleton.clone() };
    let (path, _stats) = colon_path(&pad, &tree, &ds_pad, sp, s, t_given, &sk_opts)?;
    drop(tree);
    let t = *path.last().unwrap();
    let target = pad.global_of_index(t);
    let voxels: Vec<[usize; 3]> = path.iter().map(|&i| pad.global_of_index(i)).collect();
    drop((weight, ds_pad));
    let skeleton_ms = clock.elapsed().as_secs_f64() * 1e3;
    let clock = std::time::Instant::now();
    let centerline = refine(&voxels, lumen, ds, cl_opts);
    let refine_ms = clock.elapsed().as_secs_f64() * 1e3;
    let clock = std::time::Instant::now();
    // The two fields are independent: on two cores they cost one.
    let (to_target, to_source) = rayon::join(
        || pad.geodesic(lumen, dial(&pad, &[t], sp, &SearchOptions::default())),
        || pad.geodesic(lumen, dial(&pad, &[s], sp, &SearchOptions::default())),
    );
    let dt_ms = clock.elapsed().as_secs_f64() * 1e3;
    Ok(Endpoints { source, target, to_target, to_source, centerline, skeleton_ms, refine_ms, dt_ms })
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
