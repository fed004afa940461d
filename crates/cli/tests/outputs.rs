//! Outputs through the binary (issue 17): a failed write never destroys what was at the
//! path, unwritable outputs are refused before the work, stdout that is a closed pipe or a
//! full device ends in a clear exit (never a panic), and options that would give a wrong
//! result silently (NaN exposure, zero indirect paths, an unknown filter) are refused.

#[path = "support/run.rs"]
mod run;

use run::{bin, run_within, stderr};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Duration;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-outputs-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn quick(cmd: &mut Command) -> Output {
    run_within(cmd, Duration::from_secs(60))
}

/// A 8x8 render of the Cornell box at `path` (1 spp).
fn render_tiny(path: &Path) {
    let o = quick(bin().args(["render", "--res", "8x8", "--spp", "1", "--threads", "1", "--out"]).arg(path));
    assert!(o.status.success(), "{}", stderr(&o));
}

fn assert_no_panic(o: &Output) {
    let e = stderr(o);
    assert!(!e.contains("panicked") && o.status.code() != Some(101), "panic: {e}");
}

/// `filtrace compare a.exr b.exr | true` and `render --json | true` panicked (exit 101).
#[test]
fn a_closed_stdout_pipe_ends_quietly_with_code_141() {
    let dir = temp_dir("pipe");
    let exr = dir.join("a.exr");
    render_tiny(&exr);
    let compare = ["compare", "a.exr", "a.exr", "--no-maps"];
    let render = ["render", "--res", "4x4", "--spp", "1", "--json", "--out", "b.exr"];
    for args in [&compare[..], &render[..]] {
        // The reader is closed before the child starts: dropping it after `spawn` raced
        // with a fast command on a loaded machine, which then wrote into the open pipe.
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let child = bin().args(args).current_dir(&dir).stdout(writer).stderr(Stdio::piped()).spawn().unwrap();
        let o = child.wait_with_output().unwrap();
        assert_no_panic(&o);
        assert_eq!(o.status.code(), Some(141), "{args:?}: {}", stderr(&o));
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `render --json > /dev/full` panicked; now: a message and exit code 1.
#[cfg(target_os = "linux")]
#[test]
fn a_full_stdout_is_a_clear_error() {
    let dir = temp_dir("full");
    let exr = dir.join("a.exr");
    render_tiny(&exr);
    let compare = ["compare", "a.exr", "a.exr", "--no-maps"];
    let render = ["render", "--res", "4x4", "--spp", "1", "--json", "--out", "b.exr"];
    let bench = ["bench", "filters", "--res", "8x8", "--repeats", "1", "--only", "guided"];
    for args in [&compare[..], &render[..], &bench[..]] {
        let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
        let o = bin().args(args).current_dir(&dir).stdout(full).output().unwrap();
        assert_no_panic(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains("cannot write to standard output"), "{args:?}: {}", stderr(&o));
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Before the fix the `exr` writer deleted the output on a write error (here the link that
/// stands for it); now the write fails, and nothing is removed.
#[cfg(target_os = "linux")]
#[test]
fn a_render_whose_write_fails_removes_nothing() {
    let dir = temp_dir("devfull");
    let link = dir.join("out.exr");
    std::os::unix::fs::symlink("/dev/full", &link).unwrap();
    let o = quick(bin().args(["render", "--res", "4x4", "--spp", "1", "--out"]).arg(&link));
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("out.exr"), "{}", stderr(&o));
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link is kept");
    std::fs::remove_dir_all(&dir).ok();
}

/// An existing output is replaced whole by a new render, and no temporary file is left.
#[test]
fn a_render_replaces_an_existing_output_and_leaves_no_temporary() {
    let dir = temp_dir("replace");
    let exr = dir.join("a.exr");
    std::fs::write(&exr, b"old").unwrap();
    render_tiny(&exr);
    assert!(filtrace_io::read_exr(&exr).is_ok());
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["a.exr", "a.png"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// Unwritable outputs are refused before a render that would take minutes (before the fix a
/// folder in the way of the PNG, or an output in /sys, failed only after the render).
#[test]
fn unwritable_outputs_are_refused_before_the_render() {
    let dir = temp_dir("preflight");
    std::fs::create_dir(dir.join("blocked.png")).unwrap();
    let mut cases = vec![dir.join("blocked.exr")];
    if Path::new("/sys/kernel").is_dir() {
        cases.push(PathBuf::from("/sys/filtrace-test.exr"));
    }
    for out in &cases {
        let o = run_within(
            bin().args(["render", "--res", "512x512", "--spp", "100000", "--threads", "1", "--out"]).arg(out),
            Duration::from_secs(60),
        );
        assert_no_panic(&o);
        assert_eq!(o.status.code(), Some(1), "{}", out.display());
        assert!(stderr(&o).contains("cannot be written"), "{}", stderr(&o));
    }
    assert!(!dir.join("blocked.exr").exists(), "nothing was written");
    std::fs::remove_dir_all(&dir).ok();
}

/// `compare x.exr x.relmse.exr` wrote its relMSE map over its own reference.
#[test]
fn compare_refuses_to_write_a_map_over_an_input() {
    let dir = temp_dir("compare");
    let image = dir.join("x.exr");
    render_tiny(&image);
    let reference = dir.join("x.relmse.exr");
    render_tiny(&reference);
    let before = std::fs::read(&reference).unwrap();
    let o = quick(bin().arg("compare").arg(&image).arg(&reference));
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("would overwrite an input"), "{}", stderr(&o));
    assert_eq!(std::fs::read(&reference).unwrap(), before, "the reference is untouched");
    // Through another name of the same file (canonicalised): refused as well.
    let o = quick(bin().arg("compare").arg(&image).arg(dir.join(".").join("x.relmse.exr")));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    // Maps elsewhere are fine.
    let o = quick(bin().arg("compare").arg(&image).arg(&reference).arg("--out-dir").arg(dir.join("maps")));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.join("maps/x.relmse.exr").is_file());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn experiment_refuses_an_unwritable_report_before_running() {
    let dir = temp_dir("experiment");
    std::fs::create_dir_all(dir.join("report.html")).unwrap();
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/tiny.toml");
    let o = quick(bin().arg("experiment").arg(&spec).arg("--out").arg(&dir));
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("report.html"), "{}", stderr(&o));
    assert!(!dir.join("cache").exists(), "nothing was run");
    std::fs::remove_dir_all(&dir).ok();
}

/// Values that gave a wrong result with exit code 0 are refused with a message naming them.
#[test]
fn nonsense_option_values_are_refused() {
    let cases: [(&[&str], &str); 7] = [
        (&["render", "--exposure", "nan"], "--exposure"),
        (&["render", "--exposure", "inf"], "--exposure"),
        (&["render", "--exposure=-inf"], "--exposure"),
        (&["render", "--filter", "atrous", "--indirect-paths", "0"], "--indirect-paths"),
        (&["bench", "pipeline", "--indirect-paths", "0"], "--indirect-paths"),
        (&["bench", "filters", "--only", "zzz"], "a-trous, cross-bilateral, guided"),
        (&["bench", "filters", "--only", "cross", "--no-bilateral"], "selects no filter"),
    ];
    // In a temporary folder: a value accepted by mistake renders there, not into the repo.
    let dir = temp_dir("values");
    for (args, want) in cases {
        let o = quick(bin().args(args).current_dir(&dir));
        assert_no_panic(&o);
        assert!(!o.status.success(), "{args:?} accepted");
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn help_states_the_pixel_cap() {
    for args in [&["render", "--help"][..], &["bench", "pipeline", "--help"], &["bench", "render", "--help"]]
    {
        let o = quick(bin().args(args));
        assert!(o.status.success());
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.contains("32768"), "{args:?}: {text}");
    }
}
