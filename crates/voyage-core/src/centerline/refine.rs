//! Refinement (paper §4.2): a raw voxel path from source to target centred on Ds's ridge,
//! smoothed and resampled every millimetre, every point inside the lumen; and the centring
//! cost the skeleton search uses (Dmax − Ds, normalised, raised to a power).

use glam::DVec3;
use serde::Serialize;

use super::CenterlineOptions;
#[cfg(test)]
use crate::Volume;
#[cfg(test)]
use crate::grid::Field;
use crate::grid::Sampled;

#[derive(Clone, Debug, Serialize)]
pub struct Centerline {
    /// Points in volume-local mm, source → target, about `step_mm` apart.
    pub points_mm: Vec<[f64; 3]>,
    /// Arc length from the source at each point (mm).
    pub arc_mm: Vec<f64>,
    /// Ds at each point: the local lumen radius (mm).
    pub radius_mm: Vec<f64>,
    pub length_mm: f64,
    /// Arc length (mm from the source) of a canal too narrow to fly that the centerline runs
    /// down to the colon's lowest gas (the anal canal held open round a catheter): flights
    /// start and end above it. 0 when there is none.
    pub canal_mm: f64,
}

/// Centres, smooths and resamples a voxel path from source to target.
#[cfg(test)]
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
pub fn refine_points(raw: Vec<DVec3>, ds: &impl Sampled, opts: &CenterlineOptions) -> Centerline {
    let mut pts = resample(&raw, opts.step_mm);
    for _ in 0..opts.centre_iterations {
        pts = centre(&pts, ds);
        pts = smooth(&pts, opts.smooth_mm, opts.step_mm, ds);
        pts = resample(&pts, opts.step_mm);
    }
    finish(pts, ds)
}

/// Paper §4.2's voxel cost Dmax − Ds, normalised by Dmax and raised to a power, as a weight
/// per mm: w = 1 + K·((Dmax − Ds)/Dmax)^p (padded layout). With p = 1 this is the paper's
/// cost plus the length; a high power (Bitter et al. 2001 use 16) makes narrow places so dear
/// that the path never takes a short cut where two loops of the colon touch, as they do in
/// real scans, while in the middle of the lumen it is nearly the plain length. `ds_pad`: Ds
/// in the padded layout. Written in the memory of `reuse` where it is large enough.
pub(crate) fn cost_weight_in(
    ds_pad: &[f32],
    opts: &CenterlineOptions,
    reuse: Vec<f32>,
) -> Vec<f32> {
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
    crate::mem::collect_in(reuse, ds_pad.len(), ds_pad.iter().map(|&d| weight(d)))
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
fn centre(pts: &[DVec3], ds: &impl Sampled) -> Vec<DVec3> {
    let h = 0.5;
    let mut out = pts.to_vec();
    for i in 1..pts.len().saturating_sub(1) {
        let t = (pts[i + 1] - pts[i - 1]).normalize_or_zero();
        let p = pts[i];
        let grad = DVec3::new(
            ds.sample_mm(p + DVec3::X * h) as f64 - ds.sample_mm(p - DVec3::X * h) as f64,
            ds.sample_mm(p + DVec3::Y * h) as f64 - ds.sample_mm(p - DVec3::Y * h) as f64,
            ds.sample_mm(p + DVec3::Z * h) as f64 - ds.sample_mm(p - DVec3::Z * h) as f64,
        ) / (2.0 * h);
        let across = (grad - t * grad.dot(t)).normalize_or_zero();
        // Up to 1 mm across the path, halving until Ds grows (a line search on the ridge).
        let here = ds.sample_mm(p);
        let mut len = 1.0;
        while len > 0.1 {
            let q = p + across * len;
            if ds.sample_mm(q) > here {
                out[i] = q;
                break;
            }
            len *= 0.5;
        }
    }
    out
}

/// In a wide lumen the smoothing window grows by this fraction of the radius beyond
/// [`SMOOTH_FROM_MM`]: Ds's ridge runs from haustrum to haustrum there, and a window of a few
/// millimetres kept its zigzag (on `ctc/prone-tagged`, whose right colon is 100 mm across,
/// 5% of the length). A colon of ordinary width keeps the plain window.
const SMOOTH_PER_RADIUS: f64 = 0.5;
const SMOOTH_FROM_MM: f64 = 12.0;

/// Moving average over ±`smooth_mm` (more in a wide lumen: [`SMOOTH_PER_RADIUS`]) of points
/// `step_mm` apart, ends fixed; a point whose average would leave the lumen (Ds below half
/// its own) keeps its place.
fn smooth(pts: &[DVec3], smooth_mm: f64, step_mm: f64, ds: &impl Sampled) -> Vec<DVec3> {
    let n = pts.len();
    let mut out = pts.to_vec();
    for i in 1..n.saturating_sub(1) {
        let here = ds.sample_mm(pts[i]);
        let wide = SMOOTH_PER_RADIUS * (here as f64 - SMOOTH_FROM_MM).max(0.0);
        let half = ((smooth_mm + wide) / step_mm).round() as usize;
        let w = half.min(i).min(n - 1 - i);
        let sum: DVec3 = pts[i - w..=i + w].iter().copied().sum();
        let q = sum / (2 * w + 1) as f64;
        if ds.sample_mm(q) >= 0.5 * here {
            out[i] = q;
        }
    }
    out
}

fn finish(pts: Vec<DVec3>, ds: &impl Sampled) -> Centerline {
    let arc = arc_lengths(&pts);
    let length_mm = arc.last().copied().unwrap_or(0.0);
    let radius = pts.iter().map(|&p| ds.sample_mm(p) as f64).collect();
    Centerline {
        points_mm: pts.iter().map(|p| p.to_array()).collect(),
        arc_mm: arc,
        radius_mm: radius,
        length_mm,
        canal_mm: 0.0,
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
}
