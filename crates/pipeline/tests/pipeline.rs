//! The filtered pipeline driven by analytic sources, so every expected value is known.

use filtrace_core::{Image, Rgb, Vec2, Vec3};
use filtrace_pipeline::*;

/// Two planes meeting at a vertical edge at film x = `EDGE_X` (not on a pixel boundary).
/// Left: facing the camera at depth 2, albedo 0.5, direct 1. Right: tilted, depth 3,
/// albedo 0.8, direct 0. Irradiance left 1, right 0, so indirect = albedo * E.
/// With `noise`, both direct and indirect get a deterministic per-key multiplicative noise.
struct Edge {
    noise: bool,
}
const EDGE_X: f32 = 8.3;
const A_LEFT: f32 = 0.5;

fn hash01(key: SampleKey, salt: u64) -> f32 {
    let mut h = key.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ salt;
    for v in [key.x as u64, key.y as u64, key.sample as u64] {
        h = (h ^ v).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 29;
    }
    (h >> 40) as f32 / (1u64 << 24) as f32
}

impl PathSource for Edge {
    fn trace(&self, key: SampleKey, film: Vec2, paths: u32) -> EyeSample {
        let left = film.x < EDGE_X;
        let (normal, depth, albedo, direct, e) = if left {
            (Vec3::Z, 2.0, A_LEFT, 1.0, 1.0)
        } else {
            (Vec3::new(0.6, 0.0, 0.8), 3.0, 0.8, 0.0, 0.0)
        };
        let (nd, ni) = if self.noise { (2.0 * hash01(key, 1), 2.0 * hash01(key, 2)) } else { (1.0, 1.0) };
        let indirect = if paths > 0 { Rgb::splat(albedo * e * ni) } else { Rgb::ZERO };
        EyeSample {
            hit: Some(HitGeometry { normal, depth }),
            albedo: Rgb::splat(albedo),
            direct: Rgb::splat(direct * nd) + Rgb::new(0.0, 0.01 * film.y, 0.0),
            indirect,
            ..Default::default()
        }
    }
}

fn settings(w: u32, h: u32, spp: u32) -> PipelineSettings {
    PipelineSettings { spp, seed: 7, ..PipelineSettings::paper(w, h) }
}

fn max_abs_diff(a: &Image, b: &Image) -> f32 {
    assert!(a.same_size(b) && a.channels() == b.channels());
    a.data().iter().zip(b.data()).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

fn sum(a: &Image, b: &Image) -> Image {
    let d = a.data().iter().zip(b.data()).map(|(x, y)| x + y).collect();
    Image::from_vec(a.width(), a.height(), a.channels(), d).unwrap()
}

#[test]
fn without_filtering_direct_plus_indirect_is_the_unfiltered_colour() {
    for spp in [1, 4] {
        for demodulate_albedo in [true, false] {
            for filter_direct in [false, true] {
                let st = PipelineSettings { demodulate_albedo, filter_direct, ..settings(16, 12, spp) };
                let mut r = FilteredRenderer::new(Edge { noise: true }, NoFilter, st).unwrap();
                let im = &r.render_frame().unwrap().images;
                assert_eq!(im.color.count_non_finite(), 0);
                assert!(max_abs_diff(&im.color, &im.noisy) < 1e-6);
                assert!(max_abs_diff(&im.noisy, &sum(&im.direct, &im.indirect)) < 1e-6);
                assert!(max_abs_diff(&im.indirect, &im.filtered_indirect) < 1e-6);
            }
        }
    }
}

#[test]
fn one_sample_per_pixel_is_the_guide_rays_path_traced_colour() {
    let src = Edge { noise: true };
    let mut r = FilteredRenderer::new(&src, NoFilter, settings(16, 4, 1)).unwrap();
    let im = &r.render_frame().unwrap().images;
    for y in 0..4u32 {
        for x in 0..16u32 {
            let key = SampleKey { x, y, sample: 0, seed: 7 };
            let e = src.trace(key, Vec2::new(x as f32 + 0.5, y as f32 + 0.5), 1);
            let want = e.direct + e.indirect;
            let got = im.color.rgb(x as usize, y as usize);
            assert!(
                (got - want).abs().max_element() < 1e-5 * (1.0 + want.max_element()),
                "({x},{y}) {got} vs {want}"
            );
        }
    }
}

#[test]
fn supersamples_never_take_indirect_light_across_a_geometric_edge() {
    // Noise-free: the direct layer is the fraction of a pixel's samples on the left plane,
    // and only left-plane samples may receive indirect light (A_LEFT each).
    let mut r = FilteredRenderer::new(Edge { noise: false }, NoFilter, settings(16, 8, 16)).unwrap();
    let frame = r.render_frame().unwrap();
    assert_eq!(frame.lookup_failures, 0);
    let im = &frame.images;
    let mut edge_pixels_checked = 0;
    for y in 0..8 {
        for x in 0..16 {
            let left_fraction = im.direct.rgb(x, y).x;
            let ind = im.filtered_indirect.rgb(x, y).x;
            assert!(
                (ind - A_LEFT * left_fraction).abs() < 1e-5,
                "pixel ({x},{y}): indirect {ind}, left fraction {left_fraction}"
            );
            if left_fraction > 0.0 && left_fraction < 1.0 {
                edge_pixels_checked += 1;
            }
        }
    }
    // Pixel column 8 straddles the edge: its samples split between the planes.
    assert_eq!(edge_pixels_checked, 8);
}

#[test]
fn same_seed_same_frame_other_seed_other_frame_and_buffers_are_reused() {
    let mut a = FilteredRenderer::new(Edge { noise: true }, NoFilter, settings(12, 10, 4)).unwrap();
    let first = a.render_frame().unwrap().images.color.clone();
    let again = a.render_frame().unwrap().images.color.clone();
    assert_eq!(first, again);
    let mut b = FilteredRenderer::new(Edge { noise: true }, NoFilter, settings(12, 10, 4)).unwrap();
    assert_eq!(b.render_frame().unwrap().images.color, first);
    b.set_settings(PipelineSettings { seed: 8, ..settings(12, 10, 4) }).unwrap();
    assert_ne!(b.render_frame().unwrap().images.color, first);
    // Resizing between frames.
    b.set_settings(settings(5, 3, 2)).unwrap();
    let f = b.render_frame().unwrap();
    assert_eq!((f.images.color.width(), f.images.color.height()), (5, 3));
    assert!(f.timings.total_ms >= f.timings.guide_ms);
}

/// A filter that replaces the map by a constant, to see that its output is what is used.
struct Constant(f32);
impl IndirectFilter for Constant {
    fn label(&self) -> String {
        "constant".into()
    }
    fn apply(&mut self, _noisy: &Image, guide: &GuideLayers, out: &mut Image) -> Result<(), String> {
        assert_eq!(guide.normal.channels(), 3);
        assert_eq!(guide.depth.channels(), 1);
        out.data_mut().fill(self.0);
        Ok(())
    }
}

#[test]
fn the_filtered_map_is_remodulated_by_each_samples_albedo() {
    let mut r = FilteredRenderer::new(Edge { noise: true }, Constant(2.0), settings(16, 4, 4)).unwrap();
    let im = &r.render_frame().unwrap().images;
    // Pixel 2 lies wholly on the left plane, pixel 14 on the right.
    let eps = 1e-3;
    assert!((im.filtered_indirect.rgb(2, 1).x - 2.0 * (A_LEFT + eps)).abs() < 1e-5);
    assert!((im.filtered_indirect.rgb(14, 1).x - 2.0 * (0.8 + eps)).abs() < 1e-5);
    assert!(max_abs_diff(&im.color, &sum(&im.direct, &im.filtered_indirect)) < 1e-6);
    // The noisy layer still uses the unfiltered map.
    assert!(max_abs_diff(&im.noisy, &im.color) > 0.1);
}

#[test]
fn per_pixel_indirect_counts() {
    struct Counting;
    impl PathSource for Counting {
        fn trace(&self, _k: SampleKey, _f: Vec2, paths: u32) -> EyeSample {
            let hit = Some(HitGeometry { normal: Vec3::Z, depth: 1.0 });
            EyeSample { hit, albedo: Rgb::ONE, indirect: Rgb::splat(paths as f32), ..Default::default() }
        }
    }
    let st = PipelineSettings { demodulate_albedo: false, ..settings(4, 2, 1) };
    let mut r = FilteredRenderer::new(Counting, NoFilter, st).unwrap();
    let counts: Vec<u32> = (0..8).collect();
    let im = &r.render_frame_with_counts(Some(&counts)).unwrap().images;
    for (i, c) in counts.iter().enumerate() {
        assert_eq!(im.indirect_map.rgb(i % 4, i / 4).x, *c as f32);
    }
    let err = r.render_frame_with_counts(Some(&counts[..7])).unwrap_err();
    assert_eq!(err, PipelineError::CountsLength { expected: 8, got: 7 });
}

#[test]
fn bad_settings_are_errors_not_panics() {
    let bad = [
        settings(0, 4, 1),
        settings(4, 0, 1),
        settings(4, 4, 0),
        settings(40000, 4, 1),
        settings(30000, 30000, 1),
    ];
    for st in bad {
        let e = FilteredRenderer::new(Edge { noise: false }, NoFilter, st).err().expect("must fail");
        assert!(!e.to_string().is_empty());
    }
}

#[test]
fn black_emitters_are_background_for_the_filter_but_keep_their_geometry_for_the_lookup() {
    struct Lamp;
    impl PathSource for Lamp {
        fn trace(&self, _k: SampleKey, film: Vec2, paths: u32) -> EyeSample {
            let hit = Some(HitGeometry { normal: Vec3::Y, depth: 1.0 });
            let lamp = film.x < 2.0;
            let albedo = if lamp { Rgb::ZERO } else { Rgb::splat(0.5) };
            let indirect = if paths > 0 && !lamp { Rgb::splat(0.5) } else { Rgb::ZERO };
            EyeSample { hit, albedo, direct: Rgb::ONE, indirect, ..Default::default() }
        }
    }
    struct Check;
    impl IndirectFilter for Check {
        fn label(&self) -> String {
            "check".into()
        }
        fn apply(&mut self, noisy: &Image, guide: &GuideLayers, out: &mut Image) -> Result<(), String> {
            for x in 0..4 {
                let lamp = x < 2;
                assert_eq!(guide.normal.rgb(x, 0) == Vec3::ZERO, lamp, "x = {x}");
                assert_eq!(guide.coverage.pixel(x, 0)[0], if lamp { 0.0 } else { 1.0 });
            }
            out.data_mut().copy_from_slice(noisy.data());
            Ok(())
        }
    }
    let mut r = FilteredRenderer::new(Lamp, Check, settings(4, 1, 1)).unwrap();
    let f = r.render_frame().unwrap();
    assert_eq!(f.lookup_failures, 0);
    assert!((f.images.color.rgb(3, 0).x - 1.5).abs() < 1e-5);
}

/// A source traced one path at a time that records every (pixel, path) it is asked for.
struct PathLog {
    w: u32,
    log: std::sync::Mutex<Vec<Vec<u32>>>,
    whole_pixel_calls: std::sync::atomic::AtomicU64,
}

impl PathSource for PathLog {
    fn trace(&self, _k: SampleKey, _f: Vec2, paths: u32) -> EyeSample {
        if paths > 0 {
            self.whole_pixel_calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        let hit = Some(HitGeometry { normal: Vec3::Z, depth: 1.0 });
        EyeSample { hit, albedo: Rgb::ONE, ..Default::default() }
    }
    fn traces_single_paths(&self) -> bool {
        true
    }
    fn trace_path(&self, key: SampleKey, film: Vec2, path: u32) -> EyeSample {
        assert_eq!(key.sample, 0, "indirect paths belong to the guide ray");
        assert_eq!(
            film,
            Vec2::new(key.x as f32 + 0.5, key.y as f32 + 0.5),
            "guide rays go through pixel centres"
        );
        self.log.lock().unwrap()[(key.y * self.w + key.x) as usize].push(path);
        let hit = Some(HitGeometry { normal: Vec3::Z, depth: 1.0 });
        // Path k carries k: the mean over 0..n is (n - 1) / 2.
        EyeSample { hit, albedo: Rgb::ONE, indirect: Rgb::splat(path as f32), ..Default::default() }
    }
}

#[test]
fn batched_guide_pass_traces_every_path_exactly_once() {
    let (w, h) = (7u32, 5u32);
    let n = (w * h) as usize;
    let counts: Vec<u32> = (0..n as u32).map(|p| (p * 5 + 3) % 7).collect();
    let st = PipelineSettings { demodulate_albedo: false, ..settings(w, h, 1) };
    for batch in [None, Some(1), Some(4), Some(1000)] {
        let src = PathLog {
            w,
            log: std::sync::Mutex::new(vec![Vec::new(); n]),
            whole_pixel_calls: Default::default(),
        };
        let mut r = FilteredRenderer::new(&src, NoFilter, st.clone()).unwrap();
        r.set_batch_size(batch);
        let map = r.render_frame_with_counts(Some(&counts)).unwrap().images.indirect_map.clone();
        let mut log = src.log.into_inner().unwrap();
        for (p, paths) in log.iter_mut().enumerate() {
            paths.sort_unstable();
            assert_eq!(*paths, (0..counts[p]).collect::<Vec<_>>(), "batch {batch:?}, pixel {p}");
            let want = if counts[p] == 0 { 0.0 } else { (counts[p] - 1) as f32 / 2.0 };
            assert!(
                (map.rgb(p % w as usize, p / w as usize).x - want).abs() < 1e-6,
                "batch {batch:?}, pixel {p}"
            );
        }
        assert_eq!(src.whole_pixel_calls.into_inner(), 0, "no pixel traced its paths in one call");
    }
}
