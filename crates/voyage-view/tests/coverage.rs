//! Coverage of the mucosa (issue 23): the two-way reading and the review on the colon
//! phantom, against its truth polyps; and the bookkeeping's invariants.

use glam::{DQuat, DVec3};
use voyage_core::{PrepOptions, Study, prepare};
use voyage_nav::{Camera, Direction, Pose};
use voyage_phantom::{self as phantom, ColonOptions};
use voyage_view::{
    CellMesh, Coverage, CoverageOptions, GLANCE_EVERY_MM, GLANCE_MIN_MM2, GLANCE_TURN_DEG,
    GLANCE_WAYS, Glances, Lumen, POSES_PER_VISIT, READING_FOV_DEG, Reader, Reading,
    ReadingProgress, ReadingRun, ReadingStep, glance_turns, patch_pose, read_both_ways,
    viewing_poses,
};

fn camera() -> Camera {
    Camera::new(Pose::looking(DVec3::ZERO, DVec3::Z, DVec3::Y))
}

fn indexed_mesh(study: &Study) -> CellMesh {
    let mut mesh = CellMesh::new(&study.surface, &study.cells);
    mesh.index_cells();
    mesh
}

fn centroid(mesh: &CellMesh, t: u32) -> DVec3 {
    mesh.triangles[t as usize]
        .map(|v| DVec3::from_array(mesh.positions[v as usize].map(f64::from)))
        .iter()
        .sum::<DVec3>()
        / 3.0
}

/// Seen share (by count) of the triangles on a polyp's head.
fn polyp_seen(mesh: &CellMesh, seen: &Coverage, center: DVec3, radius: f64) -> (usize, f64) {
    let on: Vec<u32> = (0..mesh.triangles.len() as u32)
        .filter(|&t| centroid(mesh, t).distance(center) <= radius + 0.6)
        .collect();
    let n = on.iter().filter(|&&t| seen.is_seen(t)).count();
    (on.len(), n as f64 / on.len().max(1) as f64)
}

fn check_reading(seed: u64) {
    let p = phantom::colon(&ColonOptions {
        seed,
        ..Default::default()
    })
    .unwrap();
    let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
    let mesh = indexed_mesh(&study);
    let mut heard: Vec<ReadingProgress> = Vec::new();
    let r: Reading = read_both_ways(
        &study,
        &mesh,
        CoverageOptions::default(),
        camera(),
        256,
        |p| heard.push(p),
    )
    .unwrap();
    // The progress heard: the steps in their order, never past their totals.
    let mut steps: Vec<ReadingStep> = heard.iter().map(|p| p.step).collect();
    steps.dedup();
    assert_eq!(
        steps[..2],
        [
            ReadingStep::Read(Direction::Forward),
            ReadingStep::Read(Direction::Backward)
        ]
    );
    assert!(
        steps[2..]
            .iter()
            .all(|s| matches!(s, ReadingStep::Review(_) | ReadingStep::Done))
    );
    assert!(heard.iter().all(|p| p.done <= p.total));
    // A flight's progress is the way it has come (mm), from 0 to about all of it.
    let forward: Vec<_> = heard
        .iter()
        .filter(|p| p.step == ReadingStep::Read(Direction::Forward))
        .collect();
    assert_eq!(forward[0].done, 0);
    let last = forward.last().unwrap();
    assert!(
        last.done as f64 >= 0.8 * last.total as f64,
        "the forward flight's progress ends at {} of {} mm",
        last.done,
        last.total
    );
    assert!(forward.windows(2).all(|w| w[1].done + 10 >= w[0].done));
    let [_, two, after] = reading_figures(&format!("seed {seed}"), &r);
    assert!(two >= 94.0, "seed {seed}: two ways {two:.2} % < 94 %");
    assert!(
        after >= 99.5,
        "seed {seed}: after review {after:.2} % < 99.5 %"
    );
    assert!(!r.patches.is_empty(), "seed {seed}: nothing left to review");
    // Every patch has a pose, one of those a visit tries, in the lumen and clear of the wall,
    // within the reading distance of a point of the patch that it looks at; so does every
    // other pose a visit may try.
    let options = CoverageOptions::default();
    let lumen = Lumen::of(&study, ReadingRun::min_wall_mm(&study));
    let aims_at = |patch: &voyage_view::Patch, pose: &Pose| {
        patch.triangles.iter().any(|&t| {
            let to = centroid(&mesh, t) - pose.position;
            to.length() <= options.reading_distance_mm && pose.z_body().dot(to.normalize()) > 0.999
        })
    };
    for v in &r.patches {
        let pose = v.pose.unwrap_or_else(|| {
            panic!(
                "seed {seed}: no pose for the {:.0} mm² patch",
                v.patch.area_mm2
            )
        });
        let tried: Vec<Pose> = viewing_poses(&v.patch, &mesh, &lumen, &options)
            .take(POSES_PER_VISIT)
            .collect();
        assert!(
            tried.iter().any(|p| p.position == pose.position),
            "seed {seed}: a visit's pose is none of those it tries"
        );
        for p in &tried {
            let ds = study.ds.sample(p.position) as f64;
            assert!(
                ds >= lumen.min_wall_mm,
                "seed {seed}: a pose {ds:.2} mm from the wall"
            );
            assert!(
                aims_at(&v.patch, p),
                "seed {seed}: a pose that looks at no point of its patch"
            );
        }
    }
    // The pose chosen for a patch (the review's visits, the window's "next unseen") shows
    // what it says it shows, and only once: marked, that area is seen, and the same frame
    // again shows nothing new.
    let mut reader = Reader::new(&study.cells, Camera::lens(READING_FOV_DEG), 128, 128);
    let mut seen = r.two_way.clone();
    let mut showing = 0;
    for patch in seen.patches(&mesh).iter().take(10) {
        let (pose, shown) = patch_pose(&mut reader, &mesh, &study.cells, patch, &lumen, &mut seen);
        let tried: Vec<Pose> = viewing_poses(patch, &mesh, &lumen, &options)
            .take(POSES_PER_VISIT)
            .collect();
        assert_eq!(pose.is_some(), !tried.is_empty());
        let Some(pose) = pose.filter(|_| shown > 0.0) else {
            continue;
        };
        showing += 1;
        assert!(
            tried.contains(&pose),
            "seed {seed}: a pose none of its patch's"
        );
        let before = seen.seen_mm2();
        let marked = reader.mark_drawn(&mesh, &mut seen);
        assert!(
            (marked - shown).abs() < 1e-6,
            "seed {seed}: {marked} against {shown} mm²"
        );
        assert!((seen.seen_mm2() - before - shown).abs() < 1e-6);
        assert_eq!(reader.probe(&mesh, &study.cells, pose, &mut seen), 0.0);
    }
    assert!(showing > 0, "seed {seed}: no patch is shown by its pose");
    // Every truth polyp of 3 mm or more is seen, most of its head, by the two-way reading
    // or the review.
    for polyp in p.truth.polyps.iter().filter(|q| q.diameter_mm >= 3.0) {
        let c = DVec3::from_array(polyp.center_mm);
        let (n, two_way) = polyp_seen(&mesh, &r.two_way, c, polyp.diameter_mm / 2.0);
        let (_, reviewed) = polyp_seen(&mesh, &r.after_review, c, polyp.diameter_mm / 2.0);
        eprintln!(
            "seed {seed}: {:.0} mm polyp in the {}{}: {n} triangles, {:.0} % seen both ways, {:.0} % after review",
            polyp.diameter_mm,
            polyp.segment,
            if polyp.behind_fold {
                ", behind a fold"
            } else {
                ""
            },
            two_way * 100.0,
            reviewed * 100.0
        );
        assert!(n >= 10, "seed {seed}: no surface found on a polyp");
        assert!(
            reviewed >= 0.5,
            "seed {seed}: a {:.0} mm polyp in the {} is {:.0} % seen",
            polyp.diameter_mm,
            polyp.segment,
            reviewed * 100.0
        );
    }
}

#[test]
fn two_way_reading_and_review_cover_the_phantom_seed_1() {
    check_reading(1);
}

#[test]
fn two_way_reading_and_review_cover_the_phantom_seed_2() {
    check_reading(2);
}

fn small_study() -> Study {
    let p = phantom::colon(&ColonOptions {
        small: true,
        ..Default::default()
    })
    .unwrap();
    prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap()
}

#[test]
fn coverage_bookkeeping() {
    let study = small_study();
    let mesh = indexed_mesh(&study);
    let options = CoverageOptions {
        min_patch_mm2: 0.0,
        ..Default::default()
    };
    let fresh = Coverage::new(&mesh, options);
    // Nothing seen: the patches are the connected parts of the whole surface.
    let whole: f64 = fresh.patches(&mesh).iter().map(|p| p.area_mm2).sum();
    assert!((whole - fresh.total_mm2()).abs() < 1e-6 * fresh.total_mm2());
    assert_eq!(fresh.percent(), 0.0);

    // A view down the lumen from the centerline's middle shows something; the same view
    // again shows nothing new; a reading distance below the nearest wall shows nothing.
    let cl = &study.centerline.points_mm;
    let i = cl.len() / 2;
    let at = DVec3::from_array(cl[i]);
    let ahead = DVec3::from_array(cl[i + 3]) - at;
    let pose = Pose::looking(at, ahead, ahead.any_orthonormal_vector());
    let cells = &study.cells;
    let mut reader = Reader::new(cells, camera(), 128, 128);
    let mut seen = fresh.clone();
    let first = reader.show(&mesh, cells, pose, &mut seen);
    assert!(first > 0.0 && (seen.seen_mm2() - first).abs() < 1e-9);
    assert_eq!(reader.show(&mesh, cells, pose, &mut seen), 0.0);

    // Every triangle marked covers a pixel of the frame and faces the eye within 75°: its
    // smoothed normal (the mean of its vertices', as shaded) does.
    let ids: std::collections::HashSet<u32> = reader.frame().ids().collect();
    for t in 0..mesh.triangles.len() as u32 {
        if seen.is_seen(t) {
            assert!(ids.contains(&t));
            let [a, b, c] = mesh.triangles[t as usize]
                .map(|v| DVec3::from_array(mesh.positions[v as usize].map(f64::from)));
            let n: DVec3 = mesh.triangles[t as usize]
                .iter()
                .map(|&v| DVec3::from_array(mesh.normals[v as usize].map(f64::from)))
                .sum::<DVec3>()
                .normalize();
            let to_eye = (at - (a + b + c) / 3.0).normalize();
            assert!(n.dot(to_eye) >= 75f64.to_radians().cos() - 1e-9);
        }
    }
    let near_wall = study.ds.sample(at) as f64;
    let mut blind = Coverage::new(
        &mesh,
        CoverageOptions {
            reading_distance_mm: 0.5 * near_wall,
            ..options
        },
    );
    assert_eq!(reader.show(&mesh, cells, pose, &mut blind), 0.0);
    // The review's targets are the listed patches first, then smaller bits down to its floor.
    let listed = fresh.patches(&mesh);
    let targets = Coverage::new(
        &mesh,
        CoverageOptions {
            min_patch_mm2: 30.0,
            review_min_mm2: 1.0,
            ..options
        },
    );
    let (big, all) = (targets.patches(&mesh), targets.review_targets(&mesh));
    assert!(all.len() >= big.len() && !big.is_empty());
    assert!(big.iter().all(|p| p.area_mm2 >= 30.0));
    assert!(all.iter().all(|p| p.area_mm2 >= 1.0));
    for (p, q) in big.iter().zip(&all) {
        assert_eq!(p.triangles, q.triangles);
    }
    assert_eq!(listed.len(), fresh.review_targets(&mesh).len());
    // A probe says what a frame would show and marks nothing: showing it then shows that.
    let back = Pose::looking(at, -ahead, ahead.any_orthonormal_vector());
    let mut probed = seen.clone();
    let would = reader.probe(&mesh, cells, back, &mut probed);
    assert!(would > 0.0 && probed.seen_mm2() == seen.seen_mm2());
    assert!((reader.show(&mesh, cells, back, &mut probed) - would).abs() < 1e-6);
    // Union: what two readings saw together, counted once.
    let mut other = fresh.clone();
    reader.show(&mesh, cells, back, &mut other);
    let mut both = seen.clone();
    both.union(&other);
    assert!(both.seen_mm2() > seen.seen_mm2() && both.seen_mm2() > other.seen_mm2());
    assert!(both.seen_mm2() <= seen.seen_mm2() + other.seen_mm2() + 1e-9);
    let again = both.seen_mm2();
    both.union(&seen);
    assert_eq!(both.seen_mm2(), again);
}

/// A reading's one-way, two-way and after-review figures (%), printed under `name`; every
/// flight reaches its end, and the way back adds to the way there.
fn reading_figures(name: &str, r: &Reading) -> [f64; 3] {
    let figures = [&r.one_way, &r.two_way, &r.after_review].map(|c| c.percent());
    let [one, two, after] = figures;
    eprintln!(
        "{name}: one way {one:.2} %, two ways {two:.2} %, after review {after:.2} % ({} patches, {} visits, {:?} glances)",
        r.patches.len(),
        r.visits,
        r.glances
    );
    assert!(
        r.flights.iter().all(|f| f.reached),
        "{name}: a flight fell short"
    );
    assert!(
        one < two,
        "{name}: one way {one:.2} % ≥ two ways {two:.2} %"
    );
    figures
}

/// A real colon read both ways and reviewed as `voyage coverage` reads it (the reading
/// lens, 256² frames), `name` for what it prints: the reading, and its one-way, two-way and
/// after-review figures (%). Every flight reaches its end.
fn read_real(name: &str, path: &std::path::Path) -> (Reading, [f64; 3]) {
    let volume = voyage_io::load(path, &Default::default()).unwrap().volume;
    let study = prepare(volume, &PrepOptions::default(), |_| {}).unwrap();
    let mesh = indexed_mesh(&study);
    let lens = Camera::lens(READING_FOV_DEG);
    let r = read_both_ways(&study, &mesh, CoverageOptions::default(), lens, 256, |_| {}).unwrap();
    let figures = reading_figures(name, &r);
    (r, figures)
}

/// The real colon mask, read at the reading lens: two ways the reading shows at least the
/// 94 % of readers in the literature, the review leaves at most 0.5 % of the mucosa unseen,
/// and every listed patch has a pose. Looking straight along the flights (no glances) it
/// showed 89 %: a chamber 85 mm wide passes the lens at a slant.
#[test]
fn the_real_colon_is_read_to_the_end() {
    let Some(path) = voyage_phantom::fixtures::colon_a_path() else {
        return;
    };
    let (r, [_, two, after]) = read_real("colon-a", &path);
    assert!(two >= 94.0, "two ways {two:.2} % < 94 %");
    assert!(
        r.glances.iter().all(|&n| n > 0),
        "no glances: {:?}",
        r.glances
    );
    assert!(after >= 99.5, "after review {after:.2} % < 99.5 %");
    let without = r.patches.iter().filter(|v| v.pose.is_none()).count();
    assert_eq!(without, 0, "{without} listed patches without a pose");
}

/// The real exam: its 100 mm wide right colon leaves about 16 % unseen by the flights
/// (issue 37's 94 % both ways is not reached there: the far wall lies beyond the reading
/// distance of the flights' lane), and the review leaves at most 0.5 % (99.40 % when it
/// visited only bits of a 3 mm polyp's footprint or more).
#[test]
fn the_real_exam_is_reviewed_to_the_end() {
    let Some(path) = voyage_phantom::fixtures::shared_file("ctc/prone-tagged.nii.gz") else {
        return;
    };
    let (_, [_, two, after]) = read_real("ctc/prone-tagged", &path);
    assert!(two >= 80.0, "two ways {two:.2} %");
    assert!(after >= 99.5, "after review {after:.2} % < 99.5 %");
}

/// A reading flight looks around once per [`GLANCE_EVERY_MM`] of travel, turned
/// [`GLANCE_TURN_DEG`] from its view where that shows enough unseen mucosa, after trying the
/// [`GLANCE_WAYS`] ways one per frame; where everything in reach has been seen it does not.
#[test]
fn glances_look_around_where_mucosa_is_unseen() {
    let study = small_study();
    let mesh = indexed_mesh(&study);
    let cells = &study.cells;
    let cl = &study.centerline;
    let i = cl.points_mm.len() / 2;
    // The next point at least `GLANCE_EVERY_MM` on, as the crow flies.
    let on_from = |i: usize| {
        let from = DVec3::from_array(cl.points_mm[i]);
        (i..cl.points_mm.len())
            .find(|&j| DVec3::from_array(cl.points_mm[j]).distance(from) >= GLANCE_EVERY_MM)
            .unwrap()
    };
    let j = on_from(i);
    let pose_at = |k: usize| {
        let at = DVec3::from_array(cl.points_mm[k]);
        let ahead = DVec3::from_array(cl.points_mm[k + 3]) - at;
        Pose::looking(at, ahead, ahead.any_orthonormal_vector())
    };
    let (first, later) = (pose_at(i), pose_at(j));
    let mut seen = Coverage::new(&mesh, CoverageOptions::default());
    let mut glances = Glances::new(cells, camera());
    let mut reader = Reader::new(cells, camera(), 128, 128);
    // Not yet far enough; then, with nothing seen, a glance once every way has been tried,
    // one per frame.
    assert!(glances.next(&mesh, cells, first, &mut seen).is_none());
    let mut tries = (0..GLANCE_WAYS).map(|_| glances.next(&mesh, cells, later, &mut seen));
    assert!(tries.by_ref().take(GLANCE_WAYS - 1).all(|g| g.is_none()));
    let glance = tries
        .next()
        .flatten()
        .expect("no glance with all the walls unseen");
    assert_eq!(glance.position, later.position);
    let turned = glance.z_body().angle_between(later.z_body()).to_degrees();
    assert!(
        (turned - GLANCE_TURN_DEG).abs() < 1e-6,
        "turned {turned:.2}°"
    );
    let before = seen.seen_mm2();
    let shown = reader.show(&mesh, cells, glance, &mut seen);
    assert!(
        shown >= 0.5 * GLANCE_MIN_MM2,
        "the glance showed {shown:.0} mm²"
    );
    assert!(seen.seen_mm2() > before && glances.taken == 1);
    // Where every way a glance could turn has been shown, there is nothing to glance at.
    let last = pose_at(on_from(j));
    for q in glance_turns().chain([DQuat::IDENTITY]) {
        let turned = Pose {
            orientation: last.orientation * q,
            ..last
        };
        reader.show(&mesh, cells, turned, &mut seen);
    }
    assert!((0..2 * GLANCE_WAYS).all(|_| glances.next(&mesh, cells, last, &mut seen).is_none()));
}

/// A pick over the chunks the ray's line meets (an indexed mesh, as the reading's) finds
/// the same hit as one over every triangle: rays from centerline points in all directions.
#[test]
fn a_pick_over_chunks_finds_what_a_pick_over_all_does() {
    let study = small_study();
    let plain = CellMesh::new(&study.surface, &study.cells);
    let indexed = indexed_mesh(&study);
    let mut rng = voyage_core::rng::Rng::new(7, 0);
    let points = &study.centerline.points_mm;
    let (mut hits, mut misses) = (0, 0);
    for i in (0..points.len()).step_by(points.len() / 40 + 1) {
        let origin = DVec3::from_array(points[i]);
        for _ in 0..25 {
            let dir = DVec3::new(rng.gauss(), rng.gauss(), rng.gauss());
            let (a, b) = (
                voyage_view::pick(&plain, None, origin, dir),
                voyage_view::pick(&indexed, None, origin, dir),
            );
            assert_eq!(a, b, "from {origin} along {dir}");
            if a.is_some() {
                hits += 1;
            } else {
                misses += 1;
            }
        }
    }
    assert!(hits > 500, "{hits} hits, {misses} misses");
}

/// Per segment, the areas add up to the whole and the segments come in their order along the
/// colon, the phantom's from the rectum to the cecum.
#[test]
fn coverage_by_segment_adds_up_in_the_colons_order() {
    let study = small_study();
    let mesh = indexed_mesh(&study);
    let mut seen = Coverage::new(&mesh, CoverageOptions::default());
    let mut reader = Reader::new(&study.cells, Camera::lens(READING_FOV_DEG), 128, 128);
    let points = &study.centerline.points_mm;
    for i in (0..points.len()).step_by(25) {
        let (p, q) = (points[i], points[(i + 5).min(points.len() - 1)]);
        let (p, q) = (DVec3::from_array(p), DVec3::from_array(q));
        let pose = Pose::looking(p, q - p, study.anterior_local());
        reader.show(&mesh, &study.cells, pose, &mut seen);
    }
    let rows = seen.by_segment(&mesh, &study);
    let total: f64 = rows.iter().map(|r| r.total_mm2).sum();
    let shown: f64 = rows.iter().map(|r| r.seen_mm2).sum();
    assert!((total - seen.total_mm2()).abs() < 1e-6 * total, "{rows:?}");
    assert!(
        (shown - seen.seen_mm2()).abs() < 1e-6 * total.max(1.0),
        "{rows:?}"
    );
    let order: Vec<usize> = rows
        .iter()
        .map(|r| {
            voyage_core::COLON_SEGMENTS
                .iter()
                .position(|&s| s == r.segment)
                .unwrap_or(usize::MAX)
        })
        .collect();
    assert!(order.windows(2).all(|w| w[0] < w[1]), "{rows:?}");
    assert_eq!(rows[0].segment, "rectum", "{rows:?}");
    assert!(rows.len() >= 5, "{rows:?}");
    assert!(
        rows.iter()
            .all(|r| r.seen_mm2 <= r.total_mm2 && r.percent() > 0.0)
    );
}
