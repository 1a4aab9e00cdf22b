//! Rendering and visibility (paper §4): culling never changes the image, the reductions of
//! the paper's Table 1 hold, and the pipe's polyps are in view.

#[cfg(not(feature = "survey"))]
compile_error!(
    "tests/render.rs needs voyage-view's `survey` feature: cargo test -p voyage-view --features survey (cargo test --workspace turns it on)"
);

use glam::DVec3;
use voyage_core::{PrepOptions, Study, prepare};
use voyage_nav::{BrickStore, Camera, Direction, FlightOptions, Pose, PotentialField, fly};
use voyage_phantom::{self as phantom, ColonOptions, Phantom};
use voyage_view::{
    CellMesh, Frame, NO_TRIANGLE, Rasterizer, Shading, Strategy, View, Visibility, look_around,
    survey,
};

/// The colon-a mask of the shared data preprocessed with the default options, or None
/// (skipped).
fn colon_a_study() -> Option<voyage_core::Study> {
    let path = voyage_phantom::fixtures::colon_a_path()?;
    let mask = voyage_io::load(&path, &Default::default()).unwrap().volume;
    Some(voyage_core::prepare(mask, &Default::default(), |_| {}).unwrap())
}

/// Poses along both automatic flights (`per_flight` each, evenly spaced, in flight order so
/// the paper's temporal coherence is exercised) and `random` look-around views.
fn flight_cameras(study: &Study, per_flight: usize, random: usize) -> Vec<Camera> {
    let nav = study.navigable(1.0).unwrap();
    let field = PotentialField::new(BrickStore::new(study, &nav).unwrap(), study.ct.geometry());
    let mut all: Vec<Pose> = Vec::new();
    let mut cameras = Vec::new();
    for d in [Direction::Forward, Direction::Backward] {
        let f = fly(&field, &study.centerline, d, &FlightOptions::default()).unwrap();
        assert!(f.reached);
        let n = f.poses.len();
        cameras.extend((0..per_flight).map(|i| Camera::new(f.poses[i * n / per_flight])));
        all.extend(f.poses);
    }
    cameras.extend(look_around(&all, random, 7).into_iter().map(Camera::new));
    cameras
}

fn check_exact_and_reduced(study: &Study, what: &str, min_paper_ratio: f64) {
    let mesh = CellMesh::new(&study.surface, &study.cells);
    let cameras = flight_cameras(study, 80, 80);
    assert!(cameras.len() >= 200);
    let s = survey(
        &mesh,
        &study.cells,
        &cameras,
        256,
        256,
        &Strategy::ALL,
        false,
    );
    for st in &s.strategies {
        eprintln!(
            "{what}: {:5} mean {:9.0} max {:8} ratio {:5.1} inexact frames {} ({} px)",
            st.strategy.name(),
            st.mean_triangles,
            st.max_triangles,
            st.ratio_to_all,
            st.inexact_frames,
            st.differing_pixels
        );
        assert_eq!(
            st.inexact_frames,
            0,
            "{what}: {} changed the image in {} frames",
            st.strategy.name(),
            st.inexact_frames
        );
    }
    assert!(s.exact);
    let get = |k: Strategy| s.get(k).unwrap().mean_triangles;
    // Something was culled, so exactness was not trivially true.
    assert!(get(Strategy::Lg) < 0.5 * get(Strategy::All), "{what}");
    let paper = s.get(Strategy::Paper).unwrap().ratio_to_all;
    assert!(
        paper >= min_paper_ratio,
        "{what}: MC : paper = {paper:.1} : 1, want ≥ {min_paper_ratio}"
    );
    assert!(
        get(Strategy::Ours) < get(Strategy::Paper),
        "{what}: ours draws no fewer triangles than the paper's"
    );
    assert!(
        get(Strategy::Paper) < get(Strategy::Lg),
        "{what}: the depth test removed nothing"
    );
    check_select_is_exact(study, &mesh, &cameras, what);
    check_reach_is_exact(study, &mesh, &cameras, what);
}

/// A frame drawn within a reach (what coverage draws) shows what the whole frame shows at
/// every pixel nearer than the reach, and nothing nearer elsewhere; it draws fewer triangles.
fn check_reach_is_exact(study: &Study, mesh: &CellMesh, cameras: &[Camera], what: &str) {
    const REACH_MM: f64 = 20.0;
    let mut mesh = mesh.clone();
    mesh.index_cells();
    let (mut whole_vis, mut near_vis) = (
        Visibility::new(&study.cells, Strategy::Ours),
        Visibility::new(&study.cells, Strategy::Ours),
    );
    let (mut whole_drawn, mut near_drawn, mut near_pixels) = (0, 0, 0);
    for cam in cameras.iter().step_by(3) {
        let view = View::new(cam, 256, 256);
        let (mut whole, mut near) = (Frame::new(256, 256), Frame::new(256, 256));
        let raster = Rasterizer::ids_only(&mesh, view);
        whole_drawn += whole_vis.draw(&mut whole, &raster, &study.cells).triangles;
        let raster = Rasterizer::ids_only(&mesh, view).within_reach(REACH_MM);
        near_drawn += near_vis.draw(&mut near, &raster, &study.cells).triangles;
        let distance = |f: &Frame, x: usize, y: usize| {
            let p = &f.pixels[y * 256 + x];
            (p.id != NO_TRIANGLE).then(|| view.pixel_distance(x as u32, y as u32, p.inv_depth))
        };
        for (y, x) in (0..256).flat_map(|y| (0..256).map(move |x| (y, x))) {
            match distance(&whole, x, y) {
                Some(d) if d <= REACH_MM => {
                    near_pixels += 1;
                    assert_eq!(
                        whole.pixels[y * 256 + x].id,
                        near.pixels[y * 256 + x].id,
                        "{what}: the reach changed a pixel {d:.2} mm away"
                    );
                }
                _ => assert!(
                    distance(&near, x, y).is_none_or(|d| d > REACH_MM),
                    "{what}: a pixel beyond the reach became nearer"
                ),
            }
        }
    }
    eprintln!("{what}: within {REACH_MM} mm: {near_drawn} triangles of {whole_drawn}");
    assert!(near_pixels > 0 && near_drawn < whole_drawn, "{what}");
}

/// `Visibility::select` (the GPU's cell list: portal outlines, no depth buffer) keeps every
/// triangle that wins a pixel: the id buffer of its cells equals the one of all cells.
fn check_select_is_exact(study: &Study, mesh: &CellMesh, cameras: &[Camera], what: &str) {
    let all: Vec<u32> = (0..study.cells.cells.len() as u32).collect();
    let all_triangles = mesh.triangles_in(&all) as f64;
    let shading = Shading::default();
    for strategy in [Strategy::Lg, Strategy::Ours] {
        let mut vis = Visibility::new(&study.cells, strategy);
        let mut drawn = 0.0;
        let sample: Vec<&Camera> = cameras.iter().step_by(3).collect();
        for cam in &sample {
            let view = View::new(cam, 256, 256);
            let raster = Rasterizer::new(mesh, view, &shading);
            let (mut reference, mut culled) = (Frame::new(256, 256), Frame::new(256, 256));
            raster.draw_cells(&mut reference.rows(), &all);
            let cells = vis.select(&study.cells, &view).cells;
            raster.draw_cells(&mut culled.rows(), &cells);
            assert!(
                reference.ids().eq(culled.ids()),
                "{what}: select ({strategy}) changed the image"
            );
            drawn += mesh.triangles_in(&cells) as f64;
        }
        let ratio = all_triangles * sample.len() as f64 / drawn;
        eprintln!(
            "{what}: select {strategy}: exact on {} frames, MC : select = {ratio:.1}",
            sample.len()
        );
        assert!(
            ratio > 3.0,
            "{what}: select ({strategy}) culled little: {ratio:.1} : 1"
        );
    }
}

#[test]
fn culling_never_changes_the_image_on_the_colon_phantom() {
    let p = phantom::colon(&ColonOptions::default()).unwrap();
    let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
    check_exact_and_reduced(&study, "colon phantom", 9.0);
}

#[test]
fn culling_never_changes_the_image_on_colon_a() {
    let Some(study) = colon_a_study() else {
        return;
    };
    check_exact_and_reduced(&study, "colon-a", 9.0);
}

/// Pixels showing a triangle with all three vertices within `r` of `c`.
fn pixels_on(frame: &Frame, mesh: &CellMesh, c: DVec3, r: f64) -> usize {
    frame
        .ids()
        .filter(|&id| {
            id != NO_TRIANGLE
                && mesh.triangles[id as usize].iter().all(|&v| {
                    (DVec3::from_array(mesh.positions[v as usize].map(f64::from)) - c).length() <= r
                })
        })
        .count()
}

#[test]
fn the_pipe_shows_its_three_polyps() {
    let Phantom { ct, truth, .. } = phantom::pipe(1).unwrap();
    let study = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    let mesh = CellMesh::new(&study.surface, &study.cells);
    let cl = &study.centerline;
    assert_eq!(truth.polyps.len(), 3);
    for polyp in &truth.polyps {
        let c = DVec3::from_array(polyp.center_mm);
        // From the centerline 35 mm before the polyp, looking at it.
        let near = (0..cl.points_mm.len())
            .min_by(|&a, &b| {
                (DVec3::from_array(cl.points_mm[a]) - c)
                    .length()
                    .total_cmp(&(DVec3::from_array(cl.points_mm[b]) - c).length())
            })
            .unwrap();
        let at = cl.arc_mm[near] - 35.0;
        let i = cl.arc_mm.partition_point(|&a| a < at).min(near);
        let eye = DVec3::from_array(cl.points_mm[i]);
        let pose = Pose::looking(eye, c - eye, (c - eye).any_orthonormal_vector());
        let view = View::new(&Camera::new(pose), 512, 512);
        let mut frame = Frame::new(512, 512);
        let cell = study.cells.cell_of_point(eye).unwrap() as u32;
        assert!(cell < mesh.cells() as u32);
        Rasterizer::new(&mesh, view, &Shading::default()).draw_cells(
            &mut frame.rows(),
            &(0..mesh.cells() as u32).collect::<Vec<_>>(),
        );
        let seen = pixels_on(&frame, &mesh, c, polyp.diameter_mm / 2.0 + 0.5);
        // Its disc seen from ~35 mm covers ≈ π(256·r/35)² pixels; at least a fifth must show.
        let r = polyp.diameter_mm / 2.0;
        let disc = std::f64::consts::PI * (256.0 * r / (c - eye).length()).powi(2);
        eprintln!(
            "polyp {} mm: {seen} px (disc ≈ {disc:.0})",
            polyp.diameter_mm
        );
        assert!(
            seen as f64 >= 0.2 * disc,
            "the {} mm polyp shows on {seen} pixels only",
            polyp.diameter_mm
        );
    }
}

/// A frame drawn in bands, one per worker (`Visibility::draw` with three threads: bands of
/// 170, 171 and 171 rows), is the frame drawn whole (one thread), pixel for pixel: ids,
/// depths and colours, for every strategy, along both flights and looking around; and the
/// bands' triangles, each counted once, are no more than the whole frame's.
#[test]
fn a_frame_drawn_in_bands_is_the_frame_drawn_whole() {
    let p = phantom::colon(&ColonOptions::default()).unwrap();
    let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
    let mut mesh = CellMesh::new(&study.surface, &study.cells);
    mesh.index_cells();
    let cameras = flight_cameras(&study, 15, 15);
    let shading = Shading::default();
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let (one, three) = (pool(1), pool(3));
    for strategy in Strategy::ALL {
        let (mut whole_vis, mut band_vis) = (
            Visibility::new(&study.cells, strategy),
            Visibility::new(&study.cells, strategy),
        );
        let (mut whole, mut banded) = (Frame::new(512, 512), Frame::new(512, 512));
        let (mut whole_tris, mut band_tris) = (0, 0);
        for cam in &cameras {
            let view = View::new(cam, 512, 512);
            // Made on the pool's thread: a rasterizer is not shared between threads.
            let draw = |vis: &mut Visibility, frame: &mut Frame| {
                vis.draw(frame, &Rasterizer::new(&mesh, view, &shading), &study.cells)
            };
            whole_tris += one.install(|| draw(&mut whole_vis, &mut whole)).triangles;
            let drawn = three.install(|| draw(&mut band_vis, &mut banded));
            band_tris += drawn.triangles;
            assert!(whole.covered() > 0);
            assert!(whole == banded, "{strategy}: the bands changed the frame");
            assert_eq!(drawn.rects.len(), drawn.cells.len());
        }
        eprintln!("{strategy}: triangles whole {whole_tris}, in bands {band_tris}");
        assert!(band_tris <= whole_tris && band_tris > 0, "{strategy}");
    }
}
