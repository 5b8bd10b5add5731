//! A luminous intensity distribution on a (φ, θ) grid around a polar axis, in candela:
//! bilinear in (φ, θ), integrated exactly, and importance sampled by cells.
//!
//! Every photometric type maps to one grid: θ is the angle from the type's polar axis `p`,
//! φ the angle about it from `e0` toward `e90`, and a local direction is
//! d = sin θ (cos φ e0 + sin φ e90) + cos θ p (all in the luminaire frame, aim along −Z):
//! * type C (C, γ): p = −Z, e0 = +X, e90 = +Y; θ = γ, φ = C;
//! * type B (H, V): p = +Y, e0 = −Z, e90 = +X; θ = 90° − V, φ = H
//!   (H turns the aim toward +X, V lifts it toward +Y);
//! * type A (H, V): p = +X, e0 = −Z, e90 = +Y; θ = 90° − H, φ = V
//!   (H turns the aim toward +X, V toward +Y).
//!
//! The stored symmetry is expanded into the full range once (type C: φ over [0°, 360°];
//! types A and B: over [−90°, 90°]); outside the measured θ range and, for A and B, behind
//! the luminaire (|φ| > 90°) the intensity is zero.

use crate::sampling::Distribution1D;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PhotometricType {
    A,
    B,
    C,
}

impl PhotometricType {
    /// (p, e0, e90) in the luminaire frame.
    fn basis(self) -> (Vec3, Vec3, Vec3) {
        match self {
            PhotometricType::C => (Vec3::NEG_Z, Vec3::X, Vec3::Y),
            PhotometricType::B => (Vec3::Y, Vec3::NEG_Z, Vec3::X),
            PhotometricType::A => (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        }
    }
}

/// Intensity on a (φ, θ) grid (radians, strictly increasing), `cd[i * theta.len() + j]` at
/// (φ_i, θ_j).
#[derive(Clone, Debug)]
pub struct IntensityTable {
    kind: PhotometricType,
    phi: Vec<f64>,
    theta: Vec<f64>,
    cd: Vec<f64>,
    /// Exact integral of the bilinear intensity over each cell (lm), for sampling.
    cells: Distribution1D,
    flux: f64,
}

/// ∫ w(θ) sin θ dθ over [θ0, θ1] for the two linear weights w0 = 1 − t, w1 = t,
/// t = (θ − θ0)/(θ1 − θ0): with ∫ (θ − θ0) sin θ dθ = [sin θ − (θ − θ0) cos θ].
fn sin_weights(t0: f64, t1: f64) -> (f64, f64) {
    let d = t1 - t0;
    let w1 = (t1.sin() - t0.sin()) / d - t1.cos();
    let w0 = (t0.cos() - t1.cos()) - w1;
    (w0, w1)
}

fn strictly_increasing(v: &[f64]) -> bool {
    v.windows(2).all(|w| w[1] > w[0])
}

impl IntensityTable {
    /// A table directly on the (φ, θ) grid, angles in radians (φ within [−π, 2π], θ within
    /// [0, π], both strictly increasing, at least two of each), candela ≥ 0 with φ outer.
    /// This is the constructor for other sources of goniometric data (pbrt's `goniometric`).
    pub fn from_grid(kind: PhotometricType, phi: Vec<f64>, theta: Vec<f64>, cd: Vec<f64>) -> Result<Self, String> {
        if phi.len() < 2 || theta.len() < 2 {
            return Err("an intensity grid needs at least two angles each way".into());
        }
        if !strictly_increasing(&phi) || !strictly_increasing(&theta) {
            return Err("grid angles must increase strictly".into());
        }
        if theta[0] < -1e-9 || theta[theta.len() - 1] > std::f64::consts::PI + 1e-9 {
            return Err("polar angles must lie within [0, 180] degrees".into());
        }
        if cd.len() != phi.len() * theta.len() {
            return Err(format!("{} intensities for a {} x {} grid", cd.len(), phi.len(), theta.len()));
        }
        if let Some(bad) = cd.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(format!("intensity {bad} is negative or not a number"));
        }
        let nt = theta.len();
        let mut w = Vec::with_capacity((phi.len() - 1) * (nt - 1));
        let mut flux = 0.0;
        for i in 0..phi.len() - 1 {
            let dphi = phi[i + 1] - phi[i];
            for j in 0..nt - 1 {
                let (w0, w1) = sin_weights(theta[j], theta[j + 1]);
                let a = cd[i * nt + j] + cd[(i + 1) * nt + j];
                let b = cd[i * nt + j + 1] + cd[(i + 1) * nt + j + 1];
                let f = 0.5 * dphi * (a * w0 + b * w1);
                flux += f;
                w.push(f.max(0.0) as f32);
            }
        }
        let cells = Distribution1D::new(&w);
        Ok(IntensityTable { kind, phi, theta, cd, cells, flux })
    }

    /// A table from a file's angles in degrees: `horizontal` (C or H) and `vertical` (γ or
    /// V), `cd` with the horizontal angle outer. Expands the symmetry the horizontal range
    /// implies; returns its description. Errors are messages for the caller to locate.
    pub fn from_file_angles(kind: PhotometricType, horizontal: &[f64], vertical: &[f64], cd: &[f64]) -> Result<(Self, &'static str), String> {
        let (nh, nv) = (horizontal.len(), vertical.len());
        if nh == 0 || nv == 0 {
            return Err("no angles".into());
        }
        if cd.len() != nh * nv {
            return Err(format!("{} intensities for {nh} x {nv} angles", cd.len()));
        }
        if !strictly_increasing(horizontal) {
            return Err("horizontal angles are not strictly increasing".into());
        }
        if !strictly_increasing(vertical) {
            return Err("vertical angles are not strictly increasing".into());
        }
        let col = |i: usize| &cd[i * nv..(i + 1) * nv];
        let (h0, h1) = (horizontal[0], horizontal[nh - 1]);
        let near = |a: f64, b: f64| (a - b).abs() < 1e-6;
        // Each expanded column: (φ in degrees, source column).
        let mut cols: Vec<(f64, usize)> = Vec::new();
        let symmetry;
        match kind {
            PhotometricType::C => {
                if nh == 1 {
                    if !near(h0, 0.0) {
                        return Err(format!("a single horizontal angle must be 0, got {h0}"));
                    }
                    symmetry = "rotational (one C-plane)";
                    cols = vec![(0.0, 0), (360.0, 0)];
                } else if near(h0, 0.0) && near(h1, 90.0) {
                    symmetry = "quadrilateral (C0-C90)";
                    for (i, &h) in horizontal.iter().enumerate() {
                        cols.extend([(h, i), (180.0 - h, i), (180.0 + h, i), (360.0 - h, i)]);
                    }
                } else if near(h0, 0.0) && near(h1, 180.0) {
                    symmetry = "bilateral about the C0-C180 plane (C0-C180)";
                    for (i, &h) in horizontal.iter().enumerate() {
                        cols.extend([(h, i), (360.0 - h, i)]);
                    }
                } else if near(h0, 90.0) && near(h1, 270.0) {
                    symmetry = "bilateral about the C90-C270 plane (C90-C270)";
                    for (i, &h) in horizontal.iter().enumerate() {
                        let m = 180.0 - h;
                        cols.extend([(h, i), (if m < 0.0 { m + 360.0 } else { m }, i)]);
                    }
                    // The mirrored half meets itself at C0 = C360.
                    if let Some(&(_, i)) = cols.iter().find(|c| near(c.0, 0.0)) {
                        cols.push((360.0, i));
                    }
                } else if near(h0, 0.0) && h1 > 180.0 && h1 <= 360.0 + 1e-6 {
                    symmetry = "none (C0-C360)";
                    cols.extend(horizontal.iter().enumerate().map(|(i, &h)| (h, i)));
                    if !near(h1, 360.0) {
                        cols.push((360.0, 0));
                    }
                } else {
                    return Err(format!("unknown horizontal symmetry: type C angles from {h0} to {h1} (expected 0, 0-90, 0-180, 90-270 or 0-360)"));
                }
                if !(vertical[0] >= -1e-6 && vertical[nv - 1] <= 180.0 + 1e-6) {
                    return Err(format!("type C vertical angles must lie within 0-180, got {} to {}", vertical[0], vertical[nv - 1]));
                }
            }
            PhotometricType::A | PhotometricType::B => {
                if near(h0, -90.0) && near(h1, 90.0) {
                    symmetry = "none (-90 to 90)";
                    cols.extend(horizontal.iter().enumerate().map(|(i, &h)| (h, i)));
                } else if near(h0, 0.0) && near(h1, 90.0) {
                    symmetry = "bilateral (0-90 mirrored)";
                    for (i, &h) in horizontal.iter().enumerate() {
                        cols.extend([(h, i), (-h, i)]);
                    }
                } else {
                    return Err(format!("unknown horizontal symmetry: type A/B angles from {h0} to {h1} (expected -90 to 90 or 0 to 90)"));
                }
                if !(vertical[0] >= -90.0 - 1e-6 && vertical[nv - 1] <= 90.0 + 1e-6) {
                    return Err(format!("type A/B vertical angles must lie within -90 to 90, got {} to {}", vertical[0], vertical[nv - 1]));
                }
            }
        }
        cols.sort_by(|a, b| a.0.total_cmp(&b.0));
        cols.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-6);
        // Vertical: type C θ = γ as given; types A and B θ = 90° − V (reversed), mirrored
        // about V = 0 when only 0-90 is given.
        let mut rows: Vec<(f64, usize)> = match kind {
            PhotometricType::C => vertical.iter().enumerate().map(|(j, &g)| (g, j)).collect(),
            _ => {
                let mut r: Vec<(f64, usize)> = vertical.iter().enumerate().map(|(j, &v)| (90.0 - v, j)).collect();
                if near(vertical[0], 0.0) && nv > 1 {
                    r.extend(vertical.iter().enumerate().map(|(j, &v)| (90.0 + v, j)));
                }
                r
            }
        };
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        rows.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-6);
        let mut theta: Vec<f64> = rows.iter().map(|r| r.0.to_radians()).collect();
        let mut row_src: Vec<Option<usize>> = rows.iter().map(|r| Some(r.1)).collect();
        if theta.len() == 1 {
            // One vertical angle: a sliver; give it a zero neighbour so that it has a cell.
            let t = theta[0];
            let (lo, hi) = if t > 0.5 { (t - 1e-3, t) } else { (t, t + 1e-3) };
            theta = vec![lo, hi];
            row_src = if t > 0.5 { vec![None, row_src[0]] } else { vec![row_src[0], None] };
        }
        let phi: Vec<f64> = cols.iter().map(|c| c.0.to_radians()).collect();
        let mut grid = Vec::with_capacity(phi.len() * theta.len());
        for &(_, i) in &cols {
            for src in &row_src {
                grid.push(src.map_or(0.0, |j| col(i)[j]));
            }
        }
        Ok((IntensityTable::from_grid(kind, phi, theta, grid)?, symmetry))
    }

    pub fn kind(&self) -> PhotometricType {
        self.kind
    }

    /// Luminous flux: the exact integral of the bilinear intensity over the sphere (lm).
    pub fn flux(&self) -> f64 {
        self.flux
    }

    pub fn max_intensity(&self) -> f64 {
        self.cd.iter().copied().fold(0.0, f64::max)
    }

    /// Multiply every intensity by `k` ≥ 0.
    pub fn scaled(mut self, k: f64) -> Self {
        for v in &mut self.cd {
            *v *= k;
        }
        self.flux *= k;
        self
    }

    /// (φ, θ) of a unit local direction.
    fn angles(&self, d: Vec3) -> (f64, f64) {
        let (p, e0, e90) = self.kind.basis();
        let ct = (d.dot(p) as f64).clamp(-1.0, 1.0);
        let mut phi = (d.dot(e90) as f64).atan2(d.dot(e0) as f64);
        if self.kind == PhotometricType::C && phi < 0.0 {
            phi += 2.0 * std::f64::consts::PI;
        }
        (phi, ct.acos())
    }

    /// Cell index and fractions (s along φ, t along θ) of a point inside the grid.
    fn locate(&self, phi: f64, theta: f64) -> Option<(usize, usize, f64, f64)> {
        let find = |v: &[f64], x: f64| -> Option<(usize, f64)> {
            let n = v.len();
            if x < v[0] - 1e-9 || x > v[n - 1] + 1e-9 {
                return None;
            }
            let i = v.partition_point(|a| *a <= x).clamp(1, n - 1) - 1;
            Some((i, ((x - v[i]) / (v[i + 1] - v[i])).clamp(0.0, 1.0)))
        };
        let (i, s) = find(&self.phi, phi)?;
        let (j, t) = find(&self.theta, theta)?;
        Some((i, j, s, t))
    }

    fn bilinear(&self, i: usize, j: usize, s: f64, t: f64) -> f64 {
        let nt = self.theta.len();
        let c = |a: usize, b: usize| self.cd[a * nt + b];
        (1.0 - s) * ((1.0 - t) * c(i, j) + t * c(i, j + 1)) + s * ((1.0 - t) * c(i + 1, j) + t * c(i + 1, j + 1))
    }

    /// Intensity (cd) toward unit direction `d` in the luminaire frame.
    pub fn eval(&self, d: Vec3) -> f64 {
        let (phi, theta) = self.angles(d);
        match self.locate(phi, theta) {
            Some((i, j, s, t)) => self.bilinear(i, j, s, t),
            None => 0.0,
        }
    }

    /// Intensity (cd) at file angles in degrees (horizontal, vertical), for tests and reports.
    pub fn eval_angles(&self, horizontal_deg: f64, vertical_deg: f64) -> f64 {
        let (h, v) = (horizontal_deg.to_radians(), vertical_deg.to_radians());
        let d = match self.kind {
            PhotometricType::C => Vec3::new((v.sin() * h.cos()) as f32, (v.sin() * h.sin()) as f32, -v.cos() as f32),
            PhotometricType::B => Vec3::new((h.sin() * v.cos()) as f32, v.sin() as f32, -(h.cos() * v.cos()) as f32),
            PhotometricType::A => Vec3::new(h.sin() as f32, (h.cos() * v.sin()) as f32, -(h.cos() * v.cos()) as f32),
        };
        self.eval(d.normalize())
    }

    /// The grid: φ and θ nodes (radians).
    pub fn grid(&self) -> (&[f64], &[f64]) {
        (&self.phi, &self.theta)
    }

    /// Probability with which [`IntensityTable::sample`] picks cell (i, j) (between φ_i,
    /// φ_i+1 and θ_j, θ_j+1).
    pub fn cell_probability(&self, i: usize, j: usize) -> f64 {
        self.cells.pmf(i * self.n_cells_theta() + j) as f64
    }

    /// (φ, θ) of a unit direction in the luminaire frame.
    pub fn direction_angles(&self, d: Vec3) -> (f64, f64) {
        self.angles(d)
    }

    fn n_cells_theta(&self) -> usize {
        self.theta.len() - 1
    }

    /// Sample a local direction: a cell in proportion to its flux, then uniformly in
    /// (φ, cos θ) inside it. Returns the direction and its solid-angle density.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, f32)> {
        if self.flux <= 0.0 {
            return None;
        }
        let (k, pmf, ur) = self.cells.sample_discrete(u.x);
        if pmf <= 0.0 {
            return None;
        }
        let nt = self.n_cells_theta();
        let (i, j) = (k / nt, k % nt);
        let phi = self.phi[i] + ur as f64 * (self.phi[i + 1] - self.phi[i]);
        let (c0, c1) = (self.theta[j].cos(), self.theta[j + 1].cos());
        let ct = c0 + u.y as f64 * (c1 - c0);
        let st = (1.0 - ct * ct).max(0.0).sqrt();
        let (p, e0, e90) = self.kind.basis();
        let d = (e0 * (st * phi.cos()) as f32 + e90 * (st * phi.sin()) as f32 + p * ct as f32).normalize();
        let pdf = pmf as f64 / ((self.phi[i + 1] - self.phi[i]) * (c0 - c1));
        Some((d, pdf as f32))
    }

    /// Solid-angle density of [`IntensityTable::sample`] for local direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        let (phi, theta) = self.angles(d);
        let Some((i, j, _, _)) = self.locate(phi, theta) else { return 0.0 };
        let pmf = self.cells.pmf(i * self.n_cells_theta() + j) as f64;
        let (c0, c1) = (self.theta[j].cos(), self.theta[j + 1].cos());
        (pmf / ((self.phi[i + 1] - self.phi[i]) * (c0 - c1))) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isotropic_table_integrates_to_four_pi() {
        let (t, _) = IntensityTable::from_file_angles(PhotometricType::C, &[0.0], &[0.0, 30.0, 90.0, 180.0], &[100.0; 4]).unwrap();
        assert!((t.flux() - 400.0 * std::f64::consts::PI).abs() < 1e-9 * t.flux());
        // Cosine (Lambertian) downlight I0 cos γ over 0-90 in 1° steps: flux π I0 up to the
        // linear interpolation of cos (error below 1e-4 relative at 1°).
        let g: Vec<f64> = (0..=90).map(|i| i as f64).collect();
        let cd: Vec<f64> = g.iter().map(|a| 1000.0 * a.to_radians().cos()).collect();
        let (t, _) = IntensityTable::from_file_angles(PhotometricType::C, &[0.0], &g, &cd).unwrap();
        assert!((t.flux() / (1000.0 * std::f64::consts::PI) - 1.0).abs() < 1e-4, "{}", t.flux());
    }

    #[test]
    fn frames_of_the_three_types() {
        // A beam only at (0°, 0°) of each type points along −Z; type C's C90 is +Y.
        let v: Vec<f64> = vec![0.0, 10.0, 90.0];
        let (c, _) = IntensityTable::from_file_angles(
            PhotometricType::C,
            &[0.0, 90.0, 180.0, 270.0, 360.0],
            &v,
            &[1.0, 0.0, 0.0, 5.0, 5.0, 5.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        )
        .unwrap();
        assert!((c.eval(Vec3::NEG_Z) - 1.0).abs() < 1e-6);
        assert!((c.eval(Vec3::Y) - 5.0).abs() < 1e-6);
        assert!(c.eval(Vec3::X).abs() < 1e-6);
        for kind in [PhotometricType::A, PhotometricType::B] {
            let (t, _) =
                IntensityTable::from_file_angles(kind, &[-90.0, 0.0, 90.0], &[-90.0, 0.0, 90.0], &[0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0, 0.0]).unwrap();
            assert!((t.eval(Vec3::NEG_Z) - 7.0).abs() < 1e-5, "{kind:?}");
            assert!(t.eval(Vec3::Z).abs() < 1e-6);
            // Halfway to +X by H = 45°.
            assert!((t.eval_angles(45.0, 0.0) - 3.5).abs() < 1e-4, "{kind:?} {}", t.eval_angles(45.0, 0.0));
            let d = Vec3::new(1.0, 0.0, -1.0).normalize();
            assert!((t.eval(d) - 3.5).abs() < 1e-4);
        }
    }

    #[test]
    fn symmetric_expansions_agree_with_full_tables() {
        let v = [0.0, 45.0, 90.0];
        // Quadrant data: C0 = [3,2,1], C90 = [6,4,2].
        let (q, _) = IntensityTable::from_file_angles(PhotometricType::C, &[0.0, 90.0], &v, &[3.0, 2.0, 1.0, 6.0, 4.0, 2.0]).unwrap();
        for (c, want) in [(0.0, 3.0), (90.0, 6.0), (180.0, 3.0), (270.0, 6.0), (45.0, 4.5), (135.0, 4.5), (315.0, 4.5)] {
            assert!((q.eval_angles(c, 0.0) - 3.0).abs() < 1e-5);
            assert!((q.eval_angles(c, 90.0 - 1e-9) - want / 3.0).abs() < 1e-4, "C{c}");
        }
        let (b, _) = IntensityTable::from_file_angles(PhotometricType::C, &[90.0, 180.0, 270.0], &v, &[1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 3.0, 3.0, 3.0]).unwrap();
        assert!((b.eval_angles(0.0, 45.0) - 2.0).abs() < 1e-5);
        assert!((b.eval_angles(300.0, 45.0) - b.eval_angles(240.0, 45.0)).abs() < 1e-5);
        assert!(IntensityTable::from_file_angles(PhotometricType::C, &[0.0, 45.0], &v, &[1.0; 6]).is_err());
    }
}
