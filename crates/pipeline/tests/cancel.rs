//! Cancelling a filtered frame (`FilteredRenderer::set_cancel`): during the guide rays
//! there is no frame; during the further samples the frame is exactly the frame of fewer
//! samples per pixel.

use filtrace_core::{Image, Rgb, Vec2, Vec3};
use filtrace_pipeline::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A slanted wall with a deterministic per-sample noise; sets `cancel` when it traces
/// sample `at` (0 = the guide ray) of any pixel.
struct Tripwire {
    cancel: Arc<AtomicBool>,
    at: Option<u32>,
}

fn hash01(key: SampleKey) -> f32 {
    let mut h = key.seed ^ 0x5851_f42d_4c95_7f2d;
    for v in [key.x as u64, key.y as u64, key.sample as u64] {
        h = (h ^ v).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 29;
    }
    (h >> 40) as f32 / (1u64 << 24) as f32
}

impl PathSource for Tripwire {
    fn trace(&self, key: SampleKey, film: Vec2, paths: u32) -> EyeSample {
        if Some(key.sample) == self.at {
            self.cancel.store(true, Ordering::SeqCst);
        }
        let n = hash01(key);
        EyeSample {
            hit: Some(HitGeometry { normal: Vec3::Z, depth: 2.0 + 0.05 * film.x }),
            albedo: Rgb::splat(0.5),
            direct: Rgb::new(n, 0.5 * n, 0.1 * film.y),
            indirect: if paths > 0 { Rgb::splat(0.3 * n) } else { Rgb::ZERO },
            ..Default::default()
        }
    }
}

fn renderer(spp: u32, at: Option<u32>) -> (FilteredRenderer<Tripwire, NoFilter>, Arc<AtomicBool>) {
    let cancel = Arc::new(AtomicBool::new(false));
    let st = PipelineSettings { spp, seed: 5, ..PipelineSettings::paper(12, 8) };
    let mut r = FilteredRenderer::new(Tripwire { cancel: cancel.clone(), at }, NoFilter, st).unwrap();
    r.set_cancel(Some(cancel.clone()));
    (r, cancel)
}

fn bits(im: &Image) -> Vec<u32> {
    im.data().iter().map(|v| v.to_bits()).collect()
}

#[test]
fn a_frame_cancelled_in_its_further_samples_is_the_frame_of_fewer_samples() {
    // Passes of further samples: 1, 1, 2, 4, 8 (samples 9..=16), ... Cancelled in the pass
    // of sample 12: that pass is dropped (or, if every pixel had already passed its check,
    // kept and the next one not started).
    let (mut r, cancel) = renderer(40, Some(12));
    let frame = r.render_frame().expect("a frame after the guide rays").clone();
    assert!(cancel.load(Ordering::SeqCst));
    assert!([9, 17].contains(&frame.spp_done), "spp_done {}", frame.spp_done);
    let (mut fewer, _) = renderer(frame.spp_done, None);
    let want = fewer.render_frame().unwrap();
    assert_eq!(want.spp_done, frame.spp_done);
    let (a, b) = (&frame.images, &want.images);
    for (name, x, y) in [
        ("color", &a.color, &b.color),
        ("noisy", &a.noisy, &b.noisy),
        ("direct", &a.direct, &b.direct),
        ("indirect", &a.indirect, &b.indirect),
        ("filtered", &a.filtered_indirect, &b.filtered_indirect),
    ] {
        assert!(bits(x) == bits(y), "layer {name} differs from the frame of {} spp", frame.spp_done);
    }
}

#[test]
fn a_frame_cancelled_in_its_guide_rays_is_no_frame() {
    let (mut r, _) = renderer(4, Some(0));
    assert_eq!(r.render_frame().map(|_| ()).unwrap_err(), PipelineError::Cancelled);
    let (mut r, cancel) = renderer(4, None);
    cancel.store(true, Ordering::SeqCst);
    assert_eq!(r.render_frame().map(|_| ()).unwrap_err(), PipelineError::Cancelled);
    let e = r.render_frame_adaptive(&filtrace_adaptive::AdaptiveParams::paper()).map(|_| ()).unwrap_err();
    assert_eq!(e, adaptive::AdaptiveFrameError::Pipeline(PipelineError::Cancelled));
    assert!(e.to_string().contains("cancelled"), "{e}");
}

#[test]
fn an_uncancelled_frame_has_every_sample() {
    let (mut r, _) = renderer(7, None);
    assert_eq!(r.render_frame().unwrap().spp_done, 7);
    let (mut r, _) = renderer(1, None);
    assert_eq!(r.render_frame().unwrap().spp_done, 1);
}
