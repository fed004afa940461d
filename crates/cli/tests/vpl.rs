//! `filtrace render --integrator vpl` and `filtrace bench vpl` end to end: a tiny render
//! with each sampler writes the EXR with the cache-distance layer and a JSON summary with
//! the stage times; the ground truth runs; bad VPL options end in a message naming them.

use std::path::PathBuf;
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_filtrace"))
}

fn run(cmd: &mut Command) -> Output {
    cmd.output().expect("the filtrace binary runs")
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-cli-vpl-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn vpl_render_with_each_sampler_and_the_ground_truth() {
    let dir = temp_dir("render");
    for sampler in ["uniform", "alpha-max", "balance", "balance-cv", "optimized", "truth"] {
        let out = dir.join(format!("{sampler}.exr"));
        let mut cmd = bin();
        cmd.args([
            "render",
            "cornell",
            "--integrator",
            "vpl",
            "--res",
            "16x16",
            "--spp",
            "2",
            "--vpls",
            "256",
        ]);
        cmd.args(["--cache-points", "32", "--cache-neighbours", "3", "--json", "--out"]).arg(&out);
        if sampler == "truth" {
            cmd.arg("--ground-truth");
        } else {
            cmd.args(["--vpl-sampler", sampler]);
        }
        let o = run(&mut cmd);
        assert!(o.status.success(), "{sampler}: {}", String::from_utf8_lossy(&o.stderr));
        let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
        for key in ["vpl_generation_ms", "cache_ms", "shading_ms", "optimisation_ms", "vpls", "mean_rgb"] {
            assert!(json.get(key).is_some(), "{sampler}: JSON lacks {key}: {json}");
        }
        assert!(json["mean_rgb"][1].as_f64().unwrap() > 0.0, "{sampler}: black image");
        let exr = std::fs::read(&out).expect("EXR written");
        assert!(exr.windows(14).any(|w| w == b"cache_distance"), "{sampler}: no cache_distance layer");
    }
}

#[test]
fn bad_vpl_options_name_the_option() {
    for (args, want) in [
        (vec!["--vpl-sampler", "nope"], "alpha-max"),
        (vec!["--vpls", "0"], "--vpls"),
        (vec!["--cache-neighbours", "9"], "cache neighbours"),
        (vec!["--vpl-clamp", "-1"], "geometry bound"),
    ] {
        let o = run(bin()
            .args(["render", "cornell", "--integrator", "vpl", "--res", "8x8", "--spp", "1"])
            .args(&args));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(want), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

#[test]
fn bench_vpl_prints_every_stage() {
    let o = run(bin().args([
        "bench",
        "vpl",
        "cornell",
        "--res",
        "16x16",
        "--vpls",
        "128",
        "--cache-points",
        "16",
        "--json",
    ]));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(json["rows"].as_array().unwrap().len(), 5, "{json}");
}
