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

/// [`FluidWindow::at`] by its definition, the cube around `v` (`cube`: its offsets, at most
/// 125) read voxel by voxel: what the window is tested against.
#[cfg(test)]
fn fluid_value(
    v: usize,
    hu: &[i16],
    m: &[u8],
    cube: &[isize],
    fluid_hu: i16,
    mark: u8,
) -> Option<f32> {
    assert!(cube.len() <= 125, "a cube of at most 5³ offsets");
    let mut values = [i16::MIN; 125];
    for (x, &d) in values.iter_mut().zip(cube) {
        *x = core_value((v as isize + d) as usize, hu, m, fluid_hu, mark);
    }
    brighter_mean(&values, fluid_hu)
}

/// A core voxel's value, or i16::MIN for any other voxel: below any fluid threshold (which
/// lies far above it; [`brighter_mean`] asserts it).
fn core_value(w: usize, hu: &[i16], m: &[u8], fluid_hu: i16, mark: u8) -> i16 {
    if m[w] & mark != 0 && hu[w] >= fluid_hu {
        hu[w]
    } else {
        i16::MIN
    }
}

/// The mean of the brighter half of the core values among `values` (the others i16::MIN),
/// as [`FluidWindow::at`] takes it.
fn brighter_mean(values: &[i16; 125], fluid_hu: i16) -> Option<f32> {
    debug_assert!(
        fluid_hu > i16::MIN,
        "i16::MIN marks voxels that are no core"
    );
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

/// The local tagged fluid's HU around voxels: the mean of the brighter half (by range, above
/// the midpoint of the fluid threshold and the brightest) of the core voxels (marked `mark`,
/// at or above `fluid_hu`; a pool's core voxel may be its partial-volume skin) in the 5³
/// cube around a voxel; None when there is none. The cube of the voxel asked last is kept as
/// five columns of 25 core values (one column per step along the row), so that the next
/// voxel along the row reads one new column, not 125 voxels. On `ctc/prone-tagged` 70 % of
/// the pools' model's 200 000 questions follow the one before along the row.
pub(super) struct FluidWindow<'a> {
    hu: &'a [i16],
    m: &'a [u8],
    fluid_hu: i16,
    mark: u8,
    /// The 25 rows' offsets across a column (±2 voxels along the second and third axes).
    rows: [isize; 25],
    /// Column c of the cube around `last` is the one at `last + c − 2` along the row, kept at
    /// slot (`last` + c − 2) mod 5.
    values: [i16; 125],
    last: Option<usize>,
}

impl<'a> FluidWindow<'a> {
    /// Windows over `hu` and `m` (a volume `nx` × `ny` voxels in plane).
    pub(super) fn new(
        hu: &'a [i16],
        m: &'a [u8],
        [nx, ny]: [usize; 2],
        fluid_hu: i16,
        mark: u8,
    ) -> Self {
        let (sy, sz) = (nx as isize, (nx * ny) as isize);
        FluidWindow {
            hu,
            m,
            fluid_hu,
            mark,
            rows: std::array::from_fn(|r| (r as isize % 5 - 2) * sy + (r as isize / 5 - 2) * sz),
            values: [i16::MIN; 125],
            last: None,
        }
    }

    /// The local fluid value around `v`.
    pub(super) fn at(&mut self, v: usize) -> Option<f32> {
        let columns = if self.last == Some(v.wrapping_sub(1)) {
            2..=2
        } else {
            -2..=2
        };
        for dx in columns {
            let x = v as isize + dx;
            let slot = (x as usize % 5) * 25;
            for (value, &row) in self.values[slot..slot + 25].iter_mut().zip(&self.rows) {
                *value = core_value(
                    (x + row) as usize,
                    self.hu,
                    self.m,
                    self.fluid_hu,
                    self.mark,
                );
            }
        }
        self.last = Some(v);
        brighter_mean(&self.values, self.fluid_hu)
    }
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

    /// A random volume asked along rows, with jumps between them: the window gives what
    /// the cube gives.
    #[test]
    fn the_window_along_a_row_is_the_cube() {
        let mut rng = crate::rng::Rng::new(35, 4);
        let [nx, ny, nz] = [11usize, 9, 8];
        let hu: Vec<i16> = (0..nx * ny * nz)
            .map(|_| rng.range(0.0, 1500.0) as i16)
            .collect();
        let m: Vec<u8> = (0..nx * ny * nz)
            .map(|_| rng.next_u64().is_multiple_of(2) as u8 * 4)
            .collect();
        let mut cube = Vec::new();
        for dk in -2isize..=2 {
            for dj in -2isize..=2 {
                for di in -2isize..=2 {
                    cube.push(di + dj * nx as isize + dk * (nx * ny) as isize);
                }
            }
        }
        let mut window = FluidWindow::new(&hu, &m, [nx, ny], 600, 4);
        let mut asked = 0;
        for k in 2..nz - 2 {
            for j in 2..ny - 2 {
                for i in 2..nx - 2 {
                    // Every third voxel is skipped, so that the window reloads too.
                    if (i + j + k) % 3 == 0 {
                        continue;
                    }
                    let v = i + nx * (j + ny * k);
                    assert_eq!(
                        window.at(v),
                        fluid_value(v, &hu, &m, &cube, 600, 4),
                        "voxel {v}"
                    );
                    asked += 1;
                }
            }
        }
        assert!(asked > 50);
    }

    #[test]
    fn unmixing_keeps_the_tissue_fraction() {
        assert_eq!(unmix(600.0, 40.0, 600.0), AIR_HU);
        assert_eq!(unmix(320.0, 40.0, 600.0), -480);
        assert_eq!(unmix(40.0, 40.0, 600.0), 40);
    }
}
