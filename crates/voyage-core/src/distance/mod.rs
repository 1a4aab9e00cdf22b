//! Distance fields over the lumen (paper §3.2): Ds, the Euclidean distance to the colon wall,
//! and Dt, the geodesic distance to the target (or source) through the lumen.

pub mod edt;
pub mod geodesic;

pub use edt::{distance_to_wall, distance_to_wall_in};
pub use geodesic::{Geodesic, geodesic_distance, geodesic_distance_like};

use crate::{Result, Volume, field::Bricked};

/// Dt to the target and Dt to the source over the lumen of Ds's box, in Ds's bricks.
///
/// One after the other although they are independent: each search works in a box-sized
/// array (130 MB on a full colon) before its result goes into bricks, and two at once would
/// break preprocessing's memory budget (3× the CT) for a gain only on more than one core.
///
/// `scratch`: memory to search in (Ds's box array, done with): fresh memory costs page faults.
pub fn dt_fields(
    lumen: &Volume<u8>,
    ds: &Bricked<f32>,
    source: [usize; 3],
    target: [usize; 3],
    scratch: Vec<f32>,
) -> Result<(Geodesic, Geodesic)> {
    let [to_target, to_source] =
        geodesic::geodesic_distance_pair_like(lumen, ds, [target, source], scratch)?;
    Ok((to_target, to_source))
}
