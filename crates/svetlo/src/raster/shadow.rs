//! Shadow maps: depth images rendered from a light. Point (and spot, and area lights by
//! their centre) use a cube of six 90° perspective faces; directional lights one
//! orthographic map over the scene's bounding sphere. A point is lit when its depth seen
//! from the light is within a slope-scaled bias of the stored one (the bias trades shadow
//! acne for a little light leaking at contact; resolution sets how sharp the edge is).

use super::{DepthBuffer, View, ViewProjection};
use glam::{Mat4, Vec2, Vec3, Vec4};

#[derive(Clone, Debug)]
pub enum ShadowMap {
    Cube {
        position: Vec3,
        faces: Vec<(View, DepthBuffer)>,
    },
    /// `to_light`: the unit direction toward the light.
    Directional {
        view: View,
        buffer: DepthBuffer,
        to_light: Vec3,
    },
}

fn look_at(origin: Vec3, dir: Vec3, up: Vec3) -> Mat4 {
    let z = dir.normalize();
    let x = up.cross(z).normalize();
    let y = z.cross(x);
    Mat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), Vec4::new(origin.x, origin.y, origin.z, 1.0))
}

fn render(view: View, tris: &[[Vec3; 3]]) -> DepthBuffer {
    let empty = view.key(f32::INFINITY);
    let mut keys = vec![empty; (view.width * view.height) as usize];
    for t in tris {
        view.raster_keys(t.map(|p| view.world_to_camera.transform_point3(p)), |i, k| {
            if k > keys[i] {
                keys[i] = k;
            }
        });
    }
    DepthBuffer { width: view.width, height: view.height, z: keys.into_iter().map(|k| if k == empty { f32::INFINITY } else { view.depth_of_key(k) }).collect() }
}

const AXES: [Vec3; 6] = [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z];

impl ShadowMap {
    /// Cube map around `position` of `res`² texels per face.
    pub fn point(position: Vec3, res: u32, tris: &[[Vec3; 3]], near: f32) -> Self {
        let faces = AXES
            .iter()
            .map(|&a| {
                let up = if a.y.abs() > 0.5 { Vec3::Z } else { Vec3::Y };
                let view = View {
                    world_to_camera: look_at(position, a, up).inverse(),
                    projection: ViewProjection::Perspective { half: Vec2::ONE },
                    width: res,
                    height: res,
                    near,
                };
                (view, render(view, tris))
            })
            .collect();
        ShadowMap::Cube { position, faces }
    }

    /// Orthographic map along `direction` (of travel) covering the sphere (`center`, `radius`).
    pub fn directional(direction: Vec3, center: Vec3, radius: f32, res: u32, tris: &[[Vec3; 3]]) -> Self {
        let d = direction.normalize();
        let up = if d.y.abs() > 0.9 { Vec3::Z } else { Vec3::Y };
        let view = View {
            world_to_camera: look_at(center - d * (2.0 * radius), d, up).inverse(),
            projection: ViewProjection::Orthographic { half: Vec2::splat(radius) },
            width: res,
            height: res,
            near: 0.0,
        };
        ShadowMap::Directional { view, buffer: render(view, tris), to_light: -d }
    }

    /// Whether `p` (surface normal `n`) sees the light according to the map.
    #[inline(always)]
    pub fn lit(&self, p: Vec3, n: Vec3) -> bool {
        let (view, buf, to_light) = match self {
            ShadowMap::Cube { position, faces } => {
                let d = p - *position;
                let a = d.abs();
                let k = if a.x >= a.y && a.x >= a.z {
                    if d.x > 0.0 {
                        0
                    } else {
                        1
                    }
                } else if a.y >= a.z {
                    if d.y > 0.0 {
                        2
                    } else {
                        3
                    }
                } else if d.z > 0.0 {
                    4
                } else {
                    5
                };
                (&faces[k].0, &faces[k].1, (-d).normalize_or_zero())
            }
            ShadowMap::Directional { view, buffer, to_light } => (view, buffer, *to_light),
        };
        let pc = view.world_to_camera.transform_point3(p);
        if pc.z <= 0.0 {
            return true;
        }
        let r = view.project(pc);
        // floor_i saturates out of range (and maps NaN to 0), as `floor() as i64` then the clamp.
        let x = super::floor_i(r.x).clamp(0, view.width as i32 - 1) as u32;
        let y = super::floor_i(r.y).clamp(0, view.height as i32 - 1) as u32;
        let stored = buf.z[(y * view.width + x) as usize];
        // One texel's footprint at the point, grown as the surface turns away from the light.
        let texel = match view.projection {
            ViewProjection::Perspective { half } => 2.0 * half.x * pc.z / view.width as f32,
            ViewProjection::Orthographic { half } => 2.0 * half.x / view.width as f32,
        };
        let cos = n.dot(to_light).abs().max(0.1);
        let bias = 2.0 * texel * (1.0 - cos * cos).sqrt() / cos + texel + 1e-4 * pc.z;
        pc.z <= stored + bias
    }
}
