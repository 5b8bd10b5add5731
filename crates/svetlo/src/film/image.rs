//! A linear RGB float image with row 0 at the top.

use crate::spectrum::Rgb;

#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub data: Vec<Rgb>,
}

impl Image {
    pub fn new(width: usize, height: usize, data: Vec<Rgb>) -> Self {
        assert_eq!(data.len(), width * height, "image data does not match its size");
        Image { width, height, data }
    }
    pub fn filled(width: usize, height: usize, c: Rgb) -> Self {
        Image { width, height, data: vec![c; width * height] }
    }
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> Rgb {
        self.data[y * self.width + x]
    }
    pub fn mean(&self) -> Rgb {
        let s: Rgb = self.data.iter().copied().sum();
        s / self.data.len().max(1) as f32
    }
}
