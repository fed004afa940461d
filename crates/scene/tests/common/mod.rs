//! Helpers shared by the loader tests.
#![allow(dead_code, unused_imports)]

use std::path::PathBuf;

/// `../shared/<rel>`, or `None` with a SKIP line when absent (a failure when `CI` is set).
pub use filtrace_core::shared_data::shared_path as shared;

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
