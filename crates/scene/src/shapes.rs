//! Tessellated built-in shapes, in object space, for TOML scene files and procedural scenes.
//! Every shape is counter-clockwise seen from outside (normals point out / up).

use filtrace_core::{Vec2, Vec3};

use crate::types::{MaterialId, Mesh};

/// Unit square `[-0.5, 0.5]^2` in the xz-plane at y = 0, facing +y, uv from 0 to 1.
pub fn quad(material: MaterialId) -> Mesh {
    Mesh {
        name: "quad".into(),
        positions: vec![
            Vec3::new(-0.5, 0.0, -0.5),
            Vec3::new(-0.5, 0.0, 0.5),
            Vec3::new(0.5, 0.0, 0.5),
            Vec3::new(0.5, 0.0, -0.5),
        ],
        normals: Vec::new(),
        uvs: vec![Vec2::new(0.0, 1.0), Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0)],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![material; 2],
    }
}

/// A quad with corner `p` and edges `e1`, `e2`, facing `e1 x e2`.
pub fn parallelogram(p: Vec3, e1: Vec3, e2: Vec3, material: MaterialId) -> Mesh {
    Mesh {
        name: "quad".into(),
        positions: vec![p, p + e1, p + e1 + e2, p + e2],
        normals: Vec::new(),
        uvs: vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![material; 2],
    }
}

/// Axis-aligned cube `[-0.5, 0.5]^3`, 12 triangles, flat shaded, faces pointing out.
pub fn cube(material: MaterialId) -> Mesh {
    let mut m = Mesh { name: "cube".into(), ..Mesh::default() };
    // Each face: outward normal n and two in-plane axes (u, v) with u x v = n.
    let faces = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y, Vec3::X),
    ];
    for (n, u, v) in faces {
        debug_assert!((u.cross(v) - n).length() < 1e-6);
        let c = 0.5 * n;
        let base = m.positions.len() as u32;
        for (su, sv) in [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)] {
            m.positions.push(c + su * u + sv * v);
            m.uvs.push(Vec2::new(su + 0.5, sv + 0.5));
        }
        m.indices.push([base, base + 1, base + 2]);
        m.indices.push([base, base + 2, base + 3]);
        m.material_ids.extend([material; 2]);
    }
    m
}

/// Unit sphere (radius 1, centre at the origin) as a UV sphere with `segments` steps around
/// the y axis and `segments / 2` from pole to pole (at least 3 x 2), smooth normals. The pole
/// rows are single triangles, so no triangle is degenerate.
pub fn sphere(segments: u32, material: MaterialId) -> Mesh {
    let nu = segments.max(3);
    let nv = (segments / 2).max(2);
    let mut m = Mesh { name: "sphere".into(), ..Mesh::default() };
    // Vertex grid (nv + 1 rows of nu + 1 columns; the seam column is duplicated for uvs).
    for j in 0..=nv {
        let theta = std::f32::consts::PI * j as f32 / nv as f32;
        for i in 0..=nu {
            let phi = std::f32::consts::TAU * i as f32 / nu as f32;
            let p = Vec3::new(theta.sin() * phi.cos(), theta.cos(), -theta.sin() * phi.sin());
            m.positions.push(p);
            m.normals.push(p);
            m.uvs.push(Vec2::new(i as f32 / nu as f32, 1.0 - j as f32 / nv as f32));
        }
    }
    let at = |i: u32, j: u32| j * (nu + 1) + i;
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j));
            if j != 0 {
                m.indices.push([a, b, d]);
            }
            if j != nv - 1 {
                m.indices.push([b, c, d]);
            }
        }
    }
    m.material_ids = vec![material; m.indices.len()];
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obj::is_degenerate;

    fn check_closed_outward(m: &Mesh) {
        // Divergence theorem: the signed volume of a closed outward mesh is positive.
        let mut vol = 0.0;
        for t in 0..m.triangle_count() {
            let [a, b, c] = m.triangle(t);
            assert!(!is_degenerate([a, b, c]), "{} triangle {t} is degenerate", m.name);
            vol += a.dot(b.cross(c)) / 6.0;
        }
        assert!(vol > 0.0, "{}: volume {vol}", m.name);
    }

    #[test]
    fn cube_is_closed_with_unit_volume() {
        let m = cube(0);
        check_closed_outward(&m);
        let vol: f32 = (0..12)
            .map(|t| {
                let [a, b, c] = m.triangle(t);
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        assert!((vol - 1.0).abs() < 1e-5);
    }

    #[test]
    fn sphere_volume_converges_to_four_thirds_pi() {
        for seg in [8, 32, 128] {
            let m = sphere(seg, 0);
            check_closed_outward(&m);
            let vol: f32 = (0..m.triangle_count())
                .map(|t| {
                    let [a, b, c] = m.triangle(t);
                    a.dot(b.cross(c)) / 6.0
                })
                .sum();
            let exact = 4.0 / 3.0 * std::f32::consts::PI;
            // Inscribed polyhedron: below the sphere, error O(1/seg^2).
            let rel = (exact - vol) / exact;
            assert!(rel > 0.0 && rel < 20.0 / (seg * seg) as f32, "seg {seg}: rel error {rel}");
            for (p, n) in m.positions.iter().zip(&m.normals) {
                assert!((p.length() - 1.0).abs() < 1e-5 && (*p - *n).length() < 1e-6);
            }
        }
    }

    #[test]
    fn quad_faces_up() {
        let m = quad(0);
        for t in 0..2 {
            let [a, b, c] = m.triangle(t);
            assert!((b - a).cross(c - a).normalize().abs_diff_eq(Vec3::Y, 1e-6));
        }
        let p = parallelogram(Vec3::ZERO, Vec3::X, Vec3::Z, 0);
        let [a, b, c] = p.triangle(0);
        assert!((b - a).cross(c - a).normalize().abs_diff_eq(Vec3::NEG_Y, 1e-6));
    }
}
