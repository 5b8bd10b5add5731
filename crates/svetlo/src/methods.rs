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
/// function of the scene and seed: a range recomputes it identically, or takes it computed
/// once ([`shared_batch`], [`radiosity_solve`]).
pub const PASS_SEPARABLE: &[&str] = &["path", "light", "ptracer", "bdpt", "direct", "whitted", "distributed", "photon", "radiosity"];

/// The Metropolis methods: their chains split by blocks of [`CHAINS_PER_BLOCK`] chains, all
/// started from one bootstrap that [`prepare`] computes once and every block shares.
///
/// [`CHAINS_PER_BLOCK`]: integrator::metropolis::CHAINS_PER_BLOCK
pub const CHAIN_SEPARABLE: &[&str] = &["pssmlt", "mlt"];

fn base_name(spec: &str) -> &str {
    spec.split_once(':').map_or(spec, |(n, _)| n)
}

/// Whether `spec` (a name with options) names a method of [`PASS_SEPARABLE`].
pub fn pass_separable(spec: &str) -> bool {
    PASS_SEPARABLE.contains(&base_name(spec))
}

/// Whether a range of `spec`'s work units can be rendered apart ([`render_passes`]): the
/// pass-separable methods (units: sample passes) and the Metropolis ones (chain blocks).
pub fn splits(spec: &str) -> bool {
    pass_separable(spec) || CHAIN_SEPARABLE.contains(&base_name(spec))
}

fn not_split(spec: &str) -> Error {
    Error::Settings(format!(
        "integrator '{spec}' is not a sum of independent pixel samples or of Metropolis chains: a range of its work cannot be rendered apart (methods that can: {}, {})",
        PASS_SEPARABLE.join(", "),
        CHAIN_SEPARABLE.join(", ")
    ))
}

/// A Metropolis job of the method `spec` (pssmlt or mlt).
fn metropolis_job(
    spec: &str,
    scene: &crate::scene::Scene,
    settings: &integrator::RenderSettings,
    job: integrator::metropolis::Job,
    progress: &integrator::Progress,
) -> Result<integrator::metropolis::JobOutput> {
    let o = spec.split_once(':').map_or("", |(_, o)| o);
    match base_name(spec) {
        "pssmlt" => integrator::pssmlt::Pssmlt::new(integrator::pssmlt::PssmltOptions::parse(o)?).job(scene, settings, job, progress),
        "mlt" => integrator::mlt::Mlt::new(integrator::mlt::MltOptions::parse(o)?).job(scene, settings, job, progress),
        _ => Err(not_split(spec)),
    }
}

/// The work units of a render split over processes, each (first index, count): sample passes
/// (first sample, samples per pixel) of an untimed render, or for Metropolis methods chain
/// blocks (first chain, chains). Ranges of units that are nodes of the pass tree over them
/// ([`integrator::passes`]) are what [`render_passes`] renders.
pub fn unit_plan(spec: &str, scene: &crate::scene::Scene, settings: &integrator::RenderSettings) -> Result<Vec<(u32, u32)>> {
    if pass_separable(spec) {
        return Ok(integrator::passes::pass_plan(settings.spp, scene.camera.width as u64 * scene.camera.height as u64));
    }
    let o = spec.split_once(':').map_or("", |(_, o)| o);
    let chains = match base_name(spec) {
        "pssmlt" => integrator::pssmlt::PssmltOptions::parse(o)?.chain.chains,
        "mlt" => integrator::mlt::MltOptions::parse(o)?.chain.chains,
        _ => return Err(not_split(spec)),
    };
    let per = integrator::metropolis::CHAINS_PER_BLOCK;
    Ok((0..integrator::metropolis::chain_blocks(chains)).map(|b| (b * per as u32, (chains - b as usize * per).min(per) as u32)).collect())
}

/// What every range of a split render shares, computed once and cut into batches by index:
/// the Metropolis bootstrap (one unit), the photon paths of photon mapping (global then
/// caustic); 0 for the others. See [`shared_batch`].
pub fn shared_units(spec: &str) -> Result<u64> {
    let o = spec.split_once(':').map_or("", |(_, o)| o);
    Ok(match base_name(spec) {
        "photon" => integrator::photon::PhotonMapper { options: integrator::photon::PhotonOptions::parse(o)? }.photon_paths(),
        n if CHAIN_SEPARABLE.contains(&n) => 1,
        _ => 0,
    })
}

/// Units `range` of what the ranges of a split render share ([`shared_units`]), as bytes:
/// batches computed apart and given in order to [`render_passes`] are exactly what a local
/// render computes.
pub fn shared_batch(
    spec: &str,
    scene: &crate::scene::Scene,
    settings: &integrator::RenderSettings,
    range: std::ops::Range<u64>,
    progress: &integrator::Progress,
) -> Result<Vec<u8>> {
    let units = shared_units(spec)?;
    if range.start >= range.end || range.end > units {
        return Err(Error::Settings(format!("'{spec}' shares units 0..{units}, not {}..{}", range.start, range.end)));
    }
    if base_name(spec) == "photon" {
        let o = spec.split_once(':').map_or("", |(_, o)| o);
        return integrator::photon::PhotonMapper { options: integrator::photon::PhotonOptions::parse(o)? }.photon_batch(scene, settings, range);
    }
    match metropolis_job(spec, scene, settings, integrator::metropolis::Job::Bootstrap, progress)? {
        integrator::metropolis::JobOutput::Bootstrap(b) => Ok(b.to_bytes()),
        integrator::metropolis::JobOutput::Film(..) => Err(Error::Invalid(format!("'{spec}': the bootstrap was asked for"))),
    }
}

fn radiosity_options(spec: &str) -> Result<crate::radiosity::RadiosityOptions> {
    if base_name(spec) != "radiosity" {
        return Err(Error::Settings(format!("integrator '{spec}' is not radiosity")));
    }
    crate::radiosity::RadiosityOptions::parse(spec.split_once(':').map_or("", |(_, o)| o))
}

fn pool(settings: &integrator::RenderSettings) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| Error::Settings(format!("thread pool: {e}")))
}

/// Radiosity split over processes: the form-factor rows its solve spreads (0: the solve makes
/// its own, see [`crate::radiosity::split`]).
pub fn radiosity_rows(spec: &str, scene: &crate::scene::Scene, settings: &integrator::RenderSettings) -> Result<u64> {
    crate::radiosity::split::row_count(scene, &radiosity_options(spec)?, settings.max_depth)
}

/// Rows `range` of radiosity's form-factor matrix as bytes, on `settings.threads` threads.
pub fn radiosity_row_batch(spec: &str, scene: &crate::scene::Scene, settings: &integrator::RenderSettings, range: std::ops::Range<u64>) -> Result<Vec<u8>> {
    let o = radiosity_options(spec)?;
    pool(settings)?.install(|| crate::radiosity::split::form_factor_rows(scene, &o, settings.max_depth, range))
}

/// The radiosity solution from every row batch ([`radiosity_row_batch`]), as bytes that
/// [`render_passes`] takes as its one shared batch: the chunks show it, none solves again.
pub fn radiosity_solve(spec: &str, scene: &crate::scene::Scene, settings: &integrator::RenderSettings, rows: &[&[u8]]) -> Result<Vec<u8>> {
    let o = radiosity_options(spec)?;
    let solved = pool(settings)?.install(|| crate::radiosity::split::solve_from_rows(scene, &o, settings.max_depth, rows))?;
    Ok(solved.to_bytes())
}

/// Render work units `range` (a node of the tree over [`unit_plan`]) of `scene` with the
/// method `spec`, from the batches of [`shared_batch`] in order (`shared`; empty: computed
/// here): the raw sums
/// that [`PartialFilm::merge`](crate::film::raw::PartialFilm::merge) combines with the other
/// nodes' into the local render's film, bit for bit.
pub fn render_passes(
    spec: &str,
    scene: &crate::scene::Scene,
    settings: &integrator::RenderSettings,
    range: std::ops::Range<u32>,
    shared: &[&[u8]],
    progress: &integrator::Progress,
) -> Result<crate::film::raw::PartialFilm> {
    if !splits(spec) {
        return Err(not_split(spec));
    }
    if settings.time_limit.is_some() {
        return Err(Error::Settings("a range of passes needs a render without a time limit".into()));
    }
    let plan = unit_plan(spec, scene, settings)?;
    let s = integrator::RenderSettings { pass_range: Some(range.clone()), ..settings.clone() };
    let cancelled = || Error::Invalid(format!("the render of passes {}..{} was cancelled", range.start, range.end));
    if !pass_separable(spec) {
        if !integrator::passes::is_node(&range, plan.len() as u32) {
            return Err(Error::Settings(format!("chain blocks {}..{} are not a node of the tree over {} blocks", range.start, range.end, plan.len())));
        }
        let boot = match shared {
            [] => None,
            [b] => Some(integrator::metropolis::Bootstrap::from_bytes(b)?),
            _ => return Err(Error::Settings(format!("'{spec}' shares one bootstrap, not {} batches", shared.len()))),
        };
        let out = metropolis_job(spec, scene, &s, integrator::metropolis::Job::Blocks(boot.as_ref()), progress)?;
        let integrator::metropolis::JobOutput::Film(film, _, mutations) = out else {
            return Err(Error::Invalid(format!("'{spec}': a film was asked for")));
        };
        if progress.cancelled() {
            return Err(cancelled());
        }
        return Ok(crate::film::raw::PartialFilm { passes: range, passes_total: plan.len() as u32, film: *film, mutations });
    }
    let want: u32 = plan.get(range.start as usize..range.end as usize).map_or(0, |p| p.iter().map(|p| p.1).sum());
    let film = if shared.is_empty() {
        by_name(spec)?.render(scene, &s, progress)?
    } else if base_name(spec) == "photon" {
        let o = spec.split_once(':').map_or("", |(_, o)| o);
        integrator::photon::PhotonMapper { options: integrator::photon::PhotonOptions::parse(o)? }.render_from_batches(scene, &s, shared, progress)?
    } else if base_name(spec) == "radiosity" {
        let [solution] = shared else {
            return Err(Error::Settings(format!("'{spec}' shares one solution, not {} batches", shared.len())));
        };
        let solved = crate::radiosity::Solved::from_bytes(scene, solution)?;
        crate::radiosity::display::RadiosityIntegrator { options: radiosity_options(spec)? }.render_solved(scene, &s, progress, solved)?
    } else {
        return Err(Error::Settings(format!("'{spec}' shares nothing between its passes")));
    };
    if progress.cancelled() {
        return Err(cancelled());
    }
    // A method that ignored the range would hand back the whole render.
    if film.spp_done != want {
        return Err(Error::Invalid(format!("'{spec}' rendered {} samples per pixel for passes {}..{}, not {want}", film.spp_done, range.start, range.end)));
    }
    Ok(crate::film::raw::PartialFilm { passes: range, passes_total: plan.len() as u32, film, mutations: 0 })
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
