//! Shared by the fuzz tests of every parser (scene loaders here, EXR in `filtrace-io`, which
//! includes this file by path): structure-aware mutations of valid seed files, a per-case
//! time limit, and a memory limit for the whole test.
//!
//! - [`Mutation`]: byte flips, truncations, splices, deletions and numeric extremes (1e38,
//!   NaN, -0, huge counts) written over number tokens or as raw 32-bit words. Mutating a valid
//!   file reaches far deeper into a parser than random bytes, which fail at the first check.
//! - [`Watchdog`]: a case that runs longer than its limit ends the process with the case named
//!   (a hang fails the test instead of stalling CI).
//! - [`limited_child`]: the test re-runs itself in a child process under `prlimit --as`, so
//!   unbounded growth fails one test instead of taking the machine down.
#![allow(dead_code)]

use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use proptest::prelude::*;

/// Address-space limit of a fuzz child process. Large enough for the test harness and a
/// plausible scene, small enough that an allocation sized by a hostile count fails.
pub const MEMORY_LIMIT_BYTES: u64 = 2 << 30;

/// Cases of the fast tier (seconds per parser) and of the `#[ignore]` slow tier (< ~60 s).
pub const FAST_CASES: u32 = 200;
pub const SLOW_CASES: u32 = 10_000;

/// Longest a single case may take before it counts as a hang.
pub const CASE_LIMIT: Duration = Duration::from_secs(10);

const ENV_CHILD: &str = "FILTRACE_FUZZ_CHILD";

/// True in the memory-limited child, which runs the fuzz body. In the parent, runs the test
/// `name` (module path inside the test binary) in such a child, asserts it passed, and
/// returns false. `ignored`: the test is in the `#[ignore]` tier (the child needs `--ignored`).
pub fn limited_child(name: &str, ignored: bool) -> bool {
    if std::env::var_os(ENV_CHILD).is_some() {
        return true;
    }
    let exe = std::env::current_exe().expect("test binary path");
    let mut args = vec![name.to_string(), "--exact".into(), "--nocapture".into(), "--test-threads=1".into()];
    if ignored {
        args.push("--ignored".into());
    }
    let mut cmd = if Command::new("prlimit").arg("--version").output().is_ok() {
        let mut c = Command::new("prlimit");
        c.arg(format!("--as={MEMORY_LIMIT_BYTES}")).arg("--").arg(&exe).args(&args);
        c
    } else {
        // No util-linux: the shell's ulimit (in KiB) does the same.
        let mut c = Command::new("sh");
        c.arg("-c").arg(format!("ulimit -v {} && exec \"$0\" \"$@\"", MEMORY_LIMIT_BYTES >> 10));
        c.arg(&exe).args(&args);
        c
    };
    let out = cmd.env(ENV_CHILD, "1").output().expect("run the fuzz child");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && stdout.contains("1 passed"),
        "fuzz child {name} failed ({}) under a {} MiB address-space limit\n--- stdout\n{}\n--- stderr\n{}",
        out.status,
        MEMORY_LIMIT_BYTES >> 20,
        tail(&stdout),
        tail(&stderr)
    );
    false
}

fn tail(s: &str) -> &str {
    let n = s.len().saturating_sub(6000);
    let mut i = n;
    while !s.is_char_boundary(i) {
        i += 1;
    }
    &s[i..]
}

/// Ends the process when one case runs longer than its limit, naming the case.
pub struct Watchdog {
    current: Arc<Mutex<(Instant, String)>>,
}

impl Watchdog {
    pub fn new(limit: Duration) -> Self {
        let current = Arc::new(Mutex::new((Instant::now(), String::from("(start)"))));
        let seen = Arc::downgrade(&current);
        std::thread::spawn(move || loop {
            std::thread::sleep(Duration::from_millis(100));
            let Some(cur) = seen.upgrade() else { return };
            let (start, what) = cur.lock().map(|g| g.clone()).unwrap_or_else(|e| e.into_inner().clone());
            if start.elapsed() > limit {
                eprintln!("HANG: a case ran over {limit:?}: {what}");
                std::process::exit(3);
            }
        });
        Watchdog { current }
    }

    /// Starts the clock for a new case described by `what` (printed if it hangs).
    pub fn case(&self, what: impl Into<String>) {
        let mut g = self.current.lock().unwrap_or_else(|e| e.into_inner());
        *g = (Instant::now(), what.into());
    }
}

/// Values that break parsers: huge, tiny, negative, non-finite, signed zero, counts near the
/// integer limits.
pub const EXTREME_NUMBERS: &[&str] = &[
    "1e38",
    "-1e38",
    "3.5e38",
    "1e-45",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "-0",
    "0",
    "-1",
    "1e308",
    "4294967295",
    "4294967296",
    "2147483647",
    "-2147483648",
    "18446744073709551615",
    "99999999999999999999",
    "65535",
    "1",
];

/// Raw 32-bit words for binary formats (lengths, counts, offsets, float bits).
pub const EXTREME_WORDS: &[u32] = &[
    0,
    1,
    0xFFFF_FFFF,
    0x7FFF_FFFF,
    0x8000_0000,
    0x0001_0000,
    0x7FC0_0000,
    0x7F80_0000,
    0x8000_0001,
    0x1000_0000,
];

/// One edit of a seed file; positions are taken modulo the current length.
#[derive(Clone, Debug)]
pub enum Mutation {
    /// Replace the byte at `pos` with `byte`.
    Flip { pos: usize, byte: u8 },
    /// Cut the file at `pos`.
    Truncate { pos: usize },
    /// Copy `len` bytes from `from` to before `to` (splice of the file with itself).
    Splice { from: usize, len: usize, to: usize },
    /// Delete `len` bytes at `pos`.
    Delete { pos: usize, len: usize },
    /// Replace the `k`-th number token (ASCII digits, sign, point, exponent) with an extreme.
    Number { k: usize, value: usize },
    /// Overwrite 4 bytes at `pos` with an extreme little-endian word.
    Word { pos: usize, value: usize },
}

pub fn mutation() -> impl Strategy<Value = Mutation> {
    let p = any::<usize>();
    prop_oneof![
        2 => (p, any::<u8>()).prop_map(|(pos, byte)| Mutation::Flip { pos, byte }),
        1 => p.prop_map(|pos| Mutation::Truncate { pos }),
        1 => (p, 1usize..64, p).prop_map(|(from, len, to)| Mutation::Splice { from, len, to }),
        1 => (p, 1usize..32).prop_map(|(pos, len)| Mutation::Delete { pos, len }),
        4 => (p, 0..EXTREME_NUMBERS.len()).prop_map(|(k, value)| Mutation::Number { k, value }),
        2 => (p, 0..EXTREME_WORDS.len()).prop_map(|(pos, value)| Mutation::Word { pos, value }),
    ]
}

/// One to `max` mutations.
pub fn mutations(max: usize) -> impl Strategy<Value = Vec<Mutation>> {
    prop::collection::vec(mutation(), 1..=max)
}

/// Byte ranges of the number tokens of `b` (ASCII text; binary bytes simply give few).
fn number_tokens(b: &[u8]) -> Vec<(usize, usize)> {
    let is_num = |c: u8| c.is_ascii_digit() || matches!(c, b'-' | b'+' | b'.' | b'e' | b'E');
    let mut v = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit()
            || (matches!(b[i], b'-' | b'.') && b.get(i + 1).is_some_and(u8::is_ascii_digit))
        {
            let s = i;
            while i < b.len() && is_num(b[i]) {
                i += 1;
            }
            v.push((s, i));
        } else {
            i += 1;
        }
    }
    v
}

/// `seed` with `muts` applied in order.
pub fn apply(seed: &[u8], muts: &[Mutation]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for m in muts {
        let n = b.len().max(1);
        match *m {
            Mutation::Flip { pos, byte } => {
                if !b.is_empty() {
                    b[pos % n] = byte;
                }
            }
            Mutation::Truncate { pos } => b.truncate(pos % n),
            Mutation::Splice { from, len, to } => {
                let from = from % n;
                let piece: Vec<u8> = b.iter().skip(from).take(len).copied().collect();
                let to = (to % n).min(b.len());
                b.splice(to..to, piece);
            }
            Mutation::Delete { pos, len } => {
                let pos = (pos % n).min(b.len());
                let end = (pos + len).min(b.len());
                b.drain(pos..end);
            }
            Mutation::Number { k, value } => {
                let toks = number_tokens(&b);
                if !toks.is_empty() {
                    let (s, e) = toks[k % toks.len()];
                    b.splice(s..e, EXTREME_NUMBERS[value].bytes());
                }
            }
            Mutation::Word { pos, value } => {
                if b.len() >= 4 {
                    let p = pos % (b.len() - 3);
                    b[p..p + 4].copy_from_slice(&EXTREME_WORDS[value].to_le_bytes());
                }
            }
        }
    }
    b
}

/// A folder under the system temp dir for one fuzz test (emptied first).
pub fn temp_dir(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("filtrace-fuzz-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create the fuzz temp dir");
    dir
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn number_mutation_replaces_a_whole_token() {
        let out = apply(b"count: 12.5e3, x -4", &[Mutation::Number { k: 1, value: 4 }]);
        assert_eq!(out, b"count: 12.5e3, x NaN");
    }
}
