//! The 3D size of a polyp: a click on it segments the bump from the surface around it, and
//! its largest diameter is measured (the size a report gives, and C-RADS reads).
//!
//! The wall around the click is fitted by a quadric height field over a ring of surface
//! points (robustly: a fold in the ring is dropped, not fitted); the polyp is the surface
//! connected to the click that stands above that wall by more than [`MIN_HEIGHT_MM`]; its
//! size is its largest extent across the wall's normal, so that a pedunculated polyp is
//! measured across its head, not along its stalk. The ring grows until it clears the polyp.

use std::collections::{BinaryHeap, HashMap};

use glam::DVec3;

use crate::mesh::CellMesh;

/// Surface this far above the fitted wall (mm) belongs to the bump.
pub const MIN_HEIGHT_MM: f64 = 0.6;
/// A bump's vertex whose normal leans toward the bump's axis by more than this cosine is
/// skirt, not head.
const SKIRT_COS: f64 = 0.2;
/// A path down the bump may climb back this far (mm): surface noise, not a fold.
const CLIMB_MM: f64 = 0.05;
/// The cuts tried, lowest first, when a bump runs into a fold.
const HEIGHT_CUTS_MM: [f64; 3] = [MIN_HEIGHT_MM, 0.9, 1.2];

/// The first ring's inner radius (mm); it grows by [`RING_GROWTH`] up to [`MAX_RING_MM`].
const FIRST_RING_MM: f64 = 6.0;
const RING_GROWTH: f64 = 1.35;
const MAX_RING_MM: f64 = 30.0;
/// The ring is [r, RING_WIDTH·r] from the click.
const RING_WIDTH: f64 = 1.5;
/// A ring point whose fitted height is off by more than this (mm) is dropped as not wall.
const FIT_TOLERANCE_MM: f64 = 1.0;

/// A polyp measured on the surface.
#[derive(Clone, Debug)]
pub struct PolypSize {
    /// Largest extent across the wall's normal (mm).
    pub diameter_mm: f64,
    /// The two surface points that span it (volume-local mm).
    pub ends: [DVec3; 2],
    /// How far the bump stands above the wall (mm).
    pub height_mm: f64,
    /// The wall's normal under the polyp (into the lumen).
    pub normal: DVec3,
    /// The bump's vertices (indices into the mesh's positions).
    pub vertices: Vec<u32>,
}

/// Segments the bump under a click at `point` on `mesh` (the surface point a pick hit,
/// with its triangle's normal `normal`) and measures it; None when nothing stands out of
/// the wall there, or the bump is too large to be a polyp (it reaches past a 30 mm ring).
pub fn measure_polyp(mesh: &CellMesh, point: DVec3, normal: DVec3) -> Option<PolypSize> {
    let near = Neighbourhood::around(mesh, point, MAX_RING_MM * RING_WIDTH);
    let mut ring = FIRST_RING_MM;
    while ring <= MAX_RING_MM {
        let wall = Wall::fit(&near, point, normal, ring)?;
        // The bump must lie inside the ring that defined the wall, or the wall was partly
        // the bump. One that reaches the ring may be joined to a fold at its foot: a higher
        // cut may part them (up to what still takes in a sessile polyp's equator).
        for cut in HEIGHT_CUTS_MM {
            let bump = near.bump(point, &wall, ring, cut);
            if bump.is_empty() {
                return None;
            }
            let reach = bump
                .iter()
                .map(|&v| wall.across(near.position(v)).length())
                .fold(0.0, f64::max);
            if reach < 0.85 * ring {
                return Some(near.size(&bump, &wall));
            }
        }
        ring *= RING_GROWTH;
    }
    None
}

/// The surface within some distance of a point: its vertices and triangles, with
/// vertex-to-triangle links.
struct Neighbourhood<'a> {
    mesh: &'a CellMesh,
    triangles: Vec<[u32; 3]>,
    /// Mesh vertex → triangles (indices into `triangles`) of the neighbourhood.
    of_vertex: HashMap<u32, Vec<u32>>,
    /// Its vertices, sorted, so that every result is independent of hash order.
    vertices: Vec<u32>,
}

impl<'a> Neighbourhood<'a> {
    fn around(mesh: &'a CellMesh, c: DVec3, radius: f64) -> Self {
        let r2 = radius * radius;
        let inside = |v: u32| {
            DVec3::from_array(mesh.positions[v as usize].map(f64::from)).distance_squared(c) <= r2
        };
        let triangles: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&v| inside(v)))
            .collect();
        let mut of_vertex: HashMap<u32, Vec<u32>> = HashMap::new();
        for (i, t) in triangles.iter().enumerate() {
            for &v in t {
                of_vertex.entry(v).or_default().push(i as u32);
            }
        }
        let mut vertices: Vec<u32> = of_vertex.keys().copied().collect();
        vertices.sort_unstable();
        Neighbourhood {
            mesh,
            triangles,
            of_vertex,
            vertices,
        }
    }

    fn position(&self, v: u32) -> DVec3 {
        DVec3::from_array(self.mesh.positions[v as usize].map(f64::from))
    }

    fn normal(&self, v: u32) -> DVec3 {
        DVec3::from_array(self.mesh.normals[v as usize].map(f64::from))
    }

    /// The vertices connected to the vertex nearest `click` through vertices standing above
    /// `wall` by more than `cut`, within `ring` of the click across the normal.
    fn bump(&self, click: DVec3, wall: &Wall, ring: f64, cut: f64) -> Vec<u32> {
        let height = |v: u32| wall.height(self.position(v));
        // Inside the ring only: the quadric means nothing beyond the points it was fitted to.
        let above = |v: u32| height(v) > cut && wall.across(self.position(v)).length() <= ring;
        let Some(start) = self
            .vertices
            .iter()
            .copied()
            .filter(|&v| above(v))
            .min_by(|&a, &b| {
                self.position(a)
                    .distance_squared(click)
                    .total_cmp(&self.position(b).distance_squared(click))
            })
            .filter(|&v| self.position(v).distance(click) < 2.0)
        else {
            return Vec::new();
        };
        let peak = self.climb(start, &height);
        // Flood down from the peak, highest first; no path may climb more than CLIMB_MM
        // above the lowest point it passed, so a fold beyond a saddle stays out.
        let mut low: HashMap<u32, f64> = HashMap::from([(peak, height(peak))]);
        let mut queue = BinaryHeap::from([Ordered(height(peak), peak)]);
        let mut out = Vec::new();
        while let Some(Ordered(_, v)) = queue.pop() {
            out.push(v);
            let floor = low[&v];
            for &t in &self.of_vertex[&v] {
                for &u in &self.triangles[t as usize] {
                    let h = height(u);
                    if above(u) && h <= floor + CLIMB_MM && !low.contains_key(&u) {
                        low.insert(u, floor.min(h));
                        queue.push(Ordered(h, u));
                    }
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// From `v` up to the highest point nearby: each step to the highest neighbour.
    fn climb(&self, mut v: u32, height: &impl Fn(u32) -> f64) -> u32 {
        loop {
            let best = self.of_vertex[&v]
                .iter()
                .flat_map(|&t| self.triangles[t as usize])
                .max_by(|&a, &b| height(a).total_cmp(&height(b)).then(b.cmp(&a)))
                .unwrap_or(v);
            if height(best) <= height(v) {
                return v;
            }
            v = best;
        }
    }

    /// The bump's size: its largest extent across the wall's normal.
    fn size(&self, bump: &[u32], wall: &Wall) -> PolypSize {
        // The head, without the concave skirt where it meets the wall (or a fold's foot):
        // there the surface faces back toward the bump's axis.
        let peak = bump
            .iter()
            .copied()
            .max_by(|&a, &b| {
                wall.height(self.position(a))
                    .total_cmp(&wall.height(self.position(b)))
                    .then(b.cmp(&a))
            })
            .map_or(DVec3::ZERO, |v| wall.across(self.position(v)));
        let head = |v: &u32| {
            let out = wall.across(self.position(*v)) - peak;
            out.try_normalize()
                .is_none_or(|out| self.normal(*v).dot(out) >= -SKIRT_COS)
        };
        // The head in the wall's (u, v) plane; its largest extent is between two corners of
        // its convex hull.
        let at_uv: HashMap<(u64, u64), DVec3> = bump
            .iter()
            .filter(|v| head(v))
            .map(|&v| {
                let p = self.position(v);
                let d = wall.across(p);
                ((d.dot(wall.u).to_bits(), d.dot(wall.v).to_bits()), p)
            })
            .collect();
        let mut corners: Vec<(f64, f64)> = at_uv
            .keys()
            .map(|&(u, v)| (f64::from_bits(u), f64::from_bits(v)))
            .collect();
        corners.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let hull = voyage_core::convex_hull(corners);
        let (mut best, mut ends) = (0.0, [DVec3::ZERO; 2]);
        for (i, a) in hull.iter().enumerate() {
            for b in &hull[i + 1..] {
                let d = (a.0 - b.0).hypot(a.1 - b.1);
                if d > best {
                    let at = |q: &(f64, f64)| at_uv[&(q.0.to_bits(), q.1.to_bits())];
                    (best, ends) = (d, [at(a), at(b)]);
                }
            }
        }
        let height_mm = bump
            .iter()
            .map(|&v| wall.height(self.position(v)))
            .fold(0.0, f64::max);
        PolypSize {
            diameter_mm: best,
            ends,
            height_mm,
            normal: wall.w,
            vertices: bump.to_vec(),
        }
    }
}

/// The wall around a click: a frame (u, v across, w along the normal) at the click and a
/// quadric height h(u, v) = c·[1, u, v, u², uv, v²].
struct Wall {
    origin: DVec3,
    u: DVec3,
    v: DVec3,
    w: DVec3,
    c: [f64; 6],
}

impl Wall {
    /// Fits the wall over the neighbourhood's vertices between `ring` and `RING_WIDTH·ring`
    /// from the click (across its normal) whose normals agree with the wall's (not the far
    /// side of the lumen), dropping points off the fit (a fold) and fitting again.
    fn fit(near: &Neighbourhood, click: DVec3, click_normal: DVec3, ring: f64) -> Option<Wall> {
        // The ring is measured across the normal: a click on a tall polyp's head is far above
        // the wall, and a ring of distances in 3D would lie on the polyp. The normal starts
        // as the clicked triangle's and becomes the ring's mean normal; only points whose
        // normals agree count (not the lumen's sides or far wall).
        let mut w = click_normal.try_normalize()?;
        let mut points: Vec<DVec3> = Vec::new();
        for _ in 0..3 {
            let ring_vertices: Vec<u32> = near
                .vertices
                .iter()
                .copied()
                .filter(|&v| {
                    let d = near.position(v) - click;
                    let across = (d - w * d.dot(w)).length();
                    across >= ring && across <= RING_WIDTH * ring && near.normal(v).dot(w) > 0.5
                })
                .collect();
            let mean: DVec3 = ring_vertices.iter().map(|&v| near.normal(v)).sum();
            points = ring_vertices.iter().map(|&v| near.position(v)).collect();
            w = mean.try_normalize()?;
        }
        let (u, v) = w.any_orthonormal_pair();
        let mut wall = Wall {
            origin: click,
            u,
            v,
            w,
            c: [0.0; 6],
        };
        for _ in 0..6 {
            if points.len() < 12 {
                return None;
            }
            wall.c = least_squares(&points, &wall)?;
            // The wall is what lies under the bumps: a point well above the fit (a fold) goes
            // at once, one below it only when far off (noise, a pocket between folds).
            let kept: Vec<DVec3> = points
                .iter()
                .copied()
                .filter(|&p| {
                    (-2.0 * FIT_TOLERANCE_MM..=0.5 * FIT_TOLERANCE_MM).contains(&wall.height(p))
                })
                .collect();
            if kept.len() == points.len() {
                break;
            }
            points = kept;
        }
        Some(wall)
    }

    fn local(&self, p: DVec3) -> [f64; 3] {
        let d = p - self.origin;
        [d.dot(self.u), d.dot(self.v), d.dot(self.w)]
    }

    /// Height of `p` above the fitted wall (mm, along w).
    fn height(&self, p: DVec3) -> f64 {
        let [x, y, z] = self.local(p);
        z - basis(x, y)
            .iter()
            .zip(&self.c)
            .map(|(b, c)| b * c)
            .sum::<f64>()
    }

    /// The part of `p − origin` across the normal.
    fn across(&self, p: DVec3) -> DVec3 {
        let d = p - self.origin;
        d - self.w * d.dot(self.w)
    }
}

fn basis(x: f64, y: f64) -> [f64; 6] {
    [1.0, x, y, x * x, x * y, y * y]
}

/// The quadric's coefficients by least squares (normal equations, Gaussian elimination with
/// partial pivoting); None when the points do not determine them.
fn least_squares(points: &[DVec3], wall: &Wall) -> Option<[f64; 6]> {
    let mut a = [[0.0f64; 7]; 6];
    for &p in points {
        let [x, y, z] = wall.local(p);
        let b = basis(x, y);
        for i in 0..6 {
            for j in 0..6 {
                a[i][j] += b[i] * b[j];
            }
            a[i][6] += b[i] * z;
        }
    }
    for col in 0..6 {
        let pivot = (col..6).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-9 {
            return None;
        }
        a.swap(col, pivot);
        let pivot_row = a[col];
        for (r, row) in a.iter_mut().enumerate() {
            if r != col {
                let f = row[col] / pivot_row[col];
                for (x, p) in row.iter_mut().zip(&pivot_row).skip(col) {
                    *x -= f * p;
                }
            }
        }
    }
    Some(std::array::from_fn(|i| a[i][6] / a[i][i]))
}

/// A height and a vertex, ordered by height (then vertex) for the flood's queue.
#[derive(PartialEq)]
struct Ordered(f64, u32);

impl Eq for Ordered {}

impl PartialOrd for Ordered {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ordered {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
    }
}
