//! The padded box the searches run on: the lumen's box with one layer of wall around it, so
//! that the 26 neighbours of every lumen voxel are valid indices even where the box touches
//! the volume's border.

use super::{BoxGrid, BrickMarks};
use crate::{
    Error, Result, Volume,
    volume::{grid_ijk, grid_index},
};

/// The box's mask with one layer of zeros around it, so that the 26 neighbours of every lumen
/// voxel are valid indices even where the box touches the volume's border.
pub struct Padded {
    pub(crate) grid: BoxGrid,
    pub(crate) dims: [usize; 3],
    pub(crate) inside: Vec<u8>,
}

/// An index into the padded layout (a search's arrays; [`Padded::index_of_global`] and
/// [`Padded::global_of_index`] convert), never a volume's flat index (a plain `usize`) or the
/// box's ([`crate::grid::BoxIndex`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PadIndex(pub usize);

impl Padded {
    #[cfg(test)]
    pub fn new(mask: &Volume<u8>, grid: &BoxGrid) -> Self {
        Self::new_in(mask, grid, Vec::new())
    }

    /// The lumen of `mask` over `grid`'s box with a wall around it, in the memory of `reuse`
    /// where it is large enough.
    pub(crate) fn new_in(mask: &Volume<u8>, grid: &BoxGrid, reuse: Vec<u8>) -> Self {
        let mut pad = Padded::shape(grid);
        pad.inside = pad.lay_out_mask(mask, 0, 0u8, |m| (m != 0) as u8, reuse, None);
        pad
    }

    /// `mask` over the box in the padded layout, each voxel as `value` makes it, `wall` in the
    /// padding, plus `spare` more `wall`s at the end; `marks` hears of the bricks holding lumen.
    pub(crate) fn lay_out_mask<T: Copy>(
        &self,
        mask: &Volume<u8>,
        spare: usize,
        wall: T,
        value: impl Fn(u8) -> T,
        reuse: Vec<T>,
        mut marks: Option<&mut BrickMarks>,
    ) -> Vec<T> {
        let n = self.len() + spare;
        let mut out = crate::mem::collect_in(reuse, n, std::iter::repeat_n(wall, n));
        let (g, grid) = (mask.geometry(), &self.grid);
        for k in 0..grid.dims[2] {
            for j in 0..grid.dims[1] {
                let src = &mask.data()[g.index(grid.lo[0], grid.lo[1] + j, grid.lo[2] + k)..]
                    [..grid.dims[0]];
                if let Some(m) = marks.as_deref_mut() {
                    m.mark_row(j, k, src, |m| m != 0);
                }
                let dst = self.row_start(j, k);
                for (d, &m) in out[dst..dst + grid.dims[0]].iter_mut().zip(src) {
                    *d = value(m);
                }
            }
        }
        out
    }

    /// The padded layout of `grid` without the mask (for searches that start from
    /// `start_from_mask`).
    pub(crate) fn shape(grid: &BoxGrid) -> Self {
        Padded {
            grid: grid.clone(),
            dims: grid.dims.map(|d| d + 2),
            inside: Vec::new(),
        }
    }

    /// Voxels of the padded box.
    pub(crate) fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Length of a search's distances: the padded box and one spare wall.
    pub(crate) fn search_len(&self) -> usize {
        self.len() + 1
    }

    /// Box row (j, k) of a padded-layout field.
    #[inline]
    pub(crate) fn row<'a>(&self, v: &'a [f32], j: usize, k: usize) -> &'a [f32] {
        &v[self.row_start(j, k)..][..self.grid.dims[0]]
    }

    /// Padded index of box row (j, k)'s first voxel.
    #[inline]
    pub(crate) fn row_start(&self, j: usize, k: usize) -> usize {
        1 + self.dims[0] * (j + 1 + self.dims[1] * (k + 1))
    }

    /// Padded index of a volume voxel that must be lumen.
    pub fn lumen_index(&self, v: [usize; 3]) -> Result<PadIndex> {
        self.index_of_global(v)
            .filter(|&i| self.inside[i.0] != 0)
            .ok_or_else(|| Error::invalid(format!("the voxel {v:?} is not in the lumen")))
    }

    /// The padded index of a volume voxel (None outside the box).
    pub fn index_of_global(&self, g: [usize; 3]) -> Option<PadIndex> {
        let l = self.grid.index_of_global(g).map(|i| self.grid.ijk(i))?;
        Some(PadIndex(grid_index(
            self.dims,
            l[0] + 1,
            l[1] + 1,
            l[2] + 1,
        )))
    }

    /// The volume voxel of a padded index.
    pub fn global_of_index(&self, idx: PadIndex) -> [usize; 3] {
        let p = grid_ijk(self.dims, idx.0);
        [0, 1, 2].map(|a| p[a] - 1 + self.grid.lo[a])
    }

    /// Offsets from an index to the first of each of the nine rows of three (along x) that
    /// hold its 26 neighbours and itself, in the order of [`Padded::neighbours`] (z, then y).
    pub(crate) fn neighbour_row_starts(&self) -> [isize; 9] {
        let (nx, ny) = (self.dims[0] as isize, self.dims[1] as isize);
        std::array::from_fn(|r| -1 + nx * ((r % 3) as isize - 1 + ny * ((r / 3) as isize - 1)))
    }

    /// 26 neighbour offsets and their lengths in mm.
    pub fn neighbours(&self, spacing: [f64; 3]) -> Vec<(isize, f32)> {
        let (nx, ny) = (self.dims[0] as isize, self.dims[1] as isize);
        let mut out = Vec::with_capacity(26);
        for dk in -1isize..=1 {
            for dj in -1isize..=1 {
                for di in -1isize..=1 {
                    if di == 0 && dj == 0 && dk == 0 {
                        continue;
                    }
                    let len = ((di as f64 * spacing[0]).powi(2)
                        + (dj as f64 * spacing[1]).powi(2)
                        + (dk as f64 * spacing[2]).powi(2))
                    .sqrt();
                    out.push((di + nx * (dj + ny * dk), len as f32));
                }
            }
        }
        out
    }

    /// Copies a box-layout field into the padded layout (`fill` in the padding), in the
    /// memory of `reuse` where it is large enough.
    pub(crate) fn pad_in(&self, v: &[f32], fill: f32, reuse: Vec<f32>) -> Vec<f32> {
        let [bx, by, bz] = self.grid.dims;
        let mut out = crate::mem::refilled(reuse, self.inside.len(), fill);
        for k in 0..bz {
            for j in 0..by {
                let d = self.row_start(j, k);
                let s = self.grid.index(0, j, k).0;
                out[d..d + bx].copy_from_slice(&v[s..s + bx]);
            }
        }
        out
    }
}
