//! The colon's surface: marching cubes at the air/wall boundary, no simplification (paper
//! §4.1: "a small polyp on the surface may be faded out").
//!
//! The scalar is `s = iso − HU` for lumen voxels and `min(iso − HU, −1)` for every other voxel,
//! so the surface wraps exactly the segmented lumen (no other gas, no outside air), while its
//! sub-voxel position still comes from the CT. Beyond the volume's border counts as wall, so the
//! surface is always closed. Normals are the gradient of `s` (of the CT, where it is the CT),
//! pointing into the lumen, where the camera is.
//!
//! The case table is not typed in: it is derived when first used from one rule per cube
//! face — on a face with two diagonal inside corners, each inside corner is cut off on its
//! own. Both cubes sharing a face see the same face, so the surface is watertight.
//!
//! **How it is made fast.** Edge-vertex caches per plane are never cleared: an entry counts
//! only if its id is newer than the layer that may share it. Runs of cubes whose corners are all
//! wall or all lumen are skipped eight at a time. Timings: BENCHMARKS.md.

use std::sync::OnceLock;

use glam::Vec3;

use crate::{Result, Volume, grid::BoxGrid};

/// A triangle mesh in volume-local mm.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }
}

/// The surface and, per triangle, the lumen voxel (volume index) of the cube it came from,
/// which decides its cell.
#[derive(Clone, Debug, Default)]
pub struct Surface {
    pub mesh: Mesh,
    pub owner_voxel: Vec<u32>,
}

/// Marching cubes over `grid` (which must hold the whole lumen, e.g. its bounding box grown
/// by one voxel). `ct`: HU with `iso` as threshold; None: the mask alone, at 0.5.
pub fn extract_surface(
    lumen: &Volume<u8>,
    ct: Option<&Volume<i16>>,
    grid: &BoxGrid,
    iso: f32,
) -> Result<Surface> {
    let s = Scalar::new(lumen, ct, grid, iso);
    let sp = lumen.spacing();
    let spacing = Vec3::new(sp[0] as f32, sp[1] as f32, sp[2] as f32);
    Ok(march(&s, spacing, lumen.dims()))
}

/// The scalar over the box plus one layer of wall all round ("padded" coordinates: padded
/// (1, 1, 1) is the box's first voxel), computed where it is needed rather than stored: only
/// the voxels beside the surface are ever read. Its sign is the lumen mask's.
struct Scalar<'a> {
    /// Padded dims.
    dims: [usize; 3],
    /// Volume voxel of padded (1,1,1).
    lo: [usize; 3],
    lumen: &'a Volume<u8>,
    ct: Option<&'a Volume<i16>>,
    iso: f32,
}

impl<'a> Scalar<'a> {
    fn new(lumen: &'a Volume<u8>, ct: Option<&'a Volume<i16>>, grid: &BoxGrid, iso: f32) -> Self {
        Scalar {
            dims: grid.dims.map(|d| d + 2),
            lo: grid.lo,
            lumen,
            ct,
            iso,
        }
    }

    /// The volume voxel of a padded position, None in the padding.
    #[inline]
    fn voxel(&self, p: [usize; 3]) -> Option<usize> {
        if (0..3).any(|a| p[a] == 0 || p[a] == self.dims[a] - 1) {
            return None;
        }
        let g = [0, 1, 2].map(|a| p[a] - 1 + self.lo[a]);
        Some(self.lumen.geometry().index(g[0], g[1], g[2]))
    }

    /// s at a padded position: positive (≥ 0.5) in the lumen, ≤ −1 elsewhere.
    #[inline]
    fn value(&self, p: [usize; 3]) -> f32 {
        self.voxel(p).map_or(-1.0, |v| self.value_at(v))
    }

    /// s at volume voxel `v` (not padding).
    #[inline(always)]
    fn value_at(&self, v: usize) -> f32 {
        let m = self.lumen.data()[v] != 0;
        match self.ct {
            Some(ct) => {
                let x = self.iso - ct.data()[v] as f32;
                if m { x.max(0.5) } else { x.min(-1.0) }
            }
            None => {
                if m {
                    0.5
                } else {
                    -0.5
                }
            }
        }
    }

    /// Whether all six neighbours of padded p are box voxels (not padding), so that
    /// [`Scalar::gradient_inside`] applies. Every vertex of a lumen that does not touch the
    /// volume's border is such a point.
    #[inline]
    fn neighbours_in_box(&self, p: [usize; 3]) -> bool {
        (0..3).all(|a| p[a] >= 2 && p[a] + 3 <= self.dims[a])
    }

    /// [`Scalar::gradient`] at padded p whose neighbours are all in the box (volume index `v`):
    /// the same central differences, addressed by strides instead of bounds-checked positions.
    #[inline]
    fn gradient_inside(&self, v: usize, spacing: Vec3) -> Vec3 {
        let [nx, ny, _] = self.lumen.dims();
        let d = |stride: usize| (self.value_at(v + stride) - self.value_at(v - stride)) / 2.0;
        Vec3::new(d(1) / spacing.x, d(nx) / spacing.y, d(nx * ny) / spacing.z)
    }

    /// The cube-face codes of padded x `lo..=hi` into `out[lo..=hi]`: bit b set where padded
    /// row `rows[b]` = (j, k) is lumen at that x (padding is not).
    fn face_codes(&self, rows: [usize; 4], lo: usize, hi: usize, out: &mut [u8]) {
        out[lo..=hi].fill(0);
        let ny = self.dims[1];
        for (bit, &r) in rows.iter().enumerate() {
            let Some(row) = self.mask_row(r % ny, r / ny) else {
                continue;
            };
            // Padded x is mask x + 1; the padding columns 0 and n + 1 stay 0.
            let (a, b) = (lo.max(1), hi.min(row.len()));
            if a > b {
                continue;
            }
            for (o, &m) in out[a..=b].iter_mut().zip(&row[a - 1..b]) {
                *o |= ((m != 0) as u8) << bit;
            }
        }
    }

    /// Padded x of the first lumen voxel of padded row (j, k) and one past its last; (0, 0)
    /// when the row has none.
    fn row_span(&self, j: usize, k: usize) -> (usize, usize) {
        let found = self
            .mask_row(j, k)
            .and_then(|row| crate::grid::first_and_last(row, &|m: u8| m != 0));
        found.map_or((0, 0), |(first, last)| (first + 1, last + 2))
    }

    /// The lumen mask along padded row (j, k) without its two padding columns; None for a
    /// row of padding.
    fn mask_row(&self, j: usize, k: usize) -> Option<&'a [u8]> {
        if j == 0 || k == 0 || j == self.dims[1] - 1 || k == self.dims[2] - 1 {
            return None;
        }
        let start = self
            .lumen
            .geometry()
            .index(self.lo[0], j - 1 + self.lo[1], k - 1 + self.lo[2]);
        Some(&self.lumen.data()[start..start + self.dims[0] - 2])
    }

    /// Central-difference gradient at padded voxel p, one-sided at the padding's edge.
    fn gradient(&self, p: [usize; 3], spacing: Vec3) -> Vec3 {
        let mut g = [0.0f32; 3];
        for (a, slot) in g.iter_mut().enumerate() {
            let (mut lo, mut hi) = (p, p);
            lo[a] = p[a].saturating_sub(1);
            hi[a] = (p[a] + 1).min(self.dims[a] - 1);
            let steps = (hi[a] - lo[a]) as f32;
            if steps > 0.0 {
                *slot = (self.value(hi) - self.value(lo)) / steps;
            }
        }
        Vec3::new(g[0] / spacing.x, g[1] / spacing.y, g[2] / spacing.z)
    }
}

/// Cube corner `c` (bits x, y, z) as an offset.
const fn corner(c: usize) -> [usize; 3] {
    [c & 1, (c >> 1) & 1, (c >> 2) & 1]
}

/// The 12 cube edges as corner pairs; edges 0–3 run along x, 4–7 along y, 8–11 along z.
const EDGES: [(usize, usize); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

fn edge_of(a: usize, b: usize) -> usize {
    EDGES
        .iter()
        .position(|&(p, q)| (p, q) == (a.min(b), a.max(b)))
        .expect("corners share an edge")
}

/// Triangles (as cube edges) for each of the 256 inside/outside patterns.
fn case_table() -> &'static [Vec<[u8; 3]>; 256] {
    static TABLE: OnceLock<[Vec<[u8; 3]>; 256]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(triangulate_case))
}

/// The six faces, corners in counter-clockwise order seen from outside the cube.
fn faces() -> [[usize; 4]; 6] {
    let mut out = [[0; 4]; 6];
    for (f, slot) in out.iter_mut().enumerate() {
        let (axis, side) = (f / 2, f % 2);
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let at = |a: usize, b: usize| (side << axis) | (a << u) | (b << v);
        // Square order (0,0) (1,0) (1,1) (0,1) in the (u, v) plane; u × v = +axis, so this is
        // counter-clockwise seen from +axis: keep it for the far side, reverse for the near.
        let mut q = [at(0, 0), at(1, 0), at(1, 1), at(0, 1)];
        if side == 0 {
            q.reverse();
        }
        *slot = q;
    }
    out
}

/// Derives the triangles of one case: per face, segments from each entry crossing to the
/// next exit crossing (cutting off inside corners one run at a time); chained across faces
/// into closed polygons; fanned into triangles.
fn triangulate_case(case: usize) -> Vec<[u8; 3]> {
    let inside = |c: usize| case >> c & 1 == 1;
    let mut next = [usize::MAX; 12];
    for face in faces() {
        let mut crossings = Vec::new(); // (edge, is_entry)
        for t in 0..4 {
            let (a, b) = (face[t], face[(t + 1) % 4]);
            if inside(a) != inside(b) {
                crossings.push((edge_of(a, b), inside(b)));
            }
        }
        for (p, &(e, is_entry)) in crossings.iter().enumerate() {
            if !is_entry {
                let (prev, _) = crossings[(p + crossings.len() - 1) % crossings.len()];
                next[prev] = e;
            }
        }
    }
    let mut seen = [false; 12];
    let mut tris = Vec::new();
    for start in 0..12 {
        if next[start] == usize::MAX || seen[start] {
            continue;
        }
        let mut poly = Vec::new();
        let mut e = start;
        while !seen[e] {
            seen[e] = true;
            poly.push(e as u8);
            e = next[e];
        }
        for t in 1..poly.len() - 1 {
            // Reversed fan: with segments entry → exit, this winding puts the normal on the
            // inside (lumen) side; `normals_point_inside` checks it.
            tris.push([poly[0], poly[t + 1], poly[t]]);
        }
    }
    tris
}

/// Vertex ids of the edges of one plane of voxels: x- and y-edges on a z-plane (the z-edges
/// between two planes are kept in the `x` array of one more).
///
/// An entry is valid only if it was made since `since` (vertex ids only grow): a plane's
/// arrays are reused for a later plane without clearing them, which for a box of 300 planes
/// was 400 MB of memset.
struct EdgeCache {
    nx: usize,
    x: Vec<u32>,
    y: Vec<u32>,
    since: u32,
}

impl EdgeCache {
    fn new(nx: usize, ny: usize) -> Self {
        EdgeCache {
            nx,
            x: vec![u32::MAX; nx * ny],
            y: vec![u32::MAX; nx * ny],
            since: 0,
        }
    }
}

/// The id an edge cache entry holds, if it is one made since `since`.
#[inline]
fn cached(entry: u32, since: u32) -> Option<u32> {
    (entry != u32::MAX && entry >= since).then_some(entry)
}

fn march(s: &Scalar, spacing: Vec3, vol_dims: [usize; 3]) -> Surface {
    let table = case_table();
    let [nx, ny, nz] = s.dims;
    let mut out = Surface::default();
    let mut lower = EdgeCache::new(nx, ny);
    let mut upper = EdgeCache::new(nx, ny);
    let mut zed = EdgeCache::new(nx, ny);
    // Per row (j, k): where its lumen voxels lie (padded x, first and one past the last;
    // empty when none). A row of cubes needs work only where one of its four corner rows has
    // lumen, which skips most of the box.
    let row_span: Vec<(usize, usize)> = (0..ny * nz).map(|r| s.row_span(r % ny, r / ny)).collect();
    let plane_has: Vec<bool> = row_span
        .chunks(ny)
        .map(|p| p.iter().any(|r| r.1 > r.0))
        .collect();
    let mut faces = vec![0u8; nx];
    for k in 0..nz - 1 {
        // `lower` is the last layer's `upper` (valid since that layer began); `upper` and the
        // z-edges start empty.
        upper.since = out.mesh.positions.len() as u32;
        zed.since = upper.since;
        if !(plane_has[k] || plane_has[k + 1]) {
            std::mem::swap(&mut lower, &mut upper);
            continue;
        }
        for j in 0..ny - 1 {
            let rows = [
                j + ny * k,
                j + 1 + ny * k,
                j + ny * (k + 1),
                j + 1 + ny * (k + 1),
            ];
            let (lo, hi) = rows
                .iter()
                .map(|&r| row_span[r])
                .filter(|sp| sp.1 > sp.0)
                .fold((usize::MAX, 0), |(lo, hi), sp| (lo.min(sp.0), hi.max(sp.1)));
            if lo > hi {
                continue;
            }
            // Cubes i with a lumen corner at x = i or i + 1.
            let (i_lo, i_hi) = (lo.saturating_sub(1), hi.min(nx - 1));
            // Corner bits of each cube's x = 0 face; the x = 1 face is the next cube's x = 0.
            s.face_codes(rows, i_lo, i_hi, &mut faces);
            let mut i = i_lo;
            while i < i_hi {
                // Eight cubes at once where nine faces in a row are all wall or all lumen (the
                // inside of a wide lumen, the gap between two loops of the colon).
                if i + 8 <= i_hi {
                    let word = |at: usize| {
                        u64::from_le_bytes(faces[at..at + 8].try_into().unwrap_or([1; 8]))
                    };
                    let w = word(i);
                    if w == word(i + 1) && (w == 0 || w == 0x0F0F_0F0F_0F0F_0F0F) {
                        i += 8;
                        continue;
                    }
                }
                // Corner c = x + 2y + 4z: x = 0 corners are bits 0, 2, 4, 6.
                let case = spread(faces[i] as usize) | spread(faces[i + 1] as usize) << 1;
                let cube = i;
                i += 1;
                if case == 0 || case == 255 {
                    continue;
                }
                let i = cube;
                let tris = &table[case];
                let mut vid = [u32::MAX; 12];
                for tri in tris {
                    for &e in tri {
                        let e = e as usize;
                        if vid[e] == u32::MAX {
                            vid[e] = edge_vertex(
                                s,
                                spacing,
                                [i, j, k],
                                e,
                                &mut lower,
                                &mut upper,
                                &mut zed,
                                &mut out.mesh,
                            );
                        }
                    }
                }
                let owner = owner_voxel(s, [i, j, k], case, vol_dims);
                for tri in tris {
                    out.mesh.triangles.push([
                        vid[tri[0] as usize],
                        vid[tri[1] as usize],
                        vid[tri[2] as usize],
                    ]);
                    out.owner_voxel.push(owner);
                }
            }
        }
        std::mem::swap(&mut lower, &mut upper);
    }
    out
}

/// Face bits (y + 2z) → cube corner bits for x = 0 (0, 2, 4, 6).
#[inline]
fn spread(face: usize) -> usize {
    (face & 1) | (face & 2) << 1 | (face & 4) << 2 | (face & 8) << 3
}

/// A lumen corner of the cube, as a volume voxel index.
fn owner_voxel(s: &Scalar, c: [usize; 3], case: usize, vol_dims: [usize; 3]) -> u32 {
    // The first lumen corner (the case has at least one): any lumen voxel of the cube is in
    // the cell of the cube or in a neighbouring one.
    let [a, b, d] = corner(case.trailing_zeros() as usize);
    // Padded → volume: a lumen corner is never in the padding.
    let g = [
        c[0] + a - 1 + s.lo[0],
        c[1] + b - 1 + s.lo[1],
        c[2] + d - 1 + s.lo[2],
    ];
    (g[0] + vol_dims[0] * (g[1] + vol_dims[1] * g[2])) as u32
}

/// The vertex on cube edge `e` of the cube at padded `c`, made once and shared.
#[allow(clippy::too_many_arguments)]
fn edge_vertex(
    s: &Scalar,
    spacing: Vec3,
    c: [usize; 3],
    e: usize,
    lower: &mut EdgeCache,
    upper: &mut EdgeCache,
    zed: &mut EdgeCache,
    mesh: &mut Mesh,
) -> u32 {
    let (a, b) = EDGES[e];
    let pa = corner(a).map(|o| o);
    let pb = corner(b);
    let ga = [c[0] + pa[0], c[1] + pa[1], c[2] + pa[2]];
    let gb = [c[0] + pb[0], c[1] + pb[1], c[2] + pb[2]];
    let nx = lower.nx;
    let slot = ga[0] + nx * ga[1];
    let (cache, since): (&mut u32, u32) = match e {
        0..=3 => {
            if ga[2] == c[2] {
                (&mut lower.x[slot], lower.since)
            } else {
                (&mut upper.x[slot], upper.since)
            }
        }
        4..=7 => {
            if ga[2] == c[2] {
                (&mut lower.y[slot], lower.since)
            } else {
                (&mut upper.y[slot], upper.since)
            }
        }
        _ => (&mut zed.x[slot], zed.since),
    };
    if let Some(id) = cached(*cache, since) {
        return id;
    }
    let fast = s.neighbours_in_box(ga) && s.neighbours_in_box(gb);
    let (va, vb, grad_a, grad_b) = if fast {
        let (a, b) = (s.voxel(ga).unwrap_or(0), s.voxel(gb).unwrap_or(0));
        (
            s.value_at(a),
            s.value_at(b),
            s.gradient_inside(a, spacing),
            s.gradient_inside(b, spacing),
        )
    } else {
        (
            s.value(ga),
            s.value(gb),
            s.gradient(ga, spacing),
            s.gradient(gb, spacing),
        )
    };
    let t = (va / (va - vb)).clamp(0.0, 1.0);
    let fa = Vec3::new(ga[0] as f32, ga[1] as f32, ga[2] as f32);
    let fb = Vec3::new(gb[0] as f32, gb[1] as f32, gb[2] as f32);
    // Padded index 1 is volume index lo; positions in volume-local mm.
    let lo = Vec3::new(s.lo[0] as f32, s.lo[1] as f32, s.lo[2] as f32) - Vec3::ONE;
    let p = (fa + (fb - fa) * t + lo) * spacing;
    let n = grad_a * (1.0 - t) + grad_b * t;
    let id = mesh.positions.len() as u32;
    mesh.positions.push(p.to_array());
    mesh.normals.push(n.normalize_or_zero().to_array());
    *cache = id;
    id
}

/// The surface's roughness: the mean angle (degrees) between neighbouring triangles, apart
/// for the rest (air) and for triangles near tagged material in the original CT (a voxel at
/// or above `fluid_hu` at the triangle's centre, or 1 mm or `near_mm` from it along an
/// axis). None for a class with no triangle pair.
pub fn roughness(
    mesh: &Mesh,
    ct: &Volume<i16>,
    fluid_hu: i16,
    near_mm: f64,
) -> (Option<f64>, Option<f64>) {
    use rayon::prelude::*;
    let g: &crate::Geometry = ct.geometry();
    let tri = &mesh.triangles;
    let pos = &mesh.positions;
    let normal = |t: &[u32; 3]| {
        let p = t.map(|i| glam::Vec3::from_array(pos[i as usize]));
        (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero()
    };
    // Samples: the centre, and 1 mm and `near_mm` from it along each axis.
    let mut offsets = vec![glam::DVec3::ZERO];
    for a in 0..3 {
        for d in [-near_mm, -1.0, 1.0, near_mm] {
            let mut o = glam::DVec3::ZERO;
            o[a] = d;
            offsets.push(o);
        }
    }
    let near_fluid: Vec<bool> = tri
        .par_iter()
        .map(|t| {
            let c = t.iter().fold(glam::DVec3::ZERO, |s, &i| {
                s + glam::Vec3::from_array(pos[i as usize]).as_dvec3()
            }) / 3.0;
            offsets.iter().any(|&o| {
                let q = [0, 1, 2].map(|a| ((c[a] + o[a]) / g.spacing[a]).round() as i64);
                (0..3).all(|a| q[a] >= 0 && q[a] < g.dims[a] as i64)
                    && ct.data()[g.index(q[0] as usize, q[1] as usize, q[2] as usize)] >= fluid_hu
            })
        })
        .collect();
    // Neighbouring triangles share an edge: sort the edges, pairs are adjacent.
    let mut edges: Vec<(u64, u32)> = tri
        .iter()
        .enumerate()
        .flat_map(|(n, t)| {
            (0..3).map(move |e| {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                (((a.min(b) as u64) << 32) | a.max(b) as u64, n as u32)
            })
        })
        .collect();
    edges.par_sort_unstable();
    let mut sums = [(0f64, 0usize); 2];
    for w in edges.windows(2) {
        if w[0].0 != w[1].0 {
            continue;
        }
        let (a, b) = (&tri[w[0].1 as usize], &tri[w[1].1 as usize]);
        let angle = normal(a)
            .dot(normal(b))
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees() as f64;
        let class = (near_fluid[w[0].1 as usize] || near_fluid[w[1].1 as usize]) as usize;
        sums[class].0 += angle;
        sums[class].1 += 1;
    }
    let mean = |(s, n): (f64, usize)| (n > 0).then(|| s / n as f64);
    (mean(sums[0]), mean(sums[1]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Geometry, grid::bounding_box};
    use std::collections::HashMap;

    fn ball(dims: [usize; 3], sp: [f64; 3], c: [f64; 3], r: f64) -> Volume<u8> {
        let g = Geometry::new(dims, sp, [0.0; 3]).unwrap();
        let data = (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                let p = [
                    i as f64 * sp[0] - c[0],
                    j as f64 * sp[1] - c[1],
                    k as f64 * sp[2] - c[2],
                ];
                ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() < r) as u8
            })
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    /// A CT that matches the ball: −1000 inside, 40 outside, linear across one voxel.
    fn ball_ct(m: &Volume<u8>, c: [f64; 3], r: f64) -> Volume<i16> {
        let g = m.geometry().clone();
        let sp = g.spacing;
        let data = (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                let p = [
                    i as f64 * sp[0] - c[0],
                    j as f64 * sp[1] - c[1],
                    k as f64 * sp[2] - c[2],
                ];
                let d = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - r; // signed, mm
                let t = (d / sp[0] + 0.5).clamp(0.0, 1.0);
                (-1000.0 + 1040.0 * t).round() as i16
            })
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    /// A ball of radius `r` mm around `c` (0.8 × 0.8 × 1.1 mm voxels), its CT, and the
    /// lumen's box.
    fn ball_study(c: [f64; 3], r: f64) -> (Volume<u8>, Volume<i16>, BoxGrid) {
        let m = ball([32, 30, 26], [0.8, 0.8, 1.1], c, r);
        let ct = ball_ct(&m, c, r);
        let grid = bounding_box(&m, 1, |v| v != 0).unwrap();
        (m, ct, grid)
    }

    #[test]
    fn every_case_gives_closed_polygons() {
        for case in 1..255 {
            let tris = &case_table()[case];
            assert!(!tris.is_empty(), "case {case}");
            // Every crossed edge appears in the triangulation.
            for (e, &(a, b)) in EDGES.iter().enumerate() {
                let crossed = (case >> a & 1) != (case >> b & 1);
                let used = tris.iter().any(|t| t.contains(&(e as u8)));
                assert_eq!(crossed, used, "case {case} edge {e}");
            }
        }
        assert!(case_table()[0].is_empty() && case_table()[255].is_empty());
    }

    #[test]
    fn ball_surface_is_watertight_inward_and_on_the_sphere() {
        let (c, r) = ([12.0, 11.0, 13.0], 8.0);
        let (m, ct, grid) = ball_study(c, r);
        for ct in [None, Some(&ct)] {
            let s = extract_surface(&m, ct, &grid, -500.0).unwrap();
            let mesh = &s.mesh;
            assert!(mesh.triangles.len() > 500);
            // Watertight and consistently wound: each directed edge once, its reverse once.
            let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
            for t in &mesh.triangles {
                for e in 0..3 {
                    *edges.entry((t[e], t[(e + 1) % 3])).or_default() += 1;
                }
            }
            for (&(a, b), &n) in &edges {
                assert_eq!(n, 1, "directed edge repeated");
                assert_eq!(
                    edges.get(&(b, a)),
                    Some(&1),
                    "edge without its twin: not closed"
                );
            }
            let centre = Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
            let mut max_err = 0.0f32;
            for t in &mesh.triangles {
                let [a, b, d] = t.map(|v| Vec3::from_array(mesh.positions[v as usize]));
                let face_n = (b - a).cross(d - a);
                let to_centre = centre - (a + b + d) / 3.0;
                assert!(
                    face_n.dot(to_centre) > 0.0,
                    "triangle faces away from the lumen"
                );
            }
            for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
                let p = Vec3::from_array(*p);
                max_err = max_err.max(((p - centre).length() - r as f32).abs());
                assert!(
                    Vec3::from_array(*n).dot(centre - p) > 0.0,
                    "normal points out of the lumen"
                );
            }
            let bound = if ct.is_some() { 0.5 } else { 1.2 };
            assert!(max_err < bound, "surface off the sphere by {max_err} mm");
            // Owners are lumen voxels.
            assert!(s.owner_voxel.iter().all(|&v| m.data()[v as usize] == 1));
        }
    }

    #[test]
    fn stride_gradient_equals_the_checked_one() {
        let (c, r) = ([12.0, 11.0, 13.0], 8.0);
        let (m, ct, grid) = ball_study(c, r);
        let sp = Vec3::new(0.8, 0.8, 1.1);
        for ct in [None, Some(&ct)] {
            let s = Scalar::new(&m, ct, &grid, -500.0);
            let mut inside = 0;
            for k in 0..s.dims[2] {
                for j in 0..s.dims[1] {
                    for i in 0..s.dims[0] {
                        let p = [i, j, k];
                        if !s.neighbours_in_box(p) {
                            continue;
                        }
                        let v = s.voxel(p).unwrap();
                        assert_eq!(s.value_at(v), s.value(p));
                        assert_eq!(s.gradient_inside(v, sp), s.gradient(p, sp), "at {p:?}");
                        inside += 1;
                    }
                }
            }
            assert!(inside > 1000);
        }
    }

    #[test]
    fn lumen_at_the_volume_border_is_closed() {
        let g = Geometry::new([6, 6, 6], [1.0; 3], [0.0; 3]).unwrap();
        let m = Volume::filled(g, 1u8).unwrap();
        let grid = bounding_box(&m, 1, |v| v != 0).unwrap();
        let s = extract_surface(&m, None, &grid, 0.0).unwrap();
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        for t in &s.mesh.triangles {
            for e in 0..3 {
                *edges.entry((t[e], t[(e + 1) % 3])).or_default() += 1;
            }
        }
        assert!(edges.keys().all(|&(a, b)| edges.contains_key(&(b, a))));
    }
}
