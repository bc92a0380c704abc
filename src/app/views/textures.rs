//! Textures of what the views show — the frames (decoded on the loader thread), the seeds,
//! the probability or uncertainty maps, and the CPU overlay — re-uploaded only when what they
//! show changes.

use super::Screen;
use crate::app::state::Layer;
use crate::app::{EndofuseApp, Shown};
use crate::appearance::hint::StrokeHint;
use crate::scene::SEED_NONE;
use egui::{ColorImage, TextureHandle, TextureOptions};

/// A view's region texture and the (frame, document edits, opacity bits, shown styles) it
/// was drawn for.
type CachedRegion = ((usize, u64, u32, u64), Option<TextureHandle>);

/// A view's stroke hint and the (frame, seed revision) it was found for.
type CachedHint = ((usize, u64), Option<StrokeHint>);

/// The textures and what each shows.
#[derive(Default)]
pub struct Textures {
    frames: Vec<Option<((usize, usize), TextureHandle)>>,
    /// Frame asked of the loader per camera, not yet arrived.
    requested: Vec<Option<usize>>,
    seeds: Vec<Option<((usize, u64), TextureHandle)>>,
    probability: Vec<Option<TextureHandle>>,
    pub probability_key: Option<(usize, Layer)>,
    pub(super) overlay_cpu: Vec<Option<(usize, TextureHandle)>>,
    /// Per camera: the hidden structures' regions for (frame, document edits, opacity).
    region: Vec<Option<CachedRegion>>,
    /// Per camera: where the next stroke helps most, for (frame, seed revision).
    hints: Vec<Option<CachedHint>>,
}

impl Textures {
    /// The fitted overlays changed (the model was moved by hand).
    pub fn forget_overlays(&mut self) {
        self.overlay_cpu.clear();
        self.region.clear();
    }
}

pub(super) fn slot<T>(v: &mut Vec<Option<T>>, i: usize) -> &mut Option<T> {
    if v.len() <= i {
        v.resize_with(i + 1, || None);
    }
    &mut v[i]
}

/// An RGBA (unmultiplied) texture of `size` pixels.
pub(super) fn rgba_texture(
    ctx: &egui::Context,
    name: String,
    size: [usize; 2],
    rgba: &[u8],
    options: TextureOptions,
) -> TextureHandle {
    ctx.load_texture(
        name,
        ColorImage::from_rgba_unmultiplied(size, rgba),
        options,
    )
}

/// The current frame's texture of camera `c`; while a new frame decodes on the loader
/// thread, the last one shown stays up.
pub(super) fn frame_texture(shown: &Shown, screen: &mut Screen, c: usize) -> Option<TextureHandle> {
    let scene = shown.doc.scene.clone()?;
    let frame = shown.view.frame;
    let current = slot(&mut screen.textures.frames, c).clone();
    if current.as_ref().is_none_or(|(k, _)| *k != (c, frame))
        && *slot(&mut screen.textures.requested, c) != Some(frame)
    {
        screen.loader.request(&scene, c, frame);
        *slot(&mut screen.textures.requested, c) = Some(frame);
    }
    current.map(|(_, t)| t)
}

pub(super) fn seeds_texture(
    shown: &Shown,
    screen: &mut Screen,
    ctx: &egui::Context,
    c: usize,
) -> Option<TextureHandle> {
    let (doc, frame) = (shown.doc, shown.view.frame);
    let key = (frame, doc.editor.revision);
    if let Some((k, tex)) = slot(&mut screen.textures.seeds, c)
        && *k == key
    {
        return Some(tex.clone());
    }
    let layer = doc.editor.layer(c, frame)?;
    let classes = doc.classes.as_ref()?;
    let colours: Vec<(u8, [u8; 3])> = (0..classes.len())
        .map(|k| (doc.seed_value(k), doc.class_colour(k)))
        .collect();
    let mut rgba = vec![0u8; layer.data.len() * 4];
    for (px, &v) in rgba.chunks_exact_mut(4).zip(&layer.data) {
        if v == SEED_NONE {
            continue;
        }
        if let Some((_, c)) = colours.iter().find(|(s, _)| *s == v) {
            px.copy_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    let tex = rgba_texture(
        ctx,
        format!("seeds-{c}"),
        [layer.width, layer.height],
        &rgba,
        TextureOptions::NEAREST,
    );
    *slot(&mut screen.textures.seeds, c) = Some((key, tex.clone()));
    Some(tex)
}

/// The hidden structures' 95 % regions of camera `c` at the current frame (a halo fading out
/// from each fitted outline, dashed at the region's edge), recomputed when the frame, the
/// fits or the opacity change. None where the frame has no fit with regions.
pub(super) fn region_texture(
    shown: &Shown,
    screen: &mut Screen,
    ctx: &egui::Context,
    c: usize,
) -> Option<TextureHandle> {
    let (doc, frame) = (shown.doc, shown.view.frame);
    let styles_shown = shown
        .view
        .styles
        .iter()
        .enumerate()
        .fold(0u64, |m, (i, s)| m | ((s.shown as u64) << (i % 64)));
    let key = (
        frame,
        doc.edits,
        shown.prefs.hidden_region_opacity.to_bits(),
        styles_shown,
    );
    if let Some((k, tex)) = slot(&mut screen.textures.region, c)
        && *k == key
    {
        return tex.clone();
    }
    let tex = region_rgba(shown, c, frame).map(|(size, rgba)| {
        rgba_texture(
            ctx,
            format!("region-{c}"),
            size,
            &rgba,
            TextureOptions::LINEAR,
        )
    });
    *slot(&mut screen.textures.region, c) = Some((key, tex.clone()));
    tex
}

/// The RGBA picture of [`region_texture`].
fn region_rgba(shown: &Shown, c: usize, frame: usize) -> Option<([usize; 2], Vec<u8>)> {
    let doc = shown.doc;
    let (scene, model) = (doc.scene.as_ref()?, doc.model.as_ref()?);
    let result = doc.results.get(&frame)?;
    if result.hidden_region.is_empty() {
        return None;
    }
    let rendered = crate::fit::tracker::render_state(scene, model, &result.state);
    let regions = result.hidden_regions(&rendered.centroids);
    let cams = crate::fit::tracker::cameras_of(scene, &result.state);
    let masks = crate::fit::tracker::region_masks(&cams, &rendered.hidden, &regions);
    let cam = scene.cameras.get(c)?;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut rgba = vec![0u8; w * h * 4];
    for (name, region) in &masks {
        let index = scene.structures.iter().position(|s| &s.name == name);
        let hidden = rendered.hidden.iter().find(|(n, _)| n == name);
        let (Some(index), Some((_, hidden))) = (index, hidden) else {
            continue;
        };
        // A structure the user hid keeps its region hidden too.
        let shown_structure = shown.view.styles.get(index).is_none_or(|s| s.shown);
        let (true, Some(region), Some(hidden)) = (shown_structure, region.get(c), hidden.get(c))
        else {
            continue;
        };
        let colour = crate::overlay::structure_colour(index);
        let alpha = crate::overlay::region_alpha(hidden, region, shown.prefs.hidden_region_opacity);
        for (px, a) in rgba.chunks_exact_mut(4).zip(alpha) {
            let a = (a.clamp(0.0, 1.0) * 255.0) as u8;
            if a > px[3] {
                px.copy_from_slice(&[colour[0], colour[1], colour[2], a]);
            }
        }
    }
    Some(([w, h], rgba))
}

/// In the uncertainty view: the unpainted patch where the forest hesitates most (recomputed
/// when the frame, the maps or the strokes change).
pub(super) fn stroke_hint(shown: &Shown, screen: &mut Screen, c: usize) -> Option<StrokeHint> {
    let frame = shown.view.frame;
    if shown.view.layer != Layer::Uncertainty {
        return None;
    }
    let maps = shown.jobs.probabilities.get(&frame)?;
    let key = (frame, shown.doc.editor.revision);
    if let Some((k, hint)) = slot(&mut screen.textures.hints, c)
        && *k == key
    {
        return *hint;
    }
    let m = maps.get(c)?;
    let hint =
        crate::appearance::hint::next_stroke(&m.uncertainty(), shown.doc.editor.layer(c, frame));
    *slot(&mut screen.textures.hints, c) = Some((key, hint));
    hint
}

/// Probability of the chosen class (in its colour) or uncertainty (dark → bright orange).
pub(super) fn probability_texture(
    shown: &Shown,
    screen: &mut Screen,
    ctx: &egui::Context,
    c: usize,
) -> Option<TextureHandle> {
    let (layer, frame) = (shown.view.layer, shown.view.frame);
    if layer == Layer::Image {
        return None;
    }
    let maps = shown.jobs.probabilities.get(&frame)?;
    let key = (frame, layer);
    let textures = &mut screen.textures;
    if textures.probability_key != Some(key) {
        textures.probability.clear();
        textures.hints.clear();
        textures.probability_key = Some(key);
    }
    if let Some(tex) = slot(&mut textures.probability, c) {
        return Some(tex.clone());
    }
    let m = maps.get(c)?;
    let rgba: Vec<u8> = match layer {
        Layer::Probability(k) => {
            let col = shown.doc.class_colour(k);
            m.class_plane(k.min(m.classes - 1))
                .data
                .iter()
                .flat_map(|&p| super::scale::probability_rgba(col, p))
                .collect()
        }
        _ => m
            .uncertainty()
            .data
            .iter()
            .flat_map(|&u| super::scale::uncertainty_rgba(u))
            .collect(),
    };
    let tex = rgba_texture(
        ctx,
        format!("prob-{c}"),
        [m.width, m.height],
        &rgba,
        TextureOptions::LINEAR,
    );
    *slot(&mut textures.probability, c) = Some(tex.clone());
    Some(tex)
}

impl EndofuseApp {
    /// Uploads frames the loader finished (those still wanted); a frame that cannot be read
    /// stops playing and says why.
    pub(crate) fn receive_frames(&mut self, ctx: &egui::Context) {
        for l in self.screen.loader.drain() {
            let textures = &mut self.screen.textures;
            if *slot(&mut textures.requested, l.camera) == Some(l.frame) {
                *slot(&mut textures.requested, l.camera) = None;
            }
            if l.frame != self.view.frame {
                continue;
            }
            match l.image {
                Ok(img) => {
                    let image = ColorImage::from_rgb(
                        [img.width() as usize, img.height() as usize],
                        img.as_raw(),
                    );
                    let tex = ctx.load_texture(
                        format!("frame-{}", l.camera),
                        image,
                        TextureOptions::LINEAR,
                    );
                    *slot(&mut textures.frames, l.camera) = Some(((l.camera, l.frame), tex));
                    ctx.request_repaint();
                }
                Err(e) => {
                    self.status.fail(e);
                    self.view.playing = false;
                }
            }
        }
    }

    /// True when every view shows the current frame (frames decode on a loader thread).
    pub fn frames_ready(&self) -> bool {
        let Some(scene) = &self.doc.scene else {
            return false;
        };
        (0..scene.cameras.len()).all(|c| {
            self.screen
                .textures
                .frames
                .get(c)
                .and_then(|f| f.as_ref())
                .is_some_and(|(k, _)| *k == (c, self.view.frame))
        })
    }
}
