//! A private scratch folder per fuzzing process (in /dev/shm when it exists: a file per
//! execution on a disk would be the bottleneck), holding a copy of the hand-made fixture scene
//! so that a fuzzed scene.json can reach its meshes, seeds and frames.
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("scratch folder");
    for e in std::fs::read_dir(from).expect("fixture folder").flatten() {
        let target = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).expect("fixture copy");
        }
    }
}

/// The scratch folder, made once per process with the fixture scene inside.
pub fn dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = if Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let d = base.join(format!("endofuse-fuzz-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        let fixture =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/handmade_scene");
        copy_dir(&fixture, &d);
        d
    })
}

/// Writes `data` as `name` in the scratch folder and returns its path.
pub fn file(name: &str, data: &[u8]) -> PathBuf {
    let p = dir().join(name);
    std::fs::write(&p, data).expect("scratch write");
    p
}
