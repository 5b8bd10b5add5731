//! Cohen's two-level substructuring (Cohen, Greenberg, Immel & Brock 1986): the system is solved
//! on the coarse patches, the fine elements only gather from them. Element-to-patch form factors
//! F_qP = Σ_{j∈P} F_qj are all that is kept (elements × patches, not elements²); the patch system
//! uses F_PQ = Σ_{q∈P} A_q F_qQ / A_P with area-averaged E and ρ, and then each element gathers
//! B_q = E_q + ρ_q Σ_P F_qP B_P. Exact when radiosity is uniform over each patch (the furnace);
//! otherwise it misses how light varies across the patches that reflect it (not across the
//! elements that receive it, which is what shows).

use super::{gauss_seidel, Recorder, Rows, Solution, SolveOptions, System};
use crate::error::{Error, Result};
use crate::radiosity::form_factor::{merge, FormFactors};
use crate::spectrum::Rgb;

pub fn solve(sys: &System, opts: &SolveOptions) -> Result<Solution> {
    let m = sys.rows.matrix()?;
    let n = sys.n();
    if sys.patch_of.len() != n {
        return Err(Error::Settings("radiosity: two-level substructuring needs the elements' patches".into()));
    }
    let np = sys.patch_of.iter().map(|&p| p as usize + 1).max().unwrap_or(0);
    // Element → patch form factors.
    let to_patch = FormFactors::from_rows(
        (0..n)
            .map(|q| {
                let (c, v) = m.row(q);
                merge(c.iter().zip(v).map(|(j, f)| (sys.patch_of[*j as usize], *f)).collect())
            })
            .collect(),
    );
    // Patch data, area-weighted.
    let mut area = vec![0.0f32; np];
    let mut e = vec![Rgb::BLACK; np];
    let mut rho = vec![Rgb::BLACK; np];
    let mut rows: Vec<Vec<(u32, f32)>> = vec![vec![]; np];
    for q in 0..n {
        let p = sys.patch_of[q] as usize;
        let a = sys.area[q];
        area[p] += a;
        e[p] += sys.emission[q] * a;
        rho[p] += sys.reflectance[q] * a;
        let (c, v) = to_patch.row(q);
        rows[p].extend(c.iter().zip(v).map(|(pp, f)| (*pp, f * a)));
    }
    let rows: Vec<Vec<(u32, f32)>> = rows.into_iter().enumerate().map(|(p, r)| merge(r).into_iter().map(|(pp, x)| (pp, x / area[p])).collect()).collect();
    for p in 0..np {
        if area[p] > 0.0 {
            e[p] *= 1.0 / area[p];
            rho[p] *= 1.0 / area[p];
        }
    }
    let fp = FormFactors::from_rows(rows);
    let patch_sys = System { emission: e, reflectance: rho, area, patch_of: vec![], rows: Rows::Matrix(&fp) };
    let patch_sol = gauss_seidel::solve(&patch_sys, opts)?;
    // Elements gather from the patches.
    let b: Vec<Rgb> = (0..n)
        .map(|q| {
            let (c, v) = to_patch.row(q);
            let mut s = Rgb::BLACK;
            for (p, f) in c.iter().zip(v) {
                s += patch_sol.b[*p as usize] * *f;
            }
            sys.emission[q] + sys.reflectance[q] * s
        })
        .collect();
    let mut rec = Recorder::new();
    for s in &patch_sol.history {
        rec.history.push(*s);
    }
    let r = sys.residual(m, &b);
    rec.record(patch_sol.history.len() + 1, r, n as u64);
    Ok(Solution { b, history: rec.history, converged: patch_sol.converged })
}
