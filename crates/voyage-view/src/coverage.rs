//! Coverage of the mucosa: which part of the surface the frames shown have shown, the
//! unseen patches left, and a camera pose that shows each.
//!
//! A triangle counts as seen when it covers a pixel of a shown frame within the reading
//! distance of the eye and faces the eye within the reading angle (its smoothed normal, as
//! shaded, not the terraced facet's): the test runs on the id
//! buffer the renderer wrote anyway, so marking costs one pass over the frame plus a facing
//! test per newly met triangle. Coverage is area, in mm², of the triangles seen over all.
//! Readers who fly one way see about 77 % of the mucosa and both ways about 94 %; stepping
//! through the unseen patches raises that to about 98 % (Pickhardt et al., 2006). The
//! paper's camera looks only where the flight goes, which leaves the wall of a wide stretch
//! unseen; a reading flight here also glances around ([`Glances`]), as readers do. The
//! reading itself, flights and review, is [`crate::ReadingRun`].

use glam::{DQuat, DVec3};
use serde::Serialize;

use crate::{
    findings::pick,
    mesh::CellMesh,
    raster::{Frame, NO_TRIANGLE, Rasterizer, View},
    visibility::{Strategy, Visibility},
};
use voyage_core::{Bricked, COLON_SEGMENTS, Cells, OFF_WALL_MM, Study};
use voyage_nav::{Camera, Pose};

/// What counts as seen, and which unseen patches are listed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CoverageOptions {
    /// A pixel farther from the eye than this (mm) shows nothing a reader can judge.
    pub reading_distance_mm: f64,
    /// The largest angle (degrees) between a triangle's normal and the direction to the eye.
    pub max_angle_deg: f64,
    /// Unseen patches smaller than this (mm²) are not listed.
    pub min_patch_mm2: f64,
    /// The review also visits unseen surface down to this area (mm²), after the listed
    /// patches (see [`REVIEW_MIN_MM2`]).
    pub review_min_mm2: f64,
    /// Reading flights look around as they go ([`Glances`]); off, they look only where the
    /// flight looks, as the paper's camera does.
    pub look_around: bool,
}

/// The smallest unseen bit the review visits (mm²): under a third of a 3 mm polyp's footprint.
/// Bits smaller than one polyp can still add up to one: where the flights glimpsed a fold's
/// far side at a grazing angle, pixels landed on some of its triangles and left the rest as
/// many small bits. A visit costs one to [`crate::POSES_PER_VISIT`] frames, and shows the
/// bits around it too: on `ctc/prone-tagged` visiting down to 2 mm² rather than the whole
/// footprint (7.07 mm²) showed 99.59 % after review, not 99.40 %, in about 5 s more of a
/// minute's reading (BENCHMARKS.md).
pub const REVIEW_MIN_MM2: f64 = 2.0;

/// The reading lens of [`read_both_ways`] and `voyage coverage` (vertical and horizontal
/// field of view of its square frames, degrees): the 120° of the primary-3D fly-through
/// whose readers saw about 77 % one way and 94 % both ways (Pickhardt et al., 2006).
pub const READING_FOV_DEG: f64 = 120.0;

impl Default for CoverageOptions {
    fn default() -> Self {
        CoverageOptions {
            reading_distance_mm: 50.0,
            max_angle_deg: 75.0,
            min_patch_mm2: 30.0,
            review_min_mm2: REVIEW_MIN_MM2,
            look_around: true,
        }
    }
}

/// Which triangles of a [`CellMesh`] have been seen (by draw index, as in the id buffer).
#[derive(Clone, Debug)]
pub struct Coverage {
    options: CoverageOptions,
    seen: Vec<bool>,
    area_mm2: Vec<f32>,
    total_mm2: f64,
    seen_mm2: f64,
    /// The frame each triangle was last met in, so that a frame tests a triangle once
    /// however many pixels it covers.
    met_in: Vec<u32>,
    frame_no: u32,
    candidates: Vec<u32>,
}

impl Coverage {
    pub fn new(mesh: &CellMesh, options: CoverageOptions) -> Self {
        let area_mm2: Vec<f32> = (0..mesh.triangles.len() as u32)
            .map(|t| {
                let [a, b, c] = triangle_points(mesh, t);
                (0.5 * (b - a).cross(c - a).length()) as f32
            })
            .collect();
        let total_mm2 = area_mm2.iter().map(|&a| a as f64).sum();
        Coverage {
            options,
            seen: vec![false; area_mm2.len()],
            total_mm2,
            seen_mm2: 0.0,
            met_in: vec![0; area_mm2.len()],
            frame_no: 0,
            candidates: Vec::new(),
            area_mm2,
        }
    }

    pub fn options(&self) -> &CoverageOptions {
        &self.options
    }

    /// Seen area over the whole surface, in percent.
    pub fn percent(&self) -> f64 {
        if self.total_mm2 > 0.0 {
            100.0 * self.seen_mm2 / self.total_mm2
        } else {
            0.0
        }
    }

    pub fn seen_mm2(&self) -> f64 {
        self.seen_mm2
    }

    pub fn total_mm2(&self) -> f64 {
        self.total_mm2
    }

    /// Area of triangle `t` (draw index), mm².
    pub fn area_of(&self, t: u32) -> f32 {
        self.area_mm2[t as usize]
    }

    /// Whether triangle `t` (draw index) has been seen.
    pub fn is_seen(&self, t: u32) -> bool {
        self.seen[t as usize]
    }

    /// Forgets everything seen.
    pub fn clear(&mut self) {
        self.seen.fill(false);
        self.seen_mm2 = 0.0;
    }

    /// Marks what `frame`, drawn from `view`, shows of `mesh`; returns the area newly seen
    /// (mm²).
    pub fn mark(&mut self, frame: &Frame, view: &View, mesh: &CellMesh) -> f64 {
        self.tally(frame, view, mesh, true)
    }

    /// The area `frame`, drawn from `view`, would newly show (mm²), left unmarked.
    pub fn gain(&mut self, frame: &Frame, view: &View, mesh: &CellMesh) -> f64 {
        self.tally(frame, view, mesh, false)
    }

    /// The unseen area `frame` shows, marked seen when `commit`.
    fn tally(&mut self, frame: &Frame, view: &View, mesh: &CellMesh, commit: bool) -> f64 {
        self.next_frame();
        self.collect_candidates(frame, view);
        let cos_max = self.options.max_angle_deg.to_radians().cos();
        let mut added = 0.0;
        for &t in &self.candidates {
            let [a, b, c] = triangle_points(mesh, t);
            let normal = smooth_normal(mesh, t);
            let to_eye = view.eye - (a + b + c) / 3.0;
            if normal.dot(to_eye) >= cos_max * normal.length() * to_eye.length() {
                self.seen[t as usize] |= commit;
                added += self.area_mm2[t as usize] as f64;
            }
        }
        if commit {
            self.seen_mm2 += added;
        }
        added
    }

    fn next_frame(&mut self) {
        self.frame_no = self.frame_no.wrapping_add(1);
        if self.frame_no == 0 {
            self.met_in.fill(0);
            self.frame_no = 1;
        }
        self.candidates.clear();
    }

    /// The unseen triangles `frame` covers within the reading distance, each once.
    fn collect_candidates(&mut self, frame: &Frame, view: &View) {
        let max = self.options.reading_distance_mm;
        let (w, h) = (frame.width as usize, frame.height as usize);
        for y in 0..h {
            for (x, p) in frame.pixels[y * w..(y + 1) * w].iter().enumerate() {
                let t = p.id;
                if t == NO_TRIANGLE
                    || self.seen[t as usize]
                    || self.met_in[t as usize] == self.frame_no
                {
                    continue;
                }
                if view.pixel_distance(x as u32, y as u32, p.inv_depth) <= max {
                    self.met_in[t as usize] = self.frame_no;
                    self.candidates.push(t);
                }
            }
        }
    }

    /// Seen and whole area of the mucosa per colon segment, in the segments' order from the
    /// rectum ([`COLON_SEGMENTS`]; "colon" last for cells the centerline does not serve).
    /// `mesh` must be `study`'s surface cut into its cells.
    pub fn by_segment(&self, mesh: &CellMesh, study: &Study) -> Vec<SegmentSeen> {
        let names = study.cell_segments();
        let mut out: Vec<SegmentSeen> = COLON_SEGMENTS
            .iter()
            .chain(&["colon"])
            .map(|&segment| SegmentSeen {
                segment,
                seen_mm2: 0.0,
                total_mm2: 0.0,
            })
            .collect();
        for (c, range) in mesh.cell_ranges.iter().enumerate() {
            let name = names.get(c).copied().unwrap_or("colon");
            let Some(row) = out.iter_mut().find(|r| r.segment == name) else {
                continue;
            };
            for t in range.clone() {
                let area = self.area_mm2[t as usize] as f64;
                row.total_mm2 += area;
                if self.seen[t as usize] {
                    row.seen_mm2 += area;
                }
            }
        }
        out.retain(|r| r.total_mm2 > 0.0);
        out
    }

    /// Joins in what `other` (over the same mesh) has seen.
    pub fn union(&mut self, other: &Coverage) {
        assert_eq!(
            self.seen.len(),
            other.seen.len(),
            "coverage of another mesh"
        );
        for (t, (s, &o)) in self.seen.iter_mut().zip(&other.seen).enumerate() {
            if o && !*s {
                *s = true;
                self.seen_mm2 += self.area_mm2[t] as f64;
            }
        }
    }

    /// The connected unseen parts of the surface (triangles sharing a vertex), at least
    /// `min_patch_mm2` each, largest first: the patches listed.
    pub fn patches(&self, mesh: &CellMesh) -> Vec<Patch> {
        self.patches_of(mesh, self.options.min_patch_mm2)
    }

    /// What a review visits: the unseen patches down to `review_min_mm2` (or `min_patch_mm2`
    /// where that is smaller), largest first, so the listed patches come first.
    pub fn review_targets(&self, mesh: &CellMesh) -> Vec<Patch> {
        let min = self.options.review_min_mm2.min(self.options.min_patch_mm2);
        self.patches_of(mesh, min)
    }

    /// The connected unseen parts of at least `min_mm2`, largest first.
    fn patches_of(&self, mesh: &CellMesh, min_mm2: f64) -> Vec<Patch> {
        let mut parent: Vec<u32> = (0..mesh.positions.len() as u32).collect();
        let unseen = || (0..self.seen.len() as u32).filter(|&t| !self.seen[t as usize]);
        for t in unseen() {
            let [a, b, c] = mesh.triangles[t as usize];
            union(&mut parent, a, b);
            union(&mut parent, a, c);
        }
        let mut root_patch: std::collections::HashMap<u32, usize> = Default::default();
        let mut groups: Vec<Vec<u32>> = Vec::new();
        for t in unseen() {
            let root = find(&mut parent, mesh.triangles[t as usize][0]);
            let at = *root_patch.entry(root).or_insert_with(|| {
                groups.push(Vec::new());
                groups.len() - 1
            });
            groups[at].push(t);
        }
        let mut patches: Vec<Patch> = groups
            .into_iter()
            .filter_map(|tris| {
                let area: f64 = tris.iter().map(|&t| self.area_mm2[t as usize] as f64).sum();
                (area >= min_mm2).then(|| Patch::new(mesh, tris, area))
            })
            .collect();
        patches.sort_by(|a, b| b.area_mm2.total_cmp(&a.area_mm2));
        patches
    }
}

/// The mucosa of one colon segment: its area and what was seen of it (mm²).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentSeen {
    pub segment: &'static str,
    pub seen_mm2: f64,
    pub total_mm2: f64,
}

impl SegmentSeen {
    pub fn percent(&self) -> f64 {
        if self.total_mm2 > 0.0 {
            100.0 * self.seen_mm2 / self.total_mm2
        } else {
            0.0
        }
    }
}

fn find(parent: &mut [u32], mut v: u32) -> u32 {
    while parent[v as usize] != v {
        let up = parent[parent[v as usize] as usize];
        parent[v as usize] = up;
        v = up;
    }
    v
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        // The smaller root wins, so the result does not depend on the order of unions.
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        parent[hi as usize] = lo;
    }
}

#[inline]
fn triangle_points(mesh: &CellMesh, t: u32) -> [DVec3; 3] {
    mesh.triangles[t as usize].map(|v| DVec3::from_array(mesh.positions[v as usize].map(f64::from)))
}

/// The mucosa's orientation at triangle `t`: the sum of its vertices' smoothed normals. A
/// facet's own normal on a terraced marching-cubes surface (a 0/1 mask, a coarse scan) tilts
/// up to 55° from the wall's, and would fail the reading angle on wall that faces the eye.
#[inline]
fn smooth_normal(mesh: &CellMesh, t: u32) -> DVec3 {
    mesh.triangles[t as usize]
        .iter()
        .map(|&v| DVec3::from_array(mesh.normals[v as usize].map(f64::from)))
        .sum()
}

/// A patch's normal is the mean over its surface within this distance of its centre (mm).
const NORMAL_RADIUS_MM: f64 = 4.0;

/// Points of a patch tried after its centre, at least this far from those before (mm).
const MORE_ANCHORS: usize = 4;
const ANCHOR_APART_MM: f64 = 3.0;

/// A point of a patch a review aims at.
struct Anchor {
    point: DVec3,
    normal: DVec3,
    triangle: u32,
}

fn centroid_of(mesh: &CellMesh, t: u32) -> DVec3 {
    let [a, b, c] = triangle_points(mesh, t);
    (a + b + c) / 3.0
}

/// The area-weighted normal of `triangles` within [`NORMAL_RADIUS_MM`] of `p` (unit): the
/// normal around a point, not the whole patch's (a long patch round a fold or a tube's whole
/// wall has normals that cancel).
fn normal_around(mesh: &CellMesh, triangles: &[u32], p: DVec3) -> DVec3 {
    let sum: DVec3 = triangles
        .iter()
        .filter(|&&t| centroid_of(mesh, t).distance(p) <= NORMAL_RADIUS_MM)
        .map(|&t| {
            let [a, b, c] = triangle_points(mesh, t);
            (b - a).cross(c - a)
        })
        .sum();
    sum.try_normalize().unwrap_or(DVec3::Z)
}

/// A connected unseen part of the surface.
#[derive(Clone, Debug)]
pub struct Patch {
    pub area_mm2: f64,
    /// Its triangles (draw indices).
    pub triangles: Vec<u32>,
    /// Volume-local mm: the centroid of the patch's triangle nearest the area-weighted
    /// centre, so that it lies on the patch even where the patch is curved.
    pub center_mm: DVec3,
    /// The triangle whose centroid is the centre.
    pub center_triangle: u32,
    /// Area-weighted mean normal around the centre (unit, into the lumen).
    pub normal: DVec3,
    /// The largest distance from the centre to a vertex of the patch, times two (mm).
    pub across_mm: f64,
}

impl Patch {
    /// The edges of the patch's triangles that no other of its triangles shares: its
    /// outline (drawn over the view when a review visits it).
    pub fn outline(&self, mesh: &CellMesh) -> Vec<[DVec3; 2]> {
        let mut count: std::collections::HashMap<[u32; 2], u32> = Default::default();
        for &t in &self.triangles {
            let [a, b, c] = mesh.triangles[t as usize];
            for (u, v) in [(a, b), (b, c), (c, a)] {
                *count.entry([u.min(v), u.max(v)]).or_insert(0) += 1;
            }
        }
        let at = |v: u32| DVec3::from_array(mesh.positions[v as usize].map(f64::from));
        let mut edges: Vec<[u32; 2]> = count
            .into_iter()
            .filter(|&(_, n)| n == 1)
            .map(|(e, _)| e)
            .collect();
        edges.sort_unstable();
        edges.into_iter().map(|[u, v]| [at(u), at(v)]).collect()
    }

    fn new(mesh: &CellMesh, triangles: Vec<u32>, area_mm2: f64) -> Patch {
        let mut weighted = DVec3::ZERO;
        for &t in &triangles {
            let [a, b, c] = triangle_points(mesh, t);
            weighted += (a + b + c) / 3.0 * (0.5 * (b - a).cross(c - a).length());
        }
        let mean = weighted / area_mm2.max(f64::MIN_POSITIVE);
        let centroid = |t: u32| centroid_of(mesh, t);
        let center_triangle = triangles
            .iter()
            .copied()
            .min_by(|&p, &q| {
                centroid(p)
                    .distance_squared(mean)
                    .total_cmp(&centroid(q).distance_squared(mean))
            })
            .unwrap_or(0);
        let center_mm = triangles
            .first()
            .map_or(mean, |_| centroid(center_triangle));
        let across_mm = 2.0
            * triangles
                .iter()
                .flat_map(|&t| triangle_points(mesh, t))
                .map(|p| p.distance(center_mm))
                .fold(0.0, f64::max);
        let normal = normal_around(mesh, &triangles, center_mm);
        Patch {
            area_mm2,
            triangles,
            center_mm,
            center_triangle,
            normal,
            across_mm,
        }
    }

    /// Where a review may aim at the patch, in turn: its centre, then up to
    /// [`MORE_ANCHORS`] triangles spread over it (each the farthest from those before), for
    /// a patch whose centre no viewpoint shows. Each with its centroid and the normal
    /// around it.
    fn anchors<'m>(&'m self, mesh: &'m CellMesh) -> impl Iterator<Item = Anchor> + 'm {
        let first = Anchor {
            point: self.center_mm,
            normal: self.normal,
            triangle: self.center_triangle,
        };
        // Made when the centre fails: the centroids, and each one's squared distance to the
        // nearest anchor so far.
        let mut centroids: Vec<DVec3> = Vec::new();
        let mut nearest: Vec<f64> = Vec::new();
        let more = (0..MORE_ANCHORS).map_while(move |_| {
            if centroids.is_empty() {
                centroids = self
                    .triangles
                    .iter()
                    .map(|&t| centroid_of(mesh, t))
                    .collect();
                nearest = centroids
                    .iter()
                    .map(|c| c.distance_squared(self.center_mm))
                    .collect();
            }
            let (i, &d) = nearest
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))?;
            if d < ANCHOR_APART_MM * ANCHOR_APART_MM {
                return None;
            }
            let t = self.triangles[i];
            let point = centroids[i];
            for (n, c) in nearest.iter_mut().zip(&centroids) {
                *n = n.min(c.distance_squared(point));
            }
            Some(Anchor {
                point,
                normal: normal_around(mesh, &self.triangles, point),
                triangle: t,
            })
        });
        std::iter::once(first).chain(more)
    }

    /// Arc length (mm from the centerline's rectum end) of the centerline point nearest the
    /// patch's centre, read just off the wall in the lumen as the findings' distances are
    /// ([`Study::arc_at`]: a loop beyond the wall is not taken for the patch's own).
    pub fn arc_mm(&self, study: &Study) -> Option<f64> {
        study.arc_at(self.center_mm + self.normal * OFF_WALL_MM)
    }
}

/// Where a camera may stand, and how far from the wall it keeps.
pub struct Lumen<'a> {
    /// Ds (mm to the wall), as prep made it.
    pub ds: &'a Bricked<f32>,
    /// The camera keeps at least this far from the wall (the navigable core's distance).
    pub min_wall_mm: f64,
    /// Up, for the poses made here (the patient's anterior).
    pub up: DVec3,
}

impl<'a> Lumen<'a> {
    /// The study's lumen, for a camera kept `min_wall_mm` from the wall, the patient's
    /// anterior up.
    pub fn of(study: &'a Study, min_wall_mm: f64) -> Self {
        Lumen {
            ds: &study.ds,
            min_wall_mm,
            up: study.anterior_local(),
        }
    }
}

/// Tilts (degrees from the patch's normal) and azimuths tried for a viewpoint, in order.
const TILTS_DEG: [f64; 4] = [0.0, 20.0, 40.0, 60.0];
const AZIMUTHS: usize = 8;
/// Nearest a viewpoint stands to the patch (mm): a closer one sees too little around it.
const MIN_VIEW_MM: f64 = 4.0;
/// Step along a candidate line of sight (mm).
const SIGHT_STEP_MM: f64 = 0.5;

/// The poses that show `patch`, in the order they are tried: each a point in the lumen, at
/// least `min_wall_mm` from the wall and within the reading distance of a point of the
/// patch, that sees that point unoccluded (a ray pick against the surface meets the patch,
/// not a fold before it) and as the reading counts it (its triangle faces the eye within the
/// reading angle), looking at it. Lines of sight are tried from along the patch's normal
/// outward in tilts up to 60° (inside the reading angle); along each, the viewpoint is the
/// one farthest from the wall. The patch's centre comes first, then other points spread over
/// it. Later poses serve where a frame from the first shows nothing new (the pick meets the
/// point, and yet none of its pixels lands on an unseen triangle the reading counts).
pub fn viewing_poses<'a>(
    patch: &'a Patch,
    mesh: &'a CellMesh,
    lumen: &'a Lumen,
    options: &'a CoverageOptions,
) -> impl Iterator<Item = Pose> + 'a {
    patch
        .anchors(mesh)
        .flat_map(move |anchor| poses_showing(anchor, mesh, lumen, options))
}

/// The poses that show `anchor` (see [`viewing_poses`]), line of sight by line of sight.
fn poses_showing<'a>(
    anchor: Anchor,
    mesh: &'a CellMesh,
    lumen: &'a Lumen,
    options: &'a CoverageOptions,
) -> impl Iterator<Item = Pose> + 'a {
    let (c, n) = (anchor.point, anchor.normal);
    let (e1, e2) = n.any_orthonormal_pair();
    let max_t = options.reading_distance_mm * 0.8;
    let cos_max = options.max_angle_deg.to_radians().cos();
    let facing = smooth_normal(mesh, anchor.triangle);
    let lines = TILTS_DEG.into_iter().flat_map(|tilt| {
        let azimuths = if tilt == 0.0 { 1 } else { AZIMUTHS };
        (0..azimuths).map(move |k| (tilt, k as f64 * std::f64::consts::TAU / azimuths as f64))
    });
    lines.filter_map(move |(tilt, phi)| {
        let (st, ct) = tilt.to_radians().sin_cos();
        let u = (n * ct + (e1 * phi.cos() + e2 * phi.sin()) * st).normalize();
        let eye = viewpoint_along(c, u, max_t, lumen)?;
        let to_patch = c - eye;
        let to_eye = -to_patch;
        if facing.dot(to_eye) < cos_max * facing.length() * to_eye.length() {
            return None;
        }
        pick(mesh, None, eye, to_patch)
            .is_some_and(|hit| hit.distance >= to_patch.length() - 1.0)
            .then(|| Pose::looking(eye, to_patch, lumen.up))
    })
}

/// Along the line from `c` in direction `u`, while it stays in the lumen, the point farthest
/// from the wall at least [`MIN_VIEW_MM`] out and `min_wall_mm` from the wall.
fn viewpoint_along(c: DVec3, u: DVec3, max_t: f64, lumen: &Lumen) -> Option<DVec3> {
    let mut best: Option<(f64, DVec3)> = None;
    let mut t = SIGHT_STEP_MM;
    while t <= max_t {
        let q = c + u * t;
        let ds = lumen.ds.sample(q) as f64;
        if ds <= 0.0 {
            break;
        }
        if t >= MIN_VIEW_MM && ds >= lumen.min_wall_mm && best.is_none_or(|(b, _)| ds > b) {
            best = Some((ds, q));
        }
        t += SIGHT_STEP_MM;
    }
    best.map(|(_, q)| q)
}

/// Draws frames with the CPU rasterizer (exact culling, ids and depths only) and marks what they show: the
/// reading of a flight, a movie, a review, or the window's frames (on a small frame of the
/// same view). It owns the frame and the culling state from frame to frame.
pub struct Reader {
    camera: Camera,
    visibility: Visibility,
    frame: Frame,
    /// The view `frame` was last drawn from.
    drawn: Option<View>,
}

/// Slack on the reading distance for what a reader's frame draws (mm): a pixel's distance is
/// computed from its depth in f32, never off by this much.
const REACH_SLACK_MM: f64 = 1.0;

impl Reader {
    /// Frames of `width` × `height` through `camera`'s lens (its pose is replaced per frame),
    /// of the surface cut into `cells`.
    pub fn new(cells: &Cells, camera: Camera, width: u32, height: u32) -> Self {
        Reader {
            camera,
            visibility: Visibility::new(cells, Strategy::Ours),
            frame: Frame::new(width, height),
            drawn: None,
        }
    }

    /// Another frame size and lens; the culling state is kept.
    pub fn set_lens(&mut self, camera: Camera, width: u32, height: u32) {
        self.camera = camera;
        if (self.frame.width, self.frame.height) != (width, height) {
            self.frame = Frame::new(width, height);
            self.drawn = None;
        }
    }

    /// Draws `mesh` (cut into `cells`) from `pose` and marks what it shows; returns the area
    /// newly seen (mm²).
    pub fn show(
        &mut self,
        mesh: &CellMesh,
        cells: &Cells,
        pose: Pose,
        coverage: &mut Coverage,
    ) -> f64 {
        let view = self.draw(mesh, cells, pose, coverage.options.reading_distance_mm);
        coverage.mark(&self.frame, &view, mesh)
    }

    /// Draws `mesh` from `pose` and returns the area the frame would newly show (mm²),
    /// left unmarked.
    pub fn probe(
        &mut self,
        mesh: &CellMesh,
        cells: &Cells,
        pose: Pose,
        coverage: &mut Coverage,
    ) -> f64 {
        let view = self.draw(mesh, cells, pose, coverage.options.reading_distance_mm);
        coverage.gain(&self.frame, &view, mesh)
    }

    /// The first of `poses` whose frame would newly show something of `coverage`, with that
    /// area (mm²); its frame stays drawn, unmarked ([`Reader::mark_drawn`]).
    pub fn first_showing(
        &mut self,
        mesh: &CellMesh,
        cells: &Cells,
        poses: impl IntoIterator<Item = Pose>,
        coverage: &mut Coverage,
    ) -> Option<(Pose, f64)> {
        poses.into_iter().find_map(|pose| {
            let shown = self.probe(mesh, cells, pose, coverage);
            (shown > 0.0).then_some((pose, shown))
        })
    }

    /// Marks what the frame last drawn shows; returns the area newly seen (mm²).
    pub fn mark_drawn(&mut self, mesh: &CellMesh, coverage: &mut Coverage) -> f64 {
        match self.drawn {
            Some(view) => coverage.mark(&self.frame, &view, mesh),
            None => 0.0,
        }
    }

    /// Draws what lies within `reach_mm` of the eye (coverage reads no pixel farther).
    fn draw(&mut self, mesh: &CellMesh, cells: &Cells, pose: Pose, reach_mm: f64) -> View {
        let camera = Camera {
            pose,
            ..self.camera
        };
        let view = View::new(&camera, self.frame.width, self.frame.height);
        let raster = Rasterizer::ids_only(mesh, view).within_reach(reach_mm + REACH_SLACK_MM);
        self.frame.clear();
        self.visibility.draw(&mut self.frame, &raster, cells);
        self.drawn = Some(view);
        view
    }

    /// The frame last drawn.
    pub fn frame(&self) -> &Frame {
        &self.frame
    }
}

/// Travel (mm) between two looks around during a reading flight.
pub const GLANCE_EVERY_MM: f64 = 7.0;
/// How far (degrees) a glance turns from the flight's view: up, down, left or right.
pub const GLANCE_TURN_DEG: f64 = 65.0;
/// A glance is taken where it would show at least this much unseen mucosa (mm²).
pub const GLANCE_MIN_MM2: f64 = 100.0;
/// Ways a glance can turn, evenly around the view.
pub const GLANCE_WAYS: usize = 8;
/// Side of the small frames that try the glances (pixels).
const PROBE_PX: u32 = 64;

/// The body-frame turns of the glances: [`GLANCE_TURN_DEG`] away from the view, toward
/// each of [`GLANCE_WAYS`] directions around it (up, up-left, left, ...).
pub fn glance_turns() -> impl Iterator<Item = DQuat> {
    (0..GLANCE_WAYS).map(glance_turn)
}

fn glance_turn(way: usize) -> DQuat {
    let around = way as f64 * std::f64::consts::TAU / GLANCE_WAYS as f64;
    let axis = DVec3::new(around.cos(), around.sin(), 0.0);
    DQuat::from_axis_angle(axis, GLANCE_TURN_DEG.to_radians())
}

/// A reader's looking around during a flight: every [`GLANCE_EVERY_MM`] of travel it tries
/// turning the view [`GLANCE_TURN_DEG`] each of [`GLANCE_WAYS`] ways on a small frame, and
/// glances the way that would show most unseen mucosa, where that is at least
/// [`GLANCE_MIN_MM2`]: the wall of a wide chamber the straight view passes at a slant.
pub struct Glances {
    probe: Reader,
    travelled_mm: f64,
    last: Option<DVec3>,
    /// While trying the ways at a stop: the next way's index, and the best so far (its
    /// gain in mm², its turn).
    trying: Option<(usize, f64, DQuat)>,
    /// Ways tried, and glances taken.
    pub tries: usize,
    pub taken: usize,
}

impl Glances {
    pub fn new(cells: &Cells, camera: Camera) -> Self {
        Glances {
            probe: Reader::new(cells, camera, PROBE_PX, PROBE_PX),
            travelled_mm: 0.0,
            last: None,
            trying: None,
            tries: 0,
            taken: 0,
        }
    }

    /// After each of the flight's frames (at `pose`, already shown): once the flight has come
    /// [`GLANCE_EVERY_MM`] since the last stop, tries one way per frame, so that no frame
    /// pays for all of them; after the last way, the glance worth taking, if any, turned
    /// from the view of that frame. The glance is not marked here: the caller shows it.
    pub fn next(
        &mut self,
        mesh: &CellMesh,
        cells: &Cells,
        pose: Pose,
        coverage: &mut Coverage,
    ) -> Option<Pose> {
        let here = pose.position;
        self.travelled_mm += self.last.map_or(0.0, |p| p.distance(here));
        self.last = Some(here);
        if self.trying.is_none() {
            if self.travelled_mm < GLANCE_EVERY_MM {
                return None;
            }
            self.travelled_mm = 0.0;
            self.trying = Some((0, f64::NEG_INFINITY, DQuat::IDENTITY));
        }
        let (way, best, best_turn) = self.trying?;
        let turn = glance_turn(way);
        let turned = |q: DQuat| Pose {
            position: here,
            orientation: pose.orientation * q,
        };
        let gain = self.probe.probe(mesh, cells, turned(turn), coverage);
        self.tries += 1;
        let (best, best_turn) = if gain > best {
            (gain, turn)
        } else {
            (best, best_turn)
        };
        if way + 1 < GLANCE_WAYS {
            self.trying = Some((way + 1, best, best_turn));
            return None;
        }
        self.trying = None;
        (best >= GLANCE_MIN_MM2).then(|| {
            self.taken += 1;
            turned(best_turn)
        })
    }
}
