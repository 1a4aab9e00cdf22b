//! The continuous geometry of a tube phantom: a lumen around an [`Axis`] with a wall, folds,
//! collapsed stretches, fluid pools and stretches filled with fluid, plus "blobs" (polyps, gas
//! pockets, pieces of opacified small bowel, a rectal catheter).
//!
//! Everything is a signed distance in mm (negative inside), evaluated at voxel centres by
//! the rasteriser. The lumen is built from the *nearest* axis segment (not a union of
//! capsules), so that a fold — a local dent of the radius at one arc length — is not
//! filled in by the neighbouring segments.

use glam::DVec3;

use super::axis::Axis;

/// One haustral fold: three crescents between the three taeniae coli, each covering a
/// third of the circumference, each with its own depth and a small shift along the axis
/// (real folds are staggered, not full rings).
#[derive(Clone, Debug)]
pub struct Fold {
    /// Arc length (mm) of the fold plane.
    pub arc: f64,
    /// Angle (rad, in the axis frame) of the first taenia; crescents lie between taeniae.
    pub phase: f64,
    /// Half of the fold's thickness at its base, along the axis (mm).
    pub half_width: f64,
    pub sectors: [FoldSector; 3],
}

#[derive(Clone, Copy, Debug)]
pub struct FoldSector {
    /// Shift of this crescent along the axis (mm).
    pub offset: f64,
    /// How far the crescent's crest reaches in from the nominal wall (mm).
    pub depth: f64,
}

impl Fold {
    /// Arc range the fold touches.
    pub fn extent(&self) -> (f64, f64) {
        let lo = self
            .sectors
            .iter()
            .map(|s| s.offset)
            .fold(f64::INFINITY, f64::min);
        let hi = self
            .sectors
            .iter()
            .map(|s| s.offset)
            .fold(f64::NEG_INFINITY, f64::max);
        (
            self.arc + lo - self.half_width,
            self.arc + hi + self.half_width,
        )
    }

    /// Sector index (0..3) and position inside it (0..1) for frame angle `theta`.
    pub fn sector_of(&self, theta: f64) -> (usize, f64) {
        let third = std::f64::consts::TAU / 3.0;
        let psi = (theta - self.phase).rem_euclid(std::f64::consts::TAU);
        let k = ((psi / third) as usize).min(2);
        (k, (psi - k as f64 * third) / third)
    }

    /// Angle of the middle of sector `k` (where its crescent is deepest).
    pub fn sector_mid_angle(&self, k: usize) -> f64 {
        self.phase + (k as f64 + 0.5) * std::f64::consts::TAU / 3.0
    }

    /// Radius reduction at (arc `s`, angle `theta`) and its partial derivatives
    /// (∂/∂s, ∂/∂θ), for turning the radial distance into a true distance.
    ///
    /// Across the axis the crescent is `sin(π·x)` of the position x in its sector (zero at
    /// the taeniae); along the axis the profile is `(1 − u²)²`, u = distance to the fold
    /// plane over the half width: a thin ridge with a rounded crest.
    fn reduction(&self, s: f64, theta: f64) -> (f64, f64, f64) {
        let (k, x) = self.sector_of(theta);
        let sec = self.sectors[k];
        let u = (s - self.arc - sec.offset) / self.half_width;
        if u.abs() >= 1.0 {
            return (0.0, 0.0, 0.0);
        }
        let g = (1.0 - u * u) * (1.0 - u * u);
        let dg = -4.0 * u * (1.0 - u * u) / self.half_width;
        let pi = std::f64::consts::PI;
        let a = (pi * x).sin();
        let da = pi * (pi * x).cos() * 3.0 / std::f64::consts::TAU;
        (sec.depth * a * g, sec.depth * a * dg, sec.depth * da * g)
    }
}

/// A stretch where the bowel is collapsed: no gas, a cord of tissue; the lumen tapers to
/// nothing over `taper` mm on either side of [start, end].
#[derive(Clone, Debug)]
pub struct Collapse {
    pub start: f64,
    pub end: f64,
    pub taper: f64,
    /// Radius of the solid tissue cord left where the lumen is gone (two walls apposed).
    pub cord_radius: f64,
    /// A neck, not a collapse: the lumen keeps this radius (mm) through the stretch
    /// (0: no lumen at all).
    pub neck_radius: f64,
}

impl Collapse {
    /// Factor (0..1) on the radius: 0 inside, smoothly 1 beyond the tapers.
    fn factor(&self, s: f64) -> f64 {
        let x = if s < self.start {
            (self.start - s) / self.taper
        } else if s > self.end {
            (s - self.end) / self.taper
        } else {
            0.0
        };
        let x = x.clamp(0.0, 1.0);
        x * x * (3.0 - 2.0 * x)
    }
}

/// A pool of tagged fluid over an arc range: lumen content with `p · gravity > level` is
/// fluid. Gravity is a unit vector in volume-local mm: +y (posterior) for a supine patient,
/// −y for a prone one; the air–fluid level is the plane `p · gravity = level` (y = const for
/// both, since gravity is ±y).
#[derive(Clone, Debug)]
pub struct Pool {
    pub start: f64,
    pub end: f64,
    pub gravity: DVec3,
    pub level: f64,
    pub hu: f64,
}

/// A stretch of the lumen filled to the brim with tagged fluid (no gas at all between
/// `start` and `end`). Its ends are cut across the axis, with the usual one-voxel ramp.
#[derive(Clone, Debug)]
pub struct Filled {
    pub start: f64,
    pub end: f64,
    pub hu: f64,
}

/// How the axis ends: rounded (colon: rectum and the blind cecal pole) or flat (a capped
/// pipe).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Ends {
    Round,
    Flat,
}

/// The tube: axis + wall + folds + collapses + pools + filled stretches.
#[derive(Clone, Debug)]
pub struct Tube {
    pub axis: Axis,
    pub wall_mm: f64,
    pub ends: Ends,
    /// Flat ends only: the caps lie this far beyond the axis's end points, so that the
    /// centerline's first and last points are inside the lumen.
    pub end_margin: f64,
    pub folds: Vec<Fold>,
    /// Per segment (vertex i → i+1), the fold that can reach it, or `u32::MAX`.
    fold_at: Vec<u32>,
    /// Collapsed stretches, disjoint (their tapers included).
    pub collapse: Vec<Collapse>,
    pub pools: Vec<Pool>,
    /// Stretches filled with fluid, disjoint.
    pub filled: Vec<Filled>,
    /// Per segment: start point, direction (end − start) and 1 / |end − start|², for the
    /// nearest-segment search that dominates the rasterisation time.
    seg_a: Vec<DVec3>,
    seg_ab: Vec<DVec3>,
    seg_inv_len2: Vec<f64>,
}

/// What the tube looks like at one point.
#[derive(Clone, Copy, Debug)]
pub struct TubeHit {
    /// Signed distance to the lumen surface (mm, negative inside the lumen).
    pub lumen: f64,
    /// Signed distance to the wall's outer surface (negative inside wall or lumen).
    pub outer: f64,
    /// Signed distance to the air–fluid level (negative in the fluid), ∞ without a pool.
    pub fluid: f64,
    /// HU of that pool's fluid.
    pub fluid_hu: f64,
}

impl TubeHit {
    /// Deep inside the lumen, away from everything.
    pub const INSIDE: TubeHit = TubeHit {
        lumen: -1e3,
        outer: -1e3,
        fluid: f64::INFINITY,
        fluid_hu: 0.0,
    };
    pub const NONE: TubeHit = TubeHit {
        lumen: f64::INFINITY,
        outer: f64::INFINITY,
        fluid: f64::INFINITY,
        fluid_hu: 0.0,
    };
}

impl Tube {
    /// Whether the stretch of arc within `margin` mm of `s` misses every collapse (with its
    /// tapers): where something placed on the wall keeps clear of them.
    pub fn clear_of_collapses(&self, s: f64, margin: f64) -> bool {
        self.collapse
            .iter()
            .all(|c| s + margin < c.start - c.taper || s - margin > c.end + c.taper)
    }

    /// ... and every stretch filled with fluid.
    pub fn clear_of_stretches(&self, s: f64, margin: f64) -> bool {
        self.clear_of_collapses(s, margin)
            && self
                .filled
                .iter()
                .all(|f| s + margin < f.start || s - margin > f.end)
    }

    pub fn new(axis: Axis, wall_mm: f64, ends: Ends) -> Tube {
        let nseg = axis.len().saturating_sub(1);
        let seg_a: Vec<DVec3> = axis.points[..nseg].to_vec();
        let seg_ab: Vec<DVec3> = (0..nseg)
            .map(|i| axis.points[i + 1] - axis.points[i])
            .collect();
        let seg_inv_len2 = seg_ab
            .iter()
            .map(|ab| 1.0 / ab.length_squared().max(1e-18))
            .collect();
        Tube {
            axis,
            wall_mm,
            ends,
            end_margin: 0.0,
            folds: Vec::new(),
            fold_at: vec![u32::MAX; nseg],
            collapse: Vec::new(),
            pools: Vec::new(),
            filled: Vec::new(),
            seg_a,
            seg_ab,
            seg_inv_len2,
        }
    }

    pub fn segments(&self) -> usize {
        self.fold_at.len()
    }

    /// The same tube round `axis`, its knots moved: every place along it (fold, collapse,
    /// filled stretch) stays where it was on the colon, at the same spline parameter, not at
    /// the same arc length. Pools are left out: gravity makes them anew on the moved tube.
    pub fn moved_to(&self, axis: Axis) -> Tube {
        let at = |s: f64| self.axis.arc_on(&axis, s);
        let collapse = self
            .collapse
            .iter()
            .map(|c| Collapse {
                start: at(c.start),
                end: at(c.end),
                ..c.clone()
            })
            .collect();
        let filled = self
            .filled
            .iter()
            .map(|f| Filled {
                start: at(f.start),
                end: at(f.end),
                ..f.clone()
            })
            .collect();
        let folds = self
            .folds
            .iter()
            .map(|f| Fold {
                arc: at(f.arc),
                ..f.clone()
            })
            .collect();
        let mut moved = Tube::new(axis, self.wall_mm, self.ends);
        moved.end_margin = self.end_margin;
        moved.collapse = collapse;
        moved.filled = filled;
        moved.set_folds(folds);
        moved
    }

    /// Sets the folds and indexes which segments each can reach (folds must not overlap).
    pub fn set_folds(&mut self, folds: Vec<Fold>) {
        self.fold_at.iter_mut().for_each(|f| *f = u32::MAX);
        for (fi, f) in folds.iter().enumerate() {
            let (lo, hi) = f.extent();
            let a = self.axis.vertex_at(lo.max(0.0));
            let b = self
                .axis
                .vertex_at(hi.max(0.0))
                .min(self.segments().saturating_sub(1));
            for slot in &mut self.fold_at[a..=b] {
                *slot = fi as u32;
            }
        }
        self.folds = folds;
    }

    /// Largest distance from the axis at which the tube still changes anything.
    pub fn reach(&self, seg: usize) -> f64 {
        let r = self.axis.radius[seg].max(self.axis.radius[seg + 1]);
        let cord = self
            .collapse
            .iter()
            .map(|c| c.cord_radius)
            .fold(0.0, f64::max);
        r.max(cord) + self.wall_mm
    }

    /// Nearest segment among the candidates `segs` (one run of the tube), sorted by their
    /// distance `seg_dist` to a centre point that is `pc` mm from `p`: since a segment is
    /// at least `seg_dist − pc` from `p`, the search stops as soon as that bound exceeds
    /// the best distance found. Returns (segment, clamped t, raw t).
    #[inline]
    fn nearest(&self, p: DVec3, segs: &[u32], seg_dist: &[f64], pc: f64) -> (usize, f64, f64) {
        let mut best = (0usize, 0.0, 0.0);
        let mut best_d2 = f64::INFINITY;
        let mut best_d = f64::INFINITY;
        for (&sg, &dc) in segs.iter().zip(seg_dist) {
            if dc - pc > best_d {
                break;
            }
            let i = sg as usize;
            let ab = self.seg_ab[i];
            let ap = p - self.seg_a[i];
            let raw = ap.dot(ab) * self.seg_inv_len2[i];
            let t = raw.clamp(0.0, 1.0);
            let d2 = (ap - ab * t).length_squared();
            if d2 < best_d2 {
                best_d2 = d2;
                best_d = d2.sqrt();
                best = (i, t, raw);
            }
        }
        best
    }

    /// Whether every point within `h` of a point at distance `d_axis` from the run `segs` is
    /// surely plain lumen content (no wall, fold, collapse, cap, pool or filled stretch
    /// nearby), so that the rasteriser can skip the search.
    pub fn surely_inside(&self, segs: &[u32], d_axis: f64, h: f64, margin: f64) -> bool {
        if !self.pools.is_empty() || !self.collapse.is_empty() || !self.filled.is_empty() {
            return false;
        }
        let last = self.segments() - 1;
        let mut r_min = f64::INFINITY;
        for &sg in segs {
            let i = sg as usize;
            if self.ends == Ends::Flat && (i == 0 || i == last) {
                return false;
            }
            let fold = match self.fold_at[i] {
                u32::MAX => 0.0,
                f => self.folds[f as usize]
                    .sectors
                    .iter()
                    .map(|s| s.depth)
                    .fold(0.0, f64::max),
            };
            r_min = r_min.min(self.axis.radius[i].min(self.axis.radius[i + 1]) - fold);
        }
        d_axis + h + margin < r_min
    }

    /// The tube at `p`, using the nearest of the candidate segments (see `Tube::nearest`).
    pub fn sample(&self, p: DVec3, segs: &[u32], seg_dist: &[f64], pc: f64) -> TubeHit {
        if segs.is_empty() {
            return TubeHit::NONE;
        }
        let (i, t, raw) = self.nearest(p, segs, seg_dist, pc);
        let ax = &self.axis;
        let seg_len = ax.arc[i + 1] - ax.arc[i];
        let last = self.segments() - 1;
        // Beyond a flat end the axial coordinate runs on past the last point.
        let flat_end =
            self.ends == Ends::Flat && ((i == 0 && raw < 0.0) || (i == last && raw > 1.0));
        let tt = if flat_end { raw } else { t };
        let q = ax.points[i] + (ax.points[i + 1] - ax.points[i]) * tt;
        let v = p - q;
        let d = v.length();
        let s = ax.arc[i] + seg_len * tt;
        let r = ax.radius[i] + (ax.radius[i + 1] - ax.radius[i]) * t;
        if d > self.reach(i) + 2.0 && !flat_end {
            return TubeHit::NONE;
        }
        let (mut r_lumen, mut r_outer) = (r, r + self.wall_mm);
        // The collapse that narrows the lumen most here (they are disjoint, so at most one
        // is below 1; the first wins a tie, which keeps a single collapse as it always was).
        let narrowest = self.collapse.iter().map(|c| (c.factor(s), c)).fold(
            None,
            |best: Option<(f64, &Collapse)>, (f, c)| {
                if best.is_none_or(|(b, _)| f < b) {
                    Some((f, c))
                } else {
                    best
                }
            },
        );
        if let Some((f, c)) = narrowest {
            if c.neck_radius > 0.0 {
                r_lumen = (r * f).max(c.neck_radius);
                r_outer = r_lumen + self.wall_mm;
            } else {
                // A small negative margin makes the core solid even on the axis itself.
                r_lumen = r * f - (1.0 - f) * 2.0 * self.wall_mm;
                r_outer = (r * f + self.wall_mm).max(c.cord_radius);
            }
        }
        let mut lumen = d - r_lumen;
        let fi = self.fold_at[i];
        if fi != u32::MAX && d > 1e-9 {
            let theta = v.dot(ax.binormal[i]).atan2(v.dot(ax.normal[i]));
            let (red, dr_ds, dr_dth) = self.folds[fi as usize].reduction(s, theta);
            if red > 0.0 {
                // |∇(d − R(s, θ))| ≈ √(1 + R_s² + (R_θ / d)²): divide so that the value is
                // close to a true distance and the partial-volume ramp keeps its width.
                let norm = (1.0 + dr_ds * dr_ds + (dr_dth / d.max(1.0)).powi(2)).sqrt();
                lumen = (d - (r_lumen - red)) / norm;
            }
        }
        let mut outer = d - r_outer;
        if flat_end {
            let axial = if i == 0 {
                -raw * seg_len
            } else {
                (raw - 1.0) * seg_len
            } - self.end_margin;
            lumen = capped(lumen, axial);
            outer = capped(outer, axial - self.wall_mm);
        }
        let (mut fluid, mut fluid_hu) = self
            .pools
            .iter()
            .find(|pl| s >= pl.start && s <= pl.end)
            .map_or((f64::INFINITY, 0.0), |pl| {
                (pl.level - p.dot(pl.gravity), pl.hu)
            });
        // A filled stretch: fluid across the whole lumen, its ends cut across the axis.
        for f in &self.filled {
            let d = (f.start - s).max(s - f.end);
            if d < fluid {
                (fluid, fluid_hu) = (d, f.hu);
            }
        }
        TubeHit {
            lumen,
            outer,
            fluid,
            fluid_hu,
        }
    }
}

/// Signed distance of a cylinder end: radial part `radial` (≤ 0 inside the cylinder) and
/// axial part `axial` (≤ 0 inside the cap plane).
#[inline]
fn capped(radial: f64, axial: f64) -> f64 {
    if radial > 0.0 && axial > 0.0 {
        (radial * radial + axial * axial).sqrt()
    } else {
        radial.max(axial)
    }
}

/// What a blob is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BlobKind {
    /// Soft tissue carved out of the lumen.
    Polyp,
    /// A separate pocket of gas with its own thin wall (small bowel).
    Pocket,
    /// A piece of an opacified small-bowel loop: a capsule of fluid (`content_hu`) with its
    /// own wall. A loop is a chain of them (equal radii, so their union is the exact tube);
    /// where one reaches into the colon's lumen (the ileocaecal valve) the colon wins.
    Loop,
    /// A lump of tagged stool (`content_hu`) on the wall, inside the lumen: colon content,
    /// like fluid; `mottled` ones hold pockets of air.
    Stool { mottled: bool },
    /// A pouch of the colon's gas outside its wall (the head, with its own `wall_mm`), joined
    /// to the lumen by a neck through the wall (the stalk): colon lumen.
    Diverticulum,
}

/// A sphere, optionally on a stalk (a capsule from `stalk.0` to `stalk.1`, radius
/// `stalk.2`): polyps (sessile or pedunculated), gas pockets, pieces of small-bowel loops.
#[derive(Clone, Debug)]
pub struct Blob {
    pub kind: BlobKind,
    pub center: DVec3,
    pub radius: f64,
    pub stalk: Option<(DVec3, DVec3, f64)>,
    /// Wall around a pocket or loop (mm); 0 for polyps.
    pub wall_mm: f64,
    /// HU of a loop's content; unused by polyps and pockets.
    pub content_hu: f64,
}

impl Blob {
    /// Signed distance to the blob's solid (head ∪ stalk).
    #[inline]
    pub fn sdf(&self, p: DVec3) -> f64 {
        let head = p.distance(self.center) - self.radius;
        match self.stalk {
            None => head,
            Some((a, b, r)) => head.min(capsule(p, a, b) - r),
        }
    }

    /// Radius of a sphere about `center` outside which the blob (with wall) changes nothing.
    pub fn reach(&self) -> f64 {
        let stalk = self.stalk.map_or(0.0, |(a, b, r)| {
            a.distance(self.center).max(b.distance(self.center)) + r
        });
        self.radius.max(stalk) + self.wall_mm
    }
}

#[inline]
fn capsule(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared().max(1e-12)).clamp(0.0, 1.0);
    p.distance(a + ab * t)
}

/// Distance from `p` to the segment [a, b] (for clearance checks).
#[inline]
pub fn segment_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    capsule(p, a, b)
}

/// A rectal catheter: a plastic tube around a polyline, tip first (inside the rectum), its
/// other end outside the body. Unlike a chain of capsules it is cut flat and open at both
/// ends, so its air channel joins the colon's gas at the tip and the air outside at the end.
#[derive(Clone, Debug)]
pub struct Catheter {
    pub points: Vec<DVec3>,
    /// Radius of the air channel.
    pub inner_radius: f64,
    /// Thickness of the plastic.
    pub wall_mm: f64,
    /// HU of the plastic.
    pub hu: f64,
    /// Gas round its lower part, if an anal canal is held open round it.
    pub canal: Option<Canal>,
    /// Its retention balloon, if inflated.
    pub balloon: Option<Balloon>,
}

/// A catheter's retention balloon: air in a plastic skin, an ellipsoid round the rectum's
/// axis through `center` (`axis` a unit vector along it), `radius` across and `half_length`
/// along, its skin `wall_mm` thick outside that.
#[derive(Clone, Copy, Debug)]
pub struct Balloon {
    pub center: DVec3,
    pub axis: DVec3,
    pub radius: f64,
    pub half_length: f64,
    pub wall_mm: f64,
}

impl Balloon {
    /// How far from its centre it reaches, skin included.
    pub fn reach(&self) -> f64 {
        self.radius.max(self.half_length) + self.wall_mm
    }

    /// Signed distances (negative inside) to its air and to its skin. The ellipsoid's is
    /// the usual bound k0 (k0 − 1) / k1 of the scaled sphere: exact on the surface, which is
    /// all the ramps need.
    #[inline]
    pub fn sdfs(&self, p: DVec3) -> (f64, f64) {
        let d = p - self.center;
        let along = d.dot(self.axis);
        let across = (d - self.axis * along).length();
        let (h, r) = (self.half_length, self.radius);
        let k0 = ((along / h).powi(2) + (across / r).powi(2)).sqrt();
        let k1 = ((along / (h * h)).powi(2) + (across / (r * r)).powi(2)).sqrt();
        let air = if k1 > 0.0 {
            k0 * (k0 - 1.0) / k1
        } else {
            -r.min(h)
        };
        (air, (air - self.wall_mm).max(-air))
    }
}

/// The gas of an anal canal held open round a catheter: within `radius` of its axis, from
/// the skin (`floor`) up to the rectum (`top`), heights in mm.
#[derive(Clone, Copy, Debug)]
pub struct Canal {
    pub radius: f64,
    pub floor: f64,
    pub top: f64,
}

impl Catheter {
    pub fn outer_radius(&self) -> f64 {
        self.inner_radius + self.wall_mm
    }

    /// How far from its axis it changes the scene: its plastic, or its canal's gas.
    pub fn reach(&self) -> f64 {
        self.balloon.map_or(self.tube_reach(), |b| {
            self.tube_reach().max(self.distance(b.center) + b.reach())
        })
    }

    /// How far from its axis the tube itself changes the scene (its balloon aside).
    pub fn tube_reach(&self) -> f64 {
        self.canal
            .map_or(self.outer_radius(), |c| c.radius.max(self.outer_radius()))
    }

    /// How far `p` lies from everything it changes (negative inside).
    pub fn clearance(&self, p: DVec3) -> f64 {
        let tube = self.distance(p) - self.tube_reach();
        self.balloon
            .map_or(tube, |b| tube.min(b.sdfs(p).0 - b.wall_mm))
    }

    /// Distance from `p` to the axis.
    pub fn distance(&self, p: DVec3) -> f64 {
        self.points
            .windows(2)
            .map(|w| capsule(p, w[0], w[1]))
            .fold(f64::INFINITY, f64::min)
    }

    /// Signed distances (negative inside) to the air channel and to the plastic, both cut by
    /// the planes across the axis at the two ends, and to its canal's gas (infinite without
    /// one).
    #[inline]
    pub fn sdfs(&self, p: DVec3) -> (f64, f64, f64) {
        let n = self.points.len();
        if n < 2 {
            return (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        }
        let d = self.distance(p);
        let canal = self.canal.map_or(f64::INFINITY, |c| {
            (d - c.radius).max(p.z - c.top).max(c.floor - p.z)
        });
        let u0 = (self.points[1] - self.points[0]).normalize_or_zero();
        let u1 = (self.points[n - 1] - self.points[n - 2]).normalize_or_zero();
        let cut = (self.points[0] - p)
            .dot(u0)
            .max((p - self.points[n - 1]).dot(u1));
        let air = (d - self.inner_radius).max(cut);
        let plastic = (d - self.outer_radius())
            .max(self.inner_radius - d)
            .max(cut);
        (air, plastic, canal)
    }
}
