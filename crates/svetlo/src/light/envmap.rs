//! Latitude-longitude environment map with Mitsuba 3's conventions (`envmap`):
//!
//! * Local frame: +y up. A direction d has u = atan2(d.x, -d.z) / 2π (wrapped to [0,1)),
//!   v = acos(d.y) / π, so the image's top row is straight up, and its left edge
//!   (u = 0) looks down -z, with u growing toward +x.
//! * The image is a grid of samples, not of cells: a column of pixels is repeated at the
//!   right for periodicity, pixel column x sits at u = (x + 1/2) / width, and pixel row y
//!   sits at v = y / (height - 1) (first row at the north pole, last at the south pole).
//!   Radiance is bilinear between those samples, times `scale`.
//! * Sampling: the density over (u, v) is the *bilinear* interpolant of luminance × sin θ
//!   at the grid's vertices, normalised (Mitsuba samples the same function); each cell is
//!   chosen by its integral, then a point inside it by inverting the bilinear patch. The
//!   solid-angle pdf is pdf_uv / (2π² sin θ). `pdf` is the exact density of `sample`, and it
//!   is positive wherever the radiance's luminance is.
//! * `to_world` must be a rotation (directions are normalised after it).

use crate::accel::pages::PagedSlice;
use crate::math::lane::lanes_of;
use crate::math::warp::sin_cos_2pi;
use crate::math::{approx, safe_sqrt, INV_2PI, INV_PI, PI};
use crate::sampling::Distribution1D;
use crate::spectrum::Rgb;
use crate::texture::Bitmap;
use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};
use std::sync::Arc;

#[derive(Clone, Debug)]
pub struct EnvMap {
    pub image: Arc<Bitmap>,
    pub to_world: Mat4,
    pub scale: f32,
    to_local: Mat3,
    /// `to_world`'s rotation part, extracted once for `grid_to_dir`.
    to_world3: Mat3,
    /// Half a texel in u, `0.5 / cols`: precomputed, since a usize-to-float conversion and a
    /// division per lookup were a tenth of the lookup's instructions (same value).
    half_texel: f32,
    /// The sampling density, which holds the vertex grid (radiance and weight together).
    dist: BilinearDistribution,
}

/// A vertex of the grid: its radiance (x, y, z) and its sampling weight (w) side by side,
/// so that evaluating the radiance where a sample landed, or the density where a ray
/// escaped, reads the cache lines the other one just read, and one four-wide bilinear
/// interpolation gives both (lane by lane the same operations as the scalar formulas).
#[derive(Clone, Copy, Debug, Default)]
struct Texel(Vec4);

impl Texel {
    fn new(rgb: Rgb, weight: f32) -> Self {
        Texel(Vec4::new(rgb.r, rgb.g, rgb.b, weight))
    }
    #[inline]
    fn weight(self) -> f32 {
        self.0.w
    }
}

/// `N` lanes' grid points located in the map's grid (see [`EnvMap::cells_of`]): each
/// one's cell (column `ix`, row `iy`) and its place in it (`fx`, `fy`).
#[derive(Clone, Copy, Debug)]
pub struct EnvCells<const N: usize> {
    ix: [u32; N],
    iy: [u32; N],
    fx: [f32; N],
    fy: [f32; N],
}

impl<const N: usize> Default for EnvCells<N> {
    fn default() -> Self {
        EnvCells { ix: [0; N], iy: [0; N], fx: [0.0; N], fy: [0.0; N] }
    }
}

impl EnvMap {
    /// Build the map and its sampling distribution. Degenerate images (empty, one row)
    /// are padded so that nothing downstream can index out of range.
    pub fn new(image: Arc<Bitmap>, to_world: Mat4, scale: f32) -> Self {
        let (w, h) = (image.width, image.height);
        let cols = w.max(1);
        let rows = h.max(2) - 1;
        let texel = |x: usize, y: usize| if w == 0 || h == 0 { Rgb::BLACK } else { image.texel(x % w, y.min(h - 1)) };
        let mut grid = Vec::with_capacity((cols + 1) * (rows + 1));
        for y in 0..=rows {
            for x in 0..=cols {
                grid.push(texel(x % cols, y));
            }
        }
        let texels: Vec<Texel> = (0..=rows)
            .flat_map(|y| {
                let sin_t = (PI * y as f32 / rows as f32).sin().max(0.0);
                let g = &grid;
                (0..=cols).map(move |x| {
                    let rgb = g[y * (cols + 1) + x];
                    Texel::new(rgb, rgb.luminance().max(0.0) * sin_t)
                })
            })
            .collect();
        let dist = BilinearDistribution::new(texels, cols, rows);
        let to_world3 = Mat3::from_mat4(to_world);
        let to_local = to_world3.inverse();
        let half_texel = 0.5 / cols as f32;
        EnvMap { image, to_world, scale, to_local, to_world3, half_texel, dist }
    }

    /// Grid coordinates in [0,1)² (u shifted by half a texel) of a world direction, and sin θ.
    fn dir_to_grid(&self, w: Vec3) -> (Vec2, f32) {
        // The angles by `approx::atan2` (error below 3e-7 rad, a hundredth of a texel of a
        // 100k-wide map): libm's atan2 and acos were a tenth of an environment-lit render.
        let l = (self.to_local * w).normalize_or_zero();
        let mut u = approx::atan2(l.x, -l.z) * INV_2PI - self.half_texel;
        // u is in [-1/2 - 1/(2 cols), 1/2]: wrapped as `u - floor(u)` would (floor is a
        // libm call without SSE4.1).
        if u < 0.0 {
            u += 1.0;
        }
        let sin_t = safe_sqrt(l.x * l.x + l.z * l.z);
        let v = approx::atan2(sin_t, l.y) * INV_PI;
        (Vec2::new(u, v), sin_t)
    }

    /// [`Self::dir_to_grid`] of `N` directions (`d[axis][lane]`), bit for bit: (u, v, sin θ)
    /// per lane. Without branches, so that the path kernel's eight lanes go through it as
    /// SIMD arithmetic (the kernel's AVX2 build vectorises the loop) rather than one by one.
    #[inline(always)]
    pub fn dirs_to_grid<const N: usize>(&self, d: &[[f32; N]; 3]) -> [[f32; N]; 3] {
        let m = &self.to_local;
        let mut out = [[0.0; N]; 3];
        for k in 0..N {
            let (lx, ly, lz) = rotate_normalize(m, d[0][k], d[1][k], d[2][k]);
            let u = approx::atan2_branchless(lx, -lz) * INV_2PI - self.half_texel;
            let sin_t = safe_sqrt(lx * lx + lz * lz);
            out[0][k] = if u < 0.0 { u + 1.0 } else { u };
            out[1][k] = approx::atan2_branchless(sin_t, ly) * INV_PI;
            out[2][k] = sin_t;
        }
        out
    }

    /// Whether the grid is larger than a core's caches (a 512x256 map's is 2 MiB): then the
    /// lookups of incoherent rays miss them, and the path kernel asks for the texels ahead
    /// ([`Self::prefetch_at`]).
    pub fn large(&self) -> bool {
        self.dist.texels.len() >= PREFETCH_TEXELS_MIN
    }

    /// Asks for the texels [`Self::eval_pdf_at`] reads at grid point `g` (as
    /// [`Self::dirs_to_grid`] gives it): a hint, which changes no value.
    #[inline(always)]
    pub fn prefetch_at(&self, g: Vec2) {
        let (ix, iy, _, _) = self.dist.locate(g);
        self.prefetch_cell(ix, iy);
    }

    /// [`Self::prefetch_at`] of lane `l` of `cells` (as [`Self::cells_of`] gives them).
    #[inline(always)]
    pub fn prefetch_in<const N: usize>(&self, cells: &EnvCells<N>, l: usize) {
        self.prefetch_cell(cells.ix[l] as usize, cells.iy[l] as usize);
    }

    #[inline(always)]
    fn prefetch_cell(&self, ix: usize, iy: usize) {
        let i = iy * (self.dist.cols + 1) + ix;
        let t = self.dist.texels.as_ptr();
        // The cell's corners: two in each of two rows (one line a row, but where the first
        // ends a line). Wrapping arithmetic: a prefetch never faults.
        for k in [i, i + 1, i + self.dist.cols + 1, i + self.dist.cols + 2] {
            crate::accel::prefetch(t.wrapping_add(k), 1);
        }
    }

    /// World direction of grid coordinates, and sin θ.
    fn grid_to_dir(&self, g: Vec2) -> (Vec3, f32) {
        // φ = 2π (g.x + 1/(2 cols)) and θ = π g.y = 2π (g.y / 2), without libm.
        let (sp, cp) = sin_cos_2pi(g.x + self.half_texel);
        let (st, ct) = sin_cos_2pi(0.5 * g.y);
        let l = Vec3::new(sp * st, ct, -cp * st);
        ((self.to_world3 * l).normalize_or_zero(), st.max(0.0))
    }

    /// [`Self::grid_to_dir`] of `N` grid points, bit for bit: the directions (`[axis][lane]`)
    /// and sin θ per lane. Without branches, so that the path kernel's lanes go through it as
    /// SIMD arithmetic (lane by lane, its two sine-cosine chains a sample were 2 % of an
    /// environment-lit render).
    #[inline(always)]
    pub fn grid_to_dirs<const N: usize>(&self, g: &[Vec2; N]) -> ([[f32; N]; 3], [f32; N]) {
        let m = &self.to_world3;
        let (mut d, mut sin) = ([[0.0; N]; 3], [0.0; N]);
        for k in 0..N {
            let (sp, cp) = sin_cos_2pi(g[k].x + self.half_texel);
            let (st, ct) = sin_cos_2pi(0.5 * g[k].y);
            let (wx, wy, wz) = rotate_normalize(m, sp * st, ct, -cp * st);
            (d[0][k], d[1][k], d[2][k]) = (wx, wy, wz);
            sin[k] = st.max(0.0);
        }
        (d, sin)
    }

    /// Radiance arriving from direction `w` (pointing away from the scene).
    pub fn eval(&self, w: Vec3) -> Rgb {
        self.eval_grid(self.dir_to_grid(w).0)
    }

    /// [`Self::eval`] and, where `with_pdf` and the radiance is not black, [`Self::pdf`] of
    /// the same direction (else 0), the direction located once: the same values as the two.
    pub fn eval_pdf(&self, w: Vec3, with_pdf: bool) -> (Rgb, f32) {
        let (g, sin_t) = self.dir_to_grid(w);
        self.eval_pdf_at(g, sin_t, with_pdf)
    }

    /// [`Self::eval_pdf`] of the direction at grid point `g` with sin θ `sin_t` (as
    /// [`Self::dirs_to_grid`] locates it).
    #[inline]
    pub fn eval_pdf_at(&self, g: Vec2, sin_t: f32, with_pdf: bool) -> (Rgb, f32) {
        self.eval_pdf_cell(self.dist.locate(g), sin_t, with_pdf)
    }

    /// [`Self::eval_pdf_at`] of lane `l`: its grid point located in `cells` (as
    /// [`Self::cells_of`] gives them), its sin θ `sin_t`.
    #[inline(always)]
    pub fn eval_pdf_in<const N: usize>(&self, cells: &EnvCells<N>, l: usize, sin_t: f32, with_pdf: bool) -> (Rgb, f32) {
        self.eval_pdf_cell((cells.ix[l] as usize, cells.iy[l] as usize, cells.fx[l], cells.fy[l]), sin_t, with_pdf)
    }

    #[inline(always)]
    fn eval_pdf_cell(&self, cell: (usize, usize, f32, f32), sin_t: f32, with_pdf: bool) -> (Rgb, f32) {
        let (le, pdf_uv) = self.eval_cell_pdf(cell);
        if !with_pdf {
            return (le, 0.0);
        }
        if le.is_black() || sin_t <= 0.0 {
            return (le, 0.0);
        }
        (le, pdf_uv / (2.0 * PI * PI * sin_t))
    }

    fn eval_grid(&self, g: Vec2) -> Rgb {
        self.eval_grid_pdf(g).0
    }

    /// The radiance at grid point `g` and `self.dist.pdf(g)`, from one bilinear
    /// interpolation of the cell's texels (radiance and weight together).
    #[inline]
    fn eval_grid_pdf(&self, g: Vec2) -> (Rgb, f32) {
        self.eval_cell_pdf(self.dist.locate(g))
    }

    /// [`Self::eval_grid_pdf`] of a located grid point (cell and fraction, as `locate`).
    #[inline(always)]
    fn eval_cell_pdf(&self, (ix, iy, fx, fy): (usize, usize, f32, f32)) -> (Rgb, f32) {
        let v = self.dist.bilerp(ix, iy, fx, fy);
        (Rgb::new(v.x, v.y, v.z) * self.scale, self.dist.density(v.w))
    }

    /// The cells and fractions (as `locate` gives them, bit for bit) of `N` grid points
    /// (`g` as [`Self::dirs_to_grid`] gives it), without branches: the path kernel's eight
    /// lanes as SIMD arithmetic. Lane by lane, `locate`'s saturating float-to-integer
    /// conversions (which LLVM does not vectorise) were most of an escaped ray's lookup,
    /// twice: its prefetch and its value.
    #[inline(always)]
    pub fn cells_of<const N: usize>(&self, g: &[[f32; N]; 3]) -> EnvCells<N> {
        let d = &self.dist;
        let mut c = EnvCells::default();
        let Some((last_col, last_row)) = d.last_cell else {
            for (k, (&gx, &gy)) in g[0].iter().zip(&g[1]).enumerate() {
                let (ix, iy, fx, fy) = d.locate(Vec2::new(gx, gy));
                (c.ix[k], c.iy[k], c.fx[k], c.fy[k]) = (ix as u32, iy as u32, fx, fy);
            }
            return c;
        };
        for (k, (&gx, &gy)) in g[0].iter().zip(&g[1]).enumerate() {
            let x = at_least_zero(gx * d.cols_f);
            let y = at_least_zero(gy * d.rows_f);
            // Truncating after the clamp to the last cell (an integer) is clamping after
            // truncating, as `locate` does: x >= 0, where truncation is monotone.
            // SAFETY: `at_least_zero` made a NaN 0, and `min` keeps the value in
            // [0, last_col], within i32's range: the conversion is defined (and a vector
            // instruction).
            let (ix, iy) = unsafe { (x.min(last_col).to_int_unchecked::<i32>(), y.min(last_row).to_int_unchecked::<i32>()) };
            // Below 2^24 the cells' indices are exact as floats (`last_cell`).
            c.fx[k] = (x - ix as f32).min(1.0);
            c.fy[k] = (y - iy as f32).min(1.0);
            (c.ix[k], c.iy[k]) = (ix as u32, iy as u32);
        }
        c
    }

    /// A direction toward the environment and its solid-angle density.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, f32)> {
        self.sample_eval(u).map(|(w, pdf, _)| (w, pdf))
    }

    /// [`Self::sample`] and the radiance from the sampled direction, interpolated at the
    /// grid point the sample chose (as Mitsuba's `envmap` does) rather than at the
    /// direction mapped back into the grid: one locate instead of two trigonometric round
    /// trips. The two differ only by the rounding of that round trip.
    pub fn sample_eval(&self, u: Vec2) -> Option<(Vec3, f32, Rgb)> {
        if self.dist.integral <= 0.0 {
            return None;
        }
        self.sample_eval_at(self.dist.sample_point(u))
    }

    /// The grid points [`Self::sample_eval`] samples for the lanes set in `lanes` (the
    /// others' are zero), drawn in stages across the lanes: every lane's row, then every
    /// lane's cell, then the rest. A large map's tables miss the caches, and lane after lane
    /// each lookup had waited alone (`Distribution1D::find`: the guide entry, then the CDF);
    /// stage by stage the lanes' misses overlap. [`Self::sample_eval_at`] finishes each
    /// sample. The distribution's integral must be positive (`sample_eval` returns None before
    /// it samples otherwise: [`Self::samples`]).
    #[inline]
    pub fn sample_points<const N: usize>(&self, u: &[Vec2; N], lanes: u32) -> [Vec2; N] {
        self.dist.sample_points(u, lanes)
    }

    /// Whether [`Self::sample_eval`] samples at all (else it returns None for every u).
    pub fn samples(&self) -> bool {
        self.dist.integral > 0.0
    }

    /// The rest of [`Self::sample_eval`] at the grid point `g` it sampled.
    #[inline(always)]
    pub fn sample_eval_at(&self, g: Vec2) -> Option<(Vec3, f32, Rgb)> {
        self.sample_eval_toward(g, || self.grid_to_dir(g))
    }

    /// [`Self::sample_eval_at`] with `g`'s direction and sin θ from `dir` (as
    /// [`Self::grid_to_dir`] or [`Self::grid_to_dirs`] gives them).
    #[inline(always)]
    pub fn sample_eval_toward(&self, g: Vec2, dir: impl FnOnce() -> (Vec3, f32)) -> Option<(Vec3, f32, Rgb)> {
        let (le, pdf_uv) = self.eval_grid_pdf(g);
        if pdf_uv <= 0.0 {
            return None;
        }
        let (w, sin_t) = dir();
        if sin_t <= 0.0 {
            return None;
        }
        Some((w, pdf_uv / (2.0 * PI * PI * sin_t), le))
    }

    /// Solid-angle density of `sample` choosing `w`.
    pub fn pdf(&self, w: Vec3) -> f32 {
        let (g, sin_t) = self.dir_to_grid(w);
        if sin_t <= 0.0 {
            return 0.0;
        }
        self.dist.pdf(g) / (2.0 * PI * PI * sin_t)
    }

    /// ∫ luminance(L) dω over the sphere (from the sampling function, so sin θ is
    /// interpolated like the luminance), including `scale`.
    pub fn luminance_integral(&self) -> f32 {
        2.0 * PI * PI * self.dist.integral * self.scale
    }
}

/// Grids of at least this many vertices (16 bytes each: 1 MiB) are asked for ahead of lookups.
const PREFETCH_TEXELS_MIN: usize = 1 << 16;

/// `(m * Vec3::new(x, y, z)).normalize_or_zero()` as glam computes them, on plain floats
/// without branches, so that the lane loops of `dirs_to_grid` and `grid_to_dirs` vectorise.
#[inline(always)]
fn rotate_normalize(m: &Mat3, x: f32, y: f32, z: f32) -> (f32, f32, f32) {
    let wx = (m.x_axis.x * x + m.y_axis.x * y) + m.z_axis.x * z;
    let wy = (m.x_axis.y * x + m.y_axis.y * y) + m.z_axis.y * z;
    let wz = (m.x_axis.z * x + m.y_axis.z * y) + m.z_axis.z * z;
    let rcp = 1.0 / ((wx * wx + wy * wy) + wz * wz).sqrt();
    let ok = rcp.is_finite() && rcp > 0.0;
    if ok {
        (wx * rcp, wy * rcp, wz * rcp)
    } else {
        (0.0, 0.0, 0.0)
    }
}

/// Sample t in [0,1) with density proportional to (1 - t) a + t b (a, b >= 0).
#[inline]
fn sample_linear(u: f32, a: f32, b: f32) -> f32 {
    if a == b {
        return u;
    }
    // Inverse CDF in a form without cancellation: t = u (a + b) / (a + sqrt(a² (1-u) + b² u)).
    let den = a + ((1.0 - u) * a * a + u * b * b).sqrt();
    if den <= 0.0 {
        return 0.0;
    }
    (u * (a + b) / den).clamp(0.0, crate::math::ONE_MINUS_EPSILON)
}

/// A density on [0,1]² proportional to the bilinear interpolant of non-negative values
/// at the vertices of a `cols` x `rows` grid of cells.
#[derive(Clone, Debug)]
struct BilinearDistribution {
    /// The vertices' values (`weight`), with the radiance they came from (on huge pages
    /// when large: escaped rays' lookups land anywhere in it).
    texels: PagedSlice<Texel>,
    /// Cells: `cols` wide (= image width), `rows` high (= image height - 1).
    cols: usize,
    rows: usize,
    /// `cols` and `rows` as floats, converted once: a usize-to-float conversion is a branchy
    /// sequence on x86-64 without AVX-512.
    cols_f: f32,
    rows_f: f32,
    /// The last cell's column and row as floats, for `EnvMap::cells_of`: None where one is
    /// 2^24 or more (not every index is a float there; then it locates lane by lane).
    last_cell: Option<(f32, f32)>,
    /// Rows of cells by the sum of their cells' integrals.
    marginal: Distribution1D,
    /// Cells within each row by their integral (mean of the 4 corners).
    conditional: Vec<Distribution1D>,
    /// ∫ f over [0,1]².
    integral: f32,
}

impl BilinearDistribution {
    fn new(texels: Vec<Texel>, cols: usize, rows: usize) -> Self {
        let stride = cols + 1;
        let f = |i: usize| texels[i].weight();
        let conditional: Vec<Distribution1D> = (0..rows)
            .map(|y| {
                let cells: Vec<f32> =
                    (0..cols).map(|x| 0.25 * (f(y * stride + x) + f(y * stride + x + 1) + f((y + 1) * stride + x) + f((y + 1) * stride + x + 1))).collect();
                Distribution1D::new(&cells)
            })
            .collect();
        // Distribution1D's integral is the mean over its cells: a row's share of the square.
        let row_integrals: Vec<f32> = conditional.iter().map(|c| c.integral).collect();
        let marginal = Distribution1D::new(&row_integrals);
        let integral = marginal.integral;
        let last_cell = (cols <= 1 << 24 && rows <= 1 << 24).then(|| ((cols - 1) as f32, (rows - 1) as f32));
        BilinearDistribution {
            texels: PagedSlice::new(texels),
            cols,
            rows,
            cols_f: cols as f32,
            rows_f: rows as f32,
            last_cell,
            marginal,
            conditional,
            integral,
        }
    }

    #[inline]
    fn corners(&self, ix: usize, iy: usize) -> [f32; 4] {
        let s = self.cols + 1;
        let f = |i: usize| self.texels[i].weight();
        [f(iy * s + ix), f(iy * s + ix + 1), f((iy + 1) * s + ix), f((iy + 1) * s + ix + 1)]
    }

    /// The texels' bilinear interpolant in cell (ix, iy) at fraction (fx, fy): radiance in
    /// x, y, z and the sampling function in w.
    #[inline]
    fn bilerp(&self, ix: usize, iy: usize, fx: f32, fy: f32) -> Vec4 {
        let s = self.cols + 1;
        let i = iy * s + ix;
        let (top, bottom) = (&self.texels[i..i + 2], &self.texels[i + s..i + s + 2]);
        (top[0].0 * (1.0 - fx) + top[1].0 * fx) * (1.0 - fy) + (bottom[0].0 * (1.0 - fx) + bottom[1].0 * fx) * fy
    }

    /// A point with density `pdf` (the integral must be positive): a row by the marginal, a
    /// cell in it by the conditional, a point in the cell by inverting the bilinear patch.
    #[inline]
    fn sample_point(&self, u: Vec2) -> Vec2 {
        let (iy, _, uy) = self.marginal.sample_discrete(u.y);
        let (ix, _, ux) = self.conditional[iy].sample_discrete(u.x);
        self.point_in_cell(ix, iy, ux, uy)
    }

    /// [`Self::sample_point`] of the lanes set in `lanes` (the others' points are zero),
    /// stage by stage (see `EnvMap::sample_points`): each stage asks for what the next
    /// one reads.
    #[inline(always)]
    fn sample_points<const N: usize>(&self, u: &[Vec2; N], lanes: u32) -> [Vec2; N] {
        // Lanes past N are none of the map's.
        let set = || lanes_of(lanes & ((1u64 << N) - 1) as u32);
        let (mut iy, mut uy) = ([0usize; N], [0.0f32; N]);
        for l in set() {
            (iy[l], _, uy[l]) = self.marginal.sample_discrete(u[l].y);
            self.conditional[iy[l]].prefetch_guide(u[l].x);
        }
        for l in set() {
            self.conditional[iy[l]].prefetch_cdf(u[l].x);
        }
        let (mut ix, mut ux) = ([0usize; N], [0.0f32; N]);
        let t = self.texels.as_ptr();
        for l in set() {
            (ix[l], _, ux[l]) = self.conditional[iy[l]].sample_discrete(u[l].x);
            // The cell's corners, two in each of two rows (wrapping: a hint never faults).
            let i = iy[l] * (self.cols + 1) + ix[l];
            for k in [i, i + 1, i + self.cols + 1, i + self.cols + 2] {
                crate::accel::prefetch(t.wrapping_add(k), 1);
            }
        }
        let mut g = [Vec2::ZERO; N];
        for l in set() {
            g[l] = self.point_in_cell(ix[l], iy[l], ux[l], uy[l]);
        }
        g
    }

    /// The point of [`Self::sample_point`] in cell (ix, iy), from its remapped numbers.
    #[inline(always)]
    fn point_in_cell(&self, ix: usize, iy: usize, ux: f32, uy: f32) -> Vec2 {
        let [f00, f10, f01, f11] = self.corners(ix, iy);
        // Inside the cell: v from its marginal (linear), then u given v (linear).
        let ty = sample_linear(uy, f00 + f10, f01 + f11);
        let tx = sample_linear(ux, f00 + (f01 - f00) * ty, f10 + (f11 - f10) * ty);
        Vec2::new((cell_f32(ix) + tx) / self.cols_f, (cell_f32(iy) + ty) / self.rows_f)
    }

    /// Cell and fractional position of grid coordinates in [0,1]².
    #[inline]
    fn locate(&self, g: Vec2) -> (usize, usize, f32, f32) {
        let x = at_least_zero(g.x * self.cols_f);
        let y = at_least_zero(g.y * self.rows_f);
        // Through u32: x and y are in [0, size] (a NaN became 0 above), far below 2^32, so
        // the conversions are the usize ones, each a single instruction.
        let ix = (x as u32 as usize).min(self.cols - 1);
        let iy = (y as u32 as usize).min(self.rows - 1);
        (ix, iy, (x - cell_f32(ix)).min(1.0), (y - cell_f32(iy)).min(1.0))
    }

    fn pdf(&self, g: Vec2) -> f32 {
        let (ix, iy, fx, fy) = self.locate(g);
        self.density(self.bilerp(ix, iy, fx, fy).w)
    }

    /// The density of a point where the sampling function is `f`.
    #[inline]
    fn density(&self, f: f32) -> f32 {
        if self.integral <= 0.0 {
            return 0.0;
        }
        f / self.integral
    }
}

/// `v.max(0.0)` with the sign of a zero kept (-0 stays -0) and a NaN taken as 0, the same
/// in scalar and vector code (`f32::max` leaves a zero's sign to the build: `locate` and
/// `EnvMap::cells_of` must agree bit for bit).
#[inline(always)]
fn at_least_zero(v: f32) -> f32 {
    if v >= 0.0 {
        v
    } else {
        0.0
    }
}

/// A cell index as a float: `i as f32` for every index of a grid (below 2^32 cells a
/// side), converted from 32 bits, a single instruction where a usize is not.
#[inline]
fn cell_f32(i: usize) -> f32 {
    i as u32 as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_sampling_inverts_its_cdf() {
        for &(a, b) in &[(1.0f32, 3.0f32), (2.0, 0.0), (0.0, 5.0), (1.0, 1.0)] {
            for k in 0..=10 {
                let u = k as f32 / 10.0 * 0.999;
                let t = sample_linear(u, a, b);
                let cdf = (a * t + 0.5 * (b - a) * t * t) / (0.5 * (a + b));
                assert!((cdf - u).abs() < 1e-5, "a={a} b={b} u={u} t={t} cdf={cdf}");
            }
        }
    }

    #[test]
    fn bilinear_pdf_integrates_to_one() {
        let f = vec![0.0, 1.0, 4.0, 2.0, 0.5, 0.0, 3.0, 1.0, 0.0, 0.0, 7.0, 1.0];
        let d = BilinearDistribution::new(f.into_iter().map(|weight| Texel::new(Rgb::BLACK, weight)).collect(), 3, 2);
        let n = 600;
        let mut s = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                s += d.pdf(Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32)) as f64;
            }
        }
        assert!((s / (n * n) as f64 - 1.0).abs() < 1e-4, "{}", s / (n * n) as f64);
    }

    #[test]
    fn eval_pdf_is_eval_and_pdf() {
        let (w, h) = (16usize, 8usize);
        let data: Vec<Rgb> = (0..w * h).map(|i| Rgb::new((i % 7) as f32, (i % 3) as f32 * 0.5, if i % 5 == 0 { 0.0 } else { 1.0 })).collect();
        let env = EnvMap::new(Arc::new(Bitmap::new(w, h, data)), Mat4::from_rotation_x(0.3), 1.5);
        let mut rng = crate::sampling::rng::Pcg32::new(3, 4);
        for k in 0..2000 {
            let d = if k == 0 { Vec3::Y } else { crate::math::warp::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32())) };
            let (le, pdf) = env.eval_pdf(d, true);
            assert_eq!(le, env.eval(d));
            let want = if le.is_black() { 0.0 } else { env.pdf(d) };
            assert_eq!(pdf.to_bits(), want.to_bits(), "{d}");
            assert_eq!(env.eval_pdf(d, false), (le, 0.0));
        }
    }

    #[test]
    fn four_wide_bilinear_is_the_scalar_formula() {
        // Radiance and density come from one Vec4 interpolation: lane by lane it must be the
        // scalar bilinear formula, bit for bit (images are unchanged by packing them).
        let (w, h) = (9usize, 6usize);
        let data: Vec<Rgb> = (0..w * h).map(|i| Rgb::new(0.1 + (i % 7) as f32 * 0.37, (i % 3) as f32 * 1.3, 0.01 * i as f32)).collect();
        let env = EnvMap::new(Arc::new(Bitmap::new(w, h, data)), Mat4::IDENTITY, 0.7);
        let mut rng = crate::sampling::rng::Pcg32::new(5, 9);
        for _ in 0..5000 {
            let g = Vec2::new(rng.next_f32(), rng.next_f32());
            let (ix, iy, fx, fy) = env.dist.locate(g);
            let s = env.dist.cols + 1;
            let t = |x: usize, y: usize| env.dist.texels[y * s + x].0;
            let lerp = |a: f32, b: f32, c: f32, d: f32| (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy;
            let (a, b, c, d) = (t(ix, iy), t(ix + 1, iy), t(ix, iy + 1), t(ix + 1, iy + 1));
            let rgb = Rgb::new(lerp(a.x, b.x, c.x, d.x), lerp(a.y, b.y, c.y, d.y), lerp(a.z, b.z, c.z, d.z)) * 0.7;
            let pdf = lerp(a.w, b.w, c.w, d.w) / env.dist.integral;
            let (got_rgb, got_pdf) = env.eval_grid_pdf(g);
            assert_eq!([got_rgb.r, got_rgb.g, got_rgb.b, got_pdf].map(f32::to_bits), [rgb.r, rgb.g, rgb.b, pdf].map(f32::to_bits), "{g}");
        }
    }

    #[test]
    fn sample_eval_radiance_is_eval_of_its_direction() {
        // The radiance `sample_eval` interpolates at its grid point must be the map's
        // radiance toward the direction it returns (up to the direction's round trip), and
        // its direction and density those of `sample`, bit for bit.
        let (w, h) = (32usize, 17usize);
        let data: Vec<Rgb> = (0..w * h).map(|i| Rgb::new(1.0 + (i % 7) as f32, 0.5 + (i % 3) as f32, if i % 5 == 0 { 0.0 } else { 2.0 })).collect();
        let env = EnvMap::new(Arc::new(Bitmap::new(w, h, data)), Mat4::from_rotation_z(0.4), 1.5);
        let mut rng = crate::sampling::rng::Pcg32::new(7, 1);
        let mut n = 0;
        for _ in 0..5000 {
            let u = Vec2::new(rng.next_f32(), rng.next_f32());
            let got = env.sample_eval(u);
            assert_eq!(got.map(|(d, p, _)| (d, p.to_bits())), env.sample(u).map(|(d, p)| (d, p.to_bits())));
            let Some((d, pdf, le)) = got else { continue };
            n += 1;
            let want = env.eval(d);
            for (a, b) in [(le.r, want.r), (le.g, want.g), (le.b, want.b)] {
                assert!((a - b).abs() <= 2e-3 * b.abs().max(1.0), "u {u}: {le:?} vs {want:?}");
            }
            assert!((pdf - env.pdf(d)).abs() <= 2e-3 * pdf, "u {u}: pdf {pdf} vs {}", env.pdf(d));
        }
        assert!(n > 4000, "{n} samples");
    }

    #[test]
    fn lanes_sample_as_one_lane_does() {
        // Wide enough for guide tables (64 cells and more), with black columns and rows so
        // that some searches land on empty intervals.
        let (w, h) = (80usize, 70usize);
        let data: Vec<Rgb> = (0..w * h)
            .map(|i| if i % w < 3 || (i / w) % 9 == 4 { Rgb::BLACK } else { Rgb::new(1.0 + (i % 7) as f32, 0.5 + (i % 3) as f32, (i % 5) as f32) })
            .collect();
        let env = EnvMap::new(Arc::new(Bitmap::new(w, h, data)), Mat4::from_rotation_y(0.7), 1.5);
        let mut rng = crate::sampling::rng::Pcg32::new(11, 2);
        let bits = |s: Option<(Vec3, f32, Rgb)>| s.map(|(d, p, le)| (d.to_array().map(f32::to_bits), p.to_bits(), [le.r, le.g, le.b].map(f32::to_bits)));
        for k in 0..2000 {
            let u: [Vec2; 8] = std::array::from_fn(|_| Vec2::new(rng.next_f32(), rng.next_f32()));
            let lanes = if k % 3 == 0 { 0xff } else { rng.next_u32() & 0xff };
            let g = env.sample_points(&u, lanes);
            for l in (0..8).filter(|l| lanes & (1 << l) != 0) {
                assert_eq!(bits(env.sample_eval_at(g[l])), bits(env.sample_eval(u[l])), "lane {l} u {}", u[l]);
            }
        }
    }

    #[test]
    fn lanes_grid_directions_are_grid_to_dir() {
        let data: Vec<Rgb> = (0..12).map(|i| Rgb::splat(i as f32)).collect();
        let mut rng = crate::sampling::rng::Pcg32::new(5, 9);
        for to_world in [Mat4::IDENTITY, Mat4::from_rotation_y(0.7), Mat4::from_euler(glam::EulerRot::XYZ, 0.3, -1.2, 2.5)] {
            for (w, h) in [(4, 3), (2048, 1024)] {
                let data: Vec<Rgb> = (0..w * h).map(|i| data[i % 12]).collect();
                let env = EnvMap::new(Arc::new(Bitmap::new(w, h, data)), to_world, 1.0);
                // Random points, the poles, the seam and cell edges.
                let mut g: Vec<Vec2> = (0..4000).map(|_| Vec2::new(rng.next_f32(), rng.next_f32())).collect();
                g.extend(
                    [0.0, 1.0, 0.5, 0.25, 0.75, 1.0 - f32::EPSILON, f32::MIN_POSITIVE]
                        .iter()
                        .flat_map(|&a| [Vec2::new(a, 0.0), Vec2::new(0.0, a), Vec2::new(a, 1.0), Vec2::new(1.0, a), Vec2::splat(a)]),
                );
                for c in g.chunks(8).filter(|c| c.len() == 8) {
                    let c: [Vec2; 8] = std::array::from_fn(|l| c[l]);
                    let (d, sin) = env.grid_to_dirs(&c);
                    for (l, &gl) in c.iter().enumerate() {
                        let (want, want_sin) = env.grid_to_dir(gl);
                        let got = Vec3::new(d[0][l], d[1][l], d[2][l]);
                        assert_eq!(got.to_array().map(f32::to_bits), want.to_array().map(f32::to_bits), "{gl}");
                        assert_eq!(sin[l].to_bits(), want_sin.to_bits(), "{gl}");
                    }
                }
            }
        }
    }

    #[test]
    fn grid_lookup_is_the_reference_formula() {
        // `dir_to_grid` and `locate` use precomputed float sizes and 32-bit conversions: they
        // must give the usize formulas' values bit for bit, on random directions, the poles,
        // the seam (u = 0/1: directions along -z, either side of it), and grid edges.
        let reference_locate = |g: Vec2, cols: usize, rows: usize| {
            let x = (g.x * cols as f32).max(0.0);
            let y = (g.y * rows as f32).max(0.0);
            let ix = (x as usize).min(cols - 1);
            let iy = (y as usize).min(rows - 1);
            (ix, iy, (x - ix as f32).min(1.0), (y - iy as f32).min(1.0))
        };
        for (w, h, rot) in
            [(512usize, 256usize, Mat4::IDENTITY), (7, 5, Mat4::from_rotation_y(0.9)), (1, 2, Mat4::IDENTITY), (3000, 1, Mat4::from_rotation_x(-0.2))]
        {
            let data: Vec<Rgb> = (0..w * h).map(|i| Rgb::new(1.0 + (i % 5) as f32, 0.5, 2.0)).collect();
            let env = EnvMap::new(Arc::new(Bitmap::new(w, h, data)), rot, 1.0);
            let mut rng = crate::sampling::rng::Pcg32::new(11, w as u64);
            let mut dirs = vec![Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z, Vec3::X, -Vec3::X, Vec3::ZERO];
            for e in [0.0f32, -0.0, 1e-7, -1e-7, 1e-30, -1e-30] {
                dirs.extend([Vec3::new(e, 0.3, -1.0), Vec3::new(e, -0.7, -1.0), Vec3::new(e, 1.0, e), Vec3::new(e, -1.0, -e)]);
            }
            for _ in 0..20_000 {
                dirs.push(crate::math::warp::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32())));
            }
            let bits = |(ix, iy, fx, fy): (usize, usize, f32, f32)| (ix, iy, fx.to_bits(), fy.to_bits());
            // The lanes' version, on these directions and on ones not of unit length (the
            // kernel's rays), special values among them.
            let mut lane_dirs: Vec<Vec3> = dirs.iter().flat_map(|&d| [d, d * 3.7, d * 1e-20, d * 2e19]).collect();
            lane_dirs.extend([Vec3::splat(f32::NAN), Vec3::new(f32::INFINITY, 1.0, 0.0), Vec3::new(1e-45, 0.0, -1e-45)]);
            for chunk in lane_dirs.chunks(8) {
                let mut d = [[0.0f32; 8]; 3];
                for (k, w) in chunk.iter().enumerate() {
                    (d[0][k], d[1][k], d[2][k]) = (w.x, w.y, w.z);
                }
                let lanes = env.dirs_to_grid(&d);
                for (k, &w) in chunk.iter().enumerate() {
                    let (g, st) = env.dir_to_grid(w);
                    assert_eq!((lanes[0][k].to_bits(), lanes[1][k].to_bits(), lanes[2][k].to_bits()), (g.x.to_bits(), g.y.to_bits(), st.to_bits()), "{w}");
                }
            }
            for d in dirs {
                let l = (env.to_local * d).normalize_or_zero();
                let mut u = approx::atan2(l.x, -l.z) * INV_2PI - 0.5 / env.dist.cols as f32;
                if u < 0.0 {
                    u += 1.0;
                }
                let sin_t = safe_sqrt(l.x * l.x + l.z * l.z);
                let v = approx::atan2(sin_t, l.y) * INV_PI;
                let (g, st) = env.dir_to_grid(d);
                assert_eq!((g.x.to_bits(), g.y.to_bits(), st.to_bits()), (u.to_bits(), v.to_bits(), sin_t.to_bits()), "{d}");
                assert_eq!(bits(env.dist.locate(g)), bits(reference_locate(g, env.dist.cols, env.dist.rows)), "{d}");
            }
            let edges = [
                Vec2::ZERO,
                Vec2::ONE,
                Vec2::new(1.0 - f32::EPSILON, 0.5),
                Vec2::new(-0.0, 1.0),
                Vec2::new(f32::NAN, 0.2),
                Vec2::new(0.999_999_9, 0.999_999_9),
            ];
            for g in edges {
                assert_eq!(bits(env.dist.locate(g)), bits(reference_locate(g, env.dist.cols, env.dist.rows)), "{g}");
            }
            // The lanes' cells: `locate`'s, on the lanes' grid points and on points off the
            // grid (NaN, infinite, negative, huge).
            let mut points: Vec<Vec2> = Vec::new();
            for chunk in lane_dirs.chunks(8) {
                let mut d = [[0.0f32; 8]; 3];
                for (k, w) in chunk.iter().enumerate() {
                    (d[0][k], d[1][k], d[2][k]) = (w.x, w.y, w.z);
                }
                let g = env.dirs_to_grid(&d);
                points.extend((0..chunk.len()).map(|k| Vec2::new(g[0][k], g[1][k])));
            }
            points.extend(edges);
            points.extend([
                Vec2::splat(f32::INFINITY),
                Vec2::splat(-f32::INFINITY),
                Vec2::new(-3.0, 7.0),
                Vec2::new(3e9, -1e-30),
                Vec2::new(f32::NAN, f32::NAN),
            ]);
            for chunk in points.chunks(8) {
                let mut g = [[0.0f32; 8]; 3];
                for (k, p) in chunk.iter().enumerate() {
                    (g[0][k], g[1][k]) = (p.x, p.y);
                }
                let cells = env.cells_of(&g);
                for (k, &p) in chunk.iter().enumerate() {
                    let lane = (cells.ix[k] as usize, cells.iy[k] as usize, cells.fx[k], cells.fy[k]);
                    assert_eq!(bits(lane), bits(env.dist.locate(p)), "{p}");
                    assert_eq!(env.eval_pdf_in(&cells, k, 0.5, true), env.eval_pdf_at(p, 0.5, true), "{p}");
                }
            }
            // Sampled grid points: the cell's position divided by the precomputed sizes.
            for _ in 0..5000 {
                let u = Vec2::new(rng.next_f32(), rng.next_f32());
                let d = &env.dist;
                let (iy, _, uy) = d.marginal.sample_discrete(u.y);
                let (ix, _, ux) = d.conditional[iy].sample_discrete(u.x);
                let [f00, f10, f01, f11] = d.corners(ix, iy);
                let ty = sample_linear(uy, f00 + f10, f01 + f11);
                let tx = sample_linear(ux, f00 + (f01 - f00) * ty, f10 + (f11 - f10) * ty);
                let want = Vec2::new((ix as f32 + tx) / d.cols as f32, (iy as f32 + ty) / d.rows as f32);
                let got = d.sample_point(u);
                assert_eq!((got.x.to_bits(), got.y.to_bits()), (want.x.to_bits(), want.y.to_bits()), "{u}");
            }
        }
    }

    #[test]
    fn prefetch_reads_nothing_out_of_the_grid() {
        // A hint anywhere a lookup may land, and outside it (NaN, the edges): it must change
        // no value and never touch memory (prefetches do not fault).
        let (w, h) = (300usize, 220usize);
        let data: Vec<Rgb> = (0..w * h).map(|i| Rgb::new((i % 7) as f32, 1.0, 2.0)).collect();
        let env = EnvMap::new(Arc::new(Bitmap::new(w, h, data)), Mat4::IDENTITY, 1.0);
        assert!(env.large());
        let g = Vec2::new(0.3, 0.7);
        let before = env.eval_pdf_at(g, 0.5, true);
        for p in [g, Vec2::ZERO, Vec2::ONE, Vec2::splat(f32::NAN), Vec2::new(-1.0, 2.0), Vec2::splat(f32::INFINITY)] {
            env.prefetch_at(p);
        }
        assert_eq!(env.eval_pdf_at(g, 0.5, true), before);
    }

    #[test]
    fn mitsuba_orientation() {
        // 4x3 image: a distinct color per pixel; look up pixel centers by direction.
        let (w, h) = (4usize, 3usize);
        let data: Vec<Rgb> = (0..w * h).map(|i| Rgb::new(i as f32, 0.0, 0.0)).collect();
        let env = EnvMap::new(Arc::new(Bitmap::new(w, h, data)), Mat4::IDENTITY, 2.0);
        let dir = |u: f32, v: f32| {
            let (phi, th) = (2.0 * PI * u, PI * v);
            Vec3::new(phi.sin() * th.sin(), th.cos(), -phi.cos() * th.sin())
        };
        // Row 0 is the north pole (+y); row 1 sits at the equator (v = 1/2), row 2 at -y.
        for x in 0..w {
            let u = (x as f32 + 0.5) / w as f32;
            let got = env.eval(dir(u, 0.5)).r;
            assert!((got - 2.0 * (4 + x) as f32).abs() < 1e-3, "column {x}: {got}");
            // Halfway between rows 1 and 2 (v = 3/4): their mean.
            let got = env.eval(dir(u, 0.75)).r;
            assert!((got - 2.0 * (6 + x) as f32).abs() < 1e-3, "column {x}, v=3/4: {got}");
        }
        // Column 0's center is at u = 1/8: phi = 45 degrees from -z toward +x.
        let d = Vec3::new(1.0, 0.0, -1.0).normalize();
        assert!((env.eval(d).r - 2.0 * 4.0).abs() < 1e-3);
        // A rotation of the map rotates the lookup.
        let rot = Mat4::from_rotation_y(0.7);
        let env_r = EnvMap::new(env.image.clone(), rot, 2.0);
        let q = dir(0.3, 0.4);
        assert!((env_r.eval(rot.transform_vector3(q)).r - env.eval(q).r).abs() < 1e-3);
    }
}
