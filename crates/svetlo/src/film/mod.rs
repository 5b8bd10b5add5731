//! The film: pixel reconstruction from samples with a filter, and the images a render writes.
//!
//! Camera-side integrators render tiles ([`FilmTile`]) in parallel and merge them in a fixed
//! order, so floating-point sums, and thus images, do not depend on scheduling.

pub mod compare;
pub mod filter;
pub mod image;
pub mod raw;

pub use self::image::Image;
pub use filter::Filter;
use filter::FilterWeights;

use crate::spectrum::Rgb;
use glam::{Vec2, Vec4, Vec4Swizzles};

#[derive(Clone, Copy, Debug, Default)]
struct Pixel {
    /// Sum of filter-weighted radiance.
    sum: Rgb,
    /// Sum of filter weights.
    weight: f64,
    /// Per-pixel sample statistics (unfiltered, the samples whose position falls in the pixel):
    /// sum and sum of squares, for the per-sample variance image.
    s1: Rgb,
    s2: Rgb,
    n: u32,
}

impl Pixel {
    #[inline]
    fn add(&mut self, s: &Pixel) {
        self.sum += s.sum;
        self.weight += s.weight;
        self.s1 += s.s1;
        self.s2 += s.s2;
        self.n += s.n;
    }

    /// A sample into the variance statistics.
    #[inline(always)]
    fn add_stats(&mut self, l: Rgb) {
        self.s1 += l;
        self.s2 += l * l;
        self.n += 1;
    }

    /// A box-filtered sample: its statistics and its whole weight.
    #[inline(always)]
    fn add_box(&mut self, l: Rgb) {
        self.add_stats(l);
        self.sum += l;
        self.weight += 1.0;
    }
}

/// The pixel owning a run of samples (the path kernel hands them over pixel by pixel), its
/// values held in locals: the run's samples add to them and they are stored once when the
/// run ends. The same additions in the same order from the pixel's stored values as adding
/// each sample in place, so the same bits; a sample inside the square of raster positions
/// whose floors are the run's skips the owner search.
struct OwnerRun {
    k: usize,
    /// Pixel `k`'s column and row in the tile.
    col: usize,
    row: usize,
    /// The square `[lo, hi)`, all of whose positions pixel `k` owns (NaN: no run yet).
    lo: Vec2,
    hi: Vec2,
    px: Pixel,
}

impl OwnerRun {
    fn new() -> Self {
        OwnerRun { k: usize::MAX, col: 0, row: 0, lo: Vec2::NAN, hi: Vec2::NAN, px: Pixel::default() }
    }

    #[inline(always)]
    fn holds(&self, p: Vec2) -> bool {
        p.x >= self.lo.x && p.x < self.hi.x && p.y >= self.lo.y && p.y < self.hi.y
    }
}

/// An image in the making, or a tile of one. Coordinates are the full film's raster.
#[derive(Clone, Debug)]
pub struct FilmTile {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
    filter: Filter,
    weights: FilterWeights,
    pixels: Vec<Pixel>,
    /// The AOV layers' filter-weighted sums (sharing the beauty's weights), pixel by pixel:
    /// channel c of pixel k's layer i at `(k * n_layers + i) * 3 + c`, so that a sample's
    /// footprint is walked once for all its layers, each pixel's in one vector loop.
    layers: Vec<f32>,
    n_layers: usize,
    /// Nothing added since the tile was made or cleared: every sum is zero, so clearing and
    /// adding it can be skipped (films that only take splats never touch their pixels).
    blank: bool,
}

impl FilmTile {
    pub fn new(x0: u32, y0: u32, x1: u32, y1: u32, filter: Filter) -> Self {
        FilmTile {
            x0,
            y0,
            x1,
            y1,
            filter,
            weights: FilterWeights::new(filter),
            pixels: vec![Pixel::default(); ((x1 - x0) * (y1 - y0)) as usize],
            layers: Vec::new(),
            n_layers: 0,
            blank: true,
        }
    }

    /// Back to black, keeping the memory (layers already allocated stay so, as zeros).
    pub fn clear(&mut self) {
        if !self.blank {
            self.pixels.fill(Pixel::default());
            self.layers.fill(0.0);
            self.blank = true;
        }
    }

    /// Add another tile's sums (the same rectangle and layers) to this one's.
    pub fn add(&mut self, o: &FilmTile) {
        debug_assert_eq!((self.x0, self.y0, self.x1, self.y1, self.n_layers), (o.x0, o.y0, o.x1, o.y1, o.n_layers));
        if o.blank {
            return;
        }
        self.blank = false;
        for (d, s) in self.pixels.iter_mut().zip(&o.pixels) {
            d.add(s);
        }
        add_buffer(&mut self.layers, &o.layers);
    }

    /// Gives the tile `n` AOV layers, all black.
    fn set_layers(&mut self, n: usize) {
        self.n_layers = n;
        self.layers = Vec::new();
    }

    /// Allocates the layer sums on first use: films that only take splats (light tracing,
    /// Metropolis) never need them.
    #[inline]
    fn ensure_layers(&mut self) {
        if self.layers.is_empty() && self.n_layers > 0 {
            self.layers = vec![0.0; self.pixels.len() * self.n_layers * 3];
        }
    }

    /// Layer `i`'s sum at pixel index `k`.
    #[inline]
    fn layer_sum(&self, k: usize, i: usize) -> Rgb {
        rgb_at(&self.layers, (k * self.n_layers + i) * 3)
    }

    /// Add a sample to the beauty and, with the same filter weights, `aov[i]` to layer i.
    pub fn add_sample_layers(&mut self, p: Vec2, l: Rgb, aov: &[Rgb]) {
        self.add_sample_touched(p, l, aov, u32::MAX);
    }

    /// [`Self::add_sample_touched`] for a run of samples (position, radiance, layers, touched
    /// mask), in order. With the box filter each takes one pixel, found once for the beauty
    /// and its layers, without the per-sample set-up of the general path; the beauty's
    /// values are summed as an [`OwnerRun`].
    pub fn add_samples_touched<'r>(&mut self, samples: impl Iterator<Item = (Vec2, Rgb, &'r [Rgb], u32)>) {
        if self.filter != Filter::Box || self.n_layers == 0 {
            for (p, l, aov, touched) in samples {
                self.add_sample_touched(p, l, aov, touched);
            }
            return;
        }
        self.blank = false;
        self.ensure_layers();
        let n3 = 3 * self.n_layers;
        let valid = if self.n_layers >= 32 { u32::MAX } else { (1u32 << self.n_layers) - 1 };
        let mut run = OwnerRun::new();
        for (p, l, aov, touched) in samples {
            let Some(px) = self.run_owner(&mut run, p) else { continue };
            px.add_box(if l.is_finite() { l } else { Rgb::BLACK });
            let k = run.k;
            let m = touched & valid;
            if m == 0 {
                continue;
            }
            let Some(px) = self.layers.get_mut(k * n3..(k + 1) * n3) else { continue };
            // The untouched layers are zero, so adding the whole row gives the same sums as
            // adding the touched ones (no sum is ever -0), as a few vector adds.
            match Rgb::as_floats(aov).get(..n3) {
                Some(row) if all_finite(row) => add_dense(px, row),
                _ => add_touched_layers(px, aov, m),
            }
        }
        self.store_run(&run);
    }

    /// [`Self::add_sample_layers`] where only the layers of bit mask `touched` may be non-zero
    /// (the others are skipped: most samples reach few of the layers).
    #[inline]
    pub fn add_sample_touched(&mut self, p: Vec2, l: Rgb, aov: &[Rgb], touched: u32) {
        self.blank = false;
        let n = self.n_layers.min(aov.len());
        let touched = touched & if n >= 32 { u32::MAX } else { (1u32 << n) - 1 };
        if touched == 0 {
            self.add_sample(p, l);
            return;
        }
        let w = self.x1 - self.x0;
        let n3 = 3 * self.n_layers;
        if self.filter == Filter::Box {
            // One pixel takes the whole sample: find it once for the beauty and every layer.
            if let Some(k) = self.owner(p) {
                self.add_box(k, if l.is_finite() { l } else { Rgb::BLACK });
                self.ensure_layers();
                if let Some(px) = self.layers.get_mut(k * n3..(k + 1) * n3) {
                    add_touched_layers(px, aov, touched);
                }
            }
            return;
        }
        // The layers this sample reaches, with their values; and all the layers' values as
        // one row (zero where it reaches none: adding a zero leaves a sum as it is).
        let mut reach = [(0usize, Rgb::BLACK); crate::lpe::aov::MAX_LAYERS];
        let mut row = [0.0f32; 3 * crate::lpe::aov::MAX_LAYERS];
        let mut nr = 0;
        let mut m = touched;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            let v = aov[i];
            if v.is_finite() && !v.is_black() && nr < reach.len() {
                reach[nr] = (i, v);
                row[3 * i..3 * i + 3].copy_from_slice(&[v.r, v.g, v.b]);
                nr += 1;
            }
        }
        let reach = &reach[..nr];
        let row = &row[..n3.min(row.len())];
        // The beauty and the layers share one footprint, walked once for all of them.
        let l = if l.is_finite() { l } else { Rgb::BLACK };
        self.add_to_owner(p, l);
        let Some(fp) = self.footprint(p) else { return };
        self.add_filtered(&fp, l);
        if reach.is_empty() {
            return;
        }
        self.ensure_layers();
        // A sample reaching a third of the layers or more adds the whole row (a vector loop),
        // fewer add theirs one by one; the sums are the same either way.
        let dense = 3 * nr >= self.n_layers;
        for y in fp.ymin..fp.ymax + 1 {
            let wy = fp.wy(&self.weights, y);
            for x in fp.xmin..fp.xmax + 1 {
                let wgt = wy * fp.wx(&self.weights, x);
                if wgt == 0.0 {
                    continue;
                }
                let k = ((y as u32 - self.y0) * w + (x as u32 - self.x0)) as usize;
                let Some(px) = self.layers.get_mut(k * n3..(k + 1) * n3) else { continue };
                if dense {
                    for (d, s) in px.iter_mut().zip(row) {
                        *d += s * wgt;
                    }
                } else {
                    for &(i, v) in reach {
                        add_rgb(px, 3 * i, v * wgt);
                    }
                }
            }
        }
    }

    /// Add a sample taken at raster position `p` (pixels, origin top-left). The filter spreads it
    /// over every pixel of this tile within its radius.
    #[inline]
    pub fn add_sample(&mut self, p: Vec2, l: Rgb) {
        let Some(l) = self.admit(p, l) else { return };
        // One copy of the splat per filter, its weight function known at compile time (no
        // match per weight); the weights are `FilterWeights::eval`'s to the bit.
        match self.filter {
            Filter::Tent { radius } => self.add_separable(p, l, move |x| Filter::Tent { radius }.eval(x)),
            Filter::Gaussian { .. } => {
                let w = self.weights;
                self.add_separable(p, l, move |x| w.gaussian(x))
            }
            Filter::Box => {
                if let Some(fp) = self.footprint(p) {
                    self.add_filtered(&fp, l);
                }
            }
        }
    }

    /// [`Self::add_sample`] for a run of samples (position, radiance), in order: the same
    /// sums, with the filter's case chosen once for the run, and consecutive samples of one
    /// pixel summed as an [`OwnerRun`] (all of a box pixel's values, a wider filter's
    /// statistics). A tent of radius 1 (Mitsuba's default) weighs without its division
    /// (`x / 1` is `x`, NaN and all).
    pub fn add_samples(&mut self, samples: &[(Vec2, Rgb)]) {
        self.add_samples_by(samples.len(), |i| samples[i]);
    }

    /// [`Self::add_samples`] of black samples at positions `ps` (light tracing's pixel
    /// samples, whose light goes by splats): the same sums, with the value's arithmetic
    /// known at compile time.
    pub fn add_black_samples(&mut self, ps: &[Vec2]) {
        self.add_samples_by(ps.len(), |i| (ps[i], Rgb::BLACK));
    }

    /// [`Self::add_samples`] of samples `at(0)`, .., `at(n - 1)`.
    #[inline(always)]
    fn add_samples_by(&mut self, n: usize, at: impl Fn(usize) -> (Vec2, Rgb)) {
        if n == 0 {
            return;
        }
        self.blank = false;
        let mut run = OwnerRun::new();
        match self.filter {
            Filter::Tent { radius: 1.0 } => {
                for (p, l) in (0..n).map(at) {
                    self.add_tent1_in_run(&mut run, p, l);
                }
            }
            Filter::Tent { radius } => {
                for (p, l) in (0..n).map(at) {
                    self.add_in_run(&mut run, p, l, move |x| Filter::Tent { radius }.eval(x));
                }
            }
            Filter::Gaussian { .. } => {
                let w = self.weights;
                for (p, l) in (0..n).map(at) {
                    self.add_in_run(&mut run, p, l, move |x| w.gaussian(x));
                }
            }
            Filter::Box => {
                self.add_box_runs(n, at);
                return;
            }
        }
        self.store_run(&run);
    }

    /// The box filter's [`Self::add_samples_by`]: each run of samples whose floors are one
    /// pixel's summed into a copy of that pixel, stored when the run ends. The sums of
    /// `run_owner`'s runs, in their order (a run ended by a sample of the same owner stores
    /// and reloads its pixel: the same values); the copy stays in registers, where the
    /// `OwnerRun` had kept its sums in memory across samples (store forwarding on each).
    #[inline(always)]
    fn add_box_runs(&mut self, n: usize, at: impl Fn(usize) -> (Vec2, Rgb)) {
        let finite = |l: Rgb| if l.is_finite() { l } else { Rgb::BLACK };
        let mut i = 0;
        while i < n {
            let (p, l) = at(i);
            i += 1;
            let Some(k) = self.owner(p) else { continue };
            let Some(&first) = self.pixels.get(k) else { continue };
            let mut px = first;
            px.add_box(finite(l));
            // The square of positions with p's floors, all of them pixel k's.
            let lo = Vec2::new(floor_i(p.x) as f32, floor_i(p.y) as f32);
            let hi = lo + Vec2::ONE;
            while i < n {
                let (p, l) = at(i);
                if !(p.x >= lo.x && p.x < hi.x && p.y >= lo.y && p.y < hi.y) {
                    break;
                }
                px.add_box(finite(l));
                i += 1;
            }
            self.pixels[k] = px;
        }
    }

    /// [`Self::add_sample`] with a filter wider than the box (`eval` its 1-D weight), the
    /// owner's statistics summed in `run`.
    #[inline(always)]
    fn add_in_run(&mut self, run: &mut OwnerRun, p: Vec2, l: Rgb, eval: impl Fn(f32) -> f32) {
        let l = if l.is_finite() { l } else { Rgb::BLACK };
        if let Some(px) = self.run_owner(run, p) {
            px.add_stats(l);
        }
        self.add_separable(p, l, eval);
    }

    /// [`Self::add_in_run`] for the tent of radius 1 (Mitsuba's default filter), a sample of
    /// the run's pixel splatted on two columns and two rows: the owner's and the neighbour's
    /// on the side of its centre that `p` lies on. The other neighbour's weight is 0 (its
    /// centre is 1 or more away; the subtraction rounds monotonically), and a zero weight is
    /// skipped, so these are the pixels and the weights of `add_separable`'s footprint that
    /// count, with the same operations: the same bits, without its four floors a sample.
    #[inline(always)]
    fn add_tent1_in_run(&mut self, run: &mut OwnerRun, p: Vec2, l: Rgb) {
        let tent = |x: f32| (1.0 - x.abs()).max(0.0);
        let l = if l.is_finite() { l } else { Rgb::BLACK };
        let owned = self.run_owner(run, p).map(|px| px.add_stats(l)).is_some();
        // Past 2^20 a column's centre is not exact in f32: the general splat.
        if !owned || run.lo.max_element() >= (1 << 20) as f32 {
            self.add_separable(p, l, tent);
            return;
        }
        let (w, h) = ((self.x1 - self.x0) as usize, (self.y1 - self.y0) as usize);
        // The weights of the owner's column and row (centre x + 0.5, exact) and of their
        // neighbours' on p's side, the sum of both neighbours' (one is 0: the sum is the
        // other's, exactly); both axes side by side, the same operations lane by lane.
        // No branch on the side: it is a coin toss per sample.
        let (x, y) = (run.lo.x, run.lo.y);
        let tent4 = |v: Vec4| (Vec4::ONE - v.abs()).max(Vec4::ZERO);
        let pp = Vec4::new(p.x, p.y, p.x, p.y);
        // (x + -0.5 is x - 0.5, bit for bit.)
        let near = tent4(Vec4::new(x, y, x, y) + Vec4::new(0.5, 0.5, -0.5, -0.5) - pp);
        let far = tent4(Vec4::new(x, y, x, y) + Vec4::new(1.5, 1.5, 1.5, 1.5) - pp);
        let side = near.zwzw() + far.xyxy();
        // Per pixel (owner, column neighbour, row neighbour, diagonal): fy * fx.
        let wgt = Vec4::new(near.x, side.x, near.x, side.x) * Vec4::new(near.y, near.y, side.y, side.y);
        // The neighbours' column and row (wrapping to usize::MAX left of or above the tile).
        let step = |right: bool| (2 * right as usize).wrapping_sub(1);
        let c1 = run.col.wrapping_add(step(p.x >= x + 0.5));
        let r1 = run.row.wrapping_add(step(p.y >= y + 0.5));
        let (cin, rin) = (c1 < w, r1 < h);
        let at = [(run.row, run.col, true), (run.row, c1, cin), (r1, run.col, rin), (r1, c1, rin && cin)];
        let pixels = &mut self.pixels[..];
        for ((r, c, inside), wgt) in at.into_iter().zip(wgt.to_array()) {
            if !inside || wgt == 0.0 {
                continue;
            }
            if let Some(px) = pixels.get_mut(r * w + c) {
                px.sum += l * wgt;
                px.weight += wgt as f64;
            }
        }
    }

    /// The values of the pixel that owns `p`, as `run`'s: the run goes on while the owner
    /// stays, else the previous run is stored and one starts (None: no pixel of the tile
    /// owns `p`, and the run goes on past it).
    #[inline(always)]
    fn run_owner<'r>(&mut self, run: &'r mut OwnerRun, p: Vec2) -> Option<&'r mut Pixel> {
        if !run.holds(p) {
            let (k, col, row) = self.owner_at(p)?;
            if k != run.k {
                self.store_run(run);
                (run.k, run.col, run.row) = (k, col, row);
                run.px = self.pixels.get(k).copied().unwrap_or_default();
            }
            // The floors of an owned position are a few thousand at most: exact as floats,
            // and so is the square's far side.
            run.lo = Vec2::new(floor_i(p.x) as f32, floor_i(p.y) as f32);
            run.hi = run.lo + Vec2::ONE;
        }
        Some(&mut run.px)
    }

    /// A run's sums back into its pixel: all of them with the box filter, else the
    /// statistics (the filtered sums went in place).
    #[inline]
    fn store_run(&mut self, run: &OwnerRun) {
        let whole = self.filter == Filter::Box;
        if let Some(px) = self.pixels.get_mut(run.k) {
            if whole {
                *px = run.px;
            } else {
                px.s1 = run.px.s1;
                px.s2 = run.px.s2;
                px.n = run.px.n;
            }
        }
    }

    /// What every sample goes through first: the tile is no longer blank, a non-finite value
    /// counts as black, and the owning pixel takes it into its variance statistics (with the
    /// box filter into its sum too). Returns the value still to splat, None where done.
    #[inline(always)]
    fn admit(&mut self, p: Vec2, l: Rgb) -> Option<Rgb> {
        self.blank = false;
        let l = if l.is_finite() { l } else { Rgb::BLACK };
        (!self.add_to_owner(p, l)).then_some(l)
    }

    /// [`Self::footprint`] and [`Self::add_filtered`] in one, for the beauty alone: each
    /// axis's weights evaluated once (`eval`: the filter's 1-D weight), then each row of
    /// the footprint as one slice zipped with the x weights. The same weights, products and
    /// sums in the same order as those two, so the same bits.
    #[inline]
    fn add_separable(&mut self, p: Vec2, l: Rgb, eval: impl Fn(f32) -> f32) {
        let Some((xmin, xmax, ymin, ymax)) = self.footprint_range(p) else { return };
        let nx = (xmax - xmin + 1) as usize;
        if nx > Footprint::SPAN || ymax - ymin + 1 > Footprint::SPAN as i64 {
            // A wide filter: the general walk (weights evaluated in place).
            if let Some(fp) = self.footprint(p) {
                self.add_filtered(&fp, l);
            }
            return;
        }
        let mut fx = [0.0f32; Footprint::SPAN];
        for (i, f) in fx[..nx].iter_mut().enumerate() {
            *f = eval((xmin + i as i64) as f32 + 0.5 - p.x);
        }
        let fx = &fx[..nx];
        let w = (self.x1 - self.x0) as usize;
        // The footprint lies inside the tile (clamped above): these do not wrap.
        let c0 = (xmin - self.x0 as i64) as usize;
        for y in ymin..ymax + 1 {
            let fy = eval(y as f32 + 0.5 - p.y);
            if fy == 0.0 {
                continue;
            }
            let start = (y - self.y0 as i64) as usize * w + c0;
            let Some(row) = self.pixels.get_mut(start..start + nx) else { continue };
            for (px, &wx) in row.iter_mut().zip(fx) {
                let wgt = fy * wx;
                if wgt == 0.0 {
                    continue;
                }
                px.sum += l * wgt;
                px.weight += wgt as f64;
            }
        }
    }

    /// The variance statistics of the pixel that owns the sample; with the box filter, whose
    /// support is exactly that pixel with weight 1, also its filtered sum (then true: done).
    #[inline]
    fn add_to_owner(&mut self, p: Vec2, l: Rgb) -> bool {
        let Some(k) = self.owner(p) else { return false };
        if self.filter == Filter::Box {
            self.add_box(k, l);
            return true;
        }
        self.pixels[k].add_stats(l);
        false
    }

    /// The index of the tile's pixel that owns a sample at `p`, if it is in the tile. A box
    /// tile also keeps a sample on its far edge: `x + u` rounds up to `x + 1` for `u` just
    /// below 1, and that sample stays in the pixel it was drawn for, so box tiles need no
    /// border and never share a pixel (the per-tile pass sums rely on it).
    #[inline]
    fn owner(&self, p: Vec2) -> Option<usize> {
        self.owner_at(p).map(|(k, _, _)| k)
    }

    /// [`Self::owner`] with its column and row in the tile.
    #[inline(always)]
    fn owner_at(&self, p: Vec2) -> Option<(usize, usize, usize)> {
        let (w, h) = (self.x1 - self.x0, self.y1 - self.y0);
        let (mut ox, mut oy) = (floor_i(p.x) - self.x0 as i64, floor_i(p.y) - self.y0 as i64);
        if self.filter == Filter::Box {
            ox -= (ox == w as i64) as i64;
            oy -= (oy == h as i64) as i64;
        }
        if ox < 0 || oy < 0 || ox as u32 >= w || oy as u32 >= h {
            return None;
        }
        Some(((oy as u32 * w + ox as u32) as usize, ox as usize, oy as usize))
    }

    /// A box-filtered sample into pixel `k`: its statistics and its whole weight.
    #[inline]
    fn add_box(&mut self, k: usize, l: Rgb) {
        if let Some(px) = self.pixels.get_mut(k) {
            px.add_box(l);
        }
    }

    /// The filter's share of a sample for every pixel of the tile within its radius: row by
    /// row, each row's pixels as one slice (no per-pixel index arithmetic or bounds check).
    #[inline(never)]
    fn add_filtered(&mut self, fp: &Footprint, l: Rgb) {
        let w = (self.x1 - self.x0) as usize;
        // The footprint lies inside the tile (`footprint` clamps it): these do not wrap.
        let (c0, nx) = ((fp.xmin - self.x0 as i64) as usize, (fp.xmax - fp.xmin + 1) as usize);
        for y in fp.ymin..fp.ymax + 1 {
            let fy = fp.wy(&self.weights, y);
            if fy == 0.0 {
                continue;
            }
            let start = (y - self.y0 as i64) as usize * w + c0;
            let Some(row) = self.pixels.get_mut(start..start + nx) else { continue };
            for (x, px) in (fp.xmin..).zip(row.iter_mut()) {
                let wgt = fy * fp.wx(&self.weights, x);
                if wgt == 0.0 {
                    continue;
                }
                px.sum += l * wgt;
                px.weight += wgt as f64;
            }
        }
    }

    /// The first and last column and row of this tile within the filter's radius of `p`
    /// (None: none).
    #[inline]
    fn footprint_range(&self, p: Vec2) -> Option<(i64, i64, i64, i64)> {
        let r = self.filter.radius();
        let xmin = (-floor_i(-(p.x - 0.5 - r))).max(self.x0 as i64);
        let xmax = floor_i(p.x - 0.5 + r).min(self.x1 as i64 - 1);
        let ymin = (-floor_i(-(p.y - 0.5 - r))).max(self.y0 as i64);
        let ymax = floor_i(p.y - 0.5 + r).min(self.y1 as i64 - 1);
        (xmin <= xmax && ymin <= ymax).then_some((xmin, xmax, ymin, ymax))
    }

    /// The pixels of this tile within the filter's radius of `p` (None: none), with the
    /// filter's separable weights evaluated once per sample for the beauty and every layer
    /// (a Gaussian's cost two `exp` each).
    #[inline]
    fn footprint(&self, p: Vec2) -> Option<Footprint> {
        let (xmin, xmax, ymin, ymax) = self.footprint_range(p)?;
        let (nx, ny) = ((xmax - xmin + 1) as usize, (ymax - ymin + 1) as usize);
        let mut fp = Footprint {
            xmin,
            xmax,
            ymin,
            ymax,
            p,
            fx: [0.0; Footprint::SPAN],
            fy: [0.0; Footprint::SPAN],
            cached: nx <= Footprint::SPAN && ny <= Footprint::SPAN,
        };
        if fp.cached {
            for (i, f) in fp.fx[..nx].iter_mut().enumerate() {
                *f = self.weights.eval((xmin + i as i64) as f32 + 0.5 - p.x);
            }
            for (j, f) in fp.fy[..ny].iter_mut().enumerate() {
                *f = self.weights.eval((ymin + j as i64) as f32 + 0.5 - p.y);
            }
        }
        Some(fp)
    }
}

/// A sample's filter footprint on a tile: its pixel range and, when the range is small enough
/// to cache, the filter's weights along each axis.
struct Footprint {
    xmin: i64,
    xmax: i64,
    ymin: i64,
    ymax: i64,
    p: Vec2,
    fx: [f32; Footprint::SPAN],
    fy: [f32; Footprint::SPAN],
    cached: bool,
}

impl Footprint {
    /// Widest cached range (pixels per axis; the default Gaussian's is 5, the tent's 3);
    /// wider filters evaluate each weight in place (the same weights). Small enough that
    /// returning a footprint is a few register moves rather than a `memcpy` per sample.
    const SPAN: usize = 8;
    #[inline(always)]
    fn wx(&self, filter: &FilterWeights, x: i64) -> f32 {
        if self.cached {
            self.fx[(x - self.xmin) as usize]
        } else {
            filter.eval(x as f32 + 0.5 - self.p.x)
        }
    }
    #[inline(always)]
    fn wy(&self, filter: &FilterWeights, y: i64) -> f32 {
        if self.cached {
            self.fy[(y - self.ymin) as usize]
        } else {
            filter.eval(y as f32 + 0.5 - self.p.y)
        }
    }
}

/// The whole film: one tile covering the image.
#[derive(Clone, Debug)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    pub filter: Filter,
    full: FilmTile,
    /// Light-side estimators (light tracing, BDPT t=1, MLT) splat here; the value is divided by
    /// `splat_scale` when the image is developed (e.g. the number of light paths per pixel).
    /// One row per pixel: the beauty's splat, then each AOV layer's (channel c of layer i of
    /// pixel k at `k * stride + 3 + 3 * i + c`, stride `3 * (1 + layers)`), so that a light
    /// path's deposit into the beauty and its layers writes one row. Empty until the first
    /// splat.
    splats: Vec<f32>,
    pub splat_scale: f32,
    /// Samples per pixel actually taken (the render may have been cancelled).
    pub spp_done: u32,
    /// Names of the AOV layers (light path expressions), in order.
    layer_names: Vec<String>,
}

impl Film {
    pub fn new(width: u32, height: u32, filter: Filter) -> Self {
        Film {
            width,
            height,
            filter,
            full: FilmTile::new(0, 0, width, height, filter),
            splats: Vec::new(),
            splat_scale: 1.0,
            spp_done: 0,
            layer_names: Vec::new(),
        }
    }

    /// A film with AOV layers of these names beside the beauty.
    pub fn with_layers(width: u32, height: u32, filter: Filter, names: &[String]) -> Self {
        let mut f = Film::new(width, height, filter);
        f.layer_names = names.to_vec();
        f.full.set_layers(names.len());
        f
    }

    /// Back to a new film's state (black, no samples, splat scale 1), keeping its memory
    /// for reuse.
    pub fn clear(&mut self) {
        self.full.clear();
        self.splats.fill(0.0);
        self.splat_scale = 1.0;
        self.spp_done = 0;
    }

    /// The AOV layers' names, in order.
    pub fn layer_names(&self) -> &[String] {
        &self.layer_names
    }

    /// Add an unfiltered contribution to layer `i` (see [`Film::splat`]).
    pub fn splat_layer(&mut self, i: usize, p: Vec2, l: Rgb) {
        if i < 32 {
            self.splat_layers(1 << i, p, l);
        }
    }

    /// Add an unfiltered contribution to each layer of bit mask `layers` (bit i: layer i).
    pub fn splat_layers(&mut self, layers: u32, p: Vec2, l: Rgb) {
        if layers == 0 {
            return;
        }
        let Some(row) = self.splat_row(p, l) else { return };
        let mut m = layers;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            add_rgb(row, 3 + 3 * i, l);
        }
    }

    /// Floats per pixel in `splats`.
    #[inline]
    fn splat_stride(&self) -> usize {
        3 * (1 + self.layer_names.len())
    }

    /// The splat row of the pixel at `p` (allocating the buffer on first use), or None where
    /// `p` is off the film or `l` is not finite.
    #[inline]
    fn splat_row(&mut self, p: Vec2, l: Rgb) -> Option<&mut [f32]> {
        if !l.is_finite() || p.x < 0.0 || p.y < 0.0 {
            return None;
        }
        let (x, y) = (p.x as u32, p.y as u32);
        if x >= self.width || y >= self.height {
            return None;
        }
        self.pixel_row(x, y)
    }

    /// Pixel (x, y)'s splat row (x < width, y < height), the buffer made on first use.
    #[inline]
    fn pixel_row(&mut self, x: u32, y: u32) -> Option<&mut [f32]> {
        let stride = self.splat_stride();
        if self.splats.is_empty() {
            self.splats = vec![0.0; (self.width * self.height) as usize * stride];
        }
        let k = (y * self.width + x) as usize * stride;
        self.splats.get_mut(k..k + stride)
    }

    /// The splat at pixel index `k` of the beauty (`slot` 0) or of layer `slot - 1` (black
    /// before any splat).
    fn splat_at(&self, k: usize, slot: usize) -> Rgb {
        rgb_at(&self.splats, k * self.splat_stride() + 3 * slot)
    }

    /// Layer `i` developed like the beauty: its filtered sums over the beauty's weights plus
    /// its scaled splats.
    pub fn layer_image(&self, i: usize) -> Image {
        let t = &self.full;
        let mut data: Vec<Rgb> =
            t.pixels.iter().enumerate().map(|(k, p)| if p.weight > 0.0 { t.layer_sum(k, i) / p.weight as f32 } else { Rgb::BLACK }).collect();
        if !self.splats.is_empty() {
            for (k, d) in data.iter_mut().enumerate() {
                *d += self.splat_at(k, 1 + i) / self.splat_scale;
            }
        }
        Image::new(self.width as usize, self.height as usize, data)
    }

    /// Every layer by name, developed.
    pub fn layer_images(&self) -> Vec<(String, Image)> {
        self.layer_names.iter().enumerate().map(|(i, n)| (n.clone(), self.layer_image(i))).collect()
    }

    /// The developed layer called `name`.
    pub fn layer(&self, name: &str) -> Option<Image> {
        self.layer_names.iter().position(|n| n == name).map(|i| self.layer_image(i))
    }

    /// A tile covering `[x0,x1) x [y0,y1)` of this film, to be filled and merged back.
    pub fn tile(&self, x0: u32, y0: u32, x1: u32, y1: u32) -> FilmTile {
        Film::tile_of(self.width, self.height, self.filter, self.layer_names.len(), x0, y0, x1, y1)
    }

    /// [`Film::tile`] of a film of this size, filter and number of layers, without the film
    /// (a render's workers make their tiles while the film is elsewhere).
    #[allow(clippy::too_many_arguments)]
    pub fn tile_of(width: u32, height: u32, filter: Filter, n_layers: usize, x0: u32, y0: u32, x1: u32, y1: u32) -> FilmTile {
        // Extend by the filter radius so samples near the border reach neighbours; a box
        // sample reaches only its own pixel (`add_to_owner`), so box tiles do not overlap.
        let r = if filter == Filter::Box { 0 } else { filter.radius().ceil() as u32 };
        let mut t = FilmTile::new(x0.saturating_sub(r), y0.saturating_sub(r), (x1 + r).min(width), (y1 + r).min(height), filter);
        t.set_layers(n_layers);
        t
    }

    pub fn merge_tile(&mut self, t: &FilmTile) {
        if t.blank {
            return;
        }
        self.full.blank = false;
        let tw = t.x1 - t.x0;
        for y in t.y0..t.y1 {
            for x in t.x0..t.x1 {
                self.full.pixels[(y * self.width + x) as usize].add(&t.pixels[((y - t.y0) * tw + (x - t.x0)) as usize]);
            }
        }
        let nl = self.full.n_layers;
        if nl > 0 && t.n_layers == nl && !t.layers.is_empty() {
            self.full.ensure_layers();
            for y in t.y0..t.y1 {
                for x in t.x0..t.x1 {
                    let (d, s) = ((y * self.width + x) as usize * 3 * nl, ((y - t.y0) * tw + (x - t.x0)) as usize * 3 * nl);
                    for (dv, sv) in self.full.layers[d..d + 3 * nl].iter_mut().zip(&t.layers[s..s + 3 * nl]) {
                        *dv += *sv;
                    }
                }
            }
        }
    }

    pub fn add_sample(&mut self, p: Vec2, l: Rgb) {
        self.full.add_sample(p, l);
    }

    /// [`Self::add_sample`] with the sample's value in each AOV layer.
    pub fn add_sample_layers(&mut self, p: Vec2, l: Rgb, aov: &[Rgb]) {
        self.full.add_sample_layers(p, l, aov);
    }

    /// Add another film's raw sums to this one's (same size, filter and layers): the step of
    /// the pass tree that makes a render's image from its passes. `spp_done` adds up; the
    /// splat scale is left to the caller (it is the whole render's spp).
    pub fn add(&mut self, o: &Film) {
        debug_assert_eq!((self.width, self.height, self.layer_names.len()), (o.width, o.height, o.layer_names.len()));
        self.full.add(&o.full);
        add_buffer(&mut self.splats, &o.splats);
        self.spp_done += o.spp_done;
    }

    /// Add an unfiltered contribution at raster position `p` (box reconstruction).
    pub fn splat(&mut self, p: Vec2, l: Rgb) {
        if let Some(row) = self.splat_row(p, l) {
            add_rgb(row, 0, l);
        }
    }

    /// `splat` at pixel (x, y)'s centre, for a caller that found the pixel (x < width,
    /// y < height) itself: the same sum without the position's conversions and checks
    /// (light tracing's splat merge made them twice per splat).
    #[inline]
    pub fn splat_pixel(&mut self, x: u32, y: u32, l: Rgb) {
        debug_assert!(x < self.width && y < self.height);
        if !l.is_finite() {
            return;
        }
        if let Some(row) = self.pixel_row(x, y) {
            add_rgb(row, 0, l);
        }
    }

    /// `splat_pixel(x, y, l)` for each of `splats` in order, the stride looked up once (the
    /// splat merge's beauty splats; the buffer made at the first finite one, as there).
    pub fn splat_pixels(&mut self, splats: impl Iterator<Item = (u32, u32, Rgb)>) {
        let (stride, width) = (self.splat_stride(), self.width);
        for (x, y, l) in splats {
            debug_assert!(x < width && y < self.height);
            if !l.is_finite() {
                continue;
            }
            if self.splats.is_empty() {
                self.splats = vec![0.0; (width * self.height) as usize * stride];
            }
            let k = (y * width + x) as usize * stride;
            if let Some(c) = self.splats.get_mut(k..k + 3) {
                c[0] += l.r;
                c[1] += l.g;
                c[2] += l.b;
            }
        }
    }

    /// The developed image: filtered samples plus scaled splats.
    pub fn image(&self) -> Image {
        let mut data: Vec<Rgb> = self.full.pixels.iter().map(|p| if p.weight > 0.0 { p.sum / p.weight as f32 } else { Rgb::BLACK }).collect();
        if !self.splats.is_empty() {
            for (k, d) in data.iter_mut().enumerate() {
                *d += self.splat_at(k, 0) / self.splat_scale;
            }
        }
        Image::new(self.width as usize, self.height as usize, data)
    }

    /// Per-sample variance of the radiance of the samples in each pixel (unbiased estimator),
    /// the convention of Mitsuba's `_var` reference images.
    pub fn variance_image(&self) -> Image {
        let data = self
            .full
            .pixels
            .iter()
            .map(|p| {
                if p.n < 2 {
                    return Rgb::BLACK;
                }
                let n = p.n as f32;
                let mean = p.s1 / n;
                ((p.s2 - mean * mean * n) / (n - 1.0)).map(|v| v.max(0.0))
            })
            .collect();
        Image::new(self.width as usize, self.height as usize, data)
    }
}

/// The colour at `buf[j..j + 3]` (black past the end: a buffer not allocated yet).
#[inline]
fn rgb_at(buf: &[f32], j: usize) -> Rgb {
    match buf.get(j..j + 3) {
        Some(c) => Rgb::new(c[0], c[1], c[2]),
        None => Rgb::BLACK,
    }
}

/// No value is infinite or NaN (`x - x` is 0 exactly for finite `x`), eight at a time
/// without an early exit (a row of eight layers is three such blocks).
#[inline(always)]
fn all_finite(v: &[f32]) -> bool {
    #[allow(clippy::eq_op)]
    let ok = |x: f32| x - x == 0.0;
    let (blocks, rest) = v.as_chunks::<8>();
    let mut all = [true; 8];
    for b in blocks {
        all = std::array::from_fn(|i| all[i] & ok(b[i]));
    }
    all.iter().all(|&a| a) && rest.iter().all(|&x| ok(x))
}

/// `dst += src` (the same lengths), eight floats at a time (the compiler's own vector loop
/// takes more floats a step than a row holds, and leaves it to its scalar tail).
#[inline(always)]
fn add_dense(dst: &mut [f32], src: &[f32]) {
    let (d8, d) = dst.as_chunks_mut::<8>();
    let (s8, s) = src.as_chunks::<8>();
    for (d, s) in d8.iter_mut().zip(s8) {
        *d = std::array::from_fn(|i| d[i] + s[i]);
    }
    for (d, s) in d.iter_mut().zip(s) {
        *d += *s;
    }
}

/// A box-filtered pixel's layers `px` (three floats each) take the layers of bit mask `m`
/// from `aov`; a non-finite value is dropped.
#[inline(always)]
fn add_touched_layers(px: &mut [f32], aov: &[Rgb], mut m: u32) {
    let (cells, _) = px.as_chunks_mut::<3>();
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if let (Some(c), Some(v)) = (cells.get_mut(i), aov.get(i)) {
            // x - x is 0 exactly for finite x (NaN otherwise): the cheapest test here by count.
            #[allow(clippy::eq_op)]
            let finite = (v.r - v.r == 0.0) & (v.g - v.g == 0.0) & (v.b - v.b == 0.0);
            if finite {
                c[0] += v.r;
                c[1] += v.g;
                c[2] += v.b;
            }
        }
    }
}

/// `buf[j..j + 3] += v`.
#[inline(always)]
fn add_rgb(buf: &mut [f32], j: usize, v: Rgb) {
    if let Some(c) = buf.get_mut(j..j + 3) {
        c[0] += v.r;
        c[1] += v.g;
        c[2] += v.b;
    }
}

/// `dst += src` for lazily allocated buffers of the same layout (empty: all zero).
fn add_buffer(dst: &mut Vec<f32>, src: &[f32]) {
    if src.is_empty() {
        return;
    }
    if dst.is_empty() {
        *dst = vec![0.0; src.len()];
    }
    for (d, s) in dst.iter_mut().zip(src) {
        *d += *s;
    }
}

/// `x.floor() as i64` without a call to the software `floorf` that baseline x86-64 (no
/// SSE4.1 `roundss`) would make: truncate, then step down for negative non-integers.
#[inline]
fn floor_i(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) > x {
        t - 1
    } else {
        t
    }
}

#[cfg(test)]
mod tile_tests {
    use super::*;

    /// Box tiles have no border: a sample whose raster position rounded up onto the tile's far
    /// edge stays in the last pixel it was drawn for, and tiles never share a pixel.
    #[test]
    fn box_tiles_keep_far_edge_samples_and_share_no_pixel() {
        let film = Film::new(32, 32, Filter::Box);
        let mut t = film.tile(16, 0, 32, 16);
        assert_eq!((t.x0, t.y0, t.x1, t.y1), (16, 0, 32, 16), "a box tile is its own pixels");
        // 31 + u for u just below 1 rounds to 32: the far edge.
        t.add_sample(Vec2::new(32.0, 16.0), Rgb::splat(2.0));
        let mut f = Film::new(32, 32, Filter::Box);
        f.merge_tile(&t);
        let img = f.image();
        assert_eq!(img.data[(15 * 32 + 31) as usize], Rgb::splat(2.0), "kept in the tile's corner pixel");
        assert_eq!(img.data.iter().filter(|p| !p.is_black()).count(), 1, "nowhere else");
        // A filter wider than a pixel still extends tiles by its radius.
        let g = Film::new(32, 32, Filter::Gaussian { stddev: 0.5 }).tile(16, 16, 32, 32);
        assert_eq!((g.x0, g.y0), (14, 14));
    }

    /// A run of box-filtered samples (the kernel's batch, adding each row whole where it is
    /// finite) sums every layer to the bit as sample-by-sample adds of the touched layers do,
    /// and drops a non-finite layer value while keeping the sample's other layers.
    #[test]
    fn box_batches_add_like_single_samples() {
        let names: Vec<String> = (0..9).map(|i| format!("l{i}")).collect();
        let film = Film::with_layers(8, 8, Filter::Box, &names);
        let (mut batch, mut single) = (film.tile(0, 0, 8, 8), film.tile(0, 0, 8, 8));
        let mut rng = crate::sampling::Pcg32::new(3, 5);
        let mut samples = Vec::new();
        for k in 0..2000 {
            let p = Vec2::new(rng.next_f32() * 8.0, rng.next_f32() * 8.0);
            let touched = (rng.next_f32() * 512.0) as u32;
            let row: Vec<Rgb> = (0..9)
                .map(|i| match (touched & (1 << i) != 0, k % 97, i) {
                    (false, _, _) => Rgb::BLACK,
                    (true, 5, 2) => Rgb::new(f32::NAN, 1.0, 1.0),
                    (true, 7, 4) => Rgb::new(1.0, f32::INFINITY, 1.0),
                    _ => Rgb::new(rng.next_f32(), rng.next_f32() * 1e-3, rng.next_f32() * 1e3),
                })
                .collect();
            samples.push((p, Rgb::splat(rng.next_f32()), row, touched));
        }
        batch.add_samples_touched(samples.iter().map(|(p, l, row, t)| (*p, *l, row.as_slice(), *t)));
        for (p, l, row, t) in &samples {
            single.add_sample_touched(*p, *l, row, *t);
        }
        let (mut a, mut b) = (Film::with_layers(8, 8, Filter::Box, &names), Film::with_layers(8, 8, Filter::Box, &names));
        a.merge_tile(&batch);
        b.merge_tile(&single);
        assert_eq!(a.image().data, b.image().data);
        for i in 0..9 {
            let (x, y) = (a.layer_image(i).data, b.layer_image(i).data);
            assert!(
                x.iter().zip(&y).all(|(x, y)| x.r.to_bits() == y.r.to_bits() && x.g.to_bits() == y.g.to_bits() && x.b.to_bits() == y.b.to_bits()),
                "layer {i}"
            );
            assert!(x.iter().all(Rgb::is_finite), "layer {i}: non-finite values dropped");
        }
        assert!(a.layer_image(2).data.iter().any(|c| !c.is_black()), "the other values of a sample with a NaN layer stay");
    }

    /// The separable splat of `add_sample` gives every pixel's sums and weight to the bit as
    /// the general footprint walk (`footprint` + `add_filtered`) does, for each filter
    /// (a wide Gaussian too, past the cached span), on a tile with a border, samples in it
    /// and near and on its edges and pixel boundaries; and so do runs of samples
    /// (`add_samples`, the tent of radius 1 without its division).
    #[test]
    fn separable_splat_matches_the_footprint_walk() {
        let filters = [
            Filter::Box,
            Filter::Tent { radius: 1.0 },
            Filter::Tent { radius: 1.7 },
            Filter::Gaussian { stddev: 0.5 },
            Filter::Gaussian { stddev: 0.37 },
            Filter::Gaussian { stddev: 1.5 },
        ];
        let mut rng = crate::sampling::Pcg32::new(11, 7);
        for f in filters {
            let film = Film::new(24, 20, f);
            let (mut fast, mut walk, mut runs) = (film.tile(8, 4, 16, 12), film.tile(8, 4, 16, 12), film.tile(8, 4, 16, 12));
            let mut samples = Vec::new();
            for k in 0..4000 {
                let mut p = Vec2::new(rng.next_f32() * 28.0 - 2.0, rng.next_f32() * 24.0 - 2.0);
                if k % 5 == 0 {
                    // On a pixel boundary or centre, where a weight may be exactly zero.
                    p = Vec2::new((p.x * 2.0).floor() * 0.5, (p.y * 2.0).round() * 0.5);
                }
                let l = Rgb::new(rng.next_f32(), rng.next_f32() * 1e-3, rng.next_f32() * 1e3);
                fast.add_sample(p, l);
                samples.push((p, l));
                walk.blank = false;
                if !walk.add_to_owner(p, l) {
                    if let Some(fp) = walk.footprint(p) {
                        walk.add_filtered(&fp, l);
                    }
                }
            }
            let bits = tile_bits;
            assert_eq!(bits(&fast), bits(&walk), "{f:?}");
            for run in samples.chunks(37) {
                runs.add_samples(run);
            }
            assert_eq!(bits(&runs), bits(&fast), "{f:?}: runs");
            assert!(fast.pixels.iter().filter(|px| px.weight > 0.0).count() > 32, "{f:?}: the samples reached the tile");
        }
    }

    /// Every pixel's sums, statistics and weight of a tile, as bits.
    fn tile_bits(t: &FilmTile) -> Vec<[u64; 11]> {
        t.pixels
            .iter()
            .map(|px| {
                let c = |v: Rgb| [v.r.to_bits() as u64, v.g.to_bits() as u64, v.b.to_bits() as u64];
                let (s, a, b) = (c(px.sum), c(px.s1), c(px.s2));
                [s[0], s[1], s[2], a[0], a[1], a[2], b[0], b[1], b[2], px.weight.to_bits(), px.n as u64]
            })
            .collect()
    }

    /// Samples in the path kernel's order, pixel by pixel with each pixel's samples in a row:
    /// a tile's pixels (`[x0, x1) x [y0, y1)`) and a ring around them, a few samples on a pixel's far edge or
    /// corner, outside the film, at a NaN position, and with non-finite radiance, some runs
    /// broken by a sample of another pixel.
    fn pixel_runs(rng: &mut crate::sampling::Pcg32, (x0, y0, x1, y1): (u32, u32, u32, u32), n: u32) -> Vec<(Vec2, Rgb)> {
        let mut out = Vec::new();
        for y in y0.saturating_sub(1)..y1 + 1 {
            for x in x0.saturating_sub(1)..x1 + 1 {
                for s in 0..n {
                    let mut p = Vec2::new(x as f32 + rng.next_f32(), y as f32 + rng.next_f32());
                    match (s + x + 3 * y) % 23 {
                        1 => p.x = x as f32 + 1.0,
                        2 => p = Vec2::new(x as f32 + 1.0, y as f32 + 1.0),
                        3 => p = Vec2::new(rng.next_f32() * 40.0 - 8.0, rng.next_f32() * 40.0 - 8.0),
                        4 => p.y = f32::NAN,
                        5 => p = Vec2::new(x as f32, y as f32),
                        // On the centre, where the tent's splat turns to the other side.
                        6 => p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5),
                        _ => {}
                    }
                    let l = match (s + 7 * x + y) % 31 {
                        1 => Rgb::new(f32::NAN, 1.0, 1.0),
                        2 => Rgb::new(1.0, 1.0, f32::INFINITY),
                        _ => Rgb::new(rng.next_f32(), rng.next_f32() * 1e-3, rng.next_f32() * 1e3),
                    };
                    out.push((p, l));
                }
            }
        }
        out
    }

    /// Runs of samples of one pixel, as the path kernel hands them over (`add_samples`,
    /// summed per run), give every pixel's sums, statistics and weight to the bit as adding
    /// the samples one by one; for each filter, on a tile inside the film and on ones at its
    /// corners (no border there), in batches that cut runs.
    #[test]
    fn owner_runs_add_like_single_samples() {
        let filters = [Filter::Box, Filter::Tent { radius: 1.0 }, Filter::Tent { radius: 1.7 }, Filter::Gaussian { stddev: 0.5 }];
        let mut rng = crate::sampling::Pcg32::new(17, 3);
        for f in filters {
            let film = Film::new(24, 20, f);
            for rect in [(8, 4, 16, 12), (16, 12, 24, 20), (0, 0, 8, 4)] {
                let (mut runs, mut single) = (film.tile(rect.0, rect.1, rect.2, rect.3), film.tile(rect.0, rect.1, rect.2, rect.3));
                let samples = pixel_runs(&mut rng, (runs.x0, runs.y0, runs.x1, runs.y1), 7);
                for batch in samples.chunks(45) {
                    runs.add_samples(batch);
                }
                for &(p, l) in &samples {
                    single.add_sample(p, l);
                }
                assert_eq!(tile_bits(&runs), tile_bits(&single), "{f:?} {rect:?}");
                assert!(runs.pixels.iter().all(|px| px.n >= 2), "{f:?} {rect:?}: every pixel took its run");
            }
        }
    }

    /// Black samples in runs (`add_black_samples`, light tracing's pixel samples) give every
    /// pixel's sums, statistics and weight to the bit as adding `Rgb::BLACK` one by one, on
    /// tiles that had other samples before (sums that are not zero), for each filter.
    #[test]
    fn black_runs_add_like_single_black_samples() {
        let filters = [Filter::Box, Filter::Tent { radius: 1.0 }, Filter::Tent { radius: 1.7 }, Filter::Gaussian { stddev: 0.5 }];
        let mut rng = crate::sampling::Pcg32::new(29, 7);
        for f in filters {
            let film = Film::new(24, 20, f);
            for rect in [(8, 4, 16, 12), (16, 12, 24, 20)] {
                let (mut runs, mut single) = (film.tile(rect.0, rect.1, rect.2, rect.3), film.tile(rect.0, rect.1, rect.2, rect.3));
                let before = pixel_runs(&mut rng, (runs.x0, runs.y0, runs.x1, runs.y1), 2);
                runs.add_samples(&before);
                single.add_samples(&before);
                let n_before: Vec<u32> = runs.pixels.iter().map(|px| px.n).collect();
                let at: Vec<Vec2> = pixel_runs(&mut rng, (runs.x0, runs.y0, runs.x1, runs.y1), 5).into_iter().map(|(p, _)| p).collect();
                for batch in at.chunks(37) {
                    runs.add_black_samples(batch);
                }
                for &p in &at {
                    single.add_sample(p, Rgb::BLACK);
                }
                assert_eq!(tile_bits(&runs), tile_bits(&single), "{f:?} {rect:?}");
                let grew = runs.pixels.iter().zip(&n_before).filter(|(px, &n)| px.n >= n + 3).count();
                assert!(2 * grew > runs.pixels.len(), "{f:?} {rect:?}: the black runs reached the tile");
            }
        }
    }

    /// A run begun on a box tile's far edge (which its last pixel keeps) takes the positions
    /// after it as adding them one by one does (`owner`'s far-edge rule).
    #[test]
    fn a_run_on_the_far_edge_adds_like_single_samples() {
        let film = Film::new(24, 20, Filter::Box);
        let (x1, y1) = (16.0, 12.0);
        let samples = [
            (Vec2::new(x1, 5.5), Rgb::splat(1.0)),
            (Vec2::new(x1 + 0.25, 5.5), Rgb::splat(2.0)),
            (Vec2::new(10.5, y1), Rgb::splat(3.0)),
            (Vec2::new(10.5, y1 + 0.5), Rgb::splat(4.0)),
            (Vec2::new(x1, y1), Rgb::splat(5.0)),
            (Vec2::new(x1 + 0.5, y1 + 0.5), Rgb::splat(6.0)),
        ];
        let (mut runs, mut single) = (film.tile(8, 4, 16, 12), film.tile(8, 4, 16, 12));
        runs.add_samples(&samples);
        for &(p, l) in &samples {
            single.add_sample(p, l);
        }
        assert_eq!(tile_bits(&runs), tile_bits(&single));
    }

    /// The same for box-filtered runs with AOV layers (`add_samples_touched`).
    #[test]
    fn owner_runs_with_layers_add_like_single_samples() {
        let names: Vec<String> = (0..3).map(|i| format!("l{i}")).collect();
        let film = Film::with_layers(16, 16, Filter::Box, &names);
        let mut rng = crate::sampling::Pcg32::new(5, 9);
        let samples: Vec<(Vec2, Rgb, Vec<Rgb>, u32)> = pixel_runs(&mut rng, (8, 0, 16, 8), 6)
            .into_iter()
            .enumerate()
            .map(|(k, (p, l))| (p, l, vec![l * 0.5, Rgb::BLACK, Rgb::splat(k as f32)], if k % 3 == 0 { 0 } else { 0b101 }))
            .collect();
        let (mut runs, mut single) = (film.tile(8, 0, 16, 8), film.tile(8, 0, 16, 8));
        runs.add_samples_touched(samples.iter().map(|(p, l, row, t)| (*p, *l, row.as_slice(), *t)));
        for (p, l, row, t) in &samples {
            single.add_sample_touched(*p, *l, row, *t);
        }
        assert_eq!(tile_bits(&runs), tile_bits(&single));
        assert_eq!(runs.layers.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), single.layers.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
        assert!(runs.pixels.iter().all(|px| px.n >= 2));
    }

    /// Tile sums (the driver's per-tile pass tree) add exactly as films do, and a blank tile
    /// (nothing added since it was cleared) adds nothing.
    #[test]
    fn tile_sums_add_like_films() {
        let film = Film::with_layers(8, 8, Filter::Box, &["a".to_string()]);
        let mut a = film.tile(0, 0, 8, 8);
        let mut b = film.tile(0, 0, 8, 8);
        a.add_sample_touched(Vec2::new(1.5, 2.5), Rgb::splat(0.25), &[Rgb::splat(0.5)], 1);
        b.add_sample_touched(Vec2::new(1.5, 2.5), Rgb::splat(0.125), &[Rgb::splat(1.0)], 1);
        let mut direct = Film::with_layers(8, 8, Filter::Box, &["a".to_string()]);
        direct.merge_tile(&a);
        direct.merge_tile(&b);
        a.add(&b);
        let mut summed = Film::with_layers(8, 8, Filter::Box, &["a".to_string()]);
        summed.merge_tile(&a);
        assert_eq!(summed.image().data, direct.image().data);
        assert_eq!(summed.layer_image(0).data, direct.layer_image(0).data);
        assert_eq!(summed.variance_image().data, direct.variance_image().data);
        b.clear();
        a.add(&b);
        let mut again = Film::with_layers(8, 8, Filter::Box, &["a".to_string()]);
        again.merge_tile(&a);
        assert_eq!(again.image().data, direct.image().data);
        assert_eq!(again.layer_image(0).data, direct.layer_image(0).data);
    }

    /// A splat at a pixel found by the caller (`splat_pixel`) adds what `splat` at the
    /// pixel's centre adds, bit for bit, with layers beside the beauty and non-finite values
    /// left out; `splat_pixels` of the same list too.
    #[test]
    fn splat_pixel_is_the_centre_splat() {
        let names = ["a".to_string(), "b".to_string()];
        let (mut by_centre, mut by_pixel) = (Film::with_layers(5, 3, Filter::Box, &names), Film::with_layers(5, 3, Filter::Box, &names));
        let mut by_run = Film::with_layers(5, 3, Filter::Box, &names);
        let values = [Rgb::new(0.1, 0.2, 0.3), Rgb::new(1e-30, -0.0, 3.5e7), Rgb::new(f32::NAN, 1.0, 1.0), Rgb::new(0.7, f32::INFINITY, 0.0)];
        let list: Vec<_> = values.iter().cycle().take(40).enumerate().map(|(k, l)| ((k * 7 % 5) as u32, (k % 3) as u32, *l)).collect();
        for &(x, y, l) in &list {
            by_centre.splat(Vec2::new(x as f32 + 0.5, y as f32 + 0.5), l);
            by_pixel.splat_pixel(x, y, l);
        }
        by_run.splat_pixels(list.into_iter());
        let bits = |f: &Film| f.splats.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&by_centre), bits(&by_pixel));
        assert_eq!(bits(&by_run), bits(&by_pixel));
        assert!(!by_pixel.splats.is_empty());
        // No finite splat (or none at all): no buffer, as `splat_pixel` leaves it.
        let mut none = Film::new(5, 3, Filter::Box);
        none.splat_pixels([(1, 1, Rgb::new(f32::NAN, 0.0, 0.0))].into_iter());
        none.splat_pixels(std::iter::empty());
        assert!(none.splats.is_empty());
    }
}
