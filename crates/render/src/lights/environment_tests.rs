//! The environment's lane versions against the scalar code, bit for bit: radiance, density
//! and samples of skies with and without zero-weight bands, for random `u`, `u` on every
//! CDF entry (where the scalar search steps off zero-width cells) and the ends of `[0, 1)`.

use super::environment::EnvironmentLight;
use crate::bsdf::tests::Rng;
use crate::integrator::lanes::{from_bits, F8, LANES};
use filtrace_core::sampling::ONE_MINUS_EPSILON;
use filtrace_core::{Rgb, Vec2, Vec3};
use filtrace_scene::Environment;

fn environments() -> Vec<EnvironmentLight> {
    let sky = |zenith: f32, horizon: f32, ground: f32| Environment::Sky {
        zenith: Rgb::splat(zenith),
        horizon: Rgb::new(horizon, 0.5 * horizon, 0.25 * horizon),
        ground: Rgb::splat(ground),
    };
    let constant = Environment::Constant { radiance: Rgb::new(0.2, 0.3, 0.4) };
    vec![
        EnvironmentLight::new(&[&sky(1.0, 0.8, 0.3)]),
        // Black ground: the lower half of the bands has weight 0 (zero-width CDF cells).
        EnvironmentLight::new(&[&sky(1.0, 0.8, 0.0)]),
        // Black zenith and ground: weights only in the bands near the horizon.
        EnvironmentLight::new(&[&sky(0.0, 2.0, 0.0)]),
        EnvironmentLight::new(&[&constant]),
        EnvironmentLight::new(&[&sky(1.0, 0.8, 0.3), &constant]),
        // All black: the degenerate distribution (no samples, density 0).
        EnvironmentLight::new(&[&sky(0.0, 0.0, 0.0)]),
    ]
}

/// The `u.x` values to try: random ones, every CDF entry and its neighbours, the ends.
fn u_values(env: &EnvironmentLight, rng: &mut Rng) -> Vec<f32> {
    let mut u: Vec<f32> = (0..2000).map(|_| rng.f32()).collect();
    // The band edges and the CDF entries, with their neighbours.
    for k in 0..=super::environment::Z_BINS {
        let x = k as f32 / super::environment::Z_BINS as f32;
        u.extend([x, f32::from_bits(x.to_bits().saturating_sub(1)), f32::from_bits(x.to_bits() + 1)]);
    }
    u.extend(
        env.distribution().cdf().iter().flat_map(|&c| {
            [c, f32::from_bits(c.to_bits().saturating_sub(1)), f32::from_bits(c.to_bits() + 1)]
        }),
    );
    u.extend([0.0, ONE_MINUS_EPSILON]);
    u.retain(|x| (0.0..1.0).contains(x));
    u
}

fn check<const A: bool>(env: &EnvironmentLight, us: &[f32], rng: &mut Rng) {
    for chunk in us.chunks(LANES) {
        let mut ux = [0.5f32; LANES];
        ux[..chunk.len()].copy_from_slice(chunk);
        let uy: [f32; LANES] = std::array::from_fn(|_| rng.f32());
        let lanes = from_bits::<A>(((1u32 << chunk.len()) - 1) as u8);
        let s = env.sample8::<A>(lanes, F8::from_array(ux), F8::from_array(uy));
        for i in 0..chunk.len() {
            let scalar = env.sample(Vec2::new(ux[i], uy[i]));
            if s.scalar.get(i) {
                continue;
            }
            match scalar {
                Some((wi, pdf)) => {
                    assert!(s.ok.get(i), "u {:?}: lane {i} has no sample", (ux[i], uy[i]));
                    let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                    assert_eq!(bits(s.wi.lane(i)), bits(wi), "u {:?}", (ux[i], uy[i]));
                    assert_eq!(s.pdf.lane(i).to_bits(), pdf.to_bits(), "u {:?}", (ux[i], uy[i]));
                    assert_eq!(bits(s.li.lane(i)), bits(env.radiance(wi)));
                }
                None => assert!(!s.ok.get(i), "u {:?}: the scalar code has no sample", (ux[i], uy[i])),
            }
        }
        // Radiance and density of arbitrary directions (the samples' and random ones).
        let dirs: [f32; LANES] =
            std::array::from_fn(|i| if i < 4 { 2.0 * uy[i] - 1.0 } else { s.wi.y.lane(i) });
        let y = F8::<A>::from_array(dirs);
        let (le, pdf) = (env.radiance8(y), env.pdf8(y));
        for (i, &dy) in dirs.iter().enumerate() {
            let w = Vec3::new(0.0, dy, (1.0 - dy * dy).max(0.0).sqrt());
            assert_eq!(le.lane(i).to_array().map(f32::to_bits), env.radiance(w).to_array().map(f32::to_bits));
            assert_eq!(pdf.lane(i).to_bits(), env.pdf(w).to_bits(), "y {dy}");
        }
    }
}

#[test]
fn environment_lanes_equal_the_scalar_code() {
    let mut rng = Rng::new(11);
    for env in environments() {
        let us = u_values(&env, &mut rng);
        check::<false>(&env, &us, &mut rng);
        #[cfg(target_arch = "x86_64")]
        if filtrace_core::cpu::isa().has_avx2() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            unsafe { check_avx2(&env, &us, &mut rng) };
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn check_avx2(env: &EnvironmentLight, us: &[f32], rng: &mut Rng) {
    check::<true>(env, us, rng);
}
