//! The rectal tube: a thin tube of air from outside the body, through the anal canal, into
//! the rectum. Its air joins the colon's gas in 3D (outside air is found slice by slice, and
//! in each slice below the perineum the tube is a hole in the body). Left in, it would make
//! the tube's outer end the colon's lowest point, so the flight would start in the tube.
//!
//! A gas component touches outside air in 3D only there: one of its runs overlaps an
//! outside run in the next axial slice. A scan that ends at the perineum cuts the tube
//! instead: its air reaches the scan's inferior slice. From that slice, going away from the
//! outside air or the scan's edge, the tube's cross-section (its gas joined within the
//! slice) is followed while it stays as narrow as a tube; where it widens is the tube's tip,
//! in the rectum. The tube's air is then outside air, and the rectum begins at the tip.
//!
//! A narrow stretch of gas that just ends is no tube: a skin fold, or the air between a
//! prone patient and the table, pinched off in one slice from the outside air of the next.
//! A tube opens into the rectum, and the gas beyond its tip is a colon segment's at least
//! (checked by the caller).

use glam::DVec3;

use super::runs::{Runs, row_of};
use crate::Volume;

/// A tube's cross-section in an axial slice is at most this (mm²): an inner radius of 6 mm
/// at 45° to the slice (real tubes are 3–8 mm wide inside).
const MAX_AREA_MM2: f64 = 160.0;
/// A narrow stretch shorter than this (mm) is the bottom of a gas region, not a tube.
const MIN_LENGTH_MM: f64 = 10.0;

/// A rectal tube found in one gas component.
#[derive(Clone, Debug)]
pub struct Tube {
    /// The component it belongs to.
    pub comp: u32,
    /// Its runs (now outside air).
    pub runs: Vec<usize>,
    /// Where it enters the body (or the scan) and where it ends, volume indices (slice
    /// centroids).
    pub entry: [f64; 3],
    pub tip: [f64; 3],
    pub length_mm: f64,
    /// It enters at the scan's inferior edge, not through the skin.
    pub from_edge: bool,
}

/// Rectal tubes: for each component `c` (its runs `run_comp[r] == c`; u32::MAX for none)
/// that touches outside air (`inside[r] == false`) across an axial slice, or has gas in the
/// scan's inferior slice (`inferior_slice`, when the axial slices run along the body), the
/// narrow stretch from there on, if it is long enough to be a tube and opens out.
pub fn find(
    runs: &Runs,
    inside: &[bool],
    run_comp: &[u32],
    is_gas: impl Fn(u32) -> bool,
    dims: [usize; 3],
    spacing: [f64; 3],
    inferior_slice: Option<usize>,
) -> Vec<Tube> {
    let mut tubes: Vec<Tube> = Vec::new();
    let at_skin = contacts(runs, inside, run_comp, &is_gas, dims)
        .into_iter()
        .map(|c| (c, false));
    let at_edge = inferior_slice
        .into_iter()
        .flat_map(|k| edge_contacts(runs, run_comp, &is_gas, dims, k))
        .map(|c| (c, true));
    for (contact, from_edge) in at_skin.chain(at_edge) {
        if tubes.iter().any(|t| t.comp == run_comp[contact.2]) {
            continue;
        }
        if let Some(t) = follow(runs, run_comp, contact, dims[2], spacing, from_edge) {
            tubes.push(t);
        }
    }
    tubes
}

/// Internal gas runs in the scan's edge slice `k`: (k, the step into the scan, the run).
fn edge_contacts(
    runs: &Runs,
    run_comp: &[u32],
    is_gas: &impl Fn(u32) -> bool,
    dims: [usize; 3],
    k: usize,
) -> Vec<(usize, i64, usize)> {
    let away = if k == 0 { 1 } else { -1 };
    (0..dims[1])
        .flat_map(|j| runs.row(j, k))
        .filter(|&r| is_gas(run_comp[r]))
        .map(|r| (k, away, r))
        .collect()
}

/// Internal gas runs that overlap outside air in the next slice: (their slice, the step in k
/// away from the outside air, the run).
fn contacts(
    runs: &Runs,
    inside: &[bool],
    run_comp: &[u32],
    is_gas: &impl Fn(u32) -> bool,
    dims: [usize; 3],
) -> Vec<(usize, i64, usize)> {
    let [_, ny, nz] = dims;
    let mut out = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k).filter(|&r| is_gas(run_comp[r])) {
                for step in [-1i64, 1] {
                    let kk = k as i64 + step;
                    if kk < 0 || kk >= nz as i64 {
                        continue;
                    }
                    let run = runs.runs[r];
                    let touches = runs.row(j, kk as usize).any(|q| {
                        !inside[q] && runs.runs[q].x0 < run.x1 && run.x0 < runs.runs[q].x1
                    });
                    if touches {
                        out.push((k, -step, r));
                    }
                }
            }
        }
    }
    out
}

/// Follows the tube from run `start` in slice `k0`, in steps of `away`: in each slice, the
/// gas of component `c` joined (in the slice) to the runs over the tube's runs of the slice
/// before. Inside the rectum the tube's air is walled off by its plastic from the rectum's
/// gas, so it is followed up to its tip, where it opens into the rectum and widens.
fn follow(
    runs: &Runs,
    run_comp: &[u32],
    (k0, away, start): (usize, i64, usize),
    nz: usize,
    spacing: [f64; 3],
    from_edge: bool,
) -> Option<Tube> {
    let c = run_comp[start];
    let max_voxels = (MAX_AREA_MM2 / (spacing[0] * spacing[1])).ceil() as usize;
    let nz = nz as i64;
    let Section::Narrow(mut blob) = in_slice(runs, run_comp, c, vec![start], max_voxels) else {
        return None;
    };
    let entry = centroid(runs, &blob);
    let mut tip;
    let mut taken = Vec::new();
    let mut slices = 0usize;
    let mut k = k0 as i64;
    loop {
        tip = centroid(runs, &blob);
        taken.extend_from_slice(&blob);
        slices += 1;
        k += away;
        if k < 0 || k >= nz {
            // A tube through the whole scan is not a rectal tube.
            return None;
        }
        let over: Vec<usize> = blob
            .iter()
            .flat_map(|&r| {
                let (j, _) = row_of(runs, r);
                let run = runs.runs[r];
                runs.row(j, k as usize).filter(move |&q| {
                    run_comp[q] == c && runs.runs[q].x0 < run.x1 && run.x0 < runs.runs[q].x1
                })
            })
            .collect();
        match in_slice(runs, run_comp, c, over, max_voxels) {
            Section::Narrow(b) => blob = b,
            Section::Wide => break,
            // The gas ends: a pocket pinched off the outside air, not a tube.
            Section::Gone => return None,
        }
    }
    let d = [0, 1, 2].map(|a| (tip[a] - entry[a]) * spacing[a]);
    let length_mm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        .sqrt()
        .max(slices as f64 * spacing[2]);
    (length_mm >= MIN_LENGTH_MM).then_some(Tube {
        comp: c,
        runs: taken,
        entry,
        tip,
        length_mm,
        from_edge,
    })
}

/// A component's gas in one slice around some runs.
enum Section {
    /// As narrow as a tube: its runs.
    Narrow(Vec<usize>),
    /// Wider than a tube.
    Wide,
    /// No gas.
    Gone,
}

/// The runs of component `c` joined to `seeds` within their slice (rows next to each other,
/// overlapping); wide when they hold more than `max_voxels` (the rectum, or the gas the
/// tube opens into).
fn in_slice(
    runs: &Runs,
    run_comp: &[u32],
    c: u32,
    mut stack: Vec<usize>,
    max_voxels: usize,
) -> Section {
    stack.sort_unstable();
    stack.dedup();
    let mut seen = stack.clone();
    let mut voxels = 0usize;
    let mut out = Vec::new();
    while let Some(r) = stack.pop() {
        let run = runs.runs[r];
        voxels += (run.x1 - run.x0) as usize;
        if voxels > max_voxels {
            return Section::Wide;
        }
        out.push(r);
        let (j, k) = row_of(runs, r);
        for jj in [j.wrapping_sub(1), j + 1] {
            if jj >= runs.ny {
                continue;
            }
            for q in runs.row(jj, k) {
                if run_comp[q] == c
                    && runs.runs[q].x0 < run.x1
                    && run.x0 < runs.runs[q].x1
                    && !seen.contains(&q)
                {
                    seen.push(q);
                    stack.push(q);
                }
            }
        }
    }
    if out.is_empty() {
        Section::Gone
    } else {
        Section::Narrow(out)
    }
}

/// Mean voxel position (volume indices) of some runs.
fn centroid(runs: &Runs, rs: &[usize]) -> [f64; 3] {
    let (mut n, mut sum) = (0.0, [0.0; 3]);
    for &r in rs {
        let (j, k) = row_of(runs, r);
        let run = runs.runs[r];
        let m = (run.x1 - run.x0) as f64;
        n += m;
        sum[0] += m * 0.5 * (run.x0 + run.x1 - 1) as f64;
        sum[1] += m * j as f64;
        sum[2] += m * k as f64;
    }
    sum.map(|v| v / n.max(1.0))
}

/// The scan's inferior axial slice (k is axial): 0 or the last, whichever lies lower in the
/// patient; None when the slices do not run along the body.
pub(super) fn inferior_slice(vol: &Volume<i16>) -> Option<usize> {
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
