//! Furniture meshes of the `classroom` scene, built from boxes and thin tubes. Units are
//! metres; each piece stands on y = 0, centred on x = z = 0, its front towards -z (where the
//! blackboard is).

use filtrace_core::Vec3;

use crate::shapes;
use crate::types::{MaterialId, Mesh};

/// Sides of a tube (a leg or a rail): 16 sides and centre-fan caps give 64 triangles.
pub const TUBE_SIDES: u32 = 16;
/// Radius of desk and chair legs (m): thin, so that their shadows are a few pixels wide.
pub const LEG_RADIUS: f32 = 0.014;

/// Appends an axis-aligned box of centre `c` and size `size`.
pub fn add_box(m: &mut Mesh, c: Vec3, size: Vec3, material: MaterialId) {
    let cube = shapes::cube(material);
    append(m, &cube, |p| c + p * size);
}

/// Appends a closed tube (cylinder) of radius `r` from `a` to `b`: `TUBE_SIDES` side quads
/// and a fan of as many triangles around each end's centre, faces pointing out.
pub fn add_tube(m: &mut Mesh, a: Vec3, b: Vec3, r: f32, material: MaterialId) {
    let axis = (b - a).normalize();
    let (u, v) = axis.any_orthonormal_pair();
    let base = m.positions.len() as u32;
    let n = TUBE_SIDES;
    for i in 0..n {
        let phi = std::f32::consts::TAU * i as f32 / n as f32;
        let d = r * (phi.cos() * u + phi.sin() * v);
        m.positions.extend([a + d, b + d]);
    }
    let (ca, cb) = (base + 2 * n, base + 2 * n + 1);
    m.positions.extend([a, b]);
    for i in 0..n {
        let j = (i + 1) % n;
        let (a0, b0, a1, b1) = (base + 2 * i, base + 2 * i + 1, base + 2 * j, base + 2 * j + 1);
        // (u, v, axis) is right-handed, so the sides wind counter-clockwise seen from outside.
        m.indices.extend([[a0, a1, b1], [a0, b1, b0], [ca, a1, a0], [cb, b0, b1]]);
    }
    m.material_ids.extend(std::iter::repeat_n(material, 4 * n as usize));
}

/// Appends `part` with its positions mapped by `f`.
fn append(m: &mut Mesh, part: &Mesh, f: impl Fn(Vec3) -> Vec3) {
    let base = m.positions.len() as u32;
    m.positions.extend(part.positions.iter().map(|&p| f(p)));
    m.indices.extend(part.indices.iter().map(|t| t.map(|i| i + base)));
    m.material_ids.extend_from_slice(&part.material_ids);
}

/// The four corners (x, z) of a `w` x `d` rectangle inset by `inset`.
fn corners(w: f32, d: f32, inset: f32) -> [(f32, f32); 4] {
    let (x, z) = (0.5 * w - inset, 0.5 * d - inset);
    [(-x, -z), (x, -z), (x, z), (-x, z)]
}

/// A two-seat school desk: a 1.3 x 0.6 m top at 0.75 m on four thin legs, foot rails
/// between the legs of each side and a book shelf under the top.
pub fn desk(top: MaterialId, metal: MaterialId) -> Mesh {
    let mut m = Mesh { name: "desk".into(), ..Mesh::default() };
    let (w, d, h) = (1.3, 0.6, 0.75);
    add_box(&mut m, Vec3::new(0.0, h - 0.015, 0.0), Vec3::new(w, 0.03, d), top);
    add_box(&mut m, Vec3::new(0.0, 0.6, 0.05), Vec3::new(w - 0.12, 0.02, 0.35), top);
    for (x, z) in corners(w, d, 0.04) {
        add_tube(&mut m, Vec3::new(x, 0.0, z), Vec3::new(x, h - 0.03, z), LEG_RADIUS, metal);
    }
    let (x, z) = (0.5 * w - 0.04, 0.5 * d - 0.04);
    for sx in [-x, x] {
        add_tube(&mut m, Vec3::new(sx, 0.06, -z), Vec3::new(sx, 0.06, z), LEG_RADIUS, metal);
        add_tube(&mut m, Vec3::new(sx, 0.59, -z), Vec3::new(sx, 0.59, z), 0.6 * LEG_RADIUS, metal);
    }
    m
}

/// A school chair: a 0.42 m seat at 0.45 m on four thin legs joined by stretchers, two
/// back posts carrying a backrest panel (behind the seat, at +z).
pub fn chair(seat: MaterialId, metal: MaterialId) -> Mesh {
    let mut m = Mesh { name: "chair".into(), ..Mesh::default() };
    let (w, h) = (0.42, 0.45);
    add_box(&mut m, Vec3::new(0.0, h - 0.015, 0.0), Vec3::new(w, 0.03, w), seat);
    add_box(&mut m, Vec3::new(0.0, 0.74, 0.5 * w - 0.01), Vec3::new(w, 0.2, 0.02), seat);
    let c = corners(w, w, 0.03);
    for (x, z) in c {
        add_tube(&mut m, Vec3::new(x, 0.0, z), Vec3::new(x, h - 0.03, z), LEG_RADIUS, metal);
    }
    for (x, z) in [c[2], c[3]] {
        add_tube(&mut m, Vec3::new(x, h, z), Vec3::new(x, 0.86, z), LEG_RADIUS, metal);
    }
    // Stretchers: along z on both sides, along x at front and back, at two heights.
    for k in 0..4 {
        let (p, q) = (c[k], c[(k + 1) % 4]);
        let y = if k % 2 == 0 { 0.2 } else { 0.14 };
        add_tube(&mut m, Vec3::new(p.0, y, p.1), Vec3::new(q.0, y, q.1), 0.7 * LEG_RADIUS, metal);
    }
    m
}

/// The teacher's desk: a solid 1.6 x 0.8 m block (a top and a closed front panel).
pub fn teacher_desk(wood: MaterialId) -> Mesh {
    let mut m = Mesh { name: "teacher_desk".into(), ..Mesh::default() };
    add_box(&mut m, Vec3::new(0.0, 0.765, 0.0), Vec3::new(1.6, 0.03, 0.8), wood);
    add_box(&mut m, Vec3::new(0.0, 0.375, -0.37), Vec3::new(1.56, 0.75, 0.04), wood);
    for x in [-0.76, 0.76] {
        add_box(&mut m, Vec3::new(x, 0.375, 0.0), Vec3::new(0.04, 0.75, 0.78), wood);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed outward meshes have positive signed volume (divergence theorem); every part
    /// here is closed, so the whole piece is too.
    fn signed_volume(m: &Mesh) -> f32 {
        (0..m.triangle_count())
            .map(|t| {
                let [a, b, c] = m.triangle(t);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    #[test]
    fn a_tube_is_closed_outward_with_the_cylinder_volume() {
        let mut m = Mesh::default();
        add_tube(&mut m, Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 3.0, 3.5), 0.1, 0);
        assert_eq!(m.triangle_count(), 4 * TUBE_SIDES as usize);
        let n = TUBE_SIDES as f32;
        // A regular n-gon of circumradius r has area n r^2 sin(2 pi / n) / 2.
        let want = 0.5 * n * 0.01 * (std::f32::consts::TAU / n).sin() * 1.25f32.sqrt();
        assert!((signed_volume(&m) - want).abs() < 1e-4 * want.max(1.0), "{}", signed_volume(&m));
    }

    #[test]
    fn furniture_is_closed_outward_and_stands_on_the_floor() {
        for m in [desk(0, 1), chair(0, 1), teacher_desk(0)] {
            assert!(signed_volume(&m) > 0.0, "{}", m.name);
            assert!(m.bounds().min.y.abs() < 1e-6, "{}: {:?}", m.name, m.bounds());
            assert_eq!(m.indices.len(), m.material_ids.len());
        }
    }
}
