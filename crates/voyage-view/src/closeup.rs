//! Close-up volume rendering (paper §5, Fig. 9, the "volume render" option): the CT ray-cast
//! in a small box in front of the camera or around a marker, so that the radiologist sees
//! what lies under a suspicious bump — a polyp is homogeneous soft tissue, stool is mottled
//! with air inside, tagged stool and fluid are bright.
//!
//! The image lines up pixel for pixel with the endoscopic view of the same [`Camera`] and
//! size (`render_rgba`): the ray of pixel (x, y) is the rasterizer's
//! `View::pixel_direction(x, y)` — `camera.pixel_ray(x + 0.5, y + 0.5, ..)`, through the
//! pixel's centre. So the GUI can lay the close-up over the surface image, or beside it.
//!
//! How a ray is cast:
//! - The box is axis-aligned in volume-local mm (voxel i at i·spacing, as everywhere) and
//!   clipped to the grid of voxel centres; rays outside it stay transparent.
//! - Once per frame the box's voxels become a brick of (HU, ∇HU) in f32, the gradient by
//!   Sobel's central differences (smoothed across) in HU/mm. One trilinear fetch then gives
//!   the value and a smooth gradient together.
//! - Samples lie on spheres around the eye every half of the smallest voxel spacing (the same
//!   distances on every ray, so no wood-grain pattern), and every quarter of that where the
//!   value jumps (a boundary is a voxel thick; sampled coarsely, flat walls show rings). The
//!   first and last samples stand for the partial steps at the box's faces.
//! - Front-to-back compositing, stopped once 98 % opaque; opacity is given per mm and
//!   corrected for the step: α_step = 1 − (1 − α_mm)^step.
//! - A headlight at the eye falling off with distance, as in the endoscopic view. Where the
//!   gradient is strong (a boundary) a sample is lit by |n·l| (two-sided: the far wall of an
//!   air pocket faces the camera from inside the tissue), made more opaque, and coloured as
//!   the material on its dense side (air mixed with tissue reads as fat otherwise); inside
//!   homogeneous tissue the gradient is noise, so the sample keeps a flat colour — otherwise
//!   noise would light a polyp as mottled as stool.
//! - Speed: blocks of 4³ voxels that are all air, or all one uniform material, are crossed in
//!   one hop (together with the blocks around them of the same kind); single voxel cells of
//!   one uniform material are composited without a fetch. Neither changes what a sample
//!   shows (a hop takes the light's falloff once, at its middle).
//!
//! Output: RGBA8, row-major, top row first, **straight (not premultiplied) alpha**, colour
//! gamma-encoded like the surface renderer ([`super::shading::encode`]); alpha 0 and colour 0
//! where the ray misses the box or meets only transparent values.
//!
//! The brick and its scratch buffers (a few MB) are allocated per close-up: keeping them
//! from frame to frame (a thread-local pool, until issue 22) measured 46.2 against 46.3 ms a
//! 256² close-up on one thread, so the allocator's own reuse is enough.

use glam::{DVec3, Vec3A, Vec4};
use rayon::prelude::*;

use super::{
    raster::View,
    shading::{Lighting, encode},
};
use voyage_core::{Error, Result, Volume};
use voyage_nav::Camera;

/// Boxes larger than this (half size, mm) are shrunk to it: the per-frame brick costs 16 bytes
/// per voxel (80 mm at 0.5 mm spacing: 65 MB), and a close-up is meant to be small.
pub const MAX_HALF_SIZE_MM: f64 = 40.0;

/// A ray stops once its remaining transmittance falls below this: what lies behind would
/// change no pixel by more than a couple of 8-bit levels.
const MIN_TRANSMITTANCE: f32 = 0.02;

/// Air below, tissue above: segmentation's threshold, midway between air and soft tissue.
const AIR_HU: f32 = -500.0;
/// Tagged stool and fluid (and bone) above: segmentation's fluid threshold.
const TAGGED_HU: f32 = 200.0;

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
    /// Extra opacity per mm on a boundary, so that surfaces show as surfaces while the tissue
    /// behind them stays translucent.
    pub surface_opacity_per_mm: f32,
    /// Brightness of unlit samples inside homogeneous tissue, relative to the colour.
    pub interior_light: f32,
    /// Headlight on boundaries: ambient + diffuse·|n·l| + specular·|n·l|¹⁶ (white). The
    /// specular part is kept small: white is what tagged material looks like.
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    /// The light falls off with distance as in the endoscopic view (`Lighting`):
    /// 1 / (1 + (d / falloff)²); farther tissue is darker, a cue to depth.
    pub falloff_mm: f32,
}

impl Default for TransferFunction {
    fn default() -> Self {
        Self::tissue()
    }
}

impl TransferFunction {
    /// Control points sorted by HU, with finite values, colours and opacities in 0..1; the
    /// lighting as in [`TransferFunction::tissue`] (its fields are public).
    pub fn new(points: Vec<TfPoint>) -> Result<Self> {
        let ok = |p: &TfPoint| {
            p.hu.is_finite()
                && (0.0..=1.0).contains(&p.opacity_per_mm)
                && p.rgb.iter().all(|c| (0.0..=1.0).contains(c))
        };
        if points.is_empty() || !points.iter().all(ok) {
            return Err(Error::invalid(
                "transfer function: needs control points with finite HU, colour and opacity in 0..1",
            ));
        }
        if points.windows(2).any(|w| w[0].hu > w[1].hu) {
            return Err(Error::invalid(
                "transfer function: control points must be sorted by HU",
            ));
        }
        Ok(TransferFunction {
            points,
            ..Self::tissue()
        })
    }

    /// The default for CT colonography: air transparent; fat (−190…−30 HU) faint yellow and
    /// nearly clear; soft tissue (0…100 HU) pink-red and translucent — a 1 cm polyp is a
    /// solid blob, about 90 % opaque through its middle, and the wall shows through its rim
    /// and around it; tagged stool and fluid, contrast and bone (> 200 HU) white and opaque
    /// within a few mm. Control points in linear RGB, like `Lighting`'s albedo.
    pub fn tissue() -> Self {
        const CLEAR: [f32; 3] = [0.0; 3];
        const FAT: [f32; 3] = [0.85, 0.68, 0.22];
        const SOFT: [f32; 3] = [0.80, 0.20, 0.15];
        const BRIGHT: [f32; 3] = [0.95, 0.93, 0.88];
        let p = |hu, rgb, opacity_per_mm| TfPoint {
            hu,
            rgb,
            opacity_per_mm,
        };
        TransferFunction {
            points: vec![
                p(-600.0, CLEAR, 0.0),
                p(-250.0, FAT, 0.0),
                p(-190.0, FAT, 0.04),
                p(-30.0, FAT, 0.04),
                p(0.0, SOFT, 0.15),
                p(100.0, SOFT, 0.15),
                p(200.0, BRIGHT, 0.6),
            ],
            boundary_hu_per_mm: [60.0, 300.0],
            surface_opacity_per_mm: 0.5,
            interior_light: 0.55,
            ambient: 0.15,
            diffuse: 0.85,
            specular: 0.1,
            falloff_mm: Lighting::default().falloff_mm,
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
        (
            rgb,
            a.opacity_per_mm + t * (b.opacity_per_mm - a.opacity_per_mm),
        )
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

/// The entry of the lookup table for `hu` (nearest HU, clamped to the table).
#[inline]
fn table_index(hu: f32) -> usize {
    ((hu + 0.5) as i32 - TABLE_MIN_HU).clamp(0, TABLE_LEN as i32 - 1) as usize
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
        CloseupBox {
            center: camera.pose.position + distance_mm * camera.pose.z_body(),
            half_size_mm,
        }
    }

    /// A box centred on a point (a marker, a polyp candidate).
    pub fn around(center: DVec3, half_size_mm: f64) -> Self {
        CloseupBox {
            center,
            half_size_mm,
        }
    }

    /// The half size actually rendered: non-negative, at most [`MAX_HALF_SIZE_MM`].
    pub fn effective_half_size(&self) -> f64 {
        if self.half_size_mm.is_finite() {
            self.half_size_mm.clamp(0.0, MAX_HALF_SIZE_MM)
        } else {
            0.0
        }
    }

    pub fn min_mm(&self) -> DVec3 {
        self.center - DVec3::splat(self.effective_half_size())
    }

    pub fn max_mm(&self) -> DVec3 {
        self.center + DVec3::splat(self.effective_half_size())
    }
}

/// Edge (voxels) of the blocks that rays cross in one hop where all of a block is air, or
/// all of it one uniform material.
const BLOCK: usize = 4;

/// A block's or a cell's class: every sample in it must be fetched and classified.
const MIXED: u16 = 0;
/// A block's class: every sample in it is transparent.
const EMPTY: u16 = u16::MAX;

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
    /// Per voxel cell (by its lowest voxel): 1 + the [`Runs`] entry every sample inside it
    /// takes, where that is sure; else [`MIXED`].
    cells: Vec<u16>,
    /// Per block of BLOCK³ cells: [`EMPTY`], 1 + the run all its cells share, or [`MIXED`].
    blocks: Vec<u16>,
    block_dims: [usize; 3],
    /// Index steps from block to block, as floats.
    block_strides: Vec3A,
    /// Per block that is not [`MIXED`]: how many blocks around it (Chebyshev distance) share
    /// its class, so that a ray crosses them all in one hop.
    reach: Vec<u8>,
}

impl Brick {
    /// The voxels from `lo` to `hi` (inclusive volume indices).
    fn new(ct: &Volume<i16>, lo: [usize; 3], hi: [usize; 3]) -> Self {
        let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let data = sobel(&Grid::around(ct, lo, dims), ct.spacing());
        let [nx, ny, nz] = dims;
        let strides = [
            usize::from(nx > 1),
            nx * usize::from(ny > 1),
            nx * ny * usize::from(nz > 1),
        ];
        // A one-voxel axis (a single slice) has no upper corner: samples stay on the slice.
        let hi = Vec3A::from_array(dims.map(|d| (d as f32 - 1.0 - 1e-3).max(0.0)));
        let block_dims = dims.map(|d| d.div_ceil(BLOCK));
        let n = data.len();
        let cells = vec![MIXED; n];
        let blocks = vec![MIXED; block_dims.iter().product()];
        let block_strides = Vec3A::new(
            1.0,
            block_dims[0] as f32,
            (block_dims[0] * block_dims[1]) as f32,
        );
        Brick {
            dims,
            lo,
            data,
            strides,
            hi,
            cells,
            blocks,
            block_dims,
            block_strides,
            reach: Vec::new(),
        }
    }

    /// Finds the cells whose every sample classifies alike: all eight corners in one run of
    /// the table (so every value in between is), and all gradients at most √`interior_g2`
    /// (so every interpolated gradient is: a norm is convex), which makes every sample an
    /// unlit interior one. Rays then composite such a sample without fetching it — most of
    /// the fat and soft tissue that the translucent transfer function lets them cross.
    fn mark_uniform(&mut self, runs: &Runs, interior_g2: f32) {
        const ROUGH: u16 = u16::MAX;
        // Per voxel: its run where its gradient is small, else ROUGH.
        let mut class = vec![ROUGH; self.data.len()];
        for (c, v) in class.iter_mut().zip(&self.data) {
            if Vec3A::new(v.y, v.z, v.w).length_squared() <= interior_g2 {
                *c = runs.of(v.x);
            }
        }
        let [dx, dy, dz] = self.strides;
        let [nx, ny, nz] = self.dims;
        let last = [nx - 1, ny - 1, nz - 1].map(|l| l.max(1));
        self.cells
            .par_chunks_mut(nx)
            .enumerate()
            .for_each(|(r, row)| {
                let (j, k) = (r % ny, r / ny);
                if (j >= last[1] && dy > 0) || (k >= last[2] && dz > 0) {
                    return;
                }
                for (i, c) in row.iter_mut().enumerate().take(last[0]) {
                    let n = i + nx * r;
                    let a = class[n];
                    let same = [dx, dy, dx + dy, dz, dz + dx, dz + dy, dz + dy + dx]
                        .iter()
                        .all(|&o| class[n + o] == a);
                    *c = if same && a != ROUGH { a + 1 } else { MIXED };
                }
            });
    }

    /// Classifies the blocks (after [`Brick::mark_uniform`]): [`EMPTY`] where every voxel a
    /// fetch in it may touch is below `clear_below` HU, one run where all its cells share it.
    fn mark_blocks(&mut self, clear_below: f32) {
        let [bx, by, _] = self.block_dims;
        let [nx, ny, _] = self.dims;
        let blocks: Vec<u16> = (0..self.blocks.len())
            .into_par_iter()
            .map(|n| {
                let b = [n % bx, (n / bx) % by, n / (bx * by)];
                let cells = |a: usize| b[a] * BLOCK..((b[a] + 1) * BLOCK).min(self.dims[a]);
                let voxels = |a: usize| b[a] * BLOCK..((b[a] + 1) * BLOCK + 1).min(self.dims[a]);
                let all_voxels = |f: &dyn Fn(usize) -> bool| {
                    voxels(2)
                        .all(|k| voxels(1).all(|j| voxels(0).all(|i| f(i + nx * (j + ny * k)))))
                };
                let all_cells = |f: &dyn Fn(usize) -> bool| {
                    cells(2).all(|k| cells(1).all(|j| cells(0).all(|i| f(i + nx * (j + ny * k)))))
                };
                if all_voxels(&|v| self.data[v].x < clear_below) {
                    return EMPTY;
                }
                let first = self.cells[b[0] * BLOCK + nx * (b[1] * BLOCK + ny * b[2] * BLOCK)];
                if first != MIXED && all_cells(&|c| self.cells[c] == first) {
                    first
                } else {
                    MIXED
                }
            })
            .collect();
        self.reach = block_reach(&blocks, self.block_dims);
        self.blocks = blocks;
    }

    #[inline]
    fn clamp(&self, p: Vec3A) -> Vec3A {
        p.clamp(Vec3A::ZERO, self.hi)
    }

    /// Whether a sample at `p` is surely transparent (its block is empty).
    #[inline]
    fn is_clear(&self, p: Vec3A) -> bool {
        let b = (self.clamp(p) * (1.0 / BLOCK as f32)).floor();
        self.blocks[b.dot(self.block_strides) as usize] == EMPTY
    }

    /// The class of the block holding `p`, and how many steps `dp` from `p` on (`p` first)
    /// stay among the blocks around it that share its class (all samples of a [`MIXED`]
    /// block are its own): at least 1. `inv_dp` is 1/`dp`, with a huge value where `dp` is 0.
    #[inline(always)]
    fn block_ahead(&self, p: Vec3A, dp: Vec3A, inv_dp: Vec3A) -> (u16, usize) {
        let q = self.clamp(p);
        let b = (q * (1.0 / BLOCK as f32)).floor();
        let i = b.dot(self.block_strides) as usize;
        let r = f32::from(self.reach[i]);
        let lo = (b - Vec3A::splat(r)) * BLOCK as f32;
        let hi = (b + Vec3A::splat(r + 1.0)) * BLOCK as f32;
        // Steps m with p + m·dp still strictly inside: m < s.
        let s = (Vec3A::select(dp.cmpge(Vec3A::ZERO), hi - p, lo - p) * inv_dp)
            .min_element()
            .clamp(0.0, 1e6);
        let m = s as u32;
        (
            self.blocks[i],
            (m + u32::from((m as f32) < s)).max(1) as usize,
        )
    }

    /// The cell holding brick coordinates `p` (voxel units from the brick's first voxel,
    /// clamped into the brick).
    #[inline(always)]
    fn locate(&self, p: Vec3A) -> Spot {
        let p = self.clamp(if p.is_finite() { p } else { Vec3A::ZERO });
        // Finite and within [0, dims − 1] after the clamp: truncation is floor (no call to
        // floorf), and the cast needs none of the checks of a saturating `as` (three of them
        // cost as much as the rest of a sample's addressing).
        // SAFETY: every lane is finite, ≥ 0 and < 2³² (see above).
        let ijk = [p.x, p.y, p.z].map(|v| unsafe { v.to_int_unchecked::<u32>() });
        let n = ijk[0] as usize + self.dims[0] * (ijk[1] as usize + self.dims[1] * ijk[2] as usize);
        Spot {
            n,
            f: p - Vec3A::new(ijk[0] as f32, ijk[1] as f32, ijk[2] as f32),
        }
    }

    /// The sample at `p`.
    #[inline(always)]
    fn sample(&self, p: Vec3A) -> Sample {
        let spot = self.locate(p);
        self.fetch(spot.n, spot.f)
    }

    /// The sample at fraction `f` of cell `n`.
    #[inline(always)]
    fn fetch(&self, n: usize, f: Vec3A) -> Sample {
        let [dx, dy, dz] = self.strides;
        let top = n + dx + dy + dz;
        // The clamp keeps every corner inside; this one check makes that plain, for the
        // unchecked reads below (eight bounds checks cost a quarter of the fetch).
        if top >= self.data.len() {
            return Sample { v: Vec4::ZERO };
        }
        // SAFETY: every index read is between n and top, and top < data.len().
        let at = |o: usize| unsafe { *self.data.get_unchecked(n + o) };
        let c = [
            at(0),
            at(dx),
            at(dy),
            at(dy + dx),
            at(dz),
            at(dz + dx),
            at(dz + dy),
            at(dz + dy + dx),
        ];
        let x00 = c[0].lerp(c[1], f.x);
        let x10 = c[2].lerp(c[3], f.x);
        let x01 = c[4].lerp(c[5], f.x);
        let x11 = c[6].lerp(c[7], f.x);
        Sample {
            v: x00.lerp(x10, f.y).lerp(x01.lerp(x11, f.y), f.z),
        }
    }
}

/// A point in the brick: the index of its cell's lowest voxel, and the point's fraction of
/// the way to the opposite corner.
struct Spot {
    n: usize,
    f: Vec3A,
}

/// What a ray reads at a point: HU and its gradient (HU/mm), interpolated.
#[derive(Clone, Copy, Debug)]
struct Sample {
    v: Vec4,
}

impl Sample {
    #[inline(always)]
    fn hu(&self) -> f32 {
        self.v.x
    }

    #[inline(always)]
    fn gradient(&self) -> Vec3A {
        Vec3A::new(self.v.y, self.v.z, self.v.w)
    }
}

/// Per block of the given classes, the largest r such that every block within Chebyshev
/// distance r (inside the grid) has the same class; 0 for [`MIXED`] blocks. Relaxation to
/// the fixed point of r(b) = min over neighbours n of (r(n) + 1, or 0 where n's class
/// differs): the cube of radius r around b is the union of the cubes of radius r − 1 around
/// its 26 neighbours.
fn block_reach(class: &[u16], dims: [usize; 3]) -> Vec<u8> {
    let mut r: Vec<u8> = class
        .iter()
        .map(|&c| if c == MIXED { 0 } else { u8::MAX })
        .collect();
    let [bx, by, bz] = dims;
    loop {
        let mut changed = false;
        for n in 0..r.len() {
            if r[n] == 0 {
                continue;
            }
            let b = [n % bx, (n / bx) % by, n / (bx * by)];
            let mut best = r[n];
            for o in 0..27 {
                let d = [o % 3, (o / 3) % 3, o / 9];
                let q = [0, 1, 2].map(|a| (b[a] + d[a]).checked_sub(1));
                let [Some(x), Some(y), Some(z)] = q else {
                    continue;
                };
                if x >= bx || y >= by || z >= bz || o == 13 {
                    continue;
                }
                let m = x + bx * (y + by * z);
                best = best.min(if class[m] == class[n] {
                    r[m].saturating_add(1)
                } else {
                    0
                });
            }
            if best != r[n] {
                r[n] = best;
                changed = true;
            }
        }
        if !changed {
            return r;
        }
    }
}

/// HU over a box of voxels, x fastest: the input of the gradient filters.
struct Grid {
    dims: [usize; 3],
    v: Vec<f32>,
}

impl Grid {
    /// The `dims` voxels from `lo`, and one more on every side (the border voxel repeated
    /// beyond the volume's edge).
    fn around(ct: &Volume<i16>, lo: [usize; 3], dims: [usize; 3]) -> Self {
        let d = dims.map(|n| n + 2);
        let vd = ct.dims();
        let at = |a: usize, n: usize| (lo[a] + n).saturating_sub(1).min(vd[a] - 1);
        let mut v = vec![0.0; d[0] * d[1] * d[2]];
        v.par_chunks_mut(d[0]).enumerate().for_each(|(r, row)| {
            let (y, z) = (at(1, r % d[1]), at(2, r / d[1]));
            for (x, o) in row.iter_mut().enumerate() {
                *o = f32::from(ct.get(at(0, x), y, z));
            }
        });
        Grid { dims: d, v }
    }

    /// `w`·(v[−1], v[0], v[+1]) along `axis` at every voxel that has both neighbours: the
    /// grid shrinks by two along `axis`.
    fn filter(&self, axis: usize, w: [f32; 3]) -> Grid {
        let mut d = self.dims;
        d[axis] -= 2;
        let stride = [1, self.dims[0], self.dims[0] * self.dims[1]][axis];
        let mut v = vec![0.0; d[0] * d[1] * d[2]];
        v.par_chunks_mut(d[0]).enumerate().for_each(|(r, row)| {
            let mut src = [0, r % d[1], r / d[1]];
            src[axis] += 1;
            let c = src[0] + self.dims[0] * (src[1] + self.dims[1] * src[2]);
            let n = row.len();
            let (a, b, e) = (
                &self.v[c - stride..][..n],
                &self.v[c..][..n],
                &self.v[c + stride..][..n],
            );
            for (o, ((a, b), e)) in row.iter_mut().zip(a.iter().zip(b).zip(e)) {
                *o = w[0] * a + w[1] * b + w[2] * e;
            }
        });
        Grid { dims: d, v }
    }
}

/// HU and gradient (HU/mm) at the inner voxels of `g`. The gradient is Sobel's: central
/// differences smoothed by (¼, ½, ¼) across, which divides the noise in homogeneous tissue
/// by about 2.7 and leaves a flat boundary's gradient as it is — so that CT noise neither
/// lights a polyp's inside like a surface nor keeps its samples from being uniform.
fn sobel(g: &Grid, spacing: [f64; 3]) -> Vec<Vec4> {
    const SMOOTH: [f32; 3] = [0.25, 0.5, 0.25];
    let (x, y, z) = (0, 1, 2);
    // Smoothed across each axis; the differences along it are taken while assembling.
    let sz = g.filter(z, SMOOTH);
    let across_x = sz.filter(y, SMOOTH);
    let across_y = sz.filter(x, SMOOTH);
    let across_z = g.filter(x, SMOOTH).filter(y, SMOOTH);
    let h = [0, 1, 2].map(|a| (0.5 / spacing[a]) as f32);
    let [nx, ny, nz] = g.dims.map(|d| d - 2);
    let mut out = vec![Vec4::ZERO; nx * ny * nz];
    out.par_chunks_mut(nx).enumerate().for_each(|(r, row)| {
        let (j, k) = (r % ny, r / ny);
        fn at(g: &Grid, i: usize, j: usize, k: usize, n: usize) -> &[f32] {
            &g.v[i + g.dims[0] * (j + g.dims[1] * k)..][..n]
        }
        let hu = at(g, 1, j + 1, k + 1, nx);
        let (xm, xp) = (at(&across_x, 0, j, k, nx), at(&across_x, 2, j, k, nx));
        let (ym, yp) = (at(&across_y, 0, j, k, nx), at(&across_y, 0, j + 2, k, nx));
        let (zm, zp) = (at(&across_z, 0, j, k, nx), at(&across_z, 0, j, k + 2, nx));
        for (i, o) in row.iter_mut().enumerate() {
            *o = Vec4::new(
                hu[i],
                (xp[i] - xm[i]) * h[0],
                (yp[i] - ym[i]) * h[1],
                (zp[i] - zm[i]) * h[2],
            );
        }
    });
    out
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
        StepTable {
            rgba: tf.table(step_mm),
            surface_alpha: step_opacity(tf.surface_opacity_per_mm, step_mm),
        }
    }

    /// Values below this are transparent (one HU of margin for the table's rounding).
    fn clear_below(&self) -> f32 {
        let first = self
            .rgba
            .iter()
            .position(|e| e.w > 0.0)
            .unwrap_or(TABLE_LEN);
        (TABLE_MIN_HU + first as i32 - 1) as f32
    }

    #[inline]
    fn get(&self, hu: f32) -> Vec4 {
        self.rgba[table_index(hu)]
    }
}

/// The table cut into runs of equal entries: a cell whose values all fall in one run
/// classifies the same wherever it is sampled.
struct Runs {
    /// Per table entry, its run.
    id: Vec<u16>,
    /// Per run: its entry, and the HU in its middle (what a ray remembers of a sample it did
    /// not fetch).
    entry: Vec<(Vec4, f32)>,
}

impl Runs {
    fn new(table: &StepTable) -> Self {
        let (mut id, mut entry) = (Vec::with_capacity(TABLE_LEN), Vec::<(Vec4, f32)>::new());
        let mut start = 0;
        for (i, e) in table.rgba.iter().enumerate() {
            if i == 0 || *e != table.rgba[i - 1] {
                if let Some(last) = entry.last_mut() {
                    last.1 = (TABLE_MIN_HU as f32) + 0.5 * (start + i - 1) as f32;
                }
                entry.push((*e, 0.0));
                start = i;
            }
            id.push((entry.len() - 1) as u16);
        }
        if let Some(last) = entry.last_mut() {
            last.1 = (TABLE_MIN_HU as f32) + 0.5 * (start + TABLE_LEN - 1) as f32;
        }
        Runs { id, entry }
    }

    /// The run of the entry that `hu` looks up.
    #[inline]
    fn of(&self, hu: f32) -> u16 {
        self.id[table_index(hu)]
    }
}

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
struct Scene<'a> {
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
    fn cast(&self, eye: DVec3, dir: DVec3) -> (Vec3A, f32) {
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
pub fn render_closeup(
    ct: &Volume<i16>,
    camera: &Camera,
    region: &CloseupBox,
    width: u32,
    height: u32,
    tf: &TransferFunction,
) -> Vec<u8> {
    let mut out = vec![0u8; width as usize * height as usize * 4];
    let Some(scene) = scene(ct, region, tf) else {
        return out;
    };
    if width == 0 || height == 0 {
        return out;
    }
    // The rasterizer's own pixel rays (the ray through each pixel's centre), so that the two
    // images line up pixel for pixel.
    let view = View::new(camera, width, height);
    let eye = camera.pose.position;
    out.par_chunks_mut(width as usize * 4)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, px) in row.chunks_exact_mut(4).enumerate() {
                let dir = view.pixel_direction(x as u32, y as u32).normalize();
                let (color, alpha) = scene.cast(eye, dir);
                px.copy_from_slice(&to_rgba8(color, alpha));
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use voyage_core::Geometry;

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
        let p = |hu| TfPoint {
            hu,
            rgb: [1.0; 3],
            opacity_per_mm: 0.5,
        };
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
        let s = b.sample(Vec3A::new(1.5, 2.25, 0.5)).v;
        // Brick (1.5, 2.25, 0.5) is volume index (2.5, 2.25, 1.5): x = 1.25 mm, z = 3 mm.
        assert!((s.x - (12.5 + 9.0)).abs() < 1e-4, "{s}");
        assert!(
            (s.y - 10.0).abs() < 1e-4 && s.z.abs() < 1e-4 && (s.w - 3.0).abs() < 1e-4,
            "{s}"
        );
    }

    #[test]
    fn a_box_outside_the_volume_renders_nothing() {
        let g = Geometry::new([8, 8, 8], [1.0; 3], [0.0; 3]).unwrap();
        let ct = Volume::filled(g, 40i16).unwrap();
        let cam = Camera::new(voyage_nav::Pose::looking(
            DVec3::new(4.0, 4.0, -10.0),
            DVec3::Z,
            DVec3::Y,
        ));
        let far = CloseupBox::around(DVec3::new(100.0, 4.0, 4.0), 5.0);
        assert!(
            render_closeup(&ct, &cam, &far, 16, 16, &TransferFunction::tissue())
                .iter()
                .all(|&v| v == 0)
        );
        let near = CloseupBox::in_front_of(&cam, 14.0, 3.0);
        let img = render_closeup(&ct, &cam, &near, 16, 16, &TransferFunction::tissue());
        // 6 mm of soft tissue: 1 − 0.85⁶ ≈ 62 % opaque.
        assert!(
            img[(8 * 16 + 8) * 4 + 3] > 140,
            "{:?}",
            &img[(8 * 16 + 8) * 4..][..4]
        );
        assert!(render_closeup(&ct, &cam, &near, 0, 16, &TransferFunction::tissue()).is_empty());
    }
}
