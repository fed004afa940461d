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

/// Standard base64 (RFC 4648, with padding), for the data URIs of glTF files built in tests.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}
