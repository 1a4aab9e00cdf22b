//! voyage-core: a CT volume in, a prepared colon ([`Study`]) out. No file formats, GPU or
//! GUI: `voyage-io` loads and exports, `voyage-nav` flies, `voyage-view` draws.
//!
//! Data moves one way: a [`Volume<i16>`] of Hounsfield units with its geometry goes through
//! the stages of [`Stage`] (segmentation, cleansing, skeleton, contacts, Ds, centerline, Dt,
//! the navigable core, surface, cells); [`prepare`] runs them in order, and each stage takes
//! values and returns values. The modules are private: what other crates use is re-exported
//! here.

mod anatomy;
mod cells;
mod centerline;
mod cleanse;
mod contacts;
mod distance;
mod error;
mod grid;
mod mem;
mod navigable;
mod prep;
pub mod rng;
mod segment;
mod simd;
mod storage;
mod surface;
mod volume;

pub use anatomy::{Orientation, PatientPosition, PositionSource};
pub use cells::{Cells, convex_hull};
pub use centerline::Centerline;
pub use cleanse::Cleansing;
pub use distance::geodesic_distance;
pub use error::{Error, Result};
pub use grid::{BoxGrid, BrickIndex, Bricked, Field, bounding_box};
pub use navigable::{DEFAULT_MIN_WALL_MM, Navigable};
pub use prep::{OFF_WALL_MM, PrepOptions, Stage, Study, Timings, prepare};
pub use segment::{
    COLON_SEGMENTS, ComponentKind, Gap, LEFT_OUT_DOUBT_ML, SegmentOptions, Segmentation, segment,
};
pub use storage::Storage;
pub use surface::{Mesh, Surface, roughness};
pub use volume::{Geometry, IDENTITY, Volume, check_dims};
