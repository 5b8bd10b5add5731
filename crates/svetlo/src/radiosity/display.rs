//! Showing a radiosity solution through the scene's camera: each camera ray finds the element
//! it hits, and the radiance leaving it is L = B / π. Flat shading uses the element's value;
//! Gouraud interpolates values at the display-mesh vertices (area-weighted averages of the
//! elements around each vertex), linearly across the element.

use super::mesh::RadiosityMesh;
use super::Shading;
use crate::integrator::{render_pixels, PixelEstimator, RenderSettings};
use crate::math::INV_PI;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;

/// Radiosity of every display vertex: the area-weighted mean of the elements that share it.
pub fn vertex_radiosity(mesh: &RadiosityMesh, b: &[Rgb]) -> Vec<Rgb> {
    let mut sum = vec![Rgb::BLACK; mesh.vertices.len()];
    let mut w = vec![0.0f32; mesh.vertices.len()];
    for (e, be) in mesh.elements.iter().zip(b) {
        for v in e.vertex {
            sum[v as usize] += *be * e.area;
            w[v as usize] += e.area;
        }
    }
    sum.iter().zip(&w).map(|(s, w)| if *w > 0.0 { *s * (1.0 / *w) } else { Rgb::BLACK }).collect()
}

/// Radiance along camera rays from a solution.
pub struct RadiosityView<'a> {
    pub mesh: &'a RadiosityMesh,
    /// Radiosity per element (the solution, or an intermediate one with the ambient term).
    pub b: &'a [Rgb],
    pub vertex_b: Vec<Rgb>,
    pub shading: Shading,
}

impl<'a> RadiosityView<'a> {
    pub fn new(mesh: &'a RadiosityMesh, b: &'a [Rgb], shading: Shading) -> Self {
        let vertex_b = if shading == Shading::Gouraud { vertex_radiosity(mesh, b) } else { vec![] };
        RadiosityView { mesh, b, vertex_b, shading }
    }

    /// Gouraud display with given vertex values (one per display vertex).
    pub fn with_vertex_values(mesh: &'a RadiosityMesh, b: &'a [Rgb], vertex_b: Vec<Rgb>) -> Self {
        RadiosityView { mesh, b, vertex_b, shading: Shading::Gouraud }
    }

    /// Radiosity leaving the surface the ray hits (None: the ray escapes).
    pub fn radiosity(&self, scene: &Scene, ray: &crate::geometry::Ray) -> Option<Rgb> {
        let hit = scene.intersect_prim(ray)?;
        Some(self.element_radiosity(&hit, ray.at(hit.t), ray.d).map(|(_, b)| b).unwrap_or(Rgb::BLACK))
    }

    /// The element hit at `p` by a ray along `d`, and the radiosity shown there (None: the
    /// surface has no element on that side).
    pub fn element_radiosity(&self, hit: &crate::accel::PrimHit, p: glam::Vec3, d: glam::Vec3) -> Option<(u32, Rgb)> {
        let i = self.mesh.element_at(hit, p, d)?;
        let e = &self.mesh.elements[i as usize];
        Some((
            i,
            match self.shading {
                Shading::Flat => self.b[i as usize],
                Shading::Gouraud => {
                    let w = self.mesh.corner_weights(hit, p, e);
                    self.vertex_b[e.vertex[0] as usize] * w[0] + self.vertex_b[e.vertex[1] as usize] * w[1] + self.vertex_b[e.vertex[2] as usize] * w[2]
                }
            },
        ))
    }
}

impl PixelEstimator for RadiosityView<'_> {
    fn li(&self, scene: &Scene, ray: &crate::geometry::Ray, _sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        let _ = settings;
        self.radiosity(scene, ray).map(|b| b * INV_PI).unwrap_or(Rgb::BLACK)
    }
}

/// The `radiosity` integrator: solve, then ray-cast the solution through the camera with the
/// settings' samples per pixel (antialiasing) and filter.
pub struct RadiosityIntegrator {
    pub options: super::RadiosityOptions,
}

impl crate::integrator::Integrator for RadiosityIntegrator {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &crate::integrator::Progress) -> crate::error::Result<crate::film::Film> {
        settings.validate()?;
        let mut solved = super::solve(scene, &self.options, settings.max_depth)?;
        if settings.hide_emitters {
            // Hidden emitters show only the light they reflect.
            let emission: Vec<Rgb> = solved.mesh.elements.iter().map(|e| e.emission).collect();
            for (x, e) in solved.b.iter_mut().zip(&emission) {
                *x -= *e;
            }
            if let Some(v) = &mut solved.vertex_b {
                for (x, e) in v.iter_mut().zip(vertex_radiosity(&solved.mesh, &emission)) {
                    *x -= e;
                }
            }
        }
        let view = solved.view(self.options.shading);
        if self.options.hybrid {
            let hybrid = super::hybrid::HybridView::new(scene, view, self.options.gather);
            return render_pixels(scene, settings, progress, &hybrid);
        }
        render_pixels(scene, settings, progress, &view)
    }
}
