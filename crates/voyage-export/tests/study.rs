//! The study's exports on the input's own grid, whatever the scan's storage order.

use voyage_core::Volume;
use voyage_io::{self as io, LoadOptions};
use voyage_phantom::{self as phantom, ColonOptions, fixtures::assert_same_volume};

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("voyage-export-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A scan stored upside down and transposed is prepared in the study storage, and `voyage
/// prep`'s volumes come back on the input's own grid: the lumen, Ds and the cleansed CT are
/// the study's, voxel for voxel, turned back; and the same as from the scan stored plainly.
#[test]
fn exports_of_a_scan_stored_otherwise_are_on_its_grid() {
    use voyage_core::{PrepOptions, prepare};
    use voyage_export::study::{StudyExports, write_study};
    let ct = phantom::colon(&ColonOptions {
        small: true,
        tagged_fluid: true,
        seed: 3,
        ..Default::default()
    })
    .unwrap()
    .ct;
    let plain = prepare(ct.clone(), &PrepOptions::default(), |_| {}).unwrap();
    assert!(plain.storage.is_identity(), "the phantom is stored L, P, S");
    assert!(
        !plain.cleansing.is_empty(),
        "the phantom's fluid is cleansed"
    );
    let stored = ct.reoriented([1, 0, 2], [false, true, true]).unwrap();
    let study = prepare(stored.clone(), &PrepOptions::default(), |_| {}).unwrap();
    assert!(!study.storage.is_identity());
    let dir = scratch("storage");
    write_study(&dir, &study, StudyExports::default()).unwrap();
    let load = |name: &str| {
        io::load(&dir.join(name), &LoadOptions::default())
            .unwrap()
            .volume
    };
    let on_input = |v: &Volume<u8>| v.reoriented([1, 0, 2], [false, true, true]).unwrap();
    // The lumen file: on the input's grid, the study's lumen turned back, and the plain
    // study's lumen stored as the input is.
    let lumen = load("lumen.nii.gz");
    assert_eq!(lumen.geometry().dims, stored.geometry().dims);
    let back = study.storage.to_input(&study.segmentation.lumen).unwrap();
    assert!(
        lumen
            .data()
            .iter()
            .zip(back.data())
            .all(|(&a, &b)| a == b as i16),
        "lumen.nii.gz is not the study's lumen on the input's grid"
    );
    let want = on_input(&plain.segmentation.lumen);
    assert!(
        back.data() == want.data(),
        "the study of the scan stored otherwise differs from the plain one's"
    );
    // The cleansed CT: the input's HU where cleansing changed nothing, the study's cleansed
    // values turned back elsewhere.
    let cleansed = load("cleansed.nii.gz");
    let want = study.storage.to_input(&study.cleansed_ct()).unwrap();
    assert_same_volume(&cleansed, &want, "cleansed.nii.gz");
    // Ds (read back as whole mm): zero outside the lumen, and in its middle where it is
    // wider than a voxel.
    let ds = load("ds.nii.gz");
    assert_eq!(ds.geometry().dims, stored.geometry().dims);
    let outside = ds
        .data()
        .iter()
        .zip(back.data())
        .filter(|&(&d, &l)| d > 0 && l == 0)
        .count();
    assert_eq!(outside, 0, "Ds > 0 outside the lumen");
    let inside = ds
        .data()
        .iter()
        .zip(back.data())
        .filter(|&(&d, &l)| d > 0 && l != 0)
        .count();
    assert!(inside > 0, "no Ds inside the lumen");
    std::fs::remove_dir_all(&dir).unwrap();
}
