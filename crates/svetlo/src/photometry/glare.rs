//! Discomfort glare: the CIE Unified Glare Rating (CIE 117-1995)
//!   UGR = 8 log10( 0.25 / Lb · Σ L² ω / p² )
//! over the luminaires the observer sees above the line of sight: L the luminance of the
//! luminous opening toward the eye (the file's intensity over the opening's projected area),
//! ω its solid angle, p the Guth position index, and Lb the background luminance, the
//! indirect illuminance at the eye (on the plane facing the view) over π.
//!
//! The position index uses the closed fit of Luckiesh and Guth's table that Radiance's
//! evalglare uses, in degrees (τ the angle from vertical of the plane through the line of
//! sight and the source, σ the angle between them):
//!   ln p = (35.2 − 0.31889 τ − 1.22 e^(−2τ/9)) 10⁻³ σ + (21 + 0.26667 τ − 0.002963 τ²) 10⁻⁵ σ².

use super::illuminance::indirect_illuminance;
use super::Opening;
use crate::integrator::RenderSettings;
use crate::light::{Light, Luminaire};
use crate::scene::Scene;
use glam::Vec3;

/// Guth position index for τ, σ in degrees.
pub fn position_index(tau: f64, sigma: f64) -> f64 {
    let a = (35.2 - 0.31889 * tau - 1.22 * (-2.0 * tau / 9.0).exp()) * 1e-3 * sigma;
    let b = (21.0 + 0.26667 * tau - 0.002963 * tau * tau) * 1e-5 * sigma * sigma;
    (a + b).exp()
}

/// Area (m²) of a luminous opening projected toward local direction `d` (unit, in the
/// luminaire's frame): the faces of its box (or cylinder) seen edge-on count by their cosines.
pub fn projected_area(o: &Opening, d: Vec3) -> f64 {
    let (x, y, z) = (d.x.abs() as f64, d.y.abs() as f64, d.z.abs() as f64);
    match *o {
        Opening::Point => 0.0,
        // Length along C0 (x), width along C90 (y).
        Opening::Rectangle { length, width, height } => length * width * z + length * height * y + width * height * x,
        Opening::Disk { diameter, height } => std::f64::consts::PI * diameter * diameter / 4.0 * z + diameter * height * (x * x + y * y).sqrt(),
    }
}

/// One luminaire's share of the rating.
#[derive(Clone, Debug)]
pub struct GlareSource {
    /// Index into the scene's lights.
    pub light: usize,
    /// Luminance toward the eye, cd/m².
    pub luminance: f64,
    /// Solid angle of the opening, sr.
    pub solid_angle: f64,
    pub position_index: f64,
    /// L² ω / p².
    pub term: f64,
}

/// The rating for one observer.
#[derive(Clone, Debug)]
pub struct Glare {
    /// None when no luminaire is in view (UGR is then undefined: no glare).
    pub ugr: Option<f64>,
    /// Background luminance Lb (cd/m²) and its standard error.
    pub background: f64,
    pub background_se: f64,
    pub sources: Vec<GlareSource>,
    /// Luminaires skipped: behind or below the line of sight, hidden, or without a luminous area.
    pub skipped: usize,
}

/// UGR at `eye` looking along `dir` (`up` the observer's vertical), the background from
/// `spp` gathering rays.
pub fn ugr(scene: &Scene, eye: Vec3, dir: Vec3, up: Vec3, spp: u32, settings: &RenderSettings) -> Glare {
    let v = dir.normalize_or_zero();
    let right = v.cross(up).normalize_or_zero();
    let v_up = right.cross(v);
    let (e_ind, e_se) = indirect_illuminance(scene, eye, v, spp, settings);
    let (background, background_se) = (e_ind / std::f64::consts::PI, e_se / std::f64::consts::PI);
    let mut sources = vec![];
    let mut skipped = 0;
    for (k, l) in scene.lights.iter().enumerate() {
        let Light::Luminaire(lum) = l else { continue };
        match source(scene, lum, eye, v, right, v_up) {
            Some(mut s) => {
                s.light = k;
                sources.push(s)
            }
            None => skipped += 1,
        }
    }
    let sum: f64 = sources.iter().map(|s| s.term).sum();
    let ugr = (sum > 0.0 && background > 0.0).then(|| 8.0 * (0.25 / background * sum).log10());
    Glare { ugr, background, background_se, sources, skipped }
}

fn source(scene: &Scene, lum: &Luminaire, eye: Vec3, v: Vec3, right: Vec3, v_up: Vec3) -> Option<GlareSource> {
    let to_src = lum.position - eye;
    let r = to_src.length() as f64;
    let s = to_src.normalize_or_zero();
    let cos_sigma = s.dot(v) as f64;
    // CIE 117 rates sources in front of the observer and above the line of sight.
    if r <= 0.0 || cos_sigma <= 0.0 || s.dot(v_up) < 0.0 {
        return None;
    }
    let area = projected_area(&lum.opening, lum.to_local(-s));
    if area <= 0.0 || scene.occluded(eye, v, lum.position) {
        return None;
    }
    let sigma = cos_sigma.clamp(-1.0, 1.0).acos().to_degrees();
    let tau = (s.dot(right).abs() as f64).atan2(s.dot(v_up) as f64).to_degrees();
    let p = position_index(tau, sigma);
    let luminance = lum.candela(-s) / area;
    let solid_angle = area / (r * r);
    Some(GlareSource { light: 0, luminance, solid_angle, position_index: p, term: luminance * luminance * solid_angle / (p * p) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn position_index_is_one_on_the_line_of_sight_and_grows_away_from_it() {
        assert!((position_index(0.0, 0.0) - 1.0).abs() < 1e-12);
        for tau in [0.0, 30.0, 60.0, 90.0] {
            let mut last = 1.0;
            for sigma in [10.0, 20.0, 40.0, 60.0] {
                let p = position_index(tau, sigma);
                assert!(p > last, "tau {tau} sigma {sigma}: {p}");
                last = p;
            }
        }
        // Straight above the line of sight (τ = 0°, shaded by the brow) a source glares less
        // than one to the side (τ = 90°) at equal σ: its index is larger (Guth: 3.3 against 1.5).
        assert!(position_index(0.0, 30.0) > 2.0 * position_index(90.0, 30.0));
    }

    #[test]
    fn projected_area_of_a_box_counts_its_faces_by_cosine() {
        let o = Opening::Rectangle { length: 0.6, width: 0.3, height: 0.1 };
        assert!((projected_area(&o, Vec3::NEG_Z) - 0.18).abs() < 1e-9);
        assert!((projected_area(&o, Vec3::X) - 0.03).abs() < 1e-9);
        let d = Vec3::new(0.0, 0.6, -0.8);
        assert!((projected_area(&o, d) - (0.18 * 0.8 + 0.06 * 0.6)).abs() < 1e-6);
        assert_eq!(projected_area(&Opening::Point, Vec3::Z), 0.0);
    }
}
