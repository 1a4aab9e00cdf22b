//! The same scan stored another way gives the same colon: every decision is made in the
//! patient frame, never by array order. The small colon phantom (with tagged fluid, so that
//! gravity is read from its air–fluid levels) is stored in 3 axis orders × 8 flips, and as
//! NIfTI and DICOM; lumen, source, target and centerline must agree.

use glam::DVec3;
use voyage_core::{PositionSource, PrepOptions, SegmentOptions, Study, Volume, prepare, segment};
use voyage_io::{LoadOptions, load};
use voyage_phantom::{self as phantom, ColonOptions};

fn phantom_ct() -> Volume<i16> {
    phantom::colon(&ColonOptions {
        small: true,
        tagged_fluid: true,
        ..ColonOptions::default()
    })
    .unwrap()
    .ct
}

/// The storage that undoes `reoriented(perm, flip)`.
fn inverse(perm: [usize; 3], flip: [bool; 3]) -> ([usize; 3], [bool; 3]) {
    let mut inv = [0; 3];
    for a in 0..3 {
        inv[perm[a]] = a;
    }
    (inv, [0, 1, 2].map(|b| flip[inv[b]]))
}

struct Answer {
    source: DVec3,
    target: DVec3,
    length: f64,
}

fn answer(s: &Study) -> Answer {
    let g = s.ct.geometry();
    Answer {
        source: g.local_to_patient(s.source_mm()),
        target: g.local_to_patient(s.target_mm()),
        length: s.centerline.length_mm,
    }
}

/// Within one voxel: at most a voxel's size along each patient axis (NIfTI keeps geometry in
/// f32: a micrometre more is allowed).
fn check(what: &str, a: &Answer, reference: &Answer, voxel: f64) {
    let off = |p: DVec3, q: DVec3| (p - q).abs().max_element();
    assert!(
        off(a.source, reference.source) <= voxel + 1e-3,
        "{what}: source {:?} mm from the reference's",
        a.source - reference.source
    );
    assert!(
        off(a.target, reference.target) <= voxel + 1e-3,
        "{what}: target {:?} mm from the reference's",
        a.target - reference.target
    );
    let rel = (a.length - reference.length).abs() / reference.length;
    assert!(
        rel <= 0.005,
        "{what}: centerline {:.1} mm against {:.1} mm",
        a.length,
        reference.length
    );
}

#[test]
fn every_storage_order_gives_the_same_colon() {
    let ct = phantom_ct();
    let voxel = ct.spacing().iter().cloned().fold(0.0, f64::max);
    let seg0 = segment(&ct, &SegmentOptions::default()).unwrap();
    assert_eq!(
        seg0.orientation.source,
        PositionSource::AirFluidLevels,
        "gravity from the levels"
    );
    assert_eq!(seg0.orientation.position.code(), "HFS");
    let reference = answer(&prepare(ct.clone(), &PrepOptions::default(), |_| {}).unwrap());
    for perm in [[0, 1, 2], [1, 2, 0], [2, 0, 1]] {
        for f in 0..8 {
            let flip = [f & 1 != 0, f & 2 != 0, f & 4 != 0];
            let stored = ct.reoriented(perm, flip).unwrap();
            let what = format!("axes {perm:?} flipped {flip:?}");
            let seg = segment(&stored, &SegmentOptions::default()).unwrap();
            assert_eq!(
                seg.orientation.position, seg0.orientation.position,
                "{what}"
            );
            let (inv, iflip) = inverse(perm, flip);
            let back = seg.lumen.reoriented(inv, iflip).unwrap();
            assert_eq!(back.geometry().dims, seg0.lumen.geometry().dims);
            let differ = back
                .data()
                .iter()
                .zip(seg0.lumen.data())
                .filter(|(a, b)| a != b)
                .count();
            assert_eq!(
                differ, 0,
                "{what}: {differ} lumen voxels differ in patient space"
            );
            let study = prepare(stored, &PrepOptions::default(), |_| {}).unwrap();
            check(&what, &answer(&study), &reference, voxel);
        }
    }
}

#[test]
fn nifti_and_dicom_stored_upside_down_give_the_same_colon() {
    let ct = phantom_ct();
    let voxel = ct.spacing().iter().cloned().fold(0.0, f64::max);
    let reference = answer(&prepare(ct.clone(), &PrepOptions::default(), |_| {}).unwrap());
    let dir = std::env::temp_dir().join(format!("voyage-orientation-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Slices in the other order (k runs toward the feet), as many converters write them.
    let flipped = ct.reoriented([0, 1, 2], [false, true, true]).unwrap();
    let nii = dir.join("flipped.nii.gz");
    voyage_io::nifti::save_i16(&nii, &flipped).unwrap();
    let dcm = dir.join("dicom");
    voyage_io::dicom_write::write_series(&dcm, &ct).unwrap();
    for path in [nii, dcm] {
        let loaded = load(&path, &LoadOptions::default()).unwrap().volume;
        let study = prepare(loaded, &PrepOptions::default(), |_| {}).unwrap();
        check(
            &path.display().to_string(),
            &answer(&study),
            &reference,
            voxel,
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A prone exam whose header says HFS: the air–fluid levels win, and a warning names both.
/// The header was trusted: cleansing found nothing and the lumen shrank, without a word.
#[test]
fn a_header_position_the_levels_contradict_is_overruled_and_said() {
    let ct = phantom::colon(&ColonOptions {
        small: true,
        tagged_fluid: true,
        prone: true,
        ..ColonOptions::default()
    })
    .unwrap()
    .ct;
    let read = |position| {
        let mut opts = PrepOptions::default();
        opts.segment.position = position;
        prepare(ct.clone(), &opts, |_| {}).unwrap()
    };
    let by_levels = read(None);
    let tagged = read(Some((
        voyage_core::PatientPosition::Hfs,
        PositionSource::Dicom,
    )));
    let seg = &tagged.segmentation;
    assert_eq!(
        seg.orientation.position,
        by_levels.segmentation.orientation.position
    );
    assert_eq!(seg.orientation.source, PositionSource::AirFluidLevels);
    assert!(
        seg.warnings
            .iter()
            .any(|w| w.contains("PatientPosition is HFS") && w.contains("air–fluid levels")),
        "{:?}",
        seg.warnings
    );
    assert!(tagged.cleansing.tagged_voxels > 0);
    assert_eq!(seg.lumen_voxels, by_levels.segmentation.lumen_voxels);
    // Given by the user, the position stands.
    let given = read(Some((
        voyage_core::PatientPosition::Hfs,
        PositionSource::Given,
    )));
    assert_eq!(given.segmentation.orientation.source, PositionSource::Given);
}
