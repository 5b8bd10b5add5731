//! The camera side of the photon methods: a path tracer (NEE and BSDF sampling under the
//! power heuristic, Russian roulette, exactly `path`'s rules) that hands every vertex with a
//! diffuse lobe to the method, which estimates the non-delta scattering there from photons.
//!
//! How path space is split at such a vertex x (depth d from the camera):
//! * light arriving straight from an emitter: NEE plus one BSDF sample, weighted by MIS, as
//!   `path` does; the BSDF-sampled ray is traced only to see whether it meets an emitter;
//! * everything else reaching x through its non-delta lobes: photons (the method's callback);
//! * the delta lobes of x (a plastic's coating): when the BSDF sample picked one, the walk
//!   goes on, so that the next vertex is handled the same way.
//!
//! Vertices with only glossy or only specular lobes are path-traced through.

use crate::bsdf::LobeFlags;
use crate::geometry::Ray;
use crate::integrator::path::{self, WalkRules, WalkVertex};
use crate::integrator::RenderSettings;
use crate::lpe::aov::LayerSample;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;

/// A camera-path vertex whose BSDF has a diffuse lobe: the walk's vertex (dereferences to
/// it) and its place among the path's diffuse vertices.
pub(crate) struct DiffuseVertex<'a> {
    pub vertex: &'a WalkVertex<'a>,
    /// How many diffuse vertices came before this one on the path.
    pub index: u32,
}

impl<'a> std::ops::Deref for DiffuseVertex<'a> {
    type Target = WalkVertex<'a>;
    fn deref(&self) -> &WalkVertex<'a> {
        self.vertex
    }
}

/// The method's part at a diffuse vertex: radiance without the throughput, and with AOVs the
/// same routed by paths into the sample's layers, times the throughput (see `WalkRules`).
pub(crate) type AtDiffuse<'f> = dyn FnMut(&DiffuseVertex, &mut dyn Sampler, Option<&mut LayerSample>) -> Rgb + 'f;

/// Radiance along `camera_ray` from emission and NEE, routed into `layers` with AOVs;
/// `at_diffuse` returns the photon part at each diffuse vertex.
pub(crate) fn camera_walk(
    scene: &Scene,
    camera_ray: &Ray,
    sampler: &mut dyn Sampler,
    settings: &RenderSettings,
    at_diffuse: &mut AtDiffuse,
    layers: &mut LayerSample,
) -> Rgb {
    path::camera_walk(scene, camera_ray, sampler, settings, &mut PhotonRules { at_diffuse, index: 0 }, layers)
}

/// The photon methods' split of path space (module comment) as rules of the camera walk.
struct PhotonRules<'f> {
    at_diffuse: &'f mut AtDiffuse<'f>,
    /// Diffuse vertices met so far.
    index: u32,
}

impl WalkRules for PhotonRules<'_> {
    fn at_vertex(&mut self, v: &WalkVertex, sampler: &mut dyn Sampler, layers: Option<&mut LayerSample>) -> Rgb {
        if !v.flags.intersects(LobeFlags::DIFFUSE) {
            return Rgb::BLACK;
        }
        let d = DiffuseVertex { vertex: v, index: self.index };
        self.index += 1;
        (self.at_diffuse)(&d, sampler, layers)
    }
    /// A non-delta sample at a diffuse vertex: photons account for that light, except what
    /// comes straight from an emitter.
    fn ends_after(&self, flags: LobeFlags, lobe: LobeFlags) -> bool {
        flags.intersects(LobeFlags::DIFFUSE) && !lobe.is_specular()
    }
}
