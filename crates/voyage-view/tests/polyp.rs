//! The 3D polyp size tool on the phantoms' truth polyps.

use glam::DVec3;
use voyage_core::{PrepOptions, prepare};
use voyage_phantom::{self as phantom, ColonOptions, Phantom};
use voyage_view::{CellMesh, measure_polyp, pick};

/// Clicks each truth polyp from the lumen in front of it and measures it; returns
/// (truth diameter, measured) per polyp of at least `min_mm`.
fn measured(p: Phantom, min_mm: f64) -> Vec<(f64, Option<f64>, String)> {
    let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
    let mesh = CellMesh::new(&study.surface, &study.cells);
    p.truth
        .polyps
        .iter()
        .filter(|q| q.diameter_mm >= min_mm)
        .map(|q| {
            let c = DVec3::from_array(q.center_mm);
            let into = DVec3::from_array(q.direction);
            let eye = c + into * (q.diameter_mm / 2.0 + 6.0);
            let hit = pick(&mesh, None, eye, c - eye).expect("the click hits the surface");
            let size = measure_polyp(&mesh, hit.point, hit.normal).map(|s| s.diameter_mm);
            (q.diameter_mm, size, format!("{} {}", q.segment, q.shape))
        })
        .collect()
}

fn check(name: &str, results: &[(f64, Option<f64>, String)]) {
    for (truth, got, what) in results {
        eprintln!("{name}: {what} polyp {truth:.1} mm measured {got:?}");
    }
    for (truth, got, what) in results {
        let got =
            got.unwrap_or_else(|| panic!("{name}: the {truth} mm {what} polyp was not found"));
        assert!(
            (got - truth).abs() <= 0.5,
            "{name}: the {truth} mm {what} polyp measured {got:.2} mm"
        );
    }
}

#[test]
fn polyp_size_on_the_colon_phantom_within_half_a_millimetre() {
    for seed in [1, 2] {
        let p = phantom::colon(&ColonOptions {
            seed,
            ..Default::default()
        })
        .unwrap();
        let r = measured(p, 5.0);
        assert!(r.len() >= 5);
        check(&format!("colon phantom seed {seed}"), &r);
    }
}

/// A click on the plain wall, away from every polyp, finds no polyp, or at most a fold's
/// short piece; never one as large as the colon.
#[test]
fn the_plain_wall_is_not_a_polyp() {
    let p = phantom::colon(&ColonOptions::default()).unwrap();
    let polyps: Vec<DVec3> = p
        .truth
        .polyps
        .iter()
        .map(|q| DVec3::from_array(q.center_mm))
        .collect();
    let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
    let mesh = CellMesh::new(&study.surface, &study.cells);
    let cl = &study.centerline.points_mm;
    let mut flat = 0;
    for i in (20..cl.len() - 20).step_by(cl.len() / 25) {
        let at = DVec3::from_array(cl[i]);
        let along = DVec3::from_array(cl[i + 1]) - at;
        let side = along.any_orthonormal_vector();
        let Some(hit) = pick(&mesh, None, at, side) else {
            continue;
        };
        if polyps.iter().any(|c| c.distance(hit.point) < 20.0) {
            continue;
        }
        match measure_polyp(&mesh, hit.point, hit.normal) {
            None => flat += 1,
            Some(s) => assert!(
                s.diameter_mm < 30.0,
                "a {:.0} mm 'polyp' on the wall",
                s.diameter_mm
            ),
        }
    }
    assert!(flat >= 5, "only {flat} plain-wall clicks found nothing");
}

#[test]
fn polyp_size_on_the_pipe_phantom_within_half_a_millimetre() {
    let p = phantom::pipe(1).unwrap();
    let r = measured(p, 5.0);
    assert!(r.len() >= 2);
    check("pipe phantom", &r);
}

/// Each truth polyp's segment, as the report names it, and its distance from the rectum end.
#[test]
fn polyps_are_placed_in_their_segments() {
    for seed in [1, 2] {
        let p = phantom::colon(&ColonOptions {
            seed,
            ..Default::default()
        })
        .unwrap();
        let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
        for q in &p.truth.polyps {
            // Just off the polyp's head, in the lumen, as a marker on it is.
            let c = DVec3::from_array(q.center_mm)
                + DVec3::from_array(q.direction) * (q.diameter_mm / 2.0 + 1.5);
            let got = study.segment_at(c);
            let arc = study.arc_at(c).unwrap();
            eprintln!(
                "seed {seed}: {} polyp at arc {:.0} (truth {:.0}): {got}",
                q.segment, arc, q.arc_mm
            );
            // The centerline found runs a few % longer than the truth's (it follows the folds).
            assert!(
                (arc - q.arc_mm).abs() <= (0.04 * q.arc_mm).max(20.0),
                "arc {arc:.0} against {:.0}",
                q.arc_mm
            );
            // The truth has no flexures: a flexure is either of its neighbours.
            let same = match got {
                "splenic flexure" => ["descending", "transverse"].contains(&q.segment.as_str()),
                "hepatic flexure" => ["transverse", "ascending"].contains(&q.segment.as_str()),
                name => name == q.segment,
            };
            assert!(
                same,
                "seed {seed}: the {} polyp at arc {arc:.0} is said to be in the {got}",
                q.segment
            );
        }
    }
}
