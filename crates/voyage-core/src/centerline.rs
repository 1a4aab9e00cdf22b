//! The centerline (paper §4.2): a path from source to target that keeps to the middle of the
//! lumen (its voxels come from the minimum-cost tree with voxel cost Dmax − Ds), then centred,
//! smoothed and resampled every millimetre. Every point stays inside the lumen. The path is
//! not the minimum-cost path itself but the longest simple path through the lumen's skeleton
//! graph ([`crate::skeleton`]): in real scans loops of the colon touch, and the minimum-cost
//! path would cut through the contacts.

use glam::DVec3;
use serde::Serialize;

use crate::{
    Result, Volume,
    distance::geodesic::Padded,
    field::Field,
    skeleton::{SkeletonOptions, colon_path, tree_search},
};

#[derive(Clone, Debug, Serialize)]
pub struct Centerline {
    /// Points in volume-local mm, source → target, about `step_mm` apart.
    pub points_mm: Vec<[f64; 3]>,
    /// Arc length from the source at each point (mm).
    pub arc_mm: Vec<f64>,
    /// Ds at each point: the local lumen radius (mm).
    pub radius_mm: Vec<f64>,
    pub length_mm: f64,
}

#[derive(Clone, Debug)]
pub struct CenterlineOptions {
    /// Spacing of the output points (mm).
    pub step_mm: f64,
    /// Half-width of the smoothing window (mm).
    pub smooth_mm: f64,
    /// Centring iterations (each moves points up the Ds ridge across the path).
    pub centre_iterations: usize,
    /// The skeleton search runs on 2×2×2 blocks when the finest spacing is below this (mm)
    /// and the lumen has more voxels than `coarse_above_voxels`.
    pub coarse_below_mm: f64,
    pub coarse_above_voxels: usize,
    /// The cost weight's power p and scale K (see [`cost_weight`]).
    pub penalty_power: u32,
    pub penalty_scale: f64,
    /// The skeleton graph the path is chosen from (see [`crate::skeleton`]).
    pub skeleton: SkeletonOptions,
}

impl Default for CenterlineOptions {
    fn default() -> Self {
        CenterlineOptions {
            step_mm: 1.0,
            smooth_mm: 4.0,
            centre_iterations: 12,
            coarse_below_mm: 1.0,
            coarse_above_voxels: 1_000_000,
            penalty_power: 16,
            penalty_scale: 5000.0,
            skeleton: SkeletonOptions::default(),
        }
    }
}

/// The centerline from `source` to `target` (volume voxels in the lumen): the longest simple
/// path between them through the skeleton graph, centred and smoothed.
pub fn centerline(
    mask: &Volume<u8>,
    ds: &Field<f32>,
    source: [usize; 3],
    target: [usize; 3],
    opts: &CenterlineOptions,
) -> Result<Centerline> {
    let pad = Padded::new(mask, &ds.grid);
    let ds_pad = pad.pad(&ds.data, 0.0);
    let weight = cost_weight(&ds_pad, opts);
    let src = pad.lumen_index(source)?;
    let dst = pad.lumen_index(target)?;
    let tree = tree_search(&pad, &[src], mask.spacing(), Some(&weight), None);
    let (path, _) = colon_path(
        &pad,
        &tree,
        &ds_pad,
        mask.spacing(),
        src,
        Some(dst),
        &opts.skeleton,
    )?;
    let voxels: Vec<[usize; 3]> = path.iter().map(|&i| pad.global_of_index(i)).collect();
    Ok(refine(&voxels, mask, ds, opts))
}

/// Centres, smooths and resamples a voxel path from source to target.
pub fn refine(
    voxels: &[[usize; 3]],
    mask: &Volume<u8>,
    ds: &Field<f32>,
    opts: &CenterlineOptions,
) -> Centerline {
    let sp = mask.geometry().spacing_vec();
    let raw: Vec<DVec3> = voxels
        .iter()
        .map(|v| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64) * sp)
        .collect();
    refine_points(raw, ds, opts)
}

/// [`refine`] of a path given in volume-local mm (each point at a lumen voxel's centre).
pub fn refine_points(raw: Vec<DVec3>, ds: &Field<f32>, opts: &CenterlineOptions) -> Centerline {
    let mut pts = resample(&raw, opts.step_mm);
    for _ in 0..opts.centre_iterations {
        pts = centre(&pts, ds);
        pts = smooth(&pts, (opts.smooth_mm / opts.step_mm).round() as usize, ds);
        pts = resample(&pts, opts.step_mm);
    }
    finish(pts, ds)
}

/// Paper §4.2's voxel cost Dmax − Ds, normalised by Dmax and raised to a power, as a weight
/// per mm: w = 1 + K·((Dmax − Ds)/Dmax)^p (padded layout). With p = 1 this is the paper's
/// cost plus the length; a high power (Bitter et al. 2001 use 16) makes narrow places so dear
/// that the path never takes a short cut where two loops of the colon touch, as they do in
/// real scans, while in the middle of the lumen it is nearly the plain length. `ds_pad`: Ds
/// in the padded layout.
pub fn cost_weight(ds_pad: &[f32], opts: &CenterlineOptions) -> Vec<f32> {
    let dmax = ds_pad.iter().cloned().fold(0.0f32, f32::max).max(1e-3);
    let k = opts.penalty_scale as f32;
    let p = opts.penalty_power;
    // Walls (Ds 0) all weigh 1 + K; only the lumen's voxels need the power.
    let weight = |d: f32| {
        if d == 0.0 {
            1.0 + k
        } else {
            1.0 + k * power(((dmax - d) / dmax).max(0.0), p)
        }
    };
    crate::mem::collect(ds_pad.len(), ds_pad.iter().map(|&d| weight(d)))
}

/// `x` to the power `n` by squaring, as `f32::powi` computes it (the same products in the same
/// order, so the same result), without its call into the runtime library for every voxel.
#[inline]
fn power(mut x: f32, mut n: u32) -> f32 {
    let mut out = 1.0f32;
    loop {
        if n & 1 != 0 {
            out *= x;
        }
        n >>= 1;
        if n == 0 {
            return out;
        }
        x *= x;
    }
}

/// Points every `step` mm along the polyline (first and last kept).
fn resample(pts: &[DVec3], step: f64) -> Vec<DVec3> {
    if pts.len() < 2 {
        return pts.to_vec();
    }
    let mut out = vec![pts[0]];
    let mut carried = 0.0;
    for w in pts.windows(2) {
        let seg = w[1] - w[0];
        let len = seg.length();
        if len == 0.0 {
            continue;
        }
        let mut t = step - carried;
        while t <= len {
            out.push(w[0] + seg * (t / len));
            t += step;
        }
        carried = len - (t - step);
    }
    if out
        .last()
        .is_some_and(|l| l.distance(pts[pts.len() - 1]) > 1e-9)
    {
        out.push(pts[pts.len() - 1]);
    }
    out
}

/// Moves each inner point up the gradient of Ds, across the path only (along-path motion
/// would bunch the points), by at most a millimetre.
fn centre(pts: &[DVec3], ds: &Field<f32>) -> Vec<DVec3> {
    let h = 0.5;
    let mut out = pts.to_vec();
    for i in 1..pts.len().saturating_sub(1) {
        let t = (pts[i + 1] - pts[i - 1]).normalize_or_zero();
        let p = pts[i];
        let grad = DVec3::new(
            ds.sample(p + DVec3::X * h, 0.0) as f64 - ds.sample(p - DVec3::X * h, 0.0) as f64,
            ds.sample(p + DVec3::Y * h, 0.0) as f64 - ds.sample(p - DVec3::Y * h, 0.0) as f64,
            ds.sample(p + DVec3::Z * h, 0.0) as f64 - ds.sample(p - DVec3::Z * h, 0.0) as f64,
        ) / (2.0 * h);
        let across = (grad - t * grad.dot(t)).normalize_or_zero();
        // Up to 1 mm across the path, halving until Ds grows (a line search on the ridge).
        let here = ds.sample(p, 0.0);
        let mut len = 1.0;
        while len > 0.1 {
            let q = p + across * len;
            if ds.sample(q, 0.0) > here {
                out[i] = q;
                break;
            }
            len *= 0.5;
        }
    }
    out
}

/// Moving average over ±`half` points, ends fixed; a point whose average would leave the
/// lumen (Ds below half its own) keeps its place.
fn smooth(pts: &[DVec3], half: usize, ds: &Field<f32>) -> Vec<DVec3> {
    let n = pts.len();
    let mut out = pts.to_vec();
    for i in 1..n.saturating_sub(1) {
        let w = half.min(i).min(n - 1 - i);
        let sum: DVec3 = pts[i - w..=i + w].iter().copied().sum();
        let q = sum / (2 * w + 1) as f64;
        if ds.sample(q, 0.0) >= 0.5 * ds.sample(pts[i], 0.0) {
            out[i] = q;
        }
    }
    out
}

fn finish(pts: Vec<DVec3>, ds: &Field<f32>) -> Centerline {
    let arc = arc_lengths(&pts);
    let length_mm = arc.last().copied().unwrap_or(0.0);
    let radius = pts.iter().map(|&p| ds.sample(p, 0.0) as f64).collect();
    Centerline {
        points_mm: pts.iter().map(|p| p.to_array()).collect(),
        arc_mm: arc,
        radius_mm: radius,
        length_mm,
    }
}

/// The length along a polyline from its first point to each point, mm.
pub(crate) fn arc_lengths(pts: &[DVec3]) -> Vec<f64> {
    let mut arc = Vec::with_capacity(pts.len());
    let mut s = 0.0;
    for (i, p) in pts.iter().enumerate() {
        if i > 0 {
            s += p.distance(pts[i - 1]);
        }
        arc.push(s);
    }
    arc
}

#[cfg(test)]
mod tests {
    #[test]
    fn power_by_squaring_is_powi() {
        for n in [0u32, 1, 2, 3, 7, 16, 17] {
            for x in [0.0f32, 0.1, 0.37, 0.5, 0.93, 0.999, 1.0] {
                assert_eq!(
                    super::power(x, n).to_bits(),
                    x.powi(n as i32).to_bits(),
                    "{x}^{n}"
                );
            }
        }
    }

    use super::*;
    use crate::{Geometry, distance::distance_to_wall};

    /// A torus-like bent tube (a half ring of radius 30 mm, tube radius 6 mm).
    fn bent_tube() -> (Volume<u8>, DVec3, f64) {
        let g = Geometry::new([90, 50, 20], [0.8, 0.8, 1.0], [0.0; 3]).unwrap();
        let c = DVec3::new(36.0, 4.0, 10.0);
        let data = (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                let p = DVec3::new(i as f64 * 0.8, j as f64 * 0.8, k as f64);
                let d = p - c;
                let ring = (d.x * d.x + d.y * d.y).sqrt();
                (d.y >= 0.0 && ((ring - 30.0).powi(2) + d.z * d.z).sqrt() < 6.0) as u8
            })
            .collect();
        (Volume::from_vec(g, data).unwrap(), c, 30.0)
    }

    #[test]
    fn follows_the_middle_of_a_bent_tube() {
        let (m, c, r) = bent_tube();
        let ds = distance_to_wall(&m).unwrap();
        // Ends: the two open ends of the half ring at y ≈ 4 mm.
        let src = [((c.x - r) / 0.8).round() as usize, 6, 10];
        let dst = [((c.x + r) / 0.8).round() as usize, 6, 10];
        let cl = centerline(&m, &ds, src, dst, &CenterlineOptions::default()).unwrap();
        let mut err = 0.0;
        for p in &cl.points_mm {
            let p = DVec3::from_array(*p);
            let ijk = (p / m.geometry().spacing_vec()).round();
            assert_eq!(
                m.get(ijk.x as usize, ijk.y as usize, ijk.z as usize),
                1,
                "point {p} outside the lumen"
            );
            let d = p - c;
            err += (((d.x * d.x + d.y * d.y).sqrt() - r).powi(2) + d.z * d.z).sqrt();
        }
        let mean = err / cl.points_mm.len() as f64;
        assert!(mean < 1.0, "mean distance to the true axis {mean} mm");
        assert!(
            (cl.length_mm - std::f64::consts::PI * r).abs() < 8.0,
            "length {}",
            cl.length_mm
        );
        assert!(cl.arc_mm.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn unreachable_target_is_an_error() {
        let g = Geometry::new([20, 5, 5], [1.0; 3], [0.0; 3]).unwrap();
        let mut m = Volume::filled(g, 0u8).unwrap();
        for i in (1..8).chain(11..19) {
            m.set(i, 2, 2, 1);
        }
        let ds = distance_to_wall(&m).unwrap();
        let e = centerline(
            &m,
            &ds,
            [1, 2, 2],
            [18, 2, 2],
            &CenterlineOptions::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("cannot be reached"), "{e}");
    }
}
