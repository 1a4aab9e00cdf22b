//! The colon phantom's volume: its size and spacing (full or small), the map from full-size
//! anatomy to it that every part of the phantom draws in, and the random streams the parts
//! beside the colon draw from. Shared by `colon.rs`, `small_bowel.rs` and `skin.rs`.

use glam::DVec3;
use voyage_core::{Geometry, Result};

pub const FULL_DIMS: [usize; 3] = [512, 512, 400];
pub const FULL_SPACING: [f64; 3] = [0.75, 0.75, 1.0];
pub const SMALL_DIMS: [usize; 3] = [128, 128, 125];
pub const SMALL_SPACING: [f64; 3] = [1.5, 1.5, 1.6];
pub const SMALL_SCALE: f64 = 0.5;

/// The small bowel's random stream (drawn only when it is on, so that the older phantoms stay
/// bit for bit what they were).
pub(crate) const STREAM_BOWEL: u64 = 0xC010_0007;
/// The skin folds' random stream.
pub(crate) const STREAM_SKIN_FOLDS: u64 = 0xC010_000A;

/// Size, spacing and the map from full-size anatomy to this volume.
#[derive(Clone, Debug)]
pub(crate) struct Frame {
    pub(crate) geom: Geometry,
    pub(crate) scale: f64,
    offset: DVec3,
}

impl Frame {
    pub(crate) fn new(small: bool) -> Result<Frame> {
        Frame::reaching_below(small, 0.0)
    }

    /// The frame whose volume reaches `below_mm` (full size) further down than the usual
    /// one's first slice: the anatomy lies as high above it.
    pub(crate) fn reaching_below(small: bool, below_mm: f64) -> Result<Frame> {
        let (dims, spacing, scale) = if small {
            (SMALL_DIMS, SMALL_SPACING, SMALL_SCALE)
        } else {
            (FULL_DIMS, FULL_SPACING, 1.0)
        };
        let usual = Geometry::new(dims, spacing, [0.0; 3])?;
        let full = Geometry::new(FULL_DIMS, FULL_SPACING, [0.0; 3])?;
        let ext = |g: &Geometry| g.extent_mm() - g.spacing_vec();
        let extra = (below_mm * scale / spacing[2]).round() as usize;
        let geom = Geometry::new([dims[0], dims[1], dims[2] + extra], spacing, [0.0; 3])?;
        let offset =
            (ext(&usual) - ext(&full) * scale) * 0.5 + DVec3::Z * (extra as f64 * spacing[2]);
        Ok(Frame {
            geom,
            scale,
            offset,
        })
    }

    /// Full-size anatomy position → this volume's local mm.
    pub(crate) fn pos(&self, p: [f64; 3]) -> DVec3 {
        DVec3::from_array(p) * self.scale + self.offset
    }

    pub(crate) fn max_spacing(&self) -> f64 {
        self.geom.spacing.iter().cloned().fold(0.0, f64::max)
    }

    /// A full-size length scaled, but not below `voxels` voxels.
    pub(crate) fn thin(&self, mm: f64, voxels: f64) -> f64 {
        (mm * self.scale).max(voxels * self.max_spacing())
    }
}
