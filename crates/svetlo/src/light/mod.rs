//! Emitters. Area lights are shapes with an emitting material; the others are standalone.
//! `sample_li` returns a direction toward the light with a solid-angle pdf (delta lights
//! report pdf 1 and `is_delta`).

use crate::geometry::{Aabb, Geometry, SurfaceInteraction};
use crate::math::{warp, Frame, INV_PI, PI};
use crate::sampling::Distribution1D;
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A light sample as seen from a reference point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the reference point toward the light.
    pub wi: Vec3,
    /// Incident radiance (or intensity / r^2 for point lights) arriving along `-wi`.
    pub li: Rgb,
    /// Solid-angle density of `wi` (1 for delta lights).
    pub pdf: f32,
    /// The sampled point on the light (for infinite lights a point beyond the scene).
    pub p: Vec3,
    /// Whether `p` is at infinity (shadow rays then run to the scene's bound).
    pub infinite: bool,
}

/// Emitting shape: one-sided (front of the geometric normal), as Mitsuba's `area`.
#[derive(Clone, Debug)]
pub struct AreaLight {
    pub shape: u32,
    pub geometry: Arc<Geometry>,
    pub radiance: Texture,
    /// Triangle selection by area (meshes only).
    pub tri_distribution: Option<Distribution1D>,
    pub area: f32,
}

#[derive(Clone, Debug)]
pub enum Light {
    Area(AreaLight),
    Point {
        position: Vec3,
        intensity: Rgb,
    },
    /// Mitsuba `spot`: smooth falloff between `cos_beam` (full) and `cos_cutoff` (zero).
    Spot {
        position: Vec3,
        frame: Frame,
        intensity: Rgb,
        cos_cutoff: f32,
        cos_beam: f32,
        cutoff_angle: f32,
        beam_width: f32,
    },
    /// Direction of travel `direction`, irradiance on a surface facing it.
    Directional {
        direction: Vec3,
        irradiance: Rgb,
    },
    Constant {
        radiance: Rgb,
    },
    /// Latitude-longitude environment map (Mitsuba `envmap`).
    EnvMap(Box<EnvMap>),
}

#[derive(Clone, Debug)]
pub struct EnvMap {
    pub image: Arc<crate::texture::Bitmap>,
    pub to_world: glam::Mat4,
    pub scale: f32,
    pub distribution: crate::sampling::Distribution2D,
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

impl AreaLight {
    pub fn new(shape: u32, geometry: Arc<Geometry>, radiance: Texture) -> Self {
        let (tri_distribution, area) = match &*geometry {
            Geometry::Mesh(m) => {
                let areas: Vec<f32> = (0..m.triangle_count()).map(|t| m.triangle_area(t)).collect();
                let area = areas.iter().sum();
                (Some(Distribution1D::new(&areas)), area)
            }
            Geometry::Sphere(s) => (None, s.area()),
        };
        AreaLight { shape, geometry, radiance, tri_distribution, area }
    }

    /// Radiance leaving point with normal `n` and uv toward direction `w`.
    #[inline]
    pub fn l(&self, n: Vec3, uv: Vec2, w: Vec3) -> Rgb {
        if n.dot(w) <= 0.0 {
            Rgb::BLACK
        } else {
            self.radiance.eval(uv)
        }
    }

    /// Uniform point on the surface by area: (point, normal, uv, pdf_area).
    pub fn sample_point(&self, u: Vec2) -> (Vec3, Vec3, Vec2, f32) {
        match &*self.geometry {
            Geometry::Mesh(m) => {
                let dist = self.tri_distribution.as_ref().expect("mesh light has a triangle distribution");
                let (t, _, ur) = dist.sample_discrete(u.x);
                let b = warp::square_to_uniform_triangle(Vec2::new(ur, u.y));
                let [p0, p1, p2] = m.vertices(t);
                let p = p0 * (1.0 - b.x - b.y) + p1 * b.x + p2 * b.y;
                let (ng, _ns, uv, _) = m.surface(t, b.x, b.y);
                (p, ng, uv, 1.0 / self.area)
            }
            Geometry::Sphere(s) => {
                let d = warp::square_to_uniform_sphere(u);
                let p = s.center + d * s.radius;
                let (n, uv, _) = s.surface(p);
                (p, n, uv, 1.0 / self.area)
            }
        }
    }

    pub fn sample_li(&self, p_ref: Vec3, u: Vec2) -> Option<LightSample> {
        let (p, n, uv) = match &*self.geometry {
            // Outside a sphere: sample the cone of directions it subtends (uniform solid angle).
            Geometry::Sphere(s) if !s.flip_normals && (p_ref - s.center).length_squared() > s.radius * s.radius * 1.0001 => {
                let dc = p_ref - s.center;
                let dist = dc.length();
                let sin_max = s.radius / dist;
                let cos_max = crate::math::safe_sqrt(1.0 - sin_max * sin_max);
                let frame = Frame::from_normal(-dc / dist);
                let wl = warp::square_to_uniform_cone(u, cos_max);
                let wi = frame.to_world(wl);
                let pdf = warp::square_to_uniform_cone_pdf(wl, cos_max);
                let t = s.intersect(p_ref, wi, f32::INFINITY).unwrap_or_else(|| {
                    // Grazing direction: the closest point on the tangent cone.
                    (dist * dist - s.radius * s.radius).max(0.0).sqrt()
                });
                let p = p_ref + wi * t;
                let (n, uv, _) = s.surface(p);
                let li = self.l(n, uv, -wi);
                return Some(LightSample { wi, li, pdf, p, infinite: false });
            }
            _ => {
                let (p, n, uv, _) = self.sample_point(u);
                (p, n, uv)
            }
        };
        let d = p - p_ref;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let cos_l = n.dot(-wi);
        if cos_l <= 0.0 {
            return None;
        }
        let pdf = dist2 / (cos_l * self.area);
        Some(LightSample { wi, li: self.radiance.eval(uv), pdf, p, infinite: false })
    }

    /// Solid-angle density of `sample_li` choosing the point `p` (normal `n`) from `p_ref`.
    pub fn pdf_li(&self, p_ref: Vec3, p: Vec3, n: Vec3) -> f32 {
        match &*self.geometry {
            Geometry::Sphere(s) if !s.flip_normals && (p_ref - s.center).length_squared() > s.radius * s.radius * 1.0001 => {
                let dist = (p_ref - s.center).length();
                let sin_max = s.radius / dist;
                let cos_max = crate::math::safe_sqrt(1.0 - sin_max * sin_max);
                1.0 / (2.0 * PI * (1.0 - cos_max))
            }
            _ => {
                let d = p - p_ref;
                let dist2 = d.length_squared();
                let cos_l = n.dot(-d).abs() / dist2.sqrt();
                if cos_l <= 0.0 {
                    return 0.0;
                }
                dist2 / (cos_l * self.area)
            }
        }
    }

    pub fn power(&self) -> f32 {
        PI * self.area * self.radiance.mean().luminance().max(0.0)
    }
}

impl Light {
    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Spot { .. } | Light::Directional { .. })
    }

    pub fn is_infinite(&self) -> bool {
        matches!(self, Light::Directional { .. } | Light::Constant { .. } | Light::EnvMap(_))
    }

    /// Spot falloff as Mitsuba 3 computes it (smoothstep-free linear ramp in angle).
    fn spot_falloff(&self, w_local: Vec3) -> f32 {
        if let Light::Spot { cos_cutoff, cos_beam, cutoff_angle, beam_width, .. } = *self {
            let c = w_local.z;
            if c <= cos_cutoff {
                return 0.0;
            }
            if c >= cos_beam {
                return 1.0;
            }
            let angle = c.clamp(-1.0, 1.0).acos();
            ((cutoff_angle - angle) / (cutoff_angle - beam_width)).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }

    /// Sample a direction toward the light from `p_ref`.
    pub fn sample_li(&self, p_ref: Vec3, u: Vec2, bounds: &SceneBounds) -> Option<LightSample> {
        match self {
            Light::Area(a) => a.sample_li(p_ref, u),
            Light::Point { position, intensity } => {
                let d = *position - p_ref;
                let dist2 = d.length_squared();
                let wi = d / dist2.sqrt();
                Some(LightSample { wi, li: *intensity / dist2, pdf: 1.0, p: *position, infinite: false })
            }
            Light::Spot { position, frame, intensity, .. } => {
                let d = *position - p_ref;
                let dist2 = d.length_squared();
                let wi = d / dist2.sqrt();
                let fall = self.spot_falloff(frame.to_local(-wi));
                if fall == 0.0 {
                    return None;
                }
                Some(LightSample { wi, li: *intensity * (fall / dist2), pdf: 1.0, p: *position, infinite: false })
            }
            Light::Directional { direction, irradiance } => {
                let wi = -*direction;
                Some(LightSample { wi, li: *irradiance, pdf: 1.0, p: p_ref + wi * (2.0 * bounds.radius + (p_ref - bounds.center).length()), infinite: true })
            }
            Light::Constant { radiance } => {
                let wi = warp::square_to_uniform_sphere(u);
                Some(LightSample {
                    wi,
                    li: *radiance,
                    pdf: warp::square_to_uniform_sphere_pdf(),
                    p: p_ref + wi * (2.0 * bounds.radius + (p_ref - bounds.center).length()),
                    infinite: true,
                })
            }
            Light::EnvMap(env) => {
                let (wi, pdf) = env.sample(u)?;
                Some(LightSample { wi, li: env.eval(wi), pdf, p: p_ref + wi * (2.0 * bounds.radius + (p_ref - bounds.center).length()), infinite: true })
            }
        }
    }

    /// Radiance arriving from an infinite light along direction `-w` (w points away from the scene).
    pub fn le_escaped(&self, w: Vec3) -> Rgb {
        match self {
            Light::Constant { radiance } => *radiance,
            Light::EnvMap(env) => env.eval(w),
            _ => Rgb::BLACK,
        }
    }

    /// Solid-angle density of `sample_li` for an escaped direction `w` (infinite lights).
    pub fn pdf_li_escaped(&self, w: Vec3) -> f32 {
        match self {
            Light::Constant { .. } => warp::square_to_uniform_sphere_pdf(),
            Light::EnvMap(env) => env.pdf(w),
            _ => 0.0,
        }
    }

    /// Total emitted power (luminance), for light selection.
    pub fn power(&self, bounds: &SceneBounds) -> f32 {
        let disk = PI * bounds.radius * bounds.radius;
        match self {
            Light::Area(a) => a.power(),
            Light::Point { intensity, .. } => 4.0 * PI * intensity.luminance(),
            Light::Spot { intensity, cos_cutoff, cos_beam, .. } => 2.0 * PI * (1.0 - 0.5 * (cos_cutoff + cos_beam)) * intensity.luminance(),
            Light::Directional { irradiance, .. } => disk * irradiance.luminance(),
            Light::Constant { radiance } => 4.0 * PI * disk * radiance.luminance(),
            Light::EnvMap(env) => 4.0 * PI * disk * env.image.mean().luminance() * env.scale,
        }
        .max(0.0)
    }
}

impl EnvMap {
    /// Build the sampling distribution: luminance weighted by sin(theta) of each row.
    pub fn new(image: Arc<crate::texture::Bitmap>, to_world: glam::Mat4, scale: f32) -> Self {
        let (w, h) = (image.width, image.height);
        let mut f = vec![0.0f32; w * h];
        for y in 0..h {
            let sin_t = (PI * (y as f32 + 0.5) / h as f32).sin();
            for x in 0..w {
                f[y * w + x] = image.texel(x, y).luminance().max(0.0) * sin_t;
            }
        }
        let distribution = crate::sampling::Distribution2D::new(&f, w, h);
        EnvMap { image, to_world, scale, distribution }
    }

    /// Mitsuba's lat-long convention in the map's local frame: +y up, u = (1 + atan2(x, -z)/pi)/2, v = acos(y)/pi.
    fn dir_to_uv(&self, w: Vec3) -> Vec2 {
        let l = self.to_world.inverse().transform_vector3(w).normalize();
        let u = 0.5 * (1.0 + l.x.atan2(-l.z) * INV_PI);
        let v = l.y.clamp(-1.0, 1.0).acos() * INV_PI;
        Vec2::new(u, v)
    }

    fn uv_to_dir(&self, uv: Vec2) -> (Vec3, f32) {
        let phi = (2.0 * uv.x - 1.0) * PI;
        let theta = uv.y * PI;
        let (st, ct) = theta.sin_cos();
        let l = Vec3::new(phi.sin() * st, ct, -phi.cos() * st);
        (self.to_world.transform_vector3(l).normalize(), st)
    }

    pub fn eval(&self, w: Vec3) -> Rgb {
        let uv = self.dir_to_uv(w);
        let (wd, ht) = (self.image.width, self.image.height);
        // Bilinear lookup, wrapping in u and clamping in v.
        let x = uv.x * wd as f32 - 0.5;
        let y = uv.y * ht as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let t = |dx: i64, dy: i64| {
            let xi = (x0 as i64 + dx).rem_euclid(wd as i64) as usize;
            let yi = (y0 as i64 + dy).clamp(0, ht as i64 - 1) as usize;
            self.image.texel(xi, yi)
        };
        ((t(0, 0) * (1.0 - fx) + t(1, 0) * fx) * (1.0 - fy) + (t(0, 1) * (1.0 - fx) + t(1, 1) * fx) * fy) * self.scale
    }

    pub fn sample(&self, u: Vec2) -> Option<(Vec3, f32)> {
        let (uv, pdf_uv) = self.distribution.sample(u);
        let (w, sin_t) = self.uv_to_dir(uv);
        if sin_t <= 0.0 || pdf_uv <= 0.0 {
            return None;
        }
        Some((w, pdf_uv / (2.0 * PI * PI * sin_t)))
    }

    pub fn pdf(&self, w: Vec3) -> f32 {
        let uv = self.dir_to_uv(w);
        let sin_t = (uv.y * PI).sin();
        if sin_t <= 0.0 {
            return 0.0;
        }
        self.distribution.pdf(uv) / (2.0 * PI * PI * sin_t)
    }
}

/// Emitted radiance at a surface hit, for the area light of its shape.
pub fn area_le(light: &AreaLight, si: &SurfaceInteraction) -> Rgb {
    light.l(si.ng, si.uv, si.wo)
}
