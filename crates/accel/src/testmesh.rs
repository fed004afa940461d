//! Procedural meshes and a minimal OBJ reader for tests and benchmarks.
//!
//! - [`subdivided_cube`]: the closed cube `[-1, 1]^3`, `12 n^2` triangles;
//! - [`displaced_sphere`]: a closed, bumpy sphere from the same grid (n = 150 gives
//!   270,000 triangles, the stand-in for the 268k-triangle mesh of the Embree figures);
//! - [`icosphere`]: a closed unit sphere with shared vertex indices;
//! - [`thin_blades`]: long thin slanted grass blades on a ground quad, the triangles
//!   whose boxes are far larger than themselves (for the pre-splitting of `presplit.rs`);
//! - [`read_obj`]: positions and faces of a Wavefront OBJ (no materials), for benchmarks
//!   until the scene loaders are used.
//!
//! All generated meshes are watertight in the strict sense: vertices on shared edges
//! are computed by the same expression from the same integers, so they are bit-identical.

use filtrace_core::Vec3;
use filtrace_scene::Mesh;
use std::collections::HashMap;

/// The deterministic generator of tests and benchmark ray sets.
pub use filtrace_core::rng::SplitMix64;

fn mesh_from(name: &str, positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> Mesh {
    let material_ids = vec![0; indices.len()];
    Mesh { name: name.to_string(), positions, normals: Vec::new(), uvs: Vec::new(), indices, material_ids }
}

/// Points of an `n x n` grid on each face of the cube `[-1, 1]^3`, as triangles wound
/// counter-clockwise seen from outside. Vertices are not shared between faces, but the
/// edge vertices of neighbouring faces are bit-identical.
fn cube_grid(n: usize, map: impl Fn(Vec3) -> Vec3) -> Mesh {
    let n = n.max(1);
    let coord = |i: usize| (2.0 * i as f32 - n as f32) / n as f32;
    let mut positions = Vec::with_capacity(6 * (n + 1) * (n + 1));
    let mut indices = Vec::with_capacity(12 * n * n);
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            let base = positions.len() as u32;
            for j in 0..=n {
                for i in 0..=n {
                    let mut p = [0.0f32; 3];
                    p[axis] = sign;
                    p[(axis + 1) % 3] = coord(i);
                    p[(axis + 2) % 3] = coord(j);
                    positions.push(map(Vec3::from_array(p)));
                }
            }
            let at = |i: usize, j: usize| base + (j * (n + 1) + i) as u32;
            for j in 0..n {
                for i in 0..n {
                    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                    if sign > 0.0 {
                        indices.push([a, b, c]);
                        indices.push([a, c, d]);
                    } else {
                        indices.push([a, c, b]);
                        indices.push([a, d, c]);
                    }
                }
            }
        }
    }
    mesh_from("cube_grid", positions, indices)
}

/// The closed cube `[-1, 1]^3` split into `12 n^2` triangles.
pub fn subdivided_cube(n: usize) -> Mesh {
    Mesh { name: format!("cube_{n}"), ..cube_grid(n, |p| p) }
}

/// A closed bumpy sphere: the cube grid projected to the unit sphere and displaced along
/// the normal by `amplitude * sin(7x) sin(5y + 1) sin(6z + 2)`. `12 n^2` triangles.
pub fn displaced_sphere(n: usize, amplitude: f32) -> Mesh {
    let m = cube_grid(n, |p| {
        let s = p.normalize();
        s * (1.0 + amplitude * (7.0 * s.x).sin() * (5.0 * s.y + 1.0).sin() * (6.0 * s.z + 2.0).sin())
    });
    Mesh { name: format!("displaced_sphere_{n}"), ..m }
}

/// The closed unit icosphere: an icosahedron subdivided `level` times (`20 * 4^level`
/// triangles), vertices shared through an edge-midpoint table.
pub fn icosphere(level: usize) -> Mesh {
    let t = (1.0 + 5.0f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut indices: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                positions.push((0.5 * (positions[a as usize] + positions[b as usize])).normalize());
                positions.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(indices.len() * 4);
        for [a, b, c] in indices {
            let ab = midpoint(a, b, &mut positions);
            let bc = midpoint(b, c, &mut positions);
            let ca = midpoint(c, a, &mut positions);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        indices = next;
    }
    mesh_from(&format!("icosphere_{level}"), positions, indices)
}

/// `count` grass blades on the ground quad `[-1, 1]^2` at `y = 0` (2 triangles): each
/// blade is 5 triangles (three tapering segments and a tip), 0.4-1 high and 0.01-0.03
/// wide at the base, leaning up to 45 degrees in a random direction and facing another,
/// so that most triangles are long, thin and diagonal to every axis. `5 count + 2`
/// triangles, positions from `seed`.
pub fn thin_blades(count: usize, seed: u64) -> Mesh {
    let mut rng = SplitMix64(seed);
    let mut positions = vec![
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(-1.0, 0.0, 1.0),
    ];
    let mut indices = vec![[0, 2, 1], [0, 3, 2]];
    for _ in 0..count {
        let base = Vec3::new(2.0 * rng.next_f32() - 1.0, 0.0, 2.0 * rng.next_f32() - 1.0);
        let height = 0.4 + 0.6 * rng.next_f32();
        let width = 0.01 + 0.02 * rng.next_f32();
        let (lean_angle, face_angle) =
            (std::f32::consts::TAU * rng.next_f32(), std::f32::consts::TAU * rng.next_f32());
        let lean = Vec3::new(lean_angle.cos(), 0.0, lean_angle.sin()) * height * rng.next_f32();
        let side = Vec3::new(face_angle.cos(), 0.0, face_angle.sin()) * (0.5 * width);
        let first = positions.len() as u32;
        for j in 0..3 {
            let f = j as f32 / 3.0;
            let centre = base + Vec3::Y * (height * f) + lean * (f * f);
            positions.extend([centre - side * (1.0 - f), centre + side * (1.0 - f)]);
        }
        positions.push(base + Vec3::Y * height + lean);
        let at = |k: u32| first + k;
        for j in 0..2 {
            let (l0, r0, l1, r1) = (at(2 * j), at(2 * j + 1), at(2 * j + 2), at(2 * j + 3));
            indices.extend([[l0, r0, r1], [l0, r1, l1]]);
        }
        indices.push([at(4), at(5), at(6)]);
    }
    mesh_from(&format!("thin_blades_{count}"), positions, indices)
}

/// Reads the vertices (`v`) and faces (`f`, fan-triangulated; `v/vt/vn` forms and
/// negative indices accepted) of a Wavefront OBJ file; zero-area triangles are dropped.
pub fn read_obj(path: &std::path::Path) -> Result<Mesh, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for (line_no, line) in text.lines().enumerate() {
        let err = |what: &str| format!("{}:{}: {what}", path.display(), line_no + 1);
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f32> = it
                    .take(3)
                    .map(|s| s.parse::<f32>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| err("bad vertex"))?;
                if c.len() != 3 {
                    return Err(err("vertex needs 3 coordinates"));
                }
                positions.push(Vec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let mut face = Vec::new();
                for tok in it {
                    let i: i64 =
                        tok.split('/').next().unwrap_or("").parse().map_err(|_| err("bad face index"))?;
                    let n = positions.len() as i64;
                    let i = if i < 0 { n + i } else { i - 1 };
                    if i < 0 || i >= n {
                        return Err(err("face index out of range"));
                    }
                    face.push(i as u32);
                }
                for k in 1..face.len().saturating_sub(1) {
                    indices.push([face[0], face[k], face[k + 1]]);
                }
            }
            _ => {}
        }
    }
    indices.retain(|&[a, b, c]| {
        let (p0, p1, p2) = (positions[a as usize], positions[b as usize], positions[c as usize]);
        (p1 - p0).cross(p2 - p0).length_squared() > 0.0
    });
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(mesh_from(&name, positions, indices))
}

/// The `k`-th ray of the box-test tests' grazing cycle for the box `lo..hi`: aimed at a
/// random corner (even `k`) or in a random direction, with its origin moved onto that
/// corner's face plane (every 4th), a zero direction component (every 5th) and `t_max = 1`
/// (every 7th, else infinity). `origin` maps a random point of `[0, 1)^3` to the origin.
/// Returns `(origin, direction, t_max)`, `None` when the direction came out zero.
#[cfg(test)]
pub(crate) fn grazing_ray(
    k: usize,
    rnd: &mut impl FnMut() -> f32,
    (lo, hi): (Vec3, Vec3),
    origin: impl FnOnce(Vec3) -> Vec3,
) -> Option<(Vec3, Vec3, f32)> {
    let corner = Vec3::select(glam::BVec3::new(rnd() < 0.5, rnd() < 0.5, rnd() < 0.5), lo, hi);
    let mut o = origin(Vec3::new(rnd(), rnd(), rnd()));
    if k.is_multiple_of(4) {
        o[k % 3] = corner[k % 3];
    }
    let mut d = if k.is_multiple_of(2) { corner - o } else { Vec3::new(rnd(), rnd(), rnd()) - 0.5 };
    if k.is_multiple_of(5) {
        d[(k / 5) % 3] = 0.0;
    }
    if d == Vec3::ZERO {
        return None;
    }
    let t_max = if k.is_multiple_of(7) { 1.0 } else { f32::INFINITY };
    Some((o, d, t_max))
}
