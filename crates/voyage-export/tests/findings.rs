//! Findings: picking on real surfaces (fast enough for a click on colon-a, and agreeing with
//! what the renderer shows), the measurement accuracy the issue asks for (the pipe's 7, 5 and
//! 3 mm polyps measured within 0.5 mm by two clicks), and exported markups that 3D Slicer's
//! schema accepts. Run in release mode (`cargo test --release -p voyage-io --test findings`).

use std::{
    path::{Path, PathBuf},
    time::Instant,
};

use glam::DVec3;
use serde_json::Value;
use voyage_core::{Geometry, PrepOptions, Study, prepare};
use voyage_export::{
    export_findings,
    markups::{MarkupsPoint, write_markups_curve},
};
use voyage_nav::{Camera, Pose};
use voyage_phantom::{self as phantom, Phantom, PolypTruth};
use voyage_view::{
    CellMesh, Findings, Frame, Hit, NO_TRIANGLE, Rasterizer, Shading, Strategy, View, Visibility,
    pick,
};

/// The colon-a mask of the shared data preprocessed with the default options, or None
/// (skipped).
fn colon_a_study() -> Option<voyage_core::Study> {
    let path = voyage_phantom::fixtures::colon_a_path()?;
    let mask = voyage_io::load(&path, &Default::default()).unwrap().volume;
    Some(voyage_core::prepare(mask, &Default::default(), |_| {}).unwrap())
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "voyage-findings-test-{name}-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

// ---------------------------------------------------------------------------------------
// 3D Slicer's markups schema.

/// Slicer's schema v1.0.3, verbatim in tests/data. It has no `$ref`, so nothing needs
/// resolving; its `$schema` names draft-07 without the trailing `#`, so the draft is given
/// explicitly rather than left to detection (the validator is built without network access).
/// Its `$id`s like "#markup/type" are not valid draft-07 anchors; no `$ref` points at them,
/// and the validator accepts them as they are.
fn slicer_validator() -> jsonschema::Validator {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/markups-schema-v1.0.3.json"
    );
    let schema = read_json(Path::new(path));
    jsonschema::options()
        .with_draft(jsonschema::Draft::Draft7)
        .build(&schema)
        .expect("Slicer's schema compiles")
}

fn assert_valid(validator: &jsonschema::Validator, doc: &Value, what: &str) {
    let errors: Vec<String> = validator
        .iter_errors(doc)
        .map(|e| format!("{} at {}", e, e.instance_path()))
        .collect();
    assert!(
        errors.is_empty(),
        "{what} does not follow Slicer's schema:\n{}",
        errors.join("\n")
    );
}

fn sample_findings() -> Findings {
    let mut f = Findings::default();
    let view = Pose::looking(DVec3::new(10.0, 10.0, 10.0), DVec3::Z, DVec3::Y);
    f.add_marker(
        DVec3::new(10.0, 12.0, 30.0),
        -DVec3::Z,
        view,
        "sessile polyp ~6 mm, ascending colon",
    );
    f.add_marker(DVec3::new(14.0, 9.0, 31.0), -DVec3::Z, view, "");
    f.add_measurement(DVec3::new(9.0, 12.0, 30.0), DVec3::new(15.0, 12.0, 30.0));
    f.add_measurement(DVec3::new(1.0, 1.0, 1.0), DVec3::new(1.0, 1.0, 4.0));
    f
}

fn tilted_geometry() -> Geometry {
    let mut g = Geometry::new([64, 64, 32], [0.8, 0.8, 1.25], [-120.0, -150.0, 40.0]).unwrap();
    g.set_direction_mat(glam::DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)));
    g
}

#[test]
fn exported_markups_follow_slicers_schema() {
    let validator = slicer_validator();
    let dir = temp_dir("schema");
    let f = sample_findings();
    export_findings(&dir, &f, &tilted_geometry(), |_, _| {
        Ok((2, 2, vec![255; 16]))
    })
    .unwrap();
    let doc = read_json(&dir.join("findings.mrk.json"));
    assert_valid(&validator, &doc, "findings.mrk.json");
    let types: Vec<_> = doc["markups"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n["type"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(types, ["Fiducial", "Line", "Line"]);

    // Nothing found yet: still a valid (empty) point list.
    export_findings(
        &dir,
        &Findings::default(),
        &tilted_geometry(),
        |_, _| unreachable!(),
    )
    .unwrap();
    assert_valid(
        &validator,
        &read_json(&dir.join("findings.mrk.json")),
        "empty findings.mrk.json",
    );

    // The centerline curve `voyage prep` writes (export::study::write_study calls this).
    let points: Vec<MarkupsPoint> = (0..12)
        .map(|i| MarkupsPoint {
            label: format!("CL-{}", i + 1),
            position_lps: [i as f64, 2.0 * i as f64, -3.5],
            description: String::new(),
        })
        .collect();
    let curve = dir.join("centerline.mrk.json");
    write_markups_curve(&curve, "Centerline", &points).unwrap();
    assert_valid(&validator, &read_json(&curve), "centerline.mrk.json");

    // The validator does look at what it is given.
    let mut bad = doc.clone();
    bad["markups"][1]["controlPoints"][0]["position"] = serde_json::json!([1.0, 2.0]);
    bad["markups"][0]["coordinateSystem"] = serde_json::json!("XYZ");
    assert_eq!(validator.iter_errors(&bad).count(), 2);
    std::fs::remove_dir_all(&dir).unwrap();
}

// ---------------------------------------------------------------------------------------
// Measuring the pipe phantom's polyps.

/// The screen's size for the measurement: odd, so that the polyp's centre, straight ahead,
/// projects onto the centre of pixel (W/2, W/2), and the row and column through it exist.
const W: u32 = 513;
/// How far the camera stands from the polyp's centre, mm.
const VIEW_MM: f64 = 25.0;

/// Whether a point of the surface belongs to the polyp as a reader sees it: on its sphere
/// (within `tol` of the radius, for the marching-cubes facets and the CT's blur), and not
/// part of the wall, which lies r/2 behind the centre (the head's centre is inside the
/// lumen by half its radius): just outside the polyp's outline the wall behind is still
/// within about 1.12 r of the centre, so nearness alone would count it for small polyps.
fn on_polyp(p: DVec3, polyp: &PolypTruth) -> bool {
    let (c, r) = (DVec3::from_array(polyp.center_mm), polyp.diameter_mm / 2.0);
    let into_lumen = DVec3::from_array(polyp.direction);
    ((p - c).length() - r).abs() <= 0.35 && (p - c).dot(into_lumen) > -0.25 * r
}

fn triangle_on_polyp(mesh: &CellMesh, id: u32, polyp: &PolypTruth) -> bool {
    id != NO_TRIANGLE
        && mesh.triangles[id as usize].iter().all(|&v| {
            on_polyp(
                DVec3::from_array(mesh.positions[v as usize].map(f64::from)),
                polyp,
            )
        })
}

/// The last pixel, walking from `start` by `step` along a row or column, whose triangle is
/// on the polyp: the reader's click on the polyp's edge.
fn edge_pixel(
    frame: &Frame,
    mesh: &CellMesh,
    polyp: &PolypTruth,
    start: (i64, i64),
    step: (i64, i64),
) -> (u32, u32) {
    let (mut x, mut y) = start;
    let at = |x: i64, y: i64| frame.id((y * W as i64 + x) as usize);
    assert!(
        triangle_on_polyp(mesh, at(x, y), polyp),
        "the polyp is not at the centre of the view"
    );
    while x + step.0 >= 0
        && x + step.0 < W as i64
        && y + step.1 >= 0
        && y + step.1 < W as i64
        && triangle_on_polyp(mesh, at(x + step.0, y + step.1), polyp)
    {
        x += step.0;
        y += step.1;
    }
    (x as u32, y as u32)
}

/// The pixel before the largest jump in depth on the way from `centre` through `end` and
/// 8 pixels beyond: where the polyp's outline occludes the wall behind it, the edge a reader
/// sees. A check that the triangles taken for the polyp's stop at its visible outline.
fn largest_depth_step(
    mesh: &CellMesh,
    camera: &Camera,
    cells: &[u32],
    centre: (i64, i64),
    end: (u32, u32),
) -> (u32, u32) {
    let step = (
        (end.0 as i64 - centre.0).signum(),
        (end.1 as i64 - centre.1).signum(),
    );
    let n = (end.0 as i64 - centre.0)
        .abs()
        .max((end.1 as i64 - centre.1).abs())
        + 8;
    let pixels: Vec<(u32, u32)> = (0..=n)
        .map(|k| {
            (
                (centre.0 + k * step.0) as u32,
                (centre.1 + k * step.1) as u32,
            )
        })
        .collect();
    let depth: Vec<f64> = pixels
        .iter()
        .map(|&px| click(mesh, camera, cells, px).distance)
        .collect();
    let k = (0..depth.len() - 1)
        .max_by(|&i, &j| (depth[i + 1] - depth[i]).total_cmp(&(depth[j + 1] - depth[j])))
        .unwrap();
    pixels[k]
}

/// The click: `pick` along the ray through the pixel's centre, among the cells drawn.
fn click(mesh: &CellMesh, camera: &Camera, cells: &[u32], px: (u32, u32)) -> Hit {
    let dir = camera.pixel_ray(px.0 as f64 + 0.5, px.1 as f64 + 0.5, W, W);
    pick(mesh, Some(cells), camera.pose.position, dir).expect("a click on the wall hits it")
}

/// The camera straight in front of the polyp: the pose a reader steers to before measuring.
/// `up` fixes which screen row and column run through the polyp.
fn camera_facing(polyp: &PolypTruth, up: DVec3) -> Camera {
    let c = DVec3::from_array(polyp.center_mm);
    let into_lumen = DVec3::from_array(polyp.direction);
    Camera::new(Pose::looking(c + VIEW_MM * into_lumen, -into_lumen, up))
}

fn pipe_study() -> (Study, Vec<PolypTruth>) {
    let Phantom { ct, truth, .. } = phantom::pipe(1).unwrap();
    let study = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    (study, truth.polyps)
}

/// The issue: "measuring the 7, 5 and 3 mm polyps of the pipe phantom gives their diameters
/// within 0.5 mm".
///
/// The reader's protocol, emulated: the camera 25 mm straight in front of the polyp (in the
/// lumen: the pipe's radius is 20 mm and the polyp's centre 18–19 mm off the axis), the
/// frame drawn as the navigator draws it, and two clicks on the polyp's opposite edges on
/// the screen row through its centre, then again on the column. Seen from the front, the
/// edge a reader sees is the polyp's outline against the wall behind it, which is the head's
/// widest circle: the phantom's sessile polyps sit with their centre r/2 inside the lumen,
/// so the circle where the head meets the wall (diameter √3·r ≈ 0.87 d) is hidden under
/// that outline, and the outline is where the diameter is measured. The edge pixel is the
/// outermost one that still shows the polyp (its triangles lie on the polyp's sphere and
/// not on the wall behind), as a reader clicks just inside the outline; its pick lands on
/// the outline's surface. The distance between the two picked points is the measurement.
/// That those pixels are the visible outline, and not an artefact of the tolerances in
/// `on_polyp`, is checked independently of the truth: each is the pixel before the largest
/// jump in depth along its walk (the polyp occluding the wall).
#[test]
fn two_clicks_measure_the_pipes_polyps_within_half_a_millimetre() {
    let (study, polyps) = pipe_study();
    let mesh = CellMesh::new(&study.surface, &study.cells);
    let all: Vec<u32> = (0..mesh.cells() as u32).collect();
    assert_eq!(
        polyps.iter().map(|p| p.diameter_mm).collect::<Vec<_>>(),
        [7.0, 5.0, 3.0]
    );
    let mut worst: f64 = 0.0;
    for polyp in &polyps {
        let axis = DVec3::from_array(polyp.direction).any_orthonormal_vector();
        let camera = camera_facing(polyp, axis);
        let eye = camera.pose.position;
        assert!(
            study.cells.cell_of_point(eye).is_some(),
            "the camera in front of the {} mm polyp is outside the lumen",
            polyp.diameter_mm
        );
        let mut frame = Frame::new(W, W);
        // What the navigator shows: the visible cells of the camera's position.
        let drawn = Visibility::new(&study.cells, Strategy::Ours).draw(
            &mut frame,
            &Rasterizer::new(&mesh, View::new(&camera, W, W), &Shading::default()),
            &study.cells,
        );
        let centre = (W as i64 / 2, W as i64 / 2);
        for (dir_name, step) in [("row", (1, 0)), ("column", (0, 1))] {
            let ends = [
                edge_pixel(&frame, &mesh, polyp, centre, (-step.0, -step.1)),
                edge_pixel(&frame, &mesh, polyp, centre, step),
            ];
            let hits = ends.map(|px| click(&mesh, &camera, &drawn.cells, px));
            let mut findings = Findings::default();
            let length = findings
                .add_measurement(hits[0].point, hits[1].point)
                .length_mm();
            let err = length - polyp.diameter_mm;
            worst = worst.max(err.abs());
            eprintln!(
                "{} mm polyp, {dir_name}: clicks at {:?} and {:?} ({} px apart), measured {length:.3} mm, error {err:+.3} mm",
                polyp.diameter_mm,
                ends[0],
                ends[1],
                (ends[1].0 + ends[1].1) - (ends[0].0 + ends[0].1)
            );
            for end in ends {
                assert_eq!(
                    largest_depth_step(&mesh, &camera, &drawn.cells, centre, end),
                    end,
                    "the {} mm polyp's edge is not where its outline is",
                    polyp.diameter_mm
                );
            }
            for (hit, px) in hits.iter().zip(ends) {
                // The click lands on the triangle the frame shows there, and so does a
                // search of every cell.
                assert_eq!(
                    hit.triangle,
                    frame.id((px.1 * W + px.0) as usize),
                    "pick and raster disagree at {px:?}"
                );
                assert_eq!(
                    pick(&mesh, Some(&all), eye, hit.point - eye).map(|h| h.triangle),
                    Some(hit.triangle)
                );
                assert!(
                    hit.normal.dot(eye - hit.point) > 0.0,
                    "the normal faces the camera"
                );
            }
            assert!(
                err.abs() <= 0.5,
                "the {} mm polyp measures {length:.3} mm along the {dir_name}",
                polyp.diameter_mm
            );
        }
    }
    eprintln!("largest error {worst:.3} mm");
}

// ---------------------------------------------------------------------------------------
// Picking on a real colon.

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// A click on colon-a (≈1.5 M triangles): how long `pick` takes over every cell and over the
/// cells the renderer drew, printed (not asserted: the machine is shared), and that both
/// agree with the id buffer under the cursor.
#[test]
fn pick_on_colon_a_is_quick_and_lands_where_the_frame_shows() {
    let Some(study) = colon_a_study() else {
        return;
    };
    let mesh = CellMesh::new(&study.surface, &study.cells);
    eprintln!(
        "colon-a: {} triangles in {} cells, {} rayon threads",
        mesh.triangles.len(),
        mesh.cells(),
        rayon::current_num_threads()
    );
    let cl = &study.centerline;
    let size = 256u32;
    let (mut t_all, mut t_drawn, mut n, mut agree, mut covered) =
        (Vec::new(), Vec::new(), 0usize, 0usize, 0usize);
    let mut visibility = Visibility::new(&study.cells, Strategy::Ours);
    let shading = Shading::default();
    for k in 1..=12 {
        let i = k * (cl.points_mm.len() - 2) / 13;
        let (p, q) = (
            DVec3::from_array(cl.points_mm[i]),
            DVec3::from_array(cl.points_mm[i + 1]),
        );
        let camera = Camera::new(Pose::looking(p, q - p, (q - p).any_orthonormal_vector()));
        let mut frame = Frame::new(size, size);
        visibility.reset();
        let drawn = visibility.draw(
            &mut frame,
            &Rasterizer::new(&mesh, View::new(&camera, size, size), &shading),
            &study.cells,
        );
        for (fx, fy) in [(0.5, 0.5), (0.2, 0.3), (0.8, 0.25), (0.3, 0.8), (0.7, 0.7)] {
            let px = ((fx * size as f64) as u32, (fy * size as f64) as u32);
            let dir = camera.pixel_ray(px.0 as f64 + 0.5, px.1 as f64 + 0.5, size, size);
            let t = Instant::now();
            let everywhere = pick(&mesh, None, p, dir);
            t_all.push(ms(t));
            let t = Instant::now();
            let among_drawn = pick(&mesh, Some(&drawn.cells), p, dir);
            t_drawn.push(ms(t));
            n += 1;
            // Culling never changes the image, so the nearest hit is among the drawn cells.
            assert_eq!(everywhere, among_drawn, "pose {k}, pixel {px:?}");
            let id = frame.id((px.1 * size + px.0) as usize);
            if id != NO_TRIANGLE {
                covered += 1;
                agree += (everywhere.map(|h| h.triangle) == Some(id)) as usize;
            }
        }
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (
            v[v.len() / 2],
            v.iter().sum::<f64>() / v.len() as f64,
            v[v.len() - 1],
        )
    };
    let (a, d) = (stats(&mut t_all), stats(&mut t_drawn));
    eprintln!(
        "pick over all cells:   median {:.2} ms, mean {:.2} ms, max {:.2} ms ({n} clicks)",
        a.0, a.1, a.2
    );
    eprintln!(
        "pick over drawn cells: median {:.2} ms, mean {:.2} ms, max {:.2} ms",
        d.0, d.1, d.2
    );
    eprintln!("pick = id buffer on {agree} of {covered} covered pixels");
    assert!(
        covered >= n * 9 / 10,
        "the views from the centerline should mostly see wall"
    );
    assert_eq!(agree, covered, "pick and the rasterizer disagree");
}

#[test]
fn findings_json_reads_back_what_was_exported() {
    let dir = temp_dir("roundtrip");
    let mut f = sample_findings();
    f.markers[0].kind = voyage_view::FindingKind::Polyp;
    f.markers[0].size_mm = Some(6.25);
    let g = tilted_geometry();
    export_findings(&dir, &f, &g, |_, _| Ok((2, 2, vec![255; 16]))).unwrap();
    let back = voyage_export::read_findings(&dir.join("findings.json"), &g).unwrap();
    assert_eq!(back.markers.len(), 2);
    for (a, b) in f.markers.iter().zip(&back.markers) {
        assert_eq!(
            (&a.label, &a.note, a.kind, a.size_mm),
            (&b.label, &b.note, b.kind, b.size_mm)
        );
        assert!(a.position.distance(b.position) < 1e-9 && a.normal.distance(b.normal) < 1e-9);
        assert!(a.view.position.distance(b.view.position) < 1e-9);
    }
    for (a, b) in f.measurements.iter().zip(&back.measurements) {
        assert!((a.length_mm() - b.length_mm()).abs() < 1e-9 && a.label == b.label);
    }
    // Not a findings file: the error names the file.
    let other = dir.join("findings.mrk.json");
    let e = voyage_export::read_findings(&other, &g)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("findings.mrk.json") && e.contains("not a voyage findings.json"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A findings.json is input like any other: its counts, sizes, texts and places are checked,
/// and a file name made from a label stays short. Each case used to pass: a NUL byte went
/// raw into report.html, a 1e308 mm polyp printed 309 digits, −5 mm was taken, a marker 1 km
/// outside the volume was placed "804 mm, splenic flexure", a 5000-character label aborted
/// the export, and 3000 markers made an 878 MB report.
#[test]
fn findings_read_back_are_checked_like_any_input() {
    let dir = temp_dir("checked");
    let g = tilted_geometry();
    export_findings(&dir, &sample_findings(), &g, |_, _| {
        Ok((2, 2, vec![255; 16]))
    })
    .unwrap();
    let path = dir.join("findings.json");
    let good = read_json(&path);
    assert!(voyage_export::read_findings(&path, &g).is_ok());
    let refused = |edit: &dyn Fn(&mut Value), expect: &str| {
        let mut doc = good.clone();
        edit(&mut doc);
        let bad = dir.join("bad.json");
        std::fs::write(&bad, serde_json::to_string(&doc).unwrap()).unwrap();
        let err = voyage_export::read_findings(&bad, &g)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("bad.json") && err.contains(expect),
            "{expect}: {err}"
        );
    };
    refused(
        &|d| d["markers"][0]["label"] = "M\u{0}1".into(),
        "control characters",
    );
    refused(
        &|d| d["markers"][0]["size_mm"] = 1e308.into(),
        "size_mm is not in",
    );
    refused(
        &|d| d["markers"][0]["size_mm"] = (-5.0).into(),
        "size_mm is not in",
    );
    refused(
        &|d| d["markers"][0]["position_lps_mm"] = serde_json::json!([1e6, 0.0, 0.0]),
        "outside the scanned volume",
    );
    refused(
        &|d| d["markers"][0]["label"] = "x".repeat(5000).into(),
        "longer than 64",
    );
    refused(
        &|d| {
            let m = d["markers"][0].clone();
            d["markers"] = Value::Array(vec![m; 3000]);
        },
        "more than 500",
    );
    // A long label (under the limit) still names a file the file system takes.
    let mut long = sample_findings();
    long.markers[0].label = "polyp-".repeat(10);
    let written = export_findings(&dir, &long, &g, |_, _| Ok((2, 2, vec![255; 16]))).unwrap();
    assert!(
        written.iter().all(|p| p.file_name().unwrap().len() <= 48),
        "{written:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Findings are read only from a regular file: a device or a FIFO never ends.
#[test]
fn findings_are_read_only_from_a_regular_file() {
    let dir = std::env::temp_dir().join(format!("voyage-findings-fifo-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("findings.json");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let g = voyage_core::Geometry::new([2, 2, 2], [1.0; 3], [0.0; 3]).unwrap();
    for path in [std::path::Path::new("/dev/zero"), fifo.as_path()] {
        let err = voyage_export::read_findings(path, &g)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("not a regular file"), "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
