//! The two-pass hybrid display: radiosity carries the diffuse transport, ray tracing adds what
//! it cannot (Wallace, Cohen & Greenberg 1987; Chen et al. 1991).
//!
//! A camera path follows specular (delta) bounces, showing emitters it meets, until it reaches
//! a surface with a non-specular lobe. There a final gather replaces the radiosity lookup:
//! direct light by light sampling (sharp shadows), and indirect light by cosine-distributed
//! gather rays that read the reflected radiosity (B − E)/π where they land, after following
//! any specular bounces on the way, where an emitter found through a specular bounce also
//! counts (caustics through glass, light in a mirror; shadow rays stop at such surfaces, so
//! nothing is counted twice). The radiosity pass sees specular-only materials by their
//! diffuse albedo (black): light that reaches a diffuse surface through a specular one and is
//! then reflected diffusely again is missing from the radiosity values (second order). With
//! `gather` = 0 the first diffuse surface shows its radiosity directly.

use super::display::RadiosityView;
use crate::bsdf::TransportMode;
use crate::geometry::ray::offset_ray_origin;
use crate::geometry::Ray;
use crate::integrator::path::sample_light_mis_to;
use crate::integrator::{PixelEstimator, RenderSettings};
use crate::math::{warp, Frame, INV_PI};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec2;

/// Specular bounces followed at most along one camera or gather path.
const MAX_SPECULAR: u32 = 16;

pub struct HybridView<'a> {
    pub view: RadiosityView<'a>,
    pub gather: u32,
    /// Shapes whose material has only delta lobes (mirror, smooth glass).
    specular: Vec<bool>,
}

impl<'a> HybridView<'a> {
    pub fn new(scene: &Scene, view: RadiosityView<'a>, gather: u32) -> Self {
        let specular = scene.shapes.iter().map(|s| !scene.materials[s.material as usize].bsdf(Vec2::splat(0.5)).flags().has_non_specular()).collect();
        HybridView { view, gather, specular }
    }

    /// Reflected radiance (B − E)/π where a ray along `d` hits (emission is counted apart).
    fn reflected(&self, hit: &crate::accel::PrimHit, ray: &Ray) -> Rgb {
        match self.view.element_radiosity(hit, ray.at(hit.t), ray.d) {
            Some((i, b)) => (b - self.view.mesh.elements[i as usize].emission).map(|x| x.max(0.0)) * INV_PI,
            None => Rgb::BLACK,
        }
    }

    /// Radiance arriving along a gather ray: the reflected radiosity at the first non-specular
    /// surface, plus emission when found through a specular bounce.
    fn gather_ray(&self, scene: &Scene, mut ray: Ray, sampler: &mut dyn Sampler) -> Rgb {
        let mut beta = Rgb::WHITE;
        for bounce in 0..=MAX_SPECULAR {
            let Some(hit) = scene.intersect_prim(&ray) else { return Rgb::BLACK };
            if !self.specular[hit.shape as usize] {
                let mut l = self.reflected(&hit, &ray);
                if bounce > 0 && scene.shapes[hit.shape as usize].light.is_some() {
                    if let Some(si) = scene.intersect(&ray) {
                        if let Some((_, area)) = scene.area_light(&si) {
                            l += area.l(si.ng, si.uv, si.wo);
                        }
                    }
                }
                return beta * l;
            }
            let Some(si) = scene.intersect(&ray) else { return Rgb::BLACK };
            let bsdf = scene.bsdf(&si);
            let Some(bs) = bsdf.sample(si.to_local(si.wo), sampler.next_1d(), sampler.next_2d(), TransportMode::Radiance) else { return Rgb::BLACK };
            if bs.pdf <= 0.0 {
                return Rgb::BLACK;
            }
            beta *= bs.weight();
            ray = si.spawn_ray(si.to_world(bs.wi));
        }
        Rgb::BLACK
    }
}

impl PixelEstimator for HybridView<'_> {
    fn li(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        let mut l = Rgb::BLACK;
        let mut beta = Rgb::WHITE;
        let mut ray = *camera_ray;
        for bounce in 0..=MAX_SPECULAR {
            let Some(hit) = scene.intersect_prim(&ray) else { break };
            let Some(si) = scene.intersect(&ray) else { break };
            if let Some((_, area)) = scene.area_light(&si) {
                if !(bounce == 0 && settings.hide_emitters) {
                    l += beta * area.l(si.ng, si.uv, si.wo);
                }
            }
            let bsdf = scene.bsdf(&si);
            let wo = si.to_local(si.wo);
            if !self.specular[hit.shape as usize] {
                if self.gather == 0 {
                    l += beta * self.reflected(&hit, &ray);
                    break;
                }
                let k = self.gather as f32;
                let mut direct = Rgb::BLACK;
                let mut indirect = Rgb::BLACK;
                let n = if si.ng.dot(si.wo) < 0.0 { -si.ng } else { si.ng };
                let frame = Frame::from_normal(n);
                for _ in 0..self.gather {
                    direct += sample_light_mis_to(scene, si.p, si.ng, &si.shading, wo, &bsdf, sampler.next_1d(), sampler.next_2d(), (1.0, 0.0), si.time).0;
                    let w = frame.to_world(warp::square_to_cosine_hemisphere(sampler.next_2d()));
                    indirect += self.gather_ray(scene, Ray::new(offset_ray_origin(si.p, si.ng, w), w), sampler);
                }
                // Cosine-distributed rays: f cos / pdf = ρ for the diffuse part.
                l += beta * (direct + bsdf.diffuse_albedo() * indirect) * (1.0 / k);
                break;
            }
            let Some(bs) = bsdf.sample(wo, sampler.next_1d(), sampler.next_2d(), TransportMode::Radiance) else { break };
            if bs.pdf <= 0.0 {
                break;
            }
            beta *= bs.weight();
            ray = si.spawn_ray(si.to_world(bs.wi));
        }
        l
    }
}
