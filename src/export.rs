//! Writing what a user made in the app, as the command line would: the painted seeds as the
//! scene's label PNGs (CONTRACT §2), and tracked frames re-rendered and written through the
//! same recorder as `endofuse track` (CONTRACT §3), with overlay PNGs.

use crate::error::Error;
use crate::fit::Model;
use crate::fit::config::Mode;
use crate::fit::tracker::TrackedFrame;
use crate::scene::Scene;
use crate::scene::template::PathTemplate;
use crate::session::FrameResult;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where seed PNGs go in a scene folder whose scene.json names none.
pub const DEFAULT_SEEDS_TEMPLATE: &str = "seeds/{camera}/{frame:06}.png";

/// Where seed PNGs go in a folder of their own (a scene that lives in memory, like the demo).
pub const FOLDER_SEEDS_TEMPLATE: &str = "{camera}/{frame:06}.png";

fn template(source: &str) -> PathTemplate {
    PathTemplate::parse(source).expect("the built-in seed templates are valid")
}

/// Writes every painted view and frame as a label PNG at `dir`/`template`; returns how many.
pub fn write_seed_pngs(
    scene: &Scene,
    dir: &Path,
    template: &PathTemplate,
    seeds: &crate::scene::Seeds,
) -> Result<usize, Error> {
    let mut n = 0;
    for (c, frames) in seeds.by_camera.iter().enumerate() {
        for (&t, img) in frames {
            let path = dir.join(template.expand(t, &scene.cameras[c].name, ""));
            crate::scene::write::write_labels(&path, img)?;
            n += 1;
        }
    }
    Ok(n)
}

/// Writes seed PNGs into a picked folder, one subfolder per camera; returns how many.
pub fn write_seeds_into_folder(
    scene: &Scene,
    dir: &Path,
    seeds: &crate::scene::Seeds,
) -> Result<usize, Error> {
    write_seed_pngs(scene, dir, &template(FOLDER_SEEDS_TEMPLATE), seeds)
}

/// Writes seed PNGs into a scene folder; adds a `seeds` entry to its scene.json when it has
/// none. Returns how many files were written and where.
pub fn write_seeds_into_scene(
    scene: &Scene,
    root: &Path,
    seeds: &crate::scene::Seeds,
) -> Result<(usize, PathBuf), Error> {
    let template = scene
        .seeds_template
        .clone()
        .unwrap_or_else(|| template(DEFAULT_SEEDS_TEMPLATE));
    let n = write_seed_pngs(scene, root, &template, seeds)?;
    if scene.seeds_template.is_none() {
        let json = root.join("scene.json");
        let text = crate::error::read_text(&json).map_err(|source| Error::Write {
            path: json.clone(),
            source,
        })?;
        let mut v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| crate::error::input_err(json.display().to_string(), e.to_string()))?;
        if let Some(o) = v.as_object_mut() {
            o.insert("seeds".into(), template.source().into());
        }
        crate::scene::write::write_json_atomic(&json, &v)?;
    }
    Ok((n, root.to_path_buf()))
}

/// Re-renders tracked states and writes them as `endofuse track` does, plus overlay PNGs.
pub fn export_results(
    scene: &Scene,
    model: &Model,
    results: &[FrameResult],
    mode: Mode,
    dir: &Path,
    forest_train_s: f64,
    config: Option<crate::fit::config::ResolvedConfig>,
) -> Result<crate::track::TrackMetrics, Error> {
    let mut recorder = crate::track::Recorder::new(scene, dir, mode);
    recorder.overlays = true;
    recorder.config = config;
    for r in results {
        let rendered = crate::fit::tracker::render_state(scene, model, &r.state);
        let hidden_regions = r.hidden_regions(&rendered.centroids);
        let region_masks = crate::fit::tracker::region_masks(
            &crate::fit::tracker::cameras_of(scene, &r.state),
            &rendered.hidden,
            &hidden_regions,
        );
        recorder.record(&TrackedFrame {
            frame: r.frame,
            state: r.state.clone(),
            energy: r.energy,
            iterations: 0,
            ms: r.ms,
            confidence: r.confidence,
            lost: r.lost,
            depth_explains_zoom: r.depth_explains_zoom,
            refused: r
                .refused
                .iter()
                .filter_map(|w| crate::scene::trajectory::known_warning(w))
                .collect(),
            labels: rendered.labels,
            hidden: rendered.hidden,
            centroids: rendered.centroids,
            hidden_regions,
            region_masks,
        })?;
    }
    let metrics = recorder.finish(forest_train_s)?;
    let marker = dir.join(EXPORT_MARKER);
    std::fs::write(
        &marker,
        "written by endofuse File → Export; a later export may replace this folder\n",
    )
    .map_err(|source| Error::Write {
        path: marker,
        source,
    })?;
    Ok(metrics)
}

/// The file an export leaves in its folder, so that a later export may replace it and nothing
/// else.
pub const EXPORT_MARKER: &str = ".endofuse-export";

/// What an export folder holds now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFolder {
    /// Missing or empty: write.
    Fresh,
    /// An earlier export (its marker is there): replace it if the user says so.
    EarlierExport,
}

/// Refuses a folder that holds anything but an earlier export (a mis-click on /usr/bin must
/// not litter it).
pub fn check_export_folder(dir: &Path) -> Result<ExportFolder, crate::error::InputError> {
    if dir.is_file() {
        return Err(crate::error::InputError::new(
            dir,
            "is a file, not a folder",
        ));
    }
    // An export nested in an earlier one (a mis-click after the browser reopened there) would
    // mix with its files.
    if let Some(outer) = dir
        .ancestors()
        .skip(1)
        .find(|a| a.join(EXPORT_MARKER).is_file())
    {
        return Err(crate::error::InputError::new(
            dir,
            format!(
                "is inside the earlier export {}: choose a folder outside it (or that folder \
                 itself, to replace it)",
                outer.display()
            ),
        ));
    }
    let mut entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(_) => return Ok(ExportFolder::Fresh),
    };
    if entries.next().is_none() {
        return Ok(ExportFolder::Fresh);
    }
    if dir.join(EXPORT_MARKER).is_file() {
        return Ok(ExportFolder::EarlierExport);
    }
    Err(crate::error::InputError::new(
        dir,
        "is not empty and holds no earlier endofuse export: choose an empty or new folder",
    ))
}

/// An export the app hands the worker: everything it needs, owned.
#[derive(Debug, Clone)]
pub struct ExportJob {
    pub scene: Arc<Scene>,
    pub model: Arc<Model>,
    pub results: Vec<FrameResult>,
    pub mode: Mode,
    pub dir: PathBuf,
    pub forest_train_s: f64,
    /// The configuration the frames were fitted with (recorded in metrics.json).
    pub config: crate::fit::FitConfig,
}

impl ExportJob {
    pub fn run(&self) -> Result<crate::track::TrackMetrics, Error> {
        let fit_level = self
            .config
            .tracking
            .fit_level(self.scene.cameras.first().map_or(0, |c| c.width));
        let mut resolved = self.config.resolved(self.mode, fit_level);
        // The frames form one range when the tracked ones are consecutive.
        if let (Some(first), Some(last)) = (self.results.first(), self.results.last())
            && last.frame + 1 - first.frame == self.results.len()
        {
            resolved.frames = Some([first.frame, last.frame]);
        }
        export_results(
            &self.scene,
            &self.model,
            &self.results,
            self.mode,
            &self.dir,
            self.forest_train_s,
            Some(resolved),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_export_folder_must_be_empty_or_an_earlier_export() {
        let dir = std::env::temp_dir().join(format!("endofuse-export-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(check_export_folder(&dir), Ok(ExportFolder::Fresh));
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(check_export_folder(&dir), Ok(ExportFolder::Fresh));
        std::fs::write(dir.join("ls"), "a program").unwrap();
        let err = check_export_folder(&dir).unwrap_err();
        assert!(err.problem.contains("not empty"), "{err}");
        std::fs::write(dir.join(EXPORT_MARKER), "").unwrap();
        assert_eq!(check_export_folder(&dir), Ok(ExportFolder::EarlierExport));
        assert!(check_export_folder(&dir.join("ls")).is_err());
        // Not nested in an earlier export, new or not.
        let err = check_export_folder(&dir.join("again")).unwrap_err();
        assert!(err.problem.contains("inside the earlier export"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
