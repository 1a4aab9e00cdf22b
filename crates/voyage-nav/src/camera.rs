//! The camera model shared by navigation, rendering and the GUI: the submarine's pose (paper
//! Fig. 2) and a perspective frustum.
//!
//! The body frame is the paper's: z_body is the viewing direction, y_body the up vector, and
//! x_body = y_body × z_body completes a right-handed frame. Looking along z with y up, x_body
//! therefore points to the viewer's **left**; the screen's right is −x_body. Pixel (0, 0) is
//! the top-left corner; pixel centres sit at +0.5.

use glam::{DMat3, DMat4, DQuat, DVec3, DVec4};
use serde::{Deserialize, Serialize};

/// Where the camera is and where it looks, in volume-local mm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub position: DVec3,
    /// Body → world rotation (columns of its matrix: x_body, y_body, z_body).
    pub orientation: DQuat,
}

impl Pose {
    pub fn x_body(&self) -> DVec3 {
        self.orientation * DVec3::X
    }
    pub fn y_body(&self) -> DVec3 {
        self.orientation * DVec3::Y
    }
    pub fn z_body(&self) -> DVec3 {
        self.orientation * DVec3::Z
    }

    /// A pose looking along `forward` with `up` as near to y_body as it can be.
    pub fn looking(position: DVec3, forward: DVec3, up: DVec3) -> Self {
        let z = forward.try_normalize().unwrap_or(DVec3::Z);
        let mut y = up - z * up.dot(z);
        if y.length_squared() < 1e-12 {
            y = z.any_orthonormal_vector();
        }
        let y = y.normalize();
        let x = y.cross(z);
        Pose {
            position,
            orientation: DQuat::from_mat3(&DMat3::from_cols(x, y, z)).normalize(),
        }
    }

    /// `[x, y, z, qw, qx, qy, qz]`, the form trajectories and `--pose` use.
    pub fn to_array(&self) -> [f64; 7] {
        let p = self.position;
        let q = self.orientation;
        [p.x, p.y, p.z, q.w, q.x, q.y, q.z]
    }
    pub fn from_array(a: [f64; 7]) -> Option<Self> {
        let q = DQuat::from_xyzw(a[4], a[5], a[6], a[3]);
        let n = q.length();
        if !a.iter().all(|v| v.is_finite()) || n < 1e-9 {
            return None;
        }
        Some(Pose {
            position: DVec3::new(a[0], a[1], a[2]),
            orientation: q / n,
        })
    }
}

/// A perspective camera: a pose plus its frustum.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub pose: Pose,
    /// Vertical field of view (degrees): 90 by default, up to 140 for a wide endoscope.
    pub fov_y_deg: f64,
    pub near_mm: f64,
    pub far_mm: f64,
}

impl Camera {
    pub const MAX_FOV_DEG: f64 = 140.0;

    pub fn new(pose: Pose) -> Self {
        Camera {
            pose,
            fov_y_deg: 90.0,
            near_mm: 0.1,
            far_mm: 1000.0,
        }
    }

    /// A lens alone: a camera of this field of view whose pose (at the origin) the user sets
    /// per frame, as a reader of flights and reviews does.
    pub fn lens(fov_y_deg: f64) -> Self {
        Camera::new(Pose::looking(DVec3::ZERO, DVec3::Z, DVec3::Y)).with_fov(fov_y_deg)
    }

    pub fn with_fov(mut self, fov_y_deg: f64) -> Self {
        self.fov_y_deg = fov_y_deg.clamp(1.0, Self::MAX_FOV_DEG);
        self
    }

    /// tan(fov/2): half the image's height at unit depth.
    pub fn tan_half_fov(&self) -> f64 {
        (self.fov_y_deg.to_radians() * 0.5).tan()
    }

    /// Unit direction in the world of the ray through pixel (px, py) of a width × height
    /// image (continuous pixel coordinates, top-left origin).
    pub fn pixel_ray(&self, px: f64, py: f64, width: u32, height: u32) -> DVec3 {
        let t = self.tan_half_fov();
        let aspect = width as f64 / height as f64;
        let sx = (2.0 * px / width as f64 - 1.0) * t * aspect;
        let sy = (1.0 - 2.0 * py / height as f64) * t;
        let p = &self.pose;
        (p.z_body() - sx * p.x_body() + sy * p.y_body()).normalize()
    }

    /// World → camera (view) matrix in a right-handed OpenGL-style eye frame (x right, y up,
    /// looking down −z).
    pub fn view_matrix(&self) -> DMat4 {
        let p = &self.pose;
        // Eye axes in the world: right = −x_body, up = y_body, back = −z_body.
        let (r, u, b) = (-p.x_body(), p.y_body(), -p.z_body());
        let e = p.position;
        DMat4::from_cols(
            DVec4::new(r.x, u.x, b.x, 0.0),
            DVec4::new(r.y, u.y, b.y, 0.0),
            DVec4::new(r.z, u.z, b.z, 0.0),
            DVec4::new(-r.dot(e), -u.dot(e), -b.dot(e), 1.0),
        )
    }

    /// Eye → clip matrix, depth 0..1 (wgpu's convention).
    pub fn projection_matrix(&self, aspect: f64) -> DMat4 {
        let f = 1.0 / self.tan_half_fov();
        let (n, far) = (self.near_mm, self.far_mm);
        let r = far / (n - far);
        DMat4::from_cols(
            DVec4::new(f / aspect, 0.0, 0.0, 0.0),
            DVec4::new(0.0, f, 0.0, 0.0),
            DVec4::new(0.0, 0.0, r, -1.0),
            DVec4::new(0.0, 0.0, r * n, 0.0),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_rays_follow_the_body_frame() {
        let pose = Pose::looking(DVec3::ZERO, DVec3::Z, DVec3::Y);
        let cam = Camera::new(pose);
        assert!((cam.pixel_ray(50.0, 50.0, 100, 100) - DVec3::Z).length() < 1e-12);
        // 90° vertical: the top edge's ray is 45° up.
        let top = cam.pixel_ray(50.0, 0.0, 100, 100);
        assert!((top - DVec3::new(0.0, 1.0, 1.0).normalize()).length() < 1e-12);
        // Screen right is −x_body.
        let right = cam.pixel_ray(100.0, 50.0, 100, 100);
        assert!(right.dot(-pose.x_body()) > 0.7);
        // The view matrix sends the pixel ray's points onto the same pixel.
        let v = cam.view_matrix();
        let proj = cam.projection_matrix(1.0);
        let clip =
            proj * v * (pose.position + 10.0 * cam.pixel_ray(80.0, 20.0, 100, 100)).extend(1.0);
        let ndc = clip.truncate() / clip.w;
        assert!(
            (ndc.x - 0.6).abs() < 1e-9 && (ndc.y - 0.6).abs() < 1e-9,
            "{ndc}"
        );
    }

    #[test]
    fn poses_round_trip_through_arrays() {
        let pose = Pose::looking(
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::Z,
        );
        let back = Pose::from_array(pose.to_array()).unwrap();
        assert!((back.position - pose.position).length() < 1e-12);
        assert!(back.orientation.angle_between(pose.orientation) < 1e-9);
        assert!(Pose::from_array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]).is_none());
        assert!((pose.y_body().dot(DVec3::Z) - 1.0).abs() < 1e-12);
    }
}
