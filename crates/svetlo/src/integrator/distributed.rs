//! Distributed ray tracing (Cook, Porter and Carpenter 1984): light path class
//! L D? (G|S)* E. Every integral of the image is sampled by distributing rays rather than
//! branching: pixel area (anti-aliasing, stratified), lens (depth of field, the thin-lens
//! camera), shutter time (motion blur: rays carry their time to every bounce and shadow
//! ray), area lights (soft shadows), and glossy reflection and refraction (BSDF sampling).
//!
//! At each hit the light reflected directly from the emitters is estimated with one light
//! sample and one BSDF sample combined by the power heuristic (as `path` does); the path
//! then continues only through glossy and specular scattering (Cook's method has no diffuse
//! interreflection): it continues when the BSDF sample is a delta lobe, or when the
//! material has no diffuse lobe at all. A material mixing a diffuse and a glossy lobe
//! (plastic, Phong, Ward, ...) ends the path after its direct light, since its sampled
//! weight cannot be split between the lobes; its delta lobes (smooth plastic's coating)
//! still reflect. So with max_depth 2 it is direct illumination and equals `path`.
//!
//! Pixel samples are stratified, as Cook's method defines it: when the settings ask for the
//! independent sampler (the default), the Owen-scrambled Sobol sampler is used instead.

use super::path::{camera_walk, WalkRules};
use super::{render_pixels, Integrator, PixelEstimator, Progress, RenderSettings};
use crate::bsdf::LobeFlags;
use crate::error::Result;
use crate::film::Film;
use crate::geometry::Ray;
use crate::lpe::aov::LayerSample;
use crate::sampling::{Sampler, SamplerKind};
use crate::scene::Scene;
use crate::spectrum::Rgb;

#[derive(Clone, Copy, Debug, Default)]
pub struct Distributed;

impl Integrator for Distributed {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        let mut s = settings.clone();
        if s.sampler == SamplerKind::Independent {
            s.sampler = SamplerKind::Sobol;
        }
        render_pixels(scene, &s, progress, self)
    }
}

impl PixelEstimator for Distributed {
    fn li(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        camera_walk(scene, camera_ray, sampler, settings, &mut CookRules, &mut Default::default())
    }
    /// The walk routes every contribution by its events (Cook's rule only ends paths).
    fn li_layers(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        camera_walk(scene, camera_ray, sampler, settings, &mut CookRules, layers)
    }
    fn supports_lpe(&self) -> bool {
        true
    }
}

/// Cook's rule: after a sample of a diffuse lobe the bounce only completes the MIS estimate
/// of direct light; delta lobes and materials without a diffuse lobe go on.
struct CookRules;
impl WalkRules for CookRules {
    fn ends_after(&self, flags: LobeFlags, lobe: LobeFlags) -> bool {
        !lobe.is_specular() && flags.intersects(LobeFlags::DIFFUSE)
    }
}
