//! Shared by the integration tests: the real colon mask from ../shared/data.
// Each test file uses its own part of this module.
#![allow(dead_code)]

use std::path::PathBuf;

use voyage_core::prep::{prepare, PrepOptions, Study};
use voyage_core::Volume;

/// ../shared/data/masks/colon-a.nii.gz, or None (with a note on stderr) where the shared data
/// is not beside the checkout.
pub fn colon_a_path() -> Option<PathBuf> {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/masks/colon-a.nii.gz"));
    if !path.exists() {
        eprintln!("skipping colon-a: {} not found", path.display());
        return None;
    }
    Some(path)
}

/// The colon-a mask as loaded (0/1 labels as i16).
pub fn colon_a_volume() -> Option<Volume<i16>> {
    Some(voyage_core::io::load(&colon_a_path()?, &Default::default()).unwrap().volume)
}

/// colon-a preprocessed with the default options.
pub fn colon_a_study() -> Option<Study> {
    Some(prepare(colon_a_volume()?, &PrepOptions::default(), |_| {}).unwrap())
}
