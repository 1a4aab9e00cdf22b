//! The radiologist's findings: markers dropped on the colon wall under the mouse cursor, each
//! with a note and the camera pose to fly back to; two-click measurements in mm. Their
//! export is `voyage_export::export_findings`.
//!
//! Everything here is in volume-local mm, the frame of the mesh and of the camera's poses;
//! LPS appears only in the exported files.

use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use voyage_nav::Pose;

use crate::mesh::CellMesh;

/// Where a ray first meets the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Volume-local mm.
    pub point: DVec3,
    /// Unit geometric normal of the triangle, facing the ray's origin (into the lumen).
    pub normal: DVec3,
    /// Index into `mesh.triangles` (the draw index, as in the rasterizer's id buffer).
    pub triangle: u32,
    /// From the ray's origin to `point`, mm.
    pub distance: f64,
}

/// The nearest front-facing triangle along the ray from `origin` along `dir` (any length),
/// searching only `cells` (those the renderer drew) or, with `None`, every cell. Back faces
/// are ignored as the renderer culls them, so a click always lands on what the user sees;
/// ties go to the smaller triangle index, as in the rasterizer's id buffer.
pub fn pick(mesh: &CellMesh, cells: Option<&[u32]>, origin: DVec3, dir: DVec3) -> Option<Hit> {
    let dir = dir.try_normalize()?;
    if !origin.is_finite() {
        return None;
    }
    let ray = Ray::new(origin, dir);
    let in_cell = |c: usize| nearest_in_cell(mesh, c, &ray);
    // A click searches about a million triangles; cells are the natural parallel chunks.
    let best = match cells {
        Some(list) => list
            .par_iter()
            .filter(|&&c| (c as usize) < mesh.cell_ranges.len())
            .filter_map(|&c| in_cell(c as usize))
            .min_by(nearer),
        None => (0..mesh.cell_ranges.len())
            .into_par_iter()
            .filter_map(in_cell)
            .min_by(nearer),
    }?;
    let (distance, triangle) = best;
    let [a, b, c] = triangle_points(mesh, triangle);
    Some(Hit {
        point: origin + dir * distance,
        normal: (b - a).cross(c - a).normalize(),
        triangle,
        distance,
    })
}

/// Orders (distance, triangle) candidates: nearer first, then the smaller triangle.
fn nearer(x: &(f64, u32), y: &(f64, u32)) -> std::cmp::Ordering {
    x.0.total_cmp(&y.0).then(x.1.cmp(&y.1))
}

/// A ray from `origin` along the unit `dir`, with what its box tests need.
struct Ray {
    origin: DVec3,
    dir: DVec3,
    inv_dir: DVec3,
}

impl Ray {
    fn new(origin: DVec3, dir: DVec3) -> Ray {
        Ray {
            origin,
            dir,
            inv_dir: dir.recip(),
        }
    }

    /// Whether the ray meets the box (slab test), padded by [`BOX_PAD_MM`] against rounding:
    /// a triangle the ray meets lies in its chunk's box, so a chunk it misses holds no hit.
    fn meets_box(&self, lo: [f32; 3], hi: [f32; 3]) -> bool {
        let lo = DVec3::from_array(lo.map(f64::from)) - BOX_PAD_MM;
        let hi = DVec3::from_array(hi.map(f64::from)) + BOX_PAD_MM;
        let (mut near, mut far) = (0.0f64, f64::INFINITY);
        for k in 0..3 {
            if self.dir[k] == 0.0 {
                if self.origin[k] < lo[k] || self.origin[k] > hi[k] {
                    return false;
                }
                continue;
            }
            let a = (lo[k] - self.origin[k]) * self.inv_dir[k];
            let b = (hi[k] - self.origin[k]) * self.inv_dir[k];
            near = near.max(a.min(b));
            far = far.min(a.max(b));
        }
        near <= far
    }
}

/// Padding of a chunk's box in the ray's box test (mm).
const BOX_PAD_MM: f64 = 1e-3;

/// The nearest hit in cell `c`: over its chunks the ray's line meets where the mesh has
/// chunks ([`CellMesh::index_cells`]), else over all its triangles. The same hit either way.
fn nearest_in_cell(mesh: &CellMesh, c: usize, ray: &Ray) -> Option<(f64, u32)> {
    let Some(chunks) = mesh.cell_chunks.get(c) else {
        return nearest_in_range(mesh, mesh.cell_ranges[c].clone(), ray.origin, ray.dir);
    };
    mesh.chunks[chunks.start as usize..chunks.end as usize]
        .iter()
        .filter(|k| ray.meets_box(k.lo, k.hi))
        .filter_map(|k| nearest_in_range(mesh, k.triangles.clone(), ray.origin, ray.dir))
        .min_by(nearer)
}

fn nearest_in_range(
    mesh: &CellMesh,
    range: Range<u32>,
    origin: DVec3,
    dir: DVec3,
) -> Option<(f64, u32)> {
    let mut best: Option<(f64, u32)> = None;
    for t in range {
        let [a, b, c] = triangle_points(mesh, t);
        if let Some(d) = intersect_front(origin, dir, a, b, c) {
            // Ascending t: a strictly nearer hit replaces, an equal one keeps the smaller id.
            if best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, t));
            }
        }
    }
    best
}

#[inline]
fn triangle_points(mesh: &CellMesh, t: u32) -> [DVec3; 3] {
    mesh.triangles[t as usize].map(|v| DVec3::from_array(mesh.positions[v as usize].map(f64::from)))
}

/// Möller–Trumbore, front faces only: the distance along the unit `dir` where the ray meets
/// triangle (a, b, c), if it does in front of the origin and against the normal
/// (b − a) × (c − a). Edges are inclusive so that a ray through a shared edge hits a triangle.
#[inline]
fn intersect_front(origin: DVec3, dir: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<f64> {
    let e1 = b - a;
    let e2 = c - a;
    let p = dir.cross(e2);
    // det = −dir · (e1 × e2): positive exactly when the ray meets the face from its normal's
    // side. Back faces, edge-on and degenerate triangles (and NaN) fail here.
    let det = e1.dot(p);
    if det <= 0.0 || det.is_nan() {
        return None;
    }
    let s = origin - a;
    let u = s.dot(p);
    if u < 0.0 || u > det {
        return None;
    }
    let q = s.cross(e1);
    let v = dir.dot(q);
    if v < 0.0 || u + v > det {
        return None;
    }
    let t = e2.dot(q) / det;
    (t > 0.0).then_some(t)
}

/// What a finding is, as a report names it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FindingKind {
    Polyp,
    Mass,
    Diverticulum,
    #[default]
    Other,
}

impl FindingKind {
    pub const ALL: [FindingKind; 4] = [
        FindingKind::Polyp,
        FindingKind::Mass,
        FindingKind::Diverticulum,
        FindingKind::Other,
    ];

    pub fn name(self) -> &'static str {
        match self {
            FindingKind::Polyp => "polyp",
            FindingKind::Mass => "mass",
            FindingKind::Diverticulum => "diverticulum",
            FindingKind::Other => "other",
        }
    }
}

/// A finding on the wall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    pub label: String,
    pub note: String,
    #[serde(default)]
    pub kind: FindingKind,
    /// Largest diameter (mm), from the 3D size tool ([`crate::measure_polyp`]).
    #[serde(default)]
    pub size_mm: Option<f64>,
    /// Volume-local mm.
    pub position: DVec3,
    /// Unit normal of the wall there, into the lumen.
    pub normal: DVec3,
    /// The camera when the marker was dropped, to fly back to.
    pub view: Pose,
}

/// A distance between two points on the wall (two clicks).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    pub label: String,
    /// Volume-local mm.
    pub a: DVec3,
    pub b: DVec3,
}

impl Measurement {
    /// Volume-local mm are real mm (spacing applied), so this is the physical distance.
    pub fn length_mm(&self) -> f64 {
        (self.b - self.a).length()
    }
}

/// Everything the radiologist noted on one study.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Findings {
    pub markers: Vec<Marker>,
    pub measurements: Vec<Measurement>,
}

impl Findings {
    /// Adds a marker labelled M1, M2, ... (one past the highest number in use, so that a
    /// label the radiologist may already have quoted never names a different finding while
    /// it exists); returns it.
    pub fn add_marker(
        &mut self,
        position: DVec3,
        normal: DVec3,
        view: Pose,
        note: impl Into<String>,
    ) -> &Marker {
        let label = next_label("M", self.markers.iter().map(|m| m.label.as_str()));
        self.markers.push(Marker {
            label,
            note: note.into(),
            kind: FindingKind::Other,
            size_mm: None,
            position,
            normal,
            view,
        });
        self.markers.last().expect("just pushed")
    }

    /// Adds a measurement labelled L1, L2, ...; returns it.
    pub fn add_measurement(&mut self, a: DVec3, b: DVec3) -> &Measurement {
        let label = next_label("L", self.measurements.iter().map(|m| m.label.as_str()));
        self.measurements.push(Measurement { label, a, b });
        self.measurements.last().expect("just pushed")
    }

    pub fn marker(&self, label: &str) -> Option<&Marker> {
        self.markers.iter().find(|m| m.label == label)
    }

    /// For editing a marker's note.
    pub fn marker_mut(&mut self, label: &str) -> Option<&mut Marker> {
        self.markers.iter_mut().find(|m| m.label == label)
    }

    pub fn measurement(&self, label: &str) -> Option<&Measurement> {
        self.measurements.iter().find(|m| m.label == label)
    }

    pub fn remove_marker(&mut self, label: &str) -> Option<Marker> {
        let i = self.markers.iter().position(|m| m.label == label)?;
        Some(self.markers.remove(i))
    }

    pub fn remove_measurement(&mut self, label: &str) -> Option<Measurement> {
        let i = self.measurements.iter().position(|m| m.label == label)?;
        Some(self.measurements.remove(i))
    }

    pub fn is_empty(&self) -> bool {
        self.markers.is_empty() && self.measurements.is_empty()
    }
}

/// The exam's colonic category of ACR C-RADS (Zalis et al., Radiology 2005), from the
/// findings: C0 an inadequate exam (here: no finding of C2 or above, and too little of the
/// mucosa seen to call it negative), C1 no polyp of 6 mm or more, C2 one or two polyps of
/// 6–9 mm, C3 a polyp of 10 mm or more or three or more of 6–9 mm, C4 a mass likely
/// malignant. Diverticula and other findings do not raise it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CRads {
    /// "C0" to "C4".
    pub category: &'static str,
    /// Why, in words.
    pub reason: String,
    /// Polyps without a size: the category holds only if they are under 6 mm.
    pub unsized_polyps: Vec<String>,
}

/// Coverage of the mucosa the reading showed in the end below this (%) makes the exam
/// inadequate (C0).
pub const C0_BELOW_COVERAGE_PCT: f64 = 90.0;

/// Whether a reading can call an exam negative: how much it showed, and what the colon it
/// read may lack.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Adequacy {
    /// The share of the mucosa the reading showed in the end (%), when known: after its
    /// review, or over the window's whole session; a flight's own figure only when there is
    /// nothing else (a reader who reviewed the unseen patches has seen them).
    pub read_pct: Option<f64>,
    /// Gas left out of the colon that may be colon (ml, the largest region of at least 100):
    /// the reading then covered part of the colon only.
    pub left_out_ml: Option<f64>,
}

/// The C-RADS category of `findings`. A negative reading is C0 (inadequate) when it showed
/// under [`C0_BELOW_COVERAGE_PCT`] of the mucosa, or when a colon region was left out of it;
/// a positive finding stands whatever was read.
pub fn c_rads(findings: &Findings, adequacy: Adequacy) -> CRads {
    let polyps: Vec<&Marker> = findings
        .markers
        .iter()
        .filter(|m| m.kind == FindingKind::Polyp)
        .collect();
    let unsized_polyps: Vec<String> = polyps
        .iter()
        .filter(|m| m.size_mm.is_none())
        .map(|m| m.label.clone())
        .collect();
    let sizes: Vec<f64> = polyps.iter().filter_map(|m| m.size_mm).collect();
    let large = sizes.iter().filter(|&&s| s >= 10.0).count();
    let medium = sizes.iter().filter(|&&s| (6.0..10.0).contains(&s)).count();
    let masses = findings
        .markers
        .iter()
        .filter(|m| m.kind == FindingKind::Mass)
        .count();
    let (category, reason) = if masses > 0 {
        ("C4", format!("{masses} colonic mass(es), likely malignant"))
    } else if large > 0 || medium >= 3 {
        (
            "C3",
            format!("{large} polyp(s) ≥ 10 mm, {medium} of 6–9 mm: possibly advanced adenoma"),
        )
    } else if medium > 0 {
        ("C2", format!("{medium} polyp(s) of 6–9 mm"))
    } else if let Some(ml) = adequacy.left_out_ml {
        (
            "C0",
            format!(
                "inadequate: no polyp of 6 mm or more in the colon read, but {ml:.0} ml of gas that may be colon was left out of it"
            ),
        )
    } else if let Some(pct) = adequacy.read_pct.filter(|&p| p < C0_BELOW_COVERAGE_PCT) {
        // A negative reading of too little mucosa is no negative exam; a positive finding
        // stands however much was seen.
        (
            "C0",
            format!(
                "inadequate: no polyp of 6 mm or more, but only {pct:.1} % of the mucosa seen (under {C0_BELOW_COVERAGE_PCT:.0} %)"
            ),
        )
    } else {
        ("C1", "no polyp of 6 mm or more".to_string())
    };
    CRads {
        category,
        reason,
        unsized_polyps,
    }
}

/// `prefix` followed by one more than the highest number among `labels` of that form.
fn next_label<'a>(prefix: &str, labels: impl Iterator<Item = &'a str>) -> String {
    let max = labels
        .filter_map(|l| l.strip_prefix(prefix)?.parse::<u64>().ok())
        .max()
        .unwrap_or(0);
    format!("{prefix}{}", max + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two squares facing −z (toward a camera at the origin looking along +z), two triangles
    /// each, one cell each: x, y ∈ [−1, 1] at z = 10 (cell 0) and at z = 5 (cell 1).
    fn two_walls() -> CellMesh {
        let mut mesh = CellMesh::default();
        for z in [10.0f32, 5.0] {
            let base = mesh.positions.len() as u32;
            mesh.positions.extend([
                [-1.0, -1.0, z],
                [-1.0, 1.0, z],
                [1.0, -1.0, z],
                [1.0, 1.0, z],
            ]);
            mesh.normals.extend([[0.0, 0.0, -1.0]; 4]);
            let start = mesh.triangles.len() as u32;
            mesh.triangles
                .extend([[base, base + 1, base + 2], [base + 1, base + 3, base + 2]]);
            mesh.cell_ranges.push(start..start + 2);
        }
        mesh
    }

    fn one_wall() -> CellMesh {
        let mut mesh = two_walls();
        mesh.triangles.truncate(2);
        mesh.cell_ranges.truncate(1);
        mesh
    }

    #[test]
    fn pick_hits_the_front_face() {
        let mesh = one_wall();
        let hit = pick(&mesh, None, DVec3::ZERO, DVec3::new(0.02, -0.03, 1.0) * 3.0).unwrap();
        assert!(
            (hit.point - DVec3::new(0.2, -0.3, 10.0)).length() < 1e-12,
            "{hit:?}"
        );
        assert!((hit.distance - hit.point.length()).abs() < 1e-12);
        assert_eq!(hit.normal, DVec3::new(0.0, 0.0, -1.0));
        assert_eq!(hit.triangle, 0);
        // The other triangle of the square (upper right half).
        assert_eq!(
            pick(&mesh, None, DVec3::ZERO, DVec3::new(0.05, 0.05, 1.0))
                .unwrap()
                .triangle,
            1
        );
    }

    #[test]
    fn pick_misses_beside_behind_and_back_faces() {
        let mesh = one_wall();
        assert_eq!(pick(&mesh, None, DVec3::ZERO, DVec3::X), None);
        assert_eq!(pick(&mesh, None, DVec3::new(5.0, 5.0, 0.0), DVec3::Z), None);
        // The wall lies behind the origin.
        assert_eq!(pick(&mesh, None, DVec3::ZERO, -DVec3::Z), None);
        // From beyond the wall looking back: its back face, culled as the renderer does.
        assert_eq!(
            pick(&mesh, None, DVec3::new(0.1, 0.2, 20.0), -DVec3::Z),
            None
        );
        // No direction, or a NaN one.
        assert_eq!(pick(&mesh, None, DVec3::ZERO, DVec3::ZERO), None);
        assert_eq!(pick(&mesh, None, DVec3::ZERO, DVec3::NAN), None);
    }

    #[test]
    fn pick_takes_the_nearest_in_the_cells_asked() {
        let mesh = two_walls();
        let (o, d) = (DVec3::new(0.3, 0.1, 0.0), DVec3::Z);
        let hit = pick(&mesh, None, o, d).unwrap();
        assert!(
            (hit.distance - 5.0).abs() < 1e-12 && hit.triangle >= 2,
            "{hit:?}"
        );
        assert_eq!(pick(&mesh, Some(&[0, 1]), o, d), Some(hit));
        // Only the far wall's cell drawn: the far wall.
        let far = pick(&mesh, Some(&[0]), o, d).unwrap();
        assert!((far.distance - 10.0).abs() < 1e-12 && far.triangle < 2);
        // Starting between the walls: the near one is behind.
        assert!(
            (pick(&mesh, None, DVec3::new(0.3, 0.1, 7.0), d)
                .unwrap()
                .distance
                - 3.0)
                .abs()
                < 1e-12
        );
        // No cells, or a cell that does not exist: nothing.
        assert_eq!(pick(&mesh, Some(&[]), o, d), None);
        assert_eq!(pick(&mesh, Some(&[7]), o, d), None);
    }

    fn with(kinds: &[(FindingKind, Option<f64>)]) -> Findings {
        let mut f = Findings::default();
        let pose = Pose::looking(DVec3::ZERO, DVec3::Z, DVec3::Y);
        for &(kind, size) in kinds {
            f.add_marker(DVec3::ZERO, DVec3::Z, pose, "");
            let m = f.markers.last_mut().unwrap();
            m.kind = kind;
            m.size_mm = size;
        }
        f
    }

    #[test]
    fn c_rads_follows_the_acr_categories() {
        use FindingKind::*;
        let cat = |k: &[(FindingKind, Option<f64>)], read_pct| {
            c_rads(
                &with(k),
                Adequacy {
                    read_pct,
                    left_out_ml: None,
                },
            )
            .category
        };
        assert_eq!(cat(&[], Some(97.0)), "C1");
        assert_eq!(cat(&[(Polyp, Some(5.9)), (Diverticulum, None)], None), "C1");
        assert_eq!(cat(&[(Polyp, Some(6.0))], None), "C2");
        assert_eq!(cat(&[(Polyp, Some(6.0)), (Polyp, Some(9.9))], None), "C2");
        assert_eq!(
            cat(
                &[(Polyp, Some(6.0)), (Polyp, Some(7.0)), (Polyp, Some(8.0))],
                None
            ),
            "C3"
        );
        assert_eq!(cat(&[(Polyp, Some(10.0))], Some(99.0)), "C3");
        assert_eq!(cat(&[(Mass, None), (Polyp, Some(4.0))], Some(50.0)), "C4");
        // Too little seen: a negative reading is inadequate; a positive finding stands.
        assert_eq!(cat(&[(Polyp, Some(4.0))], Some(85.0)), "C0");
        assert_eq!(cat(&[(Polyp, Some(12.0))], Some(85.0)), "C3");
        // Part of the colon left out: a negative reading of the rest is no negative exam.
        let part = Adequacy {
            read_pct: Some(99.0),
            left_out_ml: Some(3236.0),
        };
        assert_eq!(c_rads(&with(&[]), part).category, "C0");
        assert_eq!(c_rads(&with(&[(Polyp, Some(7.0))]), part).category, "C2");
        // An unsized polyp is named, so that the category is not read as final.
        let r = c_rads(
            &with(&[(Polyp, None), (Other, Some(20.0))]),
            Adequacy::default(),
        );
        assert_eq!(
            (r.category, r.unsized_polyps),
            ("C1", vec!["M1".to_string()])
        );
    }

    #[test]
    fn old_findings_without_kind_or_size_still_load() {
        let pose = Pose::looking(DVec3::ZERO, DVec3::Z, DVec3::Y);
        let mut json = serde_json::to_value(Marker {
            label: "M1".into(),
            note: String::new(),
            kind: FindingKind::Polyp,
            size_mm: Some(6.5),
            position: DVec3::ZERO,
            normal: DVec3::Z,
            view: pose,
        })
        .unwrap();
        assert_eq!(json["kind"], "polyp");
        json.as_object_mut().unwrap().remove("kind");
        json.as_object_mut().unwrap().remove("size_mm");
        let m: Marker = serde_json::from_value(json).unwrap();
        assert_eq!((m.kind, m.size_mm), (FindingKind::Other, None));
    }

    #[test]
    fn a_ray_through_a_shared_edge_hits_the_smaller_triangle() {
        // The diagonal from (−1, 1) to (1, −1) is shared by triangles 0 and 1.
        let hit = pick(&one_wall(), None, DVec3::ZERO, DVec3::Z).unwrap();
        assert_eq!(hit.triangle, 0);
    }
}
