//! The other layouts of the navigable voxels' distances, for `voyage bench fly` to measure
//! against the bricks navigation uses (feature `layouts`): the paper's list sorted by volume
//! index, found by binary search, and the dense box.

use voyage_core::{Error, Navigable, Result, Study};

use crate::potential::{DistanceStore, OUTSIDE, Voxel, navigable_voxels};

/// The paper's storage: lumen voxels sorted by volume index, found by binary search.
pub struct SortedStore {
    dims: [i64; 3],
    index: Vec<u32>,
    values: Vec<Voxel>,
}

impl SortedStore {
    pub fn new(study: &Study, nav: &Navigable) -> Result<Self> {
        let d = study.ds.geometry.dims;
        if d.iter().product::<usize>() > u32::MAX as usize {
            return Err(Error::invalid(
                "the volume has more voxels than a 32-bit index holds",
            ));
        }
        let mut pairs = Vec::new();
        navigable_voxels(study, nav, |g, v| {
            pairs.push(((g[0] + d[0] * (g[1] + d[1] * g[2])) as u32, v));
        });
        pairs.sort_unstable_by_key(|p| p.0);
        let (index, values) = pairs.into_iter().unzip();
        Ok(SortedStore {
            dims: d.map(|x| x as i64),
            index,
            values,
        })
    }
}

impl DistanceStore for SortedStore {
    #[inline]
    fn get(&self, g: [i64; 3]) -> Option<Voxel> {
        if (0..3).any(|a| g[a] < 0 || g[a] >= self.dims[a]) {
            return None;
        }
        let key = (g[0] + self.dims[0] * (g[1] + self.dims[1] * g[2])) as u32;
        self.index.binary_search(&key).ok().map(|i| self.values[i])
    }
    fn bytes(&self) -> usize {
        self.index.capacity() * 4 + self.values.capacity() * std::mem::size_of::<Voxel>()
    }
    fn voxels(&self) -> usize {
        self.index.len()
    }
}

/// The densest layout, for comparison: every voxel of the lumen's box (12 bytes each).
pub struct BoxStore {
    lo: [i64; 3],
    dims: [i64; 3],
    values: Vec<Voxel>,
    voxels: usize,
}

impl BoxStore {
    pub fn new(study: &Study, nav: &Navigable) -> Result<Self> {
        let grid = &study.ds.grid;
        let mut values = vec![OUTSIDE; grid.len()];
        let mut voxels = 0;
        navigable_voxels(study, nav, |g, v| {
            let l = [0, 1, 2].map(|a| g[a] - grid.lo[a]);
            values[grid.index(l[0], l[1], l[2]).0] = v;
            voxels += 1;
        });
        Ok(BoxStore {
            lo: grid.lo.map(|x| x as i64),
            dims: grid.dims.map(|x| x as i64),
            values,
            voxels,
        })
    }
}

impl DistanceStore for BoxStore {
    #[inline]
    fn get(&self, g: [i64; 3]) -> Option<Voxel> {
        let l = [g[0] - self.lo[0], g[1] - self.lo[1], g[2] - self.lo[2]];
        if (0..3).any(|a| l[a] < 0 || l[a] >= self.dims[a]) {
            return None;
        }
        let v = self.values[(l[0] + self.dims[0] * (l[1] + self.dims[1] * l[2])) as usize];
        (v.ds > 0.0).then_some(v)
    }
    fn bytes(&self) -> usize {
        self.values.capacity() * std::mem::size_of::<Voxel>()
    }
    fn voxels(&self) -> usize {
        self.voxels
    }
}
