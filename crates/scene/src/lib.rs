//! # filtrace-scene
//!
//! The scene description every renderer in filtrace consumes: triangle meshes placed by
//! instances (so that moving objects only change a transform), materials, lights and a
//! camera. Loaders turn OBJ/MTL, glTF 2.0, PLY and filtrace's TOML scene files into it;
//! `builtin` holds the scenes that need no file (the Cornell box is the default).
//!
//! The description is plain data: acceleration structures and integrators are built
//! from it, never stored in it.
//!
//! ```
//! let scene = filtrace_scene::load_scene("cornell").unwrap();
//! assert_eq!(scene.triangle_count(), 36);
//! ```

pub mod animation;
pub mod builtin;
pub mod dedup;
pub mod default_light;
pub mod error;
mod gltf_accessor;
pub mod gltf_anim;
pub mod gltf_load;
pub mod load;
mod mesh_file;
pub mod obj;
pub mod ply;
pub mod shapes;
pub mod texture;
pub mod toml_animation;
pub mod toml_scene;
pub mod types;
pub mod validate;

pub use builtin::{builtin, builtin_names};
pub use error::SceneError;
pub use load::{default_camera_for, load, load_scene, load_scene_with, load_with, LoadOptions};
pub use types::*;
