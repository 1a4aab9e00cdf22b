//! Distance fields over the lumen (paper §3.2): Ds, the Euclidean distance to the colon wall,
//! and Dt, the geodesic distance to the target (or source) through the lumen.

pub mod edt;
pub mod geodesic;

pub use edt::{add_walls, distance_to_wall, distance_to_wall_in, distance_to_wall_reusing};
pub use geodesic::{Geodesic, geodesic_distance};
