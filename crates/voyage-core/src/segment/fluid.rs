//! Tagged fluid that belongs to the colon, and gravity from the air–fluid levels.
//!
//! Residual fluid in a CT colonography is tagged with oral contrast (300–1000 HU) and lies on
//! the dependent side of a colon segment under a flat level, with the segment's air on top.
//! Oral contrast also fills small-bowel loops, which touch the colon and, through the
//! ileocecal valve, join the cecum's pool into one bright region: connectivity cannot tell
//! them apart. Geometry can: the colon's pool lies in the column *under the colon's air*,
//! across the level; the loops leave it sideways or downwards as tubes with no air above.
//!
//! So fluid is taken line by line along gravity (the voxel axis nearest to it), from the top
//! down: a bright voxel joins the colon when the line came down through gas, then at most a
//! partial-volume layer of a couple of millimetres, then only bright voxels, and has not gone
//! deeper than `MAX_DEPTH_MM` below the gas. A loop under the colon is behind two walls
//! (more than the layer allows); a loop beside it has no gas above.
//!
//! The lines are walked through their labelled voxels only (gas and bright runs, row by
//! row), never through the empty voxels between: a scan's bone is bright too, and the box
//! around the gas is most of the volume.
//!
//! The step is [`pool`]: the gas and its pools as working labels, and gravity. Once the colon
//! is chained, [`whole_pools`] takes in its fluid beyond the columns, and [`fill_fluid`] the
//! fluid a bridge crosses.

use glam::DVec3;
use rayon::prelude::*;

use super::{
    SegmentOptions,
    components::Found,
    runs::{BRIGHT, LabelRows, Runs, label_rows, paint, row_of, runs_box, runs_near},
    work::{BRIDGE, Bbox, GAS, LAYER, POOL},
};
use crate::{
    Geometry, Result, Volume,
    anatomy::{Orientation, PatientFrame, PatientPosition, PositionSource},
    volume::{ball_offsets, face_neighbours},
};

/// A pool deeper than this below its gas is not one colon segment's fluid. (The prone
/// `ctc/prone-tagged`'s descending pool is about 70 mm deep: at 60 mm its floor was cut off
/// in a straight plane.)
pub const MAX_DEPTH_MM: f64 = 100.0;

/// Between air and fluid the partial-volume layer is at most this thick (mm; at least one
/// voxel).
const MAX_LAYER_MM: f64 = 2.0;

/// Deeper than this below the gas, fluid stays the colon's only where it is wide, or where
/// it ends soon below. Wide: a horizontal chord through it, all fluid, of at least
/// [`WIDE_MM`] along one of the two horizontal axes. A pool spreads under its level along
/// its segment; a loop leaving it downward, as the ileum through the ileocecal valve, is a
/// tube at most 25 mm across (small bowel, real or the full-size phantom's 16–19 mm, 22 mm
/// as a horizontal cut where it leaves at 30°), so every horizontal chord of it is shorter.
/// Ends soon: the fluid below it along the line is less than [`TUBE_MM`] deep. The floor of
/// a pool in a narrow or short segment is narrow too, but it ends at the wall, while a tube
/// goes on down (a deeper allowance lets the ileum's rim in where its wall comes near). An
/// absolute width, not one relative to the pool: the small bowel's calibre does not scale
/// with the colon's.
const NARROW_BELOW_MM: f64 = 4.0;
const WIDE_MM: f64 = 27.0;
const TUBE_MM: f64 = 3.0;
/// A pool's floor narrower than [`WIDE_MM`] joins only where no gas lies within this (mm)
/// below it: a wall, not a loop behind a thin one.
const FLOOR_WALL_MM: f64 = 4.0;

/// The layer's thickness in voxels along an axis of spacing `step`.
fn max_gap(step: f64) -> i64 {
    ((MAX_LAYER_MM / step).round() as i64).clamp(1, 3)
}

/// What one line (a column along gravity) has seen so far.
#[derive(Clone, Copy, Default)]
struct Line {
    /// 0: nothing open; 1: below gas; 2: in fluid under gas.
    state: u8,
    /// Position of the last labelled voxel, and of the last gas voxel.
    last: i64,
    gas: i64,
}

/// A mark to write: voxel index and label.
type Mark = (usize, u8);

/// What stays fixed along every line of a walk: a step's stride in the volume's index, and
/// the limits (layer's thickness, pool's depth, depth from which fluid must be wide) in steps.
#[derive(Clone, Copy)]
struct Walk {
    stride: isize,
    gap_max: i64,
    depth_max: i64,
    narrow_below: i64,
}

impl Line {
    /// The line meets `label` at position `pos` (voxel `idx`; a step along the line is
    /// `stride` in the volume's index). Pushes the pool's and the layer's voxels.
    #[inline]
    fn visit(
        &mut self,
        pos: i64,
        label: u8,
        idx: usize,
        walk: &Walk,
        wide: impl Fn() -> bool,
        marks: &mut Vec<Mark>,
    ) {
        let Walk {
            stride,
            gap_max,
            depth_max,
            narrow_below,
        } = *walk;
        let gap = (pos - self.last).abs() - 1;
        match label {
            GAS => {
                self.state = 1;
                self.gas = pos;
            }
            _ if self.state == 1 && gap <= gap_max && (pos - self.gas).abs() <= depth_max => {
                for t in 1..=gap as isize {
                    marks.push(((idx as isize - t * stride) as usize, LAYER));
                }
                marks.push((idx, POOL));
                self.state = 2;
            }
            _ if self.state == 2
                && gap == 0
                && (pos - self.gas).abs() <= depth_max
                && ((pos - self.gas).abs() <= narrow_below || wide()) =>
            {
                marks.push((idx, POOL))
            }
            _ => self.state = 0,
        }
        self.last = pos;
    }
}

/// Calls `f(line, pos, idx, label)` for every labelled voxel of `rows` inside `bx` on lines
/// along `axis`, each line in the direction `sign`, lines of one slice together: slices are
/// independent for `axis` 0 and 1 (run in parallel, one state per slice), not for 2.
fn walk<S: Send>(
    rows: &LabelRows,
    bx: &Bbox,
    axis: usize,
    sign: i32,
    state: impl Fn() -> S + Sync,
    f: impl Fn(&mut S, usize, i64, usize, u8) + Sync,
) -> Vec<S> {
    let [nx, ny, _] = rows.dims;
    let ks: Vec<usize> = if axis == 2 && sign < 0 {
        (bx.lo[2]..=bx.hi[2]).rev().collect()
    } else {
        (bx.lo[2]..=bx.hi[2]).collect()
    };
    let slice = |s: &mut S, k: usize| {
        let js: Vec<usize> = if axis == 1 && sign < 0 {
            (bx.lo[1]..=bx.hi[1]).rev().collect()
        } else {
            (bx.lo[1]..=bx.hi[1]).collect()
        };
        for j in js {
            let row = rows.row(j, k);
            let base = nx * (j + ny * k);
            let mut visit = |x: usize, label: u8| {
                let (line, pos) = match axis {
                    0 => (j - bx.lo[1], x as i64),
                    1 => (x - bx.lo[0], j as i64),
                    _ => (
                        (x - bx.lo[0]) + (j - bx.lo[1]) * (bx.hi[0] + 1 - bx.lo[0]),
                        k as i64,
                    ),
                };
                f(s, line, pos, base + x, label);
            };
            let clip = |&(x0, x1, l): &(u32, u32, u8)| {
                (x0.max(bx.lo[0] as u32), x1.min(bx.hi[0] as u32 + 1), l)
            };
            if axis == 0 && sign < 0 {
                for (x0, x1, l) in row.iter().rev().map(clip) {
                    (x0..x1).rev().for_each(|x| visit(x as usize, l));
                }
            } else {
                for (x0, x1, l) in row.iter().map(clip) {
                    (x0..x1).for_each(|x| visit(x as usize, l));
                }
            }
        }
    };
    if axis == 2 {
        let mut s = state();
        ks.into_iter().for_each(|k| slice(&mut s, k));
        vec![s]
    } else {
        ks.into_par_iter()
            .map(|k| {
                let mut s = state();
                slice(&mut s, k);
                s
            })
            .collect()
    }
}

/// The colon's tagged fluid: the voxels (volume indices) of bright runs in the column under
/// gas (POOL), and of the layer between them (LAYER). Gravity: LPS unit vector; `bright(v)`:
/// whether voxel v is bright.
pub fn pools(
    rows: &LabelRows,
    geom: &Geometry,
    bx: &Bbox,
    gravity_lps: DVec3,
    bright: impl Fn(usize) -> bool + Sync,
    gas: impl Fn(usize) -> bool + Sync,
) -> Vec<Mark> {
    let (axis, sign) = PatientFrame::of(geom).nearest_axis(gravity_lps);
    let step = geom.spacing[axis];
    let stride = line_stride(geom, axis, sign);
    let limits = Walk {
        stride,
        gap_max: max_gap(step),
        depth_max: (MAX_DEPTH_MM / step).round() as i64,
        narrow_below: (NARROW_BELOW_MM / step).round() as i64,
    };
    let wide = |v: usize| wide(geom, v, (axis, sign), &bright, &gas);
    let w = bx.widths();
    let lines = if axis == 2 {
        w[0] * w[1]
    } else {
        w[[1, 0, 0][axis]]
    };
    let per = walk(
        rows,
        bx,
        axis,
        sign,
        || {
            (
                vec![
                    Line {
                        last: i64::MIN / 2,
                        ..Default::default()
                    };
                    lines
                ],
                Vec::new(),
            )
        },
        |(state, marks), line, pos, idx, label| {
            state[line].visit(pos, label, idx, &limits, || wide(idx), marks);
        },
    );
    per.into_iter().flat_map(|(_, m)| m).collect()
}

/// Whether bright voxel `v` lies where fluid is wide or ends soon below it (gravity along
/// voxel axis `down.0`, direction `down.1`): see [`WIDE_MM`]. A pool spreads under its level,
/// a loop leaving it is a tube.
///
/// Ends soon: less than [`TUBE_MM`] of fluid below, or a pool's floor ([`floor`]).
pub fn wide(
    geom: &Geometry,
    v: usize,
    down: (usize, i32),
    bright: &impl Fn(usize) -> bool,
    gas: &impl Fn(usize) -> bool,
) -> bool {
    let (axis, sign) = down;
    let tube_steps = (TUBE_MM / geom.spacing[axis]).ceil() as usize;
    if bright_run(geom, v, axis, sign, tube_steps, bright) < tube_steps {
        return true;
    }
    let chord = widest_across(geom, v, axis, bright);
    chord >= WIDE_MM || floor(geom, v, down, chord, bright, gas)
}

/// Whether bright voxel `v`, whose longest horizontal chord `chord` (mm) is under
/// [`WIDE_MM`], lies on a pool's floor. A floor's chords shrink as it curves up to the wall,
/// and under a chord `c` it holds at most `c / 2` of fluid (a round floor: `h ≤ c / 2` at
/// every height `h` above its lowest point); a tube leaving downward is as narrow and goes
/// on down. (`ctc/prone-tagged`'s prone sigmoid pool, round in section: its chords fall
/// below [`WIDE_MM`] 6 mm above its floor, and those 6 mm, 13 ml in all, were left tagged
/// under the cleansed level.) Below `v`, besides:
/// - each level's fluid lies within the one above it (a voxel of slack each way for noise):
///   a loop against the floor with no wall between reaches out beyond its neck (the ileum
///   under the caecal pool, at the valve);
/// - where the line meets the wall, the fluid beside it ends soon below too: a line down the
///   side of a tube leaving the floor (the ileum, grazed) ends at the tube's wall while the
///   tube goes on down next to it;
/// - it rests on a wall, not on another loop: no gas within [`FLOOR_WALL_MM`] below. Taken
///   to a thin wall with a loop's gas behind it, a floor left the wall a voxel or two, and
///   the centerline went through it (the real exam cut 60 mm at the top: at the splenic
///   flexure, 160 mm of colon left out).
fn floor(
    geom: &Geometry,
    v: usize,
    (axis, sign): (usize, i32),
    chord: f64,
    bright: &impl Fn(usize) -> bool,
    gas: &impl Fn(usize) -> bool,
) -> bool {
    let step = geom.spacing[axis];
    let tube_steps = (TUBE_MM / step).ceil() as usize;
    let floor_steps = ((chord / 2.0 / step).ceil() as usize).max(tube_steps);
    let below = bright_run(geom, v, axis, sign, floor_steps, bright);
    if below >= floor_steps {
        return false;
    }
    let stride = line_stride(geom, axis, sign);
    let at = |t: usize| (v as isize + t as isize * stride) as usize;
    let mut outline = across(geom, v, axis, bright);
    let nested = (1..=below).all(|t| {
        let w = across(geom, at(t), axis, bright);
        let within = (0..2).all(|h| (0..2).all(|e| w[h][e] <= outline[h][e] + 1));
        for (o, w) in outline.iter_mut().flatten().zip(w.iter().flatten()) {
            *o = (*o).min(*w);
        }
        within
    });
    let bottom = at(below);
    let ends_beside = || {
        beside_across(geom, bottom, axis)
            .all(|n| !bright(n) || bright_run(geom, n, axis, sign, tube_steps, bright) < tube_steps)
    };
    let here = geom.ijk(bottom)[axis];
    let room = if sign > 0 {
        geom.dims[axis] - 1 - here
    } else {
        here
    };
    let wall_steps = ((FLOOR_WALL_MM / step).ceil() as usize).min(room);
    nested && ends_beside() && (1..=wall_steps).all(|t| !gas(at(below + t)))
}

/// The step along voxel axis `axis` in direction `sign` (±1), in the volume's index.
fn line_stride(geom: &Geometry, axis: usize, sign: i32) -> isize {
    [
        1isize,
        geom.dims[0] as isize,
        (geom.dims[0] * geom.dims[1]) as isize,
    ][axis]
        * sign as isize
}

/// The two voxel axes across gravity's `down`.
fn horizontal(down: usize) -> [usize; 2] {
    [[1, 2], [0, 2], [0, 1]][down]
}

/// The eight voxels around `v` in its horizontal plane (gravity along voxel axis `down`),
/// those inside the volume.
fn beside_across(geom: &Geometry, v: usize, down: usize) -> impl Iterator<Item = usize> + '_ {
    let [a, b] = horizontal(down);
    let ijk = geom.ijk(v).map(|x| x as i64);
    (-1..=1i64)
        .flat_map(move |da| (-1..=1i64).map(move |db| (da, db)))
        .filter(|&d| d != (0, 0))
        .filter_map(move |(da, db)| {
            let mut q = ijk;
            q[a] += da;
            q[b] += db;
            (0..3)
                .all(|x| q[x] >= 0 && q[x] < geom.dims[x] as i64)
                .then(|| geom.index(q[0] as usize, q[1] as usize, q[2] as usize))
        })
}

/// The bright voxels beside bright voxel `v` along the two horizontal axes (gravity along
/// voxel axis `down`): per axis, how many follow it backwards and forwards, each counted up
/// to [`WIDE_MM`].
fn across(
    geom: &Geometry,
    v: usize,
    down: usize,
    bright: &impl Fn(usize) -> bool,
) -> [[usize; 2]; 2] {
    horizontal(down).map(|a| {
        let need = (WIDE_MM / geom.spacing[a]).ceil() as usize;
        [-1, 1].map(|sign| bright_run(geom, v, a, sign, need, bright))
    })
}

/// The longest horizontal chord through bright voxel `v` (gravity along voxel axis `down`),
/// all bright, in mm, counted up to [`WIDE_MM`].
fn widest_across(geom: &Geometry, v: usize, down: usize, bright: &impl Fn(usize) -> bool) -> f64 {
    let axes = horizontal(down);
    let runs = across(geom, v, down, bright);
    (0..2)
        .map(|h| {
            let [back, fwd] = runs[h];
            ((1 + back + fwd) as f64 * geom.spacing[axes[h]]).min(WIDE_MM)
        })
        .fold(0.0, f64::max)
}

/// Whether a horizontal chord through bright voxel `v` (gravity along voxel axis `down`),
/// all bright, is at least [`WIDE_MM`] long: fluid spread under a level, not a tube's.
pub fn wide_across(
    geom: &Geometry,
    v: usize,
    down: usize,
    bright: &impl Fn(usize) -> bool,
) -> bool {
    (0..3)
        .filter(|&a| a != down)
        .any(|a| chord_at_least(geom, v, a, WIDE_MM, bright))
}

/// How many bright voxels follow `v` along `axis` in direction `sign` (±1), counting up to
/// `limit` at most and stopping at the volume's edge.
fn bright_run(
    geom: &Geometry,
    v: usize,
    axis: usize,
    sign: i32,
    limit: usize,
    bright: impl Fn(usize) -> bool,
) -> usize {
    let stride = [1usize, geom.dims[0], geom.dims[0] * geom.dims[1]][axis];
    let at = geom.ijk(v)[axis];
    let room = if sign > 0 {
        geom.dims[axis] - 1 - at
    } else {
        at
    };
    (1..=limit.min(room))
        .take_while(|&t| {
            bright(if sign > 0 {
                v + t * stride
            } else {
                v - t * stride
            })
        })
        .count()
}

/// Whether the run of bright voxels through voxel `v` along `axis` is at least `mm` long.
/// Walks out from `v` both ways and stops as soon as it is.
fn chord_at_least(
    geom: &Geometry,
    v: usize,
    axis: usize,
    mm: f64,
    bright: impl Fn(usize) -> bool,
) -> bool {
    let need = (mm / geom.spacing[axis]).ceil() as usize;
    let up = bright_run(geom, v, axis, 1, need.saturating_sub(1), &bright);
    1 + up + bright_run(geom, v, axis, -1, need.saturating_sub(1 + up), &bright) >= need
}

/// Air–fluid interfaces seen along each voxel axis: `[axis][0]` counts lines going from gas
/// down into fluid along +axis, `[axis][1]` along −axis (within the layer's thickness).
pub fn level_counts(rows: &LabelRows, geom: &Geometry, bx: &Bbox) -> [[usize; 2]; 3] {
    let mut out = [[0usize; 2]; 3];
    let w = bx.widths();
    for (axis, counts) in out.iter_mut().enumerate() {
        let gap_max = max_gap(geom.spacing[axis]);
        let lines = if axis == 2 {
            w[0] * w[1]
        } else {
            w[[1, 0, 0][axis]]
        };
        let per = walk(
            rows,
            bx,
            axis,
            1,
            || (vec![(0u8, i64::MIN / 2); lines], [0usize; 2]),
            |(state, c), line, pos, _, label| {
                let (last, at) = state[line];
                if pos - at - 1 <= gap_max {
                    if label == BRIGHT && last == GAS {
                        c[0] += 1;
                    } else if label == GAS && last == BRIGHT {
                        c[1] += 1;
                    }
                }
                state[line] = (label, pos);
            },
        );
        for (_, c) in per {
            counts[0] += c[0];
            counts[1] += c[1];
        }
    }
    out
}

/// Gravity from the levels: the axis direction with by far the most air-over-fluid
/// interface, as an LPS unit vector (None when no clear level is seen). Each line that
/// crosses a level stands for the area of a voxel's face across its axis, so the interfaces
/// are compared in mm²: counted in lines, thick slices would weigh every level seen along the
/// slices' axis up against those seen across it (3 mm slices of a prone exam: 10 575 lines
/// along the slices' axis against 16 874 across, 5 950 against 37 970 mm²).
pub fn gravity_from_levels(rows: &LabelRows, geom: &Geometry, bx: &Bbox) -> Option<DVec3> {
    /// A level smaller than this (mm² of interface) is not evidence.
    const MIN_INTERFACE_MM2: f64 = 30.0;
    let counts = level_counts(rows, geom, bx);
    let sp = geom.spacing;
    let face_mm2 = |axis: usize| sp[(axis + 1) % 3] * sp[(axis + 2) % 3];
    let mut dirs: Vec<(f64, usize, i32)> = (0..3)
        .flat_map(|a| {
            let area = |n: usize| n as f64 * face_mm2(a);
            [(area(counts[a][0]), a, 1), (area(counts[a][1]), a, -1)]
        })
        .collect();
    dirs.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)).then(y.2.cmp(&x.2)));
    let (best, axis, sign) = dirs[0];
    if best < MIN_INTERFACE_MM2 || best < 3.0 * dirs[1].0 {
        return None;
    }
    let mut e = [0.0; 3];
    e[axis] = sign as f64;
    Some(PatientFrame::of(geom).lps(DVec3::from_array(e)).normalize())
}

/// Real pools are wider than the air above them: they fill haustral pockets and run under
/// folds beyond the column under the air, and a fluid-filled stretch holds only a bubble.
/// So the colon's fluid is also every bright voxel reached from its bright voxels within this
/// far (mm, along 6-neighbour steps through bright voxels where the fluid is
/// [`wide_across`]: a small-bowel loop leaving the pool, as the ileum through the ileocecal
/// valve, is not, even along its floor). On `ctc/prone-tagged` this
/// reach takes in 97 % of the tagged fluid of the given colon, while contrast in small-bowel
/// loops and bone, behind wall and fat, is not reached or only where a loop touches the
/// colon (0.7 ml); at 30 mm 7 ml of it came in, at 40 mm 36 ml.
pub const POOL_REACH_MM: f64 = 20.0;

/// A step down (along gravity) costs this many times its length in [`grow_bright`]: a pool
/// spreads sideways under its level, into the pockets beside the air; a loop leaving its
/// floor downward, as the ileum through the ileocecal valve, is followed a few mm at most.
pub const DOWN_COST: u32 = 8;

/// Distances in [`grow_bright`], in units of this (mm): integer sums, so that which voxels
/// lie within the reach does not depend on the order they were visited in.
const DIST_UNIT_MM: f64 = 0.01;

/// What [`grow_bright`] does at a voxel it reaches.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Left out.
    Stop,
    /// Taken, not passed through (a pool's partial-volume skin, not the wall between it and
    /// a loop beside it).
    Take,
    /// Taken and passed through.
    Pass,
}

/// Grows `work` from `seeds` (voxel indices) through the voxels where `step(i)` is
/// [`Step::Pass`], each reached within `reach_mm` (along 6-neighbour steps, each as long as
/// the spacing along its axis, and [`DOWN_COST`] times that along gravity, `down`: voxel axis
/// and direction) set to `label` and pushed to `added`; a voxel where it is [`Step::Take`] is
/// taken when reached, and not passed through. A seed is taken where it passes. A step into
/// a voxel where `free(i)` costs nothing (the core of a fluid body wider than any small-bowel
/// loop: [`Cores`]). Only voxels still 0 in `work` are taken.
#[allow(clippy::too_many_arguments)]
pub fn grow_bright(
    work: &mut crate::Volume<u8>,
    seeds: impl IntoIterator<Item = usize>,
    (reach_mm, down): (f64, Option<(usize, i32)>),
    step: impl Fn(usize) -> Step,
    free: impl Fn(usize) -> bool,
    label: u8,
    added: &mut Vec<usize>,
) {
    use std::cmp::Reverse;
    use std::collections::{BinaryHeap, HashMap};
    let g = work.geometry().clone();
    // Per axis, the cost of a step towards − and towards +.
    let unit: [[u32; 2]; 3] = [0, 1, 2].map(|a| {
        let u = (g.spacing[a] / DIST_UNIT_MM).round().max(1.0) as u32;
        match down {
            Some((axis, sign)) if axis == a => {
                if sign > 0 {
                    [u, DOWN_COST * u]
                } else {
                    [DOWN_COST * u, u]
                }
            }
            _ => [u, u],
        }
    });
    let reach = (reach_mm / DIST_UNIT_MM).round() as u32;
    let mut dist: HashMap<usize, u32, crate::mem::VoxelHash> = HashMap::default();
    let mut heap = BinaryHeap::new();
    for i in seeds {
        if dist.insert(i, 0).is_none() {
            heap.push(Reverse((0u32, i)));
        }
    }
    while let Some(Reverse((d, i))) = heap.pop() {
        if dist.get(&i).is_some_and(|&x| x < d) {
            continue;
        }
        // Every voxel queued past the seeds passed when it was queued.
        if work.data()[i] == 0 && (d > 0 || step(i) == Step::Pass) {
            work.data_mut()[i] = label;
            added.push(i);
        }
        let steps = face_neighbours(g.dims, i)
            .into_iter()
            .zip(unit.into_iter().flatten())
            .filter_map(|(q, u)| Some((q?, u)));
        for (q, u) in steps {
            let dq = if free(q) { d } else { d + u };
            if dq > reach || work.data()[q] != 0 {
                continue;
            }
            // Queued already: it passed; only a nearer way counts.
            if let Some(&x) = dist.get(&q) {
                if dq < x {
                    dist.insert(q, dq);
                    heap.push(Reverse((dq, q)));
                }
                continue;
            }
            match step(q) {
                Step::Stop => {}
                Step::Pass => {
                    dist.insert(q, dq);
                    heap.push(Reverse((dq, q)));
                }
                Step::Take => {
                    work.data_mut()[q] = label;
                    added.push(q);
                }
            }
        }
    }
}

/// Whether tagged voxel `v` is at least halfway between soft tissue (`tissue_hu`) and the
/// brightest of its six neighbours: fluid, not the partial-volume wall between two pools (a
/// bowel wall of 2 mm between two pools, blurred, stays above the fluid threshold).
pub fn above_half(hu: &[i16], v: usize, dims: [usize; 3], tissue_hu: i16) -> bool {
    let max = face_neighbours(dims, v)
        .into_iter()
        .flatten()
        .map(|w| hu[w])
        .max()
        .unwrap_or(hu[v])
        .max(hu[v]);
    2 * hu[v] as i32 >= max as i32 + tissue_hu as i32
}

/// Steps 5 and 6 on the gas: the working labels (gas, and the pools under it with their
/// layers) and the patient's orientation.
pub(super) struct Pooled {
    /// Working labels in the volume that becomes the lumen.
    pub(super) work: Volume<u8>,
    pub(super) orientation: Orientation,
    /// Fluid lies below the gas, at most a pool's depth away: everything from here on happens
    /// in this box.
    pub(super) cbox: Bbox,
    /// Voxels labelled pool or layer.
    pub(super) pooled: usize,
    /// Per row (j + ny·k): whether it holds any of them (empty without bright runs).
    pub(super) pool_rows: Vec<bool>,
    /// The header's position the levels overruled, in words.
    pub(super) conflict: Option<String>,
}

/// Labels the gas of `found`, finds gravity (given, else from the air–fluid levels, else
/// supine assumed) and labels the pools under the gas: the fluid at or above `fluid_hu`.
pub(super) fn pool(
    vol: &Volume<i16>,
    opts: &SegmentOptions,
    found: &Found,
    fluid_hu: Option<i16>,
    from_mask: bool,
) -> Result<Pooled> {
    let gas = |r: usize| found.gas_run(r);
    let mut work = Volume::filled(vol.geometry().clone(), 0u8)?;
    paint(&mut work, &found.runs, |r| gas(r).then_some(GAS));
    let Some(gas_box) = runs_box(&found.runs, vol.dims(), gas) else {
        return Err(found.no_colon(opts, from_mask));
    };
    let mut orientation = given_or_assumed(opts.position);
    let Some(bright) = &found.bright else {
        return Ok(Pooled {
            work,
            orientation,
            cbox: gas_box,
            pooled: 0,
            pool_rows: Vec::new(),
            conflict: None,
        });
    };
    let nx = vol.dims()[0];
    let cbox = gas_box.grown(
        vol.spacing()
            .map(|s| (MAX_DEPTH_MM / s).ceil() as usize + 2),
        vol.dims(),
    );
    let rows = label_rows(&found.runs, gas, bright, &cbox, nx, |_, _, _| true);
    // The levels decide unless the user gave the position: a header's PatientPosition that
    // contradicts them (a prone exam tagged HFS) is overruled, and said.
    let mut conflict = None;
    let header = matches!(opts.position, Some((_, PositionSource::Dicom)));
    if (opts.position.is_none() || header)
        && let Some(g) =
            gravity_from_levels(&level_rows(found, bright, &cbox, nx), vol.geometry(), &cbox)
    {
        let levels = PatientPosition::from_gravity(g);
        if header && orientation.gravity().dot(levels.gravity_lps()) < AGREE_COS {
            conflict = Some(format!(
                "the DICOM header's PatientPosition is {} but the air–fluid levels show {}: the levels are taken",
                orientation.position.code(),
                levels.code()
            ));
        }
        if !header || conflict.is_some() {
            orientation = Orientation::new(levels, PositionSource::AirFluidLevels);
        }
    }
    let threshold = fluid_hu.unwrap_or(i16::MAX);
    let marks = pools(
        &rows,
        vol.geometry(),
        &cbox,
        orientation.gravity(),
        |v| vol.data()[v] >= threshold,
        |v| vol.data()[v] < opts.air_hu,
    );
    let pooled = marks.len();
    let pool_rows = mark(&mut work, marks);
    Ok(Pooled {
        work,
        orientation,
        cbox,
        pooled,
        pool_rows,
        conflict,
    })
}

/// Gravity from the header and from the levels agree when within this cosine (60°).
const AGREE_COS: f64 = 0.5;

/// The position given, else supine assumed.
fn given_or_assumed(position: Option<(PatientPosition, PositionSource)>) -> Orientation {
    match position {
        Some((p, src)) => Orientation::new(p, src),
        None => Orientation::new(PatientPosition::Hfs, PositionSource::Assumed),
    }
}

/// Writes the pools' labels into `work`; returns per row (j + ny·k) whether it holds any.
fn mark(work: &mut Volume<u8>, marks: Vec<Mark>) -> Vec<bool> {
    let [nx, ny, nz] = work.dims();
    let mut rows = vec![false; ny * nz];
    for (idx, label) in marks {
        work.data_mut()[idx] = label;
        rows[idx / nx] = true;
    }
    rows
}

/// The gas runs and bright runs where air–fluid levels may lie: a level lies within a layer's
/// thickness of gas, so only gas near bright runs and bright runs near gas (not bone, most of
/// them) are looked at for it.
fn level_rows(found: &Found, bright: &Runs, cbox: &Bbox, nx: usize) -> LabelRows {
    let runs = &found.runs;
    let all = |_: usize| true;
    let near_gas =
        |x: (u32, u32), j: usize, k: usize| runs_near(runs, &|r| found.gas_run(r), x, j, k, 3);
    let gas_near_bright = |r: usize| {
        found.gas_run(r) && {
            let (j, k) = row_of(runs, r);
            runs_near(bright, &all, (runs.runs[r].x0, runs.runs[r].x1), j, k, 3)
        }
    };
    label_rows(runs, gas_near_bright, bright, cbox, nx, near_gas)
}

impl Pooled {
    /// The warning when the patient's position was assumed, or the header's overruled.
    pub(super) fn position_warning(&self, from_mask: bool) -> Option<String> {
        if let Some(c) = &self.conflict {
            return Some(c.clone());
        }
        (self.orientation.source == PositionSource::Assumed).then(|| if from_mask {
            "patient position unknown (a mask has no fluid levels): supine assumed; give --position if not".to_string()
        } else {
            "patient position unknown (no PatientPosition, no air–fluid level seen): supine assumed; give --position if not".to_string()
        })
    }
}

/// Soft tissue's HU: the bowel wall between two pools.
const TISSUE_HU: i16 = 40;

/// Fluid filling a bridged stretch: the bright voxels reached from the path's bright voxels
/// within `reach_mm`, through bright voxels.
pub(super) fn fill_fluid(
    work: &mut Volume<u8>,
    path: &[[usize; 3]],
    reach_mm: f64,
    bright: impl Fn(usize) -> bool,
    added: &mut Vec<usize>,
) {
    let g = work.geometry().clone();
    let seeds: Vec<usize> = path
        .iter()
        .map(|v| g.index(v[0], v[1], v[2]))
        .filter(|&i| work.data()[i] == 0 && bright(i))
        .collect();
    grow_bright(
        work,
        seeds,
        (reach_mm, None),
        |i| if bright(i) { Step::Pass } else { Step::Stop },
        |_| false,
        BRIDGE,
        added,
    );
}

/// The colon's tagged fluid beyond its pools' columns: bright voxels within
/// [`POOL_REACH_MM`] of the lumen's bright voxels (`lumen` is 0/1, in `lumen_box`),
/// added to the lumen. Returns them.
pub(super) fn whole_pools(
    lumen: &mut Volume<u8>,
    ct: &Volume<i16>,
    lumen_box: Option<Bbox>,
    (air_hu, fluid_hu): (i16, i16),
    gravity_lps: DVec3,
) -> Vec<usize> {
    let Some(b) = lumen_box else {
        return Vec::new();
    };
    let g = lumen.geometry().clone();
    let bright = |i: usize| ct.data()[i] >= fluid_hu;
    // Only the lumen's bright voxels with a bright neighbour outside it start the growth.
    let seeds = pool_seeds(lumen, ct, &b, fluid_hu);
    let down = PatientFrame::of(&g).nearest_axis(gravity_lps);
    // Fluid is not passed through where gas lies beside it: past the level (in the lumen
    // already) or in tagged stool mottled with gas, which cleansing's model of lumps takes.
    let by_air = |i: usize| {
        face_neighbours(g.dims, i)
            .into_iter()
            .flatten()
            .any(|q| ct.data()[q] < air_hu)
    };
    // Fluid is passed through where it is wide, at least halfway to the brightest beside it
    // (not the blurred wall between two pools), with no gas beside it. Reached from there,
    // the pool's partial-volume skin (bright, under halfway) is taken too, and so is wide
    // fluid beside gas; not a tube's fluid.
    let half = |i: usize| above_half(ct.data(), i, g.dims, TISSUE_HU);
    let wide = |i: usize| wide_across(&g, i, down.0, &bright);
    // Of the bright voxels: the skin (under halfway) is taken; fluid at least halfway is
    // taken where wide, and passed through where also not by air. Each test at most once.
    let step = |i: usize| {
        if !bright(i) {
            Step::Stop
        } else if !half(i) {
            Step::Take
        } else if !wide(i) {
            Step::Stop
        } else if by_air(i) {
            Step::Take
        } else {
            Step::Pass
        }
    };
    // The growth passes only bright voxels: the box around those joined to the seeds holds it.
    let cores = match reach_of(&g, &seeds, bright) {
        Some(b) => Cores::find(ct, b, fluid_hu),
        None => Cores::none(),
    };
    let mut grown = Vec::new();
    grow_bright(
        lumen,
        seeds,
        (POOL_REACH_MM, Some(down)),
        step,
        |i| cores.holds(g.ijk(i)),
        1,
        &mut grown,
    );
    grown
}

/// The voxels of `lumen` (0/1, in `b`) at or above `fluid_hu` in `ct` with a bright neighbour
/// outside the lumen, in storage order. The box is most of the abdomen and few of its voxels
/// are bright lumen: runs of [`SEED_RUN`] are passed over unless one of theirs is.
fn pool_seeds(lumen: &Volume<u8>, ct: &Volume<i16>, b: &Bbox, fluid_hu: i16) -> Vec<usize> {
    let g = lumen.geometry();
    let (lumen, hu) = (lumen.data(), ct.data());
    let bright = |i: usize| hu[i] >= fluid_hu;
    let seed = |i: usize| {
        face_neighbours(g.dims, i)
            .into_iter()
            .flatten()
            .any(|q| lumen[q] == 0 && bright(q))
    };
    let width = b.hi[0] - b.lo[0] + 1;
    let (bright, seed) = (&bright, &seed);
    (b.lo[2]..=b.hi[2])
        .into_par_iter()
        .flat_map_iter(|k| {
            (b.lo[1]..=b.hi[1]).flat_map(move |j| {
                let row = g.index(b.lo[0], j, k);
                let runs = lumen[row..row + width]
                    .chunks(SEED_RUN)
                    .zip(hu[row..row + width].chunks(SEED_RUN));
                runs.enumerate()
                    // No early exit inside a run: the test compiles to vector compares.
                    .filter(move |(_, (l, h))| {
                        l.iter()
                            .zip(*h)
                            .fold(false, |any, (&l, &h)| any | ((l == 1) & (h >= fluid_hu)))
                    })
                    .flat_map(move |(r, (l, _))| {
                        let start = row + r * SEED_RUN;
                        start..start + l.len()
                    })
                    .filter(move |&i| lumen[i] == 1 && bright(i) && seed(i))
            })
        })
        .collect()
}

/// Voxels tested together by [`pool_seeds`].
const SEED_RUN: usize = 32;

/// Fluid this far (mm) or further from anything but fluid is a wide body's core: a ball of
/// fluid 28 mm across fits there. A lumen filled with tagged fluid from wall to wall holds
/// one (the prone `ctc/prone-tagged`'s descending colon: 45 mm across for 12 cm); a small-
/// bowel loop, at most 25 mm across, does not.
pub const CORE_MM: f64 = 14.0;

/// Cores are found on cells about this big (mm), not on voxels: a 14 mm distance needs no
/// finer step, and the box searched is most of the abdomen (8× fewer cells at 0.75 mm).
const CELL_MM: f64 = 1.5;

/// The wide fluid bodies around the lumen: every voxel within [`CORE_MM`] of a core (the
/// union of the 28 mm balls of fluid that fit, an opening of the fluid). [`whole_pools`]
/// crosses them at no cost, so its reach counts only from their edge: a fluid-filled
/// stretch is taken whole, not cut [`POOL_REACH_MM`] from the air in a straight face, and a
/// small-bowel loop touching it is still followed that far at most.
pub struct Cores {
    /// Per cell: within [`CORE_MM`] of a core.
    body: Vec<bool>,
    lo: [usize; 3],
    cell: [usize; 3],
    cells: [usize; 3],
}

impl Cores {
    /// The bodies within the box `b` (around all the growth can pass: [`reach_of`]),
    /// in `hu`: a cell is fluid where all its voxels are at or above `fluid_hu` and at least
    /// halfway from soft tissue to the brightest of them (not the blurred wall between two
    /// pools).
    pub fn find(hu: &Volume<i16>, b: Bbox, fluid_hu: i16) -> Cores {
        let geom = hu.geometry();
        let cell = geom
            .spacing
            .map(|s| ((CELL_MM / s).round() as usize).max(1));
        let w = b.widths();
        let cells = [0, 1, 2].map(|a| w[a].div_ceil(cell[a]));
        let mut cores = Cores {
            body: Vec::new(),
            lo: b.lo,
            cell,
            cells,
        };
        let fluid = cores.fluid_cells(hu, fluid_hu);
        let cell_mm = [0, 1, 2].map(|a| cell[a] as f64 * geom.spacing[a]);
        let Ok(cell_geom) = Geometry::new(cells, cell_mm, [0.0; 3]) else {
            return cores;
        };
        let Some(distance) = Volume::from_vec(cell_geom, fluid)
            .ok()
            .and_then(|v| crate::distance::distance_to_wall(&v).ok())
        else {
            return cores;
        };
        let core: Vec<bool> = (0..cells.iter().product())
            .map(|c| {
                let [x, y, z] = [
                    c % cells[0],
                    (c / cells[0]) % cells[1],
                    c / (cells[0] * cells[1]),
                ];
                distance.get_global([x, y, z], 0.0) >= CORE_MM as f32
            })
            .collect();
        cores.body = dilate(&core, cells, cell_mm, CORE_MM);
        cores
    }

    /// No bodies.
    pub fn none() -> Cores {
        Cores {
            body: Vec::new(),
            lo: [0; 3],
            cell: [1; 3],
            cells: [0; 3],
        }
    }

    /// Per cell, whether all its voxels are fluid.
    fn fluid_cells(&self, hu: &Volume<i16>, fluid_hu: i16) -> Vec<u8> {
        let [cx, cy, cz] = self.cells;
        let (dims, g) = (hu.dims(), hu.geometry());
        // The voxels' columns under the cells along x: from the box's low x to the last
        // cell's end (past the box's high x, clipped to the volume).
        let x0 = self.lo[0];
        let x1 = (x0 + cx * self.cell[0]).min(dims[0]);
        let mut out = vec![0u8; cx * cy * cz];
        out.par_chunks_mut(cx * cy).enumerate().for_each_init(
            || (vec![0i16; x1 - x0], vec![0i16; x1 - x0]),
            |(low, high), (z, slab)| {
                for (y, row) in slab.chunks_mut(cx).enumerate() {
                    let (j0, k0) = (self.lo[1] + y * self.cell[1], self.lo[2] + z * self.cell[2]);
                    let (j1, k1) = (
                        (j0 + self.cell[1]).min(dims[1]),
                        (k0 + self.cell[2]).min(dims[2]),
                    );
                    // Each voxel column's minimum and maximum over the cells' rows first
                    // (whole rows, vector code), then over each cell's columns.
                    low.fill(i16::MAX);
                    high.fill(i16::MIN);
                    for k in k0..k1 {
                        for j in j0..j1 {
                            let i0 = g.index(x0, j, k);
                            let voxels = &hu.data()[i0..i0 + x1 - x0];
                            for ((l, h), &v) in low.iter_mut().zip(high.iter_mut()).zip(voxels) {
                                *l = (*l).min(v);
                                *h = (*h).max(v);
                            }
                        }
                    }
                    let cells = low.chunks(self.cell[0]).zip(high.chunks(self.cell[0]));
                    for (c, (l, h)) in row.iter_mut().zip(cells) {
                        let min = l.iter().copied().fold(i16::MAX, i16::min);
                        let max = h.iter().copied().fold(i16::MIN, i16::max);
                        *c = (min >= fluid_hu && 2 * min as i32 >= max as i32 + TISSUE_HU as i32)
                            as u8;
                    }
                }
            },
        );
        out
    }

    /// Whether voxel `g` (of the volume) lies in a body.
    pub fn holds(&self, g: [usize; 3]) -> bool {
        if self.body.is_empty() {
            return false;
        }
        let mut c = [0usize; 3];
        for a in 0..3 {
            let Some(l) = g[a].checked_sub(self.lo[a]) else {
                return false;
            };
            c[a] = l / self.cell[a];
            if c[a] >= self.cells[a] {
                return false;
            }
        }
        self.body[c[0] + self.cells[0] * (c[1] + self.cells[1] * c[2])]
    }
}

/// The box around every voxel reached from `seeds` through voxels where `pass(i)` (6-neighbour
/// steps, with no limit), grown by a voxel: where [`whole_pools`] may go. None without seeds.
pub fn reach_of(geom: &Geometry, seeds: &[usize], pass: impl Fn(usize) -> bool) -> Option<Bbox> {
    let mut seen = vec![0u64; geom.len().div_ceil(64)];
    let mut visit = |i: usize| {
        let (w, bit) = (i / 64, 1u64 << (i % 64));
        let new = seen[w] & bit == 0;
        seen[w] |= bit;
        new
    };
    let mut stack: Vec<usize> = seeds.iter().copied().filter(|&i| visit(i)).collect();
    let mut b: Option<Bbox> = None;
    while let Some(i) = stack.pop() {
        let at = geom.ijk(i);
        let here = Bbox { lo: at, hi: at };
        b = Some(b.map_or(here, |x| x.union(&here)));
        for q in face_neighbours(geom.dims, i).into_iter().flatten() {
            if pass(q) && visit(q) {
                stack.push(q);
            }
        }
    }
    b.map(|x| x.grown([1; 3], geom.dims))
}

/// The cells within `r_mm` of a set one (cells of `cell_mm`), by a ball stamped on each set
/// cell at the set's edge (the inside is covered by them and by itself).
fn dilate(set: &[bool], cells: [usize; 3], cell_mm: [f64; 3], r_mm: f64) -> Vec<bool> {
    let ball = ball_offsets(cell_mm, r_mm);
    let at = |p: [i64; 3]| -> Option<usize> {
        (0..3)
            .all(|a| p[a] >= 0 && p[a] < cells[a] as i64)
            .then(|| p[0] as usize + cells[0] * (p[1] as usize + cells[1] * p[2] as usize))
    };
    let mut out = set.to_vec();
    for (c, _) in set.iter().enumerate().filter(|(_, s)| **s) {
        let p = [
            (c % cells[0]) as i64,
            ((c / cells[0]) % cells[1]) as i64,
            (c / (cells[0] * cells[1])) as i64,
        ];
        let edge = [[1, 0, 0], [0, 1, 0], [0, 0, 1]].iter().any(|d| {
            [1i64, -1].iter().any(|&sgn| {
                at([p[0] + sgn * d[0], p[1] + sgn * d[1], p[2] + sgn * d[2]])
                    .is_some_and(|q| !set[q])
            })
        });
        if !edge {
            continue;
        }
        for o in &ball {
            if let Some(q) = at([p[0] + o[0], p[1] + o[1], p[2] + o[2]]) {
                out[q] = true;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Volume;

    /// A box of gas over a pool (gravity +y; 40 mm long along z, a colon segment's pool), and
    /// beside it a bright "loop" with no gas above, and under the gas, behind a 4-voxel wall,
    /// another bright loop.
    fn scene() -> Volume<u8> {
        let g = Geometry::new([40, 30, 40], [1.0; 3], [0.0; 3]).unwrap();
        let mut v = Volume::filled(g, 0u8).unwrap();
        for k in 0..40 {
            for i in 2..22 {
                for j in 2..8 {
                    v.set(i, j, k, GAS);
                }
                // One layer voxel at j = 8, fluid from 9 to 13.
                for j in 9..14 {
                    v.set(i, j, k, BRIGHT);
                }
                // Wall 14..18, then a loop under it.
                for j in 18..24 {
                    v.set(i, j, k, BRIGHT);
                }
            }
            for i in 26..36 {
                for j in 9..14 {
                    v.set(i, j, k, BRIGHT);
                }
            }
        }
        v
    }

    fn rows_of(v: &Volume<u8>) -> LabelRows {
        let [nx, ny, nz] = v.dims();
        let mut rows = LabelRows {
            runs: Vec::new(),
            row_start: vec![0],
            dims: v.dims(),
        };
        for k in 0..nz {
            for j in 0..ny {
                let row = &v.data()[nx * (j + ny * k)..nx * (j + ny * k + 1)];
                let mut x = 0;
                while x < nx {
                    let l = row[x];
                    let start = x;
                    while x < nx && row[x] == l {
                        x += 1;
                    }
                    if l != 0 {
                        rows.runs.push((start as u32, x as u32, l));
                    }
                }
                rows.row_start.push(rows.runs.len() as u32);
            }
        }
        rows
    }

    fn all(v: &Volume<u8>) -> Bbox {
        let d = v.dims();
        Bbox {
            lo: [0; 3],
            hi: [d[0] - 1, d[1] - 1, d[2] - 1],
        }
    }

    /// `pools` over all of `v` with gravity +y, its BRIGHT voxels tagged.
    fn supine_pools(v: &Volume<u8>) -> Vec<Mark> {
        pools(
            &rows_of(v),
            v.geometry(),
            &all(v),
            DVec3::Y,
            |i| v.data()[i] == BRIGHT,
            |i| v.data()[i] == GAS,
        )
    }

    /// The mark `pools` gave voxel (i, j, k) of `v`, if any.
    fn mark_at(marks: &[Mark], v: &Volume<u8>, [i, j, k]: [usize; 3]) -> Option<u8> {
        marks
            .iter()
            .find(|m| m.0 == v.geometry().index(i, j, k))
            .map(|m| m.1)
    }

    #[test]
    fn fluid_under_the_gas_joins_and_loops_stay_out() {
        let v = scene();
        let bright = |i: usize| v.data()[i] == BRIGHT;
        let marks = supine_pools(&v);
        let at = |i, j, k| mark_at(&marks, &v, [i, j, k]);
        assert_eq!(at(5, 8, 2), Some(LAYER));
        assert_eq!(at(5, 11, 2), Some(POOL));
        assert_eq!(at(5, 20, 2), None, "a loop behind two walls");
        assert_eq!(at(30, 11, 2), None, "a loop with no gas above");
        assert_eq!(marks.len(), 20 * 6 * 40);
        // A narrow loop leaving the pool downward (the ileum through the ileocecal valve)
        // stays out below the pool, and so does the loop it leads to.
        let mut w = v.clone();
        for k in 9..12 {
            for i in 10..13 {
                for j in 14..18 {
                    w.set(i, j, k, BRIGHT);
                }
            }
        }
        let marks = supine_pools(&w);
        let at = |i, j, k| mark_at(&marks, &w, [i, j, k]);
        assert_eq!(
            (at(11, 13, 10), at(11, 15, 10), at(11, 20, 10)),
            (Some(POOL), None, None)
        );
        // So does a wide one: a 16 mm ileum (the full-size phantom's, a real one's) taken
        // whole by a rule of bright 6 mm to one side.
        let mut w = v.clone();
        for k in 0..40 {
            for i in 0..40 {
                for j in 14..30 {
                    let tube = (4..20).contains(&i) && (12..28).contains(&k);
                    w.set(i, j, k, if tube { BRIGHT } else { 0 });
                }
            }
        }
        let marks = supine_pools(&w);
        let at = |i, j, k| mark_at(&marks, &w, [i, j, k]);
        assert_eq!(
            (at(12, 13, 20), at(12, 16, 20), at(12, 25, 20)),
            (Some(POOL), None, None)
        );
        // Prone: gravity anterior, the fluid is above the gas: none joins.
        let gas = |i: usize| v.data()[i] == GAS;
        assert!(pools(&rows_of(&v), v.geometry(), &all(&v), -DVec3::Y, bright, gas).is_empty());
    }

    /// A round pool (a ball of 16 mm radius, gas over its upper half, gravity +y) with a
    /// tube of 9 mm leaving its floor downward. The floor's chords are under `WIDE_MM` for
    /// its lowest 7 mm: it is taken all the same, as far as the wall; the tube is not.
    #[test]
    fn a_round_floor_is_taken_to_the_wall_and_a_tube_below_it_is_not() {
        let g = Geometry::new([40, 60, 40], [1.0; 3], [0.0; 3]).unwrap();
        let mut v = Volume::filled(g, 0u8).unwrap();
        for k in 0..40 {
            for j in 0..60 {
                for i in 0..40 {
                    let (x, y, z) = (i as f64 - 20.0, j as f64 - 20.0, k as f64 - 20.0);
                    let ball = x * x + y * y + z * z <= 16.0 * 16.0;
                    let tube = j >= 30 && x.abs() <= 4.0 && z.abs() <= 4.0;
                    if ball && j < 20 {
                        v.set(i, j, k, GAS);
                    } else if ball || tube {
                        v.set(i, j, k, BRIGHT);
                    }
                }
            }
        }
        let marks = supine_pools(&v);
        let at = |i, j, k| mark_at(&marks, &v, [i, j, k]);
        // 10 mm below the level, where a chord is 25 mm, and the floor's lowest voxel there.
        assert_eq!(at(14, 30, 20), Some(POOL));
        assert_eq!(at(14, 34, 20), Some(POOL));
        assert_eq!(at(20, 45, 20), None, "the tube below the floor");
        // Beside the tube, the floor is taken wherever a line from the gas reaches it.
        let floor = (0..40)
            .flat_map(|k| (27..60).flat_map(move |j| (0..40).map(move |i| [i, j, k])))
            .filter(|&[i, j, k]| {
                let (x, y, z) = (i as f64 - 20.0, j as f64 - 20.0, k as f64 - 20.0);
                x * x + y * y + z * z <= 16.0 * 16.0 && (x.abs() > 5.0 || z.abs() > 5.0)
            })
            .collect::<Vec<_>>();
        let taken = floor
            .iter()
            .filter(|&&p| at(p[0], p[1], p[2]).is_some())
            .count();
        assert_eq!(taken, floor.len(), "of the floor beside the tube");
        // Another loop's gas under the floor's left side, behind a wall 1.5 mm thin: the
        // floor there stays out where it is narrow (it would leave the wall a voxel thin).
        let mut w = v.clone();
        for k in 0..40 {
            for j in 28..60 {
                for i in 0..16 {
                    let (x, y, z) = (i as f64 - 20.0, j as f64 - 20.0, k as f64 - 20.0);
                    let r = (x * x + y * y + z * z).sqrt();
                    if r > 17.5 && r <= 20.0 {
                        w.set(i, j, k, GAS);
                    }
                }
            }
        }
        let marks = supine_pools(&w);
        let at = |i, j, k| mark_at(&marks, &w, [i, j, k]);
        assert_eq!(at(13, 30, 20), None, "a narrow floor over another loop");
        assert_eq!(at(27, 30, 20), Some(POOL), "the floor away from it");
    }

    #[test]
    fn gravity_is_read_from_the_level_in_any_storage_order() {
        let v = scene();
        assert_eq!(
            gravity_from_levels(&rows_of(&v), v.geometry(), &all(&v)),
            Some(DVec3::Y)
        );
        for (perm, flip) in [
            ([1, 0, 2], [true, false, false]),
            ([2, 1, 0], [false, true, true]),
            ([0, 2, 1], [false, false, true]),
        ] {
            let r = v.reoriented(perm, flip).unwrap();
            let g = gravity_from_levels(&rows_of(&r), r.geometry(), &all(&r)).unwrap();
            assert!((g - DVec3::Y).length() < 1e-9, "{perm:?} {flip:?}: {g}");
            // And the same pool, whichever way the lines run in memory.
            assert_eq!(supine_pools(&r).len(), 20 * 6 * 40, "{perm:?} {flip:?}");
        }
    }

    /// Thick slices (0.75 × 0.75 × 3 mm): a level across y (40 × 10 lines, 900 mm²) and, as
    /// many lines along the slices' axis, gas over fluid across z (40 × 10 lines, 225 mm²).
    /// Counted in lines the two tie and no gravity is read (a prone exam at 3 mm was taken as
    /// supine, assumed); in mm² the level across y wins.
    #[test]
    fn levels_are_weighed_by_area_not_by_lines() {
        let g = Geometry::new([44, 40, 20], [0.75, 0.75, 3.0], [0.0; 3]).unwrap();
        let mut v = Volume::filled(g, 0u8).unwrap();
        for i in 2..42 {
            for k in 0..10 {
                (2..8).for_each(|j| v.set(i, j, k, GAS));
                (8..13).for_each(|j| v.set(i, j, k, BRIGHT));
            }
            for j in 20..30 {
                (12..15).for_each(|k| v.set(i, j, k, GAS));
                (15..18).for_each(|k| v.set(i, j, k, BRIGHT));
            }
        }
        let counts = level_counts(&rows_of(&v), v.geometry(), &all(&v));
        assert_eq!((counts[1][0], counts[2][0]), (400, 400), "{counts:?}");
        let g = gravity_from_levels(&rows_of(&v), v.geometry(), &all(&v)).unwrap();
        assert!((g - DVec3::Y).length() < 1e-9, "{g}");
    }

    /// A gas pocket over its pool (the lumen so far, at x < 50), the pool going on as a
    /// stretch filled wall to wall (a 44 mm tube, 120 mm long along x, as `ctc/prone-tagged`'s
    /// descending colon), and past its end a small-bowel loop full of contrast (20 mm, along
    /// x, touching it with no wall between). The stretch is taken whole, far beyond the
    /// reach from the air; the loop only near the stretch's end.
    #[test]
    fn a_stretch_filled_wall_to_wall_is_taken_whole_and_a_loop_past_it_is_not() {
        let g = Geometry::new([240, 70, 100], [1.0; 3], [0.0; 3]).unwrap();
        let mut ct = Volume::filled(g.clone(), 40i16).unwrap();
        let mut lumen = Volume::filled(g.clone(), 0u8).unwrap();
        let r2 = |j: usize, k: usize, r: f64| {
            (j as f64 - 35.0).powi(2) + (k as f64 - 50.0).powi(2) <= r * r
        };
        let (mut stretch, mut loop_far) = (Vec::new(), Vec::new());
        for k in 0..100 {
            for j in 0..70 {
                for i in 10..240 {
                    let v = g.index(i, j, k);
                    if i < 170 && r2(j, k, 22.0) {
                        // Gravity +y: gas over the pool at x < 50, fluid everywhere after.
                        let gas = i < 50 && j < 28;
                        ct.data_mut()[v] = if gas { -1000 } else { 600 };
                        if i < 50 {
                            lumen.data_mut()[v] = 1;
                        } else {
                            stretch.push(v);
                        }
                    } else if i >= 170 && r2(j, k, 10.0) {
                        ct.data_mut()[v] = 600;
                        if i >= 170 + POOL_REACH_MM as usize + 6 {
                            loop_far.push(v);
                        }
                    }
                }
            }
        }
        let b = Bbox {
            lo: [10, 13, 28],
            hi: [49, 57, 72],
        };
        let grown = whole_pools(&mut lumen, &ct, Some(b), (-600, 200), DVec3::Y);
        let taken = |v: &usize| lumen.data()[*v] == 1;
        let share = stretch.iter().filter(|v| taken(v)).count() as f64 / stretch.len() as f64;
        assert!(share > 0.99, "{share:.3} of the filled stretch taken");
        assert_eq!(grown.len(), grown.iter().filter(|v| taken(v)).count());
        let far = loop_far.iter().filter(|v| taken(v)).count();
        assert_eq!(
            far,
            0,
            "{far} voxels of the loop taken beyond its first {} mm",
            POOL_REACH_MM + 6.0
        );
    }

    /// A random CT and lumen (widths not a multiple of a run, so runs end short).
    fn random_ct_and_lumen(seed: u64) -> (Volume<i16>, Volume<u8>) {
        let g = Geometry::new([45, 13, 9], [0.75, 0.75, 1.0], [0.0; 3]).unwrap();
        let mut rng = crate::rng::Rng::new(seed, 0);
        let n = g.len();
        // Some voxels exactly at the threshold the tests use (200).
        let hu = (0..n)
            .map(|i| {
                let v = rng.range(-1000.0, 1200.0) as i16;
                if i % 17 == 0 { 200 } else { v }
            })
            .collect();
        let lumen = (0..n).map(|_| (rng.uniform() < 0.3) as u8).collect();
        (
            Volume::from_vec(g.clone(), hu).unwrap(),
            Volume::from_vec(g, lumen).unwrap(),
        )
    }

    #[test]
    fn pool_seeds_are_every_voxel_of_their_definition() {
        for seed in 0..4 {
            let (ct, lumen) = random_ct_and_lumen(seed);
            let g = ct.geometry();
            // From the volume's first voxel along x to its last.
            let b = Bbox {
                lo: [0, 1, 0],
                hi: [44, 12, 8],
            };
            let bright = |i: usize| ct.data()[i] >= 200;
            let want: Vec<usize> = (0..g.len())
                .filter(|&i| {
                    let [x, y, z] = g.ijk(i);
                    (b.lo[0]..=b.hi[0]).contains(&x)
                        && (b.lo[1]..=b.hi[1]).contains(&y)
                        && (b.lo[2]..=b.hi[2]).contains(&z)
                        && lumen.data()[i] == 1
                        && bright(i)
                        && face_neighbours(g.dims, i)
                            .into_iter()
                            .flatten()
                            .any(|q| lumen.data()[q] == 0 && bright(q))
                })
                .collect();
            assert!(!want.is_empty());
            assert_eq!(pool_seeds(&lumen, &ct, &b, 200), want);
        }
    }

    #[test]
    fn fluid_cells_are_cells_all_fluid_and_halfway() {
        for seed in 0..4 {
            let (mut ct, _) = random_ct_and_lumen(seed);
            // Bright stretches, so that some cells are all fluid.
            for (i, v) in ct.data_mut().iter_mut().enumerate() {
                if (i / 7) % 3 != 0 {
                    *v = 600 + (*v).rem_euclid(300);
                }
            }
            // Odd widths to the volume's far faces: the last cell along each axis is clipped.
            let b = Bbox {
                lo: [0, 2, 0],
                hi: [44, 12, 8],
            };
            let w = b.widths();
            let cores = Cores {
                body: Vec::new(),
                lo: b.lo,
                cell: [2, 2, 2],
                cells: [0, 1, 2].map(|a| w[a].div_ceil(2)),
            };
            let got = cores.fluid_cells(&ct, 200);
            let [cx, cy, _] = cores.cells;
            let want: Vec<u8> = (0..got.len())
                .map(|c| {
                    let at = [c % cx, (c / cx) % cy, c / (cx * cy)];
                    let lo = [0, 1, 2].map(|a| b.lo[a] + 2 * at[a]);
                    let hi = [0, 1, 2].map(|a| (lo[a] + 2).min(ct.dims()[a]));
                    let values: Vec<i16> = (lo[2]..hi[2])
                        .flat_map(|k| {
                            (lo[1]..hi[1]).flat_map(move |j| (lo[0]..hi[0]).map(move |i| [i, j, k]))
                        })
                        .map(|[i, j, k]| ct.get(i, j, k))
                        .collect();
                    let (min, max) = (values.iter().min().unwrap(), values.iter().max().unwrap());
                    (*min >= 200 && 2 * *min as i32 >= *max as i32 + TISSUE_HU as i32) as u8
                })
                .collect();
            assert!(want.contains(&1) && want.contains(&0));
            assert_eq!(got, want);
        }
    }
}
