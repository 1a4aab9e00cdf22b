//! The marks cleansing keeps in the lumen volume's spare bits (bit 0 is the lumen): where the
//! pools are and what lies near them, and the lumps of stool. Every step reads them; all are
//! cleared before cleansing returns.

/// Marks in the lumen volume's spare bits while cleansing runs (cleared before it returns):
/// within two voxels of a pool, a pool's core, and the pool.
pub(super) const NEAR: u8 = 2;
pub(super) const CORE: u8 = 4;
pub(super) const POOL: u8 = 8;
/// A lump of stool's tagged voxels and the air pockets inside it (`SOLID`), and with them
/// their partial-volume skin (`LUMP`).
pub(super) const SOLID: u8 = 16;
pub(super) const LUMP: u8 = 32;
