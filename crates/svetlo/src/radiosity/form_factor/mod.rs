//! Form factors between elements: F_ij, the fraction of the power leaving element i (diffusely)
//! that arrives at element j directly. Three methods, one per file; all give sparse rows.

pub mod analytic;
pub mod hemicube;
pub mod raycast;

use super::mesh::RadiosityMesh;
use crate::error::{Error, Result};
use crate::scene::Scene;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// Which way to compute form factors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Contour integral from points of i to j, visibility by `vis_grid`² shadow rays per pair.
    /// Close pairs average over `src_grid`² points of i, the others use i's centroid (with
    /// `src_grid` = 1 every row uses one point and sums to exactly 1 in a closed scene).
    Analytic { vis_grid: u32, src_grid: u32 },
    /// Hemicube of `resolution` pixels across its top face at each element's centroid.
    Hemicube { resolution: u32 },
    /// `rays` cosine-distributed rays from random points of each element.
    Raycast { rays: u32, seed: u64 },
}

impl Default for Method {
    fn default() -> Self {
        Method::Analytic { vis_grid: 2, src_grid: 4 }
    }
}

impl Method {
    /// Parse a method name (`analytic`, `hemicube`, `raycast`) with default parameters.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "analytic" => Ok(Method::Analytic { vis_grid: 2, src_grid: 4 }),
            "hemicube" => Ok(Method::Hemicube { resolution: 64 }),
            "raycast" => Ok(Method::Raycast { rays: 1024, seed: 0 }),
            o => Err(Error::Settings(format!("radiosity: unknown form-factor method '{o}' (analytic, hemicube, raycast)"))),
        }
    }
}

/// Sort (column, value) pairs and add the duplicates.
pub(crate) fn merge(mut v: Vec<(u32, f32)>) -> Vec<(u32, f32)> {
    v.sort_unstable_by_key(|e| e.0);
    let mut out: Vec<(u32, f32)> = Vec::with_capacity(v.len());
    for (j, f) in v {
        match out.last_mut() {
            Some(last) if last.0 == j => last.1 += f,
            _ => out.push((j, f)),
        }
    }
    out
}

/// Computes rows of the form-factor matrix on demand (progressive refinement needs only the
/// rows it shoots from). Counts the rows computed.
pub struct RowSource<'a> {
    pub scene: &'a Scene,
    pub mesh: &'a RadiosityMesh,
    pub method: Method,
    hemicube: Vec<(glam::Vec3, f32)>,
    pub rows_computed: AtomicU64,
}

impl<'a> RowSource<'a> {
    pub fn new(scene: &'a Scene, mesh: &'a RadiosityMesh, method: Method) -> Result<Self> {
        match method {
            Method::Analytic { vis_grid, src_grid } if vis_grid == 0 || vis_grid > 64 || src_grid == 0 || src_grid > 64 => {
                return Err(Error::Settings(format!("radiosity: visibility and source grids must be 1..=64, got {vis_grid} and {src_grid}")))
            }
            Method::Hemicube { resolution } if !(2..=4096).contains(&resolution) => {
                return Err(Error::Settings(format!("radiosity: hemicube resolution must be 2..=4096, got {resolution}")))
            }
            Method::Raycast { rays: 0, .. } => return Err(Error::Settings("radiosity: form-factor rays must be at least 1".into())),
            _ => {}
        }
        let hemicube = match method {
            Method::Hemicube { resolution } => hemicube::pixels(resolution),
            _ => vec![],
        };
        Ok(RowSource { scene, mesh, method, hemicube, rows_computed: AtomicU64::new(0) })
    }

    /// Row i: (j, F_ij) sorted by j.
    pub fn row(&self, i: usize) -> Vec<(u32, f32)> {
        self.rows_computed.fetch_add(1, Ordering::Relaxed);
        super::FORM_FACTOR_ROWS.fetch_add(1, Ordering::Relaxed);
        match self.method {
            Method::Analytic { vis_grid, src_grid } => analytic::row(self.scene, self.mesh, i, vis_grid, src_grid),
            Method::Hemicube { .. } => hemicube::row(self.scene, self.mesh, i, &self.hemicube),
            Method::Raycast { rays, seed } => raycast::row(self.scene, self.mesh, i, rays, seed),
        }
    }

    /// Every row, in parallel.
    pub fn matrix(&self) -> FormFactors {
        self.matrix_of(|_| true)
    }

    /// The rows of the elements `which` selects, in parallel; the other rows are left empty.
    pub fn matrix_of(&self, which: impl Fn(usize) -> bool + Sync) -> FormFactors {
        let rows: Vec<Vec<(u32, f32)>> = (0..self.mesh.elements.len()).into_par_iter().map(|i| if which(i) { self.row(i) } else { vec![] }).collect();
        FormFactors::from_rows(rows)
    }
}

/// A sparse form-factor matrix in compressed rows.
#[derive(Clone, Debug, Default)]
pub struct FormFactors {
    pub row_start: Vec<usize>,
    pub cols: Vec<u32>,
    pub vals: Vec<f32>,
}

impl FormFactors {
    pub fn from_rows(rows: Vec<Vec<(u32, f32)>>) -> Self {
        let mut m = FormFactors { row_start: Vec::with_capacity(rows.len() + 1), cols: vec![], vals: vec![] };
        m.row_start.push(0);
        for r in rows {
            for (j, f) in r {
                m.cols.push(j);
                m.vals.push(f);
            }
            m.row_start.push(m.cols.len());
        }
        m
    }
    pub fn n(&self) -> usize {
        self.row_start.len().saturating_sub(1)
    }
    pub fn nnz(&self) -> usize {
        self.cols.len()
    }
    #[inline]
    pub fn row(&self, i: usize) -> (&[u32], &[f32]) {
        let (a, b) = (self.row_start[i], self.row_start[i + 1]);
        (&self.cols[a..b], &self.vals[a..b])
    }
    pub fn row_sum(&self, i: usize) -> f64 {
        self.row(i).1.iter().map(|&f| f as f64).sum()
    }
    /// Bytes the matrix occupies.
    pub fn memory(&self) -> usize {
        self.row_start.len() * 8 + self.cols.len() * 4 + self.vals.len() * 4
    }
    /// The transpose (column access for Southwell's residual updates).
    pub fn transpose(&self) -> FormFactors {
        let n = self.n();
        let mut rows: Vec<Vec<(u32, f32)>> = vec![vec![]; n];
        for i in 0..n {
            let (c, v) = self.row(i);
            for (j, f) in c.iter().zip(v) {
                rows[*j as usize].push((i as u32, *f));
            }
        }
        FormFactors::from_rows(rows)
    }
    /// Enforce reciprocity A_i F_ij = A_j F_ji by averaging the two estimates of the shared
    /// quantity A_i F_ij (removes the asymmetric part of the discretisation and sampling error).
    pub fn reciprocal(&self, areas: &[f32]) -> FormFactors {
        let t = self.transpose();
        let n = self.n();
        let rows = (0..n)
            .map(|i| {
                let mut r: Vec<(u32, f32)> = self.row(i).0.iter().zip(self.row(i).1).map(|(j, f)| (*j, 0.5 * f)).collect();
                let (c, v) = t.row(i);
                for (j, fji) in c.iter().zip(v) {
                    r.push((*j, 0.5 * fji * areas[*j as usize] / areas[i]));
                }
                merge(r)
            })
            .collect();
        FormFactors::from_rows(rows)
    }
}
