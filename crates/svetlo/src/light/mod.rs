//! Emitters, with Mitsuba 3's semantics. Area lights are shapes with an emitting material
//! (`area.rs`); the others are standalone: point and spot (`point.rs`), directional and the
//! geometry of rays from infinity (`directional.rs`), constant, and the lat-long
//! environment map (`envmap.rs`), the projector (`projector.rs`), pbrt-v4's goniometric
//! light (`goniometric.rs`).
//!
//! Two families of sampling, with the measures they use:
//! * From a reference point (next-event estimation): `sample_li` returns a direction toward
//!   the light with a solid-angle pdf; delta lights report pdf 1 and `is_delta`.
//! * From the light (light tracing, BDPT, photons): `sample_le` returns a ray leaving the
//!   light with `pdf_pos` (per unit area; 1 for a delta position) and `pdf_dir` (per unit
//!   solid angle; 1 for a delta direction). The emitted flux a sample carries is
//!   `le * |n · d| / (pdf_pos * pdf_dir)`. `pdf_le` gives the densities of a given ray, with
//!   0 for the delta parts (a continuous strategy cannot produce them) — the convention
//!   bidirectional MIS needs. Directional and infinite lights emit from the disk of the
//!   scene's bounding sphere perpendicular to the direction of travel.

pub mod area;
mod directional;
pub(crate) mod emit8;
pub mod envmap;
pub mod goniometric;
pub mod luminaire;
mod point;
pub mod projector;

pub use area::AreaLight;
pub use envmap::EnvMap;
pub use goniometric::Goniometric;
pub use luminaire::Luminaire;
pub use projector::Projector;

use crate::geometry::{Aabb, Ray, SurfaceInteraction};
use crate::math::{warp, Frame, PI};
use crate::spectrum::Rgb;
use directional::{disk_pdf, point_at_infinity, ray_from_infinity};
use glam::{Vec2, Vec3};

/// A light sample as seen from a reference point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the reference point toward the light.
    pub wi: Vec3,
    /// Incident radiance (or intensity / r^2 for point lights, irradiance for directional
    /// lights) arriving along `-wi`.
    pub li: Rgb,
    /// Solid-angle density of `wi` (1 for delta lights).
    pub pdf: f32,
    /// The sampled point on the light (for infinite lights a point beyond the scene).
    pub p: Vec3,
    /// Surface normal at `p` for area lights (bidirectional methods convert densities with
    /// it); zero for the others.
    pub n: Vec3,
    /// Whether `p` is at infinity (shadow rays then run to the scene's bound).
    pub infinite: bool,
}

/// A ray leaving a light (see the module's notes on measures).
#[derive(Clone, Copy, Debug)]
pub struct EmissionSample {
    /// Leaves the light; for area lights the origin is offset off the surface.
    pub ray: Ray,
    /// Radiance along the ray (area, constant, envmap), intensity (point, spot: including
    /// the spot's profile) or irradiance (directional).
    pub le: Rgb,
    pub pdf_pos: f32,
    pub pdf_dir: f32,
    /// Surface normal at the origin for area lights; the ray's direction for the others
    /// (so that |n · d| = 1 in the flux formula).
    pub n: Vec3,
}

#[derive(Clone, Debug)]
pub enum Light {
    Area(AreaLight),
    /// Radiant intensity `intensity` (W/sr) in every direction.
    Point {
        position: Vec3,
        intensity: Rgb,
    },
    /// Mitsuba `spot` (see `point.rs`); the beam's axis is `frame.n`. Build with `Light::spot`.
    Spot {
        position: Vec3,
        frame: Frame,
        intensity: Rgb,
        cos_cutoff: f32,
        cos_beam: f32,
        cutoff_angle: f32,
        /// `cutoff_angle.tan()`, which the texture's mapping divides by at every lookup.
        tan_cutoff: f32,
        beam_width: f32,
        /// Mitsuba's projected `texture`: multiplies the intensity, mapped over the cutoff cone.
        texture: Option<crate::texture::Texture>,
    },
    /// Direction of travel `direction`, irradiance on a surface facing it.
    Directional {
        direction: Vec3,
        irradiance: Rgb,
    },
    /// Uniform radiance from every direction.
    Constant {
        radiance: Rgb,
    },
    /// Latitude-longitude environment map (Mitsuba `envmap`).
    EnvMap(Box<EnvMap>),
    /// A luminaire from an IES or EULUMDAT file (`luminaire.rs`): a delta position (or a
    /// point of its opening per sample) with a tabulated intensity.
    Luminaire(Box<Luminaire>),
    /// A pinhole projecting an image (Mitsuba `projector`, see `projector.rs`).
    Projector(Box<Projector>),
    /// pbrt-v4's `goniometric` light (`goniometric.rs`): a point with an equal-area image
    /// of its intensity.
    Goniometric(Box<Goniometric>),
}

/// Context for light sampling: the scene's bounding sphere (infinite lights need it).
#[derive(Clone, Copy, Debug)]
pub struct SceneBounds {
    pub center: Vec3,
    pub radius: f32,
}

impl SceneBounds {
    pub fn from_aabb(b: &Aabb) -> Self {
        let (center, radius) = b.bounding_sphere();
        SceneBounds { center, radius: radius.max(1e-3) }
    }
}

/// [`Light::sample_li`] of a point light at `position` of `intensity`, seen from `p_ref`
/// (inline, for the path kernel's lanes: the same operations).
#[inline(always)]
pub(crate) fn point_sample_li(position: Vec3, intensity: Rgb, p_ref: Vec3) -> Option<LightSample> {
    let d = position - p_ref;
    let dist2 = d.length_squared();
    if dist2 == 0.0 {
        return None;
    }
    let wi = d / dist2.sqrt();
    Some(LightSample { wi, li: intensity / dist2, pdf: 1.0, p: position, n: Vec3::ZERO, infinite: false })
}

impl Light {
    /// The Mitsuba plugin name of this emitter.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Light::Area(_) => "area",
            Light::Point { .. } => "point",
            Light::Spot { .. } => "spot",
            Light::Projector(_) => "projector",
            Light::Directional { .. } => "directional",
            Light::Constant { .. } => "constant",
            Light::EnvMap(_) => "envmap",
            Light::Luminaire(_) => "ies",
            Light::Goniometric(_) => "goniometric",
        }
    }

    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Spot { .. } | Light::Directional { .. } | Light::Luminaire(_) | Light::Projector(_) | Light::Goniometric(_))
    }

    pub fn is_infinite(&self) -> bool {
        matches!(self, Light::Directional { .. } | Light::Constant { .. } | Light::EnvMap(_))
    }

    /// Sample a direction toward the light from `p_ref`.
    pub fn sample_li(&self, p_ref: Vec3, u: Vec2, bounds: &SceneBounds) -> Option<LightSample> {
        match self {
            Light::Area(a) => a.sample_li(p_ref, u),
            Light::Point { position, intensity } => point_sample_li(*position, *intensity, p_ref),
            Light::Spot { position, .. } => {
                let d = *position - p_ref;
                let dist2 = d.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let wi = d / dist2.sqrt();
                let i = self.spot_intensity(-wi);
                if i.is_black() {
                    return None;
                }
                Some(LightSample { wi, li: i / dist2, pdf: 1.0, p: *position, n: Vec3::ZERO, infinite: false })
            }
            Light::Projector(pr) => {
                let d = pr.position - p_ref;
                let dist2 = d.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let wi = d / dist2.sqrt();
                let i = pr.intensity(-wi);
                if i.is_black() {
                    return None;
                }
                Some(LightSample { wi, li: i / dist2, pdf: 1.0, p: pr.position, n: Vec3::ZERO, infinite: false })
            }
            Light::Directional { direction, irradiance } => {
                let wi = -*direction;
                Some(LightSample { wi, li: *irradiance, pdf: 1.0, p: point_at_infinity(bounds, p_ref, wi), n: Vec3::ZERO, infinite: true })
            }
            Light::Constant { radiance } => {
                let wi = warp::square_to_uniform_sphere(u);
                Some(LightSample {
                    wi,
                    li: *radiance,
                    pdf: warp::square_to_uniform_sphere_pdf(),
                    p: point_at_infinity(bounds, p_ref, wi),
                    n: Vec3::ZERO,
                    infinite: true,
                })
            }
            Light::EnvMap(env) => env.sample_eval(u).map(|s| Self::env_sample(s, p_ref, bounds)),
            Light::Luminaire(l) => l.sample_li(p_ref, u),
            Light::Goniometric(g) => g.sample_li(p_ref),
        }
    }

    /// [`Self::sample_li`] of environment map `env` from `p_ref`, finished at the grid point
    /// `g` that [`EnvMap::sample_points`] drew for its u, whose direction and sin θ are `dir`
    /// ([`EnvMap::grid_to_dirs`]): the same sample, bit for bit.
    #[inline(always)]
    pub fn sample_li_env_at(env: &EnvMap, p_ref: Vec3, g: Vec2, dir: (Vec3, f32), bounds: &SceneBounds) -> Option<LightSample> {
        env.sample_eval_toward(g, || dir).map(|s| Self::env_sample(s, p_ref, bounds))
    }

    /// The light sample of an environment map's (direction, density, radiance) seen from
    /// `p_ref`.
    #[inline(always)]
    fn env_sample((wi, pdf, li): (Vec3, f32, Rgb), p_ref: Vec3, bounds: &SceneBounds) -> LightSample {
        LightSample { wi, li, pdf, p: point_at_infinity(bounds, p_ref, wi), n: Vec3::ZERO, infinite: true }
    }

    /// Radiance arriving from an infinite light along direction `-w` (w points away from the scene).
    pub fn le_escaped(&self, w: Vec3) -> Rgb {
        match self {
            Light::Constant { radiance } => *radiance,
            Light::EnvMap(env) => env.eval(w),
            _ => Rgb::BLACK,
        }
    }

    /// [`Self::le_escaped`] and, where `with_pdf` and the radiance is not black,
    /// [`Self::pdf_li_escaped`] of the same direction (else 0): an environment map locates
    /// the direction in its image once for both.
    pub fn le_pdf_escaped(&self, w: Vec3, with_pdf: bool) -> (Rgb, f32) {
        if let Light::EnvMap(env) = self {
            return env.eval_pdf(w, with_pdf);
        }
        let le = self.le_escaped(w);
        (le, if with_pdf && !le.is_black() { self.pdf_li_escaped(w) } else { 0.0 })
    }

    /// Solid-angle density of `sample_li` for an escaped direction `w` (infinite lights).
    pub fn pdf_li_escaped(&self, w: Vec3) -> f32 {
        match self {
            Light::Constant { .. } => warp::square_to_uniform_sphere_pdf(),
            Light::EnvMap(env) => env.pdf(w),
            _ => 0.0,
        }
    }

    /// Emitted power (luminance), for choosing lights in proportion to it:
    /// * area: π A · mean radiance (one-sided Lambertian);
    /// * point: 4π I; goniometric: 4π I × the image's mean; spot: I ∫ profile dω = 2π I [1 - (sin c - sin b) / (c - b)] for cutoff c
    ///   and beam width b (exact for Mitsuba's linear-in-angle profile);
    /// * directional: E π R² (what crosses the scene's bounding disk);
    /// * constant: 4π L π R²; envmap: π R² ∫ L dω. The infinite lights' values count light
    ///   crossing the bounding sphere's cross-section, so they over-rate lights far from
    ///   what the camera sees, as every such estimate does; they are only selection weights.
    pub fn power(&self, bounds: &SceneBounds) -> f32 {
        let disk = PI * bounds.radius * bounds.radius;
        match self {
            Light::Area(a) => a.power(),
            Light::Point { intensity, .. } => 4.0 * PI * intensity.luminance(),
            Light::Spot { intensity, cutoff_angle, beam_width, texture, .. } => {
                let tex = texture.as_ref().map_or(Rgb::WHITE, |t| t.mean());
                point::spot_solid_angle(*cutoff_angle, *beam_width) * (*intensity * tex).luminance()
            }
            Light::Projector(pr) => pr.power(),
            Light::Directional { irradiance, .. } => disk * irradiance.luminance(),
            Light::Constant { radiance } => 4.0 * PI * disk * radiance.luminance(),
            Light::EnvMap(env) => disk * env.luminance_integral(),
            Light::Luminaire(l) => l.power(),
            Light::Goniometric(g) => g.power(),
        }
        .max(0.0)
    }

    /// Sample a ray leaving the light: `u_pos` chooses the origin, `u_dir` the direction.
    pub fn sample_le(&self, u_pos: Vec2, u_dir: Vec2, time: f32, bounds: &SceneBounds) -> Option<EmissionSample> {
        match self {
            Light::Area(a) => a.sample_le(u_pos, u_dir, time),
            Light::Point { position, intensity } => {
                let d = warp::square_to_uniform_sphere(u_dir);
                let mut ray = Ray::new(*position, d);
                ray.time = time;
                Some(EmissionSample { ray, le: *intensity, pdf_pos: 1.0, pdf_dir: point::POINT_PDF_DIR, n: d })
            }
            Light::Spot { position, frame, cos_cutoff, .. } => {
                let local = warp::square_to_uniform_cone(u_dir, *cos_cutoff);
                let pdf_dir = warp::square_to_uniform_cone_pdf(local, *cos_cutoff);
                let d = frame.to_world(local);
                let mut ray = Ray::new(*position, d);
                ray.time = time;
                Some(EmissionSample { ray, le: self.spot_intensity(d), pdf_pos: 1.0, pdf_dir, n: d })
            }
            Light::Projector(pr) => {
                let (d, pdf_dir) = pr.sample_direction(u_dir);
                let mut ray = Ray::new(pr.position, d);
                ray.time = time;
                Some(EmissionSample { ray, le: pr.intensity(d), pdf_pos: 1.0, pdf_dir, n: d })
            }
            Light::Directional { direction, irradiance } => {
                let (ray, pdf_pos) = ray_from_infinity(bounds, *direction, u_pos, time);
                Some(EmissionSample { ray, le: *irradiance, pdf_pos, pdf_dir: 1.0, n: *direction })
            }
            Light::Constant { .. } | Light::EnvMap(_) => {
                let ls = self.sample_li(bounds.center, u_dir, bounds)?;
                let d = -ls.wi;
                let (ray, pdf_pos) = ray_from_infinity(bounds, d, u_pos, time);
                Some(EmissionSample { ray, le: ls.li, pdf_pos, pdf_dir: ls.pdf, n: d })
            }
            Light::Luminaire(l) => l.sample_le(u_pos, u_dir, time),
            Light::Goniometric(g) => g.sample_le(u_dir, time),
        }
    }

    /// Densities (pdf_pos, pdf_dir) with which `sample_le` produces `ray`, leaving the light
    /// with normal `n` (area lights; ignored otherwise). Delta parts are reported as 0.
    pub fn pdf_le(&self, ray: &Ray, n: Vec3, bounds: &SceneBounds) -> (f32, f32) {
        match self {
            Light::Area(a) => a.pdf_le(ray, n),
            Light::Point { .. } => (0.0, point::POINT_PDF_DIR),
            Light::Spot { frame, cos_cutoff, .. } => (0.0, warp::square_to_uniform_cone_pdf(frame.to_local(ray.d), *cos_cutoff)),
            Light::Projector(pr) => (0.0, pr.pdf_direction(ray.d)),
            Light::Directional { .. } => (disk_pdf(bounds), 0.0),
            Light::Constant { .. } | Light::EnvMap(_) => (disk_pdf(bounds), self.pdf_li_escaped(-ray.d)),
            Light::Luminaire(l) => (0.0, l.pdf_dir(ray.d)),
            Light::Goniometric(g) => (0.0, g.pdf_dir(ray.d)),
        }
    }
}

/// Emitted radiance at a surface hit, for the area light of its shape.
pub fn area_le(light: &AreaLight, si: &SurfaceInteraction) -> Rgb {
    light.l(si.ng, si.uv, si.wo)
}
