//! Warps from the unit square to other domains, each with its density.
//! Densities are per unit area of the target domain (solid angle for directions).

use super::{safe_sqrt, INV_2PI, INV_4PI, INV_PI, PI};
use glam::{Vec2, Vec3};

/// Shirley-Chiu concentric map to the unit disk.
pub fn square_to_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    // Shirley-Chiu: the angle is a quarter of pi times the ratio of the coordinates, so only
    // angles in [-pi/4, pi/4] need sine and cosine (the other sector swaps them). The sector
    // picks operands rather than a branch: it is a coin flip, and mispredicted half the time.
    let wide = o.x.abs() > o.y.abs();
    let (num, r) = if wide { (o.y, o.x) } else { (o.x, o.y) };
    let (s, c) = sin_cos_quarter((PI / 4.0) * (num / r));
    let (a, b) = (r * c, r * s);
    if wide {
        Vec2::new(a, b)
    } else {
        Vec2::new(b, a)
    }
}

/// Sine and cosine of an angle in [-pi/4, pi/4] by their Taylor polynomials (relative error
/// below 4e-8 there, under one float ulp), much cheaper than a general `sin_cos`.
#[inline]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0)))));
    let c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0 + x2 * (-1.0 / 3_628_800.0)))));
    (s, c)
}

/// (sin 2πu, cos 2πu) for u in [0, 1] (other u with |u| < 2²⁰ work too, less accurately
/// far from it): the quadrant from 4u rounded, then [`sin_cos_quarter`] of the rest; within
/// 2e-7 of the exact values, with no libm call.
#[inline]
pub fn sin_cos_2pi(u: f32) -> (f32, f32) {
    // 1.5 · 2²³ rounds 4u to the nearest integer (SSE2 has no rounding instruction).
    const ROUND: f32 = 12_582_912.0;
    let a = 4.0 * u;
    let t = a + ROUND;
    let k = t - ROUND;
    let (s, c) = sin_cos_quarter((a - k) * (PI / 2.0));
    // Quadrant q turns (s, c) by q quarter turns: (s, c), (c, -s), (-s, -c), (-c, s). As
    // selects, not a jump: loops over lanes (the path kernel's sphere lights) vectorise.
    // q's low bits are t's (its ulp is 1 for |4u| < 2²²): `k as i32` saturates, which
    // vector code ran lane by lane.
    let q = t.to_bits().wrapping_sub(ROUND.to_bits());
    let (s, c) = if q & 1 == 0 { (s, c) } else { (c, -s) };
    if q & 2 == 0 {
        (s, c)
    } else {
        (-s, -c)
    }
}

pub fn square_to_uniform_disk_concentric_pdf(p: Vec2) -> f32 {
    if p.length_squared() <= 1.0 {
        INV_PI
    } else {
        0.0
    }
}

pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = safe_sqrt(1.0 - z * z);
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub fn square_to_uniform_sphere_pdf() -> f32 {
    INV_4PI
}

pub fn square_to_uniform_hemisphere(u: Vec2) -> Vec3 {
    let z = u.y;
    let r = safe_sqrt(1.0 - z * z);
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub fn square_to_uniform_hemisphere_pdf(w: Vec3) -> f32 {
    if w.z >= 0.0 {
        INV_2PI
    } else {
        0.0
    }
}

/// Malley's method: cosine-weighted hemisphere around +z.
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_uniform_disk_concentric(u);
    let z = safe_sqrt(1.0 - d.length_squared());
    Vec3::new(d.x, d.y, z)
}

pub fn square_to_cosine_hemisphere_pdf(w: Vec3) -> f32 {
    w.z.max(0.0) * INV_PI
}

/// Uniform directions inside a cone of half-angle acos(cos_max) around +z.
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = (1.0 - u.y) + u.y * cos_max;
    let sin_t = safe_sqrt(1.0 - cos_t * cos_t);
    let phi = 2.0 * PI * u.x;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

pub fn square_to_uniform_cone_pdf(w: Vec3, cos_max: f32) -> f32 {
    if w.z >= cos_max {
        1.0 / (2.0 * PI * (1.0 - cos_max))
    } else {
        0.0
    }
}

/// Barycentrics (b1, b2) uniform over a triangle (Heitz's low-distortion map).
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    let (b0, b1);
    if u.x < u.y {
        b0 = u.x / 2.0;
        b1 = u.y - b0;
    } else {
        b1 = u.y / 2.0;
        b0 = u.x - b1;
    }
    Vec2::new(b0, b1)
}

/// pbrt-v4's EqualAreaSphereToSquare (Clarberg's octahedral equal-area map): a unit
/// direction to [0,1]². Every region of the square maps to a region of the sphere 4π
/// times its area (pbrt's infinite and goniometric lights' images).
pub fn equal_area_sphere_to_square(d: Vec3) -> Vec2 {
    let (x, y, z) = (d.x.abs(), d.y.abs(), d.z.abs());
    let r = (1.0 - z).max(0.0).sqrt();
    let a = x.max(y);
    let b = if a == 0.0 { 0.0 } else { x.min(y) / a };
    let mut phi = b.atan() * 2.0 / PI;
    if x < y {
        phi = 1.0 - phi;
    }
    let mut v = phi * r;
    let mut u = r - v;
    if d.z < 0.0 {
        std::mem::swap(&mut u, &mut v);
        u = 1.0 - u;
        v = 1.0 - v;
    }
    u = u.copysign(d.x);
    v = v.copysign(d.y);
    Vec2::new(0.5 * (u + 1.0), 0.5 * (v + 1.0))
}

/// The inverse of [`equal_area_sphere_to_square`].
pub fn equal_area_square_to_sphere(p: Vec2) -> Vec3 {
    let (u, v) = (2.0 * p.x - 1.0, 2.0 * p.y - 1.0);
    let (up, vp) = (u.abs(), v.abs());
    let sd = 1.0 - (up + vp);
    let d = sd.abs();
    let r = 1.0 - d;
    let phi = if r == 0.0 { 1.0 } else { (vp - up) / r + 1.0 } * PI / 4.0;
    let z = (1.0 - r * r).copysign(sd);
    let cos_phi = phi.cos().copysign(u);
    let sin_phi = phi.sin().copysign(v);
    let s = r * (2.0 - r * r).max(0.0).sqrt();
    Vec3::new(cos_phi * s, sin_phi * s, z)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Integrate a pdf over the sphere by a fine midpoint rule in (cos theta, phi): must be 1.
    fn integrate_sphere(pdf: impl Fn(Vec3) -> f32) -> f64 {
        let (nt, np) = (400, 400);
        let mut sum = 0.0f64;
        for i in 0..nt {
            let z = -1.0 + 2.0 * (i as f64 + 0.5) / nt as f64;
            for j in 0..np {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
                let r = (1.0 - z * z).sqrt();
                let w = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                sum += pdf(w) as f64;
            }
        }
        sum * 4.0 * std::f64::consts::PI / (nt * np) as f64
    }

    #[test]
    fn quarter_sin_cos_is_accurate_to_an_ulp() {
        for i in 0..=10_000 {
            let x = -PI / 4.0 + (PI / 2.0) * i as f32 / 10_000.0;
            let (s, c) = sin_cos_quarter(x);
            let (se, ce) = (x as f64).sin_cos();
            assert!((s as f64 - se).abs() <= 1.2e-7 * se.abs().max(1e-30) + 1e-12, "sin({x}) = {s} vs {se}");
            assert!((c as f64 - ce).abs() <= 1.2e-7, "cos({x}) = {c} vs {ce}");
        }
    }

    #[test]
    fn sin_cos_2pi_is_accurate() {
        for i in 0..=100_000 {
            let u = i as f32 / 100_000.0;
            let (s, c) = sin_cos_2pi(u);
            let (se, ce) = (2.0 * std::f64::consts::PI * u as f64).sin_cos();
            assert!((s as f64 - se).abs() < 2e-7 && (c as f64 - ce).abs() < 2e-7, "u {u}: ({s}, {c}) vs ({se}, {ce})");
        }
    }

    /// The quadrant from the rounding sum's bits is `k as i32`'s, on every float of
    /// |u| < 2²⁰ (a third of them).
    #[test]
    fn sin_cos_2pi_quadrant_bits_are_the_conversion() {
        let old = |u: f32| {
            const ROUND: f32 = 12_582_912.0;
            let a = 4.0 * u;
            let k = (a + ROUND) - ROUND;
            let (s, c) = sin_cos_quarter((a - k) * (PI / 2.0));
            let q = k as i32;
            let (s, c) = if q & 1 == 0 { (s, c) } else { (c, -s) };
            if q & 2 == 0 {
                (s, c)
            } else {
                (-s, -c)
            }
        };
        let bits = |(s, c): (f32, f32)| (s.to_bits(), c.to_bits());
        for b in (0..0x4980_0000u32).step_by(3).flat_map(|b| [b, b | 0x8000_0000]) {
            let u = f32::from_bits(b);
            assert_eq!(bits(sin_cos_2pi(u)), bits(old(u)), "u {u:e}");
        }
    }

    #[test]
    fn pdfs_integrate_to_one() {
        assert!((integrate_sphere(|_| square_to_uniform_sphere_pdf()) - 1.0).abs() < 1e-3);
        assert!((integrate_sphere(square_to_uniform_hemisphere_pdf) - 1.0).abs() < 1e-2);
        assert!((integrate_sphere(square_to_cosine_hemisphere_pdf) - 1.0).abs() < 1e-3);
        assert!((integrate_sphere(|w| square_to_uniform_cone_pdf(w, 0.5)) - 1.0).abs() < 1e-2);
    }

    /// The concentric map is the two-branch Shirley-Chiu map, bit for bit (the sector
    /// selects operands instead of branching), on both sectors, their diagonals and axes.
    #[test]
    fn concentric_disk_is_the_branching_map() {
        let branching = |u: Vec2| {
            let o = 2.0 * u - Vec2::ONE;
            if o.x == 0.0 && o.y == 0.0 {
                return Vec2::ZERO;
            }
            if o.x.abs() > o.y.abs() {
                let (s, c) = sin_cos_quarter((PI / 4.0) * (o.y / o.x));
                Vec2::new(o.x * c, o.x * s)
            } else {
                let (s, c) = sin_cos_quarter((PI / 4.0) * (o.x / o.y));
                Vec2::new(o.y * s, o.y * c)
            }
        };
        let mut rng = crate::sampling::Pcg32::new(5, 17);
        let mut us: Vec<Vec2> = (0..20_000).map(|_| Vec2::new(rng.next_f32(), rng.next_f32())).collect();
        let edges = [0.0, 0.25, 0.5, 0.75, 1.0 - f32::EPSILON / 2.0];
        us.extend(edges.iter().flat_map(|&x| edges.iter().map(move |&y| Vec2::new(x, y))));
        us.extend((0..1000).map(|i| Vec2::splat(i as f32 / 1000.0)));
        us.extend((0..1000).map(|i| Vec2::new(i as f32 / 1000.0, 1.0 - i as f32 / 1000.0)));
        for u in us {
            let (got, want) = (square_to_uniform_disk_concentric(u), branching(u));
            assert_eq!(got.to_array().map(f32::to_bits), want.to_array().map(f32::to_bits), "u {u}");
        }
    }

    #[test]
    fn warps_land_in_their_domain() {
        for i in 0..32 {
            for j in 0..32 {
                let u = Vec2::new((i as f32 + 0.5) / 32.0, (j as f32 + 0.5) / 32.0);
                assert!(square_to_uniform_disk_concentric(u).length() <= 1.0 + 1e-6);
                assert!((square_to_uniform_sphere(u).length() - 1.0).abs() < 1e-5);
                let c = square_to_cosine_hemisphere(u);
                assert!(c.z >= 0.0 && (c.length() - 1.0).abs() < 1e-5);
                let b = square_to_uniform_triangle(u);
                assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
                assert!(square_to_uniform_cone(u, 0.8).z >= 0.8 - 1e-6);
            }
        }
    }
}
