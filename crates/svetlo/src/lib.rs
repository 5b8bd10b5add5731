//! svetlo: a physically based renderer. One immutable [`scene::Scene`], many ways
//! to transport light through it (see DESIGN.md in the shared folder).
//!
//! Modules are listed in dependency order: a module uses those above it, never below.

pub mod accel;
pub mod bsdf;
pub mod camera;
pub mod error;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod io;
pub mod light;
pub mod math;
pub mod radiosity;
pub mod sampling;
pub mod scene;
pub mod spectrum;
pub mod texture;

pub use error::{Error, Result};
pub use spectrum::Rgb;
