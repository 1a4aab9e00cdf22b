//! Bridging a collapsed or fluid-filled stretch: the cheapest path through the CT between the
//! facing ends of two colon gas segments.
//!
//! The cost of a voxel comes from its HU: collapsed bowel is soft tissue (its walls lie on
//! each other) or tagged fluid, both cheap; fat around the bowel is dear, bone and other gas
//! dearer, so the path follows the collapsed bowel rather than cutting across the mesentery.
//! The search runs on a box around both ends, on blocks when that box is large. In a noisy
//! (low-dose) exam a voxel costs the dearer of its own HU and the mean around it, the window
//! sized by the noise measured in the box.

use std::{cmp::Reverse, collections::BinaryHeap};

use glam::DVec3;

use super::{
    coarse::Coarse,
    compartments::Compartments,
    fluid::MAX_DEPTH_MM,
    work::{BRIDGE, Bbox, GAS, Key, LAYER, POOL},
};
use crate::{Volume, volume::ball_offsets};

/// A search box with more voxels than this is searched on coarser blocks.
const MAX_BOX_VOXELS: usize = 1 << 18;
/// Blocks are at least this big (mm): the bridge is a tube of a few mm, and a finer search
/// costs more than the rest of the segmentation.
const MIN_BLOCK_MM: f64 = 1.5;

/// Cost per mm of passing a voxel of `hu` (None: a mask, no CT).
pub fn hu_cost(hu: Option<i16>) -> f32 {
    match hu {
        None => 1.0,
        Some(h) if h < -600 => 30.0, // gas that belongs to neither segment
        Some(h) if h < -150 => 10.0,
        Some(h) if h < -30 => 6.0,  // fat
        Some(h) if h < 200 => 1.0,  // collapsed bowel wall (and organs)
        Some(h) if h < 1200 => 0.2, // tagged fluid filling the bowel (and cancellous bone)
        Some(_) => 40.0,            // cortical bone
    }
}

/// Cost per mm inside one of the two segments being joined.
const OWN_COST: f32 = 0.3;

/// HU noise (σ) at which a single voxel's HU tells fat from soft tissue well enough: about
/// a standard-dose exam's (`ctc/prone-tagged`: 19–23 HU, from neighbouring voxels).
const QUIET_HU: f64 = 25.0;

/// Mean windows are at most this many voxels along each axis.
const MAX_WINDOW: usize = 3;

/// The HU noise (σ) of the CT over a search box, from the differences between neighbouring
/// voxels along the rows where both are fat or soft tissue (robust: the median absolute
/// difference, so that the edges between tissues count little).
fn noise_sigma(ct: &Volume<i16>, bx: &Bbox) -> f64 {
    const LO: i16 = -150;
    const HI: i16 = 100;
    let mut hist = vec![0u64; (HI - LO) as usize + 1];
    let w = bx.widths();
    // Every other row of every other slice: a median of millions of pairs needs no more.
    for k in (bx.lo[2]..=bx.hi[2]).step_by(2) {
        for j in (bx.lo[1]..=bx.hi[1]).step_by(2) {
            let row = ct.geometry().index(bx.lo[0], j, k);
            for p in ct.data()[row..row + w[0]].windows(2) {
                if (LO..=HI).contains(&p[0]) && (LO..=HI).contains(&p[1]) {
                    hist[p[0].abs_diff(p[1]) as usize] += 1;
                }
            }
        }
    }
    let total: u64 = hist.iter().sum();
    let mut seen = 0;
    let median = hist
        .iter()
        .position(|&c| {
            seen += c;
            2 * seen >= total
        })
        .unwrap_or(0);
    // The MAD of a difference of two voxels: σ·√2·0.6745.
    median as f64 * 1.4826 / std::f64::consts::SQRT_2
}

/// Voxels along each axis of the mean window a voxel's cost also reads in a CT of noise
/// `sigma`: enough that the mean's noise is [`QUIET_HU`] (1: none). A low-dose exam's noise
/// (`ctc/prone-tagged` with σ 50 HU added: 45 HU measured) takes 2.
fn mean_window(sigma: f64) -> usize {
    let voxels = (sigma / QUIET_HU).powi(2);
    (1..MAX_WINDOW)
        .find(|&s| (s * s * s) as f64 >= voxels)
        .unwrap_or(MAX_WINDOW)
}

/// The CT's HU over a search box, each voxel the mean of the window of `s` voxels along
/// each axis from it (cut at the box's far sides). In a noisy exam a voxel costs the dearer
/// of what its own HU and this mean say: at σ 50 HU one voxel of fat in twelve passes for
/// soft tissue, so that a block of them, costed by its cheapest voxel, was cheap about every
/// other time and the bridge cut straight across the mesentery (`ctc/prone-tagged` with that
/// noise added: 65 mm behind the descending colon's fluid-filled stretch instead of 162 mm
/// through it). The voxel's own value keeps fat beside the bowel from looking like bowel.
struct LocalMean {
    lo: [usize; 3],
    w: [usize; 3],
    hu: Vec<f32>,
}

impl LocalMean {
    fn new(ct: &Volume<i16>, bx: &Bbox, s: usize) -> Self {
        let w = bx.widths();
        let mut hu = Vec::with_capacity(w.iter().product());
        for k in bx.lo[2]..=bx.hi[2] {
            for j in bx.lo[1]..=bx.hi[1] {
                let row = ct.geometry().index(bx.lo[0], j, k);
                hu.extend(ct.data()[row..row + w[0]].iter().map(|&h| h as f32));
            }
        }
        let stride = [1, w[0], w[0] * w[1]];
        let mut line = Vec::new();
        for a in 0..3 {
            // Every line along axis a: its first voxel has coordinate 0 on a.
            let (b, c) = ([1, 0, 0][a], [2, 2, 1][a]);
            for u in 0..w[c] {
                for t in 0..w[b] {
                    let start = t * stride[b] + u * stride[c];
                    line.clear();
                    line.extend((0..w[a]).map(|x| hu[start + x * stride[a]]));
                    for x in 0..w[a] {
                        let end = (x + s).min(w[a]);
                        let sum: f32 = line[x..end].iter().sum();
                        hu[start + x * stride[a]] = sum / (end - x) as f32;
                    }
                }
            }
        }
        LocalMean { lo: bx.lo, w, hu }
    }

    /// The mean HU at voxel `v` (inside the box), rounded.
    fn at(&self, v: [usize; 3]) -> i16 {
        let l = [0, 1, 2].map(|a| v[a] - self.lo[a]);
        self.hu[l[0] + self.w[0] * (l[1] + self.w[1] * l[2])].round() as i16
    }
}

/// The cheapest path between two voxels.
#[derive(Clone, Debug)]
pub struct Path {
    /// Voxels, `a` first, 26-connected.
    pub voxels: Vec<[usize; 3]>,
    pub length_mm: f64,
    /// Mean cost per mm outside the two segments (1 = soft tissue all the way).
    pub mean_cost: f64,
}

impl Path {
    /// Its whole cost: its length at its mean cost per mm.
    pub fn cost(&self) -> f64 {
        self.length_mm * self.mean_cost
    }
}

/// Where the cheapest path is looked for: around both ends, and a pool's depth further
/// along gravity.
///
/// A stretch filled with tagged fluid between two gas segments lies below their gas: their
/// facing ends are gas, and the fluid joining them may run a pool's depth under both (on
/// `ctc/prone-tagged` the descending colon's fluid-filled stretch runs 70–100 mm anterior
/// to the two segments' gas, and a box around the ends alone held only the tissue behind
/// it, so the bridge went through 75 mm of it).
#[derive(Clone, Copy)]
pub struct SearchBox {
    pub dims: [usize; 3],
    pub spacing: [f64; 3],
    /// Gravity's voxel axis and direction, when known.
    pub down: Option<(usize, i32)>,
}

impl SearchBox {
    fn around(&self, a: [usize; 3], b: [usize; 3]) -> Bbox {
        let dist_mm = (0..3)
            .map(|x| ((a[x] as f64 - b[x] as f64) * self.spacing[x]).powi(2))
            .sum::<f64>()
            .sqrt();
        let pad_mm = 15.0 + 0.3 * dist_mm;
        let pad = self.spacing.map(|s| (pad_mm / s).ceil() as usize);
        let mut bx = Bbox {
            lo: [0, 1, 2].map(|x| a[x].min(b[x])),
            hi: [0, 1, 2].map(|x| a[x].max(b[x])),
        }
        .grown(pad, self.dims);
        if let Some((axis, sign)) = self.down {
            let depth = (MAX_DEPTH_MM / self.spacing[axis]).ceil() as usize;
            if sign > 0 {
                bx.hi[axis] = (bx.hi[axis] + depth).min(self.dims[axis] - 1);
            } else {
                bx.lo[axis] = bx.lo[axis].saturating_sub(depth);
            }
        }
        bx
    }
}

/// The cheapest path from `a` to `b` through `ct` (or a mask's background when None), where
/// `own(v)` says that voxel `v` lies in one of the two segments being joined and
/// `other_gas(v)` that it is another gas region.
pub fn cheapest_path(
    ct: Option<&Volume<i16>>,
    within: SearchBox,
    a: [usize; 3],
    b: [usize; 3],
    own: impl Fn([usize; 3]) -> bool,
    other_gas: impl Fn([usize; 3]) -> bool,
) -> Option<Path> {
    let spacing = within.spacing;
    let bx = within.around(a, b);
    let w = bx.widths();
    let n: usize = w.iter().product();
    // Blocks of f³ voxels when the box is large.
    let finest = spacing.iter().cloned().fold(f64::INFINITY, f64::min);
    let f = ((n as f64 / MAX_BOX_VOXELS as f64).cbrt().ceil() as usize)
        .max((MIN_BLOCK_MM / finest).round() as usize)
        .max(1);
    let cw = w.map(|x| x.div_ceil(f));
    let cn = cw[0] * cw[1] * cw[2];
    let mean = ct
        .map(|ct| (ct, mean_window(noise_sigma(ct, &bx))))
        .filter(|&(_, s)| s > 1)
        .map(|(ct, s)| LocalMean::new(ct, &bx, s));
    let voxel_cost = |v: [usize; 3]| {
        let own = hu_cost(ct.map(|ct| ct.get(v[0], v[1], v[2])));
        match &mean {
            Some(m) => own.max(hu_cost(Some(m.at(v)))),
            None => own,
        }
    };
    let centre = |c: [usize; 3]| [0, 1, 2].map(|x| (bx.lo[x] + c[x] * f + f / 2).min(bx.hi[x]));
    let cost: Vec<f32> = (0..cn)
        .map(|i| {
            let c = [i % cw[0], (i / cw[0]) % cw[1], i / (cw[0] * cw[1])];
            let v = centre(c);
            if own(v) {
                OWN_COST
            } else if other_gas(v) {
                hu_cost(Some(-1000))
            } else {
                // A block costs what its cheapest voxel costs: a thin cord of collapsed
                // bowel must not fall between block centres.
                let lo = [0, 1, 2].map(|x| bx.lo[x] + c[x] * f);
                let hi = [0, 1, 2].map(|x| (lo[x] + f).min(bx.hi[x] + 1));
                let mut best = f32::INFINITY;
                for k in lo[2]..hi[2] {
                    for j in lo[1]..hi[1] {
                        for i in lo[0]..hi[0] {
                            best = best.min(voxel_cost([i, j, k]));
                        }
                    }
                }
                best
            }
        })
        .collect();
    let block_of = |v: [usize; 3]| [0, 1, 2].map(|x| ((v[x] - bx.lo[x]) / f).min(cw[x] - 1));
    let idx = |c: [usize; 3]| c[0] + cw[0] * (c[1] + cw[1] * c[2]);
    let (sa, sb) = (idx(block_of(a)), idx(block_of(b)));
    let step = spacing.map(|s| s * f as f64);
    let mut dist = vec![f32::INFINITY; cn];
    let mut prev = vec![u32::MAX; cn];
    let mut heap = BinaryHeap::new();
    dist[sa] = 0.0;
    heap.push(Reverse((Key(0.0), sa as u32)));
    while let Some(Reverse((Key(d), u))) = heap.pop() {
        let (u, d) = (u as usize, d as f32);
        if d > dist[u] {
            continue;
        }
        if u == sb {
            break;
        }
        let c = [u % cw[0], (u / cw[0]) % cw[1], u / (cw[0] * cw[1])];
        for dz in -1i64..=1 {
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    if dx == 0 && dy == 0 && dz == 0 {
                        continue;
                    }
                    let q = [c[0] as i64 + dx, c[1] as i64 + dy, c[2] as i64 + dz];
                    if (0..3).any(|x| q[x] < 0 || q[x] >= cw[x] as i64) {
                        continue;
                    }
                    let q = q.map(|x| x as usize);
                    let v = idx(q);
                    let len = ((dx as f64 * step[0]).powi(2)
                        + (dy as f64 * step[1]).powi(2)
                        + (dz as f64 * step[2]).powi(2))
                    .sqrt() as f32;
                    let nd = d + len * 0.5 * (cost[u] + cost[v]);
                    if nd < dist[v] {
                        dist[v] = nd;
                        prev[v] = u as u32;
                        heap.push(Reverse((Key(nd as f64), v as u32)));
                    }
                }
            }
        }
    }
    if !dist[sb].is_finite() {
        return None;
    }
    let mut blocks = vec![sb];
    while *blocks.last()? != sa {
        blocks.push(prev[*blocks.last()?] as usize);
    }
    blocks.reverse();
    // Back to voxels: a straight line between consecutive block centres, ends exact.
    let mut pts: Vec<[usize; 3]> = blocks
        .iter()
        .map(|&i| centre([i % cw[0], (i / cw[0]) % cw[1], i / (cw[0] * cw[1])]))
        .collect();
    pts[0] = a;
    let last = pts.len() - 1;
    pts[last] = b;
    let voxels = outside_stretch(line_voxels(&pts), &own);
    let mut length_mm = 0.0;
    let mut outside = (0.0, 0.0);
    for p in voxels.windows(2) {
        let l = (0..3)
            .map(|x| ((p[1][x] as f64 - p[0][x] as f64) * spacing[x]).powi(2))
            .sum::<f64>()
            .sqrt();
        length_mm += l;
        if !own(p[1]) {
            let c = if other_gas(p[1]) {
                hu_cost(Some(-1000))
            } else {
                voxel_cost(p[1])
            };
            outside.0 += l * c as f64;
            outside.1 += l;
        }
    }
    let mean_cost = if outside.1 > 0.0 {
        outside.0 / outside.1
    } else {
        1.0
    };
    Some(Path {
        voxels,
        length_mm,
        mean_cost,
    })
}

/// The stretch of a path (`voxels`) outside the two segments: from the last voxel of the
/// one it leaves to the first of the one it enters; the whole path when it never leaves them.
/// A path from gas down through its pool to a fluid-filled stretch bridges only the stretch.
fn outside_stretch(voxels: Vec<[usize; 3]>, own: impl Fn([usize; 3]) -> bool) -> Vec<[usize; 3]> {
    let out = |v: &[usize; 3]| !own(*v);
    match (voxels.iter().position(out), voxels.iter().rposition(out)) {
        (Some(first), Some(last)) => {
            voxels[first.saturating_sub(1)..=(last + 1).min(voxels.len() - 1)].to_vec()
        }
        _ => voxels,
    }
}

/// The voxels on straight lines through `pts` (26-connected, no repeats).
fn line_voxels(pts: &[[usize; 3]]) -> Vec<[usize; 3]> {
    let mut out: Vec<[usize; 3]> = vec![pts[0]];
    for w in pts.windows(2) {
        let (p, q) = (
            DVec3::from_array(w[0].map(|x| x as f64)),
            DVec3::from_array(w[1].map(|x| x as f64)),
        );
        let n = (q - p).abs().max_element().ceil() as usize;
        for t in 1..=n {
            let r = p + (q - p) * (t as f64 / n as f64);
            let v = [
                r.x.round() as usize,
                r.y.round() as usize,
                r.z.round() as usize,
            ];
            if out.last() != Some(&v) {
                out.push(v);
            }
        }
    }
    out
}

/// Bridges between compartments on the chain's coarse grid: from a block of one to a block
/// of another, through `ct` (None: a mask's background), around the other gas of `work`.
pub(super) struct Bridges<'a> {
    pub(super) coarse: &'a Coarse,
    pub(super) work: &'a Volume<u8>,
    pub(super) parts: &'a Compartments,
    pub(super) ct: Option<&'a Volume<i16>>,
    /// Gravity's voxel axis and direction, when known.
    pub(super) down: Option<(usize, i32)>,
}

impl Bridges<'_> {
    /// The voxel of compartment c nearest block b's middle (of its gas only, with `gas`).
    pub(super) fn voxel_of_comp(&self, block: usize, c: u32, gas: bool) -> Option<[usize; 3]> {
        let bx = self.coarse.voxels_of(block, self.work.dims());
        let mid = [0, 1, 2].map(|a| (bx.lo[a] + bx.hi[a]) / 2);
        let mut best: Option<(usize, [usize; 3])> = None;
        for k in bx.lo[2]..=bx.hi[2] {
            for j in bx.lo[1]..=bx.hi[1] {
                for i in bx.lo[0]..=bx.hi[0] {
                    if (!gas || self.work.get(i, j, k) == GAS)
                        && self.parts.at([i, j, k]) == Some(c)
                    {
                        let d = (0..3)
                            .map(|a| mid[a].abs_diff([i, j, k][a]).pow(2))
                            .sum::<usize>();
                        if best.is_none_or(|b| d < b.0) {
                            best = Some((d, [i, j, k]));
                        }
                    }
                }
            }
        }
        best.map(|b| b.1)
    }

    /// The cheapest path from block `from` of compartment `a` to block `to` of `b`.
    pub(super) fn bridge(&self, from: usize, to: usize, a: u32, b: u32) -> Option<Path> {
        let (va, vb) = (
            self.voxel_of_comp(from, a, false)?,
            self.voxel_of_comp(to, b, false)?,
        );
        let own = |v: [usize; 3]| self.parts.at(v).is_some_and(|c| c == a || c == b);
        let other = |v: [usize; 3]| {
            matches!(self.work.get(v[0], v[1], v[2]), GAS | POOL | LAYER) && !own(v)
        };
        let within = SearchBox {
            dims: self.work.dims(),
            spacing: self.work.spacing(),
            down: self.down,
        };
        cheapest_path(self.ct, within, va, vb, own, other)
    }
}

/// A tube of `radius_mm` around a bridge's path: BRIDGE where there is neither gas nor a pool.
pub(super) fn lay_bridge(
    work: &mut Volume<u8>,
    path: &[[usize; 3]],
    radius_mm: f64,
    added: &mut Vec<usize>,
) {
    let g = work.geometry().clone();
    let ball = ball_offsets(g.spacing, radius_mm);
    for v in path {
        for o in &ball {
            let q = [v[0] as i64 + o[0], v[1] as i64 + o[1], v[2] as i64 + o[2]];
            if (0..3).any(|a| q[a] < 0 || q[a] >= g.dims[a] as i64) {
                continue;
            }
            let i = g.index(q[0] as usize, q[1] as usize, q[2] as usize);
            let x = &mut work.data_mut()[i];
            if *x == 0 {
                *x = BRIDGE;
                added.push(i);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;

    /// Fat everywhere, with a soft-tissue cord bending around: the path follows the cord,
    /// not the straight line through fat; searched on blocks (fine spacing), it stays within
    /// a block of it.
    #[test]
    fn the_path_follows_the_collapsed_bowel() {
        for spacing in [1.5, 0.5] {
            follows_the_cord(spacing);
        }
    }

    fn follows_the_cord(spacing: f64) {
        let g = Geometry::new([40, 30, 10], [spacing; 3], [0.0; 3]).unwrap();
        let mut ct = Volume::filled(g, -100i16).unwrap();
        // A U-shaped cord: x = 5 from y = 5 to 15, y = 15 from x = 5 to 35, x = 35 back up.
        for k in 4..7 {
            for t in 5..=15 {
                ct.set(5, t, k, 40);
                ct.set(35, t, k, 40);
            }
            for t in 5..=35 {
                ct.set(t, 15, k, 40);
            }
        }
        let within = SearchBox {
            dims: ct.dims(),
            spacing: ct.spacing(),
            down: None,
        };
        let p = cheapest_path(
            Some(&ct),
            within,
            [5, 5, 5],
            [35, 5, 5],
            |_| false,
            |_| false,
        )
        .unwrap();
        let block = (MIN_BLOCK_MM / spacing).round().max(1.0) as usize;
        let near_cord = |v: &[usize; 3]| {
            let lo = v.map(|x| x.saturating_sub(block));
            (lo[2]..=v[2] + block).any(|k| {
                (lo[1]..=v[1] + block).any(|j| {
                    (lo[0]..=v[0] + block)
                        .any(|i| i < 40 && j < 30 && k < 10 && ct.get(i, j, k) == 40)
                })
            })
        };
        assert!(
            p.voxels.iter().all(near_cord),
            "left the cord at spacing {spacing}"
        );
        let cord_mm = 50.0 * spacing;
        assert!(
            p.length_mm > 0.9 * cord_mm && p.length_mm < 1.3 * cord_mm,
            "{} mm along a {cord_mm} mm cord",
            p.length_mm
        );
        // The ends are the given voxels, and the path is connected.
        assert_eq!(
            (p.voxels[0], p.voxels[p.voxels.len() - 1]),
            ([5, 5, 5], [35, 5, 5])
        );
        assert!(
            p.voxels
                .windows(2)
                .all(|w| (0..3).all(|x| w[0][x].abs_diff(w[1][x]) <= 1))
        );
    }

    /// Two gas segments whose ends face each other across 34 mm of fat, joined by a U of
    /// collapsed bowel (soft tissue) 12 mm thick hanging 45 mm below them: the bridge follows
    /// the bowel (about 140 mm at cost 1) rather than the mesentery's fat (34 mm at cost 6),
    /// and still does in a low-dose exam's noise (σ 50 HU), where a block costed by its
    /// cheapest single voxel took fat for tissue about every other block and cut across.
    #[test]
    fn the_bridge_follows_collapsed_bowel_through_noise() {
        let g = Geometry::new([30, 90, 100], [1.0; 3], [0.0; 3]).unwrap();
        let tube = |j: usize, k: usize| {
            let arm = |z: f64| (k as f64 - z).abs() <= 6.0 && (5..=80).contains(&j);
            let bottom = (j as f64 - 74.0).abs() <= 6.0 && (19..=81).contains(&k);
            arm(25.0) || arm(75.0) || bottom
        };
        let own = |v: [usize; 3]| tube(v[1], v[2]) && v[1] < 30 && (9..21).contains(&v[0]);
        for sigma in [0.0, 50.0] {
            let mut noise = crate::rng::Rng::new(7, 1);
            let mut ct = Volume::filled(g.clone(), -100i16).unwrap();
            for k in 0..100 {
                for j in 0..90 {
                    for i in 0..30 {
                        let bowel = tube(j, k) && (9..21).contains(&i);
                        let h = match (bowel, j < 30) {
                            (true, true) => -1000.0,
                            (true, false) => 40.0,
                            (false, _) => -100.0,
                        };
                        ct.set(i, j, k, (h + sigma * noise.gauss()).round() as i16);
                    }
                }
            }
            let within = SearchBox {
                dims: g.dims,
                spacing: g.spacing,
                down: Some((1, 1)),
            };
            let p =
                cheapest_path(Some(&ct), within, [15, 6, 25], [15, 6, 75], own, |_| false).unwrap();
            let on_bowel = p.voxels.iter().filter(|v| tube(v[1], v[2])).count();
            assert!(
                on_bowel as f64 >= 0.9 * p.voxels.len() as f64 && p.length_mm > 100.0,
                "σ {sigma} HU: {on_bowel} of {} voxels on the bowel, {:.0} mm",
                p.voxels.len(),
                p.length_mm
            );
        }
    }

    /// Two gas segments whose ends face each other across 34 mm of fat, joined by a
    /// U of tagged fluid hanging below them (gravity +y), each arm the segment's own pool
    /// for 20 mm and then fluid: as on `ctc/prone-tagged`, where the descending colon's
    /// fluid-filled stretch runs 70–100 mm anterior to the two segments' gas. The bridge goes
    /// through the fluid, and only the stretch outside the segments is bridged.
    #[test]
    fn the_bridge_goes_down_through_fluid_below_the_gas() {
        let g = Geometry::new([30, 90, 100], [1.0; 3], [0.0; 3]).unwrap();
        // Fat around the bowel.
        let mut ct = Volume::filled(g.clone(), -100i16).unwrap();
        let tube = |j: usize, k: usize| {
            let arm = |z: f64| (k as f64 - z).abs() <= 8.0 && (5..=78).contains(&j);
            let bottom = (j as f64 - 74.0).abs() <= 6.0 && (17..=83).contains(&k);
            arm(25.0) || arm(75.0) || bottom
        };
        for k in 0..100 {
            for j in 0..90 {
                for i in 3..27 {
                    if tube(j, k) {
                        ct.set(i, j, k, if j < 10 { -1000 } else { 600 });
                    }
                }
            }
        }
        let own = |v: [usize; 3]| tube(v[1], v[2]) && v[1] < 30 && (3..27).contains(&v[0]);
        let (a, b) = ([15, 6, 25], [15, 6, 75]);
        let path = |down| {
            let within = SearchBox {
                dims: g.dims,
                spacing: g.spacing,
                down,
            };
            cheapest_path(Some(&ct), within, a, b, own, |_| false).unwrap()
        };
        // Around the ends alone: through the tissue.
        assert!(path(None).mean_cost >= 1.0);
        let p = path(Some((1, 1)));
        let bright = p
            .voxels
            .iter()
            .filter(|v| ct.get(v[0], v[1], v[2]) >= 200)
            .count();
        assert!(
            bright as f64 >= 0.9 * p.voxels.len() as f64,
            "{bright} of {} voxels in fluid",
            p.voxels.len()
        );
        assert!(
            p.voxels.iter().all(|v| v[1] >= 25),
            "the bridge starts in the pool"
        );
        assert!(p.mean_cost < 0.5, "mean cost {}", p.mean_cost);
    }

    /// The noise is measured from neighbouring voxels, whatever the tissue edges: a clean CT
    /// of fat and tissue slabs has none and keeps single voxels; 50 HU of noise is read
    /// within a tenth and takes a window of 2.
    #[test]
    fn the_noise_is_measured_and_sizes_the_mean() {
        let g = Geometry::new([40, 40, 40], [0.75; 3], [0.0; 3]).unwrap();
        let bx = Bbox {
            lo: [0; 3],
            hi: [39; 3],
        };
        for sigma in [0.0, 50.0] {
            let mut noise = crate::rng::Rng::new(3, 1);
            let mut ct = Volume::filled(g.clone(), 0i16).unwrap();
            for k in 0..40 {
                for j in 0..40 {
                    for i in 0..40 {
                        let h = if (i / 5) % 2 == 0 { -100.0 } else { 40.0 };
                        ct.set(i, j, k, (h + sigma * noise.gauss()).round() as i16);
                    }
                }
            }
            let got = noise_sigma(&ct, &bx);
            assert!(
                (got - sigma).abs() <= 0.1 * sigma + 1.0,
                "σ {sigma}: {got:.1}"
            );
            assert_eq!(mean_window(got), if sigma == 0.0 { 1 } else { 2 });
        }
    }
}
