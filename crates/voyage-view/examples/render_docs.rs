//! Writes the endoscopic frames kept in docs/render/ (CPU reference renderer, 512²):
//! the pipe phantom's three polyps, and the colon phantom's folds and polyps.
//!
//! cargo run --release -p voyage-view --example render_docs -- docs/render

use std::path::Path;

use glam::DVec3;
use voyage_core::{PrepOptions, Study, prepare};
use voyage_nav::{Camera, Pose};
use voyage_phantom::{self as phantom, ColonOptions, Phantom};
use voyage_view::{CellMesh, Lighting, render_rgba};

fn main() {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "docs/render".into());
    let out = Path::new(&out);
    std::fs::create_dir_all(out).unwrap();
    let Phantom { ct, truth, .. } = phantom::pipe(1).unwrap();
    let pipe = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    let mesh = CellMesh::new(&pipe.surface, &pipe.cells);
    // All three polyps at once: from the centerline 30 mm before the first, looking at the
    // middle of the three, wide angle.
    let centres: Vec<DVec3> = truth
        .polyps
        .iter()
        .map(|p| DVec3::from_array(p.center_mm))
        .collect();
    let mid = centres.iter().sum::<DVec3>() / centres.len() as f64;
    let eye = centerline_at(&pipe, truth.polyps[0].arc_mm - 30.0);
    save(
        out,
        "pipe-three-polyps.png",
        &mesh,
        Camera::new(Pose::looking(eye, mid - eye, up_hint(mid - eye))).with_fov(110.0),
    );
    for p in &truth.polyps {
        let c = DVec3::from_array(p.center_mm);
        let eye = centerline_at(&pipe, p.arc_mm - 25.0);
        save(
            out,
            &format!("pipe-polyp-{}mm.png", p.diameter_mm),
            &mesh,
            Camera::new(Pose::looking(eye, c - eye, up_hint(c - eye))),
        );
    }
    let Phantom { ct, truth, .. } = phantom::colon(&ColonOptions::default()).unwrap();
    let colon = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    let mesh = CellMesh::new(&colon.surface, &colon.cells);
    // Down the lumen at a few places: folds.
    for arc in [300.0, 700.0, 1100.0] {
        let eye = centerline_at(&colon, arc);
        let ahead = centerline_at(&colon, arc + 15.0);
        save(
            out,
            &format!("colon-lumen-{arc:.0}mm.png"),
            &mesh,
            Camera::new(Pose::looking(eye, ahead - eye, up_hint(ahead - eye))),
        );
    }
    // Polyps: from 30 mm before each, looking at it (a polyp behind a fold may be hidden:
    // that is the point of flying both ways).
    for (i, p) in truth.polyps.iter().enumerate() {
        let c = DVec3::from_array(p.center_mm);
        let eye = centerline_at(&colon, p.arc_mm - 30.0);
        let name = format!(
            "colon-polyp-{i}-{}mm{}.png",
            p.diameter_mm,
            if p.behind_fold { "-behind-fold" } else { "" }
        );
        save(
            out,
            &name,
            &mesh,
            Camera::new(Pose::looking(eye, c - eye, up_hint(c - eye))),
        );
    }
}

/// The study's centerline point nearest to an arc length of the truth's centerline (both
/// run from the rectum; close enough for placing a camera).
fn centerline_at(study: &Study, arc: f64) -> DVec3 {
    let cl = &study.centerline;
    let i = cl
        .arc_mm
        .partition_point(|&a| a < arc)
        .min(cl.points_mm.len() - 1);
    DVec3::from_array(cl.points_mm[i])
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

fn save(dir: &Path, name: &str, mesh: &CellMesh, camera: Camera) {
    let all: Vec<u32> = (0..mesh.cells() as u32).collect();
    let rgba = render_rgba(mesh, &camera, &all, 512, 512, &Lighting::default());
    image::save_buffer(
        dir.join(name),
        &rgba,
        512,
        512,
        image::ExtendedColorType::Rgba8,
    )
    .unwrap();
    println!("wrote {}", dir.join(name).display());
}
