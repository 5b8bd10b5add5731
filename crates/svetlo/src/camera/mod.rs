//! Cameras: perspective (pinhole), thin lens, orthographic. Camera space looks down +z
//! with +y up and +x to the left of the image, as in Mitsuba (`lookat` gives to_world).

use crate::geometry::Ray;
use crate::math::warp;
use glam::{Mat4, Vec2, Vec3};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Pinhole when `aperture_radius` is 0, thin lens otherwise.
    Perspective { fov_x_deg: f32, aperture_radius: f32, focus_distance: f32 },
    /// Orthographic: the film spans [-1,1] on both axes in camera space (scale with to_world).
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
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// Camera-space position on the plane z = 1 of a raster point (pixels, origin top-left).
    fn raster_to_camera(&self, raster: Vec2) -> Vec2 {
        let ndc = Vec2::new(raster.x / self.width as f32, raster.y / self.height as f32);
        match self.projection {
            Projection::Perspective { fov_x_deg, .. } => {
                let tx = (0.5 * fov_x_deg.to_radians()).tan();
                let ty = tx / self.aspect();
                // +x of camera space is the image's left.
                Vec2::new((1.0 - 2.0 * ndc.x) * tx, (1.0 - 2.0 * ndc.y) * ty)
            }
            Projection::Orthographic => {
                let a = self.aspect();
                let (sx, sy) = if a >= 1.0 { (1.0, 1.0 / a) } else { (a, 1.0) };
                Vec2::new((1.0 - 2.0 * ndc.x) * sx, (1.0 - 2.0 * ndc.y) * sy)
            }
        }
    }

    /// The ray through raster position `raster`, lens sample `lens` in [0,1)^2 and time
    /// sample `time` in [0,1). Directions are unit length; `t_max` honours the far clip.
    pub fn generate_ray(&self, raster: Vec2, lens: Vec2, time: f32) -> Ray {
        let c = self.raster_to_camera(raster);
        let (o, d) = match self.projection {
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
        let near = self.near_clip / d.z;
        let far = self.far_clip / d.z;
        let o_cam = o + d * near;
        let ow = self.to_world.transform_point3(o_cam);
        let dw = self.to_world.transform_vector3(d);
        let len = dw.length();
        let mut ray = Ray::with_max(ow, dw / len, (far - near) * len);
        ray.time = self.shutter_open + time * (self.shutter_close - self.shutter_open);
        ray
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
