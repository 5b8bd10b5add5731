//! Samplers hand out the dimensions of one pixel sample in a fixed order. Their
//! state is a pure function of (seed, pixel, sample index), so the image does not
//! depend on thread count or tile order.

use super::rng::{hash_seed, hash_seed_after, Pcg32};
use glam::Vec2;

pub trait Sampler: Send + Sync {
    /// Position the sampler at sample `index` of pixel `(x, y)`.
    fn start_pixel_sample(&mut self, x: u32, y: u32, index: u32);
    fn next_1d(&mut self) -> f32;
    fn next_2d(&mut self) -> Vec2 {
        let a = self.next_1d();
        let b = self.next_1d();
        Vec2::new(a, b)
    }
    fn samples_per_pixel(&self) -> u32;
    /// A fresh sampler with the same settings (one per worker thread).
    fn clone_box(&self) -> Box<dyn Sampler>;
}

/// Which sampler a render uses (scene file `<sampler type=...>` or the CLI).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SamplerKind {
    /// Uniform random numbers (PCG32 per pixel sample); Mitsuba's test scenes ask for it.
    Independent,
    /// Padded Owen-scrambled Sobol (0,2)-sequences, the default: low discrepancy, lower
    /// error than independent at every spp on the Cornell box, at 0.4-0.9 of its cost at
    /// equal error (README, "Samplers").
    #[default]
    Sobol,
}

#[derive(Clone, Debug)]
pub struct IndependentSampler {
    /// `hash_seed(&[seed])`: each pixel sample's hash goes on from it.
    seed_hash: u64,
    spp: u32,
    rng: Pcg32,
}

impl IndependentSampler {
    pub fn new(spp: u32, seed: u64) -> Self {
        IndependentSampler { seed_hash: hash_seed(&[seed]), spp, rng: Pcg32::new(seed, 0) }
    }

    /// The next `N` one-dimensional values of eight samplers, row `i` the `i`-th of every
    /// one (a 2-D draw is two rows: `next_2d` draws x, then y), for the lanes of `lanes`;
    /// the others' rows hold values nobody reads and their samplers do not move.
    #[inline(always)]
    pub(crate) fn draws8<const N: usize>(s: &mut [IndependentSampler; 8], lanes: u8) -> [[f32; 8]; N] {
        let mut rngs: [Pcg32; 8] = std::array::from_fn(|l| s[l].rng.clone());
        let out = Pcg32::next_f32_lanes::<N>(&mut rngs);
        for (l, (sl, r)) in s.iter_mut().zip(rngs).enumerate() {
            if lanes & (1 << l) != 0 {
                sl.rng = r;
            }
        }
        out
    }
}

impl Sampler for IndependentSampler {
    fn start_pixel_sample(&mut self, x: u32, y: u32, index: u32) {
        // hash_seed(&[seed, x, y]), its first part's round done once.
        let h = hash_seed_after(self.seed_hash, &[x as u64, y as u64]);
        self.rng = Pcg32::new(h, index as u64);
    }
    #[inline]
    fn next_1d(&mut self) -> f32 {
        self.rng.next_f32()
    }
    /// Both draws in one virtual call (same order as two `next_1d`).
    #[inline]
    fn next_2d(&mut self) -> Vec2 {
        let a = self.rng.next_f32();
        let b = self.rng.next_f32();
        Vec2::new(a, b)
    }
    fn samples_per_pixel(&self) -> u32 {
        self.spp
    }
    fn clone_box(&self) -> Box<dyn Sampler> {
        Box::new(self.clone())
    }
}

/// Build the sampler a render asked for.
pub fn make_sampler(kind: SamplerKind, spp: u32, seed: u64) -> Box<dyn Sampler> {
    match kind {
        SamplerKind::Independent => Box::new(IndependentSampler::new(spp, seed)),
        SamplerKind::Sobol => Box::new(super::sobol::SobolSampler::new(spp, seed)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eight samplers' draws side by side are each one's `next_1d`/`next_2d` values in
    /// order, and leave each where those calls would; lanes outside the mask do not move.
    #[test]
    fn draws8_are_the_samplers_draws() {
        let mut lanes: [IndependentSampler; 8] = std::array::from_fn(|_| IndependentSampler::new(64, 21));
        for (l, s) in lanes.iter_mut().enumerate() {
            s.start_pixel_sample(l as u32 * 7, 3 + l as u32, 5 * l as u32 + 1);
        }
        let mut one = lanes.clone();
        for mask in [0xffu8, 0b1010_0110] {
            let got = IndependentSampler::draws8::<7>(&mut lanes, mask);
            for (l, s) in one.iter_mut().enumerate().filter(|(l, _)| mask & (1 << l) != 0) {
                let (a, b) = (s.next_1d(), s.next_2d());
                let (c, d, e) = (s.next_1d(), s.next_2d(), s.next_1d());
                let want = [a, b.x, b.y, c, d.x, d.y, e];
                for (row, w) in got.iter().zip(want) {
                    assert_eq!(row[l].to_bits(), w.to_bits(), "lane {l}, mask {mask:#x}");
                }
            }
        }
        for (a, b) in lanes.iter_mut().zip(&mut one) {
            assert_eq!(a.next_1d().to_bits(), b.next_1d().to_bits());
        }
    }
}
