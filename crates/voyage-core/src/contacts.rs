//! Touching loops. Where two loops of the colon lie against each other, the wall between them
//! is often thinner than a voxel, and the lumen mask joins them. A shortest path through the
//! lumen then cuts across, and Dt — the paper's pull toward the target — leads the submarine
//! from one loop into the other, skipping the colon in between (on the shared colon-a mask,
//! Dt's shortest path is a third of the centerline).
//!
//! The skeleton's path (the raw centerline) knows the colon's order. Every lumen voxel takes
//! the arc length of the path point it is geodesically nearest to (a multi-source search from
//! the path). Two neighbouring voxels whose arc lengths differ by more than
//! `arc_ratio` × the straight distance between their path points (and by at least
//! `min_arc_mm`) sit on a contact between loops: along one loop arc and straight distance
//! are alike (a hairpin bend gives π/2), across a contact the arc is many times longer. Both
//! voxels are taken out of the lumen, which puts a two-voxel wall where the scan could not show
//! one: Dt follows the colon, the surface closes over the contact (no view into the next
//! loop), and the cells stay a chain.
//!
//! The search runs on blocks ([`crate::grid::Blocks`]): the skeleton's 2×2×2 blocks on a large lumen
//! (an eighth of the voxels; the search and the scan of neighbour pairs cost 2.6 s on the
//! voxels of colon-a), single voxels on a small one. Each block takes one label (a partial
//! block, the label of the nearest labelled block); every pair of neighbouring lumen voxels in
//! blocks of far-apart labels is cut, one voxel on each side of the block face, so no such
//! pair is left, as with single voxels. It runs before Ds, which then sees the new walls.

use glam::DVec3;

use crate::{
    Volume,
    grid::{Blocks, BoxGrid, BoxIndex, PadIndex, Padded},
};

#[derive(Clone, Debug)]
pub struct ContactOptions {
    pub enabled: bool,
    pub arc_ratio: f64,
    pub min_arc_mm: f64,
}

impl Default for ContactOptions {
    fn default() -> Self {
        ContactOptions {
            enabled: true,
            arc_ratio: 3.0,
            min_arc_mm: 50.0,
        }
    }
}

const NO_LABEL: u16 = u16::MAX;

/// Takes the contact voxels out of the lumen mask (none within `keep_mm` of the points
/// `keep`, volume-local mm); returns the volume indices taken, so that a caller can put them
/// back. `path_mm` is the colon's path from source to target; `blocks`, when given, the
/// blocks of `grid` to search on (else single voxels).
pub fn cut_contacts(
    lumen: &mut Volume<u8>,
    grid: &BoxGrid,
    path_mm: &[DVec3],
    blocks: Option<&Blocks>,
    keep: &[DVec3],
    keep_mm: f64,
    opts: &ContactOptions,
) -> crate::Result<Vec<usize>> {
    if !opts.enabled || path_mm.len() < 2 {
        return Ok(Vec::new());
    }
    let own;
    let blocks = match blocks {
        Some(b) => b,
        None => {
            own = Blocks::new(lumen, grid, 1)?;
            &own
        }
    };
    let (points, arcs) = label_points(path_mm);
    let far = |a: u16, b: u16| {
        let (a, b) = (a as usize, b as usize);
        let arc = (arcs[a] - arcs[b]).abs();
        arc > opts.min_arc_mm && arc > opts.arc_ratio * points[a].distance(points[b])
    };
    let pad = padded_blocks(blocks);
    let labels = label_blocks(&pad, blocks, &points);
    let contact = contact_blocks(&pad, &labels, &far);
    let mut cut = Vec::new();
    let dims = lumen.dims();
    let g = lumen.geometry().clone();
    for (pi, _) in contact.iter().enumerate().filter(|(_, c)| **c) {
        let a = labels[pi];
        for u in blocks.voxels(pad.global_of_index(PadIndex(pi)), dims) {
            if lumen.get(u[0], u[1], u[2]) == 0 {
                continue;
            }
            for v in neighbour_voxels(u, dims) {
                if lumen.get(v[0], v[1], v[2]) == 0 {
                    continue;
                }
                let Some(b) = blocks
                    .block_of_voxel(v)
                    .and_then(|c| pad.index_of_global(c))
                    .map(|q| labels[q.0])
                else {
                    continue;
                };
                if b != NO_LABEL && b != a && far(a, b) {
                    cut.push(g.index(u[0], u[1], u[2]));
                    cut.push(g.index(v[0], v[1], v[2]));
                }
            }
        }
    }
    cut.sort_unstable();
    cut.dedup();
    let kept = |v: usize| {
        let p = g.index_to_local(DVec3::from_array(g.ijk(v).map(|x| x as f64)));
        keep.iter().any(|k| k.distance(p) <= keep_mm)
    };
    cut.retain(|&v| !kept(v));
    for &v in &cut {
        lumen.data_mut()[v] = 0;
    }
    Ok(cut)
}

/// Path points (at most `NO_LABEL` of them, thinned evenly) and their arc lengths.
fn label_points(path: &[DVec3]) -> (Vec<DVec3>, Vec<f64>) {
    let arc = crate::centerline::arc_lengths(path);
    let stride = path.len().div_ceil(NO_LABEL as usize - 1).max(1);
    let idx: Vec<usize> = (0..path.len()).step_by(stride).collect();
    (
        idx.iter().map(|&i| path[i]).collect(),
        idx.iter().map(|&i| arc[i]).collect(),
    )
}

/// The full blocks with a layer of empty blocks around, for the search, and which blocks are
/// partial, in the same layout.
struct PaddedBlocks {
    pad: Padded,
    /// 1 for a partial block, 0 else; three spare 0s at the end for [`partial_around`]'s
    /// four-byte loads.
    partial: Vec<u8>,
}

impl std::ops::Deref for PaddedBlocks {
    type Target = Padded;
    fn deref(&self) -> &Padded {
        &self.pad
    }
}

fn padded_blocks(blocks: &Blocks) -> PaddedBlocks {
    let dims = blocks.dims();
    let grid = BoxGrid { lo: [0; 3], dims };
    let pad = Padded::new(&blocks.mask, &grid);
    let full = (blocks.factor.pow(3)) as u8;
    let mut partial = vec![0u8; pad.inside.len() + 3];
    for (b, &c) in blocks.count.iter().enumerate() {
        if c > 0 && c < full {
            let q = grid.global_of_index(BoxIndex(b));
            if let Some(i) = pad.index_of_global(q) {
                partial[i.0] = 1;
            }
        }
    }
    PaddedBlocks { pad, partial }
}

/// Per padded block, the label of the geodesically nearest path point (through full blocks);
/// partial blocks take the label of the nearest labelled block by steps (breadth first from
/// all labelled blocks at once). NO_LABEL for empty blocks and blocks not reached.
fn label_blocks(pad: &PaddedBlocks, blocks: &Blocks, points: &[DVec3]) -> Vec<u16> {
    let mut labels = vec![NO_LABEL; pad.inside.len()];
    let mut sources = Vec::with_capacity(points.len());
    for (l, p) in points.iter().enumerate() {
        if let Some(i) = blocks
            .block_of_mm(*p)
            .and_then(|c| pad.index_of_global(c))
            .filter(|&i| pad.inside[i.0] != 0)
            && labels[i.0] == NO_LABEL
        {
            labels[i.0] = l as u16;
            sources.push(i);
        }
    }
    let spacing = blocks.mask.spacing();
    let search = pad.search(spacing).tree().from(&sources);
    for &u in &search.order {
        let u = u as usize;
        if let Some(p) = search.parent_of(u) {
            labels[u] = labels[p];
        }
    }
    let rows = pad.neighbour_row_starts();
    let mut frontier: Vec<usize> = search
        .order
        .iter()
        .map(|&u| u as usize)
        .filter(|&u| partial_around(&pad.partial, u, &rows) != 0)
        .collect();
    while !frontier.is_empty() {
        let mut next = Vec::new();
        for &u in &frontier {
            // The partial neighbours in the order of the search's 26 (z, then y, then x); the
            // block itself is labelled, so never taken.
            let mut around = partial_around(&pad.partial, u, &rows);
            while around != 0 {
                let bit = around.trailing_zeros() as usize;
                around &= around - 1;
                let v = (u as isize + rows[bit / 3]) as usize + bit % 3;
                if labels[v] == NO_LABEL {
                    labels[v] = labels[u];
                    next.push(v);
                }
            }
        }
        frontier = next;
    }
    labels
}

/// Which of the 27 blocks around padded index `u` (itself included) are partial: bit
/// 3·row + lane, rows as [`Padded::neighbour_row_starts`]. Each row of three is one
/// four-byte load: nine loads instead of 26 tests.
#[inline]
fn partial_around(partial: &[u8], u: usize, rows: &[isize; 9]) -> u32 {
    rows.iter().enumerate().fold(0u32, |acc, (r, &start)| {
        let at = (u as isize + start) as usize;
        let word: [u8; 4] = partial[at..at + 4].try_into().expect("a slice of four");
        // Bytes of 0 or 1: byte i's low bit to bit i.
        let w = u32::from_le_bytes(word);
        acc | ((w & 1) | ((w >> 7) & 2) | ((w >> 14) & 4)) << (3 * r)
    })
}

/// Blocks with a 26-neighbour whose label is far along the path from theirs.
fn contact_blocks(pad: &Padded, labels: &[u16], far: &dyn Fn(u16, u16) -> bool) -> Vec<bool> {
    let half: Vec<isize> = pad
        .neighbours([1.0; 3])
        .iter()
        .map(|n| n.0)
        .filter(|&o| o > 0)
        .collect();
    let mut contact = vec![false; labels.len()];
    for u in 0..labels.len() {
        let a = labels[u];
        if a == NO_LABEL {
            continue;
        }
        for &off in &half {
            let v = (u as isize + off) as usize;
            let b = labels[v];
            if b != NO_LABEL && a != b && far(a, b) {
                contact[u] = true;
                contact[v] = true;
            }
        }
    }
    contact
}

/// The 26 neighbours of voxel `u` inside a volume of `dims`.
fn neighbour_voxels(u: [usize; 3], dims: [usize; 3]) -> impl Iterator<Item = [usize; 3]> {
    (0..27).filter(|&o| o != 13).filter_map(move |o| {
        let d = [o % 3, (o / 3) % 3, o / 9];
        let v = [0, 1, 2].map(|a| (u[a] + d[a]).checked_sub(1));
        let v = [v[0]?, v[1]?, v[2]?];
        v.iter().zip(dims).all(|(&x, n)| x < n).then_some(v)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bits of `partial_around` are the 27 blocks around, in the order of the search's
    /// neighbour offsets with the block itself at bit 13.
    #[test]
    fn partial_around_reads_the_27_blocks_in_order() {
        let pad = Padded::shape(&BoxGrid {
            lo: [0; 3],
            dims: [7, 6, 5],
        });
        let n = pad.dims.iter().product::<usize>();
        let mut rng = crate::rng::Rng::new(11, 2);
        let mut partial: Vec<u8> = (0..n).map(|_| (rng.range(0.0, 1.0) < 0.3) as u8).collect();
        partial.extend([0; 3]);
        let rows = pad.neighbour_row_starts();
        let offsets: Vec<isize> = pad.neighbours([1.0; 3]).iter().map(|o| o.0).collect();
        let [nx, ny, nz] = pad.dims;
        for k in 1..nz - 1 {
            for j in 1..ny - 1 {
                for i in 1..nx - 1 {
                    let u = i + nx * (j + ny * k);
                    let mut want = 0u32;
                    for (c, &o) in offsets.iter().enumerate() {
                        let bit = if c < 13 { c } else { c + 1 };
                        want |= (partial[(u as isize + o) as usize] as u32) << bit;
                    }
                    want |= (partial[u] as u32) << 13;
                    assert_eq!(partial_around(&partial, u, &rows), want, "block {u}");
                }
            }
        }
    }
}
