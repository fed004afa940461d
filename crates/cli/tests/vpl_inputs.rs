//! The many-light renderer as a user meets it: odd inputs to `render --integrator vpl`,
//! `bench vpl` and `experiment` end in success or a message naming the value, never in a
//! silent black image, a panic or an allocation that runs the machine out of memory
//! (docs/many-light.md, "Reliability of the many-light renderer (stop 20)").

#[path = "support/run.rs"]
mod run;

use run::{bin, fresh_dir, json_lines, ok, run_within, stderr};
use std::process::Command;
use std::time::Duration;

/// `cmd`'s exit code and stderr, within `limit` ([`run_within`]).
fn code_and_stderr(cmd: &mut Command, limit: Duration) -> (Option<i32>, String) {
    let o = run_within(cmd, limit);
    (o.status.code(), stderr(&o))
}

/// A TOML scene without any light renders black: the VPL render says so, as the path
/// tracer does (on stderr, and in the JSON's `load_warnings`).
#[test]
fn vpl_render_of_a_scene_without_light_warns() {
    let dir = fresh_dir("vpl-inputs-nolight");
    let scene = dir.join("dark.toml");
    std::fs::write(
        &scene,
        "[[materials]]\nname = \"g\"\ntype = \"diffuse\"\n[[objects]]\nshape = \"cube\"\nmaterial = \"g\"\n",
    )
    .unwrap();
    let render = |json: bool| {
        let mut cmd = bin();
        cmd.arg("render").arg(&scene).args(["--integrator", "vpl", "--res", "8x8", "--spp", "1"]);
        cmd.arg("--out").arg(dir.join("dark.exr"));
        if json {
            cmd.arg("--json");
        }
        ok(cmd.output().unwrap())
    };
    let text = render(false);
    assert!(stderr(&text).contains("warning:") && stderr(&text).contains("no lights"), "{}", stderr(&text));
    let json = &json_lines(&render(true))[0];
    assert_eq!(json["vpls"], 0, "{json}");
    let warnings = json["load_warnings"].as_array().unwrap_or_else(|| panic!("no load_warnings: {json}"));
    assert!(warnings.iter().any(|w| w.as_str().unwrap().contains("no lights")), "{json}");
}

/// `--max-depth 1` is the emitters seen directly (Mitsuba's convention, as the path
/// tracer): no VPL may light a surface, so the image is the path tracer's of that depth.
#[test]
fn vpl_render_at_max_depth_1_has_no_vpls() {
    let dir = fresh_dir("vpl-inputs-depth");
    let mean = |depth: &str, vpl: bool| {
        let mut cmd = bin();
        cmd.args(["render", "cornell", "--res", "12x12", "--spp", "2", "--max-depth", depth, "--json"]);
        if vpl {
            cmd.args(["--integrator", "vpl", "--vpls", "64", "--cache-points", "8"]);
        }
        cmd.arg("--out").arg(dir.join(format!("d{depth}{vpl}.exr")));
        let json = json_lines(&ok(cmd.output().unwrap()))[0].clone();
        (json["vpls"].as_u64(), json["mean_rgb"][1].as_f64().unwrap())
    };
    let (vpls, vpl_mean) = mean("1", true);
    assert_eq!(vpls, Some(0), "VPLs at max depth 1");
    let (_, path_mean) = mean("1", false);
    assert!((vpl_mean - path_mean).abs() <= 0.05 * path_mean, "VPL {vpl_mean} vs path tracer {path_mean}");
    let (_, direct) = mean("2", true);
    assert!(direct > 1.2 * vpl_mean, "depth 2 ({direct}) adds direct light to depth 1 ({vpl_mean})");
}

/// `bench vpl` takes the counts `render` takes (1..=1000000, named when refused) and
/// refuses a frame that does not fit in memory before allocating it.
#[test]
fn bench_vpl_refuses_bad_counts_and_frames_too_large_for_memory() {
    for (args, want) in [
        (["--vpls", "100000000"], "--vpls"),
        (["--vpls", "0"], "--vpls"),
        (["--cache-points", "0"], "--cache-points"),
    ] {
        let o = bin()
            .args(["bench", "vpl", "cornell", "--res", "8x8", "--samplers", "balance"])
            .args(args)
            .output();
        let o = o.unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
    }
    let mut cmd = bin();
    cmd.args(["bench", "vpl", "cornell", "--res", "64x64", "--vpls", "1000000", "--cache-points", "100000"]);
    cmd.args(["--samplers", "balance"]).env("FILTRACE_MEMORY_LIMIT", "1G");
    let (code, err) = code_and_stderr(&mut cmd, Duration::from_secs(30));
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("not enough memory") && err.contains("importance cache"), "{err}");
}

/// An experiment whose many-light frame does not fit in memory is refused before it
/// runs, naming the spec and the method.
#[test]
fn experiment_refuses_a_vpl_method_too_large_for_memory() {
    let dir = fresh_dir("vpl-inputs-experiment");
    let spec = dir.join("huge.toml");
    let text = "name = \"huge\"\nwidth = 64\nheight = 64\nspp = [1]\n[reference]\nground_truth = \"vpl\"\n\
                [vpl]\nvpls = 1000000\ncache_points = 1000000\n[[scenes]]\nname = \"cornell\"\n\
                [[methods]]\nname = \"bal\"\nsampler = \"balance\"\n";
    std::fs::write(&spec, text).unwrap();
    let mut cmd = bin();
    cmd.arg("experiment").arg(&spec).arg("--out").arg(dir.join("out")).env("FILTRACE_MEMORY_LIMIT", "1G");
    let (code, err) = code_and_stderr(&mut cmd, Duration::from_secs(30));
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("huge.toml") && err.contains("method bal") && err.contains("not enough memory"),
        "{err}"
    );
    assert!(!dir.join("out").exists(), "nothing is written for a refused spec");
}

/// `--cache-neighbours` out of range is a usage error (exit 2) as the other counts are, and
/// a `--vpl-clamp` too large for the scene names the value typed, not only the product.
#[test]
fn out_of_range_neighbours_and_clamp_name_the_value() {
    let render = |args: &[&str]| {
        let mut cmd = bin();
        cmd.args(["render", "cornell", "--integrator", "vpl", "--res", "8x8", "--spp", "1"]).args(args);
        code_and_stderr(&mut cmd, Duration::from_secs(60))
    };
    for m in ["0", "9"] {
        let (code, err) = render(&["--cache-neighbours", m]);
        assert_eq!(code, Some(2), "--cache-neighbours {m}: {err}");
        assert!(err.contains(&format!("cache neighbours M = {m}")), "--cache-neighbours {m}: {err}");
    }
    let (code, err) = render(&["--vpl-clamp", "3e38"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--vpl-clamp 3e38") && !err.contains("panicked"), "{err}");
}
