//! The model's values smoothed where the surface under former fluid passes: they carry the
//! fluid's noise, amplified, and the faces cut through them would be rougher than in air.

use super::changes::{overwrite, slice_with};
use crate::Geometry;

/// The model's values beside the wall are smoothed with a Gaussian of this σ (mm). They
/// carry the fluid's noise, amplified: the fluid fraction divides by `c − t` (500–900 HU on
/// `ctc/prone-tagged`, and `c` varies along the pool) where air's divides by 1040 HU. On
/// that exam the faces over former fluid were 2.3× as rough as those in air (mean angle
/// between neighbouring faces' normals); 0.75 mm brings it to 1.35× (0.9 mm: 1.3×), and
/// the lumen following the smoothed values to 1.21×, well below the phantom's 3 mm polyps.
const SMOOTH_MM: f64 = 0.75;

/// Smooths the cleansed CT where the surface under former fluid passes: every voxel beside
/// (26 neighbours) a changed one, within two voxels of tagged fluid, whose 3³ holds values
/// on both sides of `surface_hu` (the air level, where the surface cuts the wall), takes the
/// Gaussian ([`SMOOTH_MM`]) mean of the cleansed values within two voxels. Tagged voxels
/// cleansing left (at or above `fluid_hu`) keep theirs, and so do the wall elsewhere and
/// under air.
pub(super) fn smooth_the_model(
    hu: &[i16],
    g: &Geometry,
    (voxels, values): (&mut Vec<u32>, &mut Vec<i16>),
    (surface_hu, fluid_hu): (i16, i16),
) {
    use rayon::prelude::*;
    let Some((&first, &last)) = voxels.first().zip(voxels.last()) else {
        return;
    };
    let [nx, ny, nz] = g.dims;
    let plane = nx * ny;
    let (k0, k1) = (first as usize / plane, last as usize / plane);
    let (klo, khi) = (
        k0.saturating_sub(1).max(2),
        (k1 + 1).min(nz.saturating_sub(3)),
    );
    if klo > khi {
        return;
    }
    let smoothing = Smoothing {
        hu,
        g,
        voxels,
        values,
        kernel: gaussian_offsets(g.spacing, SMOOTH_MM)
            .into_iter()
            .map(|(d, w)| (Ring::step(g.dims[0], d), w))
            .collect(),
        surface_hu,
        fluid_hu,
    };
    // Slabs of slices, each with its own ring (two slices loaded twice at each seam).
    const SLAB: usize = 16;
    let changes: Vec<(u32, i16)> = (klo..=khi)
        .step_by(SLAB)
        .collect::<Vec<_>>()
        .into_par_iter()
        .flat_map_iter(|from| smoothing.slab(from..=(from + SLAB - 1).min(khi)))
        .collect();
    overwrite(voxels, values, hu, &changes);
}

/// What [`smooth_the_model`] reads: the CT, the change list, the kernel and the levels.
struct Smoothing<'a> {
    hu: &'a [i16],
    g: &'a Geometry,
    voxels: &'a [u32],
    values: &'a [i16],
    kernel: Vec<(RingStep, f64)>,
    surface_hu: i16,
    fluid_hu: i16,
}

impl Smoothing<'_> {
    /// The smoothed values of slices `ks` (each at least two slices inside the volume).
    fn slab(&self, ks: std::ops::RangeInclusive<usize>) -> Vec<(u32, i16)> {
        let [nx, ny, _] = self.g.dims;
        let plane = nx * ny;
        let mut ring = Ring::new(nx, ny);
        let mut seen = vec![false; plane];
        let mut out = Vec::new();
        let (from, to) = (*ks.start(), *ks.end());
        for k in from - 2..=to + 2 {
            ring.load(k, self.hu, self.voxels, self.values);
            if k < from + 2 {
                continue;
            }
            // Slice kc = k − 2 has its two neighbours on each side loaded.
            let kc = k - 2;
            let around = ring.around(kc);
            for c in self.beside_changes(kc, &mut seen) {
                let v = c + plane * kc;
                let now = ring.at(&around, c, (2, 0));
                // Tagged voxels cleansing left (contrast in a small-bowel loop behind the
                // wall) keep their value.
                if (self.hu[v] >= self.fluid_hu && now == self.hu[v])
                    || !ring.surface_near(&around, c, self.surface_hu)
                    || !fluid_near(v, self.g, self.hu, self.fluid_hu)
                {
                    continue;
                }
                let mean: f64 = self
                    .kernel
                    .iter()
                    .map(|&(d, w)| w * ring.at(&around, c, d) as f64)
                    .sum();
                out.push((v as u32, mean.round() as i16));
            }
        }
        out
    }

    /// The voxels of slice `kc` (in-plane indices, ascending) within one voxel in plane of a
    /// changed voxel of slices kc − 1..=kc + 1, two voxels inside the slice's edges. `seen`
    /// (one flag per in-plane voxel, all false) is left as it was.
    fn beside_changes(&self, kc: usize, seen: &mut [bool]) -> Vec<usize> {
        let [nx, ny, _] = self.g.dims;
        let plane = nx * ny;
        let (lo, hi) = ((plane * (kc - 1)) as u32, (plane * (kc + 2)) as u32);
        let from = self.voxels.partition_point(|&v| v < lo);
        let to = self.voxels.partition_point(|&v| v < hi);
        // The changed voxels' places in plane (several slices change at one place, as
        // under a pool's level), then the places beside them.
        let mut changed = Vec::new();
        for &v in &self.voxels[from..to] {
            let r = v as usize % plane;
            if !seen[r] {
                seen[r] = true;
                changed.push(r);
            }
        }
        changed.iter().for_each(|&c| seen[c] = false);
        let mut near = Vec::new();
        for r in changed {
            let (i, j) = (r % nx, r / nx);
            for y in j.saturating_sub(1).max(2)..=(j + 1).min(ny - 3) {
                for x in i.saturating_sub(1).max(2)..=(i + 1).min(nx - 3) {
                    let c = x + nx * y;
                    if !seen[c] {
                        seen[c] = true;
                        near.push(c);
                    }
                }
            }
        }
        near.iter().for_each(|&c| seen[c] = false);
        near.sort_unstable();
        near
    }
}

/// Whether tagged fluid (at or above `fluid_hu` in `hu`) lay within two voxels of `v`.
fn fluid_near(v: usize, g: &Geometry, hu: &[i16], fluid_hu: i16) -> bool {
    let [nx, ny, _] = g.dims;
    (-2isize..=2).any(|dk| {
        (-2isize..=2).any(|dj| {
            let row = v as isize + nx as isize * (dj + ny as isize * dk);
            hu[(row - 2) as usize..=(row + 2) as usize]
                .iter()
                .any(|&h| h >= fluid_hu)
        })
    })
}

/// Offsets within two voxels and their weights (summing to 1) of a Gaussian of `sigma_mm`.
fn gaussian_offsets(spacing: [f64; 3], sigma_mm: f64) -> Vec<([isize; 3], f64)> {
    let mut out = Vec::new();
    for dk in -2isize..=2 {
        for dj in -2isize..=2 {
            for di in -2isize..=2 {
                let d2 = (di as f64 * spacing[0]).powi(2)
                    + (dj as f64 * spacing[1]).powi(2)
                    + (dk as f64 * spacing[2]).powi(2);
                let w = (-d2 / (2.0 * sigma_mm * sigma_mm)).exp();
                if w > 1e-3 {
                    out.push(([di, dj, dk], w));
                }
            }
        }
    }
    let sum: f64 = out.iter().map(|x| x.1).sum();
    out.iter_mut().for_each(|x| x.1 /= sum);
    out
}

/// Five slices of the cleansed CT, slice k at k mod 5.
struct Ring {
    after: Vec<i16>,
    plane: usize,
    /// [`CUBE`] as ring steps.
    cube: [RingStep; 27],
}

/// A step from a voxel of the ring's middle slice k: to slice k − 2 + .0, and by .1 in plane.
type RingStep = (usize, isize);

impl Ring {
    fn new(nx: usize, ny: usize) -> Ring {
        Ring {
            after: vec![0; 5 * nx * ny],
            plane: nx * ny,
            cube: CUBE.map(|d| Ring::step(nx, d)),
        }
    }

    /// Loads slice `k`: `hu` with the changes (`voxels` ascending, `values`) in.
    fn load(&mut self, k: usize, hu: &[i16], voxels: &[u32], values: &[i16]) {
        let slot = (k % 5) * self.plane;
        let out = &mut self.after[slot..slot + self.plane];
        slice_with(hu, (voxels, values), k, out);
    }

    /// The step by `d` (voxels; in slices at most two) in a volume `nx` voxels wide.
    fn step(nx: usize, d: [isize; 3]) -> RingStep {
        ((d[2] + 2) as usize, d[0] + d[1] * nx as isize)
    }

    /// Where slices k − 2..=k + 2 start in the ring (all loaded).
    fn around(&self, k: usize) -> [usize; 5] {
        std::array::from_fn(|n| ((k + n + 3) % 5) * self.plane)
    }

    /// The value a step from in-plane voxel `c` of the middle slice of `around`.
    fn at(&self, around: &[usize; 5], c: usize, (s, d): RingStep) -> i16 {
        self.after[(around[s] + c).wrapping_add_signed(d)]
    }

    /// Whether values on both sides of `surface_hu` lie in the 3³ around in-plane voxel `c`
    /// of the middle slice of `around`.
    fn surface_near(&self, around: &[usize; 5], c: usize, surface_hu: i16) -> bool {
        let below = self.at(around, c, (2, 0)) < surface_hu;
        self.cube
            .iter()
            .any(|&d| (self.at(around, c, d) < surface_hu) != below)
    }
}

/// The 3³ offsets around a voxel.
const CUBE: [[isize; 3]; 27] = {
    let mut out = [[0isize; 3]; 27];
    let mut n = 0;
    while n < 27 {
        out[n] = [
            (n % 3) as isize - 1,
            ((n / 3) % 3) as isize - 1,
            (n / 9) as isize - 1,
        ];
        n += 1;
    }
    out
};
