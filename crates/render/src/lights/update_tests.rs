//! [`LightSet::update_instances`] against [`LightSet::build`] of the moved scene: the
//! same lights, powers, selection and densities, bit for bit.

use super::tests::test_scene;
use super::*;
use filtrace_core::{Affine3A, Quat, Vec3};
use filtrace_scene::{Light as SceneLight, Scene};

/// Every observable of the two sets agrees bit for bit: the whole state (`Debug` prints
/// each `f32` so that it reads back to the same bits), and sampling and densities on a
/// grid of random numbers from a few points.
fn assert_same(updated: &LightSet, built: &LightSet, scene: &Scene) {
    assert_eq!(format!("{updated:?}"), format!("{built:?}"));
    for p in [Vec3::new(0.2, 0.1, -0.3), Vec3::new(-1.0, 1.5, 0.7), Vec3::new(2.0, 0.3, 0.0)] {
        for k in 0..64 {
            let u_select = (k as f32 + 0.5) / 64.0;
            let u = Vec2::new((k as f32 * 0.618_034).fract(), (k as f32 * 0.414_213).fract());
            let (a, b) = (updated.sample_li(p, u_select, u), built.sample_li(p, u_select, u));
            assert_eq!(format!("{a:?}"), format!("{b:?}"), "sample_li from {p} at {u_select}");
            if let Some(s) = a {
                let x = p + s.wi * s.dist.min(1e3);
                assert_eq!(updated.pdf_environment(s.wi).to_bits(), built.pdf_environment(s.wi).to_bits());
                for (ii, inst) in scene.instances.iter().enumerate() {
                    for prim in 0..scene.meshes[inst.mesh as usize].triangle_count() as u32 {
                        let (pa, pb) = (
                            updated.pdf_area(ii as u32, prim, p, x, Vec3::ZERO),
                            built.pdf_area(ii as u32, prim, p, x, Vec3::ZERO),
                        );
                        assert_eq!(pa.to_bits(), pb.to_bits());
                    }
                }
            }
        }
    }
}

/// The test scene with a directional light (its power follows the scene radius) and a
/// point light.
fn scene() -> Scene {
    let mut s = test_scene(true);
    s.lights
        .push(SceneLight::Directional { direction: Vec3::new(0.3, 1.0, 0.2), irradiance: Vec3::splat(2.0) });
    s.lights.push(SceneLight::Point { position: Vec3::new(0.0, 1.0, 0.0), intensity: Vec3::splat(4.0) });
    s
}

#[test]
fn moving_an_emitter_and_the_floor_equals_a_rebuild() {
    let mut s = scene();
    let mut lights = LightSet::build(&s);
    // The side light (instance 2) rotated, scaled and moved; the floor (instance 0, no
    // emitter) moved far, which changes the scene radius and so the directional power.
    s.instances[2].transform = Affine3A::from_scale_rotation_translation(
        Vec3::new(1.5, 0.5, 2.0),
        Quat::from_rotation_y(0.7) * Quat::from_rotation_x(0.2),
        Vec3::new(-1.0, 0.4, 3.0),
    );
    s.instances[0].transform = Affine3A::from_translation(Vec3::new(0.0, -4.0, 9.0));
    let before = lights.selection_pmf(lights.area_light_index(2, 0).unwrap());
    lights.update_instances(&s, &[2, 0]);
    let built = LightSet::build(&s);
    assert_same(&lights, &built, &s);
    assert_ne!(before, lights.selection_pmf(lights.area_light_index(2, 0).unwrap()), "re-weighted");
    // Several frames in a row.
    for f in 1..4 {
        s.instances[1].transform = Affine3A::from_translation(Vec3::new(0.1 * f as f32, 0.0, -0.2));
        lights.update_instances(&s, &[1]);
        assert_same(&lights, &LightSet::build(&s), &s);
    }
}

#[test]
fn animated_explicit_lights_are_re_derived() {
    let mut s = scene();
    let mut lights = LightSet::build(&s);
    let n = s.lights.len();
    s.lights[n - 1] = SceneLight::Point { position: Vec3::new(1.0, 0.5, -1.0), intensity: Vec3::splat(9.0) };
    lights.update_instances(&s, &[]);
    assert_same(&lights, &LightSet::build(&s), &s);
}

/// An emitter that becomes degenerate (scale 0) and comes back, an instance index out of
/// range and an instance list of another length: the update falls back to a rebuild.
#[test]
fn changes_an_in_place_update_cannot_follow_equal_a_rebuild() {
    let mut s = scene();
    let mut lights = LightSet::build(&s);
    let n = lights.len();
    s.instances[2].transform = Affine3A::from_scale(Vec3::ZERO);
    lights.update_instances(&s, &[2]);
    assert_same(&lights, &LightSet::build(&s), &s);
    assert_eq!(lights.len(), n - 2, "two degenerate triangles dropped");
    assert_eq!(lights.skipped(), 2);
    s.instances[2].transform = Affine3A::from_translation(Vec3::new(2.5, 0.0, 0.0));
    lights.update_instances(&s, &[2]);
    assert_same(&lights, &LightSet::build(&s), &s);
    lights.update_instances(&s, &[99]);
    assert_same(&lights, &LightSet::build(&s), &s);
    s.instances.pop();
    lights.update_instances(&s, &[]);
    assert_same(&lights, &LightSet::build(&s), &s);
}

/// The light interface agrees with the set: `sample_li` of the chosen light times the
/// sampler's pmf is the set's sample, and `pdf_li` times the pmf its density.
#[test]
fn light_interface_and_sampler_compose_to_the_set() {
    let s = scene();
    let lights = LightSet::build(&s);
    let ctx = LightSampleContext { p: Vec3::new(0.2, 0.1, -0.3) };
    for k in 0..200 {
        let u_select = (k as f32 + 0.5) / 200.0;
        let u = Vec2::new((k as f32 * 0.618_034).fract(), (k as f32 * 0.414_213).fract());
        let Some(chosen) = lights.sampler().sample(&ctx, u_select) else { panic!("no light chosen") };
        assert_eq!(chosen.p, lights.sampler().pmf(&ctx, chosen.light));
        let light = lights.light(chosen.light).unwrap();
        let le = light.sample_le(u, Vec2::new(u.y, u.x), lights.scene_center(), lights.scene_radius());
        assert_eq!(le, lights.sample_le_of(chosen.light, u, Vec2::new(u.y, u.x)));
        assert_eq!(le.map(|s| s.kind), Some(light.kind()));
        let from_set = lights.sample_li(ctx.p, u_select, u);
        let Some(ls) = light.sample_li(&ctx, u) else {
            assert!(from_set.is_none());
            continue;
        };
        assert_eq!(from_set.unwrap().pdf, chosen.p * ls.pdf);
        assert_eq!(ls.delta, light.is_delta());
        if !ls.delta {
            let x = ctx.p + ls.wi * ls.dist;
            let pdf = light.pdf_li(&ctx, ls.wi, x);
            assert!((pdf - ls.pdf).abs() <= 1e-3 * ls.pdf, "{pdf} vs {}", ls.pdf);
        }
        assert_eq!(light.bounds(lights.scene_radius()).is_none(), ls.dist.is_infinite());
    }
}
