//! The navigable core (stage `nav`): Dt to the target and to the source over the voxels at
//! least `core_mm` from the wall, which is what navigation samples (paper Eq. 2's Dt).
//!
//! Why not Dt over every lumen voxel: a shortest path hugs the wall and slips through
//! channels one voxel wide (leaks in the mask, crevices between folds) that the camera, kept
//! `min_wall_mm` from the wall, cannot follow; Dt's pull then holds it against the wall at the
//! channel's mouth, a local minimum no escape force leaves for long (seen on colon-a). Over
//! the core, Dt only leads where the camera fits. Voxels outside the core are not navigable.

use crate::{
    Error, Result, Volume,
    centerline::Centerline,
    distance::geodesic::{SearchMemory, core_distances},
    grid::Bricked,
};

/// The submarine's default distance from the wall (mm), for which `prepare` computes the
/// navigable core (`voyage_nav::Safety::default().min_wall_mm` is the same).
pub const DEFAULT_MIN_WALL_MM: f64 = 1.0;

/// Dt to both ends over the navigable core, in Ds's bricks.
#[derive(Clone, Debug)]
pub struct Navigable {
    /// [to the target, to the source], mm; +∞ outside the core.
    pub dt: [Bricked<f32>; 2],
    /// Voxels with Ds ≥ this are the core.
    pub core_mm: f64,
    /// The camera's distance from the wall the core was made for.
    pub min_wall_mm: f64,
}

impl Navigable {
    /// The core is as wide as `min_wall_mm` at least and half the centerline's narrowest
    /// radius (at most 3 mm), narrowed in halves until source and target are joined. The
    /// searches work in `memory`.
    pub fn new(
        lumen: &Volume<u8>,
        ds: &Bricked<f32>,
        centerline: &Centerline,
        min_wall_mm: f64,
        memory: &mut SearchMemory,
    ) -> Result<Self> {
        let narrowest = centerline
            .radius_mm
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min);
        let mut core = (0.5 * narrowest).clamp(min_wall_mm, 3.0f64.max(min_wall_mm));
        loop {
            if let Some(dt) = core_distances(lumen, ds, core, &centerline.points_mm, memory) {
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
