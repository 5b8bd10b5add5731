//! pbrt-v4 scene files, read onto the same [`SceneBuilder`] as Mitsuba's.
//!
//! [`lexer`] turns text into tokens with their lines, [`params`] reads typed parameter
//! lists, and the [`Loader`] here runs the directives: it keeps pbrt's graphics state (the
//! current transform, for motion blur a pair of them, the material, the area light, the
//! reverse-orientation flag) on a stack for `AttributeBegin`/`End`, follows `Include` and
//! `Import` (with cycle detection, `.gz` files decompressed), and hands shapes, materials
//! and lights to `shapes.rs`, `materials.rs`, `lights.rs`; `camera.rs` turns the camera,
//! film, filter, sampler and integrator into svetlo's camera and settings.
//!
//! Conventions bridged: pbrt's camera space has +x to the image's right, svetlo's (Mitsuba's)
//! to its left, so the camera's to_world gets a mirror in x; pbrt's `maxdepth` counts
//! bounces and becomes svetlo's `max_depth` (segments) + 1; pbrt's `fov` spans the shorter
//! image axis. What is approximated or ignored is listed in `Scene::warnings` with file and line.

pub(crate) mod camera;
mod lexer;
mod lights;
mod materials;
mod params;
mod shapes;

pub use lexer::{Lexer, Tok};

use crate::error::{Error, Result};
use crate::geometry::{AnimatedTransform, Geometry};
use crate::scene::{Scene, SceneBuilder};
use crate::texture::{Bitmap, Texture};
use glam::{Mat4, Vec3};
use lexer::Loc;
use params::ParamList;
use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::Arc;

/// Deepest `Include` nesting accepted (a guard beside the cycle check).
const MAX_INCLUDE_DEPTH: usize = 64;

/// Load a pbrt-v4 scene file (`.pbrt`, or gzip-compressed `.pbrt.gz`).
pub fn load_pbrt(path: &Path) -> Result<Scene> {
    let text = read_text(path, None)?;
    load_pbrt_from_str(&text, path)
}

/// Load a pbrt-v4 scene held in memory. `origin` stands for the file in messages, and
/// relative names (includes, meshes, images) resolve against its folder.
pub fn load_pbrt_from_str(text: &str, origin: &Path) -> Result<Scene> {
    let mut l = Loader::new(origin);
    l.run_text(text, origin)?;
    l.finish()
}

/// A file's text; `.gz` files (or any starting with gzip's magic) are decompressed.
fn read_text(path: &Path, at: Option<&Loc>) -> Result<String> {
    let bytes = read_bytes(path, at)?;
    String::from_utf8(bytes).map_err(|_| Error::Scene { file: path.to_path_buf(), msg: "the file is not UTF-8 text".into() })
}

/// A file's bytes through the memory budget, decompressed if gzip. A failure to read names
/// the directive that asked for the file (`at`) when there is one.
pub(crate) fn read_bytes(path: &Path, at: Option<&Loc>) -> Result<Vec<u8>> {
    let bytes = crate::limits::read_file(path).map_err(|e| match (at, e) {
        (Some(l), Error::Io { source, .. }) => l.err(format!("cannot read '{}': {source}", path.display())),
        (Some(l), Error::Scene { msg, .. }) => l.err(format!("'{}' {msg}", path.display())),
        (_, e) => e,
    })?;
    gunzip_if_needed(bytes, path)
}

/// Decompress gzip data (recognised by its magic number); other bytes pass through. The
/// output is bounded by the memory budget (a small bomb cannot expand without limit).
fn gunzip_if_needed(bytes: Vec<u8>, path: &Path) -> Result<Vec<u8>> {
    if bytes.len() >= 2 && bytes[0] == 0x1f && bytes[1] == 0x8b {
        let limit = crate::limits::max_memory();
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(&bytes[..])
            .take(limit.saturating_add(1))
            .read_to_end(&mut out)
            .map_err(|e| Error::Scene { file: path.to_path_buf(), msg: format!("invalid gzip data: {e}") })?;
        crate::limits::check(format!("decompressing {}", path.display()), out.len() as u64)?;
        Ok(out)
    } else {
        Ok(bytes)
    }
}

/// Which of the two transforms (shutter open, shutter close) the transform directives change.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Active {
    Start,
    End,
    All,
}

/// The area light attached to the shapes that follow (`AreaLightSource "diffuse"`).
#[derive(Clone, Debug)]
struct AreaEmission {
    radiance: Texture,
    two_sided: bool,
    /// pbrt's `power` (W): the radiance is scaled per shape to emit it.
    power: Option<f32>,
    loc: Loc,
}

#[derive(Clone, Debug)]
struct GraphicsState {
    ctm: [Mat4; 2],
    active: Active,
    reverse_orientation: bool,
    material: Option<u32>,
    area_light: Option<AreaEmission>,
    /// `Attribute "shape" ...` defaults, and the same for lights and materials.
    shape_attrs: Rc<ParamList>,
    light_attrs: Rc<ParamList>,
    material_attrs: Rc<ParamList>,
    /// Where the `AttributeBegin` that pushed this state was (None for the base).
    begun_at: Option<Loc>,
}

/// A shape kept for an object (`ObjectBegin`), placed by every `ObjectInstance`.
#[derive(Clone)]
struct ObjectShape {
    geometry: Geometry,
    material: u32,
    name: String,
}

/// What the options block said, turned into the camera and settings once the world is read.
#[derive(Default)]
struct Options {
    camera: Option<(String, ParamList, [Mat4; 2], Loc)>,
    film: Option<(String, ParamList, Loc)>,
    filter: Option<(String, ParamList, Loc)>,
    sampler: Option<(String, ParamList, Loc)>,
    integrator: Option<(String, ParamList, Loc)>,
    transform_times: (f32, f32),
}

pub(crate) struct Loader {
    b: SceneBuilder,
    gs: GraphicsState,
    stack: Vec<GraphicsState>,
    named_materials: HashMap<String, u32>,
    float_textures: HashMap<String, Texture>,
    color_textures: HashMap<String, Texture>,
    named_coordsys: HashMap<String, [Mat4; 2]>,
    objects: HashMap<String, Vec<ObjectShape>>,
    /// The object being defined: (name, its shapes, where it began).
    current_object: Option<(String, Vec<ObjectShape>, Loc)>,
    opts: Options,
    in_world: bool,
    /// Canonical paths of the files being read, outermost first (cycle detection).
    include_stack: Vec<PathBuf>,
    bitmaps: HashMap<(PathBuf, bool), Arc<Bitmap>>,
    default_material: Option<u32>,
    shape_count: usize,
    any_motion: bool,
    /// pbrt's sensor imaging ratio (exposure × iso / 100), applied to every light.
    imaging_ratio: f32,
    origin: PathBuf,
}

impl Loader {
    fn new(origin: &Path) -> Self {
        let empty = Rc::new(ParamList::default());
        Loader {
            b: SceneBuilder::new(),
            gs: GraphicsState {
                ctm: [Mat4::IDENTITY; 2],
                active: Active::All,
                reverse_orientation: false,
                material: None,
                area_light: None,
                shape_attrs: empty.clone(),
                light_attrs: empty.clone(),
                material_attrs: empty,
                begun_at: None,
            },
            stack: Vec::new(),
            named_materials: HashMap::new(),
            float_textures: HashMap::new(),
            color_textures: HashMap::new(),
            named_coordsys: HashMap::new(),
            objects: HashMap::new(),
            current_object: None,
            opts: Options { transform_times: (0.0, 1.0), ..Default::default() },
            in_world: false,
            include_stack: Vec::new(),
            bitmaps: HashMap::new(),
            default_material: None,
            shape_count: 0,
            any_motion: false,
            imaging_ratio: 1.0,
            origin: origin.to_path_buf(),
        }
    }

    fn warn(&mut self, loc: &Loc, msg: impl std::fmt::Display) {
        self.b.warnings.push(format!("{}: {msg}", loc.at()));
    }

    /// Report the parameters of a directive that nothing read.
    fn warn_unused(&mut self, what: &str, p: &ParamList) {
        let unused: Vec<(String, String)> = p.unused().map(|q| (q.loc.at(), q.name.clone())).collect();
        for (at, name) in unused {
            self.b.warnings.push(format!("{at}: {what}: parameter '{name}' ignored"));
        }
    }

    fn run_text(&mut self, text: &str, file: &Path) -> Result<()> {
        let canon = std::fs::canonicalize(file).unwrap_or_else(|_| file.to_path_buf());
        self.include_stack.push(canon);
        let mut lex = Lexer::new(text, file);
        let r = self.run(&mut lex);
        self.include_stack.pop();
        r
    }

    /// Resolve a file name given at `loc`: absolute, or relative to the including file's folder.
    fn resolve(&self, name: &str, loc: &Loc) -> PathBuf {
        let p = Path::new(name);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            loc.dir().join(p)
        }
    }

    fn include(&mut self, name: &str, loc: &Loc) -> Result<()> {
        let path = self.resolve(name, loc);
        let canon = std::fs::canonicalize(&path).map_err(|e| loc.err(format!("cannot include '{}': {e}", path.display())))?;
        if self.include_stack.contains(&canon) {
            return Err(loc.err(format!("Include cycle: '{}' includes itself (directly or through other files)", path.display())));
        }
        if self.include_stack.len() >= MAX_INCLUDE_DEPTH {
            return Err(loc.err(format!("Include nested deeper than {MAX_INCLUDE_DEPTH} files")));
        }
        let text = read_text(&path, Some(loc))?;
        self.run_text(&text, &path)
    }

    fn run(&mut self, lex: &mut Lexer) -> Result<()> {
        while let Some((tok, loc)) = lex.next()? {
            let Tok::Word(d) = tok else {
                return Err(loc.err(format!("expected a directive, got {}", tok.describe())));
            };
            self.directive(&d, &loc, lex)?;
        }
        Ok(())
    }

    fn directive(&mut self, d: &str, loc: &Loc, lex: &mut Lexer) -> Result<()> {
        match d {
            "Translate" => {
                let v = nums::<3>(lex, loc, d)?;
                self.apply(|m| m * Mat4::from_translation(Vec3::from_array(v)));
            }
            "Scale" => {
                let v = nums::<3>(lex, loc, d)?;
                self.apply(|m| m * Mat4::from_scale(Vec3::from_array(v)));
            }
            "Rotate" => {
                let [a, x, y, z] = nums::<4>(lex, loc, d)?;
                let axis = Vec3::new(x, y, z);
                if axis.length_squared() == 0.0 || !axis.is_finite() {
                    return Err(loc.err("Rotate: the axis is zero"));
                }
                // pbrt's Rotate is the same right-hand rotation about the axis as glam's.
                let r = Mat4::from_axis_angle(axis.normalize(), a.to_radians());
                self.apply(|m| m * r);
            }
            "LookAt" => {
                let v = nums::<9>(lex, loc, d)?;
                let (eye, at, up) = (Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]), Vec3::new(v[6], v[7], v[8]));
                let m = look_at(eye, at, up).ok_or_else(|| loc.err("LookAt: eye equals target, or up is parallel to the view direction"))?;
                self.apply(|c| c * m);
            }
            "Transform" | "ConcatTransform" => {
                let v = bracketed_nums(lex, loc, d, 16)?;
                let mut a = [0.0f32; 16];
                a.copy_from_slice(&v);
                // The 16 numbers are the matrix's columns (pbrt transposes the row-major list).
                let m = Mat4::from_cols_array(&a);
                if !m.is_finite() {
                    return Err(loc.err(format!("{d}: the matrix is not finite")));
                }
                if d == "Transform" {
                    self.apply(|_| m);
                } else {
                    self.apply(|c| c * m);
                }
            }
            "Identity" => self.apply(|_| Mat4::IDENTITY),
            "CoordinateSystem" => {
                let name = string_arg(lex, loc, d)?;
                self.named_coordsys.insert(name, self.gs.ctm);
            }
            "CoordSysTransform" => {
                let name = string_arg(lex, loc, d)?;
                match self.named_coordsys.get(&name) {
                    Some(m) => self.gs.ctm = *m,
                    None => self.warn(loc, format!("CoordSysTransform: no coordinate system '{name}' (ignored)")),
                }
            }
            "ActiveTransform" => {
                let (tok, l) = lex.next()?.ok_or_else(|| loc.err("ActiveTransform needs StartTime, EndTime or All"))?;
                self.gs.active = match &tok {
                    Tok::Word(w) if w == "StartTime" => Active::Start,
                    Tok::Word(w) if w == "EndTime" => Active::End,
                    Tok::Word(w) if w == "All" => Active::All,
                    other => return Err(l.err(format!("ActiveTransform needs StartTime, EndTime or All, got {}", other.describe()))),
                };
            }
            "TransformTimes" => {
                let [t0, t1] = nums::<2>(lex, loc, d)?;
                if !(t0.is_finite() && t1.is_finite() && t1 >= t0) {
                    return Err(loc.err(format!("TransformTimes: need finite start <= end, got {t0} {t1}")));
                }
                self.opts.transform_times = (t0, t1);
            }
            "ReverseOrientation" => self.gs.reverse_orientation = !self.gs.reverse_orientation,
            "AttributeBegin" | "TransformBegin" => {
                let mut saved = self.gs.clone();
                saved.begun_at = Some(loc.clone());
                self.stack.push(saved);
                if d == "TransformBegin" {
                    self.warn(loc, "TransformBegin is deprecated in pbrt-v4; treated as AttributeBegin");
                }
            }
            "AttributeEnd" | "TransformEnd" => {
                let Some(prev) = self.stack.pop() else {
                    return Err(loc.err(format!("{d} without a matching AttributeBegin")));
                };
                self.gs = prev;
                self.gs.begun_at = None;
            }
            "Attribute" => {
                let target = string_arg(lex, loc, d)?;
                let p = ParamList::read(lex)?;
                let slot = match target.as_str() {
                    "shape" => &mut self.gs.shape_attrs,
                    "light" => &mut self.gs.light_attrs,
                    "material" => &mut self.gs.material_attrs,
                    "medium" | "texture" => {
                        self.warn(loc, format!("Attribute \"{target}\" ignored"));
                        return Ok(());
                    }
                    other => return Err(loc.err(format!("Attribute: unknown target '{other}' (shape, light, material, medium, texture)"))),
                };
                *slot = Rc::new(merge(&p, slot));
            }
            "Option" => {
                let p = ParamList::read(lex)?;
                for q in &p.params {
                    self.b.warnings.push(format!("{}: Option '{}' ignored", q.loc.at(), q.name));
                }
            }
            "ColorSpace" => {
                let name = string_arg(lex, loc, d)?;
                if name != "srgb" {
                    return Err(loc.err(format!("ColorSpace '{name}' is not supported (svetlo renders in linear sRGB / Rec. 709)")));
                }
            }
            "Camera" | "Film" | "PixelFilter" | "Sampler" | "Integrator" | "Accelerator" => {
                let ty = string_arg(lex, loc, d)?;
                let p = ParamList::read(lex)?;
                if self.in_world {
                    return Err(loc.err(format!("{d} must come before WorldBegin")));
                }
                match d {
                    "Camera" => {
                        let inv = [self.gs.ctm[0].inverse(), self.gs.ctm[1].inverse()];
                        self.named_coordsys.insert("camera".into(), inv);
                        self.opts.camera = Some((ty, p, self.gs.ctm, loc.clone()));
                    }
                    "Film" => self.opts.film = Some((ty, p, loc.clone())),
                    "PixelFilter" => self.opts.filter = Some((ty, p, loc.clone())),
                    "Sampler" => self.opts.sampler = Some((ty, p, loc.clone())),
                    "Integrator" => self.opts.integrator = Some((ty, p, loc.clone())),
                    _ => {} // the accelerator is svetlo's own
                }
            }
            "WorldBegin" => {
                if self.in_world {
                    return Err(loc.err("WorldBegin given twice"));
                }
                self.in_world = true;
                self.set_imaging_ratio()?;
                self.gs.ctm = [Mat4::IDENTITY; 2];
                self.gs.active = Active::All;
                self.named_coordsys.insert("world".into(), self.gs.ctm);
            }
            "WorldEnd" => self.warn(loc, "WorldEnd is pbrt-v3 syntax; ignored"),
            "Include" | "Import" => {
                let name = string_arg(lex, loc, d)?;
                self.include(&name, loc)?;
            }
            "MakeNamedMedium" => {
                let name = string_arg(lex, loc, d)?;
                let _ = ParamList::read(lex)?;
                self.warn(loc, format!("participating media are not supported: medium '{name}' ignored"));
            }
            "MediumInterface" => {
                // One or two names: interior [exterior].
                let inside = string_arg(lex, loc, d)?;
                let outside = match lex.peek()? {
                    Some((Tok::Str(_), _)) => match lex.next()? {
                        Some((Tok::Str(s), _)) => s,
                        _ => String::new(),
                    },
                    _ => inside.clone(),
                };
                if !inside.is_empty() || !outside.is_empty() {
                    self.warn(
                        loc,
                        format!("participating media are not supported: MediumInterface \"{inside}\" \"{outside}\" ignored (surfaces render as without media)"),
                    );
                }
            }
            "Material" => {
                let ty = string_arg(lex, loc, d)?;
                let p = ParamList::read(lex)?;
                self.need_world(d, loc)?;
                let m = self.make_material(&ty, &p, loc)?;
                self.gs.material = Some(m);
            }
            "MakeNamedMaterial" => {
                let name = string_arg(lex, loc, d)?;
                let p = ParamList::read(lex)?;
                self.need_world(d, loc)?;
                let ty = p.string("type")?.ok_or_else(|| loc.err(format!("MakeNamedMaterial '{name}' needs a \"string type\"")))?.to_string();
                let m = self.make_material(&ty, &p, loc)?;
                if self.named_materials.insert(name.clone(), m).is_some() {
                    self.warn(loc, format!("named material '{name}' redefined"));
                }
            }
            "NamedMaterial" => {
                let name = string_arg(lex, loc, d)?;
                self.need_world(d, loc)?;
                let m = *self.named_materials.get(&name).ok_or_else(|| loc.err(format!("NamedMaterial: no material named '{name}'")))?;
                self.gs.material = Some(m);
            }
            "Texture" => {
                let name = string_arg(lex, loc, d)?;
                let kind = string_arg(lex, loc, d)?;
                let class = string_arg(lex, loc, d)?;
                let p = ParamList::read(lex)?;
                self.need_world(d, loc)?;
                self.make_texture(&name, &kind, &class, &p, loc)?;
            }
            "LightSource" => {
                let ty = string_arg(lex, loc, d)?;
                let p = ParamList::read(lex)?;
                self.need_world(d, loc)?;
                let p = merge(&p, &self.gs.light_attrs);
                self.light(&ty, &p, loc)?;
            }
            "AreaLightSource" => {
                let ty = string_arg(lex, loc, d)?;
                let p = ParamList::read(lex)?;
                self.need_world(d, loc)?;
                let p = merge(&p, &self.gs.light_attrs);
                self.area_light_source(&ty, &p, loc)?;
            }
            "Shape" => {
                let ty = string_arg(lex, loc, d)?;
                let p = ParamList::read(lex)?;
                self.need_world(d, loc)?;
                let p = merge(&p, &self.gs.shape_attrs);
                self.shape(&ty, &p, loc)?;
            }
            "ObjectBegin" => {
                let name = string_arg(lex, loc, d)?;
                self.need_world(d, loc)?;
                if let Some((open, _, at)) = &self.current_object {
                    return Err(loc.err(format!("ObjectBegin '{name}' inside object '{open}' (begun at {})", at.at())));
                }
                let mut saved = self.gs.clone();
                saved.begun_at = Some(loc.clone());
                self.stack.push(saved);
                self.current_object = Some((name, Vec::new(), loc.clone()));
            }
            "ObjectEnd" => {
                let Some((name, shapes, _)) = self.current_object.take() else {
                    return Err(loc.err("ObjectEnd without ObjectBegin"));
                };
                self.gs = self.stack.pop().ok_or_else(|| loc.err("ObjectEnd without ObjectBegin"))?;
                if self.objects.insert(name.clone(), shapes).is_some() {
                    self.warn(loc, format!("object '{name}' redefined"));
                }
            }
            "ObjectInstance" => {
                let name = string_arg(lex, loc, d)?;
                self.need_world(d, loc)?;
                self.instance(&name, loc)?;
            }
            other => return Err(loc.err(format!("unknown directive '{other}'"))),
        }
        Ok(())
    }

    fn need_world(&self, d: &str, loc: &Loc) -> Result<()> {
        if self.in_world {
            Ok(())
        } else {
            Err(loc.err(format!("{d} must come after WorldBegin")))
        }
    }

    /// Change the active transform(s).
    fn apply(&mut self, f: impl Fn(Mat4) -> Mat4) {
        let a = self.gs.active;
        if a != Active::End {
            self.gs.ctm[0] = f(self.gs.ctm[0]);
        }
        if a != Active::Start {
            self.gs.ctm[1] = f(self.gs.ctm[1]);
        }
    }

    /// The current transform as an animation over the transform times, or None when static.
    fn animation(&mut self, loc: &Loc) -> Result<Option<AnimatedTransform>> {
        let [a, b] = self.gs.ctm;
        if a.abs_diff_eq(b, 0.0) {
            return Ok(None);
        }
        let (t0, t1) = self.opts.transform_times;
        if t1 <= t0 {
            self.warn(loc, "the start and end transforms differ but TransformTimes has no interval: the start transform is used");
            return Ok(None);
        }
        self.any_motion = true;
        AnimatedTransform::new(&[(t0, a), (t1, b)]).map(Some).map_err(|e| loc.err(format!("motion blur: {e}")))
    }

    /// A shape for the scene or, inside ObjectBegin/End, for the object.
    /// `alpha`: the shape's cut-out texture (its material is then wrapped in a mask).
    fn emit_shape(&mut self, geometry: Geometry, loc: &Loc, kind: &str, alpha: Option<Texture>) -> Result<()> {
        self.shape_count += 1;
        let name = format!("{kind}#{} ({})", self.shape_count, loc.at());
        let mut material = match self.gs.material {
            Some(m) => m,
            None => self.default_material(),
        };
        if let Some(opacity) = alpha {
            let inner = self.b.material(material).cloned().unwrap_or_default();
            material = self.b.add_material(crate::bsdf::Material::Mask { opacity, inner: Box::new(inner) });
        }
        if let Some((_, shapes, _)) = &mut self.current_object {
            if self.gs.area_light.is_some() {
                self.b
                    .warnings
                    .push(format!("{}: area lights inside an object instance are not supported (pbrt ignores them too): the shape does not emit", loc.at()));
            }
            shapes.push(ObjectShape { geometry, material, name });
            return Ok(());
        }
        let emission = match &self.gs.area_light {
            Some(a) => Some(self.emission_for(a.clone(), &geometry)?),
            None => None,
        };
        if let Some(a) = self.gs.area_light.clone() {
            if a.two_sided {
                return self.add_two_sided_emitter(geometry, material, emission, &name, &a);
            }
        }
        match self.animation(loc)? {
            Some(anim) => {
                if emission.is_some() {
                    return Err(loc.err("an emitting shape cannot move (moving area lights are not supported)"));
                }
                self.b.add_animated_shape(geometry, material, None, &name, anim).map_err(|e| loc.err(e.to_string()))
            }
            None => self.b.add_shape(geometry, material, emission, &name).map_err(|e| loc.err(e.to_string())),
        }
    }

    fn instance(&mut self, name: &str, loc: &Loc) -> Result<()> {
        if self.current_object.is_some() {
            return Err(loc.err("ObjectInstance inside ObjectBegin/ObjectEnd is not allowed"));
        }
        let shapes = self.objects.get(name).cloned().ok_or_else(|| loc.err(format!("ObjectInstance: no object named '{name}'")))?;
        let anim = self.animation(loc)?;
        let m = self.gs.ctm[0];
        for s in shapes {
            let name = format!("{} in instance of '{name}' ({})", s.name, loc.at());
            match &anim {
                Some(a) => {
                    // The object's shapes are in instance space: key the animation on them.
                    let a = a.clone();
                    let g = transform_geometry(s.geometry, &a.reference(), loc)?;
                    self.b.add_animated_shape(g, s.material, None, &name, a).map_err(|e| loc.err(e.to_string()))?;
                }
                None => {
                    let g = transform_geometry(s.geometry, &m, loc)?;
                    self.b.add_shape(g, s.material, None, &name).map_err(|e| loc.err(e.to_string()))?;
                }
            }
        }
        Ok(())
    }

    fn default_material(&mut self) -> u32 {
        *self.default_material.get_or_insert_with(|| self.b.add_material(crate::bsdf::Material::default()))
    }

    fn finish(mut self) -> Result<Scene> {
        let end = Loc { file: Arc::new(self.origin.clone()), line: 0, col: 0 };
        if let Some(open) = self.stack.last().and_then(|g| g.begun_at.clone()) {
            return Err(open.err("AttributeBegin (or ObjectBegin) without a matching end"));
        }
        if let Some((name, _, at)) = &self.current_object {
            return Err(at.err(format!("ObjectBegin '{name}' without ObjectEnd")));
        }
        if !self.in_world {
            return Err(end.err("the file has no WorldBegin"));
        }
        self.build_camera_and_settings(&end)?;
        self.b.build()
    }
}

/// Geometry moved by `m` (instances); spheres stay analytic under a similarity.
fn transform_geometry(g: Geometry, m: &Mat4, loc: &Loc) -> Result<Geometry> {
    Ok(match g {
        Geometry::Mesh(mut mesh) => {
            mesh.transform(m);
            Geometry::Mesh(mesh)
        }
        Geometry::Sphere(s) => {
            let lin = glam::Mat3::from_mat4(*m);
            let scale = lin.determinant().abs().cbrt();
            let q = lin / scale;
            if (q.transpose() * q - glam::Mat3::IDENTITY).to_cols_array().iter().any(|v| v.abs() > 1e-4) {
                return Err(loc.err("an instance scales a sphere non-uniformly (not supported)"));
            }
            Geometry::Sphere(crate::geometry::Sphere { center: m.transform_point3(s.center), radius: s.radius * scale, ..s })
        }
        Geometry::SdfGrid(g) => Geometry::SdfGrid(Box::new(g.transformed(m).map_err(|e| loc.err(e))?)),
    })
}

/// A parameter list with the defaults of `attrs` for the names it lacks.
fn merge(p: &ParamList, attrs: &ParamList) -> ParamList {
    let mut out = ParamList { params: p.params.to_vec() };
    for a in &attrs.params {
        if !out.params.iter().any(|q| q.name == a.name) {
            out.params.push(a.clone());
        }
    }
    out
}

/// pbrt's LookAt: the world-to-camera transform of a camera at `eye` looking at `at`.
fn look_at(eye: Vec3, at: Vec3, up: Vec3) -> Option<Mat4> {
    let dir = (at - eye).normalize_or_zero();
    let right = up.normalize_or_zero().cross(dir).normalize_or_zero();
    if dir == Vec3::ZERO || right == Vec3::ZERO || !eye.is_finite() {
        return None;
    }
    let new_up = dir.cross(right);
    let camera_to_world = Mat4::from_cols(right.extend(0.0), new_up.extend(0.0), dir.extend(0.0), eye.extend(1.0));
    Some(camera_to_world.inverse())
}

fn next_num(lex: &mut Lexer, loc: &Loc, d: &str) -> Result<f32> {
    match lex.next()? {
        Some((Tok::Num(v), _)) => Ok(v as f32),
        Some((t, l)) => Err(l.err(format!("{d}: expected a number, got {}", t.describe()))),
        None => Err(loc.err(format!("{d}: expected a number, got the end of the file"))),
    }
}

/// N numbers, bare or in brackets.
fn nums<const N: usize>(lex: &mut Lexer, loc: &Loc, d: &str) -> Result<[f32; N]> {
    if matches!(lex.peek()?, Some((Tok::Open, _))) {
        let v = bracketed_nums(lex, loc, d, N)?;
        let mut a = [0.0; N];
        a.copy_from_slice(&v);
        return Ok(a);
    }
    let mut a = [0.0; N];
    for x in &mut a {
        *x = next_num(lex, loc, d)?;
    }
    Ok(a)
}

/// `[ n numbers ]`.
fn bracketed_nums(lex: &mut Lexer, loc: &Loc, d: &str, n: usize) -> Result<Vec<f32>> {
    match lex.next()? {
        Some((Tok::Open, _)) => {}
        Some((t, l)) => return Err(l.err(format!("{d}: expected '[', got {}", t.describe()))),
        None => return Err(loc.err(format!("{d}: expected '[', got the end of the file"))),
    }
    let mut v = Vec::with_capacity(n);
    loop {
        match lex.next()? {
            Some((Tok::Close, _)) => break,
            Some((Tok::Num(x), _)) => v.push(x as f32),
            Some((t, l)) => return Err(l.err(format!("{d}: expected a number or ']', got {}", t.describe()))),
            None => return Err(loc.err(format!("{d}: '[' without ']'"))),
        }
    }
    if v.len() != n {
        return Err(loc.err(format!("{d} needs {n} numbers, got {}", v.len())));
    }
    Ok(v)
}

fn string_arg(lex: &mut Lexer, loc: &Loc, d: &str) -> Result<String> {
    match lex.next()? {
        Some((Tok::Str(s), _)) => Ok(s),
        Some((t, l)) => Err(l.err(format!("{d}: expected a quoted string, got {}", t.describe()))),
        None => Err(loc.err(format!("{d}: expected a quoted string, got the end of the file"))),
    }
}
