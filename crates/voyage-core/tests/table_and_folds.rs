//! A patient on the CT table, with skin folds (issue 34): on a real prone exam the air
//! between patient and table, and skin folds closed over at the surface in some slices, were
//! taken as rectal tubes and gas segments. On the colon phantom with its truth: the real
//! catheter is the one rectal tube (none without a catheter), no table or fold air is lumen,
//! the lumen is found as well as without table and folds, and no warning speaks of another
//! tube. Each check first makes sure the phantom holds the trap: fold air enclosed in some
//! axial slices.
//!
//! Run with `cargo test --release -p voyage-core --test table_and_folds`.

use glam::DVec3;
use voyage_core::{ComponentKind, SegmentOptions, Segmentation, segment};
use voyage_phantom::{self as phantom, ColonOptions, Phantom, SkinFoldTruth, label};

/// The same phantom with a table and skin folds, and without.
fn with_and_without(opts: ColonOptions) -> (Phantom, Phantom) {
    let plain = phantom::colon(&opts).expect("colon phantom");
    let on_table = phantom::colon(&ColonOptions {
        table: true,
        skin_folds: true,
        ..opts
    })
    .expect("colon phantom on the table");
    (on_table, plain)
}

/// Whether `p` lies in a fold's air (the slab the truth describes; its closed stretch
/// included, which only moves the mouth a bridge's thickness inward).
fn in_fold(f: &SkinFoldTruth, p: DVec3) -> bool {
    let [mouth, inward, along] = [f.mouth_mm, f.inward, f.along].map(DVec3::from_array);
    let across = inward.cross(along);
    let d = p - mouth;
    let (u, l, v) = (d.dot(inward), d.dot(along), d.dot(across));
    v.abs() <= 0.5 * f.width_mm
        && (0.0..=f.depth_mm).contains(&u)
        && (f.span_mm[0]..=f.span_mm[1]).contains(&l)
}

/// Whether voxel `v` lies in the table or in outside air (a skin fold's, the wedge under the
/// body, anything outside the body).
fn table_or_outside(p: &Phantom, v: usize) -> bool {
    let q = p.ct.geometry().voxel_local(v);
    let in_table = p.truth.table.as_ref().is_some_and(|t| {
        let (lo, hi) = (t.top_y_mm.min(t.bottom_y_mm), t.top_y_mm.max(t.bottom_y_mm));
        (t.x_range_mm[0]..=t.x_range_mm[1]).contains(&q.x) && (lo..=hi).contains(&q.y)
    });
    in_table || p.labels.data()[v] == label::OUTSIDE_AIR
}

/// Air voxels (CT < −500) of skin folds that an axial flood from the slice's rim through air
/// does not reach: what fools a slice-by-slice outside-air search.
fn enclosed_fold_air(p: &Phantom) -> usize {
    let [nx, ny, nz] = p.ct.dims();
    let g = p.ct.geometry();
    let ct = p.ct.data();
    let mut enclosed = 0;
    for k in 0..nz {
        let at = |i: usize| i + k * nx * ny;
        let mut seen = vec![false; nx * ny];
        let mut stack: Vec<usize> = (0..nx * ny)
            .filter(|&i| i % nx == 0 || i % nx == nx - 1 || i / nx == 0 || i / nx == ny - 1)
            .filter(|&i| ct[at(i)] < -500)
            .collect();
        stack.iter().for_each(|&i| seen[i] = true);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % nx, i / nx);
            let next = [
                (x > 0).then(|| i - 1),
                (x + 1 < nx).then(|| i + 1),
                (y > 0).then(|| i - nx),
                (y + 1 < ny).then(|| i + nx),
            ];
            for n in next.into_iter().flatten() {
                if !seen[n] && ct[at(n)] < -500 {
                    seen[n] = true;
                    stack.push(n);
                }
            }
        }
        enclosed += (0..nx * ny)
            .filter(|&i| !seen[i] && ct[at(i)] < -500)
            .filter(|&i| {
                let q = g.voxel_local(at(i));
                p.truth.skin_folds.iter().any(|f| in_fold(f, q))
            })
            .count();
    }
    enclosed
}

/// Share of the truth's lumen that the segmentation found.
fn recall(p: &Phantom, s: &Segmentation) -> f64 {
    let (mut found, mut all) = (0usize, 0usize);
    for (&t, &l) in p.lumen.data().iter().zip(s.lumen.data()) {
        all += (t != 0) as usize;
        found += (t != 0 && l != 0) as usize;
    }
    found as f64 / all as f64
}

/// Lumen voxels in the table or in outside air (skin folds' and the wedge's included).
fn lumen_in_table_or_outside(p: &Phantom, s: &Segmentation) -> usize {
    s.lumen
        .data()
        .iter()
        .enumerate()
        .filter(|&(v, &l)| l != 0 && table_or_outside(p, v))
        .count()
}

/// Everything a phantom on the table gets wrong against the same phantom without table and
/// folds (`plain`), as messages; `catheter`: whether it has one.
fn problems(on_table: &Phantom, plain: &Phantom, catheter: bool) -> Vec<String> {
    let mut out = Vec::new();
    let enclosed = enclosed_fold_air(on_table);
    if enclosed == 0 {
        // Without the trap nothing below would mean anything.
        return vec!["no skin fold's air is enclosed in an axial slice".into()];
    }
    let s = segment(&on_table.ct, &SegmentOptions::default()).expect("segmentation");
    let base = segment(&plain.ct, &SegmentOptions::default()).expect("segmentation");
    let wrong = lumen_in_table_or_outside(on_table, &s);
    if wrong > 0 {
        out.push(format!(
            "{wrong} lumen voxels in the table or outside air (skin folds, under the body)"
        ));
    }
    let (r, r0) = (recall(on_table, &s), recall(plain, &base));
    if (r - r0).abs() > 0.005 {
        out.push(format!(
            "lumen recall {r:.4} on the table with skin folds, {r0:.4} without"
        ));
    }
    let found: Vec<_> = s
        .segments
        .iter()
        .filter(|x| x.kind == ComponentKind::RectalTube)
        .collect();
    let expected = usize::from(catheter);
    if found.len() != expected {
        out.push(format!(
            "{} rectal tubes found, {expected} expected: {:?}",
            found.len(),
            found.iter().map(|t| &t.reason).collect::<Vec<_>>()
        ));
    }
    if let (Some(tube), Some(truth)) = (found.first(), &on_table.truth.rectal_tube) {
        let g = on_table.ct.geometry();
        let [a, b] = tube
            .extent_lps_mm
            .map(|c| g.patient_to_local(DVec3::from_array(c)));
        let (lo, hi) = (a.min(b), a.max(b));
        let tip = DVec3::from_array(truth.tip_mm);
        // The small phantom's catheter (3.5 mm across in 1.5 mm voxels) leaks into the
        // rectum's gas through its thin wall, so its air is followed only up to the rectum's
        // end; at full size up to its tip.
        let rectum_end = on_table.truth.centerline_mm[0][2];
        let from = if on_table.truth.scale < 1.0 {
            rectum_end
        } else {
            tip.z - 3.0
        };
        let beside = DVec3::new(tip.x, tip.y, hi.z);
        if (beside - beside.clamp(lo, hi)).length() > 3.0 || !(from..=tip.z + 3.0).contains(&hi.z) {
            out.push(format!(
                "the tube found runs from {lo:.1} to {hi:.1}, the catheter's tip is at {tip:.1}"
            ));
        }
    }
    let reason = found.first().and_then(|t| t.reason.as_deref());
    for w in s.warnings.iter().filter(|w| w.contains("tube")) {
        if reason.is_none_or(|r| !w.contains(r)) {
            out.push(format!("a warning about another tube: {w}"));
        }
    }
    if !out.is_empty() {
        let colon: Vec<String> = s
            .segments
            .iter()
            .filter(|x| x.kept)
            .map(|x| format!("{} ({:.1} ml)", x.label, x.gas_ml))
            .collect();
        out.push(format!("colon segments: {}", colon.join(", ")));
        out.push(format!("warnings: {:?}", s.warnings));
    }
    out
}

fn check(name: &str, opts: ColonOptions) {
    let catheter = opts.rectal_tube;
    let (on_table, plain) = with_and_without(opts);
    let wrong = problems(&on_table, &plain, catheter);
    assert!(wrong.is_empty(), "{name}:\n  {}", wrong.join("\n  "));
}

fn prone(small: bool, seed: u64) -> ColonOptions {
    ColonOptions {
        small,
        seed,
        prone: true,
        tagged_fluid: true,
        rectal_tube: true,
        ..ColonOptions::default()
    }
}

fn supine(small: bool, seed: u64) -> ColonOptions {
    ColonOptions {
        small,
        seed,
        tagged_fluid: true,
        ..ColonOptions::default()
    }
}

/// Prone with tagged fluid and a rectal catheter, on the table (anterior) with skin folds
/// beside it and in the perineum beside the catheter's exit: the catheter is the one tube.
#[test]
fn prone_on_the_table_the_catheter_is_the_only_tube() {
    check("prone, small", prone(true, 1));
}

/// Supine on the table (posterior) with skin folds on the back and in the gluteal cleft
/// off the scan's inferior edge, no catheter: no rectal tube.
#[test]
fn supine_on_the_table_without_a_catheter_has_no_tube() {
    check("supine, small", supine(true, 1));
}

#[test]
fn prone_full_size_on_the_table_the_catheter_is_the_only_tube() {
    check("prone, full size", prone(false, 1));
}

#[test]
fn supine_full_size_on_the_table_without_a_catheter_has_no_tube() {
    check("supine, full size, seed 3", supine(false, 3));
}
