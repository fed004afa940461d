//! Ctrl-C (SIGINT) at known points of `filtrace render`, plain, `--filter` and
//! `--adaptive` (issue 17, defects 2-4). The binary's test hook (`FILTRACE_TEST_PAUSE`,
//! `cmd::render::test_hook`) prints `filtrace-test: STAGE` on stderr at each stage and
//! waits at the one it names, so the signal lands where each test wants it.
#![cfg(unix)]

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::time::{Duration, Instant};

/// A running `filtrace` whose stderr lines arrive on `lines` (and are kept in `seen`).
struct Run {
    child: Child,
    lines: Receiver<String>,
    seen: Vec<String>,
}

/// What a finished run left: exit status, stdout, every stderr line.
struct Done {
    status: ExitStatus,
    stdout: String,
    stderr: String,
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-cancel-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Starts `filtrace ARGS --out OUT` with the test hook pausing at `pause` (a stage name;
/// any other value only prints the stage markers).
fn start(args: &[&str], out: &Path, pause: &str) -> Run {
    let mut child = Command::new(env!("CARGO_BIN_EXE_filtrace"))
        .args(args)
        .arg("--out")
        .arg(out)
        .env("FILTRACE_TEST_PAUSE", pause)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the filtrace binary starts");
    let stderr = child.stderr.take().unwrap();
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    Run { child, lines, seen: Vec::new() }
}

impl Run {
    /// Waits (at most 60 s) for the stderr line `filtrace-test: STAGE`.
    fn wait_for(&mut self, stage: &str) {
        let want = format!("filtrace-test: {stage}");
        let deadline = Instant::now() + Duration::from_secs(60);
        while Instant::now() < deadline {
            if let Ok(line) = self.lines.recv_timeout(Duration::from_millis(50)) {
                let hit = line == want;
                self.seen.push(line);
                if hit {
                    return;
                }
            } else if self.child.try_wait().unwrap().is_some() {
                break;
            }
        }
        let _ = self.child.kill();
        panic!("no '{want}' on stderr; saw: {:?}", self.seen);
    }

    fn sigint(&self) {
        let ok = Command::new("kill").args(["-INT", &self.child.id().to_string()]).status().unwrap();
        assert!(ok.success(), "kill -INT failed");
    }

    /// Waits for the exit; panics (killing the process) after `limit`.
    fn finish(mut self, limit: Duration) -> Done {
        let start = Instant::now();
        while self.child.try_wait().unwrap().is_none() {
            if start.elapsed() > limit {
                let _ = self.child.kill();
                panic!("still running {limit:?} after SIGINT; stderr so far: {:?}", self.seen);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let mut stdout = String::new();
        self.child.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
        let status = self.child.wait().unwrap();
        // The reader thread ends with the pipe; collect what is left.
        self.seen.extend(self.lines.iter());
        Done { status, stdout, stderr: self.seen.join("\n") }
    }
}

fn json(d: &Done) -> serde_json::Value {
    serde_json::from_str(&d.stdout).unwrap_or_else(|e| panic!("stdout is not JSON ({e}): {}", d.stdout))
}

/// An `out.exr` and `out.png` holding known bytes, as a previous render would have left.
fn old_outputs(dir: &Path) -> (PathBuf, [(PathBuf, Vec<u8>); 2]) {
    let exr = dir.join("out.exr");
    let files =
        [(exr.clone(), b"an earlier render".to_vec()), (exr.with_extension("png"), b"its png".to_vec())];
    for (p, bytes) in &files {
        std::fs::write(p, bytes).unwrap();
    }
    (exr, files)
}

fn assert_untouched(files: &[(PathBuf, Vec<u8>)], d: &Done) {
    for (p, bytes) in files {
        assert_eq!(&std::fs::read(p).unwrap(), bytes, "{} was changed; stderr: {}", p.display(), d.stderr);
    }
}

const PLAIN: &[&str] = &["render", "cornell", "--res", "32x24", "--spp", "64", "--threads", "2", "--json"];
const FILTERED: &[&str] =
    &["render", "cornell", "--res", "32x24", "--spp", "4", "--threads", "2", "--json", "--filter", "atrous"];
const ADAPTIVE: &[&str] =
    &["render", "cornell", "--res", "32x24", "--spp", "4", "--threads", "2", "--json", "--adaptive"];

/// Defect 3: Ctrl-C while loading or building exits at once (the hook would wait 10 s),
/// with code 130 and a message, and leaves the earlier output as it was.
#[test]
fn ctrl_c_while_loading_or_building_exits_at_once_and_writes_nothing() {
    let dir = temp_dir("load");
    for args in [PLAIN, FILTERED, ADAPTIVE] {
        for stage in ["loaded", "built"] {
            let (out, files) = old_outputs(&dir);
            let mut run = start(args, &out, stage);
            run.wait_for(stage);
            run.sigint();
            let d = run.finish(Duration::from_secs(5));
            assert_eq!(d.status.code(), Some(130), "{args:?} at {stage}: {}", d.stderr);
            assert!(d.stderr.contains("nothing written"), "{args:?} at {stage}: {}", d.stderr);
            assert!(d.stdout.is_empty(), "{args:?} at {stage}: {}", d.stdout);
            assert_untouched(&files, &d);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Ctrl-C once the render has started but before any pass (or the guide rays) ended:
/// no pixel may be written as black for want of a sample, so nothing is written.
#[test]
fn ctrl_c_before_every_pixel_has_a_sample_writes_nothing() {
    let dir = temp_dir("first");
    for args in [PLAIN, FILTERED, ADAPTIVE] {
        let (out, files) = old_outputs(&dir);
        let mut run = start(args, &out, "rendering");
        run.wait_for("rendering");
        run.sigint();
        let d = run.finish(Duration::from_secs(10));
        assert_eq!(d.status.code(), Some(130), "{args:?}: {}", d.stderr);
        assert!(d.stderr.contains("nothing written"), "{args:?}: {}", d.stderr);
        assert_untouched(&files, &d);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Per channel: the image mean and the variance of that mean from the per-pixel variances
/// of the mean (pixels are estimated independently).
fn mean_and_variance(color: &filtrace_core::Image, variance: &filtrace_core::Image) -> [(f64, f64); 3] {
    let n = color.pixel_count() as f64;
    std::array::from_fn(|c| {
        let m: f64 = color.data().chunks_exact(3).map(|p| p[c] as f64).sum::<f64>() / n;
        let v: f64 = variance.data().chunks_exact(3).map(|p| p[c] as f64).sum::<f64>() / (n * n);
        (m, v)
    })
}

/// Defect 2: Ctrl-C in the middle of a pass of a render asked for 2^32 - 1 samples per
/// pixel (one pass of 268 M samples before the fix, which ignored Ctrl-C, and whose tiles
/// not reached came out black). Now: it stops at once, every pixel is the mean of its own
/// samples (the `samples` layer, between n and 2n), the image's mean agrees with a full
/// render's within the noise, and the header says what was asked and done.
#[test]
fn ctrl_c_during_the_passes_writes_an_unbiased_image_with_its_sample_counts() {
    let dir = temp_dir("passes");
    let out = dir.join("cut.exr");
    let (w, h) = (64, 48);
    let args = ["render", "cornell", "--res", "64x48", "--spp", "4294967295", "--threads", "2", "--json"];
    // Markers only (no stage is called "-"): the signal goes out as the pass that doubles
    // 64 samples per pixel to 128 starts.
    let mut run = start(&args, &out, "-");
    run.wait_for("pass 64");
    run.sigint();
    let d = run.finish(Duration::from_secs(10));
    assert_eq!(d.status.code(), Some(130), "{}", d.stderr);
    assert!(d.stderr.contains("cancelled: wrote"), "{}", d.stderr);
    let j = json(&d);
    assert_eq!(j["cancelled"], true);
    let (done, max) = (j["spp_done"].as_u64().unwrap(), j["spp_max"].as_u64().unwrap());
    assert!(done >= 64 && done <= max && max <= 2 * done, "spp_done {done}, spp_max {max}");

    let exr = filtrace_io::read_exr(&out).unwrap();
    assert_eq!(exr.attribute("filtrace:cancelled"), Some("true"));
    assert_eq!(exr.attribute("filtrace:spp_requested"), Some("4294967295"));
    assert_eq!(exr.attribute("filtrace:spp_done"), Some(done.to_string().as_str()));
    let counts = exr.layer(&["samples"]).expect("samples layer");
    let lo = counts.data().iter().fold(f32::MAX, |a, &b| a.min(b));
    let hi = counts.data().iter().fold(0f32, |a, &b| a.max(b));
    assert_eq!((lo as u64, hi as u64), (done, max), "the samples layer holds the per-pixel counts");

    // The full render's mean (same seed: the cut image's samples are a prefix of it, so the
    // difference is no noisier than the sum of the two variances assumed here).
    let scene = filtrace_scene::load_scene("cornell").unwrap();
    let settings = filtrace_render::RenderSettings { width: w, height: h, spp: 64, max_depth: 8, seed: 0 };
    let full = filtrace_render::Renderer::new(scene, settings).unwrap();
    let a = full.render(&std::sync::atomic::AtomicBool::new(false)).aovs();
    let want = mean_and_variance(&a.color, &a.variance);
    let got = mean_and_variance(&exr.layer(&["color"]).unwrap(), &exr.layer(&["variance"]).unwrap());
    for c in 0..3 {
        let ((m, v), (mr, vr)) = (got[c], want[c]);
        let z = (m - mr) / (v + vr).sqrt().max(1e-9);
        assert!(z.abs() < 5.0 && (m - mr).abs() < 0.05 * mr, "channel {c}: mean {m} vs {mr} (z {z:.2})");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Defect 4: Ctrl-C during the further samples of `--filter` and `--adaptive` writes the
/// frame of the samples done (exit 130), its header saying how many.
#[test]
fn ctrl_c_in_filtered_and_adaptive_renders_writes_the_frame_so_far() {
    let dir = temp_dir("filtered");
    let base = ["render", "cornell", "--res", "16x16", "--spp", "4096", "--max-depth", "3", "--threads", "1"];
    for extra in [&["--filter", "atrous"][..], &["--adaptive", "--budget-spp", "1"][..]] {
        let out = dir.join("frame.exr");
        let args: Vec<&str> = base.iter().chain(extra).chain(&["--json"]).copied().collect();
        let mut run = start(&args, &out, "-");
        run.wait_for("rendering");
        // The guide rays of 256 pixels take about a millisecond, the 4095 further samples
        // of each pixel far longer: the signal lands among the further samples.
        std::thread::sleep(Duration::from_millis(30));
        run.sigint();
        let d = run.finish(Duration::from_secs(10));
        assert_eq!(d.status.code(), Some(130), "{extra:?}: {}", d.stderr);
        assert!(d.stderr.contains("cancelled: wrote the frame"), "{extra:?}: {}", d.stderr);
        let j = json(&d);
        assert_eq!(j["cancelled"], true, "{extra:?}");
        let done = j["spp_done"].as_u64().unwrap();
        assert!((1..=4096).contains(&done), "{extra:?}: spp_done {done}");
        let exr = filtrace_io::read_exr(&out).unwrap();
        assert_eq!(exr.attribute("filtrace:cancelled"), Some("true"), "{extra:?}");
        assert_eq!(exr.attribute("filtrace:spp_requested"), Some("4096"), "{extra:?}");
        assert_eq!(exr.attribute("filtrace:spp_done"), Some(done.to_string().as_str()), "{extra:?}");
        let color = exr.layer(&["color"]).unwrap();
        assert_eq!(color.count_non_finite(), 0, "{extra:?}");
        assert!(color.mean()[0] > 0.01, "{extra:?}: black frame");
        std::fs::remove_file(&out).ok();
    }
    std::fs::remove_dir_all(&dir).ok();
}
