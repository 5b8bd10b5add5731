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

// `Rgb` is laid out as `[f32; 3]`: what `as_floats` relies on.
const _: () = assert!(std::mem::size_of::<Rgb>() == 12 && std::mem::align_of::<Rgb>() == 4);

impl Rgb {
    pub const BLACK: Rgb = Rgb { r: 0.0, g: 0.0, b: 0.0 };
    pub const WHITE: Rgb = Rgb { r: 1.0, g: 1.0, b: 1.0 };

    #[inline]
    pub const fn new(r: f32, g: f32, b: f32) -> Self {
        Rgb { r, g, b }
    }
    /// Colours as their packed floats (r, g, b of each in turn).
    #[inline]
    pub fn as_floats(v: &[Rgb]) -> &[f32] {
        // SAFETY: `repr(C)` of three f32 without padding (asserted above `impl Rgb`): the same bytes as
        // `3 * v.len()` floats, borrowed for as long as `v`.
        unsafe { std::slice::from_raw_parts(v.as_ptr().cast(), v.len() * 3) }
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
    /// Linear -> the 8-bit sRGB code PNGs store: `(linear_to_srgb(v).clamp(0, 1) * 255 + 0.5)`
    /// truncated, the same byte for every input (NaN and negatives give 0), from tables
    /// instead of a `powf` per channel (see [`Srgb8Table`]).
    #[inline]
    pub fn linear_to_srgb8(v: f32) -> u8 {
        if v.is_nan() || v <= 0.0 {
            return 0;
        }
        let t = SRGB8.get_or_init(Srgb8Table::new);
        let code = t.bucket[(v.to_bits() >> 16) as usize];
        // Within a bucket the code steps up at most once (see `Srgb8Table`).
        match t.steps.get(code as usize) {
            Some(&step) if v >= step => code + 1,
            _ => code,
        }
    }
    /// [`Self::linear_to_srgb8`] the slow way: the definition it reproduces.
    #[inline]
    pub(crate) fn linear_to_srgb8_direct(v: f32) -> u8 {
        (Rgb::linear_to_srgb(v).clamp(0.0, 1.0) * 255.0 + 0.5) as u8
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

/// The tables of [`Rgb::linear_to_srgb8`].
///
/// `steps[k]` is the smallest non-negative float whose code exceeds k; `bucket[b]` the code
/// at the smallest float of bits `b << 16` (a positive float's exponent and first seven
/// mantissa bits: buckets 0.8 % wide). The code rises by less than one per bucket (at most
/// 0.44 * 255 / 128 on the power segment, 3294 * 0.0031 / 128 on the linear one), so the
/// bucket's code, stepped once where `v` passes the next step, is the code.
struct Srgb8Table {
    steps: [f32; 255],
    bucket: Box<[u8]>,
}

static SRGB8: std::sync::OnceLock<Srgb8Table> = std::sync::OnceLock::new();

impl Srgb8Table {
    fn new() -> Srgb8Table {
        // Non-negative floats order as their bit patterns, and the code never falls as the
        // value grows, so each step is found by bisection over the bits (32 halvings).
        let mut steps = [0.0f32; 255];
        for (k, s) in steps.iter_mut().enumerate() {
            let (mut lo, mut hi) = (0u32, f32::INFINITY.to_bits());
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if Rgb::linear_to_srgb8_direct(f32::from_bits(mid)) as usize > k {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            *s = f32::from_bits(lo);
        }
        let bucket = (0..=(f32::INFINITY.to_bits() >> 16)).map(|b| steps.partition_point(|&t| f32::from_bits(b << 16) >= t) as u8).collect();
        Srgb8Table { steps, bucket }
    }
}

#[cfg(test)]
mod tests {
    use super::Rgb;

    #[test]
    fn colours_as_floats() {
        let v = [Rgb::new(1.0, 2.0, 3.0), Rgb::new(4.0, 5.0, 6.0)];
        assert_eq!(Rgb::as_floats(&v), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    fn check(v: f32) {
        assert_eq!(Rgb::linear_to_srgb8(v), Rgb::linear_to_srgb8_direct(v), "8-bit sRGB code of {v:e} (bits {:#x})", v.to_bits());
    }

    #[test]
    fn srgb8_table_matches_the_definition() {
        // Every float within 4096 ulps of each step, a sweep through [0, 2], and the edges.
        let table = super::SRGB8.get_or_init(super::Srgb8Table::new);
        for &step in table.steps.iter() {
            let b = step.to_bits();
            for d in 0..4096u32 {
                check(f32::from_bits(b + d));
                check(f32::from_bits(b.saturating_sub(d)));
            }
        }
        let mut b = 0u32;
        while b <= 2.0f32.to_bits() {
            check(f32::from_bits(b));
            b += 997;
        }
        for v in [0.0, -0.0, -1.0, f32::MIN_POSITIVE, 1e-45, 0.0031308, 1.0, 1.0 + f32::EPSILON, 1e30, f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
            check(v);
        }
        assert_eq!(Rgb::linear_to_srgb8(1.0), 255);
        assert_eq!(Rgb::linear_to_srgb8(0.0), 0);
    }

    /// Every non-negative float up to 1.0 and beyond (about 10^9 values; `--ignored`, release).
    #[test]
    #[ignore]
    fn srgb8_table_matches_the_definition_everywhere() {
        for b in 0..=1.01f32.to_bits() {
            check(f32::from_bits(b));
        }
    }
}
