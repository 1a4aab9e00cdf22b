//! Lumps of tagged stool on the wall: found beside lumen air outside the pools, with their
//! air pockets and skin, and cleansed with the pools' model.

use super::{
    marks::{LUMP, POOL, SOLID},
    model::{AIR_HU, CleanseOptions, FluidWindow, LEVEL_MARGIN_HU, mostly_air, unmix},
};
use crate::Geometry;

/// Stool is tagged material outside the lumen with lumen air within this many voxels along
/// an axis: across its partial-volume skin. Contrast in small bowel or bone lies behind the
/// colon's wall and fat, farther than that.
const STOOL_REACH: isize = 2;
/// A lump larger than this (ml) is not stool; one of fewer tagged voxels than this is noise.
const MAX_LUMP_ML: f64 = 20.0;
const MIN_LUMP_VOXELS: usize = 8;
/// How far (voxels) past a lump's tagged voxels its skin and pockets may reach.
const SKIN_VOXELS: usize = 3;

/// Whether lumen air (a voxel with `m`'s bit 0 set, below `air_hu`) lies within [`STOOL_REACH`] voxels of
/// `v` along an axis (`six`: the face neighbours' steps): where a lump of stool may start.
pub(super) fn near_lumen_air(
    v: usize,
    hu: &[i16],
    m: &[u8],
    six: &[isize; 6],
    air_hu: i16,
) -> bool {
    six.iter().any(|&d| {
        (1..=STOOL_REACH).any(|s| {
            let w = v as isize + d * s;
            w >= 0 && (w as usize) < m.len() && m[w as usize] & 1 != 0 && hu[w as usize] < air_hu
        })
    })
}

/// Finds the lumps of tagged stool: `seeds` (ascending: tagged voxels with lumen air within
/// [`STOOL_REACH`] voxels along an axis, [`near_lumen_air`]) not in a pool (outside the
/// lumen, or taken in by segmentation as fluid but joined to no pool's core), and the tagged
/// voxels joined to them (26
/// neighbours), at most [`MAX_LUMP_ML`] a lump, marked `SOLID`. Then its skin, marked `LUMP`:
/// every voxel touching it (26 neighbours) that is not lumen, and from there every voxel
/// outside the lumen that is more air than tissue, within [`SKIN_VOXELS`] of the lump's box:
/// the air pockets of mottled stool, and the outer skin the lumen's threshold left out. A
/// lump whose air runs out of that box (a tube's air, the outside) is not stool. Returns
/// each lump's voxels.
#[allow(clippy::too_many_arguments)]
pub(super) fn find_lumps(
    hu: &[i16],
    m: &mut [u8],
    g: &Geometry,
    seeds: &[u32],
    lo: [usize; 3],
    hi: [usize; 3],
    air_hu: i16,
    fluid_hu: i16,
) -> Vec<Vec<usize>> {
    let [nx, ny, _] = g.dims;
    let strides = [1isize, nx as isize, (nx * ny) as isize];
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
    let mostly_air = mostly_air(air_hu);
    let mut lumps = Vec::new();
    for v in seeds.iter().map(|&v| v as usize) {
        if !solid(v, m) || m[v] & (SOLID | LUMP) != 0 {
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
                // The box test last: it divides, and most neighbours are taken already.
                if solid(w, m) && m[w] & SOLID == 0 && within(w, lo, hi) {
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

/// What cleansing the lumps changes: voxels (ascending), their cleansed values, the voxels
/// that join the lumen, and how many tagged voxels became air.
#[derive(Default)]
pub(super) struct LumpChanges {
    pub(super) voxels: Vec<u32>,
    pub(super) values: Vec<i16>,
    pub(super) join: Vec<usize>,
    pub(super) tagged: usize,
}

/// The lumps and what the model needs to cleanse them.
pub(super) struct Lumps<'a> {
    pub(super) hu: &'a [i16],
    /// The lumen with the marks of [`find_lumps`].
    pub(super) m: &'a [u8],
    pub(super) g: &'a Geometry,
    pub(super) opts: &'a CleanseOptions,
    pub(super) air_hu: i16,
    pub(super) fluid_hu: i16,
}

impl Lumps<'_> {
    /// The pools' model on the lumps: a lump's voxel (tagged, pocket or skin) with wall beside
    /// it (a face neighbour outside the lumen and the lump, more tissue than air) is a
    /// mixture of tissue and stool, unmixed with the local stool value as at a pool's floor
    /// (soft tissue at or below `tissue_max_hu` keeps its value); any other is stool, or
    /// stool and air: air. What ends below the air level joins the lumen.
    pub(super) fn cleanse(&self, lumps: &[Vec<usize>]) -> LumpChanges {
        let mut out = LumpChanges::default();
        let mut changes: Vec<(usize, i16)> = Vec::new();
        let [nx, ny, _] = self.g.dims;
        let mut fluid = FluidWindow::new(self.hu, self.m, [nx, ny], self.fluid_hu, SOLID);
        for lump in lumps {
            for &v in lump {
                let value = self.model(v, &mut fluid);
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
    fn model(&self, v: usize, fluid: &mut FluidWindow) -> i16 {
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
            match fluid.at(v) {
                Some(c) => Some(unmix(h as f32, self.opts.tissue_hu as f32, c))
                    .filter(|&u| u >= air)
                    .unwrap_or(AIR_HU),
                None => h,
            }
        }
    }
}
