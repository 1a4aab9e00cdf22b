//! The findings' export: a JSON report, a 3D Slicer markups file and one snapshot per marker,
//! in patient LPS.

use std::path::{Path, PathBuf};

use glam::DVec3;
use serde_json::json;
use voyage_core::{Error, Geometry, LEFT_OUT_DOUBT_ML, OFF_WALL_MM, Result, Study};
use voyage_view::{Adequacy, Findings, Marker, c_rads};

use super::{
    markups::{MarkupsPoint, markups_line_node, markups_node, write_markups_nodes},
    report::{ColonRead, Exam, Report, ReportCoverage, ReportFinding, write_report_html},
    study::write_json,
};
use voyage_io::{encode_png, write_atomic};

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
    snapshot: impl FnMut(usize, &Marker) -> Result<(u32, u32, Vec<u8>)>,
) -> Result<Vec<PathBuf>> {
    Ok(write_findings(dir, findings, geometry, None, snapshot)?.0)
}

/// [`export_findings`] with each marker's segment and distance from the rectum end from
/// `study`, then `report.html` ([`super::report`]): the same snapshots, the C-RADS category
/// (with `coverage`'s two-way figure, where measured), the coverage, and what `exam` says
/// (no patient identity).
pub fn export_reading(
    dir: &Path,
    findings: &Findings,
    study: &Study,
    exam: &Exam,
    coverage: ReportCoverage,
    snapshot: impl FnMut(usize, &Marker) -> Result<(u32, u32, Vec<u8>)>,
) -> Result<Vec<PathBuf>> {
    let geometry = study.ct.geometry();
    let (mut out, pngs) = write_findings(dir, findings, geometry, Some(study), snapshot)?;
    let report = Report {
        exam: exam.clone(),
        findings: findings
            .markers
            .iter()
            .zip(pngs)
            .map(|(m, png)| {
                let place = placed(m, study);
                ReportFinding {
                    label: m.label.clone(),
                    kind: m.kind.name().to_string(),
                    size_mm: m.size_mm,
                    segment: place.0.to_string(),
                    from_rectum_mm: place.1,
                    position_lps_mm: geometry.local_to_patient(m.position).to_array(),
                    note: m.note.clone(),
                    snapshot_png: png,
                }
            })
            .collect(),
        measurements: findings
            .measurements
            .iter()
            .map(|m| (m.label.clone(), m.length_mm()))
            .collect(),
        c_rads: c_rads(
            findings,
            Adequacy {
                read_pct: coverage.read_pct(),
                left_out_ml: study
                    .segmentation
                    .largest_left_out(LEFT_OUT_DOUBT_ML)
                    .map(|s| s.gas_ml),
            },
        ),
        coverage,
        colon: ColonRead::of(study, &exam.by_hand),
    };
    let path = dir.join("report.html");
    write_report_html(&path, &report)?;
    out.push(path);
    Ok(out)
}

/// A marker's segment and distance along the centerline from the rectum end, read just off
/// the wall in the lumen.
pub(crate) fn placed(m: &Marker, study: &Study) -> (&'static str, Option<f64>) {
    let p = m.position + m.normal.normalize_or_zero() * OFF_WALL_MM;
    (study.segment_at(p), study.arc_at(p))
}

/// The snapshots, `findings.json` (with segments and distances where `study` is given) and
/// `findings.mrk.json`; the paths written and each snapshot's PNG bytes.
fn write_findings(
    dir: &Path,
    findings: &Findings,
    geometry: &Geometry,
    study: Option<&Study>,
    mut snapshot: impl FnMut(usize, &Marker) -> Result<(u32, u32, Vec<u8>)>,
) -> Result<(Vec<PathBuf>, Vec<Vec<u8>>)> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let names = snapshot_names(&findings.markers);
    let mut out = Vec::new();
    let mut pngs = Vec::new();
    for (i, (marker, name)) in findings.markers.iter().zip(&names).enumerate() {
        let path = dir.join(name);
        let (width, height, rgba) = snapshot(i, marker)?;
        let png = encode_png(&path, width, height, &rgba)?;
        write_atomic(&path, |w| w.write_all(&png))?;
        pngs.push(png);
        out.push(path);
    }
    let path = dir.join("findings.json");
    write_json(&path, &findings_json(findings, geometry, &names, study))?;
    out.push(path);
    let path = dir.join("findings.mrk.json");
    write_markups_nodes(&path, markups_nodes(findings, geometry))?;
    out.push(path);
    Ok((out, pngs))
}

/// `finding_<label>.png`, the label reduced to characters safe in any file system (labels
/// can be edited), and numbered further if two markers end up with the same name.
pub(crate) fn snapshot_names(markers: &[Marker]) -> Vec<String> {
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
        // A short stem: a label of thousands of characters made a name the file system refused.
        let safe: String = safe.chars().take(32).collect();
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

/// The report: LPS for other tools, volume-local mm and the pose for voyage itself. It
/// carries nothing about the patient's identity (voyage never holds it).
fn findings_json(
    findings: &Findings,
    g: &Geometry,
    snapshots: &[String],
    study: Option<&Study>,
) -> serde_json::Value {
    let markers: Vec<_> = findings
        .markers
        .iter()
        .zip(snapshots)
        .map(|(m, snap)| {
            let place = study.map(|s| placed(m, s));
            json!({
                "label": m.label,
                "note": m.note,
                "kind": m.kind.name(),
                "size_mm": m.size_mm,
                "segment": place.map(|p| p.0),
                "from_rectum_mm": place.and_then(|p| p.1),
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
        "frame": "*_lps_mm, normal_lps: DICOM patient LPS; position_mm: study-local mm (x = i·sx, y = j·sy, z = k·sz with the scan turned so that i, j, k run to the patient's left, back and head); view_pose_mm: camera [x, y, z, qw, qx, qy, qz] in study-local mm, z_body forward",
        "markers": markers,
        "measurements": measurements,
    })
}

/// A findings.json larger than this is no reading's (a thousand markers with notes take a
/// few hundred kB).
const MAX_FINDINGS_BYTES: u64 = 16 << 20;
/// Markers and measurements a findings.json may hold (3000 made an 878 MB report).
const MAX_FINDINGS: usize = 500;
/// A label is a short name (it also names the snapshot's file); a note is a few lines.
const MAX_LABEL_CHARS: usize = 64;
const MAX_NOTE_CHARS: usize = 4000;
/// A polyp or mass larger than this (mm) is no colon's.
const MAX_SIZE_MM: f64 = 300.0;
/// How far outside the scanned volume a marker may lie (mm): on the wall at its edge.
const PLACE_SLACK_MM: f64 = 10.0;

/// Reads the markers and measurements back from a `findings.json` an export wrote (for
/// `voyage report`), into the volume-local frame of `geometry`. Errors name the file and
/// what is wrong with it.
pub fn read_findings(path: &Path, geometry: &Geometry) -> Result<Findings> {
    let text = voyage_io::read_small_text(path, MAX_FINDINGS_BYTES)?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::format(path, format!("not JSON: {e}")))?;
    let bad = |what: &str| Error::format(path, format!("not a voyage findings.json: {what}"));
    let vec3 = |x: &serde_json::Value, key: &str| -> Result<DVec3> {
        let a = x[key]
            .as_array()
            .filter(|a| a.len() == 3)
            .ok_or_else(|| bad(&format!("no {key}")))?;
        let f: Vec<f64> = a.iter().filter_map(|n| n.as_f64()).collect();
        (f.len() == 3 && f.iter().all(|x| x.is_finite()))
            .then(|| DVec3::new(f[0], f[1], f[2]))
            .ok_or_else(|| bad(&format!("{key} is not three numbers")))
    };
    let text_of = |x: &serde_json::Value, key: &str, most: usize| -> Result<String> {
        let t = x[key].as_str().unwrap_or("").to_string();
        if t.chars().count() > most {
            return Err(bad(&format!("a {key} longer than {most} characters")));
        }
        if t.chars().any(|c| c.is_control() && c != '\n' && c != '\t') {
            return Err(bad(&format!("a {key} with control characters")));
        }
        Ok(t)
    };
    // Within the scanned volume, give or take a few mm: a marker is on the colon's wall.
    let inside = |p: DVec3, what: &str| -> Result<DVec3> {
        let reach = geometry.extent_mm() + DVec3::splat(PLACE_SLACK_MM);
        let ok =
            (p + DVec3::splat(PLACE_SLACK_MM)).cmpge(DVec3::ZERO).all() && p.cmple(reach).all();
        ok.then_some(p).ok_or_else(|| {
            bad(&format!(
                "{what} lies outside the scanned volume ({} mm LPS)",
                geometry.local_to_patient(p).round()
            ))
        })
    };
    let (markers, measurements) = (
        v["markers"]
            .as_array()
            .ok_or_else(|| bad("no markers list"))?,
        v["measurements"].as_array(),
    );
    if markers.len() + measurements.map_or(0, |m| m.len()) > MAX_FINDINGS {
        return Err(bad(&format!(
            "more than {MAX_FINDINGS} markers and measurements"
        )));
    }
    let mut findings = Findings::default();
    for m in markers {
        let pose: Vec<f64> = m["view_pose_mm"]
            .as_array()
            .map(|a| a.iter().filter_map(|n| n.as_f64()).collect())
            .unwrap_or_default();
        let view = <[f64; 7]>::try_from(pose.as_slice())
            .ok()
            .and_then(voyage_nav::Pose::from_array)
            .ok_or_else(|| bad("a marker's view_pose_mm is not a pose"))?;
        let kind = serde_json::from_value(m["kind"].clone()).unwrap_or_default();
        let label = text_of(m, "label", MAX_LABEL_CHARS)?;
        let size_mm = m["size_mm"].as_f64();
        if size_mm.is_some_and(|s| !(s > 0.0 && s <= MAX_SIZE_MM)) {
            return Err(bad(&format!(
                "marker {label}'s size_mm is not in (0, {MAX_SIZE_MM}] mm"
            )));
        }
        findings.markers.push(Marker {
            note: text_of(m, "note", MAX_NOTE_CHARS)?,
            kind,
            size_mm,
            position: inside(
                geometry.patient_to_local(vec3(m, "position_lps_mm")?),
                &format!("marker {label}"),
            )?,
            label,
            normal: (geometry.direction_mat().transpose() * vec3(m, "normal_lps")?)
                .normalize_or_zero(),
            view,
        });
    }
    for m in measurements.into_iter().flatten() {
        let label = text_of(m, "label", MAX_LABEL_CHARS)?;
        let end = |key: &str| {
            inside(
                geometry.patient_to_local(vec3(m, key)?),
                &format!("measurement {label}"),
            )
        };
        findings.measurements.push(voyage_view::Measurement {
            a: end("a_lps_mm")?,
            b: end("b_lps_mm")?,
            label,
        });
    }
    Ok(findings)
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
    use voyage_nav::Pose;

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
