//! The three materials' model: air, soft tissue and tagged fluid, their values, and a
//! tissue–fluid mixture unmixed with the fluid made air. Pools, lumps and the wall's first
//! voxel are all cleansed by it.

/// HU written for air.
pub const AIR_HU: i16 = -1000;

#[derive(Clone, Debug)]
pub struct CleanseOptions {
    /// Soft tissue (HU): the wall's value, the second material of the model.
    pub tissue_hu: i16,
    /// Soft tissue is at most this (HU): a wall, a fold or a polyp (0–100 HU) at or below it
    /// keeps its value, noise and all.
    pub tissue_max_hu: i16,
}

impl Default for CleanseOptions {
    fn default() -> Self {
        CleanseOptions {
            tissue_hu: 40,
            tissue_max_hu: 100,
        }
    }
}

/// A pool too thin for a core is seeded where fluid this far above the fluid threshold lies
/// under lumen air: a plastic pipe's or a wall's noise (≈ 150 ± 20, 40 ± 40 HU) does not
/// reach it.
pub(super) const LEVEL_MARGIN_HU: i16 = 100;

/// Below this a voxel is more air than soft tissue: halfway between the air level and soft
/// tissue's 40 HU.
pub(super) fn mostly_air(air_hu: i16) -> i16 {
    ((air_hu as i32 + 40) / 2) as i16
}

/// The local tagged fluid's HU: the mean of the brighter half (by range, above the midpoint
/// of the fluid threshold and the brightest) of the pools' core voxels in the 5³ cube
/// around `v` (`cube`: its offsets, at most 125; a core voxel may be the pool's
/// partial-volume skin); None when there is none.
pub(super) fn fluid_value(
    v: usize,
    hu: &[i16],
    m: &[u8],
    cube: &[isize],
    fluid_hu: i16,
    mark: u8,
) -> Option<f32> {
    // The core voxels' values, read once, and i16::MIN for the rest: below any threshold,
    // so the max and the sum need no branch.
    assert!(cube.len() <= 125, "a cube of at most 5³ offsets");
    let mut values = [i16::MIN; 125];
    for (x, &d) in values.iter_mut().zip(cube) {
        let w = (v as isize + d) as usize;
        let h = hu[w];
        if m[w] & mark != 0 && h >= fluid_hu {
            *x = h;
        }
    }
    let max = values.iter().fold(i16::MIN, |a, &h| a.max(h));
    if max < fluid_hu {
        return None;
    }
    let half = ((max as i32 + fluid_hu as i32) / 2) as i16;
    // Summed in integers: 125 values of at most 32 767 stay below 2²⁴, where f32 is exact,
    // so this is the sum in f32 in any order, without a chain of dependent additions.
    let (sum, n) = values
        .iter()
        .filter(|&&h| h >= half)
        .fold((0i32, 0i32), |(s, n), &h| (s + h as i32, n + 1));
    Some(sum as f32 / n as f32)
}

/// A tissue–fluid mixture of value `h` (soft tissue `t`, fluid `c`) with its fluid made air.
pub(super) fn unmix(h: f32, t: f32, c: f32) -> i16 {
    if c <= t + 1.0 {
        return h as i16;
    }
    let f = ((h - t) / (c - t)).clamp(0.0, 1.0);
    ((1.0 - f) * t + f * AIR_HU as f32).round() as i16
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random cubes of marks and values against the definition: the mean, summed in f32 in
    /// the cube's order, of the marked voxels' values at or above the midpoint of the fluid
    /// threshold and their largest.
    #[test]
    fn fluid_value_is_the_brighter_cores_mean() {
        let mut rng = crate::rng::Rng::new(35, 3);
        let cube: Vec<isize> = (0..125).collect();
        for _ in 0..2000 {
            let hu: Vec<i16> = (0..125)
                .map(|_| rng.range(-1000.0, 3000.0) as i16)
                .collect();
            let m: Vec<u8> = (0..125)
                .map(|_| rng.next_u64().is_multiple_of(3) as u8 * 4)
                .collect();
            let cores: Vec<i16> = (0..125)
                .filter(|&w| m[w] != 0 && hu[w] >= 200)
                .map(|w| hu[w])
                .collect();
            let want = cores.iter().max().map(|&max| {
                let half = ((max as i32 + 200) / 2) as i16;
                let bright: Vec<f32> = cores
                    .iter()
                    .filter(|&&h| h >= half)
                    .map(|&h| h as f32)
                    .collect();
                bright.iter().fold(0f32, |s, &h| s + h) / bright.len() as f32
            });
            assert_eq!(fluid_value(0, &hu, &m, &cube, 200, 4), want);
        }
    }

    #[test]
    fn unmixing_keeps_the_tissue_fraction() {
        assert_eq!(unmix(600.0, 40.0, 600.0), AIR_HU);
        assert_eq!(unmix(320.0, 40.0, 600.0), -480);
        assert_eq!(unmix(40.0, 40.0, 600.0), 40);
    }
}
