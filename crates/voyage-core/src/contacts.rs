//! Touching loops. Where two loops of the colon lie against each other, the wall between them
//! is often thinner than a voxel, and the lumen mask joins them. A shortest path through the
//! lumen then cuts across, and Dt — the paper's pull toward the target — leads the submarine
//! from one loop into the other, skipping the colon in between (on the shared colon-a mask,
//! Dt's shortest path is a third of the centerline).
//!
//! The skeleton's path (the raw centerline) knows the colon's order. Every lumen voxel takes
//! the arc length of the path point it is geodesically nearest to (a multi-source search from
//! the path). Two neighbouring voxels whose arc lengths differ by more than
//! `arc_ratio` × the straight distance between their path points (and by at least
//! `min_arc_mm`) sit on a contact between loops: along one loop arc and straight distance
//! are alike (a hairpin bend gives π/2), across a contact the arc is many times longer. Both
//! voxels are taken out of the lumen, which puts a two-voxel wall where the scan could not show
//! one: Dt follows the colon, the surface closes over the contact (no view into the next
//! loop), and the cells stay a chain.
//!
//! The search runs on blocks ([`crate::grid::Blocks`]): the skeleton's 2×2×2 blocks on a large lumen
//! (an eighth of the voxels; the search and the scan of neighbour pairs cost 2.6 s on the
//! voxels of colon-a), single voxels on a small one. Each block takes one label (a partial
//! block, the label of the nearest labelled block); every pair of neighbouring lumen voxels in
//! blocks of far-apart labels is cut, one voxel on each side of the block face, so no such
//! pair is left, as with single voxels. It runs before Ds, which then sees the new walls.

use glam::DVec3;

use crate::{
    Volume,
    distance::geodesic::start_from_inside_in,
    grid::{Blocks, BoxGrid, BoxIndex, PadIndex, Padded},
    mem::refilled,
};

#[derive(Clone, Debug)]
pub struct ContactOptions {
    pub enabled: bool,
    pub arc_ratio: f64,
    pub min_arc_mm: f64,
}

impl Default for ContactOptions {
    fn default() -> Self {
        ContactOptions {
            enabled: true,
            arc_ratio: 3.0,
            min_arc_mm: 50.0,
        }
    }
}

const NO_LABEL: u16 = u16::MAX;

/// The arrays of a contact cut that is done, kept for the next: prep cuts the contacts after
/// every trace of the centerline (five times on `ctc/prone-tagged`, each over blocks of the
/// same box), and fresh arrays cost each cut a fifth of its time in page faults. Empty, a
/// cut takes fresh memory.
#[derive(Default)]
pub struct ContactMemory {
    inside: Vec<u8>,
    partial: Vec<u8>,
    labels: Vec<u16>,
    dist: Vec<f32>,
    parent: Vec<u8>,
    contact: Vec<bool>,
}

/// Takes the contact voxels out of the lumen mask (none within `keep_mm` of the points
/// `keep`, volume-local mm); returns the volume indices taken, so that a caller can put them
/// back. `path_mm` is the colon's path from source to target; `blocks`, when given, the
/// blocks of `grid` to search on (else single voxels). The cut works in `memory`'s arrays where
/// they have room, and leaves its own there.
#[allow(clippy::too_many_arguments)]
pub fn cut_contacts(
    lumen: &mut Volume<u8>,
    grid: &BoxGrid,
    path_mm: &[DVec3],
    blocks: Option<&Blocks>,
    keep: &[DVec3],
    keep_mm: f64,
    opts: &ContactOptions,
    memory: &mut ContactMemory,
) -> crate::Result<Vec<usize>> {
    if !opts.enabled || path_mm.len() < 2 {
        return Ok(Vec::new());
    }
    let own;
    let blocks = match blocks {
        Some(b) => b,
        None => {
            own = Blocks::new(lumen, grid, 1)?;
            &own
        }
    };
    let (points, arcs) = label_points(path_mm);
    let far = |a: u16, b: u16| {
        let (a, b) = (a as usize, b as usize);
        let arc = (arcs[a] - arcs[b]).abs();
        arc > opts.min_arc_mm && arc > opts.arc_ratio * points[a].distance(points[b])
    };
    let pad = padded_blocks(blocks, memory);
    let labels = label_blocks(&pad, blocks, &points, memory);
    let contact = contact_blocks(&pad, &labels, &far, std::mem::take(&mut memory.contact));
    let mut cut = Vec::new();
    let dims = lumen.dims();
    let g = lumen.geometry().clone();
    for (pi, _) in contact.iter().enumerate().filter(|(_, c)| **c) {
        let a = labels[pi];
        for u in blocks.voxels(pad.global_of_index(PadIndex(pi)), dims) {
            if lumen.get(u[0], u[1], u[2]) == 0 {
                continue;
            }
            for v in neighbour_voxels(u, dims) {
                if lumen.get(v[0], v[1], v[2]) == 0 {
                    continue;
                }
                let Some(b) = blocks
                    .block_of_voxel(v)
                    .and_then(|c| pad.index_of_global(c))
                    .map(|q| labels[q.0])
                else {
                    continue;
                };
                if b != NO_LABEL && b != a && far(a, b) {
                    cut.push(g.index(u[0], u[1], u[2]));
                    cut.push(g.index(v[0], v[1], v[2]));
                }
            }
        }
    }
    cut.sort_unstable();
    cut.dedup();
    let kept = |v: usize| {
        let p = g.index_to_local(DVec3::from_array(g.ijk(v).map(|x| x as f64)));
        keep.iter().any(|k| k.distance(p) <= keep_mm)
    };
    cut.retain(|&v| !kept(v));
    for &v in &cut {
        lumen.data_mut()[v] = 0;
    }
    memory.contact = contact;
    memory.labels = labels;
    memory.partial = pad.partial;
    memory.inside = pad.pad.inside;
    Ok(cut)
}

/// Path points (at most `NO_LABEL` of them, thinned evenly) and their arc lengths.
fn label_points(path: &[DVec3]) -> (Vec<DVec3>, Vec<f64>) {
    let arc = crate::centerline::arc_lengths(path);
    let stride = path.len().div_ceil(NO_LABEL as usize - 1).max(1);
    let idx: Vec<usize> = (0..path.len()).step_by(stride).collect();
    (
        idx.iter().map(|&i| path[i]).collect(),
        idx.iter().map(|&i| arc[i]).collect(),
    )
}

/// The full blocks with a layer of empty blocks around, for the search, and which blocks are
/// partial, in the same layout (in `memory`'s arrays).
struct PaddedBlocks {
    pad: Padded,
    /// 1 for a partial block, 0 else; three spare 0s at the end for [`partial_around`]'s
    /// four-byte loads.
    partial: Vec<u8>,
}

impl std::ops::Deref for PaddedBlocks {
    type Target = Padded;
    fn deref(&self) -> &Padded {
        &self.pad
    }
}

fn padded_blocks(blocks: &Blocks, memory: &mut ContactMemory) -> PaddedBlocks {
    let dims = blocks.dims();
    let grid = BoxGrid { lo: [0; 3], dims };
    let pad = Padded::new_in(&blocks.mask, &grid, std::mem::take(&mut memory.inside));
    let full = (blocks.factor.pow(3)) as u8;
    let mut partial = refilled(
        std::mem::take(&mut memory.partial),
        pad.inside.len() + 3,
        0u8,
    );
    for (b, &c) in blocks.count.iter().enumerate() {
        if c > 0 && c < full {
            let q = grid.global_of_index(BoxIndex(b));
            if let Some(i) = pad.index_of_global(q) {
                partial[i.0] = 1;
            }
        }
    }
    PaddedBlocks { pad, partial }
}

/// Per padded block, the label of the geodesically nearest path point (through full blocks);
/// partial blocks take the label of the nearest labelled block by steps (breadth first from
/// all labelled blocks at once). NO_LABEL for empty blocks and blocks not reached.
fn label_blocks(
    pad: &PaddedBlocks,
    blocks: &Blocks,
    points: &[DVec3],
    memory: &mut ContactMemory,
) -> Vec<u16> {
    let mut labels = refilled(
        std::mem::take(&mut memory.labels),
        pad.inside.len(),
        NO_LABEL,
    );
    let mut sources = Vec::with_capacity(points.len());
    for (l, p) in points.iter().enumerate() {
        if let Some(i) = blocks
            .block_of_mm(*p)
            .and_then(|c| pad.index_of_global(c))
            .filter(|&i| pad.inside[i.0] != 0)
            && labels[i.0] == NO_LABEL
        {
            labels[i.0] = l as u16;
            sources.push(i);
        }
    }
    let spacing = blocks.mask.spacing();
    let start = start_from_inside_in(pad, std::mem::take(&mut memory.dist));
    let search = pad
        .search(spacing)
        .tree_reusing(std::mem::take(&mut memory.parent))
        .start(start)
        .from(&sources);
    for &u in &search.order {
        let u = u as usize;
        if let Some(p) = search.parent_of(u) {
            labels[u] = labels[p];
        }
    }
    let rows = pad.neighbour_row_starts();
    let mut frontier: Vec<usize> = search
        .order
        .iter()
        .map(|&u| u as usize)
        .filter(|&u| partial_around(&pad.partial, u, &rows) != 0)
        .collect();
    while !frontier.is_empty() {
        let mut next = Vec::new();
        for &u in &frontier {
            // The partial neighbours in the order of the search's 26 (z, then y, then x); the
            // block itself is labelled, so never taken.
            let mut around = partial_around(&pad.partial, u, &rows);
            while around != 0 {
                let bit = around.trailing_zeros() as usize;
                around &= around - 1;
                let v = (u as isize + rows[bit / 3]) as usize + bit % 3;
                if labels[v] == NO_LABEL {
                    labels[v] = labels[u];
                    next.push(v);
                }
            }
        }
        frontier = next;
    }
    memory.dist = search.dist;
    memory.parent = search.parent;
    labels
}

/// Which of the 27 blocks around padded index `u` (itself included) are partial: bit
/// 3·row + lane, rows as [`Padded::neighbour_row_starts`]. Each row of three is one
/// four-byte load: nine loads instead of 26 tests.
#[inline]
fn partial_around(partial: &[u8], u: usize, rows: &[isize; 9]) -> u32 {
    rows.iter().enumerate().fold(0u32, |acc, (r, &start)| {
        let at = (u as isize + start) as usize;
        let word: [u8; 4] = partial[at..at + 4].try_into().expect("a slice of four");
        // Bytes of 0 or 1: byte i's low bit to bit i.
        let w = u32::from_le_bytes(word);
        acc | ((w & 1) | ((w >> 7) & 2) | ((w >> 14) & 4)) << (3 * r)
    })
}

/// Blocks with a 26-neighbour whose label is far along the path from theirs.
/// In `reuse`'s memory where it has room.
fn contact_blocks(
    pad: &Padded,
    labels: &[u16],
    far: &dyn Fn(u16, u16) -> bool,
    reuse: Vec<bool>,
) -> Vec<bool> {
    let half: Vec<isize> = pad
        .neighbours([1.0; 3])
        .iter()
        .map(|n| n.0)
        .filter(|&o| o > 0)
        .collect();
    let mut contact = refilled(reuse, labels.len(), false);
    for u in 0..labels.len() {
        let a = labels[u];
        if a == NO_LABEL {
            continue;
        }
        for &off in &half {
            let v = (u as isize + off) as usize;
            let b = labels[v];
            if b != NO_LABEL && a != b && far(a, b) {
                contact[u] = true;
                contact[v] = true;
            }
        }
    }
    contact
}

/// The 26 neighbours of voxel `u` inside a volume of `dims`.
fn neighbour_voxels(u: [usize; 3], dims: [usize; 3]) -> impl Iterator<Item = [usize; 3]> {
    (0..27).filter(|&o| o != 13).filter_map(move |o| {
        let d = [o % 3, (o / 3) % 3, o / 9];
        let v = [0, 1, 2].map(|a| (u[a] + d[a]).checked_sub(1));
        let v = [v[0]?, v[1]?, v[2]?];
        v.iter().zip(dims).all(|(&x, n)| x < n).then_some(v)
    })
}

/// A centerline stretch narrower than this (radius, mm) may be a short cut through a
/// contact: a hole between touching loops.
const SHORTCUT_NARROW_MM: f64 = 2.0;
/// In a wide colon a hole may be wider: a stretch under this fraction of the lumen's radius
/// on both sides may be one too (on `ctc/prone-tagged`, 2.3 mm between the transverse colon
/// and the cecum, 20 mm wide on either side, skipped the ascending colon; in 3 mm slices, a
/// 3.7–4.0 mm hole between the splenic flexure's limbs, 20 and 23 mm wide, skipped 600 ml of
/// the flexure: a fifth was just too little).
const NECK_PER_SIDE: f64 = 0.25;
/// The way round must be at least this wide (Ds, mm) all along, and [`BYPASS_PER_NECK`] times
/// the stretch's narrowest radius: colon, not a crevice or another hole. Relative to the
/// neck, because the colon's own way round a hole may narrow too (a fold, a fluid-filled
/// flexure): on `ctc/prone-tagged` a 0.1 mm hole between the transverse and ascending
/// colon was taken, 300 mm of colon skipped, while the way round narrowed to 3 mm somewhere.
const BYPASS_WIDE_MM: f64 = 2.0;
const BYPASS_PER_NECK: f64 = 3.0;
/// The ends of the way round are the widest centerline points this far (mm of arc) on
/// either side of the stretch, at least [`ENDS_PER_WAY`] times as wide as the way round must
/// be.
const BYPASS_REACH_MM: f64 = 60.0;
/// Well inside the lumen, so that the way round starts and ends there; twice asked 24 mm of
/// radius beside the flexure's 4 mm hole (above), where the descending colon is 20 mm.
const ENDS_PER_WAY: f64 = 1.5;
/// Stretches this near (mm of arc) the centerline's ends are its ends narrowing, not holes.
const ENDS_MM: f64 = 20.0;
/// The plug that closes a hole: the lumen within this many mm of its narrowest point (at
/// least twice its radius). A hole between loops is a slit: on `ctc/prone-tagged` one runs
/// 7 mm from its narrowest point, and a 4 mm plug left the flight's Dt a way through it,
/// where the camera stalled.
const PLUG_MM: f64 = 8.0;

/// Holes between touching loops that the centerline went through: where it narrows under
/// [`SHORTCUT_NARROW_MM`] (or under [`NECK_PER_SIDE`] of its width on both sides) while the
/// lumen on either side is also joined by a way much wider
/// all along ([`BYPASS_WIDE_MM`], [`BYPASS_PER_NECK`]), the narrow stretch is a short cut (the colon is one
/// tube: it cannot go both ways). Returns the lumen voxels (volume indices) of a plug at each
/// such hole, for the caller to take out and trace the centerline again. `lumen` is without
/// contacts cut (a cut across the way round would hide it); `ds` is its Ds over the
/// lumen's box ([`may_have_shortcuts`] says whether it is worth computing). Points, radii and arcs are
/// the centerline's. `necks` are the
/// narrowest points of stretches found to be the only way (real necks) in earlier calls:
/// they are not looked at again, and the new ones are added.
pub fn shortcut_plugs(
    lumen: &Volume<u8>,
    points_mm: &[[f64; 3]],
    radius_mm: &[f64],
    arc_mm: &[f64],
    necks: &mut Vec<[f64; 3]>,
    ds: &crate::grid::Field<f32>,
) -> Vec<usize> {
    let mut stretches = narrow_stretches(points_mm, radius_mm, arc_mm, necks);
    // Narrowest first: each way round is looked for with the holes plugged so far closed,
    // so that two stretches are never both taken for holes each by way of the other.
    stretches.sort_by(|x, y| radius_mm[x.neck].total_cmp(&radius_mm[y.neck]));
    let mut ways = Ways::new(lumen, ds);
    let mut plugs: Vec<usize> = Vec::new();
    for s in stretches {
        let n = s.neck;
        if ways.joins(points_mm[s.ends.0], points_mm[s.ends.1], s.wide) {
            let more = plug(
                lumen,
                |v| ds.get_global(v, f32::INFINITY),
                points_mm[n],
                radius_mm[n],
            );
            ways.close(&more);
            plugs.extend(more);
        } else {
            necks.push(points_mm[n]);
        }
    }
    plugs.sort_unstable();
    plugs.dedup();
    plugs
}

/// A hole beside the centerline, found by [`plug_beside`]: the plug that closes it, its
/// narrowest radius, and the arcs of the centerline it joins.
#[derive(Clone, Debug, PartialEq)]
pub struct Hole {
    pub plugs: Vec<usize>,
    pub neck_mm: f64,
    /// The arc (mm) of the nearest centerline point on the way's side before the hole, and
    /// after it (nearer the source).
    pub arcs_mm: [f64; 2],
}

/// The plug that closes a hole between touching loops that the centerline goes round, seen
/// from the centerline point `from`: the way Dt (`dt`, from the source) takes back to the
/// source (steepest descent over the 26 neighbours) runs along one loop, then through the
/// hole into a loop earlier on the centerline, where the arc of its nearest centerline point
/// falls at once by at least `min_jump_mm`. That stretch of the way, centred on Ds, is
/// narrowest at the hole, which is plugged as [`shortcut_plugs`] plugs one. Every fall of the
/// way that is a hole is plugged, largest first (past one hole the way may cross another,
/// further on: each would otherwise take a search of Dt of its own). A fall is a hole where
/// the way is narrow: one of `wide_jump_mm` or more may be as wide as [`SHORTCUT_NARROW_MM`]
/// or [`NECK_PER_SIDE`] of the centerline's radius on both sides, a smaller one only as a
/// hole in a wall ([`thin_hole_mm`]), since within one wide chamber the centerline meanders
/// and the way may fall that far between folds a few millimetres apart. Elsewhere it crossed
/// open lumen between two stretches of the centerline (a wide flexure's dome). Empty when no
/// fall is one. `ds` is the lumen's Ds; the caller checks that the colon still holds and
/// drops a hole whose plug overlaps one taken before. The trace's rounds of plugging never
/// look beside the centerline: on `ctc/prone-tagged` with a bridge costed on local means,
/// fluid taken back in beside its pools after the trace opened a hole in the ascending colon
/// that put Dt 132 mm below the centerline's arc.
#[allow(clippy::too_many_arguments)]
pub fn plug_beside(
    lumen: &Volume<u8>,
    ds: &crate::grid::Bricked<f32>,
    dt: &crate::grid::Bricked<f32>,
    cl: &crate::centerline::Centerline,
    from: usize,
    [min_jump_mm, wide_jump_mm]: [f64; 2],
    opts: &crate::centerline::CenterlineOptions,
) -> Vec<Hole> {
    let way = descent(lumen, dt, cl.points_mm[from]);
    let arcs: Vec<f64> = way
        .iter()
        .map(|&p| crate::centerline::arc_nearest(cl, p))
        .collect();
    let mut falls: Vec<usize> = (1..way.len())
        .filter(|&t| arcs[t - 1] - arcs[t] >= min_jump_mm)
        .collect();
    falls.sort_by(|&x, &y| (arcs[y - 1] - arcs[y]).total_cmp(&(arcs[x - 1] - arcs[x])));
    let radius_at = |a: f64| {
        let i = cl.arc_mm.partition_point(|&x| x < a);
        cl.radius_mm[i.min(cl.radius_mm.len() - 1)]
    };
    let mut tried: Vec<DVec3> = Vec::new();
    let mut holes: Vec<Hole> = Vec::new();
    for t in falls {
        let crossing = way[t];
        if tried.iter().any(|c| c.distance(crossing) <= PLUG_MM) {
            continue;
        }
        tried.push(crossing);
        let Some((at, neck_mm)) = neck_near(ds, &way, t, opts) else {
            continue;
        };
        let widest = if arcs[t - 1] - arcs[t] >= wide_jump_mm {
            let side = radius_at(arcs[t - 1]).min(radius_at(arcs[t]));
            SHORTCUT_NARROW_MM.max(NECK_PER_SIDE * side)
        } else {
            thin_hole_mm(lumen.spacing())
        };
        if neck_mm > widest {
            continue;
        }
        let plugs = plug(lumen, |v| ds.get(v), at, neck_mm);
        if !plugs.is_empty() {
            holes.push(Hole {
                plugs,
                neck_mm,
                arcs_mm: [arcs[t - 1], arcs[t]],
            });
        }
    }
    holes
}

/// The widest hole (radius, mm) that a wall between loops of the colon is taken to hold
/// where nothing else says the way crossed between loops ([`plug_beside`]): as wide as
/// [`SHORTCUT_NARROW_MM`] or a voxel's diagonal, what partial volume opens in a thin wall.
/// Between folds in one chamber the way is wider: 2.4 and 3.9 mm in the cecum of
/// `ctc/prone-tagged` (1 mm slices), where its holes between loops are 0.1–0.4 mm; in 3 mm
/// slices one between the hepatic flexure's limbs is 2.6 mm.
pub fn thin_hole_mm(spacing: [f64; 3]) -> f64 {
    SHORTCUT_NARROW_MM.max(spacing.iter().map(|s| s * s).sum::<f64>().sqrt())
}

/// The narrowest point of Dt's way `way` within [`PLUG_MM`] of its step `t`, the way centred
/// on Ds within [`HOLE_REACH_MM`] of it: where, and its radius (mm).
fn neck_near(
    ds: &crate::grid::Bricked<f32>,
    way: &[DVec3],
    t: usize,
    opts: &crate::centerline::CenterlineOptions,
) -> Option<([f64; 3], f64)> {
    let crossing = way[t];
    let within = |u: &usize| way[*u].distance(crossing) <= HOLE_REACH_MM;
    let first = (0..t).rev().take_while(within).last().unwrap_or(t);
    let last = (t..way.len()).take_while(within).last().unwrap_or(t);
    let near = way[first..=last].to_vec();
    if near.len() < 2 {
        return None;
    }
    let centred = crate::centerline::refine_points(near, ds, opts);
    let n = (0..centred.points_mm.len())
        .filter(|&i| DVec3::from_array(centred.points_mm[i]).distance(crossing) <= PLUG_MM)
        .min_by(|&x, &y| centred.radius_mm[x].total_cmp(&centred.radius_mm[y]))?;
    Some((centred.points_mm[n], centred.radius_mm[n]))
}

/// Centerline points, one every `every_mm` of arc, from which Dt's way back to the source
/// ([`plug_beside`]'s descent) crosses from one loop into another: the arc of its nearest
/// centerline point falls at once by at least `min_jump_mm`. The largest falls first, one
/// point per crossing. A hole that saves Dt too little to dip along the centerline (a wide
/// flexure's Dt rises little over its dome) still draws the flight's pull into it: in the
/// real exam with noise added (σ 50 HU), a pool's floor opened into the transverse colon
/// under the splenic flexure's dome, 260 mm of arc on, and the camera sat against it.
/// The ways of later points end where they meet an earlier one's, which was looked at.
pub fn holes_by_descent(
    lumen: &Volume<u8>,
    dt: &crate::grid::Bricked<f32>,
    cl: &crate::centerline::Centerline,
    min_jump_mm: f64,
    every_mm: f64,
) -> Vec<usize> {
    let g = lumen.geometry();
    let mut arc_of: std::collections::HashMap<usize, f64> = std::collections::HashMap::new();
    let mut found: Vec<(f64, usize, DVec3)> = Vec::new();
    let mut next = 0.0;
    for (i, p) in cl.points_mm.iter().enumerate() {
        if cl.arc_mm[i] < next {
            continue;
        }
        next = cl.arc_mm[i] + every_mm;
        let mut last: Option<f64> = None;
        let mut best: Option<(f64, DVec3)> = None;
        for v in descent_voxels(lumen, dt, *p) {
            let at = g.index(v[0], v[1], v[2]);
            let seen = arc_of.get(&at).copied();
            let local = g.voxel_local(at);
            let arc = seen.unwrap_or_else(|| crate::centerline::arc_nearest(cl, local));
            if let Some(a) = last
                && a - arc >= min_jump_mm
                && best.is_none_or(|(b, _)| a - arc > b)
            {
                best = Some((a - arc, local));
            }
            if seen.is_some() {
                break;
            }
            arc_of.insert(at, arc);
            last = Some(arc);
        }
        if let Some((jump, crossing)) = best
            && !found.iter().any(|f| f.2.distance(crossing) <= PLUG_MM)
        {
            found.push((jump, i, crossing));
        }
    }
    found.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    found.into_iter().map(|f| f.1).collect()
}

/// The way round a hole beside the centerline is looked for this far (mm) from where Dt's
/// way crosses it ([`plug_beside`]): past the hole on both sides, within the two loops.
const HOLE_REACH_MM: f64 = 20.0;

/// Dt's way from `p` (volume-local mm) back to the source: voxel centres (volume-local mm),
/// each the neighbour of the last with the least Dt, until none is less.
fn descent(lumen: &Volume<u8>, dt: &crate::grid::Bricked<f32>, p: [f64; 3]) -> Vec<DVec3> {
    let g = lumen.geometry();
    descent_voxels(lumen, dt, p)
        .map(|v| g.index_to_local(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)))
        .collect()
}

/// [`descent`] as voxels, step by step.
fn descent_voxels<'a>(
    lumen: &'a Volume<u8>,
    dt: &'a crate::grid::Bricked<f32>,
    p: [f64; 3],
) -> impl Iterator<Item = [usize; 3]> + 'a {
    let g = lumen.geometry();
    let dims = lumen.dims();
    let v = g.local_to_index(DVec3::from_array(p)).round();
    let start = g
        .contains_index(v)
        .then_some([v.x as usize, v.y as usize, v.z as usize]);
    let mut d = start.map_or(f32::NAN, |s| dt.get(s));
    std::iter::successors(start, move |&at| {
        if !(d.is_finite() && d > 0.0) {
            return None;
        }
        let (n, dn) = neighbour_voxels(at, dims)
            .map(|n| (n, dt.get(n)))
            .filter(|&(n, dn)| dn < d && lumen.get(n[0], n[1], n[2]) != 0)
            .min_by(|a, b| a.1.total_cmp(&b.1))?;
        d = dn;
        Some(n)
    })
}

/// Whether the centerline has a narrow stretch that may be a hole ([`shortcut_plugs`] has
/// something to test), so that its Ds is worth computing.
pub fn may_have_shortcuts(
    points_mm: &[[f64; 3]],
    radius_mm: &[f64],
    arc_mm: &[f64],
    necks: &[[f64; 3]],
) -> bool {
    !narrow_stretches(points_mm, radius_mm, arc_mm, necks).is_empty()
}

/// A narrow stretch of the centerline that may be a hole: its narrowest point, the widest
/// points on either side that a way round would join, and how wide that way must be.
struct Stretch {
    neck: usize,
    ends: (usize, usize),
    wide: f64,
}

/// The centerline's narrow stretches ([`narrow_points`]), away from its ends and from the
/// `necks` already known, with wide enough places on either side.
fn narrow_stretches(
    points_mm: &[[f64; 3]],
    radius_mm: &[f64],
    arc_mm: &[f64],
    necks: &[[f64; 3]],
) -> Vec<Stretch> {
    let length = arc_mm.last().copied().unwrap_or(0.0);
    let narrow = narrow_points(radius_mm, arc_mm);
    let mut out = Vec::new();
    let mut i = 0;
    while i < points_mm.len() {
        if !narrow[i] {
            i += 1;
            continue;
        }
        let start = i;
        while i < points_mm.len() && narrow[i] {
            i += 1;
        }
        let (a, b) = (arc_mm[start], arc_mm[i - 1]);
        if a < ENDS_MM || b > length - ENDS_MM {
            continue;
        }
        let n = (start..i)
            .min_by(|&x, &y| radius_mm[x].total_cmp(&radius_mm[y]))
            .unwrap_or(start);
        let at = glam::DVec3::from_array(points_mm[n]);
        if necks
            .iter()
            .any(|&k| glam::DVec3::from_array(k).distance(at) <= PLUG_MM)
        {
            continue;
        }
        let wide = BYPASS_WIDE_MM.max(BYPASS_PER_NECK * radius_mm[n]);
        // The widest places on either side within reach: well inside the lumen.
        let widest = |js: &mut dyn Iterator<Item = usize>| {
            js.max_by(|&x, &y| radius_mm[x].total_cmp(&radius_mm[y]))
                .filter(|&j| radius_mm[j] >= ENDS_PER_WAY * wide)
        };
        let before = widest(&mut (0..start).filter(|&j| arc_mm[j] >= a - BYPASS_REACH_MM));
        let after = widest(&mut (i..points_mm.len()).filter(|&j| arc_mm[j] <= b + BYPASS_REACH_MM));
        if let (Some(p), Some(q)) = (before, after) {
            out.push(Stretch {
                neck: n,
                ends: (p, q),
                wide,
            });
        }
    }
    out
}

/// Whether each centerline point is narrow enough to be a hole: under
/// [`SHORTCUT_NARROW_MM`], or under [`NECK_PER_SIDE`] times the widest radius on each side
/// within [`BYPASS_REACH_MM`] of arc.
fn narrow_points(radius_mm: &[f64], arc_mm: &[f64]) -> Vec<bool> {
    let n = radius_mm.len();
    let widest = |js: std::ops::Range<usize>| js.map(|j| radius_mm[j]).fold(0.0, f64::max);
    let (mut lo, mut hi) = (0, 0);
    (0..n)
        .map(|i| {
            while arc_mm[lo] < arc_mm[i] - BYPASS_REACH_MM {
                lo += 1;
            }
            while hi + 1 < n && arc_mm[hi + 1] <= arc_mm[i] + BYPASS_REACH_MM {
                hi += 1;
            }
            let sides = widest(lo..i).min(widest(i + 1..hi + 1));
            radius_mm[i] < SHORTCUT_NARROW_MM.max(NECK_PER_SIDE * sides)
        })
        .collect()
}

/// The plug that closes a hole at `at` (volume-local mm) of radius `r` mm: the lumen within
/// [`PLUG_MM`] (at least 2r) that is no wider than the hole (Ds at most r and a voxel), so
/// that the loops on either side keep their lumen. `ds(v)`: Ds at voxel v (+∞ where unknown).
fn plug(lumen: &Volume<u8>, ds: impl Fn([usize; 3]) -> f32, at: [f64; 3], r: f64) -> Vec<usize> {
    let thin = r + lumen.spacing().iter().cloned().fold(0.0, f64::max);
    lumen_within(lumen, at, PLUG_MM.max(2.0 * r))
        .into_iter()
        .filter(|&v| (ds(lumen.geometry().ijk(v)) as f64) <= thin)
        .collect()
}

/// Searches for ways through the lumen round a narrow stretch, not through the voxels closed
/// so far; one search's memory serves the next. On `ctc/prone-tagged` a search can reach
/// millions of voxels (the wide colon on one side of a real neck), some thirty times per
/// preparation: visited and closed voxels are bits over Ds's box, not a fresh box of flags
/// and a hash set.
struct Ways<'a> {
    lumen: &'a Volume<u8>,
    ds: &'a crate::grid::Field<f32>,
    closed: BoxBits,
    seen: BoxBits,
    /// Box voxels to visit, nearest the goal first (squared distance in tenths of a mm).
    todo: std::collections::BinaryHeap<std::cmp::Reverse<(u64, usize)>>,
    /// Every voxel one search reached, to clear `seen` after it.
    reached: Vec<usize>,
}

impl<'a> Ways<'a> {
    fn new(lumen: &'a Volume<u8>, ds: &'a crate::grid::Field<f32>) -> Self {
        let n = ds.grid.len();
        Ways {
            lumen,
            ds,
            closed: BoxBits::new(n),
            seen: BoxBits::new(n),
            todo: std::collections::BinaryHeap::new(),
            reached: Vec::new(),
        }
    }

    /// Walls off lumen voxels (volume indices inside Ds's box) for the searches after.
    fn close(&mut self, voxels: &[usize]) {
        let g = self.lumen.geometry();
        for &v in voxels {
            if let Some(b) = self.ds.grid.index_of_global(g.ijk(v)) {
                self.closed.set(b.0);
            }
        }
    }

    /// Whether `from` and `to` (volume-local mm) are joined through lumen voxels with Ds at
    /// least `wide` mm, none closed (6-connected, within Ds's box). Only whether they are
    /// joined counts, so the search takes the voxel nearest `to` first (greedy best-first):
    /// along a tube it runs nearly straight there, where a breadth-first search fills every
    /// voxel nearer than `to`.
    fn joins(&mut self, from: [f64; 3], to: [f64; 3], wide: f64) -> bool {
        let grid = &self.ds.grid;
        let sp = self.lumen.spacing();
        let local = |p: [f64; 3]| -> Option<[usize; 3]> {
            let g = [0, 1, 2].map(|a| (p[a] / sp[a]).round().max(0.0) as usize);
            grid.index_of_global(g)
                .map(|_| [0, 1, 2].map(|a| g[a] - grid.lo[a]))
        };
        let (Some(s), Some(t)) = (local(from), local(to)) else {
            return false;
        };
        let d = grid.dims;
        let g = self.lumen.geometry();
        let (lumen, ds) = (self.lumen.data(), &self.ds.data);
        let to_volume =
            |l: [usize; 3]| g.index(l[0] + grid.lo[0], l[1] + grid.lo[1], l[2] + grid.lo[2]);
        let closed = &self.closed;
        let open = |b: usize, l: [usize; 3]| {
            ds[b] as f64 >= wide && !closed.get(b) && lumen[to_volume(l)] != 0
        };
        // Squared distance to `to` in tenths of a mm, as the queue's key.
        let key = |l: [usize; 3]| {
            let d2: f64 = (0..3)
                .map(|a| ((l[a] as f64 - t[a] as f64) * sp[a] * 10.0).powi(2))
                .sum();
            d2.min(u64::MAX as f64) as u64
        };
        let (sb, tb) = (
            grid.index(s[0], s[1], s[2]).0,
            grid.index(t[0], t[1], t[2]).0,
        );
        if !open(sb, s) || !open(tb, t) {
            return false;
        }
        let stride = [1, d[0], d[0] * d[1]];
        self.todo.clear();
        self.todo.push(std::cmp::Reverse((key(s), sb)));
        self.seen.set(sb);
        self.reached.push(sb);
        let mut joined = false;
        while let Some(std::cmp::Reverse((_, b))) = self.todo.pop() {
            if b == tb {
                joined = true;
                break;
            }
            let l = crate::volume::grid_ijk(d, b);
            for a in 0..3 {
                for up in [false, true] {
                    if (!up && l[a] == 0) || (up && l[a] + 1 >= d[a]) {
                        continue;
                    }
                    let (n, mut nl) = (if up { b + stride[a] } else { b - stride[a] }, l);
                    nl[a] = if up { l[a] + 1 } else { l[a] - 1 };
                    if !self.seen.get(n) && open(n, nl) {
                        self.seen.set(n);
                        self.reached.push(n);
                        self.todo.push(std::cmp::Reverse((key(nl), n)));
                    }
                }
            }
        }
        for &b in &self.reached {
            self.seen.unset(b);
        }
        self.reached.clear();
        joined
    }
}

/// One bit per voxel of a box.
struct BoxBits(Vec<u64>);

impl BoxBits {
    fn new(n: usize) -> Self {
        BoxBits(vec![0; n.div_ceil(64)])
    }
    #[inline]
    fn get(&self, i: usize) -> bool {
        self.0[i / 64] >> (i % 64) & 1 != 0
    }
    #[inline]
    fn set(&mut self, i: usize) {
        self.0[i / 64] |= 1 << (i % 64);
    }
    #[inline]
    fn unset(&mut self, i: usize) {
        self.0[i / 64] &= !(1 << (i % 64));
    }
}

/// Lumen voxels (volume indices) within `r` mm of `p` (volume-local mm).
fn lumen_within(lumen: &Volume<u8>, p: [f64; 3], r: f64) -> Vec<usize> {
    crate::volume::set_voxels_in_ball(lumen, p, r)
        .into_iter()
        .map(|v| lumen.geometry().index(v[0], v[1], v[2]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bits of `partial_around` are the 27 blocks around, in the order of the search's
    /// neighbour offsets with the block itself at bit 13.
    #[test]
    fn partial_around_reads_the_27_blocks_in_order() {
        let pad = Padded::shape(&BoxGrid {
            lo: [0; 3],
            dims: [7, 6, 5],
        });
        let n = pad.dims.iter().product::<usize>();
        let mut rng = crate::rng::Rng::new(11, 2);
        let mut partial: Vec<u8> = (0..n).map(|_| (rng.range(0.0, 1.0) < 0.3) as u8).collect();
        partial.extend([0; 3]);
        let rows = pad.neighbour_row_starts();
        let offsets: Vec<isize> = pad.neighbours([1.0; 3]).iter().map(|o| o.0).collect();
        let [nx, ny, nz] = pad.dims;
        for k in 1..nz - 1 {
            for j in 1..ny - 1 {
                for i in 1..nx - 1 {
                    let u = i + nx * (j + ny * k);
                    let mut want = 0u32;
                    for (c, &o) in offsets.iter().enumerate() {
                        let bit = if c < 13 { c } else { c + 1 };
                        want |= (partial[(u as isize + o) as usize] as u32) << bit;
                    }
                    want |= (partial[u] as u32) << 13;
                    assert_eq!(partial_around(&partial, u, &rows), want, "block {u}");
                }
            }
        }
    }

    /// Two tubes side by side along x, 5 mm of wall between them, a hole between them at
    /// x = 30 mm, and, with `joined`, a bend joining them at x = 100 mm: the colon's way
    /// round.
    #[derive(Clone, Copy)]
    struct Loops {
        tube_r: f64,
        hole_r: f64,
        /// Where along the tubes the hole lies (x, mm); the bend is at x = 100.
        hole_x: f64,
    }

    impl Loops {
        /// The tubes' axes: y of each, and z of both.
        fn axes(self) -> (f64, f64, f64) {
            let y0 = self.tube_r + 5.0;
            (y0, y0 + 2.0 * self.tube_r + 5.0, self.tube_r + 5.0)
        }

        fn mask(self, joined: bool) -> Volume<u8> {
            let (y0, y1, zc) = self.axes();
            let dims = [120, (y1 + y0).ceil() as usize, (2.0 * zc).ceil() as usize];
            let g = crate::Geometry::new(dims, [1.0; 3], [0.0; 3]).unwrap();
            let mut m = Volume::filled(g, 0u8).unwrap();
            let r = self.tube_r;
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        let (x, y, z) = (i as f64, j as f64, k as f64);
                        let tube = |yc: f64| (y - yc).hypot(z - zc) <= r && x <= 100.0;
                        let across = (y0..=y1).contains(&y);
                        let bend = joined && (x - 100.0).hypot(z - zc) <= r && across;
                        let hole = (x - self.hole_x).hypot(z - zc) <= self.hole_r && across;
                        if tube(y0) || tube(y1) || bend || hole {
                            m.data_mut()[i + dims[0] * (j + dims[1] * k)] = 1;
                        }
                    }
                }
            }
            m
        }

        /// The colon's centerline: along the first tube, round the bend, back along the
        /// second (radius the tubes').
        fn centerline_round(self) -> crate::centerline::Centerline {
            let (y0, y1, zc) = self.axes();
            let mut points: Vec<[f64; 3]> = (2..=100).map(|x| [x as f64, y0, zc]).collect();
            points.extend((y0 as usize + 1..y1 as usize).map(|y| [100.0, y as f64, zc]));
            points.extend((2..=100).rev().map(|x| [x as f64, y1, zc]));
            let arc_mm = crate::centerline::arc_lengths(
                &points
                    .iter()
                    .map(|p| DVec3::from_array(*p))
                    .collect::<Vec<_>>(),
            );
            crate::centerline::Centerline {
                radius_mm: vec![self.tube_r; points.len()],
                length_mm: *arc_mm.last().unwrap(),
                canal_mm: 0.0,
                points_mm: points,
                arc_mm,
            }
        }

        /// A path along the first tube, through the hole and back along the second, with
        /// its radii as Ds gives them.
        fn through_the_hole(
            self,
            ds: &crate::grid::Field<f32>,
        ) -> (Vec<[f64; 3]>, Vec<f64>, Vec<f64>) {
            let (y0, y1, zc) = self.axes();
            let (y0, y1) = (y0 as usize, y1 as usize);
            let mut points = Vec::new();
            points.extend((12..=30).map(|x| [x as f64, y0 as f64, zc]));
            points.extend((y0 + 1..y1).map(|y| [30.0, y as f64, zc]));
            points.extend((12..=30).rev().map(|x| [x as f64, y1 as f64, zc]));
            let radius: Vec<f64> = points
                .iter()
                .map(|p| {
                    let b = ds.grid.index_of_global(p.map(|c| c as usize)).unwrap();
                    ds.data[b.0] as f64
                })
                .collect();
            let mut arc = vec![0.0];
            for w in points.windows(2) {
                let d: f64 = (0..3)
                    .map(|a| (w[1][a] - w[0][a]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                arc.push(arc.last().unwrap() + d);
            }
            (points, radius, arc)
        }
    }

    /// A thin hole between narrow tubes, and (`ctc/prone-tagged` in 3 mm slices, where the
    /// splenic flexure's two limbs touch) a hole a fifth as wide as colon 40 mm across: the
    /// widest places on either side were under twice the width asked of the way round, and
    /// 600 ml of the flexure were skipped.
    #[test]
    fn a_hole_between_loops_is_plugged_and_a_neck_is_not() {
        for loops in [
            Loops {
                tube_r: 10.0,
                hole_r: 1.5,
                hole_x: 30.0,
            },
            Loops {
                tube_r: 20.0,
                hole_r: 4.0,
                hole_x: 30.0,
            },
        ] {
            for joined in [true, false] {
                let m = loops.mask(joined);
                let (_, ds) = box_and_ds(&m);
                let mut necks = Vec::new();
                let (points, radius, arc) = loops.through_the_hole(&ds);
                assert!(may_have_shortcuts(&points, &radius, &arc, &necks));
                let plugs = shortcut_plugs(&m, &points, &radius, &arc, &mut necks, &ds);
                if !joined {
                    assert!(plugs.is_empty(), "the only way was plugged");
                    assert_eq!(necks.len(), 1, "the neck is remembered");
                    continue;
                }
                assert!(
                    !plugs.is_empty(),
                    "the hole was not plugged ({} mm)",
                    loops.hole_r
                );
                // The plug lies round the hole's narrowest point.
                let g = m.geometry();
                let neck = (0..points.len())
                    .min_by(|&x, &y| radius[x].total_cmp(&radius[y]))
                    .unwrap();
                let at = glam::DVec3::from_array(points[neck]);
                for &v in &plugs {
                    let p = g.index_to_local(glam::DVec3::from_array(
                        crate::volume::grid_ijk(m.dims(), v).map(|x| x as f64),
                    ));
                    let reach = PLUG_MM.max(2.0 * radius[neck]);
                    assert!(p.distance(at) <= reach + 1e-9, "plugged at {p:?}");
                }
                let (y0, y1, zc) = loops.axes();
                let mut plugged = m.clone();
                plugs.iter().for_each(|&v| plugged.data_mut()[v] = 0);
                let (y0, y1, zc) = (y0 as usize, y1 as usize, zc as usize);
                let crossing = (y0..=y1).all(|j| plugged.get(30, j, zc) != 0);
                assert!(!crossing, "the hole is still open ({} mm)", loops.hole_r);
            }
        }
    }

    /// The whole volume as the box, and Ds over it.
    fn box_and_ds(m: &Volume<u8>) -> (BoxGrid, crate::grid::Field<f32>) {
        let d = m.dims();
        let grid = BoxGrid::around([[0; 3], [d[0] - 1, d[1] - 1, d[2] - 1]], 0, d);
        let ds = crate::distance::distance_to_wall_in(m, grid.clone());
        (grid, ds)
    }

    /// Dt's way back crosses between two loops 93 mm apart along the centerline (the hole
    /// 30 mm before the bend): narrow as a hole in a wall, it is plugged; as wide as a gap
    /// between folds in one chamber (beyond a voxel's diagonal and 2 mm), it is not, where
    /// 173 mm of arc apart the same gap is (a fifth of the colon's radius). Before, falls
    /// under 150 mm were not looked at: the real exam's hole of 0.1 mm between the hepatic
    /// flexure's limbs, 108 mm apart, drew the flight's pull in 3 mm slices.
    #[test]
    fn a_smaller_fall_is_a_hole_only_as_narrow_as_one_in_a_wall() {
        use crate::distance::geodesic_distance;
        let opts = crate::centerline::CenterlineOptions::default();
        for (hole_x, hole_r, plugged) in [(70.0, 1.0, true), (70.0, 2.8, false), (30.0, 2.8, true)]
        {
            let loops = Loops {
                tube_r: 14.0,
                hole_r,
                hole_x,
            };
            let m = loops.mask(true);
            let (grid, ds) = box_and_ds(&m);
            let (y0, _, zc) = loops.axes();
            let cl = loops.centerline_round();
            let dt = geodesic_distance(&m, &grid, [2, y0 as usize, zc as usize]).unwrap();
            let ds = crate::grid::Bricked::from_field(&ds, 0.0);
            let crossings = holes_by_descent(&m, &dt.dist, &cl, 60.0, 10.0);
            assert!(!crossings.is_empty(), "{hole_x} {hole_r}: no crossing");
            let hole = crossings.iter().find_map(|&i| {
                plug_beside(&m, &ds, &dt.dist, &cl, i, [60.0, 150.0], &opts)
                    .into_iter()
                    .next()
            });
            let what = hole.as_ref().map(|h| (h.neck_mm, h.arcs_mm));
            assert_eq!(hole.is_some(), plugged, "{hole_x} {hole_r}: {what:?}");
            if let Some(h) = hole {
                let jump = h.arcs_mm[0] - h.arcs_mm[1];
                let want = if hole_x == 70.0 { 93.0 } else { 173.0 };
                assert!((jump - want).abs() <= 5.0, "{what:?}");
            }
            if hole_x == 70.0 {
                assert!(holes_by_descent(&m, &dt.dist, &cl, 150.0, 10.0).is_empty());
            }
        }
    }

    /// The colon round two loops (along the first tube, the bend, back along the second)
    /// with a hole between them that the centerline goes round: Dt at the second tube's
    /// point across the hole lies far below the centerline's arc, and Dt's way back from
    /// there crosses the hole, which is plugged, the colon still whole; without a hole
    /// nothing is.
    #[test]
    fn a_hole_beside_the_centerline_is_plugged_where_dt_shows_it() {
        use crate::distance::geodesic_distance;
        for hole_r in [1.5, -1.0] {
            let loops = Loops {
                tube_r: 10.0,
                hole_r,
                hole_x: 30.0,
            };
            let m = loops.mask(true);
            let (grid, ds) = box_and_ds(&m);
            let (y0, y1, zc) = loops.axes();
            let cl = loops.centerline_round();
            let source = [2, y0 as usize, zc as usize];
            let dt = geodesic_distance(&m, &grid, source).unwrap();
            let across = cl.points_mm.iter().rposition(|p| p[0] == 30.0).unwrap();
            let at = [30, y1 as usize, zc as usize];
            let want = cl.arc_mm[across];
            if hole_r > 0.0 {
                let before = dt.dist.get(at) as f64;
                assert!(before < want - 100.0, "Dt {before:.0} mm, arc {want:.0}");
            }
            let opts = crate::centerline::CenterlineOptions::default();
            let ds = crate::grid::Bricked::from_field(&ds, 0.0);
            // The ways back from points past the hole cross it, 165 mm of arc at once.
            let crossings = holes_by_descent(&m, &dt.dist, &cl, 150.0, 10.0);
            let hole = plug_beside(&m, &ds, &dt.dist, &cl, across, [50.0; 2], &opts)
                .into_iter()
                .next();
            if hole_r < 0.0 {
                assert!(hole.is_none(), "plugged without a hole");
                assert!(crossings.is_empty(), "crossings without a hole");
                continue;
            }
            let hole = hole.expect("the hole beside was not plugged");
            assert!((hole.neck_mm - hole_r).abs() <= 1.0, "{hole:?}");
            assert_eq!(crossings.len(), 1, "{crossings:?}");
            let by_descent = plug_beside(&m, &ds, &dt.dist, &cl, crossings[0], [150.0; 2], &opts)
                .into_iter()
                .next()
                .expect("the hole was not plugged from the crossing");
            assert!(
                (by_descent.neck_mm - hole.neck_mm).abs() <= 0.5
                    && (by_descent.arcs_mm[1] - hole.arcs_mm[1]).abs() <= 2.0,
                "{:?} against {:?}",
                (by_descent.neck_mm, by_descent.arcs_mm),
                (hole.neck_mm, hole.arcs_mm)
            );
            let plugs = hole.plugs;
            let hole = DVec3::new(30.0, (y0 + y1) / 2.0, zc);
            let g = m.geometry();
            for &v in &plugs {
                let p = g.index_to_local(DVec3::from_array(g.ijk(v).map(|x| x as f64)));
                assert!(p.distance(hole) <= PLUG_MM + 3.0, "plugged at {p:?}");
            }
            let mut plugged = m.clone();
            plugs.iter().for_each(|&v| plugged.data_mut()[v] = 0);
            let dt = geodesic_distance(&plugged, &grid, source).unwrap();
            let end = [2, y1 as usize, zc as usize];
            assert!(dt.dist.get(end).is_finite(), "the plug parted the colon");
            // Dt hugs the tubes' inner walls round the bend, where the centerline keeps to
            // their middle: short by about 30 mm, as in a chamber.
            let got = dt.dist.get(at) as f64;
            assert!(
                got > want - 50.0,
                "Dt {got:.0} mm where the arc is {want:.0}"
            );
        }
    }
}
