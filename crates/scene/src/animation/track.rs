//! Keyframe tracks: a value over time given by keys and an interpolation mode.
//!
//! The modes are those of glTF 2.0 (`STEP`, `LINEAR`, `CUBICSPLINE`, glTF spec §3.11 and
//! Appendix C) plus Catmull-Rom, which TOML scenes use for smooth camera paths without
//! hand-written tangents. Rotations interpolate on the unit sphere: `LINEAR` is slerp, and
//! the cubic modes evaluate the Hermite curve on the quaternion's components and normalise
//! the result, which is what the glTF spec prescribes for `CUBICSPLINE` rotations.
//!
//! Before the first key a track holds its first value, after the last key its last value
//! (glTF viewers do the same).

use filtrace_core::{Quat, Vec3};
use std::fmt;

/// How values between two keys are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// The value of the key at or before the time (glTF `STEP`).
    Step,
    /// Straight line between keys; slerp for rotations (glTF `LINEAR`).
    Linear,
    /// Cubic Hermite with tangents from the neighbouring keys (non-uniform Catmull-Rom:
    /// slope `(p[k+1] - p[k-1]) / (t[k+1] - t[k-1])`, one-sided at the ends).
    CatmullRom,
    /// Cubic Hermite with explicit in/out tangents per key (glTF `CUBICSPLINE`).
    CubicSpline,
}

/// A value that can be keyed: positions, scales, angles and rotations.
pub trait Keyable: Copy + fmt::Debug {
    fn is_finite_value(&self) -> bool;
    fn lerp_to(self, other: Self, t: f32) -> Self;
    /// `a + (b - a) * s`-style arithmetic on the components (tangents are differences).
    fn sub(self, other: Self) -> Self;
    fn scaled(self, s: f32) -> Self;
    fn add(self, other: Self) -> Self;
    /// Brings a neighbour into the same half-space as `self` (quaternions: q and -q are the
    /// same rotation, and a cubic through both signs would swing the long way round).
    fn align(self, neighbour: Self) -> Self {
        let _ = self;
        neighbour
    }
    /// Makes a component-wise result valid again (quaternions are normalised).
    fn finish(self) -> Self {
        self
    }
}

/// Scalars and vectors key by plain arithmetic.
macro_rules! keyable_by_arithmetic {
    ($($t:ty),*) => {$(
        impl Keyable for $t {
            fn is_finite_value(&self) -> bool {
                self.is_finite()
            }
            fn lerp_to(self, other: Self, t: f32) -> Self {
                self + (other - self) * t
            }
            fn sub(self, other: Self) -> Self {
                self - other
            }
            fn scaled(self, s: f32) -> Self {
                self * s
            }
            fn add(self, other: Self) -> Self {
                self + other
            }
        }
    )*};
}

keyable_by_arithmetic!(f32, Vec3);

impl Keyable for Quat {
    fn is_finite_value(&self) -> bool {
        self.is_finite()
    }
    fn lerp_to(self, other: Self, t: f32) -> Self {
        self.slerp(other, t)
    }
    fn sub(self, other: Self) -> Self {
        Quat::from_vec4(glam::Vec4::from(self) - glam::Vec4::from(other))
    }
    fn scaled(self, s: f32) -> Self {
        Quat::from_vec4(glam::Vec4::from(self) * s)
    }
    fn add(self, other: Self) -> Self {
        Quat::from_vec4(glam::Vec4::from(self) + glam::Vec4::from(other))
    }
    fn align(self, neighbour: Self) -> Self {
        if self.dot(neighbour) < 0.0 {
            -neighbour
        } else {
            neighbour
        }
    }
    fn finish(self) -> Self {
        self.normalize()
    }
}

/// What is wrong with a track's keys. Loaders add the file and line.
#[derive(Clone, Debug, PartialEq)]
pub enum TrackError {
    /// A track needs at least one key.
    Empty,
    /// `values` (or a tangent list) does not have one entry per key.
    LengthMismatch {
        what: &'static str,
        expected: usize,
        found: usize,
    },
    /// Key times must be finite and strictly increasing.
    TimesOutOfOrder {
        index: usize,
        previous: f32,
        time: f32,
    },
    NonFiniteTime {
        index: usize,
    },
    NonFiniteValue {
        what: &'static str,
        index: usize,
    },
    /// A rotation key of (near) zero length has no direction to normalise to.
    ZeroQuaternion {
        index: usize,
    },
}

impl fmt::Display for TrackError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TrackError::Empty => write!(f, "the track has no keys"),
            TrackError::LengthMismatch { what, expected, found } => {
                write!(f, "{found} {what} for {expected} keys (need one per key)")
            }
            TrackError::TimesOutOfOrder { index, previous, time } => write!(
                f,
                "key {index} at time {time} is not after the previous key's time {previous}: \
                 key times must increase strictly"
            ),
            TrackError::NonFiniteTime { index } => write!(f, "key {index} has a non-finite time"),
            TrackError::NonFiniteValue { what, index } => write!(f, "key {index} has a non-finite {what}"),
            TrackError::ZeroQuaternion { index } => {
                write!(f, "rotation key {index} is a quaternion of zero length")
            }
        }
    }
}

impl std::error::Error for TrackError {}

/// Explicit tangents of a `CUBICSPLINE` track (glTF stores them per key, already in
/// value units per second).
#[derive(Clone, Debug, PartialEq)]
struct Tangents<T> {
    incoming: Vec<T>,
    outgoing: Vec<T>,
}

/// A keyed value over time.
#[derive(Clone, Debug, PartialEq)]
pub struct Track<T> {
    times: Vec<f32>,
    values: Vec<T>,
    interpolation: Interpolation,
    tangents: Option<Tangents<T>>,
}

impl<T: Keyable> Track<T> {
    /// A track of `Step`, `Linear` or `CatmullRom` keys. For `CubicSpline` use
    /// [`Track::cubic_spline`].
    pub fn new(times: Vec<f32>, values: Vec<T>, interpolation: Interpolation) -> Result<Self, TrackError> {
        assert!(
            interpolation != Interpolation::CubicSpline,
            "cubic splines need tangents: Track::cubic_spline"
        );
        check_times(&times)?;
        check_values(&values, times.len(), "values")?;
        Ok(Track { times, values, interpolation, tangents: None })
    }

    /// A glTF `CUBICSPLINE` track: per key an in-tangent, a value and an out-tangent.
    pub fn cubic_spline(
        times: Vec<f32>,
        incoming: Vec<T>,
        values: Vec<T>,
        outgoing: Vec<T>,
    ) -> Result<Self, TrackError> {
        check_times(&times)?;
        check_values(&values, times.len(), "values")?;
        check_values(&incoming, times.len(), "in-tangents")?;
        check_values(&outgoing, times.len(), "out-tangents")?;
        let tangents = Some(Tangents { incoming, outgoing });
        Ok(Track { times, values, interpolation: Interpolation::CubicSpline, tangents })
    }

    /// A track that never changes.
    pub fn constant(value: T) -> Self {
        Track { times: vec![0.0], values: vec![value], interpolation: Interpolation::Step, tangents: None }
    }

    pub fn interpolation(&self) -> Interpolation {
        self.interpolation
    }

    /// First and last key time.
    pub fn time_range(&self) -> (f32, f32) {
        (self.times[0], self.times[self.times.len() - 1])
    }

    /// The value at time `t` (held before the first and after the last key).
    pub fn sample(&self, t: f32) -> T {
        let last = self.times.len() - 1;
        if last == 0 || t.is_nan() || t <= self.times[0] {
            return self.values[0].finish();
        }
        if t >= self.times[last] {
            return self.values[last].finish();
        }
        // Segment k: times[k] <= t < times[k + 1].
        let k = self.times.partition_point(|&key| key <= t) - 1;
        let dt = self.times[k + 1] - self.times[k];
        let s = (t - self.times[k]) / dt;
        match self.interpolation {
            Interpolation::Step => self.values[k],
            Interpolation::Linear => self.values[k].lerp_to(self.values[k].align(self.values[k + 1]), s),
            Interpolation::CatmullRom => self.catmull_rom(k, s, dt),
            Interpolation::CubicSpline => self.cubic(k, s, dt),
        }
    }

    fn catmull_rom(&self, k: usize, s: f32, dt: f32) -> T {
        let p0 = self.values[k];
        let p1 = p0.align(self.values[k + 1]);
        let m0 = self.catmull_rom_slope(k, p0).scaled(dt);
        let m1 = self.catmull_rom_slope(k + 1, p1).scaled(dt);
        hermite(p0, m0, p1, m1, s)
    }

    /// Slope at key `i`, with neighbours aligned to `at` (the key's value as used).
    fn catmull_rom_slope(&self, i: usize, at: T) -> T {
        let prev = i.saturating_sub(1);
        let next = (i + 1).min(self.times.len() - 1);
        let (a, b) = (at.align(self.values[prev]), at.align(self.values[next]));
        b.sub(a).scaled(1.0 / (self.times[next] - self.times[prev]))
    }

    /// glTF spec, Appendix C: `m0 = dt * out[k]`, `m1 = dt * in[k + 1]`.
    fn cubic(&self, k: usize, s: f32, dt: f32) -> T {
        let tangents = self.tangents.as_ref().expect("cubic-spline track without tangents");
        let m0 = tangents.outgoing[k].scaled(dt);
        let m1 = tangents.incoming[k + 1].scaled(dt);
        hermite(self.values[k], m0, self.values[k + 1], m1, s)
    }
}

/// The cubic Hermite curve through `p0` (s = 0) and `p1` (s = 1) with tangents `m0`, `m1`.
pub fn hermite<T: Keyable>(p0: T, m0: T, p1: T, m1: T, s: f32) -> T {
    let (s2, s3) = (s * s, s * s * s);
    let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
    let h10 = s3 - 2.0 * s2 + s;
    let h01 = -2.0 * s3 + 3.0 * s2;
    let h11 = s3 - s2;
    p0.scaled(h00).add(m0.scaled(h10)).add(p1.scaled(h01)).add(m1.scaled(h11)).finish()
}

fn check_times(times: &[f32]) -> Result<(), TrackError> {
    if times.is_empty() {
        return Err(TrackError::Empty);
    }
    for (index, &time) in times.iter().enumerate() {
        if !time.is_finite() {
            return Err(TrackError::NonFiniteTime { index });
        }
        if index > 0 && time <= times[index - 1] {
            return Err(TrackError::TimesOutOfOrder { index, previous: times[index - 1], time });
        }
    }
    Ok(())
}

fn check_values<T: Keyable>(values: &[T], keys: usize, what: &'static str) -> Result<(), TrackError> {
    if values.len() != keys {
        return Err(TrackError::LengthMismatch { what, expected: keys, found: values.len() });
    }
    match values.iter().position(|v| !v.is_finite_value()) {
        Some(index) => Err(TrackError::NonFiniteValue { what, index }),
        None => Ok(()),
    }
}

/// Normalises rotation keys, refusing those of zero length (a unit quaternion is needed
/// to describe a rotation; glTF requires unit keys, TOML scenes may give any length).
pub fn normalized_rotations(keys: &[Quat]) -> Result<Vec<Quat>, TrackError> {
    keys.iter()
        .enumerate()
        .map(|(index, q)| {
            if !q.is_finite() {
                return Err(TrackError::NonFiniteValue { what: "rotation", index });
            }
            let len = q.length();
            if len < 1e-6 {
                return Err(TrackError::ZeroQuaternion { index });
            }
            Ok(*q / len)
        })
        .collect()
}
