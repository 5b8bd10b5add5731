//! Linear RGB radiometric quantities (Rec. 709 primaries, as Mitsuba's `rgb` variants).

use std::ops::{Add, AddAssign, Div, DivAssign, Index, Mul, MulAssign, Neg, Sub, SubAssign};

/// `repr(C)`: an image's `[Rgb]` is a packed `[f32; 3]` array, handed to Python without a copy.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct Rgb {
    pub r: f32,
    pub g: f32,
    pub b: f32,
}

impl Rgb {
    pub const BLACK: Rgb = Rgb { r: 0.0, g: 0.0, b: 0.0 };
    pub const WHITE: Rgb = Rgb { r: 1.0, g: 1.0, b: 1.0 };

    #[inline]
    pub const fn new(r: f32, g: f32, b: f32) -> Self {
        Rgb { r, g, b }
    }
    #[inline]
    pub const fn splat(v: f32) -> Self {
        Rgb { r: v, g: v, b: v }
    }
    #[inline]
    pub fn is_black(&self) -> bool {
        self.r == 0.0 && self.g == 0.0 && self.b == 0.0
    }
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.r.is_finite() && self.g.is_finite() && self.b.is_finite()
    }
    #[inline]
    pub fn max_component(&self) -> f32 {
        self.r.max(self.g).max(self.b)
    }
    #[inline]
    pub fn min_component(&self) -> f32 {
        self.r.min(self.g).min(self.b)
    }
    #[inline]
    pub fn mean(&self) -> f32 {
        (self.r + self.g + self.b) / 3.0
    }
    /// Luminance Y of linear Rec. 709.
    #[inline]
    pub fn luminance(&self) -> f32 {
        0.212671 * self.r + 0.715160 * self.g + 0.072169 * self.b
    }
    #[inline]
    pub fn map(self, f: impl Fn(f32) -> f32) -> Rgb {
        Rgb::new(f(self.r), f(self.g), f(self.b))
    }
    #[inline]
    pub fn sqrt(self) -> Rgb {
        self.map(|x| x.max(0.0).sqrt())
    }
    #[inline]
    pub fn exp(self) -> Rgb {
        self.map(f32::exp)
    }
    #[inline]
    pub fn clamp(self, lo: f32, hi: f32) -> Rgb {
        self.map(|x| x.clamp(lo, hi))
    }
    #[inline]
    pub fn to_array(self) -> [f32; 3] {
        [self.r, self.g, self.b]
    }
    #[inline]
    pub fn from_array(a: [f32; 3]) -> Self {
        Rgb::new(a[0], a[1], a[2])
    }
    /// Linear RGB -> CIE XYZ (D65).
    pub fn to_xyz(self) -> [f32; 3] {
        [
            0.412453 * self.r + 0.357580 * self.g + 0.180423 * self.b,
            0.212671 * self.r + 0.715160 * self.g + 0.072169 * self.b,
            0.019334 * self.r + 0.119193 * self.g + 0.950227 * self.b,
        ]
    }
    /// sRGB-encoded value in [0,1] -> linear.
    pub fn srgb_to_linear(v: f32) -> f32 {
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    }
    /// Linear -> sRGB-encoded (no clamping of the input beyond 0).
    pub fn linear_to_srgb(v: f32) -> f32 {
        let v = v.max(0.0);
        if v <= 0.0031308 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        }
    }
}

impl Index<usize> for Rgb {
    type Output = f32;
    fn index(&self, i: usize) -> &f32 {
        match i {
            0 => &self.r,
            1 => &self.g,
            _ => &self.b,
        }
    }
}

macro_rules! rgb_binop {
    ($tr:ident, $f:ident, $tra:ident, $fa:ident, $op:tt) => {
        impl $tr for Rgb {
            type Output = Rgb;
            #[inline]
            fn $f(self, o: Rgb) -> Rgb {
                Rgb::new(self.r $op o.r, self.g $op o.g, self.b $op o.b)
            }
        }
        impl $tr<f32> for Rgb {
            type Output = Rgb;
            #[inline]
            fn $f(self, o: f32) -> Rgb {
                Rgb::new(self.r $op o, self.g $op o, self.b $op o)
            }
        }
        impl $tra for Rgb {
            #[inline]
            fn $fa(&mut self, o: Rgb) {
                *self = *self $op o;
            }
        }
        impl $tra<f32> for Rgb {
            #[inline]
            fn $fa(&mut self, o: f32) {
                *self = *self $op o;
            }
        }
    };
}
rgb_binop!(Add, add, AddAssign, add_assign, +);
rgb_binop!(Sub, sub, SubAssign, sub_assign, -);
rgb_binop!(Mul, mul, MulAssign, mul_assign, *);
rgb_binop!(Div, div, DivAssign, div_assign, /);

impl Mul<Rgb> for f32 {
    type Output = Rgb;
    #[inline]
    fn mul(self, o: Rgb) -> Rgb {
        o * self
    }
}

impl Neg for Rgb {
    type Output = Rgb;
    fn neg(self) -> Rgb {
        Rgb::new(-self.r, -self.g, -self.b)
    }
}

impl std::iter::Sum for Rgb {
    fn sum<I: Iterator<Item = Rgb>>(iter: I) -> Rgb {
        iter.fold(Rgb::BLACK, |a, b| a + b)
    }
}
