//! Where an image sits in a view: one zoom and pan shared by all views (synchronised, as
//! stereo review needs), and the conversions between screen points and image pixels. Image
//! pixel coordinates here are pixel *edges*: pixel (i, j) covers [i, i+1) × [j, j+1), and its
//! centre, where the camera model puts it, is (i + 0.5, j + 0.5) − 0.5 = (i, j) in the
//! camera's convention.

use egui::{Pos2, Rect, Vec2, pos2, vec2};

/// Zoom and pan shared by every view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewTransform {
    /// Multiples of "fit the image to the view".
    pub zoom: f32,
    /// The image point (edge coordinates, px) at the view's centre.
    pub center_px: Pos2,
}

impl ViewTransform {
    pub fn fit(image_size: Vec2) -> Self {
        Self {
            zoom: 1.0,
            center_px: (image_size / 2.0).to_pos2(),
        }
    }

    /// Screen points per image pixel in a view of `rect`.
    pub fn scale(&self, rect: Rect, image_size: Vec2) -> f32 {
        let fit = (rect.width() / image_size.x).min(rect.height() / image_size.y);
        fit.max(1e-6) * self.zoom
    }

    /// Screen rectangle the whole image covers.
    pub fn image_rect(&self, rect: Rect, image_size: Vec2) -> Rect {
        let s = self.scale(rect, image_size);
        let min = rect.center() - self.center_px.to_vec2() * s;
        Rect::from_min_size(min, image_size * s)
    }

    pub fn to_image(&self, rect: Rect, image_size: Vec2, screen: Pos2) -> Pos2 {
        let r = self.image_rect(rect, image_size);
        let s = self.scale(rect, image_size);
        pos2((screen.x - r.min.x) / s, (screen.y - r.min.y) / s)
    }

    pub fn to_screen(&self, rect: Rect, image_size: Vec2, image: Pos2) -> Pos2 {
        let r = self.image_rect(rect, image_size);
        let s = self.scale(rect, image_size);
        r.min + image.to_vec2() * s
    }

    /// Zooms by `factor` keeping the image point under `screen` in place.
    pub fn zoom_about(&mut self, rect: Rect, image_size: Vec2, screen: Pos2, factor: f32) {
        let before = self.to_image(rect, image_size, screen);
        self.zoom = (self.zoom * factor).clamp(0.25, 40.0);
        let after = self.to_image(rect, image_size, screen);
        self.center_px += before - after;
    }

    /// Pans by a screen displacement.
    pub fn pan(&mut self, rect: Rect, image_size: Vec2, delta_screen: Vec2) {
        let s = self.scale(rect, image_size);
        self.center_px -= delta_screen / s;
    }
}

/// Rectangles of `n` views in a grid filling `rect` (two side by side for stereo).
pub fn grid(rect: Rect, n: usize, gap: f32) -> Vec<Rect> {
    let n = n.max(1);
    let cols = if n <= 2 {
        n
    } else {
        (n as f32).sqrt().ceil() as usize
    };
    let rows = n.div_ceil(cols);
    let w = (rect.width() - gap * (cols - 1) as f32) / cols as f32;
    let h = (rect.height() - gap * (rows - 1) as f32) / rows as f32;
    (0..n)
        .map(|i| {
            let (c, r) = (i % cols, i / cols);
            Rect::from_min_size(
                rect.min + vec2(c as f32 * (w + gap), r as f32 * (h + gap)),
                vec2(w.max(1.0), h.max(1.0)),
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn screen_and_image_coordinates_invert_and_zoom_keeps_the_cursor_point() {
        let rect = Rect::from_min_size(pos2(10.0, 20.0), vec2(400.0, 300.0));
        let size = vec2(480.0, 270.0);
        let mut t = ViewTransform::fit(size);
        let p = pos2(123.0, 77.0);
        let s = t.to_screen(rect, size, p);
        assert!((t.to_image(rect, size, s) - p).length() < 1e-3);
        let cursor = pos2(300.0, 100.0);
        let under = t.to_image(rect, size, cursor);
        t.zoom_about(rect, size, cursor, 3.0);
        assert!((t.to_image(rect, size, cursor) - under).length() < 1e-3);
        t.pan(rect, size, vec2(30.0, 0.0));
        assert!(t.to_image(rect, size, cursor).x < under.x);
        let views = grid(rect, 2, 4.0);
        assert_eq!(views.len(), 2);
        assert!(views[0].max.x < views[1].min.x);
    }
}
