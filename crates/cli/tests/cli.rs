//! The `filtrace` binary end to end: render → EXR layers and JSON keys, bad input gives a
//! message and a non-zero exit (never a panic), compare of identical images gives 0,
//! Ctrl-C writes the partial render and exits 130.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_filtrace"))
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-cli-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(cmd: &mut Command) -> Output {
    cmd.output().expect("the filtrace binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn render_tiny(dir: &Path, name: &str) -> (PathBuf, serde_json::Value) {
    let out = dir.join(format!("{name}.exr"));
    let o = run(bin()
        .args(["render", "cornell", "--res", "32x32", "--spp", "2", "--threads", "2", "--json", "--out"])
        .arg(&out));
    assert!(o.status.success(), "render failed: {}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is one JSON object");
    (out, json)
}

#[test]
fn render_writes_every_layer_and_a_complete_json_summary() {
    let dir = temp_dir("render");
    let (out, json) = render_tiny(&dir, "tiny");
    for key in [
        "scene",
        "res",
        "spp",
        "max_depth",
        "seed",
        "threads",
        "triangles",
        "build_s",
        "render_s",
        "samples_per_s",
        "mean_rgb",
        "output",
        "cancelled",
        "load_warnings",
        "degenerate_triangles_skipped",
        "nonfinite_samples",
    ] {
        assert!(json.get(key).is_some(), "JSON lacks '{key}': {json}");
    }
    assert_eq!(json["res"], "32x32");
    assert_eq!(json["spp"], 2);
    assert_eq!(json["threads"], 2);
    assert_eq!(json["cancelled"], false);
    assert!(json["triangles"].as_u64().unwrap() > 0);

    let exr = filtrace_io::read_exr(&out).unwrap();
    assert_eq!((exr.width(), exr.height()), (32, 32));
    for ch in [
        "R",
        "G",
        "B",
        "direct.R",
        "direct.G",
        "direct.B",
        "indirect.R",
        "indirect.G",
        "indirect.B",
        "albedo.R",
        "albedo.G",
        "albedo.B",
        "normal.X",
        "normal.Y",
        "normal.Z",
        "position.X",
        "position.Y",
        "position.Z",
        "depth.Z",
        "variance.R",
        "variance.G",
        "variance.B",
        "motion.X",
        "motion.Y",
        "prev_depth.Z",
        "prev_normal.X",
        "prev_normal.Y",
        "prev_normal.Z",
    ] {
        assert!(exr.channel(ch).is_some(), "missing channel {ch}: {:?}", exr.channel_names());
    }
    // The JSON mean is the mean of the colour layer that was written.
    let color = exr.layer(&["color"]).unwrap();
    let mean = color.mean();
    for k in 0..3 {
        let j = json["mean_rgb"][k].as_f64().unwrap();
        assert!((j - mean[k]).abs() < 1e-6, "{j} vs {}", mean[k]);
    }
    // The Cornell box is lit: a black image means nothing was rendered.
    assert!(mean.iter().all(|m| *m > 0.0));
    assert!(out.with_extension("png").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_input_exits_nonzero_with_a_message_and_no_panic() {
    let dir = temp_dir("bad");
    let toml = dir.join("broken.toml");
    std::fs::write(&toml, "this is [not = valid toml\n").unwrap();
    let missing = dir.join("no-such-scene.obj");
    let out = dir.join("x.exr");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec!["render".into(), missing.display().to_string()], "no-such-scene"),
        (vec!["render".into(), toml.display().to_string()], "broken.toml"),
        (vec!["render".into(), "no-such-builtin".into()], "no-such-builtin"),
        (vec!["render".into(), "--res".into(), "0x0".into()], "0x0"),
        (vec!["render".into(), "--res".into(), "abc".into()], "abc"),
        (vec!["render".into(), "--res".into(), "40000x40000".into()], "too large"),
        (vec!["render".into(), "--spp".into(), "0".into()], "at least 1"),
        (vec!["render".into(), "--threads".into(), "0".into()], "threads"),
        (
            vec!["compare".into(), missing.display().to_string(), missing.display().to_string()],
            "no-such-scene",
        ),
    ];
    for (args, needle) in cases {
        let o = run(bin().args(&args).arg("--out").arg(&out).current_dir(&dir));
        let o = if o.status.code() == Some(2) && stderr(&o).contains("--out") {
            // `compare` has no --out: run it without.
            run(bin().args(&args).current_dir(&dir))
        } else {
            o
        };
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
        assert!(err.contains(needle), "{args:?}: stderr does not mention '{needle}': {err}");
    }
    assert!(!out.exists(), "a failed render wrote {}", out.display());
    // The output name is checked before rendering.
    for bad_out in [dir.join("x.png"), dir.clone()] {
        let o = run(bin().args(["render", "--res", "8x8", "--spp", "1", "--out"]).arg(&bad_out));
        let err = stderr(&o);
        assert!(!o.status.success() && !err.contains("panicked"), "{err}");
        assert!(err.contains("exr"), "{err}");
    }
    assert!(!dir.join("x.png").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn compare_of_identical_images_is_zero_error() {
    let dir = temp_dir("compare");
    let (out, _) = render_tiny(&dir, "a");
    let maps = dir.join("maps");
    let o = run(bin().arg("compare").arg(&out).arg(&out).arg("--json").arg("--out-dir").arg(&maps));
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["mse"], 0.0);
    assert_eq!(j["rel_mse"], 0.0);
    assert_eq!(j["flip"], 0.0);
    assert_eq!(j["ssim"], 1.0);
    assert!(j["psnr"].is_null(), "identical images: infinite PSNR is null");
    for m in ["a.relmse.exr", "a.relmse.png", "a.flip.exr", "a.flip.png"] {
        assert!(maps.join(m).exists(), "{m} not written");
    }
    // A different seed is a different noisy image: non-zero error.
    let b = dir.join("b.exr");
    let o =
        run(bin().args(["render", "--res", "32x32", "--spp", "2", "--seed", "7", "--json", "--out"]).arg(&b));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(bin().arg("compare").arg(&b).arg(&out).arg("--json").arg("--no-maps"));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j["mse"].as_f64().unwrap() > 0.0 && j["flip"].as_f64().unwrap() > 0.0);
    std::fs::remove_dir_all(&dir).ok();
}

#[cfg(unix)]
#[test]
fn ctrl_c_writes_the_partial_render_and_exits_130() {
    use std::time::{Duration, Instant};
    let dir = temp_dir("ctrlc");
    let out = dir.join("long.exr");
    // Far more samples than finish in the test's lifetime.
    let mut child = bin()
        .args([
            "render",
            "--res",
            "32x32",
            "--spp",
            "4000000",
            "--passes-spp",
            "4",
            "--threads",
            "1",
            "--json",
            "--out",
        ])
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    let kill = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if start.elapsed() > Duration::from_secs(60) {
            child.kill().ok();
            panic!("render did not stop within 60 s of SIGINT");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "stderr: {}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["cancelled"], true);
    assert!(stderr(&o).contains("cancelled"), "{}", stderr(&o));
    let exr = filtrace_io::read_exr(&out).unwrap();
    assert!(exr.layer(&["color"]).unwrap().mean()[0] > 0.0, "partial image is black");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bench_render_reports_the_same_image_at_every_thread_count() {
    let out =
        run(bin().args(["bench", "render", "--res", "24x16", "--spp", "2", "--threads", "1,2", "--json"]));
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("bench render --json prints JSON");
    let rows = v["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 2);
    for row in rows {
        assert_eq!(row["samples"], 24 * 16 * 2);
        assert!(row["samples_per_s"].as_f64().unwrap() > 0.0);
    }
    // Deterministic sampling: the mean colour does not depend on the thread count.
    assert_eq!(rows[0]["mean_rgb"], rows[1]["mean_rgb"]);
}

/// `FILTRACE_SPATIAL_SPLITS` (read deep in the BVH builder): a value it cannot read renders
/// with the default budget after one warning naming the value; `off` warns nothing. The
/// image is the same either way (the BVH changes, the closest hits do not).
#[test]
fn unreadable_spatial_splits_value_warns_once_and_renders() {
    let bench = |value: &str| {
        let out = run(bin()
            .args(["bench", "render", "--res", "16x8", "--spp", "1", "--threads", "1", "--json"])
            .env("FILTRACE_SPATIAL_SPLITS", value));
        assert!(out.status.success(), "FILTRACE_SPATIAL_SPLITS={value}: {}", stderr(&out));
        let v: serde_json::Value =
            serde_json::from_slice(&out.stdout).expect("bench render --json prints JSON");
        (stderr(&out), v["rows"][0]["mean_rgb"].clone())
    };
    let (warned, mean) = bench("maybe");
    assert_eq!(warned.matches("FILTRACE_SPATIAL_SPLITS=\"maybe\"").count(), 1, "{warned}");
    let (quiet, mean_off) = bench("off");
    assert!(!quiet.contains("FILTRACE_SPATIAL_SPLITS"), "{quiet}");
    assert_eq!(mean, mean_off);
}

/// `bench animation` on a small meadow: every frame update is a top-level refit or
/// rebuild (never a full one), and the animated frame renders as the same frame built
/// still (the same mean colour up to the last bits: the still build merges every instance
/// into world space, the animated one keeps the moving ones in object space).
#[test]
fn bench_animation_updates_the_top_level_only_and_matches_the_still_frame() {
    let args = ["bench", "animation", "--blades", "500", "--rounds", "1", "--res", "16x12", "--spp", "1"];
    let out = run(bin().args(args).arg("--json"));
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("bench animation --json prints JSON");
    assert_eq!(v["update"]["frames"], 47);
    assert_eq!(v["update"]["full_rebuilds"], 0);
    assert_eq!(v["update"]["lights_updated"], 0, "the ball does not emit");
    assert_eq!(v["update"]["triangle_records"], 960);
    assert!(v["full_build_s"].as_f64().unwrap() > 0.0);
    for c in 0..3 {
        let (a, b) = (v["animated_mean_rgb"][c].as_f64().unwrap(), v["still_mean_rgb"][c].as_f64().unwrap());
        assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-3), "channel {c}: animated {a}, still {b}");
    }
    let table = run(bin().args(args));
    assert!(String::from_utf8_lossy(&table.stdout).contains("| update, mean |"));
}

/// `--trace scalar` and `--trace lockstep` write the same EXR, byte for byte (the two
/// tracers give bit-identical films).
#[test]
fn trace_modes_write_identical_images() {
    let dir = temp_dir("trace");
    let mut files = Vec::new();
    for mode in ["scalar", "lockstep"] {
        let out = dir.join(format!("{mode}.exr"));
        let o = run(bin()
            .args([
                "render",
                "cornell",
                "--res",
                "21x13",
                "--spp",
                "3",
                "--threads",
                "2",
                "--json",
                "--trace",
                mode,
            ])
            .arg("--out")
            .arg(&out));
        assert!(o.status.success(), "render --trace {mode} failed: {}", stderr(&o));
        files.push(std::fs::read(&out).unwrap());
    }
    assert!(files[0] == files[1], "scalar and lockstep EXRs differ");
    let o = run(bin().args(["render", "cornell", "--trace", "simd"]));
    assert!(!o.status.success() && stderr(&o).contains("simd"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}
