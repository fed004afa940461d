//! Built-in scenes: no file needed. `cornell` is the default of every command.
//!
//! | name | what | triangles |
//! |---|---|---:|
//! | `cornell` | the original Cornell box data with its ceiling light (see [`cornell`]) | 36 |
//!
//! All built-in scenes are deterministic: the same name gives the same scene, bit for bit.

mod cornell;

pub use cornell::{
    cornell, cornell_materials, LIGHT_RADIANCE, LIGHT_Y, MAT_BLUE, MAT_GREEN, MAT_LIGHT, MAT_RED, MAT_WHITE,
};

use crate::error::SceneError;
use crate::types::Scene;

/// Names accepted by [`builtin`], the default first.
pub fn builtin_names() -> &'static [&'static str] {
    &["cornell"]
}

/// The built-in scene `name`, or `None` if there is none of that name or it cannot be built
/// (use [`try_builtin`] to learn why).
pub fn builtin(name: &str) -> Option<Scene> {
    try_builtin(name).and_then(Result::ok)
}

/// `None` for an unknown name; `Some(Err(..))` when the scene needs a file that is missing.
pub fn try_builtin(name: &str) -> Option<Result<Scene, SceneError>> {
    match name {
        "cornell" => Some(Ok(cornell())),
        _ => None,
    }
}
