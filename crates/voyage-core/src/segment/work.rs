//! The segmentation's working labels, one byte per voxel (in the volume that becomes the
//! lumen), and the box they are confined to.

/// Internal gas of a candidate component (not lung, not outside the body).
pub const GAS: u8 = 1;
/// Bright voxels in the column under a colon segment's gas: the segment's fluid.
pub const POOL: u8 = 3;
/// The partial-volume layer between a segment's gas and its pool.
pub const LAYER: u8 = 4;
/// Added to the colon where a gap between two gas segments was bridged (the cheapest path
/// through the CT, widened to a narrow tube, and the fluid filling a stretch it crosses).
pub const BRIDGE: u8 = 5;

/// An inclusive voxel box.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bbox {
    pub lo: [usize; 3],
    pub hi: [usize; 3],
}

impl Bbox {
    pub fn widths(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| self.hi[a] + 1 - self.lo[a])
    }

    /// The box grown by `by` voxels per axis, within `dims`.
    pub fn grown(&self, by: [usize; 3], dims: [usize; 3]) -> Bbox {
        Bbox {
            lo: [0, 1, 2].map(|a| self.lo[a].saturating_sub(by[a])),
            hi: [0, 1, 2].map(|a| (self.hi[a] + by[a]).min(dims[a] - 1)),
        }
    }

    pub fn union(&self, o: &Bbox) -> Bbox {
        Bbox {
            lo: [0, 1, 2].map(|a| self.lo[a].min(o.lo[a])),
            hi: [0, 1, 2].map(|a| self.hi[a].max(o.hi[a])),
        }
    }
}

/// A distance ordered for a binary heap (distances are finite and non-negative).
#[derive(Clone, Copy, PartialEq)]
pub struct Key(pub f64);
impl Eq for Key {}
impl Ord for Key {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&o.0)
    }
}
impl PartialOrd for Key {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}

/// Height toward the feet (mm) of a volume-local point: larger is lower in the patient.
pub fn height(inferior: glam::DVec3, p: glam::DVec3) -> f64 {
    inferior.dot(p)
}

/// The LPS box of a voxel box (all eight corners: the direction may turn the axes).
pub(super) fn lps_box(geom: &crate::Geometry, b: &Bbox) -> [glam::DVec3; 2] {
    geom.patient_box(b.lo, b.hi)
}
