//! The SCENE argument of every command and of the app (CONTRACT §1): a scene folder, its
//! scene.json, or the word `demo` for the built-in phantom. The one place that knows both the
//! scene reader and the phantom generator, so that neither needs the other.

use crate::error::InputError;
use crate::scene::Scene;
use std::path::Path;

/// The word that names the built-in demo scene.
pub const DEMO: &str = "demo";

/// Opens `spec`: the built-in demo, or a scene folder or scene.json (frame headers checked).
pub fn scene(spec: &str) -> Result<Scene, InputError> {
    if spec == DEMO {
        // The word wins (CONTRACT §1); a folder of that name here is said, not opened silently.
        if Path::new(DEMO).exists() {
            log::warn!(
                "'demo' opens the built-in demo scene; to open the folder named demo here, give ./demo"
            );
        }
        crate::synth::demo_scene()
    } else {
        Scene::open(Path::new(spec))
    }
}
