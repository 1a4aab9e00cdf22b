//! The navigable core (stage `nav`): Dt to the target and to the source over the voxels at
//! least `core_mm` from the wall, which is what navigation samples (paper Eq. 2's Dt).
//!
//! Why not Dt over every lumen voxel: a shortest path hugs the wall and slips through
//! channels one voxel wide (leaks in the mask, crevices between folds) that the camera, kept
//! `min_wall_mm` from the wall, cannot follow; Dt's pull then holds it against the wall at the
//! channel's mouth, a local minimum no escape force leaves for long (seen on colon-a). Over
//! the core, Dt only leads where the camera fits. Voxels outside the core are not navigable.
//!
//! Why a step near the wall costs more: even over the core, a shortest way hugs the inner
//! side of every bend and fold, and −∇Dt there points into the wall; the wall's push answers
//! and the submarine sits (a local minimum of V). With a step costing up to [`WALL_WEIGHT`]
//! times its length within [`RAMP_MM`] of the wall, the ways keep off the wall where the
//! lumen lets them, and Dt is the length of those ways (mm), not their cost.
//!
//! Where the centerline is narrower than the camera may come to the wall (a neck), the
//! lumen around it is in the core too: one neck does not thin the core everywhere.

use crate::{
    Error, Result, Volume,
    centerline::Centerline,
    distance::geodesic::{CoreSpec, SearchMemory, core_distances},
    grid::Bricked,
};

/// The submarine's default distance from the wall (mm), for which `prepare` computes the
/// navigable core (`voyage_nav::Safety::default().min_wall_mm` is the same).
pub const DEFAULT_MIN_WALL_MM: f64 = 1.0;

/// A step costs `1 + (WALL_WEIGHT − 1)·(1 − Ds/RAMP_MM)` times its length where Ds is under
/// `RAMP_MM`. Measured on ctc/prone-tagged (stalls forward/backward): every step alike over
/// a 1 mm core (thinned to 0.5 mm everywhere by one 0.9 mm neck in the sigmoid) 30/20; a
/// step within 3 mm of the wall 4× as dear 1/1, 8× 0/0; this ramp 0/0, and the flights
/// 20 % quicker.
pub const RAMP_MM: f64 = 10.0;
pub const WALL_WEIGHT: f32 = 8.0;
/// Centerline points whose radius is under this many times the camera's distance from the
/// wall are a neck: the lumen around them (within as many, and a voxel) is in the core.
pub const NECK_PER_WALL: f64 = 2.0;

/// Dt to both ends over the navigable core, in Ds's bricks.
#[derive(Clone, Debug)]
pub struct Navigable {
    /// [to the target, to the source]: the length (mm) of the way that keeps off the wall
    /// (see the module's docs); +∞ outside the core.
    pub dt: [Bricked<f32>; 2],
    /// Voxels with Ds ≥ this are the core.
    pub core_mm: f64,
    /// The camera's distance from the wall the core was made for.
    pub min_wall_mm: f64,
}

impl Navigable {
    /// The core is the lumen `min_wall_mm` from the wall, where the camera may be, and the
    /// lumen around the centerline's necks ([`NECK_PER_WALL`]); thinned in halves until
    /// source and target are joined. The searches work in `memory`.
    pub fn new(
        lumen: &Volume<u8>,
        ds: &Bricked<f32>,
        centerline: &Centerline,
        min_wall_mm: f64,
        memory: &mut SearchMemory,
    ) -> Result<Self> {
        let neck = NECK_PER_WALL * min_wall_mm;
        let narrows: Vec<[f64; 3]> = centerline
            .points_mm
            .iter()
            .zip(&centerline.radius_mm)
            .filter(|(_, r)| **r < neck)
            .map(|(p, _)| *p)
            .collect();
        let voxel = lumen.spacing().iter().cloned().fold(0.0, f64::max);
        let mut core = min_wall_mm;
        loop {
            let spec = CoreSpec {
                min_ds_mm: core,
                ramp_mm: RAMP_MM,
                wall_weight: WALL_WEIGHT,
                narrows_mm: &narrows,
                open_mm: neck + voxel,
            };
            if let Some(dt) = core_distances(lumen, ds, &spec, &centerline.points_mm, memory) {
                return Ok(Navigable {
                    dt,
                    core_mm: core,
                    min_wall_mm,
                });
            }
            if core <= 1e-3 {
                return Err(Error::invalid(
                    "the target cannot be reached from the source through the lumen",
                ));
            }
            core = if core * 0.5 < 0.25 { 0.0 } else { core * 0.5 };
        }
    }
}
