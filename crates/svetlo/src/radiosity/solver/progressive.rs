//! Progressive refinement (Cohen, Chen, Wallace & Greenberg 1988): shoot, don't gather.
//! Each step takes the element with the most unshot power A_i |ΔB_i|, computes its row of form
//! factors (only now, and once: the rows of elements that never shoot are never computed), and sends
//! ρ_j F_ji ΔB_i = ρ_j F_ij (A_i / A_j) ΔB_i to every element j it sees. The unshot radiosity
//! is the residual of the system (exactly, when F is reciprocal).
//!
//! For display before convergence, the ambient term estimates the light not yet shot as a
//! uniform radiosity: ambient = R Σ A_i ΔB_i / Σ A_i with R = 1 / (1 − ρ̄) (the sum of all
//! interreflections of the average reflectance), and element i shows B_i + ρ_i ambient.
//!
//! Over-relaxation shoots ω ΔB_i (ΔB_i becomes (1 − ω) ΔB_i, possibly negative: selection
//! uses |ΔB|). The adaptive choice shoots what the element has plus what it can expect to
//! receive later, estimated by the ambient term: ω_i = 1 + ρ_i ambient / ΔB_i (luminances),
//! clamped to [1, 1.9].

use super::{l1d, to_d, to_rgb, Recorder, Solution, SolveOptions, System};
use crate::error::Result;
use crate::spectrum::Rgb;
use glam::DVec3;

/// The running state, for intermediate images.
pub struct State<'s> {
    pub b: &'s [Rgb],
    pub unshot: &'s [Rgb],
    pub ambient: Rgb,
}

impl State<'_> {
    /// Radiosity for display: B plus the ambient term reflected by each element.
    pub fn display(&self, reflectance: &[Rgb]) -> Vec<Rgb> {
        self.b.iter().zip(reflectance).map(|(b, r)| *b + *r * self.ambient).collect()
    }
}

/// Average reflectance and the interreflection factor R = 1 / (1 − ρ̄) per channel.
fn interreflection(sys: &System) -> Rgb {
    let a: f64 = sys.area.iter().map(|&a| a as f64).sum();
    let mut rho = Rgb::BLACK;
    for (r, ar) in sys.reflectance.iter().zip(&sys.area) {
        rho += *r * (*ar / a as f32);
    }
    rho.map(|x| 1.0 / (1.0 - x.min(0.999)))
}

fn ambient(sys: &System, unshot: &[DVec3], r: Rgb, total_area: f32) -> Rgb {
    let mut s = DVec3::ZERO;
    for (u, a) in unshot.iter().zip(&sys.area) {
        s += *u * *a as f64;
    }
    r * to_rgb(s) * (1.0 / total_area)
}

/// Solve, calling `observe(shots, state)` after each reported step (every n/8 shots or so).
pub fn solve(sys: &System, opts: &SolveOptions, observe: &mut dyn FnMut(usize, &State)) -> Result<Solution> {
    let n = sys.n();
    let mut rec = Recorder::new();
    let mut b: Vec<DVec3> = sys.emission.iter().map(|e| to_d(*e)).collect();
    let mut unshot = b.clone();
    let mut power: Vec<f64> = (0..n).map(|i| sys.area[i] as f64 * l1d(unshot[i])).collect();
    let norm = sys.emitted_power();
    let total_area: f32 = sys.area.iter().sum();
    let rr = interreflection(sys);
    let report_every = (n / 8).max(1);
    let mut rows = 0u64;
    let mut cache: Vec<Option<Vec<(u32, f32)>>> = vec![None; n];
    let mut converged = false;
    for s in 1..=opts.max_steps {
        let Some((i, _)) = power.iter().enumerate().max_by(|a, c| a.1.total_cmp(c.1)) else { break };
        let du = unshot[i];
        let w = if opts.adaptive_omega {
            let amb = ambient(sys, &unshot, rr, total_area);
            let (d, extra) = (to_rgb(du).luminance(), (sys.reflectance[i] * amb).luminance());
            if d > 0.0 {
                (1.0 + extra / d).clamp(1.0, 1.9)
            } else {
                1.0
            }
        } else {
            opts.omega
        };
        let shot = du * w as f64;
        unshot[i] = du - shot;
        power[i] = sys.area[i] as f64 * l1d(unshot[i]);
        // Rows are kept once computed: an element shoots again as light comes back to it.
        if cache[i].is_none() {
            cache[i] = Some(sys.rows.row(i));
            rows += 1;
        }
        for &(j, f) in cache[i].as_deref().unwrap_or(&[]) {
            let j = j as usize;
            let d = to_d(sys.reflectance[j]) * shot * (f as f64 * sys.area[i] as f64 / sys.area[j] as f64);
            b[j] += d;
            unshot[j] += d;
            power[j] = sys.area[j] as f64 * l1d(unshot[j]);
        }
        if s % report_every == 0 || s == opts.max_steps {
            let res = power.iter().sum::<f64>() / norm;
            rec.record(s, res, rows);
            let amb = ambient(sys, &unshot, rr, total_area);
            let (bb, uu): (Vec<Rgb>, Vec<Rgb>) = (b.iter().map(|x| to_rgb(*x)).collect(), unshot.iter().map(|x| to_rgb(*x)).collect());
            observe(s, &State { b: &bb, unshot: &uu, ambient: amb });
            if res < opts.tolerance {
                converged = true;
                break;
            }
        }
    }
    Ok(Solution { b: b.iter().map(|x| to_rgb(*x)).collect(), history: rec.history, converged })
}
