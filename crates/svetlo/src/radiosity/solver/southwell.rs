//! Southwell relaxation: keep the residual r = E + ρ F B − B of every element, and relax the
//! element with the largest residual power A_i |r_i| each step; its change reaches the others'
//! residuals through column i of ρF (taken from the transposed matrix, so no reciprocity is
//! assumed). Progressive refinement is the same algorithm with the column obtained from row i
//! by reciprocity. One reported step = n relaxations (one sweep's worth).

use super::{l1d, to_d, to_rgb, Recorder, Solution, SolveOptions, System};
use crate::error::Result;
use glam::DVec3;

pub fn solve(sys: &System, opts: &SolveOptions) -> Result<Solution> {
    let m = sys.rows.matrix()?;
    let t = m.transpose();
    let n = sys.n();
    let mut rec = Recorder::new();
    let mut b = vec![DVec3::ZERO; n];
    let mut r: Vec<DVec3> = sys.emission.iter().map(|e| to_d(*e)).collect();
    let mut power: Vec<f64> = (0..n).map(|i| sys.area[i] as f64 * l1d(r[i])).collect();
    let mut total: f64 = power.iter().sum();
    let norm = sys.emitted_power();
    let mut converged = false;
    let w = opts.omega;
    for s in 1..=opts.max_steps.saturating_mul(n.max(1)) {
        let Some((i, _)) = power.iter().enumerate().max_by(|a, c| a.1.total_cmp(c.1)) else { break };
        let ri = r[i] * w as f64;
        b[i] += ri;
        r[i] -= ri;
        let (cols, vals) = t.row(i);
        for (j, f) in cols.iter().zip(vals) {
            let j = *j as usize;
            r[j] += to_d(sys.reflectance[j]) * ri * *f as f64;
            power[j] = sys.area[j] as f64 * l1d(r[j]);
        }
        power[i] = sys.area[i] as f64 * l1d(r[i]);
        if s % n.max(1) == 0 {
            // Recompute the running total exactly once per sweep to shed rounding drift.
            total = power.iter().sum();
            let res = total / norm;
            rec.record(s / n.max(1), res, (s / n.max(1) * n) as u64);
            if res < opts.tolerance {
                converged = true;
                break;
            }
        }
    }
    let _ = total;
    let b: Vec<_> = b.iter().map(|x| to_rgb(*x)).collect();
    if !converged {
        converged = sys.residual(m, &b) < opts.tolerance;
    }
    Ok(Solution { b, history: rec.history, converged })
}
