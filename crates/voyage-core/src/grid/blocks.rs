//! The lumen's box in blocks of f×f×f voxels, for the searches that need the colon's shape but
//! not every voxel of it (the skeleton, the contacts between loops): a voxel of 0.8 mm is far
//! finer than a path through a 30 mm lumen needs, and 2×2×2 blocks have an eighth of the voxels.
//!
//! A block is *full* when all its voxels are lumen, so that no wall, however thin, disappears
//! (a block half lumen, half wall would open a short cut between two loops that the voxels do
//! not have); the lumen shrinks by at most a voxel, which the narrowest colon survives. A
//! block with some lumen voxels but not all is *partial*.

use glam::DVec3;

use crate::{Error, Geometry, Result, Volume, grid::BoxGrid};

pub struct Blocks {
    /// Voxels per block along each axis.
    pub factor: usize,
    /// Full blocks as a mask (block (0,0,0) at the origin; spacing `factor` × the voxels').
    pub mask: Volume<u8>,
    /// Lumen voxels per block (0 ..= factor³), block order.
    pub count: Vec<u8>,
    /// Volume voxel of block (0,0,0)'s first voxel.
    pub lo: [usize; 3],
    pub fine_spacing: [f64; 3],
}

/// How far (in blocks) a point may be moved onto a full block.
const MAX_SNAP_BLOCKS: i64 = 8;

/// Adds to each `out[i]` how many of `row[2i]`, `row[2i + 1]` are lumen: the skeleton's
/// blocks are 2 wide, and pairs of a fixed width compile to vector code where the general
/// chunks do not (a full colon's box is 32 M voxels).
fn count_pairs(out: &mut [u8], row: &[u8]) {
    let pairs = row.chunks_exact(2);
    let odd = pairs.remainder().first().copied();
    for (o, p) in out.iter_mut().zip(pairs) {
        *o += (p[0] != 0) as u8 + (p[1] != 0) as u8;
    }
    if let (Some(m), Some(o)) = (odd, out.get_mut(row.len() / 2)) {
        *o += (m != 0) as u8;
    }
}

impl Blocks {
    /// The blocks covering `grid` (a box inside `lumen`'s volume).
    pub fn new(lumen: &Volume<u8>, grid: &BoxGrid, factor: usize) -> Result<Blocks> {
        let f = factor.max(1);
        let dims = grid.dims.map(|n| n.div_ceil(f));
        let sp = lumen.spacing();
        let mut count = vec![0u8; dims[0] * dims[1] * dims[2]];
        let g = lumen.geometry();
        for k in 0..grid.dims[2] {
            for j in 0..grid.dims[1] {
                let row = &lumen.data()[g.index(grid.lo[0], grid.lo[1] + j, grid.lo[2] + k)..]
                    [..grid.dims[0]];
                let base = dims[0] * (j / f + dims[1] * (k / f));
                let out = &mut count[base..base + dims[0]];
                if f == 2 {
                    count_pairs(out, row);
                } else {
                    for (out, chunk) in out.iter_mut().zip(row.chunks(f)) {
                        *out += chunk.iter().map(|&m| (m != 0) as u8).sum::<u8>();
                    }
                }
            }
        }
        let full = (f * f * f) as u8;
        let geom = Geometry::new(dims, sp.map(|s| f as f64 * s), [0.0; 3])?;
        let mask = Volume::from_vec(geom, count.iter().map(|&c| (c == full) as u8).collect())?;
        Ok(Blocks {
            factor: f,
            mask,
            count,
            lo: grid.lo,
            fine_spacing: sp,
        })
    }

    pub fn dims(&self) -> [usize; 3] {
        self.mask.dims()
    }

    /// The block holding volume voxel `v`, if it lies in the blocks' box.
    pub fn block_of_voxel(&self, v: [usize; 3]) -> Option<[usize; 3]> {
        let dims = self.dims();
        let mut c = [0usize; 3];
        for a in 0..3 {
            c[a] = v[a].checked_sub(self.lo[a])? / self.factor;
            if c[a] >= dims[a] {
                return None;
            }
        }
        Some(c)
    }

    /// The block holding the voxel nearest to volume-local point `p` (mm).
    pub fn block_of_mm(&self, p: DVec3) -> Option<[usize; 3]> {
        let v = [0, 1, 2].map(|a| (p[a] / self.fine_spacing[a]).round());
        if v.iter().any(|&x| x < 0.0) {
            return None;
        }
        self.block_of_voxel(v.map(|x| x as usize))
    }

    /// The block holding voxel `v` when it is full, else the nearest full block (the seed, at
    /// the tip of a rectal tube, may lie where no whole block is lumen).
    pub fn nearest_full(&self, v: [usize; 3]) -> Result<[usize; 3]> {
        let c = [0, 1, 2].map(|a| (v[a].saturating_sub(self.lo[a]) / self.factor) as i64);
        let dims = self.dims();
        for r in 0..=MAX_SNAP_BLOCKS {
            let mut best: Option<(i64, [usize; 3])> = None;
            for dk in -r..=r {
                for dj in -r..=r {
                    for di in -r..=r {
                        let q = [c[0] + di, c[1] + dj, c[2] + dk];
                        if q.iter().zip(dims).any(|(&x, n)| x < 0 || x >= n as i64) {
                            continue;
                        }
                        let q = q.map(|x| x as usize);
                        let d2 = di * di + dj * dj + dk * dk;
                        if self.mask.get(q[0], q[1], q[2]) != 0 && best.is_none_or(|b| d2 < b.0) {
                            best = Some((d2, q));
                        }
                    }
                }
            }
            if let Some(b) = best {
                return Ok(b.1);
            }
        }
        Err(Error::invalid(format!(
            "the voxel {v:?} lies where the lumen is too narrow to follow"
        )))
    }

    /// Volume-local mm of a block's centre.
    pub fn centre_mm(&self, c: [usize; 3]) -> DVec3 {
        let half = (self.factor as f64 - 1.0) / 2.0;
        DVec3::from_array([0, 1, 2].map(|a| {
            (self.lo[a] as f64 + (self.factor * c[a]) as f64 + half) * self.fine_spacing[a]
        }))
    }

    /// The volume voxels of block `c` (those inside the volume).
    pub fn voxels(
        &self,
        c: [usize; 3],
        vol_dims: [usize; 3],
    ) -> impl Iterator<Item = [usize; 3]> + '_ {
        let f = self.factor;
        (0..f * f * f).filter_map(move |o| {
            let v = [
                self.lo[0] + f * c[0] + o % f,
                self.lo[1] + f * c[1] + (o / f) % f,
                self.lo[2] + f * c[2] + o / (f * f),
            ];
            v.iter().zip(vol_dims).all(|(&x, n)| x < n).then_some(v)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pair_counts_equal_the_general_chunks() {
        let mut rng = crate::rng::Rng::new(7, 1);
        for len in 0..70usize {
            let row: Vec<u8> = (0..len)
                .map(|_| [0u8, 1, 1, 255][rng.range(0.0, 3.999) as usize])
                .collect();
            let mut general = vec![3u8; len.div_ceil(2)];
            for (o, c) in general.iter_mut().zip(row.chunks(2)) {
                *o += c.iter().filter(|&&m| m != 0).count() as u8;
            }
            let mut pairs = vec![3u8; len.div_ceil(2)];
            count_pairs(&mut pairs, &row);
            assert_eq!(pairs, general, "row {row:?}");
        }
    }

    #[test]
    fn counts_full_and_partial_blocks() {
        let g = Geometry::new([6, 5, 4], [0.5, 0.5, 1.0], [0.0; 3]).unwrap();
        let mut data = vec![0u8; g.len()];
        // A 4×2×2 slab of lumen from voxel (1,1,1): blocks (0..=2, 0..=1, 0..=1) of the box
        // starting at (1,1,1) with factor 2 hold 8, 8 voxels in the first two blocks.
        for k in 1..3 {
            for j in 1..3 {
                for i in 1..5 {
                    data[g.index(i, j, k)] = 1;
                }
            }
        }
        data[g.index(5, 1, 1)] = 1;
        let vol = Volume::from_vec(g, data).unwrap();
        let grid = BoxGrid {
            lo: [1, 1, 1],
            dims: [5, 4, 3],
        };
        let b = Blocks::new(&vol, &grid, 2).unwrap();
        assert_eq!(b.dims(), [3, 2, 2]);
        assert_eq!(b.count[0], 8);
        assert_eq!(b.count[1], 8);
        assert_eq!(b.count[2], 1);
        assert_eq!(b.mask.data().iter().map(|&m| m as usize).sum::<usize>(), 2);
        assert_eq!(b.block_of_voxel([5, 1, 1]), Some([2, 0, 0]));
        assert_eq!(b.block_of_voxel([0, 1, 1]), None);
        assert_eq!(b.nearest_full([5, 1, 1]).unwrap(), [1, 0, 0]);
        assert_eq!(b.centre_mm([0, 0, 0]), DVec3::new(0.75, 0.75, 1.5));
        assert_eq!(
            b.voxels([2, 0, 0], vol.dims()).count(),
            4,
            "the box's last block is cut by the volume's end"
        );
    }
}
