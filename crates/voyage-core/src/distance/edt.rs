//! Ds: exact Euclidean distance transform with anisotropic spacing.
//!
//! Separable, one pass per axis (x, then y, then z), over the lumen's bounding box only; each
//! 1D transform is the lower envelope of parabolas (Felzenszwalb & Huttenlocher) over one run
//! of lumen between two walls, found by direct vector minimum for runs as short as a colon's
//! cross-sections and by the envelope's linear-time scan for longer ones. Values are squared
//! millimetres until the last pass.
//!
//! **What counts as wall.** Every voxel that is not lumen, and everything beyond the volume's
//! border: the scan does not say what lies outside its field of view, and the camera must not
//! fly there. Ds of a lumen voxel is the distance in mm from its centre to the centre of the
//! nearest non-lumen voxel (or to the first voxel centre beyond the border).
//!
//! **How it is made fast.** The first pass reads the mask directly; the others transform each
//! column only over its lumen span (runs up to 160 voxels by a direct AVX2 minimum over their
//! parabolas, longer ones by the envelope); the last pass gathers 16 columns at a time and
//! prefetches 16 slices ahead. Timings: BENCHMARKS.md.

use rayon::prelude::*;

use crate::{
    Error, Result, Volume,
    grid::{BoxGrid, Bricked, Field, bounding_box},
    volume::{next_run, runs_where},
};

/// Ds over the lumen's bounding box (grown by one voxel): distance in mm to the nearest wall
/// for lumen voxels (mask ≠ 0), 0 elsewhere.
pub fn distance_to_wall(mask: &Volume<u8>) -> Result<Field<f32>> {
    let grid = bounding_box(mask, 1, |v| v != 0)
        .ok_or_else(|| Error::invalid("the lumen mask is empty"))?;
    Ok(distance_to_wall_in(mask, grid))
}

/// [`distance_to_wall`] over a box the caller knows holds all the lumen and a voxel of wall
/// around it (or the volume's border): the mask is then read only inside it.
pub fn distance_to_wall_in(mask: &Volume<u8>, grid: BoxGrid) -> Field<f32> {
    distance_to_wall_reusing(mask, grid, Vec::new())
}

/// [`distance_to_wall_in`] written into `memory`, an earlier field's values over the same
/// box (a vector of another length is dropped): preprocessing computes Ds of one box eight
/// times or more, and on `ctc/prone-tagged` (55 M voxels) a fresh field's pages cost about as
/// much as its transform.
pub fn distance_to_wall_reusing(mask: &Volume<u8>, grid: BoxGrid, memory: Vec<f32>) -> Field<f32> {
    let sp = mask.spacing();
    let (mut f, span_y, span_z) = pass_x(mask, &grid, sp[0], memory);
    pass_y(&mut f, &grid, sp[1], &span_y);
    pass_z(&mut f, &grid, sp[2], &span_z);
    Field {
        grid,
        geometry: mask.geometry().clone(),
        data: f,
    }
}

/// Ds after the lumen voxels `walls` (volume indices) became wall: 0 there, and elsewhere the
/// nearer of the old distance and the distance to them, which is exact (the nearest wall is
/// an old one or a new one). Only voxels nearer a new wall than their old Ds can change, and
/// a new wall nearer a voxel than its old Ds lies in a cube of [`WALL_CUBE`] voxels whose
/// walls' box lies that near: each voxel is tested against the walls of such cubes alone. A
/// plug of a few hundred voxels costs milliseconds, where the transform of the whole box costs
/// a third of a second on `ctc/prone-tagged`; plugs far apart (both flexures of a 3 mm exam,
/// 12 000 voxels) do not make every voxel between them test every plug voxel.
pub fn add_walls(ds: &mut Bricked<f32>, walls: &[usize]) {
    if walls.is_empty() {
        return;
    }
    let g = ds.geometry.clone();
    let sp = g.spacing.map(|s| s as f32);
    let mut cubes: std::collections::BTreeMap<[usize; 3], Vec<[usize; 3]>> = Default::default();
    for &v in walls {
        let w = g.ijk(v);
        cubes.entry(w.map(|x| x / WALL_CUBE)).or_default().push(w);
    }
    let reach = ds.values().iter().fold(0.0f32, |m, &d| m.max(d));
    let (box_lo, box_dims) = (ds.grid.lo, ds.grid.dims);
    let steps = |a: usize| (reach / sp[a]).ceil() as usize;
    // Squared distance in the transform's order: x, then y, then z, in f32.
    let d2 = |v: [usize; 3], w: [usize; 3]| {
        let d = [0, 1, 2].map(|a| (v[a] as f32 - w[a] as f32) * sp[a]);
        d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    };
    // The nearest new wall of each voxel that one may be nearer than its old Ds, over the
    // cubes; then written, so that every test reads the old Ds.
    let mut nearer: std::collections::HashMap<[usize; 3], f32> = Default::default();
    for ijk in cubes.values() {
        let (mut lo, mut hi) = (ijk[0], ijk[0]);
        for w in ijk {
            for a in 0..3 {
                lo[a] = lo[a].min(w[a]);
                hi[a] = hi[a].max(w[a]);
            }
        }
        let from = [0, 1, 2].map(|a| lo[a].saturating_sub(steps(a)).max(box_lo[a]));
        let to = [0, 1, 2].map(|a| (hi[a] + steps(a)).min(box_lo[a] + box_dims[a] - 1));
        for k in from[2]..=to[2] {
            for j in from[1]..=to[1] {
                for i in from[0]..=to[0] {
                    let v = [i, j, k];
                    let old = ds.get(v);
                    if old <= 0.0 {
                        continue;
                    }
                    // Nearer the cube's walls' box than the old wall, or none of them can be
                    // nearer.
                    let gap = [0, 1, 2].map(|a| {
                        let below = lo[a].saturating_sub(v[a]);
                        let above = v[a].saturating_sub(hi[a]);
                        below.max(above) as f32 * sp[a]
                    });
                    if gap[0] * gap[0] + gap[1] * gap[1] + gap[2] * gap[2] >= old * old {
                        continue;
                    }
                    let near = ijk.iter().fold(f32::INFINITY, |m, &w| m.min(d2(v, w)));
                    if near < old * old {
                        let best = nearer.entry(v).or_insert(near);
                        *best = best.min(near);
                    }
                }
            }
        }
    }
    for w in cubes.values().flatten() {
        ds.set(*w, 0.0);
    }
    for (v, near) in nearer {
        if ds.get(v) > 0.0 {
            ds.set(v, near.sqrt());
        }
    }
}

/// The side (voxels) of the cubes [`add_walls`] groups new walls in.
const WALL_CUBE: usize = 16;

/// Scratch space for the 1D transforms: the envelope's parabolas and a column.
struct Scratch {
    sites: Vec<Site>,
    col: Vec<f32>,
    /// Positions and results of [`direct_envelope`].
    pos: Vec<f32>,
    out: Vec<f32>,
}

/// One parabola of the lower envelope: its site's position `v` and value `f`, and `z`, where
/// it starts to be the lowest (one record, so that a step of the envelope is one load).
#[derive(Clone, Copy, Default)]
struct Site {
    v: f32,
    f: f32,
    z: f32,
}

impl Scratch {
    fn new(n: usize) -> Self {
        Scratch {
            sites: vec![Site::default(); n + 3],
            col: vec![0.0; n],
            pos: vec![0.0; n + 8],
            out: vec![0.0; n + 8],
        }
    }
}

/// Squared distance transform of one column, in place, run by run.
///
/// A wall entry (0) stays 0 in every pass, and for an entry between two walls no parabola
/// beyond either wall can win: it is farther away and no lower than the wall's own. So each
/// run of non-zero entries is transformed on its own, between its two walls (the volume's
/// border counting as wall), and the work is proportional to the lumen, not to the box.
fn transform_column(col: &mut [f32], h: f32, s: &mut Scratch) {
    // Each run is looked up after the one before is transformed: a transform keeps its run
    // non-zero and the walls 0, so the runs are those of the input.
    let mut q = 0;
    while let Some(run) = next_run(col, q, |x| x != 0.0) {
        q = run.end;
        let run = &mut col[run];
        if run.len() <= DIRECT_MAX {
            direct_envelope(run, h, s);
        } else {
            lower_envelope(run, h, s);
        }
    }
}

/// Runs up to this long take the direct minimum over their sites, longer ones the envelope.
/// The envelope is linear in the run's length but a chain of dependent divisions and
/// unpredictable branches; the direct minimum is quadratic but branch-free and vectorizes:
/// it is the faster one for the cross-sections of a colon (runs of 30–60 voxels).
const DIRECT_MAX: usize = 160;

/// The lower envelope by brute force: each entry becomes the least of its walls' parabolas and
/// those of every site of the run, with the same positions and the same arithmetic as
/// [`lower_envelope`] (so where both pick the same site the result is the same bits).
fn direct_envelope(run: &mut [f32], h: f32, s: &mut Scratch) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2() {
        // SAFETY: the CPU has AVX2 (checked just now).
        return unsafe { direct_envelope_avx2(run, h, s) };
    }
    direct_envelope_body(run, h, s)
}

/// [`direct_envelope_body`] with each group of up to 32 entries held in four AVX registers
/// across the whole loop over the sites.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn direct_envelope_avx2(run: &mut [f32], h: f32, s: &mut Scratch) {
    let n = run.len();
    let m = n.next_multiple_of(8);
    let (pos, out) = (&mut s.pos[..m], &mut s.out[..m]);
    fill_walls(pos, out, n, h);
    let sites = (&pos[..n], &*run);
    let mut q = 0;
    while q < m {
        // SAFETY: AVX2 is enabled here; each group lies within `pos` and `out` (length m).
        q += unsafe {
            match (m - q) / 8 {
                1 => crate::simd::min_parabolas_avx2::<1>(sites, &pos[q..], &mut out[q..]),
                2 => crate::simd::min_parabolas_avx2::<2>(sites, &pos[q..], &mut out[q..]),
                3 => crate::simd::min_parabolas_avx2::<3>(sites, &pos[q..], &mut out[q..]),
                _ => crate::simd::min_parabolas_avx2::<4>(sites, &pos[q..], &mut out[q..]),
            }
        };
    }
    run.copy_from_slice(&out[..n]);
}

/// Positions `q·h` and the walls' parabolas (the nearer wall, at −h or n·h), for all of
/// `pos` and `out` (which may run past the n entries of the run).
#[inline(always)]
fn fill_walls(pos: &mut [f32], out: &mut [f32], n: usize, h: f32) {
    let (before, after) = (-h, n as f32 * h);
    for (q, (p, o)) in pos.iter_mut().zip(out.iter_mut()).enumerate() {
        *p = q as f32 * h;
        let (a, b) = (*p - before, *p - after);
        *o = (a * a).min(b * b);
    }
}

fn direct_envelope_body(run: &mut [f32], h: f32, s: &mut Scratch) {
    let n = run.len();
    let (pos, out) = (&mut s.pos[..n], &mut s.out[..n]);
    fill_walls(pos, out, n, h);
    for (&pt, &ft) in pos.iter().zip(run.iter()) {
        for (&pq, o) in pos.iter().zip(out.iter_mut()) {
            let d = pq - pt;
            *o = (d * d + ft).min(*o);
        }
    }
    run.copy_from_slice(out);
}

/// Felzenszwalb–Huttenlocher on one run with a wall (value 0) just before and just after it;
/// positions are relative to the run, in mm, so that squares stay small and f32 suffices.
fn lower_envelope(run: &mut [f32], h: f32, s: &mut Scratch) {
    let n = run.len();
    let sites = &mut s.sites[..n + 3];
    // Site 0 is the wall before the run, at position −h.
    sites[0] = Site {
        v: -h,
        f: 0.0,
        z: f32::NEG_INFINITY,
    };
    sites[1].z = f32::INFINITY;
    let mut k = 0usize;
    let mut push = |pq: f32, fq: f32, k: &mut usize| {
        let mut sct;
        loop {
            let sk = sites[*k];
            // z[0] = −∞: the first (wall) parabola is never dropped.
            sct = ((fq + pq * pq) - (sk.f + sk.v * sk.v)) / (2.0 * (pq - sk.v));
            if sct > sk.z {
                break;
            }
            *k -= 1;
        }
        *k += 1;
        sites[*k] = Site {
            v: pq,
            f: fq,
            z: sct,
        };
        sites[*k + 1].z = f32::INFINITY;
    };
    for (q, &fq) in run.iter().enumerate() {
        if fq.is_finite() {
            push(q as f32 * h, fq, &mut k);
        }
    }
    push(n as f32 * h, 0.0, &mut k);
    let mut k = 0usize;
    for (q, out) in run.iter_mut().enumerate() {
        let pq = q as f32 * h;
        while sites[k + 1].z < pq {
            k += 1;
        }
        let d = pq - sites[k].v;
        *out = d * d + sites[k].f;
    }
}

/// The first and last lumen voxel of a column (inclusive); `EMPTY` for a column of walls.
/// Beyond them the column is wall, so transforming just the span gives the same values: its
/// ends border walls (or the box's border, which counts as wall), and a column of walls is its
/// own transform and need not even be read.
#[derive(Clone, Copy)]
struct Span {
    lo: u16,
    hi: u16,
}

const EMPTY: Span = Span {
    lo: u16::MAX,
    hi: 0,
};

impl Span {
    fn add(&mut self, at: usize) {
        self.lo = self.lo.min(at as u16);
        self.hi = self.hi.max(at as u16);
    }
    fn range(self) -> Option<std::ops::RangeInclusive<usize>> {
        (self.lo <= self.hi).then_some(self.lo as usize..=self.hi as usize)
    }
}

/// First pass, along x, straight from the mask: the input is only walls and lumen, so the
/// squared distance to the nearer end of each run is all there is to it. Also finds each
/// column's lumen span: along y, indexed i + nx·k; along z, indexed i + nx·j.
/// `memory`, when it has the box's length, is written over (its walls zeroed row by row, in
/// cache); otherwise a fresh field is taken.
fn pass_x(
    mask: &Volume<u8>,
    grid: &BoxGrid,
    h: f64,
    memory: Vec<f32>,
) -> (Vec<f32>, Vec<Span>, Vec<Span>) {
    let [nx, ny, nz] = grid.dims;
    let h = h as f32;
    let g = mask.geometry();
    let dirty = memory.len() == grid.len();
    let mut f = if dirty {
        memory
    } else {
        drop(memory);
        // Room for the Dt searches, which work in this memory after it (prep).
        crate::mem::filled_with_room(
            grid.len(),
            crate::grid::Padded::shape(grid).search_len(),
            0.0f32,
        )
    };
    let runs: Vec<Vec<(u32, u32, u32)>> = f
        .par_chunks_mut(nx * ny)
        .enumerate()
        .map(|(k, slab)| {
            // (j, start, end) of each run of lumen in this slice.
            let mut runs = Vec::new();
            for (j, row) in slab.chunks_mut(nx).enumerate() {
                if dirty {
                    row.fill(0.0);
                }
                let src = &mask.data()[g.index(grid.lo[0], grid.lo[1] + j, grid.lo[2] + k)..][..nx];
                for run in runs_where(src, |m| m != 0) {
                    let len = run.len();
                    for (t, x) in row[run.clone()].iter_mut().enumerate() {
                        let d = (t + 1).min(len - t) as f32 * h;
                        *x = d * d;
                    }
                    runs.push((j as u32, run.start as u32, run.end as u32));
                }
            }
            runs
        })
        .collect();
    let mut span_y = vec![EMPTY; nx * nz];
    let mut span_z = vec![EMPTY; nx * ny];
    for (k, slice) in runs.iter().enumerate() {
        for &(j, a, b) in slice {
            let (j, a, b) = (j as usize, a as usize, b as usize);
            span_y[nx * k + a..nx * k + b]
                .iter_mut()
                .for_each(|s| s.add(j));
            span_z[nx * j + a..nx * j + b]
                .iter_mut()
                .for_each(|s| s.add(k));
        }
    }
    (f, span_y, span_z)
}

/// Second pass, along y: each z-slab is independent and fits in cache.
fn pass_y(f: &mut [f32], grid: &BoxGrid, h: f64, spans: &[Span]) {
    let [nx, ny, _] = grid.dims;
    let h = h as f32;
    f.par_chunks_mut(nx * ny).enumerate().for_each_init(
        || Scratch::new(ny),
        |s, (k, slab)| {
            for i in 0..nx {
                let Some(range) = spans[i + nx * k].range() else {
                    continue;
                };
                let (lo, n) = (*range.start(), range.end() - range.start() + 1);
                for (t, j) in range.clone().enumerate() {
                    s.col[t] = slab[i + nx * j];
                }
                let mut col = std::mem::take(&mut s.col);
                transform_column(&mut col[..n], h, s);
                for t in 0..n {
                    slab[i + nx * (lo + t)] = col[t];
                }
                s.col = col;
            }
        },
    );
}

/// How many slices ahead the last pass's gather asks for its rows.
const GATHER_AHEAD: usize = 16;

/// Columns gathered together in the last pass: a cache line of each z-slice per load.
const TILE: usize = 16;

/// Third pass, along z, ending in millimetres (the square root). Columns are strided by a whole
/// slab, so each task takes one y-row of columns, gathered `TILE` at a time (a piece of a row
/// from each slice, not one float per slice per column); the rows of different tasks never
/// overlap.
fn pass_z(f: &mut [f32], grid: &BoxGrid, h: f64, spans: &[Span]) {
    let [nx, ny, nz] = grid.dims;
    let h = h as f32;
    let plane = nx * ny;
    let shared = SharedSlice::new(f);
    (0..ny).into_par_iter().for_each_init(
        || (Scratch::new(nz), vec![0.0f32; TILE * nz]),
        |(s, tile), j| {
            for i0 in (0..nx).step_by(TILE) {
                let w = TILE.min(nx - i0);
                let base = i0 + nx * j;
                let cols = &spans[base..base + w];
                let (lo, hi) = cols.iter().fold((usize::MAX, 0), |(lo, hi), c| {
                    (lo.min(c.lo as usize), hi.max(c.hi as usize))
                });
                if lo > hi {
                    continue;
                }
                for k in lo..=hi {
                    // Slices are a slab apart, too far for the hardware to guess the next.
                    shared.prefetch(base + plane * (k + GATHER_AHEAD));
                    for t in 0..w {
                        // SAFETY: task j reads and writes only indices with this j, which no
                        // other task touches; base + t + plane·k < nx·ny·nz = len.
                        tile[k * TILE + t] = unsafe { shared.get(base + t + plane * k) };
                    }
                }
                for (t, c) in cols.iter().enumerate() {
                    let Some(range) = c.range() else { continue };
                    let (a, n) = (*range.start(), range.end() - range.start() + 1);
                    for q in 0..n {
                        s.col[q] = tile[(a + q) * TILE + t];
                    }
                    let mut col = std::mem::take(&mut s.col);
                    transform_column(&mut col[..n], h, s);
                    for q in 0..n {
                        tile[(a + q) * TILE + t] = col[q].sqrt();
                    }
                    s.col = col;
                }
                for k in lo..=hi {
                    for t in 0..w {
                        unsafe { shared.set(base + t + plane * k, tile[k * TILE + t]) };
                    }
                }
            }
        },
    );
}

/// A slice that parallel tasks write at disjoint indices.
struct SharedSlice<T> {
    ptr: *mut T,
    len: usize,
}
unsafe impl<T: Send> Sync for SharedSlice<T> {}
unsafe impl<T: Send> Send for SharedSlice<T> {}

impl<T: Copy> SharedSlice<T> {
    fn new(s: &mut [T]) -> Self {
        SharedSlice {
            ptr: s.as_mut_ptr(),
            len: s.len(),
        }
    }
    /// SAFETY: `i < len`, and no other task writes index `i` concurrently.
    unsafe fn get(&self, i: usize) -> T {
        debug_assert!(i < self.len);
        unsafe { *self.ptr.add(i) }
    }
    /// Asks the cache for index `i` (any `i`: nothing is read).
    fn prefetch(&self, i: usize) {
        crate::mem::prefetch_address(self.ptr.wrapping_add(i));
    }
    /// SAFETY: `i < len`, and no other task reads or writes index `i` concurrently.
    unsafe fn set(&self, i: usize, v: T) {
        debug_assert!(i < self.len);
        unsafe { *self.ptr.add(i) = v }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;

    /// Brute force: nearest wall voxel centre, the border counting as wall one voxel out.
    fn brute(mask: &Volume<u8>) -> Vec<f64> {
        let [nx, ny, nz] = mask.dims();
        let s = mask.spacing();
        let g = mask.geometry();
        let mut walls = Vec::new();
        for k in -1..=nz as i64 {
            for j in -1..=ny as i64 {
                for i in -1..=nx as i64 {
                    let inside = i >= 0
                        && j >= 0
                        && k >= 0
                        && i < nx as i64
                        && j < ny as i64
                        && k < nz as i64;
                    if !inside || mask.get(i as usize, j as usize, k as usize) == 0 {
                        walls.push([i as f64 * s[0], j as f64 * s[1], k as f64 * s[2]]);
                    }
                }
            }
        }
        (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                if mask.data()[idx] == 0 {
                    return 0.0;
                }
                let p = [i as f64 * s[0], j as f64 * s[1], k as f64 * s[2]];
                walls
                    .iter()
                    .map(|w| {
                        ((p[0] - w[0]).powi(2) + (p[1] - w[1]).powi(2) + (p[2] - w[2]).powi(2))
                            .sqrt()
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    fn random_mask(dims: [usize; 3], spacing: [f64; 3], seed: u64, fill: f64) -> Volume<u8> {
        let g = Geometry::new(dims, spacing, [0.0; 3]).unwrap();
        let mut rng = crate::rng::Rng::new(seed, 0);
        let data = (0..g.len())
            .map(|_| ((rng.next_u64() % 1000) as f64 / 1000.0 < fill) as u8)
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    #[test]
    fn matches_brute_force_anisotropic() {
        for (seed, fill) in [(1, 0.9), (2, 0.97), (3, 0.6), (4, 1.0)] {
            let m = random_mask([13, 11, 9], [0.82, 0.7, 1.25], seed, fill);
            let ds = crate::grid::Bricked::from_field(&distance_to_wall(&m).unwrap(), 0.0)
                .to_volume()
                .unwrap();
            let want = brute(&m);
            for (idx, (&got, &w)) in ds.data().iter().zip(&want).enumerate() {
                assert!(
                    (got as f64 - w).abs() < 1e-4,
                    "seed {seed} voxel {idx}: {got} vs {w}"
                );
            }
        }
    }

    /// Walls added to a lumen (a plug): Ds updated in place equals Ds of the new lumen made
    /// afresh, and only the voxels near the plug change.
    #[test]
    fn walls_added_give_the_ds_made_afresh() {
        for (seed, fill) in [(5, 0.97), (6, 1.0)] {
            let mut m = random_mask([30, 24, 20], [0.75, 0.75, 1.0], seed, fill);
            let grid = BoxGrid::around([[0; 3], [29, 23, 19]], 0, m.dims());
            let mut ds = Bricked::from_field(&distance_to_wall_in(&m, grid.clone()), 0.0);
            let g = m.geometry().clone();
            let plug: Vec<usize> = (0..g.len())
                .filter(|&v| {
                    let [i, j, k] = g.ijk(v);
                    // Two plugs apart, the second across cubes of `WALL_CUBE`.
                    let first = (12..15).contains(&i) && (8..16).contains(&j) && k == 9;
                    let second = (14..19).contains(&i) && j == 20 && (3..6).contains(&k);
                    m.data()[v] != 0 && (first || second)
                })
                .collect();
            assert!(plug.len() > 10);
            plug.iter().for_each(|&v| m.data_mut()[v] = 0);
            let before = ds.clone();
            add_walls(&mut ds, &plug);
            let fresh = distance_to_wall_in(&m, grid);
            let mut changed = 0;
            for v in 0..g.len() {
                let ijk = g.ijk(v);
                let want = fresh.get_global(ijk, 0.0);
                assert!(
                    (ds.get(ijk) - want).abs() <= 1e-5,
                    "seed {seed} voxel {ijk:?}"
                );
                changed += (ds.get(ijk) != before.get(ijk)) as usize;
            }
            assert!(changed >= plug.len(), "{changed} changed");
        }
    }

    /// Runs longer than [`DIRECT_MAX`] take the envelope: a long thin mask, brute-forced.
    #[test]
    fn long_runs_match_brute_force() {
        for (seed, fill) in [(5, 0.995), (6, 1.0)] {
            let m = random_mask([4, DIRECT_MAX + 40, 5], [0.82, 0.7, 1.25], seed, fill);
            let ds = crate::grid::Bricked::from_field(&distance_to_wall(&m).unwrap(), 0.0)
                .to_volume()
                .unwrap();
            for (idx, (&got, &w)) in ds.data().iter().zip(&brute(&m)).enumerate() {
                assert!(
                    (got as f64 - w).abs() < 1e-4,
                    "seed {seed} voxel {idx}: {got} vs {w}"
                );
            }
        }
    }

    /// The direct minimum (vector and scalar) and the envelope agree on random runs of every
    /// length up to past [`DIRECT_MAX`], with squared distances as the passes leave them.
    #[test]
    fn direct_minimum_equals_the_envelope() {
        let mut rng = crate::rng::Rng::new(0x9E37_79B9_7F4A_7C15, 0);
        let mut next = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let mut s = Scratch::new(DIRECT_MAX + 64);
        for n in 1..DIRECT_MAX + 40 {
            let h = 0.5 + next();
            let run: Vec<f32> = (0..n).map(|_| (next() * 12.0).powi(2)).collect();
            let mut envelope = run.clone();
            lower_envelope(&mut envelope, h, &mut s);
            let mut scalar = run.clone();
            direct_envelope_body(&mut scalar, h, &mut s);
            let mut direct = run.clone();
            direct_envelope(&mut direct, h, &mut s);
            for q in 0..n {
                let tol = 1e-5 * envelope[q].max(1.0);
                assert!(
                    (scalar[q] - envelope[q]).abs() <= tol,
                    "n {n} q {q}: {} vs {}",
                    scalar[q],
                    envelope[q]
                );
                assert_eq!(direct[q].to_bits(), scalar[q].to_bits(), "n {n} q {q}");
            }
        }
    }

    #[test]
    fn ball_centre_distance_is_radius() {
        let g = Geometry::new([41, 41, 33], [0.5, 0.5, 0.8], [0.0; 3]).unwrap();
        let c = [10.0, 10.0, 12.8];
        let r = 7.0;
        let data = (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                let p = [i as f64 * 0.5, j as f64 * 0.5, k as f64 * 0.8];
                (((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt() < r)
                    as u8
            })
            .collect();
        let m = Volume::from_vec(g, data).unwrap();
        let ds = distance_to_wall(&m).unwrap();
        let centre = ds.get_global([20, 20, 16], -1.0);
        assert!((centre as f64 - r).abs() < 0.5, "centre Ds {centre}");
    }

    #[test]
    fn empty_mask_is_an_error() {
        let g = Geometry::new([4, 4, 4], [1.0; 3], [0.0; 3]).unwrap();
        assert!(distance_to_wall(&Volume::filled(g, 0u8).unwrap()).is_err());
    }
}
