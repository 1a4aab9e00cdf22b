//! The compartments on a coarse grid of about 4 mm blocks: where the chain looks for the
//! compartments' ends and the bridges between them search.

use std::{cmp::Reverse, collections::BinaryHeap};

use glam::DVec3;

use super::work::{Bbox, Key};

/// Block size of the coarse grid (mm).
const BLOCK_MM: f64 = 4.0;

/// Compartments on blocks of about [`BLOCK_MM`]: each block takes the compartment of the
/// first candidate voxel seen in it.
pub struct Coarse {
    f: [usize; 3],
    dims: [usize; 3],
    step_mm: [f64; 3],
    label: Vec<u32>,
}

impl Coarse {
    pub fn new(dims: [usize; 3], spacing: [f64; 3]) -> Coarse {
        let f = spacing.map(|s| ((BLOCK_MM / s).round() as usize).max(1));
        let cd = [0, 1, 2].map(|a| dims[a].div_ceil(f[a]));
        Coarse {
            f,
            dims: cd,
            step_mm: [0, 1, 2].map(|a| spacing[a] * f[a] as f64),
            label: vec![u32::MAX; cd[0] * cd[1] * cd[2]],
        }
    }

    /// Marks voxels x0..x1 of row (j, k) as compartment `c`.
    pub fn mark_run(&mut self, x0: usize, x1: usize, j: usize, k: usize, c: u32) {
        let (bj, bk) = (j / self.f[1], k / self.f[2]);
        for bi in x0 / self.f[0]..=(x1 - 1) / self.f[0] {
            let at = bi + self.dims[0] * (bj + self.dims[1] * bk);
            if self.label[at] == u32::MAX {
                self.label[at] = c;
            }
        }
    }

    pub fn block_of(&self, v: [usize; 3]) -> usize {
        let b = [0, 1, 2].map(|a| v[a] / self.f[a]);
        b[0] + self.dims[0] * (b[1] + self.dims[1] * b[2])
    }

    pub(super) fn coords(&self, b: usize) -> [usize; 3] {
        [
            b % self.dims[0],
            (b / self.dims[0]) % self.dims[1],
            b / (self.dims[0] * self.dims[1]),
        ]
    }

    /// The voxel range of block `b`, for finding a voxel of it.
    pub fn voxels_of(&self, b: usize, vol_dims: [usize; 3]) -> Bbox {
        let c = self.coords(b);
        Bbox {
            lo: [0, 1, 2].map(|a| c[a] * self.f[a]),
            hi: [0, 1, 2].map(|a| ((c[a] + 1) * self.f[a]).min(vol_dims[a]) - 1),
        }
    }

    /// The farthest block of compartment `c` from block `from` (geodesic, over its blocks)
    /// and its distance.
    pub fn farthest(&self, c: u32, from: usize) -> (usize, f64) {
        self.distances(c, from).1
    }

    /// Geodesic distances (mm, 26-neighbours) from block `from` over the blocks of
    /// compartment `c` (infinite elsewhere), and the farthest block with its distance.
    pub(super) fn distances(&self, c: u32, from: usize) -> (Vec<f64>, (usize, f64)) {
        let mut dist = vec![f64::INFINITY; self.label.len()];
        let mut heap = BinaryHeap::new();
        dist[from] = 0.0;
        heap.push(Reverse((Key(0.0), from)));
        let mut best = (from, 0.0);
        while let Some(Reverse((Key(d), u))) = heap.pop() {
            if d > dist[u] {
                continue;
            }
            // Ties: the block first in patient-independent terms would need geometry; the
            // distance itself decides, and equal distances are rare on mm edge lengths.
            if d > best.1 {
                best = (u, d);
            }
            let p = self.coords(u);
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let q = [p[0] as i64 + dx, p[1] as i64 + dy, p[2] as i64 + dz];
                        if (dx, dy, dz) == (0, 0, 0)
                            || (0..3).any(|a| q[a] < 0 || q[a] >= self.dims[a] as i64)
                        {
                            continue;
                        }
                        let v = q[0] as usize
                            + self.dims[0] * (q[1] as usize + self.dims[1] * q[2] as usize);
                        if self.label[v] != c {
                            continue;
                        }
                        let len = ((dx as f64 * self.step_mm[0]).powi(2)
                            + (dy as f64 * self.step_mm[1]).powi(2)
                            + (dz as f64 * self.step_mm[2]).powi(2))
                        .sqrt();
                        let nd = d + len;
                        if nd < dist[v] {
                            dist[v] = nd;
                            heap.push(Reverse((Key(nd), v)));
                        }
                    }
                }
            }
        }
        (dist, best)
    }

    /// The blocks of each of `n` compartments, in block order.
    pub(super) fn blocks_by_comp(&self, n: usize) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); n];
        for (b, &c) in self.label.iter().enumerate() {
            if (c as usize) < n {
                out[c as usize].push(b);
            }
        }
        out
    }

    /// The block of `blocks` nearest a point (volume-local mm).
    pub(super) fn nearest(&self, blocks: &[usize], to: DVec3) -> Option<usize> {
        blocks.iter().copied().min_by(|&x, &y| {
            self.centre_mm(x)
                .distance_squared(to)
                .total_cmp(&self.centre_mm(y).distance_squared(to))
        })
    }

    /// Centre of block `b`, volume-local mm.
    pub fn centre_mm(&self, b: usize) -> DVec3 {
        let c = self.coords(b);
        DVec3::new(
            (c[0] as f64 + 0.5) * self.step_mm[0],
            (c[1] as f64 + 0.5) * self.step_mm[1],
            (c[2] as f64 + 0.5) * self.step_mm[2],
        )
    }
}
