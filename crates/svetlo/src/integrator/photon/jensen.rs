//! Photon mapping (Jensen 1996, 2001): a global and a caustic photon map, then a camera pass.
//!
//! At each camera vertex with a diffuse lobe (see `camera.rs` for the split of path space):
//! * direct light: NEE and a BSDF sample under MIS, as `path`;
//! * caustics (light that reached x through specular bounces only, L S+ x): the caustic map,
//!   built from its own, larger photon pass;
//! * the rest of the indirect light: a final gather. Rays leave x by BSDF sampling (non-delta
//!   lobes), follow delta bounces, and at the first non-specular surface y read the global
//!   map, which there estimates everything arriving at y. Emitters met on the way are
//!   ignored: NEE and the caustic map have them. With `gather=0` the global map is read at
//!   x itself, without its direct and caustic photons (fast, blotchy).
//!
//! Depth: photons remember their light segments; a lookup at camera depth d only takes
//! photons of at most `max_depth - d` segments, so the paths are those `path` solves.
//! The estimate is biased (blur of radius r); it vanishes as the photon count grows with k
//! fixed. Deterministic for a seed whatever the thread count.

use super::camera::{camera_walk, DiffuseVertex};
use super::map::{lambertian_albedo, Kernel, Lookup, Photon, PhotonMap, PrecomputedRadiance, RadianceSite, Route};
use super::trace::trace_photons;
use super::{parse_count, parse_pairs, parse_positive, photon_max_segments, pixel_footprint, segments_left};
use crate::bsdf::TransportMode;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::geometry::Ray;
use crate::integrator::{render_pixels, Integrator, PixelEstimator, Progress, RenderSettings};
use crate::lpe::aov::LayerSample;
use crate::lpe::Tracker;
use crate::path::PathConfig;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use std::time::Instant;

#[derive(Clone, Debug, PartialEq)]
pub struct PhotonOptions {
    /// Photon paths emitted for the global map.
    pub photons: u64,
    /// Photon paths emitted for the caustic map.
    pub caustic_photons: u64,
    /// Nearest photons per global lookup (0: every photon within `radius`).
    pub k: usize,
    /// Largest global lookup radius (scene units); None: 24 pixel footprints.
    pub radius: Option<f32>,
    pub caustic_k: usize,
    /// None: 6 pixel footprints.
    pub caustic_radius: Option<f32>,
    /// Final-gather rays per camera sample (0: read the global map directly).
    pub gather: u32,
    pub kernel: Kernel,
    /// Precompute the global map's radiance at every n-th photon on a Lambertian surface, read
    /// by final-gather rays (Christensen); 0: search the photons at every gather ray.
    pub precompute: u32,
    /// Count only photons a lookup point sees (`map::visible`): no leaks through thin walls.
    pub visibility: bool,
}

impl Default for PhotonOptions {
    fn default() -> Self {
        PhotonOptions {
            photons: 200_000,
            caustic_photons: 200_000,
            k: 64,
            radius: None,
            caustic_k: 32,
            caustic_radius: None,
            gather: 16,
            kernel: Kernel::Cone { k: 1.0 },
            precompute: 4,
            visibility: true,
        }
    }
}

impl PhotonOptions {
    /// `photons=N,caustic-photons=N,k=K,radius=R,caustic-k=K,caustic-radius=R,gather=N,filter=box|cone|epanechnikov,precompute=N,visibility=true|false`.
    pub fn parse(params: &str) -> Result<Self> {
        let m = "photon";
        let mut o = PhotonOptions::default();
        for (k, v) in parse_pairs(m, params)? {
            match k {
                "photons" => o.photons = parse_count(m, k, v)?,
                "caustic-photons" => o.caustic_photons = parse_count(m, k, v)?,
                "k" => o.k = parse_count(m, k, v)? as usize,
                "caustic-k" => o.caustic_k = parse_count(m, k, v)? as usize,
                "radius" => o.radius = Some(parse_positive(m, k, v)?),
                "caustic-radius" => o.caustic_radius = Some(parse_positive(m, k, v)?),
                "gather" => o.gather = parse_count(m, k, v)?.min(1 << 16) as u32,
                "filter" => o.kernel = Kernel::parse(v)?,
                "precompute" => o.precompute = parse_count(m, k, v)?.min(1 << 20) as u32,
                "visibility" => o.visibility = v.parse().map_err(|_| Error::Settings(format!("photon: visibility is true or false, got '{v}'")))?,
                _ => {
                    return Err(Error::Settings(format!(
                        "photon: unknown option '{k}' (photons, caustic-photons, k, radius, caustic-k, caustic-radius, gather, filter, precompute, visibility)"
                    )))
                }
            }
        }
        Ok(o)
    }
}

#[derive(Clone, Debug, Default)]
pub struct PhotonMapper {
    pub options: PhotonOptions,
}

/// Pass tags: the global and caustic passes draw independent photons.
const TAG_GLOBAL: u64 = 0x676c_6f62;
const TAG_CAUSTIC: u64 = 0x6361_7573;
/// Delta bounces a gather ray follows before Russian roulette may end it.
const GATHER_RR_AFTER: u32 = 4;

struct Maps {
    global: PhotonMap,
    precomputed: Option<PrecomputedRadiance>,
    caustic: PhotonMap,
    global_lookup: Lookup,
    caustic_lookup: Lookup,
}

/// The photons of photon paths traced apart: global-map photons with their radiance sites,
/// caustic-map photons.
#[derive(Default)]
struct Traced {
    global: Vec<(Photon, Option<RadianceSite>)>,
    caustic: Vec<Photon>,
}

impl PhotonMapper {
    /// Photon paths of both passes, numbered as one index space: the global pass's paths
    /// `0..photons`, then the caustic pass's.
    pub fn photon_paths(&self) -> u64 {
        self.options.photons + self.options.caustic_photons
    }

    /// Trace photon paths `range` of [`Self::photon_paths`], each from the seed and its index.
    fn trace(&self, scene: &Scene, settings: &RenderSettings, range: std::ops::Range<u64>) -> Traced {
        let o = &self.options;
        let cfg = PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters);
        let gscale = 1.0 / o.photons.max(1) as f32;
        // Every `precompute`-th path lends its Lambertian landings as precomputed-radiance sites.
        // (Precomputed radiance carries no paths: with AOVs every gather ray searches photons.)
        let aovs = settings.aovs();
        let every = if o.gather > 0 && aovs.is_empty() { o.precompute as u64 } else { 0 };
        let g = range.start.min(o.photons)..range.end.min(o.photons);
        let global = trace_photons(scene, settings.seed, TAG_GLOBAL, g, &cfg, aovs, |i, d| {
            let site_path = every > 0 && i % every == 0;
            let site = if site_path {
                d.albedo.map(|albedo| RadianceSite { p: d.p, n: if d.wi.dot(d.ng) >= 0.0 { d.ng } else { -d.ng }, ns: d.ns, albedo })
            } else {
                None
            };
            (Some((Photon { site_path, ..Photon::from_deposit(d, gscale) }, site)), true)
        });
        let cscale = 1.0 / o.caustic_photons.max(1) as f32;
        let c = range.start.max(o.photons) - o.photons..range.end.max(o.photons) - o.photons;
        let caustic = trace_photons(scene, settings.seed, TAG_CAUSTIC, c, &cfg, aovs, |_, d| {
            let keep = (d.caustic && d.surface.intersects(crate::bsdf::LobeFlags::DIFFUSE)).then(|| Photon::from_deposit(d, cscale));
            // A path stays a caustic one only through delta bounces.
            let go_on = (d.caustic || d.segments == 1) && d.surface.is_specular();
            (keep, go_on)
        });
        Traced { global, caustic }
    }

    /// Photon paths `range` of [`Self::photon_paths`] as bytes: batches traced apart (on other
    /// machines) and given in order to [`Self::render_from_batches`] are the local render's
    /// photon maps exactly.
    pub fn photon_batch(&self, scene: &Scene, settings: &RenderSettings, range: std::ops::Range<u64>) -> Result<Vec<u8>> {
        if range.start >= range.end || range.end > self.photon_paths() {
            return Err(Error::Settings(format!("photon: photon paths {}..{} of {}", range.start, range.end, self.photon_paths())));
        }
        check_light_states("photon", settings)?;
        let pool = rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| Error::Settings(format!("thread pool: {e}")))?;
        let t = pool.install(|| self.trace(scene, settings, range.clone()));
        let photons: Vec<Photon> = t.global.iter().map(|x| x.0).collect();
        let sites: Vec<Photon> = t.global.iter().filter_map(|x| x.1).map(site_as_photon).collect();
        let mut out = Vec::new();
        out.extend_from_slice(&range.start.to_le_bytes());
        out.extend_from_slice(&range.end.to_le_bytes());
        for list in [&photons, &sites, &t.caustic] {
            let b = super::map::photons_to_bytes(list);
            out.extend_from_slice(&(b.len() as u64).to_le_bytes());
            out.extend_from_slice(&b);
        }
        Ok(out)
    }

    /// The photon maps from traced photons (all paths, in index order).
    fn maps(&self, scene: &Scene, settings: &RenderSettings, global: Vec<Photon>, sites: Vec<RadianceSite>, caustic: Vec<Photon>) -> Maps {
        let o = &self.options;
        let max_seg = photon_max_segments(settings.max_depth);
        // As in `trace`: with AOVs no path lends sites.
        let every = if o.gather > 0 && settings.aovs().is_empty() { o.precompute as u64 } else { 0 };
        let site_paths = if every > 0 { o.photons.div_ceil(every) } else { 0 };
        let other_paths_scale = o.photons as f32 / (o.photons - site_paths).max(1) as f32;
        let px = pixel_footprint(scene);
        let global_lookup = Lookup { k: o.k, max_radius: o.radius.unwrap_or(24.0 * px), kernel: o.kernel };
        let global = PhotonMap::new(global);
        let precomputed = (!sites.is_empty())
            .then(|| PrecomputedRadiance::new(&global, o.visibility.then_some(scene), &sites, &global_lookup, max_seg.max(1) as usize, other_paths_scale));
        Maps {
            global,
            precomputed,
            caustic: PhotonMap::new(caustic),
            global_lookup,
            caustic_lookup: Lookup { k: o.caustic_k, max_radius: o.caustic_radius.unwrap_or(6.0 * px), kernel: o.kernel },
        }
    }

    fn build_maps(&self, scene: &Scene, settings: &RenderSettings) -> Maps {
        let t = self.trace(scene, settings, 0..self.photon_paths());
        let sites: Vec<RadianceSite> = t.global.iter().filter_map(|x| x.1).collect();
        let global: Vec<Photon> = t.global.into_iter().map(|x| x.0).collect();
        self.maps(scene, settings, global, sites, t.caustic)
    }

    /// The maps from batches of [`Self::photon_batch`] that cover the photon paths in order.
    fn maps_from_batches(&self, scene: &Scene, settings: &RenderSettings, batches: &[&[u8]]) -> Result<Maps> {
        let (mut global, mut site_photons, mut caustic) = (Vec::new(), Vec::new(), Vec::new());
        let mut next = 0u64;
        for b in batches {
            let header = |i: usize| b.get(8 * i..8 * i + 8).map(|x| u64::from_le_bytes(x.try_into().expect("8 bytes")));
            let (Some(start), Some(end)) = (header(0), header(1)) else {
                return Err(Error::Invalid(format!("photon: a photon batch of {} bytes is truncated", b.len())));
            };
            if start != next || end <= start {
                return Err(Error::Invalid(format!("photon: a batch of photon paths {start}..{end} does not follow paths 0..{next}")));
            }
            next = end;
            let mut at = 16usize;
            for list in [&mut global, &mut site_photons, &mut caustic] {
                let len = b.get(at..at + 8).map(|x| u64::from_le_bytes(x.try_into().expect("8 bytes")) as usize);
                let part = len.and_then(|n| b.get(at + 8..(at + 8).checked_add(n)?));
                let Some(part) = part else {
                    return Err(Error::Invalid(format!("photon: a photon batch of {} bytes is truncated", b.len())));
                };
                super::map::photons_from_bytes(part, list)?;
                at += 8 + part.len();
            }
            if at != b.len() {
                return Err(Error::Invalid(format!("photon: a photon batch has {} bytes too many", b.len() - at)));
            }
        }
        if next != self.photon_paths() {
            return Err(Error::Invalid(format!("photon: the batches cover photon paths 0..{next} of 0..{}", self.photon_paths())));
        }
        let sites = site_photons.iter().map(|p| RadianceSite { p: p.p, n: p.wi, ns: p.n, albedo: p.power }).collect();
        Ok(self.maps(scene, settings, global, sites, caustic))
    }

    /// The render (or with `settings.pass_range` its passes' raw sums) from photon batches
    /// traced apart, covering all photon paths in order: the local render bit for bit.
    pub fn render_from_batches(&self, scene: &Scene, settings: &RenderSettings, batches: &[&[u8]], progress: &Progress) -> Result<Film> {
        settings.validate()?;
        // The photons' bytes carry their light states (of the same AOVs as this render's).
        check_light_states("photon", settings)?;
        if settings.time_limit.is_some() {
            return Err(Error::Settings("photon: a render from photon batches has no time limit".into()));
        }
        let pool = rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| Error::Settings(format!("thread pool: {e}")))?;
        let maps = pool.install(|| self.maps_from_batches(scene, settings, batches))?;
        let est = Estimator { maps, gather: self.options.gather, visibility: self.options.visibility };
        render_pixels(scene, settings, progress, &est)
    }
}

/// A radiance site in a photon's fields, for the photon list's bytes (p, n as wi, ns as n,
/// albedo as power).
fn site_as_photon(s: RadianceSite) -> Photon {
    Photon { p: s.p, wi: s.n, power: s.albedo, n: s.ns, segments: 0, caustic: false, site_path: false, light_state: 0 }
}

impl Integrator for PhotonMapper {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        settings.validate()?;
        check_light_states("photon", settings)?;
        let start = Instant::now();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| Error::Settings(format!("thread pool: {e}")))?;
        let maps = pool.install(|| self.build_maps(scene, settings));
        // The photon passes count against a time budget.
        let mut s = settings.clone();
        if let Some(t) = s.time_limit {
            let left = t.saturating_sub(start.elapsed());
            if left.is_zero() {
                // The photon passes took the budget: one pass, so that there is an image.
                s.spp = 1;
                s.time_limit = None;
            } else {
                s.time_limit = Some(left);
            }
        }
        let est = Estimator { maps, gather: self.options.gather, visibility: self.options.visibility };
        render_pixels(scene, &s, progress, &est)
    }
}

/// Photons carry their path's events as one reverse-automaton state: an error when the AOVs'
/// reverse product is too large to have one.
pub(super) fn check_light_states(method: &str, settings: &RenderSettings) -> Result<()> {
    if settings.aovs().light_states_fit() {
        Ok(())
    } else {
        Err(Error::Settings(format!("{method}: the AOVs' automata are too large for photons to carry (use fewer or simpler expressions)")))
    }
}

struct Estimator {
    maps: Maps,
    gather: u32,
    visibility: bool,
}

impl Estimator {
    /// The photon part at a diffuse camera vertex: caustics, and the rest of the indirect
    /// light; with `layers`, also routed there by the photons' paths (times the throughput).
    fn photons_at(&self, scene: &Scene, v: &DiffuseVertex, sampler: &mut dyn Sampler, settings: &RenderSettings, mut layers: Option<&mut LayerSample>) -> Rgb {
        let left = segments_left(settings.max_depth, v.depth);
        let m = &self.maps;
        let vis = self.visibility.then_some(scene);
        // A lookup at the vertex itself, routed into `layers` when there are AOVs.
        let at_x = |map: &PhotonMap, lookup: &Lookup, accept: &dyn Fn(&Photon) -> bool, layers: Option<&mut LayerSample>| match layers {
            None => map.radiance(vis, v.si, v.bsdf, v.wo, lookup, accept, None),
            Some(out) => {
                let mut rt = Route::new(&v.events, v.si, v.flags);
                let l = map.radiance(vis, v.si, v.bsdf, v.wo, lookup, accept, Some(&mut rt));
                out.add_scaled(&rt.out, v.beta, crate::lpe::MAX_LAYERS);
                l
            }
        };
        let mut l = at_x(&m.caustic, &m.caustic_lookup, &|p| (p.segments as i32) <= left, layers.as_deref_mut());
        if self.gather == 0 {
            l += at_x(&m.global, &m.global_lookup, &|p| !p.caustic && p.segments >= 2 && (p.segments as i32) <= left, layers);
            return l;
        }
        let mut g = Rgb::BLACK;
        for _ in 0..self.gather {
            let uc = sampler.next_1d();
            let u = sampler.next_2d();
            let Some(bs) = v.bsdf.sample(v.wo, uc, u, TransportMode::Radiance) else { continue };
            if bs.lobe.is_specular() || bs.pdf <= 0.0 || bs.f.is_black() {
                continue;
            }
            let ray = v.si.spawn_ray(v.si.to_world(bs.wi));
            // The gather ray's path so far: the camera prefix and x as this sample scattered.
            let route = layers.as_deref_mut().map(|out| {
                let mut t = v.events;
                let aovs = t.set();
                t.push(aovs.scatter_event(v.si.shape, v.flags, Some(bs.lobe), bs.lobe.contains(crate::bsdf::LobeFlags::TRANSMISSION)));
                (t, out, v.beta * bs.weight() * (1.0 / self.gather as f32))
            });
            g += bs.weight() * self.gather_ray(scene, ray, v.depth + 1, sampler, settings, route);
        }
        l + g / self.gather as f32
    }

    /// Radiance a gather ray brings back from the global map, through delta bounces; `depth`
    /// is that of the first surface it meets. With `route` (the path's events so far, the
    /// sample's layers and the weight of this ray there), the map's estimate also goes to the
    /// layers by the photons' whole paths.
    fn gather_ray(
        &self,
        scene: &Scene,
        mut ray: Ray,
        mut depth: i32,
        sampler: &mut dyn Sampler,
        settings: &RenderSettings,
        mut route: Option<(Tracker, &mut LayerSample, Rgb)>,
    ) -> Rgb {
        let m = &self.maps;
        let mut t = Rgb::WHITE;
        let mut l = Rgb::BLACK;
        let mut bounces = 0u32;
        // A photon there needs one segment at least.
        while settings.depth_allows(depth + 1) {
            let Some(si) = scene.intersect(&ray) else { break };
            let bsdf = scene.bsdf(&si);
            let flags = bsdf.flags();
            let wo = si.to_local(si.wo);
            if flags.has_non_specular() {
                let left = segments_left(settings.max_depth, depth);
                let n = if si.wo.dot(si.ng) >= 0.0 { si.ng } else { -si.ng };
                let vis = self.visibility.then_some(scene);
                let accept = |p: &Photon| (p.segments as i32) <= left;
                match &mut route {
                    Some((events, out, k)) => {
                        let mut rt = Route::new(events, &si, flags);
                        l += t * m.global.radiance(vis, &si, &bsdf, wo, &m.global_lookup, accept, Some(&mut rt));
                        out.add_scaled(&rt.out, *k * t, crate::lpe::MAX_LAYERS);
                    }
                    None => {
                        let pre = match (&m.precomputed, lambertian_albedo(&bsdf, wo)) {
                            (Some(pc), Some(_)) => pc.radiance(vis, si.p, n, left, si.time),
                            _ => None,
                        };
                        l += t * pre.unwrap_or_else(|| m.global.radiance(vis, &si, &bsdf, wo, &m.global_lookup, accept, None));
                    }
                }
            }
            if !flags.is_specular() {
                break;
            }
            let uc = sampler.next_1d();
            let u = sampler.next_2d();
            let Some(bs) = bsdf.sample(wo, uc, u, TransportMode::Radiance) else { break };
            if !bs.lobe.is_specular() || bs.pdf <= 0.0 {
                break;
            }
            if let Some((events, _, _)) = &mut route {
                let aovs = events.set();
                events.push(aovs.scatter_event(si.shape, flags, Some(bs.lobe), bs.lobe.contains(crate::bsdf::LobeFlags::TRANSMISSION)));
            }
            t *= bs.weight();
            bounces += 1;
            if bounces > GATHER_RR_AFTER {
                let q = t.max_component().min(0.95);
                if sampler.next_1d() >= q {
                    break;
                }
                t /= q;
            }
            if t.is_black() {
                break;
            }
            ray = si.spawn_ray(si.to_world(bs.wi));
            depth += 1;
        }
        l
    }
}

impl PixelEstimator for Estimator {
    fn li(&self, scene: &Scene, ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        self.li_layers(scene, ray, sampler, settings, &mut LayerSample::default())
    }
    fn li_layers(&self, scene: &Scene, ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        camera_walk(scene, ray, sampler, settings, &mut |v, s, out| self.photons_at(scene, v, s, settings, out), layers)
    }
    fn supports_lpe(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse() {
        let o = PhotonOptions::parse("photons=1_000,caustic-photons=5000, k=10,radius=0.5,gather=0,filter=box").unwrap();
        assert_eq!(o.photons, 1000);
        assert_eq!(o.caustic_photons, 5000);
        assert_eq!(o.k, 10);
        assert_eq!(o.radius, Some(0.5));
        assert_eq!(o.gather, 0);
        assert_eq!(o.kernel, Kernel::Box);
        assert_eq!(PhotonOptions::parse("").unwrap(), PhotonOptions::default());
        for bad in ["photons", "photons=-3", "radius=0", "radius=nan", "filter=gauss", "colour=red"] {
            assert!(PhotonOptions::parse(bad).is_err(), "{bad}");
        }
    }
}
