//! Touching loops. Where two loops of the colon lie against each other, the wall between them
//! is often thinner than a voxel, and the lumen mask joins them. A shortest path through the
//! lumen then cuts across, and Dt — the paper's pull toward the target — leads the submarine
//! from one loop into the other, skipping the colon in between (on the shared colon-a mask,
//! Dt's shortest path is a third of the centerline).
//!
//! The centerline knows the colon's order. Every lumen voxel takes the arc length of the
//! centerline point it is geodesically nearest to (a multi-source search from the
//! centerline). Two neighbouring voxels whose arc lengths differ by more than
//! `arc_ratio` × the straight distance between their centerline points (and by at least
//! `min_arc_mm`) sit on a contact between loops: along one loop arc and straight distance
//! are alike (a hairpin bend gives π/2), across a contact the arc is many times longer. Both
//! voxels are taken out of the lumen, which puts a two-voxel wall where the scan could not show
//! one: Dt follows the colon, the surface closes over the contact (no view into the next
//! loop), and the cells stay a chain.

use glam::DVec3;

use crate::centerline::Centerline;
use crate::distance::geodesic::{dial, Padded, SearchOptions};
use crate::field::BoxGrid;
use crate::Volume;

#[derive(Clone, Debug)]
pub struct ContactOptions {
    pub enabled: bool,
    pub arc_ratio: f64,
    pub min_arc_mm: f64,
}

impl Default for ContactOptions {
    fn default() -> Self {
        ContactOptions { enabled: true, arc_ratio: 3.0, min_arc_mm: 50.0 }
    }
}

const NO_LABEL: u16 = u16::MAX;

/// Takes the contact voxels out of the lumen mask (never `keep`, volume voxels); returns the
/// volume indices taken, so that a caller can put them back.
pub fn cut_contacts(lumen: &mut Volume<u8>, grid: &BoxGrid, cl: &Centerline, keep: &[[usize; 3]], opts: &ContactOptions) -> Vec<usize> {
    if !opts.enabled || cl.points_mm.len() < 2 {
        return Vec::new();
    }
    let spacing = lumen.spacing();
    let pad = Padded::new(lumen, grid);
    let (points, arcs) = label_points(cl);
    let labels = label_voxels(&pad, &points, spacing);
    let nbrs = pad.neighbours(spacing);
    // Half the offsets: each pair once.
    let half: Vec<isize> = nbrs.iter().map(|n| n.0).filter(|&o| o > 0).collect();
    let mut cut = vec![false; pad.inside.len()];
    for u in 0..pad.inside.len() {
        let a = labels[u];
        if a == NO_LABEL {
            continue;
        }
        for &off in &half {
            let v = (u as isize + off) as usize;
            let b = labels[v];
            if b == NO_LABEL || a == b {
                continue;
            }
            let (a, b) = (a as usize, b as usize);
            let arc = (arcs[a] - arcs[b]).abs();
            if arc > opts.min_arc_mm && arc > opts.arc_ratio * points[a].distance(points[b]) {
                cut[u] = true;
                cut[v] = true;
            }
        }
    }
    for &k in keep {
        if let Some(i) = pad.index_of_global(k) {
            cut[i] = false;
        }
    }
    let mut taken = Vec::new();
    for (i, _) in cut.iter().enumerate().filter(|(_, c)| **c) {
        let g = pad.global_of_index(i);
        let v = lumen.geometry().index(g[0], g[1], g[2]);
        lumen.data_mut()[v] = 0;
        taken.push(v);
    }
    taken
}

/// Centerline points (at most `NO_LABEL` of them, thinned evenly) and their arc lengths.
fn label_points(cl: &Centerline) -> (Vec<DVec3>, Vec<f64>) {
    let n = cl.points_mm.len();
    let stride = n.div_ceil(NO_LABEL as usize - 1).max(1);
    let idx: Vec<usize> = (0..n).step_by(stride).collect();
    (idx.iter().map(|&i| DVec3::from_array(cl.points_mm[i])).collect(), idx.iter().map(|&i| cl.arc_mm[i]).collect())
}

/// Per padded voxel, the label of the geodesically nearest centerline point (NO_LABEL for
/// walls and voxels the search does not reach).
fn label_voxels(pad: &Padded, points: &[DVec3], spacing: [f64; 3]) -> Vec<u16> {
    let mut labels = vec![NO_LABEL; pad.inside.len()];
    let mut sources = Vec::with_capacity(points.len());
    for (l, p) in points.iter().enumerate() {
        let v = [0, 1, 2].map(|a| (p[a] / spacing[a]).round().max(0.0) as usize);
        if let Some(i) = pad.index_of_global(v).filter(|&i| pad.inside[i] != 0)
            && labels[i] == NO_LABEL
        {
            labels[i] = l as u16;
            sources.push(i);
        }
    }
    let search = dial(pad, &sources, spacing, &SearchOptions { tree: true, ..Default::default() });
    for &u in &search.order {
        let u = u as usize;
        if let Some(p) = search.parent_of(u) {
            labels[u] = labels[p];
        }
    }
    labels
}
