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
use crate::lpe::{AovSet, ClassPart, Event, LayerMask};
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

/// Shapes whose material has only delta lobes (mirror, smooth glass): no elements, followed
/// by extended form factors and by the hybrid display's rays.
pub fn specular_shapes(scene: &Scene) -> Vec<bool> {
    scene.shapes.iter().map(|s| !scene.materials[s.material as usize].bsdf(glam::Vec2::splat(0.5)).flags().has_non_specular()).collect()
}

/// The classes of paths behind a radiosity value, after the diffuse reflection at its element
/// ([`Self::event`], read apart): the one-bounce part ρ F E + lit reaches an emitter directly
/// (`S* L` with extended form factors, which carry light through specular surfaces) and the
/// rest reflects diffusely again (`S* D [DS]* L`). Shared by the plain and the hybrid display.
pub struct SolutionClasses {
    /// Specular events the form factors follow (none unless extended).
    s: Vec<Event>,
    /// Diffuse reflections at the surfaces with elements.
    d: Vec<Event>,
    sd: Vec<Event>,
    /// The emitters in the solution (not the environment).
    pub ends: Vec<Event>,
}

impl SolutionClasses {
    pub fn new(scene: &Scene, aovs: &AovSet, extended: bool) -> Self {
        let spec = specular_shapes(scene);
        let mut d: Vec<Event> = (0..scene.shapes.len()).filter(|&s| !spec[s]).map(|s| Self::event(aovs, s as u32)).collect();
        let mut s = if extended { specular_events(aovs, &spec) } else { Vec::new() };
        for v in [&mut d, &mut s] {
            v.sort_by_key(|e| (e.base, e.labels));
            v.dedup();
        }
        let sd = d.iter().chain(&s).copied().collect();
        use crate::light::Light;
        let mut ends: Vec<Event> =
            scene.lights.iter().filter(|l| !matches!(l, Light::Constant { .. } | Light::EnvMap(_))).map(|l| aovs.emitter_event(l)).collect();
        ends.sort_by_key(|e| (e.base, e.labels));
        ends.dedup();
        SolutionClasses { s, d, sd, ends }
    }
    /// The diffuse reflection at an element of shape `shape`, as the solution treats it.
    pub fn event(aovs: &AovSet, shape: u32) -> Event {
        Event::scatter(LobeFlags::DIFFUSE, false, false, aovs.shape_labels(shape))
    }
    /// One bounce: `S* L`.
    pub fn one(&self) -> [ClassPart<'_>; 1] {
        [ClassPart::star(&self.s)]
    }
    /// More: `S* D [DS]* L`.
    pub fn more(&self) -> [ClassPart<'_>; 3] {
        [ClassPart::star(&self.s), ClassPart::any(&self.d), ClassPart::star(&self.sd)]
    }
}

/// The singular reflections and transmissions at the shapes `spec` marks, with their labels.
pub fn specular_events(aovs: &AovSet, spec: &[bool]) -> Vec<Event> {
    let mut v: Vec<Event> = (0..spec.len())
        .filter(|&s| spec[s])
        .flat_map(|s| [false, true].map(|t| Event::scatter(LobeFlags::SPECULAR, true, t, aovs.shape_labels(s as u32))))
        .collect();
    v.sort_by_key(|e| (e.base, e.labels));
    v.dedup();
    v
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
    /// one bounce `C D L`, more `C D D+ L`), and the emission at the display vertices.
    routes: Option<Routes>,
    /// With AOVs: the one-bounce part per element and at the display vertices.
    one: Option<(Vec<Rgb>, Vec<Rgb>)>,
}

struct Routes {
    masks: Vec<[LayerMask; 3]>,
    e: Vec<Rgb>,
    vertex_e: Vec<Rgb>,
}

impl<'a> RadiosityView<'a> {
    pub fn new(mesh: &'a RadiosityMesh, b: &'a [Rgb], shading: Shading) -> Self {
        let vertex_b = if shading == Shading::Gouraud { vertex_radiosity(mesh, b) } else { vec![] };
        RadiosityView { mesh, b, vertex_b, shading, b_one: None, routes: None, one: None }
    }

    /// Gouraud display with given vertex values (one per display vertex).
    pub fn with_vertex_values(mesh: &'a RadiosityMesh, b: &'a [Rgb], vertex_b: Vec<Rgb>) -> Self {
        RadiosityView { mesh, b, vertex_b, shading: Shading::Gouraud, b_one: None, routes: None, one: None }
    }

    /// Prepare the routing of the solution's parts to `aovs` (`hidden`: the emitters' own
    /// light was taken out of `b`; `extended`: the form factors carry light through specular
    /// surfaces): a typed error when an expression takes only some paths of one part
    /// (radiosity keeps the emitted light, one bounce and the rest apart, not every bounce),
    /// or when the solver kept no one-bounce part.
    pub fn route(&mut self, scene: &Scene, aovs: &AovSet, hidden: bool, extended: bool) -> Result<()> {
        if aovs.is_empty() {
            return Ok(());
        }
        self.keep_one_bounce()?;
        let classes = SolutionClasses::new(scene, aovs, extended);
        let masks = (0..scene.shapes.len())
            .map(|s| {
                let d = SolutionClasses::event(aovs, s as u32);
                let pre = [ClassPart::one(&Event::CAMERA), ClassPart::one(&d)];
                let once: Vec<ClassPart> = pre.iter().chain(&classes.one()).copied().collect();
                let more: Vec<ClassPart> = pre.iter().chain(&classes.more()).copied().collect();
                let emit = aovs.class_layers(&[Event::CAMERA], &[], 0, &[aovs.light_event(Some(s as u32))])?;
                let once = aovs.class_layers_of(&once, &classes.ends)?;
                let more = aovs.class_layers_of(&more, &classes.ends)?;
                Ok([emit, once, more])
            })
            .collect::<std::result::Result<Vec<_>, String>>()
            .map_err(|e| {
                Error::Settings(format!(
                    "radiosity: the light path expression '{e}' takes only some of the paths of a part that radiosity keeps whole \
                     (per surface: C L, C D L, C D D+ L{})",
                    if extended { ", with specular bounces between" } else { "" }
                ))
            })?;
        let e: Vec<Rgb> = self.mesh.elements.iter().map(|e| if hidden { Rgb::BLACK } else { e.emission }).collect();
        let vertex_e = if self.shading == Shading::Gouraud { vertex_radiosity(self.mesh, &e) } else { Vec::new() };
        self.routes = Some(Routes { masks, e, vertex_e });
        Ok(())
    }

    /// Keep the solution's one-bounce part for [`Self::one_bounce`]: an error when the solver
    /// kept none.
    pub(super) fn keep_one_bounce(&mut self) -> Result<()> {
        let Some(one) = self.b_one else {
            return Err(Error::Settings("radiosity: light path expressions need a solver that keeps the one-bounce part of its solution".into()));
        };
        let vertex_one = if self.shading == Shading::Gouraud { vertex_radiosity(self.mesh, one) } else { Vec::new() };
        self.one = Some((one.to_vec(), vertex_one));
        Ok(())
    }

    /// The one-bounce part of the solution shown at `p` on element `i` (zero unless kept).
    pub(super) fn one_bounce(&self, hit: &crate::accel::PrimHit, p: glam::Vec3, i: u32) -> Rgb {
        match &self.one {
            Some((one, vertex)) => self.shown(hit, p, i, one, vertex),
            None => Rgb::BLACK,
        }
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
            let one = self.one_bounce(&hit, p, i);
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
        // The hybrid display leaves out the emitters' own light itself (its reflected values
        // are B − E).
        if settings.hide_emitters && !self.options.hybrid {
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
        // Extended form factors (ray cast, continued through specular surfaces); the
        // hierarchical solver's links stop at them.
        let extended =
            solved.solver != super::solver::SolverKind::Hierarchical && matches!(self.options.form_factors, super::form_factor::Method::Raycast { .. });
        if self.options.hybrid {
            let mut hybrid = super::hybrid::HybridView::new(scene, view, self.options.gather);
            hybrid.route(scene, settings.aovs(), extended)?;
            return render_pixels(scene, settings, progress, &hybrid);
        }
        view.route(scene, settings.aovs(), settings.hide_emitters, extended)?;
        render_pixels(scene, settings, progress, &view)
    }
}
