//! Running the `filtrace` binary from the cli's sequence tests: outputs, EXR channels and
//! Ctrl-C at a test-hook stage (included with `#[path]`; not every file uses every helper).
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_filtrace"))
}

/// An empty directory `filtrace-NAME-PID` in the system's temp dir.
pub fn fresh_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn ok(o: Output) -> Output {
    assert!(o.status.success(), "failed: {}", stderr(&o));
    o
}

/// Runs `cmd` to its end, failing the test (and killing it) after `limit`: a check that
/// should come before a long render (or a large allocation) must not wait for it.
pub fn run_within(cmd: &mut Command, limit: Duration) -> Output {
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("the binary runs");
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            child.kill().ok();
            child.wait().ok();
            panic!("{cmd:?} still running after {limit:?}: the check did not come before the work");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// Every line of stdout as JSON.
pub fn json_lines(o: &Output) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not a JSON line ({e}): {l}")))
        .collect()
}

/// Each channel of the EXR at `path`, by name, as bits.
pub fn channel_bits(path: &Path) -> Vec<(String, Vec<u32>)> {
    let exr = filtrace_io::read_exr(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut names = exr.channel_names();
    names.sort();
    names
        .into_iter()
        .map(|n| (n.clone(), exr.channel(&n).unwrap().iter().map(|v| v.to_bits()).collect()))
        .collect()
}

/// Starts `filtrace ARGS` pausing at test-hook stage `pause`; returns it and its stderr lines.
#[cfg(unix)]
pub fn start(args: &[&str], pause: &str) -> (std::process::Child, std::sync::mpsc::Receiver<String>) {
    let mut child = bin()
        .args(args)
        .env("FILTRACE_TEST_PAUSE", pause)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let err = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (child, rx)
}

/// Waits (at most 60 s) for `filtrace-test: STAGE`, then `delay`, sends SIGINT and waits
/// for the exit; returns the exit code, stdout and stderr.
#[cfg(unix)]
pub fn interrupt_at(
    args: &[&str],
    pause: &str,
    stage: &str,
    delay: Duration,
) -> (Option<i32>, String, String) {
    let (mut child, lines) = start(args, pause);
    let mut seen = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while !seen.iter().any(|l: &String| l == &format!("filtrace-test: {stage}")) {
        assert!(Instant::now() < deadline, "no stage '{stage}': {seen:?}");
        if let Ok(l) = lines.recv_timeout(Duration::from_millis(50)) {
            seen.push(l);
        }
    }
    std::thread::sleep(delay);
    Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        assert!(start.elapsed() < Duration::from_secs(20), "still running after SIGINT");
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut stdout = String::new();
    child.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
    seen.extend(lines.iter());
    (child.wait().unwrap().code(), stdout, seen.join("\n"))
}
