//! The per-frame renderer: frames reached by updates render exactly as renderers built
//! from scratch on the posed scene, and the motion AOV agrees with the previous frame's
//! G-buffer.

use filtrace_core::{Affine3A, Image, Vec2, Vec3};
use filtrace_render::frame_bench::still_at;
use filtrace_render::{Film, RenderSettings, Renderer, TraceMode};
use filtrace_scene::animation::{
    AnimNode, CameraTrack, Clock, Interpolation, SceneAnimation, Track, TransformTrack,
};
use filtrace_scene::{Camera, Scene};
use std::sync::atomic::AtomicBool;

const FLOOR: u32 = 0;
const LIGHT: u32 = 1;
const SHORT_BLOCK: u32 = 6;

fn settings(spp: u32) -> RenderSettings {
    RenderSettings { width: 40, height: 32, spp, max_depth: 5, seed: 11 }
}

fn render(r: &Renderer) -> Film {
    r.render(&AtomicBool::new(false))
}

/// Every field of every pixel as bits (-0 and +0 told apart).
fn bits(f: &Film) -> Vec<u64> {
    let mut v = Vec::new();
    for p in f.pixels() {
        v.extend([p.samples as u64, p.dropped as u64]);
        for c in 0..3 {
            v.extend([p.sum[c], p.sum_sq[c], p.sum_direct[c], p.sum_indirect[c]].map(f64::to_bits));
        }
        let s = &p.surface;
        let g = [s.albedo.to_array(), s.normal.to_array(), s.position.to_array(), [s.depth; 3]].concat();
        v.extend(g.iter().map(|x| x.to_bits() as u64));
    }
    v
}

/// Frames 0..=10 at 10 per second; each `(instance, translations)` is keyed at evenly
/// spaced times over the second, linearly; `camera` keys the eye the same way.
fn animate(scene: &mut Scene, moves: &[(u32, Vec<Vec3>)], eyes: Option<Vec<Vec3>>) {
    let mut anim = SceneAnimation::new(Clock::new(10.0, 0, 10).unwrap());
    let times = |n: usize| (0..n).map(|k| k as f32 / (n - 1).max(1) as f32).collect::<Vec<f32>>();
    for (i, keys) in moves {
        let mut track = TransformTrack::at_rest(&Affine3A::IDENTITY);
        track.translation = Some(Track::new(times(keys.len()), keys.clone(), Interpolation::Linear).unwrap());
        anim.nodes.push(AnimNode { name: format!("node {i}"), parent: None, track });
        anim.instances.push((*i, anim.nodes.len() as u32 - 1, Affine3A::IDENTITY));
    }
    if let Some(eyes) = eyes {
        let mut cam = CameraTrack::at_rest(scene.camera.clone().unwrap());
        cam.eye = Some(Track::new(times(eyes.len()), eyes, Interpolation::Linear).unwrap());
        anim.camera = Some(cam);
    }
    scene.animation = Some(anim);
}

fn cornell() -> Scene {
    filtrace_scene::builtin("cornell").unwrap()
}

/// Renders `r` and the scene built still at `frame`, in both trace modes; bit for bit.
/// The still scene keeps the animation data, so that its build keeps the same (animated)
/// instances apart: static ones are merged into world space, which changes the last bits.
fn assert_same_as_built(r: Renderer, scene: &Scene, frame: i64, spp: u32) -> Renderer {
    let mut still = still_at(scene, frame).unwrap();
    still.animation = scene.animation.clone();
    let mut r = r;
    for mode in [TraceMode::Lockstep, TraceMode::Scalar] {
        r = r.with_trace_mode(mode);
        let built = Renderer::new(still.clone(), settings(spp)).unwrap().with_trace_mode(mode);
        assert!(bits(&render(&r)) == bits(&render(&built)), "frame {frame}, {mode:?}: images differ");
    }
    r
}

/// A scene without animation is the same at every frame; an animation whose tracks hold
/// the rest pose (an instance kept out of the merged bottom level, a keyed camera) renders
/// as the still scene, bit for bit.
#[test]
fn a_static_scene_as_frame_n_is_the_still_render() {
    let scene = cornell();
    let mut r = Renderer::new(scene.clone(), settings(4)).unwrap();
    let u = r.prepare_frame(7).unwrap();
    assert_eq!((u.moved_instances, u.lights_updated, u.camera_moved), (0, false, false));
    assert_eq!(r.frame().index, 7);
    assert_same_as_built(r, &scene, 7, 4);

    let mut held = cornell();
    let eye = held.camera.as_ref().unwrap().eye;
    animate(&mut held, &[(SHORT_BLOCK, vec![Vec3::ZERO; 2])], Some(vec![eye; 3]));
    let mut r = Renderer::new(held.clone(), settings(4)).unwrap();
    assert!(!r.accel().is_merged(SHORT_BLOCK) && r.accel().is_merged(FLOOR));
    r.prepare_frame(4).unwrap();
    assert_same_as_built(r, &cornell(), 0, 4);
}

/// A block and the (emitting) light move: every frame reached by updates renders as the
/// scene built from scratch at that frame, bit for bit (hits do not depend on the BVH's
/// shape, and every record is recomputed as a fresh build does). After 0.25 s the light
/// holds still and the light set is no longer rebuilt.
#[test]
fn moved_instances_render_as_the_scene_built_from_scratch() {
    let mut scene = cornell();
    let block = vec![Vec3::ZERO, Vec3::new(-60.0, 0.0, 40.0), Vec3::new(30.0, 20.0, -50.0)];
    let light = vec![Vec3::ZERO, Vec3::new(70.0, -4.0, -60.0), Vec3::new(70.0, -4.0, -60.0)];
    let mut light_keys = light.clone();
    light_keys.push(light[2]);
    animate(&mut scene, &[(SHORT_BLOCK, block), (LIGHT, light_keys)], None);
    let mut r = Renderer::new(scene.clone(), settings(4)).unwrap();
    for (frame, light_moves) in [(2, true), (3, true), (4, true), (8, false), (10, false)] {
        let u = r.prepare_frame(frame).unwrap();
        assert_eq!(u.moved_instances, 1 + light_moves as usize, "frame {frame}: {u:?}");
        assert_eq!(u.lights_updated, light_moves, "frame {frame}: {u:?}");
        assert_eq!(u.triangle_records, 10 + 2 * light_moves as usize, "frame {frame}: {u:?}");
        r = assert_same_as_built(r, &scene, frame, 4);
    }
}

/// A camera-only update renders as a renderer built with that camera, bit for bit, and
/// touches no geometry.
#[test]
fn a_camera_update_renders_as_a_renderer_built_with_that_camera() {
    let scene = cornell();
    let moved = Camera {
        eye: Vec3::new(300.0, 250.0, -700.0),
        target: Vec3::new(250.0, 280.0, 0.0),
        ..Camera::cornell()
    };
    let mut r = Renderer::new(scene.clone(), settings(4)).unwrap();
    r.set_camera(&moved);
    let mut built_scene = scene.clone();
    built_scene.camera = Some(moved.clone());
    for mode in [TraceMode::Lockstep, TraceMode::Scalar] {
        let built = Renderer::new(built_scene.clone(), settings(4)).unwrap().with_trace_mode(mode);
        r = r.with_trace_mode(mode);
        assert!(bits(&render(&r)) == bits(&render(&built)), "{mode:?}");
    }
    let mut eyes = cornell();
    animate(&mut eyes, &[], Some(vec![moved.eye, Camera::cornell().eye]));
    let mut r = Renderer::new(eyes, settings(1)).unwrap();
    let u = r.prepare_frame(5).unwrap();
    assert!(u.camera_moved && u.moved_instances == 0 && !u.lights_updated, "{u:?}");
    assert_eq!(u.top_level, filtrace_accel::TopLevelUpdate::Unchanged);
}

/// Bilinear lookup of a 1- or 3-channel image at raster position `p` (pixel centres at
/// `+0.5`), with the four texels; `None` outside.
fn bilinear(img: &Image, p: Vec2) -> Option<(Vec3, [Vec3; 4])> {
    let q = p - Vec2::splat(0.5);
    let (x0, y0) = (q.x.floor(), q.y.floor());
    if x0 < 0.0 || y0 < 0.0 || x0 + 1.0 >= img.width() as f32 || y0 + 1.0 >= img.height() as f32 {
        return None;
    }
    let (fx, fy) = (q.x - x0, q.y - y0);
    let at = |dx: usize, dy: usize| {
        let px = img.pixel(x0 as usize + dx, y0 as usize + dy);
        if px.len() == 1 {
            Vec3::splat(px[0])
        } else {
            Vec3::new(px[0], px[1], px[2])
        }
    };
    let t = [at(0, 0), at(1, 0), at(0, 1), at(1, 1)];
    let top = t[0] * (1.0 - fx) + t[1] * fx;
    let bottom = t[2] * (1.0 - fx) + t[3] * fx;
    Some((top * (1.0 - fy) + bottom * fy, t))
}

/// Checks the motion AOV of `r`'s current frame against the previous frame's G-buffer
/// `prev` (position, depth and normal at pixel centres): where the four texels around the
/// previous position lie on one plane with the previous normal, their bilinear position
/// is the surface point's previous place `expected(x, y, current position)` within 5 % of
/// a pixel footprint, unless the depth says it was hidden then (disocclusion, skipped).
/// Returns (pixels checked, largest |motion|).
fn check_motion(
    r: &Renderer,
    prev: &filtrace_render::Aovs,
    expected: &dyn Fn(u32, u32, Vec3) -> Vec3,
) -> (usize, f32) {
    let now = render(r).aovs();
    let m = r.motion_aov();
    let (mut checked, mut largest) = (0, 0.0f32);
    for y in 0..now.height as u32 {
        for x in 0..now.width as u32 {
            let p = now.position.rgb(x as usize, y as usize);
            let mv = Vec2::from_slice(m.motion.pixel(x as usize, y as usize));
            let prev_depth = m.prev_depth.pixel(x as usize, y as usize)[0];
            let prev_normal = Vec3::from_slice(m.prev_normal.pixel(x as usize, y as usize));
            if now.depth.pixel(x as usize, y as usize)[0] == 0.0 || prev_depth == 0.0 {
                continue;
            }
            let at = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) + mv;
            let (Some((pos, texels)), Some((depth, _)), Some((_, normals))) =
                (bilinear(&prev.position, at), bilinear(&prev.depth, at), bilinear(&prev.normal, at))
            else {
                continue;
            };
            let planar = normals.iter().all(|n| (*n - prev_normal).length() < 1e-4)
                && texels.iter().all(|t| (*t - texels[0]).dot(prev_normal).abs() < 1e-2);
            if !planar {
                continue;
            }
            let footprint = texels.iter().map(|t| (*t - texels[0]).length()).fold(0.0, f32::max);
            let tolerance = 0.05 * footprint + 1e-3;
            if (depth.x - prev_depth).abs() > tolerance {
                continue; // disoccluded: something else was in front in the previous frame
            }
            let want = expected(x, y, p);
            assert!((pos - want).length() <= tolerance, "({x}, {y}) motion {mv}: {pos} vs {want}");
            checked += 1;
            largest = largest.max(mv.length());
        }
    }
    (checked, largest)
}

/// Camera move: each surface point is where it was; the previous frame's positions at
/// the pixel plus motion are the current positions.
#[test]
fn motion_vectors_reproject_the_previous_positions_for_a_camera_move() {
    let mut r = Renderer::new(cornell(), settings(1)).unwrap();
    let prev = render(&r).aovs();
    let moved = Camera {
        eye: Vec3::new(300.0, 260.0, -760.0),
        target: Vec3::new(270.0, 280.0, 0.0),
        ..Camera::cornell()
    };
    r.set_camera(&moved);
    let (checked, largest) = check_motion(&r, &prev, &|_, _, p| p);
    assert!(checked > 40 * 32 / 2, "only {checked} pixels checked");
    assert!(largest > 1.0, "the camera move should move pixels: {largest}");
}

/// Object move: points of the moved block were at `T0 T1^-1 p`, the others at `p`.
#[test]
fn motion_vectors_reproject_the_previous_positions_for_an_object_move() {
    let mut scene = cornell();
    animate(&mut scene, &[(SHORT_BLOCK, vec![Vec3::ZERO, Vec3::new(-150.0, 0.0, 100.0)])], None);
    let mut r = Renderer::new(scene, settings(1)).unwrap();
    r.prepare_frame(2).unwrap();
    let t0 = r.scene().instances[SHORT_BLOCK as usize].transform;
    let prev = render(&r).aovs();
    r.prepare_frame(4).unwrap();
    let t1 = r.scene().instances[SHORT_BLOCK as usize].transform;
    let on_block = |x: u32, y: u32| {
        let ray = r.camera().generate_ray(x, y, Vec2::splat(0.5));
        r.accel().intersect(&ray).is_some_and(|h| h.instance == SHORT_BLOCK)
    };
    let back = t0 * t1.inverse();
    let (checked, largest) =
        check_motion(&r, &prev, &|x, y, p| if on_block(x, y) { back.transform_point3(p) } else { p });
    assert!(checked > 40 * 32 / 2, "only {checked} pixels checked");
    assert!(largest > 1.0, "the block should move pixels: {largest}");
}

/// Nothing moved: motion exactly zero and the previous depth and normal are the G-buffer's.
/// Background pixels (a quad in an open scene): prev_depth and prev_normal zero, motion
/// that of the direction at infinity under the camera's rotation (zero for a translation).
#[test]
fn still_frames_have_zero_motion_and_background_is_defined() {
    let r = Renderer::new(cornell(), settings(1)).unwrap();
    let a = render(&r).aovs();
    let m = r.motion_aov();
    assert!(m.motion.data().iter().all(|&v| v == 0.0));
    for (d, want) in m.prev_depth.data().iter().zip(a.depth.data()) {
        assert!((d - want).abs() <= 1e-5 * want, "prev_depth {d} vs depth {want}");
    }
    assert_eq!(m.prev_normal.data(), a.normal.data());

    let mut open = cornell();
    open.instances.retain(|i| i.mesh == SHORT_BLOCK);
    let mut r = Renderer::new(open, settings(1)).unwrap();
    let cam = Camera::cornell();
    r.set_camera(&Camera {
        eye: cam.eye + Vec3::new(40.0, 0.0, 0.0),
        target: cam.target + Vec3::new(40.0, 0.0, 0.0),
        ..cam
    });
    let m = r.motion_aov();
    let a = render(&r).aovs();
    let background: Vec<usize> = (0..40 * 32).filter(|&i| a.depth.data()[i] == 0.0).collect();
    assert!(background.len() > 100);
    for &i in &background {
        assert_eq!(
            (m.prev_depth.data()[i], &m.prev_normal.data()[3 * i..3 * i + 3]),
            (0.0, &[0.0f32; 3][..])
        );
        assert!(m.motion.data()[2 * i..2 * i + 2].iter().all(|v| v.abs() < 1e-3), "translation: pixel {i}");
    }
    let turned = Camera { target: cam.eye + Vec3::new(0.1, 0.0, 1.0), ..cam.clone() };
    r.set_camera(&cam);
    r.set_camera(&turned);
    let m = r.motion_aov();
    let a = render(&r).aovs();
    let prev = filtrace_render::PinholeCamera::new(&cam, 40, 32);
    let i = (0..40 * 32).find(|&i| a.depth.data()[i] == 0.0).expect("a background pixel");
    let (x, y) = ((i % 40) as u32, (i / 40) as u32);
    let dir = r.camera().generate_ray(x, y, Vec2::splat(0.5)).dir;
    let want = prev.raster_of_direction(dir).unwrap() - Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    let got = Vec2::from_slice(m.motion.pixel(x as usize, y as usize));
    assert!((got - want).length() < 1e-3 && want.length() > 1.0, "{got} vs {want}");
}
