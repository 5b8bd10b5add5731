//! Textures: RGB-valued functions of a surface point (its uv, or for Mitsuba's
//! `mesh_attribute` its triangle and barycentrics). Scalar parameters (roughness, opacity,
//! weights) use the same textures, read as Mitsuba's `eval_1` reads them. pbrt-v4's
//! procedural textures (`procedural.rs`, on Perlin noise in `noise.rs`) also read the
//! point's position and normal.
//!
//! A bitmap read from an 8-bit colour file keeps its texels as the file's codes (four bytes
//! each) and decodes a code through the same 256-entry table the loader's float path uses:
//! lookups give the same values bit for bit while reading a quarter of the memory, which for
//! a large texture is most of a lookup's cost (cache misses). Its `Rgb` copy is decoded only
//! for the rare callers that ask for all texels at once ([`Bitmap::data`]).

pub mod noise;
pub mod procedural;

use crate::accel::pages::PagedSlice;
use crate::spectrum::Rgb;
use glam::{Affine2, Vec2, Vec3};
use std::sync::{Arc, OnceLock};

pub use procedural::{Mapping2D, Procedural};

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
    store: Store,
}

/// A bitmap's texels.
#[derive(Clone, Debug)]
enum Store {
    Float(Vec<Rgb>),
    /// 8-bit codes, which lookups read, and their `Rgb` values, decoded only when asked for
    /// ([`Bitmap::data`]).
    Codes(Texels8, OnceLock<Vec<Rgb>>),
}

/// The texels of an 8-bit image as its codes (RGB, padded to four bytes) and the linear value
/// of each code. A quarter of the `Rgb` copy's bytes: lookups into a large texture, which land
/// anywhere in it, then miss the cache far less often, and read back the very same values.
#[derive(Clone, Debug)]
struct Texels8 {
    /// On huge pages when large: a large texture's lookups land anywhere in it, and on 4 KiB
    /// pages nearly each missed the TLB as well (a row of 2048 texels is two pages).
    codes: PagedSlice<[u8; 4]>,
    table: &'static [f32; 256],
}

impl Texels8 {
    #[inline]
    fn rgb(&self, i: usize) -> Rgb {
        let c = self.codes[i];
        Rgb::new(self.table[c[0] as usize], self.table[c[1] as usize], self.table[c[2] as usize])
    }
}

impl Bitmap {
    pub fn new(width: usize, height: usize, data: Vec<Rgb>) -> Self {
        assert_eq!(data.len(), width * height);
        Bitmap { width, height, store: Store::Float(data) }
    }

    /// A bitmap of 8-bit texels (the fourth byte unused) whose channels decode as `table` says
    /// (sRGB to linear, or Mitsuba's `raw` code / 255).
    pub fn from_8bit(width: usize, height: usize, codes: Vec<[u8; 4]>, table: &'static [f32; 256]) -> Self {
        assert_eq!(codes.len(), width * height);
        Bitmap { width, height, store: Store::Codes(Texels8 { codes: PagedSlice::new(codes), table }, OnceLock::new()) }
    }

    /// Whether lookups read 8-bit codes ([`Bitmap::from_8bit`]).
    pub fn is_8bit(&self) -> bool {
        matches!(self.store, Store::Codes(..))
    }

    /// The texels, row by row (an 8-bit bitmap's decoded on the first call, and kept).
    pub fn data(&self) -> &[Rgb] {
        match &self.store {
            Store::Float(v) => v,
            Store::Codes(t, decoded) => decoded.get_or_init(|| (0..t.codes.len()).map(|i| t.rgb(i)).collect()),
        }
    }

    /// The texels to change in place: an 8-bit bitmap becomes a float one.
    pub fn data_mut(&mut self) -> &mut Vec<Rgb> {
        if let Store::Codes(..) = self.store {
            self.store = Store::Float(self.data().to_vec());
        }
        match &mut self.store {
            Store::Float(v) => v,
            Store::Codes(..) => unreachable!("made a float store above"),
        }
    }

    /// Asks for the cache line of texel (x, y) ahead of its lookup (a hint: one outside the
    /// image is not asked for).
    #[inline]
    fn prefetch_texel(&self, x: usize, y: usize) {
        let i = y * self.width + x;
        match &self.store {
            Store::Float(v) => {
                if let Some(t) = v.get(i) {
                    crate::accel::prefetch(t, std::mem::size_of::<Rgb>());
                }
            }
            Store::Codes(t, _) => {
                if let Some(c) = t.codes.get(i) {
                    crate::accel::prefetch(c, 4);
                }
            }
        }
    }

    #[inline]
    pub fn texel(&self, x: usize, y: usize) -> Rgb {
        let i = y * self.width + x;
        match &self.store {
            Store::Float(v) => v[i],
            Store::Codes(t, _) => t.rgb(i),
        }
    }
    /// The luminances of the texels at indices `i` (row by row), as [`Self::texel`] reads them.
    #[inline(always)]
    fn luminances(&self, i: [usize; 4]) -> [f32; 4] {
        match &self.store {
            Store::Float(v) => i.map(|i| v[i].luminance()),
            Store::Codes(t, _) => i.map(|i| t.rgb(i).luminance()),
        }
    }
    /// Bounds that every channel of every texel lies within, known without reading the
    /// texels: an 8-bit bitmap's are its code table's least and greatest values; None for a
    /// float bitmap.
    pub fn channel_bounds(&self) -> Option<(f32, f32)> {
        match &self.store {
            Store::Float(_) => None,
            Store::Codes(t, _) => Some(t.table.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)))),
        }
    }
    /// The texels row by row, as [`Bitmap::data`] holds them, without decoding a copy.
    pub fn texels(&self) -> impl Iterator<Item = Rgb> + '_ {
        (0..self.width * self.height).map(move |i| match &self.store {
            Store::Float(v) => v[i],
            Store::Codes(t, _) => t.rgb(i),
        })
    }

    pub fn mean(&self) -> Rgb {
        let s: Rgb = self.texels().sum();
        s / (self.width * self.height).max(1) as f32
    }
}

/// Where a texture is looked up: the uv, and the triangle with the barycentrics (b1, b2) of
/// the point inside it, which per-vertex and per-face mesh attributes need; the world
/// position and geometric normal, which pbrt's 3-D and direction textures need (zero where
/// a caller knows only the uv).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TexPoint {
    pub uv: Vec2,
    pub prim: u32,
    pub bary: Vec2,
    pub p: Vec3,
    pub n: Vec3,
}

impl TexPoint {
    /// `prim` of a point known only by its uv (the rasteriser, radiosity's albedos): mesh
    /// attributes give their mean there.
    pub const NO_PRIM: u32 = u32::MAX;
}

impl From<Vec2> for TexPoint {
    fn from(uv: Vec2) -> Self {
        TexPoint { uv, prim: TexPoint::NO_PRIM, ..Default::default() }
    }
}

/// Values a mesh stores per vertex or per triangle (Mitsuba's `vertex_NAME` / `face_NAME`
/// PLY properties), one to three channels widened to RGB (one channel is grey).
#[derive(Clone, Debug, PartialEq)]
pub struct MeshAttribute {
    pub name: String,
    pub per_face: bool,
    /// Per vertex or per triangle.
    pub values: Vec<Rgb>,
    /// The mesh's triangles (vertex indices), for per-vertex interpolation.
    pub indices: Arc<Vec<[u32; 3]>>,
}

impl MeshAttribute {
    fn eval(&self, p: TexPoint) -> Rgb {
        let Some(tri) = self.indices.get(p.prim as usize) else { return self.mean() };
        if self.per_face {
            return self.values.get(p.prim as usize).copied().unwrap_or(Rgb::BLACK);
        }
        let v = |k: usize| self.values.get(tri[k] as usize).copied().unwrap_or(Rgb::BLACK);
        v(0) * (1.0 - p.bary.x - p.bary.y) + v(1) * p.bary.x + v(2) * p.bary.y
    }
    fn mean(&self) -> Rgb {
        self.values.iter().copied().sum::<Rgb>() / self.values.len().max(1) as f32
    }
}

#[derive(Clone, Debug)]
pub enum Texture {
    Constant(Rgb),
    Bitmap {
        image: Arc<Bitmap>,
        filter: FilterMode,
        wrap: WrapMode,
        to_uv: Affine2,
    },
    Checkerboard {
        color0: Rgb,
        color1: Rgb,
        to_uv: Affine2,
    },
    /// Mitsuba `mesh_attribute`, bound to the mesh of the shape that uses it.
    MeshAttribute(Arc<MeshAttribute>),
    /// A `mesh_attribute` not yet bound to a mesh (the loader binds it per shape).
    UnboundAttribute(String),
    /// pbrt-v4's procedural textures and textured mixes (`procedural.rs`).
    Procedural(Arc<Procedural>),
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

/// `x.floor()`, bit for bit (signed zeros and infinities included; a NaN stays a NaN), without the libm
/// call that `floor` is on a target without SSE4.1: a bilinear lookup needed two.
#[inline]
fn floor_exact(x: f32) -> f32 {
    // Below 2^23 truncation through an integer is exact; from there on every float is whole
    // (or infinite, or NaN) and its own floor.
    if x.abs() < 8_388_608.0 {
        let t = (x as i32 as f32).copysign(x);
        if t > x {
            t - 1.0
        } else {
            t
        }
    } else {
        x
    }
}

/// A bilinear lookup of `image` at `uv` (mapped by `to_uv`), with `floor` the floor of the
/// caller's choice (both give the same bits: see [`Texture::eval_inline`]).
#[inline(always)]
fn bilinear(image: &Bitmap, wm: WrapMode, to_uv: &Affine2, uv: Vec2, floor: impl Fn(f32) -> f32) -> Rgb {
    let p = to_uv.transform_point2(uv);
    // Texel centres at half-integers (see `eval_varying` for the orientation of v).
    let (x, y) = (p.x * image.width as f32 - 0.5, p.y * image.height as f32 - 0.5);
    let (x0, y0) = (floor(x), floor(y));
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let (xa, xb) = (wrap(x0, image.width, wm), wrap(x0 + 1, image.width, wm));
    let (ya, yb) = (wrap(y0, image.height, wm), wrap(y0 + 1, image.height, wm));
    let t = |x: usize, y: usize| image.texel(x, y);
    (t(xa, ya) * (1.0 - fx) + t(xb, ya) * fx) * (1.0 - fy) + (t(xa, yb) * (1.0 - fx) + t(xb, yb) * fx) * fy
}

/// Always inlined: its in-range test is the whole of most calls (four a bilinear lookup),
/// and a call each cost more than the test.
#[inline(always)]
fn wrap(i: i64, n: usize, mode: WrapMode) -> usize {
    let n = n as i64;
    // Inside the image every mode is the identity: no division for most lookups.
    if (0..n).contains(&i) {
        return i as usize;
    }
    match mode {
        WrapMode::Repeat => i.rem_euclid(n) as usize,
        WrapMode::Clamp => i.clamp(0, n - 1) as usize,
        WrapMode::Mirror => {
            let m = i.rem_euclid(2 * n);
            (if m >= n { 2 * n - 1 - m } else { m }) as usize
        }
    }
}

/// A checkerboard's test at `uv`: true where the colour lookup gives `color0` (the float one
/// `color1`). Checkerboards of one `to_uv` share it (the principled model's table).
#[inline(always)]
pub fn checker_parity(to_uv: &Affine2, uv: Vec2) -> bool {
    let p = to_uv.transform_point2(uv);
    let (fx, fy) = (p.x - floor_exact(p.x), p.y - floor_exact(p.y));
    (fx > 0.5) == (fy > 0.5)
}

/// A checkerboard read as a float (`eval_f32`): `eval_varying`'s test with the colours the
/// other way round, then the luminance, in place (no swapped copy, no second call).
#[inline(always)]
fn checkerboard_f32(color0: &Rgb, color1: &Rgb, to_uv: &Affine2, uv: Vec2) -> f32 {
    if checker_parity(to_uv, uv) {
        color1.luminance()
    } else {
        color0.luminance()
    }
}

impl Texture {
    /// Value at a point (a uv converts); constants (the common case) inline at the call site.
    #[inline]
    pub fn eval(&self, p: impl Into<TexPoint>) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            _ => self.eval_varying(p.into()),
        }
    }

    /// Asks for the texels a lookup at `uv` reads, so that a lookup made a little later finds
    /// them in cache: a large bitmap's lookups land anywhere in it and wait on memory. A hint
    /// only (it changes no value): a bitmap's lookups inside the image (the others are left
    /// alone); other textures ignore it.
    #[inline]
    pub fn prefetch(&self, uv: Vec2) {
        if let Texture::Bitmap { image, to_uv, .. } = self {
            // A hint needs no exact place: the sizes through u32 and the texel through i32,
            // one instruction each where usize's conversions are branchy sequences without
            // AVX-512 (most of a lane's hint). `prefetch_texel` checks the index.
            let (w, h) = (image.width as u32 as f32, image.height as u32 as f32);
            let p = to_uv.transform_point2(uv);
            let (x, y) = (p.x * w - 0.5, p.y * h - 0.5);
            // The bilinear lookup's two rows at its first column (the next column mostly
            // shares the line; a nearest lookup reads one of them). NaN fails the test.
            if x >= 0.0 && y >= 0.0 && x < w && y + 1.0 < h {
                let (x, y) = (x as i32 as usize, y as i32 as usize);
                image.prefetch_texel(x, y);
                image.prefetch_texel(x, y + 1);
            }
        }
    }

    #[inline(never)]
    fn eval_varying(&self, p: TexPoint) -> Rgb {
        let uv = p.uv;
        match self {
            Texture::Constant(c) => *c,
            Texture::MeshAttribute(a) => a.eval(p),
            Texture::UnboundAttribute(_) => Rgb::BLACK,
            Texture::Procedural(t) => t.eval(&p),
            Texture::Checkerboard { color0, color1, to_uv } => {
                if checker_parity(to_uv, uv) {
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
                    FilterMode::Nearest => image.texel(wrap(floor_exact(x) as i64, image.width, *wm), wrap(floor_exact(y) as i64, image.height, *wm)),
                    FilterMode::Bilinear => bilinear(image, *wm, to_uv, uv, floor_exact),
                }
            }
        }
    }

    /// `eval`, with a bilinear bitmap's lookup inlined where it is called: inside a kernel
    /// built for AVX2 (the path kernel's) its floors are single instructions and the lookup
    /// skips the call and the dispatch of `eval`. The same value bit for bit (`f32::floor` is
    /// `floor_exact`); elsewhere `floor` may be a libm call, so only such kernels use it.
    #[inline(always)]
    pub fn eval_inline(&self, p: &TexPoint) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Bitmap { image, filter: FilterMode::Bilinear, wrap: wm, to_uv } => bilinear(image, *wm, to_uv, p.uv, f32::floor),
            _ => self.eval_varying(*p),
        }
    }
    /// Scalar parameter (roughness, opacity, weights), read as Mitsuba 3's `eval_1` reads it:
    /// a constant's first channel, a bitmap's luminance, and a checkerboard with its two
    /// colours the other way round from its colour lookup (Mitsuba's float checkerboard puts
    /// `color1` where the colour one puts `color0`; its test scenes are rendered that way).
    #[inline]
    pub fn eval_f32(&self, p: impl Into<TexPoint>) -> f32 {
        match self {
            Texture::Constant(c) => c.r,
            _ => self.eval_f32_varying(p.into()),
        }
    }

    #[inline(never)]
    fn eval_f32_varying(&self, p: TexPoint) -> f32 {
        match self {
            Texture::Checkerboard { color0, color1, to_uv } => checkerboard_f32(color0, color1, to_uv, p.uv),
            _ => self.eval(p).luminance(),
        }
    }

    /// [`Self::eval_f32`] with a checkerboard's lookup inlined where it is called (the
    /// principled model's dozen parameters): no call and no copy of the point.
    #[inline(always)]
    pub fn eval_f32_inline(&self, p: &TexPoint) -> f32 {
        match self {
            Texture::Constant(c) => c.r,
            Texture::Checkerboard { color0, color1, to_uv } => checkerboard_f32(color0, color1, to_uv, p.uv),
            _ => self.eval_f32_varying(*p),
        }
    }

    /// Gradient of the scalar value (`eval_f32`) with respect to (u, v), as Mitsuba's
    /// `eval_1_grad`: exact for a bilinear bitmap (the derivative of its interpolant inside
    /// the texel cell), zero for constants, checkerboards and mesh attributes (piecewise
    /// constant, or not functions of uv).
    pub fn eval_f32_grad(&self, p: impl Into<TexPoint>) -> Vec2 {
        let p = p.into();
        let Texture::Bitmap { image, filter, wrap: wm, to_uv } = self else { return Vec2::ZERO };
        if *filter == FilterMode::Nearest {
            return Vec2::ZERO;
        }
        let q = to_uv.transform_point2(p.uv);
        let (w, h) = (image.width as f32, image.height as f32);
        let (x, y) = (q.x * w - 0.5, q.y * h - 0.5);
        let (x0, y0) = (floor_exact(x), floor_exact(y));
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        // Each axis wrapped once, the four texels read by one match on the store.
        let (xa, xb) = (wrap(x0, image.width, *wm), wrap(x0 + 1, image.width, *wm));
        let (ya, yb) = (wrap(y0, image.height, *wm), wrap(y0 + 1, image.height, *wm));
        let [f00, f10, f01, f11] = image.luminances([ya * image.width + xa, ya * image.width + xb, yb * image.width + xa, yb * image.width + xb]);
        // d/dq of the interpolant, then the chain rule through to_uv (q = A uv + b).
        let dq = Vec2::new(((f10 - f00) * (1.0 - fy) + (f11 - f01) * fy) * w, ((f01 - f00) * (1.0 - fx) + (f11 - f10) * fx) * h);
        to_uv.matrix2.transpose() * dq
    }
    /// Mean value over the texture (for light power and radiosity albedo).
    pub fn mean(&self) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard { color0, color1, .. } => (*color0 + *color1) * 0.5,
            Texture::Bitmap { image, .. } => image.mean(),
            Texture::MeshAttribute(a) => a.mean(),
            Texture::UnboundAttribute(_) => Rgb::BLACK,
            Texture::Procedural(t) => t.mean(),
        }
    }
    pub fn is_constant(&self) -> bool {
        matches!(self, Texture::Constant(_))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_exact_is_floor_bit_for_bit() {
        let mut xs = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            -8_388_609.0,
            3e9,
            -3e9,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            1e-40,
            -1e-40,
        ];
        let mut rng = crate::sampling::rng::Pcg32::new(11, 2);
        for _ in 0..200_000 {
            // Random bit patterns cover every exponent, subnormals and NaNs included.
            xs.push(f32::from_bits(rng.next_u32()));
            xs.push((rng.next_f32() - 0.5) * 4096.0);
        }
        for x in xs {
            if x.is_nan() {
                assert!(floor_exact(x).is_nan());
            } else {
                assert_eq!(floor_exact(x).to_bits(), x.floor().to_bits(), "{x:e}");
            }
        }
    }

    /// Mitsuba 3.9.1's checkerboard (to_uv scale 25, color0 0.05, color1 0.3) gives `eval`
    /// 0.05 and `eval_1` 0.3 at uv (0.001, 0.001) and (0.03, 0.03), the reverse at (0.03, 0.001).
    #[test]
    fn checkerboard_scalar_lookup_is_mitsubas() {
        let t = Texture::Checkerboard { color0: Rgb::splat(0.05), color1: Rgb::splat(0.3), to_uv: Affine2::from_scale(Vec2::splat(25.0)) };
        for (uv, colour, scalar) in [((0.001, 0.001), 0.05, 0.3), ((0.03, 0.03), 0.05, 0.3), ((0.03, 0.001), 0.3, 0.05), ((0.001, 0.03), 0.3, 0.05)] {
            let uv = Vec2::new(uv.0, uv.1);
            assert_eq!(t.eval(uv), Rgb::splat(colour), "{uv}");
            assert!((t.eval_f32(uv) - scalar).abs() < 1e-6, "{uv}: {}", t.eval_f32(uv));
        }
    }

    /// Lookups into a bitmap of 8-bit codes give, bit for bit, what lookups into the same
    /// texels as `Rgb` give: every filter and wrap mode, uv inside and outside [0, 1].
    #[test]
    fn eight_bit_lookups_are_the_float_copys() {
        let mut rng = crate::sampling::rng::Pcg32::new(5, 9);
        // A table with every value distinct, so that a wrong channel or code shows.
        let table: &'static [f32; 256] = Box::leak(Box::new(std::array::from_fn(|i| (i as f32 / 255.0).powf(2.2) + i as f32 * 1e-3)));
        for (w, h) in [(1, 1), (2, 3), (17, 5), (64, 33)] {
            let codes: Vec<[u8; 4]> = (0..w * h).map(|_| rng.next_u32().to_le_bytes()).collect();
            let compact = Arc::new(Bitmap::from_8bit(w, h, codes.clone(), table));
            assert!(compact.is_8bit());
            let float = Arc::new(Bitmap::new(w, h, codes.iter().map(|c| Rgb::new(table[c[0] as usize], table[c[1] as usize], table[c[2] as usize])).collect()));
            assert_eq!(compact.data(), float.data());
            // Every channel lies within the 8-bit bitmap's bounds, which are the table's ends.
            let (lo, hi) = compact.channel_bounds().unwrap();
            assert_eq!((lo, hi), (table[0], table[255]));
            assert!(compact.texels().all(|c| [c.r, c.g, c.b].iter().all(|&v| lo <= v && v <= hi)));
            assert!(float.channel_bounds().is_none());
            assert_eq!(compact.mean(), float.mean());
            for filter in [FilterMode::Nearest, FilterMode::Bilinear] {
                for wrap in [WrapMode::Repeat, WrapMode::Mirror, WrapMode::Clamp] {
                    let to_uv = Affine2::from_scale_angle_translation(Vec2::new(1.7, -0.6), 0.3, Vec2::new(-0.2, 0.4));
                    let a = Texture::Bitmap { image: compact.clone(), filter, wrap, to_uv };
                    let b = Texture::Bitmap { image: float.clone(), filter, wrap, to_uv };
                    for _ in 0..2000 {
                        let uv = Vec2::new(rng.next_f32() * 3.0 - 1.0, rng.next_f32() * 3.0 - 1.0);
                        let bits = |c: Rgb| c.to_array().map(f32::to_bits);
                        assert_eq!(bits(a.eval(uv)), bits(b.eval(uv)), "{w}x{h} {filter:?} {wrap:?} {uv}");
                        assert_eq!(a.eval_f32(uv).to_bits(), b.eval_f32(uv).to_bits());
                        assert_eq!(a.eval_f32_grad(uv).to_array().map(f32::to_bits), b.eval_f32_grad(uv).to_array().map(f32::to_bits));
                    }
                    assert_eq!(a.mean(), b.mean());
                }
            }
        }
    }

    /// `eval_inline` (the path kernel's lookup) gives `eval`'s bits: with the inlined floor of
    /// the plain target and, where the CPU has it, of an AVX2 function (as in the kernel);
    /// texel edges, far-off and negative uvs and a NaN included.
    #[test]
    fn inlined_lookups_are_evals() {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        unsafe fn eval_inline_avx2(t: &Texture, p: TexPoint) -> Rgb {
            t.eval_inline(&p)
        }
        let mut rng = crate::sampling::rng::Pcg32::new(11, 3);
        let table: &'static [f32; 256] = Box::leak(Box::new(std::array::from_fn(|i| (i as f32 / 255.0).powf(2.2) + i as f32 * 1e-3)));
        let bits = |c: Rgb| c.to_array().map(f32::to_bits);
        for (w, h) in [(1, 1), (3, 2), (40, 17)] {
            let codes: Vec<[u8; 4]> = (0..w * h).map(|_| rng.next_u32().to_le_bytes()).collect();
            let floats: Vec<Rgb> = (0..w * h).map(|_| Rgb::new(rng.next_f32(), rng.next_f32(), rng.next_f32())).collect();
            for image in [Arc::new(Bitmap::from_8bit(w, h, codes, table)), Arc::new(Bitmap::new(w, h, floats))] {
                for filter in [FilterMode::Nearest, FilterMode::Bilinear] {
                    for wrap in [WrapMode::Repeat, WrapMode::Mirror, WrapMode::Clamp] {
                        let to_uv = Affine2::from_scale_angle_translation(Vec2::new(1.3, 0.8), -0.2, Vec2::new(0.1, -0.3));
                        let t = Texture::Bitmap { image: image.clone(), filter, wrap, to_uv };
                        let mut uvs: Vec<Vec2> = (0..3000).map(|_| Vec2::new(rng.next_f32() * 4.0 - 2.0, rng.next_f32() * 4.0 - 2.0)).collect();
                        // Texel centres and edges (exact floors), huge and non-finite values.
                        uvs.extend((0..=2 * w).map(|i| Vec2::new(i as f32 * 0.5 / w as f32, 0.25)));
                        uvs.extend([Vec2::new(-0.0, 0.0), Vec2::new(3e7, -5e9), Vec2::new(f32::NAN, 0.5), Vec2::new(0.5, f32::INFINITY)]);
                        for uv in uvs {
                            let p = TexPoint::from(uv);
                            let want = bits(t.eval(p));
                            assert_eq!(bits(t.eval_inline(&p)), want, "{w}x{h} {filter:?} {wrap:?} {uv}");
                            #[cfg(target_arch = "x86_64")]
                            if crate::cpu::avx2() {
                                // SAFETY: the CPU has AVX2 (checked just above).
                                assert_eq!(bits(unsafe { eval_inline_avx2(&t, p) }), want, "AVX2 {w}x{h} {filter:?} {wrap:?} {uv}");
                            }
                        }
                    }
                }
            }
        }
        for t in [Texture::Constant(Rgb::new(0.1, 0.2, 0.3)), Texture::Checkerboard { color0: Rgb::BLACK, color1: Rgb::WHITE, to_uv: Affine2::IDENTITY }] {
            let p = TexPoint::from(Vec2::new(0.3, 0.7));
            assert_eq!(bits(t.eval_inline(&p)), bits(t.eval(p)));
        }
    }

    /// A bitmap read as a scalar gives its luminance (Mitsuba's `eval_1` of an RGB bitmap).
    #[test]
    fn bitmap_scalar_lookup_is_luminance() {
        let c = Rgb::new(0.8, 0.2, 0.1);
        let t = Texture::Bitmap { image: Arc::new(Bitmap::new(1, 1, vec![c])), filter: FilterMode::Nearest, wrap: WrapMode::Repeat, to_uv: Affine2::IDENTITY };
        assert!((t.eval_f32(Vec2::new(0.3, 0.6)) - c.luminance()).abs() < 1e-6);
        assert_eq!(Texture::from(c).eval_f32(Vec2::ZERO), c.r);
    }
}
