//! Cameras: perspective (pinhole), thin lens, orthographic, with Mitsuba 3's conventions.
//! Camera space looks down +z with +y up and +x to the *left* of the image (`lookat` gives
//! to_world); `fov_x_deg` spans the image's width (see [`fov_x_from_axis`] for Mitsuba's
//! other `fov_axis` values); rays start on the near plane and end at the far plane, both
//! measured along the optical axis. The orthographic film spans x in [-1, 1] and
//! y in [-1/aspect, 1/aspect] in camera space before `to_world` scales it.
//!
//! For methods that trace from the lights, `importance.rs` adds the camera's importance
//! `We`, its densities and the sampling of a direction toward the lens.

mod importance;

pub use importance::{CameraSample, LensConnector, LensSample, Pinhole};

use crate::geometry::Ray;
use crate::math::warp;
use glam::{Mat4, Vec2, Vec3};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Pinhole when `aperture_radius` is 0, thin lens otherwise.
    Perspective { fov_x_deg: f32, aperture_radius: f32, focus_distance: f32 },
    /// Orthographic: the film spans x in [-1,1], y in [-1/aspect, 1/aspect] in camera space
    /// (scale with to_world), as Mitsuba's `orthographic`.
    Orthographic,
}

#[derive(Clone, Debug)]
pub struct Camera {
    pub to_world: Mat4,
    pub projection: Projection,
    pub width: u32,
    pub height: u32,
    pub near_clip: f32,
    pub far_clip: f32,
    /// Shutter interval, in the scene's time units; rays get a time in it.
    pub shutter_open: f32,
    pub shutter_close: f32,
}

impl Camera {
    /// A pinhole camera with Mitsuba's default clip planes (1e-2, 1e4) and an instant shutter.
    pub fn pinhole(to_world: Mat4, fov_x_deg: f32, width: u32, height: u32) -> Camera {
        Camera {
            to_world,
            projection: Projection::Perspective { fov_x_deg, aperture_radius: 0.0, focus_distance: 1.0 },
            width,
            height,
            near_clip: 1e-2,
            far_clip: 1e4,
            shutter_open: 0.0,
            shutter_close: 0.0,
        }
    }

    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// Camera-space position on the plane z = 1 of a raster point (pixels, origin top-left).
    /// Half extents of the film in camera space: on the plane z = 1 for perspective
    /// (tan of the half field of view on each axis), on z = 0 for orthographic.
    pub fn film_half_extent(&self) -> Vec2 {
        match self.projection {
            Projection::Perspective { fov_x_deg, .. } => {
                let tx = (0.5 * fov_x_deg.to_radians()).tan();
                Vec2::new(tx, tx / self.aspect())
            }
            Projection::Orthographic => Vec2::new(1.0, 1.0 / self.aspect()),
        }
    }

    /// Camera-space position on the film (plane z = 1, or z = 0 for orthographic) of a
    /// raster point (pixels, origin top-left), for a film of half extent `half`.
    fn raster_to_camera(&self, raster: Vec2, half: Vec2) -> Vec2 {
        let ndc = Vec2::new(raster.x / self.width as f32, raster.y / self.height as f32);
        // +x of camera space is the image's left, +y its top.
        (Vec2::ONE - 2.0 * ndc) * half
    }

    /// The ray through raster position `raster`, lens sample `lens` in [0,1)^2 and time
    /// sample `time` in [0,1). Directions are unit length; `t_max` honours the far clip.
    pub fn generate_ray(&self, raster: Vec2, lens: Vec2, time: f32) -> Ray {
        self.ray_generator().generate_ray(raster, lens, time)
    }

    /// `generate_ray` with the camera's constants computed once, for drawing many rays.
    pub fn ray_generator(&self) -> RayGenerator<'_> {
        let half = self.film_half_extent();
        let m = self.to_world;
        RayGenerator {
            cam: self,
            half,
            pinhole: matches!(self.projection, Projection::Perspective { aperture_radius, .. } if aperture_radius <= 0.0),
            film_scale: Vec2::new(-2.0 * half.x / self.width as f32, -2.0 * half.y / self.height as f32),
            axes: [m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate()],
            position: m.w_axis.truncate(),
        }
    }
}

/// A camera with what its rays share computed once (the film's extent takes a tangent, and
/// a pinhole's rays need only their direction in world space).
#[derive(Clone, Copy, Debug)]
pub struct RayGenerator<'a> {
    cam: &'a Camera,
    half: Vec2,
    pinhole: bool,
    /// Camera-space film position per raster unit (the film's +x is the image's left).
    film_scale: Vec2,
    /// `to_world`'s linear part (columns) and translation.
    axes: [Vec3; 3],
    position: Vec3,
}

impl RayGenerator<'_> {
    /// See [`Camera::generate_ray`].
    #[inline(always)]
    pub fn generate_ray(&self, raster: Vec2, lens: Vec2, time: f32) -> Ray {
        let cam = self.cam;
        if self.pinhole {
            // v = (c, 1) in camera space has z = 1, so the clip planes along the optical
            // axis sit at near v and far v; all of it maps to world space linearly.
            let c = self.half + raster * self.film_scale;
            let [ax, ay, az] = self.axes;
            let v = ax * c.x + ay * c.y + az;
            let len = v.length();
            let mut ray = Ray::with_max(self.position + v * cam.near_clip, v / len, (cam.far_clip - cam.near_clip) * len);
            ray.time = cam.shutter_open + time * (cam.shutter_close - cam.shutter_open);
            return ray;
        }
        let c = cam.raster_to_camera(raster, self.half);
        let (o, d) = match cam.projection {
            Projection::Perspective { aperture_radius, focus_distance, .. } => {
                let d = Vec3::new(c.x, c.y, 1.0).normalize();
                if aperture_radius > 0.0 {
                    let pl = warp::square_to_uniform_disk_concentric(lens) * aperture_radius;
                    let ft = focus_distance / d.z;
                    let focus = d * ft;
                    let o = Vec3::new(pl.x, pl.y, 0.0);
                    (o, (focus - o).normalize())
                } else {
                    (Vec3::ZERO, d)
                }
            }
            Projection::Orthographic => (Vec3::new(c.x, c.y, 0.0), Vec3::Z),
        };
        // Near and far clip are distances along the optical axis.
        let near = cam.near_clip / d.z;
        let far = cam.far_clip / d.z;
        let o_cam = o + d * near;
        let ow = cam.to_world.transform_point3(o_cam);
        let dw = cam.to_world.transform_vector3(d);
        let len = dw.length();
        let mut ray = Ray::with_max(ow, dw / len, (far - near) * len);
        ray.time = cam.shutter_open + time * (cam.shutter_close - cam.shutter_open);
        ray
    }

    /// Whether the camera is a pinhole ([`Self::pinhole_lanes`]).
    #[inline]
    pub fn is_pinhole(&self) -> bool {
        self.pinhole
    }

    /// `generate_ray` of a pinhole for `N` lanes at once (raster positions `raster`, time
    /// numbers `time`): each lane's operations are the single ray's, without branches, so
    /// that the lanes run as vector lanes (a ray's square root and divisions wait on each
    /// other). The same bits. Only for a pinhole ([`Self::is_pinhole`]).
    #[inline(always)]
    pub fn pinhole_lanes<const N: usize>(&self, raster: &[[f32; N]; 2], time: &[f32; N]) -> RayLanes<N> {
        debug_assert!(self.pinhole);
        let cam = self.cam;
        let mut r = RayLanes { o: [[0.0; N]; 3], d: [[0.0; N]; 3], t_max: [0.0; N], time: [0.0; N] };
        let [ax, ay, az] = self.axes;
        for l in 0..N {
            let c = self.half + Vec2::new(raster[0][l], raster[1][l]) * self.film_scale;
            let v = ax * c.x + ay * c.y + az;
            let len = v.length();
            let (o, d) = (self.position + v * cam.near_clip, v / len);
            for k in 0..3 {
                r.o[k][l] = o[k];
                r.d[k][l] = d[k];
            }
            r.t_max[l] = (cam.far_clip - cam.near_clip) * len;
            r.time[l] = cam.shutter_open + time[l] * (cam.shutter_close - cam.shutter_open);
        }
        r
    }
}

/// The rays of [`RayGenerator::pinhole_lanes`], one lane each: origin, direction, extent, time.
#[derive(Clone, Copy, Debug)]
pub struct RayLanes<const N: usize> {
    pub o: [[f32; N]; 3],
    pub d: [[f32; N]; 3],
    pub t_max: [f32; N],
    pub time: [f32; N],
}

/// Mitsuba's `fov_axis`: the horizontal field of view (degrees) of a `fov` given along
/// `axis` ("x", "y", "diagonal", "smaller", "larger") for a film of `width` x `height`.
pub fn fov_x_from_axis(fov_deg: f32, axis: &str, width: u32, height: u32) -> crate::Result<f32> {
    if !(fov_deg > 0.0 && fov_deg < 180.0) {
        return Err(crate::Error::Invalid(format!("field of view {fov_deg} is not in (0, 180) degrees")));
    }
    let aspect = width as f64 / height.max(1) as f64;
    let t = (0.5 * (fov_deg as f64).to_radians()).tan();
    let from_y = || 2.0 * (t * aspect).atan();
    let fov_x = match axis {
        "x" => return Ok(fov_deg),
        "y" => from_y(),
        // The diagonal's half-length is t; the width's share of it is aspect / sqrt(1 + aspect²).
        "diagonal" => 2.0 * (t * aspect / (1.0 + aspect * aspect).sqrt()).atan(),
        "smaller" => {
            if aspect > 1.0 {
                from_y()
            } else {
                return Ok(fov_deg);
            }
        }
        "larger" => {
            if aspect > 1.0 {
                return Ok(fov_deg);
            } else {
                from_y()
            }
        }
        _ => return Err(crate::Error::Invalid(format!("unknown fov_axis \"{axis}\" (x, y, diagonal, smaller, larger)"))),
    };
    Ok(fov_x.to_degrees() as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `pinhole_lanes` gives `generate_ray`'s rays bit for bit (a moving shutter, rasters
    /// across and past the film).
    #[test]
    fn pinhole_lanes_are_generate_ray() {
        let cam = Camera {
            to_world: crate::io::mitsuba::look_at(Vec3::new(0.5, -0.25, -1.0), Vec3::new(0.1, 0.3, 4.0), Vec3::Y).expect("a frame"),
            projection: Projection::Perspective { fov_x_deg: 53.0, aperture_radius: 0.0, focus_distance: 1.0 },
            width: 37,
            height: 23,
            near_clip: 0.013,
            far_clip: 170.0,
            shutter_open: 0.2,
            shutter_close: 0.7,
        };
        let gen = cam.ray_generator();
        assert!(gen.is_pinhole());
        let mut rng = crate::sampling::Pcg32::new(3, 5);
        for _ in 0..500 {
            let mut raster = [[0.0f32; 8]; 2];
            let mut time = [0.0f32; 8];
            for l in 0..8 {
                raster[0][l] = 40.0 * rng.next_f32() - 1.0;
                raster[1][l] = 25.0 * rng.next_f32() - 1.0;
                time[l] = rng.next_f32();
            }
            let r = gen.pinhole_lanes(&raster, &time);
            for l in 0..8 {
                let want = gen.generate_ray(Vec2::new(raster[0][l], raster[1][l]), Vec2::new(0.3, 0.6), time[l]);
                let got =
                    Ray { o: Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]), d: Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]), t_max: r.t_max[l], time: r.time[l] };
                let bits = |r: &Ray| (r.o.to_array().map(f32::to_bits), r.d.to_array().map(f32::to_bits), r.t_max.to_bits(), r.time.to_bits());
                assert_eq!(bits(&got), bits(&want), "lane {l}");
            }
        }
    }

    #[test]
    fn fov_axis_conversions() {
        assert_eq!(fov_x_from_axis(40.0, "x", 200, 100).unwrap(), 40.0);
        // Square pixels: tan(fx/2) = aspect tan(fy/2).
        let fx = fov_x_from_axis(30.0, "y", 200, 100).unwrap();
        assert!(((0.5 * fx.to_radians()).tan() - 2.0 * (15f32.to_radians()).tan()).abs() < 1e-5);
        assert_eq!(fov_x_from_axis(30.0, "smaller", 200, 100).unwrap(), fx);
        assert_eq!(fov_x_from_axis(30.0, "larger", 200, 100).unwrap(), 30.0);
        // Diagonal of a square film: tan(fx/2) = tan(fd/2) / sqrt(2).
        let fx = fov_x_from_axis(60.0, "diagonal", 100, 100).unwrap();
        assert!(((0.5 * fx.to_radians()).tan() - (30f32.to_radians()).tan() / 2f32.sqrt()).abs() < 1e-5);
        assert!(fov_x_from_axis(60.0, "z", 100, 100).is_err());
        assert!(fov_x_from_axis(f32::NAN, "x", 100, 100).is_err());
    }

    #[test]
    fn orthographic_extent_follows_mitsuba() {
        // Mitsuba: x spans [-1, 1] whatever the aspect; y spans [-1/aspect, 1/aspect].
        for &(w, h) in &[(200u32, 100u32), (100, 200)] {
            let cam = Camera {
                to_world: Mat4::IDENTITY,
                projection: Projection::Orthographic,
                width: w,
                height: h,
                near_clip: 0.0,
                far_clip: 10.0,
                shutter_open: 0.0,
                shutter_close: 0.0,
            };
            let a = w as f32 / h as f32;
            let r = cam.generate_ray(Vec2::new(0.0, 0.0), Vec2::splat(0.5), 0.0);
            assert!((r.o - Vec3::new(1.0, 1.0 / a, 0.0)).length() < 1e-5, "{w}x{h}: {:?}", r.o);
            assert!((r.d - Vec3::Z).length() < 1e-6);
        }
    }

    #[test]
    fn center_ray_looks_down_z() {
        let cam = Camera {
            to_world: Mat4::IDENTITY,
            projection: Projection::Perspective { fov_x_deg: 90.0, aperture_radius: 0.0, focus_distance: 1.0 },
            width: 100,
            height: 50,
            near_clip: 0.0,
            far_clip: 1e4,
            shutter_open: 0.0,
            shutter_close: 0.0,
        };
        let r = cam.generate_ray(Vec2::new(50.0, 25.0), Vec2::splat(0.5), 0.5);
        assert!((r.d - Vec3::Z).length() < 1e-6);
        // Left edge of the image is +x in camera space, at 45 degrees for a 90 degree fov.
        let r = cam.generate_ray(Vec2::new(0.0, 25.0), Vec2::splat(0.5), 0.5);
        assert!((r.d - Vec3::new(1.0, 0.0, 1.0).normalize()).length() < 1e-6);
    }
}
