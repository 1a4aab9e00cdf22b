//! The box a close-up ray-casts: where it lies and how large it may be.

use glam::DVec3;
use voyage_nav::Camera;

/// Boxes larger than this (half size, mm) are shrunk to it: the per-frame brick costs 16 bytes
/// per voxel (80 mm at 0.5 mm spacing: 65 MB), and a close-up is meant to be small.
pub const MAX_HALF_SIZE_MM: f64 = 40.0;

/// The region to ray-cast: an axis-aligned cube in volume-local mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloseupBox {
    pub center: DVec3,
    pub half_size_mm: f64,
}

impl CloseupBox {
    /// A box centred `distance_mm` ahead of the camera on its view axis.
    pub fn in_front_of(camera: &Camera, distance_mm: f64, half_size_mm: f64) -> Self {
        CloseupBox {
            center: camera.pose.position + distance_mm * camera.pose.z_body(),
            half_size_mm,
        }
    }

    /// A box centred on a point (a marker, a polyp candidate).
    pub fn around(center: DVec3, half_size_mm: f64) -> Self {
        CloseupBox {
            center,
            half_size_mm,
        }
    }

    /// The half size actually rendered: non-negative, at most [`MAX_HALF_SIZE_MM`].
    pub fn effective_half_size(&self) -> f64 {
        if self.half_size_mm.is_finite() {
            self.half_size_mm.clamp(0.0, MAX_HALF_SIZE_MM)
        } else {
            0.0
        }
    }

    pub fn min_mm(&self) -> DVec3 {
        self.center - DVec3::splat(self.effective_half_size())
    }

    pub fn max_mm(&self) -> DVec3 {
        self.center + DVec3::splat(self.effective_half_size())
    }
}
