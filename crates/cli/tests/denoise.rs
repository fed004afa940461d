//! `filtrace denoise` end to end: a Cycles frame (Blender 3.4, `fixtures/cycles_scene.py`:
//! 64x64, 4 spp with Denoising Normal/Albedo and Depth passes, and a 1024-spp reference),
//! Cycles' escaped-ray depth `1e10` on surface pixels, the default layer of each filter, the
//! output files, and bad input (all-NaN colour, bad numbers) ending in a clear error.

use filtrace_core::Image;
use filtrace_io::{read_exr, write_exr, ExrImage};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-denoise-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn denoise(input: &Path, out: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_filtrace"))
        .arg("denoise")
        .arg(input)
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("the filtrace binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn colour(path: &Path) -> Image {
    read_exr(path).unwrap().require_layer(&["color"]).unwrap()
}

/// Mean of `(x - ref)^2 / (ref^2 + 0.01)` (as `filtrace compare`).
fn rel_mse(x: &Image, r: &Image) -> f64 {
    let s: f64 = x
        .data()
        .iter()
        .zip(r.data())
        .map(|(x, r)| (*x as f64 - *r as f64).powi(2) / (*r as f64 * *r as f64 + 0.01))
        .sum();
    s / x.data().len() as f64
}

/// Per channel `[min, max]` of the finite values.
fn range(im: &Image) -> [[f32; 2]; 3] {
    let mut r = [[f32::INFINITY, f32::NEG_INFINITY]; 3];
    for px in im.data().chunks_exact(3) {
        for c in 0..3 {
            if px[c].is_finite() {
                r[c] = [r[c][0].min(px[c]), r[c][1].max(px[c])];
            }
        }
    }
    r
}

fn assert_in_range(out: &Image, r: [[f32; 2]; 3], what: &str) {
    for (i, v) in out.data().iter().enumerate() {
        let [lo, hi] = r[i % 3];
        let tol = 1e-5 * hi.abs().max(lo.abs());
        assert!(
            v.is_finite() && *v >= lo - tol && *v <= hi + tol,
            "{what}: value {i} = {v} outside [{lo}, {hi}]"
        );
    }
}

/// The Cycles fixture with Cycles' escaped-ray depth `1e10` also on every surface pixel
/// next to the background (as Cycles writes on edge pixels whose filtered normal is set).
fn cycles_with_far_edges(dir: &Path) -> PathBuf {
    let src = fixture("cycles_4spp.exr");
    let mut exr = read_exr(&src).unwrap();
    let normal = exr.require_layer(&["normal"]).unwrap();
    let name = exr.channel_names().into_iter().find(|n| n.ends_with("Depth.Z")).expect("a Depth.Z channel");
    let mut depth = exr.channel(&name).unwrap().to_vec();
    let (w, h) = (exr.width(), exr.height());
    let set = |x: usize, y: usize| normal.pixel(x, y).iter().any(|v| *v != 0.0);
    let mut edges = 0;
    for y in 0..h {
        for x in 0..w {
            let near_bg = (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| !set(xx, yy)));
            if set(x, y) && near_bg {
                depth[y * w + x] = 1e10;
                edges += 1;
            }
        }
    }
    assert!(edges > 20, "the fixture has background next to surfaces ({edges} edge pixels)");
    exr.insert_channel(&name, depth).unwrap();
    let path = dir.join("far_edges.exr");
    write_exr(&path, &exr).unwrap();
    path
}

/// Every filter on the Cycles frame, with the scale estimated and with Blender's explicit
/// `--scene-scale 16.75`, also with escaped-ray depths on edge pixels: the output is finite
/// and inside the input's range (the illumination's, when demodulation is off), and
/// À-Trous, the filter for full colour, lowers the error against the 1024-spp reference.
#[test]
fn cycles_frame_outputs_stay_in_range_and_atrous_beats_the_noisy_input() {
    let dir = temp_dir("cycles");
    let reference = colour(&fixture("cycles_1024spp.exr"));
    let far = cycles_with_far_edges(&dir);
    for input in [fixture("cycles_4spp.exr"), far] {
        let noisy = colour(&input);
        let noisy_err = rel_mse(&noisy, &reference);
        for filter in ["atrous", "guided", "bilateral"] {
            for extra in [
                &[][..],
                &["--scene-scale", "16.75"],
                &["--no-demodulate"],
                &["--no-demodulate", "--scene-scale", "16.75"],
            ] {
                let out = dir.join(format!("{filter}.exr"));
                let mut args = vec!["--filter", filter];
                args.extend_from_slice(extra);
                let o = denoise(&input, &out, &args);
                let what = format!("{} {args:?}", input.display());
                assert!(o.status.success(), "{what}: {}", stderr(&o));
                let filtered = colour(&out);
                if extra.contains(&"--no-demodulate") {
                    assert_in_range(&filtered, range(&noisy), &what);
                } else {
                    assert_eq!(filtered.count_non_finite(), 0, "{what}");
                }
                let err = rel_mse(&filtered, &reference);
                println!("{what}: relMSE {err:.3e} (noisy {noisy_err:.3e})");
                if filter == "atrous" && extra.is_empty() {
                    assert!(err < noisy_err, "{what}: relMSE {err} vs noisy {noisy_err}");
                }
                // Never an explosion (the guided filter reached relMSE 1.2e19).
                assert!(err < 1.0, "{what}: relMSE {err}");
            }
        }
    }
}

/// A filtrace render has direct and indirect layers: guided and bilateral filter the
/// indirect light by default (their design) and add the direct light; À-Trous filters the
/// colour. A Cycles frame without an indirect layer: the colour, with a note saying so.
#[test]
fn each_filter_defaults_to_the_layer_it_was_designed_for() {
    let dir = temp_dir("layers");
    let render = dir.join("c.exr");
    let o = Command::new(env!("CARGO_BIN_EXE_filtrace"))
        .args(["render", "cornell", "--res", "24x24", "--spp", "2", "--threads", "2", "--out"])
        .arg(&render)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    for (filter, layer) in [("guided", "Indirect"), ("bilateral", "Indirect"), ("atrous", "Colour")] {
        let out = dir.join(format!("{filter}.exr"));
        let o = denoise(&render, &out, &["--filter", filter]);
        assert!(o.status.success(), "{filter}: {}", stderr(&o));
        assert!(stderr(&o).contains(&format!("{layer} layer")), "{filter}: {}", stderr(&o));
        let written = read_exr(&out).unwrap();
        assert_eq!(written.layer(&["indirect_filtered"]).is_some(), layer == "Indirect", "{filter}");
    }
    let out = dir.join("cycles.exr");
    let o = denoise(&fixture("cycles_4spp.exr"), &out, &["--filter", "guided"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("no indirect layer: filtering the full colour"), "{}", stderr(&o));
    // An explicit --layer wins.
    let o = denoise(&render, &out, &["--filter", "guided", "--layer", "colour"]);
    assert!(o.status.success() && stderr(&o).contains("Colour layer"), "{}", stderr(&o));
}

/// `--out x.exr` writes the EXR and a PNG beside it; `--out x.png` is an error that writes
/// nothing (it used to write EXR bytes under the .png name).
#[test]
fn output_is_an_exr_with_a_png_beside_it() {
    let dir = temp_dir("out");
    let input = fixture("cycles_4spp.exr");
    let out = dir.join("sub/d.exr");
    let o = denoise(&input, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.exists() && dir.join("sub/d.png").exists());
    let png = std::fs::read(dir.join("sub/d.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let bad = dir.join("x.png");
    let o = denoise(&input, &bad, &[]);
    assert!(!o.status.success() && stderr(&o).contains("must be an .exr"), "{}", stderr(&o));
    assert!(!bad.exists() && !dir.join("x.exr").exists());
}

/// A colour layer without one valid value (all NaN, all 3e38) is an error, not a black
/// image with exit code 0; so is every out-of-range number.
#[test]
fn unusable_input_and_bad_numbers_are_errors() {
    let dir = temp_dir("bad");
    let src = read_exr(fixture("cycles_4spp.exr")).unwrap();
    let normal = src.require_layer(&["normal"]).unwrap();
    let (w, h) = (src.width(), src.height());
    for (tag, v) in [("nan", f32::NAN), ("huge", 3e38)] {
        let mut exr = ExrImage::new(w, h);
        exr.insert("", &["R", "G", "B"], &Image::filled(w, h, 3, v)).unwrap();
        exr.insert("normal", &["X", "Y", "Z"], &normal).unwrap();
        let input = dir.join(format!("{tag}.exr"));
        write_exr(&input, &exr).unwrap();
        let out = dir.join(format!("{tag}-out.exr"));
        for filter in ["atrous", "guided", "bilateral"] {
            let o = denoise(&input, &out, &["--filter", filter]);
            assert!(!o.status.success(), "{tag} {filter}: exit 0");
            assert!(stderr(&o).contains("no valid pixel"), "{tag} {filter}: {}", stderr(&o));
            assert!(!out.exists(), "{tag} {filter}: nothing written");
        }
    }
    let input = fixture("cycles_4spp.exr");
    let out = dir.join("o.exr");
    for (args, flag) in [
        (&["--filter", "guided", "--eps-normal", "nan"][..], "--eps-normal"),
        (&["--filter", "guided", "--eps-depth=-1"], "--eps-depth"),
        (&["--filter", "guided", "--scene-scale", "inf"], "--scene-scale"),
        (&["--filter", "guided", "--scene-scale", "0"], "--scene-scale"),
        (&["--albedo-eps", "0"], "--albedo-eps"),
        (&["--albedo-eps", "2"], "--albedo-eps"),
        (&["--filter", "guided", "--radius", "0"], "--radius"),
        (&["--filter", "bilateral", "--radius", "1000"], "--radius"),
        (&["--filter", "guided", "--radius", "4000000000"], "--radius"),
        (&["--iterations", "11"], "--iterations"),
        (&["--sigma-color", "nan"], "--sigma-color"),
    ] {
        let o = denoise(&input, &out, args);
        assert!(!o.status.success(), "{args:?}: exit 0");
        assert!(stderr(&o).contains(flag), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{args:?}");
    }
    assert!(!out.exists());
}
