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
//! Animated (a [`crate::animation::SceneAnimation`]; frame 0 is the rest pose):
//!
//! | name | what | frames | triangles |
//! |---|---|---|---:|
//! | `cornell-anim` | the Cornell box, its light circling the ceiling, the camera dollying in and panning | 0..=48 at 24/s | 36 |
//! | `classroom` | rows of desks and chairs on thin legs, two point lights moving among them, a walking camera | 0..=48 at 24/s | 38,142 |
//! | `colonnade-flight` | a camera flight through `colonnade`, between its pillars | 0..=96 at 24/s | 696 |
//!
//! All built-in scenes are deterministic: the same name gives the same scene, bit for bit.

mod bunny_room;
mod classroom;
mod colonnade;
mod colonnade_flight;
mod cornell;
mod cornell_anim;
mod furniture;
mod grass;
mod rng;

pub use bunny_room::{bunny_room, bunny_room_from, shared_candidates};
pub use classroom::{classroom, DESK_COLUMNS, DESK_ROWS};
pub use colonnade::colonnade;
pub use colonnade_flight::colonnade_flight;
pub use cornell::{
    cornell, cornell_materials, LIGHT_RADIANCE, LIGHT_Y, MAT_BLUE, MAT_GREEN, MAT_LIGHT, MAT_RED, MAT_WHITE,
};
pub use cornell_anim::cornell_anim;
pub use grass::{grass, grass_with, GrassParams};

use crate::error::SceneError;
use crate::types::Scene;

/// Names accepted by [`builtin`], the default first.
pub fn builtin_names() -> &'static [&'static str] {
    &["cornell", "colonnade", "grass", "bunny-room", "cornell-anim", "classroom", "colonnade-flight"]
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
        "cornell-anim" => Some(Ok(cornell_anim())),
        "classroom" => Some(Ok(classroom())),
        "colonnade-flight" => Some(Ok(colonnade_flight())),
        _ => None,
    }
}
