//! Memory a render will need, checked against what the machine has *before* anything big is
//! allocated, and fallible allocation of the big buffers: a frame that cannot fit ends in an
//! error naming what it needs, never in an abort (exit 134) or the OOM killer half-way.
//!
//! - [`MemoryEstimate`]: the bytes of each buffer a command allocates, by name; the
//!   estimates of each configuration are built from the `*_bytes` functions here (the
//!   path tracer's: [`plain_render`]; the filtered pipeline's: `filtrace_pipeline::memory`).
//! - [`available`]: what the machine has: `FILTRACE_MEMORY_LIMIT` when set (bytes, or with
//!   a `K`/`M`/`G` suffix, powers of 1024: for tests and for sharing a machine), else
//!   `MemAvailable` of `/proc/meminfo`, lowered to a cgroup v2 limit when one applies; where
//!   neither exists (not Linux) it is unknown and [`check`] lets the render go ahead.
//! - [`try_vec`]: a `Vec` of `n` copies made with `try_reserve_exact`, so that even a wrong
//!   estimate ends in an [`AllocError`], not an abort.

use std::fmt;

pub use crate::fallible::{bytes_of, try_resize, try_vec, AllocError, Bytes};
use crate::film::FilmPixel;

/// Name of the environment variable that overrides the available memory (bytes).
pub const LIMIT_ENV: &str = "FILTRACE_MEMORY_LIMIT";

/// The bytes a command will allocate, part by part.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryEstimate {
    /// What is being made ("a 512x512 render"), for messages.
    pub what: String,
    parts: Vec<(String, u64)>,
    /// What the user can do about it (e.g. which options lower it), for the refusal.
    pub hint: String,
}

impl MemoryEstimate {
    pub fn new(what: impl Into<String>) -> Self {
        Self { what: what.into(), parts: Vec::new(), hint: String::new() }
    }
    /// Adds a part (parts of zero bytes are kept out of messages).
    pub fn with(mut self, name: impl Into<String>, bytes: u64) -> Self {
        self.parts.push((name.into(), bytes));
        self
    }
    /// Adds every part of `other`.
    pub fn with_all(mut self, other: &MemoryEstimate) -> Self {
        self.parts.extend(other.parts.iter().cloned());
        self
    }
    pub fn with_hint(mut self, hint: impl Into<String>) -> Self {
        self.hint = hint.into();
        self
    }
    pub fn parts(&self) -> &[(String, u64)] {
        &self.parts
    }
    /// Bytes of the named part (0 when absent).
    pub fn part(&self, name: &str) -> u64 {
        self.parts.iter().filter(|(n, _)| n == name).map(|(_, b)| b).sum()
    }
    pub fn total(&self) -> u64 {
        self.parts.iter().map(|(_, b)| b).fold(0u64, |a, b| a.saturating_add(*b))
    }
}

impl fmt::Display for MemoryEstimate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} for {} (", Bytes(self.total()), self.what)?;
        let parts: Vec<String> =
            self.parts.iter().filter(|(_, b)| *b > 0).map(|(n, b)| format!("{n} {}", Bytes(*b))).collect();
        write!(f, "{})", parts.join(", "))
    }
}

/// Bytes of a `w x h` image of `channels` f32 channels.
pub fn image_bytes(w: u32, h: u32, channels: u32) -> u64 {
    bytes_of::<f32>(w as u64 * h as u64 * channels as u64)
}

/// Bytes of the path tracer's film ([`crate::Film`]).
pub fn film_bytes(w: u32, h: u32) -> u64 {
    bytes_of::<FilmPixel>(w as u64 * h as u64)
}

/// Channels of [`crate::Aovs`]: colour, variance, direct, indirect, albedo, normal and
/// position (3 each) and depth (1).
pub const AOV_CHANNELS: u32 = 7 * 3 + 1;

/// Bytes of writing `channels` f32 channels of `w x h` to an EXR with a PNG beside it: the
/// layers are copied into the EXR's channel list, and writing it takes twice that again
/// (`filtrace_io::write_exr` copies the channels, and the `exr` crate its blocks: measured,
/// `crates/cli/tests/memory.rs`), plus the encoded file, held whole until it is written
/// atomically (at most the raw size: compression never grows it much); the PNG's 8-bit
/// buffer and its encoder's output are 3 bytes per pixel each.
pub fn output_bytes(w: u32, h: u32, channels: u32) -> u64 {
    let pixels = w as u64 * h as u64;
    4 * image_bytes(w, h, channels) + 2 * 3 * pixels
}

/// A plain `render` of `w x h`: the film, its AOV images and per-pixel sample counts, and
/// the EXR + PNG output, all alive while the EXR is written. Independent of the sample
/// count (the film keeps sums).
pub fn plain_render(w: u32, h: u32) -> MemoryEstimate {
    MemoryEstimate::new(format!("a {w}x{h} render"))
        .with("film", film_bytes(w, h))
        .with("AOV images", image_bytes(w, h, AOV_CHANNELS + 1))
        .with("EXR and PNG output", output_bytes(w, h, AOV_CHANNELS + 1))
}

/// Memory the machine has for this process, and where the number comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Available {
    pub bytes: u64,
    pub source: String,
}

/// What the machine has: [`LIMIT_ENV`] if set, else Linux's `MemAvailable` (capped by a
/// cgroup v2 limit), else `None` (unknown). A malformed [`LIMIT_ENV`] is an error.
pub fn available() -> Result<Option<Available>, String> {
    if let Ok(v) = std::env::var(LIMIT_ENV) {
        let bytes = parse_bytes(&v)
            .ok_or_else(|| format!("{LIMIT_ENV}={v:?} is not a byte count (e.g. 1073741824, 512M or 8G)"))?;
        return Ok(Some(Available { bytes, source: LIMIT_ENV.to_string() }));
    }
    let Some(meminfo) = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| mem_available(&s)) else {
        return Ok(None);
    };
    let mut a = Available { bytes: meminfo, source: "MemAvailable in /proc/meminfo".into() };
    if let Some(free) = cgroup_free() {
        if free < a.bytes {
            a = Available { bytes: free, source: "this process's cgroup memory.max".into() };
        }
    }
    Ok(Some(a))
}

/// `MemAvailable` of a `/proc/meminfo` text, in bytes.
pub fn mem_available(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let mut it = line["MemAvailable:".len()..].split_whitespace();
    let value: u64 = it.next()?.parse().ok()?;
    match it.next() {
        Some("kB") => value.checked_mul(1024),
        None => Some(value),
        _ => None,
    }
}

/// Room left under the cgroup v2 limit of this process (`memory.max - memory.current`),
/// `None` without a limit.
fn cgroup_free() -> Option<u64> {
    let cgroup = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let path = cgroup.lines().find_map(|l| l.strip_prefix("0::"))?;
    let dir = std::path::Path::new("/sys/fs/cgroup").join(path.trim_start_matches('/'));
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).ok();
    let max: u64 = read("memory.max")?.trim().parse().ok()?; // "max" = no limit
    let current: u64 = read("memory.current")?.trim().parse().ok()?;
    Some(max.saturating_sub(current))
}

/// A byte count: digits, optionally followed by `K`, `M`, `G` or `T` (powers of 1024, an
/// optional `i`/`iB`/`B` after it).
pub fn parse_bytes(s: &str) -> Option<u64> {
    let s = s.trim();
    let digits = s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len());
    let value: u64 = s[..digits].parse().ok()?;
    let shift = match s[digits..].trim().to_ascii_uppercase().trim_end_matches('B').trim_end_matches('I') {
        "" => 0,
        "K" => 10,
        "M" => 20,
        "G" => 30,
        "T" => 40,
        _ => return None,
    };
    value.checked_mul(1u64 << shift)
}

/// A render refused before it started because it would not fit in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryError {
    pub needs: MemoryEstimate,
    pub available: Available,
}

impl fmt::Display for MemoryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "not enough memory: needs {} plus the scene; this machine has {} available ({})",
            self.needs,
            Bytes(self.available.bytes),
            self.available.source
        )?;
        if !self.needs.hint.is_empty() {
            write!(f, ". {}", self.needs.hint)?;
        }
        Ok(())
    }
}

impl std::error::Error for MemoryError {}

/// Refuses `needs` when it is more than `available` (nothing is refused when the
/// available memory is unknown).
pub fn check_against(needs: &MemoryEstimate, available: Option<&Available>) -> Result<(), MemoryError> {
    match available {
        Some(a) if needs.total() > a.bytes => Err(MemoryError { needs: needs.clone(), available: a.clone() }),
        _ => Ok(()),
    }
}

/// [`check_against`] what this machine has ([`available`]).
pub fn check(needs: &MemoryEstimate) -> Result<(), String> {
    let a = available()?;
    check_against(needs, a.as_ref()).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_counts_parse_with_binary_suffixes() {
        assert_eq!(parse_bytes("1234"), Some(1234));
        assert_eq!(parse_bytes(" 512M "), Some(512 << 20));
        assert_eq!(parse_bytes("8G"), Some(8 << 30));
        assert_eq!(parse_bytes("8GiB"), Some(8 << 30));
        assert_eq!(parse_bytes("3k"), Some(3 << 10));
        for bad in ["", "G", "1.5G", "-1", "12X", "99999999999999999999", "20000000000T"] {
            assert_eq!(parse_bytes(bad), None, "{bad}");
        }
    }

    #[test]
    fn mem_available_reads_kilobytes() {
        let s = "MemTotal:       24684084 kB\nMemFree: 1 kB\nMemAvailable:   23273712 kB\n";
        assert_eq!(mem_available(s), Some(23273712 * 1024));
        assert_eq!(mem_available("MemTotal: 5 kB\n"), None);
    }

    #[test]
    fn the_refusal_names_what_is_needed_and_what_there_is() {
        let needs = plain_render(16384, 16384).with_hint("lower --res");
        let a = Available { bytes: 24 << 30, source: "test".into() };
        let e = check_against(&needs, Some(&a)).unwrap_err().to_string();
        for want in ["16384x16384", "film 36.0 GiB", "24.0 GiB available", "lower --res"] {
            assert!(e.contains(want), "{want:?} missing in: {e}");
        }
        assert!(check_against(&plain_render(64, 64), Some(&a)).is_ok());
        assert!(check_against(&needs, None).is_ok(), "unknown memory: no refusal");
    }

    #[test]
    fn impossible_allocations_are_errors() {
        let e = try_vec(usize::MAX / 8, 0u64, "the test buffer").unwrap_err();
        assert!(e.to_string().contains("the test buffer"), "{e}");
        assert_eq!(try_vec(3, 7u8, "x").unwrap(), vec![7, 7, 7]);
    }
}
