//! Endoscope lighting, shared by the CPU renderer and the GPU renderer (which copies this
//! formula into WGSL): one light at the camera, falling off with distance, on a moist
//! mucosa (diffuse plus a small specular highlight, whose half vector is the view direction
//! since light and eye coincide).

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lighting {
    /// Linear RGB reflectance of the mucosa.
    pub albedo: [f32; 3],
    /// Fraction of the albedo seen without the light (keeps far walls from pure black).
    pub ambient: f32,
    /// Distance (mm) at which the light has fallen to half: 1 / (1 + (d / falloff)²).
    pub falloff_mm: f32,
    pub specular: f32,
    pub shininess: f32,
}

impl Default for Lighting {
    fn default() -> Self {
        Lighting {
            albedo: [0.82, 0.30, 0.20],
            ambient: 0.05,
            falloff_mm: 40.0,
            specular: 0.30,
            shininess: 30.0,
        }
    }
}

impl Lighting {
    /// Linear RGB of a surface point at `distance_mm` from the camera whose unit normal makes
    /// cos = `n_dot_l` with the direction back to the camera.
    #[inline]
    pub fn linear(&self, distance_mm: f32, n_dot_l: f32) -> [f32; 3] {
        let ndl = n_dot_l.clamp(0.0, 1.0);
        let r = distance_mm / self.falloff_mm;
        let att = 1.0 / (1.0 + r * r);
        let diffuse = self.ambient + (1.0 - self.ambient) * ndl * att;
        let spec = self.specular * ndl.powf(self.shininess) * att;
        self.albedo.map(|a| a * diffuse + spec)
    }

    /// 8-bit display value: linear clamped to [0, 1], gamma 1/2.2, rounded.
    #[inline]
    pub fn rgb8(&self, distance_mm: f32, n_dot_l: f32) -> [u8; 3] {
        self.linear(distance_mm, n_dot_l).map(encode)
    }
}

/// Linear → 8-bit with display gamma 2.2 (the GPU shader writes the same value into a plain
/// Unorm target, so both renderers round the same number).
#[inline]
pub fn encode(linear: f32) -> u8 {
    (linear.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_falls_off_with_distance_and_angle() {
        let l = Lighting::default();
        let near = l.rgb8(5.0, 1.0);
        let far = l.rgb8(100.0, 1.0);
        let grazing = l.rgb8(5.0, 0.1);
        assert!(near[0] > far[0] && far[0] > 0);
        assert!(near[0] > grazing[0]);
        // Half the light at the falloff distance (diffuse part, facing the camera, no specular).
        let l2 = Lighting {
            ambient: 0.0,
            specular: 0.0,
            ..l
        };
        let half = l2.linear(l.falloff_mm, 1.0)[0] / l2.linear(0.0, 1.0)[0];
        assert!((half - 0.5).abs() < 1e-6);
        // Facing away: ambient only.
        assert_eq!(l.rgb8(1.0, -1.0), l.albedo.map(|a| encode(a * l.ambient)));
    }
}
