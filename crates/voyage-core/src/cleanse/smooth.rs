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

/// How many voxels' means [`Smoothing::means`] sums at once.
const MEANS: usize = 8;

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
            let smoothed: Vec<usize> = self
                .beside_changes(kc)
                .into_iter()
                .filter(|&c| {
                    let v = c + plane * kc;
                    let now = ring.at(&around, c, (2, 0));
                    // Tagged voxels cleansing left (contrast in a small-bowel loop behind
                    // the wall) keep their value.
                    !(self.hu[v] >= self.fluid_hu && now == self.hu[v])
                        && ring.surface_near(&around, c, self.surface_hu)
                        && fluid_near(v, self.g, self.hu, self.fluid_hu)
                })
                .collect();
            for group in smoothed.chunks(MEANS) {
                let means = self.means(&ring, &around, group);
                for (&c, mean) in group.iter().zip(means) {
                    out.push(((c + plane * kc) as u32, mean.round() as i16));
                }
            }
        }
        out
    }

    /// The kernel's means at in-plane voxels `cs` (at most [`MEANS`]) of the middle slice of
    /// `around`. Each voxel's sum runs over the kernel in order, as one voxel's alone would
    /// (the same bits); the voxels' sums interleave, so that no addition waits for the one
    /// before it (one voxel at a time, the chain of 117 dependent additions set the pace).
    fn means(&self, ring: &Ring, around: &[usize; 5], cs: &[usize]) -> [f64; MEANS] {
        let mut lanes = [cs[0]; MEANS];
        lanes[..cs.len()].copy_from_slice(cs);
        let mut sums = [-0.0f64; MEANS];
        for &(d, w) in &self.kernel {
            for (sum, &c) in sums.iter_mut().zip(&lanes) {
                *sum += w * ring.at(around, c, d) as f64;
            }
        }
        sums
    }

    /// The voxels of slice `kc` (in-plane indices, ascending) within one voxel in plane of a
    /// changed voxel of slices kc − 1..=kc + 1, two voxels inside the slice's edges.
    fn beside_changes(&self, kc: usize) -> Vec<usize> {
        let [nx, ny, _] = self.g.dims;
        let plane = nx * ny;
        // The changed voxels' places in plane, each slice's ascending (several slices change
        // at one place, as under a pool's level).
        let slices = [kc - 1, kc, kc + 1].map(|k| {
            let (lo, hi) = ((plane * k) as u32, (plane * (k + 1)) as u32);
            let from = self.voxels.partition_point(|&v| v < lo);
            let to = self.voxels.partition_point(|&v| v < hi);
            self.voxels[from..to]
                .iter()
                .map(|&v| v as usize - plane * k)
                .collect::<Vec<_>>()
        });
        let changed = union_ascending(slices.each_ref().map(|s| &s[..]), 0, |_| true);
        // Then the places beside them: along the row, then across the rows.
        let (xlo, xhi) = (2, nx - 3);
        let mut along = Vec::with_capacity(3 * changed.len());
        for &r in &changed {
            let (i, row) = (r % nx, r - r % nx);
            for x in i.saturating_sub(1).max(xlo)..=(i + 1).min(xhi) {
                if along.last().is_none_or(|&l| row + x > l) {
                    along.push(row + x);
                }
            }
        }
        union_ascending([&along[..]; 3], nx, |c| (2..=ny - 3).contains(&(c / nx)))
    }
}

/// The union of three ascending lists, list n shifted by (n − 1)·`step` (one step back,
/// none, one on), of the values that `keep`: ascending, each once.
fn union_ascending(lists: [&[usize]; 3], step: usize, keep: impl Fn(usize) -> bool) -> Vec<usize> {
    let mut at = [0usize; 3];
    let mut out = Vec::with_capacity(lists.iter().map(|l| l.len()).max().unwrap_or(0));
    // Compared one step on (list n by n steps), so that nothing goes below 0.
    let head = |n: usize, at: &[usize; 3]| lists[n].get(at[n]).map(|&x| x + n * step);
    while let Some(next) = (0..3).filter_map(|n| head(n, &at)).min() {
        for n in 0..3 {
            if head(n, &at) == Some(next) {
                at[n] += 1;
            }
        }
        if next >= step && keep(next - step) {
            out.push(next - step);
        }
    }
    out
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Random changes in a small volume: the places beside them are, by definition, those
    /// two voxels inside the slice within one voxel in plane of a change one slice away or
    /// less.
    #[test]
    fn beside_changes_are_the_places_near_a_change() {
        let g = Geometry::new([9, 8, 6], [1.0; 3], [0.0; 3]).unwrap();
        let [nx, ny, nz] = g.dims;
        let hu = vec![0i16; nx * ny * nz];
        let mut rng = Rng::new(35, 2);
        for share in [2, 10, 40] {
            let voxels: Vec<u32> = (0..(nx * ny * nz) as u32)
                .filter(|_| rng.next_u64().is_multiple_of(share))
                .collect();
            let values = vec![1i16; voxels.len()];
            let smoothing = Smoothing {
                hu: &hu,
                g: &g,
                voxels: &voxels,
                values: &values,
                kernel: Vec::new(),
                surface_hu: 0,
                fluid_hu: 0,
            };
            for kc in 1..nz - 1 {
                let want: Vec<usize> = (0..nx * ny)
                    .filter(|&c| {
                        let (i, j) = (c % nx, c / nx);
                        (2..nx - 2).contains(&i)
                            && (2..ny - 2).contains(&j)
                            && voxels.iter().any(|&v| {
                                let [x, y, z] = g.ijk(v as usize);
                                x.abs_diff(i) <= 1 && y.abs_diff(j) <= 1 && z.abs_diff(kc) <= 1
                            })
                    })
                    .collect();
                assert_eq!(
                    smoothing.beside_changes(kc),
                    want,
                    "1 in {share}, slice {kc}"
                );
            }
        }
    }
}
