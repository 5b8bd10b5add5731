//! Assembles a [`Scene`] from parts, validating what user input could get wrong.

use super::{LightSelection, MovingShape, Scene, SceneSettings, Shape};
use crate::accel::Accel;
use crate::bsdf::Material;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::geometry::{AnimatedTransform, Geometry, Motion, TriangleMesh};
use crate::light::{AreaLight, Light, SceneBounds};
use crate::sampling::Distribution1D;
use crate::texture::Texture;
use std::sync::Arc;

/// Probabilities of choosing each light for next-event estimation.
pub(super) fn light_selection_distribution(lights: &[Light], bounds: &SceneBounds, how: LightSelection) -> Distribution1D {
    let n = lights.len().max(1) as f32;
    let powers: Vec<f32> = lights.iter().map(|l| l.power(bounds)).collect();
    let total: f32 = powers.iter().sum();
    let weights: Vec<f32> = match how {
        LightSelection::Uniform => vec![1.0; lights.len()],
        LightSelection::Power if total > 0.0 => powers,
        // Half by power, half uniform: power alone starves lights that matter locally (a spot in
        // a sky-lit scene: the sky's power is counted over the whole scene's cross-section), and
        // uniform alone wastes samples on faint lights. The mixture is never worse than twice either.
        LightSelection::Mixed if total > 0.0 => powers.iter().map(|p| 0.5 * p / total + 0.5 / n).collect(),
        _ => vec![1.0; lights.len()],
    };
    Distribution1D::new(&weights)
}

/// A shape as added: geometry, material, emission, name, animation.
type PendingShape = (Geometry, u32, Option<Texture>, String, Option<AnimatedTransform>);

#[derive(Default)]
pub struct SceneBuilder {
    shapes: Vec<PendingShape>,
    materials: Vec<Material>,
    lights: Vec<Light>,
    camera: Option<Camera>,
    pub settings: SceneSettings,
    pub warnings: Vec<String>,
}

impl SceneBuilder {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn add_material(&mut self, m: Material) -> u32 {
        self.materials.push(m);
        (self.materials.len() - 1) as u32
    }

    /// A material added before.
    pub fn material(&self, i: u32) -> Option<&Material> {
        self.materials.get(i as usize)
    }

    /// Add a shape with material `material`, emitting `emission` radiance if given.
    /// Meshes are checked: NaN or infinite positions and out-of-range indices are errors,
    /// zero-area triangles are dropped with a warning. `name` identifies it in messages.
    pub fn add_shape(&mut self, geometry: Geometry, material: u32, emission: Option<Texture>, name: &str) -> Result<()> {
        let geometry = match geometry {
            Geometry::Mesh(m) => Geometry::Mesh(self.validate_mesh(m, name)?),
            Geometry::Sphere(s) => {
                if !(s.radius > 0.0 && s.radius.is_finite() && s.center.is_finite()) {
                    return Err(Error::Invalid(format!("shape '{name}': sphere with radius {} at {:?}", s.radius, s.center)));
                }
                Geometry::Sphere(s)
            }
            Geometry::SdfGrid(g) => {
                if emission.is_some() {
                    return Err(Error::Invalid(format!("shape '{name}': an sdfgrid cannot be an area emitter (Mitsuba 3 does not support it either)")));
                }
                Geometry::SdfGrid(g)
            }
        };
        if material as usize >= self.materials.len() {
            return Err(Error::Invalid(format!("shape '{name}': material index {material} out of range")));
        }
        self.shapes.push((geometry, material, emission, name.to_string(), None));
        Ok(())
    }

    /// Add a shape that moves during the shutter: `geometry` is given in its pose at the
    /// animation's first keyframe (`animation.reference()`). Moving emitters are not supported
    /// (their light sampling would need the time); an animation that does not move adds a static shape.
    pub fn add_animated_shape(&mut self, geometry: Geometry, material: u32, emission: Option<Texture>, name: &str, animation: AnimatedTransform) -> Result<()> {
        if animation.is_static() {
            return self.add_shape(geometry, material, emission, name);
        }
        if emission.is_some() {
            return Err(Error::Invalid(format!("shape '{name}': an emitting shape cannot be animated (moving area lights are not supported)")));
        }
        self.add_shape(geometry, material, None, name)?;
        if let Some(last) = self.shapes.last_mut() {
            last.4 = Some(animation);
        }
        Ok(())
    }

    fn validate_mesh(&mut self, mut m: TriangleMesh, name: &str) -> Result<TriangleMesh> {
        if let Some(i) = m.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::Invalid(format!("shape '{name}': vertex {i} is not finite ({:?})", m.positions[i])));
        }
        let nv = m.positions.len() as u32;
        if let Some((t, tri)) = m.indices.iter().enumerate().find(|(_, t)| t.iter().any(|&i| i >= nv)) {
            return Err(Error::Invalid(format!("shape '{name}': triangle {t} has index {:?} but the mesh has {nv} vertices", tri)));
        }
        if !m.normals.is_empty() && m.normals.len() != m.positions.len() {
            self.warnings.push(format!("shape '{name}': {} normals for {} vertices, normals ignored", m.normals.len(), nv));
            m.normals.clear();
        }
        if m.normals.iter().any(|n| !n.is_finite()) {
            self.warnings.push(format!("shape '{name}': non-finite normals, normals ignored"));
            m.normals.clear();
        }
        if !m.uvs.is_empty() && m.uvs.len() != m.positions.len() {
            self.warnings.push(format!("shape '{name}': {} uvs for {} vertices, uvs ignored", m.uvs.len(), nv));
            m.uvs.clear();
        }
        let before = m.indices.len();
        let pos = &m.positions;
        m.indices.retain(|t| {
            let (a, b, c) = (pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]);
            (b - a).cross(c - a).length_squared() > 0.0
        });
        let dropped = before - m.indices.len();
        if dropped > 0 {
            self.warnings.push(format!("shape '{name}': dropped {dropped} zero-area triangle(s) of {before}"));
        }
        if m.indices.is_empty() {
            return Err(Error::Invalid(format!("shape '{name}': mesh has no triangle with non-zero area ({before} given)")));
        }
        Ok(m)
    }

    pub fn add_light(&mut self, l: Light) {
        self.lights.push(l);
    }

    pub fn set_camera(&mut self, c: Camera) {
        self.camera = Some(c);
    }

    pub fn has_camera(&self) -> bool {
        self.camera.is_some()
    }

    pub fn shape_count(&self) -> usize {
        self.shapes.len()
    }

    pub fn build(self) -> Result<Scene> {
        let camera = self.camera.ok_or_else(|| Error::Invalid("the scene has no sensor (camera)".into()))?;
        if camera.width == 0 || camera.height == 0 {
            return Err(Error::Invalid(format!("film size {}x{} is empty", camera.width, camera.height)));
        }
        let mut lights = self.lights;
        let mut shapes = Vec::with_capacity(self.shapes.len());
        for (i, (g, material, emission, name, animation)) in self.shapes.into_iter().enumerate() {
            let g = Arc::new(g);
            let light = emission.map(|e| {
                lights.push(Light::Area(AreaLight::new(i as u32, g.clone(), e)));
                (lights.len() - 1) as u32
            });
            let mut shape = Shape::new(g, material, light, name, animation.map(|a| Arc::new(Motion::new(a))));
            shape.detail = self.materials.get(material as usize).is_some_and(|m| m.has_detail());
            shapes.push(shape);
        }
        // The tables the used materials' BSDFs look up, built before the render starts.
        let mut used: Vec<u32> = shapes.iter().map(|s| s.material).collect();
        used.sort_unstable();
        used.dedup();
        for m in used {
            if let Some(m) = self.materials.get(m as usize) {
                m.prepare_tables();
            }
        }
        let static_ids: Vec<u32> = (0..shapes.len() as u32).filter(|&i| shapes[i as usize].motion.is_none()).collect();
        let geoms: Vec<&Geometry> = static_ids.iter().map(|&i| &*shapes[i as usize].geometry).collect();
        let accel = Accel::build(&geoms);
        let moving: Vec<MovingShape> = shapes
            .iter()
            .enumerate()
            .filter_map(|(i, s)| {
                let motion = s.motion.clone()?;
                let accel = Accel::build(&[&*s.geometry]);
                let (t0, t1) = motion.animation.time_range();
                let bounds = motion.bounds(&accel.bounds(), t0, t1);
                Some(MovingShape { shape: i as u32, accel, motion, bounds })
            })
            .collect();
        let all_bounds = moving.iter().fold(accel.bounds(), |b, m| b.union(m.bounds));
        let bounds = SceneBounds::from_aabb(&all_bounds);
        let static_shapes = if moving.is_empty() { Vec::new() } else { static_ids };
        let light_distribution = light_selection_distribution(&lights, &bounds, self.settings.light_selection);
        let environment_lights =
            lights.iter().enumerate().filter(|(_, l)| matches!(l, Light::Constant { .. } | Light::EnvMap(_))).map(|(i, _)| i as u32).collect();
        let mut warnings = self.warnings;
        if lights.is_empty() {
            warnings.push("the scene has no emitter: the image will be black".into());
        }
        Ok(Scene {
            shapes,
            materials: self.materials,
            lights,
            light_distribution,
            environment_lights,
            camera,
            accel,
            static_shapes,
            moving,
            bounds,
            settings: self.settings,
            warnings,
            packet_tree: Default::default(),
            kernel_geometry: Default::default(),
        })
    }
}
