//! The pipeline on filtrace's own path tracer (built-in Cornell box).

use filtrace_core::Image;
use filtrace_pipeline::*;
use filtrace_render::{RenderSettings, Renderer};

fn renderer(w: u32, h: u32, max_depth: i32, seed: u64) -> Renderer {
    let scene = filtrace_scene::builtin::builtin("cornell").expect("built-in Cornell box");
    Renderer::new(scene, RenderSettings { width: w, height: h, spp: 1, max_depth, seed }).unwrap()
}

#[test]
fn unfiltered_one_spp_equals_the_path_tracers_guide_sample() {
    // Same sampler streams: the pipeline's guide ray is the renderer's sample 0, so the
    // recombined direct + indirect must be the renderer's colour, pixel for pixel.
    let (w, h) = (24, 20);
    let src = RenderSource::new(renderer(w, h, 5, 3));
    let st = PipelineSettings { seed: 3, ..PipelineSettings::interactive(w, h) };
    let mut p = FilteredRenderer::new(&src, NoFilter, st).unwrap();
    let frame = p.render_frame().unwrap();
    let im = &frame.images;
    let mut nonzero = 0;
    for y in 0..h {
        for x in 0..w {
            let s = src.renderer().trace_sample(x, y, 0).radiance;
            let (want, got) = (s.color(), im.color.rgb(x as usize, y as usize));
            let tol = 1e-4 * (1.0 + want.max_element());
            assert!((got - want).abs().max_element() <= tol, "({x},{y}): {got} vs {want}");
            let d = im.direct.rgb(x as usize, y as usize);
            assert!((d - s.direct).abs().max_element() <= tol, "direct ({x},{y}): {d} vs {}", s.direct);
            nonzero += (s.indirect.max_element() > 0.0) as usize;
        }
    }
    assert!(nonzero > (w * h / 4) as usize, "indirect light should be non-zero in much of the box");
}

#[test]
fn every_filter_runs_on_the_cornell_box_and_keeps_frames_finite_and_reproducible() {
    let (w, h) = (32, 32);
    let src = RenderSource::new(renderer(w, h, 3, 0));
    for name in ["none", "atrous", "guided", "bilateral"] {
        let f = filter_by_name(name, Some(src.scene_scale())).unwrap();
        let st = PipelineSettings { spp: 2, ..PipelineSettings::paper(w, h) };
        let mut p = FilteredRenderer::new(&src, f, st).unwrap();
        let a: Image = p.render_frame().unwrap().images.color.clone();
        assert_eq!(a.count_non_finite(), 0, "{name}");
        let b = p.render_frame().unwrap().images.color.clone();
        assert_eq!(a, b, "{name}: same seed, same frame");
        // The filtered indirect light keeps the mean of the noisy one roughly (filters are
        // normalised averages; the lookup only reorders samples).
        let im = &p.last_frame().images;
        let (m0, m1) = (im.indirect.mean()[0], im.filtered_indirect.mean()[0]);
        assert!((m1 - m0).abs() <= 0.25 * m0.abs() + 1e-3, "{name}: indirect mean {m0} -> {m1}");
    }
    assert!(filter_by_name("nope", None).is_err());
}

#[test]
fn source_and_frame_resolution_must_agree() {
    let src = RenderSource::new(renderer(16, 16, 3, 0));
    let e = FilteredRenderer::new(&src, NoFilter, PipelineSettings::interactive(8, 8)).err().unwrap();
    assert!(matches!(e, PipelineError::SourceResolution { .. }));
}
