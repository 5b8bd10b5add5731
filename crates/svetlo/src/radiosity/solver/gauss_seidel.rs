//! Gauss-Seidel: one element at a time, each using the newest values of the others
//! (with ω ≠ 1, successive over-relaxation). The system matrix I − ρF is diagonally dominant
//! (row sums of ρF below 1), so the iteration converges for ω in (0, 1] and in practice a
//! little above.

use super::{Recorder, Solution, SolveOptions, System};
use crate::error::Result;

pub fn solve(sys: &System, opts: &SolveOptions) -> Result<Solution> {
    let m = sys.rows.matrix()?;
    let mut rec = Recorder::new();
    let mut b = sys.emission.clone();
    let mut converged = false;
    let w = opts.omega;
    for k in 1..=opts.max_steps {
        for i in 0..sys.n() {
            let new = sys.emission[i] + sys.gather(m, &b, i);
            b[i] = b[i] * (1.0 - w) + new * w;
        }
        let r = sys.residual(m, &b);
        rec.record(k, r, (k * sys.n()) as u64);
        if r < opts.tolerance {
            converged = true;
            break;
        }
    }
    Ok(Solution { b, history: rec.history, converged })
}
