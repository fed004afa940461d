//! `bunny-room`: the Stanford bunny (`../shared/scenes/bunny/bunny.obj`, 56,172 triangles,
//! from the Stanford 3D Scanning Repository via PyPI pymeshlab) standing on the floor of the
//! Cornell box room (walls, light and camera of [`super::cornell`], without the blocks).
//! Smooth, curved, finely tessellated geometry with per-vertex normals, under a small area
//! light. Needs the file: an error names the paths tried when it is missing.

use std::path::PathBuf;

use filtrace_core::{Affine3A, Quat, Rgb, Vec3};

use super::cornell::{cornell_materials, quad_mesh, OBJECTS};
use crate::error::SceneError;
use crate::types::{Camera, Instance, Material, Scene};

/// Height of the bunny in the room (the room is 548.8 tall).
pub const BUNNY_HEIGHT: f32 = 300.0;

/// Where the shared folder may be, in order: `$FILTRACE_SHARED`, `../shared` from the current
/// directory (the project root), `../shared` next to this source tree.
pub fn shared_candidates(rel: &str) -> Vec<PathBuf> {
    let mut v = Vec::new();
    if let Some(d) = std::env::var_os("FILTRACE_SHARED") {
        v.push(PathBuf::from(d).join(rel));
    }
    v.push(PathBuf::from("../shared").join(rel));
    v.push(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared").join(rel));
    v
}

/// The scene, with the bunny from the first of [`shared_candidates`] that exists.
pub fn bunny_room() -> Result<Scene, SceneError> {
    bunny_room_from(&shared_candidates("scenes/bunny/bunny.obj"))
}

/// The scene with the bunny read from the first existing path of `candidates`.
pub fn bunny_room_from(candidates: &[PathBuf]) -> Result<Scene, SceneError> {
    let Some(path) = candidates.iter().find(|p| p.is_file()) else {
        let tried: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
        return Err(SceneError::Invalid {
            message: format!("bunny-room needs the Stanford bunny; not found at: {}", tried.join(", ")),
        });
    };
    let bunny = crate::obj::load_obj(path)?;

    let mut s = Scene { name: "bunny-room".into(), camera: Some(Camera::cornell()), ..Scene::default() };
    s.materials = cornell_materials();
    for o in OBJECTS.iter().filter(|o| !o.name.ends_with("_block")) {
        // The floor's first quad is the floor; the others are the blocks' footprints.
        let quads = if o.name == "floor" { &o.quads[..1] } else { o.quads };
        s.add_mesh(quad_mesh(o.name, o.material, quads));
    }
    let mat = s.add_material(Material::diffuse("bunny", Rgb::new(0.8, 0.8, 0.8)));

    // Stand the bunny (y up in the file) on the floor's centre, turned 35 degrees so that its
    // head (towards -x in the file) faces the camera, BUNNY_HEIGHT tall.
    let b = bunny.bounds();
    let scale = BUNNY_HEIGHT / b.extent().y;
    let foot = Vec3::new(b.center().x, b.min.y, b.center().z);
    let to_origin = Affine3A::from_translation(-foot);
    let place = Affine3A::from_scale_rotation_translation(
        Vec3::splat(scale),
        Quat::from_rotation_y(-35f32.to_radians()),
        Vec3::new(278.0, 0.0, 290.0),
    );
    s.stats = bunny.stats.clone();
    for mut mesh in bunny.meshes {
        mesh.material_ids.iter_mut().for_each(|m| *m = mat);
        let id = s.meshes.len() as u32;
        s.meshes.push(mesh);
        s.instances.push(Instance { mesh: id, transform: place * to_origin, material_override: None });
    }
    Ok(s)
}
