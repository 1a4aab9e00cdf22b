//! Step 1's runs, which every later step works on: maximal stretches of one kind of voxel
//! (air, tagged fluid, a working label) along x in one row, found from one read of the values,
//! and what is done with them row by row (painting labels, boxes, neighbours).

use rayon::prelude::*;

use super::work::{Bbox, GAS};
use crate::{
    Volume,
    simd::{self, Test},
};

/// Bright (tagged fluid or bone) in [`LabelRows`].
pub(super) const BRIGHT: u8 = 2;

/// A run of one label: voxels x0..x1 of a row, and the label.
pub(super) type LabelRun = (u32, u32, u8);

/// Gas and bright runs, row by row (row = j + ny·k), in x order.
pub(super) struct LabelRows {
    pub(super) runs: Vec<LabelRun>,
    pub(super) row_start: Vec<u32>,
    pub(super) dims: [usize; 3],
}

impl LabelRows {
    pub(super) fn row(&self, j: usize, k: usize) -> &[LabelRun] {
        let r = j + self.dims[1] * k;
        &self.runs[self.row_start[r] as usize..self.row_start[r + 1] as usize]
    }
}

/// One stretch of lumen candidates along x: voxels x0..x1 of row (j, k).
#[derive(Clone, Copy, Debug)]
pub(super) struct Run {
    pub(super) x0: u32,
    pub(super) x1: u32,
}

impl Run {
    /// It shares an x with `other`.
    pub(super) fn overlaps(self, other: Run) -> bool {
        self.x0 < other.x1 && other.x0 < self.x1
    }
}

/// All runs, row by row: the runs of row r = j + ny*k are `runs[row_start[r]..row_start[r+1]]`.
pub(super) struct Runs {
    pub(super) runs: Vec<Run>,
    pub(super) row_start: Vec<u32>,
    /// Per run: sum of HU and count of voxels below −950 (zero for masks).
    pub(super) hu_sum: Vec<i64>,
    pub(super) dark: Vec<u32>,
    pub(super) ny: usize,
}

impl Runs {
    /// No runs yet, for rows `ny` long in j.
    pub(super) fn empty(ny: usize) -> Runs {
        Runs {
            runs: Vec::new(),
            row_start: vec![0],
            hu_sum: Vec::new(),
            dark: Vec::new(),
            ny,
        }
    }

    pub(super) fn row(&self, j: usize, k: usize) -> std::ops::Range<usize> {
        let r = j + self.ny * k;
        self.row_start[r] as usize..self.row_start[r + 1] as usize
    }

    /// The runs where `keep(run)`, in the same rows.
    pub(super) fn filtered(&self, keep: impl Fn(usize) -> bool) -> Runs {
        let mut out = Runs::empty(self.ny);
        out.row_start.reserve(self.row_start.len() - 1);
        for row in 0..self.row_start.len() - 1 {
            for r in self.row_start[row] as usize..self.row_start[row + 1] as usize {
                if keep(r) {
                    out.runs.push(self.runs[r]);
                    out.hu_sum.push(self.hu_sum[r]);
                    out.dark.push(self.dark[r]);
                }
            }
            out.row_start.push(out.runs.len() as u32);
        }
        out
    }

    /// The run holding voxel v, if any.
    pub(super) fn at(&self, v: [usize; 3]) -> Option<usize> {
        let row = self.row(v[1], v[2]);
        let rs = &self.runs[row.clone()];
        let p = rs.partition_point(|r| (r.x1 as usize) <= v[0]);
        (p < rs.len() && rs[p].x0 as usize <= v[0]).then_some(row.start + p)
    }
}

/// The runs of `test` (the air, with HU statistics when it is `Below`) and, with `bright`, the
/// runs at or above it, from one read of the values.
pub(super) fn extract_runs(
    vol: &Volume<i16>,
    test: Test,
    bright: Option<i16>,
) -> (Runs, Option<Runs>) {
    let [nx, ny, nz] = vol.dims();
    let stats = matches!(test, Test::Below(_));
    // One task per slice; concatenated in slice order so the result is thread-independent.
    let per_slice: Vec<(SliceRuns, Option<SliceRuns>)> = (0..nz)
        .into_par_iter()
        .map_init(
            || (vec![0u64; nx.div_ceil(64)], vec![0u64; nx.div_ceil(64)]),
            |words, k| {
                let slice = vol.slice_k(k);
                let mut air = SliceRuns::with_rows(ny);
                let mut fluid = bright.map(|_| SliceRuns::with_rows(ny));
                for row in slice.chunks_exact(nx) {
                    let tests = (test, bright.map(Test::AtLeast));
                    row_bits(row, tests, words);
                    air.add_row(
                        &words.0,
                        |x0, x1| if stats { run_stats(row, x0, x1) } else { None },
                    );
                    if let Some(f) = &mut fluid {
                        f.add_row(&words.1, |_, _| None);
                    }
                }
                (air, fluid)
            },
        )
        .collect();
    let (air, fluid): (Vec<SliceRuns>, Vec<Option<SliceRuns>>) = per_slice.into_iter().unzip();
    let fluid = bright.map(|_| Runs::concat(fluid.into_iter().flatten(), ny));
    (Runs::concat(air, ny), fluid)
}

/// One slice's runs, row by row.
struct SliceRuns {
    runs: Vec<Run>,
    counts: Vec<u32>,
    hu_sum: Vec<i64>,
    dark: Vec<u32>,
}

impl SliceRuns {
    fn with_rows(ny: usize) -> Self {
        SliceRuns {
            runs: Vec::new(),
            counts: Vec::with_capacity(ny),
            hu_sum: Vec::new(),
            dark: Vec::new(),
        }
    }

    /// The runs of one row's bits, each with `stats(x0, x1)` ((0, 0) where it gives none).
    fn add_row(&mut self, words: &[u64], stats: impl Fn(u32, u32) -> Option<(i64, u32)>) {
        let before = self.runs.len();
        runs_of_bits(words, |x0, x1| {
            self.runs.push(Run { x0, x1 });
            let (sum, dark) = stats(x0, x1).unwrap_or((0, 0));
            self.hu_sum.push(sum);
            self.dark.push(dark);
        });
        self.counts.push((self.runs.len() - before) as u32);
    }
}

impl Runs {
    fn concat(slices: impl IntoIterator<Item = SliceRuns>, ny: usize) -> Runs {
        let mut out = Runs::empty(ny);
        for s in slices {
            for c in s.counts {
                let last = *out.row_start.last().unwrap_or(&0);
                out.row_start.push(last + c);
            }
            out.runs.extend(s.runs);
            out.hu_sum.extend(s.hu_sum);
            out.dark.extend(s.dark);
        }
        out
    }
}

/// HU sum and count of voxels darker than −950 HU of an air run, for telling bowel gas from
/// lung. Runs reaching the row's ends lie outside the body (step 2 drops them) and the air
/// outside is most of a scan's air: they get none.
pub(super) fn run_stats(row: &[i16], x0: u32, x1: u32) -> Option<(i64, u32)> {
    if x0 == 0 || x1 as usize == row.len() {
        return None;
    }
    let seg = &row[x0 as usize..x1 as usize];
    // i32 holds the sum of a row (at most 65 536 values of magnitude ≤ 32 768).
    let sum: i32 = seg.iter().map(|&v| v as i32).sum();
    let dark = seg.iter().map(|&v| (v < -950) as u32).sum();
    Some((sum as i64, dark))
}

/// Bit x % 64 of word x / 64 of `words.0`: whether `tests.0` holds for `row[x]`; the same of
/// `words.1` for `tests.1`, if any (one read of the row for both); bits past the row are 0.
fn row_bits(row: &[i16], tests: (Test, Option<Test>), words: &mut (Vec<u64>, Vec<u64>)) {
    let (chunks, rest) = row.as_chunks::<64>();
    let (a, b) = (&mut words.0, &mut words.1);
    match tests {
        (t, None) => a
            .iter_mut()
            .zip(chunks)
            .for_each(|(w, c)| *w = simd::mask64(c, t)),
        (t, Some(u)) => {
            for ((wa, wb), c) in a.iter_mut().zip(b.iter_mut()).zip(chunks) {
                (*wa, *wb) = (simd::mask64(c, t), simd::mask64(c, u));
            }
        }
    }
    if !rest.is_empty() {
        let bits = |t: Test| {
            rest.iter()
                .enumerate()
                .fold(0u64, |w, (i, &v)| w | (t.holds(v) as u64) << i)
        };
        a[row.len() / 64] = bits(tests.0);
        if let Some(u) = tests.1 {
            b[row.len() / 64] = bits(u);
        }
    }
}

/// Calls `f(x0, x1)` for each run [x0, x1) of set bits, in order.
fn runs_of_bits(words: &[u64], mut f: impl FnMut(u32, u32)) {
    let (mut carry, mut start) = (0u64, 0u32);
    for (w, &word) in words.iter().enumerate() {
        // A bit of `edges` marks where the row changes: a run starts or ends there.
        let mut edges = word ^ (word << 1 | carry);
        carry = word >> 63;
        while edges != 0 {
            let b = edges.trailing_zeros();
            edges &= edges - 1;
            let x = 64 * w as u32 + b;
            if word >> b & 1 == 1 {
                start = x;
            } else {
                f(start, x);
            }
        }
    }
    if carry == 1 {
        f(start, 64 * words.len() as u32);
    }
}

/// Calls `f(a, b)` for every pair of runs, one in row `ra` and one in row `rb`, that share an x.
pub(super) fn for_overlaps(
    runs: &Runs,
    ra: std::ops::Range<usize>,
    rb: std::ops::Range<usize>,
    mut f: impl FnMut(usize, usize),
) {
    let (mut a, mut b) = (ra.start, rb.start);
    while a < ra.end && b < rb.end {
        let (p, q) = (runs.runs[a], runs.runs[b]);
        if p.overlaps(q) {
            f(a, b);
        }
        if p.x1 < q.x1 {
            a += 1;
        } else {
            b += 1;
        }
    }
}

/// (j, k) of run `r`'s row.
pub(super) fn row_of(runs: &Runs, r: usize) -> (usize, usize) {
    let row = runs.row_start.partition_point(|&s| s as usize <= r) - 1;
    (row % runs.ny, row / runs.ny)
}

/// Writes `value(run)` over each run that has one, slice by slice in parallel.
pub(super) fn paint(
    work: &mut Volume<u8>,
    runs: &Runs,
    value: impl Fn(usize) -> Option<u8> + Sync,
) {
    let [nx, ny, _] = work.dims();
    work.data_mut()
        .par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, slab)| {
            for j in 0..ny {
                for r in runs.row(j, k) {
                    if let Some(v) = value(r) {
                        let run = runs.runs[r];
                        slab[j * nx + run.x0 as usize..j * nx + run.x1 as usize].fill(v);
                    }
                }
            }
        });
}

/// The gas runs (where `gas(run)`) and the bright runs inside `bx`, merged row by row in x
/// order, for the fluid's line walks.
/// Bright runs only where `keep_bright((x0, x1), j, k)`.
pub(super) fn label_rows(
    runs: &Runs,
    gas: impl Fn(usize) -> bool + Sync,
    bright: &Runs,
    bx: &Bbox,
    nx: usize,
    keep_bright: impl Fn((u32, u32), usize, usize) -> bool + Sync,
) -> LabelRows {
    let ny = runs.ny;
    let nz = (runs.row_start.len() - 1) / ny;
    let per_slice: Vec<(Vec<LabelRun>, Vec<u32>)> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let (mut out, mut counts) = (Vec::new(), Vec::with_capacity(ny));
            for j in 0..ny {
                let before = out.len();
                if (bx.lo[1]..=bx.hi[1]).contains(&j) && (bx.lo[2]..=bx.hi[2]).contains(&k) {
                    let g = runs
                        .row(j, k)
                        .filter(|&r| gas(r))
                        .map(|r| (runs.runs[r].x0, runs.runs[r].x1, GAS));
                    let b = bright
                        .row(j, k)
                        .map(|r| (bright.runs[r].x0, bright.runs[r].x1, BRIGHT))
                        .filter(|r| keep_bright((r.0, r.1), j, k));
                    out.extend(g.chain(b));
                    out[before..].sort_unstable_by_key(|r| r.0);
                }
                counts.push((out.len() - before) as u32);
            }
            (out, counts)
        })
        .collect();
    let mut rows = LabelRows {
        runs: Vec::new(),
        row_start: vec![0],
        dims: [nx, ny, nz],
    };
    for (r, c) in per_slice {
        for n in c {
            let last = *rows.row_start.last().unwrap_or(&0);
            rows.row_start.push(last + n);
        }
        rows.runs.extend(r);
    }
    rows
}

/// Whether a run where `keep(run)` lies within `d` voxels of x range `x` in row (j, k) or a
/// row up to `d` steps away along y or z.
pub(super) fn runs_near(
    runs: &Runs,
    keep: &(impl Fn(usize) -> bool + Sync),
    x: (u32, u32),
    j: usize,
    k: usize,
    d: usize,
) -> bool {
    let nz = (runs.row_start.len() - 1) / runs.ny;
    let near = |b: usize, c: usize| {
        runs.row(b, c).any(|r| {
            keep(r) && runs.runs[r].x0 < x.1 + d as u32 && runs.runs[r].x1 + d as u32 > x.0
        })
    };
    (0..=d).any(|s| {
        let rows = [
            (j.wrapping_sub(s), k),
            (j + s, k),
            (j, k.wrapping_sub(s)),
            (j, k + s),
        ];
        rows.iter()
            .any(|&(b, c)| b < runs.ny && c < nz && near(b, c))
    })
}

/// The box of the runs where `keep(run)`.
pub(super) fn runs_box(
    runs: &Runs,
    dims: [usize; 3],
    keep: impl Fn(usize) -> bool,
) -> Option<Bbox> {
    let [_, ny, nz] = dims;
    let mut b: Option<Bbox> = None;
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k).filter(|&r| keep(r)) {
                let run = runs.runs[r];
                let x = Bbox {
                    lo: [run.x0 as usize, j, k],
                    hi: [run.x1 as usize - 1, j, k],
                };
                b = Some(b.map_or(x, |y| y.union(&x)));
            }
        }
    }
    b
}

/// Runs of the working labels where `keep(label)`, inside `bx` (rows outside it are empty).
/// Only rows where `scan(j, k)` are read.
pub(super) fn work_runs(
    work: &Volume<u8>,
    bx: &Bbox,
    scan: impl Fn(usize, usize) -> bool + Sync,
    keep: impl Fn(u8) -> bool + Sync,
) -> Runs {
    let [nx, ny, nz] = work.dims();
    let per_slice: Vec<SliceRuns> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let mut s = SliceRuns::with_rows(ny);
            for j in 0..ny {
                let before = s.runs.len();
                if (bx.lo[1]..=bx.hi[1]).contains(&j)
                    && (bx.lo[2]..=bx.hi[2]).contains(&k)
                    && scan(j, k)
                {
                    let row = &work.data()[nx * (j + ny * k)..nx * (j + ny * k + 1)];
                    for r in crate::volume::runs_where(&row[bx.lo[0]..=bx.hi[0]], &keep) {
                        s.runs.push(Run {
                            x0: (r.start + bx.lo[0]) as u32,
                            x1: (r.end + bx.lo[0]) as u32,
                        });
                        s.hu_sum.push(0);
                        s.dark.push(0);
                    }
                }
                s.counts.push((s.runs.len() - before) as u32);
            }
            s
        })
        .collect();
    Runs::concat(per_slice, ny)
}

/// Voxels in some runs.
pub(super) fn run_voxels(runs: &Runs, rs: &[usize]) -> usize {
    rs.iter()
        .map(|&r| (runs.runs[r].x1 - runs.runs[r].x0) as usize)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The runs of one row found through its bits, for both tests at once, are the runs of the
    /// plain per-voxel test: rows of many lengths (whole words and a remainder), runs at both
    /// ends and across word boundaries, values at and beside the thresholds.
    #[test]
    fn row_bits_give_the_runs_of_each_test() {
        let mut rng = crate::rng::Rng::new(0x2545_F491_4F6C_DD1D, 0);
        let mut next = || rng.next_u64();
        let values = [
            -1000i16,
            -501,
            -500,
            -499,
            0,
            1,
            199,
            200,
            201,
            1500,
            i16::MIN,
            i16::MAX,
        ];
        for len in [1usize, 5, 63, 64, 65, 127, 128, 130, 200, 512, 517] {
            for _ in 0..20 {
                // Stretches of one value, so that runs are long enough to cross words.
                let mut row = Vec::with_capacity(len);
                while row.len() < len {
                    let v = values[(next() % values.len() as u64) as usize];
                    let n = 1 + (next() % 90) as usize;
                    row.extend(std::iter::repeat_n(v, n.min(len - row.len())));
                }
                for tests in [
                    (Test::Below(-500), Some(Test::AtLeast(200))),
                    (Test::NonZero, None),
                    (Test::AtLeast(-500), Some(Test::NonZero)),
                ] {
                    let mut words = (
                        vec![u64::MAX; len.div_ceil(64)],
                        vec![u64::MAX; len.div_ceil(64)],
                    );
                    row_bits(&row, tests, &mut words);
                    let found = |w: &[u64]| {
                        let mut v = Vec::new();
                        runs_of_bits(w, |a, b| v.push(a as usize..b as usize));
                        v
                    };
                    let want = |t: Test| {
                        crate::volume::runs_where(&row, |v| t.holds(v)).collect::<Vec<_>>()
                    };
                    assert_eq!(found(&words.0), want(tests.0), "{tests:?} {row:?}");
                    if let Some(u) = tests.1 {
                        assert_eq!(found(&words.1), want(u), "{tests:?} {row:?}");
                    }
                }
            }
        }
    }
}
