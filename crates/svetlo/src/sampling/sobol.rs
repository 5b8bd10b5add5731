//! Padded Owen-scrambled Sobol sampler (Burley, "Practical hash-based Owen scrambling",
//! JCGT 9(4), 2020).
//!
//! Every call of `next_1d` or `next_2d` opens a new *slot* of the pixel sample. A 2-D slot
//! takes the first two dimensions of the Sobol sequence, a (0,2)-sequence in base 2; a 1-D
//! slot takes the first, van der Corput. Each slot of each pixel has its own seeds for
//! 1. an index shuffle: a nested uniform (Owen) scramble of the sample index's bits, which
//!    permutes indices only inside aligned power-of-two blocks, so the first `2^k` samples
//!    of a pixel still use one whole aligned block of the sequence, and different slots
//!    use unrelated orders (no correlation between, say, the light sample and the BSDF
//!    sample of a vertex);
//! 2. an Owen scramble of each coordinate (every bit flipped by a hash of the bits above it).
//!
//! So every slot, whatever its depth in the path, is an Owen-scrambled (0,2)-sequence: the
//! first `2^k` samples of a pixel put exactly one point in every elementary interval of
//! area `2^-k` of every 2-D slot, and one in every interval of length `2^-k` of a 1-D
//! slot. A global high-dimensional Sobol sequence (the previous sampler here) has 2-D
//! projections whose quality falls with the dimension, which stopped its error from
//! falling faster than `1/spp` past 64 spp on the Cornell box.
//!
//! Cost: the scrambles are worked in reversed-bit order, where the Laine–Karras hash
//! (constants by N. Vegdahl, 2021) has the nested property; Sobol's second dimension in
//! reversed order is a subset transform of the index's bit positions, five shift-and-xor
//! steps, and van der Corput in reversed order is the index itself. A slot's seeds are one
//! 32-bit mix each of a counter started at the pixel's key, so the eight-wide kernel works
//! eight lanes' seeds as vector code too.
//!
//! Every value is a pure function of (seed, pixel, sample index, slot): the image does not
//! depend on the thread count, the tile order or how the samples are split into passes.

use super::rng::hash_seed;
use super::Sampler;
use glam::Vec2;

/// A bijection of u32 in which output bit i depends only on input bits 0..=i
/// (Laine–Karras style; constants from Vegdahl's improved hash).
#[inline(always)]
fn lk_hash(mut x: u32, seed: u32) -> u32 {
    x ^= x.wrapping_mul(0x3d20_adea);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(0x0552_6c56);
    x ^= x.wrapping_mul(0x53a2_2864);
    x
}

/// Nested uniform (Owen) scramble of a 32-bit fraction: each bit is flipped by a hash of
/// the bits above it, so every dyadic interval is permuted as a whole.
#[inline(always)]
pub fn owen_scramble(x: u32, seed: u32) -> u32 {
    lk_hash(x.reverse_bits(), seed).reverse_bits()
}

/// Sobol's second dimension at `index`, bit-reversed: bit `p` of the result (fraction bit
/// `p` from the top) is the parity of the index bits `k` with `p ⊆ k` (as 5-bit numbers),
/// the Pascal matrix mod 2 by Lucas' theorem; a superset-sum over the positions' bits.
#[inline(always)]
pub fn sobol1_reversed(index: u32) -> u32 {
    let mut u = index;
    u ^= (u >> 1) & 0x5555_5555;
    u ^= (u >> 2) & 0x3333_3333;
    u ^= (u >> 4) & 0x0f0f_0f0f;
    u ^= (u >> 8) & 0x00ff_00ff;
    u ^= (u >> 16) & 0x0000_ffff;
    u
}

/// A 32-bit fraction to a float in [0, 1) (24 bits keep it below 1 and exact).
#[inline(always)]
fn to_unit(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Odd multiplier (2^32 / golden ratio) that spreads slot numbers before the seed hash.
const SLOT_STEP: u32 = 0x9e37_79b9;

/// A 32-bit mix with full avalanche (Wellons' "lowbias32"): two multiplications, so that
/// eight lanes' seeds are a few AVX2 instructions (a 64-bit mix per seed was half of
/// Sobol's cost in the eight-wide kernel).
#[inline(always)]
fn mix32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// Seed `j` of slot `slot` of the pixel with key `key` (j: 0 the index shuffle, 1 and 2 the
/// scrambles of the first and second coordinate): one mix of a Weyl sequence started at
/// the key. Two pixels share seeds only where their 32-bit keys are equal (about one pair
/// in a 256x256 film), which only makes those two pixels' noise alike.
#[inline(always)]
fn slot_seed(key: u32, slot: u32, j: u32) -> u32 {
    mix32(key.wrapping_add(slot.wrapping_mul(4).wrapping_add(j).wrapping_mul(SLOT_STEP)))
}

#[derive(Clone, Debug)]
pub struct SobolSampler {
    seed: u64,
    spp: u32,
    /// Hash of (seed, pixel), folded to 32 bits, and the pixel it was computed for.
    key: u32,
    pixel: (u32, u32),
    /// The sample index, bit-reversed (the input of the index shuffle).
    index_reversed: u32,
    /// Slots opened so far in this pixel sample.
    slot: u32,
}

/// A pixel's key: its 64-bit hash folded to 32 bits.
fn pixel_key(seed: u64, x: u32, y: u32) -> u32 {
    let k = hash_seed(&[seed, x as u64, y as u64]);
    (k ^ (k >> 32)) as u32
}

impl SobolSampler {
    pub fn new(spp: u32, seed: u64) -> Self {
        SobolSampler { seed, spp, key: pixel_key(seed, 0, 0), pixel: (0, 0), index_reversed: 0, slot: 0 }
    }

    /// Opens the next slot: its number.
    #[inline(always)]
    fn open_slot(&mut self) -> u32 {
        self.slot = self.slot.wrapping_add(1);
        self.slot
    }

    /// The slot's shuffled sample index.
    #[inline(always)]
    fn shuffled(&self, seed: u32) -> u32 {
        lk_hash(self.index_reversed, seed).reverse_bits()
    }
}

/// Slots of one path vertex as the eight-wide path kernel draws them: light choice (1-D),
/// light point (2-D), BSDF lobe (1-D), BSDF direction (2-D), Russian roulette (1-D).
pub(crate) const VERTEX_SLOTS: [bool; 5] = [false, true, false, true, false];

impl SobolSampler {
    /// The draws of [`VERTEX_SLOTS`] for eight samplers at once (those of `lanes`), in
    /// order (1-D slots one value, 2-D slots two): the same values as each sampler's
    /// `next_1d`/`next_2d` calls. Seeds and scrambles of all eight lanes are worked side by
    /// side (vector code where the caller is compiled for AVX2); lanes outside `lanes` get
    /// values nobody reads and their samplers do not move.
    #[inline(always)]
    pub(crate) fn vertex_draws8(s: &mut [SobolSampler; 8], lanes: u8) -> [[f32; 8]; 7] {
        let idx: [u32; 8] = std::array::from_fn(|l| s[l].index_reversed);
        let key: [u32; 8] = std::array::from_fn(|l| s[l].key);
        let slot0: [u32; 8] = std::array::from_fn(|l| s[l].slot);
        let mut out = [[0.0f32; 8]; 7];
        let mut o = 0;
        for (k, &two) in VERTEX_SLOTS.iter().enumerate() {
            let seed = |j: u32| -> [u32; 8] { std::array::from_fn(|l| slot_seed(key[l], slot0[l].wrapping_add(k as u32 + 1), j)) };
            let (shuffle, sx) = (seed(0), seed(1));
            let i: [u32; 8] = std::array::from_fn(|l| lk_hash(idx[l], shuffle[l]).reverse_bits());
            out[o] = std::array::from_fn(|l| to_unit(lk_hash(i[l], sx[l]).reverse_bits()));
            o += 1;
            if two {
                let sy = seed(2);
                out[o] = std::array::from_fn(|l| to_unit(lk_hash(sobol1_reversed(i[l]), sy[l]).reverse_bits()));
                o += 1;
            }
        }
        for (l, sl) in s.iter_mut().enumerate() {
            if lanes & (1 << l) != 0 {
                sl.slot = sl.slot.wrapping_add(VERTEX_SLOTS.len() as u32);
            }
        }
        out
    }
}

impl Sampler for SobolSampler {
    fn start_pixel_sample(&mut self, x: u32, y: u32, index: u32) {
        if (x, y) != self.pixel {
            self.pixel = (x, y);
            self.key = pixel_key(self.seed, x, y);
        }
        self.index_reversed = index.reverse_bits();
        self.slot = 0;
    }
    #[inline]
    fn next_1d(&mut self) -> f32 {
        let slot = self.open_slot();
        let i = self.shuffled(slot_seed(self.key, slot, 0));
        // Van der Corput of `i` in reversed order is `i`: scramble it, reverse once.
        to_unit(lk_hash(i, slot_seed(self.key, slot, 1)).reverse_bits())
    }
    #[inline]
    fn next_2d(&mut self) -> Vec2 {
        let slot = self.open_slot();
        let i = self.shuffled(slot_seed(self.key, slot, 0));
        let x = lk_hash(i, slot_seed(self.key, slot, 1)).reverse_bits();
        let y = lk_hash(sobol1_reversed(i), slot_seed(self.key, slot, 2)).reverse_bits();
        Vec2::new(to_unit(x), to_unit(y))
    }
    fn samples_per_pixel(&self) -> u32 {
        self.spp
    }
    fn clone_box(&self) -> Box<dyn Sampler> {
        Box::new(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::stats::chi2_sf;
    use crate::sampling::IndependentSampler;

    /// Sobol's second dimension from its direction numbers (m_k = 1, polynomial x + 1), the
    /// textbook way: XOR of the columns the index's bits select.
    fn sobol1_reference(index: u32) -> u32 {
        let mut v = [0u32; 32];
        v[0] = 1 << 31;
        for k in 1..32 {
            v[k] = v[k - 1] ^ (v[k - 1] >> 1);
        }
        (0..32).filter(|k| index >> k & 1 == 1).fold(0, |x, k| x ^ v[k])
    }

    /// The eight-lane vertex draws are each lane's `next_1d`/`next_2d` values, bit for bit,
    /// and leave each sampler where those calls would; lanes outside the mask are untouched.
    #[test]
    fn vertex_draws8_are_the_samplers_draws() {
        let mut lanes: [SobolSampler; 8] = std::array::from_fn(|_| SobolSampler::new(64, 21));
        let mut one = lanes.clone();
        for (l, (a, b)) in lanes.iter_mut().zip(one.iter_mut()).enumerate() {
            let (x, y, i) = (l as u32 * 7, 3 + l as u32, 5 * l as u32 + 1);
            a.start_pixel_sample(x, y, i);
            b.start_pixel_sample(x, y, i);
            // Lanes at different depths of their paths.
            for _ in 0..l {
                a.next_2d();
                b.next_2d();
            }
        }
        for mask in [0xffu8, 0b1010_0110] {
            let got = SobolSampler::vertex_draws8(&mut lanes, mask);
            for l in (0..8).filter(|l| mask & (1 << l) != 0) {
                let s = &mut one[l];
                let u0 = s.next_1d();
                let a = s.next_2d();
                let u1 = s.next_1d();
                let b = s.next_2d();
                let u2 = s.next_1d();
                let want = [u0, a.x, a.y, u1, b.x, b.y, u2];
                for (k, w) in want.iter().enumerate() {
                    assert_eq!(got[k][l].to_bits(), w.to_bits(), "lane {l}, draw {k}");
                }
            }
        }
        // Every sampler is where its own calls left it (masked-out lanes were not moved).
        for (a, b) in lanes.iter_mut().zip(one.iter_mut()) {
            assert_eq!(a.next_2d(), b.next_2d());
        }
    }

    #[test]
    fn second_dimension_is_sobols() {
        let mut r = crate::sampling::Pcg32::new(3, 0);
        for i in (0..4096u32).chain((0..4096).map(|_| r.next_u32())) {
            assert_eq!(sobol1_reversed(i).reverse_bits(), sobol1_reference(i), "index {i}");
        }
    }

    /// Fraction -> index of the dyadic interval of length 2^-bits.
    fn cell(v: f32, bits: u32) -> usize {
        (v as f64 * (1u64 << bits) as f64) as usize
    }

    /// Draws `slots` slots (2-D where `two[s]`) of samples `first..first + n` of a pixel.
    fn draw(s: &mut SobolSampler, px: (u32, u32), first: u32, n: u32, two: &[bool]) -> Vec<Vec<Vec2>> {
        (first..first + n)
            .map(|i| {
                s.start_pixel_sample(px.0, px.1, i);
                two.iter().map(|&t| if t { s.next_2d() } else { Vec2::new(s.next_1d(), 0.0) }).collect()
            })
            .collect()
    }

    /// A path's slot pattern: camera (2, 2, 1), then per vertex (1, 2, 1, 2, 1), ten vertices.
    fn path_slots() -> Vec<bool> {
        let mut v = vec![true, true, false];
        for _ in 0..10 {
            v.extend([false, true, false, true, false]);
        }
        v
    }

    #[test]
    fn every_slot_is_a_net_for_power_of_two_counts() {
        // Any aligned block of 2^k samples (the first ones, or a later block as a pass of a
        // progressive render sees them) fills every elementary interval of area 2^-k of every
        // 2-D slot once, and every interval of length 2^-k of each coordinate.
        let slots = path_slots();
        let mut s = SobolSampler::new(1024, 7);
        for &px in &[(0u32, 0u32), (13, 5), (1000, 77)] {
            for k in 0..=10u32 {
                let n = 1u32 << k;
                for first in [0, n, 5 * n] {
                    let pts = draw(&mut s, px, first, n, &slots);
                    for (d, &two) in slots.iter().enumerate() {
                        let splits = if two { 0..=k } else { k..=k };
                        for a in splits {
                            let mut count = vec![0u32; n as usize];
                            for p in &pts {
                                let c = if two { (cell(p[d].x, a) << (k - a)) | cell(p[d].y, k - a) } else { cell(p[d].x, k) };
                                count[c] += 1;
                            }
                            assert!(count.iter().all(|&c| c == 1), "pixel {px:?} samples {first}+{n} slot {d} split {a}");
                        }
                        if two {
                            let mut count = vec![0u32; n as usize];
                            for p in &pts {
                                count[cell(p[d].y, k)] += 1;
                            }
                            assert!(count.iter().all(|&c| c == 1), "pixel {px:?} slot {d}.y k={k}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn every_slot_is_uniform() {
        // Chi-square of each coordinate of each slot over 32x32 pixels x 3 samples (not a
        // power of two, so strata do not make the counts exact), 64 bins; and of 2-D slots'
        // joint 8x8 histogram. Bonferroni over all the tests.
        let slots = path_slots();
        let mut s = SobolSampler::new(3, 11);
        let (w, spp) = (32u32, 3u32);
        let coords: usize = slots.iter().map(|&t| if t { 3 } else { 1 }).sum();
        let mut hist = vec![vec![0f64; 64]; coords];
        for y in 0..w {
            for x in 0..w {
                for p in draw(&mut s, (x, y), 0, spp, &slots) {
                    let mut c = 0;
                    for (d, &two) in slots.iter().enumerate() {
                        hist[c][cell(p[d].x, 6)] += 1.0;
                        c += 1;
                        if two {
                            hist[c][cell(p[d].y, 6)] += 1.0;
                            hist[c + 1][cell(p[d].x, 3) * 8 + cell(p[d].y, 3)] += 1.0;
                            c += 2;
                        }
                    }
                }
            }
        }
        let n = (w * w * spp) as f64;
        let alpha = 1e-3 / coords as f64;
        for (c, h) in hist.iter().enumerate() {
            let e = n / 64.0;
            let chi2: f64 = h.iter().map(|&o| (o - e) * (o - e) / e).sum();
            let p = chi2_sf(chi2, 63.0);
            assert!(p > alpha, "coordinate {c}: chi2 {chi2:.1}, p {p:.2e}");
        }
    }

    #[test]
    fn pixels_and_slots_are_decorrelated() {
        // Correlation coefficient of the same slot in neighbouring pixels, and of consecutive
        // slots in one pixel (the shuffle must make them independent, not only each uniform):
        // each within 4.5 standard errors (1/sqrt(pairs)) of 0.
        let slots = path_slots();
        let mut s = SobolSampler::new(16, 2);
        let (w, spp) = (48u32, 16u32);
        let (mut across, mut within, mut n_across, mut n_within) = (0f64, 0f64, 0usize, 0usize);
        let mut prev: Vec<Vec<Vec2>> = Vec::new();
        for y in 0..w {
            for x in 0..w {
                let pts = draw(&mut s, (x, y), 0, spp, &slots);
                for (i, p) in pts.iter().enumerate() {
                    for d in 0..slots.len() {
                        if x > 0 {
                            across += (p[d].x as f64 - 0.5) * (prev[i][d].x as f64 - 0.5);
                            n_across += 1;
                        }
                        if d > 0 {
                            within += (p[d].x as f64 - 0.5) * (p[d - 1].x as f64 - 0.5);
                            n_within += 1;
                        }
                    }
                }
                prev = pts;
            }
        }
        let r_across = across / n_across as f64 * 12.0;
        let r_within = within / n_within as f64 * 12.0;
        assert!(r_across.abs() < 4.5 / (n_across as f64).sqrt(), "neighbour pixels: r = {r_across}");
        assert!(r_within.abs() < 4.5 / (n_within as f64).sqrt(), "consecutive slots: r = {r_within}");
        // No shared pattern: a pixel's samples are a permutation of nothing another pixel has.
        let a = draw(&mut s, (3, 3), 0, 64, &slots);
        let b = draw(&mut s, (4, 3), 0, 64, &slots);
        let same = a.iter().flatten().zip(b.iter().flatten()).filter(|(p, q)| p == q).count();
        assert!(same <= 1, "{same} equal points in two pixels");
    }

    #[test]
    fn pure_function_of_pixel_and_index() {
        let mut a = SobolSampler::new(16, 3);
        let mut b = a.clone();
        a.start_pixel_sample(5, 9, 11);
        let va: Vec<f32> = (0..80).map(|_| a.next_1d()).collect();
        b.start_pixel_sample(0, 0, 2);
        let _ = b.next_2d();
        b.start_pixel_sample(5, 9, 11);
        let vb: Vec<f32> = (0..80).map(|_| b.next_1d()).collect();
        assert_eq!(va, vb);
        // Another seed, another sequence.
        let mut c = SobolSampler::new(16, 4);
        c.start_pixel_sample(5, 9, 11);
        let vc: Vec<f32> = (0..80).map(|_| c.next_1d()).collect();
        assert_ne!(va, vc);
    }

    /// RMS error over 256 pixels of the mean of `f` over `n` samples of 2-D slot `depth`.
    fn rmse(s: &mut dyn Sampler, n: u32, depth: usize, f: &dyn Fn(Vec2) -> f64, exact: f64) -> f64 {
        let mut se = 0.0;
        for p in 0..256u32 {
            let mut acc = 0.0;
            for i in 0..n {
                s.start_pixel_sample(p, 0, i);
                for _ in 0..depth {
                    s.next_2d();
                }
                acc += f(s.next_2d());
            }
            se += (acc / n as f64 - exact).powi(2);
        }
        (se / 256.0).sqrt()
    }

    #[test]
    fn converges_faster_than_independent_in_every_slot() {
        // Smooth integrand sin(pi u) e^v (integral (2/pi)(e - 1)) and a discontinuous one (the
        // disk of radius 0.7 about the origin, as a shadow edge: area pi 0.49 / 4).
        let smooth = |u: Vec2| (std::f64::consts::PI * u.x as f64).sin() * (u.y as f64).exp();
        let smooth_exact = 2.0 / std::f64::consts::PI * (std::f64::consts::E - 1.0);
        let disk = |u: Vec2| if u.length_squared() < 0.49 { 1.0 } else { 0.0 };
        let disk_exact = std::f64::consts::PI * 0.49 / 4.0;
        let n = 256;
        for depth in [0, 1, 20] {
            let e_ind = rmse(&mut IndependentSampler::new(n, 0), n, depth, &smooth, smooth_exact);
            let e_sob = rmse(&mut SobolSampler::new(n, 0), n, depth, &smooth, smooth_exact);
            // Independent: sigma_f / 16 ~ 0.03; Owen-scrambled (0,2): ~ n^-1.5.
            assert!(e_sob < 0.05 * e_ind, "smooth, slot {depth}: sobol {e_sob:e} vs independent {e_ind:e}");
            let e_ind = rmse(&mut IndependentSampler::new(n, 0), n, depth, &disk, disk_exact);
            let e_sob = rmse(&mut SobolSampler::new(n, 0), n, depth, &disk, disk_exact);
            // Edge in 2-D: ~ n^-0.75, at n = 256 a quarter of n^-0.5 or less.
            assert!(e_sob < 0.4 * e_ind, "disk, slot {depth}: sobol {e_sob:e} vs independent {e_ind:e}");
        }
    }
}
