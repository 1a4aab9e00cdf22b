//! Electronic cleansing: the colon's tagged fluid becomes air, so that the surface under
//! former fluid is the mucosa, cut at the same air–wall level as everywhere else (the
//! paper's future work: "subtracting residual stool and liquid from the colonic interior").
//!
//! Without it the surface under fluid falls on voxel faces: the lumen takes the fluid, but
//! a fluid–wall boundary (≈ +600 → +40 HU) has no −500 HU crossing, so marching cubes puts
//! every vertex there at the lumen voxel's edge, and the mucosa shows as terraces.
//!
//! The method is a partial-volume model of the three materials (air, soft tissue, tagged
//! fluid), after Serlie et al., with the colon's geometry taken from segmentation instead
//! of from the gradient alone:
//! - Only voxels within two voxels of a pool are looked at. A pool is the lumen's tagged
//!   voxels (at or above the fluid threshold) joined to a core: a tagged voxel with at
//!   least five of six neighbours tagged (fluid, even two voxels deep; a wall's or a
//!   plastic pipe's noise above the threshold makes no core), or fluid 100 HU above the
//!   threshold right under lumen air (a layer one voxel thin). Small-bowel contrast and
//!   bone, outside the colon's lumen and its wall's first voxel, never change.
//! - A lumen voxel there that is not beside the wall, or that has lumen air within two
//!   voxels above it (against gravity), is fluid or the air–fluid layer: it becomes air. So
//!   the level and the layer vanish, and at the three-material corner where the level meets
//!   the wall the voxel is taken as air–fluid, not as tissue (which would leave a rim).
//! - A voxel beside the wall (a lumen voxel with a wall neighbour, or a wall voxel beside
//!   the fluid) brighter than soft tissue can be (100 HU) is a tissue–fluid mixture: with
//!   the local fluid value `c` (the brighter half of the cores' voxels within two voxels)
//!   and soft tissue `t` (40 HU), its fluid fraction is `f = (HU − t) / (c − t)`, and it
//!   becomes `(1 − f)·t + f·AIR`: the same fraction of air. The wall under former fluid then
//!   crosses −500 HU where half of a voxel is tissue, as it does under air, and the surface
//!   is cut there, sub-voxel. (Taking `t` at soft tissue's top instead keeps the values
//!   continuous at 100 HU, but moves the cut to 0.59 tissue: on the full-size phantom the
//!   former fluid's surface was then 0.112 mm from the true wall instead of 0.094, and
//!   11.0° rough instead of 10.0° against 9.6° in air.)
//! - Soft tissue under the fluid (a polyp, a fold) is at or below 100 HU: it keeps its HU.
//!
//! Lumen voxels that the model calls mostly tissue (cleansed value at or above the air
//! level) leave the lumen: they are the wall's partial-volume voxels that the fluid
//! threshold took in.
//!
//! Tagged stool on the wall lies outside the lumen segmentation found (it is not under the
//! gas, as fluid is) or partly in it. A lump is tagged voxels not in a pool with lumen air
//! within two voxels (across its partial-volume skin; contrast in small bowel or bone lies
//! farther, behind wall and fat), flooded through tagged voxels, with its air pockets and its
//! skin; noise is told from stool by size and by one voxel well above the threshold, and
//! tagged material that touches the air of two loops (in the thin wall between them) from
//! stool by that: cleansed with its skin, it would open a hole between the loops. The
//! same model cleanses it: beside the wall tissue and stool are unmixed, elsewhere (and at
//! the corner of stool, air and wall) it is air, and it joins the lumen.
//!
//! Then what the model leaves floating goes: partial-volume skin that no wall holds any more
//! (islands outside the lumen where pools and lumps were, unless they hold tissue inside,
//! as a polyp's head on a stalk too thin to show does), spurs of skin held by one face, and
//! air outside the lumen. Each would otherwise stand as a shard in the surface.
//!
//! The change is kept as a list of voxels with the other value (original or cleansed), so a
//! CT can be switched between the two in place: no second copy of the volume.

mod changes;
mod floating;
mod lumps;
mod marks;
mod model;
mod smooth;

use crate::{Volume, anatomy::PatientFrame};
use changes::{overwrite, slice_with};
use floating::{Islands, peel_spurs};
use lumps::{Lumps, find_lumps, near_lumen_air};
use marks::{CORE, LUMP, NEAR, POOL, RowMarks, RowSpans, SOLID};
pub use model::{AIR_HU, CleanseOptions};
use model::{FluidWindow, LEVEL_MARGIN_HU, unmix};
use smooth::smooth_the_model;

/// What cleansing changed: per voxel (volume index, ascending), the value the CT does not
/// hold now. [`Cleansing::swap`] exchanges them with the CT's.
#[derive(Clone, Debug, Default)]
pub struct Cleansing {
    voxels: Vec<u32>,
    other: Vec<i16>,
    /// Lumen voxels of tagged fluid (at or above the fluid threshold) that were made air.
    pub tagged_voxels: usize,
    /// Lumen voxels that left the lumen (mostly wall, by the model).
    pub left_lumen: usize,
    /// Lumps of tagged stool on the wall (outside the lumen segmentation found) made air,
    /// and their voxels at or above the fluid threshold.
    pub stool_lumps: usize,
    pub stool_voxels: usize,
    /// Voxels that joined the lumen where stool was.
    pub joined_lumen: usize,
}

impl Cleansing {
    pub fn is_empty(&self) -> bool {
        self.voxels.is_empty()
    }

    /// Voxels whose value cleansing changes.
    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    /// The changed voxels (volume indices, ascending).
    pub fn voxels(&self) -> &[u32] {
        &self.voxels
    }

    /// Their other values (see [`Cleansing::swap`]): the cleansed HU while the CT holds the
    /// original.
    pub fn values(&self) -> &[i16] {
        &self.other
    }

    /// Swaps the stored values with the CT's: the original CT becomes the cleansed one, and
    /// back when called again.
    pub fn swap(&mut self, ct: &mut Volume<i16>) {
        let data = ct.data_mut();
        for (&v, o) in self.voxels.iter().zip(self.other.iter_mut()) {
            std::mem::swap(&mut data[v as usize], o);
        }
    }

    /// Slice `k` of `ct` with the other values in (the cleansed CT's slice when `ct` is the
    /// original), into `out` (nx·ny values): for writing it slice by slice, with no copy of
    /// the volume.
    pub fn fill_slice(&self, ct: &Volume<i16>, k: usize, out: &mut [i16]) {
        slice_with(ct.data(), (&self.voxels, &self.other), k, out);
    }

    /// A copy of `ct` with the other values in (the cleansed CT when `ct` is the original).
    pub fn swapped_copy(&self, ct: &Volume<i16>) -> Volume<i16> {
        let mut out = ct.clone();
        let data = out.data_mut();
        for (&v, &o) in self.voxels.iter().zip(&self.other) {
            data[v as usize] = o;
        }
        out
    }
}

/// Where cleansing looks and what it knows of the exam.
pub struct Scene<'a> {
    pub ct: &'a Volume<i16>,
    /// The colon's lumen (non-zero), fluid included; voxels that leave it are set to 0.
    pub lumen: &'a mut Volume<u8>,
    /// The lumen's first and last voxel along each axis: every lumen voxel lies within it
    /// (the pools' flood leaves the box only where the volume's margin clips it).
    pub extent: [[usize; 3]; 2],
    /// Gravity, LPS unit vector.
    pub gravity_lps: glam::DVec3,
    /// Air below this (HU); tagged fluid at or above `fluid_hu`.
    pub air_hu: i16,
    pub fluid_hu: i16,
}

/// The voxels of `row` (a run of indices into `hu`) at or above `fluid_hu`, ascending. Most
/// of the colon's box is air and soft tissue: a chunk with none is passed over by its
/// largest value, which compiles to vector code.
fn bright_in(
    hu: &[i16],
    row: std::ops::RangeInclusive<usize>,
    fluid_hu: i16,
) -> impl Iterator<Item = usize> + '_ {
    const CHUNK: usize = 16;
    let start = *row.start();
    hu[row]
        .chunks(CHUNK)
        .enumerate()
        .filter(move |(_, c)| c.iter().fold(i16::MIN, |a, &h| a.max(h)) >= fluid_hu)
        .flat_map(move |(n, c)| {
            c.iter()
                .enumerate()
                .filter(move |&(_, &h)| h >= fluid_hu)
                .map(move |(i, _)| start + n * CHUNK + i)
        })
}

/// Where a voxel of the colon's box may have the lumen within [`lumps::STOOL_REACH`] voxels
/// along an axis, row by row: every voxel [`near_lumen_air`] or the lumen holds lies there.
struct NearLumen {
    spans: RowSpans,
    lo: [usize; 3],
    hi: [usize; 3],
}

impl NearLumen {
    /// The lumen (`m`'s bit 0) of the box `lo..=hi` grown by the reach, within the volume.
    fn of(m: &[u8], g: &crate::Geometry, lo: [usize; 3], hi: [usize; 3]) -> Self {
        let r = lumps::STOOL_REACH as usize;
        let spans = RowSpans::of(
            m,
            [g.dims[0], g.dims[1]],
            lo.map(|x| x.saturating_sub(r)),
            [0, 1, 2].map(|a| (hi[a] + r).min(g.dims[a] - 1)),
            1,
        );
        NearLumen { spans, lo, hi }
    }

    /// The voxels of row (j, k) within the box that may lie near the lumen, first and last.
    fn row(&self, j: usize, k: usize) -> Option<(usize, usize)> {
        let r = lumps::STOOL_REACH as usize;
        let mut out = self
            .spans
            .get(j, k)
            .map(|(a, b)| (a.saturating_sub(r), b + r));
        for s in 1..=r {
            let across = [
                (j.checked_sub(s), Some(k)),
                (Some(j + s), Some(k)),
                (Some(j), k.checked_sub(s)),
                (Some(j), Some(k + s)),
            ];
            for (y, z) in across {
                if let Some(span) = y.zip(z).and_then(|(y, z)| self.spans.get(y, z)) {
                    out = Some(out.map_or(span, |(a, b)| (a.min(span.0), b.max(span.1))));
                }
            }
        }
        let (a, b) = out?;
        let (a, b) = (a.max(self.lo[0]), b.min(self.hi[0]));
        (a <= b).then_some((a, b))
    }
}

/// Cleanses `scene.ct` in the colon: the changes, to be [`Cleansing::swap`]ped in. Empty when
/// the colon holds no tagged fluid.
pub fn cleanse(scene: Scene, opts: &CleanseOptions) -> Cleansing {
    let Scene {
        ct,
        lumen,
        extent,
        gravity_lps,
        air_hu,
        fluid_hu,
    } = scene;
    let g = ct.geometry().clone();
    let [nx, ny, nz] = g.dims;
    // Two voxels of margin inside the volume, so that no neighbour look-up leaves it.
    let lo = extent[0].map(|x| x.max(2));
    let hi = [0, 1, 2].map(|a| extent[1][a].min(g.dims[a].saturating_sub(3)));
    if (0..3).any(|a| lo[a] > hi[a]) {
        return Cleansing::default();
    }
    let strides = [1isize, nx as isize, (nx * ny) as isize];
    let hu = ct.data();
    let in_lumen = |m: u8| m & 1 != 0;
    let tagged = |v: usize, m: &[u8]| in_lumen(m[v]) && hu[v] >= fluid_hu;

    let offsets = |r: isize| {
        let mut out = Vec::new();
        for dk in -r..=r {
            for dj in -r..=r {
                for di in -r..=r {
                    out.push(di + dj * strides[1] + dk * strides[2]);
                }
            }
        }
        out
    };
    let (cube, ring) = (offsets(2), offsets(1));
    let six = [1, -1, strides[1], -strides[1], strides[2], -strides[2]];
    let (gaxis, gsign) = PatientFrame::of(&g).nearest_axis(gravity_lps);
    let up = -strides[gaxis] * gsign as isize;
    let air_above = |v: usize, m: &[u8]| {
        (1..=2).any(|s| {
            let w = (v as isize + up * s) as usize;
            in_lumen(m[w]) && hu[w] < air_hu
        })
    };
    // 1. The pools' cores: tagged voxels with at least five of their six neighbours tagged
    // (fluid, even in a pool two voxels deep; noise in a wall or in plastic brighter than
    // the threshold here and there makes none), and the seeds of thinner pools: tagged
    // voxels well above the threshold with lumen air just above.
    // Then every voxel within two voxels of a pool is marked.
    let level_hu = fluid_hu.saturating_add(LEVEL_MARGIN_HU);
    let mut queue: Vec<usize> = Vec::new();
    // Every voxel at or above the fluid threshold, in or out of the lumen, with lumen air
    // near (ascending): where lumps of stool are seeded, without a second pass over the box.
    let mut seeds: Vec<u32> = Vec::new();
    {
        let m = lumen.data_mut();
        let near_lumen = NearLumen::of(m, &g, lo, hi);
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                let Some((a, b)) = near_lumen.row(j, k) else {
                    continue;
                };
                let row = nx * (j + ny * k);
                for v in bright_in(hu, row + a..=row + b, fluid_hu) {
                    if near_lumen_air(v, hu, m, &six, air_hu) {
                        seeds.push(v as u32);
                    }
                    if !in_lumen(m[v]) {
                        continue;
                    }
                    if six
                        .iter()
                        .filter(|&&d| tagged((v as isize + d) as usize, m))
                        .count()
                        >= 5
                    {
                        m[v] |= CORE | POOL;
                        queue.push(v);
                    } else if hu[v] >= level_hu && air_above(v, m) {
                        // A pool too thin for a core: a layer under its level.
                        m[v] |= POOL;
                        queue.push(v);
                    }
                }
            }
        }
        // The pools: the tagged voxels joined to a core through tagged voxels (a pool's
        // thin edges and its partial-volume skin, not the noise). Every lumen voxel lies in
        // the extent, so the flood can leave lo..=hi only where the margin clipped it.
        let clipped = lo != extent[0] || hi != extent[1];
        let inside = |v: usize| {
            !clipped || {
                let ijk = g.ijk(v);
                (0..3).all(|a| ijk[a] >= lo[a] && ijk[a] <= hi[a])
            }
        };
        while let Some(v) = queue.pop() {
            for &d in &six {
                let w = (v as isize + d) as usize;
                if m[w] & POOL == 0 && tagged(w, m) && inside(w) {
                    m[w] |= POOL;
                    queue.push(w);
                }
            }
        }
        let pool = |v: isize, m: &[u8]| m[v as usize] & POOL != 0;
        let pools = RowMarks::of(m, [nx, ny], lo, hi);
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                if !pools.any(j, k, POOL) {
                    continue;
                }
                let row = nx * (j + ny * k);
                for v in row + lo[0]..=row + hi[0] {
                    if !pool(v as isize, m) {
                        continue;
                    }
                    if six.iter().all(|&d| pool(v as isize + d, m)) {
                        m[v] |= NEAR;
                        continue;
                    }
                    for &d in &cube {
                        m[(v as isize + d) as usize] |= NEAR;
                    }
                }
            }
        }
    }

    // Lumps of tagged stool on the wall, outside the lumen (step 3 cleanses them; the pools'
    // model leaves them alone).
    let lumps = find_lumps(hu, lumen.data_mut(), &g, &seeds, lo, hi, air_hu, fluid_hu);

    // 2. The model, voxel by voxel, over the marked ones (the marks reach 2 voxels past
    // the extent's tagged voxels, which lie inside lo..=hi).
    let t = opts.tissue_hu as f32;
    let t_max = opts.tissue_max_hu;
    let mut voxels = Vec::new();
    let mut cleansed = Vec::new();
    let mut tagged_voxels = 0usize;
    let mut leave = Vec::new();
    let m = lumen.data();
    // The marks reach two voxels past lo..=hi, which lies two inside the volume.
    let marked = RowMarks::of(m, [nx, ny], lo.map(|x| x - 2), hi.map(|x| x + 2));
    let mut fluid = FluidWindow::new(hu, m, [nx, ny], fluid_hu, CORE);
    let (klo, khi) = (lo[2].saturating_sub(2).max(2), (hi[2] + 2).min(nz - 3));
    let (jlo, jhi) = (lo[1].saturating_sub(2).max(2), (hi[1] + 2).min(ny - 3));
    let (ilo, ihi) = (lo[0].saturating_sub(2).max(2), (hi[0] + 2).min(nx - 3));
    for k in klo..=khi {
        for j in jlo..=jhi {
            if !marked.any(j, k, NEAR) {
                continue;
            }
            let row = nx * (j + ny * k);
            for i in ilo..=ihi {
                let v = row + i;
                if m[v] & NEAR == 0 || m[v] & (SOLID | LUMP) != 0 {
                    continue;
                }
                let h = hu[v];
                let at = |d: isize| (v as isize + d) as usize;
                let new = if in_lumen(m[v]) {
                    if h < air_hu {
                        continue;
                    }
                    // A lump of stool beside the pool is not wall.
                    let by_wall = six.iter().any(|&d| m[at(d)] & (1 | SOLID | LUMP) == 0);
                    if !by_wall || air_above(v, m) {
                        AIR_HU
                    } else if h <= t_max {
                        continue;
                    } else {
                        // No core near: the voxel is as bright as the fluid gets here.
                        unmix(h as f32, t, fluid.at(v).unwrap_or(h as f32))
                    }
                } else {
                    // The wall's first voxel (beside lumen that is not air) brighter than
                    // soft tissue; its value asked first, as most of the wall is tissue.
                    let by_fluid = || {
                        ring.iter().any(|&d| {
                            let w = at(d);
                            in_lumen(m[w]) && hu[w] >= air_hu
                        })
                    };
                    if h <= t_max || !by_fluid() {
                        continue;
                    }
                    match fluid.at(v) {
                        Some(c) => unmix(h as f32, t, c),
                        None => continue,
                    }
                };
                if new != h {
                    tagged_voxels += (in_lumen(m[v]) && h >= fluid_hu && new < air_hu) as usize;
                    voxels.push(v as u32);
                    cleansed.push(new);
                    if in_lumen(m[v]) && new >= air_hu {
                        leave.push(v);
                    }
                }
            }
        }
    }

    // 3. The lumps of stool: made air with the same model.
    let stool = Lumps {
        hu,
        m: lumen.data(),
        g: &g,
        opts,
        air_hu,
        fluid_hu,
    }
    .cleanse(&lumps);
    let (stool_lumps, stool_voxels) = (lumps.len(), stool.tagged);
    let lump_changes: Vec<(u32, i16)> = stool
        .voxels
        .iter()
        .copied()
        .zip(stool.values.iter().copied())
        .collect();
    overwrite(&mut voxels, &mut cleansed, hu, &lump_changes);

    // 4. What is left outside the lumen where pools and lumps were, and that the wall
    // beyond does not hold: islands of partial-volume skin in the new lumen. They are air.
    let mut join = stool.join;
    let islands = Islands {
        hu,
        g: &g,
        voxels: &voxels,
        values: &cleansed,
        leave: &leave,
        join: &join,
        air_hu,
    }
    .find(lumen.data_mut(), lo, hi, &marked);
    if !islands.is_empty() {
        let to_air: Vec<(u32, i16)> = islands.iter().map(|&v| (v as u32, AIR_HU)).collect();
        overwrite(&mut voxels, &mut cleansed, hu, &to_air);
        let m = lumen.data();
        leave.retain(|v| islands.binary_search(v).is_err());
        join.extend(islands.iter().filter(|&&v| m[v] & 1 == 0));
    }

    // 5. Clear the marks (they reach two voxels past lo..=hi, which lies two inside the
    // volume); the wall's voxels leave the lumen, former stool joins it.
    let m = lumen.data_mut();
    for k in lo[2] - 2..=hi[2] + 2 {
        for j in lo[1] - 2..=hi[1] + 2 {
            if !marked.any(j, k, marks::ALL) {
                continue;
            }
            let row = nx * (j + ny * k);
            for x in &mut m[row + lo[0] - 2..=row + hi[0] + 2] {
                *x &= !marks::ALL;
            }
        }
    }
    for &v in &leave {
        m[v] = 0;
    }
    for &v in &join {
        m[v] = 1;
    }
    smooth_the_model(hu, &g, (&mut voxels, &mut cleansed), (air_hu, fluid_hu));
    // Whatever cleansing made air is lumen (the wall's first voxel beside a pool, mostly
    // fluid; a lump's voxel segmentation had taken in and then let go), and whatever it left
    // at or above the air level is not (the smoothing moved some voxels across the level the
    // model had placed them by): the surface is cut between lumen and wall, and air on the
    // wall's side would stand as a shard, wall on the lumen's side as a pit.
    for (&v, &value) in voxels.iter().zip(&cleansed) {
        let v = v as usize;
        let air = value < air_hu;
        if air && m[v] == 0 {
            m[v] = 1;
            join.push(v);
        } else if !air && m[v] != 0 {
            m[v] = 0;
            leave.push(v);
        }
    }
    peel_spurs(m, hu, &mut voxels, &mut cleansed, &mut join, &six, air_hu);
    Cleansing {
        voxels,
        other: cleansed,
        tagged_voxels,
        left_lumen: leave.len(),
        stool_lumps,
        stool_voxels,
        joined_lumen: join.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Geometry;
    use glam::DVec3;

    /// Columns along +y (gravity): lumen air on top, tagged fluid (600 HU) below, then the
    /// wall (40 HU) whose first voxel is half fluid (320 HU); a polyp (60 HU, 3 voxels across,
    /// two high) stands on the wall in the fluid, and a small-bowel loop (500 HU) lies three
    /// voxels into the wall.
    fn scene() -> (Volume<i16>, Volume<u8>) {
        let g = Geometry::new([16, 20, 16], [1.0; 3], [0.0; 3]).unwrap();
        let mut ct = Volume::filled(g.clone(), 40i16).unwrap();
        let mut lumen = Volume::filled(g, 0u8).unwrap();
        for k in 3..13 {
            for i in 3..13 {
                for j in 3..10 {
                    let fluid = j >= 5;
                    ct.set(i, j, k, if fluid { 600 } else { -1000 });
                    lumen.set(i, j, k, 1);
                }
                ct.set(i, 10, k, 320);
                lumen.set(i, 10, k, 1);
                ct.set(i, 14, k, 500);
            }
        }
        // The polyp stands on the wall: 3 mm of tissue across, 2 mm high.
        for k in 4..7 {
            for i in 4..7 {
                for j in 8..10 {
                    ct.set(i, j, k, 60);
                    lumen.set(i, j, k, 0);
                }
            }
        }
        (ct, lumen)
    }

    /// Cleanses [`scene`]'s CT (gravity +y) with tagged fluid at or above `fluid_hu`.
    fn cleanse_scene(ct: &Volume<i16>, lumen: &mut Volume<u8>, fluid_hu: i16) -> Cleansing {
        let scene = Scene {
            ct,
            lumen,
            extent: [[3, 3, 3], [12, 10, 12]],
            gravity_lps: DVec3::Y,
            air_hu: -500,
            fluid_hu,
        };
        cleanse(scene, &CleanseOptions::default())
    }

    #[test]
    fn fluid_becomes_air_and_the_wall_is_cut_as_under_air() {
        let (mut ct, mut lumen) = scene();
        let original = ct.clone();
        let mut c = cleanse_scene(&ct, &mut lumen, 200);
        assert!(!c.is_empty());
        c.swap(&mut ct);
        // Fluid and the level: air (in the corner of three walls, smoothed with them, still
        // on the air's side of the surface).
        assert_eq!(ct.get(9, 6, 9), AIR_HU);
        assert!(ct.get(3, 9, 3) < -500, "{}", ct.get(3, 9, 3));
        // The wall's half-fluid voxel is half air now, as a wall voxel half in air would be
        // (−480 HU; the smoothing leaves a plane where it is), and leaves the lumen (the model
        // calls it mostly wall).
        assert!((ct.get(9, 10, 9) + 480).abs() <= 5, "{}", ct.get(9, 10, 9));
        assert_eq!(lumen.get(9, 10, 9), 0);
        // Lumen and cleansed values agree on every changed voxel: lumen below the air level,
        // wall at or above it. So the wall's 100 half-fluid voxels leave the lumen, and with
        // them five at the pool's edges that the model made air and the smoothing, blending
        // them with the walls round the corner, took just above the air level (−495 HU).
        let (_, before) = scene();
        for v in c.voxels.iter().map(|&v| v as usize) {
            let h = ct.data()[v];
            assert_eq!(lumen.data()[v] != 0, h < -500, "voxel {v}: {h} HU");
        }
        let left = (0..before.data().len())
            .filter(|&v| before.data()[v] != 0 && lumen.data()[v] == 0)
            .count();
        assert_eq!((c.left_lumen, left), (105, 105));
        // The polyp is still tissue (the surface goes round it); the wall beyond the smoothing's
        // reach, and the small bowel behind it, keep their values.
        assert!(ct.get(5, 8, 5) > -500, "{}", ct.get(5, 8, 5));
        assert_eq!((ct.get(9, 12, 9), ct.get(5, 14, 5)), (40, 500));
        // No marks are left in the lumen, and swapping again restores the CT.
        assert!(lumen.data().iter().all(|&m| m <= 1));
        c.swap(&mut ct);
        assert!(ct.data() == original.data());
        let mut slice = vec![0i16; 16 * 20];
        c.fill_slice(&ct, 5, &mut slice);
        assert_eq!(slice[5 + 16 * 6], AIR_HU);
    }

    /// Left floating in the fluid: a sliver of skin (−200 HU, one voxel thin) goes with it;
    /// a 3³ lump of tissue (a polyp's head whose stalk does not show) stays.
    #[test]
    fn islands_of_skin_go_and_of_tissue_stay() {
        let (mut ct, mut lumen) = scene();
        for i in 8..11 {
            for k in 8..11 {
                ct.set(i, 6, k, -200);
                lumen.set(i, 6, k, 0);
            }
        }
        for i in 8..11 {
            for j in 7..10 {
                for k in 3..6 {
                    ct.set(i, j, k, 40);
                    lumen.set(i, j, k, 0);
                }
            }
        }
        let mut c = cleanse_scene(&ct, &mut lumen, 200);
        c.swap(&mut ct);
        assert_eq!((ct.get(9, 6, 9), lumen.get(9, 6, 9)), (AIR_HU, 1));
        assert_eq!(lumen.get(9, 8, 4), 0);
        assert!(ct.get(9, 8, 4) > -500, "{}", ct.get(9, 8, 4));
    }

    #[test]
    fn no_tagged_fluid_changes_nothing() {
        let (ct, mut lumen) = scene();
        assert!(cleanse_scene(&ct, &mut lumen, 1000).is_empty());
    }
}
