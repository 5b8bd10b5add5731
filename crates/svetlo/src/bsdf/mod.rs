//! Scattering models. Directions live in the local shading frame (normal = +z), both
//! pointing away from the surface. `f` never includes the cosine; an estimator weights a
//! sample by `f * |cos(wi)| / pdf`. Delta lobes report `pdf = 1` and `f = weight / |cos(wi)|`.

pub mod blend;
pub mod blinn;
pub mod coated;
pub mod conductor;
pub mod cook_torrance;
pub mod detail;
pub(crate) mod detail_lanes;
pub mod dielectric;
pub mod diffuse;
pub mod diffuse_transmission;
pub mod fresnel;
pub mod glass;
pub(crate) mod lane_samples;
pub mod lobes;
pub mod material;
pub mod microfacet;
pub mod mix;
pub mod oren_nayar;
pub mod phong;
pub mod plastic;
pub mod principled;
pub mod ward;

pub use material::{Material, MicrofacetKind};

use crate::math::Frame;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// Which quantity is being transported: radiance (from the camera) or importance (from
/// the lights). Refraction and shading normals make scattering non-symmetric.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TransportMode {
    #[default]
    Radiance,
    Importance,
}

/// Lobe classification of a sample or a model, as bit flags.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct LobeFlags(pub u8);

impl LobeFlags {
    pub const NONE: LobeFlags = LobeFlags(0);
    pub const REFLECTION: LobeFlags = LobeFlags(1);
    pub const TRANSMISSION: LobeFlags = LobeFlags(2);
    pub const DIFFUSE: LobeFlags = LobeFlags(4);
    pub const GLOSSY: LobeFlags = LobeFlags(8);
    pub const SPECULAR: LobeFlags = LobeFlags(16);
    /// A null interaction: the ray continues unchanged (mask pass-through).
    pub const NULL: LobeFlags = LobeFlags(32);
    pub const DIFFUSE_REFLECTION: LobeFlags = LobeFlags(1 | 4);
    pub const DIFFUSE_TRANSMISSION: LobeFlags = LobeFlags(2 | 4);
    pub const GLOSSY_REFLECTION: LobeFlags = LobeFlags(1 | 8);
    pub const GLOSSY_TRANSMISSION: LobeFlags = LobeFlags(2 | 8);
    pub const SPECULAR_REFLECTION: LobeFlags = LobeFlags(1 | 16);
    pub const SPECULAR_TRANSMISSION: LobeFlags = LobeFlags(2 | 16);
    pub const NULL_TRANSMISSION: LobeFlags = LobeFlags(2 | 32);

    #[inline]
    pub fn contains(self, o: LobeFlags) -> bool {
        self.0 & o.0 == o.0
    }
    #[inline]
    pub fn intersects(self, o: LobeFlags) -> bool {
        self.0 & o.0 != 0
    }
    /// Delta lobes cannot be hit by light sampling: MIS must skip them.
    #[inline]
    pub fn is_specular(self) -> bool {
        self.intersects(LobeFlags(16 | 32))
    }
    #[inline]
    pub fn is_null(self) -> bool {
        self.intersects(LobeFlags::NULL)
    }
    #[inline]
    pub fn has_non_specular(self) -> bool {
        self.intersects(LobeFlags(4 | 8))
    }
}

impl std::ops::BitOr for LobeFlags {
    type Output = LobeFlags;
    fn bitor(self, o: LobeFlags) -> LobeFlags {
        LobeFlags(self.0 | o.0)
    }
}

#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub wi: Vec3,
    pub f: Rgb,
    /// Solid-angle density of `wi`; 1 for a delta lobe.
    pub pdf: f32,
    pub lobe: LobeFlags,
    /// Relative IOR along the sampled direction (1 unless refracted): Russian roulette
    /// uses it to undo radiance scaling.
    pub eta: f32,
}

impl BsdfSample {
    /// The sample's Monte Carlo weight f |cos| / pdf.
    #[inline]
    pub fn weight(&self) -> Rgb {
        self.f * (self.wi.z.abs() / self.pdf)
    }
}

/// A scattering model with its textures already evaluated at one surface point.
#[derive(Clone, Debug)]
pub enum BsdfModel {
    Diffuse(diffuse::Diffuse),
    SmoothConductor(conductor::SmoothConductor),
    RoughConductor(conductor::RoughConductor),
    SmoothDielectric(dielectric::SmoothDielectric),
    RoughDielectric(dielectric::RoughDielectric),
    ThinDielectric(dielectric::ThinDielectric),
    /// svetlo's `glass`: a thin absorbing pane, polarisation by polarisation (Radiance's `glass`).
    ThinGlass(glass::ThinGlass),
    SmoothPlastic(plastic::SmoothPlastic),
    RoughPlastic(plastic::RoughPlastic),
    Phong(phong::Phong),
    BlinnPhong(blinn::BlinnPhong),
    CookTorrance(cook_torrance::CookTorrance),
    OrenNayar(oren_nayar::OrenNayar),
    Ward(ward::Ward),
    /// Mitsuba `blendbsdf` of two whole BSDFs (each with its own sides and mask).
    Blend(Box<blend::Blend>),
    /// pbrt-v4's layered coated BSDF (boxed: it holds two models).
    Coated(Box<coated::Coated>),
    /// A blend of two models (pbrt-v4 `mix`; Mitsuba's `blendbsdf` of whole BSDFs is `Blend`).
    Mix(Box<mix::Mix>),
    /// pbrt-v4's Lambertian reflection and transmission.
    DiffuseTransmission(diffuse_transmission::DiffuseTransmission),
    /// Mitsuba `principled` (boxed: a dozen parameters).
    Principled(Box<principled::Principled>),
    /// Mitsuba `principledthin`.
    PrincipledThin(Box<principled::PrincipledThin>),
}

/// Forward a call to the model inside, whatever it is.
macro_rules! dispatch {
    ($self:expr, $m:ident => $e:expr) => {
        match $self {
            BsdfModel::Diffuse($m) => $e,
            BsdfModel::SmoothConductor($m) => $e,
            BsdfModel::RoughConductor($m) => $e,
            BsdfModel::SmoothDielectric($m) => $e,
            BsdfModel::RoughDielectric($m) => $e,
            BsdfModel::ThinDielectric($m) => $e,
            BsdfModel::ThinGlass($m) => $e,
            BsdfModel::SmoothPlastic($m) => $e,
            BsdfModel::RoughPlastic($m) => $e,
            BsdfModel::Phong($m) => $e,
            BsdfModel::BlinnPhong($m) => $e,
            BsdfModel::CookTorrance($m) => $e,
            BsdfModel::OrenNayar($m) => $e,
            BsdfModel::Ward($m) => $e,
            BsdfModel::Blend($m) => $e,
            BsdfModel::Coated($m) => $e,
            BsdfModel::Mix($m) => $e,
            BsdfModel::DiffuseTransmission($m) => $e,
            BsdfModel::Principled($m) => $e,
            BsdfModel::PrincipledThin($m) => $e,
        }
    };
}

/// The BSDF at one point: a model plus the wrappers Mitsuba composes around it.
#[derive(Clone, Debug)]
pub struct Bsdf {
    /// Model seen from the front (+z) side.
    pub front: BsdfModel,
    /// Model seen from the back side when two-sided (Mitsuba `twosided`); directions are
    /// mirrored to +z before it is evaluated. `None`: one-sided, the back is black
    /// (except for models that transmit, which see both sides themselves).
    pub back: Option<BsdfModel>,
    /// Mitsuba `mask`: probability that the surface is there at all.
    pub opacity: f32,
    /// Mitsuba `normalmap` / `bumpmap`: the perturbed normal in the coordinates of the
    /// surface's own shading frame; everything above is evaluated in the frame it gives
    /// (see `detail`). None: no surface detail.
    pub detail: Option<detail::Detail>,
}

impl BsdfModel {
    pub fn flags(&self) -> LobeFlags {
        dispatch!(self, m => m.flags())
    }
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        dispatch!(self, m => m.eval(wo, wi, mode))
    }
    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        dispatch!(self, m => m.sample(wo, uc, u, mode))
    }
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        dispatch!(self, m => m.pdf(wo, wi, mode))
    }
    /// ([`Self::eval`], [`Self::pdf`]), the same bits: the rough and principled models
    /// compute their half vector, D and G1 once for both.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        match self {
            BsdfModel::RoughConductor(m) => m.eval_pdf(wo, wi),
            BsdfModel::RoughPlastic(m) => m.eval_pdf(wo, wi),
            BsdfModel::RoughDielectric(m) => m.eval_pdf(wo, wi, mode),
            BsdfModel::Principled(m) => m.eval_pdf(wo, wi, mode),
            BsdfModel::PrincipledThin(m) => m.eval_pdf(wo, wi, mode),
            m => (m.eval(wo, wi, mode), m.pdf(wo, wi, mode)),
        }
    }
    /// Hemispherical-average diffuse reflectance: what radiosity uses for this surface.
    /// Specular and glossy models (conductors, dielectrics) have none: the hybrid display
    /// pass ray-traces them. Plastic and the classic two-lobe models
    /// report the albedo of their diffuse lobe.
    pub fn diffuse_albedo(&self) -> Rgb {
        match self {
            BsdfModel::Diffuse(m) => m.reflectance,
            BsdfModel::SmoothPlastic(m) => m.diffuse_albedo(),
            BsdfModel::RoughPlastic(m) => m.diffuse_albedo(),
            BsdfModel::Phong(m) => m.diffuse_reflectance,
            BsdfModel::BlinnPhong(m) => m.diffuse_reflectance,
            BsdfModel::CookTorrance(m) => m.diffuse_reflectance,
            BsdfModel::Ward(m) => m.diffuse_reflectance,
            BsdfModel::OrenNayar(m) => m.reflectance,
            BsdfModel::Blend(m) => m.diffuse_albedo(),
            BsdfModel::Principled(m) => m.diffuse_albedo(),
            BsdfModel::PrincipledThin(m) => m.diffuse_albedo(),
            _ => Rgb::BLACK,
        }
    }
    /// Whether the model scatters light arriving on its back side by itself (dielectrics;
    /// a blend, whose parts decide their sides themselves).
    pub fn handles_back_side(&self) -> bool {
        matches!(self, BsdfModel::Blend(_)) || self.flags().intersects(LobeFlags::TRANSMISSION)
    }
}

/// True for a usable density or length: positive and finite (false for NaN).
#[inline]
pub(crate) fn positive_finite(x: f32) -> bool {
    x > 0.0 && x.is_finite()
}

#[inline]
fn flip(w: Vec3) -> Vec3 {
    Vec3::new(w.x, w.y, -w.z)
}

impl Bsdf {
    pub fn new(front: BsdfModel) -> Self {
        Bsdf { front, back: None, opacity: 1.0, detail: None }
    }

    pub fn flags(&self) -> LobeFlags {
        let mut f = match &self.front {
            BsdfModel::Diffuse(m) => m.flags(),
            front => front.flags(),
        };
        if let Some(b) = &self.back {
            f = f | b.flags();
        }
        if self.opacity < 1.0 {
            f = f | LobeFlags::NULL_TRANSMISSION;
        }
        f
    }

    /// The model for this side, and whether directions must be mirrored to +z.
    #[inline]
    fn side(&self, wo: Vec3) -> Option<(&BsdfModel, bool)> {
        if wo.z >= 0.0 || self.front.handles_back_side() {
            Some((&self.front, false))
        } else {
            self.back.as_ref().map(|b| (b, true))
        }
    }

    /// For surface detail: the factor that makes the nested BSDF's value in the perturbed
    /// frame `p` one relative to the original frame, or None where it is zero. As in
    /// Mitsuba, the direction on the side the light arrives from (wi for radiance, wo for
    /// importance) must lie on the same side of the original and the perturbed normal, and
    /// the shadowing term is taken for it; the estimator's |cos| in the original frame
    /// replaces the perturbed frame's, in which the nested BSDF's cosine belongs.
    #[inline]
    fn detail_factor(d: &detail::Detail, mode: TransportMode, (wo, wi): (Vec3, Vec3), (pwo, pwi): (Vec3, Vec3)) -> Option<f32> {
        let (w, pw) = if mode == TransportMode::Radiance { (wi, pwi) } else { (wo, pwo) };
        (w.z * pw.z > 0.0).then(|| pw.z.abs() / w.z.abs() * d.shadowing(w))
    }

    /// The BSDF's value: inline where a plain Lambertian front is seen from the front
    /// (`eval_local`'s first case, most calls in diffuse scenes), the rest out of line.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        match &self.detail {
            None => self.eval_local(wo, wi, mode),
            Some(d) => self.eval_detail(d, wo, wi, mode),
        }
    }

    #[inline(never)]
    fn eval_detail(&self, d: &detail::Detail, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        let f = d.frame(wo);
        let (pwo, pwi) = (f.to_local(wo), f.to_local(wi));
        match Self::detail_factor(d, mode, (wo, wi), (pwo, pwi)) {
            Some(k) => self.eval_local(pwo, pwi, mode) * k,
            None => Rgb::BLACK,
        }
    }

    /// The density of [`Self::sample`]: inline as [`Self::eval`].
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        match &self.detail {
            None => self.pdf_local(wo, wi, mode),
            Some(d) => self.pdf_detail(d, wo, wi, mode),
        }
    }

    #[inline(never)]
    fn pdf_detail(&self, d: &detail::Detail, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        let f = d.frame(wo);
        let (pwo, pwi) = (f.to_local(wo), f.to_local(wi));
        match Self::detail_factor(d, mode, (wo, wi), (pwo, pwi)) {
            Some(_) => self.pdf_local(pwo, pwi, mode),
            None => 0.0,
        }
    }

    /// ([`Self::eval`], [`Self::pdf`]), the same bits, sharing what the model can share
    /// ([`BsdfModel::eval_pdf`]): next-event estimation needs both.
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        if self.detail.is_some() {
            return (self.eval(wo, wi, mode), self.pdf(wo, wi, mode));
        }
        let (f, pdf) = match self.side(wo) {
            Some((m, false)) => m.eval_pdf(wo, wi, mode),
            Some((m, true)) => m.eval_pdf(flip(wo), flip(wi), mode),
            None => return (Rgb::BLACK, 0.0),
        };
        (f * self.opacity, pdf * self.opacity)
    }

    /// ([`Self::eval_pdf`] toward `wi` where given, [`Self::sample`]): the same bits. A path
    /// vertex needs both (its light sample and its continuation); a rough conductor (without
    /// mask or surface detail) computes its masking from `wo` once for the two.
    pub fn eval_pdf_and_sample(&self, wo: Vec3, wi: Option<Vec3>, uc: f32, u: Vec2, mode: TransportMode) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        if let (None, true, Some((BsdfModel::RoughConductor(c), flipped))) = (&self.detail, self.opacity >= 1.0, self.side(wo)) {
            let side = |w: Vec3| if flipped { flip(w) } else { w };
            let (nee, s) = c.eval_pdf_and_sample(side(wo), wi.map(side), u);
            return Self::finish_conductor(self.opacity, flipped, nee, s);
        }
        // A principled model shares its terms of wo (wrapped as a conductor's).
        if let (None, true, Some((BsdfModel::Principled(p), flipped))) = (&self.detail, self.opacity >= 1.0, self.side(wo)) {
            let side = |w: Vec3| if flipped { flip(w) } else { w };
            let (nee, s) = p.eval_pdf_and_sample(side(wo), wi.map(side), uc, u, mode);
            return Self::finish_conductor(self.opacity, flipped, nee, s);
        }
        if let (None, true, Some((BsdfModel::PrincipledThin(p), flipped))) = (&self.detail, self.opacity >= 1.0, self.side(wo)) {
            let side = |w: Vec3| if flipped { flip(w) } else { w };
            let (nee, s) = p.eval_pdf_and_sample(side(wo), wi.map(side), uc, u);
            return Self::finish_conductor(self.opacity, flipped, nee, s);
        }
        (wi.map(|wi| self.eval_pdf(wo, wi, mode)), self.sample(wo, uc, u, mode))
    }

    /// Where this BSDF toward `wo` is a Beckmann rough conductor without mask or surface
    /// detail (the case `eval_pdf_and_sample` takes apart): the model, and whether directions
    /// are mirrored to its side, so that a caller can evaluate and sample it for several
    /// vertices at once (the path kernel: `conductor::rough_conductor_lanes`, then
    /// [`Self::finish_conductor`]).
    #[inline]
    pub(crate) fn beckmann_conductor(&self, wo: Vec3) -> Option<(&conductor::RoughConductor, bool)> {
        self.rough_conductor_of(MicrofacetKind::Beckmann, wo)
    }

    /// [`Self::beckmann_conductor`] of a GGX rough conductor (`conductor::rough_conductor_ggx_lanes`).
    #[inline]
    pub(crate) fn ggx_conductor(&self, wo: Vec3) -> Option<(&conductor::RoughConductor, bool)> {
        self.rough_conductor_of(MicrofacetKind::Ggx, wo)
    }

    #[inline]
    fn rough_conductor_of(&self, kind: MicrofacetKind, wo: Vec3) -> Option<(&conductor::RoughConductor, bool)> {
        let (None, true, Some((BsdfModel::RoughConductor(c), flipped))) = (&self.detail, self.opacity >= 1.0, self.side(wo)) else { return None };
        let wo = if flipped { flip(wo) } else { wo };
        (c.distribution.kind == kind && wo.z > 0.0).then_some((c, flipped))
    }

    /// Where this BSDF toward `wo` is a Beckmann rough plastic without mask or surface detail:
    /// the model, and whether directions are mirrored to its side, so that the path kernel
    /// can evaluate and sample several vertices at once (`plastic::rough_plastic_lanes`,
    /// finished as a conductor's by [`Self::finish_conductor`]: the same wrapping).
    #[inline]
    pub(crate) fn beckmann_plastic(&self, wo: Vec3) -> Option<(&plastic::RoughPlastic, bool)> {
        self.rough_plastic_of(MicrofacetKind::Beckmann, wo)
    }

    /// [`Self::beckmann_plastic`] of a GGX rough plastic (`plastic::rough_plastic_ggx_lanes`).
    #[inline]
    pub(crate) fn ggx_plastic(&self, wo: Vec3) -> Option<(&plastic::RoughPlastic, bool)> {
        self.rough_plastic_of(MicrofacetKind::Ggx, wo)
    }

    #[inline]
    fn rough_plastic_of(&self, kind: MicrofacetKind, wo: Vec3) -> Option<(&plastic::RoughPlastic, bool)> {
        let (None, true, Some((BsdfModel::RoughPlastic(p), flipped))) = (&self.detail, self.opacity >= 1.0, self.side(wo)) else { return None };
        let wo = if flipped { flip(wo) } else { wo };
        (p.distribution.kind == kind && wo.z > 0.0).then_some((p, flipped))
    }

    /// Where this BSDF toward `wo` (not grazing) is a Beckmann rough dielectric without mask
    /// or surface detail: the model, and whether directions are mirrored to its side (never:
    /// it takes both sides), for the path kernel's lanes (`dielectric::rough_dielectric_lanes`,
    /// finished as a conductor's by [`Self::finish_conductor`]).
    #[inline]
    pub(crate) fn beckmann_dielectric(&self, wo: Vec3) -> Option<(&dielectric::RoughDielectric, bool)> {
        let (None, true, Some((BsdfModel::RoughDielectric(d), flipped))) = (&self.detail, self.opacity >= 1.0, self.side(wo)) else { return None };
        (d.distribution.kind == MicrofacetKind::Beckmann && wo.z != 0.0).then_some((d, flipped))
    }

    /// A rough conductor's value and density toward a light sample and its own sample, on
    /// the model's side (`flipped` as `side` gave it), made those of a BSDF of this `opacity`
    /// (as `eval_pdf_and_sample` finishes them). (The opacity alone: the path kernel keeps
    /// it, not a borrow of the BSDF, until its conductor lanes' values are in.)
    #[inline]
    pub(crate) fn finish_conductor(opacity: f32, flipped: bool, nee: Option<(Rgb, f32)>, s: Option<BsdfSample>) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        let side = |w: Vec3| if flipped { flip(w) } else { w };
        let nee = nee.map(|(f, pdf)| (f * opacity, pdf * opacity));
        let s = s.map(|mut s| {
            s.wi = side(s.wi);
            s.f *= opacity;
            s.pdf *= opacity;
            s
        });
        (nee, s)
    }

    /// A sample of the BSDF: inline as [`Self::eval`] where the surface is opaque (a mask's
    /// pass-through comes first).
    #[inline]
    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        match &self.detail {
            None => self.sample_local(wo, uc, u, mode),
            Some(d) => self.sample_detail(d, wo, uc, u, mode),
        }
    }

    #[inline(never)]
    fn sample_detail(&self, d: &detail::Detail, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let f = d.frame(wo);
        let pwo = f.to_local(wo);
        let s = self.sample_local(pwo, uc, u, mode)?;
        Self::detail_sample_out(d, mode, &f, (wo, pwo), s)
    }

    /// A sample `s` drawn in the perturbed frame `f` of detail `d` (from `pwo`, which is `wo`
    /// there), turned back to the shading frame and weighted by the detail's factor.
    #[inline(always)]
    fn detail_sample_out(d: &detail::Detail, mode: TransportMode, f: &Frame, (wo, pwo): (Vec3, Vec3), mut s: BsdfSample) -> Option<BsdfSample> {
        let pwi = s.wi;
        s.wi = f.to_world(pwi);
        s.f *= Self::detail_factor(d, mode, (wo, s.wi), (pwo, pwi))?;
        Some(s)
    }

    /// [`Self::eval_pdf_and_sample`] (radiance) of an opaque one-sided Lambertian of
    /// reflectance `refl` under surface detail `d`, the same bits with the perturbed frame
    /// made once, not three times, and no `Bsdf` built: the scalar reference of the path
    /// kernel's `detail_lanes::detail_lambert_lanes`, which tests check against it.
    #[cfg(test)]
    pub(crate) fn detail_lambert(d: &detail::Detail, refl: Rgb, wo: Vec3, wi: Option<Vec3>, u: Vec2) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        let mode = TransportMode::Radiance;
        let m = diffuse::Diffuse { reflectance: refl };
        let f = d.frame(wo);
        let pwo = f.to_local(wo);
        // `lambertian_front`'s test; the back of a one-sided model is black.
        let front = pwo.z >= 0.0;
        // The model evaluated only where the detail lets light through.
        let nee = wi.map(|wi| {
            let pwi = f.to_local(wi);
            match Self::detail_factor(d, mode, (wo, wi), (pwo, pwi)) {
                Some(k) => {
                    let (v, pdf) = if front { (m.eval(pwo, pwi, mode), m.pdf(pwo, pwi, mode)) } else { (Rgb::BLACK, 0.0) };
                    (v * k, pdf)
                }
                None => (Rgb::BLACK, 0.0),
            }
        });
        let s = if front { m.sample(pwo, 0.0, u, mode) } else { None };
        (nee, s.and_then(|s| Self::detail_sample_out(d, mode, &f, (wo, pwo), s)))
    }

    /// The Lambertian front seen from the front (`side`'s answer there), without the dispatch
    /// over every model: most of the calls in diffuse scenes.
    #[inline(always)]
    fn lambertian_front(&self, wo: Vec3) -> Option<&diffuse::Diffuse> {
        match (&self.front, wo.z >= 0.0) {
            (BsdfModel::Diffuse(m), true) => Some(m),
            _ => None,
        }
    }

    #[inline]
    fn eval_local(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        match self.lambertian_front(wo) {
            Some(m) => m.eval(wo, wi, mode) * self.opacity,
            None => self.eval_side(wo, wi, mode),
        }
    }

    #[inline(never)]
    fn eval_side(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        match self.side(wo) {
            Some((m, false)) => m.eval(wo, wi, mode) * self.opacity,
            Some((m, true)) => m.eval(flip(wo), flip(wi), mode) * self.opacity,
            None => Rgb::BLACK,
        }
    }

    #[inline]
    fn pdf_local(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        match self.lambertian_front(wo) {
            Some(m) => m.pdf(wo, wi, mode) * self.opacity,
            None => self.pdf_side(wo, wi, mode),
        }
    }

    #[inline(never)]
    fn pdf_side(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        match self.side(wo) {
            Some((m, false)) => m.pdf(wo, wi, mode) * self.opacity,
            Some((m, true)) => m.pdf(flip(wo), flip(wi), mode) * self.opacity,
            None => 0.0,
        }
    }

    #[inline]
    fn sample_local(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if self.opacity < 1.0 {
            return self.sample_masked(wo, uc, u, mode);
        }
        self.sample_opaque(wo, uc, u, mode)
    }

    #[inline(never)]
    fn sample_masked(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        // Mask: pass through with probability 1 - opacity (delta, weight 1).
        if uc >= self.opacity {
            let wi = -wo;
            return Some(BsdfSample {
                wi,
                f: Rgb::splat((1.0 - self.opacity) / wi.z.abs().max(1e-12)),
                pdf: 1.0 - self.opacity,
                lobe: LobeFlags::NULL_TRANSMISSION,
                eta: 1.0,
            });
        }
        self.sample_opaque(wo, uc / self.opacity, u, mode)
    }

    /// [`Self::sample_local`] after the mask's choice (`uc` rescaled to the surface's part).
    #[inline]
    fn sample_opaque(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let mut s = match self.lambertian_front(wo) {
            Some(m) => m.sample(wo, uc, u, mode)?,
            None => return self.sample_side(wo, uc, u, mode),
        };
        s.f *= self.opacity;
        s.pdf *= self.opacity;
        Some(s)
    }

    #[inline(never)]
    fn sample_side(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let (m, flipped) = self.side(wo)?;
        let mut s = if flipped { m.sample(flip(wo), uc, u, mode)? } else { m.sample(wo, uc, u, mode)? };
        if flipped {
            s.wi = flip(s.wi);
        }
        s.f *= self.opacity;
        s.pdf *= self.opacity;
        Some(s)
    }

    pub fn diffuse_albedo(&self) -> Rgb {
        self.front.diffuse_albedo() * self.opacity
    }

    /// Probability with which `sample` from `wo` picks the delta lobe `lobe` (specular
    /// reflection or transmission, or the mask's null transmission); 0 for other lobes.
    pub fn delta_probability(&self, wo: Vec3, lobe: LobeFlags) -> f32 {
        if lobe == LobeFlags::NULL_TRANSMISSION {
            return 1.0 - self.opacity;
        }
        let wo = self.detail.map_or(wo, |d| d.frame(wo).to_local(wo));
        let Some((m, flipped)) = self.side(wo) else { return 0.0 };
        let wo = if flipped { flip(wo) } else { wo };
        model_delta_probability(m, wo, lobe) * self.opacity
    }

    /// The delta lobe `lobe` seen from `wo`, without its random choice: its direction, the
    /// lobe's own coefficient in `f` (f |cos wi| is the lobe's full weight, e.g. F for the
    /// reflection of a dielectric, not F divided by the probability of choosing it) and in
    /// `pdf` the probability with which `sample` chooses it. None: no such lobe from `wo`.
    /// Path-space Metropolis needs the two apart (perturbations follow a lobe, they do not
    /// choose it).
    pub fn sample_delta(&self, wo: Vec3, lobe: LobeFlags, mode: TransportMode) -> Option<BsdfSample> {
        let p = self.delta_probability(wo, lobe);
        if !positive_finite(p) {
            return None;
        }
        // Every delta sampler here picks its lobe by a threshold on uc: the ends of the
        // model's range and the mask's range reach each lobe that has a positive probability.
        let top = 1.0 - f32::EPSILON / 2.0;
        for uc in [0.0, self.opacity * top, top] {
            if let Some(s) = self.sample(wo, uc, Vec2::splat(0.5), mode) {
                if s.lobe == lobe && s.pdf > 0.0 {
                    let w = s.f * (s.wi.z.abs() / s.pdf) * p;
                    return Some(BsdfSample { f: w / s.wi.z.abs().max(1e-12), pdf: p, ..s });
                }
            }
        }
        None
    }
}

/// [`Bsdf::delta_probability`] for one model, `wo` on its front side.
fn model_delta_probability(m: &BsdfModel, wo: Vec3, lobe: LobeFlags) -> f32 {
    match m {
        BsdfModel::SmoothDielectric(d) => {
            let f = fresnel::dielectric(wo.z, d.eta).0;
            if lobe == LobeFlags::SPECULAR_REFLECTION {
                f
            } else if lobe == LobeFlags::SPECULAR_TRANSMISSION {
                1.0 - f
            } else {
                0.0
            }
        }
        BsdfModel::ThinDielectric(d) => {
            let r = d.reflectance(wo.z);
            if lobe == LobeFlags::SPECULAR_REFLECTION {
                r
            } else if lobe == LobeFlags::SPECULAR_TRANSMISSION {
                1.0 - r
            } else {
                0.0
            }
        }
        BsdfModel::ThinGlass(g) => {
            let r = g.reflection_probability(wo.z);
            if lobe == LobeFlags::SPECULAR_REFLECTION {
                r
            } else if lobe == LobeFlags::SPECULAR_TRANSMISSION {
                1.0 - r
            } else {
                0.0
            }
        }
        BsdfModel::SmoothConductor(_) => f32::from(lobe == LobeFlags::SPECULAR_REFLECTION && wo.z > 0.0),
        BsdfModel::SmoothPlastic(p) if lobe == LobeFlags::SPECULAR_REFLECTION && wo.z > 0.0 => p.prob_specular(fresnel::dielectric(wo.z, p.eta).0),
        BsdfModel::Mix(x) => model_delta_probability(&x.a, wo, lobe) * (1.0 - x.amount) + model_delta_probability(&x.b, wo, lobe) * x.amount,
        BsdfModel::Blend(b) => b.delta_probability(wo, lobe),
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rough models' fused evaluation (value and density together, as `sample` uses it)
    /// gives the bits of `eval` and `pdf` called apart, on both sides and in both modes.
    #[test]
    fn fused_eval_pdf_is_eval_and_pdf() {
        let mut rng = crate::sampling::rng::Pcg32::new(11, 2);
        let dir = |rng: &mut crate::sampling::rng::Pcg32| crate::math::warp::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        for kind in [MicrofacetKind::Beckmann, MicrofacetKind::Ggx] {
            for alpha in [0.02f32, 0.1, 0.5] {
                let md = microfacet::Microfacet::new(kind, alpha, alpha);
                let c =
                    conductor::RoughConductor { distribution: md, eta: Rgb::new(0.2, 0.9, 1.1), k: Rgb::new(3.9, 2.4, 2.2), specular_reflectance: Rgb::WHITE };
                let p = plastic::RoughPlastic::new(kind, alpha, Rgb::new(0.1, 0.27, 0.36), Rgb::WHITE, 1.9, false, 0.4);
                let d = dielectric::RoughDielectric { distribution: md, eta: 1.5, specular_reflectance: Rgb::WHITE, specular_transmittance: Rgb::splat(0.9) };
                for _ in 0..3000 {
                    let (wo, wi) = (dir(&mut rng), dir(&mut rng));
                    let bits = |(f, pdf): (Rgb, f32)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits());
                    let m = TransportMode::Radiance;
                    assert_eq!(bits(c.eval_pdf(wo, wi)), bits((c.eval(wo, wi, m), c.pdf(wo, wi, m))), "conductor {kind:?} {alpha} {wo} {wi}");
                    assert_eq!(bits(p.eval_pdf(wo, wi)), bits((p.eval(wo, wi, m), p.pdf(wo, wi, m))), "plastic {kind:?} {alpha} {wo} {wi}");
                    for m in [TransportMode::Radiance, TransportMode::Importance] {
                        assert_eq!(bits(d.eval_pdf(wo, wi, m)), bits((d.eval(wo, wi, m), d.pdf(wo, wi, m))), "dielectric {kind:?} {alpha} {wo} {wi}");
                    }
                    // Pairs that sampling produces (reflections and refractions about one normal).
                    let wi_r = fresnel::reflect_z(wo);
                    assert_eq!(bits(d.eval_pdf(wo, wi_r, m)), bits((d.eval(wo, wi_r, m), d.pdf(wo, wi_r, m))));
                    assert_eq!(bits(c.eval_pdf(wo, wi_r)), bits((c.eval(wo, wi_r, m), c.pdf(wo, wi_r, m))));
                }
            }
        }
    }

    /// `Bsdf::detail_lambert` gives the bits of a Lambertian `Bsdf` with that detail, over
    /// tilted and flat normals (with and without the shadowing term), directions on both sides
    /// and grazing; the flip and the shadowing term change some values.
    #[test]
    fn detail_lambert_is_the_detail_bsdf() {
        let mut rng = crate::sampling::rng::Pcg32::new(7, 3);
        let dir = |rng: &mut crate::sampling::rng::Pcg32| crate::math::warp::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let bits3 = |v: Vec3| v.to_array().map(f32::to_bits);
        let nee_bits = |n: Option<(Rgb, f32)>| n.map(|(f, pdf)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits()));
        let s_bits =
            |s: Option<BsdfSample>| s.map(|s| (bits3(s.wi), s.f.r.to_bits(), s.f.g.to_bits(), s.f.b.to_bits(), s.pdf.to_bits(), s.lobe, s.eta.to_bits()));
        let refl = Rgb::new(0.3, 0.55, 0.8);
        let (mut flipped, mut shadowed) = (0, 0);
        for n in [Vec3::new(0.3, -0.2, 0.9), Vec3::new(-0.8, 0.1, 0.3), Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.9, 0.4, 0.05)] {
            for shadowing in [true, false] {
                let d = detail::Detail::new(n, shadowing);
                let b = Bsdf { detail: Some(d), ..Bsdf::new(BsdfModel::Diffuse(diffuse::Diffuse { reflectance: refl })) };
                for i in 0..3000 {
                    let (wo, wi) = (dir(&mut rng), dir(&mut rng));
                    let wi = (i % 7 != 0).then_some(wi);
                    let u = Vec2::new(rng.next_f32(), rng.next_f32());
                    let (nee, s) = Bsdf::detail_lambert(&d, refl, wo, wi, u);
                    let (nee_b, s_b) = b.eval_pdf_and_sample(wo, wi, 0.5, u, TransportMode::Radiance);
                    assert_eq!(nee_bits(nee), nee_bits(nee_b), "{n} {wo} {wi:?}");
                    assert_eq!(s_bits(s), s_bits(s_b), "{n} {wo} {u}");
                    flipped += (wo.z * wo.dot(d.n) <= 0.0 && s.is_some()) as usize;
                    shadowed += nee.is_some_and(|(f, _)| shadowing && !f.is_black() && d.shadowing(wi.unwrap()) < 1.0) as usize;
                }
            }
        }
        assert!(flipped > 100 && shadowed > 100, "{flipped} {shadowed}");
    }

    /// BSDFs one- and two-sided, masked and with a normal map, around models with and
    /// without a fused evaluation.
    fn wrapped_models() -> Vec<Bsdf> {
        let md = microfacet::Microfacet::new(MicrofacetKind::Beckmann, 0.1, 0.1);
        let conductor = BsdfModel::RoughConductor(conductor::RoughConductor {
            distribution: md,
            eta: Rgb::new(0.200438, 0.924033, 1.10221),
            k: Rgb::new(3.91295, 2.45285, 2.14219),
            specular_reflectance: Rgb::splat(0.3),
        });
        let ggx = microfacet::Microfacet::new(MicrofacetKind::Ggx, 0.3, 0.05);
        let back = BsdfModel::RoughConductor(conductor::RoughConductor {
            distribution: ggx,
            eta: Rgb::splat(1.5),
            k: Rgb::splat(2.0),
            specular_reflectance: Rgb::WHITE,
        });
        let plastic = BsdfModel::RoughPlastic(plastic::RoughPlastic::new(MicrofacetKind::Ggx, 0.2, Rgb::new(0.1, 0.27, 0.36), Rgb::WHITE, 1.5, true, 0.5));
        let beckmann_plastic =
            BsdfModel::RoughPlastic(plastic::RoughPlastic::new(MicrofacetKind::Beckmann, 0.1, Rgb::splat(0.5), Rgb::WHITE, 1.5, false, 0.667));
        let dielectric = BsdfModel::RoughDielectric(dielectric::RoughDielectric {
            distribution: md,
            eta: 1.5,
            specular_reflectance: Rgb::WHITE,
            specular_transmittance: Rgb::splat(0.9),
        });
        let diffuse = BsdfModel::Diffuse(diffuse::Diffuse { reflectance: Rgb::splat(0.5) });
        let mut cases = vec![];
        for front in [conductor, plastic, beckmann_plastic, dielectric, diffuse] {
            cases.push(Bsdf::new(front.clone()));
            cases.push(Bsdf { back: Some(back.clone()), ..Bsdf::new(front.clone()) });
            cases.push(Bsdf { back: Some(front.clone()), opacity: 0.6, ..Bsdf::new(front.clone()) });
            cases.push(Bsdf { detail: Some(detail::Detail::new(Vec3::new(0.3, -0.2, 0.9), true)), ..Bsdf::new(front) });
        }
        cases
    }

    /// `Bsdf::eval_pdf` (what next-event estimation calls) gives the bits of `eval` and `pdf`
    /// called apart: one- and two-sided, masked, with a normal map, on models with and
    /// without a fused evaluation, directions on both sides and grazing.
    #[test]
    fn bsdf_eval_pdf_is_eval_and_pdf() {
        let mut rng = crate::sampling::rng::Pcg32::new(5, 9);
        let cases = wrapped_models();
        let bits = |(f, pdf): (Rgb, f32)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits());
        let dir = |rng: &mut crate::sampling::rng::Pcg32| crate::math::warp::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let grazing = [Vec3::new(1.0, 0.0, 1e-4).normalize(), Vec3::new(0.0, -1.0, -1e-4).normalize(), Vec3::new(0.6, 0.8, 0.0), Vec3::Z, -Vec3::Z];
        for b in &cases {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                let mut pairs: Vec<(Vec3, Vec3)> = (0..2000).map(|_| (dir(&mut rng), dir(&mut rng))).collect();
                pairs.extend(grazing.iter().flat_map(|&a| grazing.iter().map(move |&c| (a, c))));
                // Mirror pairs, where the lobes peak.
                pairs.extend((0..200).map(|_| dir(&mut rng)).map(|w| (w, fresnel::reflect_z(w))));
                for (wo, wi) in pairs {
                    assert_eq!(bits(b.eval_pdf(wo, wi, mode)), bits((b.eval(wo, wi, mode), b.pdf(wo, wi, mode))), "{:?} {mode:?} {wo} {wi}", b.front);
                }
            }
        }
    }

    /// `Bsdf::eval_pdf_and_sample` (the path kernel's call at a vertex) gives the bits of
    /// `eval_pdf` and `sample` called apart, with and without the light's direction, for every
    /// wrapped model (two-sided rough conductors take the shared path), both modes, directions
    /// on both sides and grazing; and so do a Beckmann or GGX conductor's lane of
    /// `conductor::rough_conductor_lanes` or `rough_conductor_ggx_lanes` and a Beckmann or GGX plastic's of
    /// `plastic::rough_plastic_lanes` or `rough_plastic_ggx_lanes` (finished by `finish_conductor`).
    #[test]
    fn eval_pdf_and_sample_is_eval_pdf_then_sample() {
        let mut rng = crate::sampling::rng::Pcg32::new(23, 4);
        let bits = |(f, pdf): (Rgb, f32)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits());
        let sample_bits = |s: Option<BsdfSample>| s.map(|s| (s.wi.to_array().map(f32::to_bits), bits((s.f, s.pdf)), s.lobe, s.eta.to_bits()));
        let dir = |rng: &mut crate::sampling::rng::Pcg32| crate::math::warp::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let grazing = [Vec3::new(1.0, 0.0, 1e-4).normalize(), Vec3::new(0.0, -1.0, -1e-4).normalize(), Vec3::new(0.6, 0.8, 0.0), Vec3::Z, -Vec3::Z];
        let (mut sampled, mut conductor_lanes, mut plastic_lanes) = (0, [0; 2], [0; 2]);
        for b in &wrapped_models() {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                let mut pairs: Vec<(Vec3, Vec3)> = (0..2000).map(|_| (dir(&mut rng), dir(&mut rng))).collect();
                pairs.extend(grazing.iter().flat_map(|&a| grazing.iter().map(move |&c| (a, c))));
                for (k, (wo, wi)) in pairs.into_iter().enumerate() {
                    let (uc, u) = (rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()));
                    let wi = (k % 4 != 0).then_some(wi);
                    let (nee, s) = b.eval_pdf_and_sample(wo, wi, uc, u, mode);
                    assert_eq!(nee.map(bits), wi.map(|wi| bits(b.eval_pdf(wo, wi, mode))), "{:?} {mode:?} {wo} {wi:?}", b.front);
                    let alone = b.sample(wo, uc, u, mode);
                    sampled += usize::from(alone.is_some());
                    assert_eq!(sample_bits(s), sample_bits(alone), "{:?} {mode:?} {wo} u {uc} {u}", b.front);
                    // The path kernel's way: a Beckmann conductor's lane of `rough_conductor_lanes`,
                    // a GGX one's of `rough_conductor_ggx_lanes`.
                    let conductor_lane = b.beckmann_conductor(wo).map(|c| (c, false)).or(b.ggx_conductor(wo).map(|c| (c, true)));
                    if let Some(((c, flipped), ggx)) = conductor_lane {
                        let side = |w: Vec3| if flipped { flip(w) } else { w };
                        let mut q = conductor::RoughConductorLanes::<1>::default();
                        q.set(0, c, side(wo), wi.map(side), u);
                        let out = if ggx { conductor::rough_conductor_ggx_lanes(&q, 1) } else { conductor::rough_conductor_lanes(&q, 1) };
                        let (nee_l, s_l) = out.lane(0, wi.is_some(), LobeFlags::GLOSSY_REFLECTION);
                        let (nee_m, s_m) = Bsdf::finish_conductor(b.opacity, flipped, nee_l, s_l);
                        assert_eq!(
                            (nee_m.map(bits), sample_bits(s_m)),
                            (nee.map(bits), sample_bits(s)),
                            "{:?} {mode:?} {wo} u {u}: the conductor's lane",
                            b.front
                        );
                        conductor_lanes[usize::from(ggx)] += 1;
                    }
                    // And a Beckmann plastic's lane of `plastic::rough_plastic_lanes`, a GGX
                    // one's of `rough_plastic_ggx_lanes`.
                    let plastic_lane = b.beckmann_plastic(wo).map(|p| (p, false)).or(b.ggx_plastic(wo).map(|p| (p, true)));
                    if let Some(((p, flipped), ggx)) = plastic_lane {
                        let side = |w: Vec3| if flipped { flip(w) } else { w };
                        let mut q = plastic::RoughPlasticLanes::<1>::default();
                        q.set(0, p, side(wo), wi.map(side), uc, u);
                        let out = if ggx { plastic::rough_plastic_ggx_lanes(&q, 1) } else { plastic::rough_plastic_lanes(&q, 1) };
                        let (nee_l, s_l) = out.lane(0, wi.is_some(), LobeFlags::DIFFUSE_REFLECTION);
                        let (nee_m, s_m) = Bsdf::finish_conductor(b.opacity, flipped, nee_l, s_l);
                        assert_eq!(
                            (nee_m.map(bits), sample_bits(s_m)),
                            (nee.map(bits), sample_bits(s)),
                            "{:?} {mode:?} {wo} u {uc} {u}: the plastic's lane",
                            b.front
                        );
                        plastic_lanes[usize::from(ggx)] += 1;
                    }
                }
            }
        }
        // Each kind of lane on its own, so that neither count hides a model's lanes gone missing.
        assert!(
            sampled > 50_000 && conductor_lanes.iter().chain(&plastic_lanes).all(|&n| n > 3_000),
            "{sampled} samples, {conductor_lanes:?} conductor lanes, {plastic_lanes:?} plastic lanes (Beckmann, GGX)"
        );
    }

    /// `sample_delta` gives each delta lobe's own weight and its choice probability: their
    /// ratio is what `sample` reports, and the probabilities of a model's lobes sum to one.
    #[test]
    fn sample_delta_splits_weight_and_choice() {
        let glass = Bsdf::new(BsdfModel::SmoothDielectric(dielectric::SmoothDielectric {
            eta: 1.5,
            specular_reflectance: Rgb::WHITE,
            specular_transmittance: Rgb::WHITE,
        }));
        let masked = Bsdf { opacity: 0.7, ..glass.clone() };
        for b in [&glass, &masked] {
            for wo in [Vec3::new(0.3, 0.1, 0.9).normalize(), Vec3::new(-0.5, 0.2, -0.6).normalize()] {
                for mode in [TransportMode::Radiance, TransportMode::Importance] {
                    let mut total = 0.0;
                    for lobe in [LobeFlags::SPECULAR_REFLECTION, LobeFlags::SPECULAR_TRANSMISSION, LobeFlags::NULL_TRANSMISSION] {
                        let Some(s) = b.sample_delta(wo, lobe, mode) else { continue };
                        total += s.pdf;
                        // The same lobe drawn by `sample`: weight = coefficient / probability.
                        let drawn = (0..64).filter_map(|i| b.sample(wo, (i as f32 + 0.5) / 64.0, Vec2::splat(0.5), mode)).find(|d| d.lobe == lobe);
                        if let Some(d) = drawn {
                            let (w_drawn, w_split) = (d.weight(), s.f * (s.wi.z.abs() / s.pdf));
                            assert!((w_drawn - w_split).map(f32::abs).max_component() < 1e-4, "{lobe:?}: {w_drawn:?} vs {w_split:?}");
                            assert!((d.wi - s.wi).length() < 1e-6);
                        }
                    }
                    assert!((total - 1.0).abs() < 1e-5, "lobe probabilities sum to {total}");
                }
            }
        }
        // A lobe the model does not have.
        assert!(glass.sample_delta(Vec3::Z, LobeFlags::NULL_TRANSMISSION, TransportMode::Radiance).is_none());
    }
}
