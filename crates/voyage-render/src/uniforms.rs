//! The per-frame constants the endoscope shader reads, laid out for WGSL's uniform rules.
//!
//! Every field is a `vec4` (or a `mat4x4`), so the Rust `repr(C)` layout and WGSL's
//! 16-byte alignment of `vec3` agree without hidden padding.
//!
//! Precision: positions are volume-local mm (up to ~500 mm), stored as f32. Multiplying such
//! positions by a full view-projection matrix in f32 cancels the large camera translation in
//! single precision. Instead the matrix is built in f64 with the eye's translation folded in
//! (`proj · view · translate(eye)`), and the vertex shader subtracts the eye first: the
//! matrix it sees then only rotates and projects the small eye-relative vector. The same
//! eye-relative vector gives the fragment's distance and light direction.

use bytemuck::{Pod, Zeroable};
use glam::DMat4;
use voyage_nav::Camera;
use voyage_view::Lighting;

/// Mirrors `struct Uniforms` in `endoscope.wgsl` (112 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct Uniforms {
    /// Clip position of an eye-relative point `P − eye`: `proj · view · translate(eye)`.
    pub eye_relative_to_clip: [[f32; 4]; 4],
    /// Eye (camera position) in volume-local mm; w unused.
    pub eye: [f32; 4],
    /// Linear albedo in xyz, ambient fraction in w.
    pub albedo_ambient: [f32; 4],
    /// falloff_mm, specular, shininess, unused.
    pub light: [f32; 4],
}

impl Uniforms {
    pub fn new(camera: &Camera, width: u32, height: u32, lighting: &Lighting) -> Self {
        let aspect = width as f64 / height as f64;
        let eye = camera.pose.position;
        let m =
            camera.projection_matrix(aspect) * camera.view_matrix() * DMat4::from_translation(eye);
        let [r, g, b] = lighting.albedo;
        Uniforms {
            eye_relative_to_clip: m.as_mat4().to_cols_array_2d(),
            eye: [eye.x as f32, eye.y as f32, eye.z as f32, 0.0],
            albedo_ambient: [r, g, b, lighting.ambient],
            light: [
                lighting.falloff_mm,
                lighting.specular,
                lighting.shininess,
                0.0,
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec3, Vec4};
    use voyage_nav::Pose;

    #[test]
    fn size_matches_the_wgsl_struct() {
        assert_eq!(std::mem::size_of::<Uniforms>(), 112);
    }

    /// The eye-relative matrix sends `P − eye` where the camera's own matrices send P.
    #[test]
    fn eye_relative_matrix_agrees_with_the_camera() {
        let eye = DVec3::new(310.0, 242.5, 401.0);
        let cam = Camera::new(Pose::looking(eye, DVec3::new(0.3, -1.0, 0.2), DVec3::Z));
        let u = Uniforms::new(&cam, 640, 480, &Lighting::default());
        let p = eye + DVec3::new(4.0, -30.0, 7.0);
        let want = cam.projection_matrix(640.0 / 480.0) * cam.view_matrix() * p.extend(1.0);
        let m = glam::Mat4::from_cols_array_2d(&u.eye_relative_to_clip);
        let rel = (p - eye).as_vec3();
        let got = m * Vec4::new(rel.x, rel.y, rel.z, 1.0);
        let (want, got) = (want.truncate() / want.w, got.truncate() / got.w);
        assert!((want.as_vec3() - got).length() < 1e-5, "{want} vs {got}");
    }
}
