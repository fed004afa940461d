//! `filtrace render SCENE --integrator vpl --frames A..B` end to end: one EXR (the usual
//! layers, `cache_distance`, motion) + PNG per frame and the preview; identical files for
//! the same command and for 1 or 2 threads; a frame of a sequence against the same frame
//! rendered alone (equal for `balance`, different for `optimized`, whose parameters carry
//! over); `--ground-truth` per frame; Ctrl-C; `--resume` of an `optimized` sequence equal
//! to the uninterrupted run, also after a state file is corrupt, missing or unwritable;
//! the memory check; options that do not combine (docs/many-light.md, "Sequences").

#[path = "support/run.rs"]
mod run;

use run::*;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

fn temp_dir(tag: &str) -> PathBuf {
    fresh_dir(&format!("vplseq-{tag}"))
}

/// A tiny VPL render: 16x12, 8 spp in passes of 1 (the optimiser learns after each), 64
/// VPLs and 8 cache points, so that every record sees enough samples to step.
const TINY: [(&str, &str); 8] = [
    ("--integrator", "vpl"),
    ("--res", "16x12"),
    ("--spp", "8"),
    ("--passes-spp", "1"),
    ("--max-depth", "4"),
    ("--vpls", "64"),
    ("--cache-points", "8"),
    ("--threads", "2"),
];

/// `render SCENE` with the options of TINY that `extra` does not give, then `extra`.
fn args<'a>(scene: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let defaults = TINY.iter().filter(|(k, _)| !extra.contains(k)).flat_map(|(k, v)| [*k, *v]);
    ["render", scene].into_iter().chain(defaults).chain(extra.iter().copied()).collect()
}

/// `filtrace render SCENE TINY EXTRA --out OUT`.
fn render(scene: &str, extra: &[&str], out: &Path) -> Output {
    bin().args(args(scene, extra)).arg("--out").arg(out).output().expect("filtrace runs")
}

fn frame(dir: &Path, name: &str, k: u32) -> PathBuf {
    dir.join(format!("{name}.{k:04}.exr"))
}

#[test]
fn a_classroom_vpl_sequence_writes_every_frame_with_its_layers() {
    let dir = temp_dir("files");
    let o = ok(render("classroom", &["--frames", "0..2", "--json"], &dir.join("c.exr")));
    let lines = json_lines(&o);
    assert_eq!(lines.len(), 4, "one line per frame and the summary");
    let mut seeds = Vec::new();
    for (k, line) in lines[..3].iter().enumerate() {
        assert_eq!((line["kind"].as_str(), line["frame"].as_u64()), (Some("frame"), Some(k as u64)));
        for key in ["vpl_generation_ms", "cache_ms", "shading_ms", "optimisation_ms", "cache_records"] {
            assert!(line[key].as_f64().is_some(), "frame {k} lacks '{key}': {line}");
        }
        assert_eq!((line["spp_done"].as_u64(), line["sampler"].as_str()), (Some(8), Some("optimized")));
        let want =
            filtrace_vpl::vpls::frame_vpl_seed(filtrace_vpl::vpls::VplParams::thesis().seed, 0, k as i64);
        assert_eq!(line["vpl_seed"].as_u64(), Some(want), "frame {k}: the VPL seed of its frame");
        seeds.push(want);
        let exr = filtrace_io::read_exr(frame(&dir, "c", k as u32)).unwrap();
        for layer in ["color", "direct", "indirect", "albedo", "normal", "depth", "variance", "samples"] {
            assert!(exr.layer(&[layer]).is_some(), "frame {k} lacks '{layer}'");
        }
        for ch in ["cache_distance.Y", "motion.X", "prev_depth.Z"] {
            assert!(exr.channel(ch).is_some(), "frame {k} lacks {ch}: {:?}", exr.channel_names());
        }
        assert!(exr.channel("cache_distance.Y").unwrap().iter().any(|&d| d > 0.0), "frame {k}: no cache");
        assert_eq!(exr.attribute("filtrace:frame"), Some(k.to_string().as_str()));
        assert_eq!(exr.attribute("filtrace:cancelled"), Some("false"));
        assert!(exr.layer(&["color"]).unwrap().mean()[1] > 0.0, "frame {k} is black");
        assert!(frame(&dir, "c", k as u32).with_extension("png").exists());
    }
    seeds.dedup();
    assert_eq!(seeds.len(), 3, "a VPL seed per frame");
    assert_eq!(lines[3]["rendered"], serde_json::json!([0, 1, 2]));
    assert!(dir.join("c.preview.png").exists());
    let bits: Vec<_> = (0..3).map(|k| channel_bits(&frame(&dir, "c", k))).collect();
    assert!(bits[0] != bits[1] && bits[1] != bits[2] && bits[0] != bits[2], "frames repeat");
    // The human line of a frame has the stage milliseconds.
    let o = ok(render("classroom", &["--frames", "1..1"], &dir.join("h.exr")));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("frame 1 (t = ") && text.contains(" ms, cache "), "{text}");
    std::fs::remove_dir_all(&dir).ok();
}

/// The same command twice, and with 1 or 2 threads: the same files, bit for bit (the
/// optimiser learns after every pass and carries its parameters over two frames).
#[test]
fn vpl_sequences_are_deterministic_whatever_the_thread_count() {
    let dir = temp_dir("determinism");
    for (name, threads) in [("a", "2"), ("b", "2"), ("c", "1")] {
        ok(render(
            "classroom",
            &["--frames", "0..2", "--threads", threads],
            &dir.join(format!("{name}.exr")),
        ));
    }
    for k in 0..3 {
        let a = channel_bits(&frame(&dir, "a", k));
        assert!(a == channel_bits(&frame(&dir, "b", k)), "frame {k} differs between two runs");
        assert!(a == channel_bits(&frame(&dir, "c", k)), "frame {k} differs between 1 and 2 threads");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A sequence carries the optimiser's state (thesis 5.2.2): frame 2 of `--frames 0..2`
/// starts from what frames 0 and 1 learnt, `--frames 2..2` from the prior, so the two
/// differ for `optimized`; for `balance`, which learns nothing, they are equal bit for
/// bit. Frame 0 of a sequence is the still render.
#[test]
fn a_lone_frame_equals_its_frame_in_a_sequence_unless_the_sampler_learns() {
    let dir = temp_dir("lone");
    for sampler in ["balance", "optimized"] {
        let sampler_args = ["--vpl-sampler", sampler, "--json"];
        let seq = ok(render(
            "cornell-anim",
            &[&sampler_args[..], &["--frames", "0..2"]].concat(),
            &dir.join("s.exr"),
        ));
        ok(render("cornell-anim", &[&sampler_args[..], &["--frames", "2..2"]].concat(), &dir.join("l.exr")));
        let (in_sequence, alone) = (channel_bits(&frame(&dir, "s", 2)), channel_bits(&frame(&dir, "l", 2)));
        if sampler == "balance" {
            assert!(in_sequence == alone, "balance: frame 2 differs alone");
        } else {
            let stepped = json_lines(&seq)[..2].iter().all(|l| l["records_stepped"].as_u64() > Some(0));
            assert!(stepped, "optimized: frames 0 and 1 must learn for the test to mean anything");
            assert!(in_sequence != alone, "optimized: frame 2 did not carry the parameters learnt before it");
        }
        ok(render("cornell-anim", &sampler_args, &dir.join("still.exr")));
        assert!(
            channel_bits(&dir.join("still.exr")) == channel_bits(&frame(&dir, "s", 0)),
            "{sampler}: frame 0"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn ground_truth_and_resume_work_per_frame() {
    let dir = temp_dir("truth");
    let out = dir.join("t.exr");
    let o = ok(render("cornell-anim", &["--ground-truth", "--frames", "3..4", "--spp", "2", "--json"], &out));
    let lines = json_lines(&o);
    for (k, line) in lines[..2].iter().enumerate() {
        assert_eq!(line["sampler"], "exhaustive", "frame {}", 3 + k);
        assert!(line["mean_rgb"][1].as_f64().unwrap() > 0.0);
    }
    // The frames on disk were rendered with these settings: kept; another sampler: redone.
    let again = ["--ground-truth", "--frames", "3..4", "--spp", "2", "--json", "--resume"];
    assert_eq!(
        json_lines(&ok(render("cornell-anim", &again, &out)))[2]["resumed"],
        serde_json::json!([3, 4])
    );
    let other = ["--frames", "3..4", "--spp", "2", "--json", "--resume"];
    assert_eq!(
        json_lines(&ok(render("cornell-anim", &other, &out)))[2]["rendered"],
        serde_json::json!([3, 4])
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn options_that_do_not_combine_exit_2_naming_the_option() {
    let dir = temp_dir("bad");
    let out = dir.join("b.exr");
    for (args, want) in [
        (
            &["--filter", "guided", "--frames", "0..1"][..],
            "'--filter' cannot be used with '--integrator vpl'",
        ),
        (&["--filter", "atrous"][..], "'--filter' cannot be used"),
        (&["--adaptive", "--frames", "0..1"][..], "'--adaptive' cannot be used"),
        (&["--trace", "lockstep", "--frame", "1"][..], "'--trace' cannot be used"),
        (&["--integrator", "path", "--ground-truth"][..], "'--ground-truth' need '--integrator vpl'"),
        (&["--integrator", "path", "--vpl-clamp", "0.1", "--frames", "0..1"][..], "'--vpl-clamp' need"),
    ] {
        let o = render("cornell-anim", args, &out);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
    }
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "a refused render wrote files");
    std::fs::remove_dir_all(&dir).ok();
}

/// Every VPL option given without `--integrator vpl` (also at its default value, also
/// with `--integrator path`, also for a sequence) is a usage error naming it and saying to
/// add `--integrator vpl`, exit code 2, nothing written; the defaults alone render with the
/// path tracer. (The path tracer's own options with `--integrator vpl`: the test above.)
#[test]
fn vpl_options_without_the_vpl_integrator_exit_2_naming_the_option() {
    let dir = temp_dir("need-vpl");
    let out = dir.join("n.exr");
    let plain = ["render", "cornell", "--res", "8x8", "--spp", "1", "--max-depth", "2", "--out"];
    for option in [
        &["--vpls", "64"][..],
        &["--vpls", "2048"],
        &["--vpl-sampler", "balance"],
        &["--vpl-sampler", "optimized", "--integrator", "path"],
        &["--cache-points", "8"],
        &["--cache-neighbours", "3", "--frames", "0..1"],
        &["--ground-truth"],
        &["--vpl-clamp", "0.1"],
    ] {
        let o = bin().args(plain).arg(&out).args(option).output().unwrap();
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{option:?}: {err}");
        let want = format!("'{}' needs '--integrator vpl'", option[0]);
        assert!(err.contains(&want) && err.contains("add --integrator vpl"), "{option:?}: {err}");
        assert!(!err.contains("panicked"), "{option:?}: {err}");
    }
    let several = bin().args(plain).arg(&out).args(["--vpls", "8", "--ground-truth"]).output().unwrap();
    assert_eq!(several.status.code(), Some(2));
    assert!(stderr(&several).contains("'--vpls', '--ground-truth' need"), "{}", stderr(&several));
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "a refused render wrote files");
    ok(bin().args(plain).arg(&out).output().unwrap());
    ok(bin().args(plain).arg(&out).args(["--integrator", "path"]).output().unwrap());
    std::fs::remove_dir_all(&dir).ok();
}

/// `optimized` on `classroom`, frames 0..3 (each continues the optimiser's state of the
/// one before), renders to `DIR/c.exr`; `extra` adds options.
fn optimized_sequence(dir: &Path, extra: &[&str]) -> Vec<String> {
    let out = dir.join("c.exr").to_string_lossy().into_owned();
    let mut a: Vec<String> =
        args("classroom", &["--frames", "0..3", "--json"]).iter().map(|s| s.to_string()).collect();
    a.extend(["--out".to_string(), out]);
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

fn run_sequence(dir: &Path, extra: &[&str], env: Option<(&str, &str)>) -> Output {
    let mut cmd = bin();
    cmd.args(optimized_sequence(dir, extra));
    if let Some((k, v)) = env {
        cmd.env(k, v);
    }
    cmd.output().expect("filtrace runs")
}

fn state(dir: &Path, k: u32) -> PathBuf {
    dir.join(format!("c.{k:04}.vpl-state.json"))
}

/// Frames 0..3 of `dir` and `reference` hold the same pixels, bit for bit.
fn assert_same_frames(dir: &Path, reference: &Path, what: &str) {
    for k in 0..4 {
        let (got, want) = (channel_bits(&frame(dir, "c", k)), channel_bits(&frame(reference, "c", k)));
        assert!(got == want, "{what}: frame {k} differs from the uninterrupted run");
    }
}

/// `--resume` of an `optimized` sequence stopped by Ctrl-C after frame 1 is written
/// (frames 0 and 1 on disk with their states) keeps them and renders frames 2 and 3 from
/// the state after frame 1: the files are those of the uninterrupted run, bit for bit
/// (state files too). Without carried state frame 2 would start from the prior and differ
/// (`a_lone_frame_equals_its_frame_in_a_sequence_unless_the_sampler_learns`).
#[cfg(unix)]
#[test]
fn an_optimized_sequence_resumed_after_ctrl_c_equals_the_uninterrupted_one() {
    let (whole, cut) = (temp_dir("resume-whole"), temp_dir("resume-cut"));
    let o = ok(run_sequence(&whole, &[], None));
    let steps: Vec<_> = json_lines(&o)[..4].iter().map(|l| l["records_stepped"].as_u64()).collect();
    assert!(
        steps.iter().all(|&s| s > Some(0)),
        "every frame must learn for the test to mean anything: {steps:?}"
    );
    for k in 0..4 {
        assert!(state(&whole, k).exists(), "no state after frame {k}");
    }

    let a = optimized_sequence(&cut, &[]);
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let (code, _, err) = interrupt_at(&a, "frame 1 written", "frame 1 written", Duration::ZERO);
    assert_eq!(code, Some(130), "{err}");
    assert!(!frame(&cut, "c", 2).exists() && state(&cut, 1).exists() && !state(&cut, 2).exists());
    let o = ok(run_sequence(&cut, &["--resume"], None));
    let last = &json_lines(&o)[4];
    assert_eq!(
        (last["resumed"].clone(), last["rendered"].clone()),
        (serde_json::json!([0, 1]), serde_json::json!([2, 3]))
    );
    assert_same_frames(&cut, &whole, "resumed after frame 1");
    for k in 0..4 {
        assert_eq!(
            std::fs::read(state(&cut, k)).unwrap(),
            std::fs::read(state(&whole, k)).unwrap(),
            "state {k}"
        );
    }
    std::fs::remove_dir_all(&whole).ok();
    std::fs::remove_dir_all(&cut).ok();
}

/// A state that cannot be used (corrupt, missing, of other settings) makes `--resume`
/// render its frame again from the state before it, with a note naming the file and
/// why: the files still equal the uninterrupted run's. A failed state write (test hook)
/// is an error naming the frame, and leaves the file that was there, whole, with no
/// temporary file beside it.
#[test]
fn unusable_or_unwritable_states_never_change_the_frames() {
    let (whole, dir) = (temp_dir("state-whole"), temp_dir("state-bad"));
    ok(run_sequence(&whole, &[], None));
    let copy = |k: u32| {
        for p in [frame(&whole, "c", k), frame(&whole, "c", k).with_extension("png"), state(&whole, k)] {
            std::fs::copy(&p, dir.join(p.file_name().unwrap())).unwrap();
        }
    };
    (0..3).for_each(copy);
    std::fs::write(state(&dir, 2), "{\"frame\": 2, \"width\": 16").unwrap();
    let o = ok(run_sequence(&dir, &["--resume"], None));
    let err = stderr(&o);
    assert!(
        err.contains("frame 2 is rendered again")
            && err.contains("c.0002.vpl-state.json")
            && err.contains("corrupt"),
        "{err}"
    );
    assert_eq!(json_lines(&o)[4]["rendered"], serde_json::json!([2, 3]));
    assert_same_frames(&dir, &whole, "after a corrupt state");

    // Frame 2 gone, the state after frame 1 missing, the one after frame 0 of other
    // settings: everything again.
    std::fs::remove_file(frame(&dir, "c", 2)).unwrap();
    std::fs::remove_file(state(&dir, 1)).unwrap();
    let other = std::fs::read_to_string(state(&dir, 0)).unwrap().replace("seed=0", "seed=7");
    std::fs::write(state(&dir, 0), other).unwrap();
    let o = ok(run_sequence(&dir, &["--resume"], None));
    let err = stderr(&o);
    assert!(err.contains("c.0001.vpl-state.json, is not on disk"), "{err}");
    assert!(err.contains("c.0000.vpl-state.json, was written with other settings"), "{err}");
    assert_eq!(json_lines(&o)[4]["rendered"], serde_json::json!([0, 1, 2, 3]));
    assert_same_frames(&dir, &whole, "after missing and foreign states");

    std::fs::write(state(&dir, 2), "the previous state file").unwrap();
    std::fs::remove_file(frame(&dir, "c", 3)).unwrap();
    let o = run_sequence(&dir, &[], Some(("FILTRACE_TEST_FAIL", "state 2")));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("frame 2: cannot write the state"), "{}", stderr(&o));
    assert!(stderr(&o).contains("c.0002.vpl-state.json"), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(state(&dir, 2)).unwrap(), "the previous state file");
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains("tmp")), "a temporary file was left: {names:?}");
    assert!(!frame(&dir, "c", 3).exists(), "frame 3 was rendered after the failed write");
    let o = ok(run_sequence(&dir, &["--resume"], None));
    assert_eq!(json_lines(&o)[4]["rendered"], serde_json::json!([2, 3]), "{}", stderr(&o));
    assert_same_frames(&dir, &whole, "after a failed state write");
    std::fs::remove_dir_all(&whole).ok();
    std::fs::remove_dir_all(&dir).ok();
}

/// The VPL cache's memory (three distributions over the VPLs per cache point) is
/// estimated before the scene is loaded: 100 000 VPLs x 50 000 cache points are refused
/// with the options to lower, nothing written.
#[test]
fn a_vpl_sequence_that_does_not_fit_in_memory_is_refused_before_loading() {
    let dir = temp_dir("memory");
    let big = ["--res", "512x512", "--vpls", "100000", "--cache-points", "50000", "--frames", "0..1"];
    let o = bin()
        .args(args("classroom", &big))
        .arg("--out")
        .arg(dir.join("m.exr"))
        .env("FILTRACE_MEMORY_LIMIT", "8G")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    for want in ["importance cache", "--cache-points"] {
        assert!(stderr(&o).contains(want), "{}", stderr(&o));
    }
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "a refused render wrote files");
    std::fs::remove_dir_all(&dir).ok();
}

/// Ctrl-C as for the path tracer's sequences: after frame 1 is written, frames 0 and 1
/// stay and nothing more is started; during frame 0's passes (after its second of 1 spp
/// each), frame 0 is written cut short (every pixel has 2 samples) and marked so. Exit
/// code 130.
#[cfg(unix)]
#[test]
fn ctrl_c_keeps_the_written_vpl_frames() {
    let dir = temp_dir("cancel");
    let out = dir.join("c.exr");
    let args = args("cornell-anim", &["--frames", "0..3", "--json", "--out", out.to_str().unwrap()]);
    let (code, stdout, err) = interrupt_at(&args, "frame 1 written", "frame 1 written", Duration::ZERO);
    assert_eq!(code, Some(130), "{err}");
    for k in 0..2 {
        let exr = filtrace_io::read_exr(frame(&dir, "c", k)).unwrap();
        assert_eq!(exr.attribute("filtrace:cancelled"), Some("false"));
    }
    assert!(!frame(&dir, "c", 2).exists(), "frame 2 was started after Ctrl-C");
    let last: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert_eq!(
        (last["cancelled"].as_bool(), last["rendered"].clone()),
        (Some(true), serde_json::json!([0, 1]))
    );

    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let (code, stdout, err) = interrupt_at(&args, "pass 2", "pass 2", Duration::ZERO);
    assert_eq!(code, Some(130), "{err}");
    let exr = filtrace_io::read_exr(frame(&dir, "c", 0)).unwrap();
    assert_eq!(exr.attribute("filtrace:cancelled"), Some("true"));
    assert_eq!(exr.attribute("filtrace:spp_done"), Some("2"));
    assert!(!frame(&dir, "c", 1).exists());
    let first: serde_json::Value = serde_json::from_str(stdout.lines().next().unwrap()).unwrap();
    assert_eq!((first["frame"].as_u64(), first["cancelled"].as_bool()), (Some(0), Some(true)), "{first}");
    std::fs::remove_dir_all(&dir).ok();
}
