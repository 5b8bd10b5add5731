//! Random numbers for estimators: samplers, discrete and 2-D distributions, MIS heuristics.

pub mod distribution;
pub mod rng;
pub mod sampler;
pub mod sobol;
pub mod stats;

pub use distribution::{Distribution1D, Distribution2D};
pub use rng::Pcg32;
pub use sampler::{IndependentSampler, Sampler, SamplerKind};
pub use sobol::SobolSampler;

/// Power heuristic with beta = 2 (Veach), for `nf` samples of pdf `f` against `ng` of pdf `g`.
#[inline]
pub fn power_heuristic(nf: f32, f_pdf: f32, ng: f32, g_pdf: f32) -> f32 {
    let f = nf * f_pdf;
    let g = ng * g_pdf;
    if f.is_infinite() {
        return 1.0;
    }
    let (f2, g2) = (f * f, g * g);
    if f2 + g2 == 0.0 {
        0.0
    } else {
        f2 / (f2 + g2)
    }
}

/// Balance heuristic.
#[inline]
pub fn balance_heuristic(nf: f32, f_pdf: f32, ng: f32, g_pdf: f32) -> f32 {
    let (f, g) = (nf * f_pdf, ng * g_pdf);
    if f + g == 0.0 {
        0.0
    } else {
        f / (f + g)
    }
}
