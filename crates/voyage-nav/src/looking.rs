//! How a flight looks: the view's angle to the way on, and the frames that see nothing but
//! wall. A reader flies to see the mucosa ahead, the dark lumen near the middle of the view;
//! these are the figures that say whether a flight does.
//!
//! - **View angle:** between z_body and the centerline's direction over the next
//!   [`TANGENT_MM`] toward the goal (the chord from the camera's nearest centerline point to
//!   the point that far on: a tangent over a few points follows the centerline's wiggles).
//! - **All-wall frame:** more than [`ALL_WALL_SHARE`] of a square 90° view's pixels see the
//!   wall nearer than [`WALL_NEAR_MM`] (depth along the view axis, as a depth buffer holds
//!   it). Each pixel's ray is marched through Ds (sphere tracing: a step of Ds cannot cross
//!   the wall) on a [`RAYS`]² grid: no renderer needed, and cheap enough for every frame.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use voyage_core::Study;

use crate::{
    camera::{Camera, Pose},
    flight::{Guide, nearest_from},
    potential::Direction,
};

/// The centerline's direction is taken over this much arc ahead of the camera (mm).
pub const TANGENT_MM: f64 = 20.0;
/// A pixel sees "wall" when the surface under it is nearer than this (mm, depth).
pub const WALL_NEAR_MM: f64 = 15.0;
/// A frame is all wall when more than this share of its pixels see wall.
pub const ALL_WALL_SHARE: f64 = 0.9;
/// Rays per side of the view.
pub const RAYS: u32 = 16;
/// The view angle above which a frame counts in `over_45_share` (degrees).
const OFF_DEG: f64 = 45.0;

/// The distribution of the view angle over a flight's frames (degrees).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AngleStats {
    pub median: f64,
    pub p95: f64,
    /// Share of frames more than 45° off the way on.
    pub over_45_share: f64,
}

/// How a flight looked.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Looking {
    pub view_angle_deg: AngleStats,
    /// Share of frames with over [`ALL_WALL_SHARE`] of the view nearer than
    /// [`WALL_NEAR_MM`].
    pub all_wall_share: f64,
    pub frames: usize,
}

/// How the frames `poses` of a flight in direction `dir` through `study` looked.
pub fn looking(study: &Study, dir: Direction, poses: &[Pose]) -> Looking {
    if poses.is_empty() || study.centerline.points_mm.len() < 2 {
        return Looking::default();
    }
    let guide = Guide::new(&study.centerline, dir);
    let mut near = guide.nearest(poses[0].position);
    let mut angles = Vec::with_capacity(poses.len());
    for pose in poses {
        near = nearest_from(&guide, pose.position, near);
        let way = guide.way_on(near, TANGENT_MM);
        angles.push(pose.z_body().angle_between(way).to_degrees());
    }
    let hit_mm = 0.5 * study.ct.geometry().spacing_vec().min_element();
    let walled = poses
        .iter()
        .filter(|p| wall_share(study, p, hit_mm) > ALL_WALL_SHARE)
        .count();
    Looking {
        view_angle_deg: angle_stats(&mut angles),
        all_wall_share: walled as f64 / poses.len() as f64,
        frames: poses.len(),
    }
}

/// Median, 95th percentile and share over 45° of `angles` (sorted in place).
fn angle_stats(angles: &mut [f64]) -> AngleStats {
    if angles.is_empty() {
        return AngleStats::default();
    }
    angles.sort_by(f64::total_cmp);
    let at = |q: f64| angles[((angles.len() - 1) as f64 * q).round() as usize];
    AngleStats {
        median: at(0.5),
        p95: at(0.95),
        over_45_share: angles.iter().filter(|&&a| a > OFF_DEG).count() as f64 / angles.len() as f64,
    }
}

/// The share of a square 90° view's pixels from `pose` that see the wall nearer than
/// [`WALL_NEAR_MM`]. The wall is where Ds falls to `hit_mm` (half a voxel: Ds is the
/// distance to the nearest non-lumen voxel's centre).
fn wall_share(study: &Study, pose: &Pose, hit_mm: f64) -> f64 {
    let camera = Camera::new(*pose);
    let z = pose.z_body();
    let mut near = 0usize;
    for py in 0..RAYS {
        for px in 0..RAYS {
            let ray = camera.pixel_ray(px as f64 + 0.5, py as f64 + 0.5, RAYS, RAYS);
            let reach = WALL_NEAR_MM / ray.dot(z);
            if hits_within(study, pose.position, ray, reach, hit_mm) {
                near += 1;
            }
        }
    }
    near as f64 / (RAYS * RAYS) as f64
}

/// Whether the ray from `x` along `ray` meets the wall within `reach` mm.
fn hits_within(study: &Study, x: DVec3, ray: DVec3, reach: f64, hit_mm: f64) -> bool {
    let mut t = 0.0;
    while t <= reach {
        let ds = study.ds.sample(x + ray * t) as f64;
        if ds <= hit_mm {
            return true;
        }
        t += (ds - hit_mm).max(0.25 * hit_mm);
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angle_stats_take_the_median_the_95th_percentile_and_the_share_over_45() {
        let mut a: Vec<f64> = (0..=100).map(|i| i as f64).collect();
        let s = angle_stats(&mut a);
        assert_eq!(s.median, 50.0);
        assert_eq!(s.p95, 95.0);
        assert!((s.over_45_share - 55.0 / 101.0).abs() < 1e-12);
        assert_eq!(angle_stats(&mut []), AngleStats::default());
    }
}
