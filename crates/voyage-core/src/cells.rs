//! Cells and portals (paper §4.2): the lumen cut into a chain of cells along the centerline,
//! each lumen voxel in exactly one cell, each triangle in exactly one cell, and between
//! consecutive cells a portal.
//!
//! The paper cuts with planes perpendicular to the centerline. A plane, though, also cuts
//! any other loop of the colon it meets (the sigmoid folds back on itself), and two planes a
//! few mm apart cross inside a bend. Here the cuts are level sets of Dt from the source, the
//! geodesic distance through the lumen: they run across the lumen like the paper's planes,
//! but cannot touch another loop, since there the distance is wholly different. And they give
//! the guarantee that visibility relies on: on 26-neighbours Dt changes by at most one voxel
//! diagonal, so when consecutive cuts are farther apart than that, a cell touches only the
//! cells before and after it, and every line of sight from cell a to cell b > a crosses the
//! portals a, a+1, ..., b−1 in order.
//!
//! A portal is stored as the convex hull, in the plane across the centerline, of the voxels
//! on the boundary between its two cells, with a thickness that covers the boundary's depth
//! out of that plane: its projection on screen bounds that of the real boundary.

use glam::DVec3;
use serde::Serialize;

use crate::{
    Error, Result, Volume,
    centerline::Centerline,
    grid::{BrickIndex, Bricked},
    surface::Surface,
};

#[derive(Clone, Debug)]
pub struct CellOptions {
    /// Cut when this much centerline has passed since the last cut (mm)...
    pub max_length_mm: f64,
    /// ...or when the cell holds this many triangles,
    pub max_triangles: usize,
    /// but never closer than this to the last cut (mm).
    pub min_length_mm: f64,
}

impl Default for CellOptions {
    fn default() -> Self {
        CellOptions {
            max_length_mm: 20.0,
            max_triangles: 20_000,
            min_length_mm: 6.0,
        }
    }
}

/// The boundary between cells `c` and `c + 1`.
#[derive(Clone, Debug, Serialize)]
pub struct Portal {
    /// Dt from the source at which the cut lies (mm).
    pub level_mm: f64,
    /// Index of the centerline point nearest the cut.
    pub centerline_index: usize,
    /// Centre and normal (pointing toward the target) of the portal's plane, volume-local mm.
    pub centre_mm: [f64; 3],
    pub normal: [f64; 3],
    /// Convex outline in the plane, volume-local mm, counter-clockwise about `normal`.
    pub polygon_mm: Vec<[f64; 3]>,
    /// Half-thickness (mm): the boundary lies within ±this of the plane, inside the outline.
    pub half_thickness_mm: f64,
}

impl Portal {
    /// The outline moved ±half-thickness along the normal: a prism that holds the boundary,
    /// so the screen bounds of these points bound those of the boundary.
    pub fn bounding_points(&self) -> Vec<DVec3> {
        let n = DVec3::from_array(self.normal) * self.half_thickness_mm;
        self.polygon_mm
            .iter()
            .flat_map(|p| [DVec3::from_array(*p) + n, DVec3::from_array(*p) - n])
            .collect()
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Cell {
    /// Triangles of the surface in this cell.
    pub triangles: Vec<u32>,
    pub voxels: usize,
    /// Centerline points from `span.0` to `span.1` (inclusive) lie in this cell's stretch.
    pub centerline_span: (usize, usize),
    /// The portals toward the source and toward the target (indices into `Cells::portals`).
    pub portal_back: Option<usize>,
    pub portal_front: Option<usize>,
}

#[derive(Clone, Debug)]
pub struct Cells {
    pub cells: Vec<Cell>,
    /// `portals[c]` lies between `cells[c]` and `cells[c + 1]`.
    pub portals: Vec<Portal>,
    /// Per voxel of the Dt field's bricks: its cell, or `u16::MAX` outside the lumen.
    pub voxel_cell: Bricked<u16>,
    /// Per triangle: its cell.
    pub triangle_cell: Vec<u16>,
}

impl Cells {
    /// The cell of a volume voxel (None outside the lumen).
    pub fn cell_of_voxel(&self, v: [usize; 3]) -> Option<usize> {
        let c = self.voxel_cell.get(v);
        (c != u16::MAX).then_some(c as usize)
    }

    /// The cell holding a volume-local point: that of the nearest lumen voxel among the 8
    /// around it (a camera may sit between voxel centres, inside the surface).
    pub fn cell_of_point(&self, mm: DVec3) -> Option<usize> {
        let g = &self.voxel_cell.geometry;
        let p = g.local_to_index(mm);
        let base = p.floor();
        let mut best: Option<(f64, usize)> = None;
        for c in 0..8 {
            let o = DVec3::new((c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64);
            let q = base + o;
            if q.min_element() < 0.0 {
                continue;
            }
            if let Some(cell) = self.cell_of_voxel([q.x as usize, q.y as usize, q.z as usize]) {
                let d = (q - p).length_squared();
                if best.is_none_or(|b| d < b.0) {
                    best = Some((d, cell));
                }
            }
        }
        best.map(|b| b.1)
    }
}

/// Splits the lumen into cells. `dt_source`: Dt from the source (+∞ outside).
pub fn build_cells(
    lumen: &Volume<u8>,
    dt_source: &Bricked<f32>,
    centerline: &Centerline,
    surface: &Surface,
    opts: &CellOptions,
) -> Result<Cells> {
    if centerline.points_mm.len() < 2 {
        return Err(Error::invalid("the centerline has fewer than two points"));
    }
    let cl_dt = centerline_levels(dt_source, centerline);
    let tri_dt: Vec<f32> = surface
        .owner_voxel
        .iter()
        .map(|&v| dt_source.get(lumen.geometry().ijk(v as usize)))
        .collect();
    let min_len = opts.min_length_mm.max(2.0 * diagonal(lumen.spacing()));
    let sections = Sections::of(dt_source);
    let levels = choose_levels(
        &cl_dt,
        &centerline.arc_mm,
        &tri_dt,
        &sections,
        opts,
        min_len,
    );
    let reach = diagonal(lumen.spacing()) * 1.01;
    let Labels {
        cells: voxel_cell,
        counts,
        below_cut,
    } = label_voxels(dt_source, &levels, reach);
    let table = LevelTable::new(&levels);
    let triangle_cell: Vec<u16> = tri_dt.iter().map(|&d| table.cell(d)).collect();
    let ncells = levels.len() + 1;
    let mut cells: Vec<Cell> = (0..ncells)
        .map(|c| Cell {
            triangles: Vec::new(),
            voxels: 0,
            centerline_span: (0, 0),
            portal_back: c.checked_sub(1),
            portal_front: (c + 1 < ncells).then_some(c),
        })
        .collect();
    for (t, &c) in triangle_cell.iter().enumerate() {
        cells[c as usize].triangles.push(t as u32);
    }
    for (cell, n) in cells.iter_mut().zip(counts) {
        cell.voxels = n;
    }
    set_spans(&mut cells, &cl_dt, &levels);
    let boundaries = boundary_points(&voxel_cell, &below_cut, levels.len(), lumen.spacing())?;
    let portals = levels
        .iter()
        .zip(boundaries)
        .enumerate()
        .map(|(c, (&level, pts))| make_portal(pts, c, level, centerline, &cl_dt, lumen.spacing()))
        .collect::<Result<Vec<_>>>()?;
    Ok(Cells {
        cells,
        portals,
        voxel_cell,
        triangle_cell,
    })
}

fn diagonal(sp: [f64; 3]) -> f64 {
    (sp[0] * sp[0] + sp[1] * sp[1] + sp[2] * sp[2]).sqrt()
}

/// Dt at each centerline point, made non-decreasing (the centerline runs away from the source).
fn centerline_levels(dt: &Bricked<f32>, cl: &Centerline) -> Vec<f64> {
    let mut out = Vec::with_capacity(cl.points_mm.len());
    let mut last = 0.0f64;
    for p in &cl.points_mm {
        let p = DVec3::from_array(*p);
        let ijk = dt.geometry.local_to_index(p).round();
        let d = dt.get([ijk.x as usize, ijk.y as usize, ijk.z as usize]) as f64;
        let d = if d.is_finite() { d } else { last };
        last = last.max(d);
        out.push(last);
    }
    out
}

/// Cut levels (in Dt): walk the centerline, cutting when the stretch since the last cut is
/// long enough or holds enough triangles, keeping cuts `min_len` apart in Dt. Where a cut is
/// due, it goes where the lumen is narrowest in the latter part of the stretch (`sections`):
/// at a fold rather than across a haustrum, so that its portal is small.
fn choose_levels(
    cl_dt: &[f64],
    arc: &[f64],
    tri_dt: &[f32],
    sections: &Sections,
    opts: &CellOptions,
    min_len: f64,
) -> Vec<f64> {
    let sorted = sorted_distances(tri_dt);
    let tris_below = |level: f64| sorted.partition_point(|&d| (d as f64) < level);
    let end = *cl_dt.last().unwrap_or(&0.0);
    let mut levels = Vec::new();
    let (mut last_level, mut last_arc) = (0.0f64, 0.0f64);
    for (i, &level) in cl_dt.iter().enumerate() {
        if level - last_level < min_len || end - level < min_len {
            continue;
        }
        let long = arc[i] - last_arc >= opts.max_length_mm;
        let full = tris_below(level) - tris_below(last_level) >= opts.max_triangles;
        if long || full {
            let from = last_level + min_len.max(CUT_WINDOW * (level - last_level));
            let j = (0..=i)
                .rev()
                .take_while(|&j| cl_dt[j] >= from)
                .min_by_key(|&j| sections.around(cl_dt[j]))
                .unwrap_or(i);
            levels.push(cl_dt[j]);
            last_level = cl_dt[j];
            last_arc = arc[j];
        }
    }
    levels
}

/// A due cut may move back this share of its stretch toward the last one, to a narrower place.
const CUT_WINDOW: f64 = 0.5;

/// How much lumen lies at each level of Dt: lumen voxels per bin of [`SECTION_BIN_MM`], the
/// area of a cut there times the bin's depth, side pockets at that level included (a portal's
/// outline holds them too).
struct Sections {
    voxels: Vec<u32>,
}

/// Depth in Dt of one bin of [`Sections`] (mm).
const SECTION_BIN_MM: f64 = 0.5;
/// A cut is measured over this many bins on either side of its level: a level set of Dt on
/// voxels is up to a voxel diagonal deep.
const SECTION_REACH: usize = 2;

impl Sections {
    fn of(dt: &Bricked<f32>) -> Self {
        let mut voxels: Vec<u32> = Vec::new();
        for &d in dt.values().iter().filter(|d| d.is_finite()) {
            let b = (d as f64 / SECTION_BIN_MM) as usize;
            if b >= voxels.len() {
                voxels.resize(b + 1, 0);
            }
            voxels[b] += 1;
        }
        Sections { voxels }
    }

    /// Lumen voxels within [`SECTION_REACH`] bins of `level`.
    fn around(&self, level: f64) -> u64 {
        let b = (level / SECTION_BIN_MM) as usize;
        let lo = b.saturating_sub(SECTION_REACH).min(self.voxels.len());
        let hi = (b + SECTION_REACH + 1).min(self.voxels.len());
        self.voxels[lo..hi].iter().map(|&x| x as u64).sum()
    }
}

/// The finite values of `d` (distances: ≥ 0) in increasing order. A radix sort of their bit
/// patterns, which order like the values for non-negative floats: two passes of 16 bits over a
/// million triangles instead of a comparison sort.
fn sorted_distances(d: &[f32]) -> Vec<f32> {
    let mut keys: Vec<u32> = d
        .iter()
        .filter(|x| x.is_finite())
        .map(|&x| (x.max(0.0) + 0.0).to_bits())
        .collect();
    let mut tmp = vec![0u32; keys.len()];
    for shift in [0, 16] {
        let mut start = vec![0usize; 1 << 16];
        for &k in &keys {
            start[(k >> shift) as usize & 0xffff] += 1;
        }
        let mut at = 0;
        for s in start.iter_mut() {
            (*s, at) = (at, at + *s);
        }
        for &k in &keys {
            let b = (k >> shift) as usize & 0xffff;
            tmp[start[b]] = k;
            start[b] += 1;
        }
        std::mem::swap(&mut keys, &mut tmp);
    }
    keys.into_iter().map(f32::from_bits).collect()
}

fn cell_of_level(levels: &[f64], d: f32) -> u16 {
    levels.partition_point(|&l| l <= d as f64) as u16
}

/// Each voxel's cell, the voxels per cell, and the voxels within `reach` (a voxel diagonal)
/// below a cut: only those can touch the next cell, since Dt changes by at most a diagonal
/// between neighbours, so every pair of voxels across a cut has its lower voxel among them.
struct Labels {
    cells: Bricked<u16>,
    counts: Vec<usize>,
    below_cut: Vec<u32>,
}

fn label_voxels(dt: &Bricked<f32>, levels: &[f64], reach: f64) -> Labels {
    let mut counts = vec![0usize; levels.len() + 1];
    let mut below_cut = Vec::new();
    let table = LevelTable::new(levels);
    let cells = dt.map(u16::MAX, |at, d| {
        if !d.is_finite() {
            return u16::MAX;
        }
        let c = table.cell(d) as usize;
        counts[c] += 1;
        let d = d as f64;
        if c < levels.len() && levels[c] - d <= reach {
            below_cut.push(at as u32);
        }
        c as u16
    });
    Labels {
        cells,
        counts,
        below_cut,
    }
}

/// [`cell_of_level`] by table: the cell at the start of each bin of Dt, bins narrower than the
/// gap between levels, so that at most one level falls inside a bin and one comparison
/// settles it. Same answers, without a binary search per voxel.
struct LevelTable<'a> {
    levels: &'a [f64],
    start: Vec<u16>,
    inv_bin: f64,
}

impl<'a> LevelTable<'a> {
    fn new(levels: &'a [f64]) -> Self {
        let gap = levels
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold(f64::INFINITY, f64::min);
        let bin = if gap.is_finite() {
            (gap * 0.5).max(1e-3)
        } else {
            1.0
        };
        let end = levels.last().copied().unwrap_or(0.0).max(0.0);
        let n = (end / bin) as usize + 2;
        // Half a bin early, so that rounding never starts a bin past its first voxel's cell.
        let start = (0..n)
            .map(|b| cell_of_level(levels, ((b as f64 - 0.5).max(0.0) * bin) as f32))
            .collect();
        LevelTable {
            levels,
            start,
            inv_bin: 1.0 / bin,
        }
    }

    #[inline]
    fn cell(&self, d: f32) -> u16 {
        let b = (d as f64 * self.inv_bin) as usize;
        let Some(&c) = self.start.get(b) else {
            return self.levels.len() as u16;
        };
        let mut c = c as usize;
        while c < self.levels.len() && self.levels[c] <= d as f64 {
            c += 1;
        }
        c as u16
    }
}

fn set_spans(cells: &mut [Cell], cl_dt: &[f64], levels: &[f64]) {
    for (i, &d) in cl_dt.iter().enumerate() {
        let c = cell_of_level(levels, d as f32) as usize;
        let span = &mut cells[c].centerline_span;
        if span.1 == 0 && span.0 == 0 && i > 0 {
            *span = (i, i);
        }
        span.1 = i;
    }
}

/// The portal between cells `c` and `c + 1`: boundary voxels (in either cell, 26-adjacent to
/// the other) projected on the plane across the centerline at the cut; their convex hull,
/// grown by half a voxel diagonal; the thickness their spread out of the plane.
fn make_portal(
    pts: Vec<DVec3>,
    c: usize,
    level: f64,
    cl: &Centerline,
    cl_dt: &[f64],
    sp: [f64; 3],
) -> Result<Portal> {
    let at = cl_dt
        .partition_point(|&d| d < level)
        .min(cl.points_mm.len() - 1);
    let centre = DVec3::from_array(cl.points_mm[at]);
    let a = DVec3::from_array(cl.points_mm[at.saturating_sub(2)]);
    let b = DVec3::from_array(cl.points_mm[(at + 2).min(cl.points_mm.len() - 1)]);
    let normal = (b - a).normalize_or(DVec3::Z);
    if pts.is_empty() {
        return Err(Error::invalid(format!(
            "cells {c} and {} do not touch",
            c + 1
        )));
    }
    let (u, v) = plane_axes(normal);
    let half = 0.5 * diagonal(sp);
    let mut depth = 0.0f64;
    let flat: Vec<(f64, f64)> = pts
        .iter()
        .map(|&p| {
            let d = p - centre;
            depth = depth.max(d.dot(normal).abs());
            (d.dot(u), d.dot(v))
        })
        .collect();
    let hull = convex_hull(flat);
    let polygon_mm = grow(&hull, half)
        .into_iter()
        .map(|(x, y)| (centre + u * x + v * y).to_array())
        .collect();
    Ok(Portal {
        level_mm: level,
        centerline_index: at,
        centre_mm: centre.to_array(),
        normal: normal.to_array(),
        polygon_mm,
        half_thickness_mm: depth + half,
    })
}

/// For each cut c, the centres (volume-local mm) of the voxels on either side of it: voxels
/// of cells c and c + 1 that are 26-adjacent, found from the voxels just below a cut (see
/// [`label_voxels`]), each voxel once. Cells further apart than one must never touch (that is
/// the guarantee visibility needs); if they do, that is an error.
fn boundary_points(
    cells: &Bricked<u16>,
    below_cut: &[u32],
    cuts: usize,
    sp: [f64; 3],
) -> Result<Vec<Vec<DVec3>>> {
    let dims = cells.grid.dims.map(|d| d as i64);
    let mut offs = Vec::with_capacity(26);
    for dk in -1i64..=1 {
        for dj in -1i64..=1 {
            for di in -1i64..=1 {
                if (dk, dj, di) != (0, 0, 0) {
                    offs.push([di, dj, dk]);
                }
            }
        }
    }
    // Stored indices per cut; an upper voxel is met from several lower ones, so a bit per
    // stored voxel says whether it is listed already. (The order within a list does not
    // matter: a portal is their convex hull.)
    let values = cells.values();
    let mut out: Vec<Vec<u32>> = vec![Vec::new(); cuts];
    let mut listed = vec![0u64; values.len().div_ceil(64)];
    for &here in below_cut {
        let here = here as usize;
        let l = cells.box_voxel(BrickIndex(here)).map(|x| x as i64);
        let a = values[here];
        let mut across = false;
        for o in &offs {
            let q = [l[0] + o[0], l[1] + o[1], l[2] + o[2]];
            if (0..3).any(|ax| q[ax] < 0 || q[ax] >= dims[ax]) {
                continue;
            }
            let Some(BrickIndex(there)) = cells.index_of_box(q.map(|x| x as usize)) else {
                continue;
            };
            let b = values[there];
            if b == u16::MAX || b == a {
                continue;
            }
            if a.abs_diff(b) != 1 {
                return Err(Error::invalid(format!(
                    "cells {a} and {b} touch: the cuts are too close"
                )));
            }
            if b == a + 1 {
                across = true;
                if listed[there / 64] & (1 << (there % 64)) == 0 {
                    listed[there / 64] |= 1 << (there % 64);
                    out[a as usize].push(there as u32);
                }
            }
        }
        if across {
            out[a as usize].push(here as u32);
        }
    }
    let lo = cells.grid.lo;
    Ok(out
        .into_iter()
        .map(|v| {
            v.into_iter()
                .map(|at| {
                    let [i, j, k] = cells.box_voxel(BrickIndex(at as usize));
                    DVec3::new(
                        ((i + lo[0]) as f64) * sp[0],
                        ((j + lo[1]) as f64) * sp[1],
                        ((k + lo[2]) as f64) * sp[2],
                    )
                })
                .collect()
        })
        .collect())
}

/// Two unit vectors spanning the plane with this normal, (u, v, normal) right-handed.
fn plane_axes(n: DVec3) -> (DVec3, DVec3) {
    let helper = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let u = n.cross(helper).normalize();
    (u, n.cross(u))
}

/// The convex hull, counter-clockwise (collinear points dropped).
pub fn convex_hull(pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    monotone_chain(drop_interior(pts))
}

/// Andrew's monotone chain.
fn monotone_chain(mut pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    pts.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let mut hull: Vec<(f64, f64)> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &(f64, f64)>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// (a − o) × (b − o): positive when o, a, b turn counter-clockwise.
fn cross(o: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
}

/// Akl–Toussaint: the points extreme in eight directions span a convex polygon inside the
/// hull; a point strictly inside it is no hull vertex, so leaving it out changes nothing but
/// the sort that follows (a portal's boundary has thousands of voxels, its hull dozens).
fn drop_interior(pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    if pts.len() < 64 {
        return pts;
    }
    // Directions counter-clockwise from +x: the polygon through their extreme points is then
    // counter-clockwise too.
    const DIRS: [(f64, f64); 8] = [
        (1.0, 0.0),
        (1.0, 1.0),
        (0.0, 1.0),
        (-1.0, 1.0),
        (-1.0, 0.0),
        (-1.0, -1.0),
        (0.0, -1.0),
        (1.0, -1.0),
    ];
    let mut ext = [pts[0]; 8];
    for &p in &pts {
        for (e, d) in ext.iter_mut().zip(DIRS) {
            if p.0 * d.0 + p.1 * d.1 > e.0 * d.0 + e.1 * d.1 {
                *e = p;
            }
        }
    }
    let mut poly: Vec<(f64, f64)> = Vec::with_capacity(8);
    for e in ext {
        if poly.last() != Some(&e) && poly.first() != Some(&e) {
            poly.push(e);
        }
    }
    if poly.len() < 3 {
        return pts;
    }
    let n = poly.len();
    let strictly_inside =
        |p: (f64, f64)| (0..n).all(|i| cross(poly[i], poly[(i + 1) % n], p) > 0.0);
    pts.into_iter().filter(|&p| !strictly_inside(p)).collect()
}

/// Moves each hull vertex outward by `r` along its bisector (enough that every point within
/// `r` of the hull lies inside the grown polygon).
fn grow(hull: &[(f64, f64)], r: f64) -> Vec<(f64, f64)> {
    let n = hull.len();
    if n < 3 {
        // Degenerate boundary: a square of side 2r around each point.
        let corners = hull
            .iter()
            .flat_map(|&(x, y)| {
                [
                    (x - r, y - r),
                    (x + r, y - r),
                    (x + r, y + r),
                    (x - r, y + r),
                ]
            })
            .collect();
        return convex_hull(corners);
    }
    (0..n)
        .map(|i| {
            let (p, a, b) = (hull[i], hull[(i + n - 1) % n], hull[(i + 1) % n]);
            let e1 = norm((p.0 - a.0, p.1 - a.1));
            let e2 = norm((b.0 - p.0, b.1 - p.1));
            // Outward normals of the two edges (hull is counter-clockwise).
            let n1 = (e1.1, -e1.0);
            let n2 = (e2.1, -e2.0);
            let bis = norm((n1.0 + n2.0, n1.1 + n2.1));
            let cos = (bis.0 * n1.0 + bis.1 * n1.1).max(0.2);
            (p.0 + bis.0 * r / cos, p.1 + bis.1 * r / cos)
        })
        .collect()
}

fn norm(v: (f64, f64)) -> (f64, f64) {
    let l = (v.0 * v.0 + v.1 * v.1).sqrt();
    if l == 0.0 {
        (0.0, 0.0)
    } else {
        (v.0 / l, v.1 / l)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        Geometry,
        centerline::{CenterlineOptions, centerline},
        distance::{distance_to_wall, geodesic_distance},
        grid::BoxIndex,
        grid::bounding_box,
        surface::extract_surface,
    };

    #[test]
    fn leaving_out_interior_points_keeps_the_hull() {
        let mut rng = crate::rng::Rng::new(88172645463325252, 0);
        let mut rnd = || (rng.next_u64() % 10_000) as f64 / 100.0;
        for shape in 0..4 {
            // A disc, a square and a thin slanted strip of random points, and a voxel grid
            // (many collinear and tied points).
            let pts: Vec<(f64, f64)> = match shape {
                0 => (0..3000)
                    .map(|_| (rnd() - 50.0, rnd() - 50.0))
                    .filter(|p| p.0 * p.0 + p.1 * p.1 < 2500.0)
                    .collect(),
                1 => (0..3000).map(|_| (rnd(), rnd())).collect(),
                2 => (0..3000)
                    .map(|_| (rnd(), rnd(), rnd()))
                    .map(|(t, a, b)| (t + a * 0.02, 0.5 * t - b * 0.03))
                    .collect(),
                _ => (0..40)
                    .flat_map(|i| (0..30).map(move |j| (i as f64 * 0.8, j as f64 * 1.25)))
                    .collect(),
            };
            let hull = convex_hull(pts.clone());
            assert!(
                drop_interior(pts.clone()).len() < pts.len(),
                "shape {shape}: nothing left out"
            );
            assert_eq!(hull, monotone_chain(pts), "shape {shape}");
        }
    }

    /// A U-shaped tube whose two legs run side by side 4 mm apart (wall between), as where the
    /// sigmoid folds back: a plane cut across one leg would also cut the other.
    fn u_tube() -> Volume<u8> {
        let g = Geometry::new([70, 40, 24], [1.0, 1.0, 1.0], [0.0; 3]).unwrap();
        let data = (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                let (x, y, z) = (i as f64, j as f64, k as f64);
                let r = 5.0;
                let leg1 = ((y - 10.0).powi(2) + (z - 12.0).powi(2)).sqrt() < r
                    && (5.0..=55.0).contains(&x);
                let leg2 = ((y - 24.0).powi(2) + (z - 12.0).powi(2)).sqrt() < r
                    && (5.0..=55.0).contains(&x);
                let bend = x > 55.0
                    && (((x - 55.0).powi(2) + (y - 17.0).powi(2)).sqrt() - 7.0).hypot(z - 12.0) < r;
                (leg1 || leg2 || bend) as u8
            })
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    /// The cells of lumen `m` with its centerline from `src` to `dst` (voxels), that
    /// centerline and the surface.
    fn cells_between(
        m: &Volume<u8>,
        src: [usize; 3],
        dst: [usize; 3],
        opts: &CellOptions,
    ) -> (Cells, Centerline, Surface) {
        let grid = bounding_box(m, 1, |v| v != 0).unwrap();
        let ds = distance_to_wall(m).unwrap();
        let dt = geodesic_distance(m, &grid, src).unwrap();
        let cl = centerline(m, &ds, src, dst, &CenterlineOptions::default()).unwrap();
        let surf = extract_surface(m, None, &grid, 0.0).unwrap();
        let cells = build_cells(m, &dt.dist, &cl, &surf, opts).unwrap();
        (cells, cl, surf)
    }

    /// A straight tube along x, radius 6 mm, narrowed to 3 mm by folds 2 mm thick at
    /// `folds` (x, mm).
    fn folded_tube(folds: &[f64]) -> Volume<u8> {
        let g = Geometry::new([110, 20, 20], [1.0, 1.0, 1.0], [0.0; 3]).unwrap();
        let data = (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                let x = i as f64;
                let r = if folds.iter().any(|f| (x - f).abs() <= 1.0) {
                    3.0
                } else {
                    6.0
                };
                ((j as f64 - 10.0).hypot(k as f64 - 10.0) < r && (3.0..=105.0).contains(&x)) as u8
            })
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    #[test]
    fn a_due_cut_moves_back_to_a_fold() {
        let folds = [16.0, 33.0, 47.0, 64.0, 81.0];
        let m = folded_tube(&folds);
        let (cells, _, _) = cells_between(&m, [4, 10, 10], [104, 10, 10], &CellOptions::default());
        // Every 20 mm the cuts would lie across the wide tube. Each moves back to just past
        // a fold in the latter half of its stretch, where the level set of Dt is the small cap
        // through the fold's opening.
        let cuts: Vec<f64> = cells.portals.iter().map(|p| p.centre_mm[0]).collect();
        let radii: Vec<f64> = cells
            .portals
            .iter()
            .map(|p| {
                let c = DVec3::from_array(p.centre_mm);
                p.polygon_mm
                    .iter()
                    .map(|q| DVec3::from_array(*q).distance(c))
                    .fold(0.0, f64::max)
            })
            .collect();
        assert!(cuts.len() >= 4, "cuts at x = {cuts:?}");
        for (cut, r) in cuts.iter().zip(&radii) {
            let fold = folds
                .iter()
                .map(|f| cut - f)
                .fold(f64::INFINITY, |a, d| if d >= 0.0 { a.min(d) } else { a });
            assert!(
                fold <= 3.0 && *r < 5.0,
                "cuts at x = {cuts:?} with outline radii {radii:?}, folds at {folds:?}"
            );
        }
    }

    #[test]
    fn radix_sorted_distances_match_a_comparison_sort() {
        let mut rng = crate::rng::Rng::new(7, 1);
        let mut d: Vec<f32> = (0..5000).map(|_| rng.range(0.0, 3000.0) as f32).collect();
        d.extend([0.0, f32::INFINITY, 1e-30, 2999.99, 0.5, 0.5]);
        let mut want: Vec<f32> = d.iter().copied().filter(|x| x.is_finite()).collect();
        want.sort_unstable_by(f32::total_cmp);
        assert_eq!(sorted_distances(&d), want);
    }

    #[test]
    fn level_table_agrees_with_the_binary_search() {
        let levels = [3.0, 5.9, 40.25, 41.0, 300.0];
        let table = LevelTable::new(&levels);
        let mut d = 0.0f32;
        while d < 320.0 {
            for x in [d, f32::from_bits(d.to_bits() + 1)] {
                assert_eq!(table.cell(x), cell_of_level(&levels, x), "Dt {x}");
            }
            d += 0.0625;
        }
        for &l in &levels {
            let l = l as f32;
            assert_eq!(table.cell(l), cell_of_level(&levels, l));
            assert_eq!(
                table.cell(l.next_down()),
                cell_of_level(&levels, l.next_down())
            );
        }
    }

    #[test]
    fn cells_partition_the_lumen_and_touch_only_neighbours() {
        let m = u_tube();
        let opts = CellOptions {
            max_length_mm: 12.0,
            ..Default::default()
        };
        let (cells, cl, surf) = cells_between(&m, [6, 10, 12], [6, 24, 12], &opts);
        let n = cells.cells.len();
        assert!(n >= 6, "only {n} cells");
        assert_eq!(cells.portals.len(), n - 1);
        // Every lumen voxel in exactly one cell; every triangle in one cell.
        let lumen = m.data().iter().filter(|&&v| v != 0).count();
        assert_eq!(cells.cells.iter().map(|c| c.voxels).sum::<usize>(), lumen);
        assert_eq!(
            cells.cells.iter().map(|c| c.triangles.len()).sum::<usize>(),
            surf.mesh.triangles.len()
        );
        // Cells touch only their neighbours in the chain.
        let f = &cells.voxel_cell.to_field();
        let [nx, ny, nz] = f.grid.dims;
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let a = f[f.grid.index(i, j, k)];
                    if a == u16::MAX {
                        continue;
                    }
                    for (di, dj, dk) in [
                        (1, 0, 0),
                        (0, 1, 0),
                        (0, 0, 1),
                        (1, 1, 1),
                        (1, -1, 1),
                        (-1, 1, 1),
                        (1, 1, 0),
                        (1, -1, 0),
                    ] {
                        let q = [i as i64 + di, j as i64 + dj, k as i64 + dk];
                        if q.iter()
                            .zip(&f.grid.dims)
                            .any(|(&x, &n)| x < 0 || x >= n as i64)
                        {
                            continue;
                        }
                        let b = f[f.grid.index(q[0] as usize, q[1] as usize, q[2] as usize)];
                        if b != u16::MAX {
                            assert!((a as i32 - b as i32).abs() <= 1, "cells {a} and {b} touch");
                        }
                    }
                }
            }
        }
        // The two legs lie side by side: a cell of one leg holds no voxel of the other.
        for cell in 0..n as u16 {
            let mut legs = [false; 2];
            for (idx, &c) in f.data.iter().enumerate() {
                if c == cell {
                    let [i, j, _] = f.grid.global_of_index(BoxIndex(idx));
                    if i < 50 {
                        legs[(j > 17) as usize] = true;
                    }
                }
            }
            assert!(!(legs[0] && legs[1]), "cell {cell} spans both legs");
        }
        // Portals: roughly the tube's cross-section (radius 5 mm), across the centerline.
        for p in &cells.portals {
            let c = DVec3::from_array(p.centre_mm);
            let far = p
                .polygon_mm
                .iter()
                .map(|q| DVec3::from_array(*q).distance(c))
                .fold(0.0, f64::max);
            assert!((4.0..10.0).contains(&far), "portal outline radius {far}");
            assert!(p.polygon_mm.len() >= 4);
        }
        // Cell lookup of a point on the centerline agrees with the voxel labels.
        let p = DVec3::from_array(cl.points_mm[cl.points_mm.len() / 2]);
        assert!(cells.cell_of_point(p).is_some());
    }
}
