//! Quality on a real render (slow tier): the Cornell box at 4 samples per pixel, rendered
//! in-process, against Mitsuba's 4096-spp reference (`../shared/reference`). Every filter
//! must lower the relative MSE (mean of `(x - ref)^2 / (ref^2 + 0.01)`) at least 10x.
//!
//! Set-up as in the papers: À-Trous on the demodulated colour (Dammertz et al. 2010,
//! deferred shading); guided and cross-bilateral on the demodulated indirect light, with the
//! (unfiltered) direct light added back (Bauszat et al. 2011).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use filtrace_core::Image;
use filtrace_denoise::{AtrousParams, BilateralParams, Filter, GBuffer, GuidedParams, DEFAULT_ALBEDO_EPS};

/// The reference, or `None` with a SKIP line when absent (a failure when `CI` is set).
fn reference_path() -> Option<PathBuf> {
    filtrace_core::shared_data::shared_path("reference/cornell_mitsuba_4096spp.exr")
}

fn rel_mse(x: &Image, r: &Image) -> f64 {
    let s: f64 = x
        .data()
        .iter()
        .zip(r.data())
        .map(|(x, r)| {
            let (x, r) = (*x as f64, *r as f64);
            (x - r).powi(2) / (r * r + 0.01)
        })
        .sum();
    s / x.data().len() as f64
}

#[test]
#[ignore = "slow: renders the Cornell box at 4 spp and runs every filter (~20 s)"]
fn every_filter_lowers_rel_mse_10x_on_a_4spp_cornell_box() {
    let Some(path) = reference_path() else { return };
    let reference = filtrace_io::read_exr(&path).unwrap().require_layer(&["color"]).unwrap();
    let scene = filtrace_scene::load_scene("cornell").unwrap();
    let settings = filtrace_render::RenderSettings {
        width: reference.width() as u32,
        height: reference.height() as u32,
        spp: 4,
        ..Default::default()
    };
    let renderer = filtrace_render::Renderer::new(scene, settings).unwrap();
    let mut film = renderer.new_film();
    assert!(renderer.render_pass(&mut film, 0, 4, &AtomicBool::new(false)));
    let aovs = film.aovs();
    let guide = GBuffer::new(aovs.normal.clone())
        .with_position(aovs.position.clone())
        .with_depth(aovs.depth.clone())
        .with_albedo(aovs.albedo.clone());

    let noisy = rel_mse(&aovs.color, &reference);
    println!("noisy 4 spp: relMSE {noisy:.4e}");
    let cases = [
        ("atrous (colour)", Filter::Atrous(AtrousParams::paper()), false),
        ("guided (indirect)", Filter::Guided(GuidedParams::paper()), true),
        ("bilateral (indirect)", Filter::Bilateral(BilateralParams::reference()), true),
    ];
    let mut failures = Vec::new();
    for (name, filter, indirect_only) in cases {
        let out = if indirect_only {
            let mut f = filter.apply_demodulated(&aovs.indirect, &guide, DEFAULT_ALBEDO_EPS).unwrap();
            for (o, d) in f.data_mut().iter_mut().zip(aovs.direct.data()) {
                *o += d;
            }
            f
        } else {
            filter.apply_demodulated(&aovs.color, &guide, DEFAULT_ALBEDO_EPS).unwrap()
        };
        assert_eq!(out.count_non_finite(), 0, "{name}");
        let e = rel_mse(&out, &reference);
        println!("{name}: relMSE {e:.4e} ({:.1}x lower)", noisy / e);
        if noisy / e < 10.0 {
            failures.push(format!("{name}: only {:.1}x", noisy / e));
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
