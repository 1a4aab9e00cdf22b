//! The translucency view on the full-size colon phantom with tagged fluid and tagged stool:
//! seen from 20 mm, each polyp (in air or under former fluid, cleansed) shows as soft tissue
//! and each lump of stool (in air, uncleansed) as tagged, each in ≥ 90 % of its pixels.

use glam::DVec3;
use voyage_core::{PrepOptions, Study, Volume, prepare};
use voyage_nav::{Camera, Pose};
use voyage_phantom::{self as phantom, ColonOptions, Phantom, label};
use voyage_view::{CloseupBox, Material, TranslucencyOptions, render_translucency};

const DISTANCE_MM: f64 = 20.0;
const SIZE: u32 = 384;

/// The lumen label at a point (nearest voxel).
fn label_at(p: &Phantom, mm: DVec3) -> u8 {
    let g = p.labels.geometry();
    let ijk = g.local_to_index(mm).round();
    if !g.contains_index(ijk) {
        return 0;
    }
    p.labels.get(ijk.x as usize, ijk.y as usize, ijk.z as usize)
}

/// The camera `DISTANCE_MM` from `center` along `into` (from the wall into the lumen),
/// looking back at it; None where the way from 1 mm off the sphere (radius `r`) to that spot
/// leaves the lumen's `allowed` labels.
fn camera_facing(
    p: &Phantom,
    center: DVec3,
    r: f64,
    into: DVec3,
    allowed: &[u8],
) -> Option<Camera> {
    let eye = center + DISTANCE_MM * into;
    let clear = (0..=40).all(|s| {
        allowed.contains(&label_at(
            p,
            center + into * (r + 1.0 + (DISTANCE_MM - r - 1.0) * s as f64 / 40.0),
        ))
    });
    let up = into.any_orthonormal_vector();
    clear.then(|| Camera::new(Pose::looking(eye, -into, up)))
}

/// Share of the pixels showing the sphere (centre, radius; it sits on the wall with its centre
/// half a radius into the lumen along `into`) whose class is `want`, and their count. A
/// pixel shows the sphere where its surface point lies within 0.3 mm of it and above the
/// wall's plane.
fn share(
    ct: &Volume<i16>,
    study: &Study,
    cam: &Camera,
    center: DVec3,
    radius: f64,
    into: DVec3,
    want: Material,
) -> (f64, usize) {
    let t = render_translucency(
        ct,
        &study.segmentation.lumen,
        cam,
        &CloseupBox::around(center, 15.0),
        SIZE,
        SIZE,
        &TranslucencyOptions::default(),
    );
    let on: Vec<Material> = t
        .surfels
        .iter()
        .flatten()
        .filter(|s| {
            s.point.distance(center) <= radius + 0.3
                && (s.point - center).dot(into) >= 0.3 - 0.5 * radius
        })
        .map(|s| s.material)
        .collect();
    // TRANSLUCENCY_PNG=folder writes each view, to look at.
    if let Ok(dir) = std::env::var("TRANSLUCENCY_PNG") {
        let name = format!("{dir}/{:.0}_{:.0}_{:.0}.png", center.x, center.y, center.z);
        image::save_buffer(&name, &t.rgba, SIZE, SIZE, image::ColorType::Rgba8).unwrap();
    }
    eprintln!(
        "  pixels by class {:?}: {:?}",
        Material::ALL,
        Material::ALL.map(|m| on.iter().filter(|&&x| x == m).count())
    );
    (
        on.iter().filter(|&&m| m == want).count() as f64 / on.len().max(1) as f64,
        on.len(),
    )
}

#[test]
fn polyps_read_as_soft_tissue_and_stool_as_tagged() {
    let p = phantom::colon(&ColonOptions {
        tagged_fluid: true,
        tagged_stool: true,
        ..Default::default()
    })
    .unwrap();
    let cleansed = prepare(p.ct.clone(), &PrepOptions::default(), |_| {}).unwrap();
    let raw = prepare(
        p.ct.clone(),
        &PrepOptions {
            cleanse: None,
            ..Default::default()
        },
        |_| {},
    )
    .unwrap();
    let cleansed_ct = cleansed.cleansed_ct();
    let lumen = [label::LUMEN_AIR, label::LUMEN_FLUID];

    let mut polyps = 0;
    for polyp in p.truth.polyps.iter().filter(|q| q.diameter_mm >= 3.0) {
        let (c, into) = (
            DVec3::from_array(polyp.center_mm),
            DVec3::from_array(polyp.direction),
        );
        let Some(cam) = camera_facing(&p, c, polyp.diameter_mm / 2.0, into, &lumen) else {
            eprintln!(
                "polyp {} mm in the {}: no spot 20 mm in front of it in the lumen",
                polyp.diameter_mm, polyp.segment
            );
            continue;
        };
        let (f, n) = share(
            &cleansed_ct,
            &cleansed,
            &cam,
            c,
            polyp.diameter_mm / 2.0,
            into,
            Material::SoftTissue,
        );
        eprintln!(
            "polyp {:>4.1} mm in the {:<10}: {:5.1} % of {n} pixels soft tissue",
            polyp.diameter_mm,
            polyp.segment,
            100.0 * f
        );
        assert!(
            n >= 50,
            "polyp {} mm in the {}: only {n} pixels",
            polyp.diameter_mm,
            polyp.segment
        );
        assert!(
            f >= 0.9,
            "polyp {} mm in the {}: {:.1} % soft tissue",
            polyp.diameter_mm,
            polyp.segment,
            100.0 * f
        );
        polyps += 1;
    }

    let mut lumps = 0;
    for lump in &p.truth.stool {
        let c = DVec3::from_array(lump.center_mm);
        let axis = p
            .truth
            .centerline_mm
            .iter()
            .map(|&a| DVec3::from_array(a))
            .min_by(|a, b| a.distance(c).total_cmp(&b.distance(c)))
            .unwrap();
        let r = lump.diameter_mm / 2.0;
        let wet = (0..64).any(|k| {
            let (z, phi) = (1.0 - (2 * k + 1) as f64 / 64.0, k as f64 * 2.4);
            let rho = (1.0 - z * z).sqrt();
            label_at(
                &p,
                c + (r + 1.0) * DVec3::new(rho * phi.cos(), rho * phi.sin(), z),
            ) == label::LUMEN_FLUID
        });
        let into = (axis - c).normalize();
        let cam = if wet {
            None
        } else {
            camera_facing(&p, c, r, into, &[label::LUMEN_AIR])
        };
        let Some(cam) = cam else {
            eprintln!(
                "stool {:.1} mm in the {}: under fluid or no spot 20 mm in front of it",
                lump.diameter_mm, lump.segment
            );
            continue;
        };
        let (f, n) = share(&raw.ct, &raw, &cam, c, r, into, Material::Tagged);
        eprintln!(
            "stool {:>4.1} mm in the {:<10} (mottled {}): {:5.1} % of {n} pixels tagged",
            lump.diameter_mm,
            lump.segment,
            lump.mottled,
            100.0 * f
        );
        assert!(
            n >= 50 && f >= 0.9,
            "stool {} mm in the {}: {:.1} % of {n} pixels tagged",
            lump.diameter_mm,
            lump.segment,
            100.0 * f
        );
        lumps += 1;
    }
    assert!(
        polyps >= 6 && lumps >= 6,
        "{polyps} polyps and {lumps} lumps checked"
    );
}
