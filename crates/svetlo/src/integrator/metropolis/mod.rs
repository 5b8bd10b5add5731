//! The Metropolis machinery shared by primary-sample MLT (Kelemen) and path-space MLT (Veach).
//!
//! A [`MetropolisTarget`] knows how to draw independent seed samples, and how to propose,
//! accept and reject mutations of a chain's state. The driver [`run`] does the rest:
//!
//! - **Bootstrap**: `bootstrap` independent samples estimate the normalisation
//!   b = ∫ f (f = luminance of the path's contribution). Each sample may offer several
//!   candidate start states with weights w (unbiased estimates of f/p); b = mean of Σ w.
//! - **Starts**: each chain starts at a candidate chosen with probability ∝ w, which is
//!   distributed as f/b when the bootstrap is large (sampling-importance-resampling): no
//!   start-up bias to burn in. The candidate is rebuilt by replaying its seed's random stream.
//! - **Chains**: a fixed number of independent chains, each with its own random streams, run
//!   in rounds over threads; their splats are merged in chain order, so the image depends on
//!   the seed and not on the thread count.
//! - **Expected values**: each mutation deposits the current state with weight (1 − a) and
//!   the proposal with weight a, each as b · L / f (Veach's and Kelemen's estimator).
//!
//! Film normalisation: the pixel value is (npix / N) Σ b · L / f over the N mutations, i.e.
//! splats divided by the mutations per pixel (`--spp`).

pub mod pss;

use super::{Progress, RenderSettings};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::lpe::aov::{LayerSample, BEAUTY};
use crate::lpe::{AovSet, LayerMask};
use crate::sampling::rng::hash_seed;
use crate::sampling::Pcg32;
use crate::spectrum::Rgb;
use glam::Vec2;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// What one state deposits on the film: radiance estimates at raster positions, each with
/// the layers it goes to ([`LayerMask`]: the beauty, AOVs) and whether it counts toward
/// the target f ([`TARGET`]). The target is the whole (unrestricted) beauty whatever the
/// AOVs and `--lpe`: the chains sample all paths, the layers only sort their deposits.
#[derive(Clone, Debug, Default)]
pub struct Contribution {
    pub splats: Vec<(Vec2, Rgb, LayerMask)>,
}

/// One deposit: raster position, radiance, layers.
type Deposit = (Vec2, Rgb, LayerMask);

/// Mask bit of a deposit that counts toward the chain's target f.
pub const TARGET: LayerMask = 1 << 30;
const AOV_BITS: LayerMask = (1 << crate::lpe::MAX_LAYERS) - 1;

impl Contribution {
    pub fn clear(&mut self) {
        self.splats.clear();
    }
    /// Radiance for the beauty that also counts toward f.
    pub fn push(&mut self, raster: Vec2, l: Rgb) {
        self.push_masked(raster, l, BEAUTY | TARGET);
    }
    pub fn push_masked(&mut self, raster: Vec2, l: Rgb, mask: LayerMask) {
        if l.is_finite() && !l.is_black() && mask != 0 {
            self.splats.push((raster, l, mask));
        }
    }
    /// A camera sample's value `l` (all of it counts toward f) whose parts per layer are in
    /// `layers`.
    pub fn push_layers(&mut self, aovs: &AovSet, raster: Vec2, l: Rgb, layers: &LayerSample) {
        if aovs.is_empty() {
            return self.push(raster, l);
        }
        if aovs.restricts_beauty() {
            self.push_masked(raster, l, TARGET);
            self.push_masked(raster, layers.beauty, BEAUTY);
        } else {
            self.push(raster, l);
        }
        for (i, v) in layers.aov[..aovs.aov_count()].iter().enumerate() {
            self.push_masked(raster, *v, 1 << i);
        }
    }
    /// The scalar the chain is distributed by: total luminance (non-negative, finite).
    pub fn f(&self) -> f32 {
        let f: f32 = self.splats.iter().filter(|s| s.2 & TARGET != 0).map(|(_, l, _)| l.luminance().max(0.0)).sum();
        if f.is_finite() {
            f
        } else {
            0.0
        }
    }
}

/// A proposed mutation: which kind, and the ratio T(y→x) / T(x→y) of its transition densities
/// (1 for symmetric proposals; 0 rejects).
#[derive(Clone, Copy, Debug)]
pub struct Proposal {
    pub kind: usize,
    pub t_ratio: f64,
}

/// A state space with its mutations.
pub trait MetropolisTarget: Sync {
    type State: Send;
    /// Names of the mutation kinds `Proposal::kind` indexes.
    fn mutation_names(&self) -> Vec<&'static str>;
    /// One independent seed sample drawn with `rng`: push the weight (f/p) of each candidate
    /// start state it offers.
    fn bootstrap(&self, rng: Pcg32, weights: &mut Vec<f32>);
    /// Replay the seed sample of `rng`, start a chain at its candidate `candidate`, continuing
    /// with `chain_rng`; fill `out` with that state's contribution.
    fn start(&self, rng: Pcg32, candidate: usize, chain_rng: Pcg32, out: &mut Contribution) -> Option<Self::State>;
    /// Propose a mutation of the current state and fill `out` with the proposal's contribution.
    fn propose(&self, state: &mut Self::State, out: &mut Contribution) -> Proposal;
    fn accept(&self, state: &mut Self::State);
    fn reject(&self, state: &mut Self::State);
    /// An unbiased estimate of b from one independent sample drawn with `rng`, for a target
    /// with a better estimator of b than its bootstrap weights (Veach MLT: bidirectional
    /// path tracing); None: b comes from the bootstrap weights.
    fn estimate_b(&self, _rng: Pcg32) -> Option<f64> {
        None
    }
}

/// Settings of the driver.
#[derive(Clone, Debug)]
pub struct ChainSettings {
    pub chains: usize,
    pub bootstrap: usize,
}

impl Default for ChainSettings {
    fn default() -> Self {
        ChainSettings { chains: 256, bootstrap: 100_000 }
    }
}

impl ChainSettings {
    pub fn validate(&self) -> Result<()> {
        if self.chains == 0 || self.chains > 1 << 20 {
            return Err(Error::Settings(format!("chains must be in 1..=1048576, got {}", self.chains)));
        }
        if self.bootstrap == 0 || self.bootstrap > 1 << 28 {
            return Err(Error::Settings(format!("bootstrap must be in 1..=268435456, got {}", self.bootstrap)));
        }
        Ok(())
    }
}

/// The statistics of an integrator's last render, kept for its report.
#[derive(Debug, Default)]
pub struct LastStats(std::sync::Mutex<Option<ChainStats>>);

impl LastStats {
    /// Keep the statistics of a render and pass its film on.
    pub fn keep(&self, (film, stats): (Film, ChainStats)) -> Film {
        if let Ok(mut l) = self.0.lock() {
            *l = Some(stats);
        }
        film
    }
    /// The acceptance table of the last render kept, if any.
    pub fn report(&self) -> Option<String> {
        self.0.lock().ok()?.as_ref().map(|s| s.report())
    }
}

/// Acceptance statistics and the normalisation of a Metropolis render.
#[derive(Clone, Debug, Default)]
pub struct ChainStats {
    pub names: Vec<&'static str>,
    pub proposed: Vec<u64>,
    pub accepted: Vec<u64>,
    /// Sum of acceptance probabilities a, per kind.
    pub acceptance_sum: Vec<f64>,
    /// Estimated b = ∫ f and its standard error.
    pub b: f64,
    pub b_stderr: f64,
    pub bootstrap: usize,
    /// Bootstrap samples with a non-zero contribution.
    pub bootstrap_nonzero: usize,
    pub chains: usize,
    pub mutations: u64,
    /// Per chain: the sum of everything it splatted and its number of mutations (the spread
    /// of chain means gives the image mean's standard error, chains being independent).
    pub chain_sums: Vec<[f64; 3]>,
    pub chain_mutations: Vec<u64>,
}

impl ChainStats {
    fn new(names: Vec<&'static str>) -> Self {
        let n = names.len();
        ChainStats { names, proposed: vec![0; n], accepted: vec![0; n], acceptance_sum: vec![0.0; n], ..Default::default() }
    }
    fn merge(&mut self, o: &ChainStats) {
        for k in 0..self.names.len() {
            self.proposed[k] += o.proposed[k];
            self.accepted[k] += o.accepted[k];
            self.acceptance_sum[k] += o.acceptance_sum[k];
        }
        self.mutations += o.mutations;
    }
    /// Fraction of proposals of kind `k` accepted.
    pub fn acceptance_rate(&self, k: usize) -> f64 {
        if self.proposed[k] == 0 {
            0.0
        } else {
            self.accepted[k] as f64 / self.proposed[k] as f64
        }
    }
    /// The image's mean per channel (the splats per mutation) and its standard error, from the
    /// spread between chains and the bootstrap's error in b.
    pub fn image_mean(&self) -> Option<([f64; 3], [f64; 3])> {
        let used: Vec<usize> = (0..self.chain_mutations.len()).filter(|&c| self.chain_mutations[c] > 0).collect();
        let n = used.len();
        if n < 2 || self.b <= 0.0 {
            return None;
        }
        let total: u64 = used.iter().map(|&c| self.chain_mutations[c]).sum();
        let mut mean = [0.0; 3];
        let mut se = [0.0; 3];
        let rb = self.b_stderr / self.b;
        for k in 0..3 {
            // Per-mutation means of each chain, weighted by its length.
            let m: f64 = used.iter().map(|&c| self.chain_sums[c][k]).sum::<f64>() / total as f64;
            let var: f64 = used
                .iter()
                .map(|&c| {
                    let mc = self.chain_sums[c][k] / self.chain_mutations[c] as f64;
                    (mc - m) * (mc - m)
                })
                .sum::<f64>()
                / (n - 1) as f64;
            mean[k] = m;
            let rel_chain = (var / n as f64).sqrt() / m.abs().max(f64::MIN_POSITIVE);
            se[k] = m.abs() * (rel_chain * rel_chain + rb * rb).sqrt();
        }
        Some((mean, se))
    }

    /// A short table for people.
    pub fn report(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "b           {:.6e} ± {:.2e} ({} bootstrap samples, {} non-zero)", self.b, self.b_stderr, self.bootstrap, self.bootstrap_nonzero);
        let _ = writeln!(s, "chains      {}, {} mutations", self.chains, self.mutations);
        let _ = writeln!(s, "mutation        proposed   accepted   mean a");
        for k in 0..self.names.len() {
            let mean_a = if self.proposed[k] == 0 { 0.0 } else { self.acceptance_sum[k] / self.proposed[k] as f64 };
            let _ = writeln!(s, "{:<14} {:>9} {:>9.2} % {:>8.3}", self.names[k], self.proposed[k], 100.0 * self.acceptance_rate(k), mean_a);
        }
        s
    }
}

/// Mutations per chain per round: rounds bound the memory of splat lists and let a time limit
/// or a cancellation stop the render.
const ROUND: u64 = 1024;

fn boot_rng(seed: u64, i: usize) -> Pcg32 {
    Pcg32::new(hash_seed(&[seed, 0x626f_6f74, i as u64]), 0)
}

fn b_rng(seed: u64, i: usize) -> Pcg32 {
    Pcg32::new(hash_seed(&[seed, 0x6e6f_726d, i as u64]), 0)
}

fn chain_rng(seed: u64, c: usize, stream: u64) -> Pcg32 {
    Pcg32::new(hash_seed(&[seed, 0x6368_6169, c as u64]), stream)
}

struct Chain<S> {
    state: S,
    current: Contribution,
    f: f32,
    /// Decides acceptance, independently of the target's own streams.
    rng: Pcg32,
    left: u64,
}

/// What a Metropolis integrator is asked for: the bootstrap alone, or chain blocks (with
/// `settings.pass_range`, else all) from a bootstrap given or computed.
pub enum Job<'a> {
    Bootstrap,
    Blocks(Option<&'a Bootstrap>),
}

/// What a [`Job`] makes: the bootstrap, or a film with its statistics and mutations done.
pub enum JobOutput {
    Bootstrap(Bootstrap),
    Film(Box<Film>, ChainStats, u64),
}

/// Do `job` for `target`.
pub fn job<T: MetropolisTarget>(
    target: &T,
    width: u32,
    height: u32,
    settings: &RenderSettings,
    cfg: &ChainSettings,
    job: Job,
    progress: &Progress,
) -> Result<JobOutput> {
    Ok(match job {
        Job::Bootstrap => JobOutput::Bootstrap(bootstrap(target, settings, cfg)?),
        Job::Blocks(boot) => {
            let (film, stats, done) = run_blocks(target, width, height, settings, cfg, boot, progress)?;
            JobOutput::Film(Box::new(film), stats, done)
        }
    })
}

/// [`Job`] for a scene without emitters: a zero bootstrap, or the black film (whose spp the
/// block range that starts at 0 carries, so that merged ranges count it once).
pub fn black_job(width: u32, height: u32, settings: &RenderSettings, cfg: &ChainSettings, job: Job) -> Result<JobOutput> {
    cfg.validate()?;
    Ok(match job {
        Job::Bootstrap => {
            JobOutput::Bootstrap(Bootstrap { b: 0.0, b_stderr: 0.0, nonzero: 0, sum: 0.0, cdf: Vec::new(), seed: settings.seed, samples: cfg.bootstrap })
        }
        Job::Blocks(_) => {
            let (mut film, stats) = black(width, height, settings)?;
            if settings.pass_range.as_ref().is_some_and(|r| r.start > 0) {
                film.spp_done = 0;
            }
            JobOutput::Film(Box::new(film), stats, 0)
        }
    })
}

/// The render of a scene without emitters: black, exactly (the bootstrap would have nothing
/// to find), with all samples counted as done.
pub fn black(width: u32, height: u32, settings: &RenderSettings) -> Result<(Film, ChainStats)> {
    settings.validate()?;
    let mut film = Film::with_layers(width, height, settings.filter, settings.aovs().names());
    film.spp_done = settings.spp;
    Ok((film, ChainStats::default()))
}

/// Chains per block. An untimed render adds each block's splats into a film of its own and
/// sums the blocks' films by the pass tree over block indices (`passes`): a range of blocks
/// (a node of that tree) can then run on another machine, and the nodes' films combine into
/// the local render's film bit for bit (`film::raw::PartialFilm::merge`).
pub const CHAINS_PER_BLOCK: usize = 16;

/// The blocks of `chains` chains.
pub fn chain_blocks(chains: usize) -> u32 {
    chains.div_ceil(CHAINS_PER_BLOCK) as u32
}

/// What the bootstrap leaves for the chains: the normalisation b and the candidates' CDF.
/// Computed once and shared by every block (also on other machines, through
/// [`Bootstrap::to_bytes`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Bootstrap {
    pub b: f64,
    pub b_stderr: f64,
    pub nonzero: usize,
    /// Sum of every candidate's weight.
    sum: f64,
    /// (running sum of weights, seed sample, candidate), in seed-sample order.
    cdf: Vec<(f64, u32, u32)>,
    /// The seed and bootstrap size it was drawn with (checked when it is used).
    seed: u64,
    samples: usize,
}

const BOOT_MAGIC: &[u8; 8] = b"SVLBOOT1";

impl Bootstrap {
    /// Little-endian bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(64 + 16 * self.cdf.len());
        out.extend_from_slice(BOOT_MAGIC);
        for v in [self.b, self.b_stderr, self.sum] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in [self.nonzero as u64, self.seed, self.samples as u64, self.cdf.len() as u64] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for &(c, i, k) in &self.cdf {
            out.extend_from_slice(&c.to_le_bytes());
            out.extend_from_slice(&i.to_le_bytes());
            out.extend_from_slice(&k.to_le_bytes());
        }
        out
    }

    /// Read [`Self::to_bytes`]'s output; a malformed buffer is an error.
    pub fn from_bytes(b: &[u8]) -> Result<Bootstrap> {
        let bad = |m: String| Error::Invalid(format!("bootstrap: {m}"));
        if b.len() < 64 || &b[..8] != BOOT_MAGIC {
            return Err(bad("not a svetlo bootstrap (bad magic or short)".into()));
        }
        let f = |at: usize| f64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"));
        let u = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"));
        let (bb, se, sum) = (f(8), f(16), f(24));
        let (nonzero, seed, samples, n) = (u(32), u(40), u(48), u(56));
        if n.checked_mul(16).and_then(|x| x.checked_add(64)) != Some(b.len() as u64) {
            return Err(bad(format!("{n} entries need {} bytes, got {}", n.saturating_mul(16).saturating_add(64), b.len())));
        }
        let mut cdf = Vec::with_capacity(n as usize);
        let mut last = 0.0;
        for e in b[64..].chunks_exact(16) {
            let c = f64::from_le_bytes(e[..8].try_into().expect("8 bytes"));
            let i = u32::from_le_bytes(e[8..12].try_into().expect("4 bytes"));
            let k = u32::from_le_bytes(e[12..].try_into().expect("4 bytes"));
            if !(c.is_finite() && c >= last) || i as u64 >= samples {
                return Err(bad(format!("entry {} is out of order or range", cdf.len())));
            }
            last = c;
            cdf.push((c, i, k));
        }
        if !(bb.is_finite() && se.is_finite() && sum.is_finite() && bb >= 0.0 && sum >= last) || (bb > 0.0 && cdf.is_empty()) {
            return Err(bad("bad normalisation".into()));
        }
        Ok(Bootstrap { b: bb, b_stderr: se, nonzero: nonzero as usize, sum, cdf, seed, samples: samples as usize })
    }
}

fn thread_pool(settings: &RenderSettings) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| Error::Settings(format!("thread pool: {e}")))
}

/// The bootstrap of a render: `cfg.bootstrap` independent seed samples, in index order.
pub fn bootstrap<T: MetropolisTarget>(target: &T, settings: &RenderSettings, cfg: &ChainSettings) -> Result<Bootstrap> {
    cfg.validate()?;
    let pool = thread_pool(settings)?;
    let seed = settings.seed;
    // Candidate weights of every seed sample, in index order.
    let boot: Vec<Vec<f32>> = pool.install(|| {
        (0..cfg.bootstrap)
            .into_par_iter()
            .map(|i| {
                let mut wts = Vec::new();
                target.bootstrap(boot_rng(seed, i), &mut wts);
                wts
            })
            .collect()
    });
    let mut out = Bootstrap { b: 0.0, b_stderr: 0.0, nonzero: 0, sum: 0.0, cdf: Vec::new(), seed, samples: cfg.bootstrap };
    let (mut sum, mut sum2) = (0.0f64, 0.0f64);
    for (i, wts) in boot.iter().enumerate() {
        let mut si = 0.0f64;
        for (k, &wt) in wts.iter().enumerate() {
            if wt > 0.0 && wt.is_finite() {
                si += wt as f64;
                out.cdf.push((sum + si, i as u32, k as u32));
            }
        }
        if si > 0.0 {
            out.nonzero += 1;
        }
        sum += si;
        sum2 += si * si;
    }
    drop(boot);
    let nb = cfg.bootstrap as f64;
    out.sum = sum;
    out.b = sum / nb;
    out.b_stderr = ((sum2 / nb - out.b * out.b).max(0.0) / nb).sqrt();
    if sum > 0.0 && target.estimate_b(b_rng(seed, 0)).is_some() {
        let est: Vec<f64> = pool.install(|| (0..cfg.bootstrap).into_par_iter().map(|i| target.estimate_b(b_rng(seed, i)).unwrap_or(0.0)).collect());
        let (s1, s2) = est.iter().fold((0.0, 0.0), |(a, b), &x| (a + x, b + x * x));
        out.b = s1 / nb;
        out.b_stderr = ((s2 / nb - out.b * out.b).max(0.0) / nb).sqrt();
    }
    Ok(out)
}

/// Render `target` on a `width` x `height` film by Metropolis sampling: `settings.spp`
/// mutations per pixel (or until the time limit), `cfg.chains` chains.
pub fn run<T: MetropolisTarget>(
    target: &T,
    width: u32,
    height: u32,
    settings: &RenderSettings,
    cfg: &ChainSettings,
    progress: &Progress,
) -> Result<(Film, ChainStats)> {
    let (film, stats, _) = run_blocks(target, width, height, settings, cfg, None, progress)?;
    Ok((film, stats))
}

/// [`run`] with the bootstrap given (None: computed here) and, with `settings.pass_range`,
/// only those chain blocks (a node of the tree over [`chain_blocks`]): their film's raw sums.
/// Also returns the mutations done, which normalise the splats of the whole render.
pub fn run_blocks<T: MetropolisTarget>(
    target: &T,
    width: u32,
    height: u32,
    settings: &RenderSettings,
    cfg: &ChainSettings,
    boot: Option<&Bootstrap>,
    progress: &Progress,
) -> Result<(Film, ChainStats, u64)> {
    settings.validate()?;
    cfg.validate()?;
    let start = Instant::now();
    let (w, h) = (width, height);
    let npix = w as u64 * h as u64;
    let blocks_total = chain_blocks(cfg.chains);
    let blocks = settings.pass_range.clone().unwrap_or(0..blocks_total);
    if !crate::integrator::passes::is_node(&blocks, blocks_total) {
        return Err(Error::Settings(format!("chain blocks {}..{} are not a node of the tree over {blocks_total} blocks", blocks.start, blocks.end)));
    }
    if settings.pass_range.is_some() && settings.time_limit.is_some() {
        return Err(Error::Settings("a range of chain blocks needs a render without a time limit".into()));
    }
    let empty = || Film::with_layers(w, h, settings.filter, settings.aovs().names());
    let mut stats = ChainStats::new(target.mutation_names());
    stats.bootstrap = cfg.bootstrap;
    stats.chains = cfg.chains;
    stats.chain_sums = vec![[0.0; 3]; cfg.chains];
    stats.chain_mutations = vec![0; cfg.chains];
    let total = settings.spp as u64 * npix;
    let chain_range = blocks.start as usize * CHAINS_PER_BLOCK..(blocks.end as usize * CHAINS_PER_BLOCK).min(cfg.chains);
    let per_chain = total / cfg.chains as u64;
    let extra = total % cfg.chains as u64;
    let share = |c: usize| per_chain + u64::from((c as u64) < extra);
    progress.total.store(chain_range.clone().map(share).sum(), Ordering::Relaxed);
    let pool = thread_pool(settings)?;
    let seed = settings.seed;

    let computed;
    let boot = match boot {
        Some(b) => {
            if (b.seed, b.samples) != (seed, cfg.bootstrap) {
                return Err(Error::Settings(format!(
                    "the bootstrap given was drawn with seed {} and {} samples, the render has seed {seed} and {}",
                    b.seed, b.samples, cfg.bootstrap
                )));
            }
            b
        }
        None => {
            computed = bootstrap(target, settings, cfg)?;
            &computed
        }
    };
    stats.b = boot.b;
    stats.b_stderr = boot.b_stderr;
    stats.bootstrap_nonzero = boot.nonzero;
    if boot.b <= 0.0 || progress.cancelled() {
        // Nothing reaches the camera: the black image is the answer.
        let mut film = empty();
        film.spp_done = if blocks.start == 0 { settings.spp } else { 0 };
        return Ok((film, stats, 0));
    }
    let b = boot.b as f32;
    let names = target.mutation_names();

    // Blocks run in groups that keep the threads busy; a timed render runs every chain at
    // once into one film (it cannot be split, and must stop at the limit with all chains).
    let timed = settings.time_limit.is_some();
    let group = if timed { blocks.len() } else { (2 * pool.current_num_threads()).div_ceil(CHAINS_PER_BLOCK).max(1) };
    let mut tree: crate::integrator::passes::TreeSum<Film> = Default::default();
    let add = |a: &mut Film, b: Film| a.add(&b);
    // Block films folded into the tree, reused for later groups (no fresh pages per group).
    let mut spare: Vec<Film> = Vec::new();
    let mut done = 0u64;
    let mut timed_film = empty();
    let mut g0 = blocks.start;
    while g0 < blocks.end {
        let g1 = (g0 + group as u32).min(blocks.end);
        let c0 = g0 as usize * CHAINS_PER_BLOCK;
        let c1 = (g1 as usize * CHAINS_PER_BLOCK).min(cfg.chains);
        let mut films: Vec<Film> = if timed {
            Vec::new()
        } else {
            (g0..g1)
                .map(|_| match spare.pop() {
                    Some(mut f) => {
                        f.clear();
                        f
                    }
                    None => empty(),
                })
                .collect()
        };
        // Chain starts, in proportion to the bootstrap weights.
        let mut chains: Vec<Option<Chain<T::State>>> = pool.install(|| {
            (c0..c1)
                .into_par_iter()
                .map(|c| {
                    let mut pick = chain_rng(seed, c, 0);
                    let u = pick.next_f64() * boot.sum;
                    let j = boot.cdf.partition_point(|e| e.0 <= u).min(boot.cdf.len() - 1);
                    let (_, i, k) = boot.cdf[j];
                    let mut current = Contribution::default();
                    let state = target.start(boot_rng(seed, i as usize), k as usize, chain_rng(seed, c, 1), &mut current)?;
                    let f = current.f();
                    (f > 0.0).then(|| Chain { state, current, f, rng: chain_rng(seed, c, 2), left: share(c) })
                })
                .collect()
        });
        // Fixed rounds keep the image independent of timing; under a time limit rounds start
        // small and grow to fill about a quarter of the time left.
        let mut round = if timed { 16 } else { ROUND };
        loop {
            if progress.cancelled() || settings.time_limit.is_some_and(|t| start.elapsed() >= t) {
                break;
            }
            if chains.iter().all(|c| c.as_ref().is_none_or(|c| c.left == 0)) {
                break;
            }
            let results: Vec<(Vec<Deposit>, ChainStats)> =
                pool.install(|| chains.par_iter_mut().with_max_len(1).map(|slot| advance(target, slot, round, b, &names)).collect());
            for (ci, (splats, st)) in results.iter().enumerate() {
                let c = c0 + ci;
                let film = if timed { &mut timed_film } else { &mut films[(c / CHAINS_PER_BLOCK) - g0 as usize] };
                let mut cs = [0.0f64; 3];
                for &(r, l, m) in splats {
                    if m & BEAUTY != 0 {
                        film.splat(r, l);
                        for (k, v) in cs.iter_mut().enumerate() {
                            *v += l[k] as f64;
                        }
                    }
                    film.splat_layers(m & AOV_BITS, r, l);
                }
                for (k, v) in cs.iter().enumerate() {
                    stats.chain_sums[c][k] += v;
                }
                stats.chain_mutations[c] += st.mutations;
                stats.merge(st);
                done += st.mutations;
            }
            progress.done.store(done, Ordering::Relaxed);
            let spp_so_far = ((done as f64 / npix as f64).round() as u32).max(1);
            if done > 0 && progress.wants_pass(spp_so_far) {
                let mut film = if timed { timed_film.clone() } else { tree.peek(|a: &mut Film, b: &Film| a.add(b)).unwrap_or_else(empty) };
                films.iter().for_each(|f| film.add(f));
                film.splat_scale = (done as f64 / npix as f64) as f32;
                film.spp_done = spp_so_far;
                progress.pass_done(&film);
            }
            if let Some(t) = settings.time_limit {
                let el = start.elapsed().as_secs_f64();
                let per = el / done.max(1) as f64;
                let left = (t.as_secs_f64() - el).max(0.0);
                round = ((0.25 * left / per / cfg.chains as f64) as u64).clamp(4, 4 * ROUND);
            }
        }
        for f in films {
            tree.push_recycling(f, |a, b| a.add(b), &mut spare);
        }
        g0 = g1;
    }
    let mut film = if timed { timed_film } else { tree.finish(add).unwrap_or_else(empty) };
    // Chains that could not start (f = 0 at a candidate, which a consistent target never
    // offers) leave their share of mutations undone; normalise by what was done.
    set_splat_norm(&mut film, done, npix);
    Ok((film, stats, done))
}

/// The normalisation of a Metropolis film by `done` mutations over `npix` pixels.
pub fn set_splat_norm(film: &mut Film, done: u64, npix: u64) {
    film.splat_scale = (done as f64 / npix as f64).max(f64::MIN_POSITIVE) as f32;
    film.spp_done = if done == 0 { 0 } else { ((done as f64 / npix as f64).round() as u32).max(1) };
}

/// Up to `round` mutations of one chain: its deposits (expected values) and statistics.
fn advance<T: MetropolisTarget>(target: &T, slot: &mut Option<Chain<T::State>>, round: u64, b: f32, names: &[&'static str]) -> (Vec<Deposit>, ChainStats) {
    let mut st = ChainStats::new(names.to_vec());
    let mut splats = Vec::new();
    let Some(ch) = slot.as_mut() else { return (splats, st) };
    let n = ch.left.min(round);
    let mut proposal = Contribution::default();
    for _ in 0..n {
        proposal.clear();
        let p = target.propose(&mut ch.state, &mut proposal);
        let fy = proposal.f();
        let a = if fy <= 0.0 || p.t_ratio.is_nan() || p.t_ratio <= 0.0 || !p.t_ratio.is_finite() {
            0.0
        } else {
            ((fy as f64 * p.t_ratio) / ch.f as f64).min(1.0) as f32
        };
        // Expected values: both states contribute, weighted by 1 - a and a.
        // (Deposits that only count toward f go nowhere on the film.)
        if a < 1.0 {
            let wx = (1.0 - a) * b / ch.f;
            splats.extend(ch.current.splats.iter().filter(|s| s.2 & !TARGET != 0).map(|&(r, l, m)| (r, l * wx, m)));
        }
        if a > 0.0 {
            let wy = a * b / fy;
            splats.extend(proposal.splats.iter().filter(|s| s.2 & !TARGET != 0).map(|&(r, l, m)| (r, l * wy, m)));
        }
        st.proposed[p.kind] += 1;
        st.acceptance_sum[p.kind] += a as f64;
        if ch.rng.next_f32() < a {
            st.accepted[p.kind] += 1;
            target.accept(&mut ch.state);
            std::mem::swap(&mut ch.current, &mut proposal);
            ch.f = fy;
        } else {
            target.reject(&mut ch.state);
        }
    }
    ch.left -= n;
    st.mutations = n;
    (splats, st)
}
