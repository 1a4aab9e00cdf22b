//! voyage-core: the virtual colonoscopy pipeline, free of GPU and GUI dependencies.
//!
//! Data moves one way: `io` loads a CT into a [`Volume<i16>`] of Hounsfield units with its
//! geometry; later stages (segmentation, distance fields, centerline, cells, surface,
//! navigation) take values and return values. `phantom` makes synthetic scans with ground
//! truth for tests and benchmarks.

pub mod anatomy;
pub mod blocks;
pub mod camera;
pub mod cells;
pub mod centerline;
pub mod cleanse;
pub mod contacts;
pub mod distance;
pub mod endpoints;
pub mod error;
pub mod export;
pub mod field;
pub mod findings;
pub mod flight;
pub mod io;
pub mod mem;
pub mod phantom;
pub mod potential;
pub mod prep;
pub mod render;
pub mod segment;
pub mod skeleton;
pub mod submarine;
pub mod surface;
pub mod volume;

pub use error::{Error, Result};
pub use volume::{Geometry, Volume};
