//! Inputs the fuzzers (fuzz/, issue 17) found a crash, hang or runaway allocation with, kept as
//! regression tests: each must now give an answer (a mesh or an error), promptly. A file's name
//! says which target found it and what it does; `fuzz/run.sh` reads the same folder as seeds.

use std::path::Path;

fn regressions(prefix: &str) -> Vec<(String, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/fuzz_regressions");
    let mut found: Vec<(String, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.starts_with(prefix))
        .map(|n| {
            let bytes = std::fs::read(dir.join(&n)).unwrap();
            (n, bytes)
        })
        .collect();
    found.sort();
    found
}

#[test]
fn ply_inputs_the_fuzzer_found_are_answered() {
    let cases = regressions("mesh_ply-");
    assert!(
        !cases.is_empty(),
        "the PLY regressions are in tests/fixtures/fuzz_regressions"
    );
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/fuzz_regressions");
    for (name, bytes) in cases {
        // Was a hang: an element with no properties claiming 7·10¹¹ entries. The parser now
        // answers (here an empty mesh), and loading it as a scene would is a named error.
        let _ = endofuse::geometry::mesh_io::parse_ply(&bytes);
        let loaded = endofuse::geometry::mesh_io::load_mesh(&dir.join(&name));
        assert!(loaded.is_err(), "{name}: {loaded:?}");
    }
}
