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
pub(super) const STOOL_REACH: isize = 2;
/// A lump larger than this (ml) is not stool; one of fewer tagged voxels than this is noise.
const MAX_LUMP_ML: f64 = 20.0;
const MIN_LUMP_VOXELS: usize = 8;
/// How far (voxels) past a lump's tagged voxels its skin and pockets may reach.
const SKIN_VOXELS: usize = 3;
/// The lumen air beside a lump is one, when it is, within this far (mm) of the lump's box:
/// round a fold, past a lump lying in the lumen.
const ONE_AIR_MM: f64 = 10.0;

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
            // Tagged material in a thin wall's fold between two loops touches the air of
            // both: cleansed as stool, with its skin, it would open a hole between them
            // (a prone exam with its tagging half as bright: the centerline went from the
            // hepatic flexure to the cecum through one, 300 mm of colon left out).
            ok = ok && !between_loops(&lump, &cube26, m, hu, g, air_hu);
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

/// Whether the lumen air touching `lump` (its 26 neighbours, steps `cube26`; `m`'s bit 0 is
/// the lumen) lies in two parts or more that do not meet within [`ONE_AIR_MM`] of the lump's
/// box, each reaching that far. A lump lies two voxels inside the volume, as
/// [`find_lumps`] keeps it.
fn between_loops(
    lump: &[usize],
    cube26: &[isize],
    m: &[u8],
    hu: &[i16],
    g: &Geometry,
    air_hu: i16,
) -> bool {
    let air = |w: usize| m[w] & 1 != 0 && hu[w] < air_hu;
    let [nx, ny, nz] = g.dims;
    let strides = [1isize, nx as isize, (nx * ny) as isize];
    let mut touching: Vec<usize> = lump
        .iter()
        .flat_map(|&u| cube26.iter().map(move |&d| (u as isize + d) as usize))
        .filter(|&w| air(w))
        .collect();
    touching.sort_unstable();
    touching.dedup();
    if touching.is_empty() {
        return false;
    }
    // The box: the lump's, grown by the margin, inside the volume.
    let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
    for &u in lump {
        let ijk = g.ijk(u);
        for a in 0..3 {
            (lo[a], hi[a]) = (lo[a].min(ijk[a]), hi[a].max(ijk[a]));
        }
    }
    let reach = g.spacing.map(|s| (ONE_AIR_MM / s).ceil() as usize);
    let lo = [0, 1, 2].map(|a| lo[a].saturating_sub(reach[a]));
    let hi = [0, 1, 2].map(|a| (hi[a] + reach[a]).min([nx, ny, nz][a] - 1));
    let w = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
    let local = |v: usize| {
        let ijk = g.ijk(v);
        (ijk[0] - lo[0]) + w[0] * ((ijk[1] - lo[1]) + w[1] * (ijk[2] - lo[2]))
    };
    // Floods through the air in the box (six neighbours: the lumen's own connectivity),
    // breadth first, from each touching voxel no flood has reached yet. Beside stool on one
    // loop's wall the first reaches them all within a few voxels. A part that stays inside
    // the box is an air pocket of mottled stool, not a loop.
    let mut seen = vec![0u8; w[0] * w[1] * w[2]];
    const SEEN: u8 = 1;
    const TOUCHING: u8 = 2;
    for &t in &touching {
        seen[local(t)] = TOUCHING;
    }
    let mut left = touching.len();
    let mut loops = 0;
    for &start in &touching {
        if seen[local(start)] & SEEN != 0 {
            continue;
        }
        seen[local(start)] |= SEEN;
        left -= 1;
        let mut open = false;
        let mut queue = std::collections::VecDeque::from([start]);
        while let Some(u) = queue.pop_front() {
            if left == 0 && loops == 0 {
                return false;
            }
            let ijk = g.ijk(u);
            for a in 0..3 {
                for up in [false, true] {
                    if (!up && ijk[a] == lo[a]) || (up && ijk[a] == hi[a]) {
                        open = true;
                        continue;
                    }
                    let q = if up {
                        u as isize + strides[a]
                    } else {
                        u as isize - strides[a]
                    } as usize;
                    let s = &mut seen[local(q)];
                    if *s & SEEN == 0 && air(q) {
                        left -= (*s & TOUCHING != 0) as usize;
                        *s |= SEEN;
                        queue.push_back(q);
                    }
                }
            }
        }
        loops += open as usize;
        if loops >= 2 {
            return true;
        }
    }
    false
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Two loops' air (x ≤ 14 and x ≥ `far`) either side of a wall, and a bright lump of
    /// 3 × 5 × 5 voxels in the wall at x = 15..=17 (with `pocket`, a voxel of lumen air in
    /// it: mottled stool whose bubble segmentation took for gas): the lumps found.
    fn lumps_in_a_wall(far: usize, pocket: bool) -> Vec<Vec<usize>> {
        let g = Geometry::new([40, 30, 30], [1.0; 3], [0.0; 3]).unwrap();
        let (mut hu, mut m) = (vec![40i16; g.len()], vec![0u8; g.len()]);
        for k in 2..28 {
            for j in 2..28 {
                for i in (2..=14).chain(far..=37) {
                    let v = g.index(i, j, k);
                    (hu[v], m[v]) = (-1000, 1);
                }
                if (10..15).contains(&j) && (10..15).contains(&k) {
                    for i in 15..=17 {
                        hu[g.index(i, j, k)] = 500;
                    }
                }
            }
        }
        if pocket {
            let v = g.index(16, 12, 12);
            (hu[v], m[v]) = (-1000, 1);
        }
        let seeds: Vec<u32> = (0..g.len())
            .filter(|&v| hu[v] == 500)
            .map(|v| v as u32)
            .collect();
        find_lumps(&hu, &mut m, &g, &seeds, [2; 3], [37, 27, 27], -500, 200)
    }

    #[test]
    fn tagged_material_between_two_loops_is_not_stool() {
        // On the wall of one loop, with wall behind it: stool, mottled or not.
        assert_eq!(lumps_in_a_wall(21, false).len(), 1);
        assert_eq!(lumps_in_a_wall(21, true).len(), 1);
        // Touching the other loop's air too: cleansed, it would open a hole between them.
        assert!(lumps_in_a_wall(18, false).is_empty());
    }
}
