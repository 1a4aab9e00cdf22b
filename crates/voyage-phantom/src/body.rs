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

    /// Signed distance to the skin of the body's sides (the elliptic cylinder) only.
    pub fn side_sdf(&self, p: DVec3) -> f64 {
        ellipse_sdf(DVec2::new(p.x, p.y) - self.center, self.semi).0
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

impl Background for Body {
    fn sample(&self, p: DVec3) -> (f64, u8) {
        let skin = self.skin_sdf(p);
        let w = 1.0 / self.inv_w;
        if skin > w {
            return (AIR, label::OUTSIDE_AIR);
        }
        let mut hu = AIR + ramp(skin, self.inv_w) * (MUSCLE - AIR);
        hu += ramp(skin + self.rim, self.inv_w) * (FAT - MUSCLE);
        let (h, bone) = self.spine_hu(p, hu);
        hu = h;
        let mut lab = if skin > 0.0 {
            label::OUTSIDE_AIR
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

    /// Most of a row is plain air (outside) or plain fat: find those stretches once per row
    /// and evaluate [`Body::sample`] only in between, near the skin, spine and lungs.
    fn fill_row(&self, y: f64, z: f64, sx: f64, hu: &mut [f64], labels: &mut [u8]) {
        let w = 1.0 / self.inv_w;
        let dy = y - self.center.y;
        // |x − cx| beyond which the row is surely outside (skin > w), and within which it is
        // surely fat (skin + rim ≤ −w/2); one voxel of slack on each for safety.
        let air_from = self.row_crossing(dy, w) + sx;
        let mut fat_until = self.row_crossing(dy, -self.rim - 0.5 * w) - sx;
        if let Some(f) = self.floor {
            if f - z > w {
                // Under the perineum: all outside air.
                hu.fill(AIR);
                labels.fill(label::OUTSIDE_AIR);
                return;
            }
            if z < f + self.rim + w {
                // Near the perineum (skin, rim, the spine's end): no shortcut to fat.
                fat_until = f64::NEG_INFINITY;
            }
        }
        let lungs_here = !self.below_lungs(z);
        let s = &self.spine;
        let spine_r2 = (s.reach() + 2.0 + sx).powi(2);
        let spine_dy2 = (y - s.center.y).powi(2);
        for (i, (h, l)) in hu.iter_mut().zip(labels.iter_mut()).enumerate() {
            let x = i as f64 * sx;
            let dx = (x - self.center.x).abs();
            if dx > air_from {
                (*h, *l) = (AIR, label::OUTSIDE_AIR);
            } else if dx < fat_until
                && !lungs_here
                && (x - s.center.x).powi(2) + spine_dy2 > spine_r2
            {
                (*h, *l) = (FAT, label::OTHER);
            } else {
                (*h, *l) = self.sample(DVec3::new(x, y, z));
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
