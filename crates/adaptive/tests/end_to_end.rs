//! End to end on the filtered pipeline (slow tier): on the procedural grass scene, the
//! À-Trous-filtered indirect light has a lower error with adaptive sampling than with
//! uniform sampling at the same total number of paths (Bauszat et al. 2011, §5: 67% of
//! the À-Trous error on its Grass scene). Numbers: docs/adaptive.md.

use filtrace_adaptive::{AdaptiveParams, SampleCounts};
use filtrace_core::Image;
use filtrace_pipeline::{
    adaptive as pa, FilterChoice, FilteredRenderer, NoFilter, PipelineSettings, RenderSource,
};
use filtrace_render::{RenderSettings, Renderer};

fn sq_err(a: &Image, b: &Image) -> f64 {
    a.data().iter().zip(b.data()).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>() / a.data().len() as f64
}

#[test]
#[ignore = "slow: renders the grass scene's indirect light ~1.3M paths (about 10 s on 2 cores)"]
fn adaptive_lowers_filtered_error_on_grass() {
    let (w, h) = (80u32, 60u32);
    let n = (w * h) as usize;
    let scene = filtrace_scene::builtin::builtin("grass").expect("built-in grass scene");
    let rs = RenderSettings { width: w, height: h, spp: 1, max_depth: 4, seed: 0 };
    let source = RenderSource::new(Renderer::new(scene, rs).unwrap());
    let scale = source.scene_scale();
    let mut p = FilteredRenderer::new(source, NoFilter, PipelineSettings::interactive(w, h)).unwrap();
    let frame_map = |p: &mut FilteredRenderer<RenderSource, NoFilter>, seed: u64, counts: &[u32]| {
        let st = PipelineSettings { seed, ..p.settings().clone() };
        p.set_settings(st).unwrap();
        let f = p.render_frame_with_counts(Some(counts)).unwrap();
        (f.images.indirect_map.clone(), f.images.guide.clone())
    };
    // Reference from two independent halves; their difference measures its own noise.
    let (r1, _) = frame_map(&mut p, 1001, &vec![128; n]);
    let (r2, _) = frame_map(&mut p, 1002, &vec![128; n]);
    let mut reference = r1.clone();
    for (r, b) in reference.data_mut().iter_mut().zip(r2.data()) {
        *r = 0.5 * (*r + b);
    }
    let floor = sq_err(&r1, &r2) / 4.0;

    let plan = pa::plan(p.source(), p.settings(), &AdaptiveParams::paper()).unwrap();
    assert_eq!(plan.counts.total(), 4 * n as u64);
    let uniform = SampleCounts::uniform(w as usize, h as usize, 4);
    let mut filter = FilterChoice::named("atrous").build(Some(scale)).unwrap();
    let (mut err_u, mut err_a) = (Vec::new(), Vec::new());
    for seed in 0..4 {
        for (counts, errs) in [(&uniform, &mut err_u), (&plan.counts, &mut err_a)] {
            let (noisy, guide) = frame_map(&mut p, seed, counts.counts());
            let mut out = Image::new(w as usize, h as usize, 3);
            filter.apply(&noisy, &guide, &mut out).unwrap();
            errs.push(sq_err(&out, &reference) - floor);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (u, a) = (mean(&err_u), mean(&err_a));
    println!("uniform {err_u:?}\nadaptive {err_a:?}\nfloor {floor:e}, ratio {}", a / u);
    assert!(floor < 0.25 * u, "reference too noisy: floor {floor:e} vs uniform error {u:e}");
    // Every seed must improve, and the mean by at least 5%.
    for (a, u) in err_a.iter().zip(&err_u) {
        assert!(a < u, "adaptive {a:e} >= uniform {u:e} for one seed");
    }
    assert!(a < 0.95 * u, "adaptive/uniform = {}", a / u);
}
