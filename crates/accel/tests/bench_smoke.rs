//! `ray_bench` runs on a small scene and reports consistent numbers (timings are not checked).

use filtrace_accel::bench::{incoherent_rays, primary_rays, ray_bench, RayBenchOptions};
use filtrace_accel::testmesh;
use filtrace_scene::Scene;

#[test]
fn ray_bench_reports_consistent_numbers() {
    let mut scene = Scene { name: "sphere".into(), ..Scene::default() };
    scene.add_mesh(testmesh::displaced_sphere(8, 0.1));
    let opts = RayBenchOptions::quick();
    let r = ray_bench(&scene, &opts);
    assert_eq!(r.triangles, 12 * 64);
    assert_eq!(r.primary_rays, opts.width * opts.height);
    assert_eq!(r.incoherent_rays, opts.rays);
    assert!(r.threads >= 1);
    assert_eq!(r.kernel, format!("{:?}", filtrace_accel::Simd::best()));
    for m in [r.primary_closest_mrays, r.incoherent_closest_mrays, r.incoherent_any_mrays] {
        assert!(m.is_finite() && m > 0.0);
    }
    // Same rays, same t range: any-hit and closest-hit must agree on what hits.
    assert_eq!(r.incoherent_hit_fraction, r.incoherent_any_hit_fraction);
    // Packets give the answers of single rays.
    assert_eq!(r.packet_primary_hit_fraction, r.primary_hit_fraction);
    assert_eq!(r.packet_incoherent_hit_fraction, r.incoherent_hit_fraction);
    assert_eq!(r.packet_incoherent_any_hit_fraction, r.incoherent_any_hit_fraction);
    assert_eq!(r.packet_shadow_hit_fraction, r.shadow_hit_fraction);
    assert_eq!(r.shadow_rays, opts.rays);
    assert!(r.shadow_hit_fraction > 0.05 && r.shadow_hit_fraction < 0.95, "{}", r.shadow_hit_fraction);
    for m in [r.shadow_any_mrays, r.packet_primary_closest_mrays, r.packet_shadow_mrays] {
        assert!(m.is_finite() && m > 0.0);
    }
    // The camera frames the object: a good share of pixels see it, not all.
    assert!(r.primary_hit_fraction > 0.2 && r.primary_hit_fraction < 0.9, "{}", r.primary_hit_fraction);
    let md = r.to_markdown();
    assert!(md.contains("incoherent closest") && md.contains("| primary closest |"));
    assert!(md.contains("| packet shadow any |"));
    let json = serde_json::to_string(&r).unwrap();
    assert!(json.contains("\"incoherent_any_mrays\""));
}

#[test]
fn ray_sets_are_deterministic_and_empty_for_empty_scenes() {
    let mut scene = Scene::default();
    scene.add_mesh(testmesh::icosphere(1));
    assert_eq!(incoherent_rays(&scene, 100, 3), incoherent_rays(&scene, 100, 3));
    assert_ne!(incoherent_rays(&scene, 100, 3), incoherent_rays(&scene, 100, 4));
    assert!(incoherent_rays(&Scene::default(), 100, 3).is_empty());
    assert!(primary_rays(&Scene::default(), 4, 4).is_empty());
    let r = ray_bench(&Scene::default(), &RayBenchOptions::quick());
    assert_eq!((r.triangles, r.primary_rays, r.incoherent_rays), (0, 0, 0));
}
