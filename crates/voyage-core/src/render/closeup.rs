//! Close-up volume rendering (paper §6, Fig. 9): the CT ray-cast in a small box in front of
//! the camera, so that the radiologist sees what lies under a suspicious bump — a polyp is
//! homogeneous soft tissue, stool is mottled with air inside, tagged stool and fluid are
//! bright.
//!
//! The image lines up pixel for pixel with the endoscopic view of the same [`Camera`] and size
//! (`render_rgba`): the ray of pixel (x, y) is `camera.pixel_ray(x + 0.5, y + 0.5, ..)`, the
//! ray through that pixel's centre in the rasterizer. So the GUI can lay the close-up over the
//! surface image, or show it beside it.
//!
//! How a ray is cast:
//! - The box is axis-aligned in volume-local mm and clipped to the grid of voxel centres;
//!   rays outside it stay transparent.
//! - The box's voxels are copied once per frame into a brick of (HU, ∇HU) as f32, the gradient
//!   by central differences on the voxel grid in HU/mm. One trilinear fetch of the brick then
//!   gives the value and a smooth gradient together (interpolating the voxel gradients avoids
//!   the facets of the trilinear interpolant's own, cell-wise gradient).
//! - Samples lie on spheres around the eye, every `step` mm (half the smallest voxel
//!   spacing), so neighbouring rays sample alike and no wood-grain pattern appears.
//! - Front-to-back compositing with early termination once 98 % opaque; opacity is given per
//!   mm and corrected for the step: α_step = 1 − (1 − α_mm)^step.
//! - A headlight: the light sits at the eye, as in the endoscopic view. Where the gradient is
//!   strong (a boundary) the sample is lit by |n·l| (two-sided: the far wall of an air pocket
//!   faces the camera from inside the tissue) and made more opaque, so surfaces read in 3D;
//!   inside homogeneous tissue the gradient is only noise, so the sample keeps its flat colour
//!   — otherwise noise would light a polyp as mottled as stool.
//!
//! Output: RGBA8, row-major, top row first, **straight (not premultiplied) alpha**, colour
//! gamma-encoded like the surface renderer ([`super::shading::encode`]); alpha 0 and colour 0
//! where the ray misses the box or meets only transparent values.

use glam::{DVec3, Vec3A, Vec4};
use rayon::prelude::*;

use super::shading::encode;
use crate::camera::Camera;
use crate::{Error, Result, Volume};

/// Boxes larger than this (half size, mm) are shrunk to it: the per-frame brick costs 16 bytes
/// per voxel (80 mm at 0.5 mm spacing: 65 MB), and a close-up is meant to be small.
pub const MAX_HALF_SIZE_MM: f64 = 40.0;

/// A ray stops once its remaining transmittance falls below this: what lies behind would
/// change no pixel by more than a couple of 8-bit levels.
const MIN_TRANSMITTANCE: f32 = 0.02;

/// Air below, tissue above: segmentation's threshold, midway between air and soft tissue.
const AIR_HU: f32 = -500.0;

/// The lowest HU of the lookup table (and of CT): everything below is air.
const TABLE_MIN_HU: i32 = -1024;
/// Entries of the lookup table, one per HU from [`TABLE_MIN_HU`]; values above clamp to the
/// last one (bone and metal alike).
const TABLE_LEN: usize = 4096;

/// One control point of a [`TransferFunction`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TfPoint {
    pub hu: f32,
    /// Linear RGB, 0..1.
    pub rgb: [f32; 3],
    /// Opacity of a 1 mm thick slab of this material, 0..1.
    pub opacity_per_mm: f32,
}

/// Colour and opacity per HU, piecewise linear between control points (constant beyond the
/// first and last), plus how boundaries are lit and emphasised.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    points: Vec<TfPoint>,
    /// Gradient magnitudes (HU/mm) over which a sample goes from "inside homogeneous tissue"
    /// (flat colour) to "on a boundary" (lit, with the surface opacity added): below the first,
    /// CT noise; above the second, a real interface.
    pub boundary_hu_per_mm: [f32; 2],
    /// How far across a boundary (voxels) a boundary sample looks for the material it shows.
    pub boundary_reach_voxels: f32,
    /// Extra opacity per mm on a boundary, so that surfaces show as surfaces while the tissue
    /// behind them stays translucent.
    pub surface_opacity_per_mm: f32,
    /// Brightness of unlit samples inside homogeneous tissue, relative to the colour.
    pub interior_light: f32,
    /// Headlight on boundaries: ambient + diffuse·|n·l| + specular·|n·l|¹⁶ (white).
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
}

impl Default for TransferFunction {
    fn default() -> Self {
        Self::tissue()
    }
}

impl TransferFunction {
    /// Control points sorted by HU, with finite values, colours and opacities in 0..1.
    pub fn new(points: Vec<TfPoint>) -> Result<Self> {
        let ok = |p: &TfPoint| p.hu.is_finite() && (0.0..=1.0).contains(&p.opacity_per_mm) && p.rgb.iter().all(|c| (0.0..=1.0).contains(c));
        if points.is_empty() || !points.iter().all(ok) {
            return Err(Error::invalid("transfer function: needs control points with finite HU, colour and opacity in 0..1"));
        }
        if points.windows(2).any(|w| w[0].hu > w[1].hu) {
            return Err(Error::invalid("transfer function: control points must be sorted by HU"));
        }
        Ok(TransferFunction { points, ..Self::tissue() })
    }

    /// The default for CT colonography: air transparent; fat faint yellow; soft tissue
    /// pink-red and translucent (a 1 cm polyp is a solid blob, ≈ 80 % opaque through its
    /// middle, and the wall behind it still shows); tagged stool and fluid, contrast and bone
    /// (> 200 HU) white and nearly opaque within a few mm.
    pub fn tissue() -> Self {
        const CLEAR: [f32; 3] = [0.0; 3];
        const FAT: [f32; 3] = [0.85, 0.68, 0.22];
        const SOFT: [f32; 3] = [0.80, 0.20, 0.15];
        const BRIGHT: [f32; 3] = [0.95, 0.93, 0.88];
        let p = |hu, rgb, opacity_per_mm| TfPoint { hu, rgb, opacity_per_mm };
        TransferFunction {
            points: vec![
                p(-600.0, CLEAR, 0.0),
                p(-220.0, FAT, 0.0),
                p(-150.0, FAT, 0.04),
                p(-50.0, FAT, 0.04),
                p(-10.0, SOFT, 0.15),
                p(100.0, SOFT, 0.15),
                p(200.0, BRIGHT, 0.6),
            ],
            boundary_hu_per_mm: [60.0, 300.0],
            boundary_reach_voxels: 1.0,
            surface_opacity_per_mm: 0.35,
            interior_light: 0.6,
            ambient: 0.2,
            diffuse: 0.8,
            specular: 0.12,
        }
    }

    pub fn points(&self) -> &[TfPoint] {
        &self.points
    }

    /// Linear RGB and opacity per mm at `hu`.
    pub fn eval(&self, hu: f32) -> ([f32; 3], f32) {
        let ps = &self.points;
        let i = ps.partition_point(|p| p.hu <= hu);
        if i == 0 {
            return (ps[0].rgb, ps[0].opacity_per_mm);
        }
        if i == ps.len() {
            let last = ps[ps.len() - 1];
            return (last.rgb, last.opacity_per_mm);
        }
        let (a, b) = (ps[i - 1], ps[i]);
        let t = (hu - a.hu) / (b.hu - a.hu);
        let rgb = [0, 1, 2].map(|c| a.rgb[c] + t * (b.rgb[c] - a.rgb[c]));
        (rgb, a.opacity_per_mm + t * (b.opacity_per_mm - a.opacity_per_mm))
    }

    /// The lookup table for one step length: per HU, linear RGB and the step's opacity.
    fn table(&self, step_mm: f32) -> Vec<Vec4> {
        (0..TABLE_LEN)
            .map(|i| {
                let (rgb, a) = self.eval((TABLE_MIN_HU + i as i32) as f32);
                Vec4::new(rgb[0], rgb[1], rgb[2], step_opacity(a, step_mm))
            })
            .collect()
    }
}

/// Opacity of a slab `step_mm` thick of a material whose 1 mm slab has opacity `per_mm`.
fn step_opacity(per_mm: f32, step_mm: f32) -> f32 {
    1.0 - (1.0 - per_mm.min(0.999)).powf(step_mm)
}

/// The region to ray-cast: an axis-aligned cube in volume-local mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloseupBox {
    pub center: DVec3,
    pub half_size_mm: f64,
}

impl CloseupBox {
    /// A box centred `distance_mm` ahead of the camera on its view axis.
    pub fn in_front_of(camera: &Camera, distance_mm: f64, half_size_mm: f64) -> Self {
        CloseupBox { center: camera.pose.position + distance_mm * camera.pose.z_body(), half_size_mm }
    }

    /// A box centred on a point (a marker, a polyp candidate).
    pub fn around(center: DVec3, half_size_mm: f64) -> Self {
        CloseupBox { center, half_size_mm }
    }

    /// The half size actually rendered: non-negative, at most [`MAX_HALF_SIZE_MM`].
    pub fn effective_half_size(&self) -> f64 {
        if self.half_size_mm.is_finite() { self.half_size_mm.clamp(0.0, MAX_HALF_SIZE_MM) } else { 0.0 }
    }

    pub fn min_mm(&self) -> DVec3 {
        self.center - DVec3::splat(self.effective_half_size())
    }

    pub fn max_mm(&self) -> DVec3 {
        self.center + DVec3::splat(self.effective_half_size())
    }
}

/// Edge (voxels) of the blocks that record where the brick is all air, so that rays skip it.
const BLOCK: usize = 4;

/// The box's voxels as (HU, ∂HU/∂x, ∂HU/∂y, ∂HU/∂z), gradient in HU per mm, x fastest.
struct Brick {
    dims: [usize; 3],
    /// Volume index of the brick's voxel (0, 0, 0).
    lo: [usize; 3],
    data: Vec<Vec4>,
    /// Index steps to a fetch's upper corner along x, y, z (0 along an axis of one voxel).
    strides: [usize; 3],
    /// Largest coordinate a sample may take, just under dims − 1, so that a fetch's upper
    /// corner stays inside.
    hi: Vec3A,
    /// Per block of BLOCK³ voxels: every sample whose fetch starts in it is below the
    /// threshold given to [`Brick::mark_empty`], so transparent.
    empty: Vec<bool>,
    blocks: [usize; 3],
}

impl Brick {
    /// The voxels from `lo` to `hi` (inclusive volume indices).
    fn new(ct: &Volume<i16>, lo: [usize; 3], hi: [usize; 3]) -> Self {
        let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let mut data = vec![Vec4::ZERO; dims[0] * dims[1] * dims[2]];
        data.par_chunks_mut(dims[0] * dims[1]).enumerate().for_each(|(k, slice)| {
            for (n, v) in slice.iter_mut().enumerate() {
                let g = [lo[0] + n % dims[0], lo[1] + n / dims[0], lo[2] + k];
                *v = voxel_with_gradient(ct, g);
            }
        });
        let [nx, ny, nz] = dims;
        let strides = [usize::from(nx > 1), nx * usize::from(ny > 1), nx * ny * usize::from(nz > 1)];
        // A one-voxel axis (a single slice) has no upper corner: samples stay on the slice.
        let hi = Vec3A::from_array(dims.map(|d| (d as f32 - 1.0 - 1e-3).max(0.0)));
        let blocks = dims.map(|d| d.div_ceil(BLOCK));
        Brick { dims, lo, data, strides, hi, empty: vec![false; blocks[0] * blocks[1] * blocks[2]], blocks }
    }

    /// Marks the blocks where every voxel a fetch may touch is below `hu`.
    fn mark_empty(&mut self, hu: f32) {
        let [bx, by, _] = self.blocks;
        let empty: Vec<bool> = (0..self.empty.len())
            .map(|n| {
                let b = [n % bx, (n / bx) % by, n / (bx * by)];
                let range = |a: usize| b[a] * BLOCK..((b[a] + 1) * BLOCK + 1).min(self.dims[a]);
                range(2).all(|k| range(1).all(|j| range(0).all(|i| self.data[i + self.dims[0] * (j + self.dims[1] * k)].x < hu)))
            })
            .collect();
        self.empty = empty;
    }

    #[inline]
    fn clamp(&self, p: Vec3A) -> Vec3A {
        p.clamp(Vec3A::ZERO, self.hi)
    }

    /// When a fetch at `p` is surely transparent, the number of steps `dp` that stay in its
    /// empty block (at least 1); else 0.
    #[inline]
    fn empty_steps(&self, p: Vec3A, dp: Vec3A) -> usize {
        let q = self.clamp(p);
        let b = [q.x as u32 as usize / BLOCK, q.y as u32 as usize / BLOCK, q.z as u32 as usize / BLOCK];
        if !self.empty[b[0] + self.blocks[0] * (b[1] + self.blocks[1] * b[2])] {
            return 0;
        }
        // Steps m with p + m·dp still strictly inside the block: m < s.
        let lo = Vec3A::new(b[0] as f32, b[1] as f32, b[2] as f32) * BLOCK as f32;
        let hi = lo + Vec3A::splat(BLOCK as f32);
        let to_wall = Vec3A::select(dp.cmpgt(Vec3A::ZERO), hi - p, lo - p) / dp;
        let s = to_wall.min_element();
        if s.is_finite() { (s.ceil() as u32 as usize).max(1) } else { 1 }
    }

    /// Trilinear (HU, gradient) at brick coordinates `p` (voxel units from the brick's first
    /// voxel), clamped into the brick.
    #[inline(always)]
    fn sample(&self, p: Vec3A) -> Vec4 {
        let p = self.clamp(p);
        // Non-negative after the clamp: truncation is floor, without a call to floorf.
        let (i, j, k) = (p.x as u32 as usize, p.y as u32 as usize, p.z as u32 as usize);
        let f = p - Vec3A::new(i as f32, j as f32, k as f32);
        let [dx, dy, dz] = self.strides;
        let n = i + self.dims[0] * (j + self.dims[1] * k);
        let top = n + dx + dy + dz;
        // The clamp keeps every corner inside; this one check makes that plain, for the
        // unchecked reads below (eight bounds checks cost a quarter of the fetch).
        if top >= self.data.len() {
            return Vec4::ZERO;
        }
        // SAFETY: every index read is between n and top, and top < data.len().
        let at = |o: usize| unsafe { *self.data.get_unchecked(n + o) };
        let x00 = at(0).lerp(at(dx), f.x);
        let x10 = at(dy).lerp(at(dy + dx), f.x);
        let x01 = at(dz).lerp(at(dz + dx), f.x);
        let x11 = at(dz + dy).lerp(at(dz + dy + dx), f.x);
        x00.lerp(x10, f.y).lerp(x01.lerp(x11, f.y), f.z)
    }
}

/// HU at a voxel and its gradient by central differences (one-sided at the volume's border,
/// zero along an axis of one voxel), in HU per mm.
fn voxel_with_gradient(ct: &Volume<i16>, g: [usize; 3]) -> Vec4 {
    let dims = ct.dims();
    let s = ct.spacing();
    let at = |g: [usize; 3]| f32::from(ct.get(g[0], g[1], g[2]));
    let mut grad = [0.0f32; 3];
    for a in 0..3 {
        let (mut lo, mut hi) = (g, g);
        lo[a] = g[a].saturating_sub(1);
        hi[a] = (g[a] + 1).min(dims[a] - 1);
        let span = (hi[a] - lo[a]) as f64 * s[a];
        if span > 0.0 {
            grad[a] = ((at(hi) - at(lo)) as f64 / span) as f32;
        }
    }
    Vec4::new(at(g), grad[0], grad[1], grad[2])
}

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

/// The transfer function tabulated for one step length.
struct StepTable {
    /// Per HU from [`TABLE_MIN_HU`]: linear RGB and the opacity of one step.
    rgba: Vec<Vec4>,
    /// Extra opacity of one step on a full boundary (the surface emphasis).
    surface_alpha: f32,
}

impl StepTable {
    fn new(tf: &TransferFunction, step_mm: f32) -> Self {
        StepTable { rgba: tf.table(step_mm), surface_alpha: step_opacity(tf.surface_opacity_per_mm, step_mm) }
    }

    /// Values below this are transparent (one HU of margin for the table's rounding).
    fn clear_below(&self) -> f32 {
        let first = self.rgba.iter().position(|e| e.w > 0.0).unwrap_or(TABLE_LEN);
        (TABLE_MIN_HU + first as i32 - 1) as f32
    }

    #[inline]
    fn get(&self, hu: f32) -> Vec4 {
        let i = (hu + 0.5) as i32 - TABLE_MIN_HU;
        self.rgba[i.clamp(0, TABLE_LEN as i32 - 1) as usize]
    }
}

/// Front-to-back compositing state of one ray: premultiplied linear colour, transmittance.
struct Accum {
    color: Vec3A,
    trans: f32,
}

impl Accum {
    /// Adds a sample behind everything so far; true once nothing behind can show.
    #[inline]
    fn add(&mut self, rgb: Vec3A, alpha: f32) -> bool {
        self.color += (self.trans * alpha) * rgb;
        self.trans *= 1.0 - alpha;
        self.trans < MIN_TRANSMITTANCE
    }
}

/// Everything a ray needs that is the same for the whole frame.
struct Scene<'a> {
    brick: Brick,
    tf: &'a TransferFunction,
    full: StepTable,
    sub: StepTable,
    /// How far (mm) a boundary sample looks across the boundary for its material, per axis in
    /// brick voxels.
    reach_brick: Vec3A,
    /// Squared gradient magnitude (HU/mm)² up to which a sample is inside homogeneous tissue.
    interior_g2: f32,
    /// The clipped box (mm) rays are marched through.
    lo_mm: DVec3,
    hi_mm: DVec3,
    spacing: DVec3,
    step_mm: f64,
}

impl Scene<'_> {
    /// On a boundary the value is a partial-volume mix of the two sides (air and tissue
    /// average to fat): the value a little way up the gradient (`up`, unit, mm) is the
    /// material on the dense side, so that no yellow rim wraps every polyp and fold. Only
    /// samples past the air threshold take it, so that surfaces sit where segmentation and
    /// the mesh put them.
    #[inline]
    fn dense_side(&self, p: Vec3A, hu: f32, up: Vec3A) -> f32 {
        self.brick.sample(p + up * self.reach_brick).x.max(hu)
    }

    /// Premultiplied linear RGB and alpha seen along the ray from `eye` in direction `dir`
    /// (unit, mm).
    fn cast(&self, eye: DVec3, dir: DVec3) -> (Vec3A, f32) {
        let Some((t0, t1)) = clip_ray(eye, dir, self.lo_mm, self.hi_mm) else { return (Vec3A::ZERO, 0.0) };
        let view = dir.as_vec3a();
        let lo_idx = DVec3::from_array(self.brick.lo.map(|v| v as f64));
        let to_brick = |t: f64| ((eye + t * dir) / self.spacing - lo_idx).as_vec3a();
        let mut acc = Accum { color: Vec3A::ZERO, trans: 1.0 };
        // Samples on spheres around the eye, the same distances for every ray; each stands
        // for the stretch of ray before it. The first and a last one at the exit cover the
        // partial stretches, so that a face of the box cut through tissue shows no rings.
        let first = (t0 / self.step_mm).ceil();
        let last = (t1 / self.step_mm).floor();
        if first > last {
            self.add_partial(&mut acc, to_brick(t1), view, (t1 - t0) / self.step_mm);
            return (acc.color, 1.0 - acc.trans);
        }
        let mut p = to_brick(first * self.step_mm);
        let dp = (dir * self.step_mm / self.spacing).as_vec3a();
        let mut prev = self.brick.sample(p);
        if self.add_partial(&mut acc, p, view, first - t0 / self.step_mm) {
            return (acc.color, 1.0 - acc.trans);
        }
        let (mut k, n) = (0, (last - first) as usize);
        while k < n {
            p += dp;
            k += 1;
            let skip = self.brick.empty_steps(p, dp);
            if skip > 0 {
                // Past the empty block; coming out of air, the next sample refines its stretch.
                let m = (skip - 1).min(n - k);
                p += dp * m as f32;
                k += m;
                prev = Vec4::splat(f32::NEG_INFINITY);
                continue;
            }
            let s = self.brick.sample(p);
            let done = if (s.x - prev.x).abs() > REFINE_HU { self.add_refined(&mut acc, p - dp, dp, s, view) } else { self.add(&mut acc, p, s, view, &self.full) };
            if done {
                return (acc.color, 1.0 - acc.trans);
            }
            prev = s;
        }
        self.add_partial(&mut acc, to_brick(t1), view, t1 / self.step_mm - last);
        (acc.color, 1.0 - acc.trans)
    }

    #[inline]
    fn add(&self, acc: &mut Accum, p: Vec3A, s: Vec4, view: Vec3A, table: &StepTable) -> bool {
        match self.classify(p, s, view, table) {
            Some((rgb, alpha)) => acc.add(rgb, alpha),
            None => false,
        }
    }

    /// The stretch from `start` to `start + dp` (brick units) in sub-steps; `end` is the
    /// sample at its end.
    fn add_refined(&self, acc: &mut Accum, start: Vec3A, dp: Vec3A, end: Vec4, view: Vec3A) -> bool {
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
        match self.classify(p, self.brick.sample(p), view, &self.full) {
            Some((rgb, alpha)) => acc.add(rgb, 1.0 - (1.0 - alpha).powf(fraction.clamp(0.0, 1.0) as f32)),
            None => false,
        }
    }

    /// Colour (lit where on a boundary) and opacity of the sample `s` taken at `p`; None when
    /// transparent.
    #[inline(always)]
    fn classify(&self, p: Vec3A, s: Vec4, view: Vec3A, table: &StepTable) -> Option<(Vec3A, f32)> {
        let tf = self.tf;
        let grad = Vec3A::new(s.y, s.z, s.w);
        let g2 = grad.length_squared();
        // Inside homogeneous tissue (most samples that are not air): no square root needed.
        if g2 <= self.interior_g2 {
            let e = table.get(s.x);
            return (e.w > 0.0).then(|| (Vec3A::from_vec4(e) * tf.interior_light, e.w));
        }
        if s.x < AIR_HU && table.get(s.x).w <= 0.0 {
            return None;
        }
        let g = g2.sqrt();
        let w = smoothstep(tf.boundary_hu_per_mm[0], tf.boundary_hu_per_mm[1], g);
        let hu = if s.x >= AIR_HU { s.x + w * (self.dense_side(p, s.x, grad / g) - s.x) } else { s.x };
        let e = table.get(hu);
        if e.w <= 0.0 {
            return None;
        }
        let ndl = (grad.dot(view) / g).abs();
        let lit = Vec3A::from_vec4(e) * (tf.ambient + tf.diffuse * ndl) + Vec3A::splat(tf.specular * ndl.powi(16));
        let alpha = 1.0 - (1.0 - e.w) * (1.0 - w * table.surface_alpha);
        Some(((Vec3A::from_vec4(e) * tf.interior_light).lerp(lit, w), alpha))
    }
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0).max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The frame-constant part of a render, or None when the box misses the volume.
fn scene<'a>(ct: &Volume<i16>, region: &CloseupBox, tf: &'a TransferFunction) -> Option<Scene<'a>> {
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
    let mut brick = Brick::new(ct, lo, hi);
    brick.mark_empty(full.clear_below().min(AIR_HU));
    Some(Scene {
        brick,
        tf,
        full,
        sub: StepTable::new(tf, (step_mm / SUB_STEPS as f64) as f32),
        interior_g2: tf.boundary_hu_per_mm[0].max(0.0).powi(2),
        reach_brick: (tf.boundary_reach_voxels as f64 * spacing.min_element() / spacing).as_vec3a(),
        lo_mm,
        hi_mm,
        spacing,
        step_mm,
    })
}

/// Straight-alpha RGBA8 of a premultiplied linear colour.
fn to_rgba8(color: Vec3A, alpha: f32) -> [u8; 4] {
    let a = (alpha.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    if a == 0 {
        return [0; 4];
    }
    let c = color / alpha;
    [encode(c.x), encode(c.y), encode(c.z), a]
}

/// Ray-casts the CT inside `region` for `camera`: a `width` × `height` RGBA8 image with
/// straight alpha, row-major, top row first, aligned pixel for pixel with the endoscopic view
/// of the same camera and size. Alpha is 0 where the ray misses the box (or the volume) or
/// meets nothing but transparent values. Rows are rendered in parallel; the result does not
/// depend on the number of threads.
pub fn render_closeup(ct: &Volume<i16>, camera: &Camera, region: &CloseupBox, width: u32, height: u32, tf: &TransferFunction) -> Vec<u8> {
    let mut out = vec![0u8; width as usize * height as usize * 4];
    let Some(scene) = scene(ct, region, tf) else { return out };
    if width == 0 || height == 0 {
        return out;
    }
    let eye = camera.pose.position;
    out.par_chunks_mut(width as usize * 4).enumerate().for_each(|(y, row)| {
        for (x, px) in row.chunks_exact_mut(4).enumerate() {
            let dir = camera.pixel_ray(x as f64 + 0.5, y as f64 + 0.5, width, height);
            let (color, alpha) = scene.cast(eye, dir);
            px.copy_from_slice(&to_rgba8(color, alpha));
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;

    #[test]
    fn transfer_function_interpolates_and_clamps() {
        let tf = TransferFunction::tissue();
        assert_eq!(tf.eval(-1000.0).1, 0.0);
        assert_eq!(tf.eval(-3000.0).1, 0.0);
        let (soft, a_soft) = tf.eval(40.0);
        assert!(soft[0] > 2.0 * soft[1] && a_soft > 0.1, "{soft:?} {a_soft}");
        let (fat, a_fat) = tf.eval(-100.0);
        assert!(fat[1] > 2.0 * fat[2] && a_fat < a_soft);
        let (bright, a_bright) = tf.eval(1000.0);
        assert!(bright.iter().all(|&c| c > 0.8) && a_bright > a_soft);
        // Halfway between two points.
        let mid = tf.eval(150.0);
        assert!((mid.1 - 0.5 * (0.15 + 0.6)).abs() < 1e-6);
        assert!(TransferFunction::new(vec![]).is_err());
        let p = |hu| TfPoint { hu, rgb: [1.0; 3], opacity_per_mm: 0.5 };
        assert!(TransferFunction::new(vec![p(10.0), p(0.0)]).is_err());
    }

    #[test]
    fn step_opacity_composes_to_the_per_mm_opacity() {
        // Four quarter-mm steps are one mm.
        let a = step_opacity(0.3, 0.25);
        assert!(((1.0 - (1.0 - a).powi(4)) - 0.3).abs() < 1e-6);
        assert_eq!(step_opacity(0.0, 0.5), 0.0);
    }

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

    #[test]
    fn the_brick_interpolates_values_and_gradients() {
        // HU = 10·x(mm) + 3·z(mm): the gradient is (10, 0, 3) everywhere inside.
        let g = Geometry::new([6, 5, 4], [0.5, 1.0, 2.0], [0.0; 3]).unwrap();
        let data: Vec<i16> = (0..g.len())
            .map(|n| {
                let [i, _, k] = g.ijk(n);
                (10.0 * i as f64 * 0.5 + 3.0 * k as f64 * 2.0) as i16
            })
            .collect();
        let ct = Volume::from_vec(g, data).unwrap();
        let b = Brick::new(&ct, [1, 0, 1], [4, 4, 3]);
        let s = b.sample(Vec3A::new(1.5, 2.25, 0.5));
        // Brick (1.5, 2.25, 0.5) is volume index (2.5, 2.25, 1.5): x = 1.25 mm, z = 3 mm.
        assert!((s.x - (12.5 + 9.0)).abs() < 1e-4, "{s}");
        assert!((s.y - 10.0).abs() < 1e-4 && s.z.abs() < 1e-4 && (s.w - 3.0).abs() < 1e-4, "{s}");
    }

    #[test]
    fn a_box_outside_the_volume_renders_nothing() {
        let g = Geometry::new([8, 8, 8], [1.0; 3], [0.0; 3]).unwrap();
        let ct = Volume::filled(g, 40i16).unwrap();
        let cam = Camera::new(crate::camera::Pose::looking(DVec3::new(4.0, 4.0, -10.0), DVec3::Z, DVec3::Y));
        let far = CloseupBox::around(DVec3::new(100.0, 4.0, 4.0), 5.0);
        assert!(render_closeup(&ct, &cam, &far, 16, 16, &TransferFunction::tissue()).iter().all(|&v| v == 0));
        let near = CloseupBox::in_front_of(&cam, 14.0, 3.0);
        let img = render_closeup(&ct, &cam, &near, 16, 16, &TransferFunction::tissue());
        // 6 mm of soft tissue: 1 − 0.85⁶ ≈ 62 % opaque.
        assert!(img[(8 * 16 + 8) * 4 + 3] > 140, "{:?}", &img[(8 * 16 + 8) * 4..][..4]);
        assert!(render_closeup(&ct, &cam, &near, 0, 16, &TransferFunction::tissue()).is_empty());
    }
}
#[cfg(test)]
mod debug_rim {
    use super::*;
    use crate::Geometry;
    #[test]
    fn rim() {
        let g = Geometry::new([64; 3], [0.75; 3], [0.0; 3]).unwrap();
        let c = DVec3::splat(24.0);
        let data: Vec<i16> = (0..g.len()).map(|n| { let [i,j,k] = g.ijk(n); let p = DVec3::new(i as f64, j as f64, k as f64)*0.75; let f = (0.5 - ((p-c).length()-6.0)/0.75).clamp(0.0,1.0); (-1000.0 + f*1040.0).round() as i16 }).collect();
        let ct = Volume::from_vec(g, data).unwrap();
        let tf = TransferFunction::tissue();
        let sc = scene(&ct, &CloseupBox::around(c, 15.0), &tf).unwrap();
        for off in [5.0, 5.5, 5.8, 6.0] {
            let eye = c + DVec3::new(off, 0.0, -30.0);
            let lo_idx = DVec3::from_array(sc.brick.lo.map(|v| v as f64));
            eprintln!("offset {off}");
            let mut t = 22.0;
            while t < 32.0 {
                let pm = eye + DVec3::Z * t;
                let p = (pm / sc.spacing - lo_idx).as_vec3a();
                let s = sc.brick.sample(p);
                let grad = Vec3A::new(s.y, s.z, s.w); let gl = grad.length();
                let w = smoothstep(tf.boundary_hu_per_mm[0], tf.boundary_hu_per_mm[1], gl);
                let dense = if w > 0.0 { sc.dense_side(p, s.x, grad / gl) } else { s.x };
                let cl = sc.classify(p, s, Vec3A::Z, &sc.full);
                if s.x > -900.0 { eprintln!("  t {t:.2} hu {:.0} g {gl:.0} w {w:.2} dense {dense:.0} -> {:?}", s.x, cl); }
                t += 0.375;
            }
        }
    }
}
#[cfg(test)]
mod debug_bench {
    use super::*;
    use crate::Geometry;
    struct Cpu(u64);
    impl Cpu {
        fn now() -> Self { Cpu(std::fs::read_to_string("/proc/thread-self/schedstat").unwrap().split_whitespace().next().unwrap().parse().unwrap()) }
        fn elapsed(&self) -> std::time::Duration { std::time::Duration::from_nanos(Cpu::now().0 - self.0) }
    }
    #[test]
    fn bench() {
        let g = Geometry::new([64, 64, 48], [0.75, 0.75, 1.0], [0.0; 3]).unwrap();
        let data: Vec<i16> = (0..g.len()).map(|n| (-100 + ((n * 2654435761) % 41) as i64 - 20) as i16).collect();
        let ct = Volume::from_vec(g, data).unwrap();
        let tf = TransferFunction::tissue();
        let c = DVec3::new(24.0, 24.0, 24.0);
        let sc = scene(&ct, &CloseupBox::around(c, 20.0), &tf).unwrap();
        let dp = Vec3A::new(0.3, 0.2, 0.25);
        let n = 2_700_000;
        let t = Cpu::now();
        let mut acc = Vec4::ZERO;
        let mut p = Vec3A::new(2.0, 2.0, 2.0);
        for i in 0..n { acc += sc.brick.sample(p); p += dp; if i % 100 == 99 { p = Vec3A::new(2.0 + (i % 7) as f32, 2.0 + (i % 13) as f32, 2.0); } }
        eprintln!("fetch only: {:.1} ns/fetch {acc}", t.elapsed().as_secs_f64() * 1e9 / n as f64);
        let t = Cpu::now();
        let mut a = Accum { color: Vec3A::ZERO, trans: 1.0 };
        let mut p = Vec3A::new(2.0, 2.0, 2.0);
        for i in 0..n { let s = sc.brick.sample(p); sc.add(&mut a, p, s, Vec3A::Z, &sc.full); a.trans = 1.0; p += dp; if i % 100 == 99 { p = Vec3A::new(2.0 + (i % 7) as f32, 2.0 + (i % 13) as f32, 2.0); } }
        eprintln!("fetch+classify: {:.1} ns/fetch {}", t.elapsed().as_secs_f64() * 1e9 / n as f64, a.color);
        let cam = crate::camera::Camera::new(crate::camera::Pose::looking(c - DVec3::Z * 25.0, DVec3::Z, DVec3::Y));
        let mut best = f64::MAX;
        for _ in 0..7 {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            let ms = pool.install(|| {
                let t = Cpu::now();
                let img = render_closeup(&ct, &cam, &CloseupBox::around(c, 20.0), 256, 256, &tf);
                std::hint::black_box(img);
                t.elapsed().as_secs_f64() * 1e3
            });
            best = best.min(ms);
        }
        eprintln!("render: best {best:.1} ms");
    }
}
