//! pbrt-v4's layered BSDF (`coateddiffuse`, `coatedconductor`): a dielectric interface (smooth
//! or rough) at the top of a slab of thickness `thickness`, a reflecting base (diffuse or
//! conductor) at its bottom, and in between a homogeneous medium of unit extinction with
//! single-scattering `albedo` and Henyey-Greenstein asymmetry `g` (albedo 0: a purely
//! absorbing layer, transmittance exp(-thickness/|cos|)). Light is followed through the
//! stack by a stochastic random walk of at most `max_depth` interface events:
//!
//! * `sample`: one walk from `wo`; its weight (f cos / pdf of the whole walk) is exact. The
//!   returned pair keeps that weight but reports the `pdf` estimate below (f rescaled), so
//!   that MIS against light sampling uses the same density on both sides, as pbrt does with
//!   its proportional pdfs.
//! * `eval`: pbrt's estimator with next-event connections through the exit interface,
//!   averaged over `n_samples` walks; unbiased, so its expectation is the layered BSDF.
//! * `pdf`: pbrt's approximation (the reflection of the top plus a transmit-reflect-transmit
//!   estimate), mixed 9:1 with the uniform sphere density so it is never zero.
//!
//! `eval` and `pdf` are random: their generators are seeded by the directions (and `sample`'s
//! by its random numbers), so the same arguments give the same value, whatever the thread.
//! Interface lobes restricted to transmission or reflection are drawn by rejection (a sample
//! of the other kind ends the walk), which keeps every estimate unbiased. The stack is
//! two-sided: directions below the surface are mirrored, and a pair on opposite sides
//! scatters nothing (the base is opaque).

use super::{BsdfModel, BsdfSample, LobeFlags, TransportMode};
use crate::math::PI;
use crate::sampling::rng::Pcg32;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

#[derive(Clone, Debug)]
pub struct Coated {
    /// The coating's interface (a dielectric model: eta = coating IOR / outside IOR).
    pub top: BsdfModel,
    /// The base under it (diffuse or conductor, IORs relative to the coating).
    pub bottom: BsdfModel,
    pub thickness: f32,
    pub albedo: Rgb,
    pub g: f32,
    pub max_depth: u32,
    pub n_samples: u32,
}

fn hash(v: &[f32]) -> u64 {
    v.iter().fold(0x9e37_79b9_7f4a_7c15u64, |h, x| crate::sampling::rng::mix64(h ^ x.to_bits() as u64).wrapping_add(0x9e37_79b9))
}

fn flip_mode(m: TransportMode) -> TransportMode {
    match m {
        TransportMode::Radiance => TransportMode::Importance,
        TransportMode::Importance => TransportMode::Radiance,
    }
}

fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 && (a2 + b2).is_finite() {
        a2 / (a2 + b2)
    } else if a.is_infinite() {
        1.0
    } else {
        0.0
    }
}

/// Henyey-Greenstein phase function for directions both pointing away from the scattering
/// point (pbrt's convention: forward scattering is wi = -wo).
fn hg(wo: Vec3, wi: Vec3, g: f32) -> f32 {
    let cos = wo.dot(wi);
    let d = 1.0 + g * g + 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * PI * d * d.max(1e-12).sqrt())
}

/// Sample wi from HG about the forward direction -wo; returns (wi, pdf = phase value).
fn sample_hg(wo: Vec3, g: f32, u: Vec2) -> (Vec3, f32) {
    let cos = if g.abs() < 1e-3 {
        1.0 - 2.0 * u.x
    } else {
        let s = (1.0 - g * g) / (1.0 + g - 2.0 * g * u.x);
        (1.0 + g * g - s * s) / (2.0 * g)
    }
    .clamp(-1.0, 1.0);
    // cos is between the forward direction -wo and wi.
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    let f = crate::math::Frame::from_normal(-wo);
    let wi = f.to_world(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos));
    (wi, hg(wo, wi, g))
}

fn is_specular(m: &BsdfModel) -> bool {
    m.flags().is_specular() && !m.flags().has_non_specular()
}

/// A sample of `m` kept only if it transmits (`want_t`) or reflects (rejection; see module notes).
fn sample_kind(m: &BsdfModel, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode, want_t: bool) -> Option<BsdfSample> {
    let s = m.sample(wo, uc, u, mode)?;
    let t = s.wi.z * wo.z < 0.0;
    (t == want_t && s.pdf > 0.0 && s.wi.z != 0.0 && s.f.max_component() > 0.0).then_some(s)
}

impl Coated {
    fn tr(&self, dz: f32, w: Vec3) -> f32 {
        if dz.abs() <= f32::MIN_POSITIVE {
            1.0
        } else {
            (-(dz / w.z).abs()).exp()
        }
    }

    fn has_medium(&self) -> bool {
        self.albedo.max_component() > 0.0 && self.thickness > 0.0
    }

    pub fn flags(&self) -> LobeFlags {
        let mut f = LobeFlags::REFLECTION;
        if is_specular(&self.top) {
            f = f | LobeFlags::SPECULAR;
        }
        if self.bottom.flags().intersects(LobeFlags::DIFFUSE) || self.has_medium() {
            f = f | LobeFlags::DIFFUSE;
        } else {
            f = f | LobeFlags::GLOSSY;
        }
        f
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        let mut rng = Pcg32::new(hash(&[wo.x, wo.y, wo.z]), hash(&[wi.x, wi.y, wi.z]));
        self.eval_with(wo, wi, mode, &mut rng)
    }

    /// One estimate of f(wo, wi) from the generator `rng` (tests average many).
    pub fn eval_with(&self, wo: Vec3, wi: Vec3, mode: TransportMode, rng: &mut Pcg32) -> Rgb {
        let (wo, wi) = if wo.z < 0.0 { (-wo, -wi) } else { (wo, wi) };
        if wi.z <= 0.0 || wo.z == 0.0 {
            return Rgb::BLACK;
        }
        let n = self.n_samples.max(1);
        let mut f = self.top.eval(wo, wi, mode) * n as f32;
        let mut r = || rng.next_f32();
        let (exit, non_exit, exit_z) = (&self.top, &self.bottom, self.thickness);
        for _ in 0..n {
            let Some(wos) = sample_kind(&self.top, wo, r(), Vec2::new(r(), r()), mode, true) else { continue };
            let Some(wis) = sample_kind(exit, wi, r(), Vec2::new(r(), r()), flip_mode(mode), true) else { continue };
            let mut beta = wos.f * (wos.wi.z.abs() / wos.pdf);
            let mut z = self.thickness;
            // Which interface the walk is at (z alone cannot tell when the thickness is 0).
            let mut at_top = true;
            let mut w = wos.wi;
            for depth in 0..self.max_depth {
                if depth > 3 && beta.max_component() < 0.25 {
                    let q = (1.0 - beta.max_component()).max(0.0);
                    if r() < q {
                        break;
                    }
                    beta /= 1.0 - q;
                }
                if !self.has_medium() {
                    at_top = !at_top;
                    z = if at_top { self.thickness } else { 0.0 };
                    beta *= self.tr(self.thickness, w);
                } else {
                    let dz = -(1.0 - r()).ln() * w.z.abs();
                    let zp = if w.z > 0.0 { z + dz } else { z - dz };
                    if zp == z {
                        break;
                    }
                    if 0.0 < zp && zp < self.thickness {
                        // Scattering in the medium: connect through the exit interface.
                        let mut wt = 1.0;
                        if !is_specular(exit) {
                            wt = power_heuristic(wis.pdf, hg(-w, -wis.wi, self.g));
                        }
                        f += beta * self.albedo * hg(-w, -wis.wi, self.g) * wt * self.tr(zp - exit_z, wis.wi) * wis.f / wis.pdf;
                        let (nw, ppdf) = sample_hg(-w, self.g, Vec2::new(r(), r()));
                        if ppdf <= 0.0 || nw.z == 0.0 {
                            break;
                        }
                        beta *= self.albedo; // phase value / its pdf = 1
                        w = nw;
                        z = zp;
                        if z < exit_z && w.z > 0.0 && !is_specular(exit) {
                            let fe = exit.eval(-w, wi, mode);
                            if fe.max_component() > 0.0 {
                                // The density with which the connection strategy picks this direction.
                                let wt = power_heuristic(ppdf, exit.pdf(wi, -w, flip_mode(mode)));
                                f += beta * self.tr(zp - exit_z, w) * fe * wt;
                            }
                        }
                        continue;
                    }
                    z = zp.clamp(0.0, self.thickness);
                    at_top = z >= self.thickness;
                }
                if at_top {
                    // Reflection back into the layer at the exit interface.
                    let Some(bs) = sample_kind(exit, -w, r(), Vec2::new(r(), r()), mode, false) else { break };
                    beta = beta * bs.f * (bs.wi.z.abs() / bs.pdf);
                    w = bs.wi;
                } else {
                    if !is_specular(non_exit) {
                        let mut wt = 1.0;
                        if !is_specular(exit) {
                            wt = power_heuristic(wis.pdf, non_exit.pdf(-w, -wis.wi, mode));
                        }
                        f += beta * non_exit.eval(-w, -wis.wi, mode) * wis.wi.z.abs() * wt * self.tr(self.thickness, wis.wi) * wis.f / wis.pdf;
                    }
                    let Some(bs) = sample_kind(non_exit, -w, r(), Vec2::new(r(), r()), mode, false) else { break };
                    beta = beta * bs.f * (bs.wi.z.abs() / bs.pdf);
                    w = bs.wi;
                    if !is_specular(exit) {
                        let fe = exit.eval(-w, wi, mode);
                        if fe.max_component() > 0.0 {
                            let mut wt = 1.0;
                            if !is_specular(non_exit) {
                                wt = power_heuristic(bs.pdf, exit.pdf(wi, -w, flip_mode(mode)));
                            }
                            f += beta * self.tr(self.thickness, bs.wi) * fe * wt;
                        }
                    }
                }
            }
        }
        f / n as f32
    }

    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let flip = wo.z < 0.0;
        let wo_u = if flip { -wo } else { wo };
        let fl = |w: Vec3| if flip { -w } else { w };
        let bs = self.top.sample(wo_u, uc, u, mode)?;
        if bs.pdf <= 0.0 || bs.wi.z == 0.0 {
            return None;
        }
        if bs.wi.z > 0.0 {
            // Reflection at the top: its own sample (exact density, or a delta lobe).
            return Some(BsdfSample { wi: fl(bs.wi), ..bs });
        }
        let mut rng = Pcg32::new(hash(&[wo.x, wo.y, wo.z]), hash(&[uc, u.x, u.y]));
        let mut r = || rng.next_f32();
        let mut beta = bs.f * (bs.wi.z.abs() / bs.pdf);
        let mut w = bs.wi;
        let mut z = self.thickness;
        let mut at_top = true;
        let mut specular_path = bs.lobe.is_specular();
        for depth in 0..self.max_depth {
            let rr = beta.max_component();
            if depth > 3 && rr < 0.25 {
                let q = (1.0 - rr).max(0.0);
                if r() < q {
                    return None;
                }
                beta /= 1.0 - q;
            }
            if w.z == 0.0 {
                return None;
            }
            if self.has_medium() {
                let dz = -(1.0 - r()).ln() * w.z.abs();
                let zp = if w.z > 0.0 { z + dz } else { z - dz };
                if zp == z {
                    return None;
                }
                if 0.0 < zp && zp < self.thickness {
                    let (nw, ppdf) = sample_hg(-w, self.g, Vec2::new(r(), r()));
                    if ppdf <= 0.0 || nw.z == 0.0 {
                        return None;
                    }
                    beta *= self.albedo;
                    specular_path = false;
                    w = nw;
                    z = zp;
                    continue;
                }
                z = zp.clamp(0.0, self.thickness);
                at_top = z >= self.thickness;
            } else {
                at_top = !at_top;
                z = if at_top { self.thickness } else { 0.0 };
                beta *= self.tr(self.thickness, w);
            }
            let interface = if at_top { &self.top } else { &self.bottom };
            let w_local = -w;
            let s = interface.sample(w_local, r(), Vec2::new(r(), r()), mode)?;
            if s.pdf <= 0.0 || s.wi.z == 0.0 {
                return None;
            }
            beta = beta * s.f * (s.wi.z.abs() / s.pdf);
            specular_path &= s.lobe.is_specular();
            w = s.wi;
            if s.wi.z * w_local.z < 0.0 {
                // Transmitted: out through the top (the base is opaque).
                if !at_top || w.z <= 0.0 {
                    return None;
                }
                let lobe = if specular_path {
                    LobeFlags::SPECULAR_REFLECTION
                } else if self.flags().intersects(LobeFlags::DIFFUSE) {
                    LobeFlags::DIFFUSE_REFLECTION
                } else {
                    LobeFlags::GLOSSY_REFLECTION
                };
                if specular_path {
                    return Some(BsdfSample { wi: fl(w), f: beta / w.z.abs(), pdf: 1.0, lobe, eta: 1.0 });
                }
                // Keep the walk's weight, report the estimated density (module notes).
                let pdf = self.pdf(wo, fl(w), mode);
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                return Some(BsdfSample { wi: fl(w), f: beta * (pdf / w.z.abs()), pdf, lobe, eta: 1.0 });
            }
        }
        None
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        let (wo, wi) = if wo.z < 0.0 { (-wo, -wi) } else { (wo, wi) };
        if wi.z <= 0.0 {
            return 0.0;
        }
        let mut rng = Pcg32::new(hash(&[wi.x, wi.y, wi.z]), hash(&[wo.x, wo.y, wo.z]));
        let mut r = || rng.next_f32();
        let n = self.n_samples.max(1);
        let (t, rb) = (&self.top, &self.bottom);
        let mut sum = n as f32 * t.pdf(wo, wi, mode);
        for _ in 0..n {
            let Some(wos) = sample_kind(t, wo, r(), Vec2::new(r(), r()), mode, true) else { continue };
            let Some(wis) = sample_kind(t, wi, r(), Vec2::new(r(), r()), flip_mode(mode), true) else { continue };
            if is_specular(t) {
                sum += rb.pdf(-wos.wi, -wis.wi, mode);
            } else if let Some(rs) = rb.sample(-wos.wi, r(), Vec2::new(r(), r()), mode).filter(|s| s.pdf > 0.0) {
                if !is_specular(rb) {
                    let rpdf = rb.pdf(-wos.wi, -wis.wi, mode);
                    sum += power_heuristic(wis.pdf, rpdf) * rpdf;
                    let tpdf = t.pdf(-rs.wi, wi, mode);
                    sum += power_heuristic(rs.pdf, tpdf) * tpdf;
                } else {
                    sum += t.pdf(-rs.wi, wi, mode);
                }
            }
        }
        0.1 / (4.0 * PI) + 0.9 * sum / n as f32
    }
}
