//! The rectal tube: a thin tube of air from outside the body, through the anal canal, into
//! the rectum. Its air joins the colon's gas in 3D (outside air is found slice by slice, and
//! in each slice below the perineum the tube is a hole in the body). Left in, it would make
//! the tube's outer end the colon's lowest point, so the flight would start in the tube.
//!
//! A gas component touches outside air in 3D only there: one of its runs overlaps an
//! outside run in the next axial slice. A scan that ends at the perineum cuts the tube
//! instead: its air reaches the scan's inferior slice. From that slice, going away from the
//! outside air or the scan's edge, the tube's cross-section (its gas joined within the
//! slice) is followed while it stays as narrow as a tube; where it widens is the tube's tip,
//! in the rectum. The tube's air is then outside air, and the rectum begins at the tip.
//!
//! A narrow stretch of gas that just ends is no tube: a skin fold, or the air between a
//! prone patient and the table, pinched off in one slice from the outside air of the next.
//! A tube opens into the rectum, and the gas beyond its tip is a colon segment's at least
//! (checked by the caller).
//!
//! Gas round a tube is not the tube: the anal canal's gas round the catheter reaches the
//! skin too, and in a slice it is a ring round the catheter's plastic and air. A part of a
//! section that closes round other gas of its component is such a ring: it is left out, so
//! the canal's gas stays colon (the colon's lowest gas is at the anus) and the catheter's
//! air is followed on inside it. Where the plastic is too thin to show (1.5 mm voxels), the
//! two are one and are taken together.

use glam::DVec3;

use super::runs::{Runs, row_of, run_voxels};
use crate::Volume;

/// A tube's cross-section in an axial slice is at most this (mm²): an inner radius of 6 mm
/// at 45° to the slice (real tubes are 3–8 mm wide inside).
const MAX_AREA_MM2: f64 = 160.0;
/// A narrow stretch shorter than this (mm) is the bottom of a gas region, not a tube.
const MIN_LENGTH_MM: f64 = 10.0;
/// A section of gas that closes round at least this much (mm², a catheter 2 mm across or
/// more with its wall), other gas of its component among it, is gas round a catheter, not a
/// tube's own air.
const MIN_CORE_MM2: f64 = 3.0;

/// A rectal tube found in one gas component.
#[derive(Clone, Debug)]
pub struct Tube {
    /// The component it belongs to.
    pub comp: u32,
    /// Its runs (now outside air).
    pub runs: Vec<usize>,
    /// Where it enters the body (or the scan) and where it ends, volume indices (slice
    /// centroids).
    pub entry: [f64; 3],
    pub tip: [f64; 3],
    pub length_mm: f64,
    /// It enters at the scan's inferior edge, not through the skin.
    pub from_edge: bool,
}

/// Rectal tubes: for each component `c` (its runs `run_comp[r] == c`; u32::MAX for none)
/// that touches outside air (`inside[r] == false`) across an axial slice, or has gas in the
/// scan's inferior slice (`inferior_slice`, when the axial slices run along the body), the
/// narrow stretch from there on, if it is long enough to be a tube and opens out.
pub fn find(
    runs: &Runs,
    inside: &[bool],
    run_comp: &[u32],
    is_gas: impl Fn(u32) -> bool,
    dims: [usize; 3],
    spacing: [f64; 3],
    inferior_slice: Option<usize>,
) -> Vec<Tube> {
    let mut tubes: Vec<Tube> = Vec::new();
    let at_skin = contacts(runs, inside, run_comp, &is_gas, dims)
        .into_iter()
        .map(|c| (c, false));
    let at_edge = inferior_slice
        .into_iter()
        .flat_map(|k| edge_contacts(runs, run_comp, &is_gas, dims, k))
        .map(|c| (c, true));
    for (contact, from_edge) in at_skin.chain(at_edge) {
        if tubes.iter().any(|t| t.comp == run_comp[contact.2]) {
            continue;
        }
        if let Some(t) = follow(runs, run_comp, contact, dims[2], spacing, from_edge) {
            tubes.push(t);
        }
    }
    tubes
}

/// Internal gas runs in the scan's edge slice `k`: (k, the step into the scan, the run).
fn edge_contacts(
    runs: &Runs,
    run_comp: &[u32],
    is_gas: &impl Fn(u32) -> bool,
    dims: [usize; 3],
    k: usize,
) -> Vec<(usize, i64, usize)> {
    let away = if k == 0 { 1 } else { -1 };
    (0..dims[1])
        .flat_map(|j| runs.row(j, k))
        .filter(|&r| is_gas(run_comp[r]))
        .map(|r| (k, away, r))
        .collect()
}

/// Internal gas runs that overlap outside air in the next slice: (their slice, the step in k
/// away from the outside air, the run).
fn contacts(
    runs: &Runs,
    inside: &[bool],
    run_comp: &[u32],
    is_gas: &impl Fn(u32) -> bool,
    dims: [usize; 3],
) -> Vec<(usize, i64, usize)> {
    let [_, ny, nz] = dims;
    let mut out = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k).filter(|&r| is_gas(run_comp[r])) {
                for step in [-1i64, 1] {
                    let kk = k as i64 + step;
                    if kk < 0 || kk >= nz as i64 {
                        continue;
                    }
                    let run = runs.runs[r];
                    let touches = runs
                        .row(j, kk as usize)
                        .any(|q| !inside[q] && runs.runs[q].overlaps(run));
                    if touches {
                        out.push((k, -step, r));
                    }
                }
            }
        }
    }
    out
}

/// Follows the tube from run `start` in slice `k0`, in steps of `away`: in each slice, the
/// gas of component `c` joined (in the slice) to the runs over the tube's runs of the slice
/// before. Inside the rectum the tube's air is walled off by its plastic from the rectum's
/// gas, so it is followed up to its tip, where it opens into the rectum and widens.
fn follow(
    runs: &Runs,
    run_comp: &[u32],
    (k0, away, start): (usize, i64, usize),
    nz: usize,
    spacing: [f64; 3],
    from_edge: bool,
) -> Option<Tube> {
    let c = run_comp[start];
    let shape = SectionShape {
        max_voxels: (MAX_AREA_MM2 / (spacing[0] * spacing[1])).ceil() as usize,
        min_core_voxels: (MIN_CORE_MM2 / (spacing[0] * spacing[1])).ceil() as usize,
    };
    let nz = nz as i64;
    // Gas round a catheter's air from the start (the anal canal's) is no tube: the
    // catheter's own air reaches the skin or the scan's edge too, and is followed from there.
    let Section::Narrow(mut blob) = in_slice(runs, run_comp, c, vec![start], &shape) else {
        return None;
    };
    let entry = centroid(runs, &blob);
    let mut tip;
    let mut taken = Vec::new();
    let mut slices = 0usize;
    let mut k = k0 as i64;
    loop {
        tip = centroid(runs, &blob);
        taken.extend_from_slice(&blob);
        slices += 1;
        k += away;
        if k < 0 || k >= nz {
            // A tube through the whole scan is not a rectal tube.
            return None;
        }
        let over: Vec<usize> = blob
            .iter()
            .flat_map(|&r| {
                let (j, _) = row_of(runs, r);
                let run = runs.runs[r];
                runs.row(j, k as usize)
                    .filter(move |&q| run_comp[q] == c && runs.runs[q].overlaps(run))
            })
            .collect();
        match in_slice(runs, run_comp, c, over, &shape) {
            Section::Narrow(b) => blob = b,
            // All the gas over the tube closes round other gas: where that is the tube's own
            // air (the plastic was open below), the tube goes on in it; else what was
            // followed was gas round a catheter (a crescent of the canal's at the anus,
            // closing into a ring), no tube.
            Section::Around(inner) if same_rows_overlap(runs, &inner, &blob) => blob = inner,
            Section::Around(_) => return None,
            // The tube opens into the rectum.
            Section::Wide => break,
            // The gas ends: a pocket pinched off the outside air, not a tube.
            Section::Gone => return None,
        }
    }
    let d = [0, 1, 2].map(|a| (tip[a] - entry[a]) * spacing[a]);
    let length_mm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        .sqrt()
        .max(slices as f64 * spacing[2]);
    (length_mm >= MIN_LENGTH_MM).then_some(Tube {
        comp: c,
        runs: taken,
        entry,
        tip,
        length_mm,
        from_edge,
    })
}

/// A component's gas in one slice around some runs.
enum Section {
    /// As narrow as a tube: its runs (with the gas any ring left out closed round).
    Narrow(Vec<usize>),
    /// All of it closes round other gas of its component (gas round a catheter): that gas.
    Around(Vec<usize>),
    /// Wider than a tube.
    Wide,
    /// No gas.
    Gone,
}

/// What a tube's section may be, in voxels of a slice: at most `max_voxels` of gas; a part
/// that closes round at least `min_core_voxels` (plastic, air, whatever lies inside), gas of
/// its component among them, is gas round a catheter, not the tube's own air.
struct SectionShape {
    max_voxels: usize,
    min_core_voxels: usize,
}

/// A ring round a catheter is left out of a section however wide, up to this many times a
/// tube's section: beyond, the gas is the rectum's, and the tube opens into it.
const RING_SPAN: usize = 4;

/// The runs of component `c` joined to `seeds` within their slice (rows next to each other,
/// overlapping); wide when they hold more than the shape's voxels (the rectum, or the gas the
/// tube opens into). Of the parts the seeds reach, those that close round the component's
/// other gas (the anal canal's gas round a catheter's air) are left out for the gas they
/// close round.
fn in_slice(
    runs: &Runs,
    run_comp: &[u32],
    c: u32,
    mut seeds: Vec<usize>,
    shape: &SectionShape,
) -> Section {
    seeds.sort_unstable();
    seeds.dedup();
    let mut seen: Vec<usize> = Vec::new();
    let mut reached = 0usize;
    let mut parts: Vec<Vec<usize>> = Vec::new();
    for seed in seeds {
        if seen.contains(&seed) {
            continue;
        }
        seen.push(seed);
        let mut stack = vec![seed];
        let mut part = Vec::new();
        while let Some(r) = stack.pop() {
            let run = runs.runs[r];
            reached += (run.x1 - run.x0) as usize;
            if reached > RING_SPAN * shape.max_voxels {
                return Section::Wide;
            }
            part.push(r);
            let (j, k) = row_of(runs, r);
            for jj in [j.wrapping_sub(1), j + 1] {
                if jj >= runs.ny {
                    continue;
                }
                for q in runs.row(jj, k) {
                    if run_comp[q] == c && runs.runs[q].overlaps(run) && !seen.contains(&q) {
                        seen.push(q);
                        stack.push(q);
                    }
                }
            }
        }
        parts.push(part);
    }
    if parts.is_empty() {
        return Section::Gone;
    }
    let (mut own, mut inner) = (Vec::new(), Vec::new());
    for part in parts {
        let closed = closed_round_gas(runs, run_comp, c, &part, shape.min_core_voxels);
        if closed.is_empty() {
            own.extend(part);
        } else {
            inner.extend(closed);
        }
    }
    inner.retain(|r| !own.contains(r));
    inner.sort_unstable();
    inner.dedup();
    if run_voxels(runs, &own) + run_voxels(runs, &inner) > shape.max_voxels {
        Section::Wide
    } else if own.is_empty() {
        Section::Around(inner)
    } else {
        own.extend(inner);
        Section::Narrow(own)
    }
}

/// Whether some run of `a` lies over (same row, overlapping) some run of `b`, in the next
/// slice or the same.
fn same_rows_overlap(runs: &Runs, a: &[usize], b: &[usize]) -> bool {
    a.iter().any(|&p| {
        let (jp, rp) = (row_of(runs, p).0, runs.runs[p]);
        b.iter().any(|&q| {
            let (jq, rq) = (row_of(runs, q).0, runs.runs[q]);
            jp == jq && rp.overlaps(rq)
        })
    })
}

/// The runs of component `c` (other than `part`'s) that the runs `part` (of one slice,
/// joined) close round, when they close round at least `min_core` voxels of the slice: a
/// ring of gas round a catheter and its air. Empty when they close round no such gas.
fn closed_round_gas(
    runs: &Runs,
    run_comp: &[u32],
    c: u32,
    part: &[usize],
    min_core: usize,
) -> Vec<usize> {
    let rows = || part.iter().map(|&r| (row_of(runs, r), runs.runs[r]));
    let (j0, j1) = rows().fold((usize::MAX, 0), |(a, b), ((j, _), _)| (a.min(j), b.max(j)));
    let (x0, x1) = rows().fold((u32::MAX, 0), |(a, b), (_, r)| (a.min(r.x0), b.max(r.x1)));
    let k = row_of(runs, part[0]).1;
    // The box with a free border, so that everything outside the part joins up round it.
    let (w, h) = ((x1 - x0) as usize + 2, j1 - j0 + 3);
    let mut cell = vec![FREE; w * h];
    for ((j, _), r) in rows() {
        let row = (j - j0 + 1) * w;
        cell[row + (r.x0 - x0) as usize + 1..row + (r.x1 - x0) as usize + 1].fill(PART);
    }
    reach_from_border(&mut cell, w, h);
    if cell.iter().filter(|&&v| v == FREE).count() < min_core {
        return Vec::new();
    }
    (j0..=j1)
        .flat_map(|j| runs.row(j, k).map(move |q| (j, q)))
        .filter(|&(j, q)| {
            let r = runs.runs[q];
            let row = (j - j0 + 1) * w;
            run_comp[q] == c
                && !part.contains(&q)
                && (r.x0.max(x0)..r.x1.min(x1)).any(|x| cell[row + (x - x0) as usize + 1] == FREE)
        })
        .map(|(_, q)| q)
        .collect()
}

/// Cells of [`closed_round_gas`]'s box: free, the part's gas, reached from the border.
const FREE: u8 = 0;
const PART: u8 = 1;
const OUT: u8 = 2;

/// Marks the free cells reached from the box's corner, 8-connected: the dual of gas joined
/// 4-connected, so that a gap between two runs that only touch at a corner is no enclosure.
/// What stays free is enclosed.
fn reach_from_border(cell: &mut [u8], w: usize, h: usize) {
    let mut stack = vec![(0usize, 0usize)];
    cell[0] = OUT;
    while let Some((x, y)) = stack.pop() {
        for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
            for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                let n = ny * w + nx;
                if cell[n] == FREE {
                    cell[n] = OUT;
                    stack.push((nx, ny));
                }
            }
        }
    }
}

/// Mean voxel position (volume indices) of some runs.
fn centroid(runs: &Runs, rs: &[usize]) -> [f64; 3] {
    let (mut n, mut sum) = (0.0, [0.0; 3]);
    for &r in rs {
        let (j, k) = row_of(runs, r);
        let run = runs.runs[r];
        let m = (run.x1 - run.x0) as f64;
        n += m;
        sum[0] += m * 0.5 * (run.x0 + run.x1 - 1) as f64;
        sum[1] += m * j as f64;
        sum[2] += m * k as f64;
    }
    sum.map(|v| v / n.max(1.0))
}

/// The scan's inferior axial slice (k is axial): 0 or the last, whichever lies lower in the
/// patient; None when the slices do not run along the body.
pub(super) fn inferior_slice(vol: &Volume<i16>) -> Option<usize> {
    let g = vol.geometry();
    let nz = vol.dims()[2];
    let first = g.index_to_patient(DVec3::ZERO);
    let last = g.index_to_patient(DVec3::new(0.0, 0.0, nz.saturating_sub(1) as f64));
    let along = last - first;
    if along.length() < 1e-9 || along.z.abs() < 0.7 * along.length() {
        return None;
    }
    Some(if along.z < 0.0 { nz - 1 } else { 0 })
}

#[cfg(test)]
mod tests {
    use super::super::runs::Run;
    use super::*;

    const DIMS: [usize; 3] = [40, 40, 70];
    const SPACING: [f64; 3] = [0.75, 0.75, 1.0];
    /// Body from this slice up; below it, the air outside.
    const SKIN_K: usize = 5;
    /// The rectum's gas from this slice up.
    const RECTUM_K: usize = 45;
    /// The catheter's tip, in the rectum.
    const TIP_K: usize = 55;

    /// A catheter up into the rectum (its air channel 2.5 voxels in radius, its plastic to
    /// 4) from its open end at slice `from_k` (0: the scan's inferior edge; else in the air
    /// outside), through a canal of gas round it from the skin to the rectum (to 7 voxels)
    /// when `canal_gas`; the plastic open to the canal's gas on one side over `open_k`; the
    /// canal's gas only on one side (a crescent) below `crescent_k`.
    #[derive(Clone, Copy, Default)]
    struct Catheter {
        from_k: usize,
        canal_gas: bool,
        open_k: Option<[usize; 2]>,
        crescent_k: Option<usize>,
    }

    /// What a voxel is.
    #[derive(Clone, Copy, PartialEq, Debug)]
    enum Kind {
        Outside,
        Gas,
        Tissue,
    }

    impl Catheter {
        fn kind(&self, i: usize, j: usize, k: usize) -> Kind {
            let (dx, dy) = (i as f64 - 20.0, j as f64 - 20.0);
            let r = dx.hypot(dy);
            let catheter = (self.from_k..TIP_K).contains(&k);
            let open =
                self.open_k.is_some_and(|[a, b]| (a..b).contains(&k)) && dx > 0.0 && dy.abs() < 1.5;
            let canal =
                self.canal_gas && r <= 7.0 && self.crescent_k.is_none_or(|c| k >= c || dx > 2.0);
            if catheter && r <= 2.5 {
                Kind::Gas
            } else if catheter && r <= 4.0 && !open {
                Kind::Tissue
            } else if k < SKIN_K {
                Kind::Outside
            } else if (k >= RECTUM_K && r <= 16.0) || canal {
                Kind::Gas
            } else {
                Kind::Tissue
            }
        }

        /// The runs of gas and outside air, whether each is inside the body, and each one's
        /// component (all the body's gas is one; outside air is none).
        fn scene(&self) -> (Runs, Vec<bool>, Vec<u32>) {
            let [nx, ny, nz] = DIMS;
            let mut runs = Runs::empty(ny);
            let (mut inside, mut comp) = (Vec::new(), Vec::new());
            for k in 0..nz {
                for j in 0..ny {
                    let mut i = 0;
                    while i < nx {
                        let what = self.kind(i, j, k);
                        let x0 = i;
                        while i < nx && self.kind(i, j, k) == what {
                            i += 1;
                        }
                        if what == Kind::Tissue {
                            continue;
                        }
                        runs.runs.push(Run {
                            x0: x0 as u32,
                            x1: i as u32,
                        });
                        runs.hu_sum.push(0);
                        runs.dark.push(0);
                        inside.push(what == Kind::Gas);
                        comp.push(if what == Kind::Gas { 0 } else { u32::MAX });
                    }
                    runs.row_start.push(runs.runs.len() as u32);
                }
            }
            (runs, inside, comp)
        }

        /// The tube found: the largest distance (voxels) of its runs from the catheter's axis
        /// outside the slices `open_k`, its entry's and its tip's slice.
        fn tube(&self) -> (f64, f64, f64) {
            let (runs, inside, comp) = self.scene();
            let edge = (self.from_k == 0).then_some(0);
            let tubes = find(&runs, &inside, &comp, |c| c == 0, DIMS, SPACING, edge);
            assert_eq!(tubes.len(), 1, "{tubes:?}");
            let t = &tubes[0];
            let open = |k: usize| self.open_k.is_some_and(|[a, b]| (a..b).contains(&k));
            let reach = t
                .runs
                .iter()
                .map(|&r| (row_of(&runs, r), runs.runs[r]))
                .filter(|&((_, k), _)| !open(k))
                .map(|((j, _), run)| {
                    [run.x0 as f64, run.x1 as f64 - 1.0]
                        .map(|x| (x - 20.0).hypot(j as f64 - 20.0))
                        .into_iter()
                        .fold(0.0, f64::max)
                })
                .fold(0.0, f64::max);
            (reach, t.entry[2], t.tip[2])
        }
    }

    /// The tube is the catheter's air from where it enters to its tip, and nothing round it.
    fn assert_catheter(c: Catheter, what: &str) {
        let (reach, entry, tip) = c.tube();
        assert!(
            reach <= 2.5,
            "{what}: the tube takes gas {reach} voxels from its axis"
        );
        assert!(
            entry <= (c.from_k + 1) as f64,
            "{what}: the tube enters at slice {entry}"
        );
        assert!(
            tip >= (TIP_K - 2) as f64,
            "{what}: the tube ends at slice {tip}"
        );
    }

    #[test]
    fn the_catheter_is_the_tube_and_the_canal_gas_round_it_is_not() {
        for from_k in [0, 2] {
            let c = Catheter {
                from_k,
                ..Default::default()
            };
            // Without gas round it, the catheter's air is followed up to where it opens.
            assert_catheter(c, "no canal");
            // The canal's gas reaches the skin: it closes round the catheter's air, so it is
            // not followed as a tube; the catheter is.
            let canal = Catheter {
                canal_gas: true,
                ..c
            };
            assert_catheter(canal, "canal");
            // Where the plastic is open to the canal's gas, the two are one; above, the tube
            // is the catheter's air again.
            let open = Catheter {
                open_k: Some([20, 25]),
                ..canal
            };
            assert_catheter(open, "plastic open");
            // A crescent of the canal's gas at the skin that closes round the catheter
            // higher up is no tube either.
            let crescent = Catheter {
                crescent_k: Some(20),
                ..canal
            };
            assert_catheter(crescent, "crescent");
        }
    }

    #[test]
    fn gas_round_the_catheters_air_is_told_from_its_air() {
        let c = Catheter {
            canal_gas: true,
            ..Default::default()
        };
        let (runs, _, comp) = c.scene();
        let part = |k: usize, round: bool| -> Vec<usize> {
            (0..DIMS[1])
                .flat_map(|j| runs.row(j, k))
                .filter(|&r| {
                    let (j, _) = row_of(&runs, r);
                    let x = runs.runs[r].x0 as f64;
                    ((x - 20.0).hypot(j as f64 - 20.0) > 3.0) == round
                })
                .collect()
        };
        let core = (MIN_CORE_MM2 / (SPACING[0] * SPACING[1])).ceil() as usize;
        // The ring closes round the catheter's air, and only that.
        let inner = closed_round_gas(&runs, &comp, 0, &part(30, true), core);
        assert_eq!(inner, part(30, false));
        assert!(closed_round_gas(&runs, &comp, 0, &part(30, false), core).is_empty());
        // Round the catheter's plastic alone (its air not gas of the component), it is no
        // ring round gas.
        let no_air: Vec<u32> = (0..comp.len())
            .map(|r| {
                let (j, _) = row_of(&runs, r);
                let x = runs.runs[r].x0 as f64;
                if (x - 20.0).hypot(j as f64 - 20.0) <= 3.0 {
                    u32::MAX
                } else {
                    comp[r]
                }
            })
            .collect();
        assert!(closed_round_gas(&runs, &no_air, 0, &part(30, true), core).is_empty());
    }
}
