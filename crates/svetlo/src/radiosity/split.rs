//! The radiosity solve in pieces that run apart (`svetlo.distributed`): ranges of rows of the
//! form-factor matrix computed anywhere, the solve from all the rows in one place, and the
//! solution as bytes that every display task reads instead of solving again.
//!
//! A row is a function of the scene, the mesh and the form-factor method alone (the local
//! solve computes the rows independently, in parallel, with [`RowSource::row`]), so rows made
//! apart and put together in order are the local matrix, and the solve from them is the local
//! solve bit for bit. The hierarchical solver refines its links between solves, a pass at a
//! time; its link form factors are not spread: it solves in one place ([`solve_from_rows`]
//! with no rows). So does progressive refinement with rows on demand, which computes only the
//! rows of the elements that shoot.

use super::form_factor::{FormFactors, RowSource};
use super::mesh::{MeshOptions, RadiosityMesh};
use super::solver::SolverKind;
use super::{plan, solve_hierarchical, solve_matrix, Plan, RadiosityOptions, Solved};
use crate::bytes::ByteReader;
use crate::error::{Error, Result};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use rayon::prelude::*;
use std::ops::Range;

/// Sparse rows of F: (column, value) sorted by column.
type Rows = Vec<Vec<(u32, f32)>>;

const ROWS_MAGIC: &[u8; 8] = b"SVLFFRW1";
const SOLUTION_MAGIC: &[u8; 8] = b"SVLRADS1";

fn bad(what: &str, msg: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("radiosity {what}: {msg}"))
}

/// Rows of F a distributed solve spreads: every element's for a solve on the full matrix, 0
/// where the solve makes its own (hierarchical links, progressive rows on demand).
pub fn row_count(scene: &Scene, opts: &RadiosityOptions, max_depth: i32) -> Result<u64> {
    Ok(match plan(scene, opts, max_depth)? {
        Plan::Matrix(p) if !p.on_demand => p.mesh.elements.len() as u64,
        _ => 0,
    })
}

/// Rows `range` of the form-factor matrix (of [`row_count`] rows), as bytes for
/// [`solve_from_rows`]. Runs on the current rayon pool.
pub fn form_factor_rows(scene: &Scene, opts: &RadiosityOptions, max_depth: i32, range: Range<u64>) -> Result<Vec<u8>> {
    let Plan::Matrix(p) = plan(scene, opts, max_depth)? else {
        return Err(Error::Settings("radiosity: the hierarchical solver has no form-factor rows to spread".into()));
    };
    let n = p.mesh.elements.len() as u64;
    if p.on_demand || range.start >= range.end || range.end > n {
        let have = if p.on_demand { 0 } else { n };
        return Err(Error::Settings(format!("radiosity: the solve spreads rows 0..{have}, not {}..{}", range.start, range.end)));
    }
    let source = RowSource::new(scene, &p.mesh, opts.form_factors)?;
    let rows: Rows = (range.start as usize..range.end as usize).into_par_iter().map(|i| source.row(i)).collect();
    let nnz: usize = rows.iter().map(Vec::len).sum();
    let mut out = Vec::with_capacity(32 + 4 * rows.len() + 8 * nnz);
    out.extend_from_slice(ROWS_MAGIC);
    for v in [n, range.start, range.end] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for r in &rows {
        out.extend_from_slice(&(r.len() as u32).to_le_bytes());
        for &(j, f) in r {
            out.extend_from_slice(&j.to_le_bytes());
            out.extend_from_slice(&f.to_le_bytes());
        }
    }
    Ok(out)
}

/// The rows in `blocks` (from [`form_factor_rows`], in any order), checked to be every row of
/// an `n`-element matrix exactly once, in row order.
fn assemble(blocks: &[&[u8]], n: u64) -> Result<FormFactors> {
    let mut parts: Vec<(u64, Rows)> = Vec::with_capacity(blocks.len());
    for b in blocks {
        let mut r = ByteReader::new(b, "radiosity form-factor rows");
        if r.take(8).ok() != Some(&ROWS_MAGIC[..]) {
            return Err(bad("form-factor rows", "not svetlo form-factor rows (bad magic)"));
        }
        let (m, start, end) = (r.u64()?, r.u64()?, r.u64()?);
        if m != n || start >= end || end > n {
            return Err(bad("form-factor rows", format!("rows {start}..{end} of {m} elements, for a mesh of {n}")));
        }
        let mut rows = Vec::with_capacity((end - start) as usize);
        for _ in start..end {
            let k = r.u32()? as usize;
            if k as u64 * 8 > r.left() as u64 {
                return Err(bad("form-factor rows", "truncated row"));
            }
            let row = (0..k)
                .map(|_| {
                    let (j, f) = (r.u32()?, r.f32()?);
                    if j as u64 >= n || !f.is_finite() {
                        return Err(bad("form-factor rows", format!("entry ({j}, {f}) is out of range")));
                    }
                    Ok((j, f))
                })
                .collect::<Result<Vec<_>>>()?;
            rows.push(row);
        }
        r.end()?;
        parts.push((start, rows));
    }
    parts.sort_by_key(|p| p.0);
    let mut next = 0u64;
    let mut all = Vec::with_capacity(n as usize);
    for (start, rows) in parts {
        if start != next {
            return Err(bad("form-factor rows", format!("the blocks leave a gap or overlap at row {next} (a block starts at {start})")));
        }
        next += rows.len() as u64;
        all.extend(rows);
    }
    if next != n {
        return Err(bad("form-factor rows", format!("the blocks hold rows 0..{next} of {n}")));
    }
    Ok(FormFactors::from_rows(all))
}

/// Solve from the rows of [`form_factor_rows`] (every one of [`row_count`]'s, in blocks in
/// any order; none where the count is 0: the solve makes its own), as [`super::solve`] would.
pub fn solve_from_rows(scene: &Scene, opts: &RadiosityOptions, max_depth: i32, blocks: &[&[u8]]) -> Result<Solved> {
    match plan(scene, opts, max_depth)? {
        Plan::Hierarchical(o) if blocks.is_empty() => solve_hierarchical(scene, &o, max_depth),
        Plan::Matrix(p) if p.on_demand && blocks.is_empty() => solve_matrix(scene, opts, p, None, &mut |_, _, _| {}),
        Plan::Matrix(p) if !p.on_demand => {
            let m = assemble(blocks, p.mesh.elements.len() as u64)?;
            solve_matrix(scene, opts, p, Some(m), &mut |_, _, _| {})
        }
        _ => Err(Error::Settings(format!("radiosity: this solve makes its own form factors, but {} blocks of rows were given", blocks.len()))),
    }
}

fn solver_code(k: SolverKind) -> u8 {
    match k {
        SolverKind::Auto => 0,
        SolverKind::Jacobi => 1,
        SolverKind::GaussSeidel => 2,
        SolverKind::Southwell => 3,
        SolverKind::Progressive => 4,
        SolverKind::TwoLevel => 5,
        SolverKind::Ssg => 6,
        SolverKind::Hierarchical => 7,
    }
}

fn solver_of(c: u8) -> Result<SolverKind> {
    const KINDS: [SolverKind; 8] = [
        SolverKind::Auto,
        SolverKind::Jacobi,
        SolverKind::GaussSeidel,
        SolverKind::Southwell,
        SolverKind::Progressive,
        SolverKind::TwoLevel,
        SolverKind::Ssg,
        SolverKind::Hierarchical,
    ];
    KINDS.get(c as usize).copied().ok_or_else(|| bad("solution", format!("unknown solver {c}")))
}

fn put_rgbs(out: &mut Vec<u8>, v: &[Rgb]) {
    out.extend_from_slice(&(v.len() as u64).to_le_bytes());
    for c in v {
        for x in [c.r, c.g, c.b] {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
}

fn put_optional(out: &mut Vec<u8>, v: Option<&[Rgb]>) {
    out.push(v.is_some() as u8);
    if let Some(v) = v {
        put_rgbs(out, v);
    }
}

impl Solved {
    /// What a display needs of the solution, as bytes: the mesh's options (not the mesh:
    /// [`Self::from_bytes`] builds it again), the solver, the radiosities per element, at the
    /// vertices where the solver gives them and of one bounce.
    pub fn to_bytes(&self) -> Vec<u8> {
        let m = &self.mesh_options;
        let mut out = Vec::with_capacity(64 + 12 * (2 * self.b.len() + self.vertex_b.as_ref().map_or(0, Vec::len)));
        out.extend_from_slice(SOLUTION_MAGIC);
        out.push(solver_code(self.solver));
        out.push(self.converged as u8);
        out.push(m.max_edge.is_some() as u8);
        out.extend_from_slice(&m.max_edge.unwrap_or(0.0).to_le_bytes());
        for v in [m.max_elements as u64, m.sphere_segments as u64, m.shape_splits.len() as u64] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for s in &m.shape_splits {
            out.extend_from_slice(&s.to_le_bytes());
        }
        put_rgbs(&mut out, &self.b);
        put_optional(&mut out, self.vertex_b.as_deref());
        put_optional(&mut out, self.b_one.as_deref());
        out
    }

    /// The solution of [`Self::to_bytes`] for `scene` (the one it was solved on), its mesh
    /// built again; statistics of the solve are not carried (zero).
    pub fn from_bytes(scene: &Scene, b: &[u8]) -> Result<Solved> {
        let mut r = ByteReader::new(b, "radiosity solution");
        if r.take(8).ok() != Some(&SOLUTION_MAGIC[..]) {
            return Err(bad("solution", "not a svetlo radiosity solution (bad magic)"));
        }
        let solver = solver_of(r.u8()?)?;
        let converged = r.u8()? != 0;
        let has_edge = r.u8()? != 0;
        let edge = r.f32()?;
        let (max_elements, sphere_segments) = (r.u64()?, r.u64()?);
        let k = r.count(4)?;
        let shape_splits = (0..k).map(|_| r.u32()).collect::<Result<Vec<_>>>()?;
        let mesh_options = MeshOptions {
            max_edge: has_edge.then_some(edge),
            max_elements: usize::try_from(max_elements).unwrap_or(usize::MAX),
            sphere_segments: usize::try_from(sphere_segments).map_err(|_| bad("solution", "sphere segments out of range"))?,
            shape_splits,
        };
        let bv = r.counted_rgbs()?;
        let vertex_b = if r.u8()? != 0 { Some(r.counted_rgbs()?) } else { None };
        let b_one = if r.u8()? != 0 { Some(r.counted_rgbs()?) } else { None };
        r.end()?;
        let mesh = RadiosityMesh::build(scene, &mesh_options)?;
        let (ne, nv) = (mesh.elements.len(), mesh.vertices.len());
        if bv.len() != ne || b_one.as_ref().is_some_and(|v| v.len() != ne) || vertex_b.as_ref().is_some_and(|v| v.len() != nv) {
            return Err(bad("solution", format!("its values are not of this scene's mesh ({ne} elements, {nv} vertices)")));
        }
        Ok(Solved {
            mesh,
            b: bv,
            solver,
            history: vec![],
            converged,
            rows_computed: 0,
            nnz: 0,
            matrix_bytes: 0,
            mesh_seconds: 0.0,
            form_factor_seconds: 0.0,
            solve_seconds: 0.0,
            hierarchy: None,
            mesh_options,
            vertex_b,
            b_one,
        })
    }
}
