//! The path space shared by every bidirectional method (light tracing, BDPT, Metropolis,
//! photon tracing): vertices carrying densities in area measure, random walks from the
//! camera and from the lights, the connection of a light subpath to a camera subpath and
//! its multiple-importance weight (Veach's thesis, ch. 10; the bookkeeping follows pbrt's).
//!
//! Measures and conventions:
//! * `pdf_fwd`: the density with which the walk that built a vertex sampled it from its
//!   predecessor, per unit area at the vertex (per unit solid angle for a vertex at infinity);
//!   `pdf_rev`: the same for a walk in the other direction, sampling it from its successor.
//!   Densities of delta (specular) choices are stored as 0 and the vertex is marked `delta`.
//! * `beta`: the subpath's throughput up to the vertex (the Monte Carlo weight of the walk):
//!   1 at the camera, Le cos / (pmf pdf_pos pdf_dir) leaving a light.
//! * A full path of s light vertices and t camera vertices has s + t - 1 segments; with
//!   Mitsuba's `max_depth` D a camera subpath has at most D + 1 vertices and a light subpath
//!   at most D, so every strategy of every admissible path exists and the MIS weights of
//!   one path sum to one.
//! * Strategies never implemented (t = 0: a light path hitting the lens) get no weight; the
//!   (s, t) = (1, 1) strategy (an emitter connected straight to the camera) exists for area
//!   lights only, as a point light is invisible to a camera ray.
//!
//! Use (what `integrator/bdpt.rs` does per pixel sample; any [`Sampler`](crate::sampling::Sampler),
//! e.g. a primary-sample-space one, drives the walks):
//!
//! ```ignore
//! let cfg = PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters);
//! camera_subpath(scene, &cfg, &ray, raster, sampler, &mut camera);
//! light_subpath(scene, &cfg, ray.time, sampler, &mut light);
//! for t in 1..=camera.len() {
//!     for s in 0..=light.len() {
//!         if let Some(c) = connect(scene, &cfg, &light, &camera, s, t, sampler, true) {
//!             // c.l * c.weight at c.raster (t = 1, a splat) or at the pixel's own raster
//!         }
//!     }
//! }
//! ```

mod camera_batch;
mod connect;
mod mis;
mod shadow;
mod step8;
mod vertex;
mod walk;

pub use camera_batch::{BatchScratch, CameraBatch, Staged};
pub use connect::{camera_connection, connect, weighted_camera_connection, CameraConnection, Connection};
pub use mis::mis_weight;
pub use shadow::{set_lane, ClosestHits, ShadowPackets};
pub(crate) use step8::WalkLanes;
pub use vertex::{Event, EventKind, Vertex, VertexKind};
pub use walk::{camera_subpath, light_subpath, random_walk};
pub(crate) use walk::{camera_subpath_traced, light_subpath_traced, light_walk_draws, light_walk_from, light_walk_light, LightWalk};

use crate::scene::Scene;

/// What the walks and connections need to know about the render.
#[derive(Clone, Copy, Debug)]
pub struct PathConfig {
    /// Most vertices a camera subpath may have (max_depth + 1; unbounded: usize::MAX).
    pub max_camera_vertices: usize,
    /// Most vertices a light subpath may have (max_depth).
    pub max_light_vertices: usize,
    /// Russian roulette from this many segments on.
    pub rr_depth: i32,
    /// Leave out paths of one segment (emitters seen directly).
    pub hide_emitters: bool,
    /// Whether the camera can be connected to (perspective and thin lens; not orthographic).
    pub camera_connectible: bool,
    /// The camera's connection constants (None: orthographic), computed once per render.
    pub lens: Option<crate::camera::LensConnector>,
}

impl PathConfig {
    /// `max_depth` in Mitsuba's meaning (-1 unbounded).
    pub fn new(scene: &Scene, max_depth: i32, rr_depth: i32, hide_emitters: bool) -> Self {
        let (cam, light) = if max_depth < 0 { (usize::MAX, usize::MAX) } else { (max_depth as usize + 1, max_depth as usize) };
        PathConfig {
            max_camera_vertices: cam,
            max_light_vertices: light,
            rr_depth,
            hide_emitters,
            camera_connectible: !matches!(scene.camera.projection, crate::camera::Projection::Orthographic),
            lens: scene.camera.lens_connector(),
        }
    }

    /// Whether a path of `vertices` vertices fits in max_depth.
    pub fn allows(&self, vertices: usize) -> bool {
        vertices <= self.max_camera_vertices
    }
}
