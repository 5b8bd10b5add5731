//! A projector: a pinhole that throws an image onto the scene (delta position), with
//! Mitsuba 3's `projector` semantics. The texture gives the irradiance `E(u, v)` on the image
//! plane one unit in front of the pinhole (local +z); the plane spans `tan_x` by `tan_y`
//! (half-extents). Local direction (x, y, z) hits it at u = 1/2 - x / (2 z tan_x),
//! v = 1/2 - y / (2 z tan_y) (u to the image's right, v down, as Mitsuba's sensors), and the
//! radiant intensity there is `I = π scale E(u, v) / cos³θ` — the π and the cos³ as Mitsuba
//! 3.9.1 evaluates them (measured through its `sample_direction`).
//!
//! pbrt-v4's `projection` light is the same pinhole with another intensity law
//! ([`ProjectorModel::Intensity`], build with [`Projector::pbrt`]): the image's pixel *is*
//! the radiant intensity, `I = scale · rgb(u, v)` (nearest texel, no 1/cos³), and its `fov`
//! spans the image's shorter axis. So a pbrt projector of image P equals a Mitsuba one of
//! irradiance E = P cos³θ / π (and the same scale); the two agree on the axis only up to
//! that π. pbrt's frame: the image's top is toward the light's +y and its left toward −x
//! (pbrt flips y, `Scale(1, -1, 1)`, and reads rows top down), so its local frame is the
//! CTM's with x negated. pbrt samples emission by the image (texels by value × cos³θ, the
//! solid angle a unit of image-plane area subtends), and so does this model.

use crate::math::PI;
use crate::sampling::Distribution2D;
use crate::spectrum::Rgb;
use crate::texture::{Bitmap, FilterMode, Texture, WrapMode};
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::sync::Arc;

#[derive(Clone, Debug)]
pub struct Projector {
    pub position: Vec3,
    /// World to local directions (the inverse of `to_world`'s linear part).
    world_to_local: Mat3,
    /// Local to world (for emitted rays).
    local_to_world: Mat3,
    pub tan_x: f32,
    pub tan_y: f32,
    pub irradiance: Texture,
    pub scale: f32,
    pub model: ProjectorModel,
    /// pbrt's model: texels by value × cos³θ (row-major, the image's layout).
    dist: Option<Distribution2D>,
    /// pbrt's model: ∫ luminance(I) dω (pixel-centre quadrature, as pbrt's `power`).
    pbrt_power: f32,
}

/// What the image means (see the module notes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProjectorModel {
    /// Mitsuba 3: irradiance on the image plane, `I = π scale E / cos³θ`.
    Irradiance,
    /// pbrt-v4: radiant intensity, `I = scale · P`.
    Intensity,
}

impl Projector {
    /// A projector at the origin of `to_world` looking along its +z, with horizontal field of
    /// view `fov_x_deg` (0 < fov < 180) and the image's `aspect` (width / height). `None`
    /// for a degenerate transform or field of view.
    pub fn new(to_world: &Mat4, fov_x_deg: f32, aspect: f32, irradiance: Texture, scale: f32) -> Option<Projector> {
        let local_to_world = Mat3::from_mat4(*to_world);
        let det = local_to_world.determinant();
        if !(det.abs() > 1e-12 && det.is_finite() && fov_x_deg > 0.0 && fov_x_deg < 180.0 && aspect > 0.0 && aspect.is_finite()) {
            return None;
        }
        let tan_x = (0.5 * fov_x_deg.to_radians()).tan();
        Some(Projector {
            position: to_world.transform_point3(Vec3::ZERO),
            world_to_local: local_to_world.inverse(),
            local_to_world,
            tan_x,
            tan_y: tan_x / aspect,
            irradiance,
            scale,
            model: ProjectorModel::Irradiance,
            dist: None,
            pbrt_power: 0.0,
        })
    }

    /// pbrt-v4's `projection` light: at the origin of the light's transform `to_world` (pbrt's
    /// CTM, looking along +z), `fov_deg` across the image's shorter axis, intensity
    /// `scale · image` (linear RGB). None for a degenerate transform, fov or image.
    pub fn pbrt(to_world: &Mat4, fov_deg: f32, image: Arc<Bitmap>, scale: f32) -> Option<Projector> {
        let (w, h) = (image.width, image.height);
        if w == 0 || h == 0 || !(fov_deg > 0.0 && fov_deg < 180.0) {
            return None;
        }
        let aspect = w as f32 / h as f32;
        let t = (0.5 * fov_deg.to_radians()).tan();
        let tan_x = if aspect > 1.0 { t * aspect } else { t };
        let fov_x = 2.0 * tan_x.atan().to_degrees();
        // pbrt's image left is toward −x (module notes); the projector's is toward +x.
        let flip = Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let tex = Texture::Bitmap { image: image.clone(), filter: FilterMode::Nearest, wrap: WrapMode::Clamp, to_uv: glam::Affine2::IDENTITY };
        let mut p = Projector::new(&(*to_world * flip), fov_x, aspect, tex, scale)?;
        p.model = ProjectorModel::Intensity;
        // Texel weights: luminance × cos³θ at the texel's centre (dω = cos³θ dA).
        let mut f = Vec::with_capacity(w * h);
        let mut sum = 0.0f64;
        for y in 0..h {
            for x in 0..w {
                let cos = p.plane_cos(Vec2::new((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32));
                let v = image.texel(x, y).luminance().max(0.0) * cos * cos * cos;
                sum += v as f64;
                f.push(v);
            }
        }
        p.pbrt_power = (scale as f64 * 4.0 * (p.tan_x * p.tan_y) as f64 * sum / (w * h) as f64) as f32;
        p.dist = (sum > 0.0).then(|| Distribution2D::new(&f, w, h));
        Some(p)
    }

    /// The projector's frame (local +z along the beam, +x toward the image's left) to world.
    pub fn to_world(&self) -> Mat4 {
        Mat4::from_mat3_translation(self.local_to_world, self.position)
    }

    /// Horizontal field of view (degrees) and the image's aspect (width / height).
    pub fn fov_x_deg(&self) -> f32 {
        2.0 * self.tan_x.atan().to_degrees()
    }

    pub fn aspect(&self) -> f32 {
        self.tan_x / self.tan_y
    }

    /// The image of `w` × `h` texels (pixel centres) that gives this projector's intensity
    /// under `model`, at the same `scale`: converts one model into the other (exact at the
    /// centres; the in-between values follow the target's lookup).
    pub fn image_for(&self, model: ProjectorModel, w: usize, h: usize) -> Bitmap {
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let uv = Vec2::new((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                let cos = self.plane_cos(uv);
                let c = self.irradiance.eval(uv);
                let k = match (self.model, model) {
                    (a, b) if a == b => 1.0,
                    // E = P cos³ / π, P = π E / cos³.
                    (ProjectorModel::Intensity, ProjectorModel::Irradiance) => cos * cos * cos / PI,
                    _ => PI / (cos * cos * cos),
                };
                data.push(c * k);
            }
        }
        Bitmap::new(w, h, data)
    }

    /// Cosine to the axis of the image-plane point at `uv`.
    fn plane_cos(&self, uv: Vec2) -> f32 {
        let q = Vec3::new((1.0 - 2.0 * uv.x) * self.tan_x, (1.0 - 2.0 * uv.y) * self.tan_y, 1.0);
        1.0 / q.length()
    }

    /// ∫ luminance(I) dω at scale 1, for pbrt's `power`.
    pub fn unit_power(&self) -> f32 {
        if self.scale > 0.0 {
            self.power() / self.scale
        } else {
            0.0
        }
    }

    /// Image-plane coordinates of world direction `w` (leaving the projector), and the cosine
    /// to the axis; None outside the image.
    fn project(&self, w: Vec3) -> Option<(Vec2, f32)> {
        let l = (self.world_to_local * w).normalize_or_zero();
        if l.z <= 0.0 {
            return None;
        }
        let uv = Vec2::new(0.5 - l.x / (2.0 * l.z * self.tan_x), 0.5 - l.y / (2.0 * l.z * self.tan_y));
        ((0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y)).then_some((uv, l.z))
    }

    /// Radiant intensity toward world direction `w` (unit, leaving the projector).
    pub fn intensity(&self, w: Vec3) -> Rgb {
        match self.project(w) {
            Some((uv, cos)) => match self.model {
                ProjectorModel::Irradiance => self.irradiance.eval(uv) * (PI * self.scale / (cos * cos * cos)),
                ProjectorModel::Intensity => self.irradiance.eval(uv) * self.scale,
            },
            None => Rgb::BLACK,
        }
    }

    /// Emitted power (luminance): ∫ I dω = π scale ∫ E dA over the image plane (Mitsuba's
    /// model; pbrt's: scale ∫ P cos³θ dA by pixel centres, as pbrt computes it).
    pub fn power(&self) -> f32 {
        if self.model == ProjectorModel::Intensity {
            return self.pbrt_power;
        }
        PI * self.scale * 4.0 * self.tan_x * self.tan_y * self.irradiance.mean().luminance()
    }

    /// A direction through a uniformly chosen point of the image plane, and its solid-angle
    /// density: dω = dA cos³θ, so pdf = 1 / (4 tan_x tan_y cos³θ).
    /// pbrt's model samples the image's texels instead (module notes).
    pub fn sample_direction(&self, u: Vec2) -> (Vec3, f32) {
        let u = match &self.dist {
            Some(d) => d.sample(u).0,
            None => u,
        };
        let q = Vec3::new((1.0 - 2.0 * u.x) * self.tan_x, (1.0 - 2.0 * u.y) * self.tan_y, 1.0);
        let d = (self.local_to_world * q).normalize();
        (d, self.pdf_direction(d))
    }

    /// Solid-angle density of [`Self::sample_direction`] for world direction `w`.
    pub fn pdf_direction(&self, w: Vec3) -> f32 {
        match self.project(w) {
            Some((uv, cos)) => {
                let p_uv = self.dist.as_ref().map_or(1.0, |d| d.pdf(uv));
                p_uv / (4.0 * self.tan_x * self.tan_y * cos * cos * cos)
            }
            None => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::{Bitmap, FilterMode, WrapMode};
    use std::sync::Arc;

    /// Mitsuba's look_at(origin (0,0,1), target 0, up y) as a matrix (columns: left, up, dir).
    fn look_down() -> Mat4 {
        Mat4::from_cols(Vec3::NEG_X.extend(0.0), Vec3::Y.extend(0.0), Vec3::NEG_Z.extend(0.0), Vec3::new(0.0, 0.0, 1.0).extend(1.0))
    }

    /// Mitsuba 3.9.1, a constant irradiance 1: `sample_direction` weights (intensity / d²) at
    /// three points, whatever the fov: π on the axis, then π / cos³θ / d².
    #[test]
    fn intensity_matches_mitsuba_constant() {
        let p = Projector::new(&look_down(), 90.0, 1.0, Texture::from(1.0), 1.0).unwrap();
        for (x, want) in [(Vec3::ZERO, PI), (Vec3::new(0.1, 0.05, 0.0), 3.16117), (Vec3::new(0.3, 0.0, 0.5), 14.6548)] {
            let d = x - p.position;
            let w = p.intensity(d.normalize()) / d.length_squared();
            assert!((w.r - want).abs() < 1e-4 * want, "{x}: {w:?} vs {want}");
        }
    }

    /// The image's orientation: a 2x2 image, each texel a different colour, seen through the
    /// four quadrants (u to the right of the projector's view, v down).
    #[test]
    fn image_orientation() {
        let c = [Rgb::new(1.0, 0.0, 0.0), Rgb::new(0.0, 1.0, 0.0), Rgb::new(0.0, 0.0, 1.0), Rgb::new(1.0, 1.0, 0.0)];
        let image = Arc::new(Bitmap::new(2, 2, c.to_vec()));
        let tex = Texture::Bitmap { image, filter: FilterMode::Nearest, wrap: WrapMode::Clamp, to_uv: glam::Affine2::IDENTITY };
        let p = Projector::new(&look_down(), 90.0, 1.0, tex, 1.0).unwrap();
        // Looking down -z with up +y, the view's right is +x: texel (1, 0) is at +x, +y.
        let at = |x: f32, y: f32| p.intensity(Vec3::new(x, y, -1.0).normalize());
        assert!(at(0.5, 0.5).g > 0.0 && at(0.5, 0.5).r == 0.0);
        assert!(at(-0.5, 0.5).r > 0.0 && at(-0.5, 0.5).g == 0.0);
        assert!(at(-0.5, -0.5).b > 0.0);
        assert!(at(0.5, -0.5).r > 0.0 && at(0.5, -0.5).g > 0.0);
        assert_eq!(at(1.5, 0.0), Rgb::BLACK, "outside the frustum");
        assert_eq!(p.intensity(Vec3::Z), Rgb::BLACK, "behind");
    }

    /// sample_direction's density integrates to 1 over the frustum and matches pdf_direction;
    /// power = ∫ I dω estimated with it.
    #[test]
    fn sampling_density_and_power() {
        let p = Projector::new(&look_down(), 70.0, 1.5, Texture::from(Rgb::new(0.2, 0.5, 0.9)), 2.0).unwrap();
        let mut rng = crate::sampling::Pcg32::new(3, 1);
        let n = 20000;
        let mut power = 0.0f64;
        for _ in 0..n {
            let u = Vec2::new(rng.next_f32(), rng.next_f32());
            let (d, pdf) = p.sample_direction(u);
            assert!((pdf - p.pdf_direction(d)).abs() <= 1e-4 * pdf);
            power += (p.intensity(d).luminance() / pdf) as f64;
        }
        // Constant intensity ratio: the estimate has no variance beyond rounding.
        assert!(((power / n as f64) as f32 - p.power()).abs() < 1e-3 * p.power());
    }
}
