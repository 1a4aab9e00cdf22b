//! Close-up volume rendering (paper Fig. 9): known answers on synthetic volumes — where a
//! sphere shows and how large, polyp against stool against tagged stool, nothing outside the
//! box, alignment with the endoscopic view's camera — and the pipe phantom's 7 mm polyp.

use glam::DVec3;
use voyage_core::{Geometry, Volume};
use voyage_nav::{Camera, Pose};
use voyage_phantom as phantom;
use voyage_view::{CloseupBox, TransferFunction, View, render_closeup};

const AIR: f64 = -1000.0;
const SOFT: f64 = 40.0;
const SIZE: u32 = 256;

/// A 64³ volume of 0.75 mm voxels whose HU at each voxel centre (mm) is `hu(p)`.
fn volume(hu: impl Fn(DVec3) -> f64) -> Volume<i16> {
    let g = Geometry::new([64; 3], [0.75; 3], [0.0; 3]).unwrap();
    let data: Vec<i16> = (0..g.len())
        .map(|n| {
            let [i, j, k] = g.ijk(n);
            hu(g.index_to_local(DVec3::new(i as f64, j as f64, k as f64))).round() as i16
        })
        .collect();
    Volume::from_vec(g, data).unwrap()
}

/// Fraction of a voxel inside a surface at signed distance `sdf` (mm): a one-voxel ramp, as
/// partial volume in a scan.
fn inside(sdf: f64) -> f64 {
    (0.5 - sdf / 0.75).clamp(0.0, 1.0)
}

/// `value` inside a sphere, `outside` elsewhere, with partial volume at its surface.
fn sphere(p: DVec3, c: DVec3, r: f64, value: f64, outside: f64) -> f64 {
    let f = inside((p - c).length() - r);
    outside + f * (value - outside)
}

const CENTER: DVec3 = DVec3::new(24.0, 24.0, 24.0);

/// Looking along +z at `target` from `distance` mm, screen up = −y.
fn camera_at(target: DVec3, distance: f64) -> Camera {
    Camera::new(Pose::looking(
        target - DVec3::Z * distance,
        DVec3::Z,
        -DVec3::Y,
    ))
}

fn alpha(img: &[u8], x: u32, y: u32) -> u8 {
    img[((y * SIZE + x) * 4 + 3) as usize]
}

fn rgb(img: &[u8], x: u32, y: u32) -> [f64; 3] {
    let i = ((y * SIZE + x) * 4) as usize;
    [img[i] as f64, img[i + 1] as f64, img[i + 2] as f64]
}

/// Pixels whose centres lie within `r` pixels of (cx, cy).
fn disc(cx: f64, cy: f64, r: f64) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for y in 0..SIZE {
        for x in 0..SIZE {
            if (x as f64 + 0.5 - cx).hypot(y as f64 + 0.5 - cy) <= r {
                out.push((x, y));
            }
        }
    }
    out
}

/// Radius (pixels) of a sphere of radius `r` at distance `d` on the axis of a 90° view: its
/// silhouette cone has half-angle asin(r/d).
fn projected_radius(r: f64, d: f64) -> f64 {
    let focal = SIZE as f64 / 2.0;
    focal * r / (d * d - r * r).sqrt()
}

#[test]
fn a_soft_tissue_sphere_renders_as_an_opaque_disc_of_its_projected_size() {
    let r = 6.0;
    let ct = volume(|p| sphere(p, CENTER, r, SOFT, AIR));
    let cam = camera_at(CENTER, 30.0);
    let img = render_closeup(
        &ct,
        &cam,
        &CloseupBox::in_front_of(&cam, 30.0, 15.0),
        SIZE,
        SIZE,
        &TransferFunction::tissue(),
    );
    let expect = projected_radius(r, 30.0);
    let c = SIZE as f64 / 2.0;
    // Through the middle of the disc a ray crosses ≥ 9.6 mm of tissue: ≥ 75 % opaque.
    for (x, y) in disc(c, c, 0.6 * expect) {
        let [red, g, b] = rgb(&img, x, y);
        assert!(
            alpha(&img, x, y) > 190,
            "({x}, {y}) alpha {}",
            alpha(&img, x, y)
        );
        assert!(
            red > 1.5 * g && red > 1.5 * b,
            "({x}, {y}) is not soft-tissue red: {:?}",
            [red, g, b]
        );
    }
    let opaque = disc(c, c, 2.0 * expect)
        .into_iter()
        .filter(|&(x, y)| alpha(&img, x, y) >= 128)
        .count();
    let measured = (opaque as f64 / std::f64::consts::PI).sqrt();
    eprintln!("sphere disc radius: rendered {measured:.2} px, projected {expect:.2} px");
    assert!(
        (measured - expect).abs() <= 1.5,
        "rendered radius {measured:.2} px, projected {expect:.2} px"
    );
    let every_pixel = disc(c, c, 1e9);
    let outside = every_pixel
        .into_iter()
        .filter(|&(x, y)| (x as f64 + 0.5 - c).hypot(y as f64 + 0.5 - c) > expect + 2.0);
    for (x, y) in outside {
        assert_eq!(
            alpha(&img, x, y),
            0,
            "({x}, {y}) outside the sphere is not transparent"
        );
    }
}

/// A counter-based hash to 0..1 (deterministic stool texture).
fn hash01(n: u64) -> f64 {
    let mut z = n.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// Stool: soft tissue with air pockets, one 1.5 mm cell in three being gas.
fn stool_hu(p: DVec3) -> f64 {
    let cell = (p / 1.5).floor();
    let key = (cell.x as u64) | ((cell.y as u64) << 20) | ((cell.z as u64) << 40);
    if hash01(key) < 0.35 { -900.0 } else { SOFT }
}

/// Three 5 mm-radius spheres in air in a row along x — a polyp (homogeneous 40 HU), stool
/// (mottled), tagged stool (400 HU) — in front of a soft-tissue wall.
fn polyp_stool_tagged() -> (Volume<i16>, [DVec3; 3]) {
    let r = 5.0;
    let c = [CENTER - DVec3::X * 12.0, CENTER, CENTER + DVec3::X * 12.0];
    let wall_z = CENTER.z + 9.0;
    let ct = volume(|p| {
        let wall = AIR + inside(wall_z - p.z) * (SOFT - AIR);
        let stool = AIR + inside((p - c[1]).length() - r) * (stool_hu(p) - AIR);
        sphere(p, c[0], r, SOFT, AIR)
            .max(stool)
            .max(sphere(p, c[2], r, 400.0, AIR))
            .max(wall)
    });
    (ct, c)
}

/// Over pixels: mean luminance, colour variance (the sum of the three channels' variances),
/// and mean whiteness (smallest channel / largest).
fn stats(img: &[u8], px: &[(u32, u32)]) -> (f64, f64, f64) {
    let n = px.len() as f64;
    let colours: Vec<[f64; 3]> = px.iter().map(|&(x, y)| rgb(img, x, y)).collect();
    let mean = [0, 1, 2].map(|c| colours.iter().map(|v| v[c]).sum::<f64>() / n);
    let var = (0..3)
        .map(|c| {
            colours
                .iter()
                .map(|v| (v[c] - mean[c]).powi(2))
                .sum::<f64>()
                / n
        })
        .sum();
    let lum = 0.2126 * mean[0] + 0.7152 * mean[1] + 0.0722 * mean[2];
    let white = colours
        .iter()
        .map(|c| c.iter().copied().fold(f64::MAX, f64::min) / c.iter().copied().fold(1.0, f64::max))
        .sum::<f64>()
        / n;
    (lum, var, white)
}

#[test]
fn a_polyp_is_homogeneous_stool_is_mottled_and_tagged_stool_is_white() {
    let (ct, c) = polyp_stool_tagged();
    let d = 30.0;
    let cam = camera_at(CENTER, d);
    let img = render_closeup(
        &ct,
        &cam,
        &CloseupBox::around(CENTER, 20.0),
        SIZE,
        SIZE,
        &TransferFunction::tissue(),
    );
    let view = View::new(&cam, SIZE, SIZE);
    let r_px = projected_radius(5.0, d);
    let regions: Vec<Vec<(u32, u32)>> = c
        .iter()
        .map(|&p| {
            let (x, y) = view.project(view.to_eye(p));
            // The middle half of the disc: the headlight shades a sphere's rim.
            disc(x, y, 0.5 * r_px)
        })
        .collect();
    for (px, what) in regions.iter().zip(["polyp", "stool", "tagged"]) {
        assert!(
            px.iter().all(|&(x, y)| alpha(&img, x, y) > 200),
            "{what} is not opaque"
        );
    }
    let [polyp, stool, tagged] = [0, 1, 2].map(|i| stats(&img, &regions[i]));
    eprintln!(
        "luminance, colour variance, whiteness: polyp {polyp:.2?}, stool {stool:.2?}, tagged {tagged:.2?}"
    );
    assert!(
        stool.1 > 4.0 * polyp.1,
        "stool variance {:.1} is not ≫ the polyp's {:.1}",
        stool.1,
        polyp.1
    );
    assert!(
        tagged.2 > polyp.2 + 0.3 && tagged.0 > polyp.0 + 30.0,
        "tagged stool is not whiter than the polyp"
    );
}

#[test]
fn rays_that_miss_the_box_are_transparent() {
    // Tissue everywhere: whatever ray enters the box sees something.
    let ct = volume(|_| SOFT);
    let (d, h) = (30.0, 10.0);
    let cam = camera_at(CENTER, d);
    let img = render_closeup(
        &ct,
        &cam,
        &CloseupBox::in_front_of(&cam, d, h),
        SIZE,
        SIZE,
        &TransferFunction::tissue(),
    );
    // Seen straight on, the box's outline is its front face: |x|, |y| ≤ h at depth d − h.
    let edge = h / (d - h);
    let view = View::new(&cam, SIZE, SIZE);
    let (mut hit, mut missed) = (0, 0);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let r = view.pixel_direction(x, y);
            let s = (r.dot(view.right) / r.dot(view.forward))
                .abs()
                .max((r.dot(view.up) / r.dot(view.forward)).abs());
            if s > edge * 1.001 {
                assert_eq!(
                    alpha(&img, x, y),
                    0,
                    "({x}, {y}) misses the box but is not transparent"
                );
                missed += 1;
            } else if s < edge * 0.95 {
                assert!(
                    alpha(&img, x, y) > 0,
                    "({x}, {y}) crosses the box but is transparent"
                );
                hit += 1;
            }
        }
    }
    assert!(hit > 10_000 && missed > 10_000, "{hit} {missed}");
}

/// Alpha-weighted centroid (pixel coordinates) of the image within `r` pixels of (x, y).
fn centroid(img: &[u8], (x, y): (f64, f64), r: f64) -> (f64, f64) {
    let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
    for (px, py) in disc(x, y, r) {
        let w = alpha(img, px, py) as f64;
        sx += w * (px as f64 + 0.5);
        sy += w * (py as f64 + 0.5);
        sw += w;
    }
    assert!(sw > 0.0, "nothing rendered near ({x:.1}, {y:.1})");
    (sx / sw, sy / sw)
}

#[test]
fn the_closeup_lines_up_with_the_endoscopic_camera() {
    // Small bright beads at the box centre and near its far corner, seen obliquely.
    let (half, bead) = (12.0, 1.5);
    let eye = CENTER + DVec3::new(-14.0, 9.0, -22.0);
    let cam =
        Camera::new(Pose::looking(eye, CENTER - eye, DVec3::new(0.3, -1.0, 0.2))).with_fov(70.0);
    let region = CloseupBox::in_front_of(&cam, (CENTER - eye).length(), half);
    let far_sign = (region.center - eye).signum();
    let corner = region.center + far_sign * (half - 2.5);
    let ct = volume(|p| {
        sphere(p, region.center, bead, 400.0, AIR).max(sphere(p, corner, bead, 400.0, AIR))
    });
    let img = render_closeup(&ct, &cam, &region, SIZE, SIZE, &TransferFunction::tissue());
    let view = View::new(&cam, SIZE, SIZE);
    // The box centre is on the view axis: the image centre.
    let (cx, cy) = centroid(&img, (128.0, 128.0), 12.0);
    assert!(
        (cx - 128.0).abs() < 0.3 && (cy - 128.0).abs() < 0.3,
        "centre bead at ({cx:.2}, {cy:.2})"
    );
    // The corner bead where the camera's projection puts it (and where the rasterizer would).
    let want = view.project(view.to_eye(corner));
    let clip = cam.projection_matrix(1.0) * cam.view_matrix() * corner.extend(1.0);
    let ndc = clip.truncate() / clip.w;
    let by_matrix = ((ndc.x + 1.0) * 128.0, (1.0 - ndc.y) * 128.0);
    assert!((want.0 - by_matrix.0).abs() < 1e-6 && (want.1 - by_matrix.1).abs() < 1e-6);
    let got = centroid(&img, want, 10.0);
    eprintln!(
        "corner bead: rendered ({:.2}, {:.2}), projected ({:.2}, {:.2})",
        got.0, got.1, want.0, want.1
    );
    assert!((got.0 - want.0).abs() < 0.3 && (got.1 - want.1).abs() < 0.3);
}

#[test]
fn the_result_does_not_depend_on_the_thread_count() {
    let (ct, _) = polyp_stool_tagged();
    let cam = camera_at(CENTER, 30.0);
    let region = CloseupBox::around(CENTER, 20.0);
    let tf = TransferFunction::tissue();
    let many = render_closeup(&ct, &cam, &region, 64, 64, &tf);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let one = pool.install(|| render_closeup(&ct, &cam, &region, 64, 64, &tf));
    assert_eq!(many, one);
}

#[test]
fn the_pipe_polyp_shows_as_an_opaque_soft_tissue_blob() {
    let p = phantom::pipe(1).unwrap();
    let polyp = p
        .truth
        .polyps
        .iter()
        .find(|q| q.diameter_mm == 7.0)
        .unwrap();
    let c = DVec3::from_array(polyp.center_mm);
    // On the pipe's axis 25 mm (of arc) before the polyp, looking at it.
    let t = &p.truth;
    let i = t
        .centerline_arc_mm
        .partition_point(|&a| a < polyp.arc_mm - 25.0);
    let eye = DVec3::from_array(t.centerline_mm[i]);
    let cam = Camera::new(Pose::looking(
        eye,
        c - eye,
        (c - eye).any_orthonormal_vector(),
    ));
    let region = CloseupBox::in_front_of(&cam, (c - eye).length(), 8.0);
    let img = render_closeup(
        &p.ct,
        &cam,
        &region,
        SIZE,
        SIZE,
        &TransferFunction::tissue(),
    );
    let view = View::new(&cam, SIZE, SIZE);
    let (x, y) = view.project(view.to_eye(c));
    assert!((x - 128.0).abs() < 1e-6 && (y - 128.0).abs() < 1e-6);
    // The middle third of the polyp's head (3.5 mm radius, ≈ 31 mm away: ≈ 15 px).
    let r_px = projected_radius(polyp.diameter_mm / 2.0, (c - eye).length());
    for (px, py) in disc(x, y, r_px / 3.0) {
        let [red, g, b] = rgb(&img, px, py);
        assert!(
            alpha(&img, px, py) > 230,
            "({px}, {py}) alpha {}",
            alpha(&img, px, py)
        );
        assert!(
            red > 1.4 * g && red > 1.4 * b,
            "({px}, {py}) is not soft tissue: {:?}",
            [red, g, b]
        );
    }
}
