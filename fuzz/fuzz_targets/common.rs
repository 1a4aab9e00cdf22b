//! The loaders take paths, as users give them: each input is written to a file in a
//! per-process scratch folder (tmpfs when there is one) and loaded from there.

use std::path::PathBuf;

pub fn scratch(name: &str) -> PathBuf {
    let base = if std::path::Path::new("/dev/shm").is_dir() {
        PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    let dir = base.join(format!("voyage-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir.join(name)
}

/// Saves `bytes` as `name` in the scratch folder (a file a header beside it may name).
#[allow(dead_code)]
pub fn save_as(name: &str, bytes: &[u8]) {
    std::fs::write(scratch(name), bytes).expect("write scratch file");
}

/// Loads `bytes` saved as `name`; any `Err` is fine, a panic is the bug being hunted.
pub fn load_as(name: &str, bytes: &[u8]) {
    let path = scratch(name);
    std::fs::write(&path, bytes).expect("write scratch file");
    let _ = voyage_io::load(&path, &voyage_io::LoadOptions::default());
}
