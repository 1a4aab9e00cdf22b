//! The brick: the box's voxels with their gradient, built once per frame, and what a ray
//! reads from it (a trilinear sample, and the blocks and cells it may cross without one).

use glam::{Vec3A, Vec4};
use rayon::prelude::*;

use super::transfer::Runs;
use voyage_core::Volume;

/// Edge (voxels) of the blocks that rays cross in one hop where all of a block is air, or
/// all of it one uniform material.
const BLOCK: usize = 4;

/// A block's or a cell's class: every sample in it must be fetched and classified.
pub(super) const MIXED: u16 = 0;
/// A block's class: every sample in it is transparent.
pub(super) const EMPTY: u16 = u16::MAX;

/// The box's voxels as (HU, ∂HU/∂x, ∂HU/∂y, ∂HU/∂z), gradient in HU per mm, x fastest.
pub(super) struct Brick {
    dims: [usize; 3],
    /// Volume index of the brick's voxel (0, 0, 0).
    pub(super) lo: [usize; 3],
    data: Vec<Vec4>,
    /// Index steps to a fetch's upper corner along x, y, z (0 along an axis of one voxel).
    strides: [usize; 3],
    /// Largest coordinate a sample may take, just under dims − 1, so that a fetch's upper
    /// corner stays inside.
    hi: Vec3A,
    /// Per voxel cell (by its lowest voxel): 1 + the [`Runs`] entry every sample inside it
    /// takes, where that is sure; else [`MIXED`].
    pub(super) cells: Vec<u16>,
    /// Per block of BLOCK³ cells: [`EMPTY`], 1 + the run all its cells share, or [`MIXED`].
    blocks: Vec<u16>,
    block_dims: [usize; 3],
    /// Index steps from block to block, as floats.
    block_strides: Vec3A,
    /// Per block that is not [`MIXED`]: how many blocks around it (Chebyshev distance) share
    /// its class, so that a ray crosses them all in one hop.
    reach: Vec<u8>,
}

impl Brick {
    /// The voxels from `lo` to `hi` (inclusive volume indices).
    pub(super) fn new(ct: &Volume<i16>, lo: [usize; 3], hi: [usize; 3]) -> Self {
        let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let data = sobel(&Grid::around(ct, lo, dims), ct.spacing());
        let [nx, ny, nz] = dims;
        let strides = [
            usize::from(nx > 1),
            nx * usize::from(ny > 1),
            nx * ny * usize::from(nz > 1),
        ];
        // A one-voxel axis (a single slice) has no upper corner: samples stay on the slice.
        let hi = Vec3A::from_array(dims.map(|d| (d as f32 - 1.0 - 1e-3).max(0.0)));
        let block_dims = dims.map(|d| d.div_ceil(BLOCK));
        let n = data.len();
        let cells = vec![MIXED; n];
        let blocks = vec![MIXED; block_dims.iter().product()];
        let block_strides = Vec3A::new(
            1.0,
            block_dims[0] as f32,
            (block_dims[0] * block_dims[1]) as f32,
        );
        Brick {
            dims,
            lo,
            data,
            strides,
            hi,
            cells,
            blocks,
            block_dims,
            block_strides,
            reach: Vec::new(),
        }
    }

    /// Finds the cells whose every sample classifies alike: all eight corners in one run of
    /// the table (so every value in between is), and all gradients at most √`interior_g2`
    /// (so every interpolated gradient is: a norm is convex), which makes every sample an
    /// unlit interior one. Rays then composite such a sample without fetching it — most of
    /// the fat and soft tissue that the translucent transfer function lets them cross.
    pub(super) fn mark_uniform(&mut self, runs: &Runs, interior_g2: f32) {
        const ROUGH: u16 = u16::MAX;
        // Per voxel: its run where its gradient is small, else ROUGH.
        let mut class = vec![ROUGH; self.data.len()];
        for (c, v) in class.iter_mut().zip(&self.data) {
            if Vec3A::new(v.y, v.z, v.w).length_squared() <= interior_g2 {
                *c = runs.of(v.x);
            }
        }
        let [dx, dy, dz] = self.strides;
        let [nx, ny, nz] = self.dims;
        let last = [nx - 1, ny - 1, nz - 1].map(|l| l.max(1));
        self.cells
            .par_chunks_mut(nx)
            .enumerate()
            .for_each(|(r, row)| {
                let (j, k) = (r % ny, r / ny);
                if (j >= last[1] && dy > 0) || (k >= last[2] && dz > 0) {
                    return;
                }
                for (i, c) in row.iter_mut().enumerate().take(last[0]) {
                    let n = i + nx * r;
                    let a = class[n];
                    let same = [dx, dy, dx + dy, dz, dz + dx, dz + dy, dz + dy + dx]
                        .iter()
                        .all(|&o| class[n + o] == a);
                    *c = if same && a != ROUGH { a + 1 } else { MIXED };
                }
            });
    }

    /// Classifies the blocks (after [`Brick::mark_uniform`]): [`EMPTY`] where every voxel a
    /// fetch in it may touch is below `clear_below` HU, one run where all its cells share it.
    pub(super) fn mark_blocks(&mut self, clear_below: f32) {
        let [bx, by, _] = self.block_dims;
        let [nx, ny, _] = self.dims;
        let blocks: Vec<u16> = (0..self.blocks.len())
            .into_par_iter()
            .map(|n| {
                let b = [n % bx, (n / bx) % by, n / (bx * by)];
                let cells = |a: usize| b[a] * BLOCK..((b[a] + 1) * BLOCK).min(self.dims[a]);
                let voxels = |a: usize| b[a] * BLOCK..((b[a] + 1) * BLOCK + 1).min(self.dims[a]);
                let all_voxels = |f: &dyn Fn(usize) -> bool| {
                    voxels(2)
                        .all(|k| voxels(1).all(|j| voxels(0).all(|i| f(i + nx * (j + ny * k)))))
                };
                let all_cells = |f: &dyn Fn(usize) -> bool| {
                    cells(2).all(|k| cells(1).all(|j| cells(0).all(|i| f(i + nx * (j + ny * k)))))
                };
                if all_voxels(&|v| self.data[v].x < clear_below) {
                    return EMPTY;
                }
                let first = self.cells[b[0] * BLOCK + nx * (b[1] * BLOCK + ny * b[2] * BLOCK)];
                if first != MIXED && all_cells(&|c| self.cells[c] == first) {
                    first
                } else {
                    MIXED
                }
            })
            .collect();
        self.reach = block_reach(&blocks, self.block_dims);
        self.blocks = blocks;
    }

    #[inline]
    fn clamp(&self, p: Vec3A) -> Vec3A {
        p.clamp(Vec3A::ZERO, self.hi)
    }

    /// Whether a sample at `p` is surely transparent (its block is empty).
    #[inline]
    pub(super) fn is_clear(&self, p: Vec3A) -> bool {
        let b = (self.clamp(p) * (1.0 / BLOCK as f32)).floor();
        self.blocks[b.dot(self.block_strides) as usize] == EMPTY
    }

    /// The class of the block holding `p`, and how many steps `dp` from `p` on (`p` first)
    /// stay among the blocks around it that share its class (all samples of a [`MIXED`]
    /// block are its own): at least 1. `inv_dp` is 1/`dp`, with a huge value where `dp` is 0.
    #[inline(always)]
    pub(super) fn block_ahead(&self, p: Vec3A, dp: Vec3A, inv_dp: Vec3A) -> (u16, usize) {
        let q = self.clamp(p);
        let b = (q * (1.0 / BLOCK as f32)).floor();
        let i = b.dot(self.block_strides) as usize;
        let r = f32::from(self.reach[i]);
        let lo = (b - Vec3A::splat(r)) * BLOCK as f32;
        let hi = (b + Vec3A::splat(r + 1.0)) * BLOCK as f32;
        // Steps m with p + m·dp still strictly inside: m < s.
        let s = (Vec3A::select(dp.cmpge(Vec3A::ZERO), hi - p, lo - p) * inv_dp)
            .min_element()
            .clamp(0.0, 1e6);
        let m = s as u32;
        (
            self.blocks[i],
            (m + u32::from((m as f32) < s)).max(1) as usize,
        )
    }

    /// The cell holding brick coordinates `p` (voxel units from the brick's first voxel,
    /// clamped into the brick).
    #[inline(always)]
    pub(super) fn locate(&self, p: Vec3A) -> Spot {
        let p = self.clamp(if p.is_finite() { p } else { Vec3A::ZERO });
        // Finite and within [0, dims − 1] after the clamp: truncation is floor (no call to
        // floorf), and the cast needs none of the checks of a saturating `as` (three of them
        // cost as much as the rest of a sample's addressing).
        // SAFETY: every lane is finite, ≥ 0 and < 2³² (see above).
        let ijk = [p.x, p.y, p.z].map(|v| unsafe { v.to_int_unchecked::<u32>() });
        let n = ijk[0] as usize + self.dims[0] * (ijk[1] as usize + self.dims[1] * ijk[2] as usize);
        Spot {
            n,
            f: p - Vec3A::new(ijk[0] as f32, ijk[1] as f32, ijk[2] as f32),
        }
    }

    /// The sample at `p`.
    #[inline(always)]
    pub(super) fn sample(&self, p: Vec3A) -> Sample {
        let spot = self.locate(p);
        self.fetch(spot.n, spot.f)
    }

    /// The sample at fraction `f` of cell `n`.
    #[inline(always)]
    pub(super) fn fetch(&self, n: usize, f: Vec3A) -> Sample {
        let [dx, dy, dz] = self.strides;
        let top = n + dx + dy + dz;
        // The clamp keeps every corner inside; this one check makes that plain, for the
        // unchecked reads below (eight bounds checks cost a quarter of the fetch).
        if top >= self.data.len() {
            return Sample { v: Vec4::ZERO };
        }
        // SAFETY: every index read is between n and top, and top < data.len().
        let at = |o: usize| unsafe { *self.data.get_unchecked(n + o) };
        let c = [
            at(0),
            at(dx),
            at(dy),
            at(dy + dx),
            at(dz),
            at(dz + dx),
            at(dz + dy),
            at(dz + dy + dx),
        ];
        let x00 = c[0].lerp(c[1], f.x);
        let x10 = c[2].lerp(c[3], f.x);
        let x01 = c[4].lerp(c[5], f.x);
        let x11 = c[6].lerp(c[7], f.x);
        Sample {
            v: x00.lerp(x10, f.y).lerp(x01.lerp(x11, f.y), f.z),
        }
    }
}

/// A point in the brick: the index of its cell's lowest voxel, and the point's fraction of
/// the way to the opposite corner.
pub(super) struct Spot {
    pub(super) n: usize,
    pub(super) f: Vec3A,
}

/// What a ray reads at a point: HU and its gradient (HU/mm), interpolated.
#[derive(Clone, Copy, Debug)]
pub(super) struct Sample {
    v: Vec4,
}

impl Sample {
    #[inline(always)]
    pub(super) fn hu(&self) -> f32 {
        self.v.x
    }

    #[inline(always)]
    pub(super) fn gradient(&self) -> Vec3A {
        Vec3A::new(self.v.y, self.v.z, self.v.w)
    }
}

/// Per block of the given classes, the largest r such that every block within Chebyshev
/// distance r (inside the grid) has the same class; 0 for [`MIXED`] blocks. Relaxation to
/// the fixed point of r(b) = min over neighbours n of (r(n) + 1, or 0 where n's class
/// differs): the cube of radius r around b is the union of the cubes of radius r − 1 around
/// its 26 neighbours.
fn block_reach(class: &[u16], dims: [usize; 3]) -> Vec<u8> {
    let mut r: Vec<u8> = class
        .iter()
        .map(|&c| if c == MIXED { 0 } else { u8::MAX })
        .collect();
    let [bx, by, bz] = dims;
    loop {
        let mut changed = false;
        for n in 0..r.len() {
            if r[n] == 0 {
                continue;
            }
            let b = [n % bx, (n / bx) % by, n / (bx * by)];
            let mut best = r[n];
            for o in 0..27 {
                let d = [o % 3, (o / 3) % 3, o / 9];
                let q = [0, 1, 2].map(|a| (b[a] + d[a]).checked_sub(1));
                let [Some(x), Some(y), Some(z)] = q else {
                    continue;
                };
                if x >= bx || y >= by || z >= bz || o == 13 {
                    continue;
                }
                let m = x + bx * (y + by * z);
                best = best.min(if class[m] == class[n] {
                    r[m].saturating_add(1)
                } else {
                    0
                });
            }
            if best != r[n] {
                r[n] = best;
                changed = true;
            }
        }
        if !changed {
            return r;
        }
    }
}

/// HU over a box of voxels, x fastest: the input of the gradient filters.
struct Grid {
    dims: [usize; 3],
    v: Vec<f32>,
}

impl Grid {
    /// The `dims` voxels from `lo`, and one more on every side (the border voxel repeated
    /// beyond the volume's edge).
    fn around(ct: &Volume<i16>, lo: [usize; 3], dims: [usize; 3]) -> Self {
        let d = dims.map(|n| n + 2);
        let vd = ct.dims();
        let at = |a: usize, n: usize| (lo[a] + n).saturating_sub(1).min(vd[a] - 1);
        let mut v = vec![0.0; d[0] * d[1] * d[2]];
        v.par_chunks_mut(d[0]).enumerate().for_each(|(r, row)| {
            let (y, z) = (at(1, r % d[1]), at(2, r / d[1]));
            for (x, o) in row.iter_mut().enumerate() {
                *o = f32::from(ct.get(at(0, x), y, z));
            }
        });
        Grid { dims: d, v }
    }

    /// `w`·(v[−1], v[0], v[+1]) along `axis` at every voxel that has both neighbours: the
    /// grid shrinks by two along `axis`.
    fn filter(&self, axis: usize, w: [f32; 3]) -> Grid {
        let mut d = self.dims;
        d[axis] -= 2;
        let stride = [1, self.dims[0], self.dims[0] * self.dims[1]][axis];
        let mut v = vec![0.0; d[0] * d[1] * d[2]];
        v.par_chunks_mut(d[0]).enumerate().for_each(|(r, row)| {
            let mut src = [0, r % d[1], r / d[1]];
            src[axis] += 1;
            let c = src[0] + self.dims[0] * (src[1] + self.dims[1] * src[2]);
            let n = row.len();
            let (a, b, e) = (
                &self.v[c - stride..][..n],
                &self.v[c..][..n],
                &self.v[c + stride..][..n],
            );
            for (o, ((a, b), e)) in row.iter_mut().zip(a.iter().zip(b).zip(e)) {
                *o = w[0] * a + w[1] * b + w[2] * e;
            }
        });
        Grid { dims: d, v }
    }
}

/// HU and gradient (HU/mm) at the inner voxels of `g`. The gradient is Sobel's: central
/// differences smoothed by (¼, ½, ¼) across, which divides the noise in homogeneous tissue
/// by about 2.7 and leaves a flat boundary's gradient as it is — so that CT noise neither
/// lights a polyp's inside like a surface nor keeps its samples from being uniform.
fn sobel(g: &Grid, spacing: [f64; 3]) -> Vec<Vec4> {
    const SMOOTH: [f32; 3] = [0.25, 0.5, 0.25];
    let (x, y, z) = (0, 1, 2);
    // Smoothed across each axis; the differences along it are taken while assembling.
    let sz = g.filter(z, SMOOTH);
    let across_x = sz.filter(y, SMOOTH);
    let across_y = sz.filter(x, SMOOTH);
    let across_z = g.filter(x, SMOOTH).filter(y, SMOOTH);
    let h = [0, 1, 2].map(|a| (0.5 / spacing[a]) as f32);
    let [nx, ny, nz] = g.dims.map(|d| d - 2);
    let mut out = vec![Vec4::ZERO; nx * ny * nz];
    out.par_chunks_mut(nx).enumerate().for_each(|(r, row)| {
        let (j, k) = (r % ny, r / ny);
        fn at(g: &Grid, i: usize, j: usize, k: usize, n: usize) -> &[f32] {
            &g.v[i + g.dims[0] * (j + g.dims[1] * k)..][..n]
        }
        let hu = at(g, 1, j + 1, k + 1, nx);
        let (xm, xp) = (at(&across_x, 0, j, k, nx), at(&across_x, 2, j, k, nx));
        let (ym, yp) = (at(&across_y, 0, j, k, nx), at(&across_y, 0, j + 2, k, nx));
        let (zm, zp) = (at(&across_z, 0, j, k, nx), at(&across_z, 0, j, k + 2, nx));
        for (i, o) in row.iter_mut().enumerate() {
            *o = Vec4::new(
                hu[i],
                (xp[i] - xm[i]) * h[0],
                (yp[i] - ym[i]) * h[1],
                (zp[i] - zm[i]) * h[2],
            );
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use voyage_core::Geometry;

    #[test]
    fn the_brick_interpolates_values_and_gradients() {
        // HU = 10·x(mm) + 3·z(mm): the gradient is (10, 0, 3) everywhere inside.
        let g = Geometry::new([6, 5, 4], [0.5, 1.0, 2.0], [0.0; 3]).unwrap();
        let data: Vec<i16> = (0..g.len())
            .map(|n| {
                let [i, _, k] = g.ijk(n);
                (10.0 * i as f64 * 0.5 + 3.0 * k as f64 * 2.0) as i16
            })
            .collect();
        let ct = Volume::from_vec(g, data).unwrap();
        let b = Brick::new(&ct, [1, 0, 1], [4, 4, 3]);
        let s = b.sample(Vec3A::new(1.5, 2.25, 0.5)).v;
        // Brick (1.5, 2.25, 0.5) is volume index (2.5, 2.25, 1.5): x = 1.25 mm, z = 3 mm.
        assert!((s.x - (12.5 + 9.0)).abs() < 1e-4, "{s}");
        assert!(
            (s.y - 10.0).abs() < 1e-4 && s.z.abs() < 1e-4 && (s.w - 3.0).abs() < 1e-4,
            "{s}"
        );
    }
}
