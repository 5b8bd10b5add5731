//! The options block: camera, film, pixel filter, sampler and integrator onto svetlo's
//! camera and scene settings; and pbrt-v4's equal-area octahedral environment maps resampled
//! onto svetlo's latitude-longitude map.

use super::lexer::Loc;
use super::Loader;
use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::film::Filter;
use crate::io::mitsuba::fov_x_from_axis;
use crate::math::PI;
use crate::sampling::SamplerKind;
use crate::spectrum::Rgb;
use crate::texture::Bitmap;
use glam::{Mat4, Vec2, Vec3};

/// svetlo's lat-long map is built directly in the pbrt light's frame.
pub const LATLONG_FROM_PBRT: Mat4 = Mat4::IDENTITY;

pub use crate::math::warp::{equal_area_sphere_to_square, equal_area_square_to_sphere};

/// Bilinear lookup of a square equal-area image at `uv` (row 0 at the top, as stored).
fn lookup(img: &Bitmap, uv: Vec2) -> Rgb {
    let (w, h) = (img.width as f32, img.height as f32);
    let (x, y) = (uv.x * w - 0.5, uv.y * h - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |dx: f32, dy: f32| {
        let xi = ((x0 + dx).max(0.0) as usize).min(img.width - 1);
        let yi = ((y0 + dy).max(0.0) as usize).min(img.height - 1);
        img.texel(xi, yi)
    };
    (at(0.0, 0.0) * (1.0 - fx) + at(1.0, 0.0) * fx) * (1.0 - fy) + (at(0.0, 1.0) * (1.0 - fx) + at(1.0, 1.0) * fx) * fy
}

/// Resample an N×N equal-area map onto a 2N × (N+1) lat-long grid in svetlo's EnvMap
/// convention (module envmap.rs), in the same frame.
pub fn equal_area_to_latlong(img: &Bitmap) -> Bitmap {
    let n = img.width.max(1);
    let (w, h) = (2 * n, n + 1);
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        let theta = PI * y as f32 / (h - 1) as f32;
        for x in 0..w {
            let phi = 2.0 * PI * (x as f32 + 0.5) / w as f32;
            let l = Vec3::new(phi.sin() * theta.sin(), theta.cos(), -phi.cos() * theta.sin());
            data.push(lookup(img, equal_area_sphere_to_square(l.normalize())));
        }
    }
    Bitmap::new(w, h, data)
}

/// Luminance irradiance from the upper (+z, light space) hemisphere of an equal-area map:
/// every texel covers 4π/N² sr.
pub fn upper_irradiance(img: &Bitmap) -> f32 {
    let (w, h) = (img.width, img.height);
    let mut e = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            let d = equal_area_square_to_sphere(Vec2::new((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32));
            if d.z > 0.0 {
                e += (img.texel(x, y).luminance() * d.z) as f64;
            }
        }
    }
    (e * 4.0 * std::f64::consts::PI / (w * h) as f64) as f32
}

impl Loader {
    /// pbrt's imaging ratio, exposure time × iso / 100 (film `iso`, camera shutter), that
    /// scales every light; computed when the world begins.
    pub(super) fn set_imaging_ratio(&mut self) -> Result<()> {
        let (open, close) = match &self.opts.camera {
            Some((_, p, _, _)) => (p.float("shutteropen", 0.0)?, p.float("shutterclose", 1.0)?),
            None => (0.0, 1.0),
        };
        let iso = match &self.opts.film {
            Some((_, p, _)) => p.float("iso", 100.0)?,
            None => 100.0,
        };
        self.imaging_ratio = (close - open) * iso / 100.0;
        if !(self.imaging_ratio > 0.0 && self.imaging_ratio.is_finite()) {
            let loc = self.opts.camera.as_ref().map(|c| c.3.clone());
            let msg = format!("exposure (shutterclose - shutteropen = {}) × iso ({iso}) / 100 must be positive", close - open);
            return Err(match loc {
                Some(l) => l.err(msg),
                None => crate::error::Error::Invalid(msg),
            });
        }
        Ok(())
    }

    pub(super) fn build_camera_and_settings(&mut self, end: &Loc) -> Result<()> {
        // Film.
        let (mut width, mut height) = (1280i64, 720i64);
        if let Some((ty, p, loc)) = self.opts.film.take() {
            if !matches!(ty.as_str(), "rgb" | "gbuffer" | "spectral") {
                return Err(loc.err(format!("unknown film '{ty}' (rgb, gbuffer, spectral)")));
            }
            if ty != "rgb" {
                self.warn(&loc, format!("film '{ty}' written as an RGB image"));
            }
            width = p.int("xresolution", 1280)?;
            height = p.int("yresolution", 720)?;
            for k in ["cropwindow", "pixelbounds"] {
                if p.get(k).is_some() {
                    self.warn(&loc, format!("film '{k}' is not supported yet: the whole image is rendered"));
                }
            }
            let _ = (p.get("iso"), p.string("filename")?, p.float("diagonal", 35.0)?, p.float("maxcomponentvalue", f32::INFINITY)?, p.bool("savefp16", true)?);
            if p.float("whitebalance", 0.0)? != 0.0 {
                self.warn(&loc, "film 'whitebalance' is not supported: no white balancing");
            }
            if let Some(s) = p.string("sensor")? {
                if s != "cie1931" {
                    self.warn(&loc, format!("sensor '{s}' is not supported: the CIE 1931 observer is used"));
                }
            }
            self.warn_unused(&format!("Film \"{ty}\""), &p);
            if !(1..=1 << 16).contains(&width) || !(1..=1 << 16).contains(&height) {
                return Err(loc.err(format!("film resolution {width}x{height} is not between 1 and 65536")));
            }
        }
        let (width, height) = (width as u32, height as u32);
        let aspect = width as f32 / height as f32;

        // Camera.
        let Some((ty, p, ctm, loc)) = self.opts.camera.take() else {
            return Err(end.err("the scene has no Camera"));
        };
        if !ctm[0].abs_diff_eq(ctm[1], 0.0) {
            self.warn(&loc, "a moving camera is not supported: the start transform is used");
        }
        let inv = ctm[0].inverse();
        if !inv.is_finite() {
            return Err(loc.err("the camera transform is singular"));
        }
        // pbrt's camera +x is the image's right, svetlo's its left.
        let mut to_world = inv * Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let frame = p.float("frameaspectratio", aspect)?;
        if (frame - aspect).abs() > 1e-3 * aspect {
            self.warn(&loc, format!("frameaspectratio {frame} differs from the film's {aspect}: pixels stay square (the film's aspect is used)"));
        }
        let default_half = if aspect > 1.0 { Vec2::new(aspect, 1.0) } else { Vec2::new(1.0, 1.0 / aspect) };
        let half = match p.floats("screenwindow")? {
            None => default_half,
            Some(w) if w.len() == 4 => {
                let (cx, cy) = (0.5 * (w[0] + w[1]), 0.5 * (w[2] + w[3]));
                let h = Vec2::new(0.5 * (w[1] - w[0]), 0.5 * (w[3] - w[2]));
                if cx.abs() > 1e-6 * h.x.abs().max(1.0) || cy.abs() > 1e-6 * h.y.abs().max(1.0) || h.x <= 0.0 || h.y <= 0.0 {
                    return Err(loc.err("screenwindow: only windows centred on the axis (xmin = -xmax, ymin = -ymax) are supported"));
                }
                if ((h.x / h.y) - aspect).abs() > 1e-3 * aspect {
                    self.warn(&loc, "screenwindow's aspect differs from the film's: its width is used");
                }
                h
            }
            Some(w) => return Err(loc.err(format!("screenwindow needs 4 numbers, got {}", w.len()))),
        };
        let (open, close) = (p.float("shutteropen", 0.0)?, p.float("shutterclose", 1.0)?);
        if close < open {
            return Err(loc.err("shutterclose is before shutteropen"));
        }
        let projection = match ty.as_str() {
            "perspective" => {
                let fov = p.float("fov", 90.0)?;
                if !(fov > 0.0 && fov < 180.0) {
                    return Err(loc.err(format!("fov must be in (0, 180) degrees, got {fov}")));
                }
                // pbrt's fov spans the shorter axis of the default window; a window scales it.
                let t = (0.5 * fov.to_radians()).tan() * half.x / default_half.x;
                let fov_short = if aspect > 1.0 { 2.0 * (t * default_half.x / aspect).atan() } else { 2.0 * t.atan() };
                let fov_x = fov_x_from_axis(fov_short.to_degrees(), "smaller", aspect).ok_or_else(|| loc.err("bad fov"))?;
                let lens = p.float("lensradius", 0.0)?;
                let focus = p.float("focaldistance", 1e6)?;
                if !(lens >= 0.0 && focus > 0.0) {
                    return Err(loc.err(format!("need lensradius >= 0 ({lens}) and focaldistance > 0 ({focus})")));
                }
                Projection::Perspective { fov_x_deg: fov_x, aperture_radius: lens, focus_distance: focus }
            }
            "orthographic" => {
                if p.float("lensradius", 0.0)? > 0.0 {
                    self.warn(&loc, "an orthographic camera's lens (depth of field) is not supported");
                }
                let _ = p.get("focaldistance");
                // svetlo's orthographic film spans x in [-1, 1] before to_world.
                to_world *= Mat4::from_scale(Vec3::new(half.x, half.x, 1.0));
                Projection::Orthographic
            }
            "realistic" | "spherical" => return Err(loc.err(format!("camera '{ty}' is not supported"))),
            other => return Err(loc.err(format!("unknown camera '{other}'"))),
        };
        self.warn_unused(&format!("Camera \"{ty}\""), &p);
        let (shutter_open, shutter_close) = if self.any_motion { (open, close) } else { (0.0, 0.0) };
        self.b.set_camera(Camera { to_world, projection, width, height, near_clip: 0.0, far_clip: f32::INFINITY, shutter_open, shutter_close });

        // Pixel filter (pbrt's default: gaussian, radius 1.5, sigma 0.5).
        let filter = match self.opts.filter.take() {
            None => Filter::Gaussian { stddev: 0.5 },
            Some((ty, p, loc)) => {
                let f = match ty.as_str() {
                    "box" => {
                        let r = (p.float("xradius", 0.5)?, p.float("yradius", 0.5)?);
                        if r != (0.5, 0.5) {
                            self.warn(&loc, format!("box filter radius {r:?} rendered with radius 0.5 (one pixel)"));
                        }
                        Filter::Box
                    }
                    "triangle" => {
                        let (x, y) = (p.float("xradius", 2.0)?, p.float("yradius", 2.0)?);
                        if x != y {
                            self.warn(&loc, "triangle filter: x and y radii differ; the x radius is used");
                        }
                        Filter::Tent { radius: positive(x, "xradius", &loc)? }
                    }
                    "gaussian" => {
                        let sigma = positive(p.float("sigma", 0.5)?, "sigma", &loc)?;
                        let (x, _y) = (p.float("xradius", 1.5)?, p.float("yradius", 1.5)?);
                        if (x - 3.0 * sigma).abs() > 1e-3 {
                            self.warn(&loc, format!("gaussian filter: pbrt truncates at radius {x}; svetlo's reaches 4 sigma ({})", 4.0 * sigma));
                        }
                        Filter::Gaussian { stddev: sigma }
                    }
                    "mitchell" | "lanczos" => {
                        self.warn(&loc, format!("filter '{ty}' is not supported: a gaussian (sigma 0.5) is used"));
                        for k in ["xradius", "yradius", "B", "C", "tau"] {
                            let _ = p.get(k);
                        }
                        Filter::Gaussian { stddev: 0.5 }
                    }
                    other => return Err(loc.err(format!("unknown pixel filter '{other}'"))),
                };
                self.warn_unused(&format!("PixelFilter \"{ty}\""), &p);
                f
            }
        };
        self.b.settings.filter = filter;

        // Sampler (pbrt's default: zsobol, 16 spp).
        self.b.settings.spp = 16;
        self.b.settings.sampler = SamplerKind::Sobol;
        if let Some((ty, p, loc)) = self.opts.sampler.take() {
            let spp = p.int("pixelsamples", 16)?;
            if !(1..=u32::MAX as i64).contains(&spp) {
                return Err(loc.err(format!("pixelsamples must be positive, got {spp}")));
            }
            self.b.settings.spp = spp as u32;
            let seed = p.int("seed", 0)?;
            self.b.settings.seed = seed.max(0) as u64;
            self.b.settings.sampler = match ty.as_str() {
                "independent" => SamplerKind::Independent,
                "sobol" | "zsobol" | "paddedsobol" => SamplerKind::Sobol,
                "halton" | "pmj02bn" | "stratified" => {
                    self.warn(&loc, format!("sampler '{ty}' replaced by the Sobol sampler"));
                    SamplerKind::Sobol
                }
                other => return Err(loc.err(format!("unknown sampler '{other}'"))),
            };
            for k in ["randomization", "jitter", "xsamples", "ysamples"] {
                let _ = p.get(k);
            }
            self.warn_unused(&format!("Sampler \"{ty}\""), &p);
        }

        // Integrator (pbrt's default: volpath, maxdepth 5).
        let (ty, p, loc) = self.opts.integrator.take().unwrap_or_else(|| ("volpath".into(), Default::default(), end.clone()));
        let name = match ty.as_str() {
            "path" => "path",
            "volpath" => {
                self.warn(&loc, "integrator 'volpath' rendered by 'path' (participating media are not supported)");
                "path"
            }
            "randomwalk" | "simplepath" => {
                self.warn(&loc, format!("integrator '{ty}' rendered by 'path' (the same paths, with next-event estimation and MIS)"));
                "path"
            }
            "bdpt" => "bdpt",
            "mlt" => "pssmlt",
            "sppm" => "sppm",
            "lightpath" => "light",
            "ambientocclusion" | "simplevolpath" | "aov" => {
                self.warn(&loc, format!("integrator '{ty}' is not supported: 'path' is used"));
                "path"
            }
            other => return Err(loc.err(format!("unknown integrator '{other}'"))),
        };
        self.b.settings.integrator = name.to_string();
        let maxdepth = p.int("maxdepth", 5)?;
        if !(-1..=i32::MAX as i64 - 1).contains(&maxdepth) {
            return Err(loc.err(format!("maxdepth must be >= 0 (or -1), got {maxdepth}")));
        }
        // pbrt counts bounces, svetlo segments from the camera.
        self.b.settings.max_depth = if maxdepth < 0 { -1 } else { maxdepth as i32 + 1 };
        for k in ["regularize", "lightsampler", "mutationsperpixel", "iterations", "photonsperiteration", "radius", "visualizestrategies", "visualizeweights"] {
            if p.get(k).is_some() {
                self.warn(&loc, format!("integrator parameter '{k}' ignored (svetlo's own defaults)"));
            }
        }
        self.warn_unused(&format!("Integrator \"{ty}\""), &p);
        Ok(())
    }
}

fn positive(v: f32, name: &str, loc: &Loc) -> Result<f32> {
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(loc.err(format!("'{name}' must be positive, got {v}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The octahedral map inverts, and it is equal-area: uniform points on the square land
    /// uniformly on the sphere (moments of z and of x·y as for a uniform sphere).
    #[test]
    fn equal_area_map_round_trips_and_preserves_area() {
        let mut rng = crate::sampling::rng::Pcg32::new(7, 1);
        let (mut mz, mut mz2, n) = (0.0f64, 0.0f64, 200_000);
        for _ in 0..n {
            let p = Vec2::new(rng.next_f32(), rng.next_f32());
            let d = equal_area_square_to_sphere(p);
            assert!((d.length() - 1.0).abs() < 1e-4, "{p:?} -> {d:?}");
            let q = equal_area_sphere_to_square(d);
            assert!((q - p).length() < 1e-3, "{p:?} -> {d:?} -> {q:?}");
            mz += d.z as f64;
            mz2 += (d.z * d.z) as f64;
        }
        let (mz, mz2) = (mz / n as f64, mz2 / n as f64);
        // Standard errors: sqrt(1/3 / n) = 1.3e-3 and sqrt((1/5 - 1/9) / n) = 6.7e-4.
        assert!(mz.abs() < 5e-3 && (mz2 - 1.0 / 3.0).abs() < 3e-3, "{mz} {mz2}");
    }

    #[test]
    fn constant_map_irradiance_is_pi() {
        let img = Bitmap::new(64, 64, vec![Rgb::WHITE; 64 * 64]);
        assert!((upper_irradiance(&img) - PI).abs() < 0.02);
        let ll = equal_area_to_latlong(&img);
        assert!(ll.data().iter().all(|c| (c.r - 1.0).abs() < 1e-5));
    }
}
