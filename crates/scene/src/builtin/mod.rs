//! Built-in scenes: no file needed (except `bunny-room`, which reads the Stanford bunny).
//! `cornell` is the default of every command.
//!
//! | name | what | triangles |
//! |---|---|---:|
//! | `cornell` | the original Cornell box data with its ceiling light (see [`cornell`]) | 36 |
//! | `colonnade` | a hall of thin pillars and beams lit by a low window light: long thin shadows | 696 |
//! | `grass` | 16,000 thin curved blades on a meadow, area light + sky: sub-pixel geometry | 81,924 |
//! | `bunny-room` | the Stanford bunny in the Cornell room (needs `../shared/scenes/bunny/bunny.obj`) | ~56,000 |
//!
//! All built-in scenes are deterministic: the same name gives the same scene, bit for bit.

mod bunny_room;
mod colonnade;
mod cornell;
mod grass;
mod rng;

pub use bunny_room::{bunny_room, bunny_room_from, shared_candidates};
pub use colonnade::colonnade;
pub use cornell::{
    cornell, cornell_materials, LIGHT_RADIANCE, LIGHT_Y, MAT_BLUE, MAT_GREEN, MAT_LIGHT, MAT_RED, MAT_WHITE,
};
pub use grass::{grass, grass_with, GrassParams};

use crate::error::SceneError;
use crate::types::Scene;

/// Names accepted by [`builtin`], the default first.
pub fn builtin_names() -> &'static [&'static str] {
    &["cornell", "colonnade", "grass", "bunny-room"]
}

/// The built-in scene `name`, or `None` if there is none of that name or it cannot be built
/// (use [`try_builtin`] to learn why: `bunny-room` needs a file).
pub fn builtin(name: &str) -> Option<Scene> {
    try_builtin(name).and_then(Result::ok)
}

/// `None` for an unknown name; `Some(Err(..))` when the scene needs a file that is missing.
pub fn try_builtin(name: &str) -> Option<Result<Scene, SceneError>> {
    match name {
        "cornell" => Some(Ok(cornell())),
        "colonnade" => Some(Ok(colonnade())),
        "grass" => Some(Ok(grass())),
        "bunny-room" => Some(bunny_room()),
        _ => None,
    }
}
