//! Fields restricted to a box of the volume: the distance fields and the potential live only
//! around the lumen, so they are stored over the lumen's bounding box (plus a margin), not over
//! the whole CT — a 512×512×400 scan would otherwise cost 400 MB per f32 field.

use crate::{Geometry, Result, Volume};

/// A flat index into a [`BoxGrid`] (a [`Field`]'s data), never a volume's flat index or a
/// padded one ([`crate::PadIndex`]): [`BoxGrid::index_of_global`] and
/// [`BoxGrid::global_of_index`] convert.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BoxIndex(pub usize);

/// An index into a [`Bricked`] field's stored values ([`Bricked::values`]), brick by brick:
/// [`Bricked::index_of_box`] and [`Bricked::box_voxel`] convert.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BrickIndex(pub usize);

/// An axis-aligned box of voxels inside a volume: `lo` is its first voxel, `dims` its size.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BoxGrid {
    pub lo: [usize; 3],
    pub dims: [usize; 3],
}

impl BoxGrid {
    /// The box from voxel `extent[0]` to voxel `extent[1]` (both inside), grown by `margin`
    /// voxels on every side as far as the volume (of `dims`) reaches.
    pub fn around(extent: [[usize; 3]; 2], margin: usize, dims: [usize; 3]) -> BoxGrid {
        let [lo, hi] = extent;
        let lo_m = [0, 1, 2].map(|a| lo[a].saturating_sub(margin));
        let hi_m = [0, 1, 2].map(|a| (hi[a] + margin).min(dims[a] - 1));
        BoxGrid {
            lo: lo_m,
            dims: [0, 1, 2].map(|a| hi_m[a] - lo_m[a] + 1),
        }
    }
    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Index inside the box of box-local voxel (i, j, k).
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> BoxIndex {
        BoxIndex(crate::volume::grid_index(self.dims, i, j, k))
    }
    /// Box-local (i, j, k) of a box index.
    #[inline]
    pub fn ijk(&self, index: BoxIndex) -> [usize; 3] {
        crate::volume::grid_ijk(self.dims, index.0)
    }
    /// Box index of a volume voxel, or None when it lies outside the box.
    #[inline]
    pub fn index_of_global(&self, g: [usize; 3]) -> Option<BoxIndex> {
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
    pub fn global_of_index(&self, index: BoxIndex) -> [usize; 3] {
        let [i, j, k] = self.ijk(index);
        [i + self.lo[0], j + self.lo[1], k + self.lo[2]]
    }
}

/// The bounding box of the voxels where `pred` holds, grown by `margin` voxels and clipped to
/// the volume. None when no voxel matches.
pub fn bounding_box<T: Copy>(
    vol: &Volume<T>,
    margin: usize,
    pred: impl Fn(T) -> bool,
) -> Option<BoxGrid> {
    let [nx, ny, nz] = vol.dims();
    let mut lo = [usize::MAX; 3];
    let mut hi = [0usize; 3];
    for k in 0..nz {
        let slice = vol.slice_k(k);
        for j in 0..ny {
            let Some((first, last)) = first_and_last(&slice[j * nx..(j + 1) * nx], &pred) else {
                continue;
            };
            lo = [lo[0].min(first), lo[1].min(j), lo[2].min(k)];
            hi = [hi[0].max(last), hi[1].max(j), hi[2].max(k)];
        }
    }
    if lo[0] == usize::MAX {
        return None;
    }
    Some(BoxGrid::around([lo, hi], margin, vol.dims()))
}

/// The first and last positions in `row` where `pred` holds. Most rows of a scan hold no
/// lumen: they are tested 32 values at a time without an early exit, which compiles to vector
/// code (a byte at a time, the lumen's box of a 512×512×400 scan took 70 ms).
pub(crate) fn first_and_last<T: Copy>(
    row: &[T],
    pred: &impl Fn(T) -> bool,
) -> Option<(usize, usize)> {
    const W: usize = 32;
    let hit = |c: &[T]| c.iter().fold(false, |a, &v| a | pred(v));
    let first_chunk = row.chunks(W).position(hit)?;
    let last_chunk = row.chunks(W).rposition(hit).unwrap_or(first_chunk);
    let first = first_chunk * W + row[first_chunk * W..].iter().position(|&v| pred(v))?;
    let end = (last_chunk * W + W).min(row.len());
    let last = row[..end].iter().rposition(|&v| pred(v)).unwrap_or(first);
    Some((first, last))
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
        Field {
            grid,
            geometry,
            data: vec![v; n],
        }
    }
    /// Value at a volume voxel; `outside` when the voxel is not in the box.
    #[inline]
    pub fn get_global(&self, g: [usize; 3], outside: T) -> T {
        self.grid.index_of_global(g).map_or(outside, |i| self[i])
    }
}

impl<T> std::ops::Index<BoxIndex> for Field<T> {
    type Output = T;
    #[inline]
    fn index(&self, i: BoxIndex) -> &T {
        &self.data[i.0]
    }
}

impl<T> std::ops::IndexMut<BoxIndex> for Field<T> {
    #[inline]
    fn index_mut(&mut self, i: BoxIndex) -> &mut T {
        &mut self.data[i.0]
    }
}

impl Field<f32> {
    /// Trilinear interpolation at a volume-local position (mm); corners outside the box
    /// count as `outside`.
    pub fn sample(&self, mm: glam::DVec3, outside: f32) -> f32 {
        let p = self.geometry.local_to_index(mm);
        let base = p.floor();
        // Inside the box all eight corners are a first one's index plus strides (the
        // centring samples Ds about 300 000 times per trace).
        let (lo, dims) = (self.grid.lo, self.grid.dims);
        let inside = [base.x, base.y, base.z]
            .iter()
            .zip(lo.iter().zip(dims))
            .all(|(&b, (&l, n))| b >= l as f64 && b + 1.0 < (l + n) as f64);
        if inside {
            let [x, y, z] = [base.x, base.y, base.z].map(|b| b as usize);
            let first = self.grid.index(x - lo[0], y - lo[1], z - lo[2]).0;
            let stride = [1, dims[0], dims[0] * dims[1]];
            return blend(p - base, |o| {
                self.data[first + o[0] * stride[0] + o[1] * stride[1] + o[2] * stride[2]]
            });
        }
        trilinear(&self.geometry, mm, |g| self.get_global(g, outside), outside)
    }
}

/// A field of f32 read trilinearly at volume-local positions (mm), 0 where it does not
/// reach: Ds as the centring reads it, in box layout or in bricks.
pub trait Sampled {
    fn sample_mm(&self, mm: glam::DVec3) -> f32;
}

impl Sampled for Field<f32> {
    #[inline]
    fn sample_mm(&self, mm: glam::DVec3) -> f32 {
        self.sample(mm, 0.0)
    }
}

/// Bricks whose `outside` is 0 (Ds's).
impl Sampled for Bricked<f32> {
    #[inline]
    fn sample_mm(&self, mm: glam::DVec3) -> f32 {
        self.sample(mm)
    }
}

/// Side of a brick of [`Bricked`] (as a power of two).
const BRICK_SHIFT: usize = 3;
const BRICK: usize = 1 << BRICK_SHIFT;
const BRICK_VOXELS: usize = BRICK * BRICK * BRICK;
const ABSENT: u32 = u32::MAX;

/// Values over a [`BoxGrid`] kept only in the 8×8×8 bricks that hold anything but `outside`.
///
/// Why: the lumen fills an eighth of its bounding box (4.5 M of 32 M voxels on a full colon),
/// so a box-layout f32 field costs 130 MB where the bricks that hold lumen cost 25–35 MB. The
/// study keeps Ds, both Dt fields and the voxels' cells this way, which keeps preprocessing
/// within its memory budget. A lookup is a table load and a multiply-add.
#[derive(Clone, Debug, PartialEq)]
pub struct Bricked<T> {
    pub grid: BoxGrid,
    pub geometry: Geometry,
    /// Value of voxels in absent bricks (and beyond the box).
    pub outside: T,
    layout: Layout,
    /// Slots × 512 values, x fastest inside a brick; voxels of an edge brick past the box hold
    /// `outside`.
    data: Vec<T>,
}

/// Which bricks of a box are stored, and where.
#[derive(Clone, Debug, PartialEq)]
struct Layout {
    /// Bricks per axis.
    nb: [usize; 3],
    /// Per brick (x fastest): its slot, or [`ABSENT`].
    table: Vec<u32>,
    /// Per slot: its brick.
    bricks: Vec<u32>,
}

/// Which bricks of a box hold a value worth keeping, marked row by row while the rows are
/// read for something else (a search's start from the mask), for
/// [`Bricked::from_rows_marked`]: no second pass over the box.
pub struct BrickMarks {
    dims: [usize; 3],
    nb: [usize; 3],
    table: Vec<u32>,
}

impl BrickMarks {
    pub fn new(grid: &BoxGrid) -> Self {
        let nb = grid.dims.map(|d| d.div_ceil(BRICK));
        BrickMarks {
            dims: grid.dims,
            nb,
            table: vec![0u32; nb[0] * nb[1] * nb[2]],
        }
    }

    /// Marks the bricks of box row (j, k) where `keep` holds for one of its values.
    #[inline]
    pub fn mark_row<S: Copy>(&mut self, j: usize, k: usize, row: &[S], keep: impl Fn(S) -> bool) {
        let base = self.nb[0] * ((j >> BRICK_SHIFT) + self.nb[1] * (k >> BRICK_SHIFT));
        for (c, chunk) in row[..self.dims[0]].chunks(BRICK).enumerate() {
            // No early exit: the fold compiles to branch-free vector code.
            if self.table[base + c] == 0 && chunk.iter().fold(false, |a, &s| a | keep(s)) {
                self.table[base + c] = 1;
            }
        }
    }
}

impl Layout {
    /// The bricks where `keep` holds for one of the values of the box rows `row(j, k)`.
    fn of_rows<'a, S: Copy + 'a>(
        grid: &BoxGrid,
        row: &impl Fn(usize, usize) -> &'a [S],
        keep: impl Fn(S) -> bool,
    ) -> Self {
        let mut marks = BrickMarks::new(grid);
        for k in 0..grid.dims[2] {
            for j in 0..grid.dims[1] {
                marks.mark_row(j, k, row(j, k), &keep);
            }
        }
        Layout::of_marks(marks)
    }

    /// The marked bricks, numbered in order.
    fn of_marks(marks: BrickMarks) -> Self {
        let BrickMarks { nb, mut table, .. } = marks;
        let mut bricks = Vec::new();
        for (b, t) in table.iter_mut().enumerate() {
            if *t != 0 {
                *t = bricks.len() as u32;
                bricks.push(b as u32);
            } else {
                *t = ABSENT;
            }
        }
        Layout { nb, table, bricks }
    }

    /// Brick (x, y, z) of a slot.
    #[inline]
    fn brick_of_slot(&self, slot: usize) -> [usize; 3] {
        let b = self.bricks[slot] as usize;
        [
            b % self.nb[0],
            (b / self.nb[0]) % self.nb[1],
            b / (self.nb[0] * self.nb[1]),
        ]
    }

    #[inline]
    fn slot_of(&self, l: [usize; 3]) -> u32 {
        self.table[(l[0] >> BRICK_SHIFT)
            + self.nb[0] * ((l[1] >> BRICK_SHIFT) + self.nb[1] * (l[2] >> BRICK_SHIFT))]
    }
}

impl<T: Copy + PartialEq> Bricked<T> {
    /// From box rows: `row(j, k)` is box row (j, k), `grid.dims[0]` long; a brick is kept
    /// where `keep` holds for one of its values, and each value passes through `map`
    /// (`map(s)` must be `outside` where `keep(s)` is false). Two streaming passes: which
    /// bricks to keep, then the copy.
    pub fn from_rows<'a, S: Copy + 'a>(
        grid: &BoxGrid,
        geometry: &Geometry,
        outside: T,
        row: impl Fn(usize, usize) -> &'a [S],
        keep: impl Fn(S) -> bool,
        map: impl Fn(S) -> T,
    ) -> Self {
        let layout = Layout::of_rows(grid, &row, keep);
        Bricked::fill(grid, geometry, layout, outside, row, map)
    }

    /// [`Bricked::from_rows`] into the bricks `marks` marked (values in the others must map to
    /// `outside`).
    pub fn from_rows_marked<'a, S: Copy + 'a>(
        grid: &BoxGrid,
        geometry: &Geometry,
        outside: T,
        marks: BrickMarks,
        row: impl Fn(usize, usize) -> &'a [S],
        map: impl Fn(S) -> T,
    ) -> Self {
        Bricked::fill(grid, geometry, Layout::of_marks(marks), outside, row, map)
    }

    /// From box rows of the same box as `like`, into the bricks `like` stores (so one pass,
    /// over those bricks only); values in the other bricks must map to `outside`.
    pub fn from_rows_like<'a, U, S: Copy + 'a>(
        like: &Bricked<U>,
        outside: T,
        row: impl Fn(usize, usize) -> &'a [S],
        map: impl Fn(S) -> T,
    ) -> Self {
        Bricked::fill(
            &like.grid,
            &like.geometry,
            like.layout.clone(),
            outside,
            row,
            map,
        )
    }

    fn fill<'a, S: Copy + 'a>(
        grid: &BoxGrid,
        geometry: &Geometry,
        layout: Layout,
        outside: T,
        row: impl Fn(usize, usize) -> &'a [S],
        map: impl Fn(S) -> T,
    ) -> Self {
        Bricked::fill_with(grid, geometry, layout, outside, |j, k, ci, dst| {
            let n = dst.len();
            for (d, &s) in dst.iter_mut().zip(&row(j, k)[ci..ci + n]) {
                *d = map(s);
            }
        })
    }

    /// The bricks of `layout`, each row of each brick written by `row(j, k, ci, dst)`: box
    /// row (j, k) from x = ci on, into `dst` (as long as the brick's part of the row).
    fn fill_with(
        grid: &BoxGrid,
        geometry: &Geometry,
        layout: Layout,
        outside: T,
        mut row: impl FnMut(usize, usize, usize, &mut [T]),
    ) -> Self {
        let [bx, by, bz] = grid.dims;
        let mut data = crate::mem::filled(layout.bricks.len() * BRICK_VOXELS, outside);
        for (slot, bricks) in data.chunks_mut(BRICK_VOXELS).enumerate() {
            let [ci, cj, ck] = layout.brick_of_slot(slot).map(|c| c * BRICK);
            let n = BRICK.min(bx - ci);
            for z in 0..BRICK.min(bz - ck) {
                for y in 0..BRICK.min(by - cj) {
                    row(
                        cj + y,
                        ck + z,
                        ci,
                        &mut bricks[BRICK * (y + BRICK * z)..][..n],
                    );
                }
            }
        }
        Bricked {
            grid: grid.clone(),
            geometry: geometry.clone(),
            outside,
            layout,
            data,
        }
    }

    /// A box-layout field in bricks (bricks holding only `outside` left out).
    pub fn from_field(f: &Field<T>, outside: T) -> Self {
        let bx = f.grid.dims[0];
        Bricked::from_rows(
            &f.grid,
            &f.geometry,
            outside,
            |j, k| &f.data[f.grid.index(0, j, k).0..][..bx],
            |v| v != outside,
            |v| v,
        )
    }

    /// The same bricks holding `f(index, value)` of each stored value (index into
    /// [`Bricked::values`]; `f` must give `outside` for `self.outside`).
    pub fn map<U: Copy + PartialEq>(
        &self,
        outside: U,
        mut f: impl FnMut(usize, T) -> U,
    ) -> Bricked<U> {
        let data = crate::mem::collect(
            self.data.len(),
            self.data.iter().enumerate().map(|(at, &v)| f(at, v)),
        );
        Bricked {
            grid: self.grid.clone(),
            geometry: self.geometry.clone(),
            outside,
            layout: self.layout.clone(),
            data,
        }
    }

    /// Value at box-local voxel `l` (which must lie in the box).
    #[inline]
    pub fn get_box(&self, l: [usize; 3]) -> T {
        self.index_of_box(l)
            .map_or(self.outside, |at| self.data[at.0])
    }

    /// Value at a volume voxel (`outside` beyond the box).
    #[inline]
    pub fn get(&self, g: [usize; 3]) -> T {
        let mut l = [0usize; 3];
        for a in 0..3 {
            match g[a].checked_sub(self.grid.lo[a]) {
                Some(x) if x < self.grid.dims[a] => l[a] = x,
                _ => return self.outside,
            }
        }
        self.get_box(l)
    }

    /// Box-local voxel of an index into [`Bricked::values`].
    #[inline]
    pub fn box_voxel(&self, at: BrickIndex) -> [usize; 3] {
        let BrickIndex(at) = at;
        let bb = self.layout.brick_of_slot(at / BRICK_VOXELS);
        let o = at % BRICK_VOXELS;
        [
            bb[0] * BRICK + (o & (BRICK - 1)),
            bb[1] * BRICK + ((o >> BRICK_SHIFT) & (BRICK - 1)),
            bb[2] * BRICK + (o >> (2 * BRICK_SHIFT)),
        ]
    }

    /// Index into [`Bricked::values`] of box-local voxel `l`, None in an absent brick.
    #[inline]
    pub fn index_of_box(&self, l: [usize; 3]) -> Option<BrickIndex> {
        let slot = self.layout.slot_of(l);
        (slot != ABSENT).then(|| BrickIndex(slot as usize * BRICK_VOXELS + within_brick(l)))
    }

    /// Writes `v` at a volume voxel whose brick is stored; false (nothing written) elsewhere.
    #[inline]
    pub fn set(&mut self, g: [usize; 3], v: T) -> bool {
        let l = [0, 1, 2].map(|a| g[a].wrapping_sub(self.grid.lo[a]));
        if (0..3).any(|a| l[a] >= self.grid.dims[a]) {
            return false;
        }
        match self.index_of_box(l) {
            Some(at) => {
                self.data[at.0] = v;
                true
            }
            None => false,
        }
    }

    /// The stored values, brick by brick (see [`Bricked::box_voxel`]); voxels of edge bricks
    /// past the box hold `outside`.
    pub fn values(&self) -> &[T] {
        &self.data
    }

    /// Heap bytes held.
    pub fn bytes(&self) -> usize {
        self.data.capacity() * std::mem::size_of::<T>()
            + (self.layout.table.capacity() + self.layout.bricks.capacity()) * 4
    }

    /// Axial slice k spread over the whole volume (x fastest), `outside` elsewhere: for
    /// writing a field without a whole volume in memory.
    pub fn fill_slice(&self, k: usize, out: &mut [T]) {
        out.fill(self.outside);
        let lo = self.grid.lo;
        let [bx, by, bz] = self.grid.dims;
        if k < lo[2] || k >= lo[2] + bz {
            return;
        }
        let nx = self.geometry.dims[0];
        let lk = k - lo[2];
        for j in 0..by {
            let start = lo[0] + nx * (j + lo[1]);
            for c in 0..self.layout.nb[0] {
                let slot = self.layout.slot_of([c * BRICK, j, lk]);
                if slot == ABSENT {
                    continue;
                }
                let x0 = c * BRICK;
                let n = BRICK.min(bx - x0);
                let at = slot as usize * BRICK_VOXELS + within_brick([0, j, lk]);
                out[start + x0..start + x0 + n].copy_from_slice(&self.data[at..at + n]);
            }
        }
    }

    /// The field in the box layout (`outside` in absent bricks).
    pub fn to_field(&self) -> Field<T> {
        let [bx, by, bz] = self.grid.dims;
        let mut data = crate::mem::filled(self.grid.len(), self.outside);
        for k in 0..bz {
            for j in 0..by {
                let row = &mut data[self.grid.index(0, j, k).0..][..bx];
                for (c, chunk) in row.chunks_mut(BRICK).enumerate() {
                    if let Some(BrickIndex(at)) = self.index_of_box([c * BRICK, j, k]) {
                        chunk.copy_from_slice(&self.data[at..at + chunk.len()]);
                    }
                }
            }
        }
        Field {
            grid: self.grid.clone(),
            geometry: self.geometry.clone(),
            data,
        }
    }

    /// The field spread over the whole volume (`outside` beyond the box).
    pub fn to_volume(&self) -> Result<Volume<T>> {
        let mut v = Volume::filled(self.geometry.clone(), self.outside)?;
        let [nx, ny, _] = self.geometry.dims;
        for (k, slice) in v.data_mut().chunks_mut(nx * ny).enumerate() {
            self.fill_slice(k, slice);
        }
        Ok(v)
    }
}

impl Bricked<f32> {
    /// Trilinear interpolation at a volume-local position (mm); corners beyond the stored
    /// bricks count as `outside`.
    pub fn sample(&self, mm: glam::DVec3) -> f32 {
        trilinear(&self.geometry, mm, |g| self.get(g), self.outside)
    }
}

#[inline]
fn within_brick(l: [usize; 3]) -> usize {
    (l[0] & (BRICK - 1)) + BRICK * ((l[1] & (BRICK - 1)) + BRICK * (l[2] & (BRICK - 1)))
}

/// Trilinear interpolation of voxel values `at` at a volume-local position; corners at
/// negative indices count as `outside`.
fn trilinear(
    geometry: &Geometry,
    mm: glam::DVec3,
    at: impl Fn([usize; 3]) -> f32,
    outside: f32,
) -> f32 {
    let p = geometry.local_to_index(mm);
    let base = p.floor();
    blend(p - base, |o| {
        let g = [0, 1, 2].map(|a| base[a] + o[a] as f64);
        if g.iter().all(|&x| x >= 0.0) {
            at(g.map(|x| x as usize))
        } else {
            outside
        }
    })
}

/// The eight corners' values (`corner` of the offset, 0 or 1 per axis) weighted by their
/// share at `t` (the point's place in the cell), in a fixed order; a corner of weight 0 is
/// not read.
#[inline]
fn blend(t: glam::DVec3, corner: impl Fn([usize; 3]) -> f32) -> f32 {
    let mut acc = 0.0f64;
    for c in 0..8 {
        let o = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
        let w = (if o[0] > 0 { t.x } else { 1.0 - t.x })
            * (if o[1] > 0 { t.y } else { 1.0 - t.y })
            * (if o[2] > 0 { t.z } else { 1.0 - t.z });
        if w == 0.0 {
            continue;
        }
        acc += w * corner(o) as f64;
    }
    acc as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sampling_inside_the_box_reads_the_corners_the_general_way_reads() {
        let g = Geometry::new([9, 8, 7], [0.75, 0.6, 1.25], [0.0; 3]).unwrap();
        let grid = BoxGrid {
            lo: [2, 1, 1],
            dims: [5, 6, 4],
        };
        let mut rng = crate::rng::Rng::new(7, 0);
        // Some values infinite (as Dt's beyond the lumen): a corner of weight 0 must not be
        // read, or a point on a voxel centre beside one would come out NaN.
        let data = (0..grid.len())
            .map(|i| {
                if i % 11 == 0 {
                    f32::INFINITY
                } else {
                    rng.range(0.0, 20.0) as f32
                }
            })
            .collect();
        let f = Field {
            grid: grid.clone(),
            geometry: g.clone(),
            data,
        };
        let mut inside = 0;
        for n in 0..4000 {
            // Points across the box and a voxel beyond it; some on voxel centres exactly.
            let mut ijk = [0, 1, 2].map(|_| rng.range(0.0, 9.0));
            if n % 5 == 0 {
                ijk = ijk.map(f64::round);
            }
            let mm = glam::DVec3::from_array(ijk) * g.spacing_vec();
            let general = trilinear(&g, mm, |c| f.get_global(c, -1.0), -1.0);
            let fast = f.sample(mm, -1.0);
            assert_eq!(fast.to_bits(), general.to_bits(), "at {ijk:?}");
            assert!(!fast.is_nan(), "at {ijk:?}");
            inside += (0..3).all(|a| {
                ijk[a].floor() as usize >= grid.lo[a]
                    && (ijk[a].floor() as usize) + 1 < grid.lo[a] + grid.dims[a]
            }) as usize;
        }
        assert!(inside > 300, "{inside} points inside");
    }

    #[test]
    fn slices_equal_the_spread_volume() {
        let g = Geometry::new([7, 6, 5], [1.0, 0.5, 2.0], [0.0; 3]).unwrap();
        let grid = BoxGrid {
            lo: [2, 1, 1],
            dims: [3, 4, 3],
        };
        let data = (0..grid.len()).map(|i| i as f32 + 1.0).collect();
        let f = Bricked::from_field(
            &Field {
                grid,
                geometry: g.clone(),
                data,
            },
            -1.0,
        );
        let v = f.to_volume().unwrap();
        let mut s = vec![0.0f32; 7 * 6];
        for k in 0..5 {
            f.fill_slice(k, &mut s);
            assert_eq!(&s[..], v.slice_k(k));
            for j in 0..6 {
                for i in 0..7 {
                    assert_eq!(v.get(i, j, k), f.get([i, j, k]), "voxel {i},{j},{k}");
                }
            }
        }
        assert_eq!(
            v.data().iter().filter(|&&x| x > 0.0).count(),
            36,
            "every box value placed once"
        );
        assert_eq!(f.get([2, 1, 1]), 1.0);
        assert_eq!(f.get([0, 0, 0]), -1.0);
    }

    #[test]
    fn bricks_hold_what_the_box_field_holds() {
        // A box not a multiple of 8 on any axis, values in a few scattered places.
        let g = Geometry::new([30, 27, 25], [0.8, 0.8, 1.25], [0.0; 3]).unwrap();
        let grid = BoxGrid {
            lo: [3, 2, 1],
            dims: [21, 19, 18],
        };
        let mut data = vec![f32::INFINITY; grid.len()];
        // Values in the lower two of three layers of bricks only.
        for (n, v) in data.iter_mut().enumerate() {
            let [_, j, k] = grid.ijk(BoxIndex(n));
            if (n % 97 < 3 && k < 9) || (j == 17 && k < 16) {
                *v = n as f32 * 0.5;
            }
        }
        let f = Field {
            grid: grid.clone(),
            geometry: g.clone(),
            data,
        };
        let b = Bricked::from_field(&f, f32::INFINITY);
        assert_eq!(b.to_field(), f);
        for k in 0..25 {
            for j in 0..27 {
                for i in 0..30 {
                    assert_eq!(
                        b.get([i, j, k]).to_bits(),
                        f.get_global([i, j, k], f32::INFINITY).to_bits(),
                        "voxel {i},{j},{k}"
                    );
                }
            }
        }
        // Every stored value sits at the box voxel `box_voxel` names, and back.
        for (at, &v) in b.values().iter().enumerate() {
            let l = b.box_voxel(BrickIndex(at));
            if l.iter().zip(&grid.dims).all(|(&x, &d)| x < d) {
                assert_eq!(v.to_bits(), f[grid.index(l[0], l[1], l[2])].to_bits());
                assert_eq!(b.index_of_box(l), Some(BrickIndex(at)));
            } else {
                assert_eq!(v, f32::INFINITY, "padding of an edge brick");
            }
        }
        // Only bricks holding a value are stored: none of the top layer.
        assert!(b.values().len() <= 18 * 512);
        let doubled = b.map(f32::INFINITY, |_, v| 2.0 * v);
        assert_eq!(doubled.get([4, 2, 1]), 2.0 * b.get([4, 2, 1]));
        let p = glam::DVec3::new(7.3, 5.1, 9.9);
        assert_eq!(b.sample(p).to_bits(), f.sample(p, f32::INFINITY).to_bits());
    }

    #[test]
    fn first_and_last_agree_with_a_plain_scan() {
        let mut rng = crate::rng::Rng::new(4, 1);
        for len in [0usize, 1, 31, 32, 33, 64, 100, 512] {
            for _ in 0..50 {
                let row: Vec<u8> = (0..len)
                    .map(|_| (rng.range(0.0, 1.0) < 0.03) as u8)
                    .collect();
                let want = row
                    .iter()
                    .position(|&v| v != 0)
                    .map(|f| (f, row.iter().rposition(|&v| v != 0).unwrap()));
                assert_eq!(first_and_last(&row, &|v: u8| v != 0), want, "{row:?}");
            }
        }
    }
}
