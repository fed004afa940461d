//! The pipeline on filtrace's own path tracer (built-in Cornell box).

use filtrace_core::Image;
use filtrace_pipeline::*;
use filtrace_render::{RenderSettings, Renderer};

#[path = "support/frames.rs"]
mod frames;
use frames::assert_frames_identical;

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

/// The path tracer seen through `trace` only: the pipeline then calls it once per pixel
/// with the pixel's whole path count (the per-pixel reference of the batched pass).
struct PerPixel<'a>(&'a RenderSource);

impl PathSource for PerPixel<'_> {
    fn trace(&self, key: SampleKey, film: filtrace_core::Vec2, paths: u32) -> EyeSample {
        self.0.trace(key, film, paths)
    }
    fn resolution(&self) -> Option<(u32, u32)> {
        self.0.resolution()
    }
}

/// Uneven per-pixel counts with zeros, a deterministic hash of the pixel.
fn uneven_counts(n: usize) -> Vec<u32> {
    (0..n as u64).map(|p| ((p.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 59) % 6) as u32).collect()
}

#[test]
fn batched_indirect_paths_equal_the_per_pixel_paths_bit_for_bit() {
    // The batched guide pass (§4.3 schedule, one path per call) against the per-pixel one,
    // on the real path tracer: uneven counts with zeros, pixels spanning batches (batch
    // sizes 1, 7 and the resolution), a uniform frame, and a second eye sample per pixel.
    let (w, h) = (20, 14);
    let src = RenderSource::new(renderer(w, h, 5, 11));
    assert!(src.traces_single_paths());
    let st = PipelineSettings { seed: 11, spp: 2, ..PipelineSettings::paper(w, h) };
    let counts = uneven_counts((w * h) as usize);
    assert!(counts.contains(&0) && counts.iter().any(|&c| c >= 4));
    let mut reference = FilteredRenderer::new(PerPixel(&src), NoFilter, st.clone()).unwrap();
    let want = reference.render_frame_with_counts(Some(&counts)).unwrap().clone();
    let want_uniform = {
        let st3 = PipelineSettings { indirect_paths: 3, ..st.clone() };
        reference.set_settings(st3).unwrap();
        reference.render_frame().unwrap().clone()
    };
    assert!(want.images.indirect_map.mean()[0] > 0.0, "the test needs indirect light");
    for batch in [None, Some(7), Some(1)] {
        let mut p = FilteredRenderer::new(&src, NoFilter, st.clone()).unwrap();
        p.set_batch_size(batch);
        let got = p.render_frame_with_counts(Some(&counts)).unwrap();
        assert_frames_identical(got, &want, &format!("counts, batch {batch:?}"));
        p.set_settings(PipelineSettings { indirect_paths: 3, ..st.clone() }).unwrap();
        let got = p.render_frame().unwrap();
        assert_frames_identical(got, &want_uniform, &format!("uniform, batch {batch:?}"));
    }
}

#[test]
fn batched_frames_do_not_depend_on_the_thread_count() {
    let (w, h) = (16, 12);
    let src = RenderSource::new(renderer(w, h, 4, 5));
    let st = PipelineSettings { seed: 5, ..PipelineSettings::interactive(w, h) };
    let counts = uneven_counts((w * h) as usize);
    let frame_with = |threads: usize, batch: Option<usize>| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut p = FilteredRenderer::new(&src, NoFilter, st.clone()).unwrap();
            p.set_batch_size(batch);
            p.render_frame_with_counts(Some(&counts)).unwrap().clone()
        })
    };
    let one = frame_with(1, None);
    for (threads, batch) in [(3, None), (4, Some(5)), (2, Some(64))] {
        assert_frames_identical(
            &frame_with(threads, batch),
            &one,
            &format!("{threads} threads, batch {batch:?}"),
        );
    }
}

#[test]
fn pixels_with_more_paths_than_one_trace_paths_call_equal_the_per_pixel_paths() {
    // The default guide pass traces a pixel's paths in calls of at most 64: a pixel with
    // more (and one with exactly 64, 65) must still sum them in path order from zero.
    let (w, h) = (4, 3);
    let src = RenderSource::new(renderer(w, h, 4, 3));
    let st = PipelineSettings { seed: 3, ..PipelineSettings::interactive(w, h) };
    let counts: Vec<u32> = vec![0, 1, 63, 64, 65, 129, 200, 2, 64, 3, 130, 1];
    let mut reference = FilteredRenderer::new(PerPixel(&src), NoFilter, st.clone()).unwrap();
    let want = reference.render_frame_with_counts(Some(&counts)).unwrap().clone();
    for batch in [None, Some(50)] {
        let mut p = FilteredRenderer::new(&src, NoFilter, st.clone()).unwrap();
        p.set_batch_size(batch);
        let got = p.render_frame_with_counts(Some(&counts)).unwrap();
        assert_frames_identical(got, &want, &format!("batch {batch:?}"));
    }
}

#[test]
fn first_hit_is_the_geometry_of_the_eye_ray_without_its_light() {
    // `first_hit` (the adaptive pre-pass) against `trace(.., 0)`: the same hit, albedo and
    // position bit for bit, at the guide rays and at jittered positions, misses included.
    let (w, h) = (24, 18);
    let src = RenderSource::new(renderer(w, h, 3, 9));
    let mut misses = 0;
    for y in 0..h {
        for x in 0..w {
            for (sample, off) in [(0, (0.5, 0.5)), (1, (0.13, 0.91))] {
                let key = SampleKey { x, y, sample, seed: 9 };
                let film = filtrace_core::Vec2::new(x as f32 + off.0, y as f32 + off.1);
                let (a, b) = (src.first_hit(key, film), src.trace(key, film, 0));
                let bits = |e: &EyeSample| {
                    let hit = e.hit.map(|h| (h.normal.to_array().map(f32::to_bits), h.depth.to_bits()));
                    (hit, e.albedo.to_array().map(f32::to_bits), e.position.to_array().map(f32::to_bits))
                };
                assert_eq!(bits(&a), bits(&b), "pixel ({x}, {y}), sample {sample}");
                misses += a.hit.is_none() as u32;
            }
        }
    }
    assert!(misses < w * h * 2, "the test needs hits");
}

#[test]
fn filtered_frames_do_not_depend_on_the_thread_count() {
    // The whole frame (guide pass, filter, lookup at 2 spp) with 1, 2 and 3 threads, for
    // every filter. Tall enough, with a small radius, for the guided filter's box sums to
    // run in several bands of rows (which once were sized by the thread count, changing
    // the rounding by ~1e-8; fixed in commit 9744f4a).
    let (w, h) = (24, 160);
    let src = RenderSource::new(renderer(w, h, 3, 21));
    let st = PipelineSettings { seed: 21, spp: 2, ..PipelineSettings::paper(w, h) };
    for name in ["none", "atrous", "guided", "bilateral"] {
        let frame_with = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let radius = (name == "guided" || name == "bilateral").then_some(3);
                let f = FilterChoice { radius, ..FilterChoice::named(name) }
                    .build(Some(src.scene_scale()))
                    .unwrap();
                let mut p = FilteredRenderer::new(&src, f, st.clone()).unwrap();
                p.render_frame().unwrap().clone()
            })
        };
        let one = frame_with(1);
        assert!(one.images.filtered_map.mean()[0] > 0.0, "the test needs indirect light");
        for threads in [2, 3] {
            assert_frames_identical(&frame_with(threads), &one, &format!("{name}, {threads} threads"));
        }
    }
}
