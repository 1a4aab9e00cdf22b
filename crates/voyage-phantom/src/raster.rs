//! Turns the continuous geometry into voxels: CT (HU with partial volume and noise), the
//! ground-truth lumen mask and a label volume.
//!
//! Speed: a full-size colon is 10⁸ voxels around a 1.5 m axis, so nothing may ask "which
//! axis segment is nearest" for every voxel. A brick index (8³ voxels per brick) lists, for
//! the few bricks near the tube, the candidate segments grouped into runs along the axis
//! (one run per part of the colon passing by), pruned so that each voxel tests a few dozen
//! segments. Every other voxel only evaluates the cheap analytic background. Slices are
//! filled in parallel; each voxel is a pure function of its position and the seed, so the
//! result does not depend on the number of threads.

use glam::DVec3;
use rayon::prelude::*;

use super::{
    label,
    rng::voxel_noise,
    tube::{Blob, BlobKind, Catheter, Tube, TubeHit},
};
use voyage_core::{Geometry, Result, Volume};

/// The tissue outside the tube and blobs: HU and label at a point (volume-local mm).
pub trait Background: Sync {
    fn sample(&self, p: DVec3) -> (f64, u8);

    /// Fills one row (fixed y and z; x = i·`sx`). Backgrounds with large uniform regions
    /// override this to skip the per-voxel work; the result must equal [`Background::sample`].
    fn fill_row(&self, y: f64, z: f64, sx: f64, hu: &mut [f64], labels: &mut [u8]) {
        for (i, (h, l)) in hu.iter_mut().zip(labels.iter_mut()).enumerate() {
            (*h, *l) = self.sample(DVec3::new(i as f64 * sx, y, z));
        }
    }
}

/// HU of the tube's materials.
#[derive(Clone, Copy, Debug)]
pub struct Materials {
    pub lumen_air: f64,
    pub wall: f64,
    pub polyp: f64,
    pub pocket_air: f64,
}

/// Everything the rasteriser needs.
pub struct Scene<'a, B: Background> {
    pub geom: Geometry,
    pub tube: &'a Tube,
    pub blobs: &'a [Blob],
    /// A rectal catheter (drawn over everything else).
    pub catheter: Option<&'a Catheter>,
    pub materials: Materials,
    pub background: &'a B,
    pub noise_sigma: f64,
    pub noise_key: u64,
    /// Round the noisy HU to multiples of this step (a windowed 8-bit export's grey levels).
    pub quantize: Option<f64>,
}

/// The rasterised phantom.
pub struct Rendered {
    pub ct: Volume<i16>,
    pub lumen: Volume<u8>,
    pub labels: Volume<u8>,
}

const BRICK: usize = 8;
/// Axis segments per chunk when deciding which bricks a stretch of tube can touch.
const CHUNK: usize = 8;

/// Candidates for one brick.
#[derive(Default)]
struct BrickData {
    center: DVec3,
    /// Candidate segments, per run sorted by their distance to `center` (`seg_dist`).
    segs: Vec<u32>,
    seg_dist: Vec<f64>,
    /// Ranges into `segs`, one per run of consecutive segments (one part of the tube).
    runs: Vec<(u32, u32)>,
    /// The whole brick is plain lumen content of one run: no search needed.
    inside: bool,
    blobs: Vec<u16>,
    /// The catheter may reach into the brick.
    catheter: bool,
}

struct BrickIndex {
    nb: [usize; 3],
    bricks: Vec<Option<Box<BrickData>>>,
}

impl BrickIndex {
    #[inline]
    fn get(&self, bi: usize, bj: usize, bk: usize) -> Option<&BrickData> {
        self.bricks[bi + self.nb[0] * (bj + self.nb[1] * bk)].as_deref()
    }
}

/// Partial-volume fraction inside a surface at signed distance `sdf` (mm): a smoothstep
/// across one voxel (`inv_w` = 1 / voxel size), exactly ½ on the surface, so "fraction > ½"
/// and "voxel centre inside" are the same thing.
#[inline]
fn ramp(sdf: f64, inv_w: f64) -> f64 {
    let x = (0.5 - sdf * inv_w).clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Whether `p` lies in one of the air pockets of mottled stool: a lattice of bubbles about
/// 3 mm apart (fixed in space, so every thread draws the same).
fn air_pocket(p: DVec3) -> bool {
    (p.x * 2.1).sin() + (p.y * 1.9).sin() + (p.z * 2.3).sin() > 1.6
}

impl<B: Background> Scene<'_, B> {
    /// Rasterises the scene.
    pub fn render(&self) -> Result<Rendered> {
        let index = self.build_index();
        let [nx, ny, nz] = self.geom.dims;
        let plane = nx * ny;
        let mut ct = vec![0i16; plane * nz];
        let mut lumen = vec![0u8; plane * nz];
        let mut labels = vec![0u8; plane * nz];
        ct.par_chunks_mut(plane)
            .zip(lumen.par_chunks_mut(plane))
            .zip(labels.par_chunks_mut(plane))
            .enumerate()
            .for_each(|(k, ((c, l), lb))| self.fill_slice(&index, k, c, l, lb));
        Ok(Rendered {
            ct: Volume::from_vec(self.geom.clone(), ct)?,
            lumen: Volume::from_vec(self.geom.clone(), lumen)?,
            labels: Volume::from_vec(self.geom.clone(), labels)?,
        })
    }

    fn brick_center_and_half_diagonal(&self, b: [usize; 3]) -> (DVec3, f64) {
        let s = self.geom.spacing;
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for a in 0..3 {
            let first = b[a] * BRICK;
            let last = (first + BRICK - 1).min(self.geom.dims[a] - 1);
            lo[a] = first as f64 * s[a];
            hi[a] = last as f64 * s[a];
        }
        let (lo, hi) = (DVec3::from_array(lo), DVec3::from_array(hi));
        ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
    }

    /// Brick range (inclusive) covering the mm box [lo, hi].
    fn brick_range(
        &self,
        lo: DVec3,
        hi: DVec3,
        nb: [usize; 3],
    ) -> Option<([usize; 3], [usize; 3])> {
        let s = self.geom.spacing;
        let mut a = [0usize; 3];
        let mut b = [0usize; 3];
        for ax in 0..3 {
            let i0 = (lo[ax] / s[ax]).floor();
            let i1 = (hi[ax] / s[ax]).ceil();
            let n = self.geom.dims[ax] as f64;
            if i1 < 0.0 || i0 > n - 1.0 {
                return None;
            }
            a[ax] = (i0.max(0.0) as usize) / BRICK;
            b[ax] = ((i1.min(n - 1.0)) as usize / BRICK).min(nb[ax] - 1);
        }
        Some((a, b))
    }

    fn build_index(&self) -> BrickIndex {
        let nb = self.geom.dims.map(|d| d.div_ceil(BRICK));
        let nbricks = nb[0] * nb[1] * nb[2];
        let mut chunks: Vec<Vec<u32>> = vec![Vec::new(); nbricks];
        let mut blobs: Vec<Vec<u16>> = vec![Vec::new(); nbricks];
        let margin = self.geom.spacing.iter().cloned().fold(0.0, f64::max) + 1.0;
        let tube = self.tube;
        let pts = &tube.axis.points;
        let nseg = tube.segments();
        for (c, first) in (0..nseg).step_by(CHUNK).enumerate() {
            let segs = first..(first + CHUNK).min(nseg);
            let reach = segs.clone().map(|i| tube.reach(i)).fold(0.0, f64::max) + margin;
            let (mut lo, mut hi) = (pts[first], pts[first]);
            for i in segs.clone() {
                lo = lo.min(pts[i + 1]);
                hi = hi.max(pts[i + 1]);
            }
            let Some((a, b)) = self.brick_range(lo - reach, hi + reach, nb) else {
                continue;
            };
            for_each_brick(a, b, |bi| {
                let (center, h) = self.brick_center_and_half_diagonal(bi);
                let near = segs
                    .clone()
                    .map(|i| seg_distance(center, pts[i], pts[i + 1]))
                    .fold(f64::INFINITY, f64::min);
                if near <= reach + h {
                    chunks[bi[0] + nb[0] * (bi[1] + nb[1] * bi[2])].push(c as u32);
                }
            });
        }
        for (bl, blob) in self.blobs.iter().enumerate() {
            let reach = blob.reach() + margin;
            let Some((a, b)) = self.brick_range(blob.center - reach, blob.center + reach, nb)
            else {
                continue;
            };
            for_each_brick(a, b, |bi| {
                let (center, h) = self.brick_center_and_half_diagonal(bi);
                if center.distance(blob.center) <= reach + h {
                    blobs[bi[0] + nb[0] * (bi[1] + nb[1] * bi[2])].push(bl as u16);
                }
            });
        }
        let mut catheter = vec![false; nbricks];
        if let Some(c) = self.catheter {
            let reach = c.reach() + margin;
            for w in c.points.windows(2) {
                let Some((a, b)) =
                    self.brick_range(w[0].min(w[1]) - reach, w[0].max(w[1]) + reach, nb)
                else {
                    continue;
                };
                for_each_brick(a, b, |bi| {
                    let (center, h) = self.brick_center_and_half_diagonal(bi);
                    if seg_distance(center, w[0], w[1]) <= reach + h {
                        catheter[bi[0] + nb[0] * (bi[1] + nb[1] * bi[2])] = true;
                    }
                });
            }
        }
        let bricks = chunks
            .into_par_iter()
            .zip(blobs.into_par_iter())
            .zip(catheter.into_par_iter())
            .enumerate()
            .map(|(id, ((ch, bl), cath))| {
                if ch.is_empty() && bl.is_empty() && !cath {
                    return None;
                }
                let bi = [id % nb[0], (id / nb[0]) % nb[1], id / (nb[0] * nb[1])];
                let (center, h) = self.brick_center_and_half_diagonal(bi);
                let mut data = self.prune_runs(&ch, center, h);
                data.blobs = bl;
                data.catheter = cath;
                Some(Box::new(data))
            })
            .collect();
        BrickIndex { nb, bricks }
    }

    /// Groups a brick's chunks into runs of consecutive chunks and keeps, per run, only the
    /// segments that can be the nearest one for some voxel of the brick: a voxel x within
    /// h of the centre c has its nearest segment within dist(c, nearest) + h, and any
    /// segment is at least dist(c, seg) − h from x, so segments with dist(c, seg) >
    /// dmin + 2h can never win.
    fn prune_runs(&self, chunks: &[u32], center: DVec3, h: f64) -> BrickData {
        let pts = &self.tube.axis.points;
        let nseg = self.tube.segments();
        let mut data = BrickData::default();
        let mut start = 0;
        while start < chunks.len() {
            let mut end = start + 1;
            while end < chunks.len() && chunks[end] == chunks[end - 1] + 1 {
                end += 1;
            }
            let first = chunks[start] as usize * CHUNK;
            let last = ((chunks[end - 1] as usize + 1) * CHUNK).min(nseg);
            let dist: Vec<f64> = (first..last)
                .map(|i| seg_distance(center, pts[i], pts[i + 1]))
                .collect();
            let dmin = dist.iter().cloned().fold(f64::INFINITY, f64::min);
            let mut kept: Vec<(f64, u32)> = (first..last)
                .zip(&dist)
                .filter(|(_, d)| **d <= dmin + 2.0 * h)
                .map(|(i, d)| (*d, i as u32))
                .collect();
            kept.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let run_start = data.segs.len() as u32;
            data.segs.extend(kept.iter().map(|k| k.1));
            data.seg_dist.extend(kept.iter().map(|k| k.0));
            data.runs.push((run_start, data.segs.len() as u32));
            start = end;
        }
        data.center = center;
        let margin = self.geom.spacing.iter().cloned().fold(0.0, f64::max);
        data.inside = data.runs.len() == 1
            && self
                .tube
                .surely_inside(&data.segs, dmin_all(&data.seg_dist), h, margin);
        data
    }

    fn fill_slice(
        &self,
        index: &BrickIndex,
        k: usize,
        ct: &mut [i16],
        lumen: &mut [u8],
        labels: &mut [u8],
    ) {
        let [nx, ny, _] = self.geom.dims;
        let [sx, sy, sz] = self.geom.spacing;
        let z = k as f64 * sz;
        let inv_w = 3.0 / (sx + sy + sz);
        let sigma = self.noise_sigma;
        let mut bg = vec![0.0f64; nx];
        let mut bg_label = vec![0u8; nx];
        for j in 0..ny {
            let y = j as f64 * sy;
            self.background.fill_row(y, z, sx, &mut bg, &mut bg_label);
            let row = nx * j;
            lumen[row..row + nx].fill(0);
            labels[row..row + nx].copy_from_slice(&bg_label);
            for bi in 0..index.nb[0] {
                let Some(brick) = index.get(bi, j / BRICK, k / BRICK) else {
                    continue;
                };
                for i in bi * BRICK..((bi + 1) * BRICK).min(nx) {
                    let p = DVec3::new(i as f64 * sx, y, z);
                    let (hu, lum, lab) = self.compose(p, brick, bg[i], bg_label[i], inv_w);
                    bg[i] = hu;
                    lumen[row + i] = lum;
                    labels[row + i] = lab;
                }
            }
            let first = (row + nx * ny * k) as u64;
            match self.quantize {
                None => {
                    for (i, (c, hu)) in ct[row..row + nx].iter_mut().zip(&bg).enumerate() {
                        *c = round_to_i16(
                            hu + sigma * voxel_noise(self.noise_key, first + i as u64) as f64,
                        );
                    }
                }
                Some(q) => {
                    for (i, (c, hu)) in ct[row..row + nx].iter_mut().zip(&bg).enumerate() {
                        let v = hu + sigma * voxel_noise(self.noise_key, first + i as u64) as f64;
                        *c = round_to_i16(round_half_away(v / q) * q);
                    }
                }
            }
        }
    }

    /// HU (noise-free), lumen flag and label of a voxel near the tube or a blob.
    #[inline]
    fn compose(&self, p: DVec3, b: &BrickData, bg: f64, bg_label: u8, inv_w: f64) -> (f64, u8, u8) {
        let mut hit = if b.inside {
            TubeHit::INSIDE
        } else {
            TubeHit::NONE
        };
        let mut outer = hit.outer;
        let pc = if b.inside { 0.0 } else { p.distance(b.center) };
        for &(r0, r1) in if b.inside { &[][..] } else { &b.runs[..] } {
            let (r0, r1) = (r0 as usize, r1 as usize);
            let h = self
                .tube
                .sample(p, &b.segs[r0..r1], &b.seg_dist[r0..r1], pc);
            if h.lumen < hit.lumen {
                hit = h;
            }
            outer = outer.min(h.outer);
        }
        let (mut polyp, mut pocket) = (f64::INFINITY, f64::INFINITY);
        let mut pocket_outer = f64::INFINITY;
        // Small-bowel loop: content, wall and the content's HU.
        let (mut sb, mut sb_outer, mut sb_hu) = (f64::INFINITY, f64::INFINITY, 0.0);
        // Tagged stool: the nearest lump, its HU and whether it is mottled with air.
        let (mut stool, mut stool_hu, mut mottled) = (f64::INFINITY, 0.0, false);
        // Diverticula: the colon's gas outside its wall, in their own wall.
        let mut pouch = f64::INFINITY;
        for &bl in &b.blobs {
            let blob = &self.blobs[bl as usize];
            match blob.kind {
                BlobKind::Polyp => polyp = polyp.min(blob.sdf(p)),
                BlobKind::Pocket => {
                    let d = blob.sdf(p);
                    pocket = pocket.min(d);
                    pocket_outer = pocket_outer.min(d - blob.wall_mm);
                }
                BlobKind::Loop => {
                    let d = blob.sdf(p);
                    if d < sb {
                        (sb, sb_hu) = (d, blob.content_hu);
                    }
                    sb_outer = sb_outer.min(d - blob.wall_mm);
                }
                BlobKind::Stool { mottled: m } => {
                    let d = blob.sdf(p);
                    if d < stool {
                        (stool, stool_hu, mottled) = (d, blob.content_hu, m);
                    }
                }
                BlobKind::Diverticulum => {
                    let d = blob.sdf(p);
                    pouch = pouch.min(d);
                    outer = outer.min(d - blob.wall_mm);
                }
            }
        }
        let lumen = hit.lumen.min(pouch).max(-polyp);
        let m = &self.materials;
        let a = ramp(lumen, inv_w);
        let q = ramp(pocket, inv_w);
        let fluid_frac = if hit.fluid.is_finite() {
            ramp(hit.fluid, inv_w)
        } else {
            0.0
        };
        let content = m.lumen_air + fluid_frac * (hit.fluid_hu - m.lumen_air);
        // Stool replaces the lumen's content where it lies (without stool, the content as
        // it always was).
        let content = if stool.is_finite() {
            content
                + ramp(stool, inv_w)
                    * (if mottled && air_pocket(p) {
                        m.lumen_air
                    } else {
                        stool_hu
                    } - content)
        } else {
            content
        };
        let tissue_hu = m.wall + ramp(polyp, inv_w) * (m.polyp - m.wall);
        let (mut hu, mut lum, mut lab);
        if sb == f64::INFINITY && sb_outer == f64::INFINITY {
            // The colon, polyps and gas pockets only (every phantom without the newer
            // options): exactly the arithmetic it always had.
            let tissue = ramp(outer.min(polyp).min(pocket_outer), inv_w).max((a + q).min(1.0));
            hu = a * content
                + q * m.pocket_air
                + (tissue - a - q).max(0.0) * tissue_hu
                + (1.0 - tissue) * bg;
            (lum, lab) = if lumen < 0.0 {
                (
                    1,
                    if stool < 0.0 {
                        label::STOOL
                    } else if hit.fluid < 0.0 {
                        label::LUMEN_FLUID
                    } else {
                        label::LUMEN_AIR
                    },
                )
            } else if pocket < 0.0 {
                (0, label::SMALL_BOWEL_GAS)
            } else if polyp < 0.0 {
                (0, label::POLYP)
            } else if outer.min(pocket_outer) < 0.0 {
                (0, label::WALL)
            } else {
                (0, bg_label)
            };
        } else {
            // With small-bowel loops: where a loop's content and the colon's lumen overlap
            // (the ileocaecal valve) the colon's content wins, and each one's wall gives way
            // to the other's content, so the two open into each other there.
            let l = ramp(sb, inv_w).min(1.0 - a);
            let tissue = ramp(outer.min(polyp).min(pocket_outer).min(sb_outer), inv_w)
                .max((a + q + l).min(1.0));
            hu = a * content
                + q * m.pocket_air
                + l * sb_hu
                + (tissue - a - q - l).max(0.0) * tissue_hu
                + (1.0 - tissue) * bg;
            (lum, lab) = if lumen < 0.0 {
                (
                    1,
                    if stool < 0.0 {
                        label::STOOL
                    } else if hit.fluid < 0.0 {
                        label::LUMEN_FLUID
                    } else {
                        label::LUMEN_AIR
                    },
                )
            } else if sb < 0.0 {
                // Loops of gas (below the air level) or of contrast.
                (
                    0,
                    if sb_hu < -500.0 {
                        label::SMALL_BOWEL_GAS
                    } else {
                        label::SMALL_BOWEL_FLUID
                    },
                )
            } else if pocket < 0.0 {
                (0, label::SMALL_BOWEL_GAS)
            } else if polyp < 0.0 {
                (0, label::POLYP)
            } else if outer.min(pocket_outer).min(sb_outer) < 0.0 {
                (0, label::WALL)
            } else {
                (0, bg_label)
            };
        }
        if let Some(c) = self.catheter.filter(|_| b.catheter) {
            let (air, plastic, canal) = c.sdfs(p);
            // An anal canal's gas round it is the colon's lowest lumen.
            if canal < 0.5 / inv_w {
                let cg = ramp(canal, inv_w);
                hu = cg * m.lumen_air + (1.0 - cg) * hu;
                if canal < 0.0 {
                    (lum, lab) = (1, label::LUMEN_AIR);
                }
            }
            // Its balloon fills the rectum wall to wall: its air holds the rectum open (lumen),
            // its skin keeps that air apart from the colon's above and below.
            if let Some(bl) = c.balloon {
                let (air, skin) = bl.sdfs(p);
                if air.min(skin) < 0.5 / inv_w {
                    let ba = ramp(air, inv_w);
                    let bs = ramp(skin, inv_w).min(1.0 - ba);
                    hu = ba * m.pocket_air + bs * c.hu + (1.0 - ba - bs) * hu;
                    if air < 0.0 {
                        (lum, lab) = (1, label::RECTAL_BALLOON);
                    } else if skin < 0.0 {
                        (lum, lab) = (0, label::WALL);
                    }
                }
            }
            // The catheter displaces whatever is there: colon content, wall, tissue, outside
            // air. Its air is not colon lumen.
            let plastic_hu = c.hu;
            let ca = ramp(air, inv_w);
            let cp = ramp(plastic, inv_w).min(1.0 - ca);
            hu = ca * m.pocket_air + cp * plastic_hu + (1.0 - ca - cp) * hu;
            if air < 0.0 {
                (lum, lab) = (0, label::RECTAL_TUBE);
            } else if plastic < 0.0 {
                (lum, lab) = (0, label::WALL);
            }
        }
        (hu, lum, lab)
    }
}

/// Nearest integer (halves away from zero) as f64, without a libm call.
#[inline]
fn round_half_away(v: f64) -> f64 {
    let v = v.clamp(-1e15, 1e15);
    (if v >= 0.0 { v + 0.5 } else { v - 0.5 }) as i64 as f64
}

/// Nearest i16 (halves away from zero), saturating; `f64::round` is a libm call on
/// baseline x86-64, and this runs 10⁸ times.
#[inline]
fn round_to_i16(v: f64) -> i16 {
    let v = v.clamp(i16::MIN as f64, i16::MAX as f64);
    (if v >= 0.0 { v + 0.5 } else { v - 0.5 }) as i16
}

fn dmin_all(d: &[f64]) -> f64 {
    d.iter().cloned().fold(f64::INFINITY, f64::min)
}

fn for_each_brick(a: [usize; 3], b: [usize; 3], mut f: impl FnMut([usize; 3])) {
    for bk in a[2]..=b[2] {
        for bj in a[1]..=b[1] {
            for bi in a[0]..=b[0] {
                f([bi, bj, bk]);
            }
        }
    }
}

/// Distance from `p` to the segment [a, b].
#[inline]
pub fn seg_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared().max(1e-18)).clamp(0.0, 1.0);
    p.distance(a + ab * t)
}
