//! For tests: the real data beside the checkout (`../shared/data`) and how a test that cannot
//! run says so. Where `VOYAGE_REQUIRE_ALL` is set (CI sets it) such a test fails instead, so
//! that a skip is never a silent pass.

use std::path::PathBuf;

/// `../shared/data` beside the checkout, or None after [`skip`] where it is not there.
pub fn shared_data() -> Option<PathBuf> {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"));
    if path.is_dir() {
        Some(path)
    } else {
        skip(&format!("{} not found", path.display()));
        None
    }
}

/// The real colon mask `masks/colon-a.nii.gz` of the shared data, or None after [`skip`].
pub fn colon_a_path() -> Option<PathBuf> {
    let path = shared_data()?.join("masks/colon-a.nii.gz");
    if !path.exists() {
        skip(&format!("colon-a: {} not found", path.display()));
        return None;
    }
    Some(path)
}

/// A test that cannot run here says why on stderr; where `VOYAGE_REQUIRE_ALL` is set it
/// panics instead.
pub fn skip(why: &str) {
    assert!(
        std::env::var_os("VOYAGE_REQUIRE_ALL").is_none(),
        "cannot run: {why} (VOYAGE_REQUIRE_ALL is set)"
    );
    eprintln!("skipping: {why}");
}
