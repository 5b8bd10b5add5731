//! The one registry of rendering methods: a method's name and options (`bdpt`,
//! `radiosity:solver=hierarchical`, ...) become an [`Integrator`]. The CLI, the Python
//! package, the preview and the distributed driver all ask here, so a method added once is
//! everywhere. It sits above `integrator` and `radiosity`, so neither imports the other.

use crate::error::{Error, Result};
use crate::integrator::{self, Integrator};

/// A method's name, what it computes, and whether it takes `name:key=value,...` options.
pub struct Method {
    pub name: &'static str,
    pub summary: &'static str,
    pub options: bool,
}

/// Every method [`by_name`] knows, in the order the documentation lists them.
pub const METHODS: &[Method] = &[
    Method { name: "path", summary: "path tracing with next-event estimation and MIS (eight-wide kernel where the scene qualifies)", options: true },
    Method { name: "light", summary: "light (particle) tracing: paths from the lights connected to the camera; alias 'ptracer'", options: false },
    Method { name: "bdpt", summary: "bidirectional path tracing, every (s,t) strategy under the power heuristic", options: false },
    Method { name: "direct", summary: "direct illumination only (emitters seen and one bounce of light)", options: false },
    Method { name: "whitted", summary: "Whitted ray tracing: local model at diffuse surfaces, ideal mirrors and refraction", options: false },
    Method { name: "distributed", summary: "Cook's distributed ray tracing: glossy lobes, soft shadows, depth of field, motion blur", options: false },
    Method { name: "zbuffer", summary: "Z-buffer rasterisation with local models and shadow maps", options: false },
    Method { name: "radiosity", summary: "finite-element radiosity (form factors, solvers, hierarchy, two-pass hybrid)", options: true },
    Method { name: "photon", summary: "Jensen's photon mapping with caustic map and final gather", options: true },
    Method { name: "sppm", summary: "stochastic progressive photon mapping", options: true },
    Method { name: "pssmlt", summary: "primary-sample-space Metropolis light transport (Kelemen)", options: true },
    Method { name: "mlt", summary: "Veach's path-space Metropolis light transport", options: true },
];

/// The integrator a name selects (scene file `<integrator type=...>` or `--integrator`):
/// `NAME` or `NAME:key=value,...` for the methods that take options.
pub fn by_name(spec: &str) -> Result<Box<dyn Integrator>> {
    use crate::radiosity::{display::RadiosityIntegrator, RadiosityOptions};
    use integrator::{mlt, photon, pssmlt};
    let (name, opts) = match spec.split_once(':') {
        Some((n, o)) => (n, Some(o)),
        None => (spec, None),
    };
    let takes_options = METHODS.iter().any(|m| m.name == name && m.options);
    if opts.is_some() && !takes_options {
        return Err(Error::Settings(format!("integrator '{name}' takes no options (got '{spec}')")));
    }
    let o = opts.unwrap_or("");
    Ok(match name {
        // `path:simd=false` forces the scalar tracer (see `path_simd`).
        "path" => Box::new(integrator::path_simd::SimdPathTracer::parse(o)?),
        "light" | "ptracer" => Box::new(integrator::light::LightTracer),
        "bdpt" => Box::new(integrator::bdpt::Bdpt),
        "direct" => Box::new(integrator::direct::DirectIntegrator::default()),
        "whitted" => Box::new(integrator::whitted::Whitted),
        "distributed" => Box::new(integrator::distributed::Distributed),
        "zbuffer" => Box::new(integrator::zbuffer::ZBuffer::default()),
        "radiosity" => Box::new(RadiosityIntegrator { options: RadiosityOptions::parse(o)? }),
        "photon" => Box::new(photon::PhotonMapper { options: photon::PhotonOptions::parse(o)? }),
        "sppm" => Box::new(photon::Sppm { options: photon::SppmOptions::parse(o)? }),
        "pssmlt" => Box::new(pssmlt::Pssmlt::new(pssmlt::PssmltOptions::parse(o)?)),
        "mlt" => Box::new(mlt::Mlt::new(mlt::MltOptions::parse(o)?)),
        _ => {
            let names: Vec<String> = METHODS.iter().map(|m| if m.options { format!("{}[:options]", m.name) } else { m.name.to_string() }).collect();
            return Err(Error::Settings(format!("unknown integrator '{name}' (available: {})", names.join(", "))));
        }
    })
}

/// The methods whose image is a sum over the camera-side pass driver, so that a range of its
/// passes can be rendered anywhere ([`render_passes`]). `photon` and `radiosity` qualify
/// because their precomputation (the photon maps, the radiosity solve) is a deterministic
/// function of the scene and seed: every range recomputes it, identically.
pub const PASS_SEPARABLE: &[&str] = &["path", "light", "ptracer", "bdpt", "direct", "whitted", "distributed", "photon", "radiosity"];

/// Whether `spec` (a name with options) names a method of [`PASS_SEPARABLE`].
pub fn pass_separable(spec: &str) -> bool {
    PASS_SEPARABLE.contains(&spec.split_once(':').map_or(spec, |(n, _)| n))
}

/// Render passes `range` (a node of the pass tree of `settings.spp`) of `scene` with the method
/// `spec`: the raw sums that [`PartialFilm::merge`](crate::film::raw::PartialFilm::merge)
/// combines with the other nodes' into the local render's film, bit for bit.
pub fn render_passes(
    spec: &str,
    scene: &crate::scene::Scene,
    settings: &integrator::RenderSettings,
    range: std::ops::Range<u32>,
    progress: &integrator::Progress,
) -> Result<crate::film::raw::PartialFilm> {
    if !pass_separable(spec) {
        return Err(Error::Settings(format!(
            "integrator '{spec}' is not a sum of independent pixel samples: a range of its passes cannot be rendered apart (methods that can: {})",
            PASS_SEPARABLE.join(", ")
        )));
    }
    if settings.time_limit.is_some() {
        return Err(Error::Settings("a range of passes needs a render without a time limit".into()));
    }
    let method = by_name(spec)?;
    let plan = integrator::passes::pass_plan(settings.spp, scene.camera.width as u64 * scene.camera.height as u64);
    let want: u32 = plan.get(range.start as usize..range.end as usize).map_or(0, |p| p.iter().map(|p| p.1).sum());
    let s = integrator::RenderSettings { pass_range: Some(range.clone()), ..settings.clone() };
    let film = method.render(scene, &s, progress)?;
    if progress.cancelled() {
        return Err(Error::Invalid(format!("the render of passes {}..{} was cancelled", range.start, range.end)));
    }
    // A method that ignored the range would hand back the whole render.
    if film.spp_done != want {
        return Err(Error::Invalid(format!("'{spec}' rendered {} samples per pixel for passes {}..{}, not {want}", film.spp_done, range.start, range.end)));
    }
    Ok(crate::film::raw::PartialFilm { passes: range, passes_total: plan.len() as u32, film })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_method_is_made() {
        for m in METHODS {
            assert!(by_name(m.name).is_ok(), "{}", m.name);
        }
        assert!(by_name("ptracer").is_ok());
    }

    #[test]
    fn options_only_where_taken() {
        assert!(by_name("bdpt:x=1").is_err());
        assert!(by_name("sppm:alpha=0.5").is_ok());
        let e = by_name("nope").err().expect("unknown").to_string();
        assert!(e.contains("unknown integrator 'nope'") && e.contains("radiosity[:options]"), "{e}");
    }
}
