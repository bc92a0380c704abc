//! A 2D raster of any pixel type, row-major. Masks, label images, depth, distance and
//! probability maps are all planes with a name that says what they hold.

/// Row-major `width × height` pixels.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Plane<T> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<T>,
}

/// Binary mask (true = inside).
pub type Mask = Plane<bool>;
/// 8-bit labels: 0 = background, otherwise a structure's label.
pub type LabelImage = Plane<u8>;
/// Per-pixel distances (px) or signed distances (φ, positive inside).
pub type DistanceMap = Plane<f32>;

impl<T: Clone> Plane<T> {
    pub fn filled(width: usize, height: usize, value: T) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }
}

impl<T> Plane<T> {
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Option<Self> {
        (data.len() == width * height).then_some(Self {
            width,
            height,
            data,
        })
    }

    #[inline]
    pub fn index(&self, x: usize, y: usize) -> usize {
        y * self.width + x
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> &T {
        &self.data[y * self.width + x]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, v: T) {
        let i = y * self.width + x;
        self.data[i] = v;
    }

    pub fn same_size<U>(&self, other: &Plane<U>) -> bool {
        self.width == other.width && self.height == other.height
    }

    pub fn map<U>(&self, f: impl Fn(&T) -> U) -> Plane<U> {
        Plane {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(f).collect(),
        }
    }
}

impl LabelImage {
    /// Pixels equal to `label`.
    pub fn mask_of(&self, label: u8) -> Mask {
        self.map(|&v| v == label)
    }
}

impl Mask {
    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&b| b).count()
    }
}

/// Dice coefficient of two masks of the same size; `None` when both are empty.
pub fn dice(a: &Mask, b: &Mask) -> Option<f64> {
    let (mut inter, mut sa, mut sb) = (0usize, 0usize, 0usize);
    for (&x, &y) in a.data.iter().zip(&b.data) {
        inter += (x && y) as usize;
        sa += x as usize;
        sb += y as usize;
    }
    (sa + sb > 0).then(|| 2.0 * inter as f64 / (sa + sb) as f64)
}
