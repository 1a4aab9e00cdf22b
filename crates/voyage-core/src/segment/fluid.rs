//! Tagged fluid that belongs to the colon, and gravity from the air–fluid levels.
//!
//! Residual fluid in a CT colonography is tagged with oral contrast (300–1000 HU) and lies on
//! the dependent side of a colon segment under a flat level, with the segment's air on top.
//! Oral contrast also fills small-bowel loops, which touch the colon and, through the
//! ileocecal valve, join the cecum's pool into one bright region: connectivity cannot tell
//! them apart. Geometry can: the colon's pool lies in the column *under the colon's air*,
//! across the level; the loops leave it sideways or downwards as tubes with no air above.
//!
//! So fluid is taken line by line along gravity (the voxel axis nearest to it), from the top
//! down: a bright voxel joins the colon when the line came down through gas, then at most a
//! partial-volume layer of a couple of millimetres, then only bright voxels, and has not gone
//! deeper than `MAX_DEPTH_MM` below the level. A loop under the colon is behind two walls
//! (more than the layer allows); a loop beside it has no gas above.

use super::work::{Bbox, BRIGHT, GAS, LAYER, POOL};
use crate::anatomy::PatientFrame;
use crate::Volume;
use glam::DVec3;

/// A pool deeper than this below its level is not one colon segment's fluid.
pub const MAX_DEPTH_MM: f64 = 60.0;

/// Between air and fluid the partial-volume layer is at most this thick (mm; at least one
/// voxel).
const MAX_LAYER_MM: f64 = 2.0;

/// The layer's thickness in voxels along an axis of spacing `step`.
fn max_gap(step: f64) -> u32 {
    ((MAX_LAYER_MM / step).round() as u32).clamp(1, 3)
}

/// Visits the voxels of `bx` so that each line along `axis` is walked in the direction
/// `sign`: `f(line, index)` gets the line's number (0..lines) and the voxel's volume index.
fn sweep(dims: [usize; 3], bx: &Bbox, axis: usize, sign: i32, mut f: impl FnMut(usize, usize)) {
    let w = bx.widths();
    let others: Vec<usize> = (0..3).filter(|&a| a != axis).collect();
    let (b, c) = (others[0], others[1]);
    let range = |a: usize| -> Box<dyn Iterator<Item = usize>> {
        if a == axis && sign < 0 { Box::new((bx.lo[a]..=bx.hi[a]).rev()) } else { Box::new(bx.lo[a]..=bx.hi[a]) }
    };
    for k in range(2) {
        for j in range(1) {
            let row = dims[0] * (j + dims[1] * k);
            for i in range(0) {
                let p = [i, j, k];
                let line = (p[b] - bx.lo[b]) + (p[c] - bx.lo[c]) * w[b];
                f(line, row + i);
            }
        }
    }
}

/// Marks the colon's tagged fluid in `work` (GAS and BRIGHT set): bright voxels in the column
/// under gas become POOL, the layer between them LAYER. Gravity: LPS unit vector. Returns the
/// voxels marked.
pub fn mark_pools(work: &mut Volume<u8>, bx: &Bbox, gravity_lps: DVec3) -> usize {
    let frame = PatientFrame::of(work.geometry());
    let (axis, sign) = frame.nearest_axis(gravity_lps);
    let step = work.spacing()[axis];
    let gap_max = max_gap(step);
    let depth_max = (MAX_DEPTH_MM / step).round() as u32;
    let dims = work.dims();
    let stride = [1isize, dims[0] as isize, (dims[0] * dims[1]) as isize][axis] * sign as isize;
    let lines = bx.lines(axis);
    // Per line: 0 closed, 1 below gas (counting the layer), 2 in fluid; voxels since the gas.
    let mut state = vec![0u8; lines];
    let mut gap = vec![0u32; lines];
    let mut depth = vec![0u32; lines];
    let data = work.data_mut();
    let mut marked = 0;
    sweep(dims, bx, axis, sign, |line, v| match data[v] {
        GAS => {
            state[line] = 1;
            gap[line] = 0;
            depth[line] = 0;
        }
        BRIGHT | POOL if state[line] != 0 && depth[line] < depth_max => {
            if state[line] == 1 {
                // The layer just walked through lies between the air and this fluid.
                for t in 1..=gap[line] as isize {
                    let u = (v as isize - t * stride) as usize;
                    if data[u] == 0 {
                        data[u] = LAYER;
                        marked += 1;
                    }
                }
            }
            if data[v] == BRIGHT {
                data[v] = POOL;
                marked += 1;
            }
            state[line] = 2;
            depth[line] += 1;
        }
        _ => {
            if state[line] == 1 && gap[line] < gap_max {
                gap[line] += 1;
                depth[line] += 1;
            } else {
                state[line] = 0;
            }
        }
    });
    marked
}

/// Air–fluid interfaces seen along each voxel axis: `[axis][0]` counts lines going from gas
/// down into fluid along +axis, `[axis][1]` along −axis.
pub fn level_counts(work: &Volume<u8>, bx: &Bbox) -> [[usize; 2]; 3] {
    let dims = work.dims();
    let data = work.data();
    let mut out = [[0usize; 2]; 3];
    for (axis, counts) in out.iter_mut().enumerate() {
        let gap_max = max_gap(work.spacing()[axis]);
        let lines = bx.lines(axis);
        // Per line: what was last seen (0 nothing, GAS, BRIGHT) and the voxels since.
        let mut last = vec![0u8; lines];
        let mut gap = vec![0u32; lines];
        sweep(dims, bx, axis, 1, |line, v| {
            let x = data[v];
            if x == GAS || x == BRIGHT {
                let near = gap[line] <= gap_max;
                if x == BRIGHT && last[line] == GAS && near {
                    counts[0] += 1;
                } else if x == GAS && last[line] == BRIGHT && near {
                    counts[1] += 1;
                }
                last[line] = x;
                gap[line] = 0;
            } else {
                gap[line] = gap[line].saturating_add(1);
            }
        });
    }
    out
}

/// Gravity from the levels: the axis direction with by far the most air-over-fluid
/// interfaces, as an LPS unit vector (None when no clear level is seen).
pub fn gravity_from_levels(work: &Volume<u8>, bx: &Bbox) -> Option<DVec3> {
    /// A level smaller than this (voxels of interface) is not evidence.
    const MIN_INTERFACE: usize = 40;
    let counts = level_counts(work, bx);
    let mut dirs: Vec<(usize, usize, i32)> = (0..3).flat_map(|a| [(counts[a][0], a, 1), (counts[a][1], a, -1)]).collect();
    dirs.sort_by(|x, y| y.0.cmp(&x.0).then(x.1.cmp(&y.1)).then(y.2.cmp(&x.2)));
    let (best, axis, sign) = dirs[0];
    let runner_up = dirs[1].0;
    if best < MIN_INTERFACE || best < 3 * runner_up {
        return None;
    }
    let col = PatientFrame::of(work.geometry()).lps(DVec3::from_array({
        let mut e = [0.0; 3];
        e[axis] = sign as f64;
        e
    }));
    Some(col.normalize())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;

    /// A box of gas over a pool (gravity +y), and beside it a bright "loop" with no gas above,
    /// and under the gas, behind a 4-voxel wall, another bright loop.
    fn scene() -> Volume<u8> {
        let g = Geometry::new([30, 30, 6], [1.0; 3], [0.0; 3]).unwrap();
        let mut v = Volume::filled(g, 0u8).unwrap();
        for k in 0..6 {
            for i in 2..12 {
                for j in 2..8 {
                    v.set(i, j, k, GAS);
                }
                // One layer voxel at j = 8, fluid from 9 to 13.
                for j in 9..14 {
                    v.set(i, j, k, BRIGHT);
                }
                // Wall 14..18, then a loop under it.
                for j in 18..24 {
                    v.set(i, j, k, BRIGHT);
                }
            }
            for i in 14..24 {
                for j in 9..14 {
                    v.set(i, j, k, BRIGHT);
                }
            }
        }
        v
    }

    #[test]
    fn fluid_under_the_gas_joins_and_loops_stay_out() {
        let mut v = scene();
        let bx = Bbox { lo: [0; 3], hi: [29, 29, 5] };
        let n = mark_pools(&mut v, &bx, DVec3::Y);
        assert_eq!(v.get(5, 8, 2), LAYER);
        assert_eq!(v.get(5, 11, 2), POOL);
        assert_eq!(v.get(5, 20, 2), BRIGHT, "a loop behind two walls");
        assert_eq!(v.get(18, 11, 2), BRIGHT, "a loop with no gas above");
        assert_eq!(n, 10 * 6 * 6);
        // Prone: gravity anterior, the fluid is above the gas: none joins.
        let mut w = scene();
        assert_eq!(mark_pools(&mut w, &bx, -DVec3::Y), 0);
    }

    #[test]
    fn gravity_is_read_from_the_level_in_any_storage_order() {
        let v = scene();
        let bx = Bbox { lo: [0; 3], hi: [29, 29, 5] };
        assert_eq!(gravity_from_levels(&v, &bx), Some(DVec3::Y));
        for (perm, flip) in [([1, 0, 2], [true, false, false]), ([2, 1, 0], [false, true, true])] {
            let r = v.reoriented(perm, flip).unwrap();
            let d = r.dims();
            let bx = Bbox { lo: [0; 3], hi: [d[0] - 1, d[1] - 1, d[2] - 1] };
            let g = gravity_from_levels(&r, &bx).unwrap();
            assert!((g - DVec3::Y).length() < 1e-9, "{perm:?} {flip:?}: {g}");
        }
    }
}
