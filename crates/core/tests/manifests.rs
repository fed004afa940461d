//! Every workspace member inherits the workspace's `rust-version`: a member without it has
//! no declared MSRV, so clippy's `incompatible_msrv` lint is silent there and an API newer
//! than the declared toolchain goes unnoticed.

use std::path::Path;

#[test]
fn every_member_inherits_the_workspace_rust_version() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let workspace = std::fs::read_to_string(root.join("Cargo.toml")).expect("workspace Cargo.toml");
    assert!(
        workspace.lines().any(|l| l.trim_start().starts_with("rust-version = \"")),
        "the workspace Cargo.toml declares no rust-version under [workspace.package]"
    );
    let mut members = 0;
    for krate in std::fs::read_dir(root.join("crates")).expect("crates/") {
        let manifest = krate.expect("crates/ entry").path().join("Cargo.toml");
        let Ok(text) = std::fs::read_to_string(&manifest) else { continue };
        members += 1;
        assert!(
            text.lines().any(|l| l.trim() == "rust-version.workspace = true"),
            "{} lacks `rust-version.workspace = true`",
            manifest.display()
        );
    }
    assert!(members > 5, "found only {members} member manifests under {}", root.display());
}
