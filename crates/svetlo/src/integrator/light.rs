//! Light tracing (particle tracing): paths start at the lights and every vertex is
//! connected to the camera (next-event estimation toward the lens), splatting where it
//! lands on the film. This is BDPT's t = 1 family alone, unweighted: it sees every path
//! whose last scattering before the camera is diffuse or glossy, and none that reach the
//! camera through a specular surface (a mirror or glass seen directly stays black).
//!
//! Estimator measure: area at every vertex. One light path per pixel sample, so with
//! W·H·spp paths the splats are divided by spp (see `camera/importance.rs`).

use super::splat::{render_splatting, render_tile_by_sample, SampleOut, Splat, SplatEstimator, TileJob};
use super::{Integrator, Progress, RenderSettings};
use crate::accel::packet::LANES;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::geometry::Ray;
use crate::lpe::LightTracker;
use crate::path::{camera_connection, connect, light_subpath, CameraConnection, PathConfig, ShadowPackets, Vertex};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec2;

#[derive(Clone, Copy, Debug, Default)]
pub struct LightTracer;

struct Estimator {
    cfg: PathConfig,
    /// Shadow rays of one subpath's connections as packets (None: one at a time).
    packets: Option<ShadowPackets>,
}

/// Camera connections waiting for their shadow rays, in the order they were made: the
/// rays of consecutive light paths go as one packet, and the splats leave in that order, so
/// the splat lists are those of testing each ray alone.
struct Pending {
    splats: [(Rgb, Vec2); LANES],
    rays: [Ray; LANES],
    n: usize,
}

impl Pending {
    /// A segment of no length cannot be blocked: a ray of no length, which no packet tests.
    const CLEAR: Ray = Ray { o: glam::Vec3::ZERO, d: glam::Vec3::Z, t_max: 0.0, time: 0.0 };

    fn new() -> Pending {
        Pending { splats: [(Rgb::BLACK, Vec2::ZERO); LANES], rays: [Self::CLEAR; LANES], n: 0 }
    }

    fn push(&mut self, packets: &ShadowPackets, c: CameraConnection, out: &mut SampleOut) {
        self.splats[self.n] = (c.l, c.raster);
        self.rays[self.n] = c.shadow.unwrap_or(Self::CLEAR);
        self.n += 1;
        if self.n == LANES {
            self.flush(packets, out);
        }
    }

    fn flush(&mut self, packets: &ShadowPackets, out: &mut SampleOut) {
        let blocked = packets.occluded(&self.rays[..self.n]);
        for (i, &(l, r)) in self.splats[..self.n].iter().enumerate() {
            if blocked & (1 << i) == 0 {
                out.splat(r, l);
            }
        }
        self.n = 0;
    }
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
    /// With packets (and no AOVs): the samples of `sample`, in its order, with the shadow
    /// rays of the connections to the camera tested eight at a time across light paths.
    fn render_tile(&self, t: TileJob, sampler: &mut dyn Sampler, path: &mut Vec<Vertex>, splats: &mut Vec<Splat>) {
        let Some(packets) = self.packets.as_ref().filter(|_| t.settings.aovs().is_empty()) else {
            return render_tile_by_sample(self, t, sampler, path, splats);
        };
        let [x0, y0, x1, y1] = t.rect;
        let cam = t.scene.camera.ray_generator();
        let mut out = SampleOut { splats, layers: Default::default() };
        let mut pending = Pending::new();
        for y in y0..y1 {
            for x in x0..x1 {
                for s in t.s0..t.s0 + t.n {
                    let (raster, ray) = super::camera_sample(&cam, sampler, x, y, s);
                    light_subpath(t.scene, &self.cfg, ray.time, sampler, path);
                    for s in 1..=path.len() {
                        if let Some(c) = camera_connection(t.scene, &self.cfg, path, s, sampler) {
                            pending.push(packets, c, &mut out);
                        }
                    }
                    t.tile.add_sample(raster, Rgb::BLACK);
                }
            }
        }
        pending.flush(packets, &mut out);
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
        let est = Estimator { cfg: PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters), packets: ShadowPackets::new(scene) };
        Ok(render_splatting(scene, settings, progress, &est, 0)?.film)
    }
}
