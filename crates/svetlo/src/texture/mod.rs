//! Textures: RGB-valued functions of the surface's uv. Scalar parameters (roughness,
//! opacity) use the same textures and read the first channel.

use crate::spectrum::Rgb;
use glam::{Affine2, Vec2};
use std::sync::Arc;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FilterMode {
    Nearest,
    #[default]
    Bilinear,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum WrapMode {
    #[default]
    Repeat,
    Mirror,
    Clamp,
}

/// A linear RGB image with row 0 at the top, as it is stored in files.
#[derive(Clone, Debug)]
pub struct Bitmap {
    pub width: usize,
    pub height: usize,
    pub data: Vec<Rgb>,
}

impl Bitmap {
    pub fn new(width: usize, height: usize, data: Vec<Rgb>) -> Self {
        assert_eq!(data.len(), width * height);
        Bitmap { width, height, data }
    }
    #[inline]
    pub fn texel(&self, x: usize, y: usize) -> Rgb {
        self.data[y * self.width + x]
    }
    pub fn mean(&self) -> Rgb {
        let s: Rgb = self.data.iter().copied().sum();
        s / self.data.len().max(1) as f32
    }
}

#[derive(Clone, Debug)]
pub enum Texture {
    Constant(Rgb),
    Bitmap { image: Arc<Bitmap>, filter: FilterMode, wrap: WrapMode, to_uv: Affine2 },
    Checkerboard { color0: Rgb, color1: Rgb, to_uv: Affine2 },
}

impl Default for Texture {
    fn default() -> Self {
        Texture::Constant(Rgb::splat(0.5))
    }
}

impl From<Rgb> for Texture {
    fn from(c: Rgb) -> Self {
        Texture::Constant(c)
    }
}

impl From<f32> for Texture {
    fn from(v: f32) -> Self {
        Texture::Constant(Rgb::splat(v))
    }
}

fn wrap(i: i64, n: usize, mode: WrapMode) -> usize {
    let n = n as i64;
    match mode {
        WrapMode::Repeat => i.rem_euclid(n) as usize,
        WrapMode::Clamp => i.clamp(0, n - 1) as usize,
        WrapMode::Mirror => {
            let m = i.rem_euclid(2 * n);
            (if m >= n { 2 * n - 1 - m } else { m }) as usize
        }
    }
}

impl Texture {
    /// Value at `uv`; constants (the common case) inline at the call site.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            _ => self.eval_varying(uv),
        }
    }

    #[inline(never)]
    fn eval_varying(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard { color0, color1, to_uv } => {
                let p = to_uv.transform_point2(uv);
                let (fx, fy) = (p.x - p.x.floor(), p.y - p.y.floor());
                if (fx > 0.5) == (fy > 0.5) {
                    *color0
                } else {
                    *color1
                }
            }
            Texture::Bitmap { image, filter, wrap: wm, to_uv } => {
                let p = to_uv.transform_point2(uv);
                // Mitsuba 3's convention: v = 0 is the top row of the image (its OBJ reader flips
                // v so that OBJ files, whose v = 0 is the bottom, come out upright).
                let x = p.x * image.width as f32;
                let y = p.y * image.height as f32;
                match filter {
                    FilterMode::Nearest => image.texel(wrap(x.floor() as i64, image.width, *wm), wrap(y.floor() as i64, image.height, *wm)),
                    FilterMode::Bilinear => {
                        let (x, y) = (x - 0.5, y - 0.5);
                        let (x0, y0) = (x.floor(), y.floor());
                        let (fx, fy) = (x - x0, y - y0);
                        let (x0, y0) = (x0 as i64, y0 as i64);
                        let t = |dx: i64, dy: i64| image.texel(wrap(x0 + dx, image.width, *wm), wrap(y0 + dy, image.height, *wm));
                        (t(0, 0) * (1.0 - fx) + t(1, 0) * fx) * (1.0 - fy) + (t(0, 1) * (1.0 - fx) + t(1, 1) * fx) * fy
                    }
                }
            }
        }
    }
    /// Scalar parameter: the first channel.
    #[inline]
    pub fn eval_f32(&self, uv: Vec2) -> f32 {
        self.eval(uv).r
    }
    /// Mean value over the texture (for light power and radiosity albedo).
    pub fn mean(&self) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard { color0, color1, .. } => (*color0 + *color1) * 0.5,
            Texture::Bitmap { image, .. } => image.mean(),
        }
    }
    pub fn is_constant(&self) -> bool {
        matches!(self, Texture::Constant(_))
    }
}
