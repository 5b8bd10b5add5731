//! Piecewise-constant distributions: discrete choice (lights, triangles) and 2-D images.

use glam::Vec2;

#[derive(Clone, Debug)]
pub struct Distribution1D {
    /// Unnormalised function values.
    pub func: Vec<f32>,
    /// Normalised CDF, `func.len() + 1` entries from 0 to 1.
    pub cdf: Vec<f32>,
    pub integral: f32,
    /// For long distributions, where the search for u in [j/G, (j+1)/G) starts: the largest
    /// i with cdf[i] <= j/G (G = the length). Empty below [`GUIDE_MIN`] entries.
    guide: Vec<u32>,
    /// `guide.len()` as a float, converted once (a usize-to-float conversion is a branchy
    /// sequence on x86-64 without AVX-512).
    guide_len_f: f32,
}

/// Distributions at least this long get a guide table: their searches would otherwise walk
/// a binary search through a CDF larger than a few cache lines (an environment map's rows).
const GUIDE_MIN: usize = 64;

/// Distributions up to this long are searched by counting ([`Distribution1D::find_short`]).
const SHORT_MAX: usize = 16;

/// The guide table of `cdf` with `g` entries (see [`Distribution1D::guide`]).
fn guide_table(cdf: &[f32], g: usize) -> Vec<u32> {
    let mut out = Vec::with_capacity(g);
    let mut i = 0usize;
    for j in 0..g {
        let t = j as f32 / g as f32;
        while i + 1 < cdf.len() && cdf[i + 1] <= t {
            i += 1;
        }
        out.push(i as u32);
    }
    out
}

impl Distribution1D {
    /// Values must be finite and non-negative; an all-zero function becomes uniform.
    pub fn new(func: &[f32]) -> Self {
        let n = func.len();
        let mut cdf = vec![0.0f32; n + 1];
        let mut acc = 0.0f64;
        for i in 0..n {
            acc += func[i].max(0.0) as f64 / n as f64;
            cdf[i + 1] = acc as f32;
        }
        let integral = acc as f32;
        if integral > 0.0 {
            for c in cdf.iter_mut().skip(1) {
                *c /= integral;
            }
        } else {
            for (i, c) in cdf.iter_mut().enumerate() {
                *c = i as f32 / n.max(1) as f32;
            }
        }
        if n > 0 {
            cdf[n] = 1.0;
        }
        let guide = if n >= GUIDE_MIN { guide_table(&cdf, n) } else { Vec::new() };
        let guide_len_f = guide.len() as f32;
        Distribution1D { func: func.to_vec(), cdf, integral, guide, guide_len_f }
    }
    pub fn len(&self) -> usize {
        self.func.len()
    }
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }
    /// Probability of choosing entry `i` when sampling discretely.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.cdf[i + 1] - self.cdf[i]
    }
    /// Out of line: the search is for long distributions; short ones stay inline.
    #[inline(never)]
    fn find(&self, u: f32) -> usize {
        // Largest i with cdf[i] <= u, and a non-empty interval.
        let i = self.last_at_most(u).min(self.func.len() - 1);
        if self.cdf[i + 1] > self.cdf[i] {
            return i; // the common case: the interval found is not empty
        }
        self.nonempty_near(i)
    }
    /// [`Self::find`] of a short distribution, inline: the entries of the CDF at most u are a
    /// prefix of it (it is non-decreasing, and cdf[0] = 0), so counting them gives the binary
    /// search's index without its call and its branches, which random u mispredict (a scene's
    /// few lights, chosen at every path vertex). cdf[n] is left out: it bounds the index by
    /// n - 1 as `find`'s `min` does.
    #[inline(always)]
    fn find_short(&self, u: f32) -> usize {
        let n = self.func.len();
        let i = self.cdf[1..n].iter().map(|&c| usize::from(c <= u)).sum::<usize>();
        if self.cdf[i + 1] > self.cdf[i] {
            return i;
        }
        self.nonempty_near(i)
    }
    /// The entry `find` takes where the interval of entry `i` is empty: the nearest non-empty
    /// one below it, else above it.
    #[inline(never)]
    fn nonempty_near(&self, mut i: usize) -> usize {
        while i > 0 && self.pmf(i) == 0.0 {
            i -= 1;
        }
        while self.pmf(i) == 0.0 && i + 1 < self.func.len() {
            i += 1;
        }
        i
    }
    /// The largest i with cdf[i] <= u (0 if none): a binary search, or where there is a guide
    /// table, a short walk from its entry for u. The CDF is non-decreasing, so both find the
    /// same index (the walk goes down past entries above u, then up past entries at most u).
    #[inline]
    fn last_at_most(&self, u: f32) -> usize {
        if self.guide.is_empty() {
            return self.cdf.partition_point(|&c| c <= u).saturating_sub(1);
        }
        let mut i = self.guide[self.guide_index(u)] as usize;
        // Down past entries above u (all of them for a NaN u: nothing compares with it).
        while i > 0 && !matches!(self.cdf[i].partial_cmp(&u), Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)) {
            i -= 1;
        }
        while i + 1 < self.cdf.len() && self.cdf[i + 1] <= u {
            i += 1;
        }
        i
    }
    /// The guide table's entry for u (the table must not be empty). A NaN u goes to entry
    /// 0, as the binary search sends it. Through u32, a single instruction: the same index,
    /// as both conversions saturate and `min` bounds it.
    #[inline(always)]
    fn guide_index(&self, u: f32) -> usize {
        ((u * self.guide_len_f) as u32 as usize).min(self.guide.len() - 1)
    }
    /// Asks for the guide table's entry that [`Self::sample_discrete`] of u reads first (a
    /// hint, which changes no value; nothing without a guide table).
    #[inline(always)]
    pub fn prefetch_guide(&self, u: f32) {
        if !self.guide.is_empty() {
            crate::accel::prefetch(self.guide.as_ptr().wrapping_add(self.guide_index(u)), 1);
        }
    }
    /// Asks for the CDF entries where [`Self::sample_discrete`] of u starts its walk (reads
    /// the guide table's entry: ask for it first, [`Self::prefetch_guide`]).
    #[inline(always)]
    pub fn prefetch_cdf(&self, u: f32) {
        if !self.guide.is_empty() {
            let i = self.guide[self.guide_index(u)] as usize;
            // The walk reads cdf[i] and cdf[i + 1] at least (wrapping: a hint never faults).
            let c = self.cdf.as_ptr().wrapping_add(i);
            crate::accel::prefetch(c, 1);
            crate::accel::prefetch(c.wrapping_add(1), 1);
        }
    }
    /// Discrete sample: (index, pmf, u remapped to [0,1) within the chosen interval).
    #[inline(always)]
    pub fn sample_discrete(&self, u: f32) -> (usize, f32, f32) {
        let i = match self.func.len() {
            // No entry (a scene without lights): probability 0, which every caller checks
            // before using the index.
            0 => return (0, 0.0, 0.0),
            // One entry (a scene's only light): nothing to search.
            1 => return (0, 1.0, u),
            // Two (a quad light's triangles): one comparison. Neither interval can be empty
            // where u lands, since u < 1.
            2 => usize::from(u >= self.cdf[1]),
            n if n <= SHORT_MAX => self.find_short(u),
            _ => self.find(u),
        };
        let p = self.pmf(i);
        let ur = if p > 0.0 { ((u - self.cdf[i]) / p).clamp(0.0, crate::math::ONE_MINUS_EPSILON) } else { 0.0 };
        (i, p, ur)
    }
    /// Continuous sample in [0,1): (x, pdf, index).
    #[inline]
    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let (i, p, ur) = self.sample_discrete(u);
        let n = self.func.len() as f32;
        let x = ((i as f32 + ur) / n).min(crate::math::ONE_MINUS_EPSILON);
        let pdf = if self.integral > 0.0 { self.func[i] / self.integral } else { 1.0 };
        let _ = p;
        (x, pdf, i)
    }
    /// Density of `sample_continuous` at x in [0,1).
    pub fn pdf_continuous(&self, x: f32) -> f32 {
        let n = self.func.len();
        let i = ((x * n as f32) as usize).min(n - 1);
        if self.integral > 0.0 {
            self.func[i] / self.integral
        } else {
            1.0
        }
    }
}

/// A 2-D piecewise-constant distribution over [0,1]^2 (rows by v, columns by u).
#[derive(Clone, Debug)]
pub struct Distribution2D {
    conditional: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// `func` is row-major, `height` rows of `width` values.
    pub fn new(func: &[f32], width: usize, height: usize) -> Self {
        let conditional: Vec<Distribution1D> = (0..height).map(|y| Distribution1D::new(&func[y * width..(y + 1) * width])).collect();
        let marg: Vec<f32> = conditional.iter().map(|c| c.integral).collect();
        Distribution2D { marginal: Distribution1D::new(&marg), conditional }
    }
    /// Returns the point in [0,1)^2 and its density w.r.t. area in [0,1]^2.
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (y, py, row) = self.marginal.sample_continuous(u.y);
        let (x, px, _) = self.conditional[row].sample_continuous(u.x);
        (Vec2::new(x, y), px * py)
    }
    pub fn pdf(&self, p: Vec2) -> f32 {
        let h = self.conditional.len();
        let row = ((p.y * h as f32) as usize).min(h - 1);
        self.marginal.pdf_continuous(p.y) * self.conditional[row].pdf_continuous(p.x)
    }
}

#[cfg(test)]
mod tests {
    /// The guide table's walk finds the binary search's index for every u: random ones, the
    /// CDF's own values and their neighbours, the ends and beyond, NaN; with runs of zero
    /// weights (flat CDF stretches) and one huge weight (most of the CDF in one step).
    #[test]
    fn guided_search_is_the_binary_search() {
        let mut rng = crate::sampling::rng::Pcg32::new(5, 9);
        for case in 0..40 {
            let n = 64 + case * 37;
            let f: Vec<f32> = (0..n)
                .map(|i| match case % 4 {
                    0 => rng.next_f32(),
                    1 => {
                        if rng.next_f32() < 0.7 {
                            0.0
                        } else {
                            rng.next_f32()
                        }
                    }
                    2 => {
                        if i == n / 3 {
                            1e6
                        } else {
                            rng.next_f32() * 1e-3
                        }
                    }
                    _ => 0.0,
                })
                .collect();
            let d = Distribution1D::new(&f);
            assert_eq!(d.guide.len(), n);
            let mut us: Vec<f32> = (0..2000).map(|_| rng.next_f32()).collect();
            for &c in &d.cdf {
                us.extend([c, f32::from_bits(c.to_bits().saturating_sub(1)), f32::from_bits(c.to_bits() + 1)]);
            }
            us.extend([0.0, -0.0, -1e-9, 1.0, 1.5, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, crate::math::ONE_MINUS_EPSILON]);
            for &u in &us {
                let want = d.cdf.partition_point(|&c| c <= u).saturating_sub(1);
                assert_eq!(d.last_at_most(u), want, "case {case} u {u}");
            }
        }
    }

    use super::*;

    /// The counting search of short distributions takes `find`'s entry for every u: random
    /// ones, the CDF's own values and their neighbours, the ends and beyond, NaN; with zero
    /// weights at the ends and inside (empty intervals), all zero, and one huge weight.
    #[test]
    fn short_search_is_find() {
        let mut rng = crate::sampling::rng::Pcg32::new(11, 4);
        let mut checked = 0;
        for case in 0..60 {
            let n = 3 + case % (SHORT_MAX - 2);
            let f: Vec<f32> = (0..n)
                .map(|i| match case % 5 {
                    0 => rng.next_f32(),
                    1 if rng.next_f32() < 0.5 => 0.0,
                    1 => rng.next_f32(),
                    2 if i == 0 || i == n - 1 => 0.0,
                    2 => 1.0 + rng.next_f32(),
                    3 if i == n / 2 => 1e6,
                    3 => rng.next_f32() * 1e-3,
                    _ => 0.0,
                })
                .collect();
            let d = Distribution1D::new(&f);
            let mut us: Vec<f32> = (0..500).map(|_| rng.next_f32()).collect();
            for &c in &d.cdf {
                us.extend([c, f32::from_bits(c.to_bits().saturating_sub(1)), f32::from_bits(c.to_bits() + 1)]);
            }
            us.extend([0.0, -0.0, -1e-9, 1.0, 1.5, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, crate::math::ONE_MINUS_EPSILON]);
            for &u in &us {
                assert_eq!(d.find_short(u), d.find(u), "case {case} n {n} u {u} cdf {:?}", d.cdf);
                checked += 1;
            }
        }
        assert!(checked > 30_000);
    }

    #[test]
    fn discrete_matches_weights() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]);
        assert!((d.pmf(0) - 0.25).abs() < 1e-6 && d.pmf(1) == 0.0 && (d.pmf(2) - 0.75).abs() < 1e-6);
        assert_eq!(d.sample_discrete(0.1).0, 0);
        assert_eq!(d.sample_discrete(0.25).0, 2);
        assert_eq!(d.sample_discrete(0.999).0, 2);
    }

    #[test]
    fn continuous_pdf_consistent() {
        let d = Distribution1D::new(&[1.0, 2.0, 0.5, 4.0]);
        for k in 0..100 {
            let u = (k as f32 + 0.5) / 100.0;
            let (x, pdf, _) = d.sample_continuous(u);
            assert!((pdf - d.pdf_continuous(x)).abs() < 1e-5);
        }
        let d2 = Distribution2D::new(&[1.0, 2.0, 3.0, 4.0, 0.0, 1.0], 3, 2);
        // The pdf integrates to one over the unit square.
        let mut s = 0.0;
        for i in 0..30 {
            for j in 0..20 {
                s += d2.pdf(Vec2::new((i as f32 + 0.5) / 30.0, (j as f32 + 0.5) / 20.0));
            }
        }
        assert!((s / 600.0 - 1.0).abs() < 1e-4);
    }
}
