//! Showing a radiosity solution through the scene's camera: each camera ray finds the element
//! it hits, and the radiance leaving it is L = B / π. Flat shading uses the element's value;
//! Gouraud interpolates values at the display-mesh vertices (area-weighted averages of the
//! elements around each vertex), linearly across the element.

use super::mesh::RadiosityMesh;
use super::Shading;
use crate::bsdf::LobeFlags;
use crate::error::{Error, Result};
use crate::integrator::{render_pixels, PixelEstimator, RenderSettings};
use crate::lpe::aov::LayerSample;
use crate::lpe::{AovSet, Event, LayerMask};
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
    /// The one-bounce part of `b` (see [`super::Solved::b_one`]), for light path expressions.
    pub b_one: Option<&'a [Rgb]>,
    /// With AOVs: per scene shape, the layers of its three classes of paths (emission `C L`,
    /// one bounce `C D L`, more `C D D+ L`), and the parts' values at the display vertices.
    routes: Option<Routes>,
}

struct Routes {
    masks: Vec<[LayerMask; 3]>,
    e: Vec<Rgb>,
    one: Vec<Rgb>,
    vertex_e: Vec<Rgb>,
    vertex_one: Vec<Rgb>,
}

impl<'a> RadiosityView<'a> {
    pub fn new(mesh: &'a RadiosityMesh, b: &'a [Rgb], shading: Shading) -> Self {
        let vertex_b = if shading == Shading::Gouraud { vertex_radiosity(mesh, b) } else { vec![] };
        RadiosityView { mesh, b, vertex_b, shading, b_one: None, routes: None }
    }

    /// Gouraud display with given vertex values (one per display vertex).
    pub fn with_vertex_values(mesh: &'a RadiosityMesh, b: &'a [Rgb], vertex_b: Vec<Rgb>) -> Self {
        RadiosityView { mesh, b, vertex_b, shading: Shading::Gouraud, b_one: None, routes: None }
    }

    /// Prepare the routing of the solution's parts to `aovs` (`hidden`: the emitters' own
    /// light was taken out of `b`): a typed error when an expression takes only some paths
    /// of one part (radiosity keeps the emitted light, one bounce and the rest apart, not
    /// every bounce), or when the solver kept no one-bounce part.
    pub fn route(&mut self, scene: &Scene, aovs: &AovSet, hidden: bool) -> Result<()> {
        if aovs.is_empty() {
            return Ok(());
        }
        let Some(one) = self.b_one else {
            return Err(Error::Settings("radiosity: light path expressions need a solver with form factors per element (not hierarchical)".into()));
        };
        let d = |shape: usize| Event::scatter(LobeFlags::DIFFUSE, false, false, aovs.shape_labels(shape as u32));
        let mut any_d: Vec<Event> = (0..scene.shapes.len()).map(d).collect();
        any_d.sort_by_key(|e| e.labels);
        any_d.dedup();
        let ends = aovs.emitter_events(scene);
        let masks = (0..scene.shapes.len())
            .map(|s| {
                let emit = aovs.class_layers(&[Event::CAMERA], &[], 0, &[aovs.light_event(Some(s as u32))])?;
                let once = aovs.class_layers(&[Event::CAMERA, d(s)], &[], 0, &ends)?;
                let more = aovs.class_layers(&[Event::CAMERA, d(s)], &any_d, 1, &ends)?;
                Ok([emit, once, more])
            })
            .collect::<std::result::Result<Vec<_>, String>>()
            .map_err(|e| {
                Error::Settings(format!(
                    "radiosity: the light path expression '{e}' takes only some of the paths of a part that radiosity keeps whole \
                     (per surface: C L, C D L, C D D+ L)"
                ))
            })?;
        let e: Vec<Rgb> = self.mesh.elements.iter().map(|e| if hidden { Rgb::BLACK } else { e.emission }).collect();
        let (vertex_e, vertex_one) =
            if self.shading == Shading::Gouraud { (vertex_radiosity(self.mesh, &e), vertex_radiosity(self.mesh, one)) } else { (Vec::new(), Vec::new()) };
        self.routes = Some(Routes { masks, e, one: one.to_vec(), vertex_e, vertex_one });
        Ok(())
    }

    /// A per-element quantity shown at `p` on element `i` as the view shows radiosity.
    fn shown(&self, hit: &crate::accel::PrimHit, p: glam::Vec3, i: u32, elem: &[Rgb], vertex: &[Rgb]) -> Rgb {
        match self.shading {
            Shading::Flat => elem[i as usize],
            Shading::Gouraud => {
                let e = &self.mesh.elements[i as usize];
                let w = self.mesh.corner_weights(hit, p, e);
                vertex[e.vertex[0] as usize] * w[0] + vertex[e.vertex[1] as usize] * w[1] + vertex[e.vertex[2] as usize] * w[2]
            }
        }
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
    /// The shown radiosity split into emitted light, one bounce and the rest (their
    /// difference, so that the parts sum to the image), each to its layers.
    fn li_layers(&self, scene: &Scene, ray: &crate::geometry::Ray, _sampler: &mut dyn Sampler, _settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        let Some(hit) = scene.intersect_prim(ray) else { return Rgb::BLACK };
        let p = ray.at(hit.t);
        let Some((i, b)) = self.element_radiosity(&hit, p, ray.d) else { return Rgb::BLACK };
        if let Some(r) = &self.routes {
            let e = self.shown(&hit, p, i, &r.e, &r.vertex_e);
            let one = self.shown(&hit, p, i, &r.one, &r.vertex_one);
            let m = r.masks[hit.shape as usize];
            layers.add(m[0], e * INV_PI);
            layers.add(m[1], one * INV_PI);
            layers.add(m[2], (b - e - one) * INV_PI);
        }
        b * INV_PI
    }
    fn supports_lpe(&self) -> bool {
        true
    }
}

/// The `radiosity` integrator: solve, then ray-cast the solution through the camera with the
/// settings' samples per pixel (antialiasing) and filter.
pub struct RadiosityIntegrator {
    pub options: super::RadiosityOptions,
}

impl crate::integrator::Integrator for RadiosityIntegrator {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &crate::integrator::Progress) -> Result<crate::film::Film> {
        settings.validate()?;
        let solved = super::solve(scene, &self.options, settings.max_depth)?;
        self.render_solved(scene, settings, progress, solved)
    }
}

impl RadiosityIntegrator {
    /// Show a solution of this integrator's system (made here or by
    /// [`super::split::solve_from_rows`] elsewhere) through the camera.
    pub fn render_solved(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        progress: &crate::integrator::Progress,
        mut solved: super::Solved,
    ) -> Result<crate::film::Film> {
        settings.validate()?;
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
        let mut view = solved.view(self.options.shading);
        if self.options.hybrid {
            settings.check_lpe_support("radiosity's hybrid display", false)?;
            let hybrid = super::hybrid::HybridView::new(scene, view, self.options.gather);
            return render_pixels(scene, settings, progress, &hybrid);
        }
        view.route(scene, settings.aovs(), settings.hide_emitters)?;
        render_pixels(scene, settings, progress, &view)
    }
}
