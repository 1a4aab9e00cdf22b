//! Writes the pictures kept in docs/closeup/ (what each shows: docs/closeup/README.md) and
//! times the close-up on the colon phantom (0.75 mm in-plane), on one thread and on all.
//!
//! cargo run --release -p voyage-view --example closeup_look -- docs/closeup [spheres,pipe,colon,tagged,time]

use std::{path::Path, time::Instant};

use glam::DVec3;
use voyage_core::{Geometry, PrepOptions, Study, Volume, prepare};
use voyage_nav::{Camera, Pose};
use voyage_phantom::{self as phantom, ColonOptions, Phantom, Truth};
use voyage_view::{
    CellMesh, CloseupBox, Lighting, TransferFunction, View, render_closeup, render_rgba,
};

const SIZE: u32 = 384;
/// Field of view of the phantom views: narrower than the endoscope's 90°, a close look.
const FOV: f64 = 60.0;

fn main() {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "docs/closeup".into());
    let out = Path::new(&out);
    std::fs::create_dir_all(out).unwrap();
    // An optional second argument picks some of: spheres, pipe, colon, tagged, time.
    let only = std::env::args().nth(2).unwrap_or_default();
    let wanted = |what: &str| only.is_empty() || only.split(',').any(|w| w == what);
    let tf = TransferFunction::tissue();
    if wanted("spheres") {
        spheres(out, &tf);
    }
    if wanted("pipe") {
        pipe(out, &tf);
    }
    if wanted("colon") {
        colon(out, &tf, false);
    }
    if wanted("tagged") {
        colon(out, &tf, true);
    }
    if wanted("time") {
        time(&tf);
    }
    if wanted("wall") {
        wall(&tf);
    }
}

/// A synthetic stand-in for the colon scene, small enough for an instruction counter
/// (`valgrind --tool=callgrind`): air, a 2.5 mm soft-tissue wall with a 7 mm polyp, fat
/// behind, 20 HU of noise, 0.75 × 0.75 × 1 mm; seen obliquely from 25 mm, a 40 mm box.
fn wall(tf: &TransferFunction) {
    let g = Geometry::new([80, 80, 64], [0.75, 0.75, 1.0], [0.0; 3]).unwrap();
    let c = DVec3::new(30.0, 30.0, 30.0);
    let inside = |sdf: f64| (0.5 - sdf / 0.75).clamp(0.0, 1.0);
    let hu = |p: DVec3, n: usize| {
        let noise = 20.0 * (hash01(DVec3::splat(n as f64 * 1.5)) - 0.5) * 3.46;
        let wall = inside(c.z + 3.5 - p.z) * inside(p.z - c.z - 6.0);
        let fat = inside(c.z + 6.0 - p.z);
        let polyp = inside((p - c).length() - 3.5);
        let t = (1.0 - fat) * (-1000.0 + wall.max(polyp) * 1040.0) + fat * -100.0;
        t + noise
    };
    let data: Vec<i16> = (0..g.len())
        .map(|n| {
            let [i, j, k] = g.ijk(n);
            hu(
                g.index_to_local(DVec3::new(i as f64, j as f64, k as f64)),
                n,
            ) as i16
        })
        .collect();
    let ct = Volume::from_vec(g, data).unwrap();
    let eye = c + DVec3::new(10.0, 5.0, -22.0);
    let cam = Camera::new(Pose::looking(eye, c - eye, -DVec3::Y));
    let region = CloseupBox::in_front_of(&cam, (c - eye).length(), 20.0);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let n = std::env::var("REPEATS").map_or(15, |v| v.parse().unwrap());
    let mut ms: Vec<f64> = (0..n)
        .map(|_| {
            one.install(|| {
                let t = Instant::now();
                std::hint::black_box(render_closeup(&ct, &cam, &region, 256, 256, tf));
                t.elapsed().as_secs_f64() * 1e3
            })
        })
        .collect();
    println!(
        "synthetic wall, 256², 40 mm box, 1 thread, wall time: {}",
        summary(&mut ms)
    );
}

/// Polyp, stool and tagged stool side by side in front of a wall, with the CT slice through
/// their centres.
fn spheres(out: &Path, tf: &TransferFunction) {
    let (ct, centre) = three_spheres();
    // 75°: the three spheres, 34 mm from edge to edge, fill the view from 30 mm.
    let cam =
        Camera::new(Pose::looking(centre - DVec3::Z * 30.0, DVec3::Z, -DVec3::Y)).with_fov(75.0);
    let img = render_closeup(&ct, &cam, &CloseupBox::around(centre, 20.0), SIZE, SIZE, tf);
    let slice = ct_slice(&ct, (centre.z / ct.spacing()[2]).round() as usize, SIZE);
    save(out, "spheres.png", &[&over_black(&img), &slice]);
}

/// A 64³ volume of 0.75 mm voxels: three 5 mm spheres in air — homogeneous 40 HU (polyp),
/// 40 HU with air pockets (stool), 400 HU (tagged stool) — 9 mm in front of a soft-tissue wall.
fn three_spheres() -> (Volume<i16>, DVec3) {
    let g = Geometry::new([64; 3], [0.75; 3], [0.0; 3]).unwrap();
    let c = DVec3::splat(24.0);
    let centres = [c - DVec3::X * 12.0, c, c + DVec3::X * 12.0];
    let inside = |sdf: f64| (0.5 - sdf / 0.75).clamp(0.0, 1.0);
    let hu = |p: DVec3| {
        let stool = if hash01(p) < 0.35 { -900.0 } else { 40.0 };
        let values = [40.0, stool, 400.0];
        let mut v = -1000.0 + inside(c.z + 9.0 - p.z) * 1040.0;
        for (q, value) in centres.iter().zip(values) {
            v = v.max(-1000.0 + inside((p - *q).length() - 5.0) * (value + 1000.0));
        }
        v
    };
    let data: Vec<i16> = (0..g.len())
        .map(|n| {
            let [i, j, k] = g.ijk(n);
            hu(g.index_to_local(DVec3::new(i as f64, j as f64, k as f64))) as i16
        })
        .collect();
    (Volume::from_vec(g, data).unwrap(), c)
}

/// A hash of the 1.5 mm cell holding `p`, to 0..1 (the stool's air pockets).
fn hash01(p: DVec3) -> f64 {
    let cell = (p / 1.5).floor();
    let mut z = (cell.x as u64) | ((cell.y as u64) << 20) | ((cell.z as u64) << 40);
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// The pipe phantom's 7 mm polyp from 25 mm: surface, close-up, close-up over the surface.
fn pipe(out: &Path, tf: &TransferFunction) {
    let Phantom { ct, truth, .. } = phantom::pipe(1).unwrap();
    let study = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    let p = &truth.polyps[0];
    let c = DVec3::from_array(p.center_mm);
    let eye = truth_centerline_at(&truth, p.arc_mm - 25.0);
    let cam = Camera::new(Pose::looking(eye, c - eye, up_hint(c - eye))).with_fov(FOV);
    triptych(
        out,
        &format!("pipe-polyp-{}mm.png", p.diameter_mm),
        &study,
        &cam,
        &CloseupBox::in_front_of(&cam, (c - eye).length(), 10.0),
        tf,
    );
}

/// The colon phantom: a polyp (soft tissue on a soft-tissue wall in fat), or with tagged
/// fluid, a pool's air–fluid level; and the one-thread timing of a 40 mm box at 256².
fn colon(out: &Path, tf: &TransferFunction, tagged: bool) {
    let Phantom { ct, truth, .. } = phantom::colon(&ColonOptions {
        tagged_fluid: tagged,
        ..Default::default()
    })
    .unwrap();
    let study = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    if !tagged {
        let p = truth
            .polyps
            .iter()
            .find(|p| !p.behind_fold && p.diameter_mm >= 6.0)
            .unwrap();
        let c = DVec3::from_array(p.center_mm);
        let eye = truth_centerline_at(&truth, p.arc_mm - 25.0);
        let cam = Camera::new(Pose::looking(eye, c - eye, up_hint(c - eye))).with_fov(FOV);
        let region = CloseupBox::in_front_of(&cam, (c - eye).length(), 12.0);
        triptych(
            out,
            &format!("colon-polyp-{}mm.png", p.diameter_mm),
            &study,
            &cam,
            &region,
            tf,
        );
        return;
    }
    let pool = &truth.fluid_pools[0];
    let arc = 0.5 * (pool.start_arc_mm + pool.end_arc_mm);
    let eye = truth_centerline_at(&truth, arc - 20.0);
    let ahead = truth_centerline_at(&truth, arc);
    // Looking down the lumen and a little towards the pool's side (posterior, +y).
    let dir = (ahead - eye).normalize() + DVec3::Y * 0.4;
    let cam = Camera::new(Pose::looking(eye, dir, up_hint(dir))).with_fov(FOV);
    triptych(
        out,
        "colon-tagged-fluid.png",
        &study,
        &cam,
        &CloseupBox::in_front_of(&cam, 22.0, 15.0),
        tf,
    );
}

/// Times a 40 mm box at 256² around the colon phantom's first polyp (0.75 mm in-plane),
/// seen from 25 mm with the endoscope's 90°.
fn time(tf: &TransferFunction) {
    let Phantom { ct, truth, .. } = phantom::colon(&ColonOptions::default()).unwrap();
    let p = &truth.polyps[0];
    let c = DVec3::from_array(p.center_mm);
    let eye = truth_centerline_at(&truth, p.arc_mm - 25.0);
    let cam = Camera::new(Pose::looking(eye, c - eye, up_hint(c - eye)));
    let region = CloseupBox::in_front_of(&cam, (c - eye).length(), 20.0);
    let (ct, cam, region) = (&ct, &cam, &region);
    // On one thread: wall time, and the thread's own CPU time (the build machines are shared,
    // so wall time includes waiting for a core).
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let (mut wall, mut cpu): (Vec<f64>, Vec<f64>) = (0..std::env::var("REPEATS")
        .map_or(15, |v| v.parse().unwrap()))
        .map(|_| {
            one.install(|| {
                let (t, c) = (Instant::now(), thread_cpu_ns());
                std::hint::black_box(render_closeup(ct, cam, region, 256, 256, tf));
                (
                    t.elapsed().as_secs_f64() * 1e3,
                    c.zip(thread_cpu_ns())
                        .map_or(f64::NAN, |(a, b)| (b - a) as f64 * 1e-6),
                )
            })
        })
        .unzip();
    let mut all: Vec<f64> = (0..15)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(render_closeup(ct, cam, region, 256, 256, tf));
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    println!("close-up 256², 40 mm box, 0.75 mm CT (median of 15, min..max):");
    println!("  1 thread, CPU time:  {}", summary(&mut cpu));
    println!("  1 thread, wall time: {}", summary(&mut wall));
    println!(
        "  {} threads, wall:    {}",
        rayon::current_num_threads(),
        summary(&mut all)
    );
}

fn summary(ms: &mut [f64]) -> String {
    ms.sort_by(f64::total_cmp);
    format!(
        "{:.1} ms ({:.1}..{:.1})",
        ms[ms.len() / 2],
        ms[0],
        ms[ms.len() - 1]
    )
}

/// CPU time of the calling thread (Linux), ns.
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Surface view with the box drawn in, the close-up over black, and over the surface.
fn triptych(
    out: &Path,
    name: &str,
    study: &Study,
    cam: &Camera,
    region: &CloseupBox,
    tf: &TransferFunction,
) {
    let mesh = CellMesh::new(&study.surface, &study.cells);
    let all: Vec<u32> = (0..mesh.cells() as u32).collect();
    let surface = render_rgba(&mesh, cam, &all, SIZE, SIZE, &Lighting::default());
    let closeup = render_closeup(&study.ct, cam, region, SIZE, SIZE, tf);
    let mut outlined = surface.clone();
    draw_box(&mut outlined, cam, region);
    save(
        out,
        name,
        &[&outlined, &over_black(&closeup), &over(&closeup, &surface)],
    );
}

/// The box's twelve edges, in yellow, where in front of the camera.
fn draw_box(img: &mut [u8], cam: &Camera, region: &CloseupBox) {
    let view = View::new(cam, SIZE, SIZE);
    let (lo, hi) = (region.min_mm(), region.max_mm());
    let corner = |n: usize| {
        DVec3::new(
            [lo.x, hi.x][n & 1],
            [lo.y, hi.y][(n >> 1) & 1],
            [lo.z, hi.z][n >> 2],
        )
    };
    for a in 0..8 {
        for bit in [1, 2, 4] {
            if a & bit != 0 {
                continue;
            }
            let (p, q) = (corner(a), corner(a | bit));
            for s in 0..=400 {
                let e = view.to_eye(p.lerp(q, s as f64 / 400.0));
                if e.z <= view.near {
                    continue;
                }
                let (x, y) = view.project(e);
                if x >= 0.0 && y >= 0.0 && x < SIZE as f64 && y < SIZE as f64 {
                    let i = (y as usize * SIZE as usize + x as usize) * 4;
                    img[i..i + 4].copy_from_slice(&[255, 220, 0, 255]);
                }
            }
        }
    }
}

/// Straight-alpha RGBA over an opaque image (in display values: a picture, not a measurement).
fn over(top: &[u8], bottom: &[u8]) -> Vec<u8> {
    let mut out = bottom.to_vec();
    for (o, t) in out.chunks_exact_mut(4).zip(top.chunks_exact(4)) {
        let a = t[3] as f32 / 255.0;
        for c in 0..3 {
            o[c] = (a * t[c] as f32 + (1.0 - a) * o[c] as f32).round() as u8;
        }
        o[3] = 255;
    }
    out
}

fn over_black(img: &[u8]) -> Vec<u8> {
    over(img, &vec![0; img.len()])
}

/// Axial slice k, soft-tissue window (W 400, L 40), scaled to a size × size square.
fn ct_slice(ct: &Volume<i16>, k: usize, size: u32) -> Vec<u8> {
    let [nx, ny, _] = ct.dims();
    let mut out = vec![0u8; size as usize * size as usize * 4];
    for (n, px) in out.chunks_exact_mut(4).enumerate() {
        let (x, y) = (n % size as usize, n / size as usize);
        let hu = ct.get(x * nx / size as usize, y * ny / size as usize, k) as f64;
        let v = ((hu - (40.0 - 200.0)) / 400.0 * 255.0).clamp(0.0, 255.0) as u8;
        px.copy_from_slice(&[v, v, v, 255]);
    }
    out
}

/// Images of SIZE² side by side, 4 px of grey between.
fn save(dir: &Path, name: &str, images: &[&Vec<u8>]) {
    let gap = 4usize;
    let s = SIZE as usize;
    let w = images.len() * s + (images.len() - 1) * gap;
    let mut out = vec![64u8; w * s * 4];
    for (n, img) in images.iter().enumerate() {
        for y in 0..s {
            let dst = (y * w + n * (s + gap)) * 4;
            out[dst..dst + s * 4].copy_from_slice(&img[y * s * 4..(y + 1) * s * 4]);
        }
    }
    image::save_buffer(
        dir.join(name),
        &out,
        w as u32,
        SIZE,
        image::ExtendedColorType::Rgba8,
    )
    .unwrap();
    println!("wrote {}", dir.join(name).display());
}

/// The phantom's true centerline at an arc length (where its polyps and pools are given).
fn truth_centerline_at(truth: &Truth, arc: f64) -> DVec3 {
    let i = truth
        .centerline_arc_mm
        .partition_point(|&a| a < arc)
        .min(truth.centerline_mm.len() - 1);
    DVec3::from_array(truth.centerline_mm[i])
}

fn up_hint(forward: DVec3) -> DVec3 {
    // Anterior (−y in the phantoms' volume frame) up, as a supine patient seen from the feet.
    let up = DVec3::new(0.0, -1.0, 0.0);
    if up.cross(forward).length() < 1e-3 {
        DVec3::Z
    } else {
        up
    }
}
