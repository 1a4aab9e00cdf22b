//! Steps 2–4: the gas components inside the body. Outside air is found per axial slice
//! ([`inside_body`]), the rest joined in 3D ([`connect_3d`]), lungs told from bowel gas
//! ([`classify_lungs`]) and rectal tubes taken out ([`tube`]); the user's points are looked up
//! in them, and they are listed in the end ([`report`]).

use glam::DVec3;
use rayon::prelude::*;

use super::{
    Component, ComponentKind, SegmentOptions,
    runs::{Runs, extract_runs, for_overlaps, run_stats, run_voxels},
    tube::{self, Tube},
};
use crate::{Error, Result, Volume, simd::Test};

/// What steps 1–4 found: the air's runs (and the bright runs of tagged fluid), the gas
/// components inside the body and the rectal tubes.
pub(super) struct Found {
    pub(super) runs: Runs,
    /// The runs at or above the fluid's HU (None: no fluid is looked for).
    pub(super) bright: Option<Runs>,
    pub(super) comps: Vec<Component>,
    /// Per run: its component (u32::MAX: outside air, a rectal tube's air).
    pub(super) run_comp: Vec<u32>,
    pub(super) tubes: Vec<Tube>,
}

/// The gas components of the user's points: the seeds' and those of the points to exclude.
pub(super) struct Points {
    pub(super) seeds: Vec<usize>,
    pub(super) exclude: Vec<usize>,
}

/// Steps 1–4 on a scan (or a mask, `from_mask`: all of it is inside, no lungs, no tube).
pub(super) fn find(
    vol: &Volume<i16>,
    opts: &SegmentOptions,
    fluid_hu: Option<i16>,
    from_mask: bool,
) -> Found {
    // Air, its statistics and the bright runs of tagged fluid, all in one pass over the values.
    let (mut runs, bright) = if from_mask {
        extract_runs(vol, Test::NonZero, None)
    } else {
        extract_runs(vol, Test::Below(opts.air_hu), fluid_hu)
    };
    let mut inside = if from_mask {
        vec![true; runs.runs.len()]
    } else {
        let mut inside = inside_body(&runs, vol.dims());
        reclaim_cut_gas(&runs, &mut inside, vol.dims());
        inside
    };
    let mut labels = UnionFind::new(runs.runs.len());
    connect_3d(&runs, &inside, vol.dims(), &mut labels);
    let (mut comps, mut run_comp) = component_stats(&runs, &inside, vol, &mut labels, from_mask);
    classify_lungs(&mut comps, from_mask);
    if let Some(split) = parenchyma_joined(&runs, &inside, &comps, &run_comp, vol) {
        // Joined again with the parenchyma kept apart: it is a lung of its own.
        let apart = split.apart;
        (runs, inside) = (split.runs, split.inside);
        let mut labels = UnionFind::new(runs.runs.len());
        connect_3d_where(&runs, vol.dims(), &mut labels, |a, b| {
            inside[a] && inside[b] && apart[a] == apart[b]
        });
        (comps, run_comp) = component_stats(&runs, &inside, vol, &mut labels, from_mask);
        classify_lungs(&mut comps, from_mask);
    }
    let tubes = if from_mask {
        Vec::new()
    } else {
        rectal_tubes(
            &runs,
            &inside,
            &run_comp,
            &comps,
            vol,
            opts.chain.min_segment_ml,
        )
    };
    for t in &tubes {
        // Its air is the outside's, carried in.
        t.runs.iter().for_each(|&r| run_comp[r] = u32::MAX);
    }
    Found {
        runs,
        bright,
        comps,
        run_comp,
        tubes,
    }
}

impl Found {
    /// Whether component `c` (u32::MAX: none) is gas: inside the body, not lung.
    pub(super) fn is_gas(&self, c: u32) -> bool {
        is_gas(&self.comps, c)
    }

    /// Whether run `r` is gas.
    pub(super) fn gas_run(&self, r: usize) -> bool {
        self.is_gas(self.run_comp[r])
    }

    /// The gas components of the user's seeds and points to exclude, or an error that says
    /// why a point is in none.
    pub(super) fn user_points(&self, vol: &Volume<i16>, opts: &SegmentOptions) -> Result<Points> {
        let gas_at = |what: &str, mm: &DVec3| {
            gas_component(
                &self.comps,
                &self.runs,
                &self.run_comp,
                vol,
                *mm,
                what,
                opts,
            )
        };
        let seeds = opts
            .seeds_mm
            .iter()
            .map(|mm| gas_at("the seed", mm))
            .collect::<Result<Vec<_>>>()?;
        let exclude = opts
            .exclude_mm
            .iter()
            .map(|mm| gas_at("the point to exclude", mm))
            .collect::<Result<Vec<_>>>()?;
        Ok(Points { seeds, exclude })
    }

    /// The error when no gas is big enough to be a colon ([`no_colon`]).
    pub(super) fn no_colon(&self, opts: &SegmentOptions, from_mask: bool) -> Error {
        no_colon(&self.comps, opts, from_mask)
    }
}

fn is_gas(comps: &[Component], c: u32) -> bool {
    c != u32::MAX && comps[c as usize].kind != ComponentKind::Lung
}

/// The rectal tubes in the gas components ([`tube::find`]) that open into the rectum: a
/// colon segment's gas (`min_segment_ml`) beyond the tip.
fn rectal_tubes(
    runs: &Runs,
    inside: &[bool],
    run_comp: &[u32],
    comps: &[Component],
    vol: &Volume<i16>,
    min_segment_ml: f64,
) -> Vec<Tube> {
    let voxel_ml = super::voxel_ml(vol);
    let mut tubes = tube::find(
        runs,
        inside,
        run_comp,
        |c| is_gas(comps, c),
        vol.dims(),
        vol.spacing(),
        tube::inferior_slice(vol),
    );
    // A tube opens into the rectum: a colon segment's gas beyond its tip.
    tubes.retain(|t| {
        let beyond = comps[t.comp as usize]
            .voxels
            .saturating_sub(run_voxels(runs, &t.runs));
        beyond as f64 * voxel_ml >= min_segment_ml
    });
    tubes
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
                for_overlaps(runs, runs.row(j - 1, k), runs.row(j, k), |a, b| {
                    uf.union(a - first, b - first)
                });
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

/// Step 2, second half: gas the side of the volume cuts. Bowel gas that reaches the
/// scan's edge touches a slice's border, so step 2 takes it for outside air; but in 3D it is
/// cut off from the outside air around the body (tissue encloses it everywhere but at the
/// edge). Of the 6-connected pieces of what step 2 found outside, those other than the
/// largest (the air around the body, joined from slice to slice) that reach the slices'
/// border on one side, or on two that meet at a corner, are inside after all. A piece that
/// reaches opposite sides lies across the scan (air under a table as wide as the field of
/// view) and stays outside. A colon cut by the scan's side would otherwise lose that gas
/// without a word.
fn reclaim_cut_gas(runs: &Runs, inside: &mut [bool], dims: [usize; 3]) {
    let [nx, ny, nz] = dims;
    let outside: Vec<bool> = inside.iter().map(|&i| !i).collect();
    let mut uf = UnionFind::new(runs.runs.len());
    connect_3d(runs, &outside, dims, &mut uf);
    let mut voxels = vec![0usize; runs.runs.len()];
    // Per piece, the sides of the slices it reaches: bits 0–3 for x = 0, x = nx − 1, y = 0,
    // y = ny − 1.
    let mut sides = vec![0u8; runs.runs.len()];
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                if !outside[r] {
                    continue;
                }
                let run = runs.runs[r];
                let root = uf.find(r);
                voxels[root] += (run.x1 - run.x0) as usize;
                sides[root] |= u8::from(run.x0 == 0)
                    | u8::from(run.x1 as usize == nx) << 1
                    | u8::from(j == 0) << 2
                    | u8::from(j == ny - 1) << 3;
            }
        }
    }
    let Some(air) = (0..voxels.len()).max_by_key(|&r| voxels[r]) else {
        return;
    };
    let across = |s: u8| s & 0b0011 == 0b0011 || s & 0b1100 == 0b1100;
    for r in 0..runs.runs.len() {
        if outside[r] {
            let root = uf.find(r);
            if root != air && !across(sides[root]) {
                inside[r] = true;
            }
        }
    }
}

/// Step 3: 6-connected components of the inside runs.
pub(super) fn connect_3d(runs: &Runs, inside: &[bool], dims: [usize; 3], uf: &mut UnionFind) {
    connect_3d_where(runs, dims, uf, |a, b| inside[a] && inside[b]);
}

/// Joins face-touching runs where `joins(a, b)`.
fn connect_3d_where(
    runs: &Runs,
    dims: [usize; 3],
    uf: &mut UnionFind,
    joins: impl Fn(usize, usize) -> bool,
) {
    let [_, ny, nz] = dims;
    for k in 0..nz {
        for j in 0..ny {
            let here = runs.row(j, k);
            if here.is_empty() {
                continue;
            }
            if j > 0 {
                for_overlaps(runs, runs.row(j - 1, k), here.clone(), |a, b| {
                    if joins(a, b) {
                        uf.union(a, b)
                    }
                });
            }
            if k > 0 {
                for_overlaps(runs, runs.row(j, k - 1), here.clone(), |a, b| {
                    if joins(a, b) {
                        uf.union(a, b)
                    }
                });
            }
        }
    }
}

/// Lung parenchyma that thick slices join to bowel gas in one component (ml).
const PARENCHYMA_APART_ML: f64 = 100.0;
/// Within this distance (mm) of bowel gas's dark middle lies its partial-volume rim: along
/// each axis the nearest whole number of voxels, at least one. A slice's rim is the slice
/// next to it: rounded up, 2.5 mm slices reached two, 5 mm into the lung over the dome.
const RIM_MM: f64 = 3.0;

/// The air's runs with lung parenchyma cut out of them as runs of their own; per run, whether
/// it is inside the body and whether it is parenchyma.
struct Split {
    runs: Runs,
    inside: Vec<bool>,
    apart: Vec<bool>,
}

/// Lung parenchyma joined to bowel gas: the runs with it cut out as runs of their own; None
/// where there is none
/// ([`PARENCHYMA_APART_ML`]). Through thick slices the diaphragm under a lung base averages to
/// air over the splenic flexure's gas, and the two become one component, gas enough to pass
/// for bowel as a whole (`ctc/prone-tagged` in 2.5 or 3 mm slices: 3 940–3 970 ml, 0.66 of it
/// dark, the left lung's 720 ml in it). Bowel gas is dark (below −950 HU) but for a
/// partial-volume rim about a voxel thick; lung parenchyma is nowhere dark. So the voxels of a
/// non-lung component farther than [`RIM_MM`] from any run with a dark voxel, joined, are
/// parenchyma where they hold this much (in real colon compartments of the 1 mm exam such
/// voxels make a few ml). Voxels, not whole runs: a run of parenchyma over the colon's dome
/// reaches past it for centimetres, and counted whole it kept 30–63 ml of the lung base in
/// the colon (the same exam in 3 and 2.5 mm slices).
fn parenchyma_joined(
    runs: &Runs,
    inside: &[bool],
    comps: &[Component],
    run_comp: &[u32],
    vol: &Volume<i16>,
) -> Option<Split> {
    let dims = vol.dims();
    // Only a component larger than the parenchyma looked for can hold it.
    let bowel = |r: usize| {
        inside[r]
            && run_comp[r] != u32::MAX
            && comps[run_comp[r] as usize].kind != ComponentKind::Lung
            && comps[run_comp[r] as usize].volume_ml > PARENCHYMA_APART_ML
    };
    let (far, run_of) = far_from_dark(runs, dims, vol.spacing(), &bowel);
    let sp = vol.spacing();
    let voxel_ml = sp[0] * sp[1] * sp[2] / 1000.0;
    let all: Vec<usize> = (0..far.runs.len()).collect();
    if run_voxels(&far, &all) as f64 * voxel_ml < PARENCHYMA_APART_ML {
        return None;
    }
    let mut blobs = UnionFind::new(far.runs.len());
    connect_3d_where(&far, dims, &mut blobs, |_, _| true);
    let mut voxels = vec![0usize; far.runs.len()];
    for p in 0..far.runs.len() {
        voxels[blobs.find(p)] += run_voxels(&far, &[p]);
    }
    let apart: Vec<bool> = (0..far.runs.len())
        .map(|p| voxels[blobs.find(p)] as f64 * voxel_ml >= PARENCHYMA_APART_ML)
        .collect();
    if !apart.iter().any(|&a| a) {
        return None;
    }
    let mut cut: Vec<Vec<(u32, u32)>> = vec![Vec::new(); runs.runs.len()];
    for (p, &r) in run_of.iter().enumerate().filter(|&(p, _)| apart[p]) {
        cut[r].push((far.runs[p].x0, far.runs[p].x1));
    }
    Some(cut_out(runs, inside, &cut, vol))
}

/// `runs` with the stretches `cut[r]` of each run r (in x order, inside it) made runs of their
/// own (`apart`). The pieces' HU statistics are read again.
fn cut_out(runs: &Runs, inside: &[bool], cut: &[Vec<(u32, u32)>], vol: &Volume<i16>) -> Split {
    let [nx, ny, nz] = vol.dims();
    let mut out = Runs::empty(ny);
    let (mut inside_out, mut apart) = (Vec::new(), Vec::new());
    for k in 0..nz {
        for j in 0..ny {
            let values = &vol.data()[nx * (j + ny * k)..nx * (j + ny * k + 1)];
            for r in runs.row(j, k) {
                let run = runs.runs[r];
                let mut push = |x0: u32, x1: u32, is_cut: bool, whole: bool| {
                    if x0 >= x1 {
                        return;
                    }
                    out.runs.push(super::runs::Run { x0, x1 });
                    let (sum, dark) = if whole {
                        (runs.hu_sum[r], runs.dark[r])
                    } else {
                        run_stats(values, x0, x1).unwrap_or((0, 0))
                    };
                    out.hu_sum.push(sum);
                    out.dark.push(dark);
                    inside_out.push(inside[r]);
                    apart.push(is_cut);
                };
                if cut[r].is_empty() {
                    push(run.x0, run.x1, false, true);
                    continue;
                }
                let mut x = run.x0;
                for &(c0, c1) in &cut[r] {
                    push(x, c0, false, false);
                    push(c0, c1, true, false);
                    x = c1;
                }
                push(x, run.x1, false, false);
            }
            out.row_start.push(out.runs.len() as u32);
        }
    }
    Split {
        runs: out,
        inside: inside_out,
        apart,
    }
}

/// The stretches of runs of `of` with no dark voxel that lie farther than [`RIM_MM`] from
/// any run of `of` with one (each axis's distance), as runs of their own, and the run each
/// is a stretch of.
fn far_from_dark(
    runs: &Runs,
    dims: [usize; 3],
    sp: [f64; 3],
    of: &impl Fn(usize) -> bool,
) -> (Runs, Vec<usize>) {
    let [_, ny, nz] = dims;
    let reach = sp.map(|s| (RIM_MM / s).round().max(1.0) as i64);
    // The x-extents of the dark runs, row by row (those of row r at `dark[start[r]..start[r + 1]]`).
    let mut dark = Vec::new();
    let mut start = Vec::with_capacity(ny * nz + 1);
    for k in 0..nz {
        for j in 0..ny {
            start.push(dark.len());
            let extents = runs.row(j, k).filter(|&r| of(r) && runs.dark[r] > 0);
            dark.extend(extents.map(|r| (runs.runs[r].x0, runs.runs[r].x1)));
        }
    }
    start.push(dark.len());
    let around: Vec<(i64, i64)> = (-reach[2]..=reach[2])
        .flat_map(|dk| (-reach[1]..=reach[1]).map(move |dj| (dj, dk)))
        .collect();
    // The stretches of x0..x1 within reach of a dark run in the rows around (j, k).
    let mut near: Vec<(i64, i64)> = Vec::new();
    let nears = |x0: u32, x1: u32, j: usize, k: usize, near: &mut Vec<(i64, i64)>| {
        near.clear();
        let (lo, hi) = (x0 as i64 - reach[0], x1 as i64 + reach[0]);
        for &(dj, dk) in &around {
            let (jj, kk) = (j as i64 + dj, k as i64 + dk);
            if jj < 0 || kk < 0 || jj >= ny as i64 || kk >= nz as i64 {
                continue;
            }
            let r = jj as usize + ny * kk as usize;
            let row = &dark[start[r]..start[r + 1]];
            let at = row.partition_point(|&(_, e)| (e as i64) <= lo);
            for &(e0, e1) in row[at..].iter().take_while(|&&(e0, _)| (e0 as i64) < hi) {
                near.push((e0 as i64 - reach[0], e1 as i64 + reach[0]));
            }
        }
        near.sort_unstable();
    };
    let mut far = Runs::empty(ny);
    let mut run_of = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                if !of(r) || runs.dark[r] > 0 {
                    continue;
                }
                let run = runs.runs[r];
                nears(run.x0, run.x1, j, k, &mut near);
                // What the near stretches leave of the run, in x order.
                let mut x = run.x0 as i64;
                let mut push = |a: i64, b: i64| {
                    if a < b {
                        far.runs.push(super::runs::Run {
                            x0: a as u32,
                            x1: b as u32,
                        });
                        far.hu_sum.push(0);
                        far.dark.push(0);
                        run_of.push(r);
                    }
                };
                for &(a, b) in &near {
                    push(x, a.min(run.x1 as i64));
                    x = x.max(b);
                }
                push(x, run.x1 as i64);
            }
            far.row_start.push(far.runs.len() as u32);
        }
    }
    (far, run_of)
}

/// Per component statistics; returns the components and, per run, its component (or MAX).
fn component_stats(
    runs: &Runs,
    inside: &[bool],
    vol: &Volume<i16>,
    uf: &mut UnionFind,
    from_mask: bool,
) -> (Vec<Component>, Vec<u32>) {
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
                    acc.push(Acc {
                        lo: [usize::MAX; 3],
                        ..Default::default()
                    });
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
                a.hi = [
                    a.hi[0].max(run.x1 as usize - 1),
                    a.hi[1].max(j),
                    a.hi[2].max(k),
                ];
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
                centroid_mm: [
                    a.sum[0] / n * sp[0],
                    a.sum[1] / n * sp[1],
                    a.sum[2] / n * sp[2],
                ],
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

/// The gas component holding a point the user gave (`what`: "the seed", ...), or an error
/// that says why there is none.
fn gas_component(
    comps: &[Component],
    runs: &Runs,
    run_comp: &[u32],
    vol: &Volume<i16>,
    mm: DVec3,
    what: &str,
    opts: &SegmentOptions,
) -> Result<usize> {
    let at = vol.geometry().describe_point(mm);
    let [i, j, k] = voxel_of(vol, mm)
        .ok_or_else(|| Error::invalid(format!("{what} {at} lies outside the volume")))?;
    match runs.at([i, j, k]).map(|r| run_comp[r]) {
        Some(c) if c != u32::MAX && comps[c as usize].kind != ComponentKind::Lung => Ok(c as usize),
        Some(c) if c != u32::MAX => Err(Error::invalid(format!(
            "{what} {at} lies in a lung, not in the bowel"
        ))),
        Some(_) => Err(Error::invalid(format!(
            "{what} {at} lies in air outside the body"
        ))),
        None => Err(Error::invalid(format!(
            "{what} {at} is not in gas (HU {} ≥ {})",
            vol.get(i, j, k),
            opts.air_hu
        ))),
    }
}

/// The error when no gas is big enough to be a colon.
fn no_colon(comps: &[Component], opts: &SegmentOptions, from_mask: bool) -> Error {
    let biggest = comps
        .iter()
        .filter(|c| c.kind != ComponentKind::Lung)
        .map(|c| c.volume_ml)
        .fold(0.0, f64::max);
    if from_mask {
        return Error::invalid(if comps.is_empty() {
            "the mask holds no lumen: every voxel is 0".to_string()
        } else {
            format!(
                "the mask's largest lumen region is {biggest:.1} ml, too small for a colon (at least {} ml expected)",
                opts.min_colon_ml
            )
        });
    }
    Error::invalid(format!(
        "no colon lumen found: the largest gas inside the body, lungs left out, is {biggest:.1} ml (at least {} ml expected; is this a CT colonography? a --seed picks any gas)",
        opts.min_colon_ml
    ))
}

fn voxel_of(vol: &Volume<i16>, mm: DVec3) -> Option<[usize; 3]> {
    let ijk = vol.geometry().local_to_index(mm).round();
    vol.geometry()
        .contains_index(ijk)
        .then_some([ijk.x as usize, ijk.y as usize, ijk.z as usize])
}

/// Largest first; tiny components are only counted.
pub(super) fn report(comps: Vec<Component>, min_ml: f64) -> (Vec<Component>, usize) {
    let mut listed: Vec<Component> = Vec::new();
    let mut small = 0;
    for c in comps {
        if c.kind == ComponentKind::Colon || c.volume_ml >= min_ml {
            listed.push(c);
        } else {
            small += 1;
        }
    }
    listed.sort_by_key(|c| std::cmp::Reverse(c.voxels));
    (listed, small)
}

/// Union-find over run indices, with path halving and union by size.
pub(super) struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    pub(super) fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }
    pub(super) fn find(&mut self, mut x: usize) -> usize {
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
