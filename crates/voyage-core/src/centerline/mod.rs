//! The centerline stage (paper §4.2): the colon's two ends and the path between them that
//! keeps to the middle of the lumen. In order:
//!
//! 1. [`trace_skeleton`] (`ends.rs`): the ends (given, or the rectum nearest the seed and the
//!    cecum) and the raw path, the longest simple path through the lumen's skeleton graph
//!    (`graph.rs`): in real scans loops of the colon touch, and every shortest path would cut
//!    through the contacts. On a large lumen it runs on 2×2×2 blocks, before the voxels' Ds.
//! 2. [`centre_skeleton`]: the path snapped to the voxels and refined (`refine.rs`): centred
//!    on Ds's ridge, smoothed, resampled every millimetre, inside the lumen.
//!
//! [`CenterlineOptions`] holds every choice of the stage.

mod ends;
mod graph;
mod longest;
mod refine;

use glam::DVec3;

pub(crate) use ends::arc_nearest;
#[cfg(test)]
pub(crate) use ends::find_endpoints;
pub use ends::{Endpoints, Skeleton, centre_skeleton, mm_of, trace_skeleton, uses_blocks};
pub use graph::{SkeletonMemory, SkeletonOptions};
pub use refine::Centerline;
pub(crate) use refine::arc_lengths;
#[cfg(test)]
use refine::refine;
pub(crate) use refine::refine_points;

#[cfg(test)]
use crate::{Result, Volume, grid::Field, grid::Padded};
#[cfg(test)]
use graph::SkeletonGraph;
#[cfg(test)]
use refine::cost_weight_in;

#[derive(Clone, Debug)]
pub struct CenterlineOptions {
    /// User-given source / target, volume-local mm.
    pub source_mm: Option<DVec3>,
    pub target_mm: Option<DVec3>,
    /// Automatic ends and the skeleton's branch tips are voxels with Ds ≥ this fraction of
    /// the largest Ds, so an end is never a crevice by the wall.
    pub min_width: f64,
    /// Spacing of the output points (mm).
    pub step_mm: f64,
    /// Half-width of the smoothing window (mm).
    pub smooth_mm: f64,
    /// Centring iterations (each moves points up the Ds ridge across the path).
    pub centre_iterations: usize,
    /// The skeleton search runs on 2×2×2 blocks when the finest spacing is below this (mm)
    /// and the lumen has more voxels than `coarse_above_voxels`.
    pub coarse_below_mm: f64,
    pub coarse_above_voxels: usize,
    /// The cost weight's power p and scale K (see `refine.rs`).
    pub penalty_power: u32,
    pub penalty_scale: f64,
    /// The skeleton graph the path is chosen from (see `graph.rs`).
    pub skeleton: SkeletonOptions,
}

impl Default for CenterlineOptions {
    fn default() -> Self {
        CenterlineOptions {
            source_mm: None,
            target_mm: None,
            min_width: 0.25,
            step_mm: 1.0,
            smooth_mm: 4.0,
            centre_iterations: 12,
            coarse_below_mm: 1.0,
            coarse_above_voxels: 1_000_000,
            penalty_power: 16,
            penalty_scale: 5000.0,
            skeleton: SkeletonOptions::default(),
        }
    }
}

#[cfg(test)]
/// The centerline from `source` to `target` (volume voxels in the lumen): the longest simple
/// path between them through the skeleton graph, centred and smoothed.
pub fn centerline(
    mask: &Volume<u8>,
    ds: &Field<f32>,
    source: [usize; 3],
    target: [usize; 3],
    opts: &CenterlineOptions,
) -> Result<Centerline> {
    let pad = Padded::new(mask, &ds.grid);
    let ds_pad = pad.pad_in(&ds.data, 0.0, Vec::new());
    let weight = cost_weight_in(&ds_pad, opts, Vec::new());
    let src = pad.lumen_index(source)?;
    let dst = pad.lumen_index(target)?;
    let tree = pad
        .search(mask.spacing())
        .weighted(&weight)
        .tree()
        .from(&[src]);
    let mut memory = graph::SkeletonMemory::default();
    let graph = SkeletonGraph::new(&pad, &tree, &ds_pad, mask.spacing(), src, opts, &mut memory);
    let path = graph.colon_path(&tree, &ds_pad, Some(dst), &[], opts)?;
    let voxels: Vec<[usize; 3]> = path.iter().map(|&i| pad.global_of_index(i)).collect();
    Ok(refine(&voxels, mask, ds, opts))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Geometry, distance::distance_to_wall};

    /// A torus-like bent tube (a half ring of radius 30 mm, tube radius 6 mm).
    fn bent_tube() -> (Volume<u8>, DVec3, f64) {
        let g = Geometry::new([90, 50, 20], [0.8, 0.8, 1.0], [0.0; 3]).unwrap();
        let c = DVec3::new(36.0, 4.0, 10.0);
        let data = (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                let p = DVec3::new(i as f64 * 0.8, j as f64 * 0.8, k as f64);
                let d = p - c;
                let ring = (d.x * d.x + d.y * d.y).sqrt();
                (d.y >= 0.0 && ((ring - 30.0).powi(2) + d.z * d.z).sqrt() < 6.0) as u8
            })
            .collect();
        (Volume::from_vec(g, data).unwrap(), c, 30.0)
    }

    #[test]
    fn follows_the_middle_of_a_bent_tube() {
        let (m, c, r) = bent_tube();
        let ds = distance_to_wall(&m).unwrap();
        // Ends: the two open ends of the half ring at y ≈ 4 mm.
        let src = [((c.x - r) / 0.8).round() as usize, 6, 10];
        let dst = [((c.x + r) / 0.8).round() as usize, 6, 10];
        let cl = centerline(&m, &ds, src, dst, &CenterlineOptions::default()).unwrap();
        let mut err = 0.0;
        for p in &cl.points_mm {
            let p = DVec3::from_array(*p);
            let ijk = (p / m.geometry().spacing_vec()).round();
            assert_eq!(
                m.get(ijk.x as usize, ijk.y as usize, ijk.z as usize),
                1,
                "point {p} outside the lumen"
            );
            let d = p - c;
            err += (((d.x * d.x + d.y * d.y).sqrt() - r).powi(2) + d.z * d.z).sqrt();
        }
        let mean = err / cl.points_mm.len() as f64;
        assert!(mean < 1.0, "mean distance to the true axis {mean} mm");
        assert!(
            (cl.length_mm - std::f64::consts::PI * r).abs() < 8.0,
            "length {}",
            cl.length_mm
        );
        assert!(cl.arc_mm.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn unreachable_target_is_an_error() {
        let g = Geometry::new([20, 5, 5], [1.0; 3], [0.0; 3]).unwrap();
        let mut m = Volume::filled(g, 0u8).unwrap();
        for i in (1..8).chain(11..19) {
            m.set(i, 2, 2, 1);
        }
        let ds = distance_to_wall(&m).unwrap();
        let e = centerline(
            &m,
            &ds,
            [1, 2, 2],
            [18, 2, 2],
            &CenterlineOptions::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("cannot be reached"), "{e}");
    }
}
