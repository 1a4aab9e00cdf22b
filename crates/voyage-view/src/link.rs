//! Supine and prone linked: where each place along one position's colon lies along the
//! other's, and where a point on one's wall lies on the other's.
//!
//! Between the two scans the colon moves (the transverse colon and the sigmoid by
//! centimetres), its fluid moves, and stretches collapse or open; the colon's order from the
//! rectum does not change. So the link is a monotone correspondence of the two centerlines
//! ([`Link`]), made by dynamic time warping of their profiles sampled every [`STEP_MM`]: the
//! place in the patient's frame (after a rigid fit of one colon onto the other), the way
//! on, the lumen's radius and the share of the length from the rectum. The ends (rectum,
//! cecum) and the flexures, the highest point of the colon on either side, anchor it: the
//! warp runs between them piece by piece. A stretch collapsed or under fluid in one position
//! has a centerline too (bridged), so it maps through the other's open lumen.
//!
//! A point on the wall maps by its place along the colon and its side round it
//! ([`Link::show_in`]): the arc through the link, the direction from the centerline turned
//! with the colon there, the depth under the wall kept.

use glam::{DQuat, DVec3};

use voyage_core::{Centerline, Study};

/// The profiles are sampled this often along each centerline (mm).
pub const STEP_MM: f64 = 2.0;

/// A profile point's place weighs one unit per this many mm of distance.
const PLACE_SCALE_MM: f64 = 10.0;
/// The share of the length from the rectum weighs one unit per this many mm of difference.
const SHARE_SCALE_MM: f64 = 60.0;
/// The lumen's radius weighs one unit per this many mm of difference, at most one unit: a
/// collapsed or distended stretch is still the same place.
const RADIUS_SCALE_MM: f64 = 8.0;
/// Weight of the way on (1 − cos of the angle between the two tangents).
const TANGENT_WEIGHT: f64 = 1.5;
/// Cost of a step that stays on one centerline while the other moves on (a stretch longer in
/// one position), per step.
const STRETCH_COST: f64 = 0.15;

/// A flexure is an anchor only where the two positions put it within this share of their
/// lengths of each other; elsewhere the warp runs past it unanchored.
const FLEXURE_AGREEMENT: f64 = 0.12;

/// One position's centerline, sampled for the warp.
#[derive(Clone, Debug)]
struct Profile {
    arc: Vec<f64>,
    /// Patient LPS mm.
    place: Vec<DVec3>,
    /// Unit, in LPS.
    tangent: Vec<DVec3>,
    radius: Vec<f64>,
    length: f64,
}

impl Profile {
    fn of(study: &Study) -> Profile {
        let cl = &study.centerline;
        let g = study.ct.geometry();
        let length = cl.length_mm.max(cl.arc_mm.last().copied().unwrap_or(0.0));
        let n = (length / STEP_MM).floor() as usize + 1;
        let arc: Vec<f64> = (0..n).map(|k| (k as f64 * STEP_MM).min(length)).collect();
        let at = |s: f64| {
            let (p, r) = on_centerline(cl, s);
            (g.local_to_patient(p), r)
        };
        let (place, radius): (Vec<DVec3>, Vec<f64>) = arc.iter().map(|&s| at(s)).unzip();
        let tangent = (0..n)
            .map(|k| {
                // Over ±10 mm: the way on, not the centring's wiggles.
                let span = (10.0 / STEP_MM).round() as usize;
                let (a, b) = (k.saturating_sub(span), (k + span).min(n - 1));
                (place[b] - place[a]).normalize_or(DVec3::Z)
            })
            .collect();
        Profile {
            arc,
            place,
            tangent,
            radius,
            length,
        }
    }

    fn len(&self) -> usize {
        self.arc.len()
    }

    /// The sample nearest arc `s`.
    fn index_at(&self, s: f64) -> usize {
        ((s / STEP_MM).round().max(0.0) as usize).min(self.len() - 1)
    }

    /// The splenic and hepatic flexures: the highest point (most superior) on the patient's
    /// left and on the right of the colon's middle, as samples, when the splenic comes first.
    fn flexures(&self) -> Option<(usize, usize)> {
        let (lo, hi) = self
            .place
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.x), hi.max(p.x))
            });
        let middle = 0.5 * (lo + hi);
        // LPS: +x is the patient's left, +z superior. The rectum's first stretch is never a
        // flexure.
        let skip = self.index_at(self.length * 0.15);
        let highest = |left: bool| {
            (skip..self.len())
                .filter(|&k| (self.place[k].x > middle) == left)
                .max_by(|&a, &b| self.place[a].z.total_cmp(&self.place[b].z))
        };
        let (splenic, hepatic) = (highest(true)?, highest(false)?);
        (splenic < hepatic).then_some((splenic, hepatic))
    }
}

/// The correspondence of two positions' centerlines: `a_arc[k]` on the first is the place
/// `b_arc[k]` on the second. Both increase.
#[derive(Clone, Debug)]
pub struct Link {
    a_arc: Vec<f64>,
    b_arc: Vec<f64>,
    /// Whether the flexures anchored the warp (else it ran from end to end alone).
    pub anchored: bool,
    /// Mean distance (mm) between linked places after the rigid fit: how far the colon
    /// moved beyond the patient's own shift, on average.
    pub mean_moved_mm: f64,
}

impl Link {
    /// Links the centerlines of `a` and `b` (two positions of one exam).
    pub fn between(a: &Study, b: &Study) -> Link {
        let (pa, pb) = (Profile::of(a), Profile::of(b));
        // A first fit by the centroids, then the rigid fit of what the warp matched, twice.
        let mut fit = Rigid::centroids(&pa.place, &pb.place);
        let pieces = anchors(&pa, &pb);
        let anchored = pieces.len() > 2;
        let mut path = Vec::new();
        for _ in 0..3 {
            path = warp(&pa, &pb, &fit, &pieces);
            let (x, y): (Vec<DVec3>, Vec<DVec3>) = path
                .iter()
                .map(|&(i, j)| (pa.place[i], pb.place[j]))
                .unzip();
            fit = Rigid::fit(&x, &y);
        }
        let mean_moved_mm = if path.is_empty() {
            0.0
        } else {
            path.iter()
                .map(|&(i, j)| pa.place[i].distance(fit.apply(pb.place[j])))
                .sum::<f64>()
                / path.len() as f64
        };
        let (a_arc, b_arc) = monotone(&path, &pa, &pb);
        Link {
            a_arc,
            b_arc,
            anchored,
            mean_moved_mm,
        }
    }

    /// The link the other way round.
    pub fn reversed(&self) -> Link {
        Link {
            a_arc: self.b_arc.clone(),
            b_arc: self.a_arc.clone(),
            ..*self
        }
    }

    /// The correspondence as it is kept: arcs on the first centerline and, at the same
    /// index, on the second (both increasing).
    pub fn arcs(&self) -> (&[f64], &[f64]) {
        (&self.a_arc, &self.b_arc)
    }

    /// The arc on the second centerline of the place at arc `s` on the first.
    pub fn map(&self, s: f64) -> f64 {
        interpolate(&self.a_arc, &self.b_arc, s)
    }

    /// Where the point `p` (local mm of `from`, in its lumen: a point on the wall moved
    /// [`voyage_core::OFF_WALL_MM`] along its normal) lies in `to` (local mm): its arc
    /// mapped, its direction from the centerline turned with the colon, its distance from the
    /// wall kept. None when `p` is near no part of the colon.
    pub fn show_in(&self, from: &Study, to: &Study, p: DVec3) -> Option<DVec3> {
        let s = from.arc_at(p)?;
        let (c_from, t_from) = centerline_at(from, s);
        let offset = p - c_from;
        // Along the way on only beyond the centerline's ends (a cecal pole, the rectum).
        let along = offset.dot(t_from);
        let radial = offset - t_from * along;
        let (c_to, t_to) = centerline_at(to, self.map(s));
        let base = c_to + t_to * along;
        // Directions compared in the patient's frame: both studies' axes run along L, P, S.
        let turn = DQuat::from_rotation_arc(t_from, t_to);
        let dir = (turn * radial).normalize_or_zero();
        if dir == DVec3::ZERO {
            return Some(base);
        }
        let depth =
            wall_along(from, c_from + t_from * along, radial.normalize_or_zero()) - radial.length();
        let wall = wall_along(to, base, dir);
        Some(base + dir * (wall - depth).clamp(0.0, wall))
    }
}

/// A rigid motion in LPS (rotation, then translation) that takes the second position's
/// places onto the first's.
#[derive(Clone, Copy, Debug)]
struct Rigid {
    rotation: DQuat,
    translation: DVec3,
}

impl Rigid {
    fn centroids(a: &[DVec3], b: &[DVec3]) -> Rigid {
        Rigid {
            rotation: DQuat::IDENTITY,
            translation: mean(a) - mean(b),
        }
    }

    /// The rotation and translation that best take `y` onto `x` (least squares, Horn's
    /// quaternion method).
    fn fit(x: &[DVec3], y: &[DVec3]) -> Rigid {
        let (mx, my) = (mean(x), mean(y));
        let mut s = [[0.0f64; 3]; 3];
        for (p, q) in x.iter().zip(y) {
            let (p, q) = ((*p - mx).to_array(), (*q - my).to_array());
            for r in 0..3 {
                for c in 0..3 {
                    s[r][c] += q[r] * p[c];
                }
            }
        }
        let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
        let n = [
            [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
            [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
            [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
            [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
        ];
        let q = largest_eigenvector(n);
        let rotation = DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize();
        let rotation = if rotation.is_finite() {
            rotation
        } else {
            DQuat::IDENTITY
        };
        Rigid {
            rotation,
            translation: mx - rotation * my,
        }
    }

    fn apply(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }
}

/// The eigenvector of the largest eigenvalue of a symmetric 4×4 matrix (power iteration on
/// the matrix shifted to be positive definite).
fn largest_eigenvector(n: [[f64; 4]; 4]) -> [f64; 4] {
    let shift: f64 = n
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let mut v = [1.0, 0.0, 0.0, 0.0];
    for _ in 0..200 {
        let mut w = [0.0; 4];
        for r in 0..4 {
            w[r] = shift * v[r] + (0..4).map(|c| n[r][c] * v[c]).sum::<f64>();
        }
        let norm = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm == 0.0 {
            return [1.0, 0.0, 0.0, 0.0];
        }
        v = w.map(|x| x / norm);
    }
    v
}

fn mean(p: &[DVec3]) -> DVec3 {
    p.iter().copied().sum::<DVec3>() / p.len().max(1) as f64
}

/// The pieces the warp runs between, as (sample on a, sample on b): the two ends, and the
/// flexures where both positions find them at about the same share of their length.
fn anchors(a: &Profile, b: &Profile) -> Vec<(usize, usize)> {
    let mut out = vec![(0, 0)];
    if let (Some((sa, ha)), Some((sb, hb))) = (a.flexures(), b.flexures()) {
        let share = |p: &Profile, k: usize| p.arc[k] / p.length.max(1.0);
        for (i, j) in [(sa, sb), (ha, hb)] {
            let last = out[out.len() - 1];
            if (share(a, i) - share(b, j)).abs() <= FLEXURE_AGREEMENT && i > last.0 && j > last.1 {
                out.push((i, j));
            }
        }
    }
    let end = (a.len() - 1, b.len() - 1);
    if out[out.len() - 1].0 < end.0 && out[out.len() - 1].1 < end.1 {
        out.push(end);
    } else {
        out.truncate(1);
        out.push(end);
    }
    out
}

/// The cheapest monotone path through the profiles' cost, piece by piece between anchors.
fn warp(a: &Profile, b: &Profile, fit: &Rigid, anchors: &[(usize, usize)]) -> Vec<(usize, usize)> {
    let mean_length = 0.5 * (a.length + b.length);
    let cost = |i: usize, j: usize| {
        let place = a.place[i].distance(fit.apply(b.place[j])) / PLACE_SCALE_MM;
        let share = (a.arc[i] / a.length.max(1.0) - b.arc[j] / b.length.max(1.0)).abs()
            * mean_length
            / SHARE_SCALE_MM;
        let radius = ((a.radius[i] - b.radius[j]).abs() / RADIUS_SCALE_MM).min(1.0);
        let turn = TANGENT_WEIGHT * (1.0 - a.tangent[i].dot(fit.rotation * b.tangent[j]));
        place + share + radius + turn
    };
    let mut path = vec![anchors[0]];
    for w in anchors.windows(2) {
        let piece = warp_piece(w[0], w[1], &cost);
        path.extend(piece.into_iter().skip(1));
    }
    path
}

/// Dynamic time warping from `from` to `to` (inclusive), steps (1,1), (1,0), (0,1).
fn warp_piece(
    from: (usize, usize),
    to: (usize, usize),
    cost: &impl Fn(usize, usize) -> f64,
) -> Vec<(usize, usize)> {
    let (n, m) = (to.0 - from.0 + 1, to.1 - from.1 + 1);
    let mut d = vec![f64::INFINITY; n * m];
    for i in 0..n {
        for j in 0..m {
            let c = cost(from.0 + i, from.1 + j);
            let before = if i == 0 && j == 0 {
                0.0
            } else {
                let diag = if i > 0 && j > 0 {
                    d[(i - 1) * m + j - 1]
                } else {
                    f64::INFINITY
                };
                let up = if i > 0 {
                    d[(i - 1) * m + j] + STRETCH_COST
                } else {
                    f64::INFINITY
                };
                let left = if j > 0 {
                    d[i * m + j - 1] + STRETCH_COST
                } else {
                    f64::INFINITY
                };
                diag.min(up).min(left)
            };
            d[i * m + j] = c + before;
        }
    }
    let (mut i, mut j) = (n - 1, m - 1);
    let mut path = vec![(from.0 + i, from.1 + j)];
    while i > 0 || j > 0 {
        let at = |i: usize, j: usize| d[i * m + j];
        let mut best = (f64::INFINITY, i, j);
        if i > 0 && j > 0 {
            best = (at(i - 1, j - 1), i - 1, j - 1);
        }
        if i > 0 && at(i - 1, j) + STRETCH_COST < best.0 {
            best = (at(i - 1, j) + STRETCH_COST, i - 1, j);
        }
        if j > 0 && at(i, j - 1) + STRETCH_COST < best.0 {
            best = (at(i, j - 1) + STRETCH_COST, i, j - 1);
        }
        (i, j) = (best.1, best.2);
        path.push((from.0 + i, from.1 + j));
    }
    path.reverse();
    path
}

/// The path as two strictly increasing arc lists. A run of steps along one centerline alone
/// (a stretch longer in one position) keeps its first point; the interpolation then spreads
/// the run over the step that leaves it.
fn monotone(path: &[(usize, usize)], a: &Profile, b: &Profile) -> (Vec<f64>, Vec<f64>) {
    let mut a_arc: Vec<f64> = Vec::new();
    let mut b_arc: Vec<f64> = Vec::new();
    for &(i, j) in path {
        let (sa, sb) = (a.arc[i], b.arc[j]);
        if a_arc.last().is_none_or(|&l| sa > l) && b_arc.last().is_none_or(|&l| sb > l) {
            a_arc.push(sa);
            b_arc.push(sb);
        }
    }
    // The ends are the ends.
    match (a_arc.last_mut(), b_arc.last_mut()) {
        (Some(la), Some(lb)) if *la < a.length && *lb < b.length => {
            a_arc.push(a.length);
            b_arc.push(b.length);
        }
        (Some(la), Some(lb)) => (*la, *lb) = (a.length.max(*la), b.length.max(*lb)),
        _ => {}
    }
    (a_arc, b_arc)
}

/// `ys` at `x` along increasing `xs`, linear between samples, held beyond the ends.
fn interpolate(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    match xs.len() {
        0 => x,
        1 => ys[0],
        _ => {
            let i = xs.partition_point(|&a| a <= x).clamp(1, xs.len() - 1);
            let (x0, x1) = (xs[i - 1], xs[i]);
            let t = if x1 > x0 {
                ((x - x0) / (x1 - x0)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            ys[i - 1] + (ys[i] - ys[i - 1]) * t
        }
    }
}

/// The centerline point (local mm) at arc `s` and the way on there (over ±5 mm).
pub fn centerline_at(study: &Study, s: f64) -> (DVec3, DVec3) {
    let point = |s: f64| on_centerline(&study.centerline, s).0;
    let c = point(s);
    let t = (point(s + 5.0) - point(s - 5.0)).normalize_or(DVec3::Z);
    (c, t)
}

/// The centerline's point (local mm) and radius at arc `s`, linear between its points.
fn on_centerline(cl: &Centerline, s: f64) -> (DVec3, f64) {
    if cl.points_mm.len() < 2 {
        let p = cl
            .points_mm
            .first()
            .map_or(DVec3::ZERO, |p| DVec3::from_array(*p));
        return (p, cl.radius_mm.first().copied().unwrap_or(0.0));
    }
    let i = cl
        .arc_mm
        .partition_point(|&a| a <= s)
        .clamp(1, cl.arc_mm.len().max(2) - 1);
    let (a0, a1) = (cl.arc_mm[i - 1], cl.arc_mm[i]);
    let t = if a1 > a0 {
        ((s - a0) / (a1 - a0)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let p = DVec3::from_array(cl.points_mm[i - 1]).lerp(DVec3::from_array(cl.points_mm[i]), t);
    (
        p,
        cl.radius_mm[i - 1] + (cl.radius_mm[i] - cl.radius_mm[i - 1]) * t,
    )
}

/// How far (mm) from `c` along the unit `dir` the lumen reaches (Ds falls to the wall), at
/// most 80 mm.
fn wall_along(study: &Study, c: DVec3, dir: DVec3) -> f64 {
    const STEP: f64 = 0.5;
    let mut d = 0.0;
    while d < 80.0 {
        if study.ds.sample(c + dir * (d + STEP)) <= 0.25 {
            return d;
        }
        d += STEP;
    }
    d
}
