//! Exact duplicate triangles, dropped at load.
//!
//! A million coincident triangles make every ray that reaches them test a million
//! triangles (one such file rendered for hours), and they add nothing to the image but
//! z-fighting between their materials. Two triangles of one mesh are duplicates when they
//! have the same three vertex positions (bit for bit, -0 = +0) in the same cyclic order,
//! i.e. the same surface facing the same way; the reversed order (the back of a two-sided
//! wall) is kept. The first in file order is kept. Only duplicates within one mesh are
//! found (those are what a mesh file can hold); O(n) with a hash map.

use std::collections::HashMap;
use std::path::Path;

use filtrace_core::Vec3;

use crate::types::{Mesh, Scene};

/// Removes the duplicates of every mesh of `scene`, with one warning per mesh that had any.
pub fn remove_duplicate_triangles(scene: &mut Scene, path: &Path) {
    for mesh in &mut scene.meshes {
        let (dropped, other_material) = dedup_mesh(mesh);
        if dropped == 0 {
            continue;
        }
        let mut w = format!(
            "{}: mesh '{}': {dropped} exact duplicate triangles (same corners as an earlier one) dropped",
            path.display(),
            mesh.name
        );
        if other_material > 0 {
            w += &format!(
                "; {other_material} of them had another material than the kept one, which now shows alone"
            );
        }
        scene.stats.warnings.push(w);
    }
}

/// The triangle's corners as bits, rotated so that the smallest comes first (winding kept).
fn key(p: [Vec3; 3]) -> [[u32; 3]; 3] {
    let bits = p.map(|v| (v + Vec3::ZERO).to_array().map(f32::to_bits)); // -0 + 0 = +0
    let first = (0..3).min_by_key(|&i| bits[i]).unwrap_or(0);
    [bits[first], bits[(first + 1) % 3], bits[(first + 2) % 3]]
}

/// Drops `mesh`'s duplicate triangles; returns (dropped, dropped with another material).
fn dedup_mesh(mesh: &mut Mesh) -> (usize, usize) {
    let mut seen: HashMap<[[u32; 3]; 3], u32> = HashMap::with_capacity(mesh.indices.len());
    let (mut dropped, mut other_material) = (0, 0);
    let mut keep = vec![true; mesh.indices.len()];
    for (i, k) in keep.iter_mut().enumerate() {
        let material = mesh.material_ids[i];
        match seen.entry(key(mesh.triangle(i))) {
            std::collections::hash_map::Entry::Vacant(e) => {
                e.insert(material);
            }
            std::collections::hash_map::Entry::Occupied(e) => {
                *k = false;
                dropped += 1;
                other_material += usize::from(*e.get() != material);
            }
        }
    }
    if dropped > 0 {
        let mut flags = keep.iter();
        mesh.indices.retain(|_| *flags.next().unwrap_or(&true));
        let mut flags = keep.iter();
        mesh.material_ids.retain(|_| *flags.next().unwrap_or(&true));
    }
    (dropped, other_material)
}
