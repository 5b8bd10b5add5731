//! Reading scenes and meshes, reading and writing images. Nothing else touches files.

pub mod export;
pub mod exr_encode;
pub mod image_io;
pub mod mesh_files;
pub mod mitsuba;
pub mod pbrt;
mod ply_binary;
pub mod serialized;
pub mod spectra;
pub mod vol;

pub use image_io::{read_exr, read_image, read_pfm, write_exr, write_image, write_pfm, write_png};
pub use mitsuba::{load_scene, load_scene_from_str};
pub use pbrt::{load_pbrt, load_pbrt_from_str};

/// The scene file formats svetlo reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    Mitsuba,
    Pbrt,
}

impl SceneFormat {
    /// The format a file name says: `.pbrt` and `.pbrt.gz` are pbrt-v4, anything else Mitsuba XML.
    pub fn from_path(path: &std::path::Path) -> SceneFormat {
        let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        if name.ends_with(".pbrt") || name.ends_with(".pbrt.gz") {
            SceneFormat::Pbrt
        } else {
            SceneFormat::Mitsuba
        }
    }
}

/// Load a scene in `format`, or in the format its extension says. `defaults` (`-D`) apply to
/// Mitsuba files only; for pbrt files they are an error.
pub fn load_scene_as(path: &std::path::Path, format: Option<SceneFormat>, defaults: &[(String, String)]) -> crate::error::Result<crate::scene::Scene> {
    match format.unwrap_or_else(|| SceneFormat::from_path(path)) {
        SceneFormat::Mitsuba => load_scene(path, defaults),
        SceneFormat::Pbrt => {
            if let Some((k, _)) = defaults.first() {
                return Err(crate::error::Error::Settings(format!("-D {k}=...: pbrt-v4 scenes have no parameters to define")));
            }
            load_pbrt(path)
        }
    }
}
