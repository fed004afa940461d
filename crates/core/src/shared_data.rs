//! Where tests find the data kept outside the repository (`../shared` next to the project
//! root: reference renders, scanned meshes), and what a test does when it is absent.
//!
//! The rule, the same for every crate's tests:
//! - absent and the `CI` environment variable set: the test **fails** (CI must run it);
//! - absent elsewhere: the test prints a `SKIP` line and passes;
//! - present but unreadable or malformed: the caller fails (a read error is never a skip).
//!
//! Only existence is checked here; reading is the caller's job.

use std::path::{Path, PathBuf};

/// The `../shared` folder seen from the workspace root (every crate sits at `crates/NAME`).
pub fn shared_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared")
}

/// `../shared/<rel>` when it exists; otherwise [`absent`] decides (skip, or fail under CI).
pub fn shared_path(rel: &str) -> Option<PathBuf> {
    let p = shared_root().join(rel);
    if p.exists() {
        Some(p)
    } else {
        absent(&p);
        None
    }
}

/// Reports that the test data at `path` is missing: panics when `CI` is set, else prints a
/// `SKIP` line so the skipped test is visible in the test output.
pub fn absent(path: &Path) {
    let ci = std::env::var_os("CI").is_some_and(|v| !v.is_empty());
    if ci {
        panic!("{} is missing and CI is set: CI must run every test (check out ../shared)", path.display());
    }
    println!("SKIP: {} not found (../shared is absent; with CI set this fails)", path.display());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absent_data_skips_without_ci_and_fails_with_it() {
        // Run in a child process so that setting `CI` does not leak into other tests.
        if let Some(ci) = std::env::var_os("FILTRACE_SHARED_DATA_CHILD") {
            std::env::set_var("CI", ci);
            let _ = shared_path("no/such/file.exr");
            return;
        }
        let exe = std::env::current_exe().unwrap();
        let run = |ci: &str| {
            std::process::Command::new(&exe)
                .args(["--exact", "shared_data::tests::absent_data_skips_without_ci_and_fails_with_it"])
                .args(["--nocapture", "--test-threads=1"])
                .env("FILTRACE_SHARED_DATA_CHILD", ci)
                .output()
                .unwrap()
        };
        let skipped = run("");
        assert!(skipped.status.success());
        assert!(String::from_utf8_lossy(&skipped.stdout).contains("SKIP: "));
        let failed = run("true");
        assert!(!failed.status.success(), "a missing file under CI must fail the test");
        assert!(
            String::from_utf8_lossy(&failed.stdout).contains("CI is set")
                || String::from_utf8_lossy(&failed.stderr).contains("CI is set")
        );
    }
}
