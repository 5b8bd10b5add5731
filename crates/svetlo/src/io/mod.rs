//! Reading scenes and meshes, reading and writing images. Nothing else touches files.

pub mod image_io;
pub mod mesh_files;
pub mod mitsuba;
pub mod serialized;
pub mod spectra;

pub use image_io::{read_exr, read_image, read_pfm, write_exr, write_image, write_pfm, write_png};
pub use mitsuba::{load_scene, load_scene_from_str};
