//! A blend of two BSDFs, f = (1 - amount) f_a + amount f_b: pbrt-v4's `mix` material (which
//! picks one of the two at random per point, with probability `amount` for the second: the
//! same BSDF in expectation) and Mitsuba 3's `blendbsdf`. Sampling picks a model by `amount`
//! and reports the blended density, so that MIS sees the mixture.

use super::{BsdfModel, BsdfSample, LobeFlags, TransportMode};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Debug)]
pub struct Mix {
    pub a: BsdfModel,
    pub b: BsdfModel,
    /// Weight of `b`, in [0, 1].
    pub amount: f32,
}

impl Mix {
    pub fn flags(&self) -> LobeFlags {
        self.a.flags() | self.b.flags()
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        self.a.eval(wo, wi, mode) * (1.0 - self.amount) + self.b.eval(wo, wi, mode) * self.amount
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        self.a.pdf(wo, wi, mode) * (1.0 - self.amount) + self.b.pdf(wo, wi, mode) * self.amount
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let t = self.amount;
        // Pick a model by uc and reuse the rest of uc's range inside it.
        let (chosen, p, uc) = if uc < 1.0 - t { (&self.a, 1.0 - t, uc / (1.0 - t)) } else { (&self.b, t, (uc - (1.0 - t)) / t) };
        let s = chosen.sample(wo, uc.min(1.0 - f32::EPSILON / 2.0), u, mode)?;
        if s.lobe.is_specular() {
            // A delta lobe: the other model has no density along it; its share of the
            // weight is the chance of choosing it times the blend weight, which cancel.
            return Some(BsdfSample { f: s.f * p, pdf: s.pdf * p, ..s });
        }
        let f = self.eval(wo, s.wi, mode);
        let pdf = self.pdf(wo, s.wi, mode);
        (pdf > 0.0 && pdf.is_finite()).then_some(BsdfSample { f, pdf, ..s })
    }
}
