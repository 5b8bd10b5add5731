//! Where the shared test scenes (with their reference images) are: `../shared/scenes`
//! beside the repository.

use std::path::{Path, PathBuf};

/// The shared scenes folder, whether or not it exists.
pub fn shared_scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes")
}

/// The shared scenes folder, or `None` (after saying so on stderr) where it is missing, for
/// tests that pass without it.
pub fn shared() -> Option<PathBuf> {
    let p = shared_scenes_dir();
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("SKIPPED: {} not found (the shared scenes folder must sit beside the repository)", p.display());
        None
    }
}
