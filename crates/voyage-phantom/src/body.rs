//! The body around the colon: an analytic abdomen, cheap enough to evaluate at every one of
//! 10⁸ voxels.
//!
//! An elliptic cylinder of fat with a rim of muscle and skin, a lumbar spine (vertebral
//! bodies with cortex, cancellous bone and discs, and a posterior arch), and optionally the
//! bases of both lungs in the top slices: domes of aerated lung that reach lowest at their
//! lateral and posterior edges (the costophrenic recesses), as in a real CT colonography.
//!
//! Optionally the body ends below in a flat perineum (`floor`): the slices under it are air
//! outside the body, and the spine stops a rim's thickness above it. The colon phantom gives
//! the body this bottom only when it has a rectal catheter, which leaves the body there.
//!
//! Optionally the body lies on a CT table ([`Table`]) on its dependent side, its skin pressed
//! flat against it over a contact strip, so that beside the strip a wedge of outside air
//! narrows to nothing between skin and table; and skin folds ([`SkinFold`]) cut thin crevices
//! of outside air into it, some closed over by skin in part of their length, so that axial
//! slices there hold air enclosed in the body.

use glam::{DVec2, DVec3};

use super::{label, raster::Background};

pub const AIR: f64 = -1000.0;
pub const FAT: f64 = -100.0;
pub const MUSCLE: f64 = 50.0;
pub const SOFT_TISSUE: f64 = 40.0;
pub const CANCELLOUS: f64 = 400.0;
pub const CORTEX: f64 = 1000.0;
pub const DISC: f64 = 80.0;
pub const LUNG: f64 = -850.0;
/// The table's carbon-fibre shell and the foam inside it.
pub const TABLE_SHELL: f64 = 350.0;
pub const TABLE_FOAM: f64 = -935.0;

/// One lung base: an elliptic footprint (in x, y) whose lower surface is a dome,
/// `z = dome_top − (dome_top − recess) · q²` with q the normalised radius in the footprint.
#[derive(Clone, Debug)]
pub struct Lung {
    pub center: DVec2,
    pub semi: DVec2,
    /// Height of the lung's floor in the middle of the dome and at its rim (mm).
    pub dome_top: f64,
    pub recess: f64,
}

impl Lung {
    /// Approximate signed distance (a lower bound of the true distance outside).
    pub fn sdf(&self, p: DVec3) -> f64 {
        let (e, q2) = ellipse_sdf(DVec2::new(p.x, p.y) - self.center, self.semi);
        let floor = self.dome_top - (self.dome_top - self.recess) * q2.min(1.0);
        e.max(floor - p.z)
    }
}

/// The spine: vertebral bodies (a cylinder of radius `radius` in x, y) broken by discs
/// every `period` mm, with a ring-shaped posterior arch behind them.
#[derive(Clone, Debug)]
pub struct Spine {
    pub center: DVec2,
    pub radius: f64,
    pub cortex: f64,
    pub period: f64,
    pub disc: f64,
    pub arch_center: DVec2,
    pub arch_inner: f64,
    pub arch_outer: f64,
}

impl Spine {
    /// Distance (xy only) beyond which the spine changes nothing.
    pub fn reach(&self) -> f64 {
        (self.arch_center - self.center).length() + self.arch_outer
    }

    /// Signed distance to the vertebral column's bone (body ∪ arch), ignoring discs.
    pub fn sdf_xy(&self, p: DVec3) -> f64 {
        let q = DVec2::new(p.x, p.y);
        let body = (q - self.center).length() - self.radius;
        let r = (q - self.arch_center).length();
        let arch = (r - self.arch_outer).max(self.arch_inner - r);
        body.min(arch)
    }
}

/// A flat CT table, the same in every slice: a slab (in x, y) of foam in a shell, whose top
/// (the face the body rests on) is the plane y = `top`.
#[derive(Clone, Debug)]
pub struct Table {
    pub center_x: f64,
    pub half_width: f64,
    pub top: f64,
    /// +1: the table lies at larger y than its top (posterior: a supine patient); −1: anterior.
    pub down: f64,
    pub thickness: f64,
    /// Thickness of the shell around the foam.
    pub shell: f64,
}

impl Table {
    /// How far `y` lies beyond the top, into the table's side (negative on the body's side).
    #[inline]
    pub fn beyond_top(&self, y: f64) -> f64 {
        (y - self.top) * self.down
    }

    /// Signed distance (x, y) to the slab shrunk by `inset` on every face.
    #[inline]
    fn slab_sdf(&self, x: f64, y: f64, inset: f64) -> f64 {
        let half = 0.5 * self.thickness;
        let qx = (x - self.center_x).abs() - (self.half_width - inset);
        let qy = (self.beyond_top(y) - half).abs() - (half - inset);
        DVec2::new(qx.max(0.0), qy.max(0.0)).length() + qx.max(qy).min(0.0)
    }

    /// Whether the table changes anything in the row at `y` (its faces' partial volume
    /// included): beyond that [`Table::sample`] is plain air.
    fn reaches_row(&self, y: f64, w: f64) -> bool {
        let half = 0.5 * self.thickness;
        (self.beyond_top(y) - half).abs() - half <= w
    }

    /// HU and label of what lies at (x, y) outside the body: shell, foam or air. The table is
    /// not the patient: its voxels are [`label::OTHER`], the air around it outside air.
    fn sample(&self, x: f64, y: f64, inv_w: f64) -> (f64, u8) {
        let outer = self.slab_sdf(x, y, 0.0);
        if outer * inv_w > 1.0 {
            return (AIR, label::OUTSIDE_AIR);
        }
        let inner = self.slab_sdf(x, y, self.shell);
        let hu = AIR
            + ramp(outer, inv_w) * (TABLE_SHELL - AIR)
            + ramp(inner, inv_w) * (TABLE_FOAM - TABLE_SHELL);
        let lab = if outer < 0.0 {
            label::OTHER
        } else {
            label::OUTSIDE_AIR
        };
        (hu, lab)
    }
}

/// A skin fold: a thin slit of outside air from the skin into the body, in the frame
/// (`inward`, `along`, `across`) from its mouth on the skin: `depth` deep along `inward`,
/// over `span` along `along`, `half_width` either side across. Over the stretch `closed` of
/// its length (if any) a bridge of skin `bridge` thick closes its mouth: there the slit is air
/// enclosed in the body, joined to the outside only through the rest of its length.
#[derive(Clone, Debug)]
pub struct SkinFold {
    pub mouth: DVec3,
    pub inward: DVec3,
    pub along: DVec3,
    pub across: DVec3,
    pub depth: f64,
    pub half_width: f64,
    pub span: (f64, f64),
    pub closed: Option<(f64, f64)>,
    pub bridge: f64,
    /// Skin that lines the slit where it runs through fat.
    pub lining: f64,
}

impl SkinFold {
    /// The slit reaches this far (× its depth) out of the skin, so that its mouth opens
    /// cleanly through a curved skin whatever the slit's tilt; outside the body it changes
    /// nothing.
    const OPEN_OUT: f64 = 0.25;

    /// Point in the fold's frame: (inward, along, across).
    #[inline]
    fn local(&self, p: DVec3) -> (f64, f64, f64) {
        let d = p - self.mouth;
        (d.dot(self.inward), d.dot(self.along), d.dot(self.across))
    }

    /// Signed distance (a box's: exact near the faces, a lower bound beyond) to the fold's air.
    pub fn sdf(&self, p: DVec3) -> f64 {
        let (u, l, v) = self.local(p);
        let slit = (v.abs() - self.half_width)
            .max(-Self::OPEN_OUT * self.depth - u)
            .max(u - self.depth)
            .max(self.span.0 - l)
            .max(l - self.span.1);
        match self.closed {
            None => slit,
            Some((a, b)) => slit.max(-(u - self.bridge).max(a - l).max(l - b)),
        }
    }

    /// Distance from `p` to the slit's mid-plane rectangle (mouth to depth, over its span).
    pub fn plane_distance(&self, p: DVec3) -> f64 {
        let (u, l, v) = self.local(p);
        let du = u - u.clamp(0.0, self.depth);
        let dl = l - l.clamp(self.span.0, self.span.1);
        (du * du + dl * dl + v * v).sqrt()
    }

    /// Points on the slit's mid-plane about `step` apart (mouth to depth, over its span).
    pub fn plane_points(&self, step: f64) -> Vec<DVec3> {
        let nu = (self.depth / step).ceil().max(1.0) as usize;
        let nl = ((self.span.1 - self.span.0) / step).ceil().max(1.0) as usize;
        (0..=nu)
            .flat_map(|i| (0..=nl).map(move |j| (i, j)))
            .map(|(i, j)| {
                let u = self.depth * i as f64 / nu as f64;
                let l = self.span.0 + (self.span.1 - self.span.0) * j as f64 / nl as f64;
                self.mouth + self.inward * u + self.along * l
            })
            .collect()
    }

    /// A box (volume-local mm) outside which the fold's distance exceeds its lining + `pad`.
    fn bounds(&self, pad: f64) -> (DVec3, DVec3) {
        // Beyond a corner the box distance [`SkinFold::sdf`] is down to 1/√3 of the true one.
        let reach = 2.0 * (self.half_width + self.lining + pad);
        let us = [-Self::OPEN_OUT * self.depth, self.depth];
        let ls = [self.span.0, self.span.1];
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for u in us {
            for l in ls {
                let c = self.mouth + self.inward * u + self.along * l;
                lo = lo.min(c);
                hi = hi.max(c);
            }
        }
        (lo - DVec3::splat(reach), hi + DVec3::splat(reach))
    }
}

/// The abdomen.
#[derive(Clone, Debug)]
pub struct Body {
    pub center: DVec2,
    pub semi: DVec2,
    /// Muscle and skin rim thickness.
    pub rim: f64,
    pub spine: Spine,
    pub lungs: Vec<Lung>,
    /// Height (z, mm) of the skin of a flat perineum under which there is only outside air;
    /// `None`: the body fills every slice.
    pub floor: Option<f64>,
    /// The table the body lies on (its skin flat against the table's top); `None`: no table.
    pub table: Option<Table>,
    /// Skin folds cut into the body.
    pub folds: Vec<SkinFold>,
    /// 1 / voxel size, for the partial-volume ramp.
    pub inv_w: f64,
}

/// First-order signed distance to an ellipse (good near the boundary) and the normalised
/// squared radius q² = (x/a)² + (y/b)².
#[inline]
pub fn ellipse_sdf(d: DVec2, semi: DVec2) -> (f64, f64) {
    let u = d / semi;
    let q2 = u.length_squared();
    let q = q2.sqrt();
    let grad = (d / (semi * semi)).length();
    if q < 1e-9 || grad < 1e-12 {
        return (-semi.min_element(), q2);
    }
    ((q - 1.0) * q / grad, q2)
}

#[inline]
fn ramp(sdf: f64, inv_w: f64) -> f64 {
    let x = (0.5 - sdf * inv_w).clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

impl Body {
    /// Signed distance to the skin (approximate), the perineum included.
    pub fn skin_sdf(&self, p: DVec3) -> f64 {
        let side = self.side_sdf(p);
        match self.floor {
            None => side,
            Some(f) => side.max(f - p.z),
        }
    }

    /// Signed distance to the skin of the body's sides only: the elliptic cylinder, flattened
    /// where it rests on the table.
    pub fn side_sdf(&self, p: DVec3) -> f64 {
        let side = ellipse_sdf(DVec2::new(p.x, p.y) - self.center, self.semi).0;
        match &self.table {
            None => side,
            Some(t) => side.max(t.beyond_top(p.y)),
        }
    }

    /// What may change row (y, z) besides the body itself: the table, and the skin folds
    /// with the x range each may reach. Whatever is left out changes nothing in the row.
    fn near_row(&self, y: f64, z: f64) -> RowNear<'_> {
        let w = 1.0 / self.inv_w;
        let folds = self
            .folds
            .iter()
            .map(|f| (f, f.bounds(w)))
            .filter(|(_, (lo, hi))| (lo.y..=hi.y).contains(&y) && (lo.z..=hi.z).contains(&z))
            .map(|(f, (lo, hi))| (f, lo.x, hi.x))
            .collect();
        RowNear {
            table: self.table.as_ref().filter(|t| t.reaches_row(y, w)),
            folds,
        }
    }

    /// What lies at (x, y) outside the body: air, or the table.
    #[inline]
    fn outside(&self, table: Option<&Table>, x: f64, y: f64) -> (f64, u8) {
        match table {
            None => (AIR, label::OUTSIDE_AIR),
            Some(t) => t.sample(x, y, self.inv_w),
        }
    }

    /// [`Background::sample`] where only `table` and `folds` may reach `p`.
    fn sample_near(
        &self,
        p: DVec3,
        table: Option<&Table>,
        folds: &[(&SkinFold, f64, f64)],
    ) -> (f64, u8) {
        let skin = self.skin_sdf(p);
        let w = 1.0 / self.inv_w;
        let (out_hu, out_label) = self.outside(table, p.x, p.y);
        if skin > w {
            return (out_hu, out_label);
        }
        // A fold's air is outside air cut into the body: the skin runs round it, and lines
        // it where it crosses the fat. Without folds both distances are +∞.
        let (fold, lined) =
            folds
                .iter()
                .fold((f64::INFINITY, f64::INFINITY), |(air, lined), (f, _, _)| {
                    let d = f.sdf(p);
                    (air.min(d), lined.min(d - f.lining))
                });
        let cut = skin.max(-fold);
        let mut hu = out_hu + ramp(cut, self.inv_w) * (MUSCLE - out_hu);
        hu += ramp((skin + self.rim).max(-lined), self.inv_w) * (FAT - MUSCLE);
        let (h, bone) = self.spine_hu(p, hu);
        hu = h;
        let mut lab = if cut > 0.0 {
            out_label
        } else if bone {
            label::BONE
        } else {
            label::OTHER
        };
        for lung in &self.lungs {
            if self.below_lungs(p.z) {
                continue;
            }
            let d = lung.sdf(p);
            hu += ramp(d, self.inv_w) * (LUNG - hu);
            if d < 0.0 {
                lab = label::LUNG;
            }
        }
        (hu, lab)
    }

    /// Where the spine ends below (the coccyx), a rim's thickness above the perineum.
    fn spine_bottom(&self) -> Option<f64> {
        self.floor.map(|f| f + self.rim)
    }

    fn spine_hu(&self, p: DVec3, hu: f64) -> (f64, bool) {
        let s = &self.spine;
        let q = DVec2::new(p.x, p.y);
        if (q - s.center).length() > s.reach() + 2.0 {
            return (hu, false);
        }
        let mut vb = (q - s.center).length() - s.radius;
        let bottom = self.spine_bottom().map_or(f64::NEG_INFINITY, |b| b - p.z);
        vb = vb.max(bottom);
        // Discs: slabs of thickness `disc` centred every `period` mm.
        let dz = (p.z.rem_euclid(s.period) - 0.5 * s.period).abs();
        let disc = dz - 0.5 * s.disc;
        let in_disc = ramp(-disc, self.inv_w); // 1 between discs (bone), 0 in a disc
        let r = (q - s.arch_center).length();
        let arch = (r - s.arch_outer).max(s.arch_inner - r).max(bottom);
        let mut h = hu + ramp(arch, self.inv_w) * (CORTEX - hu);
        let body = ramp(vb, self.inv_w);
        let bone = CORTEX + ramp(vb + s.cortex, self.inv_w) * (CANCELLOUS - CORTEX);
        let column = DISC + in_disc * (bone - DISC);
        h += body * (column - h);
        let is_bone = (vb < 0.0 && disc > 0.0) || arch < 0.0;
        (h, is_bone)
    }
}

/// What may reach one row of voxels besides the body: see [`Body::near_row`].
struct RowNear<'a> {
    table: Option<&'a Table>,
    /// Each fold with the x range it may reach.
    folds: Vec<(&'a SkinFold, f64, f64)>,
}

impl Background for Body {
    fn sample(&self, p: DVec3) -> (f64, u8) {
        let folds: Vec<_> = self
            .folds
            .iter()
            .map(|f| (f, f64::NEG_INFINITY, f64::INFINITY))
            .collect();
        self.sample_near(p, self.table.as_ref(), &folds)
    }

    /// Most of a row is plain air or table (outside) or plain fat: find those stretches once
    /// per row and evaluate [`Body::sample`] only in between, near the skin, spine, lungs and
    /// skin folds.
    fn fill_row(&self, y: f64, z: f64, sx: f64, hu: &mut [f64], labels: &mut [u8]) {
        let w = 1.0 / self.inv_w;
        let dy = y - self.center.y;
        // |x − cx| beyond which the row is surely outside (skin > w), and within which it is
        // surely fat (skin + rim ≤ −w/2); one voxel of slack on each for safety.
        let air_from = self.row_crossing(dy, w) + sx;
        let mut fat_until = self.row_crossing(dy, -self.rim - 0.5 * w) - sx;
        let near = self.near_row(y, z);
        if let Some(f) = self.floor {
            if f - z > w {
                // Under the perineum: only what lies outside the body.
                for (i, (h, l)) in hu.iter_mut().zip(labels.iter_mut()).enumerate() {
                    (*h, *l) = self.outside(near.table, i as f64 * sx, y);
                }
                return;
            }
            if z < f + self.rim + w {
                // Near the perineum (skin, rim, the spine's end): no shortcut to fat.
                fat_until = f64::NEG_INFINITY;
            }
        }
        if self
            .table
            .as_ref()
            .is_some_and(|t| t.beyond_top(y) > -(self.rim + w))
        {
            // Within a rim's thickness of the skin pressed flat on the table: no fat.
            fat_until = f64::NEG_INFINITY;
        }
        let lungs_here = !self.below_lungs(z);
        let s = &self.spine;
        let spine_r2 = (s.reach() + 2.0 + sx).powi(2);
        let spine_dy2 = (y - s.center.y).powi(2);
        for (i, (h, l)) in hu.iter_mut().zip(labels.iter_mut()).enumerate() {
            let x = i as f64 * sx;
            let dx = (x - self.center.x).abs();
            if dx > air_from {
                (*h, *l) = self.outside(near.table, x, y);
            } else if dx < fat_until
                && !lungs_here
                && (x - s.center.x).powi(2) + spine_dy2 > spine_r2
                && !near
                    .folds
                    .iter()
                    .any(|&(_, a, b)| x + sx >= a && x - sx <= b)
            {
                (*h, *l) = (FAT, label::OTHER);
            } else {
                (*h, *l) = self.sample_near(DVec3::new(x, y, z), near.table, &near.folds);
            }
        }
    }
}

impl Body {
    /// No lung reaches down to height `z`.
    fn below_lungs(&self, z: f64) -> bool {
        let w = 1.0 / self.inv_w;
        self.lungs.iter().all(|l| z + 2.0 * w < l.recess)
    }

    /// The |x − cx| at which the skin distance along the row at `dy` reaches `level`
    /// (bisection; the distance grows with |x − cx| along a row). 0 if already above it.
    fn row_crossing(&self, dy: f64, level: f64) -> f64 {
        let f = |t: f64| ellipse_sdf(DVec2::new(t, dy), self.semi).0 - level;
        if f(0.0) >= 0.0 {
            return 0.0;
        }
        let (mut lo, mut hi) = (0.0, self.semi.x + self.semi.y + level.abs() + 1.0);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if f(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }
}
