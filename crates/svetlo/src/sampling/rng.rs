//! PCG32 (O'Neill): small state, good statistics, streams selected by the increment.

#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

const MULT: u64 = 0x5851_f42d_4c95_7f2d;

impl Pcg32 {
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Pcg32 { state: 0, inc: (stream << 1) | 1 };
        r.next_u32();
        r.state = r.state.wrapping_add(seed);
        r.next_u32();
        r
    }
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(MULT).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }
    /// Uniform in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
    /// The next `N` floats of each of eight generators, row `i` the `i`-th draw of every one:
    /// the values of `N` calls of `next_f32` on each, the states advanced alike. Side by side
    /// in arrays (vector code in a caller compiled for AVX2: eight 64-bit steps in a few
    /// multiplies rather than eight dependent ones).
    #[inline(always)]
    pub fn next_f32_lanes<const N: usize>(r: &mut [Pcg32; 8]) -> [[f32; 8]; N] {
        let mut state: [u64; 8] = std::array::from_fn(|l| r[l].state);
        let inc: [u64; 8] = std::array::from_fn(|l| r[l].inc);
        let mut out = [[0.0f32; 8]; N];
        for row in out.iter_mut() {
            for l in 0..8 {
                let old = state[l];
                state[l] = old.wrapping_mul(MULT).wrapping_add(inc[l]);
                let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
                let rot = (old >> 59) as u32;
                row[l] = (xorshifted.rotate_right(rot) >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
            }
        }
        for (g, s) in r.iter_mut().zip(state) {
            g.state = s;
        }
        out
    }
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        let hi = (self.next_u32() as u64) << 21;
        let lo = (self.next_u32() >> 11) as u64;
        ((hi | lo) as f64) * (1.0 / (1u64 << 53) as f64)
    }
}

/// A 64-bit mix (splitmix64 finaliser), for deriving independent seeds from indices.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash several integers into one seed.
#[inline]
pub fn hash_seed(parts: &[u64]) -> u64 {
    hash_seed_after(0x9e37_79b9_7f4a_7c15, parts)
}

/// [`hash_seed`] of the parts that gave `h` followed by `parts`: a caller that hashes many
/// tuples with the same first parts hashes those once.
#[inline]
pub fn hash_seed_after(h: u64, parts: &[u64]) -> u64 {
    parts.iter().fold(h, |h, &p| mix64(h ^ p.wrapping_add(0x9e37_79b9_7f4a_7c15)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A seed hashed on from its first parts' hash is the whole tuple's.
    #[test]
    fn hash_seed_after_continues_hash_seed() {
        for (seed, x, y) in [(0u64, 0u64, 0u64), (1, 2, 3), (u64::MAX, 47, 1 << 40), (0x1234_5678_9abc, u64::MAX, 0)] {
            assert_eq!(hash_seed_after(hash_seed(&[seed]), &[x, y]), hash_seed(&[seed, x, y]));
        }
    }

    /// The eight generators side by side give each one's `next_f32` values in order and
    /// leave each where those calls would.
    #[test]
    fn lanes_draw_as_each_generator() {
        let mut lanes: [Pcg32; 8] = std::array::from_fn(|l| Pcg32::new(mix64(l as u64), 3 * l as u64 + 1));
        let mut one = lanes.clone();
        for _ in 0..3 {
            let rows = Pcg32::next_f32_lanes::<7>(&mut lanes);
            for (l, g) in one.iter_mut().enumerate() {
                for row in &rows {
                    assert_eq!(row[l].to_bits(), g.next_f32().to_bits(), "lane {l}");
                }
            }
        }
        for (a, b) in lanes.iter_mut().zip(&mut one) {
            assert_eq!(a.next_u32(), b.next_u32());
        }
    }
}
