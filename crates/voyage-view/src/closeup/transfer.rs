//! The transfer function (colour and opacity per HU) and its lookup tables: one per step
//! length, and cut into runs of equal entries for the cells a ray crosses without a fetch.

use glam::Vec4;

use crate::shading::Lighting;
use voyage_core::{Error, Result};

/// The lowest HU of the lookup table (and of CT): everything below is air.
const TABLE_MIN_HU: i32 = -1024;
/// Entries of the lookup table, one per HU from [`TABLE_MIN_HU`]; values above clamp to the
/// last one (bone and metal alike).
const TABLE_LEN: usize = 4096;

/// One control point of a [`TransferFunction`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TfPoint {
    pub hu: f32,
    /// Linear RGB, 0..1.
    pub rgb: [f32; 3],
    /// Opacity of a 1 mm thick slab of this material, 0..1.
    pub opacity_per_mm: f32,
}

/// Colour and opacity per HU, piecewise linear between control points (constant beyond the
/// first and last), plus how boundaries are lit and emphasised.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    points: Vec<TfPoint>,
    /// Gradient magnitudes (HU/mm) over which a sample goes from "inside homogeneous tissue"
    /// (flat colour) to "on a boundary" (lit, with the surface opacity added): below the first,
    /// CT noise; above the second, a real interface.
    pub boundary_hu_per_mm: [f32; 2],
    /// Extra opacity per mm on a boundary, so that surfaces show as surfaces while the tissue
    /// behind them stays translucent.
    pub surface_opacity_per_mm: f32,
    /// Brightness of unlit samples inside homogeneous tissue, relative to the colour.
    pub interior_light: f32,
    /// Headlight on boundaries: ambient + diffuse·|n·l| + specular·|n·l|¹⁶ (white). The
    /// specular part is kept small: white is what tagged material looks like.
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    /// The light falls off with distance as in the endoscopic view (`Lighting`):
    /// 1 / (1 + (d / falloff)²); farther tissue is darker, a cue to depth.
    pub falloff_mm: f32,
}

impl Default for TransferFunction {
    fn default() -> Self {
        Self::tissue()
    }
}

impl TransferFunction {
    /// Control points sorted by HU, with finite values, colours and opacities in 0..1; the
    /// lighting as in [`TransferFunction::tissue`] (its fields are public).
    pub fn new(points: Vec<TfPoint>) -> Result<Self> {
        let ok = |p: &TfPoint| {
            p.hu.is_finite()
                && (0.0..=1.0).contains(&p.opacity_per_mm)
                && p.rgb.iter().all(|c| (0.0..=1.0).contains(c))
        };
        if points.is_empty() || !points.iter().all(ok) {
            return Err(Error::invalid(
                "transfer function: needs control points with finite HU, colour and opacity in 0..1",
            ));
        }
        if points.windows(2).any(|w| w[0].hu > w[1].hu) {
            return Err(Error::invalid(
                "transfer function: control points must be sorted by HU",
            ));
        }
        Ok(TransferFunction {
            points,
            ..Self::tissue()
        })
    }

    /// The default for CT colonography: air transparent; fat (−190…−30 HU) faint yellow and
    /// nearly clear; soft tissue (0…100 HU) pink-red and translucent — a 1 cm polyp is a
    /// solid blob, about 90 % opaque through its middle, and the wall shows through its rim
    /// and around it; tagged stool and fluid, contrast and bone (> 200 HU) white and opaque
    /// within a few mm. Control points in linear RGB, like `Lighting`'s albedo.
    pub fn tissue() -> Self {
        const CLEAR: [f32; 3] = [0.0; 3];
        const FAT: [f32; 3] = [0.85, 0.68, 0.22];
        const SOFT: [f32; 3] = [0.80, 0.20, 0.15];
        const BRIGHT: [f32; 3] = [0.95, 0.93, 0.88];
        let p = |hu, rgb, opacity_per_mm| TfPoint {
            hu,
            rgb,
            opacity_per_mm,
        };
        TransferFunction {
            points: vec![
                p(-600.0, CLEAR, 0.0),
                p(-250.0, FAT, 0.0),
                p(-190.0, FAT, 0.04),
                p(-30.0, FAT, 0.04),
                p(0.0, SOFT, 0.15),
                p(100.0, SOFT, 0.15),
                p(200.0, BRIGHT, 0.6),
            ],
            boundary_hu_per_mm: [60.0, 300.0],
            surface_opacity_per_mm: 0.5,
            interior_light: 0.55,
            ambient: 0.15,
            diffuse: 0.85,
            specular: 0.1,
            falloff_mm: Lighting::default().falloff_mm,
        }
    }

    pub fn points(&self) -> &[TfPoint] {
        &self.points
    }

    /// Linear RGB and opacity per mm at `hu`.
    pub fn eval(&self, hu: f32) -> ([f32; 3], f32) {
        let ps = &self.points;
        let i = ps.partition_point(|p| p.hu <= hu);
        if i == 0 {
            return (ps[0].rgb, ps[0].opacity_per_mm);
        }
        if i == ps.len() {
            let last = ps[ps.len() - 1];
            return (last.rgb, last.opacity_per_mm);
        }
        let (a, b) = (ps[i - 1], ps[i]);
        let t = (hu - a.hu) / (b.hu - a.hu);
        let rgb = [0, 1, 2].map(|c| a.rgb[c] + t * (b.rgb[c] - a.rgb[c]));
        (
            rgb,
            a.opacity_per_mm + t * (b.opacity_per_mm - a.opacity_per_mm),
        )
    }

    /// The lookup table for one step length: per HU, linear RGB and the step's opacity.
    fn table(&self, step_mm: f32) -> Vec<Vec4> {
        (0..TABLE_LEN)
            .map(|i| {
                let (rgb, a) = self.eval((TABLE_MIN_HU + i as i32) as f32);
                Vec4::new(rgb[0], rgb[1], rgb[2], step_opacity(a, step_mm))
            })
            .collect()
    }
}

/// The entry of the lookup table for `hu` (nearest HU, clamped to the table).
#[inline]
fn table_index(hu: f32) -> usize {
    ((hu + 0.5) as i32 - TABLE_MIN_HU).clamp(0, TABLE_LEN as i32 - 1) as usize
}

/// Opacity of a slab `step_mm` thick of a material whose 1 mm slab has opacity `per_mm`.
fn step_opacity(per_mm: f32, step_mm: f32) -> f32 {
    1.0 - (1.0 - per_mm.min(0.999)).powf(step_mm)
}

/// The transfer function tabulated for one step length.
pub(super) struct StepTable {
    /// Per HU from [`TABLE_MIN_HU`]: linear RGB and the opacity of one step.
    rgba: Vec<Vec4>,
    /// Extra opacity of one step on a full boundary (the surface emphasis).
    pub(super) surface_alpha: f32,
}

impl StepTable {
    pub(super) fn new(tf: &TransferFunction, step_mm: f32) -> Self {
        StepTable {
            rgba: tf.table(step_mm),
            surface_alpha: step_opacity(tf.surface_opacity_per_mm, step_mm),
        }
    }

    /// Values below this are transparent (one HU of margin for the table's rounding).
    pub(super) fn clear_below(&self) -> f32 {
        let first = self
            .rgba
            .iter()
            .position(|e| e.w > 0.0)
            .unwrap_or(TABLE_LEN);
        (TABLE_MIN_HU + first as i32 - 1) as f32
    }

    #[inline]
    pub(super) fn get(&self, hu: f32) -> Vec4 {
        self.rgba[table_index(hu)]
    }
}

/// The table cut into runs of equal entries: a cell whose values all fall in one run
/// classifies the same wherever it is sampled.
pub(super) struct Runs {
    /// Per table entry, its run.
    id: Vec<u16>,
    /// Per run: its entry, and the HU in its middle (what a ray remembers of a sample it did
    /// not fetch).
    pub(super) entry: Vec<(Vec4, f32)>,
}

impl Runs {
    pub(super) fn new(table: &StepTable) -> Self {
        let (mut id, mut entry) = (Vec::with_capacity(TABLE_LEN), Vec::<(Vec4, f32)>::new());
        let mut start = 0;
        for (i, e) in table.rgba.iter().enumerate() {
            if i == 0 || *e != table.rgba[i - 1] {
                if let Some(last) = entry.last_mut() {
                    last.1 = (TABLE_MIN_HU as f32) + 0.5 * (start + i - 1) as f32;
                }
                entry.push((*e, 0.0));
                start = i;
            }
            id.push((entry.len() - 1) as u16);
        }
        if let Some(last) = entry.last_mut() {
            last.1 = (TABLE_MIN_HU as f32) + 0.5 * (start + TABLE_LEN - 1) as f32;
        }
        Runs { id, entry }
    }

    /// The run of the entry that `hu` looks up.
    #[inline]
    pub(super) fn of(&self, hu: f32) -> u16 {
        self.id[table_index(hu)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transfer_function_interpolates_and_clamps() {
        let tf = TransferFunction::tissue();
        assert_eq!(tf.eval(-1000.0).1, 0.0);
        assert_eq!(tf.eval(-3000.0).1, 0.0);
        let (soft, a_soft) = tf.eval(40.0);
        assert!(soft[0] > 2.0 * soft[1] && a_soft > 0.1, "{soft:?} {a_soft}");
        let (fat, a_fat) = tf.eval(-100.0);
        assert!(fat[1] > 2.0 * fat[2] && a_fat < a_soft);
        let (bright, a_bright) = tf.eval(1000.0);
        assert!(bright.iter().all(|&c| c > 0.8) && a_bright > a_soft);
        // Halfway between two points.
        let mid = tf.eval(150.0);
        assert!((mid.1 - 0.5 * (0.15 + 0.6)).abs() < 1e-6);
        assert!(TransferFunction::new(vec![]).is_err());
        let p = |hu| TfPoint {
            hu,
            rgb: [1.0; 3],
            opacity_per_mm: 0.5,
        };
        assert!(TransferFunction::new(vec![p(10.0), p(0.0)]).is_err());
    }

    #[test]
    fn step_opacity_composes_to_the_per_mm_opacity() {
        // Four quarter-mm steps are one mm.
        let a = step_opacity(0.3, 0.25);
        assert!(((1.0 - (1.0 - a).powi(4)) - 0.3).abs() < 1e-6);
        assert_eq!(step_opacity(0.0, 0.5), 0.0);
    }
}
