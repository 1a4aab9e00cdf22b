//! The centerline on a real, complete colon (colon-a: 512×512×321 at 0.82×0.82×1.25 mm, loops
//! touching over wide contacts). Needs `../shared/data`; skips with a message without it. Run
//! in release mode (`cargo test --release -p voyage-core --test colon_a`).

use voyage_core::prep::{prepare, PrepOptions};

mod common;

#[test]
fn colon_a_centerline_runs_rectum_to_cecum() {
    let Some(ct) = common::colon_a_volume() else { return };
    let dims = ct.dims();
    let s = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    let cl = &s.centerline;
    eprintln!("length {:.0} mm, source {:?}, target {:?}, timings {:?}", cl.length_mm, s.source, s.target, s.timings);
    // Source low (the rectum, where the rectal tube is).
    assert!(s.source[2] < dims[2] / 8, "source {:?} is not low", s.source);
    // Target (cecum) in the lower half, on the patient's right (identity LPS: small i).
    assert!(s.target[2] < dims[2] / 2, "target {:?} is not low", s.target);
    assert!(s.target[0] < dims[0] / 2, "target {:?} is not on the patient's right", s.target);
    // The whole colon, not a short cut: at least 1.1 m. The lumen holds about 3 m of tube
    // that no path passes twice (see the report on the topology branch), hence the upper bound.
    assert!(cl.length_mm > 1100.0 && cl.length_mm < 3200.0, "length {} mm", cl.length_mm);
    let lumen = &s.segmentation.lumen;
    for p in &cl.points_mm {
        let q = lumen.geometry().local_to_index(glam::DVec3::from_array(*p)).round();
        assert_eq!(lumen.get(q.x as usize, q.y as usize, q.z as usize), 1, "point {p:?} outside the lumen");
    }
}

/// colon-a as a CT: air in soft tissue with a partial-volume edge, so the whole pipeline
/// (thresholding, outside air, components) runs on it; the result must agree with the mask's.
#[test]
fn colon_a_as_a_pseudo_ct() {
    let Some(mask) = common::colon_a_volume() else { return };
    let ct = pseudo_ct(&mask);
    let s = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    assert!(!s.segmentation.from_mask);
    let (mut both, mut a, mut b) = (0usize, 0usize, 0usize);
    for (&m, &l) in mask.data().iter().zip(s.segmentation.lumen.data()) {
        both += (m != 0 && l != 0) as usize;
        a += (m != 0) as usize;
        b += (l != 0) as usize;
    }
    let dice = 2.0 * both as f64 / (a + b) as f64;
    assert!(dice > 0.97, "Dice {dice}");
    let cl = &s.centerline;
    assert!(cl.length_mm > 1100.0, "length {} mm", cl.length_mm);
    let lumen = &s.segmentation.lumen;
    for p in &cl.points_mm {
        let q = lumen.geometry().local_to_index(glam::DVec3::from_array(*p)).round();
        assert_eq!(lumen.get(q.x as usize, q.y as usize, q.z as usize), 1, "point {p:?} outside the lumen");
    }
}

/// −1000 HU in the lumen, +40 HU around, blurred by [¼ ½ ¼] along each axis.
fn pseudo_ct(mask: &voyage_core::Volume<i16>) -> voyage_core::Volume<i16> {
    let [nx, ny, nz] = mask.dims();
    let mut f: Vec<f32> = mask.data().iter().map(|&m| if m != 0 { 1.0 } else { 0.0 }).collect();
    for (stride, n) in [(1, nx), (nx, ny), (nx * ny, nz)] {
        let src = f.clone();
        for (idx, out) in f.iter_mut().enumerate() {
            let c = (idx / stride) % n;
            let at = |d: isize| src[(idx as isize + d * stride as isize) as usize];
            let lo = if c > 0 { at(-1) } else { at(0) };
            let hi = if c + 1 < n { at(1) } else { at(0) };
            *out = 0.25 * lo + 0.5 * at(0) + 0.25 * hi;
        }
    }
    let data = f.iter().map(|&g| (40.0 - 1040.0 * g).round() as i16).collect();
    voyage_core::Volume::from_vec(mask.geometry().clone(), data).unwrap()
}
