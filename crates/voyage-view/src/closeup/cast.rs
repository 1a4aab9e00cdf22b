//! Casting one ray: clipped to the box, sampled on spheres around the eye, composited front
//! to back, lit and classified; with the frame-constant scene every ray shares.

use glam::{DVec3, Vec3A};

use super::{
    brick::{Brick, EMPTY, MIXED, Sample},
    region::CloseupBox,
    transfer::{Runs, StepTable, TransferFunction},
};
use voyage_core::Volume;

/// A ray stops once its remaining transmittance falls below this: what lies behind would
/// change no pixel by more than a couple of 8-bit levels.
const MIN_TRANSMITTANCE: f32 = 0.02;

/// Air below, tissue above: segmentation's threshold, midway between air and soft tissue.
const AIR_HU: f32 = -500.0;
/// Tagged stool and fluid (and bone) above: segmentation's fluid threshold.
const TAGGED_HU: f32 = 200.0;

/// Where a ray `o + t·d` (t ≥ 0) is inside the box [lo, hi], by slabs; None when it misses.
fn clip_ray(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t0 <= t1).then_some((t0, t1))
}

/// Sub-steps per step where the value changes by more than [`REFINE_HU`] from one sample to
/// the next: a boundary is about a voxel thick, two samples at most, and where they fall on
/// it varies from ray to ray — sampled coarsely, flat walls show rings.
const SUB_STEPS: usize = 4;
const REFINE_HU: f32 = 100.0;

/// Front-to-back compositing state of one ray: premultiplied linear colour, transmittance,
/// and the headlight's strength where the ray is.
struct Accum {
    color: Vec3A,
    trans: f32,
    light: f32,
    /// 1 / the light's falloff distance (mm⁻¹).
    inv_falloff: f32,
}

impl Accum {
    /// Moves to `t` mm from the eye.
    #[inline(always)]
    fn at(&mut self, t: f32) {
        let r = t * self.inv_falloff;
        self.light = 1.0 / (1.0 + r * r);
    }

    /// Adds a sample behind everything so far; true once nothing behind can show.
    #[inline]
    fn add(&mut self, rgb: Vec3A, alpha: f32) -> bool {
        self.color += (self.trans * alpha * self.light) * rgb;
        self.trans *= 1.0 - alpha;
        self.trans < MIN_TRANSMITTANCE
    }
}

/// A ray in brick units: its step, its direction in mm (for lighting), and the distance from
/// the eye (mm) of its first sample and between samples.
struct Ray {
    dp: Vec3A,
    view: Vec3A,
    t: f32,
    step: f32,
}

/// Everything a ray needs that is the same for the whole frame.
pub(super) struct Scene<'a> {
    brick: Brick,
    tf: &'a TransferFunction,
    full: StepTable,
    sub: StepTable,
    runs: Runs,
    /// Squared gradient magnitude (HU/mm)² up to which a sample is inside homogeneous tissue.
    interior_g2: f32,
    /// Values below this are transparent whatever their gradient.
    clear_below: f32,
    /// One voxel (the smallest spacing), per axis in brick units: how far a boundary sample
    /// looks for its dense side.
    reach: Vec3A,
    /// Where the boundary weight starts (HU/mm), and 1 / the width of its ramp.
    boundary: (f32, f32),
    /// 1 / voxel spacing: mm to brick units.
    inv_spacing: DVec3,
    /// The clipped box (mm) rays are marched through.
    lo_mm: DVec3,
    hi_mm: DVec3,
    step_mm: f64,
}

impl Scene<'_> {
    /// HU one voxel from `p` up the gradient (`up`, unit, mm): across a boundary, on its
    /// dense side.
    #[inline]
    fn dense_side(&self, p: Vec3A, up: Vec3A) -> f32 {
        self.brick.sample(p + up * self.reach).hu()
    }

    /// Premultiplied linear RGB and alpha seen along the ray from `eye` in direction `dir`
    /// (unit, mm).
    pub(super) fn cast(&self, eye: DVec3, dir: DVec3) -> (Vec3A, f32) {
        let Some((t0, t1)) = clip_ray(eye, dir, self.lo_mm, self.hi_mm) else {
            return (Vec3A::ZERO, 0.0);
        };
        let view = dir.as_vec3a();
        let lo_idx = DVec3::from_array(self.brick.lo.map(|v| v as f64));
        let to_brick = |t: f64| ((eye + t * dir) * self.inv_spacing - lo_idx).as_vec3a();
        let mut acc = Accum {
            color: Vec3A::ZERO,
            trans: 1.0,
            light: 1.0,
            inv_falloff: 1.0 / self.tf.falloff_mm.max(1e-3),
        };
        // Samples on spheres around the eye, the same distances for every ray; each stands
        // for the stretch of ray before it. The first and a last one at the exit cover the
        // partial stretches, so that a face of the box cut through tissue shows no rings.
        let first = (t0 / self.step_mm).ceil();
        let last = (t1 / self.step_mm).floor();
        if first > last {
            acc.at(t1 as f32);
            self.add_partial(&mut acc, to_brick(t1), view, (t1 - t0) / self.step_mm);
            return (acc.color, 1.0 - acc.trans);
        }
        let p = to_brick(first * self.step_mm);
        acc.at((first * self.step_mm) as f32);
        if self.add_partial(&mut acc, p, view, first - t0 / self.step_mm) {
            return (acc.color, 1.0 - acc.trans);
        }
        let dp = (dir * self.step_mm * self.inv_spacing).as_vec3a();
        let ray = Ray {
            dp,
            view,
            t: (first * self.step_mm) as f32,
            step: self.step_mm as f32,
        };
        if !self.march(&mut acc, p, &ray, (last - first) as usize) {
            acc.at(t1 as f32);
            self.add_partial(&mut acc, to_brick(t1), view, t1 / self.step_mm - last);
        }
        (acc.color, 1.0 - acc.trans)
    }

    /// The `n` whole steps after the sample at `p`; true once nothing behind can show.
    /// Block by block: across empty and uniform blocks in one hop, sample by sample through
    /// the others.
    fn march(&self, acc: &mut Accum, mut p: Vec3A, ray: &Ray, n: usize) -> bool {
        let dp = ray.dp;
        let inv_dp = Vec3A::select(dp.cmpeq(Vec3A::ZERO), Vec3A::splat(f32::MAX), dp.recip());
        let mut prev_hu = if self.brick.is_clear(p) {
            f32::NEG_INFINITY
        } else {
            self.brick.sample(p).hu()
        };
        let mut k = 0;
        while k < n {
            let next = p + dp;
            let (block, m) = self.brick.block_ahead(next, dp, inv_dp);
            let m = m.min(n - k);
            if block == EMPTY {
                // Coming out of air, the next sample fetched refines its stretch.
                prev_hu = f32::NEG_INFINITY;
            } else if block != MIXED
                && (self.runs.entry[block as usize - 1].1 - prev_hu).abs() <= REFINE_HU
            {
                let (e, hu) = self.runs.entry[block as usize - 1];
                prev_hu = hu;
                // Lit as at the middle of the hop.
                acc.at(ray.t + (k as f32 + 0.5 * (m + 1) as f32) * ray.step);
                if e.w > 0.0
                    && acc.add(
                        Vec3A::from_vec4(e) * self.tf.interior_light,
                        1.0 - (1.0 - e.w).powi(m as i32),
                    )
                {
                    return true;
                }
            } else if self.samples(acc, p, ray, k, m, &mut prev_hu) {
                return true;
            }
            p += dp * m as f32;
            k += m;
        }
        false
    }

    /// The `m` samples after `p` (step `k` of the ray), one by one; true once nothing behind
    /// can show.
    fn samples(
        &self,
        acc: &mut Accum,
        mut p: Vec3A,
        ray: &Ray,
        k: usize,
        m: usize,
        prev_hu: &mut f32,
    ) -> bool {
        for j in 1..=m {
            p += ray.dp;
            acc.at(ray.t + (k + j) as f32 * ray.step);
            let spot = self.brick.locate(p);
            if let Some(uniform) = self.brick.cells.get(spot.n).and_then(|&c| c.checked_sub(1)) {
                let (e, hu) = self.runs.entry[uniform as usize];
                // Unless coming from far off (a boundary just crossed: fetch and refine).
                if (hu - *prev_hu).abs() <= REFINE_HU {
                    if e.w > 0.0 && acc.add(Vec3A::from_vec4(e) * self.tf.interior_light, e.w) {
                        return true;
                    }
                    *prev_hu = hu;
                    continue;
                }
            }
            let s = self.brick.fetch(spot.n, spot.f);
            // Refine where the value jumps, unless only within air.
            let jump =
                (s.hu() - *prev_hu).abs() > REFINE_HU && s.hu().max(*prev_hu) >= self.clear_below;
            let done = if jump {
                self.add_refined(acc, p - ray.dp, ray.dp, s, ray.view)
            } else {
                self.add(acc, p, s, ray.view, &self.full)
            };
            if done {
                return true;
            }
            *prev_hu = s.hu();
        }
        false
    }

    #[inline(always)]
    fn add(&self, acc: &mut Accum, p: Vec3A, s: Sample, view: Vec3A, table: &StepTable) -> bool {
        match self.classify(p, s, view, table) {
            Some((rgb, alpha)) => acc.add(rgb, alpha),
            None => false,
        }
    }

    /// The stretch from `start` to `start + dp` (brick units) in sub-steps; `end` is the
    /// sample at its end.
    fn add_refined(
        &self,
        acc: &mut Accum,
        start: Vec3A,
        dp: Vec3A,
        end: Sample,
        view: Vec3A,
    ) -> bool {
        for k in 1..SUB_STEPS {
            let p = start + dp * (k as f32 / SUB_STEPS as f32);
            if self.add(acc, p, self.brick.sample(p), view, &self.sub) {
                return true;
            }
        }
        self.add(acc, start + dp, end, view, &self.sub)
    }

    /// The sample at `p` standing for `fraction` of a step.
    fn add_partial(&self, acc: &mut Accum, p: Vec3A, view: Vec3A, fraction: f64) -> bool {
        if self.brick.is_clear(p) {
            return false;
        }
        match self.classify(p, self.brick.sample(p), view, &self.full) {
            Some((rgb, alpha)) => acc.add(
                rgb,
                1.0 - (1.0 - alpha).powf(fraction.clamp(0.0, 1.0) as f32),
            ),
            None => false,
        }
    }

    /// Colour (lit where on a boundary) and opacity of a sample; None when transparent.
    #[inline(always)]
    fn classify(
        &self,
        p: Vec3A,
        s: Sample,
        view: Vec3A,
        table: &StepTable,
    ) -> Option<(Vec3A, f32)> {
        let tf = self.tf;
        let grad = s.gradient();
        let g2 = grad.length_squared();
        // Inside homogeneous tissue (most samples that are not air): no square root needed.
        if g2 <= self.interior_g2 {
            let e = table.get(s.hu());
            return (e.w > 0.0).then(|| (Vec3A::from_vec4(e) * tf.interior_light, e.w));
        }
        if s.hu() < AIR_HU && table.get(s.hu()).w <= 0.0 {
            return None;
        }
        let inv_g = g2.sqrt().recip();
        let t = ((g2 * inv_g - self.boundary.0) * self.boundary.1).clamp(0.0, 1.0);
        let w = t * t * (3.0 - 2.0 * t);
        // On a boundary the value is a partial-volume mix of the two sides (air and soft
        // tissue average to fat; air and tagged fluid to soft tissue): past the air threshold,
        // show the material a voxel up the gradient, so that no yellow or pink rim wraps
        // every fold, polyp and pool, and the surface sits where segmentation and the mesh
        // put it. (Tagged material itself needs no look: nothing above it is different.)
        let hu = if (AIR_HU..TAGGED_HU).contains(&s.hu()) {
            s.hu() + w * (self.dense_side(p, grad * inv_g) - s.hu()).max(0.0)
        } else {
            s.hu()
        };
        let e = table.get(hu);
        if e.w <= 0.0 {
            return None;
        }
        let ndl = grad.dot(view).abs() * inv_g;
        let lit = Vec3A::from_vec4(e) * (tf.ambient + tf.diffuse * ndl)
            + Vec3A::splat(tf.specular * ndl.powi(16));
        let alpha = 1.0 - (1.0 - e.w) * (1.0 - w * table.surface_alpha);
        Some((
            (Vec3A::from_vec4(e) * tf.interior_light).lerp(lit, w),
            alpha,
        ))
    }
}

/// The frame-constant part of a render, or None when the box misses the volume.
pub(super) fn scene<'a>(
    ct: &Volume<i16>,
    region: &CloseupBox,
    tf: &'a TransferFunction,
) -> Option<Scene<'a>> {
    let geom = ct.geometry();
    let spacing = geom.spacing_vec();
    let last = DVec3::from_array(geom.dims.map(|d| (d - 1) as f64)) * spacing;
    let lo_mm = region.min_mm().max(DVec3::ZERO);
    let hi_mm = region.max_mm().min(last);
    if !(lo_mm.cmple(hi_mm).all()) {
        return None;
    }
    // Voxels whose cells the clipped box touches, plus one for the gradient's reach.
    let lo_i = (lo_mm / spacing).floor();
    let hi_i = (hi_mm / spacing).ceil();
    let lo = [0, 1, 2].map(|a| (lo_i[a] as usize).saturating_sub(1));
    let hi = [0, 1, 2].map(|a| (hi_i[a] as usize + 1).min(geom.dims[a] - 1));
    let step_mm = 0.5 * spacing.min_element();
    let full = StepTable::new(tf, step_mm as f32);
    let runs = Runs::new(&full);
    let interior_g2 = tf.boundary_hu_per_mm[0].max(0.0).powi(2);
    let mut brick = Brick::new(ct, lo, hi);
    brick.mark_uniform(&runs, interior_g2);
    let clear_below = full.clear_below().min(AIR_HU);
    brick.mark_blocks(clear_below);
    Some(Scene {
        brick,
        tf,
        full,
        sub: StepTable::new(tf, (step_mm / SUB_STEPS as f64) as f32),
        runs,
        interior_g2,
        clear_below,
        boundary: (
            tf.boundary_hu_per_mm[0],
            1.0 / (tf.boundary_hu_per_mm[1] - tf.boundary_hu_per_mm[0]).max(1e-6),
        ),
        inv_spacing: spacing.recip(),
        reach: (spacing.min_element() / spacing).as_vec3a(),
        lo_mm,
        hi_mm,
        step_mm,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_are_clipped_by_slabs() {
        let (lo, hi) = (DVec3::splat(-1.0), DVec3::splat(1.0));
        let (t0, t1) = clip_ray(DVec3::new(0.0, 0.0, -5.0), DVec3::Z, lo, hi).unwrap();
        assert!((t0 - 4.0).abs() < 1e-12 && (t1 - 6.0).abs() < 1e-12);
        assert!(clip_ray(DVec3::new(2.0, 0.0, -5.0), DVec3::Z, lo, hi).is_none());
        // Behind the eye: missed.
        assert!(clip_ray(DVec3::new(0.0, 0.0, 5.0), DVec3::Z, lo, hi).is_none());
        // From inside: starts at the eye.
        let (t0, t1) = clip_ray(DVec3::ZERO, DVec3::X, lo, hi).unwrap();
        assert!(t0 == 0.0 && (t1 - 1.0).abs() < 1e-12);
    }
}
