//! Animated transforms for motion blur: keyframes of a shape's to_world, interpolated in
//! time as translation (linear), rotation (spherical linear) and scale (linear), held at the
//! first and last keyframes outside their interval.
//!
//! A moving shape's geometry is stored in world space at its first keyframe (the reference
//! pose), so that methods that ignore time (radiosity) see it there; at time t it is carried
//! by the relative transform `A(t) A(t0)⁻¹`.

use super::Aabb;
use crate::error::{Error, Result};
use glam::{Mat3, Mat4, Quat, Vec3};

#[derive(Clone, Copy, Debug)]
struct Key {
    time: f32,
    translation: Vec3,
    rotation: Quat,
    scale: Vec3,
}

impl Key {
    fn matrix(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

#[derive(Clone, Debug)]
pub struct AnimatedTransform {
    keys: Vec<Key>,
}

impl AnimatedTransform {
    /// Keyframes `(time, to_world)`, times strictly increasing. Each matrix must be a
    /// translation, rotation and (possibly non-uniform, non-zero) scale, without shear or
    /// projection: those cannot be interpolated meaningfully.
    pub fn new(keys: &[(f32, Mat4)]) -> Result<Self> {
        if keys.is_empty() {
            return Err(Error::Invalid("an animation needs at least one keyframe".into()));
        }
        let mut out: Vec<Key> = Vec::with_capacity(keys.len());
        for (i, &(time, m)) in keys.iter().enumerate() {
            if !time.is_finite() {
                return Err(Error::Invalid(format!("keyframe {i}: time {time} is not finite")));
            }
            if let Some(prev) = out.last() {
                if time <= prev.time {
                    return Err(Error::Invalid(format!("keyframe {i}: time {time} does not follow the previous keyframe's {}", prev.time)));
                }
            }
            if !m.is_finite() || m.row(3) != glam::Vec4::W {
                return Err(Error::Invalid(format!("keyframe {i}: the transform is not finite or is projective")));
            }
            let lin = Mat3::from_mat4(m);
            if lin.determinant().abs() < 1e-12 {
                return Err(Error::Invalid(format!("keyframe {i}: the transform is singular (zero scale)")));
            }
            if let Some(prev) = out.last() {
                if (prev.scale.x * prev.scale.y * prev.scale.z).signum() != lin.determinant().signum() {
                    return Err(Error::Invalid(format!("keyframe {i}: mirrors where the previous keyframe does not (the scale would pass through zero)")));
                }
            }
            let (scale, rotation, translation) = m.to_scale_rotation_translation();
            let key = Key { time, translation, rotation: rotation.normalize(), scale };
            // Shear does not survive the decomposition: the recomposed matrix differs.
            let back = key.matrix();
            let tol = 1e-4 * lin.to_cols_array().iter().fold(1.0f32, |a, v| a.max(v.abs()));
            if (Mat3::from_mat4(back) - lin).to_cols_array().iter().any(|d| d.abs() > tol) {
                return Err(Error::Invalid(format!("keyframe {i}: the transform has shear; only translation, rotation and scale can be animated")));
            }
            out.push(key);
        }
        Ok(AnimatedTransform { keys: out })
    }

    /// Does the transform change at all?
    pub fn is_static(&self) -> bool {
        self.keys.windows(2).all(|w| w[0].translation == w[1].translation && w[0].rotation == w[1].rotation && w[0].scale == w[1].scale)
    }

    /// to_world at time `t`.
    pub fn at(&self, t: f32) -> Mat4 {
        let k = &self.keys;
        if t <= k[0].time || k.len() == 1 {
            return k[0].matrix();
        }
        let last = k[k.len() - 1];
        if t >= last.time {
            return last.matrix();
        }
        let i = k.partition_point(|key| key.time <= t) - 1;
        let (a, b) = (k[i], k[i + 1]);
        let f = (t - a.time) / (b.time - a.time);
        Mat4::from_scale_rotation_translation(a.scale.lerp(b.scale, f), a.rotation.slerp(b.rotation, f), a.translation.lerp(b.translation, f))
    }

    /// to_world at the first keyframe: the pose a moving shape's geometry is stored in.
    pub fn reference(&self) -> Mat4 {
        self.keys[0].matrix()
    }

    /// Time of the first keyframe.
    pub fn reference_time(&self) -> f32 {
        self.keys[0].time
    }

    /// First and last keyframe times: the pose is constant outside.
    pub fn time_range(&self) -> (f32, f32) {
        (self.keys[0].time, self.keys[self.keys.len() - 1].time)
    }

    /// The same animation after a fixed transform `parent` (an instance's placement).
    pub fn after(&self, parent: Mat4) -> Result<Self> {
        let keys: Vec<(f32, Mat4)> = self.keys.iter().map(|k| (k.time, parent * k.matrix())).collect();
        Self::new(&keys)
    }
}

/// A shape's motion relative to its stored (reference) pose.
#[derive(Clone, Debug)]
pub struct Motion {
    pub animation: AnimatedTransform,
    reference_inv: Mat4,
}

/// Samples of the shutter interval at which the bounds of a moving shape are taken; rotation
/// between them is covered by the padding in [`Motion::bounds`].
const BOUND_STEPS: usize = 64;

impl Motion {
    pub fn new(animation: AnimatedTransform) -> Self {
        let reference_inv = animation.reference().inverse();
        Motion { animation, reference_inv }
    }

    /// Reference pose to world at time `t`.
    #[inline]
    pub fn relative(&self, t: f32) -> Mat4 {
        self.animation.at(t) * self.reference_inv
    }

    /// Bounds of the box `b` (reference pose) over the times `[t0, t1]`: the union over the
    /// keyframes in it and `BOUND_STEPS` steps, each box grown by the largest distance a
    /// corner can move between steps (so rotation between samples stays inside).
    pub fn bounds(&self, b: &Aabb, t0: f32, t1: f32) -> Aabb {
        let corners: Vec<Vec3> = (0..8).map(|i| Vec3::new([b.min.x, b.max.x][i & 1], [b.min.y, b.max.y][(i >> 1) & 1], [b.min.z, b.max.z][i >> 2])).collect();
        let mut times: Vec<f32> = (0..=BOUND_STEPS).map(|i| t0 + (t1 - t0) * i as f32 / BOUND_STEPS as f32).collect();
        times.extend(self.animation.keys.iter().map(|k| k.time).filter(|&t| t > t0 && t < t1));
        times.sort_by(f32::total_cmp);
        let mut out = Aabb::EMPTY;
        let mut prev: Option<Vec<Vec3>> = None;
        let mut pad = 0.0f32;
        for &t in &times {
            let m = self.relative(t);
            let now: Vec<Vec3> = corners.iter().map(|&c| m.transform_point3(c)).collect();
            for &p in &now {
                out = out.grow(p);
            }
            if let Some(prev) = &prev {
                for (a, b) in prev.iter().zip(&now) {
                    pad = pad.max(a.distance(*b));
                }
            }
            prev = Some(now);
        }
        // Between two samples a point on a rotating box moves along an arc whose sagitta is
        // below the chord; the chord length bounds it.
        Aabb { min: out.min - Vec3::splat(pad), max: out.max + Vec3::splat(pad) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_translation_rotation_scale() {
        let a = Mat4::IDENTITY;
        let b = Mat4::from_scale_rotation_translation(Vec3::new(2.0, 1.0, 1.0), Quat::from_rotation_z(1.0), Vec3::new(4.0, 0.0, 0.0));
        let anim = AnimatedTransform::new(&[(0.0, a), (2.0, b)]).unwrap();
        let m = anim.at(1.0);
        let (s, r, t) = m.to_scale_rotation_translation();
        assert!((t - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-5);
        assert!((s - Vec3::new(1.5, 1.0, 1.0)).length() < 1e-5);
        assert!(r.angle_between(Quat::from_rotation_z(0.5)) < 1e-4);
        // Held outside the keyframes.
        assert!(anim.at(-1.0).abs_diff_eq(a, 1e-6));
        assert!(anim.at(3.0).abs_diff_eq(b, 1e-5));
    }

    #[test]
    fn rejects_bad_keyframes() {
        let m = Mat4::IDENTITY;
        assert!(AnimatedTransform::new(&[]).is_err());
        assert!(AnimatedTransform::new(&[(1.0, m), (1.0, m)]).is_err());
        assert!(AnimatedTransform::new(&[(1.0, m), (0.0, m)]).is_err());
        assert!(AnimatedTransform::new(&[(f32::NAN, m)]).is_err());
        let shear = Mat4::from_cols_array(&[1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        assert!(AnimatedTransform::new(&[(0.0, shear)]).is_err());
        assert!(AnimatedTransform::new(&[(0.0, Mat4::from_scale(Vec3::new(1.0, 0.0, 1.0)))]).is_err());
    }

    #[test]
    fn bounds_contain_every_pose() {
        let anim =
            AnimatedTransform::new(&[(0.0, Mat4::IDENTITY), (1.0, Mat4::from_rotation_y(3.0) * Mat4::from_translation(Vec3::new(2.0, 0.0, 0.0)))]).unwrap();
        let motion = Motion::new(anim);
        let b = Aabb { min: Vec3::splat(-0.5), max: Vec3::splat(0.5) };
        let u = motion.bounds(&b, 0.0, 1.0);
        for i in 0..=1000 {
            let m = motion.relative(i as f32 / 1000.0);
            for c in [b.min, b.max, Vec3::new(b.min.x, b.max.y, b.min.z), Vec3::new(b.max.x, b.min.y, b.max.z)] {
                let p = m.transform_point3(c);
                assert!(p.cmpge(u.min).all() && p.cmple(u.max).all(), "{p:?} outside {u:?}");
            }
        }
    }
}
