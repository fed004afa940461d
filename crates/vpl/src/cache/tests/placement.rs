//! Cache point placement through a G-buffer.

use super::super::*;
use filtrace_core::Vec3;

/// A 64 × 48 G-buffer: the left quarter is background, the rest a tilted plane.
fn gbuffer() -> (usize, usize, Vec<Vec3>, Vec<Vec3>) {
    let (w, h) = (64, 48);
    let mut positions = vec![Vec3::ZERO; w * h];
    let mut normals = vec![Vec3::ZERO; w * h];
    for y in 0..h {
        for x in w / 4..w {
            positions[y * w + x] = Vec3::new(x as f32, y as f32, 0.1 * x as f32);
            normals[y * w + x] = Vec3::new(0.0, 0.0, 2.0);
        }
    }
    (w, h, positions, normals)
}

#[test]
fn points_lie_on_distinct_surface_pixels_deterministically() {
    let (w, h, positions, normals) = gbuffer();
    let view = GBufferView { width: w, height: h, positions: &positions, normals: &normals };
    for count in [1, 10, 300, 2048] {
        let points = place_cache_points(&view, count, 17).unwrap();
        assert_eq!(points.len(), count.min(w * h * 3 / 4), "count {count}");
        let mut seen = std::collections::HashSet::new();
        for p in &points {
            let px = p.pixel as usize;
            assert!(px % w >= w / 4, "pixel {px} is background");
            assert_eq!(p.position, positions[px]);
            assert!((p.normal - Vec3::Z).length() < 1e-6, "normals are normalised");
            assert!(seen.insert(px), "pixel {px} taken twice");
        }
        assert_eq!(points, place_cache_points(&view, count, 17).unwrap(), "same seed, same points");
    }
}

/// Stratification: with one point per cell, every cell of the covered area gets one.
#[test]
fn points_cover_the_screen_evenly() {
    let (w, h, positions, normals) = gbuffer();
    let view = GBufferView { width: w, height: h, positions: &positions, normals: &normals };
    let points = place_cache_points(&view, 192, 3).unwrap();
    // 16 x 12 blocks of 4 x 4 pixels over the surface part: each holds at least one point.
    let mut blocks = vec![0; 16 * 12];
    for p in &points {
        let (x, y) = (p.pixel as usize % w, p.pixel as usize / w);
        blocks[(y / 4) * 16 + x / 4] += 1;
    }
    let empty = (0..16 * 12).filter(|&b| b % 16 >= 4 && blocks[b] == 0).count();
    assert!(empty <= 2, "{empty} empty surface blocks");
}

#[test]
fn bad_and_empty_gbuffers() {
    let positions = vec![Vec3::ZERO; 10];
    let normals = vec![Vec3::ZERO; 12];
    let view = GBufferView { width: 4, height: 3, positions: &positions, normals: &normals };
    let err = place_cache_points(&view, 5, 0).unwrap_err();
    assert!(err.contains("4x3") && err.contains("10"), "{err}");
    let positions = vec![Vec3::ZERO; 12];
    let view = GBufferView { width: 4, height: 3, positions: &positions, normals: &normals };
    assert!(place_cache_points(&view, 5, 0).unwrap().is_empty(), "all background: no points");
    let nan = vec![Vec3::splat(f32::NAN); 12];
    let view = GBufferView { width: 4, height: 3, positions: &nan, normals: &nan };
    assert!(place_cache_points(&view, 5, 0).unwrap().is_empty(), "NaN is background");
}
