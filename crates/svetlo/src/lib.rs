//! svetlo: a physically based renderer. One immutable [`scene::Scene`], many ways
//! to transport light through it (see DESIGN.md in the shared folder).
//!
//! Dependency order (a module uses only those before it; rustfmt lists them alphabetically):
//! math, spectrum, geometry, accel, sampling, texture, bsdf, camera, film, light, scene, path,
//! then the methods (integrator, raster, radiosity), and io (files) last.

pub mod accel;
pub mod bsdf;
pub(crate) mod bytes;
pub mod camera;
pub mod cpu;
pub mod error;
pub mod film;
#[doc(hidden)]
pub mod fuzzing;
pub mod geometry;
pub mod integrator;
pub mod io;
pub mod light;
pub mod limits;
pub mod lpe;
pub mod math;
pub mod methods;
pub mod path;
pub mod photometry;
pub mod radiosity;
pub mod raster;
pub mod sampling;
pub mod scene;
pub mod spectrum;
pub mod texture;

pub use error::{Error, Result};
pub use spectrum::Rgb;
