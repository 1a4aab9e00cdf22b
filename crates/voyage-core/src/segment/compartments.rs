//! Step 6's compartments: gas regions with the pools and layers under their levels, joined
//! in 3D (air split by a level stays one compartment); which of them may be colon segments
//! (big enough, no skin fold's crevice, or seeded; never excluded), the rectum among them,
//! and each one's role in the chain.

use glam::DVec3;

use super::{
    SegmentOptions,
    components::{Found, Points, UnionFind, connect_3d},
    fluid::Pooled,
    runs::{Run, Runs, row_of, work_runs},
    work::{Bbox, GAS, LAYER, POOL, height, lps_box},
};
use crate::{Error, Result, Volume, anatomy::PatientFrame};

/// One gas region with its fluid.
#[derive(Clone, Debug)]
pub struct Compartment {
    pub voxels: usize,
    pub gas_voxels: usize,
    /// Sum of voxel positions (volume-local mm), for the centroid.
    pub sum_mm: DVec3,
    pub bbox: Bbox,
    /// Its lowest gas voxel in the patient frame (see [`lowest_in`]).
    pub lowest: [usize; 3],
    pub lowest_height: f64,
}

impl Compartment {
    pub fn centroid_mm(&self) -> DVec3 {
        self.sum_mm / self.voxels.max(1) as f64
    }
}

/// What a compartment may be in the chain.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Large gas that is neither lung nor stomach: colon, wherever it lies.
    Major,
    /// Big enough for a segment; colon where it lies on the colon's way.
    Minor,
    /// Large gas where the stomach lies (high on the left): the stomach, or a splenic flexure
    /// cut off by collapses of the descending and transverse colon. A minor that is colon
    /// also where it joins the two compartments of a gap the chain jumped across fat, through
    /// collapsed bowel on one side at least ([`chain`](super::chain)): a stomach does not lie
    /// between two of the colon's stumps.
    Upper,
    /// Too small, or excluded.
    Out,
}

/// The compartments and their runs.
pub(super) struct Compartments {
    /// The runs of gas, pool and layer.
    pub(super) runs: Runs,
    /// Per run: its compartment.
    pub(super) run_comp: Vec<u32>,
    pub(super) list: Vec<Compartment>,
    /// Every gas component's compartment.
    pub(super) of_gas: Vec<Option<u32>>,
    pub(super) voxel_ml: f64,
    /// A rectal catheter was found: the gas round it may hold an anal canal open below the
    /// rectum.
    pub(super) catheter: bool,
}

/// An axial section of bowel holds at least this much gas (mm², a disc 10 mm in radius); an
/// anal canal held open round a catheter holds under 100.
const BOWEL_SECTION_MM2: f64 = 300.0;

impl Compartments {
    /// Gas with its pools and layers. Without pools they are the gas components, from their
    /// runs; with pools, from the labels.
    pub(super) fn new(vol: &Volume<i16>, found: &Found, pooled: &Pooled) -> Compartments {
        let with_pools = pooled.pooled > 0;
        let runs = if with_pools {
            let scan = |j: usize, k: usize| {
                pooled.pool_rows[j + vol.dims()[1] * k]
                    || found.runs.row(j, k).any(|r| found.gas_run(r))
            };
            work_runs(&pooled.work, &pooled.cbox, scan, |x| {
                x == GAS || x == POOL || x == LAYER
            })
        } else {
            found.runs.filtered(|r| found.gas_run(r))
        };
        let mut uf = UnionFind::new(runs.runs.len());
        connect_3d(&runs, &vec![true; runs.runs.len()], vol.dims(), &mut uf);
        let (list, run_comp) = compartment_stats(
            &runs,
            with_pools.then_some(&pooled.work),
            &mut uf,
            vol.geometry(),
            PatientFrame::of(vol.geometry()).inferior(),
        );
        let mut parts = Compartments {
            runs,
            run_comp,
            list,
            of_gas: Vec::new(),
            voxel_ml: super::voxel_ml(vol),
            catheter: !found.tubes.is_empty(),
        };
        parts.of_gas = parts.gas_compartments(found);
        parts
    }

    /// Every gas component's compartment.
    fn gas_compartments(&self, found: &Found) -> Vec<Option<u32>> {
        let mut of_gas: Vec<Option<u32>> = vec![None; found.comps.len()];
        for (r, &c) in found.run_comp.iter().enumerate() {
            if found.is_gas(c) && of_gas[c as usize].is_none() {
                let (j, k) = row_of(&found.runs, r);
                of_gas[c as usize] = self.at([found.runs.runs[r].x0 as usize, j, k]);
            }
        }
        of_gas
    }

    /// The compartment holding voxel `v`, if any.
    pub(super) fn at(&self, v: [usize; 3]) -> Option<u32> {
        self.runs
            .at(v)
            .map(|r| self.run_comp[r])
            .filter(|&c| c != u32::MAX)
    }

    /// Compartment `c`'s gas (ml).
    pub(super) fn gas_ml(&self, c: u32) -> f64 {
        self.list[c as usize].gas_voxels as f64 * self.voxel_ml
    }

    /// The source side: the middle of compartment `c`'s lowest 2 mm ([`lowest_middle`]).
    pub(super) fn lowest_middle(&self, c: u32, geom: &crate::Geometry) -> [usize; 3] {
        lowest_middle(
            &self.runs,
            &self.run_comp,
            &self.list[c as usize],
            c,
            geom,
            PatientFrame::of(geom).inferior(),
        )
    }
}

/// Which compartments may be colon, and where the colon starts.
pub(super) struct Candidates {
    /// The compartments of the user's seeds and of the points to exclude.
    pub(super) seeded: Vec<u32>,
    pub(super) excluded: Vec<u32>,
    /// Per compartment: its gas lies in a crevice ([`crevices`]).
    pub(super) crevice: Vec<bool>,
    /// Per compartment: a segment candidate, big enough and no crevice, or seeded; never
    /// excluded.
    pub(super) candidate: Vec<bool>,
    /// The rectum: the candidate holding the lowest voxel in the patient frame (a seed makes
    /// its gas a candidate; where it lies, not the seed, decides the rectum).
    pub(super) rectum: u32,
    /// Per compartment: its role in the chain ([`roles`]).
    pub(super) roles: Vec<Role>,
    /// Per compartment: large gas no wider than small bowel's ([`small_bowel_wide`]), made
    /// minor.
    pub(super) narrow: Vec<bool>,
}

impl Candidates {
    /// The candidates among `parts`, with the user's `points`; an error where a seed's gas is
    /// also excluded, or no candidate is left.
    pub(super) fn choose(
        parts: &Compartments,
        points: &Points,
        vol: &Volume<i16>,
        opts: &SegmentOptions,
        found: &Found,
        from_mask: bool,
    ) -> Result<Candidates> {
        let seeded: Vec<u32> = points
            .seeds
            .iter()
            .filter_map(|&c| parts.of_gas[c])
            .collect();
        let excluded: Vec<u32> = points
            .exclude
            .iter()
            .filter_map(|&c| parts.of_gas[c])
            .collect();
        if let Some(i) = seeded.iter().position(|c| excluded.contains(c)) {
            return Err(Error::invalid(format!(
                "the seed {} lies in gas also excluded (by another point)",
                vol.geometry().describe_point(opts.seeds_mm[i])
            )));
        }
        let min_ml = opts.chain.min_segment_ml;
        let crevice = crevices(parts, min_ml, vol.spacing());
        let candidate: Vec<bool> = (0..parts.list.len() as u32)
            .map(|c| {
                !excluded.contains(&c)
                    && ((parts.gas_ml(c) >= min_ml && !crevice[c as usize]) || seeded.contains(&c))
            })
            .collect();
        let rectum =
            lowest(&parts.list, &candidate).ok_or_else(|| found.no_colon(opts, from_mask))?;
        let (roles, narrow) = roles(parts, rectum, |c| candidate[c as usize], vol.geometry());
        Ok(Candidates {
            seeded,
            excluded,
            crevice,
            candidate,
            rectum,
            roles,
            narrow,
        })
    }
}

/// Crevices: gas thin all over, a skin fold's (closed over at the skin in every axial slice,
/// it is not found as outside air), not bowel. Only compartments from `min_ml` on are looked
/// at.
fn crevices(parts: &Compartments, min_ml: f64, spacing: [f64; 3]) -> Vec<bool> {
    parts
        .list
        .iter()
        .enumerate()
        .map(|(c, comp)| {
            let ml = comp.gas_voxels as f64 * parts.voxel_ml;
            (min_ml..=CREVICE_MAX_ML).contains(&ml)
                && inscribed_radius_mm(&parts.runs, &parts.run_comp, c as u32, &comp.bbox, spacing)
                    < CREVICE_MM
        })
        .collect()
}

/// The candidate holding the lowest voxel in the patient frame (ties: the first).
fn lowest(list: &[Compartment], candidate: &[bool]) -> Option<u32> {
    (0..list.len() as u32)
        .filter(|&c| candidate[c as usize])
        .max_by(|&a, &b| {
            list[a as usize]
                .lowest_height
                .total_cmp(&list[b as usize].lowest_height)
                .then(b.cmp(&a))
        })
}

/// Compartments (6-connected runs of gas, pool and layer) with their statistics, and each
/// run's compartment.
/// `work`: the labels, to count gas among pools (None: every voxel is gas).
fn compartment_stats(
    runs: &Runs,
    work: Option<&Volume<u8>>,
    uf: &mut UnionFind,
    geom: &crate::Geometry,
    inferior: DVec3,
) -> (Vec<Compartment>, Vec<u32>) {
    let [nx, ny, nz] = geom.dims;
    let sp = geom.spacing;
    let mut of_root = vec![u32::MAX; runs.runs.len()];
    let mut run_comp = vec![u32::MAX; runs.runs.len()];
    let mut out: Vec<Compartment> = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for r in runs.row(j, k) {
                let root = uf.find(r);
                if of_root[root] == u32::MAX {
                    of_root[root] = out.len() as u32;
                    out.push(Compartment {
                        voxels: 0,
                        gas_voxels: 0,
                        sum_mm: DVec3::ZERO,
                        bbox: Bbox {
                            lo: [usize::MAX; 3],
                            hi: [0; 3],
                        },
                        lowest: [0; 3],
                        lowest_height: f64::NEG_INFINITY,
                    });
                }
                let c = of_root[root];
                run_comp[r] = c;
                let run = runs.runs[r];
                let (x0, x1) = (run.x0 as usize, run.x1 as usize);
                let cm = &mut out[c as usize];
                let n = x1 - x0;
                cm.voxels += n;
                cm.gas_voxels += work.map_or(n, |w| {
                    w.data()[nx * (j + ny * k) + x0..nx * (j + ny * k) + x1]
                        .iter()
                        .filter(|&&x| x == GAS)
                        .count()
                });
                cm.sum_mm += DVec3::new(
                    (x0 + x1 - 1) as f64 * 0.5 * sp[0] * n as f64,
                    (j * n) as f64 * sp[1],
                    (k * n) as f64 * sp[2],
                );
                cm.bbox = Bbox {
                    lo: [
                        cm.bbox.lo[0].min(x0),
                        cm.bbox.lo[1].min(j),
                        cm.bbox.lo[2].min(k),
                    ],
                    hi: [
                        cm.bbox.hi[0].max(x1 - 1),
                        cm.bbox.hi[1].max(j),
                        cm.bbox.hi[2].max(k),
                    ],
                };
                // The lowest voxel of the run lies at one of its ends.
                for x in [x0, x1 - 1] {
                    let h = height(
                        inferior,
                        geom.index_to_local(DVec3::new(x as f64, j as f64, k as f64)),
                    );
                    if h > cm.lowest_height {
                        cm.lowest_height = h;
                        cm.lowest = [x, j, k];
                    }
                }
            }
        }
    }
    (out, run_comp)
}

/// The voxel of compartment `c` nearest the middle of its lowest 2 mm (patient frame): the
/// same place whatever the storage order, where the lowest single voxel would be picked by
/// ties.
fn lowest_middle(
    runs: &Runs,
    run_comp: &[u32],
    comp: &Compartment,
    c: u32,
    geom: &crate::Geometry,
    inferior: DVec3,
) -> [usize; 3] {
    const SLAB_MM: f64 = 2.0;
    let floor = comp.lowest_height - SLAB_MM;
    let mut voxels = Vec::new();
    // The height along a row changes by inferior.x·sx per voxel: a row whose highest
    // possible value is below the slab is passed over.
    let (x_lo, x_hi) = (
        comp.bbox.lo[0] as f64 * geom.spacing[0],
        comp.bbox.hi[0] as f64 * geom.spacing[0],
    );
    let best_x = (inferior.x * x_lo).max(inferior.x * x_hi);
    for k in comp.bbox.lo[2]..=comp.bbox.hi[2] {
        for j in comp.bbox.lo[1]..=comp.bbox.hi[1] {
            if best_x
                + inferior.y * j as f64 * geom.spacing[1]
                + inferior.z * k as f64 * geom.spacing[2]
                < floor
            {
                continue;
            }
            for r in runs.row(j, k).filter(|&r| run_comp[r] == c) {
                let run = runs.runs[r];
                for x in run.x0 as usize..run.x1 as usize {
                    if height(
                        inferior,
                        geom.index_to_local(DVec3::new(x as f64, j as f64, k as f64)),
                    ) >= floor
                    {
                        voxels.push([x, j, k]);
                    }
                }
            }
        }
    }
    let mm = |v: [usize; 3]| geom.index_to_local(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64));
    let mid = voxels.iter().map(|&v| mm(v)).sum::<DVec3>() / voxels.len().max(1) as f64;
    voxels
        .into_iter()
        .min_by(|&a, &b| {
            mm(a)
                .distance(mid)
                .total_cmp(&mm(b).distance(mid))
                .then_with(|| {
                    let (p, q) = (
                        geom.index_to_patient(DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64)),
                        geom.index_to_patient(DVec3::new(b[0] as f64, b[1] as f64, b[2] as f64)),
                    );
                    p.x.total_cmp(&q.x)
                        .then(p.y.total_cmp(&q.y))
                        .then(p.z.total_cmp(&q.z))
                })
        })
        .unwrap_or(comp.lowest)
}

/// Gas from this size on (ml) that is neither lung nor stomach is colon, wherever it lies: in
/// an insufflated exam the colon's compartments are the largest gas below the diaphragm.
const MAJOR_ML: f64 = 200.0;

/// Each compartment's role in the chain: major (colon, [`MAJOR_ML`] of gas or more, unless
/// it lies where the stomach does or is no wider than small bowel), minor (a candidate
/// segment) or out; and whether it was made minor for being no wider than small bowel.
fn roles(
    parts: &Compartments,
    rectum: u32,
    candidate: impl Fn(u32) -> bool,
    geom: &crate::Geometry,
) -> (Vec<Role>, Vec<bool>) {
    let comps = &parts.list;
    let big = |c: u32| {
        c != rectum
            && candidate(c)
            && comps[c as usize].gas_voxels as f64 * parts.voxel_ml >= MAJOR_ML
    };
    let all = colon_box(parts, rectum, big, geom);
    (0..comps.len() as u32)
        .map(|c| {
            if !candidate(c) && c != rectum {
                (Role::Out, false)
            } else if big(c) && !flat(&comps[c as usize], geom) {
                if stomach_like(&comps[c as usize], geom, &all) {
                    (Role::Upper, false)
                } else if small_bowel_wide(parts, c, geom.spacing) {
                    (Role::Minor, true)
                } else {
                    (Role::Major, false)
                }
            } else {
                (Role::Minor, false)
            }
        })
        .unzip()
}

/// Gas-filled small bowel is at most this wide (mm; wider is dilated): an insufflated colon
/// holding [`MAJOR_ML`] of gas is wider somewhere (on `ctc/prone-tagged` its two large
/// compartments hold balls 37 and 54 mm across; the full-size phantom's small-bowel loops,
/// 249 ml of gas behind a closed ileocecal valve, 21 mm).
pub(super) const SMALL_BOWEL_MAX_MM: f64 = 25.0;

/// No ball wider than [`SMALL_BOWEL_MAX_MM`] fits in compartment `c`: its large gas is
/// small bowel's, a loop or a chain of loops, not colon. It is then a minor compartment,
/// colon only where it lies on the colon's way: chained as a major, loops lying between two
/// collapsed stretches of the colon stood in for the stretch between them.
fn small_bowel_wide(parts: &Compartments, c: u32, spacing: [f64; 3]) -> bool {
    let (comp, r) = (&parts.list[c as usize], SMALL_BOWEL_MAX_MM / 2.0);
    // The exact ball needs a distance map over the whole box (a third of a second for
    // `ctc/prone-tagged`'s 3.2 l): a colon's wide gas shows on coarse cells first.
    coarse_radius_at_least_mm(&parts.runs, &parts.run_comp, c, &comp.bbox, spacing) < r
        && inscribed_radius_mm(&parts.runs, &parts.run_comp, c, &comp.bbox, spacing) < r
}

/// All of its gas in the top 40 % of the large gas's box, its middle on the patient's left:
/// where the stomach lies under the left diaphragm (a splenic flexure alone in its own
/// compartment would look the same, and is then given back by a seed).
fn stomach_like(comp: &Compartment, geom: &crate::Geometry, all: &[DVec3; 2]) -> bool {
    let b = lps_box(geom, &comp.bbox);
    let c = geom.local_to_patient(comp.centroid_mm());
    let span = all[1] - all[0];
    b[0].z > all[0].z + 0.6 * span.z && c.x > all[0].x + 0.5 * span.x
}

/// Thinner than [`MIN_BOX_MM`] along some axis of the patient frame: a sheet of gas (air over
/// the water of a phantom's tank, under a prone patient's skin folds), not a bowel.
fn flat(comp: &Compartment, geom: &crate::Geometry) -> bool {
    let b = lps_box(geom, &comp.bbox);
    (b[1] - b[0]).min_element() < MIN_BOX_MM
}

/// A colon compartment's box is at least this wide along every axis (mm).
const MIN_BOX_MM: f64 = 15.0;

/// The LPS box of the rectum's compartment and those where `with(c)`: the colon's. It
/// begins at the rectum: where a catheter holds an anal canal open below it, the canal's gas
/// does not stretch the box down ([`Compartments::bowel_from_z`]).
pub(super) fn colon_box(
    parts: &Compartments,
    rectum: u32,
    with: impl Fn(u32) -> bool,
    geom: &crate::Geometry,
) -> [DVec3; 2] {
    let comps = &parts.list;
    let b = (0..comps.len() as u32)
        .filter(|&c| with(c))
        .fold(comps[rectum as usize].bbox, |a, c| {
            a.union(&comps[c as usize].bbox)
        });
    let [mut lo, hi] = lps_box(geom, &b);
    let rectum_from = parts
        .catheter
        .then(|| parts.bowel_from_z(rectum, geom))
        .flatten();
    if let Some(z) = rectum_from {
        lo.z = lo.z.max(z);
    }
    [lo, hi]
}

impl Compartments {
    /// Height (LPS z, mm) of the lowest axial slice in which compartment `c` is as wide as a
    /// bowel ([`BOWEL_SECTION_MM2`]); None if it is nowhere.
    pub(super) fn bowel_from_z(&self, c: u32, geom: &crate::Geometry) -> Option<f64> {
        let b = &self.list[c as usize].bbox;
        let voxel_mm2 = geom.spacing[0] * geom.spacing[1];
        let mid = [0, 1].map(|a| (b.lo[a] + b.hi[a]) as f64 / 2.0);
        (b.lo[2]..=b.hi[2])
            .filter(|&k| {
                let voxels: u32 = (b.lo[1]..=b.hi[1])
                    .flat_map(|j| self.runs.row(j, k))
                    .filter(|&r| self.run_comp[r] == c)
                    .map(|r| self.runs.runs[r].x1 - self.runs.runs[r].x0)
                    .sum();
                voxels as f64 * voxel_mm2 >= BOWEL_SECTION_MM2
            })
            .map(|k| {
                geom.index_to_patient(DVec3::new(mid[0], mid[1], k as f64))
                    .z
            })
            .reduce(f64::min)
    }
}

/// Gas of a compartment (up to [`CREVICE_MAX_ML`]) whose widest inscribed ball is narrower
/// than this radius (mm) lies in a crevice: a skin fold (1–2 mm), not a bowel, whose gas
/// even collapsed holds bubbles wider than 5 mm.
pub(super) const CREVICE_MM: f64 = 2.5;

const CREVICE_MAX_ML: f64 = 50.0;

/// The runs of compartment `c` (in `runs`, within `bbox`), each with its row (j, k).
fn runs_of<'a>(
    runs: &'a Runs,
    run_comp: &'a [u32],
    c: u32,
    bbox: &'a Bbox,
) -> impl Iterator<Item = (usize, usize, Run)> + 'a {
    (bbox.lo[2]..=bbox.hi[2]).flat_map(move |k| {
        (bbox.lo[1]..=bbox.hi[1]).flat_map(move |j| {
            runs.row(j, k)
                .filter(move |&r| run_comp[r] == c)
                .map(move |r| (j, k, runs.runs[r]))
        })
    })
}

/// Cells of about this size (mm) for [`coarse_radius_at_least_mm`].
const COARSE_CELL_MM: f64 = 3.0;

/// A radius (mm) that the widest ball inside compartment `c` reaches at least: the distance
/// from a cell (of about [`COARSE_CELL_MM`]) that it fills whole to the nearest cell that it
/// does not, less half a cell's diagonal. (Every point of the ball that this leaves lies
/// nearer the middle of a whole cell than of any other, so in it.)
fn coarse_radius_at_least_mm(
    runs: &Runs,
    run_comp: &[u32],
    c: u32,
    bbox: &Bbox,
    spacing: [f64; 3],
) -> f64 {
    let f = spacing.map(|s| ((COARSE_CELL_MM / s).round() as usize).max(1));
    // One cell of margin: the wall all round.
    let cells = [0, 1, 2].map(|a| bbox.widths()[a].div_ceil(f[a]) + 2);
    let cell_mm = [0, 1, 2].map(|a| f[a] as f64 * spacing[a]);
    let mut count = vec![0u32; cells.iter().product()];
    let at = |x: usize, j: usize, k: usize| {
        let [cx, cy, cz] = [
            (x - bbox.lo[0]) / f[0] + 1,
            (j - bbox.lo[1]) / f[1] + 1,
            (k - bbox.lo[2]) / f[2] + 1,
        ];
        cx + cells[0] * (cy + cells[1] * cz)
    };
    for (j, k, Run { x0, x1 }) in runs_of(runs, run_comp, c, bbox) {
        let (x0, x1) = (x0 as usize, x1 as usize);
        // The run's voxels cell by cell along the row.
        let mut x = x0;
        while x < x1 {
            let end = (bbox.lo[0] + ((x - bbox.lo[0]) / f[0] + 1) * f[0]).min(x1);
            count[at(x, j, k)] += (end - x) as u32;
            x = end;
        }
    }
    let full = (f[0] * f[1] * f[2]) as u32;
    let mask: Vec<u8> = count.iter().map(|&n| (n == full) as u8).collect();
    let Some(max) = crate::Geometry::new(cells, cell_mm, [0.0; 3])
        .ok()
        .and_then(|g| Volume::from_vec(g, mask).ok())
        .and_then(|v| crate::distance::distance_to_wall(&v).ok())
        .map(|d| d.data.iter().cloned().fold(0.0f32, f32::max) as f64)
    else {
        return 0.0;
    };
    let half_diagonal = cell_mm.iter().map(|m| m * m).sum::<f64>().sqrt() / 2.0;
    max - half_diagonal
}

/// The radius (mm) of the widest ball inside compartment `c` (its runs in `runs`, within
/// `bbox`).
fn inscribed_radius_mm(
    runs: &Runs,
    run_comp: &[u32],
    c: u32,
    bbox: &Bbox,
    spacing: [f64; 3],
) -> f64 {
    // One voxel of margin: the wall all round.
    let dims = bbox.widths().map(|w| w + 2);
    let Ok(g) = crate::Geometry::new(dims, spacing, [0.0; 3]) else {
        return f64::INFINITY;
    };
    let Ok(mut mask) = Volume::filled(g, 0u8) else {
        return f64::INFINITY;
    };
    for (j, k, Run { x0, x1 }) in runs_of(runs, run_comp, c, bbox) {
        let row = mask
            .geometry()
            .index(0, j - bbox.lo[1] + 1, k - bbox.lo[2] + 1);
        let from = row + x0 as usize - bbox.lo[0] + 1;
        mask.data_mut()[from..from + (x1 - x0) as usize].fill(1);
    }
    let grid = crate::grid::BoxGrid::around([[0; 3], dims.map(|d| d - 1)], 0, dims);
    let ds = crate::distance::distance_to_wall_in(&mask, grid);
    ds.data.iter().cloned().fold(0.0f32, f32::max) as f64
}
