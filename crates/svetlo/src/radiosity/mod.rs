//! Radiosity: the scene's surfaces cut into elements of constant radiosity, the form factors
//! between them, and the linear system B = E + ρ ⊙ (F B) per RGB channel, solved by one of
//! several methods; then shown through the scene's camera by ray casting.
//!
//! Units (DESIGN.md): B and E in W/m², L = B / π leaving a diffuse surface. Emission comes from
//! the shapes' area lights (E = π × mean radiance of the emitter's texture, front side only);
//! reflectance is each material's diffuse albedo (`Bsdf::diffuse_albedo`), black for
//! conductors and dielectrics. Point, directional and environment lights do not take part.

pub mod display;
pub mod form_factor;
pub mod hierarchical;
pub mod hybrid;
pub mod mesh;
pub mod solver;
pub mod split;

use crate::error::{Error, Result};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use form_factor::{FormFactors, Method, RowSource};
use mesh::{MeshOptions, RadiosityMesh};
use solver::{SolveOptions, SolverKind, Step, System};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// How radiosity is shown: one value per element, or interpolated from the vertices.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Shading {
    Flat,
    #[default]
    Gouraud,
}

/// Everything that selects a radiosity method.
#[derive(Clone, Debug)]
pub struct RadiosityOptions {
    pub mesh: MeshOptions,
    pub form_factors: Method,
    /// The form-factor method was chosen by the user (the automatic solver then keeps the
    /// full matrix, the only solver that uses it; hierarchical links are always analytic).
    pub form_factors_given: bool,
    pub solver: SolverKind,
    pub solve: SolveOptions,
    /// Average A_i F_ij and A_j F_ji before solving.
    pub reciprocity: bool,
    pub shading: Shading,
    /// Settings of the hierarchical solver.
    pub hierarchical: hierarchical::HierarchicalOptions,
    /// Two-pass display: ray tracing adds specular paths and a final gather ([`hybrid`]).
    pub hybrid: bool,
    /// Final-gather rays (and light samples) per camera sample of the hybrid display; 0 reads the solution directly.
    pub gather: u32,
}

impl Default for RadiosityOptions {
    fn default() -> Self {
        RadiosityOptions {
            mesh: MeshOptions::default(),
            form_factors: Method::default(),
            form_factors_given: false,
            solver: SolverKind::Auto,
            solve: SolveOptions::default(),
            reciprocity: false,
            shading: Shading::Gouraud,
            hierarchical: Default::default(),
            hybrid: false,
            gather: 16,
        }
    }
}

impl RadiosityOptions {
    /// Options from `key=value` pairs separated by commas, e.g.
    /// `form-factors=hemicube,solver=progressive,element-size=0.05,tolerance=1e-3`.
    /// Keys: form-factors, solver, element-size, max-elements, tolerance, max-steps, omega
    /// (a number or `adaptive`), hemicube-resolution, rays, visibility-grid, source-grid, seed, reciprocity
    /// (true/false), shading (flat/gouraud); hierarchical solver: epsilon, min-area, refine (f/bf),
    /// importance (true/false), passes; display: hybrid (true/false), gather (final-gather rays).
    pub fn parse(params: &str) -> Result<Self> {
        let mut o = RadiosityOptions::default();
        let (mut res, mut rays, mut vis, mut src, mut seed) = (None, None, None, None, None);
        for kv in params.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (k, v) = kv.split_once('=').ok_or_else(|| Error::Settings(format!("radiosity: expected key=value, got '{kv}'")))?;
            let num = |v: &str| v.parse::<f64>().map_err(|_| Error::Settings(format!("radiosity: {k} needs a number, got '{v}'")));
            let int = |v: &str| v.parse::<u64>().map_err(|_| Error::Settings(format!("radiosity: {k} needs a whole number, got '{v}'")));
            match k {
                "form-factors" | "ff" => {
                    o.form_factors = Method::parse(v)?;
                    o.form_factors_given = true;
                }
                "solver" => o.solver = SolverKind::parse(v)?,
                "element-size" | "max-edge" => o.mesh.max_edge = Some(num(v)? as f32),
                "max-elements" => o.mesh.max_elements = int(v)? as usize,
                "tolerance" => o.solve.tolerance = num(v)?,
                "max-steps" => o.solve.max_steps = int(v)? as usize,
                "omega" if v == "adaptive" => o.solve.adaptive_omega = true,
                "omega" => o.solve.omega = num(v)? as f32,
                "hemicube-resolution" => res = Some(int(v)? as u32),
                "rays" => rays = Some(int(v)? as u32),
                "visibility-grid" => vis = Some(int(v)? as u32),
                "source-grid" => src = Some(int(v)? as u32),
                "seed" => seed = Some(int(v)?),
                "reciprocity" => o.reciprocity = v.parse().map_err(|_| Error::Settings(format!("radiosity: reciprocity is true or false, got '{v}'")))?,
                "shading" => {
                    o.shading = match v {
                        "flat" => Shading::Flat,
                        "gouraud" => Shading::Gouraud,
                        _ => return Err(Error::Settings(format!("radiosity: shading is flat or gouraud, got '{v}'"))),
                    }
                }
                "hybrid" => o.hybrid = v.parse().map_err(|_| Error::Settings(format!("radiosity: hybrid is true or false, got '{v}'")))?,
                "gather" => o.gather = int(v)?.min(1 << 16) as u32,
                "epsilon" => o.hierarchical.epsilon = num(v)?,
                "min-area" => o.hierarchical.min_area = Some(num(v)? as f32),
                "passes" => o.hierarchical.max_passes = int(v)? as usize,
                "refine" => {
                    o.hierarchical.rule = match v {
                        "f" | "F" => hierarchical::Rule::F,
                        "bf" | "BF" => hierarchical::Rule::BF,
                        _ => return Err(Error::Settings(format!("radiosity: refine is f or bf, got '{v}'"))),
                    }
                }
                "importance" => {
                    o.hierarchical.importance = v.parse().map_err(|_| Error::Settings(format!("radiosity: importance is true or false, got '{v}'")))?
                }
                _ => return Err(Error::Settings(format!("radiosity: unknown option '{k}'"))),
            }
        }
        match &mut o.form_factors {
            Method::Analytic { vis_grid, src_grid } => {
                *vis_grid = vis.unwrap_or(*vis_grid);
                *src_grid = src.unwrap_or(*src_grid);
            }
            Method::Hemicube { resolution } => *resolution = res.unwrap_or(*resolution),
            Method::Raycast { rays: r, seed: s } => {
                *r = rays.unwrap_or(*r);
                *s = seed.unwrap_or(*s);
            }
        }
        o.solve.validate()?;
        Ok(o)
    }

    /// The solver that runs for a scene whose regular mesh has `elements` elements: the one
    /// asked for, or for [`SolverKind::Auto`] hierarchical from [`AUTO_HIERARCHICAL_FROM`]
    /// elements on (bench/radiosity: it reaches the full matrix's accuracy in less time, by a
    /// factor that widens with the element count) and Gauss-Seidel on the full matrix below
    /// (small matrices are quick, and exact on their mesh) or when a form-factor method was chosen.
    pub fn solver_for(&self, elements: usize) -> SolverKind {
        match self.solver {
            SolverKind::Auto if self.form_factors_given || elements < AUTO_HIERARCHICAL_FROM => SolverKind::GaussSeidel,
            SolverKind::Auto => SolverKind::Hierarchical,
            s => s,
        }
    }
}

/// Elements of the regular mesh from which the automatic solver is hierarchical.
pub const AUTO_HIERARCHICAL_FROM: usize = 1500;
/// The automatic hierarchical solve's element size, without one given: the scene's bounding
/// radius over this (the matrix's default is radius / 5).
pub const AUTO_HIERARCHICAL_EDGE_DIVISOR: f32 = 8.0;

/// A solved scene: the mesh, the radiosity of each element and how the solve went.
pub struct Solved {
    pub mesh: RadiosityMesh,
    pub b: Vec<Rgb>,
    /// The solver that ran (the automatic choice resolved).
    pub solver: SolverKind,
    pub history: Vec<Step>,
    pub converged: bool,
    /// Form-factor rows computed.
    pub rows_computed: u64,
    /// Non-zero form factors stored (0 when progressive computed rows on demand).
    pub nnz: usize,
    pub matrix_bytes: usize,
    pub mesh_seconds: f64,
    pub form_factor_seconds: f64,
    pub solve_seconds: f64,
    /// Links, nodes and leaves of a hierarchical solve.
    pub hierarchy: Option<hierarchical::Stats>,
    /// What `mesh` was built from ([`RadiosityMesh::build`] makes it again from them).
    pub mesh_options: MeshOptions,
    /// Gouraud values at the display vertices when the solver provides its own (hierarchical:
    /// interpolated over its leaves); None: area-weighted means of the elements around each vertex.
    pub vertex_b: Option<Vec<Rgb>>,
    /// The light of exactly one diffuse bounce, ρ F E plus the positional lights' `lit`
    /// (paths `L D E`, with extended form factors `L S* D E`), for light path expressions;
    /// None where the solver keeps no form-factor matrix to compute it from.
    pub b_one: Option<Vec<Rgb>>,
}

impl Solved {
    /// The solution shown through a camera.
    pub fn view(&self, shading: Shading) -> display::RadiosityView<'_> {
        let mut v = self.plain_view(shading);
        v.b_one = self.b_one.as_deref();
        v
    }

    fn plain_view(&self, shading: Shading) -> display::RadiosityView<'_> {
        match &self.vertex_b {
            Some(v) if shading == Shading::Gouraud => display::RadiosityView::with_vertex_values(&self.mesh, &self.b, v.clone()),
            _ => display::RadiosityView::new(&self.mesh, &self.b, shading),
        }
    }

    /// Radiosity at every display vertex (for Gouraud display and the PLY output).
    pub fn vertex_radiosity(&self) -> Vec<Rgb> {
        self.vertex_b.clone().unwrap_or_else(|| display::vertex_radiosity(&self.mesh, &self.b))
    }
}

/// The system's per-element data.
pub fn system<'a>(mesh: &RadiosityMesh, rows: solver::Rows<'a>) -> System<'a> {
    System {
        emission: mesh.elements.iter().map(|e| e.source()).collect(),
        reflectance: mesh.elements.iter().map(|e| e.reflectance).collect(),
        area: mesh.elements.iter().map(|e| e.area).collect(),
        patch_of: mesh.elements.iter().map(|e| e.patch).collect(),
        rows,
    }
}

/// Mesh, compute form factors, solve. `max_depth` has Mitsuba's meaning: with a bound, the
/// solution holds exactly the light of paths of at most max_depth − 1 diffuse bounces
/// (Jacobi sweeps from E) unless the truncation is below the tolerance anyway.
pub fn solve(scene: &Scene, opts: &RadiosityOptions, max_depth: i32) -> Result<Solved> {
    solve_observed(scene, opts, max_depth, &mut |_, _, _| {})
}

/// [`solve`], calling `observe(mesh, shots, state)` at each reported step of a progressive
/// solve (for intermediate images with the ambient term).
pub fn solve_observed(
    scene: &Scene,
    opts: &RadiosityOptions,
    max_depth: i32,
    observe: &mut dyn FnMut(&RadiosityMesh, usize, &solver::progressive::State),
) -> Result<Solved> {
    match plan(scene, opts, max_depth)? {
        Plan::Hierarchical(o) => solve_hierarchical(scene, &o, max_depth),
        Plan::Matrix(p) => solve_matrix(scene, opts, p, None, observe),
    }
}

/// Solves begun by this process and form-factor rows it computed, since it started: a
/// distributed render's tests read them to show that no chunk repeats the solve.
static SOLVES: AtomicU64 = AtomicU64::new(0);
static FORM_FACTOR_ROWS: AtomicU64 = AtomicU64::new(0);

/// (solves begun, form-factor rows computed) by this process so far.
pub fn counters() -> (u64, u64) {
    (SOLVES.load(Ordering::Relaxed), FORM_FACTOR_ROWS.load(Ordering::Relaxed))
}

/// How a scene's solve goes, decided before any form factor is computed.
pub enum Plan {
    /// Quadtrees and links, with these options (the automatic choice's element size filled in).
    Hierarchical(RadiosityOptions),
    Matrix(MatrixPlan),
}

/// A solve on the regular mesh's form-factor matrix.
pub struct MatrixPlan {
    pub mesh: RadiosityMesh,
    pub mesh_seconds: f64,
    /// The solver that runs (never hierarchical).
    pub kind: SolverKind,
    /// Diffuse bounces that `max_depth` allows (None: unbounded).
    bounces: Option<usize>,
    /// Bounces made exactly by Jacobi sweeps, where the bound matters above the tolerance.
    truncate: Option<usize>,
    /// Progressive refinement computing only the rows it shoots from.
    pub on_demand: bool,
}

/// Mesh the scene and choose the solver (see [`RadiosityOptions::solver_for`]).
pub fn plan(scene: &Scene, opts: &RadiosityOptions, max_depth: i32) -> Result<Plan> {
    if opts.solver == SolverKind::Hierarchical {
        return Ok(Plan::Hierarchical(opts.clone()));
    }
    let t0 = Instant::now();
    let mesh = RadiosityMesh::build(scene, &opts.mesh)?;
    let mesh_seconds = t0.elapsed().as_secs_f64();
    let mut kind = opts.solver_for(mesh.elements.len());
    // The hierarchy's roots carry one `lit` per input triangle, too coarse for the pools of
    // light of luminaires and point lights: those scenes solve on the regular mesh.
    if kind == SolverKind::Hierarchical && scene.lights.iter().any(|l| l.is_delta()) {
        if opts.solver == SolverKind::Hierarchical {
            return Err(crate::error::Error::Settings(
                "radiosity: the hierarchical solver does not take point lights or luminaires; use solver=gauss-seidel (or auto)".into(),
            ));
        }
        kind = SolverKind::GaussSeidel;
    }
    if kind == SolverKind::Hierarchical {
        // Chosen automatically without an element size: finer leaves than the matrix's default
        // (the hierarchy only refines where the oracle asks; bench/radiosity README).
        let mut o = opts.clone();
        o.mesh.max_edge = o.mesh.max_edge.or(Some(scene.bounds.radius.max(1e-6) / AUTO_HIERARCHICAL_EDGE_DIVISOR));
        return Ok(Plan::Hierarchical(o));
    }
    let rho_max = mesh.elements.iter().map(|e| e.reflectance.max_component()).fold(0.0f32, f32::max) as f64;
    let bounces = if max_depth >= 0 { Some((max_depth - 1).max(0) as usize) } else { None };
    let truncate = bounces.filter(|&k| rho_max.powi(k as i32) > opts.solve.tolerance * 1e-2);
    let on_demand = kind == SolverKind::Progressive && !opts.reciprocity && truncate.is_none();
    Ok(Plan::Matrix(MatrixPlan { mesh, mesh_seconds, kind, bounces, truncate, on_demand }))
}

/// Solve a matrix plan, its form factors computed here, or `given` (every row, computed
/// elsewhere by [`form_factor::RowSource::row`]: the same matrix).
pub(crate) fn solve_matrix(
    scene: &Scene,
    opts: &RadiosityOptions,
    plan: MatrixPlan,
    given: Option<FormFactors>,
    observe: &mut dyn FnMut(&RadiosityMesh, usize, &solver::progressive::State),
) -> Result<Solved> {
    SOLVES.fetch_add(1, Ordering::Relaxed);
    let MatrixPlan { mesh, mesh_seconds, kind, bounces, truncate, on_demand } = plan;
    let source = RowSource::new(scene, &mesh, opts.form_factors)?;
    let given_rows = given.as_ref().map_or(0, |m| m.n() as u64);
    let t1 = Instant::now();
    let matrix: Option<FormFactors> = match given {
        Some(m) => Some(m),
        None if on_demand => None,
        None => Some(source.matrix()),
    };
    let matrix = matrix.map(|m| {
        if opts.reciprocity {
            let areas: Vec<f32> = mesh.elements.iter().map(|e| e.area).collect();
            m.reciprocal(&areas)
        } else {
            m
        }
    });
    let form_factor_seconds = t1.elapsed().as_secs_f64();
    let rows = match &matrix {
        Some(m) => solver::Rows::Matrix(m),
        None => solver::Rows::OnDemand(&source),
    };
    let sys = system(&mesh, rows);
    let t2 = Instant::now();
    let sol = match truncate {
        Some(k) => solver::jacobi::bounces(&sys, k)?,
        None if kind == SolverKind::Progressive => {
            opts.solve.validate()?;
            solver::progressive::solve(&sys, &opts.solve, &mut |s, st| observe(&mesh, s, st))?
        }
        None => kind.solve(&sys, &opts.solve)?,
    };
    let solve_seconds = t2.elapsed().as_secs_f64();
    // One bounce: the light of the positional lights (`lit`, already reflected once) and the
    // emission gathered once (not the lit light, which would be a second bounce).
    let emitted: Vec<Rgb> = mesh.elements.iter().map(|e| e.emission).collect();
    let mut b_one: Vec<Rgb> = mesh.elements.iter().map(|e| e.lit).collect();
    match (&matrix, bounces) {
        (_, Some(0)) => {}
        (Some(m), _) => {
            for (i, o) in b_one.iter_mut().enumerate() {
                *o += sys.gather(m, &emitted, i);
            }
        }
        // Rows on demand: only the emitters' rows, by reciprocity F_ij A_i = F_ji A_j.
        (None, _) => {
            for j in (0..sys.n()).filter(|&j| !emitted[j].is_black()) {
                for (i, f) in sys.rows.row(j) {
                    let i = i as usize;
                    if sys.area[i] > 0.0 {
                        b_one[i] += sys.reflectance[i] * emitted[j] * (f * sys.area[j] / sys.area[i]);
                    }
                }
            }
        }
    }
    let b_one = Some(b_one);
    let rows_computed = source.rows_computed.load(Ordering::Relaxed) + given_rows;
    let (nnz, matrix_bytes) = matrix.as_ref().map(|m| (m.nnz(), m.memory())).unwrap_or((0, 0));
    drop(sys);
    Ok(Solved {
        mesh,
        b: sol.b,
        solver: kind,
        history: sol.history,
        converged: sol.converged,
        rows_computed,
        nnz,
        matrix_bytes,
        mesh_seconds,
        form_factor_seconds,
        solve_seconds,
        hierarchy: None,
        mesh_options: opts.mesh.clone(),
        vertex_b: None,
        b_one,
    })
}

fn solve_hierarchical(scene: &Scene, opts: &RadiosityOptions, max_depth: i32) -> Result<Solved> {
    SOLVES.fetch_add(1, Ordering::Relaxed);
    opts.solve.validate()?;
    let t = Instant::now();
    let bounces = if max_depth >= 0 { Some((max_depth - 1).max(0) as usize) } else { None };
    // Truncate only where it matters, as for the matrix solvers (ρ_max^k above the tolerance).
    let rho_max = scene.materials.iter().map(|m| m.bsdf(glam::Vec2::splat(0.5)).diffuse_albedo().max_component()).fold(0.0f32, f32::max) as f64;
    let bounces = bounces.filter(|&k| rho_max.powi(k as i32) > opts.solve.tolerance * 1e-2);
    let o = hierarchical::solve(scene, &opts.mesh, &opts.hierarchical, opts.solve.tolerance, opts.solve.max_steps.min(10_000), bounces)?;
    let total = t.elapsed().as_secs_f64();
    Ok(Solved {
        mesh: o.mesh,
        b: o.b,
        solver: SolverKind::Hierarchical,
        history: o.history,
        converged: o.converged,
        rows_computed: o.stats.form_factors,
        nnz: o.stats.links,
        matrix_bytes: o.stats.memory,
        mesh_seconds: 0.0,
        form_factor_seconds: o.stats.refine_seconds,
        solve_seconds: total - o.stats.refine_seconds,
        hierarchy: Some(o.stats),
        mesh_options: o.mesh_options,
        vertex_b: Some(o.vertex_b),
        b_one: Some(o.b_one),
    })
}
