//! Light tracing (particle tracing): paths start at the lights and every vertex is
//! connected to the camera (next-event estimation toward the lens), splatting where it
//! lands on the film. This is BDPT's t = 1 family alone, unweighted: it sees every path
//! whose last scattering before the camera is diffuse or glossy, and none that reach the
//! camera through a specular surface (a mirror or glass seen directly stays black).
//!
//! Estimator measure: area at every vertex. One light path per pixel sample, so with
//! W·H·spp paths the splats are divided by spp (see `camera/importance.rs`).

use super::splat::{render_splatting, SampleOut, SplatEstimator};
use super::{Integrator, Progress, RenderSettings};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::geometry::Ray;
use crate::lpe::LightTracker;
use crate::path::{connect, light_subpath, PathConfig, Vertex};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec2;

#[derive(Clone, Copy, Debug, Default)]
pub struct LightTracer;

struct Estimator {
    cfg: PathConfig,
}

impl SplatEstimator for Estimator {
    type Scratch = Vec<Vertex>;
    fn scratch(&self) -> Vec<Vertex> {
        Vec::with_capacity(16)
    }
    fn sample(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        ray: &Ray,
        _raster: Vec2,
        sampler: &mut dyn Sampler,
        path: &mut Vec<Vertex>,
        out: &mut SampleOut,
    ) -> Rgb {
        light_subpath(scene, &self.cfg, ray.time, sampler, path);
        // With AOVs: the reverse automata's states over the vertices before the connected one.
        let aovs = settings.aovs();
        let mut events = (!aovs.is_empty() && !path.is_empty()).then(|| LightTracker::light(aovs, aovs.endpoint_event(scene, &path[0])));
        for s in 1..=path.len() {
            if let Some(c) = connect(scene, &self.cfg, path, &[], s, 1, sampler, false) {
                if let Some(r) = c.raster {
                    match events {
                        None => out.splat(r, c.l),
                        Some(mut e) => {
                            if s >= 2 {
                                e.push(aovs.connected_event(&path[s - 1], c.sampled_p));
                            }
                            out.splat_layers(e.meets_camera(), r, c.l);
                        }
                    }
                }
            }
            if let (Some(e), true) = (events.as_mut(), s >= 2) {
                if let Some(ev) = aovs.sampled_event(&path[s - 1]) {
                    e.push(ev);
                }
            }
        }
        Rgb::BLACK
    }
    fn supports_lpe(&self) -> bool {
        true
    }
}

/// Checks shared by the methods that connect to the camera.
pub(crate) fn require_connectible_camera(scene: &Scene, method: &str) -> Result<()> {
    if matches!(scene.camera.projection, crate::camera::Projection::Orthographic) {
        return Err(Error::Settings(format!(
            "the {method} integrator connects paths to the camera, which an orthographic camera does not allow; use path or bdpt"
        )));
    }
    Ok(())
}

impl Integrator for LightTracer {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        require_connectible_camera(scene, "light")?;
        let est = Estimator { cfg: PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters) };
        Ok(render_splatting(scene, settings, progress, &est, 0)?.film)
    }
}
