//! The centerline on a real, complete colon (colon-a: 512×512×321 at 0.82×0.82×1.25 mm, loops
//! touching over wide contacts). Needs `../shared/data`; skips with a message without it. Run
//! in release mode (`cargo test --release -p voyage-core --test colon_a`).

use voyage_core::{PrepOptions, prepare};

mod common;

/// The colon-a mask of the shared data as loaded (0/1 labels as i16), or None (skipped).
fn colon_a_volume() -> Option<voyage_core::Volume<i16>> {
    let path = voyage_phantom::fixtures::colon_a_path()?;
    Some(voyage_io::load(&path, &Default::default()).unwrap().volume)
}

#[test]
fn colon_a_centerline_runs_rectum_to_cecum() {
    let Some(ct) = colon_a_volume() else {
        return;
    };
    let dims = ct.dims();
    let s = prepare(ct, &PrepOptions::default(), |_| {}).unwrap();
    let cl = &s.centerline;
    eprintln!(
        "length {:.0} mm, source {:?}, target {:?}, timings {:?}",
        cl.length_mm, s.source, s.target, s.timings
    );
    // Source low (the rectum, where the rectal tube is).
    assert!(
        s.source[2] < dims[2] / 8,
        "source {:?} is not low",
        s.source
    );
    // Target (cecum) in the lower half, on the patient's right (identity LPS: small i).
    assert!(
        s.target[2] < dims[2] / 2,
        "target {:?} is not low",
        s.target
    );
    assert!(
        s.target[0] < dims[0] / 2,
        "target {:?} is not on the patient's right",
        s.target
    );
    // Its one segment is named by where the centerline ends, in the right colon (the chain's
    // coarse end, farthest through the gas of touching loops, was in the transverse colon).
    let colon: Vec<&str> = s
        .segmentation
        .segments
        .iter()
        .filter(|g| g.kept)
        .map(|g| g.label.as_str())
        .collect();
    assert!(
        colon.len() == 1
            && colon[0].starts_with("rectum")
            && (colon[0].ends_with("ascending") || colon[0].ends_with("cecum")),
        "colon segments {colon:?}"
    );
    // The whole colon, not a short cut: at least 1.1 m. The lumen holds about 3 m of tube
    // that no path passes twice (see the report on the topology branch), hence the upper bound.
    assert!(
        cl.length_mm > 1100.0 && cl.length_mm < 3200.0,
        "length {} mm",
        cl.length_mm
    );
    let lumen = &s.segmentation.lumen;
    for p in &cl.points_mm {
        let q = lumen
            .geometry()
            .local_to_index(glam::DVec3::from_array(*p))
            .round();
        assert_eq!(
            lumen.get(q.x as usize, q.y as usize, q.z as usize),
            1,
            "point {p:?} outside the lumen"
        );
    }
    // Findings and patches are placed along the colon by the centerline point that serves
    // their lumen: with Dt as the guide (the centerline is 1.4–1.7× as long), markers at
    // 1049, 1149 and 2947 mm read 652, 639 and 1999 mm.
    common::assert_markers_read_back(&s, "colon-a");
}

/// Given endpoints keep to the colon between them. Reversed ends give the same colon backwards;
/// a target halfway along gives the first half; two points in the middle give the stretch
/// between them. Neither the longest path between two given points (it wanders through the
/// contacts to gain length) nor the shortest (it cuts through them) does: with the reversed
/// ends that gave 442 mm of a 3014 mm colon, with the halfway target 2439 mm.
#[test]
fn colon_a_given_endpoints_keep_to_the_colon_between_them() {
    let Some(ct) = colon_a_volume() else {
        return;
    };
    let auto = prepare(ct.clone(), &PrepOptions::default(), |_| {}).unwrap();
    let (pts, arc) = (&auto.centerline.points_mm, &auto.centerline.arc_mm);
    let at = |mm: f64| arc.partition_point(|&a| a < mm).min(pts.len() - 1);
    let point = |i: usize| glam::DVec3::from_array(pts[i]);
    let total = auto.centerline.length_mm;
    let (first, last) = (0, pts.len() - 1);
    for (from, to) in [
        (last, first),
        (first, at(total / 2.0)),
        (at(total / 5.0), at(total / 2.0)),
        (at(total / 2.0), first),
    ] {
        let mut opts = PrepOptions::default();
        opts.centerline.source_mm = Some(point(from));
        opts.centerline.target_mm = Some(point(to));
        let s = prepare(ct.clone(), &opts, |_| {}).unwrap();
        let cl = &s.centerline;
        let expected = (arc[from] - arc[to]).abs();
        assert!(
            (cl.length_mm - expected).abs() < 0.05 * expected + 20.0,
            "{from} -> {to}: length {:.0} mm, the colon between them {expected:.0} mm",
            cl.length_mm
        );
        // Each point lies by the automatic centerline, at an arc length that moves steadily
        // from the source's to the target's (a jump would be a short cut through a contact).
        let mut along = Vec::with_capacity(cl.points_mm.len());
        for p in &cl.points_mm {
            let p = glam::DVec3::from_array(*p);
            let (i, d) = (0..pts.len())
                .map(|i| (i, point(i).distance(p)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert!(
                d < 10.0,
                "{from} -> {to}: point {p} is {d:.1} mm from the colon's centerline"
            );
            along.push(arc[i]);
        }
        let jump = along
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0f64, f64::max);
        assert!(
            jump < 20.0,
            "{from} -> {to}: the path jumps {jump:.0} mm along the colon"
        );
        assert!(
            (along[0] - arc[from]).abs() < 20.0 && (along[along.len() - 1] - arc[to]).abs() < 20.0,
            "{from} -> {to}: runs {:.0} -> {:.0} mm",
            along[0],
            along[along.len() - 1]
        );
    }
}

/// colon-a as a CT: air in soft tissue with a partial-volume edge, so the whole pipeline
/// (thresholding, outside air, components) runs on it; the result must agree with the mask's.
#[test]
fn colon_a_as_a_pseudo_ct() {
    let Some(mask) = colon_a_volume() else {
        return;
    };
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
        let q = lumen
            .geometry()
            .local_to_index(glam::DVec3::from_array(*p))
            .round();
        assert_eq!(
            lumen.get(q.x as usize, q.y as usize, q.z as usize),
            1,
            "point {p:?} outside the lumen"
        );
    }
}

/// −1000 HU in the lumen, +40 HU around, blurred by [¼ ½ ¼] along each axis.
fn pseudo_ct(mask: &voyage_core::Volume<i16>) -> voyage_core::Volume<i16> {
    let [nx, ny, nz] = mask.dims();
    let mut f: Vec<f32> = mask
        .data()
        .iter()
        .map(|&m| if m != 0 { 1.0 } else { 0.0 })
        .collect();
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
    let data = f
        .iter()
        .map(|&g| (40.0 - 1040.0 * g).round() as i16)
        .collect();
    voyage_core::Volume::from_vec(mask.geometry().clone(), data).unwrap()
}
