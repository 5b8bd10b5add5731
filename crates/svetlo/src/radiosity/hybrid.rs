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
//!
//! Light path expressions: the tracker steps through the vertices the display traces (camera,
//! specular bounces, the gather vertex, specular bounces of the gather ray, the emitter of
//! direct light and of light found through a specular bounce). Where a radiosity value is read
//! (the landing point's diffuse reflection, then a whole class of paths behind it), it is
//! split into its one-bounce part and the rest (see [`SolutionClasses`]) and each part goes to
//! the layers that take all of its paths after the prefix traced; an expression that takes only
//! some of them after some prefix is an error at setup, naming the AOV.

use super::display::{specular_events, specular_shapes, RadiosityView, SolutionClasses};
use crate::bsdf::{LobeFlags, TransportMode};
use crate::error::{Error, Result};
use crate::geometry::ray::offset_ray_origin;
use crate::geometry::Ray;
use crate::integrator::path::sample_light_mis_to;
use crate::integrator::{PixelEstimator, RenderSettings};
use crate::lpe::aov::LayerSample;
use crate::lpe::{AovSet, ClassPart, ClassRouter, Event, Tracker};
use crate::math::{warp, Frame, INV_PI};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;

/// Specular bounces followed at most along one camera or gather path.
const MAX_SPECULAR: u32 = 16;

/// The router's classes: the one-bounce part of a radiosity value and the rest.
const ONE: usize = 0;
const MORE: usize = 1;

pub struct HybridView<'a> {
    pub view: RadiosityView<'a>,
    pub gather: u32,
    /// Shapes whose material has only delta lobes (mirror, smooth glass).
    specular: Vec<bool>,
    /// With AOVs: the layers of each part of the radiosity values read ([`Self::route`]).
    router: Option<ClassRouter>,
}

impl<'a> HybridView<'a> {
    pub fn new(scene: &Scene, view: RadiosityView<'a>, gather: u32) -> Self {
        HybridView { view, gather, specular: specular_shapes(scene), router: None }
    }

    /// Prepare the routing to `aovs` (`extended`: the solution's form factors carry light
    /// through specular surfaces). A typed error names an expression that takes only some of
    /// the paths behind a radiosity value after some prefix the display traces.
    pub fn route(&mut self, scene: &Scene, aovs: &AovSet, extended: bool) -> Result<()> {
        if aovs.is_empty() {
            return Ok(());
        }
        self.view.keep_one_bounce()?;
        let classes = SolutionClasses::new(scene, aovs, extended);
        let spec = specular_events(aovs, &self.specular);
        let mut d: Vec<Event> = Vec::new();
        let mut x: Vec<Event> = Vec::new();
        for (s, shape) in scene.shapes.iter().enumerate().filter(|(s, _)| !self.specular[*s]) {
            d.push(SolutionClasses::event(aovs, s as u32));
            let flags = scene.materials[shape.material as usize].bsdf(glam::Vec2::splat(0.5)).flags();
            x.push(aovs.scatter_event(s as u32, flags, None, false));
        }
        // Camera, specular bounces, (the gather vertex, specular bounces,) the landing point.
        let camera = ClassPart::one(&Event::CAMERA);
        let prefix = if self.gather == 0 {
            vec![camera, ClassPart::star(&spec), ClassPart::any(&d)]
        } else {
            vec![camera, ClassPart::star(&spec), ClassPart::any(&x), ClassPart::star(&spec), ClassPart::any(&d)]
        };
        let (one, more) = (classes.one(), classes.more());
        let router = aovs.class_router(&prefix, &[(&one, &classes.ends), (&more, &classes.ends)]).map_err(|e| {
            Error::Settings(format!(
                "radiosity's hybrid display: {e} takes only some of the paths behind a radiosity value it reads \
                 (at the landing point D: its one bounce D{s} L and the rest D{s} D [DS]* L cannot be split further)",
                s = if extended { " S*" } else { "" }
            ))
        })?;
        self.router = Some(router);
        Ok(())
    }

    /// Reflected radiance (B − E)/π where a ray along `d` hits (emission is counted apart),
    /// and the element hit.
    fn reflected(&self, hit: &crate::accel::PrimHit, ray: &Ray) -> Option<(u32, Rgb)> {
        let (i, b) = self.view.element_radiosity(hit, ray.at(hit.t), ray.d)?;
        Some((i, (b - self.view.mesh.elements[i as usize].emission).map(|x| x.max(0.0)) * INV_PI))
    }

    /// [`Self::reflected`] where the path so far (`t`, up to the diffuse reflection there)
    /// reads it, routed in its two parts with throughput `k`.
    fn read(&self, hit: &crate::accel::PrimHit, ray: &Ray, t: &Tracker, k: Rgb, layers: &mut LayerSample) -> Rgb {
        let Some((i, r)) = self.reflected(hit, ray) else { return Rgb::BLACK };
        if let Some(router) = &self.router {
            let one = self.view.one_bounce(hit, ray.at(hit.t), i) * INV_PI;
            layers.add(router.layers(t, ONE), k * one);
            layers.add(router.layers(t, MORE), k * (r - one));
        }
        r
    }

    /// Radiance arriving along a gather ray: the reflected radiosity at the first non-specular
    /// surface, plus emission when found through a specular bounce; routed with throughput
    /// `k` after the prefix `t` (up to the gather vertex).
    fn gather_ray(&self, scene: &Scene, mut ray: Ray, sampler: &mut dyn Sampler, mut t: Tracker, k: Rgb, layers: &mut LayerSample) -> Rgb {
        let aovs = t.set();
        let mut beta = Rgb::WHITE;
        for bounce in 0..=MAX_SPECULAR {
            let Some(hit) = scene.intersect_prim(&ray) else { return Rgb::BLACK };
            if !self.specular[hit.shape as usize] {
                let mut l = Rgb::BLACK;
                if bounce > 0 && scene.shapes[hit.shape as usize].light.is_some() {
                    if let Some(si) = scene.intersect(&ray) {
                        if let Some((_, area)) = scene.area_light(&si) {
                            let e = area.l(si.ng, si.uv, si.wo);
                            l += e;
                            if self.router.is_some() {
                                layers.add(t.ends(aovs.light_event(Some(hit.shape))), k * beta * e);
                            }
                        }
                    }
                }
                t.push(SolutionClasses::event(aovs, hit.shape));
                l += self.read(&hit, &ray, &t, k * beta, layers);
                return beta * l;
            }
            let Some(si) = scene.intersect(&ray) else { return Rgb::BLACK };
            let bsdf = scene.bsdf(&si);
            let Some(bs) = bsdf.sample(si.to_local(si.wo), sampler.next_1d(), sampler.next_2d(), TransportMode::Radiance) else { return Rgb::BLACK };
            if bs.pdf <= 0.0 {
                return Rgb::BLACK;
            }
            beta *= bs.weight();
            if !bs.lobe.is_null() {
                t.push(aovs.scatter_event(si.shape, bsdf.flags(), Some(bs.lobe), bs.lobe.contains(LobeFlags::TRANSMISSION)));
            }
            ray = si.spawn_ray(si.to_world(bs.wi));
        }
        Rgb::BLACK
    }

    /// The display's radiance along `camera_ray`, each contribution also in `layers` (with AOVs).
    fn radiance(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        let aovs = settings.aovs();
        let routed = self.router.is_some();
        let mut t = Tracker::camera(aovs);
        let mut l = Rgb::BLACK;
        let mut beta = Rgb::WHITE;
        let mut ray = *camera_ray;
        for bounce in 0..=MAX_SPECULAR {
            let Some(hit) = scene.intersect_prim(&ray) else { break };
            let Some(si) = scene.intersect(&ray) else { break };
            if let Some((_, area)) = scene.area_light(&si) {
                if !(bounce == 0 && settings.hide_emitters) {
                    let c = beta * area.l(si.ng, si.uv, si.wo);
                    l += c;
                    if routed {
                        layers.add(t.ends(aovs.light_event(Some(si.shape))), c);
                    }
                }
            }
            let bsdf = scene.bsdf(&si);
            let wo = si.to_local(si.wo);
            let flags = bsdf.flags();
            if !self.specular[hit.shape as usize] {
                if self.gather == 0 {
                    let mut td = t;
                    td.push(SolutionClasses::event(aovs, hit.shape));
                    l += beta * self.read(&hit, &ray, &td, beta, layers);
                    break;
                }
                let k = 1.0 / self.gather as f32;
                let albedo = bsdf.diffuse_albedo();
                let mut direct = Rgb::BLACK;
                let mut indirect = Rgb::BLACK;
                let n = if si.ng.dot(si.wo) < 0.0 { -si.ng } else { si.ng };
                let frame = Frame::from_normal(n);
                // The gather vertex: reflection on the camera's side, labelled by its lobes.
                let mut tx = t;
                tx.push(aovs.scatter_event(si.shape, flags, None, false));
                for _ in 0..self.gather {
                    let (c, li, through) =
                        sample_light_mis_to(scene, si.p, si.ng, &si.shading, wo, &bsdf, sampler.next_1d(), sampler.next_2d(), (1.0, 0.0), si.time);
                    direct += c;
                    if routed && !c.is_black() {
                        layers.add(t.ends2(aovs.scatter_event(si.shape, flags, None, through), aovs.emitter_event(&scene.lights[li as usize])), beta * c * k);
                    }
                    let w = frame.to_world(warp::square_to_cosine_hemisphere(sampler.next_2d()));
                    indirect += self.gather_ray(scene, Ray::new(offset_ray_origin(si.p, si.ng, w), w), sampler, tx, beta * albedo * k, layers);
                }
                // Cosine-distributed rays: f cos / pdf = ρ for the diffuse part.
                l += beta * (direct + albedo * indirect) * k;
                break;
            }
            let Some(bs) = bsdf.sample(wo, sampler.next_1d(), sampler.next_2d(), TransportMode::Radiance) else { break };
            if bs.pdf <= 0.0 {
                break;
            }
            beta *= bs.weight();
            if !bs.lobe.is_null() {
                t.push(aovs.scatter_event(si.shape, flags, Some(bs.lobe), bs.lobe.contains(LobeFlags::TRANSMISSION)));
            }
            ray = si.spawn_ray(si.to_world(bs.wi));
        }
        l
    }
}

impl PixelEstimator for HybridView<'_> {
    fn li(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        self.radiance(scene, camera_ray, sampler, settings, &mut LayerSample::default())
    }
    fn li_layers(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        self.radiance(scene, camera_ray, sampler, settings, layers)
    }
    fn supports_lpe(&self) -> bool {
        true
    }
}
