//! Emission samples of eight light paths' starts as one eight-lane vector step, for the
//! lanes whose light is a mesh area light of constant radiance and whose chosen triangle
//! has a precomputed frame (`AreaLight::sample_le`'s framed case): the point on the
//! triangle, the cosine-weighted direction, its density and the offset origin. Light
//! tracing's lockstep lanes start their paths here together; each lane's numbers are
//! `sample_le`'s bit for bit (the same operations in the same order, branches as selects;
//! a test compares them). The triangle and the light are chosen lane by lane before.
//!
//! As `path::step8`: plain arrays, no `bool` array, and `#[inline(never)]` copies per
//! instruction set (inlined into its caller the loop stayed scalar).

use super::area::AreaLight;
use super::EmissionSample;
use crate::accel::packet::LANES;
use crate::geometry::Ray;
use crate::math::lane::{cosine_hemisphere, offset3};
use crate::math::INV_PI;
use glam::{Vec2, Vec3};

/// What [`emit8`] reads of a lane (plain arrays only).
#[derive(Clone, Default)]
struct EmitNums {
    /// The chosen triangle: its first vertex and two edges, and its frame.
    p0: [[f32; LANES]; 3],
    e1: [[f32; LANES]; 3],
    e2: [[f32; LANES]; 3],
    fs: [[f32; LANES]; 3],
    ft: [[f32; LANES]; 3],
    fnn: [[f32; LANES]; 3],
    /// The point's numbers (the triangle choice's remapped one, the second) and the
    /// direction's.
    u_pos: [[f32; LANES]; 2],
    u_dir: [[f32; LANES]; 2],
}

/// What [`emit8`] writes per lane.
#[derive(Clone, Default)]
struct EmitOut {
    o: [[f32; LANES]; 3],
    d: [[f32; LANES]; 3],
    pdf_dir: [f32; LANES],
}

/// The lanes of one step: gathered lane by lane ([`Self::gather`]), sampled together
/// ([`Self::run`]), read lane by lane ([`Self::sample`]).
pub(crate) struct EmitLanes {
    v: EmitNums,
    o: EmitOut,
    /// Lanes gathered since the last [`Self::clear`].
    lanes: u8,
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    avx512: bool,
}

impl Default for EmitLanes {
    fn default() -> Self {
        EmitLanes { v: EmitNums::default(), o: EmitOut::default(), lanes: 0, avx512: crate::cpu::avx512() }
    }
}

impl EmitLanes {
    /// Lane `l`'s emission sample from `light` with the numbers `sample_le` takes, into the
    /// lanes where the step computes it (true); false: the caller samples it alone.
    #[inline]
    pub fn gather(&mut self, l: usize, light: &AreaLight, u_pos: Vec2, u_dir: Vec2) -> bool {
        let Some((tri, frame, ur)) = light.framed_triangle(u_pos) else { return false };
        let x = &mut self.v;
        let put = |a: &mut [[f32; LANES]; 3], w: Vec3| {
            a[0][l] = w.x;
            a[1][l] = w.y;
            a[2][l] = w.z;
        };
        put(&mut x.p0, tri[0]);
        put(&mut x.e1, tri[1]);
        put(&mut x.e2, tri[2]);
        put(&mut x.fs, frame.s);
        put(&mut x.ft, frame.t);
        put(&mut x.fnn, frame.n);
        x.u_pos[0][l] = ur;
        x.u_pos[1][l] = u_pos.y;
        x.u_dir[0][l] = u_dir.x;
        x.u_dir[1][l] = u_dir.y;
        self.lanes |= 1 << l;
        true
    }

    /// Whether lane `l` was gathered since the last [`Self::clear`].
    #[inline]
    pub fn has(&self, l: usize) -> bool {
        self.lanes & (1 << l) != 0
    }

    /// The gathered lanes' samples.
    #[inline]
    pub fn run(&mut self) {
        if self.lanes == 0 {
            return;
        }
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: `cpu::avx512()` checked the CPU, and AVX2 is checked here.
            if self.avx512 {
                return unsafe { emit8_avx512(&self.v, &mut self.o) };
            }
            if crate::cpu::avx2() {
                return unsafe { emit8_avx2(&self.v, &mut self.o) };
            }
        }
        emit8(&self.v, &mut self.o)
    }

    /// After [`Self::run`]: gathered lane `l`'s sample, `light.sample_le(.., time)`'s.
    #[inline]
    pub fn sample(&self, l: usize, light: &AreaLight, time: f32) -> EmissionSample {
        debug_assert!(self.has(l));
        let (v, o) = (&self.v, &self.o);
        let get = |a: &[[f32; LANES]; 3]| Vec3::new(a[0][l], a[1][l], a[2][l]);
        let mut ray = Ray::new(get(&o.o), get(&o.d));
        ray.time = time;
        light.framed_emission(ray, get(&v.fnn), o.pdf_dir[l])
    }

    /// Empties the lanes for the next step.
    #[inline]
    pub fn clear(&mut self) {
        self.lanes = 0;
    }
}

/// `AreaLight::sample_le`'s framed case for eight lanes: `square_to_uniform_triangle`, the
/// point, `square_to_cosine_hemisphere` and its density, `Frame::to_world`,
/// `offset_ray_origin`.
#[inline(always)]
fn emit8(v: &EmitNums, o: &mut EmitOut) {
    for l in 0..LANES {
        let g = |a: &[[f32; LANES]; 3]| [a[0][l], a[1][l], a[2][l]];
        let (p0, e1, e2, fs, ft, fnn) = (g(&v.p0), g(&v.e1), g(&v.e2), g(&v.fs), g(&v.ft), g(&v.fnn));
        // Heitz's triangle map: b0 = ux / 2, b1 = uy - b0 below the diagonal, else
        // b1 = uy / 2, b0 = ux - b1.
        let (ux, uy) = (v.u_pos[0][l], v.u_pos[1][l]);
        let below = ux < uy;
        let half = (if below { ux } else { uy }) / 2.0;
        let (b0, b1) = if below { (half, uy - half) } else { (ux - half, half) };
        let p = [(p0[0] + e1[0] * b0) + e2[0] * b1, (p0[1] + e1[1] * b0) + e2[1] * b1, (p0[2] + e1[2] * b0) + e2[2] * b1];
        let w = cosine_hemisphere(v.u_dir[0][l], v.u_dir[1][l]);
        o.pdf_dir[l] = w[2].max(0.0) * INV_PI;
        let d = [(fs[0] * w[0] + ft[0] * w[1]) + fnn[0] * w[2], (fs[1] * w[0] + ft[1] * w[1]) + fnn[1] * w[2], (fs[2] * w[0] + ft[2] * w[1]) + fnn[2] * w[2]];
        let origin = offset3(p, fnn, d);
        for k in 0..3 {
            o.o[k][l] = origin[k];
            o.d[k][l] = d[k];
        }
    }
}

/// [`emit8`] compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline(never)]
unsafe fn emit8_avx2(v: &EmitNums, o: &mut EmitOut) {
    emit8(v, o)
}

/// [`emit8`] compiled for AVX-512VL (the same 256-bit code, 32 vector registers).
///
/// # Safety
/// The CPU must support AVX2, AVX-512F and AVX-512VL.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
#[inline(never)]
unsafe fn emit8_avx512(v: &EmitNums, o: &mut EmitOut) {
    emit8(v, o)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Geometry, TriangleMesh};
    use crate::sampling::Pcg32;
    use crate::spectrum::Rgb;
    use crate::texture::Texture;
    use std::sync::Arc;

    /// The samples' bits: ray, radiance, densities, normal.
    fn bits(es: &EmissionSample) -> Vec<u32> {
        let mut b: Vec<u32> = [es.ray.o, es.ray.d, es.n].iter().flat_map(|v| v.to_array()).map(f32::to_bits).collect();
        b.extend([es.ray.t_max, es.ray.time, es.le.r, es.le.g, es.le.b, es.pdf_pos, es.pdf_dir].map(f32::to_bits));
        b
    }

    /// Eight lanes sampled together give `AreaLight::sample_le`'s samples bit for bit (every
    /// copy of the step): mesh lights of flat triangles far from the origin and near it,
    /// their normals flipped by vertex normals, a triangle of no area, one without a frame
    /// (not gathered), and the numbers' ends and diagonals as well as random ones.
    #[test]
    fn emit8_is_sample_le() {
        let mut rng = Pcg32::new(7, 5);
        let mut f = move || rng.next_f32();
        let ends = [0.0, 0.5, 0.25, 0.75, crate::math::ONE_MINUS_EPSILON, 1e-7];
        let (mut gathered, mut alone) = (0, 0);
        for round in 0..400 {
            let scale = if round % 3 == 0 { 1000.0 } else { 2.0 };
            let mut positions: Vec<Vec3> = (0..6).map(|_| Vec3::new(f() - 0.5, f() - 0.5, f() - 0.5) * scale).collect();
            positions[5] = positions[4];
            let indices = vec![[0, 1, 2], [0, 2, 3], [1, 3, 4], [3, 4, 5]];
            let up = (positions[1] - positions[0]).cross(positions[2] - positions[0]).normalize();
            let normals = match round % 3 {
                0 => Vec::new(),
                1 => vec![-up; 6],
                // Normals across the first triangle's plane: it has no frame.
                _ => vec![up, up, -up, up, up, up],
            };
            let mesh = TriangleMesh { positions, normals, uvs: Vec::new(), indices };
            let light = AreaLight::new(0, Arc::new(Geometry::Mesh(mesh)), Texture::Constant(Rgb::new(1.0, 2.0, 3.0)));
            let mut lanes = EmitLanes::default();
            let mut u = |k: usize| if (round + k).is_multiple_of(4) { ends[(round * 3 + k) % ends.len()] } else { f() };
            let us: Vec<(Vec2, Vec2)> = (0..LANES).map(|k| (Vec2::new(u(k), u(k + 1)), Vec2::new(u(k + 2), u(k + 3)))).collect();
            let mut taken = [false; LANES];
            for (l, &(u_pos, u_dir)) in us.iter().enumerate() {
                taken[l] = lanes.gather(l, &light, u_pos, u_dir);
            }
            lanes.run();
            let mut copies = vec![EmitOut::default()];
            emit8(&lanes.v, &mut copies[0]);
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::avx2() {
                copies.push(EmitOut::default());
                // SAFETY: the CPU has AVX2.
                unsafe { emit8_avx2(&lanes.v, copies.last_mut().expect("pushed")) };
            }
            for (l, &(u_pos, u_dir)) in us.iter().enumerate() {
                let want = light.sample_le(u_pos, u_dir, 0.5);
                if !taken[l] {
                    alone += 1;
                    continue;
                }
                gathered += 1;
                let want = want.map(|es| bits(&es));
                let got = bits(&lanes.sample(l, &light, 0.5));
                // `sample_le` refuses a direction of no density; its walk does the same.
                let got = (lanes.o.pdf_dir[l] > 0.0).then_some(got);
                assert_eq!(got, want, "round {round} lane {l}");
                for o in &copies {
                    let g = |a: &[[f32; LANES]; 3]| [a[0][l], a[1][l], a[2][l]].map(f32::to_bits);
                    assert_eq!((g(&o.o), g(&o.d), o.pdf_dir[l].to_bits()), (g(&lanes.o.o), g(&lanes.o.d), lanes.o.pdf_dir[l].to_bits()));
                }
            }
            lanes.clear();
        }
        assert!(gathered > 2000 && alone > 100, "{gathered} {alone}");
    }
}
