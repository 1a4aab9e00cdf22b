//! The axis of a tube (pipe or colon): a smooth curve through hand-placed knots, resampled
//! to a dense polyline with uniform arc-length steps, with a nominal radius and a
//! rotation-minimising frame at every vertex.
//!
//! The same polyline is both what the phantom is built around and the ground-truth
//! centerline, so the truth is exact by construction.

use glam::DVec3;

use voyage_core::{Error, Result};

/// A control point of the axis, with the nominal lumen radius there.
#[derive(Clone, Copy, Debug)]
pub struct Knot {
    pub pos: DVec3,
    pub radius: f64,
}

/// Dense polyline with arc length, radius and frame per vertex.
#[derive(Clone, Debug)]
pub struct Axis {
    pub points: Vec<DVec3>,
    pub arc: Vec<f64>,
    pub radius: Vec<f64>,
    pub tangent: Vec<DVec3>,
    /// Rotation-minimising (parallel-transported) frame: `normal`, `binormal` ⟂ `tangent`.
    pub normal: Vec<DVec3>,
    pub binormal: Vec<DVec3>,
    /// Arc length at each knot.
    pub knot_arc: Vec<f64>,
    pub length: f64,
    /// Arc length at the dense spline samples, [`SPAN_SAMPLES`] per knot span: the map
    /// between arc and the spline's parameter (knot index and fraction), which two shapes of
    /// one colon through the same knots share.
    span_arc: Vec<f64>,
}

/// Dense samples per knot span before resampling.
const SPAN_SAMPLES: usize = 256;

impl Axis {
    /// Builds the axis through `knots` (centripetal Catmull–Rom, so there are no cusps or
    /// self-loops inside a span), resampled every `max_step` mm or a little less.
    pub fn through(knots: &[Knot], max_step: f64) -> Result<Axis> {
        if knots.len() < 2 {
            return Err(Error::invalid("an axis needs at least two knots"));
        }
        if !(max_step > 0.0 && max_step.is_finite()) {
            return Err(Error::invalid(format!(
                "axis step {max_step} mm is not positive"
            )));
        }
        let (dense, dense_arc, knot_arc) = sample_spline(knots);
        let length = *dense_arc.last().unwrap_or(&0.0);
        if length <= max_step {
            return Err(Error::invalid("axis is shorter than one step"));
        }
        let n = (length / max_step).ceil() as usize;
        let step = length / n as f64;
        let mut points = Vec::with_capacity(n + 1);
        let mut arc = Vec::with_capacity(n + 1);
        let mut cursor = 0usize;
        for v in 0..=n {
            let s = (v as f64 * step).min(length);
            while cursor + 2 < dense_arc.len() && dense_arc[cursor + 1] < s {
                cursor += 1;
            }
            let (s0, s1) = (dense_arc[cursor], dense_arc[cursor + 1]);
            let t = if s1 > s0 {
                ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            points.push(dense[cursor].lerp(dense[cursor + 1], t));
            arc.push(s);
        }
        let radius = arc
            .iter()
            .map(|&s| knot_radius(knots, &knot_arc, s))
            .collect();
        let tangent = tangents(&points);
        let (normal, binormal) = rotation_minimising_frames(&points, &tangent);
        Ok(Axis {
            points,
            arc,
            radius,
            tangent,
            normal,
            binormal,
            knot_arc,
            length,
            span_arc: dense_arc,
        })
    }

    /// The spline's parameter at arc length `s`: knot index plus the fraction of the span.
    pub fn param_at(&self, s: f64) -> f64 {
        let a = &self.span_arc;
        let i = a.partition_point(|&x| x <= s).clamp(1, a.len() - 1);
        let (s0, s1) = (a[i - 1], a[i]);
        let t = if s1 > s0 {
            ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        ((i - 1) as f64 + t) / SPAN_SAMPLES as f64
    }

    /// Arc length at the spline's parameter `u` (see [`Axis::param_at`]).
    pub fn arc_at_param(&self, u: f64) -> f64 {
        let a = &self.span_arc;
        let x = (u * SPAN_SAMPLES as f64).clamp(0.0, (a.len() - 1) as f64);
        let i = (x.floor() as usize).min(a.len() - 2);
        a[i] + (a[i + 1] - a[i]) * (x - i as f64)
    }

    /// Arc length on `other` (the same knots moved) of the point at arc `s` here: the same
    /// place of the same colon in its other shape.
    pub fn arc_on(&self, other: &Axis, s: f64) -> f64 {
        other.arc_at_param(self.param_at(s))
    }

    /// Takes `reference`'s frames (the same knots, before they moved), each turned onto this
    /// axis's tangent at the same place: an angle around the tube then names the same side of
    /// it in the patient's frame in both shapes, where each shape's own rotation-minimising
    /// frame would have twisted differently along the way.
    pub fn reframe_like(&mut self, reference: &Axis) {
        for i in 0..self.len() {
            let at = reference.vertex_at(self.arc_on(reference, self.arc[i]));
            let t = self.tangent[i];
            let n = reference.normal[at];
            let n = (n - t * n.dot(t)).normalize_or(self.normal[i]);
            self.normal[i] = n;
            self.binormal[i] = t.cross(n);
        }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Vertex index at (or just before) arc length `s`.
    pub fn vertex_at(&self, s: f64) -> usize {
        let step = self.length / (self.len() - 1) as f64;
        ((s / step).floor().max(0.0) as usize).min(self.len() - 1)
    }

    /// Point on the axis at arc length `s` (linear between vertices).
    pub fn point_at(&self, s: f64) -> DVec3 {
        let (i, t) = self.locate(s);
        self.points[i].lerp(self.points[(i + 1).min(self.len() - 1)], t)
    }

    /// Nominal radius at arc length `s`.
    pub fn radius_at(&self, s: f64) -> f64 {
        let (i, t) = self.locate(s);
        let r1 = self.radius[(i + 1).min(self.len() - 1)];
        self.radius[i] + (r1 - self.radius[i]) * t
    }

    /// Unit vector from the axis at arc `s` towards the wall at frame angle `angle`.
    pub fn radial_at(&self, s: f64, angle: f64) -> DVec3 {
        let i = self.vertex_at(s);
        (self.normal[i] * angle.cos() + self.binormal[i] * angle.sin()).normalize_or_zero()
    }

    fn locate(&self, s: f64) -> (usize, f64) {
        let step = self.length / (self.len() - 1) as f64;
        let x = (s / step).clamp(0.0, (self.len() - 1) as f64);
        let i = (x.floor() as usize).min(self.len() - 2);
        (i, x - i as f64)
    }

    /// Smallest radius of curvature along the axis, each divided by the local radius:
    /// below about 1 the tube would fold into itself on the inside of the bend.
    pub fn min_bend_ratio(&self, extra_mm: f64) -> (f64, usize) {
        let mut worst = (f64::INFINITY, 0);
        // Curvature from the turn of the tangent over ±3 vertices: robust to tiny wiggles.
        let w = 3usize;
        for i in w..self.len().saturating_sub(w) {
            let turn = self.tangent[i - w].angle_between(self.tangent[i + w]);
            let ds = self.arc[i + w] - self.arc[i - w];
            let rho = if turn > 1e-9 {
                ds / turn
            } else {
                f64::INFINITY
            };
            let ratio = rho / (self.radius[i] + extra_mm);
            if ratio < worst.0 {
                worst = (ratio, i);
            }
        }
        worst
    }

    /// The smallest lumen-to-lumen distance (mm) between different parts of the tube: pairs
    /// of vertices further apart along the axis than half a turn of a bend that the tube
    /// could make (π·(r + extra)), so that only genuinely different parts are compared.
    /// Returns (gap, i, j).
    pub fn min_part_gap(&self, extra_mm: f64, stride: usize) -> (f64, usize, usize) {
        let stride = stride.max(1);
        let mut worst = (f64::INFINITY, 0, 0);
        for i in (0..self.len()).step_by(stride) {
            for j in (i..self.len()).step_by(stride) {
                let reach = std::f64::consts::PI * (self.radius[i].max(self.radius[j]) + extra_mm);
                if self.arc[j] - self.arc[i] <= reach {
                    continue;
                }
                let gap = self.points[i].distance(self.points[j]) - self.radius[i] - self.radius[j];
                if gap < worst.0 {
                    worst = (gap, i, j);
                }
            }
        }
        worst
    }
}

/// Centripetal Catmull–Rom through the knots, densely sampled: (points, arc, knot arcs).
fn sample_spline(knots: &[Knot]) -> (Vec<DVec3>, Vec<f64>, Vec<f64>) {
    let n = knots.len();
    let p = |i: isize| -> DVec3 {
        if i < 0 {
            2.0 * knots[0].pos - knots[1].pos
        } else if i as usize >= n {
            2.0 * knots[n - 1].pos - knots[n - 2].pos
        } else {
            knots[i as usize].pos
        }
    };
    let mut dense = vec![knots[0].pos];
    let mut arc = vec![0.0];
    let mut knot_arc = vec![0.0];
    for span in 0..n - 1 {
        let i = span as isize;
        let (p0, p1, p2, p3) = (p(i - 1), p(i), p(i + 1), p(i + 2));
        for k in 1..=SPAN_SAMPLES {
            let q = catmull_rom(p0, p1, p2, p3, k as f64 / SPAN_SAMPLES as f64);
            let last = *dense.last().unwrap_or(&q);
            arc.push(arc.last().copied().unwrap_or(0.0) + last.distance(q));
            dense.push(q);
        }
        knot_arc.push(*arc.last().unwrap_or(&0.0));
    }
    (dense, arc, knot_arc)
}

/// Centripetal (α = ½) Catmull–Rom between p1 and p2, u ∈ [0, 1] (Barry–Goldman form).
fn catmull_rom(p0: DVec3, p1: DVec3, p2: DVec3, p3: DVec3, u: f64) -> DVec3 {
    let knot = |a: DVec3, b: DVec3| a.distance(b).sqrt().max(1e-6);
    let t0 = 0.0;
    let t1 = t0 + knot(p0, p1);
    let t2 = t1 + knot(p1, p2);
    let t3 = t2 + knot(p2, p3);
    let t = t1 + (t2 - t1) * u;
    let a1 = p0 * ((t1 - t) / (t1 - t0)) + p1 * ((t - t0) / (t1 - t0));
    let a2 = p1 * ((t2 - t) / (t2 - t1)) + p2 * ((t - t1) / (t2 - t1));
    let a3 = p2 * ((t3 - t) / (t3 - t2)) + p3 * ((t - t2) / (t3 - t2));
    let b1 = a1 * ((t2 - t) / (t2 - t0)) + a2 * ((t - t0) / (t2 - t0));
    let b2 = a2 * ((t3 - t) / (t3 - t1)) + a3 * ((t - t1) / (t3 - t1));
    b1 * ((t2 - t) / (t2 - t1)) + b2 * ((t - t1) / (t2 - t1))
}

/// Radius at arc `s`: smoothstep between the knots' radii, so it varies smoothly (C¹).
fn knot_radius(knots: &[Knot], knot_arc: &[f64], s: f64) -> f64 {
    let k = knot_arc
        .partition_point(|&a| a <= s)
        .clamp(1, knots.len() - 1);
    let (s0, s1) = (knot_arc[k - 1], knot_arc[k]);
    let t = if s1 > s0 {
        ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let t = t * t * (3.0 - 2.0 * t);
    knots[k - 1].radius + (knots[k].radius - knots[k - 1].radius) * t
}

fn tangents(points: &[DVec3]) -> Vec<DVec3> {
    let n = points.len();
    (0..n)
        .map(|i| {
            let a = points[i.saturating_sub(1)];
            let b = points[(i + 1).min(n - 1)];
            (b - a).normalize_or(DVec3::Z)
        })
        .collect()
}

/// Parallel transport by double reflection (Wang et al., "Computation of rotation
/// minimizing frames", ACM TOG 2008): the frame does not spin about the axis, so an angle
/// around the tube (used for the folds' crescents) means the same thing all along it.
fn rotation_minimising_frames(points: &[DVec3], tangent: &[DVec3]) -> (Vec<DVec3>, Vec<DVec3>) {
    let n = points.len();
    let t0 = tangent[0];
    let helper = if t0.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let mut r = (helper - t0 * helper.dot(t0)).normalize_or(DVec3::Y);
    let mut normal = Vec::with_capacity(n);
    normal.push(r);
    for i in 0..n - 1 {
        let v1 = points[i + 1] - points[i];
        let c1 = v1.dot(v1);
        if c1 < 1e-18 {
            normal.push(r);
            continue;
        }
        let r_l = r - v1 * (2.0 / c1 * v1.dot(r));
        let t_l = tangent[i] - v1 * (2.0 / c1 * v1.dot(tangent[i]));
        let v2 = tangent[i + 1] - t_l;
        let c2 = v2.dot(v2);
        let next = if c2 < 1e-18 {
            r_l
        } else {
            r_l - v2 * (2.0 / c2 * v2.dot(r_l))
        };
        // Re-orthogonalise against rounding drift.
        let t = tangent[i + 1];
        r = (next - t * next.dot(t)).normalize_or(r);
        normal.push(r);
    }
    let binormal = tangent
        .iter()
        .zip(&normal)
        .map(|(t, n)| t.cross(*n))
        .collect();
    (normal, binormal)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_axis_has_exact_length_and_orthonormal_frames() {
        let knots = [
            Knot {
                pos: DVec3::ZERO,
                radius: 5.0,
            },
            Knot {
                pos: DVec3::new(0.0, 0.0, 50.0),
                radius: 10.0,
            },
            Knot {
                pos: DVec3::new(0.0, 0.0, 100.0),
                radius: 5.0,
            },
        ];
        let a = Axis::through(&knots, 1.0).unwrap();
        assert!((a.length - 100.0).abs() < 1e-6);
        assert_eq!(a.len(), 101);
        assert!((a.radius_at(50.0) - 10.0).abs() < 1e-9);
        for i in 0..a.len() {
            assert!(a.tangent[i].dot(a.normal[i]).abs() < 1e-9);
            assert!((a.binormal[i].length() - 1.0).abs() < 1e-9);
        }
    }
}
