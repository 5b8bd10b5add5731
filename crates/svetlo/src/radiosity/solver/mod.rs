//! Solvers of the radiosity system B = E + ρ ⊙ (F B), per RGB channel. Every solver reports the
//! same residual after each step: the power-weighted L1 norm of r = E + ρ F B − B relative to
//! the emitted power, Σ_i A_i |r_i| / Σ_i A_i |E_i| (channels summed). At a residual of 1e-2
//! the energy still missing or in excess is 1 % of what the lights emit.

pub mod gauss_seidel;
pub mod jacobi;
pub mod progressive;
pub mod southwell;
pub mod ssg;
pub mod two_level;

use super::form_factor::{FormFactors, RowSource};
use crate::error::{Error, Result};
use crate::spectrum::Rgb;
use std::time::Instant;

/// The linear system, element by element.
pub struct System<'a> {
    pub emission: Vec<Rgb>,
    pub reflectance: Vec<Rgb>,
    pub area: Vec<f32>,
    /// Patch of each element (two-level substructuring); may be empty for the other solvers.
    pub patch_of: Vec<u32>,
    /// The form factors, as a whole matrix or computed a row at a time.
    pub rows: Rows<'a>,
}

/// Where a solver gets rows of F.
pub enum Rows<'a> {
    Matrix(&'a FormFactors),
    OnDemand(&'a RowSource<'a>),
}

impl Rows<'_> {
    pub fn row(&self, i: usize) -> Vec<(u32, f32)> {
        match self {
            Rows::Matrix(m) => {
                let (c, v) = m.row(i);
                c.iter().copied().zip(v.iter().copied()).collect()
            }
            Rows::OnDemand(s) => s.row(i),
        }
    }
    pub fn matrix(&self) -> Result<&FormFactors> {
        match self {
            Rows::Matrix(m) => Ok(m),
            Rows::OnDemand(_) => Err(Error::Settings("radiosity: this solver needs the whole form-factor matrix".into())),
        }
    }
}

/// When to stop.
#[derive(Clone, Debug)]
pub struct SolveOptions {
    /// Relative residual to reach.
    pub tolerance: f64,
    /// Sweeps (Jacobi, Gauss-Seidel) or shots (Southwell, progressive) at most.
    pub max_steps: usize,
    /// Over-relaxation for Gauss-Seidel (SOR) and progressive shooting; 1 = none.
    pub omega: f32,
    /// Progressive only: choose ω per shot from the ambient estimate instead of `omega`.
    pub adaptive_omega: bool,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions { tolerance: 1e-3, max_steps: 1_000_000, omega: 1.0, adaptive_omega: false }
    }
}

impl SolveOptions {
    pub fn validate(&self) -> Result<()> {
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            return Err(Error::Settings(format!("radiosity: tolerance must be positive, got {}", self.tolerance)));
        }
        if !(self.omega > 0.0 && self.omega < 2.0) {
            return Err(Error::Settings(format!("radiosity: over-relaxation ω must be in (0, 2), got {}", self.omega)));
        }
        Ok(())
    }
}

/// One line of a convergence report.
#[derive(Clone, Copy, Debug)]
pub struct Step {
    /// Sweeps, or shots, so far.
    pub step: usize,
    pub residual: f64,
    pub seconds: f64,
    /// Form-factor rows used so far (progressive: the rows it had to compute).
    pub rows: u64,
}

#[derive(Clone, Debug)]
pub struct Solution {
    pub b: Vec<Rgb>,
    pub history: Vec<Step>,
    pub converged: bool,
}

impl System<'_> {
    pub fn n(&self) -> usize {
        self.emission.len()
    }

    /// Σ A_i |E_i| (the normaliser of the residual); 1 if nothing emits, to avoid 0/0.
    pub fn emitted_power(&self) -> f64 {
        let p: f64 = self.emission.iter().zip(&self.area).map(|(e, a)| *a as f64 * l1(*e)).sum();
        if p > 0.0 {
            p
        } else {
            1.0
        }
    }

    /// (ρ F B)_i: the radiosity element i reflects when the others have radiosity B.
    #[inline]
    pub fn gather(&self, m: &FormFactors, b: &[Rgb], i: usize) -> Rgb {
        let (c, v) = m.row(i);
        let mut s = Rgb::BLACK;
        for (j, f) in c.iter().zip(v) {
            s += b[*j as usize] * *f;
        }
        self.reflectance[i] * s
    }

    /// The relative residual of B against the whole matrix.
    pub fn residual(&self, m: &FormFactors, b: &[Rgb]) -> f64 {
        use rayon::prelude::*;
        let s: f64 = (0..self.n()).into_par_iter().map(|i| self.area[i] as f64 * l1(self.emission[i] + self.gather(m, b, i) - b[i])).sum();
        s / self.emitted_power()
    }
}

/// Accumulators in f64: shooting adds thousands of small increments to each element, and f32
/// sums would drift by ~1e-5 relative, above the tolerances the tests ask for.
#[inline]
pub(crate) fn to_d(c: Rgb) -> glam::DVec3 {
    glam::DVec3::new(c.r as f64, c.g as f64, c.b as f64)
}
#[inline]
pub(crate) fn to_rgb(c: glam::DVec3) -> Rgb {
    Rgb::new(c.x as f32, c.y as f32, c.z as f32)
}
#[inline]
pub(crate) fn l1d(c: glam::DVec3) -> f64 {
    c.x.abs() + c.y.abs() + c.z.abs()
}

#[inline]
pub(crate) fn l1(c: Rgb) -> f64 {
    c.r.abs() as f64 + c.g.abs() as f64 + c.b.abs() as f64
}

/// Timer and history shared by the solvers.
pub(crate) struct Recorder {
    start: Instant,
    pub history: Vec<Step>,
}

impl Recorder {
    pub fn new() -> Self {
        Recorder { start: Instant::now(), history: vec![] }
    }
    pub fn record(&mut self, step: usize, residual: f64, rows: u64) {
        self.history.push(Step { step, residual, seconds: self.start.elapsed().as_secs_f64(), rows });
    }
}

/// Which solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolverKind {
    /// The default: chosen per scene by [`crate::radiosity::RadiosityOptions::solver_for`]
    /// (hierarchical on large meshes, Gauss-Seidel on the full matrix otherwise).
    Auto,
    Jacobi,
    GaussSeidel,
    Southwell,
    Progressive,
    /// Cohen's two-level substructuring (system on patches, elements gather).
    TwoLevel,
    /// Super-Shoot-Gather: patches shoot their unshot power at once, elements gather it.
    Ssg,
    /// Hanrahan–Salzman–Aupperle: quadtrees and links instead of a matrix (`radiosity::hierarchical`).
    Hierarchical,
}

impl SolverKind {
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "auto" => Ok(SolverKind::Auto),
            "jacobi" => Ok(SolverKind::Jacobi),
            "gauss-seidel" | "gs" => Ok(SolverKind::GaussSeidel),
            "southwell" => Ok(SolverKind::Southwell),
            "progressive" => Ok(SolverKind::Progressive),
            "two-level" => Ok(SolverKind::TwoLevel),
            "ssg" | "super-shoot-gather" => Ok(SolverKind::Ssg),
            "hierarchical" | "hr" => Ok(SolverKind::Hierarchical),
            o => Err(Error::Settings(format!(
                "radiosity: unknown solver '{o}' (auto, jacobi, gauss-seidel, southwell, progressive, ssg, two-level, hierarchical)"
            ))),
        }
    }

    pub fn solve(self, sys: &System, opts: &SolveOptions) -> Result<Solution> {
        opts.validate()?;
        match self {
            SolverKind::Jacobi => jacobi::solve(sys, opts),
            // With a matrix already built, the automatic choice is Gauss-Seidel.
            SolverKind::GaussSeidel | SolverKind::Auto => gauss_seidel::solve(sys, opts),
            SolverKind::Southwell => southwell::solve(sys, opts),
            SolverKind::Progressive => progressive::solve(sys, opts, &mut |_, _| {}),
            SolverKind::TwoLevel => two_level::solve(sys, opts),
            SolverKind::Ssg => ssg::solve(sys, opts),
            SolverKind::Hierarchical => {
                Err(Error::Settings("radiosity: the hierarchical solver builds its own links from the scene (radiosity::solve)".into()))
            }
        }
    }
}
