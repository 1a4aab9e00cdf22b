//! The whole preprocessing on phantoms with ground truth: the lumen, the centerline, the
//! polyps on the surface, the cells.

use glam::{DVec3, Vec3};
use voyage_core::{PrepOptions, Study, prepare};
use voyage_phantom::{self as phantom, ColonOptions, Phantom};

fn dice(a: &[u8], b: &[u8]) -> f64 {
    let (mut both, mut na, mut nb) = (0usize, 0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (x != 0, y != 0);
        both += (x && y) as usize;
        na += x as usize;
        nb += y as usize;
    }
    2.0 * both as f64 / (na + nb) as f64
}

/// Mean over our centerline points of the distance to the true polyline (points ≤ 1 mm apart).
fn mean_distance_to_truth(ours: &[[f64; 3]], truth: &[[f64; 3]]) -> f64 {
    let t: Vec<DVec3> = truth.iter().map(|p| DVec3::from_array(*p)).collect();
    ours.iter()
        .map(|p| {
            t.iter()
                .map(|q| q.distance(DVec3::from_array(*p)))
                .fold(f64::INFINITY, f64::min)
        })
        .sum::<f64>()
        / ours.len() as f64
}

fn check(p: &Phantom, s: &Study, what: &str) {
    let d = dice(p.lumen.data(), s.segmentation.lumen.data());
    assert!(d >= 0.97, "{what}: lumen Dice {d:.4}");
    let cl = &s.centerline;
    // Inside the lumen everywhere.
    for q in &cl.points_mm {
        let ijk =
            s.ct.geometry()
                .local_to_index(DVec3::from_array(*q))
                .round();
        assert_eq!(
            s.segmentation
                .lumen
                .get(ijk.x as usize, ijk.y as usize, ijk.z as usize),
            1,
            "{what}: centerline point {q:?} outside the lumen"
        );
    }
    // Near the true centerline: the ends are compared from the truth's side (ours may run
    // further into a blind end than the truth's inset source and target).
    let mean = mean_distance_to_truth(&p.truth.centerline_mm, &cl.points_mm);
    assert!(
        mean <= 2.0,
        "{what}: mean distance to the true centerline {mean:.2} mm"
    );
    let rel = (cl.length_mm - p.truth.centerline_length_mm) / p.truth.centerline_length_mm;
    assert!(
        rel.abs() < 0.1,
        "{what}: length {:.0} vs {:.0} mm",
        cl.length_mm,
        p.truth.centerline_length_mm
    );
    // Every polyp is on the surface: vertices within 1 mm of its sphere, on the lumen side.
    let mesh = &s.surface.mesh;
    for polyp in &p.truth.polyps {
        let c = DVec3::from_array(polyp.center_mm).as_vec3();
        let r = (polyp.diameter_mm / 2.0) as f32;
        let into = DVec3::from_array(polyp.direction).as_vec3();
        let near = mesh
            .positions
            .iter()
            .filter(|v| {
                let v = Vec3::from_array(**v);
                ((v - c).length() - r).abs() <= 1.0 && (v - c).dot(into) > 0.0
            })
            .count();
        assert!(
            near >= 3,
            "{what}: polyp of {} mm in the {} has {near} vertices within 1 mm of its surface",
            polyp.diameter_mm,
            polyp.segment
        );
    }
    // Cells: a partition of the lumen and of the triangles.
    let cells = &s.cells;
    assert_eq!(
        cells.cells.iter().map(|c| c.voxels).sum::<usize>(),
        s.segmentation.lumen_voxels,
        "{what}: cells vs lumen"
    );
    assert_eq!(
        cells.cells.iter().map(|c| c.triangles.len()).sum::<usize>(),
        mesh.triangles.len()
    );
    assert!(cells.cells.len() > 5, "{what}: {} cells", cells.cells.len());
}

#[test]
fn small_colon_with_distractors() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        seed: 2,
        ..Default::default()
    })
    .unwrap();
    let s = prepare(p.ct.clone(), &PrepOptions::default(), |_| {}).unwrap();
    check(&p, &s, "small colon");
    // The source is in the rectum, the target in the cecum.
    let src = DVec3::from_array(p.truth.source_mm);
    let dst = DVec3::from_array(p.truth.target_mm);
    assert!(
        s.source_mm().distance(src) < 30.0,
        "source {} vs truth {src}",
        s.source_mm()
    );
    assert!(
        s.target_mm().distance(dst) < 30.0,
        "target {} vs truth {dst}",
        s.target_mm()
    );
}

#[test]
fn full_size_colon() {
    let p = phantom::colon(&ColonOptions::default()).unwrap();
    let s = prepare(p.ct.clone(), &PrepOptions::default(), |_| {}).unwrap();
    check(&p, &s, "colon");
}

#[test]
fn the_papers_pipe() {
    let p = phantom::pipe(1).unwrap();
    let s = prepare(p.ct.clone(), &PrepOptions::default(), |_| {}).unwrap();
    check(&p, &s, "pipe");
}

#[test]
fn mask_input_gives_the_same_colon() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        seed: 4,
        ..Default::default()
    })
    .unwrap();
    let mask = p.lumen.map(|m| m as i16);
    let s = prepare(mask, &PrepOptions::default(), |_| {}).unwrap();
    assert!(s.segmentation.from_mask);
    assert_eq!(s.segmentation.lumen.data(), p.lumen.data());
    let mean = mean_distance_to_truth(&p.truth.centerline_mm, &s.centerline.points_mm);
    assert!(mean <= 2.0, "mask input: mean distance {mean:.2} mm");
}

#[test]
fn tagged_fluid_belongs_to_the_lumen() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        seed: 5,
        tagged_fluid: true,
        ..Default::default()
    })
    .unwrap();
    let s = prepare(p.ct.clone(), &PrepOptions::default(), |_| {}).unwrap();
    check(&p, &s, "small colon with tagged fluid");
    // Nearly every voxel of true fluid is lumen (without the fluid step: none of them). The
    // ones missed lie on the fluid's edge against the wall, where the noise-free HU is near
    // the 200 HU threshold and the noise decides.
    let fluid: Vec<usize> = (0..p.labels.data().len())
        .filter(|&i| p.labels.data()[i] == phantom::label::LUMEN_FLUID)
        .collect();
    assert!(
        fluid.len() > 1000,
        "the phantom has {} fluid voxels",
        fluid.len()
    );
    let found = fluid
        .iter()
        .filter(|&&i| s.segmentation.lumen.data()[i] != 0)
        .count();
    assert!(
        found as f64 >= 0.9 * fluid.len() as f64,
        "{found} of {} fluid voxels in the lumen",
        fluid.len()
    );
}

/// Every stage is deterministic: one thread or two, the same study bit for bit.
#[test]
fn the_same_study_whatever_the_threads() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        seed: 9,
        ..Default::default()
    })
    .unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| prepare(p.ct.clone(), &PrepOptions::default(), |_| {}).unwrap())
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.segmentation.lumen.data(), b.segmentation.lumen.data());
    let same = |x: &[f32], y: &[f32]| {
        x.len() == y.len() && x.iter().zip(y).all(|(x, y)| x.to_bits() == y.to_bits())
    };
    assert!(same(a.ds.values(), b.ds.values()), "Ds differs");
    assert!(
        same(a.dt_source.values(), b.dt_source.values()),
        "Dt to the source differs"
    );
    for i in 0..2 {
        assert!(
            same(
                a.nav.as_ref().unwrap().dt[i].values(),
                b.nav.as_ref().unwrap().dt[i].values()
            ),
            "the navigable core's Dt {i} differs"
        );
    }
    assert_eq!(a.centerline.points_mm, b.centerline.points_mm);
    assert_eq!(a.surface.mesh.triangles, b.surface.mesh.triangles);
    assert_eq!(a.surface.mesh.positions, b.surface.mesh.positions);
    assert_eq!(a.cells.triangle_cell, b.cells.triangle_cell);
}

/// Given endpoints: the rectum and the cecum swapped give the same colon backwards, close to
/// the true centerline; one voxel as both ends, and a mask with no lumen, are clear errors.
#[test]
fn given_endpoints_and_their_errors() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        seed: 2,
        ..Default::default()
    })
    .unwrap();
    let mut opts = PrepOptions::default();
    opts.centerline.source_mm = Some(DVec3::from_array(p.truth.target_mm));
    opts.centerline.target_mm = Some(DVec3::from_array(p.truth.source_mm));
    let s = prepare(p.ct.clone(), &opts, |_| {}).unwrap();
    let mean = mean_distance_to_truth(&s.centerline.points_mm, &p.truth.centerline_mm);
    assert!(mean <= 2.0, "swapped ends: mean distance {mean:.2} mm");
    let truth_len = p
        .truth
        .centerline_mm
        .windows(2)
        .map(|w| DVec3::from_array(w[0]).distance(DVec3::from_array(w[1])))
        .sum::<f64>();
    assert!(
        (s.centerline.length_mm - truth_len).abs() < 0.1 * truth_len,
        "swapped ends: {:.0} mm, truth {truth_len:.0} mm",
        s.centerline.length_mm
    );
    opts.centerline.target_mm = opts.centerline.source_mm;
    let e = prepare(p.ct.clone(), &opts, |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("the source and the target are the same voxel"),
        "{e}"
    );
    let empty = p.lumen.map(|_| 0i16);
    let mut as_mask = PrepOptions::default();
    as_mask.segment.mask = Some(true);
    let e = prepare(empty, &as_mask, |_| {}).unwrap_err().to_string();
    assert!(e.contains("the mask holds no lumen"), "{e}");
}

/// Three slices of the small colon phantom are no colon: refused with the reason, where they
/// used to give a 124 mm centerline and a "bridged" gap.
#[test]
fn a_volume_too_thin_for_a_colon_is_refused() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        ..Default::default()
    })
    .unwrap();
    let g = p.ct.geometry();
    let [nx, ny, nz] = g.dims;
    let k0 = nz / 2;
    let slab = p.ct.data()[nx * ny * k0..nx * ny * (k0 + 3)].to_vec();
    let geom = voyage_core::Geometry::new([nx, ny, 3], g.spacing, [0.0; 3]).unwrap();
    let thin = voyage_core::Volume::from_vec(geom, slab).unwrap();
    let Err(err) = prepare(thin, &PrepOptions::default(), |_| {}) else {
        panic!("three slices prepared as a colon");
    };
    let err = err.to_string();
    assert!(err.contains("too thin to hold a colon"), "{err}");
}
