//! Interpolation against values computed by hand from the definitions.

use super::*;
use crate::types::Camera;
use filtrace_core::{Affine3A, Quat, Vec3};
use std::f32::consts::FRAC_PI_2;

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-5 * (1.0 + b.abs())
}

#[test]
fn step_holds_the_earlier_key_and_the_ends() {
    let k = Track::new(vec![1.0, 2.0, 4.0], vec![10.0f32, 20.0, 40.0], Interpolation::Step).unwrap();
    assert_eq!(k.sample(0.0), 10.0); // before the first key
    assert_eq!(k.sample(1.0), 10.0);
    assert_eq!(k.sample(1.999), 10.0);
    assert_eq!(k.sample(2.0), 20.0);
    assert_eq!(k.sample(3.9), 20.0);
    assert_eq!(k.sample(9.0), 40.0); // after the last key
    assert_eq!(k.sample(f32::NAN), 10.0);
}

#[test]
fn linear_vectors() {
    let a = Vec3::new(0.0, 2.0, -4.0);
    let b = Vec3::new(10.0, 2.0, 4.0);
    let k = Track::new(vec![0.0, 4.0], vec![a, b], Interpolation::Linear).unwrap();
    assert_eq!(k.sample(1.0), Vec3::new(2.5, 2.0, -2.0));
    assert_eq!(k.sample(2.0), Vec3::new(5.0, 2.0, 0.0));
}

#[test]
fn linear_rotations_slerp_the_short_way() {
    let q0 = Quat::IDENTITY;
    let q1 = Quat::from_rotation_y(FRAC_PI_2);
    let k = Track::new(vec![0.0, 1.0], vec![q0, q1], Interpolation::Linear).unwrap();
    let mid = k.sample(0.5);
    assert!(mid.angle_between(Quat::from_rotation_y(FRAC_PI_2 / 2.0)) < 1e-5, "{mid:?}");
    // -q1 is the same rotation: slerp must still take the 45-degree way, not the 135 one.
    let k = Track::new(vec![0.0, 1.0], vec![q0, -q1], Interpolation::Linear).unwrap();
    let mid = k.sample(0.5);
    assert!(mid.angle_between(Quat::from_rotation_y(FRAC_PI_2 / 2.0)) < 1e-5, "{mid:?}");
}

/// glTF spec Appendix C with keys (t=0, v=0, out=1) and (t=2, v=1, in=0), at t = 1:
/// s = 0.5, m0 = 2 * 1, m1 = 2 * 0, so p = 0.5*0 + 0.125*2 + 0.5*1 - 0.125*0 = 0.75.
#[test]
fn cubic_spline_follows_the_gltf_formula() {
    let k = Track::cubic_spline(vec![0.0, 2.0], vec![5.0f32, 0.0], vec![0.0, 1.0], vec![1.0, 7.0]).unwrap();
    assert!(close(k.sample(1.0), 0.75), "{}", k.sample(1.0));
    // s = 0.25: h00 = 0.84375, h10 = 0.140625, h01 = 0.15625, h11 = -0.046875.
    assert!(close(k.sample(0.5), 0.140625 * 2.0 + 0.15625), "{}", k.sample(0.5));
    assert_eq!(k.sample(0.0), 0.0);
    assert_eq!(k.sample(2.0), 1.0);
}

#[test]
fn cubic_spline_rotations_are_normalised() {
    let q0 = Quat::IDENTITY;
    let q1 = Quat::from_rotation_x(FRAC_PI_2);
    let zero = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    let k = Track::cubic_spline(vec![0.0, 1.0], vec![zero, zero], vec![q0, q1], vec![zero, zero]).unwrap();
    let mid = k.sample(0.5);
    assert!(close(mid.length(), 1.0));
    // Zero tangents and symmetric keys: halfway is the 45-degree rotation.
    assert!(mid.angle_between(Quat::from_rotation_x(FRAC_PI_2 / 2.0)) < 1e-4, "{mid:?}");
}

/// Keys (0, 0), (1, 1), (2, 4): slopes 1 (one-sided), (4 - 0) / 2 = 2, (4 - 1) / 1 = 3.
/// In segment 0 at s = 0.5 with dt = 1: 0.125 * 1 + 0.5 * 1 - 0.125 * 2 = 0.375;
/// in segment 1 at s = 0.5: 0.5 * 1 + 0.125 * 2 + 0.5 * 4 - 0.125 * 3 = 2.375.
#[test]
fn catmull_rom_tangents_from_neighbours() {
    let k = Track::new(vec![0.0, 1.0, 2.0], vec![0.0f32, 1.0, 4.0], Interpolation::CatmullRom).unwrap();
    assert!(close(k.sample(0.5), 0.375), "{}", k.sample(0.5));
    assert!(close(k.sample(1.5), 2.375), "{}", k.sample(1.5));
    for (t, v) in [(0.0, 0.0), (1.0, 1.0), (2.0, 4.0)] {
        assert!(close(k.sample(t), v), "passes through key at {t}");
    }
}

/// Non-uniform key spacing: keys (0, 0), (1, 1), (3, 2) lie on the line v = t for the first
/// two and v = 1 + (t - 1) / 2 after; the slope at key 1 is (2 - 0) / 3 and the curve is
/// continuous in value and in slope across the key.
#[test]
fn catmull_rom_non_uniform_spacing_is_c1() {
    let k = Track::new(vec![0.0, 1.0, 3.0], vec![0.0f32, 1.0, 2.0], Interpolation::CatmullRom).unwrap();
    let h = 1e-3;
    let left = (k.sample(1.0) - k.sample(1.0 - h)) / h;
    let right = (k.sample(1.0 + h) - k.sample(1.0)) / h;
    assert!((left - 2.0 / 3.0).abs() < 1e-2 && (right - 2.0 / 3.0).abs() < 1e-2, "{left} {right}");
}

#[test]
fn bad_keys_are_refused_with_the_key_named() {
    let lin = Interpolation::Linear;
    assert_eq!(Track::<f32>::new(vec![], vec![], lin).unwrap_err(), TrackError::Empty);
    let e = Track::new(vec![0.0, 2.0, 1.0], vec![0.0f32; 3], lin).unwrap_err();
    assert_eq!(e, TrackError::TimesOutOfOrder { index: 2, previous: 2.0, time: 1.0 });
    assert!(e.to_string().contains("key 2"), "{e}");
    let e = Track::new(vec![0.0, 0.0], vec![0.0f32; 2], lin).unwrap_err();
    assert!(matches!(e, TrackError::TimesOutOfOrder { index: 1, .. }), "equal times: {e}");
    let e = Track::new(vec![0.0, f32::NAN], vec![0.0f32; 2], lin).unwrap_err();
    assert_eq!(e, TrackError::NonFiniteTime { index: 1 });
    let e =
        Track::new(vec![0.0, 1.0], vec![Vec3::ZERO, Vec3::new(0.0, f32::INFINITY, 0.0)], lin).unwrap_err();
    assert_eq!(e, TrackError::NonFiniteValue { what: "values", index: 1 });
    let e = Track::new(vec![0.0, 1.0], vec![0.0f32], lin).unwrap_err();
    assert_eq!(e, TrackError::LengthMismatch { what: "values", expected: 2, found: 1 });
    let e = Track::cubic_spline(vec![0.0], vec![], vec![1.0f32], vec![0.0]).unwrap_err();
    assert_eq!(e, TrackError::LengthMismatch { what: "in-tangents", expected: 1, found: 0 });
}

#[test]
fn rotations_are_normalised_and_zero_ones_refused() {
    let q = normalized_rotations(&[Quat::from_xyzw(0.0, 0.0, 0.0, 2.0)]).unwrap();
    assert_eq!(q[0], Quat::IDENTITY);
    let e = normalized_rotations(&[Quat::IDENTITY, Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)]).unwrap_err();
    assert_eq!(e, TrackError::ZeroQuaternion { index: 1 });
    let e = normalized_rotations(&[Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0)]).unwrap_err();
    assert!(matches!(e, TrackError::NonFiniteValue { index: 0, .. }));
}

#[test]
fn transform_track_keeps_the_rest_pose_of_unkeyed_components() {
    let rest = Affine3A::from_scale_rotation_translation(
        Vec3::splat(2.0),
        Quat::from_rotation_z(0.3),
        Vec3::new(1.0, 2.0, 3.0),
    );
    let mut track = TransformTrack::at_rest(&rest);
    assert!(track.time_range().is_none());
    assert!(track.sample(5.0).abs_diff_eq(rest, 1e-6));
    let keys = vec![Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0)];
    track.translation = Some(Track::new(vec![0.0, 2.0], keys, Interpolation::Linear).unwrap());
    let m = track.sample(1.0);
    let expected = Affine3A::from_scale_rotation_translation(
        Vec3::splat(2.0),
        Quat::from_rotation_z(0.3),
        Vec3::new(2.0, 0.0, 0.0),
    );
    assert!(m.abs_diff_eq(expected, 1e-5), "{m:?}");
    assert_eq!(track.time_range(), Some((0.0, 2.0)));
}

#[test]
fn camera_track_moves_only_what_is_keyed() {
    let mut track = CameraTrack::at_rest(Camera::cornell());
    let keys = vec![30.0, 60.0];
    track.vfov_deg = Some(Track::new(vec![1.0, 3.0], keys, Interpolation::Linear).unwrap());
    let cam = track.sample(2.0);
    assert_eq!(cam.vfov_deg, 45.0);
    assert_eq!(cam.eye, Camera::cornell().eye);
    assert_eq!(track.time_range(), Some((1.0, 3.0)));
}

#[test]
fn clock_maps_frames_and_refuses_outside_ones() {
    let clock = Clock::new(24.0, 0, 48).unwrap();
    assert_eq!(clock.time_of(12).unwrap(), 0.5);
    assert_eq!(clock.frame_count(), 49);
    let e = clock.time_of(49).unwrap_err();
    assert_eq!(e, ClockError::FrameOutside { frame: 49, first: 0, last: 48 });
    assert!(e.to_string().contains("frame 49"));
    assert!(Clock::new(0.0, 0, 1).is_err());
    assert!(Clock::new(f32::NAN, 0, 1).is_err());
    assert_eq!(Clock::new(24.0, 5, 4).unwrap_err(), ClockError::EmptyRange { first: 5, last: 4 });
}
