//! Fields restricted to a box of the volume: the distance fields and the potential live only
//! around the lumen, so they are stored over the lumen's bounding box (plus a margin), not over
//! the whole CT — a 512×512×400 scan would otherwise cost 400 MB per f32 field.

use crate::{Geometry, Result, Volume};

/// An axis-aligned box of voxels inside a volume: `lo` is its first voxel, `dims` its size.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BoxGrid {
    pub lo: [usize; 3],
    pub dims: [usize; 3],
}

impl BoxGrid {
    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Index inside the box of box-local voxel (i, j, k).
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        crate::volume::grid_index(self.dims, i, j, k)
    }
    /// Box-local (i, j, k) of a box index.
    #[inline]
    pub fn ijk(&self, index: usize) -> [usize; 3] {
        crate::volume::grid_ijk(self.dims, index)
    }
    /// Box index of a volume voxel, or None when it lies outside the box.
    #[inline]
    pub fn index_of_global(&self, g: [usize; 3]) -> Option<usize> {
        let mut l = [0usize; 3];
        for a in 0..3 {
            l[a] = g[a].checked_sub(self.lo[a])?;
            if l[a] >= self.dims[a] {
                return None;
            }
        }
        Some(self.index(l[0], l[1], l[2]))
    }
    /// Volume voxel of a box index.
    #[inline]
    pub fn global_of_index(&self, index: usize) -> [usize; 3] {
        let [i, j, k] = self.ijk(index);
        [i + self.lo[0], j + self.lo[1], k + self.lo[2]]
    }
}

/// The bounding box of the voxels where `pred` holds, grown by `margin` voxels and clipped to
/// the volume. None when no voxel matches.
pub fn bounding_box<T: Copy>(vol: &Volume<T>, margin: usize, pred: impl Fn(T) -> bool) -> Option<BoxGrid> {
    let [nx, ny, nz] = vol.dims();
    let mut lo = [usize::MAX; 3];
    let mut hi = [0usize; 3];
    for k in 0..nz {
        let slice = vol.slice_k(k);
        for j in 0..ny {
            let row = &slice[j * nx..(j + 1) * nx];
            let Some(first) = row.iter().position(|&v| pred(v)) else { continue };
            let last = row.iter().rposition(|&v| pred(v)).unwrap_or(first);
            lo = [lo[0].min(first), lo[1].min(j), lo[2].min(k)];
            hi = [hi[0].max(last), hi[1].max(j), hi[2].max(k)];
        }
    }
    if lo[0] == usize::MAX {
        return None;
    }
    let dims = vol.dims();
    let lo_m = [0, 1, 2].map(|a| lo[a].saturating_sub(margin));
    let hi_m = [0, 1, 2].map(|a| (hi[a] + margin).min(dims[a] - 1));
    Some(BoxGrid { lo: lo_m, dims: [0, 1, 2].map(|a| hi_m[a] - lo_m[a] + 1) })
}

/// Values over a [`BoxGrid`] of a volume with the given geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct Field<T> {
    pub grid: BoxGrid,
    pub geometry: Geometry,
    pub data: Vec<T>,
}

impl<T: Copy> Field<T> {
    pub fn filled(grid: BoxGrid, geometry: Geometry, v: T) -> Self {
        let n = grid.len();
        Field { grid, geometry, data: vec![v; n] }
    }
    /// Value at a volume voxel; `outside` when the voxel is not in the box.
    #[inline]
    pub fn get_global(&self, g: [usize; 3], outside: T) -> T {
        self.grid.index_of_global(g).map_or(outside, |i| self.data[i])
    }
    /// Axial slice k of the field spread over the whole volume (x fastest), `outside` beyond
    /// the box: for writing a field without a whole volume in memory.
    pub fn fill_slice(&self, k: usize, out: &mut [T], outside: T) {
        out.fill(outside);
        let lo = self.grid.lo;
        let [bx, by, bz] = self.grid.dims;
        if k < lo[2] || k >= lo[2] + bz {
            return;
        }
        let nx = self.geometry.dims[0];
        for j in 0..by {
            let src = &self.data[self.grid.index(0, j, k - lo[2])..][..bx];
            let start = lo[0] + nx * (j + lo[1]);
            out[start..start + bx].copy_from_slice(src);
        }
    }

    /// The field spread over the whole volume, `outside` beyond the box (for exports).
    pub fn to_volume(&self, outside: T) -> Result<Volume<T>> {
        let mut v = Volume::filled(self.geometry.clone(), outside)?;
        let [nx, ny, _] = self.geometry.dims;
        for (k, slice) in v.data_mut().chunks_mut(nx * ny).enumerate() {
            self.fill_slice(k, slice, outside);
        }
        Ok(v)
    }
}

/// The part of a volume inside a box, as a flat vector in box order.
pub fn crop<T: Copy>(vol: &Volume<T>, grid: &BoxGrid) -> Vec<T> {
    let mut out = Vec::with_capacity(grid.len());
    let [bx, by, bz] = grid.dims;
    for k in 0..bz {
        for j in 0..by {
            let start = vol.geometry().index(grid.lo[0], j + grid.lo[1], k + grid.lo[2]);
            out.extend_from_slice(&vol.data()[start..start + bx]);
        }
    }
    out
}

impl Field<f32> {
    /// Trilinear interpolation at a volume-local position (mm); corners outside the box
    /// count as `outside`.
    pub fn sample(&self, mm: glam::DVec3, outside: f32) -> f32 {
        let p = self.geometry.local_to_index(mm);
        let base = p.floor();
        let t = p - base;
        let mut acc = 0.0f64;
        for c in 0..8 {
            let o = [(c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64];
            let w = (if o[0] > 0.0 { t.x } else { 1.0 - t.x }) * (if o[1] > 0.0 { t.y } else { 1.0 - t.y }) * (if o[2] > 0.0 { t.z } else { 1.0 - t.z });
            if w == 0.0 {
                continue;
            }
            let g = [base.x + o[0], base.y + o[1], base.z + o[2]];
            let v = if g.iter().all(|&x| x >= 0.0) {
                self.get_global([g[0] as usize, g[1] as usize, g[2] as usize], outside)
            } else {
                outside
            };
            acc += w * v as f64;
        }
        acc as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_equal_the_spread_volume() {
        let g = Geometry::new([7, 6, 5], [1.0, 0.5, 2.0], [0.0; 3]).unwrap();
        let grid = BoxGrid { lo: [2, 1, 1], dims: [3, 4, 3] };
        let data = (0..grid.len()).map(|i| i as f32 + 1.0).collect();
        let f = Field { grid, geometry: g.clone(), data };
        let v = f.to_volume(-1.0).unwrap();
        let mut s = vec![0.0f32; 7 * 6];
        for k in 0..5 {
            f.fill_slice(k, &mut s, -1.0);
            assert_eq!(&s[..], v.slice_k(k));
            for j in 0..6 {
                for i in 0..7 {
                    assert_eq!(v.get(i, j, k), f.get_global([i, j, k], -1.0), "voxel {i},{j},{k}");
                }
            }
        }
        assert_eq!(v.data().iter().filter(|&&x| x > 0.0).count(), 36, "every box value placed once");
        assert_eq!(f.get_global([2, 1, 1], -1.0), 1.0);
        assert_eq!(f.get_global([0, 0, 0], -1.0), -1.0);
    }
}
