//! Photon maps: photons in a kd-tree, and the radiance estimate from their density.
//!
//! Reflected radiance at x toward wo from the n photons in a disc of radius r:
//! `L ≈ Σ f(wo, wi_p) Φ_p |wi_p·ns| / |wi_p·ng| · K(d_p)`, with K a 2-D kernel normalised over
//! the disc (box: 1/(π r²)). Photon flux crosses the geometric surface; the ratio of cosines
//! turns it into the shading frame's irradiance (it is 1 without shading normals).

use super::trace::Deposit;
use crate::accel::{KdPoint, KdTree};
use crate::bsdf::{Bsdf, BsdfModel, TransportMode};
use crate::error::{Error, Result};
use crate::geometry::SurfaceInteraction;
use crate::lpe::aov::LayerSample;
use crate::lpe::Tracker;
use crate::math::PI;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub(crate) struct Photon {
    pub p: Vec3,
    pub wi: Vec3,
    pub power: Rgb,
    /// Geometric normal of the surface it landed on, on the side it arrived from.
    pub n: Vec3,
    pub segments: u16,
    pub caustic: bool,
    /// Its path gave the sites of the precomputed radiance (then it takes no part in it).
    pub site_path: bool,
    /// Its path's events, as the reverse automata's state (see `Deposit::light_state`).
    pub light_state: u32,
}

impl Photon {
    /// A stored photon from a landing, its power scaled (by 1 / number of emitted paths).
    pub fn from_deposit(d: &Deposit, scale: f32) -> Self {
        Photon {
            p: d.p,
            wi: d.wi,
            n: if d.wi.dot(d.ng) >= 0.0 { d.ng } else { -d.ng },
            power: d.power * scale,
            segments: d.segments.min(u16::MAX as u32) as u16,
            caustic: d.caustic,
            site_path: false,
            light_state: d.light_state,
        }
    }
}

/// Where a density estimate's photons go by their paths (AOVs): the camera prefix up to the
/// lookup point, the lookup point's scattering (reflection, or transmission when the photon
/// arrived on the other side), then the photon's light subpath. The estimate is split by
/// photon, so each photon's share goes to the layers its whole path matches.
pub(crate) struct Route<'a> {
    reflect: Tracker<'a>,
    transmit: Tracker<'a>,
    /// The routed estimate (filled by [`PhotonMap::radiance`]).
    pub out: LayerSample,
}

impl<'a> Route<'a> {
    /// A lookup at `si` (BSDF lobes `flags`) reached by a camera prefix in state `prefix`.
    pub fn new(prefix: &Tracker<'a>, si: &SurfaceInteraction, flags: crate::bsdf::LobeFlags) -> Self {
        let set = prefix.set();
        let at = |through| {
            let mut t = *prefix;
            t.push(set.scatter_event(si.shape, flags, None, through));
            t
        };
        Route { reflect: at(false), transmit: at(true), out: LayerSample::default() }
    }

    /// Photon `ph` adds `value` at a point whose outgoing side is `front` (of the normal `ng`).
    #[inline]
    pub fn add_photon(&mut self, ph: &Photon, ng: Vec3, front: bool, value: Rgb) {
        let t = if (ph.wi.dot(ng) > 0.0) == front { &self.reflect } else { &self.transmit };
        self.out.add(t.meets_state(ph.light_state), value);
    }
}

/// Bytes of one photon: p, wi, power, n (12 f32), segments (u16), caustic and site_path (u8
/// each), light_state (u32).
const PHOTON_BYTES: usize = 56;

/// Photons as little-endian bytes, to send a photon pass traced on one machine to another.
pub(crate) fn photons_to_bytes(photons: &[Photon]) -> Vec<u8> {
    let mut out = Vec::with_capacity(8 + photons.len() * PHOTON_BYTES);
    out.extend_from_slice(b"SVLPHOT1");
    for ph in photons {
        for v in [ph.p.x, ph.p.y, ph.p.z, ph.wi.x, ph.wi.y, ph.wi.z, ph.power.r, ph.power.g, ph.power.b, ph.n.x, ph.n.y, ph.n.z] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&ph.segments.to_le_bytes());
        out.push(ph.caustic as u8);
        out.push(ph.site_path as u8);
        out.extend_from_slice(&ph.light_state.to_le_bytes());
    }
    out
}

/// Read [`photons_to_bytes`]'s output (appending to `out`); malformed bytes are an error.
pub(crate) fn photons_from_bytes(b: &[u8], out: &mut Vec<Photon>) -> Result<()> {
    if b.len() < 8 || &b[..8] != b"SVLPHOT1" || !(b.len() - 8).is_multiple_of(PHOTON_BYTES) {
        return Err(Error::Invalid(format!("photons: not a svetlo photon list ({} bytes)", b.len())));
    }
    out.reserve((b.len() - 8) / PHOTON_BYTES);
    for c in b[8..].chunks_exact(PHOTON_BYTES) {
        let f = |i: usize| f32::from_le_bytes(c[4 * i..4 * i + 4].try_into().expect("4 bytes"));
        let v: [f32; 12] = std::array::from_fn(f);
        if !v.iter().all(|x| x.is_finite()) || c[50] > 1 || c[51] > 1 {
            return Err(Error::Invalid("photons: a photon is not finite or its flags are not 0 or 1".into()));
        }
        out.push(Photon {
            p: Vec3::new(v[0], v[1], v[2]),
            wi: Vec3::new(v[3], v[4], v[5]),
            power: Rgb { r: v[6], g: v[7], b: v[8] },
            n: Vec3::new(v[9], v[10], v[11]),
            segments: u16::from_le_bytes([c[48], c[49]]),
            caustic: c[50] == 1,
            site_path: c[51] == 1,
            light_state: u32::from_le_bytes([c[52], c[53], c[54], c[55]]),
        });
    }
    Ok(())
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
    /// `bsdf`, from the photons `accept` lets through that landed on a surface facing the same
    /// way (Jensen's filter: no photons from the other side of a thin wall or a corner's
    /// other face).
    /// With `visibility`, only photons the point sees count (see [`visible`]). With `route`,
    /// the estimate is also split by the photons' paths into `route.out`.
    #[allow(clippy::too_many_arguments)]
    pub fn radiance(
        &self,
        visibility: Option<&Scene>,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        wo: Vec3,
        lookup: &Lookup,
        accept: impl Fn(&Photon) -> bool,
        mut route: Option<&mut Route>,
    ) -> Rgb {
        let n = if si.wo.dot(si.ng) >= 0.0 { si.ng } else { -si.ng };
        let accept = |ph: &Photon| ph.n.dot(n) > SAME_ORIENTATION_COS && accept(ph);
        // Visibility is tested on the photons found only (not on every candidate of the
        // search): hidden ones do not count, and the disc stays the one the k reached.
        let seen = |ph: &Photon| visibility.is_none_or(|sc| visible(sc, si.p, n, ph.p, ph.n, si.time));
        let mut sum = Rgb::BLACK;
        let front = si.wo.dot(si.ng) > 0.0;
        let mut add = |ph: &Photon, d2: f32, r2: f32| {
            let wi = si.to_local(ph.wi);
            let cos_g = ph.wi.dot(si.ng).abs();
            if cos_g <= 0.0 {
                return;
            }
            let f = bsdf.eval(wo, wi, TransportMode::Radiance);
            if !f.is_black() {
                let v = f * ph.power * (wi.z.abs() / cos_g * lookup.kernel.weight(d2, r2));
                sum += v;
                if let Some(rt) = route.as_deref_mut() {
                    rt.add_photon(ph, si.ng, front, v);
                }
            }
        };
        let r2 = if lookup.k == 0 {
            let r2 = lookup.max_radius * lookup.max_radius;
            self.tree.for_each_in_radius(si.p, lookup.max_radius, |ph, d2| {
                if accept(ph) && seen(ph) {
                    add(ph, d2, r2)
                }
            });
            r2
        } else {
            let found = self.tree.k_nearest(si.p, lookup.k, lookup.max_radius, accept);
            let (inside, r2) = knn_disc(&found, lookup);
            if r2 <= 0.0 {
                return Rgb::BLACK;
            }
            for &(i, d2) in inside {
                let ph = &self.tree.items()[i];
                if seen(ph) {
                    add(ph, d2, r2);
                }
            }
            r2
        };
        if let Some(rt) = route {
            rt.out.scale(1.0 / (PI * r2));
        }
        sum / (PI * r2)
    }
}

/// The photons of a k-nearest search that count, and the disc's squared radius. With k found
/// the disc reaches the k-th, which lies on its edge: it is left out, as the k - 1 inside over
/// the disc's area is the unbiased density of a uniform Poisson process (k / area overshoots
/// by k / (k - 1)). With fewer, the disc is the largest allowed and all count.
fn knn_disc<'a>(found: &'a [(usize, f32)], lookup: &Lookup) -> (&'a [(usize, f32)], f32) {
    if found.len() == lookup.k && lookup.k > 0 {
        (&found[..lookup.k - 1], found[lookup.k - 1].1)
    } else {
        (found, lookup.max_radius * lookup.max_radius)
    }
}

/// The reflectance of the side of `bsdf` that `w` (local) is on, where that side is purely
/// Lambertian (then reflected radiance is albedo / π times irradiance, whatever wo).
pub(crate) fn lambertian_albedo(bsdf: &Bsdf, w: Vec3) -> Option<Rgb> {
    let m = if w.z >= 0.0 || bsdf.front.handles_back_side() { &bsdf.front } else { bsdf.back.as_ref()? };
    match m {
        BsdfModel::Diffuse(d) => Some(d.reflectance * bsdf.opacity),
        _ => None,
    }
}

/// A place where a photon landed on a Lambertian side, whose radiance is precomputed.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RadianceSite {
    pub p: Vec3,
    /// Geometric normal on the lit side.
    pub n: Vec3,
    pub ns: Vec3,
    pub albedo: Rgb,
}

#[derive(Clone, Copy, Debug)]
struct RadiancePoint {
    p: Vec3,
    n: Vec3,
    first: u32,
}

impl KdPoint for RadiancePoint {
    #[inline]
    fn position(&self) -> Vec3 {
        self.p
    }
}

/// Christensen's precomputed radiance ("Faster photon map global illumination", 1999): the
/// global map's estimate at a subset of the photons on Lambertian surfaces, so that a final
/// gather ray landing on one reads its nearest site (same orientation) instead of searching k
/// photons. Kept per photon path length (cumulative over `buckets` segment counts) so that
/// depth-limited lookups stay exact about which paths they count. The extra blur (the distance
/// to the nearest site) vanishes as photons grow, like the estimate's own.
pub(crate) struct PrecomputedRadiance {
    tree: KdTree<RadiancePoint>,
    /// values[first + b]: radiance of photons of at most b + 1 segments (the last bucket: all).
    values: Vec<Rgb>,
    buckets: usize,
    max_radius: f32,
}

/// Whether a lookup point `p` (surface normal `n` on the seen side) sees a photon at `q`
/// (normal `nq` on its lit side): a shadow ray between the two, each end lifted off its
/// surface by a quarter of their distance (more than the sagitta of a sphere of radius half
/// that distance, so curved surfaces do not shadow themselves). Without it light leaks through
/// thin walls into the room beside, along the surfaces that run under them.
pub(crate) fn visible(scene: &Scene, p: Vec3, n: Vec3, q: Vec3, nq: Vec3, time: f32) -> bool {
    let lift = VISIBILITY_LIFT * (q - p).length();
    lift == 0.0 || !scene.occluded_at(p + n * lift, n, q + nq * lift, time)
}

const VISIBILITY_LIFT: f32 = 0.25;

/// Orientation agreement of a photon's surface with the lookup point's (cos 60°).
pub(crate) const SAME_ORIENTATION_COS: f32 = 0.5;

/// Orientation agreement for a site to stand for a lookup point (cos 25°).
const SITE_NORMAL_COS: f32 = 0.9;

impl PrecomputedRadiance {
    /// `buckets`: photon segment counts told apart (1 when depth is unbounded);
    /// `other_paths_scale`: photon paths emitted over those that gave no site.
    pub fn new(map: &PhotonMap, visibility: Option<&Scene>, sites: &[RadianceSite], lookup: &Lookup, buckets: usize, other_paths_scale: f32) -> Self {
        use rayon::prelude::*;
        let buckets = buckets.max(1);
        let per_site: Vec<Vec<Rgb>> = sites
            .par_iter()
            .map(|s| {
                let mut b = vec![Rgb::BLACK; buckets];
                // Only photons of other paths than the sites': a density estimated where a photon
                // is known to be (or read at the site nearest a point, whose cell is larger
                // where photons are sparser) would be biased by that photon's own position.
                let found = map.tree.k_nearest(s.p, lookup.k, lookup.max_radius, |ph| !ph.site_path && ph.n.dot(s.n) > SAME_ORIENTATION_COS);
                let (inside, r2) = knn_disc(&found, lookup);
                if r2 > 0.0 {
                    for &(i, d2) in inside {
                        let ph = &map.tree.items()[i];
                        // Photons carry no time (the map averages the shutter): test at its start.
                        if visibility.is_some_and(|sc| !visible(sc, s.p, s.n, ph.p, ph.n, 0.0)) {
                            continue;
                        }
                        let cos_g = ph.wi.dot(s.n);
                        let k = (ph.segments as usize).clamp(1, buckets) - 1;
                        b[k] += ph.power * (ph.wi.dot(s.ns).abs() / cos_g * lookup.kernel.weight(d2, r2));
                    }
                }
                let scale = s.albedo * (other_paths_scale / (PI * PI * r2.max(f32::MIN_POSITIVE)));
                let mut acc = Rgb::BLACK;
                for v in b.iter_mut() {
                    acc += *v;
                    *v = if r2 > 0.0 { acc * scale } else { Rgb::BLACK };
                }
                b
            })
            .collect();
        let points: Vec<RadiancePoint> = sites.iter().enumerate().map(|(i, s)| RadiancePoint { p: s.p, n: s.n, first: (i * buckets) as u32 }).collect();
        PrecomputedRadiance { tree: KdTree::new(points), values: per_site.into_iter().flatten().collect(), buckets, max_radius: lookup.max_radius }
    }

    /// Radiance leaving a Lambertian point `p` on the side of geometric normal `n`, from
    /// photons of at most `segments` segments, sites tested for visibility at `time`; None where
    /// no site is near enough.
    pub fn radiance(&self, visibility: Option<&Scene>, p: Vec3, n: Vec3, segments: i32, time: f32) -> Option<Rgb> {
        let found =
            self.tree.k_nearest(p, 1, self.max_radius, |s| s.n.dot(n) > SITE_NORMAL_COS && visibility.is_none_or(|sc| visible(sc, p, n, s.p, s.n, time)));
        let &(i, _) = found.first()?;
        let b = (segments.max(1) as usize).min(self.buckets) - 1;
        Some(self.values[self.tree.items()[i].first as usize + b])
    }
}
