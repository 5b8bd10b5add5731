//! Lambertian reflection: f = R / pi, cosine-weighted sampling.

use super::{BsdfSample, LobeFlags, TransportMode};
use crate::math::{warp, INV_PI};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Diffuse {
    pub reflectance: Rgb,
}

impl Diffuse {
    #[inline]
    pub fn flags(&self) -> LobeFlags {
        LobeFlags::DIFFUSE_REFLECTION
    }
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        self.reflectance * INV_PI
    }
    #[inline]
    pub fn sample(&self, wo: Vec3, _uc: f32, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = warp::square_to_cosine_hemisphere(u);
        let pdf = warp::square_to_cosine_hemisphere_pdf(wi);
        if pdf <= 0.0 {
            return None;
        }
        Some(BsdfSample { wi, f: self.reflectance * INV_PI, pdf, lobe: LobeFlags::DIFFUSE_REFLECTION, eta: 1.0 })
    }
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        warp::square_to_cosine_hemisphere_pdf(wi)
    }
}
