//! Mitsuba's `blendbsdf`: (1 - w) f_a + w f_b. Sampling picks `b` with probability w and
//! reports the mixture's value and density for continuous directions (so that MIS sees
//! the BSDF's true pdf); a delta lobe keeps its own, scaled by the choice probability.

use super::{Bsdf, BsdfSample, LobeFlags, TransportMode};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Debug)]
pub struct Blend {
    pub a: Bsdf,
    pub b: Bsdf,
    /// Weight of `b`, in [0, 1].
    pub weight: f32,
}

impl Blend {
    pub fn flags(&self) -> LobeFlags {
        match self.weight {
            w if w <= 0.0 => self.a.flags(),
            w if w >= 1.0 => self.b.flags(),
            _ => self.a.flags() | self.b.flags(),
        }
    }
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        let w = self.weight;
        self.a.eval(wo, wi, mode) * (1.0 - w) + self.b.eval(wo, wi, mode) * w
    }
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        let w = self.weight;
        self.a.pdf(wo, wi, mode) * (1.0 - w) + self.b.pdf(wo, wi, mode) * w
    }
    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let w = self.weight;
        let (chosen, p, uc) = if uc < w { (&self.b, w, uc / w) } else { (&self.a, 1.0 - w, ((uc - w) / (1.0 - w)).min(1.0 - f32::EPSILON / 2.0)) };
        let mut s = chosen.sample(wo, uc, u, mode)?;
        if s.lobe.is_specular() {
            s.f *= p;
            s.pdf *= p;
        } else {
            s.f = self.eval(wo, s.wi, mode);
            s.pdf = self.pdf(wo, s.wi, mode);
        }
        Some(s)
    }
    pub fn diffuse_albedo(&self) -> Rgb {
        self.a.diffuse_albedo() * (1.0 - self.weight) + self.b.diffuse_albedo() * self.weight
    }
    pub fn delta_probability(&self, wo: Vec3, lobe: LobeFlags) -> f32 {
        self.a.delta_probability(wo, lobe) * (1.0 - self.weight) + self.b.delta_probability(wo, lobe) * self.weight
    }
}
