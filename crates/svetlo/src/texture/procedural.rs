//! pbrt-v4's procedural textures, evaluated at a surface point's uv, world position and
//! geometric normal ([`TexPoint`]): `bilerp`, `directionmix`, `dots`, `fbm`, `wrinkled`,
//! `windy`, `marble`, the `mix` and `scale` of textured inputs, and other textures seen
//! through pbrt's 2-D mappings (uv, spherical, cylindrical, planar).
//!
//! * 2-D mappings give pbrt's (s, t): uv: (su u + du, sv v + dv); spherical: (θ/π, φ/2π) of
//!   the direction from the texture space's origin (θ from +z); cylindrical:
//!   ((π + atan2(y, x)) / 2π, z); planar: (ds + p·v1, dt + p·v2). Texture space is the
//!   CTM at the `Texture` directive (`world_to_texture` is its inverse), as in pbrt.
//! * 3-D textures read the texture-space point (pbrt's PointTransformMapping).
//! * No ray differentials: noise is the zero-footprint sum (see `noise.rs`), so fine octaves
//!   alias at a distance where pbrt would fade them out.
//! * Points that carry no position or normal (the rasteriser, radiosity's albedo, an area
//!   light's emission, which svetlo looks up by uv alone) read the texture at p = 0, n = 0.

use super::noise::{fbm, noise2, turbulence};
use super::{TexPoint, Texture};
use crate::math::{INV_2PI, INV_PI, PI};
use crate::spectrum::Rgb;
use glam::{Mat4, Vec2, Vec3};

/// pbrt's 2-D texture mappings.
#[derive(Clone, Debug, PartialEq)]
pub enum Mapping2D {
    Uv { su: f32, sv: f32, du: f32, dv: f32 },
    Spherical { world_to_texture: Mat4 },
    Cylindrical { world_to_texture: Mat4 },
    Planar { world_to_texture: Mat4, v1: Vec3, v2: Vec3, ds: f32, dt: f32 },
}

impl Mapping2D {
    pub const IDENTITY: Mapping2D = Mapping2D::Uv { su: 1.0, sv: 1.0, du: 0.0, dv: 0.0 };

    /// pbrt's (s, t) at a point.
    pub fn st(&self, p: &TexPoint) -> Vec2 {
        match self {
            Mapping2D::Uv { su, sv, du, dv } => Vec2::new(su * p.uv.x + du, sv * p.uv.y + dv),
            Mapping2D::Spherical { world_to_texture } => {
                let v = world_to_texture.transform_point3(p.p).normalize_or_zero();
                let theta = v.z.clamp(-1.0, 1.0).acos();
                let mut phi = v.y.atan2(v.x);
                if phi < 0.0 {
                    phi += 2.0 * PI;
                }
                Vec2::new(theta * INV_PI, phi * INV_2PI)
            }
            Mapping2D::Cylindrical { world_to_texture } => {
                let q = world_to_texture.transform_point3(p.p);
                Vec2::new((PI + q.y.atan2(q.x)) * INV_2PI, q.z)
            }
            Mapping2D::Planar { world_to_texture, v1, v2, ds, dt } => {
                let q = world_to_texture.transform_point3(p.p);
                Vec2::new(ds + q.dot(*v1), dt + q.dot(*v2))
            }
        }
    }
}

/// pbrt's marble spline: nine control colours, cubic Bézier segments.
const MARBLE: [[f32; 3]; 9] = [
    [0.58, 0.58, 0.6],
    [0.58, 0.58, 0.6],
    [0.58, 0.58, 0.6],
    [0.5, 0.5, 0.5],
    [0.6, 0.59, 0.58],
    [0.58, 0.58, 0.6],
    [0.58, 0.58, 0.6],
    [0.2, 0.2, 0.33],
    [0.58, 0.58, 0.6],
];

#[derive(Clone, Debug)]
pub enum Procedural {
    /// Bilinear in (s, t) between the corner values (not clamped: pbrt extrapolates).
    Bilerp {
        mapping: Mapping2D,
        v00: Rgb,
        v01: Rgb,
        v10: Rgb,
        v11: Rgb,
    },
    /// `a = |n · dir|`: a tex1 + (1 - a) tex2 (`dir` unit, in world space).
    DirectionMix {
        tex1: Texture,
        tex2: Texture,
        dir: Vec3,
    },
    /// Polka dots: one dot of radius 0.35 in about half the unit cells of (s, t).
    Dots {
        mapping: Mapping2D,
        inside: Texture,
        outside: Texture,
    },
    Fbm {
        world_to_texture: Mat4,
        omega: f32,
        octaves: u32,
    },
    Wrinkled {
        world_to_texture: Mat4,
        omega: f32,
        octaves: u32,
    },
    Windy {
        world_to_texture: Mat4,
    },
    Marble {
        world_to_texture: Mat4,
        omega: f32,
        octaves: u32,
        scale: f32,
        variation: f32,
    },
    /// (1 - amount) tex1 + amount tex2.
    Mix {
        tex1: Texture,
        tex2: Texture,
        amount: Texture,
    },
    Scale {
        tex: Texture,
        scale: Texture,
    },
    /// Another texture looked up at this mapping's (s, t) as its uv.
    Mapped {
        mapping: Mapping2D,
        inner: Texture,
    },
}

/// Whether (s, t) falls inside a dot (pbrt-v4's InsidePolkaDot).
pub fn inside_polka_dot(st: Vec2) -> bool {
    let (sc, tc) = ((st.x + 0.5).floor(), (st.y + 0.5).floor());
    if noise2(sc + 0.5, tc + 0.5) <= 0.0 {
        return false;
    }
    let radius = 0.35f32;
    let max_shift = 0.5 - radius;
    let centre = Vec2::new(sc + max_shift * noise2(sc + 1.5, tc + 2.8), tc + max_shift * noise2(sc + 4.5, tc + 9.8));
    (st - centre).length_squared() < radius * radius
}

fn marble_colour(t: f32) -> Rgb {
    let n = MARBLE.len() - 3;
    let first = ((t * n as f32).floor().max(0.0) as usize).min(n - 1);
    let t = t * n as f32 - first as f32;
    let c = |i: usize| Rgb::new(MARBLE[first + i][0], MARBLE[first + i][1], MARBLE[first + i][2]);
    // de Casteljau.
    let l = |a: Rgb, b: Rgb| a * (1.0 - t) + b * t;
    let (s0, s1, s2) = (l(c(0), c(1)), l(c(1), c(2)), l(c(2), c(3)));
    let (s0, s1) = (l(s0, s1), l(s1, s2));
    l(s0, s1) * 1.5
}

impl Procedural {
    /// pbrt-v4's name of the texture class.
    pub fn pbrt_name(&self) -> &'static str {
        match self {
            Procedural::Bilerp { .. } => "bilerp",
            Procedural::DirectionMix { .. } => "directionmix",
            Procedural::Dots { .. } => "dots",
            Procedural::Fbm { .. } => "fbm",
            Procedural::Wrinkled { .. } => "wrinkled",
            Procedural::Windy { .. } => "windy",
            Procedural::Marble { .. } => "marble",
            Procedural::Mix { .. } => "mix",
            Procedural::Scale { .. } => "scale",
            Procedural::Mapped { .. } => "mapped",
        }
    }

    pub fn eval(&self, p: &TexPoint) -> Rgb {
        let tex_point = |m: &Mat4| m.transform_point3(p.p);
        match self {
            Procedural::Bilerp { mapping, v00, v01, v10, v11 } => {
                let st = mapping.st(p);
                let (s, t) = (st.x, st.y);
                *v00 * ((1.0 - s) * (1.0 - t)) + *v10 * (s * (1.0 - t)) + *v01 * ((1.0 - s) * t) + *v11 * (s * t)
            }
            Procedural::DirectionMix { tex1, tex2, dir } => {
                let a = p.n.dot(*dir).abs().min(1.0);
                let t1 = if a != 0.0 { tex1.eval(*p) } else { Rgb::BLACK };
                let t2 = if a != 1.0 { tex2.eval(*p) } else { Rgb::BLACK };
                t1 * a + t2 * (1.0 - a)
            }
            Procedural::Dots { mapping, inside, outside } => {
                if inside_polka_dot(mapping.st(p)) {
                    inside.eval(*p)
                } else {
                    outside.eval(*p)
                }
            }
            Procedural::Fbm { world_to_texture, omega, octaves } => Rgb::splat(fbm(tex_point(world_to_texture), *omega, *octaves)),
            Procedural::Wrinkled { world_to_texture, omega, octaves } => Rgb::splat(turbulence(tex_point(world_to_texture), *omega, *octaves)),
            Procedural::Windy { world_to_texture } => {
                let q = tex_point(world_to_texture);
                Rgb::splat(fbm(0.1 * q, 0.5, 3).abs() * fbm(q, 0.5, 6))
            }
            Procedural::Marble { world_to_texture, omega, octaves, scale, variation } => {
                let q = tex_point(world_to_texture) * *scale;
                let m = q.y + variation * fbm(q, *omega, *octaves);
                marble_colour(0.5 + 0.5 * m.sin())
            }
            Procedural::Mix { tex1, tex2, amount } => {
                let a = amount.eval_f32(*p);
                tex1.eval(*p) * (1.0 - a) + tex2.eval(*p) * a
            }
            Procedural::Scale { tex, scale } => tex.eval(*p) * scale.eval_f32(*p),
            Procedural::Mapped { mapping, inner } => inner.eval(TexPoint { uv: mapping.st(p), ..*p }),
        }
    }

    /// An estimate of the mean, for light power and radiosity albedo: exact for bilerp over
    /// the unit square; the noise textures by their value at a fixed set of 512 points of
    /// texture space; the dots by their area fraction (about half the cells hold a dot).
    pub fn mean(&self) -> Rgb {
        let sampled = |f: &dyn Fn(Vec3) -> Rgb| {
            let mut s = Rgb::BLACK;
            for i in 0..512u32 {
                // A fixed lattice offset off the integer points (noise is zero on them).
                let q = Vec3::new((i % 8) as f32 * 1.37 + 0.31, ((i / 8) % 8) as f32 * 1.37 + 0.17, (i / 64) as f32 * 1.37 + 0.43);
                s += f(q);
            }
            s / 512.0
        };
        match self {
            Procedural::Bilerp { v00, v01, v10, v11, .. } => (*v00 + *v01 + *v10 + *v11) * 0.25,
            Procedural::DirectionMix { tex1, tex2, .. } => (tex1.mean() + tex2.mean()) * 0.5,
            Procedural::Dots { inside, outside, .. } => {
                let f = 0.5 * PI * 0.35 * 0.35;
                inside.mean() * f + outside.mean() * (1.0 - f)
            }
            Procedural::Fbm { omega, octaves, .. } => sampled(&|q| Rgb::splat(fbm(q, *omega, *octaves))),
            Procedural::Wrinkled { omega, octaves, .. } => sampled(&|q| Rgb::splat(turbulence(q, *omega, *octaves))),
            Procedural::Windy { .. } => sampled(&|q| Rgb::splat(fbm(0.1 * q, 0.5, 3).abs() * fbm(q, 0.5, 6))),
            Procedural::Marble { omega, octaves, variation, .. } => sampled(&|q| marble_colour(0.5 + 0.5 * (q.y + variation * fbm(q, *omega, *octaves)).sin())),
            Procedural::Mix { tex1, tex2, amount } => {
                let a = amount.mean().luminance();
                tex1.mean() * (1.0 - a) + tex2.mean() * a
            }
            Procedural::Scale { tex, scale } => tex.mean() * scale.mean().luminance(),
            Procedural::Mapped { inner, .. } => inner.mean(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at_uv(u: f32, v: f32) -> TexPoint {
        TexPoint::from(Vec2::new(u, v))
    }

    #[test]
    fn bilerp_corners_and_centre() {
        let (a, b, c, d) = (Rgb::new(1.0, 0.0, 0.0), Rgb::new(0.0, 1.0, 0.0), Rgb::new(0.0, 0.0, 1.0), Rgb::splat(2.0));
        let t = Procedural::Bilerp { mapping: Mapping2D::IDENTITY, v00: a, v01: b, v10: c, v11: d };
        assert_eq!(t.eval(&at_uv(0.0, 0.0)), a);
        assert_eq!(t.eval(&at_uv(0.0, 1.0)), b);
        assert_eq!(t.eval(&at_uv(1.0, 0.0)), c);
        assert_eq!(t.eval(&at_uv(1.0, 1.0)), d);
        let m = t.eval(&at_uv(0.5, 0.5));
        assert!((m - (a + b + c + d) * 0.25).map(f32::abs).max_component() < 1e-6);
        assert_eq!(t.mean(), (a + b + c + d) * 0.25);
        // The uv mapping's scale and offset: s = 2u + 0.5.
        let t2 = Procedural::Bilerp { mapping: Mapping2D::Uv { su: 2.0, sv: 1.0, du: 0.5, dv: 0.0 }, v00: a, v01: b, v10: c, v11: d };
        assert_eq!(t2.eval(&at_uv(0.25, 0.0)), c);
    }

    #[test]
    fn directionmix_along_and_across() {
        let (r, g) = (Texture::from(Rgb::new(1.0, 0.0, 0.0)), Texture::from(Rgb::new(0.0, 1.0, 0.0)));
        let t = Procedural::DirectionMix { tex1: r, tex2: g, dir: Vec3::Y };
        let with_n = |n: Vec3| t.eval(&TexPoint { n, ..Default::default() });
        assert_eq!(with_n(Vec3::Y), Rgb::new(1.0, 0.0, 0.0));
        assert_eq!(with_n(-Vec3::Y), Rgb::new(1.0, 0.0, 0.0), "|n · dir|: both sides");
        assert_eq!(with_n(Vec3::X), Rgb::new(0.0, 1.0, 0.0));
        let half = with_n(Vec3::new(0.0, 0.5, 0.75f32.sqrt()));
        assert!((half.r - 0.5).abs() < 1e-6 && (half.g - 0.5).abs() < 1e-6);
    }

    /// A dot is a disk of radius 0.35 around its centre: the cell's value at the centre is
    /// `inside` wherever the cell has a dot, and cell corners (at least 0.5 - 0.15 from any
    /// centre, farther than the radius) are `outside`.
    #[test]
    fn dots_inside_and_outside() {
        let t = Procedural::Dots { mapping: Mapping2D::IDENTITY, inside: Texture::from(1.0), outside: Texture::from(0.0) };
        let (mut with, mut without) = (0, 0);
        for s in -6..6 {
            for u in -6..6 {
                let (sc, tc) = (s as f32, u as f32);
                let corner = t.eval(&at_uv(sc + 0.5, tc + 0.5)).r;
                assert_eq!(corner, 0.0, "cell ({s}, {u}) corner");
                let has = noise2(sc + 0.5, tc + 0.5) > 0.0;
                let c = Vec2::new(sc + 0.15 * noise2(sc + 1.5, tc + 2.8), tc + 0.15 * noise2(sc + 4.5, tc + 9.8));
                assert_eq!(t.eval(&at_uv(c.x, c.y)).r, if has { 1.0 } else { 0.0 }, "cell ({s}, {u}) centre");
                // Just inside and just outside the radius.
                if has {
                    assert_eq!(t.eval(&at_uv(c.x + 0.349, c.y)).r, 1.0);
                    assert_eq!(t.eval(&at_uv(c.x + 0.351, c.y)).r, 0.0);
                    with += 1;
                } else {
                    without += 1;
                }
            }
        }
        assert!(with > 20 && without > 20, "{with} cells with dots, {without} without");
    }

    #[test]
    fn noise_textures_at_lattice_points() {
        let at = |p: Vec3| TexPoint { p, ..Default::default() };
        let id = Mat4::IDENTITY;
        let f = Procedural::Fbm { world_to_texture: id, omega: 0.5, octaves: 1 };
        let w = Procedural::Wrinkled { world_to_texture: id, omega: 0.5, octaves: 1 };
        let q = Vec3::new(3.0, -2.0, 5.0);
        assert_eq!(f.eval(&at(q)), Rgb::BLACK);
        // Turbulence of one octave at a lattice point: only the 0.2 × ω tail remains.
        assert!((w.eval(&at(q)).r - 0.1).abs() < 1e-6);
        // The texture transform: a point's value is the texture-space point's.
        let m = Mat4::from_translation(Vec3::new(0.25, 0.0, 0.0));
        let f8 = Procedural::Fbm { world_to_texture: m, omega: 0.5, octaves: 8 };
        let p = Vec3::new(0.1, 0.7, 0.3);
        assert_eq!(f8.eval(&at(p)).r, fbm(p + Vec3::new(0.25, 0.0, 0.0), 0.5, 8));
        // Marble at y = 0 with no variation: sin 0 = 0, t = 1/2, inside pbrt's spline.
        let mb = Procedural::Marble { world_to_texture: id, omega: 0.5, octaves: 8, scale: 1.0, variation: 0.0 };
        assert_eq!(mb.eval(&at(Vec3::new(0.3, 0.0, 0.8))), marble_colour(0.5));
        // The spline passes through 1.5 × its first and last control colours.
        assert!((marble_colour(0.0) - Rgb::new(0.87, 0.87, 0.9)).map(f32::abs).max_component() < 1e-6);
        assert!((marble_colour(1.0) - Rgb::new(0.87, 0.87, 0.9)).map(f32::abs).max_component() < 1e-6);
    }

    #[test]
    fn mappings() {
        let at = |p: Vec3| TexPoint { p, ..Default::default() };
        let id = Mat4::IDENTITY;
        let sph = Mapping2D::Spherical { world_to_texture: id };
        assert!((sph.st(&at(Vec3::new(0.0, 0.0, 2.0))) - Vec2::new(0.0, 0.0)).length() < 1e-6);
        assert!((sph.st(&at(Vec3::new(0.0, 3.0, 0.0))) - Vec2::new(0.5, 0.25)).length() < 1e-6);
        let cyl = Mapping2D::Cylindrical { world_to_texture: id };
        assert!((cyl.st(&at(Vec3::new(1.0, 0.0, 0.7))) - Vec2::new(0.5, 0.7)).length() < 1e-6);
        let pl = Mapping2D::Planar { world_to_texture: id, v1: Vec3::X, v2: Vec3::Z, ds: 0.5, dt: -1.0 };
        assert!((pl.st(&at(Vec3::new(0.2, 9.0, 0.4))) - Vec2::new(0.7, -0.6)).length() < 1e-6);
    }
}
