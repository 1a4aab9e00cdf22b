//! A colon cut by the side of the scanned volume (issue 38, item 3): its gas at the edge
//! touches the slices' border, and the slice-by-slice search for the air outside the body
//! took it for that air, so the colon lost it without a word (on the phantom cut 10 mm into
//! the descending colon: 58 of 201 ml kept, 116 ml left out as "other"). The gas is kept,
//! the colon is said to reach the side, on the side the patient's anatomy names, and a
//! bridge at the edge is said to be one, not a collapsed stretch.
//!
//! Run with `cargo test --release -p voyage-core --test volume_edge`.

use voyage_core::{Geometry, SegmentOptions, Volume, segment};
use voyage_phantom::{self as phantom, ColonOptions, label};

/// The first `keep` columns (i) of `ct`, where it sits in the patient.
fn first_columns(ct: &Volume<i16>, keep: usize) -> Volume<i16> {
    let [nx, ny, nz] = ct.dims();
    let g = ct.geometry();
    let mut data = Vec::with_capacity(keep * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            let row = (k * ny + j) * nx;
            data.extend_from_slice(&ct.data()[row..row + keep.min(nx)]);
        }
    }
    let geom = Geometry {
        dims: [keep, ny, nz],
        ..g.clone()
    };
    Volume::from_vec(geom, data).expect("the cut volume")
}

#[test]
fn a_colon_cut_by_the_side_of_the_scan_keeps_its_gas_and_is_said_to() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        ..Default::default()
    })
    .expect("colon phantom");
    let [nx, ny, nz] = p.ct.dims();
    // The phantom runs i → the patient's left; cut 10 mm into the descending colon.
    let colon_hi = (0..nx * ny * nz)
        .filter(|&v| p.labels.data()[v] == label::LUMEN_AIR)
        .map(|v| v % nx)
        .max()
        .expect("colon gas");
    let keep = colon_hi + 1 - (10.0 / p.ct.spacing()[0]).round() as usize;
    let cut = first_columns(&p.ct, keep);
    let gas_in_cut = (0..nx * ny * nz)
        .filter(|&v| p.labels.data()[v] == label::LUMEN_AIR && v % nx < keep)
        .count();
    let s = segment(&cut, &SegmentOptions::default()).expect("segmentation");
    let kept = (0..keep * ny * nz)
        .filter(|&v| {
            let (i, rest) = (v % keep, v / keep);
            let (j, k) = (rest % ny, rest / ny);
            s.lumen.get(i, j, k) == 1 && p.labels.get(i, j, k) == label::LUMEN_AIR
        })
        .count();
    eprintln!(
        "cut at i = {keep}: {kept} of the {gas_in_cut} colon gas voxels left in the scan kept; warnings: {:#?}",
        s.warnings
    );
    assert!(
        kept as f64 >= 0.95 * gas_in_cut as f64,
        "{kept} of {gas_in_cut} colon gas voxels kept"
    );
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("reaches the side of the scanned volume at the patient's left")),
        "{:?}",
        s.warnings
    );
    assert!(
        !s.warnings
            .iter()
            .any(|w| w.contains("left out of the colon")),
        "{:?}",
        s.warnings
    );
    // A bridge with an end at the cut is the colon leaving the scan, and says so.
    let sp = cut.spacing()[0];
    for g in &s.gaps {
        let ends = [g.from_lps_mm, g.to_lps_mm].map(|p| {
            let v = cut.geometry().patient_to_index(glam::DVec3::from_array(p));
            (keep as f64 - 1.0 - v.x) * sp
        });
        if ends.iter().any(|&mm| mm <= 5.0) {
            assert!(g.at_edge(), "{g:?}");
        }
    }
    assert!(
        !s.warnings
            .iter()
            .any(|w| w.starts_with("collapsed") && w.contains("descending")),
        "{:?}",
        s.warnings
    );
}

/// The whole phantom reaches no side: no such warning.
#[test]
fn a_colon_inside_the_scan_is_not_said_to_reach_its_side() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        ..Default::default()
    })
    .expect("colon phantom");
    let s = segment(&p.ct, &SegmentOptions::default()).expect("segmentation");
    assert!(
        !s.warnings.iter().any(|w| w.contains("scanned volume")),
        "{:?}",
        s.warnings
    );
    assert!(s.gaps.iter().all(|g| !g.at_edge()));
}

/// Slices `from..to` of `ct`, where they sit in the patient.
fn slices(ct: &Volume<i16>, from: usize, to: usize) -> Volume<i16> {
    let [nx, ny, _] = ct.dims();
    let g = ct.geometry();
    let data = ct.data()[from * nx * ny..to * nx * ny].to_vec();
    let mut origin = g.origin;
    for (r, o) in origin.iter_mut().enumerate() {
        *o += g.direction[r][2] * g.spacing[2] * from as f64;
    }
    let geom = Geometry {
        dims: [nx, ny, to - from],
        origin,
        ..g.clone()
    };
    Volume::from_vec(geom, data).expect("the cut volume")
}

/// A scan that ends 10 mm into the colon's highest gas (a splenic flexure above the last
/// slice), or 10 mm above the rectum's lowest gas: the colon is said to reach the head or the
/// feet end of the scanned volume. Before, only the slices' border counted, and a colon cut
/// by the first or last slice was read as if it ended there.
#[test]
fn a_colon_cut_by_the_first_or_last_slice_is_said_to_reach_that_end() {
    let p = phantom::colon(&ColonOptions {
        small: true,
        ..Default::default()
    })
    .expect("colon phantom");
    let [nx, ny, nz] = p.ct.dims();
    let gas_k: Vec<usize> = (0..nx * ny * nz)
        .filter(|&v| p.labels.data()[v] == label::LUMEN_AIR)
        .map(|v| v / (nx * ny))
        .collect();
    let (lo, hi) = (*gas_k.iter().min().unwrap(), *gas_k.iter().max().unwrap());
    let mm = (10.0 / p.ct.spacing()[2]).round() as usize;
    // The phantom's k runs to the patient's head.
    for (cut, end) in [
        (slices(&p.ct, 0, hi + 1 - mm), "head end"),
        (slices(&p.ct, lo + mm, nz), "feet end"),
    ] {
        let s = segment(&cut, &SegmentOptions::default()).expect("segmentation");
        eprintln!("cut at the {end}: warnings {:#?}", s.warnings);
        assert!(
            s.warnings
                .iter()
                .any(|w| w.contains(&format!("scanned volume at the patient's {end}"))),
            "{end}: {:?}",
            s.warnings
        );
    }
}
