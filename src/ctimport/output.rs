//! The `import-ct` output folder (CONTRACT §4): `meshes/*.obj`, `meshes/*_catalog/*.obj`,
//! `structures.json` (the scene.json `structures` entries) and `ct.json` (the report). Written
//! into a temporary sibling folder and renamed at the end, so a failure leaves nothing half-made
//! and an existing folder is replaced only with `--force`.

use super::{ImportOptions, ImportReport};
use crate::error::{Error, InputError};
use crate::geometry::Mesh;
use crate::geometry::mesh_io::write_obj;
use crate::scene::format::StructureEntry;
use std::path::{Path, PathBuf};

/// The path with links and `..` resolved where it exists, as given otherwise.
pub fn canonical(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf())
}

/// Refuses an output folder that exists and is not empty, unless `force` — and even then
/// refuses what replacing would destroy beyond an earlier output: the working folder or one
/// above it, a folder holding one of the `inputs`, a folder that is not an endofuse output
/// (no ct.json, structures.json or scene.json in it), a scene where `replaces` allows only
/// meshes, and a scene holding what the user made in it (seeds, a session, run results).
pub fn check_target(
    out: &Path,
    force: bool,
    inputs: &[&Path],
    replaces: Replaces,
) -> Result<(), Error> {
    if out.is_file() {
        return Err(InputError::new(out, "is a file; --out needs a folder").into());
    }
    let non_empty = std::fs::read_dir(out).is_ok_and(|mut d| d.next().is_some());
    if !non_empty {
        return Ok(());
    }
    if !force {
        return Err(InputError::new(
            out,
            "output folder exists and is not empty (choose another or pass --force to replace it)",
        )
        .into());
    }
    refuse_destroying(out, inputs, "--force will not replace it")?;
    let target = canonical(out);
    let earlier_output = ["ct.json", "structures.json", "scene.json"]
        .iter()
        .any(|f| target.join(f).is_file());
    if !earlier_output {
        return Err(InputError::new(
            out,
            "is not an earlier endofuse output (no ct.json or scene.json): --force replaces only those",
        )
        .into());
    }
    if replaces == Replaces::MeshesOnly && target.join("scene.json").is_file() {
        return Err(InputError::new(
            out,
            "holds a scene (scene.json): --force replaces only an earlier import-ct output (ct.json, structures.json, meshes/)",
        )
        .into());
    }
    // What the command wrote is all --force may take: anything else in the folder is the
    // user's (painted seeds, a session under any name, run results, frames or ground truth of a
    // scene written by hand). An import-ct --force over a scene folder wiped all of those.
    if let Some(other) = not_written_by(&target, replaces) {
        return Err(InputError::new(
            out,
            format!(
                "holds {other}: --force will not replace it (move it, or choose another folder)"
            ),
        )
        .into());
    }
    Ok(())
}

/// The first entry of `dir` that the command `replaces` names did not write, said for the
/// user; None when the folder holds only what it writes: ct.json, structures.json and meshes/
/// (import-ct), and for new-scene also scene.json and the frames it copied (the first part of
/// each camera's relative frame path).
fn not_written_by(dir: &Path, replaces: Replaces) -> Option<String> {
    let mut ours: Vec<String> = ["ct.json", "structures.json", "meshes"]
        .map(String::from)
        .to_vec();
    if replaces == Replaces::Scenes {
        ours.push("scene.json".into());
        let scene = std::fs::read_to_string(dir.join("scene.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
        let cameras = scene
            .as_ref()
            .and_then(|v| v.get("cameras"))
            .and_then(|c| c.as_array())
            .cloned()
            .unwrap_or_default();
        for cam in cameras {
            let frames = cam.get("frames");
            let path = frames
                .and_then(|f| f.as_str())
                .or_else(|| frames.and_then(|f| f.get("video")).and_then(|v| v.as_str()));
            if let Some(first) = path
                .map(Path::new)
                .filter(|p| p.is_relative())
                .and_then(|p| p.components().next())
            {
                ours.push(first.as_os_str().to_string_lossy().into_owned());
            }
        }
    }
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !ours.contains(n))
        .collect();
    names.sort();
    let first = names.first()?;
    Some(match first.as_str() {
        "seeds" => "painted seeds (seeds/)".to_string(),
        "gt" => "ground truth (gt/)".to_string(),
        n if n.ends_with(".endofuse.json") => format!("a saved session ({n})"),
        n => format!(
            "'{n}', which {} did not write",
            match replaces {
                Replaces::MeshesOnly => "import-ct",
                Replaces::Scenes => "new-scene",
            }
        ),
    })
}

/// What `--force` may replace besides an earlier import-ct output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replaces {
    /// `import-ct`: its own outputs only, never a scene folder.
    MeshesOnly,
    /// `new-scene`: also a scene it made earlier, while nothing the user made is in it.
    Scenes,
}

/// Refuses replacing `out` when that would destroy more than an output: when it is the
/// working folder or one above it, or holds one of the `inputs`. `consequence` ends the
/// message (what the command will not do).
pub fn refuse_destroying(out: &Path, inputs: &[&Path], consequence: &str) -> Result<(), Error> {
    let target = canonical(out);
    let here = std::env::current_dir()
        .and_then(std::fs::canonicalize)
        .unwrap_or_default();
    if here.starts_with(&target) {
        return Err(InputError::new(
            out,
            format!("is the working folder or one above it: {consequence}"),
        )
        .into());
    }
    for input in inputs {
        let input = canonical(input);
        if input.starts_with(&target) {
            return Err(InputError::new(
                out,
                format!("holds an input ({}): {consequence}", input.display()),
            )
            .into());
        }
    }
    Ok(())
}

/// A temporary folder next to `out`, renamed onto it by [`commit`].
pub fn staging(out: &Path) -> Result<PathBuf, Error> {
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_else(|| "out".into());
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|source| Error::Write {
        path: parent.to_path_buf(),
        source,
    })?;
    let tmp = parent.join(format!(".{name}.partial-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    remove_left_by_dead_runs(parent, &name);
    std::fs::create_dir_all(&tmp).map_err(|source| Error::Write {
        path: tmp.clone(),
        source,
    })?;
    Ok(tmp)
}

/// Removes `.NAME.partial-PID` folders (and their `.replaced` set-asides) beside `out` whose
/// process is gone: what a killed or crashed run left. Where the system cannot say whether a
/// process lives (no /proc), nothing is removed.
fn remove_left_by_dead_runs(parent: &Path, name: &str) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let prefix = format!(".{name}.partial-");
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    for e in entries.flatten() {
        let file = e.file_name();
        let Some(rest) = file.to_str().and_then(|f| f.strip_prefix(&prefix)) else {
            continue;
        };
        let pid = rest.strip_suffix(".replaced").unwrap_or(rest);
        let Ok(pid) = pid.parse::<u32>() else {
            continue;
        };
        let is_dir = e.file_type().is_ok_and(|t| t.is_dir());
        if is_dir && pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Moves the staged folder onto `out`. What was there is moved aside first and removed only
/// once the new folder is in place, so a failed rename loses nothing.
pub fn commit(tmp: &Path, out: &Path) -> Result<(), Error> {
    // Named after the staging folder, process id included: one left by a killed run does not
    // block the next.
    let aside = tmp.with_file_name(format!(
        "{}.replaced",
        tmp.file_name()
            .map_or_else(Default::default, |n| n.to_string_lossy())
    ));
    let had_old = out.exists();
    if had_old {
        std::fs::rename(out, &aside).map_err(|source| Error::Write {
            path: out.to_path_buf(),
            source,
        })?;
    }
    if let Err(source) = std::fs::rename(tmp, out) {
        if had_old {
            let _ = std::fs::rename(&aside, out);
        }
        return Err(Error::Write {
            path: out.to_path_buf(),
            source,
        });
    }
    if had_old {
        std::fs::remove_dir_all(&aside).map_err(|source| Error::Remove {
            path: aside,
            source,
        })?;
    }
    Ok(())
}

/// The scene.json entries of the imported structures, paths relative to the output folder.
pub fn structure_entries(report: &ImportReport) -> Vec<StructureEntry> {
    report
        .structures
        .iter()
        .map(|s| StructureEntry {
            name: s.name.clone(),
            label: s.label as i64,
            visible: s.visible,
            mesh: format!("meshes/{}.obj", s.name),
            catalog: Some(format!("meshes/{}_catalog", s.name)),
        })
        .collect()
}

/// Writes everything into a staging folder, then renames it onto `out`.
pub fn write(out: &Path, report: &ImportReport, options: &ImportOptions) -> Result<(), Error> {
    let tmp = staging(out)?;
    let result = write_into(&tmp, report, options);
    match result {
        Ok(()) => commit(&tmp, out),
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            Err(e)
        }
    }
}

/// Writes the meshes, catalogs, structures.json and ct.json into `dir` (which exists).
pub fn write_into(dir: &Path, report: &ImportReport, options: &ImportOptions) -> Result<(), Error> {
    let w = |path: PathBuf| move |source| Error::Write { path, source };
    let meshes_dir = dir.join("meshes");
    std::fs::create_dir_all(&meshes_dir).map_err(w(meshes_dir.clone()))?;
    let meshes: Vec<&Mesh> = report.structures.iter().map(|s| &s.mesh).collect();
    // One joint field per sample, applied to every structure: a hidden tumour moves with the
    // tissue around it (the same generator a scene without a catalog uses).
    let catalog = crate::shape::generate_catalog(
        &meshes,
        0,
        options.catalog_size,
        crate::shape::CATALOG_SEED,
    );
    for (s, samples) in report.structures.iter().zip(&catalog) {
        let path = meshes_dir.join(format!("{}.obj", s.name));
        write_obj(&path, &s.mesh).map_err(w(path.clone()))?;
        let cat_dir = meshes_dir.join(format!("{}_catalog", s.name));
        std::fs::create_dir_all(&cat_dir).map_err(w(cat_dir.clone()))?;
        for (k, vertices) in samples.iter().enumerate() {
            let p = cat_dir.join(format!("{k:03}.obj"));
            let m = Mesh::new(vertices.clone(), s.mesh.faces.clone());
            write_obj(&p, &m).map_err(w(p.clone()))?;
        }
    }
    let entries = structure_entries(report);
    let p = dir.join("structures.json");
    let text = serde_json::to_string_pretty(&entries).unwrap_or_default();
    std::fs::write(&p, text + "\n").map_err(w(p.clone()))?;
    let p = dir.join("ct.json");
    let text = serde_json::to_string_pretty(report).unwrap_or_default();
    std::fs::write(&p, text + "\n").map_err(w(p.clone()))?;
    Ok(())
}

/// One structure of a meshes folder (`import-ct`'s output, or meshes a user made).
#[derive(Debug, Clone)]
pub struct FolderStructure {
    pub entry: StructureEntry,
    pub mesh: Mesh,
    /// The mesh file and its catalog folder, if any, as found.
    pub mesh_path: PathBuf,
    pub catalog_path: Option<PathBuf>,
}

/// Reads a folder of structures: `DIR/structures.json` as `import-ct` writes it (paths relative
/// to DIR), else `kidney.obj` (or .stl/.ply), `tumour_exo*.obj` (visible) and `tumour_endo*.obj`
/// (hidden), in `DIR` or `DIR/meshes`, each with its `NAME_catalog/` folder when there is one.
pub fn read_structures_dir(dir: &Path) -> Result<Vec<FolderStructure>, InputError> {
    let listed = dir.join("structures.json");
    if listed.is_file() {
        let text = crate::error::read_text(&listed)
            .map_err(|e| InputError::new(&listed, format!("cannot read: {e}")))?;
        let entries: Vec<StructureEntry> = serde_json::from_str(&text)
            .map_err(|e| InputError::new(&listed, format!("malformed structures list: {e}")))?;
        if entries.is_empty() {
            return Err(InputError::new(&listed, "lists no structures"));
        }
        if let Some(e) = entries.iter().find(|e| !(1..=254).contains(&e.label)) {
            return Err(InputError::new(
                &listed,
                format!(
                    "'{}' has label {}: labels are 1–254 (0 is background, 255 background seeds)",
                    e.name, e.label
                ),
            ));
        }
        return entries
            .into_iter()
            .map(|entry| {
                let mesh_path = dir.join(&entry.mesh);
                let mesh = crate::geometry::mesh_io::load_mesh(&mesh_path)?;
                let catalog_path = entry.catalog.as_ref().map(|c| dir.join(c));
                Ok(FolderStructure {
                    entry,
                    mesh,
                    mesh_path,
                    catalog_path,
                })
            })
            .collect();
    }
    let base = if dir.join("meshes").is_dir() {
        dir.join("meshes")
    } else {
        dir.to_path_buf()
    };
    let files = std::fs::read_dir(&base)
        .map_err(|e| InputError::new(&base, format!("cannot read the meshes folder: {e}")))?;
    let mut found: Vec<(String, PathBuf)> = files
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter_map(|p| {
            let ext = p.extension()?.to_str()?.to_ascii_lowercase();
            let stem = p.file_stem()?.to_str()?.to_string();
            matches!(ext.as_str(), "obj" | "stl" | "ply").then_some((stem, p))
        })
        .filter(|(stem, _)| {
            stem == "kidney" || stem.starts_with("tumour_exo") || stem.starts_with("tumour_endo")
        })
        .collect();
    // Kidney first, then the visible tumours, then the hidden ones, each by name: labels 1, 2, 3
    // for kidney, tumour_exo and tumour_endo, as `synth` and CONTRACT's example number them
    // (by name alone tumour_endo came second, and synth's seeds were then refused).
    found.sort_by_key(|(stem, _)| {
        (
            stem != "kidney",
            !stem.starts_with("tumour_exo"),
            stem.clone(),
        )
    });
    if found.first().is_none_or(|(s, _)| s != "kidney") {
        return Err(InputError::new(
            &base,
            "no structures.json and no kidney.obj (expected kidney.obj, tumour_exo*.obj, tumour_endo*.obj)",
        ));
    }
    let mut out = Vec::new();
    if found.len() > 254 {
        return Err(InputError::new(&base, "more than 254 structures"));
    }
    for (label, (stem, path)) in (1u8..).zip(found) {
        let mesh = crate::geometry::mesh_io::load_mesh(&path)?;
        let cat = base.join(format!("{stem}_catalog"));
        let catalog_path = cat.is_dir().then_some(cat);
        let rel = |p: &Path| {
            p.strip_prefix(dir)
                .map(|r| r.to_string_lossy().to_string())
                .unwrap_or_else(|_| p.to_string_lossy().to_string())
        };
        out.push(FolderStructure {
            entry: StructureEntry {
                name: stem.clone(),
                label: label as i64,
                visible: !stem.starts_with("tumour_endo"),
                mesh: rel(&path),
                catalog: catalog_path.as_deref().map(rel),
            },
            mesh,
            mesh_path: path,
            catalog_path,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A meshes folder without structures.json is numbered kidney 1, visible tumours next,
    /// hidden ones last (as synth and CONTRACT's example: tumour_exo 2, tumour_endo 3), and
    /// only tumour_endo* are hidden.
    #[test]
    fn a_plain_meshes_folder_numbers_kidney_visible_then_hidden_tumours() {
        let dir =
            std::env::temp_dir().join(format!("endofuse-plain-meshes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mesh = crate::geometry::mesh::icosphere(1);
        for name in [
            "tumour_endo",
            "tumour_exo_2",
            "kidney",
            "tumour_exo",
            "notes",
        ] {
            crate::geometry::mesh_io::write_obj(&dir.join(format!("{name}.obj")), &mesh).unwrap();
        }
        let found = read_structures_dir(&dir).unwrap();
        let order: Vec<(&str, i64, bool)> = found
            .iter()
            .map(|s| (s.entry.name.as_str(), s.entry.label, s.entry.visible))
            .collect();
        assert_eq!(
            order,
            [
                ("kidney", 1, true),
                ("tumour_exo", 2, true),
                ("tumour_exo_2", 3, true),
                ("tumour_endo", 4, false),
            ]
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
