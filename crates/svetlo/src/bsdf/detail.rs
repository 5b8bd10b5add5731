//! Surface detail (Mitsuba 3's `normalmap` and `bumpmap`): the nested BSDF is evaluated in a
//! perturbed shading frame. Both maps give a perturbed normal in the coordinates of the
//! surface's own shading frame; [`Detail`] turns it into the frame as Mitsuba does: the
//! normal is mirrored about the original one when the direction the path arrives from lies
//! below it (`flip_invalid_normals`), the tangent follows the original one, and the result
//! is attenuated by the microfacet shadowing term of Estevez et al. (Ray Tracing Gems
//! 2019) against the bump terminator (`use_shadowing_function`).

use crate::math::Frame;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// `normalmap`: the texel's RGB in [0, 1] is the normal 2c - 1 in the tangent space of the
/// original shading frame.
pub fn normal_map_normal(texel: Rgb) -> Vec3 {
    Vec3::new(2.0 * texel.r - 1.0, 2.0 * texel.g - 1.0, 2.0 * texel.b - 1.0)
}

/// `bumpmap`: the surface displaced along the shading normal by the height h(u, v), whose
/// gradient (already multiplied by the map's scale) is `grad`. The perturbed partial
/// derivatives dp/du + n (dh/du - n.dp/du) and likewise for v give the new normal, turned
/// to the geometric normal's side and given in the coordinates of `shading`.
pub fn bump_map_normal(grad: Vec2, shading: &Frame, ng: Vec3, dpdu: Vec3, dpdv: Vec3) -> Vec3 {
    let n0 = shading.n;
    let du = dpdu + n0 * (grad.x - n0.dot(dpdu));
    let dv = dpdv + n0 * (grad.y - n0.dot(dpdv));
    let n = du.cross(dv);
    shading.to_local(if n.dot(ng) < 0.0 { -n } else { n })
}

/// The perturbed normal of a normal or bump map, unit, in the original shading frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detail {
    pub n: Vec3,
    /// Attenuate by the shadowing term (Mitsuba's default; `use_shadowing_function`).
    pub shadowing: bool,
}

impl Detail {
    /// From an unnormalised normal; one that is zero or not finite leaves the frame as it is.
    pub fn new(n: Vec3, shadowing: bool) -> Self {
        let len2 = n.length_squared();
        let n = if len2 > 0.0 && len2.is_finite() { n / len2.sqrt() } else { Vec3::Z };
        Detail { n, shadowing }
    }

    /// The perturbed frame (in the original frame's coordinates) seen from `wo`, the
    /// direction the path arrives from: the normal is mirrored about the original one when
    /// `wo` lies below it, so that the nested BSDF sees the path arrive from its front.
    #[inline]
    pub fn frame(&self, wo: Vec3) -> Frame {
        let n = if wo.z * wo.dot(self.n) <= 0.0 { Vec3::new(-self.n.x, -self.n.y, self.n.z) } else { self.n };
        let s = Vec3::X - n * n.x;
        let len2 = s.length_squared();
        let s = if len2 > 1e-12 { s / len2.sqrt() } else { Vec3::Y };
        Frame { s, t: n.cross(s), n }
    }

    /// The shadowing term for the light-side direction `w` (original frame): 1 for an
    /// unperturbed normal, falling toward grazing `w` as the normal tilts.
    #[inline]
    pub fn shadowing(&self, w: Vec3) -> f32 {
        if !self.shadowing {
            return 1.0;
        }
        let tan2 = |v: Vec3| (1.0 - v.z * v.z).max(0.0) / (v.z * v.z);
        let alpha2 = (0.125 * tan2(self.n)).min(1.0);
        let g = 2.0 / (1.0 + (1.0 + alpha2 * tan2(w)).sqrt());
        if g.is_finite() {
            g
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    /// The flat normal map (0.5, 0.5, 1) leaves the frame and the BSDF as they are.
    #[test]
    fn identity_normal_map() {
        let d = Detail::new(normal_map_normal(Rgb::new(0.5, 0.5, 1.0)), true);
        let f = d.frame(Vec3::new(0.3, -0.2, 0.9).normalize());
        assert!(close(f.n, Vec3::Z) && close(f.s, Vec3::X) && close(f.t, Vec3::Y));
        assert!((d.shadowing(Vec3::new(0.99, 0.0, 0.01).normalize()) - 1.0).abs() < 1e-6);
    }

    /// A tilted normal: orthonormal right-handed frame with the tangent in the plane of the
    /// original tangent; mirrored when the path arrives from below it; the shadowing term
    /// is 1 along the normal and falls toward grazing light.
    #[test]
    fn tilted_normal() {
        let d = Detail::new(normal_map_normal(Rgb::new(0.9, 0.5, 0.6)), true);
        let above = Vec3::new(0.5, 0.0, 0.8).normalize();
        let f = d.frame(above);
        assert!(close(f.n, d.n));
        assert!(f.s.y.abs() < 1e-6 && (f.s.dot(f.n)).abs() < 1e-6 && close(f.s.cross(f.t), f.n));
        // Below the perturbed normal (not the original one): mirrored normal.
        let below = Vec3::new(-0.9, 0.0, 0.1).normalize();
        assert!(below.dot(d.n) < 0.0);
        assert!(close(d.frame(below).n, Vec3::new(-d.n.x, -d.n.y, d.n.z)));
        assert!((d.shadowing(Vec3::Z) - 1.0).abs() < 1e-6);
        let g = d.shadowing(Vec3::new(0.999, 0.0, 0.045).normalize());
        assert!(g > 0.0 && g < 0.9, "{g}");
        assert_eq!(Detail { shadowing: false, ..d }.shadowing(Vec3::new(1.0, 0.0, 0.01)), 1.0);
        // No direction at all: unperturbed.
        assert_eq!(Detail::new(Vec3::ZERO, true).n, Vec3::Z);
    }

    /// A height field h = a u on the plane p = (u, v, 0): the normal of the displaced plane
    /// (u, v, a u) is (-a, 0, 1) normalised; a zero gradient changes nothing.
    #[test]
    fn bump_map_normals() {
        let f = Frame::from_normal_tangent(Vec3::Z, Vec3::X);
        assert!(close(Detail::new(bump_map_normal(Vec2::ZERO, &f, Vec3::Z, Vec3::X, Vec3::Y), true).n, Vec3::Z));
        let a = 0.7;
        let n = Detail::new(bump_map_normal(Vec2::new(a, 0.0), &f, Vec3::Z, Vec3::X, Vec3::Y), true).n;
        assert!(close(n, Vec3::new(-a, 0.0, 1.0).normalize()), "{n}");
        // Whatever the gradient, the normal stays on the geometric normal's side.
        assert!(bump_map_normal(Vec2::new(0.0, -50.0), &f, Vec3::Z, Vec3::X, Vec3::Y).z > 0.0);
    }
}
