//! Bounded memory (issue 17, defect 7) and the adaptive render's spp (defect 10), end to
//! end: a render that cannot fit is refused before the scene is loaded, with a message
//! naming what it needs and what the machine has (never an abort, exit 134); the filtered
//! render's estimate does not grow with spp; the plain render's estimate agrees with the
//! bytes its buffers really take (this test binary's allocator counts them).
//!
//! `FILTRACE_MEMORY_LIMIT` (bytes, or with a K/M/G suffix) stands for the machine's
//! available memory, so the refusals are tested without allocating gigabytes.

use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::atomic::Ordering;

#[path = "../../pipeline/tests/support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::{serial, LIVE, PEAK};

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-memory-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `filtrace render ARGS` with `FILTRACE_MEMORY_LIMIT` set to `limit` (unset for `None`).
fn render(args: &[&str], limit: Option<&str>) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_filtrace"));
    c.arg("render").args(args).env_remove("FILTRACE_MEMORY_LIMIT");
    if let Some(l) = limit {
        c.env("FILTRACE_MEMORY_LIMIT", l);
    }
    c.output().expect("the filtrace binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A refusal: exit code 1 (an error, not an abort), a message naming the need, the
/// resolution, what is available and what to change; no output written.
fn assert_refused(o: &Output, res: &str, out: &std::path::Path) -> String {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(1), "expected a clean refusal, got {:?}: {e}", o.status);
    for want in ["not enough memory: needs", res, "available", "Lower --res"] {
        assert!(e.contains(want), "{want:?} missing in: {e}");
    }
    assert!(!out.exists(), "nothing is written");
    e
}

#[test]
fn a_film_bigger_than_the_memory_limit_is_refused_before_the_scene_is_loaded() {
    let _s = serial();
    let dir = temp_dir("film");
    let out = dir.join("big.exr");
    // The scene does not exist: the refusal must come first (before loading anything).
    let o = render(
        &["no-such-scene.obj", "--res", "16384x16384", "--spp", "1", "--out", out.to_str().unwrap()],
        Some("4G"),
    );
    let e = assert_refused(&o, "16384x16384", &out);
    assert!(e.contains("film 36.0 GiB"), "{e}");
    assert!(e.contains("4.0 GiB available (FILTRACE_MEMORY_LIMIT)"), "{e}");
    // A small render under the same limit goes ahead.
    let o = render(&["cornell", "--res", "16x16", "--spp", "1", "--out", out.to_str().unwrap()], Some("4G"));
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn sixteen_k_squared_is_refused_by_what_this_machine_really_has() {
    let _s = serial();
    // Film 36 GiB + AOVs 22 GiB + EXR/PNG output 45.5 GiB: 103.5 GiB.
    let needs = filtrace_render::memory::plain_render(16384, 16384).total();
    assert!(needs > 100 << 30, "{needs}");
    let available = filtrace_render::memory::available().unwrap();
    let Some(a) = available.filter(|a| a.bytes < needs) else {
        eprintln!("this machine has {needs} bytes or more available (or no /proc/meminfo): not refused here");
        return;
    };
    let dir = temp_dir("real");
    let out = dir.join("big.exr");
    let o = render(&["cornell", "--res", "16384x16384", "--spp", "1", "--out", out.to_str().unwrap()], None);
    let e = assert_refused(&o, "16384x16384", &out);
    assert!(e.contains(&a.source), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_filtered_render_is_refused_alike_at_4_and_4096_spp() {
    let _s = serial();
    let dir = temp_dir("filtered");
    let out = dir.join("f.exr");
    let needs = |spp: &str| {
        let args = ["--filter", "atrous", "--spp", spp, "--res", "512x512", "--out", out.to_str().unwrap()];
        let o = render(&args, Some("1M"));
        let e = assert_refused(&o, "512x512 filtered frame", &out);
        e.split(" plus the scene").next().unwrap().to_string()
    };
    let (few, many) = (needs("4"), needs("4096"));
    assert_eq!(few, many, "the estimate must not depend on spp");
    // Before: 4096 spp stored 52-byte records of every sample, 55.8 GB at 512x512.
    assert!(many.contains("MiB for a 512x512"), "{many}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_malformed_memory_limit_is_an_error() {
    let _s = serial();
    let o = render(&["--res", "8x8", "--spp", "1", "--out", "/nonexistent/x.exr"], Some("lots"));
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("FILTRACE_MEMORY_LIMIT=\"lots\""), "{}", stderr(&o));
}

fn json_spp(args: &[&str]) -> u64 {
    let dir = temp_dir("adaptive");
    let out = dir.join("a.exr");
    let mut all =
        vec!["cornell", "--res", "16x12", "--max-depth", "3", "--json", "--out", out.to_str().unwrap()];
    all.extend_from_slice(args);
    let o = render(&all, None);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    std::fs::remove_dir_all(&dir).ok();
    json["spp"].as_u64().expect("spp in the summary")
}

#[test]
fn adaptive_spp_follows_the_budget_unless_given() {
    let _s = serial();
    assert_eq!(json_spp(&["--adaptive", "--budget-spp", "2"]), 2, "--spp follows --budget-spp");
    assert_eq!(json_spp(&["--adaptive"]), 4, "the defaults agree: budget 4, spp 4");
    assert_eq!(json_spp(&["--adaptive", "--budget-spp", "2", "--spp", "3"]), 3, "--spp given wins");
    assert_eq!(json_spp(&["--filter", "none", "--spp", "5"]), 5);
}

/// Peak bytes the allocator holds above the start while `f` runs.
fn peak_during(f: impl FnOnce()) -> u64 {
    let base = LIVE.load(Ordering::SeqCst);
    PEAK.store(base, Ordering::SeqCst);
    f();
    (PEAK.load(Ordering::SeqCst) - base) as u64
}

#[test]
fn the_plain_render_estimate_matches_the_buffers_it_allocates() {
    let _s = serial();
    let (w, h) = (320u32, 200u32);
    let dir = temp_dir("estimate");
    let exr_path = dir.join("e.exr");
    // What `render` allocates per pixel, in its order: film, AOVs, sample counts, EXR, PNG
    // (`write_outputs`); the scene and the renderer are not part of the estimate.
    let peak = peak_during(|| {
        let film = filtrace_render::Film::try_new(w as usize, h as usize).unwrap();
        let mut a = film.try_aovs().unwrap();
        // Noise, so that the EXR's compression sees what a render gives it, not zeros.
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for im in [&mut a.color, &mut a.direct, &mut a.normal, &mut a.depth, &mut a.variance] {
            for v in im.data_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *v = (x >> 40) as f32 / (1u64 << 24) as f32;
            }
        }
        let mut exr = filtrace_io::ExrImage::new(w as usize, h as usize);
        let rgb: &[&str] = &["R", "G", "B"];
        for (name, image) in [
            ("", &a.color),
            ("direct", &a.direct),
            ("indirect", &a.indirect),
            ("albedo", &a.albedo),
            ("normal", &a.normal),
            ("position", &a.position),
            ("variance", &a.variance),
        ] {
            exr.insert(name, rgb, image).unwrap();
        }
        exr.insert("depth", &["Z"], &a.depth).unwrap();
        let counts = film.sample_counts();
        exr.insert("samples", &["Y"], &counts).unwrap();
        filtrace_io::write_exr(&exr_path, &exr).unwrap();
        let tonemap = filtrace_io::TonemapParams::srgb_clamp();
        filtrace_io::write_png(exr_path.with_extension("png"), &a.color, &tonemap).unwrap();
    });
    let est = filtrace_render::memory::plain_render(w, h);
    let ratio = peak as f64 / est.total() as f64;
    eprintln!("plain render {w}x{h}: peak {peak} bytes, estimate {est} ({ratio:.3})");
    assert!((0.9..=1.1).contains(&ratio), "peak {peak} vs estimate {}: {ratio:.3}", est.total());
    std::fs::remove_dir_all(&dir).ok();
}
