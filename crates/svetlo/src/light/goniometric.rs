//! pbrt-v4's goniometric light: a point (delta position) whose radiant intensity toward a
//! direction is a colour times one image channel, looked up in pbrt-v4's equal-area
//! octahedral square (`math::warp::equal_area_sphere_to_square`, the infinite light's map).
//!
//! * Image: square, one value per texel (pbrt averages an RGB file's three channels), nearest
//!   lookup, row 0 at the top as stored: direction w (in the image's frame) reads the texel
//!   under `equal_area_sphere_to_square(w)`.
//! * Frame: pbrt puts the image's +z (the square's centre) along the light's +y: the image
//!   frame is the light's (the CTM's) with y and z swapped (`renderFromLight * swapYZ`).
//!   `to_world` below is already that composition.
//! * Emission sampling: texels chosen in proportion to their value (one 2-D piecewise-constant
//!   distribution over the square), then a uniform point inside; the map preserves area, so
//!   the solid-angle density is pdf_square / 4π, exactly proportional to the intensity.

use super::{EmissionSample, LightSample};
use crate::geometry::Ray;
use crate::math::warp::{equal_area_sphere_to_square, equal_area_square_to_sphere};
use crate::math::PI;
use crate::sampling::Distribution2D;
use crate::spectrum::Rgb;
use glam::{Mat3, Mat4, Vec2, Vec3};

#[derive(Clone, Debug)]
pub struct Goniometric {
    pub position: Vec3,
    /// Image frame to world (directions), and its inverse.
    local_to_world: Mat3,
    world_to_local: Mat3,
    /// Colour × scale (W/sr per unit of the image's value).
    pub intensity: Rgb,
    /// The image's single channel, `res` × `res`, row 0 at the top.
    pub values: Vec<f32>,
    pub res: usize,
    dist: Distribution2D,
    /// Mean of `values`.
    mean: f32,
}

impl Goniometric {
    /// `to_world`: image frame to world (pbrt's `renderFromLight * swapYZ`); its linear part
    /// must be invertible. `values`: `res`² non-negative finite texels. None otherwise.
    pub fn new(to_world: &Mat4, intensity: Rgb, values: Vec<f32>, res: usize) -> Option<Goniometric> {
        let local_to_world = Mat3::from_mat4(*to_world);
        let det = local_to_world.determinant();
        if !(res > 0 && values.len() == res * res && det.abs() > 1e-12 && det.is_finite()) {
            return None;
        }
        if values.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return None;
        }
        let dist = Distribution2D::new(&values, res, res);
        let mean = (values.iter().map(|&v| v as f64).sum::<f64>() / values.len() as f64) as f32;
        Some(Goniometric {
            position: to_world.transform_point3(Vec3::ZERO),
            local_to_world,
            world_to_local: local_to_world.inverse(),
            intensity,
            values,
            res,
            dist,
            mean,
        })
    }

    /// The image frame to world.
    pub fn to_world(&self) -> Mat4 {
        Mat4::from_mat3_translation(self.local_to_world, self.position)
    }

    /// Image-frame direction (unit) of world direction `w`.
    pub fn to_local(&self, w: Vec3) -> Vec3 {
        (self.world_to_local * w).normalize_or_zero()
    }

    fn texel(&self, uv: Vec2) -> f32 {
        let n = self.res as f32;
        let x = ((uv.x * n) as usize).min(self.res - 1);
        let y = ((uv.y * n) as usize).min(self.res - 1);
        self.values[y * self.res + x]
    }

    /// Radiant intensity toward world direction `w` (unit, leaving the light).
    pub fn eval(&self, w: Vec3) -> Rgb {
        let l = self.to_local(w);
        if l == Vec3::ZERO {
            return Rgb::BLACK;
        }
        self.intensity * self.texel(equal_area_sphere_to_square(l))
    }

    /// ∫ I dω over the sphere: every texel covers 4π / res² sr (luminance).
    pub fn power(&self) -> f32 {
        4.0 * PI * self.mean * self.intensity.luminance()
    }

    /// The factor `power` multiplies the colour's luminance by: 4π × the image's mean.
    pub fn solid_angle_weight(&self) -> f32 {
        4.0 * PI * self.mean
    }

    pub fn sample_li(&self, p_ref: Vec3) -> Option<LightSample> {
        let d = self.position - p_ref;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let i = self.eval(-wi);
        if i.is_black() {
            return None;
        }
        Some(LightSample { wi, li: i / dist2, pdf: 1.0, p: self.position, n: Vec3::ZERO, infinite: false })
    }

    pub fn sample_le(&self, u_dir: Vec2, time: f32) -> Option<EmissionSample> {
        if self.mean <= 0.0 {
            return None;
        }
        let (uv, pdf_uv) = self.dist.sample(u_dir);
        if pdf_uv <= 0.0 {
            return None;
        }
        let d = (self.local_to_world * equal_area_square_to_sphere(uv)).normalize_or_zero();
        if d == Vec3::ZERO {
            return None;
        }
        let mut ray = Ray::new(self.position, d);
        ray.time = time;
        Some(EmissionSample { ray, le: self.eval(d), pdf_pos: 1.0, pdf_dir: pdf_uv / (4.0 * PI), n: d })
    }

    /// Solid-angle density of `sample_le`'s direction `w` (world).
    pub fn pdf_dir(&self, w: Vec3) -> f32 {
        let l = self.to_local(w);
        if l == Vec3::ZERO || self.mean <= 0.0 {
            return 0.0;
        }
        self.dist.pdf(equal_area_sphere_to_square(l)) / (4.0 * PI)
    }

    /// pbrt's frame: the image frame is the light's with y and z swapped.
    pub fn pbrt_swap_yz() -> Mat4 {
        Mat4::from_cols(Vec3::X.extend(0.0), Vec3::Z.extend(0.0), Vec3::Y.extend(0.0), glam::Vec4::W)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4×4 image with one value per texel: each texel's centre direction reads it back.
    #[test]
    fn texel_lookup_by_direction() {
        let values: Vec<f32> = (0..16).map(|i| i as f32 + 1.0).collect();
        let g = Goniometric::new(&Mat4::IDENTITY, Rgb::WHITE, values, 4).unwrap();
        for y in 0..4 {
            for x in 0..4 {
                let uv = Vec2::new((x as f32 + 0.5) / 4.0, (y as f32 + 0.5) / 4.0);
                let w = equal_area_square_to_sphere(uv);
                assert_eq!(g.eval(w).r, (y * 4 + x) as f32 + 1.0, "texel ({x}, {y})");
            }
        }
    }

    /// pbrt's swapYZ: the square's centre (image +z) looks along the light's +y.
    #[test]
    fn pbrt_frame_puts_the_image_pole_on_y() {
        let m = Goniometric::pbrt_swap_yz();
        assert!((m.transform_vector3(Vec3::Z) - Vec3::Y).length() < 1e-6);
        assert!((m.transform_vector3(Vec3::Y) - Vec3::Z).length() < 1e-6);
        assert!((m.transform_vector3(Vec3::X) - Vec3::X).length() < 1e-6);
    }
}
