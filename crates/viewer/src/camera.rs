//! Camera moves of the viewer, as functions of a [`Camera`] (eye, target, up, vertical field
//! of view) and an input amount: orbit about the target, pan, zoom (dolly towards the
//! target), fly (move eye and target together) and field of view.
//!
//! The camera is kept as the scene file describes it and each move transforms it, so a
//! camera that was not moved is the file's camera bit for bit (the still image then equals
//! `filtrace render`'s). Moves are pure functions: the tests (and the window tests, which
//! compute where a mouse drag must lead) call the same code as the window.

use filtrace_core::Vec3;
use filtrace_scene::Camera;

/// Radians of orbit per pixel of mouse drag.
pub const ORBIT_RAD_PER_PIXEL: f32 = 0.005;
/// Fraction of the eye-target distance panned per pixel of drag, per unit of image height.
pub const PAN_PER_PIXEL: f32 = 1.0;
/// Zoom factor per scroll step (a wheel notch is one step).
pub const ZOOM_PER_STEP: f32 = 0.9;
/// Fly speed: eye-target distances per second.
pub const FLY_SPEED: f32 = 0.5;
/// Field of view limits in degrees.
pub const VFOV_RANGE: (f32, f32) = (5.0, 120.0);
/// Closest the eye may come to the target when zooming (a fraction of the start distance
/// would be scene-dependent; this keeps `eye != target`).
const MIN_DISTANCE: f32 = 1e-4;

/// Unit axes of the camera: forward (eye to target), right and the true up.
fn axes(cam: &Camera) -> (Vec3, Vec3, Vec3) {
    let forward = (cam.target - cam.eye).normalize_or_zero();
    let right = forward.cross(cam.up).normalize_or_zero();
    (forward, right, right.cross(forward))
}

/// Orbits the eye about the target: `dx` pixels of drag turn it about the up axis, `dy`
/// about the right axis (dragging right turns the scene right, as in most viewers). The
/// pitch stops short of the poles so that `up` never becomes parallel to the view.
pub fn orbit(cam: &Camera, dx: f32, dy: f32) -> Camera {
    let up = cam.up.normalize_or_zero();
    let offset = cam.eye - cam.target;
    let yaw = glam_quat(up, -dx * ORBIT_RAD_PER_PIXEL);
    let mut offset = yaw * offset;
    let (_, right, _) = axes(&Camera { eye: cam.target + offset, ..cam.clone() });
    let pitched = glam_quat(right, -dy * ORBIT_RAD_PER_PIXEL) * offset;
    // Keep at least ~1 degree away from the up axis.
    if pitched.normalize_or_zero().dot(up).abs() < 0.9998 {
        offset = pitched;
    }
    Camera { eye: cam.target + offset, ..cam.clone() }
}

fn glam_quat(axis: Vec3, angle: f32) -> filtrace_core::Quat {
    filtrace_core::Quat::from_axis_angle(axis, angle)
}

/// Moves eye and target in the image plane; `dx, dy` in pixels of an image `height` pixels
/// high, so that the point under the cursor at the target's depth follows the cursor.
pub fn pan(cam: &Camera, dx: f32, dy: f32, height: f32) -> Camera {
    let (_, right, up) = axes(cam);
    let distance = (cam.target - cam.eye).length();
    let per_pixel =
        PAN_PER_PIXEL * 2.0 * distance * (0.5 * cam.vfov_deg.to_radians()).tan() / height.max(1.0);
    let shift = (-dx * right + dy * up) * per_pixel;
    Camera { eye: cam.eye + shift, target: cam.target + shift, ..cam.clone() }
}

/// Moves the eye towards the target (`steps > 0`) or away, by [`ZOOM_PER_STEP`] per step.
pub fn zoom(cam: &Camera, steps: f32) -> Camera {
    let offset = cam.eye - cam.target;
    let distance = offset.length();
    let new = (distance * ZOOM_PER_STEP.powf(steps)).max(MIN_DISTANCE);
    Camera { eye: cam.target + offset * (new / distance.max(f32::MIN_POSITIVE)), ..cam.clone() }
}

/// Flies eye and target together: `forward`, `right`, `up` in eye-target distances
/// (W/S, D/A, E/Q keys times [`FLY_SPEED`] times the frame's seconds).
pub fn fly(cam: &Camera, forward: f32, right: f32, up: f32) -> Camera {
    let (f, r, u) = axes(cam);
    let distance = (cam.target - cam.eye).length();
    let shift = (forward * f + right * r + up * u) * distance;
    Camera { eye: cam.eye + shift, target: cam.target + shift, ..cam.clone() }
}

/// The field of view changed by `delta_deg`, within [`VFOV_RANGE`].
pub fn with_fov(cam: &Camera, delta_deg: f32) -> Camera {
    let vfov_deg = (cam.vfov_deg + delta_deg).clamp(VFOV_RANGE.0, VFOV_RANGE.1);
    Camera { vfov_deg, ..cam.clone() }
}

/// `eye,target,up,fov` as 10 comma-separated numbers (what `--camera` takes and the
/// viewer prints), in full precision.
pub fn format_camera(cam: &Camera) -> String {
    let v = |v: Vec3| format!("{},{},{}", v.x, v.y, v.z);
    format!("{},{},{},{}", v(cam.eye), v(cam.target), v(cam.up), cam.vfov_deg)
}

/// Parses [`format_camera`]'s form: `ex,ey,ez,tx,ty,tz,ux,uy,uz,fov` (finite numbers, eye
/// distinct from target, up not parallel to the view, fov in (0, 180)).
pub fn parse_camera(s: &str) -> Result<Camera, String> {
    let values: Vec<f32> = s
        .split(',')
        .map(|v| v.trim().parse::<f32>().map_err(|_| format!("--camera: '{}' is not a number", v.trim())))
        .collect::<Result<_, _>>()?;
    if values.len() != 10 {
        return Err(format!(
            "--camera: expected 10 numbers eye(3),target(3),up(3),fov, got {} in '{s}'",
            values.len()
        ));
    }
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(format!("--camera: {v} is not a finite number"));
    }
    let v3 = |i: usize| Vec3::new(values[i], values[i + 1], values[i + 2]);
    let cam = Camera { eye: v3(0), target: v3(3), up: v3(6), vfov_deg: values[9] };
    let forward = (cam.target - cam.eye).normalize_or_zero();
    if forward == Vec3::ZERO {
        return Err("--camera: eye and target are the same point".into());
    }
    if forward.cross(cam.up).length() < 1e-6 {
        return Err("--camera: up is parallel to the viewing direction (or zero)".into());
    }
    if !(cam.vfov_deg > 0.0 && cam.vfov_deg < 180.0) {
        return Err(format!("--camera: field of view {} is not in (0, 180) degrees", cam.vfov_deg));
    }
    Ok(cam)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-3 * (1.0 + a.length())
    }

    #[test]
    fn orbit_keeps_the_distance_and_the_target_and_undoes() {
        let c = Camera::cornell();
        let d = (c.eye - c.target).length();
        let o = orbit(&c, 40.0, -25.0);
        assert_eq!(o.target, c.target);
        assert!(((o.eye - o.target).length() - d).abs() < 1e-4 * d);
        // Offsets from the target (length 1 here), so that tolerances are about the move.
        assert!(!close(o.eye - o.target, c.eye - c.target));
        // A yaw alone is undone by the opposite yaw.
        let back = orbit(&orbit(&c, 30.0, 0.0), -30.0, 0.0);
        assert!(close(back.eye - back.target, c.eye - c.target), "{:?} vs {:?}", back.eye, c.eye);
        // Dragging right moves the eye to the camera's left (the scene turns right).
        let (_, right, _) = axes(&c);
        assert!((orbit(&c, 10.0, 0.0).eye - c.eye).dot(right) < 0.0);
    }

    #[test]
    fn orbit_stops_before_the_pole() {
        let mut c = Camera::cornell();
        for _ in 0..200 {
            c = orbit(&c, 0.0, 50.0);
        }
        let f = (c.target - c.eye).normalize();
        assert!(f.cross(c.up).length() > 1e-3, "{f:?}");
    }

    #[test]
    fn pan_fly_zoom_fov() {
        let c = Camera::cornell();
        let p = pan(&c, 10.0, 0.0, 100.0);
        assert!(close(p.eye - c.eye, p.target - c.target));
        let (_, right, _) = axes(&c);
        assert!((p.eye - c.eye).dot(right) < 0.0, "dragging right moves the camera left");
        let f = fly(&c, 0.5, 0.0, 0.0);
        assert!(close(f.eye, c.eye + Vec3::Z * 0.5), "{:?}", f.eye);
        let z = zoom(&c, 1.0);
        assert!(((z.eye - z.target).length() - 0.9).abs() < 1e-4);
        assert_eq!(with_fov(&c, 500.0).vfov_deg, VFOV_RANGE.1);
        assert_eq!(zoom(&c, 1e6).eye, c.target + (c.eye - c.target) * MIN_DISTANCE);
    }

    #[test]
    fn camera_text_round_trips_and_bad_text_is_an_error() {
        let c = orbit(&Camera::cornell(), 3.0, 7.0);
        assert_eq!(parse_camera(&format_camera(&c)).unwrap(), c);
        for (bad, says) in [
            ("1,2,3", "expected 10"),
            ("0,0,0,0,0,0,0,1,0,45", "same point"),
            ("0,0,0,0,1,0,0,1,0,45", "parallel"),
            ("0,0,0,0,0,1,0,1,0,180", "field of view"),
            ("0,0,0,0,0,1,0,1,0,nan", "finite"),
            ("0,0,0,0,0,1,0,1,0,x", "not a number"),
        ] {
            let e = parse_camera(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
