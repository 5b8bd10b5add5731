//! A luminaire from a photometric file: radiant intensity from an [`IntensityTable`] in the
//! luminaire's frame (γ = 0 along the frame's −Z, C0 along +X, C90 along +Y), at the origin
//! of `to_world` or, with `spread`, from a uniformly chosen point of the luminous opening
//! (the same distribution from every point: the far-field table spread over the face).
//!
//! Units: the table is in candela; one candela of white light is 1/683 W/sr with the
//! Rec.709 luminance weights, and a colour is normalised to luminance 1, so a file of Φ lm
//! puts Φ lm (× `scale`) into the scene.
//!
//! Sampling: the position is a delta (or, spread, a point of the opening chosen once per
//! sample and carried by the light vertex); directions for emission are drawn by the
//! table's cells in proportion to their flux.

use super::{EmissionSample, LightSample};
use crate::geometry::Ray;
use crate::photometry::{IntensityTable, Opening, LM_PER_W};
use crate::spectrum::Rgb;
use glam::{Mat4, Vec2, Vec3};
use std::sync::Arc;

#[derive(Clone, Debug)]
pub struct Luminaire {
    pub position: Vec3,
    /// The frame's axes in the world (orthonormal, right-handed).
    pub axes: [Vec3; 3],
    pub table: Arc<IntensityTable>,
    /// W/sr per candela, per channel.
    pub per_cd: Rgb,
    /// The opening emission is spread over (None: a point).
    pub spread: Option<Opening>,
    /// The file's luminous opening (whether or not emission is spread over it): the
    /// luminous area that glare ratings divide the intensity by.
    pub opening: Opening,
    /// For reports: the file's name and label, and its input power (W) where it states one.
    pub name: String,
    pub input_watts: Option<f64>,
}

impl Luminaire {
    /// `to_world`: position and orientation (its linear part is orthonormalised: scale does
    /// not stretch the distribution). `color` is normalised to luminance 1.
    pub fn new(table: Arc<IntensityTable>, to_world: &Mat4, scale: f32, color: Rgb, spread: Option<Opening>) -> Self {
        let position = to_world.transform_point3(Vec3::ZERO);
        let z = to_world.transform_vector3(Vec3::Z).try_normalize().unwrap_or(Vec3::Z);
        let x0 = to_world.transform_vector3(Vec3::X);
        let x = (x0 - z * x0.dot(z)).try_normalize().unwrap_or_else(|| crate::math::Frame::from_normal(z).s);
        let y = z.cross(x);
        let lum = color.luminance();
        let color = if lum > 0.0 { color / lum } else { Rgb::WHITE };
        let per_cd = color * (scale / LM_PER_W as f32);
        let opening = spread.unwrap_or(Opening::Point);
        let spread = spread.filter(|o| o.area() > 0.0);
        Luminaire { position, axes: [x, y, z], table, per_cd, spread, opening, name: String::new(), input_watts: None }
    }

    /// World direction `w` in the luminaire's frame (x = C0, y = C90, z = up, γ = 0 at −z).
    pub fn to_local(&self, w: Vec3) -> Vec3 {
        Vec3::new(w.dot(self.axes[0]), w.dot(self.axes[1]), w.dot(self.axes[2]))
    }

    fn to_world(&self, v: Vec3) -> Vec3 {
        self.axes[0] * v.x + self.axes[1] * v.y + self.axes[2] * v.z
    }

    /// Radiant intensity (W/sr) toward world direction `w` (unit, leaving the luminaire).
    pub fn intensity(&self, w: Vec3) -> Rgb {
        self.per_cd * self.table.eval(self.to_local(w)) as f32
    }

    /// Luminous intensity (cd) toward world direction `w`, scale included.
    pub fn candela(&self, w: Vec3) -> f64 {
        self.intensity(w).luminance() as f64 * LM_PER_W
    }

    /// Luminous flux put into the scene (lm).
    pub fn flux_lm(&self) -> f64 {
        self.table.flux() * self.per_cd.luminance() as f64 * LM_PER_W
    }

    /// Radiant power by luminance (W), for light selection.
    pub fn power(&self) -> f32 {
        (self.table.flux() * self.per_cd.luminance() as f64) as f32
    }

    /// The emitting point for a sample `u` (the centre without spread).
    pub fn origin(&self, u: Vec2) -> Vec3 {
        match self.spread {
            None | Some(Opening::Point) => self.position,
            Some(Opening::Rectangle { length, width, .. }) => {
                self.position + self.to_world(Vec3::new((u.x - 0.5) * length as f32, (u.y - 0.5) * width as f32, 0.0))
            }
            Some(Opening::Disk { diameter, .. }) => {
                let d = crate::math::warp::square_to_uniform_disk_concentric(u) * (0.5 * diameter as f32);
                self.position + self.to_world(Vec3::new(d.x, d.y, 0.0))
            }
        }
    }

    pub fn sample_li(&self, p_ref: Vec3, u: Vec2) -> Option<LightSample> {
        let p = self.origin(u);
        let d = p - p_ref;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let i = self.intensity(-wi);
        if i.is_black() {
            return None;
        }
        Some(LightSample { wi, li: i / dist2, pdf: 1.0, p, n: Vec3::ZERO, infinite: false })
    }

    pub fn sample_le(&self, u_pos: Vec2, u_dir: Vec2, time: f32) -> Option<EmissionSample> {
        let (local, pdf_dir) = self.table.sample(u_dir)?;
        if pdf_dir <= 0.0 {
            return None;
        }
        let d = self.to_world(local);
        let mut ray = Ray::new(self.origin(u_pos), d);
        ray.time = time;
        Some(EmissionSample { ray, le: self.intensity(d), pdf_pos: 1.0, pdf_dir, n: d })
    }

    /// Solid-angle density of `sample_le`'s direction `w` (world).
    pub fn pdf_dir(&self, w: Vec3) -> f32 {
        self.table.pdf(self.to_local(w))
    }
}
