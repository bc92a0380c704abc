//! `new-scene` (CONTRACT §1): a scene folder from a patient's own files — a calibration file
//! (any format [`crate::calib`] reads), the anatomy (a CT label volume run through `import-ct`,
//! or a meshes folder), and the views (one video or image folder per camera, or one
//! side-by-side stereo video). Frames are referenced where they are unless asked to copy them.
//! Everything is checked before anything is written: the calibration's image size against the
//! videos, the views' frame counts, and finally the assembled scene opens as `info` would open
//! it. The folder is built under a temporary name and renamed at the end.

use crate::calib;
use crate::ctimport::{self, ImportOptions, output};
use crate::error::{Error, InputError};
use crate::geometry::Camera;
use crate::scene::format::{CameraEntry, FORMAT_V1, FramesEntry, SceneFile, StructureEntry};
use crate::scene::template::PathTemplate;
use crate::video;
use std::path::{Path, PathBuf};

/// Where the anatomy comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Anatomy {
    Ct {
        labels: PathBuf,
        options: ImportOptions,
    },
    Meshes(PathBuf),
}

/// Where the frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Views {
    /// One video file or image folder per camera: (camera name, file). Either every view names
    /// a camera of the calibration, or none does (empty names) and they follow its order.
    PerCamera(Vec<(String, PathBuf)>),
    /// One video whose left and right halves are the two cameras.
    SideBySide(PathBuf),
}

#[derive(Debug, Clone, PartialEq)]
pub struct NewSceneOptions {
    pub out: PathBuf,
    pub calib: PathBuf,
    pub anatomy: Anatomy,
    pub views: Views,
    /// Copy videos or frames into the scene instead of referring to them.
    pub copy_frames: bool,
    /// Use only the first frames (default: as many as every view has).
    pub frames: Option<usize>,
    pub force: bool,
}

/// What was made, for the message a user reads next.
#[derive(Debug, Clone)]
pub struct NewSceneReport {
    pub scene_json: PathBuf,
    pub cameras: Vec<String>,
    pub size: (u32, u32),
    pub frame_count: usize,
    pub fps: f64,
    pub structures: Vec<(String, bool)>,
    pub ct: Option<ctimport::ImportReport>,
    /// The views' frame counts when they differ (the scene takes the shortest).
    pub uneven_views: Option<String>,
    /// What the user should check though nothing was wrong (an odd-width side-by-side video).
    pub notes: Vec<String>,
}

impl NewSceneReport {
    /// What the user should check: views of different lengths, then the other notes.
    pub fn all_notes(&self) -> Vec<String> {
        let uneven = self.uneven_views.as_ref().map(|c| {
            format!(
                "the views have different frame counts ({c}); the scene uses the first {}",
                self.frame_count
            )
        });
        uneven
            .into_iter()
            .chain(self.notes.iter().cloned())
            .collect()
    }

    /// What the user does next.
    pub fn next_steps(&self) -> String {
        let uneven: String = self
            .all_notes()
            .iter()
            .map(|n| format!("\nnote: {n}"))
            .collect();
        let structures: Vec<String> = self
            .structures
            .iter()
            .map(|(n, v)| format!("{n}{}", if *v { "" } else { " (hidden)" }))
            .collect();
        format!(
            "new-scene: {} — {} cameras ({}) at {}×{}, {} frames at {:.2} fps; structures: {}\n\
             next: open it with `endofuse open {}`, paint background (key 1) and structure (2, 3, …) \
             strokes on the first frames (B brush, E eraser), train the forest (T), place the model \
             (Place automatically, or M and drag), then track (Ctrl+T); `endofuse track` places it \
             automatically{uneven}",
            self.scene_json.display(),
            self.cameras.len(),
            self.cameras.join(", "),
            self.size.0,
            self.size.1,
            self.frame_count,
            self.fps,
            structures.join(", "),
            shell_quoted(
                &self
                    .scene_json
                    .parent()
                    .unwrap_or(Path::new("."))
                    .display()
                    .to_string()
            )
        )
    }
}

/// A view as found: its frames entry (relative to the scene, or absolute), size, frame count.
struct View {
    /// The file or folder the user gave.
    source: PathBuf,
    frames: FramesEntry,
    size: (u32, u32),
    frame_count: usize,
    fps: Option<f64>,
    /// What to copy when `copy_frames`: (source, path inside the scene).
    copies: Vec<(PathBuf, String)>,
}

/// `text` as one word for a POSIX shell: as it is when it needs no quoting, else in single
/// quotes (a folder "dir with space" made the printed next step two arguments).
fn shell_quoted(text: &str) -> String {
    let plain = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_alphanumeric() || "/._-+:,@%=".contains(c));
    if plain {
        text.to_string()
    } else {
        format!("'{}'", text.replace('\'', "'\\''"))
    }
}

/// A video file: probed; with `copy`, it will be copied as `NAME.ext` in the scene.
fn video_view(path: &Path, name: &str, copy: bool) -> Result<View, InputError> {
    let info = video::probe(path).map_err(crate::scene::frames::video_input_error)?;
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_string())
        .unwrap_or_else(|| "mp4".into());
    let inside = format!("{name}.{ext}");
    // scene.json's frame paths are templates: a path's own braces are doubled.
    let (frames, copies) = if copy {
        (
            PathTemplate::escape(&inside),
            vec![(path.to_path_buf(), inside)],
        )
    } else {
        (
            PathTemplate::escape(&output::canonical(path).to_string_lossy()),
            Vec::new(),
        )
    };
    Ok(View {
        source: path.to_path_buf(),
        frames: FramesEntry::Path(frames),
        size: (info.width, info.height),
        frame_count: info.frame_count,
        fps: Some(info.fps),
        copies,
    })
}

/// A folder of numbered PNG/JPEG frames (`000000.png`, `frame_12.jpg`, …): one prefix, one
/// suffix, consecutive numbers. Referenced by a template when the numbers start at 0 with a
/// fixed width; copied (renumbered) otherwise or with `copy`.
fn folder_view(dir: &Path, name: &str, copy: bool) -> Result<View, InputError> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| InputError::new(dir, format!("cannot read the frames folder: {e}")))?;
    let mut numbered: Vec<(u64, String)> = Vec::new();
    let mut pattern: Option<(String, String, usize)> = None;
    for e in entries.filter_map(|e| e.ok()) {
        let file = e.file_name().to_string_lossy().to_string();
        let lower = file.to_ascii_lowercase();
        if !(lower.ends_with(".png") || lower.ends_with(".jpg") || lower.ends_with(".jpeg")) {
            continue;
        }
        let stem_end = file.rfind('.').unwrap_or(file.len());
        let stem = &file[..stem_end];
        let digits_start = stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let digits = &stem[digits_start..];
        let Ok(n) = digits.parse::<u64>() else {
            continue;
        };
        let key = (
            stem[..digits_start].to_string(),
            file[stem_end..].to_string(),
            digits.len(),
        );
        match &pattern {
            None => pattern = Some(key),
            Some(p) if p.0 != key.0 || p.1 != key.1 => {
                return Err(InputError::new(
                    dir,
                    format!(
                        "frames are named in two ways ('{}N{}' and '{}N{}'): one numbered sequence per folder",
                        p.0, p.1, key.0, key.1
                    ),
                ));
            }
            Some(p) if p.2 != key.2 => pattern = Some((p.0.clone(), p.1.clone(), 0)),
            _ => {}
        }
        numbered.push((n, file));
    }
    let Some((prefix, suffix, width)) = pattern else {
        return Err(InputError::new(
            dir,
            "no numbered PNG or JPEG frames in this folder",
        ));
    };
    numbered.sort();
    let first = numbered[0].0;
    if let Some(w) = numbered.windows(2).find(|w| w[1].0 != w[0].0 + 1) {
        return Err(InputError::new(
            dir,
            format!("frame numbers jump from {} to {}", w[0].0, w[1].0),
        ));
    }
    let first_path = dir.join(&numbered[0].1);
    let size = image::ImageReader::open(&first_path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| InputError::new(&first_path, format!("cannot read frame: {e}")))?
        .into_dimensions()
        .map_err(|e| InputError::new(&first_path, format!("not a readable image: {e}")))?;
    let ext = suffix.trim_start_matches('.').to_ascii_lowercase();
    let (frames, copies) = if copy || first != 0 || width == 0 {
        let copies = numbered
            .iter()
            .enumerate()
            .map(|(t, (_, f))| (dir.join(f), format!("{name}/{t:06}.{ext}")))
            .collect();
        (
            format!("{}/{{frame:06}}.{ext}", PathTemplate::escape(name)),
            copies,
        )
    } else {
        // The folder's and the names' own braces doubled: only the frame number is a
        // placeholder (a folder named `br{x}` was read as an unknown one).
        let template = format!(
            "{}{{frame:0{width}}}{}",
            PathTemplate::escape(&prefix),
            PathTemplate::escape(&suffix)
        );
        (
            PathTemplate::escape(&output::canonical(dir).to_string_lossy())
                + std::path::MAIN_SEPARATOR_STR
                + &template,
            Vec::new(),
        )
    };
    Ok(View {
        source: dir.to_path_buf(),
        frames: FramesEntry::Path(frames),
        size,
        frame_count: numbered.len(),
        fps: None,
        copies,
    })
}

fn view_of(path: &Path, name: &str, copy: bool) -> Result<View, InputError> {
    if path.is_dir() {
        folder_view(path, name, copy)
    } else if !path.exists() {
        Err(InputError::new(path, "no such video file or frames folder"))
    } else if video::is_video_path(path) {
        video_view(path, name, copy)
    } else {
        Err(InputError::new(
            path,
            "is neither a video (.mp4, .mov, .avi, .mkv, .m4v, .webm) nor a folder of frames",
        ))
    }
}

/// Builds the scene folder (see the module doc).
pub fn new_scene(
    options: &NewSceneOptions,
    progress: &dyn Fn(&str),
) -> Result<NewSceneReport, Error> {
    let mut inputs: Vec<&Path> = vec![&options.calib];
    inputs.push(match &options.anatomy {
        Anatomy::Ct { labels, .. } => labels,
        Anatomy::Meshes(dir) => dir,
    });
    let view_files = view_paths(&options.views);
    inputs.extend(view_files.iter().map(PathBuf::as_path));
    output::check_target(
        &options.out,
        options.force,
        &inputs,
        output::Replaces::Scenes,
    )?;
    let calibration = calib::read(&options.calib)?;
    progress("reading the views");
    let names: Vec<String> = calibration.cameras.iter().map(|c| c.name.clone()).collect();
    let mut notes = Vec::new();
    let views: Vec<(String, View)> = match &options.views {
        Views::SideBySide(path) => {
            if names.len() != 2 {
                return Err(InputError::new(
                    &options.calib,
                    format!(
                        "a side-by-side video needs a stereo calibration; this file has {} camera(s)",
                        names.len()
                    ),
                )
                .into());
            }
            let v = video_view(path, "stereo", options.copy_frames)?;
            if v.size.0 < 2 {
                return Err(InputError::new(
                    path,
                    format!(
                        "is {} px wide: a side-by-side video holds two views",
                        v.size.0
                    ),
                )
                .into());
            }
            let (l, r) = video::Crop::side_by_side(v.size.0, v.size.1);
            if v.size.0 % 2 == 1 {
                notes.push(format!(
                    "{} is {} px wide, an odd width: the views are x 0–{} and {}–{}, the middle column left out of both; check that the right view starts where the recording's does (a column off is a pixel of disparity)",
                    path.display(),
                    v.size.0,
                    l.width - 1,
                    r.x,
                    r.x + r.width - 1
                ));
            }
            // The object form's `video` is a plain path, not a template.
            let video = match &v.frames {
                FramesEntry::Path(p) => PathTemplate::parse(p)
                    .ok()
                    .and_then(|t| t.literal())
                    .unwrap_or_else(|| p.clone()),
                FramesEntry::Video { video, .. } => video.clone(),
            };
            let half = |c: video::Crop| View {
                source: path.clone(),
                frames: FramesEntry::Video {
                    video: video.clone(),
                    crop: Some([c.x as i64, c.y as i64, c.width as i64, c.height as i64]),
                },
                size: (c.width, c.height),
                frame_count: v.frame_count,
                fps: v.fps,
                copies: Vec::new(),
            };
            let (mut left, right) = (half(l), half(r));
            left.copies = v.copies;
            vec![(names[0].clone(), left), (names[1].clone(), right)]
        }
        Views::PerCamera(list) => {
            if list.len() != names.len() {
                return Err(InputError::new(
                    &options.calib,
                    format!(
                        "the calibration has {} camera(s) ({}) but {} view(s) were given",
                        names.len(),
                        names.join(", "),
                        list.len()
                    ),
                )
                .into());
            }
            // Each view names a camera of the calibration, once; or no view is named and
            // they follow the calibration's order.
            let unnamed = list.iter().all(|(n, _)| n.is_empty());
            let mut out: Vec<(String, View)> = Vec::new();
            for (i, (given, path)) in list.iter().enumerate() {
                let given = if unnamed { &names[i] } else { given };
                if !names.contains(given) {
                    return Err(InputError::new(
                        "--view",
                        format!(
                            "'{given}' is not a camera of {} (its cameras: {})",
                            options.calib.display(),
                            names.join(", ")
                        ),
                    )
                    .into());
                }
                if out.iter().any(|(n, _)| n == given) {
                    return Err(InputError::new(
                        "--view",
                        format!("camera '{given}' is given twice"),
                    )
                    .into());
                }
                out.push((given.clone(), view_of(path, given, options.copy_frames)?));
            }
            out.sort_by_key(|(n, _)| names.iter().position(|m| m == n));
            out
        }
    };
    let size = views[0].1.size;
    for (name, v) in &views {
        if v.size != size {
            return Err(InputError::new(
                &v.source,
                format!(
                    "camera '{name}' frames are {}×{} but camera '{}' frames are {}×{}",
                    v.size.0, v.size.1, views[0].0, size.0, size.1
                ),
            )
            .into());
        }
    }
    let cameras = calibration.cameras(size.0, size.1).map_err(|e| {
        InputError::new(
            &options.calib,
            format!("{e} (the views are {}×{})", size.0, size.1),
        )
    })?;
    let available = views.iter().map(|(_, v)| v.frame_count).min().unwrap_or(0);
    let frame_count = match options.frames {
        Some(n) if n > available => {
            let (name, _) = views
                .iter()
                .min_by_key(|(_, v)| v.frame_count)
                .expect("views are not empty");
            return Err(InputError::new(
                "--frames",
                format!("{n} frames asked for but camera '{name}' has only {available}"),
            )
            .into());
        }
        Some(0) => return Err(InputError::new("--frames", "must be at least 1").into()),
        Some(n) => n,
        None => available,
    };
    let rates: Vec<(&str, &View, f64)> = views
        .iter()
        .filter_map(|(n, v)| Some((n.as_str(), v, v.fps?)))
        .collect();
    if let Some((n0, _, r0)) = rates.first()
        && let Some((n, v, r)) = rates.iter().find(|(_, _, r)| (r / r0 - 1.0).abs() > 0.01)
    {
        return Err(InputError::new(
            &v.source,
            format!("camera '{n}' runs at {r:.3} fps but camera '{n0}' at {r0:.3} fps: the views would drift apart"),
        )
        .into());
    }
    let fps = rates.first().map(|r| r.2).unwrap_or(30.0);
    let counts: Vec<String> = views
        .iter()
        .map(|(n, v)| format!("{n} {}", v.frame_count))
        .collect();
    let uneven = views.iter().any(|(_, v)| v.frame_count != available);

    let tmp = output::staging(&options.out)?;
    let result = assemble(&tmp, options, &cameras, &views, frame_count, fps, progress);
    let (structures, ct) = match result {
        Ok(r) => r,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            return Err(e);
        }
    };
    output::commit(&tmp, &options.out)?;
    Ok(NewSceneReport {
        scene_json: options.out.join("scene.json"),
        cameras: cameras.iter().map(|c| c.name.clone()).collect(),
        size,
        frame_count,
        fps,
        structures,
        ct,
        uneven_views: uneven.then(|| counts.join(", ")),
        notes,
    })
}

fn view_paths(views: &Views) -> Vec<PathBuf> {
    match views {
        Views::SideBySide(p) => vec![p.clone(), p.clone()],
        Views::PerCamera(list) => list.iter().map(|(_, p)| p.clone()).collect(),
    }
}

type Assembled = (Vec<(String, bool)>, Option<ctimport::ImportReport>);

fn assemble(
    dir: &Path,
    options: &NewSceneOptions,
    cameras: &[Camera],
    views: &[(String, View)],
    frame_count: usize,
    fps: f64,
    progress: &dyn Fn(&str),
) -> Result<Assembled, Error> {
    let write_err = |path: &Path| {
        let path = path.to_path_buf();
        move |source| Error::Write { path, source }
    };
    // The anatomy.
    let (entries, ct): (Vec<StructureEntry>, _) = match &options.anatomy {
        Anatomy::Ct { labels, options: o } => {
            let report = ctimport::read_and_build(labels, o, progress)?;
            progress("writing meshes and the deformation catalog");
            output::write_into(dir, &report, o)?;
            (output::structure_entries(&report), Some(report))
        }
        Anatomy::Meshes(src) => {
            let found = output::read_structures_dir(src)?;
            let meshes = dir.join("meshes");
            std::fs::create_dir_all(&meshes).map_err(write_err(&meshes))?;
            let mut entries = Vec::new();
            for s in &found {
                let ext = s
                    .mesh_path
                    .extension()
                    .map(|e| e.to_string_lossy().to_string())
                    .unwrap_or_else(|| "obj".into());
                let rel = format!("meshes/{}.{ext}", s.entry.name);
                std::fs::copy(&s.mesh_path, dir.join(&rel)).map_err(write_err(&dir.join(&rel)))?;
                let catalog = match &s.catalog_path {
                    Some(c) => {
                        let rel = format!("meshes/{}_catalog", s.entry.name);
                        copy_dir(c, &dir.join(&rel))?;
                        Some(rel)
                    }
                    None => None,
                };
                entries.push(StructureEntry {
                    mesh: rel,
                    catalog,
                    ..s.entry.clone()
                });
            }
            (entries, None)
        }
    };
    // The frames.
    for (_, v) in views {
        for (from, to) in &v.copies {
            let target = dir.join(to);
            if let Some(parent) = target.parent() {
                std::fs::create_dir_all(parent).map_err(write_err(parent))?;
            }
            std::fs::copy(from, &target).map_err(write_err(&target))?;
        }
    }
    let file = SceneFile {
        format: FORMAT_V1.into(),
        fps,
        frame_count: frame_count as i64,
        cameras: cameras
            .iter()
            .zip(views)
            .map(|(c, (_, v))| CameraEntry::from_camera(c, v.frames.clone()))
            .collect(),
        structures: entries.clone(),
        // No guessed pose: `track` and the app place the model from the images (a pose guessed
        // without them was polished into a wrong fit that nothing flagged).
        initial_pose: None,
        seeds: Some("seeds/{camera}/{frame:06}.png".into()),
        ground_truth: None,
        zoom_changes: Vec::new(),
        k1_vs_focal: None,
    };
    let json = dir.join("scene.json");
    let text = serde_json::to_string_pretty(&file).unwrap_or_default();
    std::fs::write(&json, text + "\n").map_err(write_err(&json))?;
    // The scene must open as `info` would open it (frames, meshes, catalogs).
    progress("checking the scene");
    let scene = crate::scene::Scene::open(dir)?;
    crate::fit::Model::build(&scene)?;
    Ok((
        entries
            .iter()
            .map(|e| (e.name.clone(), e.visible))
            .collect(),
        ct,
    ))
}

fn copy_dir(from: &Path, to: &Path) -> Result<(), Error> {
    let err = |path: &Path| {
        let path = path.to_path_buf();
        move |source| Error::Write { path, source }
    };
    std::fs::create_dir_all(to).map_err(err(to))?;
    let entries = std::fs::read_dir(from)
        .map_err(|e| InputError::new(from, format!("cannot read catalog folder: {e}")))?;
    for e in entries.filter_map(|e| e.ok()) {
        let p = e.path();
        if p.is_file() {
            let target = to.join(e.file_name());
            std::fs::copy(&p, &target).map_err(err(&target))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::shell_quoted;

    /// The printed next step is one shell word whatever the folder's name.
    #[test]
    fn paths_are_quoted_for_the_shell_when_they_need_it() {
        assert_eq!(shell_quoted("/tmp/case-3/scene_a"), "/tmp/case-3/scene_a");
        assert_eq!(shell_quoted("/tmp/dir with space"), "'/tmp/dir with space'");
        assert_eq!(shell_quoted("/tmp/it's"), "'/tmp/it'\\''s'");
        assert_eq!(shell_quoted("/tmp/$HOME`x`"), "'/tmp/$HOME`x`'");
        assert_eq!(shell_quoted(""), "''");
    }
}
