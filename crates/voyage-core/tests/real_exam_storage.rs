//! The real exam (`ctc/prone-tagged`) stored other ways gives the same colon: NIfTI in other
//! axis orders and flips, and DICOM series of axial, coronal and sagittal slices. The
//! segmentation's lumen agrees to 0.1% of its voxels and the bridged gaps to two voxels;
//! the prepared study (made in the study storage, `voyage_core::Storage`) is the same: the
//! same cleansed CT, the same lumen with its contacts cut, the same centerline. Needs
//! `../shared/data`; skips with a message without it. Run in release mode
//! (`cargo test --release -p voyage-core --test real_exam_storage`).

use std::path::PathBuf;

use glam::DVec3;
use voyage_core::{Geometry, PrepOptions, SegmentOptions, Study, Volume, prepare, segment};
use voyage_io::{LoadOptions, load};

fn exam_path() -> Option<PathBuf> {
    voyage_phantom::fixtures::shared_file("ctc/prone-tagged.nii.gz")
}

/// The (perm, flip) of [`Volume::reoriented`] that stores a volume of geometry `from` the way
/// `to` is stored (the same grid in the patient, axes permuted and flipped).
fn storage_like(from: &Geometry, to: &Geometry) -> ([usize; 3], [bool; 3]) {
    let (mf, mt) = (from.direction_mat(), to.direction_mat());
    let mut perm = [0; 3];
    let mut flip = [false; 3];
    for b in 0..3 {
        let (a, dot) = (0..3)
            .map(|a| (a, mf.col(a).dot(mt.col(b))))
            .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))
            .unwrap();
        assert!(dot.abs() > 0.99, "axis {b} has no parallel axis");
        perm[b] = a;
        flip[b] = dot < 0.0;
    }
    (perm, flip)
}

/// `v` (stored as `from`) in `to`'s storage.
fn restored<T: Copy + Send + Sync>(v: &Volume<T>, to: &Geometry) -> Volume<T> {
    let (perm, flip) = storage_like(v.geometry(), to);
    let back = v.reoriented(perm, flip).unwrap();
    assert_eq!(back.geometry().dims, to.dims);
    let off = DVec3::from_array(back.geometry().origin) - DVec3::from_array(to.origin);
    assert!(off.length() < 0.01, "origins {off:?} apart");
    back
}

/// The voxels cleansing changes, as a mask.
fn cleansed_mask(s: &Study) -> Volume<u8> {
    let mut m = Volume::filled(s.ct.geometry().clone(), 0u8).unwrap();
    for &v in s.cleansing.voxels() {
        m.data_mut()[v as usize] = 1;
    }
    m
}

fn differ(a: &Volume<u8>, b: &Volume<u8>) -> usize {
    a.data()
        .iter()
        .zip(b.data())
        .filter(|(x, y)| (**x != 0) != (**y != 0))
        .count()
}

#[test]
fn every_storage_of_the_real_exam_gives_the_same_segmentation() {
    let Some(path) = exam_path() else {
        return;
    };
    let ct = load(&path, &LoadOptions::default()).unwrap().volume;
    let geom = ct.geometry().clone();
    let voxel = geom.spacing.iter().cloned().fold(0.0, f64::max);
    let ref_seg = segment(&ct, &SegmentOptions::default()).unwrap();
    let ref_lumen = &ref_seg.lumen;
    let reference = prepare(ct.clone(), &PrepOptions::default(), |_| {}).unwrap();
    let ref_cleansed = cleansed_mask(&reference);
    let lumen_voxels = ref_lumen.data().iter().filter(|&&v| v != 0).count();

    let dir = std::env::temp_dir().join(format!("voyage-exam-storage-{}", std::process::id()));
    let mut variants: Vec<(String, Volume<i16>)> = Vec::new();
    for (perm, flip) in [
        ([1, 0, 2], [false, false, false]),
        ([0, 1, 2], [true, true, true]),
        ([0, 2, 1], [false, true, false]),
        ([2, 0, 1], [true, false, false]),
    ] {
        variants.push((
            format!("NIfTI axes {perm:?} flipped {flip:?}"),
            ct.reoriented(perm, flip).unwrap(),
        ));
    }
    // DICOM series of slices across each axis: axial (as acquired), coronal, sagittal.
    for (name, perm) in [
        ("axial", [0, 1, 2]),
        ("coronal", [0, 2, 1]),
        ("sagittal", [1, 2, 0]),
    ] {
        let series = dir.join(name);
        voyage_io::dicom_write::write_series(&series, &ct.reoriented(perm, [false; 3]).unwrap())
            .unwrap();
        let loaded = load(&series, &LoadOptions::default()).unwrap().volume;
        std::fs::remove_dir_all(&series).ok();
        variants.push((format!("DICOM {name}"), loaded));
    }

    for (what, stored) in variants {
        let seg = segment(&stored, &SegmentOptions::default()).unwrap();
        let d = differ(&restored(&seg.lumen, &geom), ref_lumen);
        let s = prepare(stored, &PrepOptions::default(), |_| {}).unwrap();
        // Both studies are in the study storage: compared voxel for voxel.
        assert_eq!(s.ct.dims(), reference.ct.dims(), "{what}");
        let dc = differ(&cleansed_mask(&s), &ref_cleansed);
        let dv = s
            .cleansed_ct()
            .data()
            .iter()
            .zip(reference.cleansed_ct().data())
            .filter(|(a, b)| a != b)
            .count();
        let df = differ(&s.segmentation.lumen, &reference.segmentation.lumen);
        let dl = (s.centerline.length_mm - reference.centerline.length_mm).abs();
        eprintln!(
            "{what}: segmentation's lumen differs in {d} voxels ({:.3}%), cleansing in {dc}, the cleansed CT in {dv}; after the centerline's contacts {df}; centerline {:.1} mm against {:.1}",
            100.0 * d as f64 / lumen_voxels as f64,
            s.centerline.length_mm,
            reference.centerline.length_mm
        );
        assert_eq!(dv, 0, "{what}: the cleansed CT differs in {dv} voxels");
        assert_eq!(df, 0, "{what}: the study's lumen differs in {df} voxels");
        assert!(
            dl < 1.0,
            "{what}: the centerline's length differs by {dl:.1} mm"
        );
        assert_eq!(
            (s.source, s.target),
            (reference.source, reference.target),
            "{what}"
        );
        assert!(
            d as f64 <= 0.001 * lumen_voxels as f64,
            "{what}: the segmentation's lumen differs in {d} of {lumen_voxels} voxels"
        );
        let gaps = &seg.gaps;
        let ref_gaps = &ref_seg.gaps;
        assert_eq!(gaps.len(), ref_gaps.len(), "{what}: gaps {gaps:?}");
        for (g, r) in gaps.iter().zip(ref_gaps) {
            assert_eq!(g.between, r.between, "{what}");
            for (p, q) in [(g.from_lps_mm, r.from_lps_mm), (g.to_lps_mm, r.to_lps_mm)] {
                let off = (DVec3::from_array(p) - DVec3::from_array(q)).length();
                assert!(
                    off <= 2.0 * voxel + 1e-3,
                    "{what}: a gap's end {off:.1} mm from the reference's"
                );
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
