//! Pools of tagged fluid in the dependent parts of the colon, each with a flat level.

use glam::DVec3;

use super::{
    anatomy::{segment, segment_name},
    options::ColonOptions,
    streams::{STREAM_POOLS, STREAM_VALVE_POOL},
    stretches::near_collapse,
};
use crate::{
    arr,
    rng::Rng,
    small_bowel::Valve,
    truth::{PoolTruth, SegmentTruth},
    tube::{Pool, Tube},
};

/// Segments where tagged fluid pools: the posterior, dependent ones for a supine patient,
/// and for a prone one the anterior ones (the sigmoid's and transverse colon's anterior
/// loops and the caecal pole), each of which is a local low point under gravity, so its pool
/// has a flat level and leaves gas above it.
const POOL_SEGMENTS: &[&str] = &["rectum", "descending", "ascending"];
const PRONE_POOL_SEGMENTS: &[&str] = &["sigmoid", "transverse", "cecum"];

/// Pools of tagged fluid in the dependent parts of some segments. Each pool sits at the
/// most dependent point of its segment (largest `p · gravity + radius`: posterior supine,
/// anterior prone); its level lies 30–50 % of the radius above the lumen's floor there,
/// and it extends along the colon as long as the lumen's floor is below the level — where
/// the colon rises above the level, the pool ends by itself, so the level is flat and the
/// fluid physically plausible.
///
/// With opacified small bowel a pool also fills the caecum's dependent side around the
/// ileocaecal valve, deep enough to cover the valve's opening (even without tagged fluid);
/// it comes first, and the usual pool of that part of the colon (ascending supine, caecum
/// prone), which it would overlap, is left out.
pub(super) fn make_pools(
    tube: &Tube,
    segments: &[SegmentTruth],
    opts: &ColonOptions,
    gravity: DVec3,
    valve: Option<&Valve>,
) -> Vec<(Pool, PoolTruth)> {
    let ax = &tube.axis;
    let floor = |i: usize| ax.points[i].dot(gravity) + ax.radius[i];
    let mut pools: Vec<(Pool, PoolTruth)> = Vec::new();
    if let Some(v) = valve {
        let mut rng = Rng::new(opts.seed, STREAM_VALVE_POOL);
        let depth = (rng.range(0.35, 0.5) * ax.radius[v.vertex]).max(v.min_depth);
        let hu = rng.range(400.0, 700.0);
        let name = segment_name(segments, ax.arc[v.vertex]);
        if let Some(p) = pool_from(tube, v.vertex, floor(v.vertex) - depth, gravity, hu, &name) {
            pools.push(p);
        }
    }
    if opts.tagged_fluid {
        let mut rng = Rng::new(opts.seed, STREAM_POOLS);
        for &name in if opts.prone {
            PRONE_POOL_SEGMENTS
        } else {
            POOL_SEGMENTS
        } {
            let Ok(seg) = segment(segments, name) else {
                continue;
            };
            let (a, b) = (ax.vertex_at(seg.start_arc_mm), ax.vertex_at(seg.end_arc_mm));
            let open = |i: &usize| !near_collapse(tube, ax.arc[*i], 0.0);
            let Some(anchor) = (a..=b)
                .filter(open)
                .max_by(|&i, &j| floor(i).total_cmp(&floor(j)))
            else {
                continue;
            };
            let depth = rng.range(0.3, 0.5) * ax.radius[anchor];
            let hu = rng.range(400.0, 700.0);
            let Some(p) = pool_from(tube, anchor, floor(anchor) - depth, gravity, hu, name) else {
                continue;
            };
            if pools
                .iter()
                .any(|(q, _)| p.0.start < q.end && p.0.end > q.start)
            {
                continue;
            }
            pools.push(p);
        }
    }
    pools.sort_by(|x, y| x.0.start.total_cmp(&y.0.start));
    pools
}

/// The pool with level `level` (along `gravity`) around axis vertex `anchor`: as far along
/// the colon both ways as the lumen's floor lies below the level, never across a collapsed
/// cord (the anchor's side is kept).
fn pool_from(
    tube: &Tube,
    anchor: usize,
    level: f64,
    gravity: DVec3,
    hu: f64,
    name: &str,
) -> Option<(Pool, PoolTruth)> {
    let ax = &tube.axis;
    let floor = |i: usize| ax.points[i].dot(gravity) + ax.radius[i];
    let mut lo = anchor;
    while lo > 0 && floor(lo - 1) > level {
        lo -= 1;
    }
    let mut hi = anchor;
    while hi + 1 < ax.len() && floor(hi + 1) > level {
        hi += 1;
    }
    let (mut start, mut end) = (ax.arc[lo] - ax.radius[lo], ax.arc[hi] + ax.radius[hi]);
    for c in &tube.collapse {
        if start < c.end + c.taper && end > c.start - c.taper {
            // Fluid does not cross the collapsed cord: keep the anchor's side.
            if ax.arc[anchor] < c.start {
                end = end.min(c.start - c.taper);
            } else {
                start = start.max(c.end + c.taper);
            }
        }
    }
    if start >= end {
        return None;
    }
    let pool = Pool {
        start,
        end,
        gravity,
        level,
        hu,
    };
    // The level is the plane y = level·g_y (gravity is ±y).
    let truth = PoolTruth {
        segment: name.into(),
        start_arc_mm: start,
        end_arc_mm: end,
        level_y_mm: level * gravity.y,
        gravity_lps: arr(gravity),
        hu,
    };
    Some((pool, truth))
}
