//! Shared by the integration tests: the real colon mask from ../shared/data (and how a test
//! without it skips), the phantom valve's mouth, a voxel's position.
// Each test file uses its own part of this module.
#![allow(dead_code)]

use std::path::PathBuf;

use voyage_core::Volume;
use voyage_core::prep::{PrepOptions, Study, prepare};

/// ../shared/data/masks/colon-a.nii.gz, or None (with a note on stderr) where the shared data
/// is not beside the checkout.
pub fn colon_a_path() -> Option<PathBuf> {
    let path = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/masks/colon-a.nii.gz"
    ));
    if !path.exists() {
        skip(&format!("colon-a: {} not found", path.display()));
        return None;
    }
    Some(path)
}

/// The colon-a mask as loaded (0/1 labels as i16).
pub fn colon_a_volume() -> Option<Volume<i16>> {
    Some(
        voyage_core::io::load(&colon_a_path()?, &Default::default())
            .unwrap()
            .volume,
    )
}

/// colon-a preprocessed with the default options.
pub fn colon_a_study() -> Option<Study> {
    Some(prepare(colon_a_volume()?, &PrepOptions::default(), |_| {}).unwrap())
}

/// The mouth of the ileocecal valve of a colon phantom with opacified small bowel: the point
/// where the terminal ileum opens into the caecum (volume-local mm) and the ileum's radius
/// (mm); None without small bowel.
pub fn valve_mouth(t: &voyage_core::phantom::Truth) -> Option<(glam::DVec3, f64)> {
    let ileum = t
        .small_bowel_loops
        .iter()
        .filter(|l| l.enters_cecum)
        .map(|l| l.radius_mm)
        .fold(0.0, f64::max);
    t.ileocecal_valve_mm
        .map(|p| (glam::DVec3::from_array(p), ileum))
}

/// The centre of voxel `v` (volume index) in volume-local mm.
pub fn voxel_mm(g: &voyage_core::Geometry, v: usize) -> glam::DVec3 {
    g.index_to_local(glam::DVec3::from_array(g.ijk(v).map(|x| x as f64)))
}

/// A test that cannot run here says so; where `VOYAGE_REQUIRE_ALL` is set (CI sets it) it
/// fails instead, so that a skip is never a silent pass.
pub fn skip(why: &str) {
    assert!(
        std::env::var_os("VOYAGE_REQUIRE_ALL").is_none(),
        "cannot run: {why} (VOYAGE_REQUIRE_ALL is set)"
    );
    eprintln!("skipping: {why}");
}
