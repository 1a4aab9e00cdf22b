//! The colon as a chain of gas segments, rectum → cecum.
//!
//! A real exam's colon is often in several gas segments: a collapsed or fluid-filled stretch
//! splits it. Each *compartment* (a gas region with the tagged fluid under its level) is
//! reduced to a coarse grid of ~4 mm blocks, where its two ends are found by a double sweep
//! of geodesic distance. The chain starts at the rectum (the compartment holding the lowest
//! gas in the patient frame), leaves each compartment at its end farthest from where it
//! entered, and goes on to the nearest free end of another compartment, bridged by the
//! cheapest path through the CT ([`super::bridge`]), while one lies within `max_gap_mm`.

use glam::DVec3;

use super::{
    bridge::{Bridges, Path},
    coarse::Coarse,
    compartments::{Candidates, Compartment, Compartments, Role, colon_box},
    course::Course,
    fluid::Pooled,
    work::Bbox,
};
use crate::{Volume, anatomy::PatientFrame};

/// How many of the nearest free compartments are bridged to at each step.
const CANDIDATES: usize = 3;

#[derive(Clone, Debug)]
pub struct ChainOptions {
    /// A compartment with less gas than this (ml) is not a colon segment by itself.
    pub min_segment_ml: f64,
    /// Segments farther apart than this (mm, end to end) are not joined.
    pub max_gap_mm: f64,
    /// A bridge whose mean cost per mm outside the segments is above this goes through fat
    /// or bone, not collapsed bowel.
    pub max_bridge_cost: f64,
}

impl Default for ChainOptions {
    fn default() -> Self {
        ChainOptions {
            min_segment_ml: 5.0,
            max_gap_mm: 100.0,
            max_bridge_cost: 4.0,
        }
    }
}

/// One link of the chain: a compartment, where it is entered and left (blocks).
#[derive(Clone, Debug)]
pub struct Link {
    pub comp: u32,
    pub entry: usize,
    pub exit: usize,
}

/// Why a compartment is not in the chain.
#[derive(Clone, Debug, PartialEq)]
pub enum Left {
    TooSmall,
    /// Its nearest block lies this far (mm) from the chain's end, beyond `max_gap_mm`.
    TooFar(f64),
    /// Within reach (mm from the chain's end), but the chain had reached the cecum.
    BeyondCecum(f64),
    /// Within reach (mm from the chain's end: its nearest block), but the tail took no
    /// bridge to it (its ends lie back along the course, or beyond reach, or no cheap way
    /// through the CT leads there).
    NotOnward(f64),
    BridgeTooDear {
        gap_mm: f64,
        cost: f64,
    },
    /// The user said it is not colon.
    Excluded,
}

pub struct Chain {
    pub links: Vec<Link>,
    /// `gaps[i]` joins `links[i]` and `links[i + 1]`.
    pub gaps: Vec<Path>,
    /// Where the course ends at the cecum, when large compartments reach it.
    pub cecum: Option<Cecum>,
    pub left: Vec<(u32, Left)>,
}

/// The compartment that ends the course, and its blocks at the cecum, the pole first (see
/// [`cecum_blocks`]).
pub struct Cecum {
    pub comp: u32,
    pub blocks: Vec<usize>,
}

/// Step 7's outcome: the chain of compartments, on its coarse grid, and where it ends.
pub(super) struct Chained {
    pub(super) coarse: Coarse,
    pub(super) chain: Chain,
    /// The pole of the cecum's gas, when the course ended there.
    pub(super) cecum_voxel: Option<[usize; 3]>,
    /// What the user must hear of (a seed's gas joined, or not).
    pub(super) warnings: Vec<String>,
}

/// Step 7: the chain of `cand`'s compartments from the rectum, bridged through the CT (`ct`;
/// None: a mask's background) between the labels of `pooled`, the seeds' gas joined at its
/// end, the excluded said so.
pub(super) fn colon(
    parts: &Compartments,
    cand: &Candidates,
    pooled: &Pooled,
    ct: Option<&Volume<i16>>,
    opts: &ChainOptions,
) -> Chained {
    let geom = pooled.work.geometry();
    let coarse = coarse_grid(parts, cand, &pooled.cbox, geom.dims, geom.spacing);
    let ways = Bridges {
        coarse: &coarse,
        work: &pooled.work,
        parts,
        ct,
        down: ct.map(|_| PatientFrame::of(geom).nearest_axis(pooled.orientation.gravity())),
    };
    let course = Course::new(
        geom,
        colon_box(
            parts,
            cand.rectum,
            |c| cand.roles[c as usize] == Role::Major,
            geom,
        ),
    );
    let mut ch = chain(
        &coarse,
        &parts.list,
        parts.voxel_ml,
        cand.rectum,
        &cand.roles,
        &course,
        opts,
        |from, to, a, b| ways.bridge(from, to, a, b),
    );
    // The pole of the cecum's gas: fluid may lie lower, and is cleansed or cut away.
    let cecum_voxel = ch.cecum.as_ref().and_then(|c| {
        c.blocks
            .iter()
            .find_map(|&b| ways.voxel_of_comp(b, c.comp, true))
    });
    let warnings = join_seeds(&mut ch, &coarse, parts, cand, |from, to, a, b| {
        ways.bridge(from, to, a, b)
    });
    for (c, why) in &mut ch.left {
        if cand.excluded.contains(c) {
            *why = Left::Excluded;
        }
    }
    Chained {
        coarse,
        chain: ch,
        cecum_voxel,
        warnings,
    }
}

impl Chain {
    /// Compartment `comp`, entered and left at `ends`, taken into gap `g` in place of its
    /// bridge: `bridges` lead to it and on from it.
    fn take_into_gap(&mut self, g: usize, bridges: [Path; 2], comp: u32, ends: [usize; 2]) {
        self.gaps.splice(g..=g, bridges);
        self.links.insert(
            g + 1,
            Link {
                comp,
                entry: ends[0],
                exit: ends[1],
            },
        );
    }

    /// Gap `g` now leaves its first compartment at block `exit` and enters the next at
    /// `entry` (a compartment entered and left at one block is left where it is entered).
    fn move_gap_ends(&mut self, g: usize, exit: usize, entry: usize) {
        self.links[g].exit = exit;
        let next = &mut self.links[g + 1];
        if next.exit == next.entry {
            next.exit = entry;
        }
        next.entry = entry;
    }
}

impl Chained {
    /// The gas of the chained compartments (ml).
    pub(super) fn gas_ml(&self, parts: &Compartments) -> f64 {
        self.chain.links.iter().map(|l| parts.gas_ml(l.comp)).sum()
    }
}

/// The coarse grid of the candidates (and the rectum) within `cbox`.
fn coarse_grid(
    parts: &Compartments,
    cand: &Candidates,
    cbox: &Bbox,
    dims: [usize; 3],
    spacing: [f64; 3],
) -> Coarse {
    let mut coarse = Coarse::new(dims, spacing);
    for k in cbox.lo[2]..=cbox.hi[2] {
        for j in cbox.lo[1]..=cbox.hi[1] {
            for r in parts.runs.row(j, k) {
                let c = parts.run_comp[r];
                if c == cand.rectum || cand.candidate[c as usize] {
                    coarse.mark_run(
                        parts.runs.runs[r].x0 as usize,
                        parts.runs.runs[r].x1 as usize,
                        j,
                        k,
                        c,
                    );
                }
            }
        }
    }
    coarse
}

/// A seed's gas is colon, wherever the chain went: joined at the chain's end (`bridge` as in
/// [`chain`]). Returns what the user must hear of it.
fn join_seeds(
    ch: &mut Chain,
    coarse: &Coarse,
    parts: &Compartments,
    cand: &Candidates,
    bridge: impl Fn(usize, usize, u32, u32) -> Option<Path>,
) -> Vec<String> {
    let mut warnings = Vec::new();
    for &s in &cand.seeded {
        if ch.links.iter().any(|l| l.comp == s) {
            continue;
        }
        let last = ch.links.last().map_or(0, |l| l.exit);
        let at = coarse.centre_mm(last);
        let lowest = coarse.block_of(parts.list[s as usize].lowest);
        let entry = [lowest]
            .into_iter()
            .chain([coarse.farthest(s, lowest).0])
            .min_by(|&x, &y| {
                coarse
                    .centre_mm(x)
                    .distance(at)
                    .total_cmp(&coarse.centre_mm(y).distance(at))
            })
            .unwrap_or(0);
        let from = ch.links.last().map(|l| l.comp).unwrap_or(cand.rectum);
        if let Some(p) = bridge(last, entry, from, s) {
            warnings.push(format!("the seed's gas was not joined to the colon by itself: joined to its end through {:.0} mm of tissue", p.length_mm));
            ch.links.push(Link {
                comp: s,
                entry,
                exit: coarse.farthest(s, entry).0,
            });
            ch.gaps.push(p);
            ch.left.retain(|(c, _)| *c != s);
        } else {
            warnings.push(format!("the seed's gas ({:.0} ml) could not be joined to the colon: no way to it through the CT", parts.gas_ml(s)));
        }
    }
    warnings
}

/// Orders the colon's compartments from `rectum` to the cecum.
///
/// 1. The spine: the rectum, then every major compartment in the order of the colon's
///    course ([`Course::along`] of its centroid), each joined to the one before where they
///    face each other ([`facing_ends`]), however far apart: the stretch between them is
///    collapsed or filled with fluid.
/// 2. Minor compartments on the way: one that lies between two spine neighbours, and costs
///    little more to pass through than the bridge that skips it, is taken in; where a
///    bridge crosses fat, a compartment that joins its two ends through collapsed bowel is
///    taken in ([`take_in_between`]), and a bridge that jumps across fat from a loop is
///    made again stump to stump where that runs through collapsed bowel ([`join_stumps`]).
/// 3. The tail: from the last compartment, the nearest free end further along the course,
///    while one lies within `max_gap_mm` and its bridge is cheap (what the chain did before
///    there were majors, and still does when there are none).
///
/// `bridge(from_block, to_block, a, b)` is the cheapest path between two blocks of
/// compartments a and b; `voxel_ml` the volume of a voxel.
#[allow(clippy::too_many_arguments)]
pub fn chain(
    coarse: &Coarse,
    comps: &[Compartment],
    voxel_ml: f64,
    rectum: u32,
    roles: &[Role],
    course: &Course,
    opts: &ChainOptions,
    mut bridge: impl FnMut(usize, usize, u32, u32) -> Option<Path>,
) -> Chain {
    let blocks = coarse.blocks_by_comp(comps.len());
    let along = |c: u32| course.along(comps[c as usize].centroid_mm());
    let entry = coarse.block_of(comps[rectum as usize].lowest);
    let mut ch = Chain {
        links: vec![Link {
            comp: rectum,
            entry,
            exit: entry,
        }],
        gaps: Vec::new(),
        cecum: None,
        left: Vec::new(),
    };
    let mut majors: Vec<u32> = (0..comps.len() as u32)
        .filter(|&c| c != rectum && roles[c as usize] == Role::Major)
        .collect();
    majors.sort_by(|&a, &b| along(a).total_cmp(&along(b)));
    for &b in &majors {
        let a = ch.links[ch.links.len() - 1].clone();
        let Some((exit, entry)) = facing_ends(coarse, &blocks, &a, b, EARLY_EXIT_MM) else {
            continue;
        };
        match bridge(exit, entry, a.comp, b) {
            Some(p) => {
                ch.links.last_mut().expect("the rectum").exit = exit;
                ch.gaps.push(p);
                ch.links.push(Link {
                    comp: b,
                    entry,
                    exit: entry,
                });
            }
            None => ch.left.push((b, Left::TooFar(f64::INFINITY))),
        }
    }
    // The last compartment is left at the cecum's pole, where the course knows it; else at
    // its end farthest from where it was entered.
    let last = ch.links.len() - 1;
    let c = ch.links[last].comp;
    let at_cecum = if majors.is_empty() {
        Vec::new()
    } else {
        cecum_blocks(coarse, &blocks[c as usize], course)
    };
    ch.links[last].exit = match at_cecum.first() {
        Some(&b) => b,
        None => coarse.farthest(c, ch.links[last].entry).0,
    };
    // The course ended at the cecum: the gas beyond it is the ileum's, not colon.
    if !at_cecum.is_empty() && course.along(coarse.centre_mm(ch.links[last].exit)) >= COURSE_END {
        ch.cecum = Some(Cecum {
            comp: c,
            blocks: at_cecum,
        });
    }
    let mut free: Vec<u32> = (0..comps.len() as u32)
        .filter(|&c| c != rectum && matches!(roles[c as usize], Role::Minor | Role::Upper))
        .collect();
    if !majors.is_empty() {
        take_in_on_the_way(coarse, &blocks, &mut ch, &mut free, &mut bridge);
        let between: Vec<u32> = free
            .iter()
            .copied()
            .filter(|&c| match roles[c as usize] {
                Role::Upper => true,
                Role::Minor => comps[c as usize].gas_voxels as f64 * voxel_ml >= BETWEEN_MIN_ML,
                _ => false,
            })
            .collect();
        for c in between {
            let upper = roles[c as usize] == Role::Upper;
            if take_in_between(coarse, &blocks, &mut ch, c, upper, &mut bridge) {
                free.retain(|&x| x != c);
            }
        }
        join_stumps(coarse, &blocks, &mut ch, &mut bridge);
    }
    if ch.cecum.is_none() {
        extend_tail(
            coarse,
            comps,
            &mut ch,
            &mut free,
            (!majors.is_empty()).then_some(course),
            opts,
            &mut bridge,
        );
    }
    // Whatever stayed free was not taken from the chain's end: too far from it, past the
    // cecum, or not reached within reach.
    let end = coarse.centre_mm(ch.links[ch.links.len() - 1].exit);
    for &c in &free {
        if !ch.left.iter().any(|(x, _)| *x == c) {
            let d = blocks[c as usize]
                .iter()
                .map(|&b| coarse.centre_mm(b).distance(end))
                .fold(f64::INFINITY, f64::min);
            let why = if d > opts.max_gap_mm {
                Left::TooFar(d)
            } else if ch.cecum.is_some() {
                Left::BeyondCecum(d)
            } else {
                Left::NotOnward(d)
            };
            ch.left.push((c, why));
        }
    }
    let links = ch.links.clone();
    ch.left.retain(|(c, _)| !links.iter().any(|l| l.comp == *c));
    for c in 0..comps.len() as u32 {
        if c != rectum && roles[c as usize] == Role::Out {
            ch.left.push((c, Left::TooSmall));
        }
    }
    ch
}

/// The cecum's blocks among a compartment's `blocks`: those furthest along the course
/// (within [`CECUM_BAND`]), lowest first in the patient frame: the cecal pole comes first.
fn cecum_blocks(coarse: &Coarse, blocks: &[usize], course: &Course) -> Vec<usize> {
    let along: Vec<f64> = blocks
        .iter()
        .map(|&b| course.along(coarse.centre_mm(b)))
        .collect();
    let last = along.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let mut band: Vec<usize> = blocks
        .iter()
        .zip(&along)
        .filter(|&(_, &t)| t >= last - CECUM_BAND)
        .map(|(&b, _)| b)
        .collect();
    band.sort_by(|&x, &y| {
        course
            .height(coarse.centre_mm(x))
            .total_cmp(&course.height(coarse.centre_mm(y)))
    });
    band
}

/// A chain whose large compartments reach this far along the course (fraction) has reached
/// the cecum.
const COURSE_END: f64 = 0.9;

/// How far short of the course's end (fraction) a block may be and still be the cecum's.
const CECUM_BAND: f64 = 0.03;

/// A compartment left farther than this (mm, through its gas) short of its far end would
/// leave the rest of it a dead end: a loop passing close by another compartment's middle,
/// not where the colon goes on (see [`facing_ends`]).
const EARLY_EXIT_MM: f64 = 100.0;

/// How much a block's distance from its compartment's end adds to the cost of joining there
/// (mm per mm), when the nearest join leaves early ([`EARLY_EXIT_MM`]).
const OFF_END: f64 = 0.5;

/// Where compartment `a` (entered at `a.entry`) and compartment `b` face each other: a block
/// in the far half of `a` from its entry and a block of `b`, each the nearest to the other
/// (two rounds from `b`'s centroid). A collapsed stretch leaves two stumps that face each
/// other end to end; where the nearest block of `a` instead lies far short of its far end
/// (a sigmoid loop under a sagging transverse colon, [`EARLY_EXIT_MM`]), the blocks are
/// chosen again, each the cheapest for the other, a pair costing its distance plus [`OFF_END`]
/// times how far each block lies from its compartment's end (`a`'s end farthest from its
/// entry, `b`'s nearer end).
fn facing_ends(
    coarse: &Coarse,
    blocks: &[Vec<usize>],
    a: &Link,
    b: u32,
    early_exit_mm: f64,
) -> Option<(usize, usize)> {
    let (dist, (far_end, far)) = coarse.distances(a.comp, a.entry);
    let far_half: Vec<usize> = blocks[a.comp as usize]
        .iter()
        .copied()
        .filter(|&x| dist[x] >= 0.5 * far)
        .collect();
    let of_b = &blocks[b as usize];
    let centroid =
        of_b.iter().map(|&x| coarse.centre_mm(x)).sum::<DVec3>() / of_b.len().max(1) as f64;
    let mut exit = coarse.nearest(&far_half, centroid)?;
    let mut entry = coarse.nearest(of_b, coarse.centre_mm(exit))?;
    for _ in 0..2 {
        exit = coarse.nearest(&far_half, coarse.centre_mm(entry))?;
        entry = coarse.nearest(of_b, coarse.centre_mm(exit))?;
    }
    let off_a = |x: usize| far - dist[x];
    if off_a(exit) <= early_exit_mm {
        return Some((exit, entry));
    }
    let off_b = off_ends(coarse, b, of_b)?;
    let off_b = |x: usize| off_b[x];
    let cheapest = |candidates: &[usize], off: &dyn Fn(usize) -> f64, to: usize| {
        let to = coarse.centre_mm(to);
        candidates.iter().copied().min_by(|&x, &y| {
            let cost = |x: usize| coarse.centre_mm(x).distance(to) + OFF_END * off(x);
            cost(x).total_cmp(&cost(y))
        })
    };
    let mut exit = far_end;
    let mut entry = cheapest(of_b, &off_b, exit)?;
    for _ in 0..2 {
        exit = cheapest(&far_half, &off_a, entry)?;
        entry = cheapest(of_b, &off_b, exit)?;
    }
    Some((exit, entry))
}

/// For each block of compartment `c` (`blocks`), the geodesic distance (mm) to the nearer
/// of its two ends (a double sweep from its first block); None when it has no blocks.
fn off_ends(coarse: &Coarse, c: u32, blocks: &[usize]) -> Option<Vec<f64>> {
    let start = *blocks.first()?;
    let (one, _) = coarse.farthest(c, start);
    let (from_one, (other, _)) = coarse.distances(c, one);
    let (from_other, _) = coarse.distances(c, other);
    Some(
        from_one
            .iter()
            .zip(&from_other)
            .map(|(a, b)| a.min(*b))
            .collect(),
    )
}

/// A minor compartment is on the way between two neighbours when passing by it is at most
/// this much longer than the straight way (fraction, and at least [`DETOUR_MIN_MM`]).
const DETOUR: f64 = 0.25;
const DETOUR_MIN_MM: f64 = 20.0;
/// ... and when its two bridges cost at most this much more than the one that skips it.
const DETOUR_COST: f64 = 1.25;

/// Step 2 of [`chain`]: minor compartments between spine neighbours join the chain there.
fn take_in_on_the_way(
    coarse: &Coarse,
    blocks: &[Vec<usize>],
    ch: &mut Chain,
    free: &mut Vec<u32>,
    bridge: &mut impl FnMut(usize, usize, u32, u32) -> Option<Path>,
) {
    let mut g = 0;
    while g < ch.gaps.len() {
        let (a, b) = (ch.links[g].clone(), ch.links[g + 1].clone());
        let (p, q) = (coarse.centre_mm(a.exit), coarse.centre_mm(b.entry));
        let straight = p.distance(q);
        let detour = |x: usize| {
            let c = coarse.centre_mm(x);
            c.distance(p) + c.distance(q)
        };
        // The minor compartments on the way, least detour first.
        let mut near: Vec<(f64, u32)> = free
            .iter()
            .map(|&c| {
                let d = blocks[c as usize]
                    .iter()
                    .map(|&x| detour(x))
                    .fold(f64::INFINITY, f64::min);
                (d, c)
            })
            .filter(|&(d, _)| d <= straight + (DETOUR * straight).max(DETOUR_MIN_MM))
            .collect();
        near.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        let direct = ch.gaps[g].cost();
        let mut taken = false;
        for &(_, m) in near.iter().take(CANDIDATES) {
            let of_m = &blocks[m as usize];
            let (Some(m_in), Some(m_out)) = (coarse.nearest(of_m, p), coarse.nearest(of_m, q))
            else {
                continue;
            };
            let (Some(p1), Some(p2)) = (
                bridge(a.exit, m_in, a.comp, m),
                bridge(m_out, b.entry, m, b.comp),
            ) else {
                continue;
            };
            if p1.cost() + p2.cost() <= DETOUR_COST * direct {
                ch.take_into_gap(g, [p1, p2], m, [m_in, m_out]);
                free.retain(|&x| x != m);
                taken = true;
                break;
            }
        }
        // After a minor is taken in, the gap before it is looked at again.
        if !taken {
            g += 1;
        }
    }
}

/// Step 2c of [`chain`]: a gap whose bridge jumps across fat (dearer than [`COLLAPSED_COST`]
/// per mm, and at least [`JUMP_MM`] long) between the nearest blocks of its two compartments
/// is bridged again stump to stump where that runs through collapsed bowel: the colon goes
/// on where it collapsed, not where a loop of it passes near the next piece (the sigmoid
/// collapsed: its piece joined 37 mm across fat from a loop, the collapse's middle passed at
/// 28–35 mm).
fn join_stumps(
    coarse: &Coarse,
    blocks: &[Vec<usize>],
    ch: &mut Chain,
    bridge: &mut impl FnMut(usize, usize, u32, u32) -> Option<Path>,
) {
    for g in 0..ch.gaps.len() {
        let jump = &ch.gaps[g];
        if through_bowel(jump) || jump.length_mm < JUMP_MM {
            continue;
        }
        let (a, b) = (ch.links[g].clone(), ch.links[g + 1].clone());
        let Some((a_exit, b_in)) = facing_ends(coarse, blocks, &a, b.comp, 0.0) else {
            continue;
        };
        let Some(p) = bridge(a_exit, b_in, a.comp, b.comp) else {
            continue;
        };
        if !through_bowel(&p) {
            continue;
        }
        ch.gaps[g] = p;
        ch.move_gap_ends(g, a_exit, b_in);
    }
}

/// A bridge across fat shorter than this (mm) is a thin wall between two pieces that touch,
/// not a jump from one loop to another ([`join_stumps`]).
const JUMP_MM: f64 = 10.0;

/// A minor compartment taken into a gap of the chain by [`take_in_between`] holds at least
/// this much gas (ml): a stretch of colon between two collapses, not a pocket of small-bowel
/// gas (`ctc/prone-tagged` holds one of 10 ml high on the left, 120 and 99 mm of soft tissue
/// from the sigmoid's two pieces).
const BETWEEN_MIN_ML: f64 = 50.0;

/// A gap whose bridge crosses fat (mean cost above this per mm) is no collapsed stretch:
/// the chain jumped there; a bridge at most this dear runs through collapsed bowel.
const COLLAPSED_COST: f64 = 2.0;

/// Whether bridge `p` runs through collapsed bowel, not across fat ([`COLLAPSED_COST`]).
fn through_bowel(p: &Path) -> bool {
    p.mean_cost <= COLLAPSED_COST
}

/// Step 2b of [`chain`]: large gas where the stomach lies ([`Role::Upper`], compartment `m`)
/// is taken into a gap of the chain whose bridge crosses fat, where it joins the gap's two
/// compartments at facing ends, through collapsed bowel on one side at least (a bridge at
/// most [`COLLAPSED_COST`] per mm), for less than the bridge that skips it: a splenic flexure
/// cut off by collapses of the descending and transverse colon, which the chain had skipped
/// from the sigmoid's loop under the transverse colon across the mesentery (on the colon
/// phantom with all three collapsed, 996 mm of a 1562 mm colon; the bridge through the
/// phantom's collapsed transverse colon costs 4.3 per mm, its thin cord in fat). A stomach
/// does not lie on the colon's way between two of its stumps. A smaller compartment
/// (`upper` false) is taken in only through collapsed bowel on both sides, whatever the
/// bridges cost: a sigmoid–descending stretch between two collapses, which the chain had
/// skipped from a sigmoid loop across the fat to the cecum beside it (prone with the
/// sigmoid and descending collapsed: 0.21× the colon's length). Returns whether it was taken.
fn take_in_between(
    coarse: &Coarse,
    blocks: &[Vec<usize>],
    ch: &mut Chain,
    m: u32,
    upper: bool,
    bridge: &mut impl FnMut(usize, usize, u32, u32) -> Option<Path>,
) -> bool {
    // A smaller compartment is joined end to end, stump to stump: its loops may pass nearer
    // the gap's compartments elsewhere.
    let early = if upper { EARLY_EXIT_MM } else { 0.0 };
    for g in 0..ch.gaps.len() {
        if through_bowel(&ch.gaps[g]) {
            continue;
        }
        let direct = ch.gaps[g].cost();
        let (a, b) = (ch.links[g].clone(), ch.links[g + 1].clone());
        let Some((a_exit, m_in)) = facing_ends(coarse, blocks, &a, m, early) else {
            continue;
        };
        let at_m = Link {
            comp: m,
            entry: m_in,
            exit: m_in,
        };
        let Some((m_out, b_in)) = facing_ends(coarse, blocks, &at_m, b.comp, early) else {
            continue;
        };
        let (Some(p1), Some(p2)) = (
            bridge(a_exit, m_in, a.comp, m),
            bridge(m_out, b_in, m, b.comp),
        ) else {
            continue;
        };
        let take = if upper {
            (through_bowel(&p1) || through_bowel(&p2)) && p1.cost() + p2.cost() < direct
        } else {
            through_bowel(&p1) && through_bowel(&p2)
        };
        if take {
            ch.move_gap_ends(g, a_exit, b_in);
            ch.take_into_gap(g, [p1, p2], m, [m_in, m_out]);
            return true;
        }
    }
    false
}

/// Step 3 of [`chain`]: from the chain's end, on to the nearest free end (further along the
/// course, when `course` is given) while one is within reach and its bridge is cheap.
fn extend_tail(
    coarse: &Coarse,
    comps: &[Compartment],
    ch: &mut Chain,
    free: &mut Vec<u32>,
    course: Option<&Course>,
    opts: &ChainOptions,
    bridge: &mut impl FnMut(usize, usize, u32, u32) -> Option<Path>,
) {
    // Both ends of every free compartment: a double sweep from its lowest voxel.
    let ends: Vec<Option<[usize; 2]>> = (0..comps.len())
        .map(|c| {
            free.contains(&(c as u32)).then(|| {
                let a = coarse
                    .farthest(c as u32, coarse.block_of(comps[c].lowest))
                    .0;
                [a, coarse.farthest(c as u32, a).0]
            })
        })
        .collect();
    loop {
        let here = &ch.links[ch.links.len() - 1];
        let (at_comp, exit) = (here.comp, here.exit);
        let at = coarse.centre_mm(exit);
        let onward = |e: usize| {
            course.is_none_or(|k| k.along(coarse.centre_mm(e)) >= k.along(at) - ONWARD_SLACK)
        };
        let mut options: Vec<(f64, u32, usize)> = free
            .iter()
            .flat_map(|&c| ends[c as usize].into_iter().flatten().map(move |e| (c, e)))
            .filter(|&(_, e)| onward(e))
            .map(|(c, e)| (coarse.centre_mm(e).distance(at), c, e))
            .collect();
        options.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        // The nearest few ends are bridged and the cheapest bridge wins: the nearest end by
        // straight distance may lie across fat, while the collapsed bowel leads to another.
        let mut tried: Vec<u32> = Vec::new();
        let mut best: Option<(f64, u32, usize, Path)> = None;
        for (d, c, e) in options {
            if tried.contains(&c) {
                continue;
            }
            if d > opts.max_gap_mm || tried.len() == CANDIDATES {
                break;
            }
            tried.push(c);
            match bridge(exit, e, at_comp, c) {
                Some(p) if p.mean_cost <= opts.max_bridge_cost => {
                    let cost = p.cost();
                    if best.as_ref().is_none_or(|b| cost < b.0) {
                        best = Some((cost, c, e, p));
                    }
                }
                Some(p) => {
                    ch.left.retain(|(x, _)| *x != c);
                    ch.left.push((
                        c,
                        Left::BridgeTooDear {
                            gap_mm: p.length_mm,
                            cost: p.mean_cost,
                        },
                    ));
                }
                None => {}
            }
        }
        let Some((_, c, e, p)) = best else { break };
        ch.links.push(Link {
            comp: c,
            entry: e,
            exit: coarse.farthest(c, e).0,
        });
        ch.gaps.push(p);
        free.retain(|&x| x != c);
        ch.left.retain(|(x, _)| *x != c);
    }
}

/// How far back along the course (fraction) the tail may step: a loop of the colon turns
/// back a little.
const ONWARD_SLACK: f64 = 0.05;

/// Anatomical name of a place in the colon, from where it lies in the colon's box in the
/// patient frame (u: right 0 → left 1; v: inferior 0 → superior 1).
pub fn region(u: f64, v: f64) -> &'static str {
    if u > 0.68 {
        if v > 0.8 {
            "splenic flexure"
        } else {
            "descending"
        }
    } else if u < 0.32 {
        if v > 0.8 {
            "hepatic flexure"
        } else if v < 0.4 {
            "cecum"
        } else {
            "ascending"
        }
    } else if v < 0.35 {
        "rectosigmoid"
    } else if v < 0.55 {
        "sigmoid"
    } else {
        "transverse"
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;

    fn plain_course() -> Course {
        let g = Geometry::new([200, 20, 20], [1.0; 3], [0.0; 3]).unwrap();
        Course::new(&g, [DVec3::ZERO, DVec3::new(200.0, 20.0, 20.0)])
    }

    /// Three gas tubes along x in a row with gaps of 10 and 30 blocks' worth; the chain goes
    /// from the first (the "rectum") to the nearest next, then the last, entering each at its
    /// near end.
    #[test]
    fn chain_goes_end_to_end() {
        let dims = [200, 20, 20];
        let mut coarse = Coarse::new(dims, [1.0; 3]);
        let spans = [(0usize, 40usize), (60, 100), (130, 190)];
        let comps: Vec<Compartment> = spans
            .iter()
            .map(|&(a, b)| Compartment {
                voxels: 1,
                gas_voxels: 1,
                sum_mm: DVec3::ZERO,
                bbox: Bbox {
                    lo: [a, 8, 8],
                    hi: [b - 1, 11, 11],
                },
                lowest: [a, 9, 9],
                lowest_height: 0.0,
            })
            .collect();
        for (c, &(a, b)) in spans.iter().enumerate() {
            for k in 8..12 {
                for j in 8..12 {
                    coarse.mark_run(a, b, j, k, c as u32);
                }
            }
        }
        // The three minor compartments chained from the first, with `opts` and `bridge`.
        let chained =
            |opts: &ChainOptions,
             bridge: &mut dyn FnMut(usize, usize, u32, u32) -> Option<Path>| {
                chain(
                    &coarse,
                    &comps,
                    1.0,
                    0,
                    &[Role::Minor; 3],
                    &plain_course(),
                    opts,
                    bridge,
                )
            };
        let mut asked = Vec::new();
        let ch = chained(&ChainOptions::default(), &mut |from, to, a, b| {
            asked.push((a, b));
            let (p, q) = (coarse.centre_mm(from), coarse.centre_mm(to));
            Some(Path {
                voxels: vec![],
                length_mm: p.distance(q),
                mean_cost: 1.0,
            })
        });
        assert_eq!(
            ch.links.iter().map(|l| l.comp).collect::<Vec<_>>(),
            vec![0, 1, 2]
        );
        assert_eq!(
            asked,
            vec![(0, 1), (0, 2), (1, 2)],
            "the nearest few are bridged to"
        );
        assert!(
            (ch.gaps[0].length_mm - 20.0).abs() < 8.5 && (ch.gaps[1].length_mm - 30.0).abs() < 8.5
        );
        // The cheapest bridge wins, not the nearest end: through fat to 1 (20 mm at 6 per
        // mm), along collapsed bowel to 2 (90 mm at 1).
        let lax = ChainOptions {
            max_bridge_cost: 10.0,
            ..Default::default()
        };
        let ch = chained(&lax, &mut |from, to, _, b| {
            let (p, q) = (coarse.centre_mm(from), coarse.centre_mm(to));
            Some(Path {
                voxels: vec![],
                length_mm: p.distance(q),
                mean_cost: if b == 1 { 6.0 } else { 1.0 },
            })
        });
        assert_eq!(
            ch.links.iter().map(|l| l.comp).collect::<Vec<_>>(),
            vec![0, 2, 1]
        );
        // A bridge through fat leaves the segment out, and says why.
        let ch = chained(&ChainOptions::default(), &mut |_, _, _, _| {
            Some(Path {
                voxels: vec![],
                length_mm: 20.0,
                mean_cost: 6.0,
            })
        });
        assert_eq!(ch.links.len(), 1);
        assert!(
            ch.left
                .iter()
                .any(|(c, l)| *c == 1 && matches!(l, Left::BridgeTooDear { .. }))
        );
        // Too far apart: not joined.
        let far = ChainOptions {
            max_gap_mm: 10.0,
            ..Default::default()
        };
        let ch = chained(&far, &mut |_, _, _, _| None);
        assert_eq!(ch.links.len(), 1);
        assert!(
            ch.left
                .iter()
                .all(|(_, l)| matches!(l, Left::TooFar(d) if *d > 10.0))
        );
        // Within reach but no way to them: left out, and not said to be too far.
        let ch = chained(&ChainOptions::default(), &mut |_, _, _, _| None);
        assert_eq!(ch.links.len(), 1);
        assert!(
            ch.left
                .iter()
                .all(|(_, l)| matches!(l, Left::NotOnward(d) if *d <= 100.0)),
            "{:?}",
            ch.left
        );
    }
}
