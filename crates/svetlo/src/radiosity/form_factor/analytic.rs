//! Form factors from Lambert's contour integral: the unoccluded form factor from a
//! differential area at x (normal n) to a polygon is
//!   F = (1 / 2π) Σ_k γ_k n · (R_k × R_{k+1}) / |R_k × R_{k+1}|,
//! with R_k the unit vectors to the polygon's vertices and γ_k the angle between them.
//! The polygon is first clipped to the half-space above x's tangent plane (the formula
//! assumes it lies there). Element-to-element factors average the point value over points of
//! the source element and multiply by a visibility fraction sampled with shadow rays.

use super::super::mesh::{Element, RadiosityMesh};
use crate::scene::Scene;
use glam::{DVec3, Vec3};

/// The part of a polygon where `n · (v − x) ≥ 0` (Sutherland–Hodgman against one plane).
fn clip_above(x: DVec3, n: DVec3, poly: &[DVec3]) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(poly.len() + 2);
    for k in 0..poly.len() {
        let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
        let (da, db) = (n.dot(a - x), n.dot(b - x));
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            out.push(a + (b - a) * t);
        }
    }
    out
}

/// Unoccluded form factor from a differential area at `x` with unit normal `n` to a planar
/// polygon (any winding), by the contour integral.
pub fn point_to_polygon(x: Vec3, n: Vec3, poly: &[Vec3]) -> f64 {
    let (x, n) = (x.as_dvec3(), n.as_dvec3());
    let poly: Vec<DVec3> = poly.iter().map(|p| p.as_dvec3()).collect();
    let clipped = clip_above(x, n, &poly);
    if clipped.len() < 3 {
        return 0.0;
    }
    let mut sum = 0.0;
    for k in 0..clipped.len() {
        let a = (clipped[k] - x).normalize_or_zero();
        let b = (clipped[(k + 1) % clipped.len()] - x).normalize_or_zero();
        let c = a.cross(b);
        let len = c.length();
        if len < 1e-15 {
            continue;
        }
        let gamma = len.atan2(a.dot(b));
        sum += gamma * n.dot(c) / len;
    }
    (sum / (2.0 * std::f64::consts::PI)).abs()
}

/// Midpoints of a triangle split k × k (k² points of equal weight).
pub fn triangle_points(p: &[Vec3; 3], k: u32) -> Vec<Vec3> {
    let kf = k as f32;
    let mut pts = Vec::with_capacity((k * k) as usize);
    for j in 0..k {
        for i in 0..k - j {
            let (fi, fj) = (i as f32, j as f32);
            let up = ((fi + 1.0 / 3.0) / kf, (fj + 1.0 / 3.0) / kf);
            pts.push(p[0] + (p[1] - p[0]) * up.0 + (p[2] - p[0]) * up.1);
            if i + j + 1 < k {
                let dn = ((fi + 2.0 / 3.0) / kf, (fj + 2.0 / 3.0) / kf);
                pts.push(p[0] + (p[1] - p[0]) * dn.0 + (p[2] - p[0]) * dn.1);
            }
        }
    }
    pts
}

/// Unoccluded area-averaged form factor from triangle `src` (normal `n`) to a polygon, by the
/// midpoint rule over k² sub-triangles (error O(1/k²) for separated surfaces).
pub fn triangle_to_polygon(src: &[Vec3; 3], n: Vec3, target: &[Vec3], k: u32) -> f64 {
    let pts = triangle_points(src, k.max(1));
    pts.iter().map(|x| point_to_polygon(*x, n, target)).sum::<f64>() / pts.len() as f64
}

/// Does any corner of `b` lie strictly above `a`'s plane (so `a` may see part of `b`)?
#[inline]
pub(crate) fn sees(a: &Element, b: &Element) -> bool {
    let eps = 1e-6 * a.radius().max(b.radius());
    b.p.iter().any(|v| a.normal.dot(*v - a.centroid) > eps)
}

/// Row i of the form-factor matrix: every element j both sides can see, the contour integral
/// averaged over points of i (the centroid, or `src_grid`² points when the pair is close), times the fraction of
/// `vis_grid`² shadow rays to points of j that are unblocked.
pub fn row(scene: &Scene, mesh: &RadiosityMesh, i: usize, vis_grid: u32, src_grid: u32) -> Vec<(u32, f32)> {
    use rayon::prelude::*;
    let ei = &mesh.elements[i];
    let ri = ei.radius();
    let near_pts = triangle_points(&ei.p, src_grid.max(1));
    let far_pts = [ei.centroid];
    // The targets in parallel (progressive refinement computes one row at a time); each entry
    // depends on (i, j) only and the collect keeps j's order, so the row does not depend on threads.
    mesh.elements
        .par_iter()
        .enumerate()
        .with_min_len(64)
        .filter_map(|(j, ej)| {
            if j == i || !sees(ei, ej) || !sees(ej, ei) {
                return None;
            }
            let near = (ej.centroid - ei.centroid).length() < 3.0 * (ri + ej.radius());
            let src: &[Vec3] = if near { &near_pts } else { &far_pts };
            let targets = triangle_points(&ej.p, vis_grid.max(1));
            let mut f = 0.0;
            for (s, x) in src.iter().enumerate() {
                let fx = point_to_polygon(*x, ei.normal, &ej.p);
                if fx <= 0.0 {
                    continue;
                }
                // One ray per source point when there are many, the whole target grid otherwise.
                let v = if src.len() > 1 {
                    if scene.occluded(*x, ei.normal, targets[s % targets.len()]) {
                        0.0
                    } else {
                        1.0
                    }
                } else {
                    targets.iter().filter(|y| !scene.occluded(*x, ei.normal, **y)).count() as f64 / targets.len() as f64
                };
                f += fx * v;
            }
            let f = f / src.len() as f64;
            (f > 0.0).then_some((j as u32, f as f32))
        })
        .collect()
}

/// Closed forms from Howell's catalogue, for tests and as documentation of what the
/// numerical methods approximate.
pub mod closed_form {
    use std::f64::consts::PI;

    /// Directly opposed parallel rectangles a × b at distance c.
    pub fn parallel_rectangles(a: f64, b: f64, c: f64) -> f64 {
        let (x, y) = (a / c, b / c);
        let (x2, y2) = (x * x, y * y);
        2.0 / (PI * x * y)
            * (0.5 * ((1.0 + x2) * (1.0 + y2) / (1.0 + x2 + y2)).ln()
                + x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan()
                + y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan()
                - x * x.atan()
                - y * y.atan())
    }

    /// Perpendicular rectangles sharing an edge of length `l`: from the one of width `w`
    /// to the one of height `h`.
    pub fn perpendicular_rectangles(l: f64, w: f64, h: f64) -> f64 {
        let (hh, ww) = (h / l, w / l);
        let (h2, w2) = (hh * hh, ww * ww);
        let a = (1.0 + w2) * (1.0 + h2) / (1.0 + w2 + h2);
        let b = w2 * (1.0 + w2 + h2) / ((1.0 + w2) * (w2 + h2));
        let c = h2 * (1.0 + h2 + w2) / ((1.0 + h2) * (h2 + w2));
        1.0 / (PI * ww)
            * (ww * (1.0 / ww).atan() + hh * (1.0 / hh).atan() - (h2 + w2).sqrt() * (1.0 / (h2 + w2).sqrt()).atan()
                + 0.25 * (a.ln() + w2 * b.ln() + h2 * c.ln()))
    }

    /// Coaxial parallel discs of radii r1 (source) and r2 at distance h.
    pub fn coaxial_discs(r1: f64, r2: f64, h: f64) -> f64 {
        let (a, b) = (r1 / h, r2 / h);
        let x = 1.0 + (1.0 + b * b) / (a * a);
        0.5 * (x - (x * x - 4.0 * (b / a) * (b / a)).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_to_coaxial_disc_is_closed_form() {
        // dA to a coaxial disc of radius r at height h: r² / (h² + r²).
        let poly: Vec<Vec3> = (0..4096)
            .map(|k| {
                let phi = k as f32 / 4096.0 * std::f32::consts::TAU;
                Vec3::new(phi.cos(), phi.sin(), 2.0)
            })
            .collect();
        let f = point_to_polygon(Vec3::ZERO, Vec3::Z, &poly);
        assert!((f - 0.2).abs() < 1e-5, "{f}");
    }

    #[test]
    fn clipping_keeps_the_visible_part() {
        // A large square in the plane z = 0 half above the tangent plane of a point facing +x:
        // a half plane seen from its edge subtends F = 1/2 as the square grows.
        let s = 1e4f32;
        let poly = [Vec3::new(0.0, -s, -s), Vec3::new(0.0, s, -s), Vec3::new(0.0, s, s), Vec3::new(0.0, -s, s)];
        // Point on the plane x = -1 facing +x: sees the whole square, F → 1.
        assert!((point_to_polygon(Vec3::new(-1.0, 0.0, 0.0), Vec3::X, &poly) - 1.0).abs() < 1e-3);
        // Point facing +z beside the plane: half the hemisphere's projected disc is the plane, F → 1/2.
        let f = point_to_polygon(Vec3::new(-1e-3, 0.0, 0.0), Vec3::Z, &poly);
        assert!((f - 0.5).abs() < 1e-3, "{f}");
    }
}
