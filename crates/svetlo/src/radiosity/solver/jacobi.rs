//! Jacobi iteration: B⁽ᵏ⁺¹⁾ = E + ρ F B⁽ᵏ⁾, all elements from the previous sweep. Starting
//! from B⁽⁰⁾ = E, sweep k holds exactly the light of paths with at most k bounces, which is
//! what a depth-limited display needs ([`bounces`]).

use super::{Recorder, Solution, SolveOptions, System};
use crate::error::Result;
use crate::spectrum::Rgb;
use rayon::prelude::*;

fn sweep(sys: &System, m: &super::FormFactors, b: &[Rgb]) -> Vec<Rgb> {
    (0..sys.n()).into_par_iter().map(|i| sys.emission[i] + sys.gather(m, b, i)).collect()
}

pub fn solve(sys: &System, opts: &SolveOptions) -> Result<Solution> {
    let m = sys.rows.matrix()?;
    let mut rec = Recorder::new();
    let mut b = sys.emission.clone();
    let mut converged = false;
    for k in 1..=opts.max_steps {
        b = sweep(sys, m, &b);
        let r = sys.residual(m, &b);
        rec.record(k, r, (k * sys.n()) as u64);
        if r < opts.tolerance {
            converged = true;
            break;
        }
    }
    Ok(Solution { b, history: rec.history, converged })
}

/// Radiosity with at most `k` diffuse bounces (k Jacobi sweeps from E).
pub fn bounces(sys: &System, k: usize) -> Result<Solution> {
    let m = sys.rows.matrix()?;
    let mut rec = Recorder::new();
    let mut b = sys.emission.clone();
    for s in 1..=k {
        b = sweep(sys, m, &b);
        rec.record(s, sys.residual(m, &b), (s * sys.n()) as u64);
    }
    Ok(Solution { b, history: rec.history, converged: true })
}
