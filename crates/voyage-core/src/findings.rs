//! The radiologist's findings: markers dropped on the colon wall under the mouse cursor, each
//! with a note and the camera pose to fly back to; two-click measurements in mm; and their
//! export (a JSON report, a 3D Slicer markups file, one snapshot per marker).
//!
//! Everything here is in volume-local mm, the frame of the mesh and of the camera's poses;
//! LPS appears only in the exported files.

use std::ops::Range;
use std::path::{Path, PathBuf};

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::camera::Pose;
use crate::export::markups::{MarkupsPoint, markups_line_node, markups_node, write_markups_nodes};
use crate::export::study::write_json;
use crate::io::atomic::write_atomic;
use crate::render::mesh::CellMesh;
use crate::{Error, Geometry, Result};

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
    let in_range = |r: &Range<u32>| nearest_in_range(mesh, r.clone(), origin, dir);
    // A click searches about a million triangles; cells are the natural parallel chunks.
    let best = match cells {
        Some(list) => list
            .par_iter()
            .filter_map(|&c| mesh.cell_ranges.get(c as usize))
            .filter_map(in_range)
            .min_by(nearer),
        None => mesh
            .cell_ranges
            .par_iter()
            .filter_map(in_range)
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

/// A finding on the wall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    pub label: String,
    pub note: String,
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

/// `prefix` followed by one more than the highest number among `labels` of that form.
fn next_label<'a>(prefix: &str, labels: impl Iterator<Item = &'a str>) -> String {
    let max = labels
        .filter_map(|l| l.strip_prefix(prefix)?.parse::<u64>().ok())
        .max()
        .unwrap_or(0);
    format!("{prefix}{}", max + 1)
}

/// Markers in red and measurements in yellow in Slicer, apart from the green centerline.
const MARKER_COLOR: [f64; 3] = [1.0, 0.2, 0.2];
const MEASUREMENT_COLOR: [f64; 3] = [1.0, 0.85, 0.1];

/// Writes into `dir` (created if missing) `finding_<label>.png` per marker (the RGBA image
/// `snapshot(i, marker)` gives), then `findings.json` and `findings.mrk.json` (3D Slicer
/// markups: a `Fiducial` list of the markers, one `Line` per measurement), all in patient LPS
/// through `geometry`. Each file is written atomically; the snapshots come first so that the
/// report never names a picture that is not there. Returns the paths written.
pub fn export_findings(
    dir: &Path,
    findings: &Findings,
    geometry: &Geometry,
    mut snapshot: impl FnMut(usize, &Marker) -> Result<(u32, u32, Vec<u8>)>,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let names = snapshot_names(&findings.markers);
    let mut out = Vec::new();
    for (i, (marker, name)) in findings.markers.iter().zip(&names).enumerate() {
        let path = dir.join(name);
        let (width, height, rgba) = snapshot(i, marker)?;
        write_png(&path, width, height, &rgba)?;
        out.push(path);
    }
    let path = dir.join("findings.json");
    write_json(&path, &findings_json(findings, geometry, &names))?;
    out.push(path);
    let path = dir.join("findings.mrk.json");
    write_markups_nodes(&path, markups_nodes(findings, geometry))?;
    out.push(path);
    Ok(out)
}

/// `finding_<label>.png`, the label reduced to characters safe in any file system (labels
/// can be edited), and numbered further if two markers end up with the same name.
fn snapshot_names(markers: &[Marker]) -> Vec<String> {
    let mut names: Vec<String> = Vec::with_capacity(markers.len());
    for (i, m) in markers.iter().enumerate() {
        let safe: String = m
            .label
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let mut name = format!("finding_{safe}.png");
        let mut n = i + 1;
        while names.contains(&name) {
            name = format!("finding_{safe}_{n}.png");
            n += 1;
        }
        names.push(name);
    }
    names
}

fn write_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<()> {
    use image::ImageEncoder;
    let want = width as u64 * height as u64 * 4;
    if width == 0 || height == 0 || rgba.len() as u64 != want {
        return Err(Error::format(
            path,
            format!(
                "snapshot of {width}×{height} pixels has {} bytes, not {want}",
                rgba.len()
            ),
        ));
    }
    write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(rgba, width, height, image::ExtendedColorType::Rgba8)
            .map_err(std::io::Error::other)
    })
}

/// The report: LPS for other tools, volume-local mm and the pose for voyage itself. It
/// carries nothing about the patient's identity (voyage never holds it).
fn findings_json(findings: &Findings, g: &Geometry, snapshots: &[String]) -> serde_json::Value {
    let markers: Vec<_> = findings
        .markers
        .iter()
        .zip(snapshots)
        .map(|(m, snap)| {
            json!({
                "label": m.label,
                "note": m.note,
                "position_lps_mm": g.local_to_patient(m.position).to_array(),
                "position_mm": m.position.to_array(),
                "normal_lps": normal_to_patient(g, m.normal).to_array(),
                "view_pose_mm": m.view.to_array(),
                "snapshot": snap,
            })
        })
        .collect();
    let measurements: Vec<_> = findings
        .measurements
        .iter()
        .map(|m| {
            json!({
                "label": m.label,
                "a_lps_mm": g.local_to_patient(m.a).to_array(),
                "b_lps_mm": g.local_to_patient(m.b).to_array(),
                "length_mm": m.length_mm(),
            })
        })
        .collect();
    json!({
        "frame": "*_lps_mm, normal_lps: DICOM patient LPS; position_mm: volume-local mm (x = i·sx, y = j·sy, z = k·sz); view_pose_mm: camera [x, y, z, qw, qx, qy, qz] in volume-local mm, z_body forward",
        "markers": markers,
        "measurements": measurements,
    })
}

/// Directions turn with the direction matrix alone (a rotation: no origin, no inverse transpose).
fn normal_to_patient(g: &Geometry, n: DVec3) -> DVec3 {
    (g.direction_mat() * n).normalize_or_zero()
}

/// The markups file's nodes: the markers as one point list (notes as descriptions), then a
/// line per measurement.
fn markups_nodes(findings: &Findings, g: &Geometry) -> Vec<serde_json::Value> {
    let lps = |p: DVec3| g.local_to_patient(p).to_array();
    let points: Vec<MarkupsPoint> = findings
        .markers
        .iter()
        .map(|m| MarkupsPoint {
            label: m.label.clone(),
            position_lps: lps(m.position),
            description: m.note.clone(),
        })
        .collect();
    let mut nodes = vec![markups_node("Fiducial", "Findings", &points, MARKER_COLOR)];
    nodes.extend(findings.measurements.iter().map(|m| {
        let end = |suffix: &str, p: DVec3| MarkupsPoint {
            label: format!("{}-{suffix}", m.label),
            position_lps: lps(p),
            description: String::new(),
        };
        markups_line_node(&m.label, end("1", m.a), end("2", m.b), MEASUREMENT_COLOR)
    }));
    nodes
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

    #[test]
    fn a_ray_through_a_shared_edge_hits_the_smaller_triangle() {
        // The diagonal from (−1, 1) to (1, −1) is shared by triangles 0 and 1.
        let hit = pick(&one_wall(), None, DVec3::ZERO, DVec3::Z).unwrap();
        assert_eq!(hit.triangle, 0);
    }

    fn pose() -> Pose {
        Pose::looking(
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(0.0, 1.0, 1.0),
            DVec3::X,
        )
    }

    fn sample() -> Findings {
        let mut f = Findings::default();
        f.add_marker(
            DVec3::new(10.0, 20.0, 30.0),
            DVec3::Y,
            pose(),
            "sessile polyp, 6 mm",
        );
        f.add_marker(
            DVec3::new(11.5, 20.25, 30.125),
            -DVec3::X,
            pose(),
            "fold \"thickening\"\nsecond line",
        );
        f.add_measurement(DVec3::new(1.0, 2.0, 3.0), DVec3::new(4.0, 6.0, 3.0));
        f
    }

    #[test]
    fn labels_count_up_and_are_not_reused_while_higher_ones_exist() {
        let mut f = sample();
        assert_eq!(
            f.markers
                .iter()
                .map(|m| m.label.as_str())
                .collect::<Vec<_>>(),
            ["M1", "M2"]
        );
        assert_eq!(f.measurements[0].label, "L1");
        assert_eq!(f.measurements[0].length_mm(), 5.0);
        assert_eq!(f.add_marker(DVec3::ZERO, DVec3::Z, pose(), "").label, "M3");
        assert_eq!(
            f.remove_marker("M2").unwrap().note,
            "fold \"thickening\"\nsecond line"
        );
        assert!(f.remove_marker("M2").is_none());
        assert_eq!(f.add_marker(DVec3::ZERO, DVec3::Z, pose(), "").label, "M4");
        assert_eq!(f.add_measurement(DVec3::ZERO, DVec3::ONE).label, "L2");
        assert!(f.remove_measurement("L1").is_some());
        assert_eq!(f.add_measurement(DVec3::ZERO, DVec3::ONE).label, "L3");
        f.marker_mut("M1").unwrap().note = "edited".into();
        assert_eq!(f.marker("M1").unwrap().note, "edited");
        assert!(f.measurement("L1").is_none() && f.measurement("L3").is_some());
        assert!(!f.is_empty() && Findings::default().is_empty());
    }

    #[test]
    fn findings_round_trip_through_json() {
        let f = sample();
        let text = serde_json::to_string(&f).unwrap();
        let back: Findings = serde_json::from_str(&text).unwrap();
        assert_eq!(back, f);
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("voyage-findings-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    fn geometry() -> Geometry {
        let mut g = Geometry::new([10, 10, 10], [0.5, 0.5, 2.0], [100.0, -50.0, 7.0]).unwrap();
        // Axial, patient facing the other way: x and y flipped.
        g.set_direction_mat(glam::DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)));
        g
    }

    fn grey(i: usize, _: &Marker) -> Result<(u32, u32, Vec<u8>)> {
        Ok((4, 3, vec![40 * i as u8; 4 * 3 * 4]))
    }

    #[test]
    fn export_writes_every_file_and_no_temporary_one() {
        let dir = temp_dir("export").join("new-subfolder");
        let f = sample();
        let written = export_findings(&dir, &f, &geometry(), grey).unwrap();
        let names: Vec<_> = written
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            names,
            [
                "finding_M1.png",
                "finding_M2.png",
                "findings.json",
                "findings.mrk.json"
            ]
        );
        let mut listed: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        listed.sort();
        assert_eq!(
            listed,
            [
                "finding_M1.png",
                "finding_M2.png",
                "findings.json",
                "findings.mrk.json"
            ],
            "temporary files left"
        );
        let png = image::open(dir.join("finding_M2.png")).unwrap().to_rgba8();
        assert_eq!(
            (png.width(), png.height(), png.get_pixel(3, 2).0),
            (4, 3, [40; 4])
        );

        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("findings.json")).unwrap())
                .unwrap();
        let m = &report["markers"][1];
        assert_eq!(m["label"], "M2");
        assert_eq!(m["note"], f.markers[1].note);
        assert_eq!(m["snapshot"], "finding_M2.png");
        // LPS = origin + diag(−1, −1, 1)·local.
        assert_eq!(
            m["position_lps_mm"],
            json!([100.0 - 11.5, -50.0 - 20.25, 7.0 + 30.125])
        );
        assert_eq!(m["position_mm"], json!([11.5, 20.25, 30.125]));
        assert_eq!(m["normal_lps"], json!([1.0, -0.0, 0.0]));
        assert_eq!(
            Pose::from_array(serde_json::from_value(m["view_pose_mm"].clone()).unwrap()).unwrap(),
            f.markers[1].view
        );
        let l = &report["measurements"][0];
        assert_eq!(
            (l["label"].as_str(), l["length_mm"].as_f64()),
            (Some("L1"), Some(5.0))
        );
        assert_eq!(l["b_lps_mm"], json!([96.0, -56.0, 10.0]));

        let mrk: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("findings.mrk.json")).unwrap())
                .unwrap();
        let nodes = mrk["markups"].as_array().unwrap();
        assert_eq!(nodes.len(), 2);
        assert_eq!(
            (nodes[0]["type"].as_str(), nodes[1]["type"].as_str()),
            (Some("Fiducial"), Some("Line"))
        );
        assert_eq!(
            nodes[0]["controlPoints"][1]["description"],
            f.markers[1].note
        );
        assert_eq!(
            nodes[0]["controlPoints"][1]["position"],
            m["position_lps_mm"]
        );
        assert_eq!(nodes[1]["measurements"][0]["value"].as_f64(), Some(5.0));
        assert_eq!(nodes[1]["controlPoints"][1]["position"], l["b_lps_mm"]);
        std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
    }

    #[test]
    fn export_of_nothing_writes_an_empty_report() {
        let dir = temp_dir("empty");
        let written = export_findings(
            &dir,
            &Findings::default(),
            &geometry(),
            |_, _| unreachable!(),
        )
        .unwrap();
        assert_eq!(written.len(), 2);
        let mrk: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("findings.mrk.json")).unwrap())
                .unwrap();
        assert_eq!(mrk["markups"][0]["controlPoints"], json!([]));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn export_errors_name_the_path() {
        // A folder inside a regular file can be neither made nor written (even by root,
        // for whom permission bits do not stop anything).
        let base = temp_dir("unwritable");
        std::fs::create_dir_all(&base).unwrap();
        let file = base.join("a-file");
        std::fs::write(&file, b"x").unwrap();
        let dir = file.join("findings");
        let err = export_findings(&dir, &sample(), &geometry(), grey).unwrap_err();
        assert!(err.to_string().contains(&*dir.to_string_lossy()), "{err}");

        // A snapshot of the wrong size names its file, and so does the callback's own error.
        let ok = base.join("ok");
        let err = export_findings(&ok, &sample(), &geometry(), |_, _| Ok((4, 4, vec![0; 10])))
            .unwrap_err();
        assert!(err.to_string().contains("finding_M1.png"), "{err}");
        let err = export_findings(&ok, &sample(), &geometry(), |_, _| {
            Err(Error::invalid("no GPU"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("no GPU"), "{err}");
        assert_eq!(
            std::fs::read_dir(&ok).unwrap().count(),
            0,
            "something was written"
        );
        std::fs::remove_dir_all(&base).unwrap();
    }

    #[test]
    fn duplicate_labels_get_distinct_snapshots() {
        let mut f = sample();
        f.markers[1].label = "M1".into();
        f.add_marker(DVec3::ZERO, DVec3::Z, pose(), "");
        f.markers[2].label = "a/b c".into();
        let names = snapshot_names(&f.markers);
        assert_eq!(
            names,
            ["finding_M1.png", "finding_M1_2.png", "finding_a_b_c.png"]
        );
    }
}
