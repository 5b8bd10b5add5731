//! pbrt-v4 shapes onto svetlo's geometry: triangle meshes as given; PLY files through the
//! project's PLY reader (quads split into two triangles); bilinear patches, partial spheres,
//! disks, cylinders and curves tessellated; Loop subdivision applied to its level; full
//! spheres kept analytic.
//!
//! Orientation follows pbrt: a mesh with normals faces them (ReverseOrientation negates
//! them); one without faces its winding, flipped by ReverseOrientation and by a mirroring
//! transform; quadrics face outward, flipped by either (pbrt flips their object-space normal
//! when the transform swaps handedness).

use super::lexer::Loc;
use super::params::ParamList;
use super::Loader;
use crate::error::Result;
use crate::geometry::{Geometry, Sphere, TriangleMesh};
use crate::io::mesh_files;
use crate::math::PI;
use crate::texture::Texture;
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::collections::HashMap;

/// Segments of tessellated curved shapes over a full turn (as the Mitsuba loader's).
const SEGMENTS: usize = crate::geometry::shapes::CIRCLE_SEGMENTS;
/// Steps along each parameter of a non-planar bilinear patch.
pub const BILINEAR_STEPS: usize = 16;

impl Loader {
    pub(super) fn shape(&mut self, ty: &str, p: &ParamList, loc: &Loc) -> Result<()> {
        let m = self.gs.ctm[0];
        let reverse = self.gs.reverse_orientation;
        let mirrored = m.determinant() < 0.0;
        // pbrt's alpha cuts the surface out stochastically: Mitsuba's mask, the surface
        // present with probability alpha.
        let mut alpha = None;
        if p.get("alpha").is_some() {
            let a = self.float_param(p, "alpha", 1.0)?;
            match a {
                Texture::Constant(c) if c.r <= 0.0 => return Ok(()), // fully transparent: pbrt drops the shape
                Texture::Constant(c) if c.r >= 1.0 => {}
                t => alpha = Some(t),
            }
        }
        for k in ["emission", "displacement", "edgelength"] {
            if p.get(k).is_some() {
                self.warn(loc, format!("Shape '{ty}': '{k}' is not supported; ignored"));
            }
        }
        let geometry = match ty {
            "trianglemesh" => {
                let mesh = triangle_mesh(p, loc)?;
                Geometry::Mesh(place(mesh, &m, reverse, false))
            }
            "plymesh" => {
                let name = p.string("filename")?.ok_or_else(|| loc.err("plymesh needs a \"string filename\""))?;
                let path = self.resolve(name, loc);
                let bytes = super::read_bytes(&path, Some(loc))?;
                let loaded = mesh_files::load_ply_bytes(&bytes, &path, false)?;
                for w in loaded.warnings {
                    self.warn(loc, w);
                }
                Geometry::Mesh(place(loaded.mesh, &m, reverse, false))
            }
            "bilinearmesh" => {
                let mesh = bilinear_mesh(p, loc)?;
                Geometry::Mesh(place(mesh, &m, reverse, false))
            }
            "loopsubdiv" => {
                let levels = p.int("levels", 3)?;
                if !(0..=8).contains(&levels) {
                    return Err(loc.err(format!("loopsubdiv: levels must be between 0 and 8, got {levels}")));
                }
                let mut mesh = triangle_mesh(p, loc)?;
                // Each level quadruples the triangles: refuse before building what cannot fit.
                let tris = mesh.indices.len() as u64;
                crate::limits::check_items(format!("{}: loopsubdiv of {tris} triangles to level {levels}", loc.at()), tris << (2 * levels), 64)?;
                for _ in 0..levels {
                    mesh = loop_subdivide(&mesh);
                }
                mesh_files::compute_vertex_normals(&mut mesh);
                mesh.uvs.clear();
                Geometry::Mesh(place(mesh, &m, reverse, false))
            }
            "sphere" => {
                let r = positive(p.float("radius", 1.0)?, "radius", loc)?;
                let zmin = p.float("zmin", -r)?.clamp(-r, r);
                let zmax = p.float("zmax", r)?.clamp(-r, r);
                let phimax = p.float("phimax", 360.0)?.clamp(0.0, 360.0);
                let flip = reverse ^ mirrored;
                let full = zmin <= -r && zmax >= r && phimax >= 360.0;
                match (full, similarity(&m)) {
                    (true, Some(s)) => Geometry::Sphere(Sphere { center: m.transform_point3(Vec3::ZERO), radius: r * s, flip_normals: flip }),
                    _ => {
                        let (t0, t1) = ((zmin / r).clamp(-1.0, 1.0).acos(), (zmax / r).clamp(-1.0, 1.0).acos());
                        let mesh = grid(SEGMENTS / 2, SEGMENTS / 4, |u, v| {
                            let phi = u * phimax.to_radians();
                            let theta = t0 + (t1 - t0) * v;
                            let n = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
                            (n * r, n)
                        });
                        Geometry::Mesh(place(mesh, &m, reverse, mirrored))
                    }
                }
            }
            "disk" => {
                let (h, r) = (p.float("height", 0.0)?, positive(p.float("radius", 1.0)?, "radius", loc)?);
                let ri = p.float("innerradius", 0.0)?.clamp(0.0, r);
                let phimax = p.float("phimax", 360.0)?.clamp(0.0, 360.0).to_radians();
                let mesh = grid(SEGMENTS, 8, |u, v| {
                    let phi = u * phimax;
                    let rad = r + (ri - r) * v;
                    (Vec3::new(rad * phi.cos(), rad * phi.sin(), h), Vec3::Z)
                });
                Geometry::Mesh(place(mesh, &m, reverse, mirrored))
            }
            "cylinder" => {
                let r = positive(p.float("radius", 1.0)?, "radius", loc)?;
                let (z0, z1) = (p.float("zmin", -1.0)?, p.float("zmax", 1.0)?);
                let phimax = p.float("phimax", 360.0)?.clamp(0.0, 360.0).to_radians();
                let mesh = grid(SEGMENTS, 1, |u, v| {
                    let phi = u * phimax;
                    let n = Vec3::new(phi.cos(), phi.sin(), 0.0);
                    (Vec3::new(r * n.x, r * n.y, z0 + (z1 - z0) * v), n)
                });
                Geometry::Mesh(place(mesh, &m, reverse, mirrored))
            }
            "curve" => {
                let mesh = curve(p, loc)?;
                Geometry::Mesh(place(mesh, &m, reverse, false))
            }
            "cone" | "paraboloid" | "hyperboloid" | "nurbs" | "heightfield" => {
                return Err(loc.err(format!("shape '{ty}' is pbrt-v3 only (pbrt-v4 removed it)")));
            }
            other => return Err(loc.err(format!("unknown shape '{other}'"))),
        };
        self.warn_unused(&format!("Shape \"{ty}\""), p);
        self.emit_shape(geometry, loc, ty, alpha)
    }
}

fn positive(v: f32, name: &str, loc: &Loc) -> Result<f32> {
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(loc.err(format!("'{name}' must be positive, got {v}")))
    }
}

/// The uniform scale of `m` if its linear part is a rotation times it (mirrors allowed).
fn similarity(m: &Mat4) -> Option<f32> {
    let l = Mat3::from_mat4(*m);
    let s = l.determinant().abs().cbrt();
    if !(s > 0.0 && s.is_finite()) {
        return None;
    }
    let q = l / s;
    (q.transpose() * q - Mat3::IDENTITY).to_cols_array().iter().all(|v| v.abs() < 1e-4).then_some(s)
}

/// An object-space mesh into the world: transformed, and its normals negated when pbrt
/// would flip the surface (`reverse` xor `quadric_mirror`).
fn place(mut mesh: TriangleMesh, m: &Mat4, reverse: bool, quadric_mirror: bool) -> TriangleMesh {
    mesh.transform(m);
    if reverse {
        for t in &mut mesh.indices {
            t.swap(1, 2);
        }
    }
    if reverse ^ quadric_mirror {
        for n in &mut mesh.normals {
            *n = -*n;
        }
    }
    mesh
}

/// A (cols+1) × (rows+1) vertex grid over (u, v) in [0,1]², uv = (u, v).
fn grid(cols: usize, rows: usize, f: impl Fn(f32, f32) -> (Vec3, Vec3)) -> TriangleMesh {
    let mut m = TriangleMesh::default();
    for j in 0..=rows {
        for i in 0..=cols {
            let (u, v) = (i as f32 / cols as f32, j as f32 / rows as f32);
            let (p, n) = f(u, v);
            m.positions.push(p);
            m.normals.push(n);
            m.uvs.push(Vec2::new(u, v));
        }
    }
    let w = cols as u32 + 1;
    for j in 0..rows as u32 {
        for i in 0..cols as u32 {
            let (a, b, c, d) = (j * w + i, j * w + i + 1, (j + 1) * w + i, (j + 1) * w + i + 1);
            m.indices.push([a, b, d]);
            m.indices.push([a, d, c]);
        }
    }
    m
}

/// Indices of a mesh shape: `integer indices` in groups of `k`, or 0..k when there are
/// exactly k vertices and no indices.
fn indices(p: &ParamList, loc: &Loc, nv: usize, k: usize, what: &str) -> Result<Vec<u32>> {
    let idx = match p.ints("indices")? {
        Some((_, v)) => v,
        None if nv == k => (0..k as i64).collect(),
        None => return Err(loc.err(format!("{what} needs \"integer indices\" (it has {nv} vertices)"))),
    };
    if idx.is_empty() || idx.len() % k != 0 {
        return Err(loc.err(format!("{what}: {} indices are not a whole number of {k}-vertex faces", idx.len())));
    }
    if let Some(bad) = idx.iter().find(|&&i| i < 0 || i as usize >= nv) {
        return Err(loc.err(format!("{what}: index {bad} out of range (there are {nv} vertices)")));
    }
    Ok(idx.into_iter().map(|i| i as u32).collect())
}

/// Per-vertex attributes of a mesh (`N`, `uv`): kept when their count matches.
fn attributes(p: &ParamList, loc: &Loc, nv: usize, what: &str) -> Result<(Vec<Vec3>, Vec<Vec2>)> {
    let n = p.points3("N")?.unwrap_or_default();
    let uv = match p.points2("uv")? {
        Some(v) => v,
        None => p.points2("st")?.unwrap_or_default(),
    };
    if !n.is_empty() && n.len() != nv {
        return Err(loc.err(format!("{what}: {} normals for {nv} vertices", n.len())));
    }
    if !uv.is_empty() && uv.len() != nv {
        return Err(loc.err(format!("{what}: {} uvs for {nv} vertices", uv.len())));
    }
    for k in ["S", "faceIndices"] {
        let _ = p.get(k);
    }
    Ok((n, uv))
}

fn triangle_mesh(p: &ParamList, loc: &Loc) -> Result<TriangleMesh> {
    let positions = p.points3("P")?.ok_or_else(|| loc.err("trianglemesh needs \"point3 P\""))?;
    let idx = indices(p, loc, positions.len(), 3, "trianglemesh")?;
    let (normals, uvs) = attributes(p, loc, positions.len(), "trianglemesh")?;
    Ok(TriangleMesh { positions, normals, uvs, indices: idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect() })
}

/// Bilinear patches (vertices p00 p10 p01 p11): planar ones as two triangles (exact), others
/// as a BILINEAR_STEPS² grid of the bilinear surface, with its interpolated normals and uvs.
fn bilinear_mesh(p: &ParamList, loc: &Loc) -> Result<TriangleMesh> {
    let pos = p.points3("P")?.ok_or_else(|| loc.err("bilinearmesh needs \"point3 P\""))?;
    let idx = indices(p, loc, pos.len(), 4, "bilinearmesh")?;
    let (normals, uvs) = attributes(p, loc, pos.len(), "bilinearmesh")?;
    let mut out = TriangleMesh::default();
    let with_n = !normals.is_empty();
    for q in idx.chunks_exact(4) {
        let c = [q[0] as usize, q[1] as usize, q[2] as usize, q[3] as usize];
        let [p00, p10, p01, p11] = c.map(|i| pos[i]);
        let uvq = if uvs.is_empty() { [Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0)] } else { c.map(|i| uvs[i]) };
        let nq = if with_n { Some(c.map(|i| normals[i])) } else { None };
        let planar = (p11 - p00).dot((p10 - p00).cross(p01 - p00)).abs() <= 1e-6 * (p10 - p00).length() * (p01 - p00).length() * (p11 - p00).length();
        let steps = if planar { 1 } else { BILINEAR_STEPS };
        let lerp2 = |a: Vec3, b: Vec3, cc: Vec3, d: Vec3, u: f32, v: f32| (a * (1.0 - u) + b * u) * (1.0 - v) + (cc * (1.0 - u) + d * u) * v;
        let base = out.positions.len() as u32;
        for j in 0..=steps {
            for i in 0..=steps {
                let (u, v) = (i as f32 / steps as f32, j as f32 / steps as f32);
                let pp = lerp2(p00, p10, p01, p11, u, v);
                out.positions.push(pp);
                let t = (uvq[0] * (1.0 - u) + uvq[1] * u) * (1.0 - v) + (uvq[2] * (1.0 - u) + uvq[3] * u) * v;
                out.uvs.push(t);
                let n = match nq {
                    Some([a, b, cc, d]) => lerp2(a, b, cc, d, u, v).normalize_or_zero(),
                    // The patch's own normal, dp/du × dp/dv, as pbrt orients it.
                    None => {
                        let dpdu = (p10 - p00) * (1.0 - v) + (p11 - p01) * v;
                        let dpdv = (p01 - p00) * (1.0 - u) + (p11 - p10) * u;
                        dpdu.cross(dpdv).normalize_or_zero()
                    }
                };
                out.normals.push(n);
            }
        }
        let w = steps as u32 + 1;
        for j in 0..steps as u32 {
            for i in 0..steps as u32 {
                let (a, b, cc, d) = (base + j * w + i, base + j * w + i + 1, base + (j + 1) * w + i, base + (j + 1) * w + i + 1);
                out.indices.push([a, b, d]);
                out.indices.push([a, d, cc]);
            }
        }
    }
    Ok(out)
}

/// One level of Loop subdivision (Loop 1987, with Warren's weights as pbrt uses them:
/// β = 3/16 for valence 3, 3/(8n) otherwise; boundary vertices and edges by the cubic
/// B-spline rules). Positions only: the limit surface is approached as levels grow.
pub fn loop_subdivide(m: &TriangleMesh) -> TriangleMesh {
    let nv = m.positions.len();
    // Edge -> the vertices opposite it in its (one or two) faces.
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for t in &m.indices {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push(c);
        }
    }
    // Edges in sorted order, not the map's (seeded per process): a vertex's neighbours are
    // summed in this order, so the map's order would change the new positions' last bits.
    let mut keys: Vec<_> = edges.keys().copied().collect();
    keys.sort_unstable();
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); nv];
    let mut boundary_nb: Vec<Vec<u32>> = vec![Vec::new(); nv];
    for &(a, b) in &keys {
        let opp = &edges[&(a, b)];
        neighbours[a as usize].push(b);
        neighbours[b as usize].push(a);
        if opp.len() == 1 {
            boundary_nb[a as usize].push(b);
            boundary_nb[b as usize].push(a);
        }
    }
    let pos = &m.positions;
    let mut out = TriangleMesh::default();
    for v in 0..nv {
        let p = pos[v];
        let np = if boundary_nb[v].len() == 2 {
            p * 0.75 + (pos[boundary_nb[v][0] as usize] + pos[boundary_nb[v][1] as usize]) * 0.125
        } else if !boundary_nb[v].is_empty() || neighbours[v].is_empty() {
            p // a corner or non-manifold vertex stays
        } else {
            let n = neighbours[v].len() as f32;
            let beta = if neighbours[v].len() == 3 { 3.0 / 16.0 } else { 3.0 / (8.0 * n) };
            p * (1.0 - n * beta) + neighbours[v].iter().map(|&u| pos[u as usize]).sum::<Vec3>() * beta
        };
        out.positions.push(np);
    }
    let mut edge_vertex: HashMap<(u32, u32), u32> = HashMap::new();
    for (a, b) in keys {
        let opp = &edges[&(a, b)];
        let (pa, pb) = (pos[a as usize], pos[b as usize]);
        let p = if opp.len() == 2 { (pa + pb) * 0.375 + (pos[opp[0] as usize] + pos[opp[1] as usize]) * 0.125 } else { (pa + pb) * 0.5 };
        edge_vertex.insert((a, b), out.positions.len() as u32);
        out.positions.push(p);
    }
    let ev = |a: u32, b: u32| edge_vertex[&(a.min(b), a.max(b))];
    for t in &m.indices {
        let [a, b, c] = *t;
        let (ab, bc, ca) = (ev(a, b), ev(b, c), ev(c, a));
        out.indices.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    out
}

/// Curves as tessellated geometry: `cylinder` and `flat` as tubes of the curve's width
/// (a flat curve in pbrt always faces the ray; a tube has the same silhouette), `ribbon` as
/// a strip whose orientation follows the normals `N`. Cubic Bézier or B-spline segments.
fn curve(p: &ParamList, loc: &Loc) -> Result<TriangleMesh> {
    let cp = p.points3("P")?.ok_or_else(|| loc.err("curve needs \"point3 P\""))?;
    let basis = p.string("basis")?.unwrap_or("bezier").to_string();
    let degree = p.int("degree", 3)?;
    if degree != 3 {
        return Err(loc.err(format!("curve: only cubic curves (degree 3) are supported, got degree {degree}")));
    }
    let segs: Vec<[Vec3; 4]> = match basis.as_str() {
        "bezier" => {
            if cp.len() < 4 || (cp.len() - 1) % 3 != 0 {
                return Err(loc.err(format!("curve: a cubic Bézier needs 3n+1 control points, got {}", cp.len())));
            }
            (0..(cp.len() - 1) / 3).map(|i| [cp[3 * i], cp[3 * i + 1], cp[3 * i + 2], cp[3 * i + 3]]).collect()
        }
        "bspline" => {
            if cp.len() < 4 {
                return Err(loc.err("curve: a cubic B-spline needs at least 4 control points"));
            }
            // Uniform B-spline segments to Bézier control points.
            (0..cp.len() - 3)
                .map(|i| {
                    let (p0, p1, p2, p3) = (cp[i], cp[i + 1], cp[i + 2], cp[i + 3]);
                    [(p0 + p1 * 4.0 + p2) / 6.0, (p1 * 2.0 + p2) / 3.0, (p1 + p2 * 2.0) / 3.0, (p1 + p2 * 4.0 + p3) / 6.0]
                })
                .collect()
        }
        other => return Err(loc.err(format!("curve: unknown basis '{other}' (bezier, bspline)"))),
    };
    let w = p.float("width", 1.0)?;
    let (w0, w1) = (p.float("width0", w)?, p.float("width1", w)?);
    let ty = p.string("type")?.unwrap_or("flat").to_string();
    let normals = p.points3("N")?;
    let _ = p.int("splitdepth", 3)?;
    let n_seg = segs.len();
    let steps = 16;
    let mut out = TriangleMesh::default();
    let around = if ty == "ribbon" { 1 } else { 12 };
    for (si, s) in segs.iter().enumerate() {
        let bez = |t: f32| {
            let it = 1.0 - t;
            s[0] * (it * it * it) + s[1] * (3.0 * it * it * t) + s[2] * (3.0 * it * t * t) + s[3] * (t * t * t)
        };
        let dbez = |t: f32| {
            let it = 1.0 - t;
            (s[1] - s[0]) * (3.0 * it * it) + (s[2] - s[1]) * (6.0 * it * t) + (s[3] - s[2]) * (3.0 * t * t)
        };
        let base = out.positions.len() as u32;
        for k in 0..=steps {
            let t = k as f32 / steps as f32;
            let g = (si as f32 + t) / n_seg as f32;
            let radius = 0.5 * (w0 + (w1 - w0) * g);
            let c = bez(t);
            let tan = dbez(t).normalize_or_zero();
            let tan = if tan == Vec3::ZERO { Vec3::Z } else { tan };
            if ty == "ribbon" {
                let n = match &normals {
                    Some(ns) if ns.len() == n_seg + 1 => (ns[si] * (1.0 - t) + ns[si + 1] * t).normalize_or_zero(),
                    _ => return Err(loc.err("curve: a ribbon needs \"normal N\" with one normal per segment end")),
                };
                let side = n.cross(tan).normalize_or_zero() * radius;
                for (e, sgn) in [(0, -1.0f32), (1, 1.0)] {
                    out.positions.push(c + side * sgn);
                    out.normals.push(n);
                    out.uvs.push(Vec2::new(g, e as f32));
                }
            } else {
                let f = crate::math::Frame::from_normal(tan);
                for a in 0..=around {
                    let phi = 2.0 * PI * a as f32 / around as f32;
                    let dir = f.s * phi.cos() + f.t * phi.sin();
                    out.positions.push(c + dir * radius);
                    out.normals.push(dir);
                    out.uvs.push(Vec2::new(g, a as f32 / around as f32));
                }
            }
        }
        let ring = around as u32 + 1;
        for k in 0..steps as u32 {
            for a in 0..around as u32 {
                let (i0, i1) = (base + k * ring + a, base + (k + 1) * ring + a);
                out.indices.push([i0, i0 + 1, i1 + 1]);
                out.indices.push([i0, i1 + 1, i1]);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Loop subdivision of a tetrahedron keeps it closed (every edge in two faces), shrinks
    /// it toward its centroid, and quadruples its faces per level.
    #[test]
    fn loop_subdivision_is_closed_and_smooths() {
        let m = TriangleMesh {
            positions: vec![Vec3::new(1.0, 1.0, 1.0), Vec3::new(-1.0, -1.0, 1.0), Vec3::new(-1.0, 1.0, -1.0), Vec3::new(1.0, -1.0, -1.0)],
            indices: vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]],
            ..Default::default()
        };
        let s = loop_subdivide(&loop_subdivide(&m));
        assert_eq!(s.indices.len(), 64);
        assert_eq!(s.positions.len(), 4 + 6 + 24); // V' = V + E per level: 4+6=10, 10+24=34
        let mut count: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &s.indices {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        assert!(count.values().all(|&c| c == 2));
        let rmax = s.positions.iter().map(|p| p.length()).fold(0.0f32, f32::max);
        assert!(rmax < 3f32.sqrt() * 0.9, "corners pulled in: {rmax}");
    }

    /// The same mesh subdivides to the same bits every time: the edge map's order (seeded
    /// anew for each map) must not reach the sums over a vertex's neighbours.
    #[test]
    fn loop_subdivision_is_deterministic() {
        // An octahedron: valence 4 everywhere, so each vertex sums four neighbours.
        let p = [Vec3::X, -Vec3::X, Vec3::Y * 0.7, -Vec3::Y * 1.3, Vec3::Z * 0.9, -Vec3::Z * 1.1];
        let m = TriangleMesh {
            positions: p.to_vec(),
            indices: vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]],
            ..Default::default()
        };
        let bits = |m: &TriangleMesh| m.positions.iter().flat_map(|v| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()]).collect::<Vec<_>>();
        let first = bits(&loop_subdivide(&loop_subdivide(&m)));
        for _ in 0..32 {
            assert_eq!(bits(&loop_subdivide(&loop_subdivide(&m))), first);
        }
    }

    #[test]
    fn grid_spans_its_domain() {
        let g = grid(4, 2, |u, v| (Vec3::new(u, v, 0.0), Vec3::Z));
        assert_eq!(g.indices.len(), 16);
        assert!((g.area() - 1.0).abs() < 1e-6);
    }
}
