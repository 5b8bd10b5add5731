//! pbrt-v4's `diffusetransmission`: Lambertian reflection R/π on the side light arrives
//! from and Lambertian transmission T/π to the other side, the same from either side (no
//! refraction, so radiance and importance transport alike). Sampling picks reflection or
//! transmission by their largest channels, then a cosine-weighted direction.

use super::{BsdfSample, LobeFlags, TransportMode};
use crate::math::{warp, INV_PI};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct DiffuseTransmission {
    pub reflectance: Rgb,
    pub transmittance: Rgb,
}

impl DiffuseTransmission {
    /// Probability of sampling reflection.
    fn pr(&self) -> f32 {
        let (r, t) = (self.reflectance.max_component().max(0.0), self.transmittance.max_component().max(0.0));
        if r + t > 0.0 {
            r / (r + t)
        } else {
            0.5
        }
    }

    pub fn flags(&self) -> LobeFlags {
        let mut f = LobeFlags::NONE;
        if self.reflectance.max_component() > 0.0 {
            f = f | LobeFlags::DIFFUSE_REFLECTION;
        }
        if self.transmittance.max_component() > 0.0 {
            f = f | LobeFlags::DIFFUSE_TRANSMISSION;
        }
        f
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z == 0.0 || wi.z == 0.0 {
            Rgb::BLACK
        } else if (wo.z > 0.0) == (wi.z > 0.0) {
            self.reflectance * INV_PI
        } else {
            self.transmittance * INV_PI
        }
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let pr = self.pr();
        let mut wi = warp::square_to_cosine_hemisphere(u);
        let reflect = uc < pr;
        // The hemisphere of wo for reflection, the other one for transmission.
        if (wo.z < 0.0) == reflect {
            wi.z = -wi.z;
        }
        let pdf = self.pdf(wo, wi, mode);
        if pdf <= 0.0 || pdf.is_nan() {
            return None;
        }
        let lobe = if reflect { LobeFlags::DIFFUSE_REFLECTION } else { LobeFlags::DIFFUSE_TRANSMISSION };
        Some(BsdfSample { wi, f: self.eval(wo, wi, mode), pdf, lobe, eta: 1.0 })
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> f32 {
        if wo.z == 0.0 || wi.z == 0.0 {
            return 0.0;
        }
        let pr = self.pr();
        let p = if (wo.z > 0.0) == (wi.z > 0.0) { pr } else { 1.0 - pr };
        p * wi.z.abs() * INV_PI
    }
}
