//! Navigation through a prepared colon ([`voyage_core::Study`]): the camera, the potential
//! field that pulls it from rectum to cecum (paper Eq. 2), the submarine that obeys it
//! (Eqs. 3–9) and never leaves the safe set, and the automatic flight with its stall watch.
//!
//! Everything is in volume-local millimetres, like the study.

mod camera;
mod flight;
#[cfg(feature = "layouts")]
mod layouts;
mod looking;
mod potential;
mod submarine;

pub use camera::{Camera, Pose};
pub use flight::{
    Autopilot, Flight, FlightOptions, FlightRun, LOOK_AHEAD_MM, Rescue, STUCK_S, WEDGED_S, fly,
    start_pose,
};
#[cfg(feature = "layouts")]
pub use layouts::{BoxStore, SortedStore};
pub use looking::{ALL_WALL_SHARE, AngleStats, Looking, RAYS, TANGENT_MM, WALL_NEAR_MM, looking};
pub use potential::{
    BrickStore, DS_FLOOR_MM, Direction, DistanceStore, PotentialField, PotentialParams, Sample,
    Voxel, potential_field,
};
pub use submarine::{
    Dynamics, EASE_FROM_MM, Forces, Input, Look, Modes, STOP_SHORT_MM, Safety, State, StepReport,
    Submarine, delta_q, euler_step,
};
/// The navigable core's Dt, made by `prepare` (`Study::nav`, `Study::navigable`).
pub use voyage_core::Navigable;
