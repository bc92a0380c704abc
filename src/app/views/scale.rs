//! The colour scale of the probability and uncertainty maps, drawn in a corner of each view: a
//! bar from 0 to 1 in the colours the map blends over the image at the chosen opacity, with its
//! ticks and what the value is (the class's probability, or 1 − the margin between the two most
//! likely classes). The colours come from the same functions the map textures are made with, so
//! the scale cannot disagree with the map.

use super::colour32;
use crate::app::Shown;
use crate::app::state::Layer;
use egui::{Color32, Pos2, Rect, Stroke, pos2, vec2};

/// The colour and alpha a probability `p` of a class drawn in `col` gets in the map.
pub fn probability_rgba(col: [u8; 3], p: f32) -> [u8; 4] {
    [col[0], col[1], col[2], (p.clamp(0.0, 1.0) * 255.0) as u8]
}

/// The colour and alpha an uncertainty `u` gets in the map (dark → bright orange).
pub fn uncertainty_rgba(u: f32) -> [u8; 4] {
    let u = u.clamp(0.0, 1.0);
    [
        255,
        (80.0 + 175.0 * u) as u8,
        (40.0 * (1.0 - u)) as u8,
        (u * 255.0) as u8,
    ]
}

/// What a map pixel of `rgba` looks like over a mid-dark tissue grey at `opacity`.
fn over_grey(rgba: [u8; 4], opacity: f32) -> Color32 {
    let grey = 70.0;
    let a = rgba[3] as f32 / 255.0 * opacity.clamp(0.0, 1.0);
    let mix = |c: u8| (grey + (c as f32 - grey) * a).round() as u8;
    Color32::from_rgb(mix(rgba[0]), mix(rgba[1]), mix(rgba[2]))
}

/// The colour and alpha of a map value v ∈ [0, 1].
type Colouring = Box<dyn Fn(f32) -> [u8; 4]>;

/// The bar's title and colouring, for the layer shown (None for the image).
fn scale_of(shown: &Shown, layer: Layer) -> Option<(String, Colouring)> {
    match layer {
        Layer::Image => None,
        Layer::Probability(k) => {
            let name = shown
                .doc
                .classes
                .as_ref()
                .and_then(|c| c.names.get(k))
                .map_or_else(|| format!("class {k}"), |n| n.replace('_', " "));
            let col = shown.doc.class_colour(k);
            Some((
                format!("P({name})"),
                Box::new(move |v| probability_rgba(col, v)),
            ))
        }
        Layer::Uncertainty => Some((
            "uncertainty (1 - margin)".into(),
            Box::new(uncertainty_rgba),
        )),
    }
}

/// Draws the scale at the bottom-right of `view` when a map is shown.
pub fn draw(shown: &Shown, painter: &egui::Painter, view: Rect) {
    let Some((title, colour)) = scale_of(shown, shown.view.layer) else {
        return;
    };
    let opacity = shown.prefs.probability_opacity;
    let (bar_w, bar_h) = (12.0, (view.height() * 0.35).clamp(50.0, 140.0));
    let bar = Rect::from_min_size(
        pos2(view.right() - 14.0 - bar_w, view.bottom() - 12.0 - bar_h),
        vec2(bar_w, bar_h),
    );
    let font = egui::FontId::proportional(11.0);
    let text = Color32::from_gray(230);
    // A dark backing, so the labels read over any frame.
    let title_galley = painter.layout_no_wrap(title, font.clone(), text);
    let backing = Rect::from_min_max(
        pos2(
            (bar.left() - 34.0).min(bar.right() - title_galley.size().x - 4.0),
            bar.top() - title_galley.size().y - 8.0,
        ),
        bar.right_bottom() + vec2(6.0, 6.0),
    );
    painter.rect_filled(backing, 3.0, colour32([0, 0, 0], 170));
    painter.galley(
        pos2(
            bar.right() - title_galley.size().x,
            bar.top() - title_galley.size().y - 4.0,
        ),
        title_galley,
        text,
    );
    let steps = 32;
    let mut mesh = egui::Mesh::default();
    for i in 0..=steps {
        let v = i as f32 / steps as f32;
        let y = bar.bottom() - v * bar.height();
        let c = over_grey(colour(v), opacity);
        mesh.colored_vertex(pos2(bar.left(), y), c);
        mesh.colored_vertex(pos2(bar.right(), y), c);
        if i > 0 {
            let b = 2 * i as u32;
            mesh.add_triangle(b - 2, b - 1, b);
            mesh.add_triangle(b - 1, b + 1, b);
        }
    }
    painter.add(egui::Shape::mesh(mesh));
    painter.rect_stroke(
        bar,
        0.0,
        Stroke::new(1.0, Color32::from_gray(200)),
        egui::StrokeKind::Outside,
    );
    for v in [0.0f32, 0.5, 1.0] {
        let y = bar.bottom() - v * bar.height();
        painter.line_segment(
            [pos2(bar.left() - 4.0, y), Pos2::new(bar.left(), y)],
            Stroke::new(1.0, text),
        );
        painter.text(
            pos2(bar.left() - 6.0, y),
            egui::Align2::RIGHT_CENTER,
            format!("{v}"),
            font.clone(),
            text,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_ends_where_the_map_does() {
        // p = 0 leaves the tissue untouched; p = 1 at full opacity is the class colour.
        assert_eq!(
            over_grey(probability_rgba([0, 200, 0], 0.0), 1.0),
            Color32::from_gray(70)
        );
        assert_eq!(
            over_grey(probability_rgba([0, 200, 0], 1.0), 1.0),
            Color32::from_rgb(0, 200, 0)
        );
        assert_eq!(
            over_grey(uncertainty_rgba(1.0), 1.0),
            Color32::from_rgb(255, 255, 0)
        );
        // Half opacity: half-way to the colour.
        assert_eq!(
            over_grey(probability_rgba([170, 70, 70], 1.0), 0.5),
            Color32::from_rgb(120, 70, 70)
        );
    }
}
