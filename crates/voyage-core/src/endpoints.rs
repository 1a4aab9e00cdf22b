//! Source (rectum) and target (cecum), found automatically or given by the user; the two Dt
//! fields of paper Eq. 2 (distance to the target for flying forward, to the source for flying
//! back); and the centerline between them (paper §4.2).
//!
//! The automatic source is the rectum: the candidate nearest the seed (the colon's lowest
//! voxel, where the rectal tube enters). The automatic target is the cecum, the colon's other
//! end: the candidate farthest from the source. Near and far are measured with the centerline's cost (a path that keeps to the middle), not
//! with plain length: in real scans loops of the colon touch, and the plain shortest path
//! would cut through the contact and find the wrong ends. Only voxels at least a quarter of
//! the widest radius from the wall are candidates, so an end is never a crevice by the wall.

use glam::DVec3;

use crate::centerline::{cost_weight, refine, trace_path, Centerline, CenterlineOptions};
use crate::distance::geodesic::{dial, Geodesic, Padded};
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
}

/// Finds (or checks) the endpoints, traces the centerline, and computes both Dt fields.
pub fn find_endpoints(lumen: &Volume<u8>, ds: &Field<f32>, seed: [usize; 3], opts: &EndpointOptions, cl_opts: &CenterlineOptions) -> Result<Endpoints> {
    let pad = Padded::new(lumen, &ds.grid);
    let sp = lumen.spacing();
    let weight = cost_weight(&pad, ds, cl_opts);
    let wide = candidates(&pad, ds, opts.min_width);
    let given_source = opts.source_mm.map(|p| lumen_voxel(lumen, p, "source")).transpose()?;
    let given_target = opts.target_mm.map(|p| lumen_voxel(lumen, p, "target")).transpose()?;
    let source = match given_source {
        Some(s) => s,
        None => {
            let from_seed = dial(&pad, &[(pad.lumen_index(seed)?, 0)], sp, Some(&weight), false);
            pad.global_of_index(nearest(&from_seed.dist, &wide))
        }
    };
    let s = pad.lumen_index(source)?;
    let target = match given_target {
        Some(t) => t,
        None => {
            let from_source = dial(&pad, &[(s, 0)], sp, Some(&weight), false);
            pad.global_of_index(farthest(&from_source.dist, &wide))
        }
    };
    let t = pad.lumen_index(target)?;
    let from_target = dial(&pad, &[(t, 0)], sp, Some(&weight), false);
    if !from_target.dist[s].is_finite() {
        return Err(Error::invalid(format!(
            "the target {} mm cannot be reached from the source {} mm through the lumen",
            mm_of(lumen, target),
            mm_of(lumen, source)
        )));
    }
    let path = trace_path(&pad, &from_target.dist, &weight, sp, s)?;
    let centerline = refine(&path, lumen, ds, cl_opts);
    let to_target = pad.geodesic(lumen, dial(&pad, &[(t, 0)], sp, None, false));
    let to_source = pad.geodesic(lumen, dial(&pad, &[(s, 0)], sp, None, false));
    Ok(Endpoints { source, target, to_target, to_source, centerline })
}

/// Lumen voxels wide enough to be an endpoint (padded layout).
fn candidates(pad: &Padded, ds: &Field<f32>, min_width: f64) -> Vec<bool> {
    let dmax = ds.data.iter().cloned().fold(0.0f32, f32::max);
    let floor = (min_width as f32 * dmax).min(dmax);
    pad.pad(&ds.data, 0.0).into_iter().map(|d| d > 0.0 && d >= floor).collect()
}

/// The reachable candidate with the smallest distance.
fn nearest(dist: &[f32], wide: &[bool]) -> usize {
    let mut best = (f32::INFINITY, 0usize);
    for (i, (&d, &w)) in dist.iter().zip(wide).enumerate() {
        if w && d < best.0 {
            best = (d, i);
        }
    }
    best.1
}

/// The reachable candidate with the largest distance.
fn farthest(dist: &[f32], wide: &[bool]) -> usize {
    let mut best = (f32::NEG_INFINITY, 0usize);
    for (i, (&d, &w)) in dist.iter().zip(wide).enumerate() {
        if w && d.is_finite() && d > best.0 {
            best = (d, i);
        }
    }
    best.1
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
