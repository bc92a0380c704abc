//! A results folder (`track --out`, `classify --out`, and `synth --out`'s phantom) written
//! whole or not at all.
//!
//! Outputs are written into a hidden staging folder beside `--out` and renamed onto it only
//! when every frame succeeded: a bad frame half-way, a full disk or a kill leaves `--out` as
//! it was (a `.NAME.partial-PID` folder may remain; its name says what it is), never a mix of
//! old and new frames. An existing `--out` is replaced only when it is empty or an earlier
//! `track`/`classify` result (it holds metrics.json; for `synth`, an earlier phantom), and never
//! when it holds the scene or the working folder: anything else in it is the user's, and is
//! refused.

use crate::ctimport::output::{commit, refuse_destroying, staging};
use crate::error::{Error, InputError};
use std::path::Path;

/// What an existing `--out` may hold and still be replaced whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Earlier {
    /// An earlier `track` or `classify` result: it holds metrics.json.
    Results,
    /// A phantom `synth` wrote: it holds scene.json and gt/trajectory.json.
    Phantom,
}

impl Earlier {
    fn found_in(self, out: &Path) -> bool {
        match self {
            Earlier::Results => out.join("metrics.json").is_file(),
            Earlier::Phantom => is_phantom(out),
        }
    }

    fn refusal(self) -> &'static str {
        match self {
            Earlier::Results => {
                "holds files that are not an earlier track or classify result (no metrics.json): choose an empty or new folder"
            }
            Earlier::Phantom => {
                "holds files that are not an earlier synth phantom (scene.json, gt/trajectory.json, meshes, seeds and the cameras' frames, nothing else): choose an empty or new folder"
            }
        }
    }
}

/// Does `dir` hold a phantom `synth` wrote and nothing else: scene.json, gt/trajectory.json,
/// and no top-level entry but those synth writes (its meshes, seeds, ground truth and the
/// cameras' frame folders)? A session, seeds or results saved into it make it the user's.
fn is_phantom(dir: &Path) -> bool {
    if !dir.join("gt/trajectory.json").is_file() {
        return false;
    }
    let Ok(text) = crate::error::read_text(&dir.join("scene.json")) else {
        return false;
    };
    let Ok(scene) = serde_json::from_str::<serde_json::Value>(&text) else {
        return false;
    };
    let mut allowed: Vec<String> = ["scene.json", "meshes", "gt", "seeds"]
        .map(String::from)
        .to_vec();
    if let Some(cameras) = scene["cameras"].as_array() {
        allowed.extend(
            cameras
                .iter()
                .filter_map(|c| c["name"].as_str().map(String::from)),
        );
    }
    std::fs::read_dir(dir).is_ok_and(|entries| {
        entries.flatten().all(|e| {
            e.file_name()
                .to_str()
                .is_some_and(|n| allowed.iter().any(|a| a == n))
        })
    })
}

/// Refuses an `out` that replacing would destroy more than an earlier result of.
pub fn check(out: &Path, inputs: &[&Path]) -> Result<(), Error> {
    check_for(out, inputs, Earlier::Results)
}

/// [`check`] for a folder that may hold an `earlier` output of another kind.
pub fn check_for(out: &Path, inputs: &[&Path], earlier: Earlier) -> Result<(), Error> {
    if out.exists() && !out.is_dir() {
        return Err(InputError::new(
            out,
            "is a file, not a folder: choose a folder for the results",
        )
        .into());
    }
    // Checked even for an empty folder: the commit renames `out` itself aside.
    if out.exists() {
        refuse_destroying(out, inputs, "results would replace it; choose a new folder")?;
    }
    let empty = std::fs::read_dir(out).map_or(true, |mut d| d.next().is_none());
    if !empty && !earlier.found_in(out) {
        return Err(InputError::new(out, earlier.refusal()).into());
    }
    Ok(())
}

/// Checks `out`, runs `write` into a staging folder and moves that onto `out` when it
/// succeeds; on failure the staging folder is removed and `out` is untouched.
pub fn write_whole<T>(
    out: &Path,
    inputs: &[&Path],
    write: impl FnOnce(&Path) -> Result<T, Error>,
) -> Result<T, Error> {
    write_whole_over(out, inputs, Earlier::Results, write)
}

/// [`write_whole`] over a folder that may hold an `earlier` output of another kind.
pub fn write_whole_over<T>(
    out: &Path,
    inputs: &[&Path],
    earlier: Earlier,
    write: impl FnOnce(&Path) -> Result<T, Error>,
) -> Result<T, Error> {
    // An empty folder a phantom goes into is written in place: renaming it would refuse the
    // working folder and mount points, and lose its permissions. On failure it is emptied.
    let empty = std::fs::read_dir(out).is_ok_and(|mut d| d.next().is_none());
    if earlier == Earlier::Phantom && out.is_dir() && empty {
        return write(out).inspect_err(|_| {
            if let Ok(entries) = std::fs::read_dir(out) {
                for e in entries.flatten() {
                    let p = e.path();
                    let _ = if p.is_dir() && !p.is_symlink() {
                        std::fs::remove_dir_all(&p)
                    } else {
                        std::fs::remove_file(&p)
                    };
                }
            }
        });
    }
    check_for(out, inputs, earlier)?;
    let tmp = staging(out)?;
    match write(&tmp) {
        Ok(v) => {
            commit(&tmp, out).inspect_err(|_| {
                let _ = std::fs::remove_dir_all(&tmp);
            })?;
            Ok(v)
        }
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            // Name the file as the user knows it: under --out, not the staging folder (gone).
            Err(match e {
                Error::Write { path, source } => Error::Write {
                    path: path
                        .strip_prefix(&tmp)
                        .map_or_else(|_| path.clone(), |rel| out.join(rel)),
                    source,
                },
                other => other,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("endofuse-results-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// What a killed run left beside `--out` (its process gone) is removed by the next run.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_killed_runs_staging_folder_is_removed_by_the_next() {
        let out = scratch("killed");
        let parent = out.parent().unwrap();
        let name = out.file_name().unwrap().to_string_lossy().to_string();
        // Above Linux's largest process id (2²²): no such process can exist.
        let left = parent.join(format!(".{name}.partial-999999999"));
        let aside = parent.join(format!(".{name}.partial-999999998.replaced"));
        for d in [&left, &aside] {
            std::fs::create_dir_all(d.join("masks")).unwrap();
        }
        write_whole(&out, &[], |tmp| {
            std::fs::write(tmp.join("metrics.json"), "{}").map_err(|source| Error::Write {
                path: tmp.to_path_buf(),
                source,
            })
        })
        .unwrap();
        assert!(
            !left.exists() && !aside.exists(),
            "left-overs of a dead run stayed"
        );
        let _ = std::fs::remove_dir_all(&out);
    }

    #[test]
    fn a_failed_run_leaves_the_earlier_result_and_no_staging_folder() {
        let out = scratch("earlier");
        std::fs::create_dir_all(out.join("masks")).unwrap();
        std::fs::write(out.join("metrics.json"), "{\"old\": true}").unwrap();
        std::fs::write(out.join("masks/000000.png"), "old").unwrap();
        let failed: Result<(), Error> = write_whole(&out, &[], |tmp| {
            std::fs::write(tmp.join("metrics.json"), "{\"new\": true}").unwrap();
            Err(crate::error::input_err("frame 3", "cannot decode"))
        });
        assert!(failed.is_err());
        assert_eq!(
            std::fs::read_to_string(out.join("metrics.json")).unwrap(),
            "{\"old\": true}"
        );
        assert!(out.join("masks/000000.png").is_file());
        let leftovers: Vec<_> = std::fs::read_dir(out.parent().unwrap())
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".partial-"))
            .filter(|e| e.file_name().to_string_lossy().contains("earlier"))
            .collect();
        assert!(leftovers.is_empty(), "staging folder left behind");
        // A run that succeeds replaces the whole folder: no old frame stays beside the new.
        write_whole(&out, &[], |tmp| {
            std::fs::write(tmp.join("metrics.json"), "{\"new\": true}").map_err(|source| {
                Error::Write {
                    path: tmp.to_path_buf(),
                    source,
                }
            })
        })
        .unwrap();
        assert_eq!(
            std::fs::read_to_string(out.join("metrics.json")).unwrap(),
            "{\"new\": true}"
        );
        assert!(
            !out.join("masks").exists(),
            "old frames mixed with new ones"
        );
        let _ = std::fs::remove_dir_all(&out);
    }

    #[test]
    fn a_folder_of_other_files_or_holding_the_scene_is_refused() {
        let out = scratch("user-files");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join("notes.txt"), "mine").unwrap();
        let e = check(&out, &[]).unwrap_err().to_string();
        assert!(e.contains("no metrics.json"), "{e}");
        std::fs::remove_file(out.join("notes.txt")).unwrap();
        check(&out, &[]).expect("an empty folder is fine");
        std::fs::create_dir_all(out.join("scene")).unwrap();
        std::fs::write(out.join("metrics.json"), "{}").unwrap();
        let e = check(&out, &[&out.join("scene")]).unwrap_err().to_string();
        assert!(e.contains("holds an input"), "{e}");
        let file = out.join("metrics.json");
        let e = check(&file, &[]).unwrap_err().to_string();
        assert!(e.contains("is a file"), "{e}");
        let _ = std::fs::remove_dir_all(&out);
    }
}
