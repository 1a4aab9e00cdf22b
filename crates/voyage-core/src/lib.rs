//! voyage-core: a CT volume in, a prepared colon (`prep::Study`) out. No file formats, GPU or
//! GUI: `voyage-io` loads and exports, `voyage-nav` flies, `voyage-view` draws.
//!
//! Data moves one way: a [`Volume<i16>`] of Hounsfield units with its geometry goes through
//! segmentation, cleansing, distance fields, centerline, surface and cells (`prep::prepare`
//! runs them in order); each stage takes values and returns values.

pub mod anatomy;
pub mod blocks;
pub mod cells;
pub mod centerline;
pub mod cleanse;
pub mod contacts;
pub mod distance;
pub mod error;
pub mod field;
pub mod mem;
pub mod navigable;
pub mod prep;
pub mod rng;
pub mod segment;
mod simd;
pub mod surface;
pub mod volume;

pub use error::{Error, Result};
pub use prep::Study;
pub use volume::{Geometry, Volume};
