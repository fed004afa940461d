//! Memory of the filtered pipeline: independent of spp (the further samples are traced and
//! looked up a chunk at a time), the chunking changes no bit of the frame, and the estimate
//! of `filtrace_pipeline::memory` agrees with what the allocator is really asked for.
//!
//! The allocator of this test binary counts live bytes and their peak; every test holds
//! the lock of `counting_alloc::serial` so that no other test allocates while one measures.

use std::sync::atomic::Ordering;

use filtrace_core::{Image, Rgb, Vec2, Vec3};
use filtrace_pipeline::memory::{adaptive_bytes, filter_bytes, frame_bytes};
use filtrace_pipeline::*;

#[path = "support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::{serial, LIVE, PEAK};

/// Peak live bytes above the start while `f` runs, and its result.
fn peak_during<T>(f: impl FnOnce() -> T) -> (u64, T) {
    let base = LIVE.load(Ordering::SeqCst);
    PEAK.store(base, Ordering::SeqCst);
    let out = f();
    ((PEAK.load(Ordering::SeqCst) - base) as u64, out)
}

/// Two planes meeting at x = 5.3 (a geometric edge for the lookup), deterministic noise on
/// every sample; the guide rays (not the further samples) of the top band escape, so that
/// lookups there find no guide that hit.
struct Scene;

fn noise(key: SampleKey, salt: u64) -> f32 {
    let mut h = key.seed ^ salt.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    for v in [key.x as u64, key.y as u64, key.sample as u64] {
        h = (h ^ v).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 31;
    }
    (h >> 40) as f32 / (1u64 << 24) as f32
}

impl PathSource for Scene {
    fn trace(&self, key: SampleKey, film: Vec2, paths: u32) -> EyeSample {
        if film.y < 2.0 && key.sample == 0 {
            return EyeSample { direct: Rgb::splat(0.3), ..Default::default() };
        }
        let (normal, depth, albedo) =
            if film.x < 5.3 { (Vec3::Z, 2.0, 0.5) } else { (Vec3::new(0.6, 0.0, 0.8), 3.0, 0.8) };
        let indirect = if paths > 0 { Rgb::new(noise(key, 1), 0.5, noise(key, 2)) } else { Rgb::ZERO };
        EyeSample {
            hit: Some(HitGeometry { normal, depth }),
            albedo: Rgb::new(albedo, noise(key, 3), 0.25),
            position: Vec3::new(film.x, film.y, depth),
            direct: Rgb::new(noise(key, 4), film.y * 0.01, 1.0),
            indirect,
        }
    }
}

fn layers(f: &Frame) -> [&Image; 8] {
    let im = &f.images;
    [
        &im.color,
        &im.noisy,
        &im.direct,
        &im.indirect,
        &im.filtered_indirect,
        &im.filtered_direct,
        &im.indirect_map,
        &im.filtered_map,
    ]
}

fn assert_same_bits(a: &Frame, b: &Frame, what: &str) {
    for (k, (x, y)) in layers(a).iter().zip(layers(b)).enumerate() {
        let bits = |i: &Image| i.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(x), bits(y), "{what}: layer {k} differs");
    }
    assert_eq!(a.lookup_failures, b.lookup_failures, "{what}: lookup failures");
}

#[test]
fn chunked_frames_equal_the_unchunked_frame_bit_for_bit() {
    let _s = serial();
    for (spp, demod, fd) in [(1, true, false), (2, true, false), (5, false, true), (9, true, false)] {
        let st = PipelineSettings {
            spp,
            seed: 11,
            demodulate_albedo: demod,
            filter_direct: fd,
            ..PipelineSettings::paper(13, 9)
        };
        let filter = || filter_by_name("atrous", Some(10.0)).unwrap();
        let mut whole = FilteredRenderer::new(Scene, filter(), st.clone()).unwrap();
        whole.set_sample_chunk(usize::MAX);
        let want = whole.render_frame().unwrap().clone();
        assert!(want.lookup_failures > 0 || spp == 1, "the sky band should make lookups fail");
        for chunk in [1, 2, 7, 64, 1000] {
            let mut p = FilteredRenderer::new(Scene, filter(), st.clone()).unwrap();
            p.set_sample_chunk(chunk);
            assert_same_bits(p.render_frame().unwrap(), &want, &format!("spp {spp}, chunk {chunk}"));
        }
    }
}

#[test]
fn the_pipelines_buffers_do_not_grow_with_spp() {
    let _s = serial();
    let bytes = |spp: u32| {
        let st = PipelineSettings { spp, ..PipelineSettings::paper(64, 64) };
        let mut p = FilteredRenderer::new(Scene, NoFilter, st.clone()).unwrap();
        p.set_sample_chunk(4096);
        p.render_frame().unwrap();
        let est = frame_bytes(&st, None, 4096).total();
        assert_eq!(p.buffer_bytes(), est, "spp {spp}: estimate vs buffers built");
        p.buffer_bytes()
    };
    let (few, many) = (bytes(4), bytes(4096));
    assert_eq!(few, bytes(1025), "records are bounded by the chunk from 64x64x1024 samples on");
    assert_eq!(many, few, "spp 4096 holds what spp 4 holds");
    // The case: 512x512 at 4096 spp stored 56 GB of records.
    let st = PipelineSettings { spp: 4096, ..PipelineSettings::paper(512, 512) };
    let est = frame_bytes(&st, None, SAMPLE_CHUNK);
    assert!(est.total() < 64 << 20, "{est}");
    let st4 = PipelineSettings { spp: 4, ..st.clone() };
    assert_eq!(est.total(), frame_bytes(&st4, None, SAMPLE_CHUNK).total());
}

/// Jitter of a further sample in its pixel, as the pipeline draws it (a hash of the key).
fn jitter(key: SampleKey) -> Vec2 {
    use filtrace_core::rng::{splitmix64, unit_f32};
    let mut h = key.seed ^ 0x243f_6a88_85a3_08d3;
    for v in [key.x as u64, key.y as u64, key.sample as u64] {
        h = splitmix64(h ^ v.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    }
    Vec2::new(unit_f32(h), unit_f32(splitmix64(h)))
}

fn rgb(im: &Image, p: usize) -> Rgb {
    let d = &im.data()[3 * p..3 * p + 3];
    Rgb::new(d[0], d[1], d[2])
}

fn set(im: &mut Image, p: usize, c: Rgb) {
    im.data_mut()[3 * p..3 * p + 3].copy_from_slice(&c.to_array());
}

/// The frame as the pipeline made it before it streamed its further samples: the guide
/// rays (one `trace` per pixel), the filter, then a record of *every* further sample,
/// then the lookup and box mean over the stored records. Serial and naive, from public
/// parts only (lookup, filter slot, demodulation constant).
#[allow(clippy::needless_range_loop)] // pixel `p` indexes every layer alike
fn two_pass_frame<S: PathSource, F: IndirectFilter>(src: &S, filter: &mut F, st: &PipelineSettings) -> Frame {
    use filtrace_pipeline::pipeline::DEMODULATION_EPS as EPS;
    let (w, h) = (st.width as usize, st.height as usize);
    let (n, extra, demod) = (w * h, st.spp as usize - 1, st.demodulate_albedo);
    let img = |c| Image::new(w, h, c);
    let mut guide =
        GuideLayers { normal: img(3), depth: img(1), albedo: img(3), position: img(3), coverage: img(1) };
    let (mut map, mut fmap) = (img(3), img(3));
    let mut geometry = GuideGeometry::new(w, h);
    let mut guide_direct = vec![Rgb::ZERO; n];
    // 1. Guide rays.
    for p in 0..n {
        let key = SampleKey { x: (p % w) as u32, y: (p / w) as u32, sample: 0, seed: st.seed };
        let e = src.trace(key, Vec2::new(key.x as f32 + 0.5, key.y as f32 + 0.5), st.indirect_paths);
        geometry.hits[p] = e.hit;
        guide_direct[p] = e.direct;
        let reflects = !demod || e.albedo.max_element() > 0.0;
        let (nrm, depth) = e.hit.map_or((Rgb::ZERO, 0.0), |g| (g.normal, g.depth));
        set(&mut guide.normal, p, if reflects { nrm } else { Rgb::ZERO });
        guide.depth.data_mut()[p] = depth;
        set(&mut guide.albedo, p, e.albedo);
        set(&mut guide.position, p, e.position);
        guide.coverage.data_mut()[p] = if e.hit.is_some() && reflects { 1.0 } else { 0.0 };
        set(&mut map, p, if demod { e.indirect / (e.albedo + EPS) } else { e.indirect });
    }
    // 2. Filter.
    filter.apply(&map, &guide, &mut fmap).unwrap();
    // 3. Every further sample, stored.
    let mut records = Vec::with_capacity(n * extra);
    for p in 0..n {
        for s in 1..=extra as u32 {
            let key = SampleKey { x: (p % w) as u32, y: (p / w) as u32, sample: s, seed: st.seed };
            let film = Vec2::new(key.x as f32, key.y as f32) + jitter(key);
            records.push((film, src.trace(key, film, 0)));
        }
    }
    // 4. Lookup and box mean.
    let remod = |a: Rgb| if demod { a + EPS } else { Rgb::ONE };
    let inv = 1.0 / (extra + 1) as f32;
    let mut f = Frame::default();
    let im = &mut f.images;
    for l in [&mut im.color, &mut im.noisy, &mut im.direct, &mut im.indirect, &mut im.filtered_indirect] {
        *l = img(3);
    }
    for p in 0..n {
        let m = remod(rgb(&guide.albedo, p));
        let (mut d, mut ind, mut find) = (guide_direct[p], m * rgb(&map, p), m * rgb(&fmap, p));
        for (film, e) in &records[p * extra..(p + 1) * extra] {
            d += e.direct;
            let Some(hit) = &e.hit else { continue };
            match most_similar_guide(&geometry, *film, hit) {
                Some(g) => {
                    ind += remod(e.albedo) * rgb(&map, g);
                    find += remod(e.albedo) * rgb(&fmap, g);
                }
                None => f.lookup_failures += 1,
            }
        }
        let (d, ind, find) = (d * inv, ind * inv, find * inv);
        set(&mut im.direct, p, d);
        set(&mut im.indirect, p, ind);
        set(&mut im.filtered_indirect, p, find);
        set(&mut im.noisy, p, d + ind);
        set(&mut im.color, p, d + find);
    }
    if st.filter_direct {
        im.filtered_direct = img(3);
        filter.apply(&im.direct, &guide, &mut im.filtered_direct).unwrap();
        for p in 0..n {
            set(&mut im.color, p, rgb(&im.filtered_direct, p) + rgb(&im.filtered_indirect, p));
        }
    }
    (im.indirect_map, im.filtered_map, im.guide) = (map, fmap, guide);
    f
}

#[test]
fn streamed_frames_equal_the_two_pass_frame_with_every_sample_stored() {
    let _s = serial();
    let configs = [(1, true, false), (2, true, false), (5, false, true), (9, true, false), (4, true, true)];
    for name in ["none", "atrous", "guided"] {
        for &(spp, demod, fd) in &configs {
            let st = PipelineSettings {
                spp,
                seed: 3,
                demodulate_albedo: demod,
                filter_direct: fd,
                ..PipelineSettings::paper(14, 10)
            };
            let want = two_pass_frame(&Scene, &mut filter_by_name(name, Some(10.0)).unwrap(), &st);
            let mut p = FilteredRenderer::new(Scene, filter_by_name(name, Some(10.0)).unwrap(), st).unwrap();
            p.set_sample_chunk(17); // chunks that split pixels
            assert_same_bits(p.render_frame().unwrap(), &want, &format!("{name} spp {spp}"));
        }
    }
}

#[test]
fn streamed_frames_on_the_path_tracer_equal_the_two_pass_frame() {
    let _s = serial();
    use filtrace_render::{RenderSettings, Renderer};
    let (w, h) = (20, 15);
    let scene = filtrace_scene::builtin::builtin("cornell").unwrap();
    let r =
        Renderer::new(scene, RenderSettings { width: w, height: h, spp: 1, max_depth: 4, seed: 5 }).unwrap();
    let src = RenderSource::new(r);
    for spp in [1, 3, 6] {
        let st = PipelineSettings { spp, seed: 5, ..PipelineSettings::paper(w, h) };
        let filter = || filter_by_name("atrous", Some(src.scene_scale())).unwrap();
        let want = two_pass_frame(&src, &mut filter(), &st);
        let mut p = FilteredRenderer::new(&src, filter(), st).unwrap();
        p.set_sample_chunk(250);
        assert_same_bits(p.render_frame().unwrap(), &want, &format!("cornell spp {spp}"));
    }
}

/// Peak bytes of building a pipeline with filter `name` and rendering one frame (adaptive
/// or not), measured in a fresh process (this binary, running [`measure_child`], on 2
/// threads) so that no earlier test has already made the filters' thread-local scratch;
/// and the estimate.
fn measured_and_estimated(name: &str, adaptive: bool, w: u32, h: u32, spp: u32) -> (u64, u64) {
    let exe = std::env::current_exe().unwrap();
    let o = std::process::Command::new(exe)
        .args(["--exact", "measure_child", "--nocapture", "--test-threads", "1"])
        .env("FILTRACE_MEASURE", format!("{name} {adaptive} {w} {h} {spp}"))
        .env("RAYON_NUM_THREADS", "2")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr);
    let peak = text
        .lines()
        .find_map(|l| l.split("measured peak ").nth(1))
        .unwrap_or_else(|| panic!("no measurement from the child: {text}"));
    let st = PipelineSettings { spp, ..PipelineSettings::paper(w, h) };
    let est = frame_bytes(&st, None, SAMPLE_CHUNK).total()
        + filter_bytes(name, w, h)
        + if adaptive { adaptive_bytes(w, h) } else { 0 };
    (peak.trim().parse().unwrap(), est)
}

/// The child of [`measured_and_estimated`]: does nothing unless `FILTRACE_MEASURE` is set.
#[test]
fn measure_child() {
    let Ok(spec) = std::env::var("FILTRACE_MEASURE") else { return };
    let _s = serial();
    let v: Vec<&str> = spec.split(' ').collect();
    let (name, adaptive) = (v[0], v[1] == "true");
    let [w, h, spp] = [2, 3, 4].map(|i| v[i].parse::<u32>().unwrap());
    // Start rayon's pool first: its threads are not the frame's memory.
    rayon::join(|| (), || ());
    let st = PipelineSettings { spp, ..PipelineSettings::paper(w, h) };
    let (peak, ()) = peak_during(|| {
        let f = filter_by_name(name, Some(10.0)).unwrap();
        let mut p = FilteredRenderer::new(Scene, f, st).unwrap();
        if adaptive {
            let (_, plan) = p.render_frame_adaptive(&filtrace_adaptive::AdaptiveParams::paper()).unwrap();
            drop(plan);
        } else {
            p.render_frame().unwrap();
        }
    });
    println!("measured peak {peak}");
}

#[test]
fn the_estimate_matches_the_allocators_peak_for_every_filter() {
    let mut bad = Vec::new();
    for (name, adaptive) in
        [("none", false), ("atrous", false), ("guided", false), ("bilateral", false), ("none", true)]
    {
        for (w, h, spp) in [(96, 64, 4), (160, 120, 2)] {
            let (peak, est) = measured_and_estimated(name, adaptive, w, h, spp);
            let ratio = peak as f64 / est as f64;
            let line =
                format!("{name}, adaptive {adaptive}, {w}x{h}: peak {peak} vs estimate {est} ({ratio:.3})");
            eprintln!("{line}; {:.1} bytes per pixel", peak as f64 / (w * h) as f64);
            if !(0.9..=1.1).contains(&ratio) {
                bad.push(line);
            }
        }
    }
    assert!(bad.is_empty(), "estimates off by more than 10 %: {bad:#?}");
}
