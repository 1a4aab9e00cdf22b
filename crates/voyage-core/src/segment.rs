//! Segmentation of the colon's air (paper §3.2: "the voxels inside the colon are easily
//! extracted with a region growing method").
//!
//! Everything works on *runs*: maximal stretches of air along x in one row. A CT of
//! 512×512×400 voxels holds a few hundred thousand air runs, so connected components,
//! outside-air removal and region growing cost a pass over the HU values plus work on the runs.
//!
//! 1. Threshold: air is HU < `air_hu` (−500, midway between air and soft tissue, where the
//!    partial-volume boundary lies).
//! 2. Outside air: in each axial slice, air connected (4-neighbours) to the slice's border lies
//!    outside the body. Slice by slice and not in 3D, because a rectal tube carries air from
//!    the colon out of the body: in 3D the colon would leak into the outside air.
//! 3. Components: the remaining air, 6-connected in 3D (diagonal contact through a thin wall
//!    does not join two loops of the colon).
//! 4. Lungs: large components whose air is not dark enough to be gas (lung parenchyma lies
//!    around −850 HU, bowel gas at −1000).
//! 5. The colon: the component holding the seed when one is given (region growing from it),
//!    else the largest remaining component.
//!
//! A lumen mask (0/1 labels from another segmenter) skips steps 1, 2 and 4.

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::{Error, Result, Volume};

#[derive(Clone, Debug)]
pub struct SegmentOptions {
    /// Air is HU below this.
    pub air_hu: i16,
    /// A point in the colon's air (volume-local mm). None: automatic.
    pub seed_mm: Option<DVec3>,
    /// Treat the input as a lumen mask (non-zero = lumen). None: detect (values only 0 and 1).
    pub mask: Option<bool>,
    /// Components smaller than this (ml) are not reported one by one.
    pub min_report_ml: f64,
    /// Without a seed, the colon must hold at least this much gas (ml): a few millilitres
    /// of gas are bowel gas or noise, not a colon to fly through.
    pub min_colon_ml: f64,
    /// Tagged fluid is HU at or above this; None: no fluid is added to the lumen.
    pub fluid_hu: Option<i16>,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions { air_hu: -500, seed_mm: None, mask: None, min_report_ml: 0.5, min_colon_ml: 10.0, fluid_hu: Some(200) }
    }
}

/// What a gas component is taken to be.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ComponentKind {
    Colon,
    Lung,
    Other,
}

#[derive(Clone, Debug, Serialize)]
pub struct Component {
    pub voxels: usize,
    pub volume_ml: f64,
    /// Mean position, volume-local mm.
    pub centroid_mm: [f64; 3],
    pub bbox_lo: [usize; 3],
    pub bbox_hi: [usize; 3],
    /// Mean HU (None for mask input).
    pub mean_hu: Option<f64>,
    /// Fraction of voxels darker than −950 HU: bowel gas is mostly that dark, lung is not.
    pub dark_fraction: Option<f64>,
    pub kind: ComponentKind,
}

#[derive(Clone, Debug)]
pub struct Segmentation {
    /// 1 = colon lumen.
    pub lumen: Volume<u8>,
    pub lumen_voxels: usize,
    /// Internal gas components, largest first (those above `min_report_ml`).
    pub components: Vec<Component>,
    /// Smaller components not listed one by one.
    pub small_components: usize,
    /// Voxels of tagged fluid (and of the air–fluid interface) counted in the lumen.
    pub fluid_voxels: usize,
    /// Whether the input was taken as a mask.
    pub from_mask: bool,
    /// Voxel of air (from the seed, or the colon's lowest voxel) the colon was grown from.
    pub seed_voxel: [usize; 3],
    /// The lumen's first and last voxel along each axis (its bounding box, both ends inside).
    pub extent: [[usize; 3]; 2],
}

/// One stretch of lumen candidates along x: voxels x0..x1 of row (j, k).
#[derive(Clone, Copy, Debug)]
struct Run {
    x0: u32,
    x1: u32,
}

/// All runs, row by row: the runs of row r = j + ny*k are `runs[row_start[r]..row_start[r+1]]`.
struct Runs {
    runs: Vec<Run>,
    row_start: Vec<u32>,
    /// Per run: sum of HU and count of voxels below −950 (zero for masks).
    hu_sum: Vec<i64>,
    dark: Vec<u32>,
    ny: usize,
}

impl Runs {
    fn row(&self, j: usize, k: usize) -> std::ops::Range<usize> {
        let r = j + self.ny * k;
        self.row_start[r] as usize..self.row_start[r + 1] as usize
    }
}

/// Segments the colon lumen from a CT (or takes it from a mask).
pub fn segment(vol: &Volume<i16>, opts: &SegmentOptions) -> Result<Segmentation> {
    let from_mask = opts.mask.unwrap_or_else(|| is_mask(vol));
    let fluid_hu = opts.fluid_hu.filter(|_| !from_mask);
    // Air, its statistics and the bright runs of tagged fluid, all in one pass over the values.
    let (runs, bright) = if from_mask { extract_runs(vol, Test::NonZero, None) } else { extract_runs(vol, Test::Below(opts.air_hu), fluid_hu) };
    let inside = if from_mask { vec![true; runs.runs.len()] } else { inside_body(&runs, vol.dims()) };
    let mut labels = UnionFind::new(runs.runs.len());
    connect_3d(&runs, &inside, vol.dims(), &mut labels);
    let (mut comps, run_comp) = component_stats(&runs, &inside, vol, &mut labels, from_mask);
    classify_lungs(&mut comps, from_mask);
    let colon = choose_colon(&comps, &runs, &run_comp, vol, opts, from_mask)?;
    comps[colon].kind = ComponentKind::Colon;
    let mut lumen = rasterize(&runs, &run_comp, colon, vol)?;
    let fluid_voxels = match bright {
        Some(bright) => add_tagged_fluid(&bright, &mut lumen, &air_extents(&runs, &run_comp, colon)),
        None => 0,
    };
    let seed_voxel = match opts.seed_mm {
        Some(mm) => voxel_of(vol, mm)?,
        None => lowest_voxel(&runs, &run_comp, colon, vol.dims()),
    };
    // Fluid may reach beyond the air's box; the mask is read again only then.
    let extent = match fluid_voxels {
        0 => colon_extent(&runs, &run_comp, colon, vol.dims()),
        _ => crate::field::bounding_box(&lumen, 0, |v| v != 0).map(|b| [b.lo, [0, 1, 2].map(|a| b.lo[a] + b.dims[a] - 1)]),
    }
    .ok_or_else(|| Error::invalid("the colon holds no voxels"))?;
    let lumen_voxels = comps[colon].voxels + fluid_voxels;
    let (components, small) = report(comps, colon, opts.min_report_ml);
    Ok(Segmentation { lumen, lumen_voxels, components, small_components: small, fluid_voxels, from_mask, seed_voxel, extent })
}

/// A volume holding only 0 and 1 is a mask, not a CT.
pub fn is_mask(vol: &Volume<i16>) -> bool {
    // Chunks tested without an early exit inside (vector code); a CT fails on its first chunk.
    let chunks = || vol.data().par_chunks(1 << 14);
    chunks().all(|c| c.iter().fold(true, |a, &v| a & (v as u16 <= 1))) && chunks().any(|c| c.iter().fold(false, |a, &v| a | (v == 1)))
}

/// Which values a pass collects runs of.
#[derive(Clone, Copy, Debug)]
enum Test {
    /// Below the threshold: air in a CT.
    Below(i16),
    /// At or above the threshold: tagged fluid (and bone).
    AtLeast(i16),
    /// Not 0: a mask's labels.
    NonZero,
}

impl Test {
    #[inline(always)]
    fn holds(self, v: i16) -> bool {
        match self {
            Test::Below(t) => v < t,
            Test::AtLeast(t) => v >= t,
            Test::NonZero => v != 0,
        }
    }
}

/// The runs of `test` (the air, with HU statistics when it is `Below`) and, with `bright`, the
/// runs at or above it, from one read of the values.
fn extract_runs(vol: &Volume<i16>, test: Test, bright: Option<i16>) -> (Runs, Option<Runs>) {
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
                    air.add_row(&words.0, |x0, x1| if stats { run_stats(row, x0, x1) } else { None });
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
        SliceRuns { runs: Vec::new(), counts: Vec::with_capacity(ny), hu_sum: Vec::new(), dark: Vec::new() }
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
        let mut out = Runs { runs: Vec::new(), row_start: vec![0], hu_sum: Vec::new(), dark: Vec::new(), ny };
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
fn run_stats(row: &[i16], x0: u32, x1: u32) -> Option<(i64, u32)> {
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
        (t, None) => a.iter_mut().zip(chunks).for_each(|(w, c)| *w = word_bits(c, t)),
        (t, Some(u)) => {
            for ((wa, wb), c) in a.iter_mut().zip(b.iter_mut()).zip(chunks) {
                (*wa, *wb) = (word_bits(c, t), word_bits(c, u));
            }
        }
    }
    if !rest.is_empty() {
        let bits = |t: Test| rest.iter().enumerate().fold(0u64, |w, (i, &v)| w | (t.holds(v) as u64) << i);
        a[row.len() / 64] = bits(tests.0);
        if let Some(u) = tests.1 {
            b[row.len() / 64] = bits(u);
        }
    }
}

/// The 64 bits of one word of [`row_bits`]: SSE2 compares, 16 voxels per mask.
#[inline(always)]
fn word_bits(v: &[i16; 64], test: Test) -> u64 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of x86_64; each load reads 8 of the 64 values.
        unsafe {
            let (t, invert) = match test {
                Test::Below(t) => (_mm_set1_epi16(t), 0),
                Test::AtLeast(t) => (_mm_set1_epi16(t), 0xFFFF),
                Test::NonZero => (_mm_setzero_si128(), 0xFFFF),
            };
            let cmp = |at: usize| {
                let x = _mm_loadu_si128(v.as_ptr().add(at) as *const __m128i);
                match test {
                    Test::NonZero => _mm_cmpeq_epi16(x, t),
                    _ => _mm_cmplt_epi16(x, t),
                }
            };
            (0..4).fold(0u64, |w, q| {
                let m = _mm_movemask_epi8(_mm_packs_epi16(cmp(16 * q), cmp(16 * q + 8))) as u32 ^ invert;
                w | (m as u64) << (16 * q)
            })
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        v.iter().enumerate().fold(0u64, |w, (b, &x)| w | (test.holds(x) as u64) << b)
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
fn for_overlaps(runs: &Runs, ra: std::ops::Range<usize>, rb: std::ops::Range<usize>, mut f: impl FnMut(usize, usize)) {
    let (mut a, mut b) = (ra.start, rb.start);
    while a < ra.end && b < rb.end {
        let (p, q) = (runs.runs[a], runs.runs[b]);
        if p.x0 < q.x1 && q.x0 < p.x1 {
            f(a, b);
        }
        if p.x1 < q.x1 {
            a += 1;
        } else {
            b += 1;
        }
    }
}

/// Step 2: per slice, runs 4-connected to the slice's border are outside air.
fn inside_body(runs: &Runs, dims: [usize; 3]) -> Vec<bool> {
    let [nx, ny, nz] = dims;
    let per_slice: Vec<Vec<bool>> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let first = runs.row(0, k).start;
            let last = runs.row(ny - 1, k).end;
            let mut uf = UnionFind::new(last - first);
            for j in 1..ny {
                for_overlaps(runs, runs.row(j - 1, k), runs.row(j, k), |a, b| uf.union(a - first, b - first));
            }
            let mut outside = vec![false; last - first];
            for j in 0..ny {
                for r in runs.row(j, k) {
                    let run = runs.runs[r];
                    if j == 0 || j == ny - 1 || run.x0 == 0 || run.x1 as usize == nx {
                        let root = uf.find(r - first);
                        outside[root] = true;
                    }
                }
            }
            (0..last - first).map(|r| !outside[uf.find(r)]).collect()
        })
        .collect();
    per_slice.into_iter().flatten().collect()
}

/// Step 3: 6-connected components of the inside runs.
fn connect_3d(runs: &Runs, inside: &[bool], dims: [usize; 3], uf: &mut UnionFind) {
    let [_, ny, nz] = dims;
    for k in 0..nz {
        for j in 0..ny {
            let here = runs.row(j, k);
            if here.is_empty() {
                continue;
            }
            if j > 0 {
                for_overlaps(runs, runs.row(j - 1, k), here.clone(), |a, b| {
                    if inside[a] && inside[b] {
                        uf.union(a, b)
                    }
                });
            }
            if k > 0 {
                for_overlaps(runs, runs.row(j, k - 1), here.clone(), |a, b| {
                    if inside[a] && inside[b] {
                        uf.union(a, b)
                    }
                });
            }
        }
    }
}

/// Per component statistics; returns the components and, per run, its component (or MAX).
fn component_stats(runs: &Runs, inside: &[bool], vol: &Volume<i16>, uf: &mut UnionFind, from_mask: bool) -> (Vec<Component>, Vec<u32>) {
    let [_, ny, nz] = vol.dims();
    let sp = vol.spacing();
    let mut comp_of_root = vec![u32::MAX; runs.runs.len()];
    let mut run_comp = vec![u32::MAX; runs.runs.len()];
    #[derive(Default, Clone)]
    struct Acc {
        n: usize,
        sum: [f64; 3],
        lo: [usize; 3],
        hi: [usize; 3],
        hu: i64,
        dark: u64,
    }
    let mut acc: Vec<Acc> = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                if !inside[r] {
                    continue;
                }
                let root = uf.find(r);
                if comp_of_root[root] == u32::MAX {
                    comp_of_root[root] = acc.len() as u32;
                    acc.push(Acc { lo: [usize::MAX; 3], ..Default::default() });
                }
                let c = comp_of_root[root];
                run_comp[r] = c;
                let a = &mut acc[c as usize];
                let run = runs.runs[r];
                let len = (run.x1 - run.x0) as usize;
                a.n += len;
                a.sum[0] += (run.x0 as f64 + run.x1 as f64 - 1.0) * 0.5 * len as f64;
                a.sum[1] += (j * len) as f64;
                a.sum[2] += (k * len) as f64;
                a.lo = [a.lo[0].min(run.x0 as usize), a.lo[1].min(j), a.lo[2].min(k)];
                a.hi = [a.hi[0].max(run.x1 as usize - 1), a.hi[1].max(j), a.hi[2].max(k)];
                a.hu += runs.hu_sum[r];
                a.dark += runs.dark[r] as u64;
            }
        }
    }
    let voxel_ml = sp[0] * sp[1] * sp[2] / 1000.0;
    let comps = acc
        .into_iter()
        .map(|a| {
            let n = a.n as f64;
            Component {
                voxels: a.n,
                volume_ml: n * voxel_ml,
                centroid_mm: [a.sum[0] / n * sp[0], a.sum[1] / n * sp[1], a.sum[2] / n * sp[2]],
                bbox_lo: a.lo,
                bbox_hi: a.hi,
                mean_hu: (!from_mask).then(|| a.hu as f64 / n),
                dark_fraction: (!from_mask).then(|| a.dark as f64 / n),
                kind: ComponentKind::Other,
            }
        })
        .collect();
    (comps, run_comp)
}

/// Step 4: lung parenchyma is air mixed with tissue; bowel gas is nearly pure air.
fn classify_lungs(comps: &mut [Component], from_mask: bool) {
    if from_mask {
        return;
    }
    for c in comps.iter_mut() {
        if c.volume_ml > 1.0 && c.dark_fraction.unwrap_or(1.0) < 0.3 {
            c.kind = ComponentKind::Lung;
        }
    }
}

/// Step 5: the seed's component, or the largest component that is not lung.
fn choose_colon(comps: &[Component], runs: &Runs, run_comp: &[u32], vol: &Volume<i16>, opts: &SegmentOptions, from_mask: bool) -> Result<usize> {
    if let Some(mm) = opts.seed_mm {
        let [i, j, k] = voxel_of(vol, mm)?;
        let at = vol.geometry().describe_point(mm);
        let row = runs.row(j, k);
        let hit = row.clone().find(|&r| runs.runs[r].x0 as usize <= i && i < runs.runs[r].x1 as usize);
        return match hit.map(|r| run_comp[r]) {
            Some(c) if c != u32::MAX && comps[c as usize].kind != ComponentKind::Lung => Ok(c as usize),
            Some(c) if c != u32::MAX => Err(Error::invalid(format!("the seed {at} lies in a lung, not in the colon"))),
            Some(_) => Err(Error::invalid(format!("the seed {at} lies in air outside the body"))),
            None => Err(Error::invalid(format!(
                "the seed {at} is not in air (HU {} ≥ {})",
                vol.get(i, j, k),
                opts.air_hu
            ))),
        };
    }
    comps
        .iter()
        .enumerate()
        .filter(|(_, c)| c.kind != ComponentKind::Lung)
        .max_by_key(|(_, c)| c.voxels)
        .map(|(i, _)| i)
        .filter(|&i| comps[i].volume_ml >= opts.min_colon_ml)
        .ok_or_else(|| {
            let biggest = comps.iter().filter(|c| c.kind != ComponentKind::Lung).map(|c| c.volume_ml).fold(0.0, f64::max);
            if from_mask {
                return Error::invalid(if comps.is_empty() {
                    "the mask holds no lumen: every voxel is 0".to_string()
                } else {
                    format!("the mask's largest lumen region is {biggest:.1} ml, too small for a colon (at least {} ml expected)", opts.min_colon_ml)
                });
            }
            Error::invalid(format!(
                "no colon lumen found: the largest gas inside the body, lungs left out, is {biggest:.1} ml (at least {} ml expected; is this a CT colonography? a --seed picks any gas)",
                opts.min_colon_ml
            ))
        })
}

fn voxel_of(vol: &Volume<i16>, mm: DVec3) -> Result<[usize; 3]> {
    let ijk = vol.geometry().local_to_index(mm).round();
    if !vol.geometry().contains_index(ijk) {
        return Err(Error::invalid(format!("the seed {} lies outside the volume", vol.geometry().describe_point(mm))));
    }
    Ok([ijk.x as usize, ijk.y as usize, ijk.z as usize])
}

/// Per row (j + ny·k): the x range [lo, hi) that the colon's air spans in it; (u32::MAX, 0)
/// where none.
fn air_extents(runs: &Runs, run_comp: &[u32], colon: usize) -> Vec<(u32, u32)> {
    (0..runs.row_start.len() - 1)
        .map(|row| {
            let rs = runs.row_start[row] as usize..runs.row_start[row + 1] as usize;
            let mut ext = (u32::MAX, 0);
            for r in rs.filter(|&r| run_comp[r] == colon as u32) {
                ext = (ext.0.min(runs.runs[r].x0), ext.1.max(runs.runs[r].x1));
            }
            ext
        })
        .collect()
}

fn rasterize(runs: &Runs, run_comp: &[u32], colon: usize, vol: &Volume<i16>) -> Result<Volume<u8>> {
    let [nx, ny, _] = vol.dims();
    let mut lumen = Volume::filled(vol.geometry().clone(), 0u8)?;
    lumen.data_mut().par_chunks_mut(nx * ny).enumerate().for_each(|(k, slab)| {
        for j in 0..ny {
            for r in runs.row(j, k) {
                if run_comp[r] == colon as u32 {
                    let run = runs.runs[r];
                    slab[j * nx + run.x0 as usize..j * nx + run.x1 as usize].fill(1);
                }
            }
        }
    });
    Ok(lumen)
}

/// Tagged fluid (paper-era scans had none; CT colonography today tags residual fluid with oral
/// contrast): bright pools lying in the colon under a flat level. A 6-connected component of
/// voxels at or above `fluid_hu` joins the lumen when enough of it lies within two voxels of
/// the colon's air, and so does the thin partial-volume layer between air and fluid (voxels
/// beside the fluid and within two voxels of the air). Bone is as bright, but never that close to the colon's air: the wall and fat
/// lie between. Returns the voxels added.
fn add_tagged_fluid(runs: &Runs, lumen: &mut Volume<u8>, air_rows: &[(u32, u32)]) -> usize {
    const AIR: u8 = 1;
    const FLUID: u8 = 2;
    const LAYER: u8 = 3;
    /// Fewer contacts than this is a brush past the wall, not a pool.
    const MIN_CONTACTS: usize = 20;
    if runs.runs.is_empty() {
        return 0;
    }
    let all = vec![true; runs.runs.len()];
    let mut uf = UnionFind::new(runs.runs.len());
    connect_3d(runs, &all, lumen.dims(), &mut uf);
    let g = lumen.geometry().clone();
    let [nx, ny, nz] = g.dims;
    let air_near = |lumen: &Volume<u8>, i: usize, j: usize, k: usize| {
        (1..=2).any(|d| {
            face_neighbours(i, j, k, d)
                .iter()
                .any(|&(a, b, c)| a < nx && b < ny && c < nz && lumen.get(a, b, c) == AIR)
        })
    };
    // Most bright runs are bone, far from the colon: a run can touch air within two voxels
    // only if its own row or a row up to two steps along y or z has air near its x range.
    let may_touch_air = |x: std::ops::Range<u32>, j: usize, k: usize| {
        let rows = [(j, k), (j.wrapping_sub(1), k), (j + 1, k), (j.wrapping_sub(2), k), (j + 2, k), (j, k.wrapping_sub(1)), (j, k + 1), (j, k.wrapping_sub(2)), (j, k + 2)];
        rows.iter().any(|&(b, c)| b < ny && c < nz && {
            let (lo, hi) = air_rows[b + ny * c];
            lo < x.end + 2 && hi + 2 > x.start
        })
    };
    let mut contacts = vec![0usize; runs.runs.len()];
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                let run = runs.runs[r];
                if !may_touch_air(run.x0..run.x1, j, k) {
                    continue;
                }
                let n = (run.x0..run.x1).filter(|&i| air_near(lumen, i as usize, j, k)).count();
                if n > 0 {
                    contacts[uf.find(r)] += n;
                }
            }
        }
    }
    let mut added = 0;
    let mut pools = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                if contacts[uf.find(r)] >= MIN_CONTACTS {
                    let run = runs.runs[r];
                    for i in run.x0 as usize..run.x1 as usize {
                        lumen.set(i, j, k, FLUID);
                    }
                    added += (run.x1 - run.x0) as usize;
                    pools.push((run, j, k));
                }
            }
        }
    }
    if added == 0 {
        return 0;
    }
    // The interface: voxels beside fluid and within two voxels of the air.
    let beside = |lumen: &Volume<u8>, i: usize, j: usize, k: usize, what: u8| {
        face_neighbours(i, j, k, 1)
            .iter()
            .any(|&(a, b, c)| a < nx && b < ny && c < nz && lumen.get(a, b, c) == what)
    };
    let mut layer = Vec::new();
    for &(run, j, k) in &pools {
        for i in run.x0 as usize..run.x1 as usize {
            for (a, b, c) in face_neighbours(i, j, k, 1) {
                if a < nx && b < ny && c < nz && lumen.get(a, b, c) == 0 && (beside(lumen, a, b, c, AIR) || air_near(lumen, a, b, c)) {
                    layer.push(g.index(a, b, c));
                }
            }
        }
    }
    for &idx in &layer {
        if lumen.data()[idx] == 0 {
            lumen.data_mut()[idx] = LAYER;
            added += 1;
        }
    }
    // Back to 0/1: only the pools and the layer hold other labels.
    for (run, j, k) in pools {
        let at = g.index(run.x0 as usize, j, k);
        lumen.data_mut()[at..at + (run.x1 - run.x0) as usize].fill(1);
    }
    for idx in layer {
        lumen.data_mut()[idx] = 1;
    }
    added
}

/// The six voxels `d` steps away along the axes; below zero wraps to a huge index, which the
/// callers' bounds tests reject.
fn face_neighbours(i: usize, j: usize, k: usize, d: usize) -> [(usize, usize, usize); 6] {
    [(i.wrapping_sub(d), j, k), (i + d, j, k), (i, j.wrapping_sub(d), k), (i, j + d, k), (i, j, k.wrapping_sub(d)), (i, j, k + d)]
}

/// The colon voxel lowest in k (first slice), middle of its first run: used as the seed when
/// none was given.
fn lowest_voxel(runs: &Runs, run_comp: &[u32], colon: usize, dims: [usize; 3]) -> [usize; 3] {
    let [_, ny, nz] = dims;
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                if run_comp[r] == colon as u32 {
                    let run = runs.runs[r];
                    return [((run.x0 + run.x1) / 2) as usize, j, k];
                }
            }
        }
    }
    [0, 0, 0]
}

/// The first and last voxel along each axis of the colon's runs.
fn colon_extent(runs: &Runs, run_comp: &[u32], colon: usize, dims: [usize; 3]) -> Option<[[usize; 3]; 2]> {
    let [_, ny, nz] = dims;
    let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k).filter(|&r| run_comp[r] == colon as u32) {
                let run = runs.runs[r];
                lo = [lo[0].min(run.x0 as usize), lo[1].min(j), lo[2].min(k)];
                hi = [hi[0].max(run.x1 as usize - 1), hi[1].max(j), hi[2].max(k)];
            }
        }
    }
    (lo[0] != usize::MAX).then_some([lo, hi])
}

/// Largest first, the colon marked; tiny components are only counted.
fn report(comps: Vec<Component>, colon: usize, min_ml: f64) -> (Vec<Component>, usize) {
    let mut listed: Vec<Component> = Vec::new();
    let mut small = 0;
    for (i, c) in comps.into_iter().enumerate() {
        if i == colon || c.volume_ml >= min_ml {
            listed.push(c);
        } else {
            small += 1;
        }
    }
    listed.sort_by_key(|c| std::cmp::Reverse(c.voxels));
    (listed, small)
}

/// Union-find over run indices, with path halving and union by size.
struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind { parent: (0..n as u32).collect(), size: vec![1; n] }
    }
    fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] as usize != x {
            let p = self.parent[x] as usize;
            self.parent[x] = self.parent[p];
            x = p;
        }
        x
    }
    fn union(&mut self, a: usize, b: usize) {
        let (mut ra, mut rb) = (self.find(a), self.find(b));
        if ra == rb {
            return;
        }
        if self.size[ra] < self.size[rb] {
            std::mem::swap(&mut ra, &mut rb);
        }
        self.parent[rb] = ra as u32;
        self.size[ra] += self.size[rb];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;

    /// The runs of one row found through its bits, for both tests at once, are the runs of the
    /// plain per-voxel test: rows of many lengths (whole words and a remainder), runs at both
    /// ends and across word boundaries, values at and beside the thresholds.
    #[test]
    fn row_bits_give_the_runs_of_each_test() {
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let values = [-1000i16, -501, -500, -499, 0, 1, 199, 200, 201, 1500, i16::MIN, i16::MAX];
        for len in [1usize, 5, 63, 64, 65, 127, 128, 130, 200, 512, 517] {
            for _ in 0..20 {
                // Stretches of one value, so that runs are long enough to cross words.
                let mut row = Vec::with_capacity(len);
                while row.len() < len {
                    let v = values[(next() % values.len() as u64) as usize];
                    let n = 1 + (next() % 90) as usize;
                    row.extend(std::iter::repeat_n(v, n.min(len - row.len())));
                }
                for tests in [(Test::Below(-500), Some(Test::AtLeast(200))), (Test::NonZero, None), (Test::AtLeast(-500), Some(Test::NonZero))] {
                    let mut words = (vec![u64::MAX; len.div_ceil(64)], vec![u64::MAX; len.div_ceil(64)]);
                    row_bits(&row, tests, &mut words);
                    let found = |w: &[u64]| {
                        let mut v = Vec::new();
                        runs_of_bits(w, |a, b| v.push(a as usize..b as usize));
                        v
                    };
                    let want = |t: Test| crate::volume::runs_where(&row, |v| t.holds(v)).collect::<Vec<_>>();
                    assert_eq!(found(&words.0), want(tests.0), "{tests:?} {row:?}");
                    if let Some(u) = tests.1 {
                        assert_eq!(found(&words.1), want(u), "{tests:?} {row:?}");
                    }
                }
            }
        }
    }

    /// A body of tissue (40 HU) in outside air, with a big gas tube, a small gas pocket, and
    /// a "lung" of −850 HU.
    fn toy() -> Volume<i16> {
        let g = Geometry::new([60, 50, 40], [1.0, 1.0, 1.5], [0.0; 3]).unwrap();
        let mut v = Volume::filled(g, -1000i16).unwrap();
        for k in 0..40 {
            for j in 0..50 {
                for i in 0..60 {
                    let body = ((i as f64 - 30.0) / 27.0).powi(2) + ((j as f64 - 25.0) / 22.0).powi(2) < 1.0;
                    if !body {
                        continue;
                    }
                    let tube = (i as f64 - 20.0).powi(2) + (j as f64 - 25.0).powi(2) < 36.0 && (3..37).contains(&k);
                    let pocket = (i as f64 - 40.0).powi(2) + (j as f64 - 20.0).powi(2) + (k as f64 - 10.0).powi(2) < 6.0;
                    let lung = (i as f64 - 40.0).powi(2) + (j as f64 - 30.0).powi(2) < 30.0 && k >= 30;
                    let hu = if tube || pocket { -1000 } else if lung { -850 } else { 40 };
                    v.set(i, j, k, hu);
                }
            }
        }
        v
    }

    /// The toy's tube holds 5.6 ml of gas: below the default minimum for a colon.
    fn toy_options() -> SegmentOptions {
        SegmentOptions { min_colon_ml: 1.0, ..Default::default() }
    }

    #[test]
    fn too_little_gas_is_no_colon() {
        let e = segment(&toy(), &SegmentOptions::default()).unwrap_err().to_string();
        assert!(e.contains("no colon lumen") && e.contains("5.6 ml"), "{e}");
    }

    #[test]
    fn finds_the_tube_not_the_pocket_lung_or_outside() {
        let v = toy();
        let s = segment(&v, &toy_options()).unwrap();
        assert!(!s.from_mask);
        assert_eq!(s.lumen.get(20, 25, 20), 1);
        assert_eq!(s.lumen.get(40, 20, 10), 0, "small pocket taken");
        assert_eq!(s.lumen.get(40, 30, 35), 0, "lung taken");
        assert_eq!(s.lumen.get(0, 0, 0), 0, "outside air taken");
        assert_eq!(s.lumen_voxels, s.lumen.data().iter().filter(|&&m| m == 1).count());
        assert!(s.components.iter().any(|c| c.kind == ComponentKind::Lung));
        assert_eq!(s.components[0].kind, ComponentKind::Colon);
        assert_eq!(s.seed_voxel[2], 3, "automatic seed at the lowest slice of the colon");
    }

    #[test]
    fn seed_picks_its_component_and_bad_seeds_fail() {
        let v = toy();
        let seeded = SegmentOptions { seed_mm: Some(DVec3::new(40.0, 20.0, 15.0)), ..Default::default() };
        let s = segment(&v, &seeded).unwrap();
        assert_eq!(s.lumen.get(40, 20, 10), 1);
        assert_eq!(s.lumen.get(20, 25, 20), 0);
        let in_tissue = SegmentOptions { seed_mm: Some(DVec3::new(30.0, 10.0, 30.0)), ..Default::default() };
        assert!(segment(&v, &in_tissue).unwrap_err().to_string().contains("not in air"));
        let outside = SegmentOptions { seed_mm: Some(DVec3::new(0.0, 0.0, 0.0)), ..Default::default() };
        assert!(segment(&v, &outside).unwrap_err().to_string().contains("outside the body"));
        let beyond = SegmentOptions { seed_mm: Some(DVec3::new(500.0, 0.0, 0.0)), ..Default::default() };
        assert!(segment(&v, &beyond).is_err());
    }

    #[test]
    fn mask_input_is_detected_and_used() {
        let v = toy();
        let s = segment(&v, &toy_options()).unwrap();
        let mask = s.lumen.map(|m| m as i16);
        let again = segment(&mask, &toy_options()).unwrap();
        assert!(again.from_mask);
        assert_eq!(again.lumen, s.lumen);
    }

    #[test]
    fn no_gas_is_an_error() {
        let g = Geometry::new([10, 10, 10], [1.0; 3], [0.0; 3]).unwrap();
        let v = Volume::filled(g, 40i16).unwrap();
        assert!(segment(&v, &SegmentOptions::default()).unwrap_err().to_string().contains("no colon"));
    }
}
