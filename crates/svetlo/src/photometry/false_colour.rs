//! False-colour pictures of photometric quantities (as Radiance's `falsecolor`): a palette
//! from dark blue through green and yellow to red over a linear or logarithmic scale, a
//! legend bar with its values and unit, and iso-lines where the value crosses a legend step.
//! Used for work-plane illuminance grids (lx) and rendered luminance (cd/m²).

use crate::film::Image;
use crate::spectrum::Rgb;

/// Legend steps (bands of colour; iso-lines sit on their boundaries).
pub const STEPS: usize = 8;

/// The mapping from a value to [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scale {
    pub lo: f64,
    pub hi: f64,
    /// Logarithmic between lo and hi (both must then be positive).
    pub log: bool,
}

impl Scale {
    /// `lo:hi` (e.g. `0:500`); `log` maps logarithmically (lo > 0).
    pub fn parse(s: &str, log: bool) -> Result<Scale, String> {
        let (a, b) = s.split_once(':').ok_or_else(|| format!("'{s}' is not lo:hi"))?;
        let num = |x: &str| x.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("'{x}' is not a number"));
        let sc = Scale { lo: num(a)?, hi: num(b)?, log };
        if sc.hi <= sc.lo {
            return Err(format!("the scale's top {} must exceed its bottom {}", sc.hi, sc.lo));
        }
        if log && sc.lo <= 0.0 {
            return Err("a logarithmic scale needs a positive bottom".into());
        }
        Ok(sc)
    }

    /// 0 to the largest value (or 1 when all are zero); log: a thousandth of the largest up.
    pub fn auto(values: &[f64], log: bool) -> Scale {
        let hi = values.iter().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
        let hi = if hi > 0.0 { hi } else { 1.0 };
        Scale { lo: if log { hi * 1e-3 } else { 0.0 }, hi, log }
    }

    pub fn t(&self, v: f64) -> f64 {
        let t = if self.log { (v.max(self.lo * 1e-9).ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln()) } else { (v - self.lo) / (self.hi - self.lo) };
        if t.is_nan() {
            0.0
        } else {
            t.clamp(0.0, 1.0)
        }
    }

    /// The value at t (inverse of [`Self::t`] inside the scale).
    pub fn value(&self, t: f64) -> f64 {
        if self.log {
            (self.lo.ln() + t * (self.hi.ln() - self.lo.ln())).exp()
        } else {
            self.lo + t * (self.hi - self.lo)
        }
    }
}

/// sRGB colour of t in [0, 1]: piecewise linear through dark blue, blue, cyan, green, yellow,
/// orange, red (monotone in lightness up to yellow, so the bands read in order).
pub fn palette(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 7] =
        [[20.0, 10.0, 90.0], [30.0, 60.0, 220.0], [20.0, 190.0, 230.0], [40.0, 200.0, 60.0], [240.0, 230.0, 40.0], [250.0, 140.0, 20.0], [210.0, 20.0, 20.0]];
    let x = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f64;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f64;
    let mut c = [0u8; 3];
    for (k, ck) in c.iter_mut().enumerate() {
        *ck = (STOPS[i][k] + f * (STOPS[i + 1][k] - STOPS[i][k])).round() as u8;
    }
    c
}

/// A 3 × 5 pixel font for the legend: digits, sign, point, e and the units' letters.
fn glyph(ch: char) -> Option<[u8; 5]> {
    Some(match ch {
        '0' => [0b111, 0b101, 0b101, 0b101, 0b111],
        '1' => [0b010, 0b110, 0b010, 0b010, 0b111],
        '2' => [0b111, 0b001, 0b111, 0b100, 0b111],
        '3' => [0b111, 0b001, 0b011, 0b001, 0b111],
        '4' => [0b101, 0b101, 0b111, 0b001, 0b001],
        '5' => [0b111, 0b100, 0b111, 0b001, 0b111],
        '6' => [0b111, 0b100, 0b111, 0b101, 0b111],
        '7' => [0b111, 0b001, 0b010, 0b010, 0b010],
        '8' => [0b111, 0b101, 0b111, 0b101, 0b111],
        '9' => [0b111, 0b101, 0b111, 0b001, 0b111],
        '.' => [0b000, 0b000, 0b000, 0b000, 0b010],
        '-' => [0b000, 0b000, 0b111, 0b000, 0b000],
        '+' => [0b000, 0b010, 0b111, 0b010, 0b000],
        '/' => [0b001, 0b001, 0b010, 0b100, 0b100],
        '%' => [0b101, 0b001, 0b010, 0b100, 0b101],
        'e' => [0b000, 0b111, 0b111, 0b100, 0b111],
        'l' => [0b110, 0b010, 0b010, 0b010, 0b111],
        'x' => [0b000, 0b101, 0b010, 0b101, 0b000],
        'c' => [0b000, 0b111, 0b100, 0b100, 0b111],
        'd' => [0b001, 0b001, 0b111, 0b101, 0b111],
        'm' => [0b000, 0b111, 0b111, 0b101, 0b101],
        ' ' => [0; 5],
        _ => return None,
    })
}

/// An 8-bit sRGB canvas (converted to the linear [`Image`] at the end).
struct Canvas {
    w: usize,
    h: usize,
    px: Vec<[u8; 3]>,
}

impl Canvas {
    fn set(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.w && y < self.h {
            self.px[y * self.w + x] = c;
        }
    }

    /// Text at (x, y) (top left), each font pixel `s` × `s`.
    fn text(&mut self, x: usize, y: usize, s: usize, txt: &str, c: [u8; 3]) {
        for (k, ch) in txt.chars().enumerate() {
            let Some(g) = glyph(ch) else { continue };
            for (row, bits) in g.iter().enumerate() {
                for col in 0..3 {
                    if (bits >> (2 - col)) & 1 == 1 {
                        for dy in 0..s {
                            for dx in 0..s {
                                self.set(x + (k * 4 + col) * s + dx, y + row * s + dy, c);
                            }
                        }
                    }
                }
            }
        }
    }

    fn into_image(self) -> Image {
        let data = self
            .px
            .iter()
            .map(|c| Rgb::new(Rgb::srgb_to_linear(c[0] as f32 / 255.0), Rgb::srgb_to_linear(c[1] as f32 / 255.0), Rgb::srgb_to_linear(c[2] as f32 / 255.0)))
            .collect();
        Image::new(self.w, self.h, data)
    }
}

/// A legend value in at most 6 characters.
fn label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (0.01..10.0).contains(&a) {
        format!("{v:.2}")
    } else if (10.0..100_000.0).contains(&a) {
        format!("{v:.0}")
    } else {
        format!("{v:.0e}")
    }
}

/// `values` (row-major, `w` × `h`, row 0 at the top) in false colour with a legend bar to the
/// right titled `unit`; with `iso`, black lines where the value crosses a step boundary.
pub fn picture(values: &[f64], w: usize, h: usize, scale: &Scale, unit: &str, iso: bool) -> Image {
    let font = if h >= 200 { 2 } else { 1 };
    let legend_w = 10 + 24 * font + 6 * 4 * font;
    let height = h.max((STEPS + 1) * 8 * font + 10);
    let mut c = Canvas { w: w + legend_w, h: height, px: vec![[255, 255, 255]; (w + legend_w) * height] };
    let band = |v: f64| ((scale.t(v) * STEPS as f64) as usize).min(STEPS - 1);
    for y in 0..h {
        for x in 0..w {
            let v = values[y * w + x];
            let b = band(v);
            let edge = iso && ((x + 1 < w && band(values[y * w + x + 1]) != b) || (y + 1 < h && band(values[(y + 1) * w + x]) != b));
            c.set(x, y, if edge { [0, 0, 0] } else { palette(scale.t(v)) });
        }
    }
    // The bar: STEPS bands from the top (highest) down, each labelled at its lower edge.
    let (bx, top) = (w + 6, 6 * font + 4);
    let bh = (height - top - 4 * font).max(STEPS) / STEPS;
    c.text(bx, 2, font, unit, [0, 0, 0]);
    for s in 0..STEPS {
        let k = STEPS - 1 - s;
        let col = palette((k as f64 + 0.5) / STEPS as f64);
        for y in 0..bh {
            for x in 0..8 * font {
                c.set(bx + x, top + s * bh + y, col);
            }
        }
        let v = scale.value(k as f64 / STEPS as f64);
        c.text(bx + 10 * font, top + s * bh + bh.saturating_sub(5 * font), font, &label(v), [0, 0, 0]);
    }
    c.text(bx + 10 * font, top, font, &label(scale.hi), [0, 0, 0]);
    c.into_image()
}

/// A grid of `nu` × `nv` cell values (`values[i * nv + j]`, i along u) as a plan view:
/// `px` pixels per cell, bilinear between cell centres, u to the right and v up.
pub fn grid_picture(values: &[f64], nu: usize, nv: usize, px: usize, scale: &Scale, unit: &str) -> Image {
    let (w, h) = (nu * px, nv * px);
    let at = |i: usize, j: usize| values[i.min(nu - 1) * nv + j.min(nv - 1)];
    let mut img = vec![0.0; w * h];
    for y in 0..h {
        // v grows upward: the last row of pixels is j = 0.
        let fv = ((h - 1 - y) as f64 + 0.5) / px as f64 - 0.5;
        for x in 0..w {
            let fu = (x as f64 + 0.5) / px as f64 - 0.5;
            let (i0, j0) = (fu.floor().max(0.0) as usize, fv.floor().max(0.0) as usize);
            let (tu, tv) = ((fu - i0 as f64).clamp(0.0, 1.0), (fv - j0 as f64).clamp(0.0, 1.0));
            let a = at(i0, j0) * (1.0 - tu) + at(i0 + 1, j0) * tu;
            let b = at(i0, j0 + 1) * (1.0 - tu) + at(i0 + 1, j0 + 1) * tu;
            img[y * w + x] = a * (1.0 - tv) + b * tv;
        }
    }
    picture(&img, w, h, scale, unit, true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn palette_runs_from_blue_to_red_and_scales_invert() {
        assert!(palette(0.0)[2] > palette(0.0)[0] && palette(1.0)[0] > palette(1.0)[2]);
        for log in [false, true] {
            let s = Scale { lo: 2.0, hi: 500.0, log };
            for t in [0.0, 0.3, 0.7, 1.0] {
                assert!((s.t(s.value(t)) - t).abs() < 1e-12);
            }
            assert_eq!(s.t(1e9), 1.0);
            assert_eq!(s.t(-1.0), 0.0);
        }
        assert!(Scale::parse("0:500", false).is_ok());
        assert!(Scale::parse("5:1", false).is_err() && Scale::parse("0:5", true).is_err() && Scale::parse("x", false).is_err());
    }

    #[test]
    fn grid_picture_has_iso_lines_between_bands_and_a_legend() {
        // A ramp along u over 8 cells crosses every band boundary: each of the 7 inner
        // boundaries draws a black column somewhere in every row of the plan.
        let (nu, nv) = (8, 3);
        let values: Vec<f64> = (0..nu * nv).map(|k| (k / nv) as f64 * 100.0).collect();
        let sc = Scale { lo: 0.0, hi: 700.0, log: false };
        let img = grid_picture(&values, nu, nv, 10, &sc, "lx");
        assert!(img.width > 80 && img.height >= 30);
        let black = |x: usize, y: usize| img.data[y * img.width + x].max_component() < 1e-3;
        for y in 0..30 {
            let lines = (0..79).filter(|&x| black(x, y) && !black(x + 1, y)).count();
            assert_eq!(lines, 7, "row {y}");
        }
        // The legend's top band is red, its bottom band blue.
        let red = img.data[(img.height / 8) * img.width + 80 + 7];
        assert!(red.r > red.b, "{red:?}");
    }
}
