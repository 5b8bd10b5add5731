//! Perlin's gradient noise as pbrt-v4 evaluates it (its `Noise`, `FBm` and `Turbulence`),
//! so that pbrt's noise textures come out the same: Ken Perlin's reference permutation of
//! 0..255 (his "improved noise", 2002), twelve gradient directions chosen by the hash's low
//! four bits, and the quintic fade 6t⁵ − 15t⁴ + 10t³. Noise is zero at every lattice point.
//!
//! svetlo has no ray differentials, so the filter footprint is zero: pbrt's octave count
//! then clamps to the maximum, and its partial last octave vanishes (FBm) or becomes its
//! 0.2 average (turbulence). These are those zero-footprint sums.

use glam::Vec3;

/// Perlin's reference permutation (the table pbrt repeats twice).
const PERM: [u8; 256] = [
    151, 160, 137, 91, 90, 15, 131, 13, 201, 95, 96, 53, 194, 233, 7, 225, 140, 36, 103, 30, 69, 142, 8, 99, 37, 240, 21, 10, 23, 190, 6, 148, 247, 120, 234,
    75, 0, 26, 197, 62, 94, 252, 219, 203, 117, 35, 11, 32, 57, 177, 33, 88, 237, 149, 56, 87, 174, 20, 125, 136, 171, 168, 68, 175, 74, 165, 71, 134, 139, 48,
    27, 166, 77, 146, 158, 231, 83, 111, 229, 122, 60, 211, 133, 230, 220, 105, 92, 41, 55, 46, 245, 40, 244, 102, 143, 54, 65, 25, 63, 161, 1, 216, 80, 73,
    209, 76, 132, 187, 208, 89, 18, 169, 200, 196, 135, 130, 116, 188, 159, 86, 164, 100, 109, 198, 173, 186, 3, 64, 52, 217, 226, 250, 124, 123, 5, 202, 38,
    147, 118, 126, 255, 82, 85, 212, 207, 206, 59, 227, 47, 16, 58, 17, 182, 189, 28, 42, 223, 183, 170, 213, 119, 248, 152, 2, 44, 154, 163, 70, 221, 153,
    101, 155, 167, 43, 172, 9, 129, 22, 39, 253, 19, 98, 108, 110, 79, 113, 224, 232, 178, 185, 112, 104, 218, 246, 97, 228, 251, 34, 242, 193, 238, 210, 144,
    12, 191, 179, 162, 241, 81, 51, 145, 235, 249, 14, 239, 107, 49, 192, 214, 31, 181, 199, 106, 157, 184, 84, 204, 176, 115, 121, 50, 45, 127, 4, 150, 254,
    138, 236, 205, 93, 222, 114, 67, 29, 24, 72, 243, 141, 128, 195, 78, 66, 215, 61, 156, 180,
];

/// The doubled table's entry `i` (0 ≤ i < 512).
#[inline]
fn perm(i: usize) -> usize {
    PERM[i & 255] as usize
}

/// Dot product of the lattice point's gradient with the offset (dx, dy, dz).
#[inline]
fn grad(x: usize, y: usize, z: usize, d: Vec3) -> f32 {
    let h = perm(perm(perm(x) + y) + z) & 15;
    let u = if h < 8 || h == 12 || h == 13 { d.x } else { d.y };
    let v = if h < 4 || h == 12 || h == 13 { d.y } else { d.z };
    (if h & 1 != 0 { -u } else { u }) + (if h & 2 != 0 { -v } else { v })
}

#[inline]
fn fade(t: f32) -> f32 {
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

#[inline]
fn lerp(t: f32, a: f32, b: f32) -> f32 {
    (1.0 - t) * a + t * b
}

/// Perlin noise at `p`, in about [-1, 1].
pub fn noise(p: Vec3) -> f32 {
    if !p.is_finite() {
        return 0.0;
    }
    let f = p.floor();
    let d = p - f;
    // Cell indices wrap at 256 (pbrt masks them); a float far beyond i64 saturates, harmlessly.
    let w = |v: f32| (v as i64 & 255) as usize;
    let (ix, iy, iz) = (w(f.x), w(f.y), w(f.z));
    let g = |ox: usize, oy: usize, oz: usize| grad(ix + ox, iy + oy, iz + oz, d - Vec3::new(ox as f32, oy as f32, oz as f32));
    let (wx, wy, wz) = (fade(d.x), fade(d.y), fade(d.z));
    let x00 = lerp(wx, g(0, 0, 0), g(1, 0, 0));
    let x10 = lerp(wx, g(0, 1, 0), g(1, 1, 0));
    let x01 = lerp(wx, g(0, 0, 1), g(1, 0, 1));
    let x11 = lerp(wx, g(0, 1, 1), g(1, 1, 1));
    lerp(wz, lerp(wy, x00, x10), lerp(wy, x01, x11))
}

/// pbrt's two-argument noise (z = 1/2).
pub fn noise2(x: f32, y: f32) -> f32 {
    noise(Vec3::new(x, y, 0.5))
}

/// Fractional Brownian motion: Σ ωⁱ noise(1.99ⁱ p) over `octaves` octaves.
pub fn fbm(p: Vec3, omega: f32, octaves: u32) -> f32 {
    let (mut sum, mut lambda, mut o) = (0.0, 1.0, 1.0);
    for _ in 0..octaves {
        sum += o * noise(lambda * p);
        lambda *= 1.99;
        o *= omega;
    }
    sum
}

/// Turbulence: Σ ωⁱ |noise(1.99ⁱ p)|, plus pbrt's 0.2 average for the octave beyond.
pub fn turbulence(p: Vec3, omega: f32, octaves: u32) -> f32 {
    let (mut sum, mut lambda, mut o) = (0.0, 1.0, 1.0);
    for _ in 0..octaves {
        sum += o * noise(lambda * p).abs();
        lambda *= 1.99;
        o *= omega;
    }
    sum + o * 0.2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permutation_is_a_permutation() {
        let mut seen = [false; 256];
        for &v in &PERM {
            assert!(!seen[v as usize], "{v} twice");
            seen[v as usize] = true;
        }
    }

    /// Gradient noise vanishes on the integer lattice (every offset there is zero), is
    /// continuous, and stays within the bound of twelve-direction Perlin noise.
    #[test]
    fn zero_on_the_lattice_and_bounded() {
        for x in -3..4 {
            for y in -3..4 {
                for z in -3..4 {
                    let p = Vec3::new(x as f32, y as f32, z as f32);
                    assert_eq!(noise(p), 0.0, "{p}");
                    // Continuity across the lattice point.
                    assert!(noise(p + Vec3::splat(1e-4)).abs() < 1e-3);
                }
            }
        }
        let mut rng = crate::sampling::Pcg32::new(9, 2);
        let mut any = 0.0f32;
        for _ in 0..20000 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 40.0 - Vec3::splat(20.0);
            let n = noise(p);
            assert!(n.abs() <= 1.05, "{p}: {n}");
            any = any.max(n.abs());
        }
        assert!(any > 0.5, "noise is not flat: max |n| = {any}");
    }

    /// fbm and turbulence are their octave sums, term by term.
    #[test]
    fn octave_sums() {
        let p = Vec3::new(0.37, 1.21, -2.6);
        let (omega, oct) = (0.6f32, 5u32);
        let (mut f, mut t) = (0.0, 0.0);
        for i in 0..oct {
            let n = noise(p * 1.99f32.powi(i as i32));
            f += omega.powi(i as i32) * n;
            t += omega.powi(i as i32) * n.abs();
        }
        t += omega.powi(oct as i32) * 0.2;
        assert!((fbm(p, omega, oct) - f).abs() < 1e-5);
        assert!((turbulence(p, omega, oct) - t).abs() < 1e-5);
        assert_eq!(fbm(p, omega, 0), 0.0);
        assert_eq!(fbm(p, omega, 1), noise(p));
        // The lattice: every octave's point is 1.99ⁱ × an integer point, not a lattice point,
        // but the first octave's noise is zero there.
        assert_eq!(fbm(Vec3::new(2.0, -1.0, 3.0), omega, 1), 0.0);
    }
}
