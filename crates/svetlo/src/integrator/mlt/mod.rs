//! Veach's Metropolis light transport (Veach & Guibas 1997; Veach's thesis, ch. 11): Markov
//! chains over light paths (`path::Vertex` lists, light to camera) with the bidirectional
//! mutation and the lens, caustic and multi-chain perturbations, run by the shared
//! Metropolis driver (bootstrap for b and the starts, chains over threads, expected-value
//! splats).
//!
//! The chains cover every path from an area light to a pinhole camera, specular vertices
//! (mirrors, glass, the coat of plastic, mask pass-through) included (`space.rs`): the
//! bidirectional mutation alone reaches all of them (it can regenerate a whole path, and a
//! camera-side walk makes any path that ends on a light), so nothing is left to a second
//! estimator.
//!
//! Options (`mlt:key=value,...`): `bidir`, `lens`, `caustic`, `multi` (relative
//! probabilities of the mutations, 0 switches one off; defaults 0.4, 0.25, 0.25, 0.1),
//! `chains` (256), `bootstrap` (100000 independent paths).

pub mod mutations;
pub mod space;

use self::space::{MPath, Space};
use super::metropolis::{self, ChainSettings, ChainStats, Contribution, MetropolisTarget, Proposal};
use super::pssmlt::parse_chain_option;
use super::{Integrator, Progress, RenderSettings};
use crate::camera::Projection;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::light::Light;
use crate::path::{camera_subpath, connect, light_subpath, PathConfig};
use crate::sampling::{Pcg32, Sampler};
use crate::scene::Scene;
use glam::Vec2;

/// Mutation kinds, in `Proposal::kind` order.
pub const MUTATIONS: [&str; 4] = ["bidirectional", "lens", "caustic", "multi-chain"];

#[derive(Clone, Debug)]
pub struct MltOptions {
    /// Relative probabilities of the mutations, in `MUTATIONS` order.
    pub weights: [f64; 4],
    pub chain: ChainSettings,
}

impl Default for MltOptions {
    fn default() -> Self {
        MltOptions { weights: [0.4, 0.25, 0.25, 0.1], chain: ChainSettings::default() }
    }
}

impl MltOptions {
    pub fn parse(params: &str) -> Result<Self> {
        let mut o = MltOptions::default();
        for kv in params.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (k, v) = kv.split_once('=').ok_or_else(|| Error::Settings(format!("mlt: expected key=value, got '{kv}'")))?;
            if parse_chain_option("mlt", &mut o.chain, k, v)? {
                continue;
            }
            let num = |v: &str| v.parse::<f64>().map_err(|_| Error::Settings(format!("mlt: {k} needs a number, got '{v}'")));
            match k {
                "bidir" | "bidirectional" => o.weights[0] = num(v)?,
                "lens" => o.weights[1] = num(v)?,
                "caustic" => o.weights[2] = num(v)?,
                "multi" | "multi-chain" => o.weights[3] = num(v)?,
                _ => return Err(Error::Settings(format!("mlt: unknown option '{k}' (bidir, lens, caustic, multi, chains, bootstrap)"))),
            }
        }
        o.validate()?;
        Ok(o)
    }

    pub fn validate(&self) -> Result<()> {
        if self.weights.iter().any(|w| !(w.is_finite() && *w >= 0.0)) {
            return Err(Error::Settings("mlt: mutation probabilities must be finite and >= 0".into()));
        }
        if self.weights[0] <= 0.0 {
            // Only the bidirectional mutation changes a path's length and light end: without it
            // the chains are not ergodic.
            return Err(Error::Settings("mlt: the bidirectional mutation cannot be switched off (the perturbations alone do not reach all paths)".into()));
        }
        self.chain.validate()
    }
}

#[derive(Debug, Default)]
pub struct Mlt {
    pub options: MltOptions,
    last: metropolis::LastStats,
}

/// Whether Veach MLT can render `scene` (area lights only, a pinhole camera).
fn check_scene(scene: &Scene) -> Result<()> {
    match scene.camera.projection {
        Projection::Perspective { aperture_radius: 0.0, .. } => {}
        _ => return Err(Error::Settings("mlt: needs a pinhole perspective camera (use pssmlt for thin lens or orthographic)".into())),
    }
    if scene.lights.iter().any(|l| !matches!(l, Light::Area(_))) {
        return Err(Error::Settings("mlt: needs a scene lit by area lights only (use pssmlt for point, spot, directional or environment lights)".into()));
    }
    Ok(())
}

impl Mlt {
    pub fn new(options: MltOptions) -> Self {
        Mlt { options, last: Default::default() }
    }

    /// The render and the chains' statistics.
    pub fn render_with_stats(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<(Film, ChainStats)> {
        match self.job(scene, settings, metropolis::Job::Blocks(None), progress)? {
            metropolis::JobOutput::Film(film, stats, _) => Ok((*film, stats)),
            metropolis::JobOutput::Bootstrap(_) => Err(Error::Invalid("mlt: a film was asked for".into())),
        }
    }

    /// The bootstrap alone, or chain blocks (see [`metropolis::Job`]).
    pub fn job(&self, scene: &Scene, settings: &RenderSettings, job: metropolis::Job, progress: &Progress) -> Result<metropolis::JobOutput> {
        self.options.validate()?;
        let (w, h) = (scene.camera.width, scene.camera.height);
        if scene.lights.is_empty() {
            return metropolis::black_job(w, h, settings, &self.options.chain, job);
        }
        let t = Target::new(scene, settings, self.options.weights)?;
        metropolis::job(&t, w, h, settings, &self.options.chain, job, progress)
    }
}

impl Integrator for Mlt {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        Ok(self.last.keep(self.render_with_stats(scene, settings, progress)?))
    }
    fn report(&self) -> Option<String> {
        self.last.report()
    }
}

/// The chains' target: a path and its contribution splatted at its film position.
pub struct Target<'a> {
    pub space: Space<'a>,
    /// Bidirectional walks for the estimate of b.
    cfg: PathConfig,
    /// Probabilities of the mutations, in `MUTATIONS` order.
    pub probs: [f64; 4],
    /// Powers of each mutation's T(y→x)/T(x→y): 1 for rendering; tests set -1 (the ratio
    /// upside down) to check that a wrong acceptance ratio is detected.
    #[doc(hidden)]
    pub ratio_power: [f64; 4],
    /// The render's AOVs: each path's deposit goes to the layers its events match.
    lpe: Option<std::sync::Arc<crate::lpe::AovSet>>,
}

impl<'a> Target<'a> {
    /// The chains' target for `scene` with mutation probabilities `weights` (any scale).
    pub fn new(scene: &'a Scene, settings: &RenderSettings, weights: [f64; 4]) -> Result<Self> {
        check_scene(scene)?;
        let total: f64 = weights.iter().sum();
        if total.is_nan() || total <= 0.0 {
            return Err(Error::Settings("mlt: no mutation has a positive probability".into()));
        }
        Ok(Target {
            space: Space::new(scene, settings.max_depth, settings.hide_emitters),
            cfg: PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters),
            probs: weights.map(|w| w / total),
            ratio_power: [1.0; 4],
            lpe: settings.lpe.clone(),
        })
    }
}

pub struct State {
    pub x: MPath,
    y: Option<MPath>,
    rng: Pcg32,
}

impl Target<'_> {
    /// The contribution of `x` as film splats.
    pub fn contribution(&self, x: &MPath, out: &mut Contribution) {
        let aovs = self.lpe.as_deref().unwrap_or(crate::lpe::AovSet::empty());
        let mask = if aovs.is_empty() { crate::lpe::aov::BEAUTY } else { aovs.path_layers(self.space.scene, &x.v) };
        out.push_masked(x.raster(), self.space.contribution(x), mask | metropolis::TARGET);
    }

    /// Propose by mutation `kind`: the proposal and T(y→x)/T(x→y), or None (stay).
    pub fn mutate(&self, kind: usize, x: &MPath, rng: &mut Pcg32) -> Option<(MPath, f64)> {
        match kind {
            0 => mutations::bidirectional(&self.space, x, rng),
            1 => mutations::lens(&self.space, x, rng),
            2 => mutations::caustic(&self.space, x, rng),
            _ => mutations::multi_chain(&self.space, x, rng),
        }
    }
}

impl MetropolisTarget for Target<'_> {
    type State = State;
    fn mutation_names(&self) -> Vec<&'static str> {
        MUTATIONS.to_vec()
    }
    fn bootstrap(&self, mut rng: Pcg32, weights: &mut Vec<f32>) {
        let w = match mutations::independent(&self.space, &mut rng) {
            Some((y, p)) => (self.space.contribution(&y).luminance() as f64 / p) as f32,
            None => 0.0,
        };
        weights.push(if w.is_finite() { w.max(0.0) } else { 0.0 });
    }
    fn start(&self, mut rng: Pcg32, _candidate: usize, chain_rng: Pcg32, out: &mut Contribution) -> Option<State> {
        let (x, _) = mutations::independent(&self.space, &mut rng)?;
        self.contribution(&x, out);
        Some(State { x, y: None, rng: chain_rng })
    }
    fn propose(&self, st: &mut State, out: &mut Contribution) -> Proposal {
        let u = st.rng.next_f64();
        let mut acc = 0.0;
        let mut kind = MUTATIONS.len() - 1;
        for (i, p) in self.probs.iter().enumerate() {
            acc += p;
            if u < acc && *p > 0.0 {
                kind = i;
                break;
            }
        }
        match self.mutate(kind, &st.x, &mut st.rng) {
            Some((y, ratio)) => {
                self.contribution(&y, out);
                st.y = Some(y);
                Proposal { kind, t_ratio: if self.ratio_power[kind] == 1.0 { ratio } else { ratio.powf(self.ratio_power[kind]) } }
            }
            None => {
                st.y = None;
                Proposal { kind, t_ratio: 0.0 }
            }
        }
    }
    fn accept(&self, st: &mut State) {
        if let Some(y) = st.y.take() {
            st.x = y;
        }
    }
    fn reject(&self, st: &mut State) {
        st.y = None;
    }
    /// b by one bidirectional sample (a film position anywhere on the image), every strategy
    /// counted: far less noisy than the independent paths' weights where light comes through
    /// narrow openings.
    fn estimate_b(&self, rng: Pcg32) -> Option<f64> {
        let scene = self.space.scene;
        let cam = &scene.camera;
        let mut sampler = RngSampler(rng);
        let u = sampler.next_2d();
        let raster = Vec2::new(u.x * cam.width as f32, u.y * cam.height as f32);
        let lens = sampler.next_2d();
        let ray = cam.generate_ray(raster, lens, sampler.next_1d());
        let (mut camera, mut light) = (Vec::new(), Vec::new());
        camera_subpath(scene, &self.cfg, &ray, raster, &mut sampler, &mut camera);
        light_subpath(scene, &self.cfg, ray.time, &mut sampler, &mut light);
        let mut sum = 0.0f64;
        for t in 1..=camera.len() {
            for s in 0..=light.len() {
                if s + t < 2 || !self.cfg.allows(s + t) {
                    continue;
                }
                let Some(c) = connect(scene, &self.cfg, &light, &camera, s, t, &mut sampler, true) else { continue };
                sum += (c.l * c.weight).luminance() as f64;
            }
        }
        Some(if sum.is_finite() { sum } else { 0.0 })
    }
}

/// A sampler over one random stream (for the estimate of b).
struct RngSampler(Pcg32);

impl Sampler for RngSampler {
    fn start_pixel_sample(&mut self, _x: u32, _y: u32, _index: u32) {}
    fn next_1d(&mut self) -> f32 {
        self.0.next_f32()
    }
    fn samples_per_pixel(&self) -> u32 {
        1
    }
    fn clone_box(&self) -> Box<dyn Sampler> {
        Box::new(RngSampler(self.0.clone()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse_and_reject_bad_input() {
        let o = MltOptions::parse("bidir=1,lens=0,caustic=2,multi=0.5,chains=4,bootstrap=10").unwrap();
        assert_eq!((o.weights, o.chain.chains, o.chain.bootstrap), ([1.0, 0.0, 2.0, 0.5], 4, 10));
        for bad in ["bidir=0", "lens=-1", "caustic=nan", "multi=x", "chains=x", "complement-spp=1", "lens"] {
            assert!(MltOptions::parse(bad).is_err(), "{bad} accepted");
        }
        assert!(crate::methods::by_name("mlt:lens=x").is_err());
    }

    #[test]
    fn transition_choice_probabilities_are_normalised() {
        use super::mutations::{n_pos, pd};
        for k in 1..8 {
            let s: f64 = (1..=k + 1).map(|kd| pd(kd, k)).sum();
            assert!((s - 1.0).abs() < 1e-12);
            for kd in 1..=k + 1 {
                assert!(n_pos(kd, k) >= 1);
            }
        }
    }
}
