//! The camera as the adjoint of a light: importance `We`, for light tracing, BDPT and
//! photon-based methods (perspective and thin-lens cameras; the orthographic camera has a
//! delta direction and cannot be connected to, so these functions return nothing for it).
//!
//! Normalisation: with θ the angle between a ray and the optical axis, A the film's area on
//! the camera-space plane z = 1 (`4 tan(fov_x/2) tan(fov_y/2)`) and L the lens area (π r²;
//! 1 for a pinhole, whose position is a delta),
//!
//!   We = 1 / (A L cos⁴θ) inside the film, 0 outside,
//!
//! so that ∫_lens ∫_dirs We cos θ dω dA_lens = 1 over the *whole film*: the measurement
//! with this We is the film's mean radiance. A pixel's value (box filter) is the mean over
//! that pixel, W·H times the measurement restricted to it. So a light tracer that traces
//! N light paths and splats `β f |cos| We / pdf` at `raster` estimates pixel values when
//! its splats are scaled by (width · height) / N.
//!
//! Densities of camera rays (`generate_ray` with uniform film and lens samples):
//! pdf_pos = 1 / L on the lens (0 for a pinhole: a delta, as lights' `pdf_le` reports),
//! pdf_dir = 1 / (A cos³θ) per unit solid angle.

use super::{Camera, Projection};
use crate::geometry::Ray;
use crate::math::{warp, PI};
use glam::{Mat4, Vec2, Vec3};

/// A connection from a point in the scene to the camera's lens.
#[derive(Clone, Copy, Debug)]
pub struct CameraSample {
    /// Importance carried along the ray from the lens point toward the reference point.
    pub we: f32,
    /// Unit direction from the reference point toward the lens point.
    pub wi: Vec3,
    /// Density of the lens point, in solid angle at the reference point:
    /// dist² / (cos θ_lens · L) (with L = 1 for a pinhole, whose position is a delta).
    pub pdf: f32,
    /// Where the connection lands on the film (pixels, origin top-left).
    pub raster: Vec2,
    /// The lens point (world space) and the camera's forward axis there.
    pub p_lens: Vec3,
    pub n_lens: Vec3,
}

impl Camera {
    fn perspective_params(&self) -> Option<(f32, f32)> {
        match self.projection {
            Projection::Perspective { aperture_radius, focus_distance, .. } => Some((aperture_radius.max(0.0), focus_distance)),
            Projection::Orthographic => None,
        }
    }

    /// Film area on the plane z = 1 of camera space (perspective cameras).
    pub fn film_area(&self) -> f32 {
        let e = self.film_half_extent();
        4.0 * e.x * e.y
    }

    /// Lens area π r², or 1 for a pinhole (a delta position).
    pub fn lens_area(&self) -> f32 {
        match self.perspective_params() {
            Some((r, _)) if r > 0.0 => PI * r * r,
            _ => 1.0,
        }
    }

    /// Whether the camera's position is a single point (pinhole perspective).
    pub fn is_pinhole(&self) -> bool {
        matches!(self.perspective_params(), Some((r, _)) if r == 0.0)
    }

    /// The camera's constants for connections, computed once (a matrix inverse and a
    /// tangent): None for the orthographic camera. Methods that connect many times keep it
    /// (`PathConfig::lens`); it goes stale if the camera is changed afterwards.
    pub fn lens_connector(&self) -> Option<LensConnector> {
        let (radius, focus) = self.perspective_params()?;
        Some(LensConnector {
            to_world: self.to_world,
            to_camera: self.to_world.inverse(),
            radius,
            focus,
            half: self.film_half_extent(),
            film_area: self.film_area(),
            lens_area: self.lens_area(),
            size: Vec2::new(self.width as f32, self.height as f32),
            near_clip: self.near_clip,
            far_clip: self.far_clip,
            n_lens: self.to_world.transform_vector3(Vec3::Z).normalize_or_zero(),
            center: self.to_world.transform_point3(Vec3::ZERO),
        })
    }

    /// Importance carried by a world-space ray leaving the camera, and where it lands on
    /// the film; None outside the film or the lens. For a thin lens the ray's origin is
    /// moved along it to the lens plane.
    pub fn we(&self, ray: &Ray) -> Option<(f32, Vec2)> {
        self.lens_connector()?.we(ray)
    }

    /// Densities (pdf_pos per unit lens area, pdf_dir per unit solid angle) with which
    /// `generate_ray` produces `ray` from uniform film and lens samples; zeros outside.
    pub fn pdf_we(&self, ray: &Ray) -> (f32, f32) {
        self.lens_connector().map_or((0.0, 0.0), |c| c.pdf_we(ray))
    }

    /// Choose a point on the lens (uniform by area; the center for a pinhole) and connect
    /// `p_ref` to it. None if `p_ref` is outside the near/far range or the connection
    /// misses the film.
    pub fn sample_wi(&self, p_ref: Vec3, u: Vec2) -> Option<CameraSample> {
        self.lens_connector()?.sample_wi(p_ref, u)
    }
}

/// [`CameraSample`] without the directions: what [`LensConnector::sample_lens`] gives.
#[derive(Clone, Copy, Debug)]
pub struct LensSample {
    pub we: f32,
    pub pdf: f32,
    pub raster: Vec2,
    pub p_lens: Vec3,
}

/// What [`LensConnector::sample_lens`] computes with for a pinhole
/// ([`LensConnector::pinhole`]): there the lens sample is not used.
#[derive(Clone, Copy, Debug)]
pub struct Pinhole {
    pub to_camera: Mat4,
    pub near_clip: f32,
    pub far_clip: f32,
    /// Half extent of the film on the plane z = 1, and its size in pixels.
    pub half: Vec2,
    pub size: Vec2,
    /// Film area times lens area (importance is 1 / (areas cos⁴θ)).
    pub areas: f32,
    pub lens_area: f32,
    /// The lens center (world space), where every connection ends.
    pub center: Vec3,
}

/// A perspective camera's importance, densities and lens connections with its constants
/// (inverse transform, film extent, areas) computed once: [`Camera::lens_connector`].
/// The same arithmetic as the camera's own methods, which are made of it.
#[derive(Clone, Copy, Debug)]
pub struct LensConnector {
    to_world: Mat4,
    to_camera: Mat4,
    radius: f32,
    focus: f32,
    /// Half extent of the film on the plane z = 1.
    half: Vec2,
    film_area: f32,
    lens_area: f32,
    /// Film width and height in pixels.
    size: Vec2,
    near_clip: f32,
    far_clip: f32,
    /// The camera's forward axis (world space).
    n_lens: Vec3,
    /// The lens center (world space): a pinhole's every connection ends there.
    center: Vec3,
}

impl LensConnector {
    /// Importance and raster position of a ray leaving the lens at camera-space point
    /// `o` (z = 0; ignored for a pinhole) in unit camera-space direction `d`.
    #[inline]
    fn we_local(&self, o: Vec3, d: Vec3) -> Option<(f32, Vec2)> {
        let (radius, focus) = (self.radius, self.focus);
        let cos_t = d.z;
        if cos_t <= 0.0 {
            return None;
        }
        // The film point is where the chief ray through the lens center to the same point
        // of the focus plane crosses z = 1.
        let q = if radius > 0.0 {
            let p_focus = o + d * (focus / cos_t);
            Vec2::new(p_focus.x, p_focus.y) / focus
        } else {
            Vec2::new(d.x, d.y) / cos_t
        };
        // Camera space to raster (+x of camera space is the image's left, +y its top).
        let ndc = 0.5 * (Vec2::ONE - q / self.half);
        let raster = Vec2::new(ndc.x * self.size.x, ndc.y * self.size.y);
        if !(raster.x >= 0.0 && raster.y >= 0.0 && raster.x < self.size.x && raster.y < self.size.y) {
            return None;
        }
        let cos2 = cos_t * cos_t;
        Some((1.0 / (self.film_area * self.lens_area * cos2 * cos2), raster))
    }

    /// [`Camera::we`].
    pub fn we(&self, ray: &Ray) -> Option<(f32, Vec2)> {
        self.we_and_direction(ray).map(|(we, raster, _)| (we, raster))
    }

    /// [`Self::we`] with the ray's unit camera-space direction, which [`Self::pdf_we`] needs
    /// too (computed once: BDPT's MIS asks for camera densities per connection).
    #[inline]
    fn we_and_direction(&self, ray: &Ray) -> Option<(f32, Vec2, Vec3)> {
        let radius = self.radius;
        let m = self.to_camera;
        let d = m.transform_vector3(ray.d).normalize_or_zero();
        let mut o = m.transform_point3(ray.o);
        if radius > 0.0 {
            if d.z <= 0.0 {
                return None;
            }
            o -= d * (o.z / d.z);
            if o.x * o.x + o.y * o.y > radius * radius * (1.0 + 1e-4) {
                return None;
            }
        }
        self.we_local(o, d).map(|(we, raster)| (we, raster, d))
    }

    /// [`Camera::pdf_we`].
    pub fn pdf_we(&self, ray: &Ray) -> (f32, f32) {
        let Some((_, _, d)) = self.we_and_direction(ray) else {
            return (0.0, 0.0);
        };
        let pdf_pos = if self.radius == 0.0 { 0.0 } else { 1.0 / self.lens_area };
        (pdf_pos, 1.0 / (self.film_area * d.z * d.z * d.z))
    }

    /// The constants of [`Self::sample_lens`] for a pinhole (None for a thin lens, or a
    /// lens center that is not finite), for connections computed several at a time.
    pub fn pinhole(&self) -> Option<Pinhole> {
        if self.radius > 0.0 || !self.center.is_finite() {
            return None;
        }
        Some(Pinhole {
            to_camera: self.to_camera,
            near_clip: self.near_clip,
            far_clip: self.far_clip,
            half: self.half,
            size: self.size,
            // `we_local`'s product, left to right.
            areas: self.film_area * self.lens_area,
            lens_area: self.lens_area,
            center: self.center,
        })
    }

    /// The world-to-camera transform.
    pub fn to_camera(&self) -> Mat4 {
        self.to_camera
    }

    /// [`Camera::sample_wi`].
    pub fn sample_wi(&self, p_ref: Vec3, u: Vec2) -> Option<CameraSample> {
        let LensSample { we, pdf, raster, p_lens } = self.sample_lens(p_ref, u)?;
        let wi = (p_lens - p_ref).normalize_or_zero();
        Some(CameraSample { we, wi, pdf, raster, p_lens, n_lens: self.n_lens })
    }

    /// [`Self::sample_wi`] without the direction toward the lens, which a connection
    /// computes itself (light tracing's camera connections; inlined there).
    #[inline]
    pub fn sample_lens(&self, p_ref: Vec3, u: Vec2) -> Option<LensSample> {
        let radius = self.radius;
        let p = self.to_camera.transform_point3(p_ref);
        if p.z < self.near_clip || p.z > self.far_clip {
            return None;
        }
        // A pinhole's lens is its center: no warp (a light vertex's connection is hot).
        let o = if radius > 0.0 {
            let lens = warp::square_to_uniform_disk_concentric(u) * radius;
            Vec3::new(lens.x, lens.y, 0.0)
        } else {
            Vec3::ZERO
        };
        let to_ref = p - o;
        let dist2 = to_ref.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let d = to_ref / dist2.sqrt();
        let (we, raster) = self.we_local(o, d)?;
        let pdf = dist2 / (d.z * self.lens_area);
        // The same transform of the same zero as the thin lens's, done once for a pinhole.
        let p_lens = if radius > 0.0 { self.to_world.transform_point3(o) } else { self.center };
        Some(LensSample { we, pdf, raster, p_lens })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Pcg32;

    fn camera(aperture: f32) -> Camera {
        // Mitsuba's lookat from (1, 2, -3) toward (0.5, 1.5, 2), up +y.
        let to_world = crate::io::mitsuba::look_at(Vec3::new(1.0, 2.0, -3.0), Vec3::new(0.5, 1.5, 2.0), Vec3::Y).expect("a frame");
        Camera {
            to_world,
            projection: Projection::Perspective { fov_x_deg: 50.0, aperture_radius: aperture, focus_distance: 4.0 },
            width: 64,
            height: 48,
            near_clip: 1e-3,
            far_clip: 1e3,
            shutter_open: 0.0,
            shutter_close: 0.0,
        }
    }

    #[test]
    fn generate_ray_round_trips_through_we() {
        for aperture in [0.0, 0.2] {
            let cam = camera(aperture);
            let mut rng = Pcg32::new(1, 2);
            for _ in 0..200 {
                let raster = Vec2::new(rng.next_f32() * 64.0, rng.next_f32() * 48.0);
                let lens = Vec2::new(rng.next_f32(), rng.next_f32());
                let ray = cam.generate_ray(raster, lens, 0.5);
                let (we, r2) = cam.we(&ray).expect("a camera ray carries importance");
                assert!((r2 - raster).length() < 2e-3, "aperture {aperture}: {raster} -> {r2}");
                assert!(we > 0.0);
                // sample_wi toward a point on that ray with the same lens sample finds the same pixel.
                let p = ray.at(2.5);
                let cs = cam.sample_wi(p, lens).expect("visible point");
                assert!((cs.raster - raster).length() < 2e-3, "sample_wi raster {} vs {raster}", cs.raster);
                assert!((cs.wi + ray.d).length() < 1e-3);
            }
        }
    }

    /// ∫_lens ∫_hemisphere We cos θ dω dA = 1 and ∫ pdf_dir dω = 1, by Monte Carlo with
    /// uniform directions (fixed seed; tolerance 5 standard errors).
    #[test]
    fn importance_integrates_to_one() {
        for aperture in [0.0, 0.2] {
            let cam = camera(aperture);
            let fwd = cam.to_world.transform_vector3(Vec3::Z).normalize();
            let frame = crate::math::Frame::from_normal(fwd);
            let mut rng = Pcg32::new(7, aperture.to_bits() as u64);
            let n = 400_000;
            let (mut s_we, mut s2_we, mut s_pdf, mut s2_pdf) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for _ in 0..n {
                let l = warp::square_to_uniform_disk_concentric(Vec2::new(rng.next_f32(), rng.next_f32())) * aperture;
                let o = cam.to_world.transform_point3(Vec3::new(l.x, l.y, 0.0));
                let wl = warp::square_to_uniform_hemisphere(Vec2::new(rng.next_f32(), rng.next_f32()));
                let d = frame.to_world(wl);
                let ray = Ray::new(o, d);
                // Estimator of the double integral: We cos / (pdf_dir_uniform * pdf_lens_uniform).
                let lens_pdf = 1.0 / cam.lens_area() as f64;
                let x = cam.we(&ray).map_or(0.0, |(we, _)| we as f64 * wl.z as f64) * 2.0 * std::f64::consts::PI / lens_pdf;
                s_we += x;
                s2_we += x * x;
                let y = cam.pdf_we(&ray).1 as f64 * 2.0 * std::f64::consts::PI;
                s_pdf += y;
                s2_pdf += y * y;
            }
            let nf = n as f64;
            for (s, s2, what) in [(s_we, s2_we, "We"), (s_pdf, s2_pdf, "pdf_dir")] {
                let mean = s / nf;
                let se = ((s2 / nf - mean * mean) / nf).sqrt();
                assert!((mean - 1.0).abs() < 5.0 * se, "aperture {aperture}: ∫{what} = {mean} ± {se}");
            }
        }
    }

    /// End to end: the fraction of camera rays (uniform over film and lens) that hit a small
    /// tilted disk equals ∫_disk cos θ_disk E_lens[We / pdf] dA, estimated with `sample_wi`.
    /// Both sides are Monte Carlo; tolerance 5 combined standard errors.
    #[test]
    fn sample_wi_agrees_with_ray_generation() {
        for aperture in [0.0, 0.3] {
            let cam = camera(aperture);
            let center = cam.to_world.transform_point3(Vec3::new(0.3, -0.2, 2.5));
            let normal = Vec3::new(0.3, 0.5, -1.0).normalize();
            let radius = 0.35f32;
            let disk_frame = crate::math::Frame::from_normal(normal);
            let mut rng = Pcg32::new(3, 4);
            // Side 1: ray generation.
            let n_rays = 600_000;
            let mut hits = 0u64;
            for _ in 0..n_rays {
                let raster = Vec2::new(rng.next_f32() * cam.width as f32, rng.next_f32() * cam.height as f32);
                let ray = cam.generate_ray(raster, Vec2::new(rng.next_f32(), rng.next_f32()), 0.0);
                let denom = ray.d.dot(normal);
                if denom.abs() > 1e-8 {
                    let t = (center - ray.o).dot(normal) / denom;
                    if t > 0.0 && (ray.at(t) - center).length_squared() < radius * radius {
                        hits += 1;
                    }
                }
            }
            let p_hit = hits as f64 / n_rays as f64;
            let se_hit = (p_hit * (1.0 - p_hit) / n_rays as f64).sqrt();
            // Side 2: connections from points on the disk.
            let n_conn = 200_000;
            let area = (PI * radius * radius) as f64;
            let (mut s, mut s2) = (0.0f64, 0.0f64);
            for _ in 0..n_conn {
                let q = warp::square_to_uniform_disk_concentric(Vec2::new(rng.next_f32(), rng.next_f32())) * radius;
                let p = center + disk_frame.to_world(Vec3::new(q.x, q.y, 0.0));
                let x = match cam.sample_wi(p, Vec2::new(rng.next_f32(), rng.next_f32())) {
                    Some(cs) => (cs.we / cs.pdf * cs.wi.dot(normal).abs()) as f64 * area,
                    None => 0.0,
                };
                s += x;
                s2 += x * x;
            }
            let mean = s / n_conn as f64;
            let se = ((s2 / n_conn as f64 - mean * mean) / n_conn as f64).sqrt();
            let tol = 5.0 * (se * se + se_hit * se_hit).sqrt();
            assert!(p_hit > 0.01, "the disk must be well inside the view: {p_hit}");
            assert!((mean - p_hit).abs() < tol, "aperture {aperture}: rays {p_hit} vs connections {mean} (tol {tol})");
        }
    }

    #[test]
    fn orthographic_has_no_connections() {
        let mut cam = camera(0.0);
        cam.projection = Projection::Orthographic;
        assert!(cam.sample_wi(Vec3::new(0.5, 1.5, 2.0), Vec2::splat(0.5)).is_none());
        assert!(cam.we(&Ray::new(Vec3::ZERO, Vec3::Z)).is_none());
    }
}
