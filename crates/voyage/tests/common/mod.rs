//! Shared by the integration tests of the `voyage` binary.

/// A test that cannot run here says so; where `VOYAGE_REQUIRE_ALL` is set (CI sets it) it
/// fails instead, so that a skip is never a silent pass.
pub fn skip(why: &str) {
    assert!(
        std::env::var_os("VOYAGE_REQUIRE_ALL").is_none(),
        "cannot run: {why} (VOYAGE_REQUIRE_ALL is set)"
    );
    eprintln!("skipping: {why}");
}
