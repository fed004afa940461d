//! Helpers shared by the loader tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// `../shared` from the project root, or `None` (with a printed message) when absent;
/// under CI (the `CI` variable set) a missing file fails the test instead of skipping it.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared").join(rel);
    if p.exists() {
        return Some(p);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{} not found (../shared is required when CI is set)",
        p.display()
    );
    println!("SKIPPED: {} not found (../shared is absent)", p.display());
    None
}

/// Writes `files` (name, content) into a fresh folder under the system temp dir.
pub fn temp_files(tag: &str, files: &[(&str, &[u8])]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("filtrace-scene-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for (name, content) in files {
        std::fs::write(dir.join(name), content).unwrap();
    }
    dir
}
