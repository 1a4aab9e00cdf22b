//! Phantom → file → load gives back the phantom: geometry and every HU, through NIfTI and
//! through a full-size DICOM series; and `voyage prep`'s volumes of a scan stored otherwise
//! come back on that scan's grid.

use voyage_io::{self as io, LoadOptions, dicom_write, nifti};
use voyage_phantom::{self as phantom, ColonOptions, fixtures::assert_same_volume};

fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("voyage-rt-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn small_colon_and_pipe_through_nifti() {
    let dir = scratch("nifti");
    let colon = phantom::colon(&ColonOptions {
        small: true,
        seed: 7,
        ..Default::default()
    })
    .unwrap();
    let p = dir.join("colon.nii.gz");
    nifti::save(&p, &colon.ct).unwrap();
    assert_same_volume(
        &colon.ct,
        &io::load(&p, &LoadOptions::default()).unwrap().volume,
        "colon .nii.gz",
    );
    let m = dir.join("lumen.nii");
    nifti::save(&m, &colon.lumen).unwrap();
    let back = io::load(&m, &LoadOptions::default()).unwrap().volume;
    assert!(
        back.data()
            .iter()
            .zip(colon.lumen.data())
            .all(|(&a, &b)| a == b as i16),
        "mask round trip"
    );
    let pipe = phantom::pipe(1).unwrap();
    let p = dir.join("pipe.nii.gz");
    nifti::save(&p, &pipe.ct).unwrap();
    assert_same_volume(
        &pipe.ct,
        &io::load(&p, &LoadOptions::default()).unwrap().volume,
        "pipe .nii.gz",
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn full_size_colon_through_a_dicom_series() {
    let dir = scratch("dicom");
    let colon = phantom::colon(&ColonOptions::default()).unwrap();
    assert_eq!(colon.ct.dims(), [512, 512, 400]);
    dicom_write::write_series(&dir, &colon.ct).unwrap();
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 400);
    let loaded = io::load(&dir, &LoadOptions::default()).unwrap();
    assert_eq!(loaded.meta.files, 400);
    assert_same_volume(&colon.ct, &loaded.volume, "colon DICOM series");
    std::fs::remove_dir_all(&dir).unwrap();
}
