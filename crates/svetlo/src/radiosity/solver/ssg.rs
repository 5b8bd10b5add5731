//! Super-Shoot-Gather: progressive refinement whose sources are groups, not elements. Each
//! step takes the patch (the group of elements cut from one input triangle) with the most
//! unshot power Σ_{i∈P} A_i |ΔB_i| and sends all of it at once (the "super shoot"); every
//! element j receives it by gathering with its own form factors to the group's elements,
//! ΔB_j += ρ_j Σ_{i∈P} F_ji ΔB_i (columns of the row-stored matrix, so no reciprocity is
//! assumed, unlike element shooting). Sources are few and large (one shot empties a whole
//! patch), receivers are fine: the patch/element split of two-level substructuring, used by a
//! shooting solver. One reported step = as many group shots as there are patches.

use super::{l1d, to_d, to_rgb, Recorder, Solution, SolveOptions, System};
use crate::error::{Error, Result};
use glam::DVec3;

pub fn solve(sys: &System, opts: &SolveOptions) -> Result<Solution> {
    let m = sys.rows.matrix()?;
    let n = sys.n();
    if sys.patch_of.len() != n {
        return Err(Error::Settings("radiosity: super-shoot-gather needs the elements' patches".into()));
    }
    let t = m.transpose();
    let np = sys.patch_of.iter().map(|&p| p as usize + 1).max().unwrap_or(0);
    let mut members: Vec<Vec<u32>> = vec![vec![]; np];
    for (i, &p) in sys.patch_of.iter().enumerate() {
        members[p as usize].push(i as u32);
    }
    let mut rec = Recorder::new();
    let mut b = vec![DVec3::ZERO; n];
    let mut unshot: Vec<DVec3> = sys.emission.iter().map(|e| to_d(*e)).collect();
    let mut power: Vec<f64> = (0..n).map(|i| sys.area[i] as f64 * l1d(unshot[i])).collect();
    let mut group = vec![0.0f64; np];
    for (i, &p) in sys.patch_of.iter().enumerate() {
        group[p as usize] += power[i];
    }
    let norm = sys.emitted_power();
    let w = opts.omega as f64;
    let mut converged = false;
    let mut shot = vec![];
    for s in 1..=opts.max_steps.saturating_mul(np.max(1)) {
        let Some((p, _)) = group.iter().enumerate().max_by(|a, c| a.1.total_cmp(c.1)) else { break };
        shot.clear();
        for &i in &members[p] {
            let i = i as usize;
            let d = unshot[i] * w;
            b[i] += d;
            unshot[i] -= d;
            shot.push((i, d));
        }
        for &(i, d) in &shot {
            let (cols, vals) = t.row(i);
            for (j, f) in cols.iter().zip(vals) {
                unshot[*j as usize] += to_d(sys.reflectance[*j as usize]) * d * *f as f64;
            }
        }
        // Refresh the powers of the shooters and of everything that received.
        for &(i, _) in &shot {
            let (cols, _) = t.row(i);
            for j in cols.iter().map(|j| *j as usize).chain(std::iter::once(i)) {
                let new = sys.area[j] as f64 * l1d(unshot[j]);
                group[sys.patch_of[j] as usize] += new - power[j];
                power[j] = new;
            }
        }
        if s % np.max(1) == 0 {
            // Exact totals once per reported step, shedding the running sums' rounding drift.
            group.iter_mut().for_each(|g| *g = 0.0);
            for (i, &q) in sys.patch_of.iter().enumerate() {
                group[q as usize] += power[i];
            }
            let res = power.iter().sum::<f64>() / norm;
            rec.record(s / np.max(1), res, (s / np.max(1) * n) as u64);
            if res < opts.tolerance {
                converged = true;
                break;
            }
        }
    }
    let b: Vec<_> = b.iter().map(|x| to_rgb(*x)).collect();
    if !converged {
        converged = sys.residual(m, &b) < opts.tolerance;
    }
    Ok(Solution { b, history: rec.history, converged })
}
