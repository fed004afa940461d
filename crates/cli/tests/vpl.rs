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
        let cached = !matches!(sampler, "uniform" | "truth");
        assert_eq!(json["cache_rays"].as_u64().unwrap() > 0, cached, "{sampler}: {json}");
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
        (vec!["--vpl-clamp", "-1"], "--vpl-clamp -1.0"),
        (vec!["--cache-faint-share", "1"], "cache faint share 1"),
        (vec!["--cache-faint-share", "nan"], "not a finite number"),
        (vec!["--cache-faint-share", "-0.1"], "cache faint share -0.1"),
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

/// The faint share only moves rays from traced to faint: the records and the VPLs with a
/// contribution are the same whatever the share.
#[test]
fn bench_vpl_faint_share_trades_rays_for_faint_vpls() {
    let rows = |share: &str| {
        let o = run(bin().args(["bench", "vpl", "cornell", "--res", "16x16", "--vpls", "128"]).args([
            "--cache-points",
            "16",
            "--samplers",
            "balance",
            "--cache-faint-share",
            share,
            "--json",
        ]));
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
        let row = &json["rows"][0];
        (row["cache_rays"].as_u64().unwrap(), row["cache_faint_vpls"].as_u64().unwrap())
    };
    let (exact, none) = rows("0");
    let (traced, faint) = rows("0.3");
    assert_eq!(none, 0);
    assert!(faint > 0 && traced + faint == exact, "{traced} + {faint} vs {exact}");
}

/// `--integrator vpl` renders in the path tracer's progressive passes: with `optimized`
/// learning after each of 4 passes, the image is the same with 1 and 2 threads.
#[test]
fn vpl_render_is_progressive_and_thread_independent() {
    let dir = temp_dir("passes");
    let mean = |threads: &str| {
        let out = dir.join(format!("t{threads}.exr"));
        let o = run(bin()
            .args([
                "render",
                "cornell",
                "--integrator",
                "vpl",
                "--res",
                "12x12",
                "--spp",
                "8",
                "--passes-spp",
                "2",
            ])
            .args(["--vpls", "128", "--cache-points", "16", "--threads", threads, "--json", "--out"])
            .arg(&out));
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
        assert_eq!(json["spp_done"], 8, "{json}");
        assert_eq!(json["cancelled"], false, "{json}");
        json["mean_rgb"].clone()
    };
    assert_eq!(mean("1"), mean("2"));
}

/// Ctrl-C after the second pass (1 + 1 samples) writes the two-sample image and exits
/// with 130, as the path tracer does.
#[test]
fn ctrl_c_keeps_the_finished_passes_of_a_vpl_render() {
    use std::io::{BufRead, BufReader};
    let dir = temp_dir("cancel");
    let out = dir.join("c.exr");
    let mut child = bin()
        .args([
            "render",
            "cornell",
            "--integrator",
            "vpl",
            "--res",
            "8x8",
            "--spp",
            "64",
            "--passes-spp",
            "1",
        ])
        .args(["--vpls", "64", "--cache-points", "8", "--json", "--out"])
        .arg(&out)
        .env("FILTRACE_TEST_PAUSE", "pass 2")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the filtrace binary starts");
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines().map_while(Result::ok);
    assert!(lines.any(|l| l == "filtrace-test: pass 2"), "no pause marker");
    let kill = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let rest: Vec<String> = lines.collect();
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{rest:?}");
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!((json["spp_done"].as_u64(), json["cancelled"].as_bool()), (Some(2), Some(true)), "{json}");
    assert!(out.exists() && rest.iter().any(|l| l.contains("cancelled")), "{rest:?}");
}
