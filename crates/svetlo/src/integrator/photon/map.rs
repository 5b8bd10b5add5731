//! Photon maps: photons in a kd-tree, and the radiance estimate from their density.
//!
//! Reflected radiance at x toward wo from the n photons in a disc of radius r:
//! `L ≈ Σ f(wo, wi_p) Φ_p |wi_p·ns| / |wi_p·ng| · K(d_p)`, with K a 2-D kernel normalised over
//! the disc (box: 1/(π r²)). Photon flux crosses the geometric surface; the ratio of cosines
//! turns it into the shading frame's irradiance (it is 1 without shading normals).

use super::trace::Deposit;
use crate::accel::{KdPoint, KdTree};
use crate::bsdf::{Bsdf, TransportMode};
use crate::error::{Error, Result};
use crate::geometry::SurfaceInteraction;
use crate::math::PI;
use crate::spectrum::Rgb;
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub(crate) struct Photon {
    pub p: Vec3,
    pub wi: Vec3,
    pub power: Rgb,
    pub segments: u16,
    pub caustic: bool,
}

impl Photon {
    /// A stored photon from a landing, its power scaled (by 1 / number of emitted paths).
    pub fn from_deposit(d: &Deposit, scale: f32) -> Self {
        Photon { p: d.p, wi: d.wi, power: d.power * scale, segments: d.segments.min(u16::MAX as u32) as u16, caustic: d.caustic }
    }
}

impl KdPoint for Photon {
    #[inline]
    fn position(&self) -> Vec3 {
        self.p
    }
}

/// Density-estimation kernel over the disc of the lookup.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kernel {
    /// Constant: 1 / (π r²).
    Box,
    /// Jensen's cone filter, weight 1 - d / (k r), normalised by 1 - 2 / (3k).
    Cone { k: f32 },
    /// 2 (1 - d²/r²) / (π r²).
    Epanechnikov,
}

impl Kernel {
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "box" => Ok(Kernel::Box),
            "cone" => Ok(Kernel::Cone { k: 1.0 }),
            "epanechnikov" => Ok(Kernel::Epanechnikov),
            _ => Err(Error::Settings(format!("photon filter is box, cone or epanechnikov, got '{s}'"))),
        }
    }

    /// Kernel weight times π r² (so that the box kernel weighs 1).
    #[inline]
    fn weight(self, d2: f32, r2: f32) -> f32 {
        match self {
            Kernel::Box => 1.0,
            Kernel::Cone { k } => (1.0 - (d2 / r2).sqrt() / k).max(0.0) / (1.0 - 2.0 / (3.0 * k)),
            Kernel::Epanechnikov => 2.0 * (1.0 - d2 / r2).max(0.0),
        }
    }
}

/// How a radiance estimate gathers photons: the `k` nearest within `max_radius`, or (k = 0)
/// every photon within `max_radius`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lookup {
    pub k: usize,
    pub max_radius: f32,
    pub kernel: Kernel,
}

pub(crate) struct PhotonMap {
    tree: KdTree<Photon>,
}

impl PhotonMap {
    pub fn new(photons: Vec<Photon>) -> Self {
        PhotonMap { tree: KdTree::new(photons) }
    }

    /// Radiance reflected at `si` toward `wo` (local shading frame) by the non-delta part of
    /// `bsdf`, from the photons `accept` lets through.
    pub fn radiance(&self, si: &SurfaceInteraction, bsdf: &Bsdf, wo: Vec3, lookup: &Lookup, accept: impl Fn(&Photon) -> bool) -> Rgb {
        let mut sum = Rgb::BLACK;
        let mut add = |ph: &Photon, d2: f32, r2: f32| {
            let wi = si.to_local(ph.wi);
            let cos_g = ph.wi.dot(si.ng).abs();
            if cos_g <= 0.0 {
                return;
            }
            let f = bsdf.eval(wo, wi, TransportMode::Radiance);
            if !f.is_black() {
                sum += f * ph.power * (wi.z.abs() / cos_g * lookup.kernel.weight(d2, r2));
            }
        };
        let r2 = if lookup.k == 0 {
            let r2 = lookup.max_radius * lookup.max_radius;
            self.tree.for_each_in_radius(si.p, lookup.max_radius, |ph, d2| {
                if accept(ph) {
                    add(ph, d2, r2)
                }
            });
            r2
        } else {
            let found = self.tree.k_nearest(si.p, lookup.k, lookup.max_radius, &accept);
            // Fewer than k photons within the maximum: the disc is the maximum one.
            let r2 = if found.len() == lookup.k { found.last().map_or(0.0, |&(_, d2)| d2) } else { lookup.max_radius * lookup.max_radius };
            if r2 <= 0.0 {
                return Rgb::BLACK;
            }
            for &(i, d2) in &found {
                add(&self.tree.items()[i], d2, r2);
            }
            r2
        };
        sum / (PI * r2)
    }
}
