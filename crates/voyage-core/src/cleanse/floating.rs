//! What the model leaves floating, found and made air: islands of partial-volume skin that
//! no wall holds any more, and spurs of skin that the wall holds by one face. Each would
//! otherwise stand as a shard in the surface.

use super::{
    changes::{overwrite, value_after},
    marks::{LUMP, NEAR, RowMarks, SOLID},
    model::AIR_HU,
};
use crate::Geometry;

/// The changes so far, to find what they left floating.
pub(super) struct Islands<'a> {
    pub(super) hu: &'a [i16],
    pub(super) g: &'a Geometry,
    /// Changed voxels (ascending) and their new values.
    pub(super) voxels: &'a [u32],
    pub(super) values: &'a [i16],
    /// Lumen voxels that leave it, voxels that join it (ascending).
    pub(super) leave: &'a [usize],
    pub(super) join: &'a [usize],
    pub(super) air_hu: i16,
}

/// The marks of a pool's surroundings or a lump, that [`Islands::find`] looks at.
const MARKED: u8 = NEAR | SOLID | LUMP;
/// Spare bits [`Islands::find`] marks (and clears): a marked voxel solid once cleansed, and
/// one held by the wall beyond (or, among the loose ones, already put in an island).
const STAYS: u8 = 64;
const HELD: u8 = 128;

impl Islands<'_> {
    fn value(&self, v: usize) -> i16 {
        value_after(self.voxels, self.values, self.hu, v)
    }

    /// Outside the lumen `m` once cleansed, at or above the air level.
    fn solid(&self, m: &[u8], v: usize) -> bool {
        self.stays_solid(
            m[v],
            self.leave.binary_search(&v).is_ok(),
            self.join.binary_search(&v).is_ok(),
            self.value(v),
        )
    }

    /// [`Islands::solid`] for a voxel marked `m` before, that `leaves` or `joins` the lumen
    /// and is `value` once cleansed.
    fn stays_solid(&self, m: u8, leaves: bool, joins: bool, value: i16) -> bool {
        let lumen = if m & 1 != 0 { !leaves } else { joins };
        !lumen && value >= self.air_hu
    }

    /// Voxels marked near a pool or in a lump (within lo..=hi grown by one; the marks reach
    /// two past it, and lo..=hi lies two inside the volume; `rows` says which rows hold
    /// marks) that are solid once cleansed but joined to nothing solid outside the marks,
    /// through face neighbours solid and marked: ascending. `m` is the lumen before
    /// cleansing, with the marks; the two spare bits it lends are clear again on return.
    pub(super) fn find(
        &self,
        m: &mut [u8],
        lo: [usize; 3],
        hi: [usize; 3],
        rows: &RowMarks,
    ) -> Vec<usize> {
        let [nx, ny, _] = self.g.dims;
        let six = [
            1isize,
            -1,
            nx as isize,
            -(nx as isize),
            (nx * ny) as isize,
            -((nx * ny) as isize),
        ];
        let (blo, bhi) = (lo.map(|x| x - 1), hi.map(|x| x + 1));
        // The marked voxels solid once cleansed (by the scan, ascending, so the change lists
        // are read in order), and whether each is held: from outside (a face neighbour
        // outside the lumen, unmarked or past the box, where nothing changed), then through
        // the others.
        let (mut leave, mut join, mut changed) = (
            Ascending::new(self.leave),
            Ascending::new(self.join),
            Ascending::new(self.voxels),
        );
        let mut solid = Vec::new();
        let mut queue = Vec::new();
        for k in blo[2]..=bhi[2] {
            for j in blo[1]..=bhi[1] {
                if !rows.any(j, k, MARKED) {
                    continue;
                }
                let row = nx * (j + ny * k);
                for i in blo[0]..=bhi[0] {
                    let v = row + i;
                    if m[v] & MARKED == 0 {
                        continue;
                    }
                    let value = changed
                        .find(v as u32)
                        .map_or(self.hu[v], |n| self.values[n]);
                    if !self.stays_solid(m[v], leave.has(v), join.has(v), value) {
                        continue;
                    }
                    m[v] |= STAYS;
                    solid.push(v);
                    let at = [i, j, k];
                    // Step d of `six` leaves the box: +axis d / 2 at its top, −axis at
                    // its bottom.
                    let past_box = |d: usize| {
                        let a = d / 2;
                        at[a] == if d.is_multiple_of(2) { bhi[a] } else { blo[a] }
                    };
                    let held = (0..6).any(|d| {
                        let w = (v as isize + six[d]) as usize;
                        m[w] & 1 == 0 && (m[w] & MARKED == 0 || past_box(d))
                    });
                    if held {
                        m[v] |= HELD;
                        queue.push(v);
                    }
                }
            }
        }
        let joined = |m: &[u8], w: usize| m[w] & (STAYS | HELD) == STAYS;
        while let Some(v) = queue.pop() {
            for &d in &six {
                let w = (v as isize + d) as usize;
                if joined(m, w) {
                    m[w] |= HELD;
                    queue.push(w);
                }
            }
        }
        // An island with tissue inside it (a voxel of at least 0 HU all of whose neighbours
        // are solid) is a polyp's head on a stalk too thin to show, not skin: it stays.
        let inner = |m: &[u8], v: usize| {
            self.value(v) >= 0
                && six.iter().all(|&d| {
                    let w = (v as isize + d) as usize;
                    m[w] & STAYS != 0 || self.solid(m, w)
                })
        };
        let mut out = Vec::new();
        for &start in &solid {
            if !joined(m, start) {
                continue;
            }
            m[start] |= HELD;
            let mut island = vec![start];
            let mut next = 0;
            while next < island.len() {
                let v = island[next];
                next += 1;
                for &d in &six {
                    let w = (v as isize + d) as usize;
                    if joined(m, w) {
                        m[w] |= HELD;
                        island.push(w);
                    }
                }
            }
            if !island.iter().any(|&v| inner(m, v)) {
                out.extend(island);
            }
        }
        for &v in &solid {
            m[v] &= !(STAYS | HELD);
        }
        out.sort_unstable();
        out
    }
}

/// Look-ups in an ascending list, in ascending order: each costs the steps past the last.
struct Ascending<'a, T> {
    list: &'a [T],
    at: usize,
}

impl<'a, T: Ord + Copy> Ascending<'a, T> {
    fn new(list: &'a [T]) -> Self {
        Ascending { list, at: 0 }
    }

    /// Where `v` is in the list; `v` is at least the last one asked for.
    fn find(&mut self, v: T) -> Option<usize> {
        while self.at < self.list.len() && self.list[self.at] < v {
            self.at += 1;
        }
        (self.list.get(self.at) == Some(&v)).then_some(self.at)
    }

    fn has(&mut self, v: T) -> bool {
        self.find(v).is_some()
    }
}

/// Passes of [`peel_spurs`]: a spur up to this many voxels long goes.
const SPUR_PASSES: usize = 4;

/// Spurs of skin that the wall holds by one face, beside what cleansing changed: a voxel
/// outside the lumen, below 0 HU (partial volume, not tissue), with five of its six face
/// neighbours lumen, becomes air and lumen; again, for longer spurs. `voxels` stays
/// ascending.
pub(super) fn peel_spurs(
    m: &mut [u8],
    hu: &[i16],
    voxels: &mut Vec<u32>,
    values: &mut Vec<i16>,
    join: &mut Vec<usize>,
    six: &[isize; 6],
    air_hu: i16,
) {
    let spur = |m: &[u8], v: usize| {
        m[v] == 0
            && six
                .iter()
                .filter(|&&d| m[(v as isize + d) as usize] & 1 != 0)
                .count()
                >= 5
            && (air_hu..0).contains(&value_after(voxels, values, hu, v))
    };
    let changed = |v: usize| voxels.binary_search(&(v as u32)).is_ok();
    // The first pass looks at every changed voxel and its face neighbours; a later one only
    // at the face neighbours of the voxels just peeled (nothing else changed around the
    // others), that are changed or beside a changed voxel.
    let mut spurs: Vec<usize> = voxels
        .iter()
        .flat_map(|&v| {
            six.iter()
                .map(move |&d| (v as isize + d) as usize)
                .chain([v as usize])
        })
        .filter(|&v| spur(m, v))
        .collect();
    let mut peeled: Vec<(u32, i16)> = Vec::new();
    for _ in 0..SPUR_PASSES {
        spurs.sort_unstable();
        spurs.dedup();
        if spurs.is_empty() {
            break;
        }
        for &v in &spurs {
            m[v] = 1;
            join.push(v);
            peeled.push((v as u32, AIR_HU));
        }
        spurs = spurs
            .iter()
            .flat_map(|&v| six.iter().map(move |&d| (v as isize + d) as usize))
            .filter(|&w| changed(w) || six.iter().any(|&d| changed((w as isize + d) as usize)))
            .filter(|&w| spur(m, w))
            .collect();
    }
    peeled.sort_unstable();
    overwrite(voxels, values, hu, &peeled);
}
