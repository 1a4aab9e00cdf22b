//! The grid layouts every stage shares, all over the lumen's bounding box (grown by one
//! voxel): the box itself and fields over it ([`BoxGrid`], [`Field`]); the same box kept only
//! in the 8³ bricks that hold lumen ([`Bricked`]); the box with a layer of wall around it, the
//! searches' layout ([`Padded`]); and the box in f³ blocks for the coarse searches
//! ([`Blocks`]). Each layout converts to and from volume voxels through its own
//! `index_of_global` / `global_of_index`, and each layout's flat index is its own type
//! ([`BoxIndex`], [`BrickIndex`], [`PadIndex`]; a volume's is a plain `usize`).

mod blocks;
mod field;
mod padded;

pub use blocks::Blocks;
pub(crate) use field::first_and_last;
pub use field::{BoxGrid, BoxIndex, BrickIndex, BrickMarks, Bricked, Field, Sampled, bounding_box};
pub use padded::{PadIndex, Padded};
