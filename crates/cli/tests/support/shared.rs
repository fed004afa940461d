//! `../shared` test inputs, shared by the cli's test files (included with `#[path]`).

use std::path::PathBuf;

/// `../shared/<rel>` from the project root; `None` when absent, a failure under CI.
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
    println!("SKIPPED: {} not found", p.display());
    None
}
