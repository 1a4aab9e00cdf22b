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
//! skin; noise is told from stool by size and by one voxel well above the threshold. The
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

use crate::{Geometry, Volume, anatomy::PatientFrame};

/// HU written for air.
pub const AIR_HU: i16 = -1000;

#[derive(Clone, Debug)]
pub struct CleanseOptions {
    /// Soft tissue (HU): the wall's value, the second material of the model.
    pub tissue_hu: i16,
    /// Soft tissue is at most this (HU): a wall, a fold or a polyp (0–100 HU) at or below it
    /// keeps its value, noise and all.
    pub tissue_max_hu: i16,
}

impl Default for CleanseOptions {
    fn default() -> Self {
        CleanseOptions {
            tissue_hu: 40,
            tissue_max_hu: 100,
        }
    }
}

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

/// Slice `k` (of `out.len()` values) of `hu` with `changes` in (volume indices ascending,
/// and their values).
fn slice_with(hu: &[i16], (voxels, values): (&[u32], &[i16]), k: usize, out: &mut [i16]) {
    let (lo, hi) = ((out.len() * k) as u32, (out.len() * (k + 1)) as u32);
    out.copy_from_slice(&hu[lo as usize..hi as usize]);
    let from = voxels.partition_point(|&v| v < lo);
    let to = voxels.partition_point(|&v| v < hi);
    for (&v, &x) in voxels[from..to].iter().zip(&values[from..to]) {
        out[(v - lo) as usize] = x;
    }
}

/// Where cleansing looks and what it knows of the exam.
pub struct Scene<'a> {
    pub ct: &'a Volume<i16>,
    /// The colon's lumen (non-zero), fluid included; voxels that leave it are set to 0.
    pub lumen: &'a mut Volume<u8>,
    /// The lumen's first and last voxel along each axis.
    pub extent: [[usize; 3]; 2],
    /// Gravity, LPS unit vector.
    pub gravity_lps: glam::DVec3,
    /// Air below this (HU); tagged fluid at or above `fluid_hu`.
    pub air_hu: i16,
    pub fluid_hu: i16,
}

/// Marks in the lumen volume's spare bits while cleansing runs (cleared before it returns):
/// within two voxels of a pool, a pool's core, and the pool.
const NEAR: u8 = 2;
const CORE: u8 = 4;
const POOL: u8 = 8;
/// A lump of stool's tagged voxels and the air pockets inside it (`SOLID`), and with them
/// their partial-volume skin (`LUMP`).
const SOLID: u8 = 16;
const LUMP: u8 = 32;

/// Stool is tagged material outside the lumen with lumen air within this many voxels along
/// an axis: across its partial-volume skin. Contrast in small bowel or bone lies behind the
/// colon's wall and fat, farther than that.
const STOOL_REACH: isize = 2;
/// A lump larger than this (ml) is not stool; one of fewer tagged voxels than this is noise.
const MAX_LUMP_ML: f64 = 20.0;
const MIN_LUMP_VOXELS: usize = 8;
/// How far (voxels) past a lump's tagged voxels its skin and pockets may reach.
const SKIN_VOXELS: usize = 3;

/// A pool too thin for a core is seeded where fluid this far above the fluid threshold lies
/// under lumen air: a plastic pipe's or a wall's noise (≈ 150 ± 20, 40 ± 40 HU) does not
/// reach it.
const LEVEL_MARGIN_HU: i16 = 100;

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
    // Every voxel at or above the fluid threshold, in or out of the lumen (ascending): where
    // lumps of stool are looked for, without a second pass over the box.
    let mut bright: Vec<usize> = Vec::new();
    {
        let m = lumen.data_mut();
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                let row = nx * (j + ny * k);
                for v in row + lo[0]..=row + hi[0] {
                    if hu[v] < fluid_hu {
                        continue;
                    }
                    bright.push(v);
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
        // thin edges and its partial-volume skin, not the noise).
        let inside = |v: usize| {
            let ijk = g.ijk(v);
            (0..3).all(|a| ijk[a] >= lo[a] && ijk[a] <= hi[a])
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
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
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
    let lumps = find_lumps(hu, lumen.data_mut(), &g, &bright, lo, hi, air_hu, fluid_hu);

    // 2. The model, voxel by voxel, over the marked ones (the marks reach 2 voxels past
    // the extent's tagged voxels, which lie inside lo..=hi).
    let t = opts.tissue_hu as f32;
    let t_max = opts.tissue_max_hu;
    let mut voxels = Vec::new();
    let mut cleansed = Vec::new();
    let mut tagged_voxels = 0usize;
    let mut leave = Vec::new();
    let m = lumen.data();
    let (klo, khi) = (lo[2].saturating_sub(2).max(2), (hi[2] + 2).min(nz - 3));
    let (jlo, jhi) = (lo[1].saturating_sub(2).max(2), (hi[1] + 2).min(ny - 3));
    let (ilo, ihi) = (lo[0].saturating_sub(2).max(2), (hi[0] + 2).min(nx - 3));
    for k in klo..=khi {
        for j in jlo..=jhi {
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
                        unmix(
                            h as f32,
                            t,
                            fluid_value(v, hu, m, &cube, fluid_hu, CORE).unwrap_or(h as f32),
                        )
                    }
                } else {
                    // The wall's first voxel: beside lumen that is not air.
                    let by_fluid = ring.iter().any(|&d| {
                        let w = at(d);
                        in_lumen(m[w]) && hu[w] >= air_hu
                    });
                    if !by_fluid || h <= t_max {
                        continue;
                    }
                    match fluid_value(v, hu, m, &cube, fluid_hu, CORE) {
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
    .cleanse(&lumps, &cube);
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
    .find(lumen.data_mut(), lo, hi);
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
            let row = nx * (j + ny * k);
            for x in &mut m[row + lo[0] - 2..=row + hi[0] + 2] {
                *x &= !(NEAR | CORE | POOL | SOLID | LUMP);
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

/// The model's values beside the wall are smoothed with a Gaussian of this σ (mm). They
/// carry the fluid's noise, amplified: the fluid fraction divides by `c − t` (500–900 HU on
/// `ctc/prone-tagged`, and `c` varies along the pool) where air's divides by 1040 HU. On
/// that exam the faces over former fluid were 2.3× as rough as those in air (mean angle
/// between neighbouring faces' normals); 0.75 mm brings it to 1.35× (0.9 mm: 1.3×), and
/// the lumen following the smoothed values to 1.21×, well below the phantom's 3 mm polyps.
const SMOOTH_MM: f64 = 0.75;

/// Smooths the cleansed CT where the surface under former fluid passes: every voxel beside
/// (26 neighbours) a changed one, within two voxels of tagged fluid, whose 3³ holds values
/// on both sides of `surface_hu` (the air level, where the surface cuts the wall), takes the
/// Gaussian ([`SMOOTH_MM`]) mean of the cleansed values within two voxels. Tagged voxels
/// cleansing left (at or above `fluid_hu`) keep theirs, and so do the wall elsewhere and
/// under air.
fn smooth_the_model(
    hu: &[i16],
    g: &Geometry,
    (voxels, values): (&mut Vec<u32>, &mut Vec<i16>),
    (surface_hu, fluid_hu): (i16, i16),
) {
    use rayon::prelude::*;
    let Some((&first, &last)) = voxels.first().zip(voxels.last()) else {
        return;
    };
    let [nx, ny, nz] = g.dims;
    let plane = nx * ny;
    let (k0, k1) = (first as usize / plane, last as usize / plane);
    let (klo, khi) = (
        k0.saturating_sub(1).max(2),
        (k1 + 1).min(nz.saturating_sub(3)),
    );
    if klo > khi {
        return;
    }
    let smoothing = Smoothing {
        hu,
        g,
        voxels,
        values,
        kernel: gaussian_offsets(g.spacing, SMOOTH_MM)
            .into_iter()
            .map(|(d, w)| (Ring::step(g.dims[0], d), w))
            .collect(),
        surface_hu,
        fluid_hu,
    };
    // Slabs of slices, each with its own ring (two slices loaded twice at each seam).
    const SLAB: usize = 16;
    let changes: Vec<(u32, i16)> = (klo..=khi)
        .step_by(SLAB)
        .collect::<Vec<_>>()
        .into_par_iter()
        .flat_map_iter(|from| smoothing.slab(from..=(from + SLAB - 1).min(khi)))
        .collect();
    overwrite(voxels, values, hu, &changes);
}

/// What [`smooth_the_model`] reads: the CT, the change list, the kernel and the levels.
struct Smoothing<'a> {
    hu: &'a [i16],
    g: &'a Geometry,
    voxels: &'a [u32],
    values: &'a [i16],
    kernel: Vec<(RingStep, f64)>,
    surface_hu: i16,
    fluid_hu: i16,
}

impl Smoothing<'_> {
    /// The smoothed values of slices `ks` (each at least two slices inside the volume).
    fn slab(&self, ks: std::ops::RangeInclusive<usize>) -> Vec<(u32, i16)> {
        let [nx, ny, _] = self.g.dims;
        let plane = nx * ny;
        let mut ring = Ring::new(nx, ny);
        let mut seen = vec![false; plane];
        let mut out = Vec::new();
        let (from, to) = (*ks.start(), *ks.end());
        for k in from - 2..=to + 2 {
            ring.load(k, self.hu, self.voxels, self.values);
            if k < from + 2 {
                continue;
            }
            // Slice kc = k − 2 has its two neighbours on each side loaded.
            let kc = k - 2;
            let around = ring.around(kc);
            for c in self.beside_changes(kc, &mut seen) {
                let v = c + plane * kc;
                let now = ring.at(&around, c, (2, 0));
                // Tagged voxels cleansing left (contrast in a small-bowel loop behind the
                // wall) keep their value.
                if (self.hu[v] >= self.fluid_hu && now == self.hu[v])
                    || !ring.surface_near(&around, c, self.surface_hu)
                    || !fluid_near(v, self.g, self.hu, self.fluid_hu)
                {
                    continue;
                }
                let mean: f64 = self
                    .kernel
                    .iter()
                    .map(|&(d, w)| w * ring.at(&around, c, d) as f64)
                    .sum();
                out.push((v as u32, mean.round() as i16));
            }
        }
        out
    }

    /// The voxels of slice `kc` (in-plane indices, ascending) within one voxel in plane of a
    /// changed voxel of slices kc − 1..=kc + 1, two voxels inside the slice's edges. `seen`
    /// (one flag per in-plane voxel, all false) is left as it was.
    fn beside_changes(&self, kc: usize, seen: &mut [bool]) -> Vec<usize> {
        let [nx, ny, _] = self.g.dims;
        let plane = nx * ny;
        let (lo, hi) = ((plane * (kc - 1)) as u32, (plane * (kc + 2)) as u32);
        let from = self.voxels.partition_point(|&v| v < lo);
        let to = self.voxels.partition_point(|&v| v < hi);
        // The changed voxels' places in plane (several slices change at one place, as
        // under a pool's level), then the places beside them.
        let mut changed = Vec::new();
        for &v in &self.voxels[from..to] {
            let r = v as usize % plane;
            if !seen[r] {
                seen[r] = true;
                changed.push(r);
            }
        }
        changed.iter().for_each(|&c| seen[c] = false);
        let mut near = Vec::new();
        for r in changed {
            let (i, j) = (r % nx, r / nx);
            for y in j.saturating_sub(1).max(2)..=(j + 1).min(ny - 3) {
                for x in i.saturating_sub(1).max(2)..=(i + 1).min(nx - 3) {
                    let c = x + nx * y;
                    if !seen[c] {
                        seen[c] = true;
                        near.push(c);
                    }
                }
            }
        }
        near.iter().for_each(|&c| seen[c] = false);
        near.sort_unstable();
        near
    }
}

/// Whether tagged fluid (at or above `fluid_hu` in `hu`) lay within two voxels of `v`.
fn fluid_near(v: usize, g: &Geometry, hu: &[i16], fluid_hu: i16) -> bool {
    let [nx, ny, _] = g.dims;
    (-2isize..=2).any(|dk| {
        (-2isize..=2).any(|dj| {
            let row = v as isize + nx as isize * (dj + ny as isize * dk);
            hu[(row - 2) as usize..=(row + 2) as usize]
                .iter()
                .any(|&h| h >= fluid_hu)
        })
    })
}

/// Offsets within two voxels and their weights (summing to 1) of a Gaussian of `sigma_mm`.
fn gaussian_offsets(spacing: [f64; 3], sigma_mm: f64) -> Vec<([isize; 3], f64)> {
    let mut out = Vec::new();
    for dk in -2isize..=2 {
        for dj in -2isize..=2 {
            for di in -2isize..=2 {
                let d2 = (di as f64 * spacing[0]).powi(2)
                    + (dj as f64 * spacing[1]).powi(2)
                    + (dk as f64 * spacing[2]).powi(2);
                let w = (-d2 / (2.0 * sigma_mm * sigma_mm)).exp();
                if w > 1e-3 {
                    out.push(([di, dj, dk], w));
                }
            }
        }
    }
    let sum: f64 = out.iter().map(|x| x.1).sum();
    out.iter_mut().for_each(|x| x.1 /= sum);
    out
}

/// Five slices of the cleansed CT, slice k at k mod 5.
struct Ring {
    after: Vec<i16>,
    plane: usize,
    /// [`CUBE`] as ring steps.
    cube: [RingStep; 27],
}

/// A step from a voxel of the ring's middle slice k: to slice k − 2 + .0, and by .1 in plane.
type RingStep = (usize, isize);

impl Ring {
    fn new(nx: usize, ny: usize) -> Ring {
        Ring {
            after: vec![0; 5 * nx * ny],
            plane: nx * ny,
            cube: CUBE.map(|d| Ring::step(nx, d)),
        }
    }

    /// Loads slice `k`: `hu` with the changes (`voxels` ascending, `values`) in.
    fn load(&mut self, k: usize, hu: &[i16], voxels: &[u32], values: &[i16]) {
        let slot = (k % 5) * self.plane;
        let out = &mut self.after[slot..slot + self.plane];
        slice_with(hu, (voxels, values), k, out);
    }

    /// The step by `d` (voxels; in slices at most two) in a volume `nx` voxels wide.
    fn step(nx: usize, d: [isize; 3]) -> RingStep {
        ((d[2] + 2) as usize, d[0] + d[1] * nx as isize)
    }

    /// Where slices k − 2..=k + 2 start in the ring (all loaded).
    fn around(&self, k: usize) -> [usize; 5] {
        std::array::from_fn(|n| ((k + n + 3) % 5) * self.plane)
    }

    /// The value a step from in-plane voxel `c` of the middle slice of `around`.
    fn at(&self, around: &[usize; 5], c: usize, (s, d): RingStep) -> i16 {
        self.after[(around[s] + c).wrapping_add_signed(d)]
    }

    /// Whether values on both sides of `surface_hu` lie in the 3³ around in-plane voxel `c`
    /// of the middle slice of `around`.
    fn surface_near(&self, around: &[usize; 5], c: usize, surface_hu: i16) -> bool {
        let below = self.at(around, c, (2, 0)) < surface_hu;
        self.cube
            .iter()
            .any(|&d| (self.at(around, c, d) < surface_hu) != below)
    }
}

/// The 3³ offsets around a voxel.
const CUBE: [[isize; 3]; 27] = {
    let mut out = [[0isize; 3]; 27];
    let mut n = 0;
    while n < 27 {
        out[n] = [
            (n % 3) as isize - 1,
            ((n / 3) % 3) as isize - 1,
            (n / 9) as isize - 1,
        ];
        n += 1;
    }
    out
};

/// Passes of [`peel_spurs`]: a spur up to this many voxels long goes.
const SPUR_PASSES: usize = 4;

/// Spurs of skin that the wall holds by one face, beside what cleansing changed: a voxel
/// outside the lumen, below 0 HU (partial volume, not tissue), with five of its six face
/// neighbours lumen, becomes air and lumen; again, for longer spurs. `voxels` stays
/// ascending.
fn peel_spurs(
    m: &mut [u8],
    hu: &[i16],
    voxels: &mut Vec<u32>,
    values: &mut Vec<i16>,
    join: &mut Vec<usize>,
    six: &[isize; 6],
    air_hu: i16,
) {
    let spur = |m: &[u8], v: usize| {
        m[v] == 0
            && six
                .iter()
                .filter(|&&d| m[(v as isize + d) as usize] & 1 != 0)
                .count()
                >= 5
            && (air_hu..0).contains(&value_after(voxels, values, hu, v))
    };
    let changed = |v: usize| voxels.binary_search(&(v as u32)).is_ok();
    // The first pass looks at every changed voxel and its face neighbours; a later one only
    // at the face neighbours of the voxels just peeled (nothing else changed around the
    // others), that are changed or beside a changed voxel.
    let mut spurs: Vec<usize> = voxels
        .iter()
        .flat_map(|&v| {
            six.iter()
                .map(move |&d| (v as isize + d) as usize)
                .chain([v as usize])
        })
        .filter(|&v| spur(m, v))
        .collect();
    let mut peeled: Vec<(u32, i16)> = Vec::new();
    for _ in 0..SPUR_PASSES {
        spurs.sort_unstable();
        spurs.dedup();
        if spurs.is_empty() {
            break;
        }
        for &v in &spurs {
            m[v] = 1;
            join.push(v);
            peeled.push((v as u32, AIR_HU));
        }
        spurs = spurs
            .iter()
            .flat_map(|&v| six.iter().map(move |&d| (v as isize + d) as usize))
            .filter(|&w| changed(w) || six.iter().any(|&d| changed((w as isize + d) as usize)))
            .filter(|&w| spur(m, w))
            .collect();
    }
    peeled.sort_unstable();
    overwrite(voxels, values, hu, &peeled);
}

/// A voxel's value once cleansed, from the change list `voxels` (ascending) / `values`.
fn value_after(voxels: &[u32], values: &[i16], hu: &[i16], v: usize) -> i16 {
    voxels
        .binary_search(&(v as u32))
        .map_or(hu[v], |n| values[n])
}

/// Writes `changes` (voxel and new value, ascending, each voxel once) over the change list
/// `voxels` / `values` (ascending): a new value replaces the one listed, and a voxel given
/// back its original value `hu` leaves the list.
fn overwrite(voxels: &mut Vec<u32>, values: &mut Vec<i16>, hu: &[i16], changes: &[(u32, i16)]) {
    if changes.is_empty() {
        return;
    }
    let mut all: Vec<(u32, i16)> = Vec::with_capacity(voxels.len() + changes.len());
    let mut old = voxels
        .iter()
        .copied()
        .zip(values.iter().copied())
        .peekable();
    let mut new = changes.iter().copied().peekable();
    loop {
        let next = match (old.peek(), new.peek()) {
            (Some(&(a, _)), Some(&(b, _))) if a < b => old.next(),
            (Some(&(a, _)), Some(&(b, _))) if a == b => {
                old.next();
                new.next()
            }
            (Some(_), None) => old.next(),
            (_, Some(_)) => new.next(),
            (None, None) => break,
        };
        all.extend(next.filter(|&(v, h)| hu[v as usize] != h));
    }
    (*voxels, *values) = all.into_iter().unzip();
}

/// Finds the lumps of tagged stool: tagged voxels not in a pool (outside the lumen, or taken
/// in by segmentation as fluid but joined to no pool's core) with lumen air within
/// [`STOOL_REACH`] voxels along an axis, and the tagged voxels joined to them (26
/// neighbours), at most [`MAX_LUMP_ML`] a lump, marked `SOLID`. Then its skin, marked `LUMP`:
/// every voxel touching it (26 neighbours) that is not lumen, and from there every voxel
/// outside the lumen that is more air than tissue, within [`SKIN_VOXELS`] of the lump's box:
/// the air pockets of mottled stool, and the outer skin the lumen's threshold left out. A
/// lump whose air runs out of that box (a tube's air, the outside) is not stool. Returns
/// each lump's voxels.
#[allow(clippy::too_many_arguments)]
fn find_lumps(
    hu: &[i16],
    m: &mut [u8],
    g: &Geometry,
    bright: &[usize],
    lo: [usize; 3],
    hi: [usize; 3],
    air_hu: i16,
    fluid_hu: i16,
) -> Vec<Vec<usize>> {
    let [nx, ny, _] = g.dims;
    let strides = [1isize, nx as isize, (nx * ny) as isize];
    let six = [1, -1, strides[1], -strides[1], strides[2], -strides[2]];
    let cube26: Vec<isize> = (-1..=1)
        .flat_map(|k| {
            (-1..=1).flat_map(move |j| (-1..=1).map(move |i| i + j * strides[1] + k * strides[2]))
        })
        .filter(|&d| d != 0)
        .collect();
    let in_lumen = |x: u8| x & 1 != 0;
    let within = |v: usize, lo: [usize; 3], hi: [usize; 3]| {
        let ijk = g.ijk(v);
        (0..3).all(|a| ijk[a] >= lo[a] && ijk[a] <= hi[a])
    };
    let max_voxels = (MAX_LUMP_ML * 1000.0 / g.spacing.iter().product::<f64>()) as usize;
    // Tagged and not a pool's: outside the lumen, or a few voxels of it that segmentation
    // took for fluid.
    let solid = |v: usize, m: &[u8]| m[v] & POOL == 0 && hu[v] >= fluid_hu;
    let near_air = |v: usize, m: &[u8]| {
        six.iter().any(|&d| {
            (1..=STOOL_REACH).any(|s| {
                let w = v as isize + d * s;
                w >= 0
                    && (w as usize) < m.len()
                    && in_lumen(m[w as usize])
                    && hu[w as usize] < air_hu
            })
        })
    };
    let mostly_air = mostly_air(air_hu);
    let mut lumps = Vec::new();
    for &v in bright {
        if !solid(v, m) || m[v] & (SOLID | LUMP) != 0 || !near_air(v, m) {
            continue;
        }
        // The lump: flood through tagged voxels (26 neighbours: a corner's partial
        // volume leaves bits of a lump joined by a corner).
        let mut lump = vec![v];
        m[v] |= SOLID;
        let mut next = 0;
        while next < lump.len() && lump.len() <= max_voxels {
            let u = lump[next];
            next += 1;
            for &d in &cube26 {
                let w = (u as isize + d) as usize;
                if within(w, lo, hi) && solid(w, m) && m[w] & SOLID == 0 {
                    m[w] |= SOLID;
                    lump.push(w);
                }
            }
        }
        // Its box, grown by the skin's reach (inside lo..=hi, which lies two voxels
        // inside the volume, so that 26 neighbours never leave it).
        let (mut blo, mut bhi) = (hi, lo);
        for &u in &lump {
            let ijk = g.ijk(u);
            for a in 0..3 {
                (blo[a], bhi[a]) = (blo[a].min(ijk[a]), bhi[a].max(ijk[a]));
            }
        }
        let blo = [0, 1, 2].map(|a| blo[a].saturating_sub(SKIN_VOXELS).max(lo[a]));
        let bhi = [0, 1, 2].map(|a| (bhi[a] + SKIN_VOXELS).min(hi[a]));
        // Stool, not noise on plastic or a wall: one voxel well above the threshold,
        // and a few voxels at least unless it is what a pool left (stool lying in
        // one, mostly taken in with its fluid).
        let by_pool = || {
            lump.iter().any(|&u| {
                cube26
                    .iter()
                    .any(|&d| m[(u as isize + d) as usize] & POOL != 0)
            })
        };
        let mut ok = lump.len() <= max_voxels
            && lump
                .iter()
                .any(|&u| hu[u] >= fluid_hu.saturating_add(LEVEL_MARGIN_HU))
            && (lump.len() >= MIN_LUMP_VOXELS || by_pool());
        if ok {
            // The skin touching the tagged voxels, whatever its value; the air
            // pockets, flooded through air outside the lumen (air that leaves the
            // box is not a pocket); then the pockets' and the skin's own outer
            // skin, more air than tissue.
            let mut grow = |lump: &mut Vec<usize>, from: usize, pred: &dyn Fn(i16) -> bool| {
                let to = lump.len();
                for n in from..to {
                    let u = lump[n] as isize;
                    for dk in -1..=1 {
                        for dj in -1..=1 {
                            for di in -1..=1 {
                                let w = (u + di + dj * strides[1] + dk * strides[2]) as usize;
                                if in_lumen(m[w]) || m[w] & (SOLID | LUMP) != 0 || !pred(hu[w]) {
                                    continue;
                                }
                                if !within(w, blo, bhi) {
                                    ok = false;
                                    continue;
                                }
                                m[w] |= LUMP;
                                lump.push(w);
                            }
                        }
                    }
                }
                to
            };
            grow(&mut lump, 0, &|_| true);
            let mut from = 0;
            loop {
                let before = lump.len();
                from = grow(&mut lump, from, &|h| h < air_hu);
                if lump.len() == before {
                    break;
                }
            }
            grow(&mut lump, 0, &|h| h < mostly_air);
        }
        if !ok {
            // Not stool: its voxels stay marked `LUMP` alone, so that no other seed
            // floods it again (cleared with the other marks), and the pools' model
            // leaves them as they are.
            for &u in &lump {
                m[u] = (m[u] & !SOLID) | LUMP;
            }
            continue;
        }
        lumps.push(lump);
    }
    lumps
}

/// The changes so far, to find what they left floating.
struct Islands<'a> {
    hu: &'a [i16],
    g: &'a Geometry,
    /// Changed voxels (ascending) and their new values.
    voxels: &'a [u32],
    values: &'a [i16],
    /// Lumen voxels that leave it, voxels that join it (ascending).
    leave: &'a [usize],
    join: &'a [usize],
    air_hu: i16,
}

/// The marks of a pool's surroundings or a lump, that [`Islands::find`] looks at.
const MARKED: u8 = NEAR | SOLID | LUMP;
/// Spare bits [`Islands::find`] marks (and clears): a marked voxel solid once cleansed, and
/// one held by the wall beyond (or, among the loose ones, already put in an island).
const STAYS: u8 = 64;
const HELD: u8 = 128;

impl Islands<'_> {
    fn value(&self, v: usize) -> i16 {
        value_after(self.voxels, self.values, self.hu, v)
    }

    /// Outside the lumen `m` once cleansed, at or above the air level.
    fn solid(&self, m: &[u8], v: usize) -> bool {
        self.stays_solid(
            m[v],
            self.leave.binary_search(&v).is_ok(),
            self.join.binary_search(&v).is_ok(),
            self.value(v),
        )
    }

    /// [`Islands::solid`] for a voxel marked `m` before, that `leaves` or `joins` the lumen
    /// and is `value` once cleansed.
    fn stays_solid(&self, m: u8, leaves: bool, joins: bool, value: i16) -> bool {
        let lumen = if m & 1 != 0 { !leaves } else { joins };
        !lumen && value >= self.air_hu
    }

    /// Voxels marked near a pool or in a lump (within lo..=hi grown by one; the marks reach
    /// two past it, and lo..=hi lies two inside the volume) that are solid once cleansed but
    /// joined to nothing solid outside the marks, through face neighbours solid and marked:
    /// ascending. `m` is the lumen before cleansing, with the marks; the two spare bits it
    /// lends are clear again on return.
    fn find(&self, m: &mut [u8], lo: [usize; 3], hi: [usize; 3]) -> Vec<usize> {
        let [nx, ny, _] = self.g.dims;
        let six = [
            1isize,
            -1,
            nx as isize,
            -(nx as isize),
            (nx * ny) as isize,
            -((nx * ny) as isize),
        ];
        let (blo, bhi) = (lo.map(|x| x - 1), hi.map(|x| x + 1));
        // The marked voxels solid once cleansed (by the scan, ascending, so the change lists
        // are read in order), and whether each is held: from outside (a face neighbour
        // outside the lumen, unmarked or past the box, where nothing changed), then through
        // the others.
        let (mut leave, mut join, mut changed) = (
            Ascending::new(self.leave),
            Ascending::new(self.join),
            Ascending::new(self.voxels),
        );
        let mut solid = Vec::new();
        let mut queue = Vec::new();
        for k in blo[2]..=bhi[2] {
            for j in blo[1]..=bhi[1] {
                let row = nx * (j + ny * k);
                for i in blo[0]..=bhi[0] {
                    let v = row + i;
                    if m[v] & MARKED == 0 {
                        continue;
                    }
                    let value = changed
                        .find(v as u32)
                        .map_or(self.hu[v], |n| self.values[n]);
                    if !self.stays_solid(m[v], leave.has(v), join.has(v), value) {
                        continue;
                    }
                    m[v] |= STAYS;
                    solid.push(v);
                    let at = [i, j, k];
                    // Step d of `six` leaves the box: +axis d / 2 at its top, −axis at
                    // its bottom.
                    let past_box = |d: usize| {
                        let a = d / 2;
                        at[a] == if d.is_multiple_of(2) { bhi[a] } else { blo[a] }
                    };
                    let held = (0..6).any(|d| {
                        let w = (v as isize + six[d]) as usize;
                        m[w] & 1 == 0 && (m[w] & MARKED == 0 || past_box(d))
                    });
                    if held {
                        m[v] |= HELD;
                        queue.push(v);
                    }
                }
            }
        }
        let joined = |m: &[u8], w: usize| m[w] & (STAYS | HELD) == STAYS;
        while let Some(v) = queue.pop() {
            for &d in &six {
                let w = (v as isize + d) as usize;
                if joined(m, w) {
                    m[w] |= HELD;
                    queue.push(w);
                }
            }
        }
        // An island with tissue inside it (a voxel of at least 0 HU all of whose neighbours
        // are solid) is a polyp's head on a stalk too thin to show, not skin: it stays.
        let inner = |m: &[u8], v: usize| {
            self.value(v) >= 0
                && six.iter().all(|&d| {
                    let w = (v as isize + d) as usize;
                    m[w] & STAYS != 0 || self.solid(m, w)
                })
        };
        let mut out = Vec::new();
        for &start in &solid {
            if !joined(m, start) {
                continue;
            }
            m[start] |= HELD;
            let mut island = vec![start];
            let mut next = 0;
            while next < island.len() {
                let v = island[next];
                next += 1;
                for &d in &six {
                    let w = (v as isize + d) as usize;
                    if joined(m, w) {
                        m[w] |= HELD;
                        island.push(w);
                    }
                }
            }
            if !island.iter().any(|&v| inner(m, v)) {
                out.extend(island);
            }
        }
        for &v in &solid {
            m[v] &= !(STAYS | HELD);
        }
        out.sort_unstable();
        out
    }
}

/// Look-ups in an ascending list, in ascending order: each costs the steps past the last.
struct Ascending<'a, T> {
    list: &'a [T],
    at: usize,
}

impl<'a, T: Ord + Copy> Ascending<'a, T> {
    fn new(list: &'a [T]) -> Self {
        Ascending { list, at: 0 }
    }

    /// Where `v` is in the list; `v` is at least the last one asked for.
    fn find(&mut self, v: T) -> Option<usize> {
        while self.at < self.list.len() && self.list[self.at] < v {
            self.at += 1;
        }
        (self.list.get(self.at) == Some(&v)).then_some(self.at)
    }

    fn has(&mut self, v: T) -> bool {
        self.find(v).is_some()
    }
}

/// Below this a voxel is more air than soft tissue: halfway between the air level and soft
/// tissue's 40 HU.
fn mostly_air(air_hu: i16) -> i16 {
    ((air_hu as i32 + 40) / 2) as i16
}

/// What cleansing the lumps changes: voxels (ascending), their cleansed values, the voxels
/// that join the lumen, and how many tagged voxels became air.
#[derive(Default)]
struct LumpChanges {
    voxels: Vec<u32>,
    values: Vec<i16>,
    join: Vec<usize>,
    tagged: usize,
}

/// The lumps and what the model needs to cleanse them.
struct Lumps<'a> {
    hu: &'a [i16],
    /// The lumen with the marks of [`find_lumps`].
    m: &'a [u8],
    g: &'a Geometry,
    opts: &'a CleanseOptions,
    air_hu: i16,
    fluid_hu: i16,
}

impl Lumps<'_> {
    /// The pools' model on the lumps: a lump's voxel (tagged, pocket or skin) with wall beside
    /// it (a face neighbour outside the lumen and the lump, more tissue than air) is a
    /// mixture of tissue and stool, unmixed with the local stool value as at a pool's floor
    /// (soft tissue at or below `tissue_max_hu` keeps its value); any other is stool, or
    /// stool and air: air. What ends below the air level joins the lumen.
    fn cleanse(&self, lumps: &[Vec<usize>], cube: &[isize]) -> LumpChanges {
        let mut out = LumpChanges::default();
        let mut changes: Vec<(usize, i16)> = Vec::new();
        for lump in lumps {
            for &v in lump {
                let value = self.model(v, cube);
                let h = self.hu[v];
                if value < self.air_hu {
                    if self.m[v] & 1 == 0 {
                        out.join.push(v);
                    }
                    out.tagged += (h >= self.fluid_hu) as usize;
                }
                if value != h {
                    changes.push((v, value));
                }
            }
        }
        changes.sort_unstable_by_key(|&(v, _)| v);
        out.join.sort_unstable();
        (out.voxels, out.values) = changes.into_iter().map(|(v, h)| (v as u32, h)).unzip();
        out
    }

    fn six(&self) -> [isize; 6] {
        let [nx, ny, _] = self.g.dims;
        let (sy, sz) = (nx as isize, (nx * ny) as isize);
        [1, -1, sy, -sy, sz, -sz]
    }

    /// A lump's voxel's cleansed value.
    fn model(&self, v: usize, cube: &[isize]) -> i16 {
        let (hu, m, air) = (self.hu, self.m, mostly_air(self.air_hu));
        let h = hu[v];
        let wall = self.six().iter().any(|&d| {
            let w = (v as isize + d) as usize;
            m[w] & (1 | SOLID | LUMP) == 0 && hu[w] >= air
        });
        // Beside the wall: below soft tissue's top, the wall itself (or its skin, more air
        // than tissue: the corner where stool, air and wall met, taken as air); brighter,
        // tissue and stool mixed, unmixed, and where that leaves more air than tissue, that
        // corner again.
        if !wall || h < air {
            AIR_HU
        } else if h <= self.opts.tissue_max_hu {
            h
        } else {
            match fluid_value(v, hu, m, cube, self.fluid_hu, SOLID) {
                Some(c) => Some(unmix(h as f32, self.opts.tissue_hu as f32, c))
                    .filter(|&u| u >= air)
                    .unwrap_or(AIR_HU),
                None => h,
            }
        }
    }
}

/// The local tagged fluid's HU: the mean of the brighter half (by range, above the midpoint
/// of the fluid threshold and the brightest) of the pools' core voxels in the 5³ cube
/// around `v` (a core voxel may be the pool's partial-volume skin); None when there is none.
fn fluid_value(
    v: usize,
    hu: &[i16],
    m: &[u8],
    cube: &[isize],
    fluid_hu: i16,
    mark: u8,
) -> Option<f32> {
    let core = |d: isize| {
        let w = (v as isize + d) as usize;
        (m[w] & mark != 0 && hu[w] >= fluid_hu).then_some(hu[w])
    };
    let max = cube.iter().filter_map(|&d| core(d)).max()?;
    let half = ((max as i32 + fluid_hu as i32) / 2) as i16;
    let (sum, n) = cube
        .iter()
        .filter_map(|&d| core(d))
        .filter(|&h| h >= half)
        .fold((0f32, 0f32), |(s, n), h| (s + h as f32, n + 1.0));
    Some(sum / n)
}

/// A tissue–fluid mixture of value `h` (soft tissue `t`, fluid `c`) with its fluid made air.
fn unmix(h: f32, t: f32, c: f32) -> i16 {
    if c <= t + 1.0 {
        return h as i16;
    }
    let f = ((h - t) / (c - t)).clamp(0.0, 1.0);
    ((1.0 - f) * t + f * AIR_HU as f32).round() as i16
}

#[cfg(test)]
mod tests {
    use super::*;
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

    #[test]
    fn unmixing_keeps_the_tissue_fraction() {
        assert_eq!(unmix(600.0, 40.0, 600.0), AIR_HU);
        assert_eq!(unmix(320.0, 40.0, 600.0), -480);
        assert_eq!(unmix(40.0, 40.0, 600.0), 40);
    }
}
