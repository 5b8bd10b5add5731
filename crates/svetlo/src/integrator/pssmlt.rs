//! Primary-sample-space Metropolis light transport (Kelemen et al. 2002).
//!
//! The state is the vector of uniform numbers a sampling method consumes; the method turns it
//! into a path and its contribution. The target density is the luminance of that contribution,
//! b is estimated by the bootstrap, and mutations are Kelemen's small steps (a Gaussian
//! perturbation of every coordinate on the torus) and large steps (independent samples). Both
//! proposals are symmetric, so a = min(1, f(y) / f(x)).
//!
//! Target `bdpt` (the default): one bidirectional sample, as Kelemen et al. did: the camera
//! subpath reads stream 0 (raster position anywhere on the image, lens, time, then the
//! walk), the light subpath stream 1 and the connections stream 2, so that one subpath
//! growing does not shift the others' coordinates. Every strategy (s, t) is MIS-weighted and
//! deposited where it lands (t = 1 elsewhere on the film); f is their total luminance, so
//! no depth or strategy is truncated away.
//!
//! Target `path`: the path tracer (next-event estimation + MIS); coordinates 0-1 pick the
//! raster position anywhere on the image, 2-4 the lens and time, the rest feed the path.
//!
//! Light path expressions: each deposit goes to the layers its path matches (the path
//! tracer's and BDPT's own routing); the chain's target stays the whole beauty.
//!
//! Options (`pssmlt:key=value,...`): `large-step` (probability, default 0.3), `sigma` (small
//! step deviation, 0.01), `chains` (256), `bootstrap` (100000 seed samples), `target`
//! (`bdpt` or `path`).

use super::bdpt::StrategyRouter;
use super::light::require_connectible_camera;
use super::metropolis::pss::PssSampler;
use super::metropolis::{self, ChainSettings, ChainStats, Contribution, MetropolisTarget, Proposal, TARGET};
use super::path::PathTracer;
use super::{Integrator, PixelEstimator, Progress, RenderSettings};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::lpe::aov::LayerSample;
use crate::lpe::AovSet;
use crate::path::{camera_subpath, connect, light_subpath, PathConfig, Vertex};
use crate::sampling::{Pcg32, Sampler};
use crate::scene::Scene;
use glam::Vec2;

/// Which sampling method the primary samples drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum PssTargetKind {
    #[default]
    Bdpt,
    Path,
}

#[derive(Clone, Debug)]
pub struct PssmltOptions {
    pub large_step_probability: f32,
    pub sigma: f32,
    pub target: PssTargetKind,
    pub chain: ChainSettings,
}

impl Default for PssmltOptions {
    fn default() -> Self {
        PssmltOptions { large_step_probability: 0.3, sigma: 0.01, target: PssTargetKind::Bdpt, chain: ChainSettings::default() }
    }
}

/// Parse `key=value` pairs shared by both Metropolis integrators; returns false for a key it
/// does not know.
pub(crate) fn parse_chain_option(name: &str, cfg: &mut ChainSettings, k: &str, v: &str) -> Result<bool> {
    let int = |v: &str| v.parse::<usize>().map_err(|_| Error::Settings(format!("{name}: {k} needs a whole number, got '{v}'")));
    match k {
        "chains" => cfg.chains = int(v)?,
        "bootstrap" => cfg.bootstrap = int(v)?,
        _ => return Ok(false),
    }
    Ok(true)
}

impl PssmltOptions {
    pub fn parse(params: &str) -> Result<Self> {
        let mut o = PssmltOptions::default();
        for kv in params.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (k, v) = kv.split_once('=').ok_or_else(|| Error::Settings(format!("pssmlt: expected key=value, got '{kv}'")))?;
            let num = |v: &str| v.parse::<f32>().map_err(|_| Error::Settings(format!("pssmlt: {k} needs a number, got '{v}'")));
            if parse_chain_option("pssmlt", &mut o.chain, k, v)? {
                continue;
            }
            match k {
                "large-step" => o.large_step_probability = num(v)?,
                "sigma" => o.sigma = num(v)?,
                "target" => {
                    o.target = match v {
                        "path" => PssTargetKind::Path,
                        "bdpt" => PssTargetKind::Bdpt,
                        _ => return Err(Error::Settings(format!("pssmlt: target is bdpt or path, got '{v}'"))),
                    }
                }
                _ => return Err(Error::Settings(format!("pssmlt: unknown option '{k}' (large-step, sigma, chains, bootstrap, target)"))),
            }
        }
        o.validate()?;
        Ok(o)
    }

    pub fn validate(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.large_step_probability) {
            return Err(Error::Settings(format!("pssmlt: large-step must be in [0, 1], got {}", self.large_step_probability)));
        }
        if !(self.sigma > 0.0 && self.sigma <= 1.0) {
            return Err(Error::Settings(format!("pssmlt: sigma must be in (0, 1], got {}", self.sigma)));
        }
        self.chain.validate()
    }
}

#[derive(Debug, Default)]
pub struct Pssmlt {
    pub options: PssmltOptions,
    last: metropolis::LastStats,
}

impl Pssmlt {
    pub fn new(options: PssmltOptions) -> Self {
        Pssmlt { options, last: Default::default() }
    }

    /// Render and return the chain statistics as well.
    pub fn render_with_stats(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<(Film, ChainStats)> {
        match self.job(scene, settings, metropolis::Job::Blocks(None), progress)? {
            metropolis::JobOutput::Film(film, stats, _) => Ok((*film, stats)),
            metropolis::JobOutput::Bootstrap(_) => Err(crate::error::Error::Invalid("pssmlt: a film was asked for".into())),
        }
    }

    /// The bootstrap alone, or chain blocks (see [`metropolis::Job`]).
    pub fn job(&self, scene: &Scene, settings: &RenderSettings, job: metropolis::Job, progress: &Progress) -> Result<metropolis::JobOutput> {
        self.options.validate()?;
        let (w, h) = (scene.camera.width, scene.camera.height);
        if scene.lights.is_empty() {
            return metropolis::black_job(w, h, settings, &self.options.chain, job);
        }
        match self.options.target {
            PssTargetKind::Bdpt => {
                require_connectible_camera(scene, "pssmlt")?;
                let cfg = PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters);
                let t = BdptTarget { scene, cfg, opts: &self.options, aovs: settings.aovs() };
                metropolis::job(&t, w, h, settings, &self.options.chain, job, progress)
            }
            PssTargetKind::Path => {
                let t = PathTarget { scene, settings, opts: &self.options };
                metropolis::job(&t, w, h, settings, &self.options.chain, job, progress)
            }
        }
    }
}

impl Integrator for Pssmlt {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        Ok(self.last.keep(self.render_with_stats(scene, settings, progress)?))
    }
    fn report(&self) -> Option<String> {
        self.last.report()
    }
}

const KINDS: [&str; 2] = ["small step", "large step"];

/// The path tracer driven by primary samples.
struct PathTarget<'a> {
    scene: &'a Scene,
    settings: &'a RenderSettings,
    opts: &'a PssmltOptions,
}

impl PathTarget<'_> {
    fn eval(&self, s: &mut PssSampler, out: &mut Contribution) {
        s.start_stream(0);
        let cam = &self.scene.camera;
        let u = s.next_2d();
        let raster = Vec2::new(u.x * cam.width as f32, u.y * cam.height as f32);
        let lens = s.next_2d();
        let time = s.next_1d();
        let ray = cam.generate_ray(raster, lens, time);
        let aovs = self.settings.aovs();
        let mut layers = LayerSample::default();
        let l = if aovs.is_empty() {
            PathTracer.li(self.scene, &ray, s, self.settings)
        } else {
            PathTracer.li_layers(self.scene, &ray, s, self.settings, &mut layers)
        };
        out.push_layers(aovs, raster, l, &layers);
    }
}

impl MetropolisTarget for PathTarget<'_> {
    type State = PssSampler;
    fn mutation_names(&self) -> Vec<&'static str> {
        KINDS.to_vec()
    }
    fn bootstrap(&self, rng: Pcg32, weights: &mut Vec<f32>) {
        let mut s = PssSampler::new(rng, self.opts.sigma, self.opts.large_step_probability, 1);
        let mut c = Contribution::default();
        self.eval(&mut s, &mut c);
        weights.push(c.f());
    }
    fn start(&self, rng: Pcg32, _candidate: usize, chain_rng: Pcg32, out: &mut Contribution) -> Option<PssSampler> {
        let mut s = PssSampler::new(rng, self.opts.sigma, self.opts.large_step_probability, 1);
        self.eval(&mut s, out);
        s.set_rng(chain_rng);
        Some(s)
    }
    fn propose(&self, s: &mut PssSampler, out: &mut Contribution) -> Proposal {
        s.start_iteration();
        self.eval(s, out);
        Proposal { kind: usize::from(s.is_large_step()), t_ratio: 1.0 }
    }
    fn accept(&self, s: &mut PssSampler) {
        s.accept();
    }
    fn reject(&self, s: &mut PssSampler) {
        s.reject();
    }
}

/// Bidirectional path tracing driven by primary samples (three streams).
struct BdptTarget<'a> {
    scene: &'a Scene,
    cfg: PathConfig,
    opts: &'a PssmltOptions,
    aovs: &'a AovSet,
}

pub struct BdptState {
    sampler: PssSampler,
    camera: Vec<Vertex>,
    light: Vec<Vertex>,
}

impl BdptTarget<'_> {
    fn fresh(&self, rng: Pcg32) -> BdptState {
        BdptState {
            sampler: PssSampler::new(rng, self.opts.sigma, self.opts.large_step_probability, 3),
            camera: Vec::with_capacity(16),
            light: Vec::with_capacity(16),
        }
    }

    fn eval(&self, st: &mut BdptState, out: &mut Contribution) {
        let scene = self.scene;
        let cam = &scene.camera;
        let s = &mut st.sampler;
        s.start_stream(0);
        let u = s.next_2d();
        let raster = Vec2::new(u.x * cam.width as f32, u.y * cam.height as f32);
        let lens = s.next_2d();
        let time = s.next_1d();
        let ray = cam.generate_ray(raster, lens, time);
        camera_subpath(scene, &self.cfg, &ray, raster, s, &mut st.camera);
        s.start_stream(1);
        light_subpath(scene, &self.cfg, ray.time, s, &mut st.light);
        s.start_stream(2);
        let aovs = self.aovs;
        let mut here = crate::spectrum::Rgb::BLACK;
        let mut layers = LayerSample::default();
        // Each strategy's path routed as BDPT routes it.
        let mut router = StrategyRouter::new(aovs, &st.light, &st.camera);
        for t in 1..=st.camera.len() {
            router.at_t(&st.camera, t);
            for sl in 0..=st.light.len() {
                router.at_s(scene, &st.light, sl);
                if sl + t < 2 || !self.cfg.allows(sl + t) {
                    continue;
                }
                let Some(c) = connect(scene, &self.cfg, &st.light, &st.camera, sl, t, s, true) else { continue };
                let v = c.l * c.weight;
                let mask = router.layers(scene, &st.light, &st.camera, sl, t, &c);
                match c.raster {
                    Some(r) => out.push_masked(r, v, mask | TARGET),
                    None => {
                        here += v;
                        layers.add(mask, v);
                    }
                }
            }
        }
        out.push_layers(aovs, raster, here, &layers);
    }
}

impl MetropolisTarget for BdptTarget<'_> {
    type State = BdptState;
    fn mutation_names(&self) -> Vec<&'static str> {
        KINDS.to_vec()
    }
    fn bootstrap(&self, rng: Pcg32, weights: &mut Vec<f32>) {
        let mut st = self.fresh(rng);
        let mut c = Contribution::default();
        self.eval(&mut st, &mut c);
        weights.push(c.f());
    }
    fn start(&self, rng: Pcg32, _candidate: usize, chain_rng: Pcg32, out: &mut Contribution) -> Option<BdptState> {
        let mut st = self.fresh(rng);
        self.eval(&mut st, out);
        st.sampler.set_rng(chain_rng);
        Some(st)
    }
    fn propose(&self, st: &mut BdptState, out: &mut Contribution) -> Proposal {
        st.sampler.start_iteration();
        self.eval(st, out);
        Proposal { kind: usize::from(st.sampler.is_large_step()), t_ratio: 1.0 }
    }
    fn accept(&self, st: &mut BdptState) {
        st.sampler.accept();
    }
    fn reject(&self, st: &mut BdptState) {
        st.sampler.reject();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse_and_reject_bad_input() {
        let o = PssmltOptions::parse("large-step=0.2, sigma=0.05,chains=8,bootstrap=100,target=path").unwrap();
        assert_eq!((o.large_step_probability, o.sigma, o.chain.chains, o.chain.bootstrap, o.target), (0.2, 0.05, 8, 100, PssTargetKind::Path));
        for bad in ["large-step=2", "sigma=0", "chains=0", "bootstrap=-1", "target=photon", "nonsense=1", "sigma", "sigma=abc"] {
            assert!(PssmltOptions::parse(bad).is_err(), "{bad} accepted");
        }
        assert!(crate::methods::by_name("pssmlt:sigma=x").is_err());
    }
}
