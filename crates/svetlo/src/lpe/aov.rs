//! AOVs: a set of named expressions (and an optional restriction of the beauty), bound to a
//! scene's labels, and the per-path trackers every integrator advances one step per vertex.
//!
//! A contribution is reported with a [`LayerMask`]: bit i for AOV i, [`BEAUTY`] for the
//! beauty (always set when the beauty is not restricted). Trackers are `Copy` arrays: a walk
//! keeps one and copies it at branches, with no allocation.

use super::{ClassPart, Event, Lpe, LpeError};
use crate::scene::Scene;
use crate::spectrum::Rgb;

/// Most AOVs of one render (the beauty's restriction, if any, comes on top).
pub const MAX_LAYERS: usize = 15;
/// Bit i: AOV i takes the contribution; `BEAUTY`: the beauty does.
pub type LayerMask = u32;
pub const BEAUTY: LayerMask = 1 << 31;

/// The AOVs of a render and the beauty's restriction. The empty set (no AOVs, the beauty
/// unrestricted) costs a loop of zero steps per vertex.
#[derive(Clone, Debug, Default)]
pub struct AovSet {
    names: Vec<String>,
    /// The AOVs' expressions, then the beauty's restriction when there is one.
    lpes: Vec<Lpe>,
    beauty_filter: bool,
    labels: Vec<String>,
    /// Per scene shape: the bits of the labels that name it.
    shape_labels: Vec<u32>,
    /// All forward automata as one (built by [`AovSet::bind`]): a camera path's state is
    /// one small integer and a vertex one table step, whatever the number of AOVs.
    product: Option<Product>,
}

/// The product of a set's forward automata over the label masks the scene's shapes carry.
#[derive(Clone, Debug)]
struct Product {
    /// Distinct label masks of events (0 first); an event's class is base + 9 x index.
    masks: Vec<u32>,
    n_classes: usize,
    table: Vec<u32>,
    /// Per (state, class): the layers that take a path ending there with that event (those
    /// whose automaton accepts after the step, with the base mask), in one lookup.
    ends: Vec<LayerMask>,
    /// Per product state: each automaton's own state (for meeting light subpaths).
    states: Vec<[u32; MAX_LAYERS + 1]>,
    /// The product of the reverse automata and, per (forward, reverse) pair of product
    /// states, the layers a joined path goes to; None when too large.
    rev: Option<RevProduct>,
}

#[derive(Clone, Debug)]
struct RevProduct {
    table: Vec<u32>,
    states: usize,
    /// `meets[q * states + r]`.
    meets: Vec<LayerMask>,
}

/// Most entries of the table of meeting product states.
const MAX_MEET_ENTRIES: usize = 1 << 18;

/// Most states of the product automaton; larger products fall back to one step per AOV.
const MAX_PRODUCT_STATES: usize = 1 << 14;

/// A product state: each automaton's state (the AOVs', then the beauty's restriction).
type ProductState = [u32; MAX_LAYERS + 1];

/// Breadth-first search of the product of `n` automata (`step(i, state, event)` for automaton
/// i) over the base events times the label masks `masks`: the states in discovery order and the
/// transition table (state × class). None when it would exceed [`MAX_PRODUCT_STATES`] or
/// `fits(states)` says no.
fn product_search(masks: &[u32], n: usize, step: impl Fn(usize, u32, Event) -> u32, fits: impl Fn(usize) -> bool) -> Option<(Vec<ProductState>, Vec<u32>)> {
    use std::collections::HashMap;
    let base = super::automaton::BASE_COUNT;
    let nc = base * masks.len();
    let start = [Lpe::START; MAX_LAYERS + 1];
    let mut index: HashMap<ProductState, u32> = HashMap::from([(start, 0)]);
    let mut states = vec![start];
    let mut table = Vec::new();
    let mut q = 0;
    while q < states.len() {
        let cur = states[q];
        for c in 0..nc {
            let e = Event { base: (c % base) as u8, labels: masks[c / base] };
            let mut next = start;
            for i in 0..n {
                next[i] = step(i, cur[i], e);
            }
            let id = match index.get(&next) {
                Some(&id) => id,
                None => {
                    if states.len() >= MAX_PRODUCT_STATES || !fits(states.len() + 1) {
                        return None;
                    }
                    index.insert(next, states.len() as u32);
                    states.push(next);
                    states.len() as u32 - 1
                }
            };
            table.push(id);
        }
        q += 1;
    }
    Some((states, table))
}

static EMPTY: AovSet = AovSet { names: Vec::new(), lpes: Vec::new(), beauty_filter: false, labels: Vec::new(), shape_labels: Vec::new(), product: None };

impl AovSet {
    /// The set with nothing in it.
    pub fn empty() -> &'static AovSet {
        &EMPTY
    }

    /// Named AOVs and an optional restriction of the beauty. Names must be distinct and
    /// usable as EXR layer names (no '.').
    pub fn new(aovs: Vec<(String, Lpe)>, beauty: Option<Lpe>) -> Result<AovSet, LpeError> {
        if aovs.len() > MAX_LAYERS {
            return Err(LpeError::at("", 0, format!("at most {MAX_LAYERS} AOVs per render, got {}", aovs.len())));
        }
        let mut names: Vec<String> = Vec::new();
        let mut lpes = Vec::new();
        for (n, l) in aovs {
            if n.is_empty() || n.contains('.') || n.chars().any(|c| c.is_whitespace() || c == '/') || names.contains(&n) || n == "beauty" {
                return Err(LpeError::at(&l.source, 0, format!("AOV name '{n}' must be unique, not 'beauty', and without '.', '/' or spaces")));
            }
            names.push(n);
            lpes.push(l);
        }
        let beauty_filter = beauty.is_some();
        lpes.extend(beauty);
        // One label list for the set; each expression's labels map to its bits.
        let mut labels: Vec<String> = Vec::new();
        for l in &mut lpes {
            let bits = l
                .labels()
                .iter()
                .map(|x| {
                    if !labels.contains(x) {
                        labels.push(x.clone());
                    }
                    labels.iter().position(|y| y == x).expect("just added") as u8
                })
                .collect();
            l.bind_labels(bits);
        }
        if labels.len() > 32 {
            return Err(LpeError::at("", 0, "more than 32 distinct labels over all AOVs".into()));
        }
        Ok(AovSet { names, lpes, beauty_filter, labels, shape_labels: Vec::new(), product: None })
    }

    /// Compile `name = expression` pairs and the beauty's optional restriction; an error
    /// names the AOV whose expression is wrong.
    pub fn compile(aovs: &[(String, String)], beauty: Option<&str>) -> Result<AovSet, LpeError> {
        let mut list = Vec::new();
        for (n, e) in aovs {
            let l = Lpe::new(e).map_err(|mut err| {
                err.msg = format!("AOV '{n}': {}", err.msg);
                err
            })?;
            list.push((n.clone(), l));
        }
        let b = beauty.map(Lpe::new).transpose()?;
        AovSet::new(list, b)
    }

    /// What a render asks for (the CLI's `--aov`, `--aov-preset`, `--lpe`; Python's `aovs`,
    /// `aov_preset`, `lpe`), compiled and bound to `scene`: None when nothing is asked, else
    /// the set and the warnings of [`Self::bind`]. The only preset is `lecture`.
    pub fn request(scene: &Scene, aovs: &[(String, String)], preset: Option<&str>, beauty: Option<&str>) -> Result<Option<(AovSet, Vec<String>)>, LpeError> {
        let all = Self::requested(aovs, preset)?;
        if all.is_empty() && beauty.is_none() {
            return Ok(None);
        }
        let mut set = AovSet::compile(&all, beauty)?;
        let warnings = set.bind(scene);
        Ok(Some((set, warnings)))
    }

    /// The AOVs a request names, in their layer order: `aovs`, then the preset's.
    pub fn requested(aovs: &[(String, String)], preset: Option<&str>) -> Result<Vec<(String, String)>, LpeError> {
        let mut all = aovs.to_vec();
        match preset {
            None => {}
            Some("lecture") => all.extend(super::LECTURE_PRESET.iter().map(|(n, e)| (n.to_string(), e.to_string()))),
            Some(other) => return Err(LpeError::at(other, 0, format!("unknown AOV preset '{other}' (lecture)"))),
        }
        Ok(all)
    }

    /// Resolve labels against the scene's shape ids; returns a warning per label that names
    /// nothing and per expression that can match no path.
    pub fn bind(&mut self, scene: &Scene) -> Vec<String> {
        self.shape_labels =
            scene.shapes.iter().map(|s| self.labels.iter().enumerate().filter(|(_, l)| **l == s.name).fold(0u32, |m, (i, _)| m | 1 << i)).collect();
        let mut warn: Vec<String> = self
            .labels
            .iter()
            .filter(|l| !scene.shapes.iter().any(|s| &s.name == *l))
            .map(|l| format!("light path expression label '{l}' names no shape of the scene"))
            .collect();
        for l in &self.lpes {
            if !l.can_match() {
                warn.push(format!("light path expression '{}' can match no path", l.source));
            }
        }
        self.product = self.build_product();
        warn
    }

    /// The set without its product automata: paths are then routed by one step per
    /// automaton, as sets too large for a product are (tests compare the two routings).
    pub fn without_products(mut self) -> Self {
        self.product = None;
        self
    }

    /// The product automaton by breadth-first search from the start, None when it would
    /// exceed [`MAX_PRODUCT_STATES`].
    fn build_product(&self) -> Option<Product> {
        if self.lpes.is_empty() {
            return None;
        }
        let mut masks = vec![0u32];
        for &m in &self.shape_labels {
            if !masks.contains(&m) {
                masks.push(m);
            }
        }
        let nc = super::automaton::BASE_COUNT * masks.len();
        let n = self.lpes.len();
        let (states, table) = product_search(&masks, n, |i, q, e| self.lpes[i].step(q, e), |_| true)?;
        let accept: Vec<LayerMask> =
            states.iter().map(|st| (0..n).filter(|&i| self.lpes[i].accepts(st[i])).fold(self.base_mask(), |m, i| m | self.bit(i))).collect();
        let ends = table.iter().map(|&q| accept[q as usize]).collect();
        let rev = self.build_rev_product(&masks, &states);
        Some(Product { masks, n_classes: nc, table, ends, states, rev })
    }

    /// The reverse automata's product (breadth-first from the start) and its meeting table.
    fn build_rev_product(&self, masks: &[u32], fwd: &[[u32; MAX_LAYERS + 1]]) -> Option<RevProduct> {
        let n = self.lpes.len();
        let (states, table) = product_search(masks, n, |i, q, e| self.lpes[i].rev_step(q, e), |count| count * fwd.len() <= MAX_MEET_ENTRIES)?;
        let mut meets = Vec::with_capacity(fwd.len() * states.len());
        for f in fwd {
            for r in &states {
                meets.push((0..n).filter(|&i| self.lpes[i].meets(f[i], r[i])).fold(self.base_mask(), |m, i| m | self.bit(i)));
            }
        }
        Some(RevProduct { table, states: states.len(), meets })
    }

    /// Whether a light subpath's automaton states fit one integer (the reverse product
    /// state), which photons carry from the light to the lookup that completes their path.
    pub fn light_states_fit(&self) -> bool {
        self.is_empty() || self.product.as_ref().is_some_and(|p| p.rev.is_some())
    }

    /// The forward and reverse product automata as plain integer states, when both were
    /// built: what a method that routes many joined paths per sample (BDPT's strategies)
    /// steps without carrying a state per automaton.
    #[inline]
    pub fn product_view(&self) -> Option<ProductView<'_>> {
        let p = self.product.as_ref()?;
        Some(ProductView { p, rp: p.rev.as_ref()? })
    }

    /// The forward product automaton with events as precomputed classes, when it was built
    /// (sets bound to a scene and not too large): what a kernel that steps many camera
    /// paths at once keeps per path, one integer.
    #[inline]
    pub fn forward_view(&self) -> Option<ForwardView<'_>> {
        self.product.as_ref().map(|p| ForwardView { p })
    }

    /// States of the product automaton (0: none was built).
    pub fn product_states(&self) -> usize {
        self.product.as_ref().map_or(0, |p| p.states.len())
    }

    pub fn is_empty(&self) -> bool {
        self.lpes.is_empty()
    }
    pub fn names(&self) -> &[String] {
        &self.names
    }
    pub fn aov_count(&self) -> usize {
        self.names.len()
    }
    pub fn expressions(&self) -> &[Lpe] {
        &self.lpes
    }
    /// Whether the beauty holds only the paths of an expression.
    pub fn restricts_beauty(&self) -> bool {
        self.beauty_filter
    }
    /// The label bits of scene shape `shape`.
    #[inline]
    pub fn shape_labels(&self, shape: u32) -> u32 {
        self.shape_labels.get(shape as usize).copied().unwrap_or(0)
    }
    /// The event of a light vertex on scene shape `shape` (None: not a shape).
    #[inline]
    pub fn light_event(&self, shape: Option<u32>) -> Event {
        Event { labels: shape.map_or(0, |s| self.shape_labels(s)), ..Event::LIGHT }
    }

    /// The event of reaching emitter `light` (by sampling it or by hitting it): B for the
    /// environment (what escaped rays see), L with its shape's labels otherwise.
    #[inline]
    pub fn emitter_event(&self, light: &crate::light::Light) -> Event {
        use crate::light::Light;
        match light {
            Light::Area(a) => self.light_event(Some(a.shape)),
            Light::Constant { .. } | Light::EnvMap(_) => Event::BACKGROUND,
            _ => Event::LIGHT,
        }
    }

    /// The event of scattering at a surface of shape `shape` with BSDF lobes `flags`:
    /// `lobe` the lobe sampled (None: an evaluated direction, next-event estimation or a
    /// connection), `transmission` whether the directions lie on opposite sides.
    #[inline]
    pub fn scatter_event(&self, shape: u32, flags: crate::bsdf::LobeFlags, lobe: Option<crate::bsdf::LobeFlags>, transmission: bool) -> Event {
        let singular = lobe.is_some_and(|l| l.contains(crate::bsdf::LobeFlags::SPECULAR));
        Event::scatter(flags, singular, transmission, self.shape_labels(shape))
    }

    /// The event of a path endpoint on an emitter: a light subpath's first vertex, or a
    /// camera subpath that ended on an emitter or escaped (no light: the environment).
    #[inline]
    pub fn endpoint_event(&self, scene: &Scene, v: &crate::path::Vertex) -> Event {
        match v.light {
            Some(li) => self.emitter_event(&scene.lights[li as usize]),
            None => Event::BACKGROUND,
        }
    }

    /// The event of scattering at subpath vertex `v` as its walk sampled it; None for a
    /// null interaction (a mask let the path through: not a vertex of the expression).
    #[inline]
    pub fn sampled_event(&self, v: &crate::path::Vertex) -> Option<Event> {
        if v.event.kind == crate::path::EventKind::Null {
            return None;
        }
        let flags = v.lobes;
        Some(Event::scatter(flags, v.delta, v.event.transmission, self.shape_labels(v.shape)))
    }

    /// The event of reflecting at subpath vertex `v` by its BSDF's non-delta lobes: from it
    /// [`Self::sampled_from`] and [`Self::connected`] make the vertex's other events without
    /// another look at the BSDF (for methods that connect a vertex many times).
    #[inline]
    pub fn reflect_event(&self, v: &crate::path::Vertex) -> Event {
        let flags = v.lobes;
        Event::scatter(flags, false, false, self.shape_labels(v.shape))
    }

    /// [`Self::sampled_event`] from the vertex's reflection event ([`Self::reflect_event`]).
    #[inline]
    pub fn sampled_from(reflect: Event, v: &crate::path::Vertex) -> Option<Event> {
        if v.event.kind == crate::path::EventKind::Null {
            return None;
        }
        // Singular when the walk chose a delta lobe (base 5 = 3 + S), else the lobes' kind.
        let base = if v.delta { 5 } else { reflect.base };
        Some(Event { base: base + 3 * v.event.transmission as u8, ..reflect })
    }

    /// [`Self::connected_event`] from the vertex's reflection event ([`Self::reflect_event`]).
    #[inline]
    pub fn connected(reflect: Event, v: &crate::path::Vertex, q: glam::Vec3) -> Event {
        let through = (v.wo.dot(v.ng) > 0.0) != ((q - v.p).dot(v.ng) > 0.0);
        Event { base: reflect.base + 3 * through as u8, ..reflect }
    }

    /// The event of scattering at subpath vertex `v` toward point `q` (a connection).
    #[inline]
    pub fn connected_event(&self, v: &crate::path::Vertex, q: glam::Vec3) -> Event {
        let flags = v.lobes;
        let through = (v.wo.dot(v.ng) > 0.0) != ((q - v.p).dot(v.ng) > 0.0);
        Event::scatter(flags, false, through, self.shape_labels(v.shape))
    }

    /// The event of scattering at path vertex `v` between points `a` and `b` (either order):
    /// a delta vertex by the lobe its walk chose, a non-delta one by its BSDF's non-delta
    /// lobes, transmission when `a` and `b` lie on opposite sides; None for a null vertex.
    #[inline]
    pub fn vertex_event(&self, v: &crate::path::Vertex, a: glam::Vec3, b: glam::Vec3) -> Option<Event> {
        use crate::path::EventKind;
        if v.event.kind == EventKind::Null {
            return None;
        }
        let flags = v.lobes;
        let through = ((a - v.p).dot(v.ng) > 0.0) != ((b - v.p).dot(v.ng) > 0.0);
        Some(Event::scatter(flags, v.delta, through, self.shape_labels(v.shape)))
    }

    /// The layers that take a whole path given light first (`path[0]` on an emitter, the
    /// last vertex the camera), as path-space Metropolis builds it.
    pub fn path_layers(&self, scene: &Scene, path: &[crate::path::Vertex]) -> LayerMask {
        let k = path.len().saturating_sub(1);
        if self.is_empty() || k == 0 {
            return self.base_mask();
        }
        let mut t = Tracker::camera(self);
        for i in (1..k).rev() {
            if let Some(e) = self.vertex_event(&path[i], path[i - 1].p, path[i + 1].p) {
                t.push(e);
            }
        }
        t.ends(self.endpoint_event(scene, &path[0]))
    }

    /// The layers that take every path of a class (see [`Lpe::class_verdict`]); Err names
    /// an expression that takes only some of them.
    pub fn class_layers(&self, prefix: &[Event], repeat: &[Event], min_repeat: usize, ends: &[Event]) -> Result<LayerMask, String> {
        let mut parts: Vec<ClassPart> = prefix.iter().map(ClassPart::one).collect();
        parts.push(ClassPart { events: repeat, min: min_repeat, more: true });
        self.class_layers_of(&parts, ends)
    }

    /// [`Self::class_layers`] of the class `parts` then one of `ends` (see [`Lpe::class_verdict_of`]).
    pub fn class_layers_of(&self, parts: &[ClassPart], ends: &[Event]) -> Result<LayerMask, String> {
        let mut m = self.base_mask();
        for (i, l) in self.lpes.iter().enumerate() {
            match l.class_verdict_of(parts, ends) {
                Some(true) => m |= self.bit(i),
                Some(false) => {}
                None => return Err(l.source.clone()),
            }
        }
        Ok(m)
    }

    /// Routes for classes of paths that continue traced camera prefixes: for every path of
    /// `prefix` (the events a method traces before it reads a value that stands for a whole
    /// class), each class `(parts, ends)` must be taken whole or not at all by every
    /// expression. Err names the AOV (or the beauty's restriction) that takes only some paths
    /// of a class after some prefix.
    pub fn class_router(&self, prefix: &[ClassPart], classes: &[(&[ClassPart], &[Event])]) -> Result<ClassRouter, String> {
        let mut verdicts = Vec::with_capacity(classes.len());
        for &(parts, ends) in classes {
            let mut per_lpe = Vec::with_capacity(self.lpes.len());
            for (i, l) in self.lpes.iter().enumerate() {
                let v = l.state_verdicts(parts, ends);
                let reach = l.class_states(Lpe::START, prefix);
                if reach.iter().zip(&v).any(|(r, v)| *r && v.is_none()) {
                    return Err(match self.names.get(i) {
                        Some(n) => format!("AOV '{n}' ('{}')", l.source),
                        None => format!("--lpe '{}'", l.source),
                    });
                }
                per_lpe.push(v.iter().map(|v| *v == Some(true)).collect::<Vec<bool>>());
            }
            verdicts.push(per_lpe);
        }
        // With the product automaton: each product state's layers per class, one lookup.
        let product = self.product.as_ref().map(|p| {
            p.states
                .iter()
                .flat_map(|st| {
                    verdicts
                        .iter()
                        .map(move |per_lpe| per_lpe.iter().enumerate().filter(|(i, v)| v[st[*i] as usize]).fold(self.base_mask(), |m, (i, _)| m | self.bit(i)))
                })
                .collect()
        });
        Ok(ClassRouter { classes: classes.len(), verdicts, product })
    }

    /// The events of reaching each of the scene's emitters.
    pub fn emitter_events(&self, scene: &Scene) -> Vec<Event> {
        scene.lights.iter().map(|l| self.emitter_event(l)).collect()
    }

    #[inline]
    fn bit(&self, i: usize) -> LayerMask {
        if i < self.names.len() {
            1 << i
        } else {
            BEAUTY
        }
    }
    #[inline]
    fn base_mask(&self) -> LayerMask {
        if self.beauty_filter {
            0
        } else {
            BEAUTY
        }
    }
}

/// The product automata of an [`AovSet`] ([`AovSet::product_view`]): forward states `q`
/// (a camera prefix, as [`Tracker`] holds them) and reverse states `r` (a light subpath, as
/// [`LightTracker`] holds them), with the same steps.
#[derive(Clone, Copy, Debug)]
pub struct ProductView<'a> {
    p: &'a Product,
    rp: &'a RevProduct,
}

impl ProductView<'_> {
    /// The state of a path that has left the camera ([`Tracker::camera`]).
    #[inline]
    pub fn camera(&self) -> u32 {
        self.p.step(0, Event::CAMERA)
    }
    #[inline]
    pub fn step(&self, q: u32, e: Event) -> u32 {
        self.p.step(q, e)
    }
    /// The layers that take a camera prefix in state `q` ending with event `e`.
    #[inline]
    pub fn ends(&self, q: u32, e: Event) -> LayerMask {
        self.p.ends(q, e)
    }
    /// The reverse state of a light subpath that starts with event `e` ([`LightTracker::light`]).
    #[inline]
    pub fn light(&self, e: Event) -> u32 {
        self.rev_step(0, e)
    }
    #[inline]
    pub fn rev_step(&self, r: u32, e: Event) -> u32 {
        self.rp.table[r as usize * self.p.n_classes + self.p.class(e)]
    }
    /// The layers that take camera prefix `q` joined to light subpath `r` ([`LightTracker::meets`]).
    #[inline]
    pub fn meets(&self, q: u32, r: u32) -> LayerMask {
        self.rp.meets[q as usize * self.rp.states + r as usize]
    }
}

/// The forward product automaton of an [`AovSet`] ([`AovSet::forward_view`]) over event
/// classes: an event's class ([`ForwardView::class`]) is found once, where the events of a
/// scene's shapes are tabulated, and each vertex of a path is then one table step.
#[derive(Clone, Copy, Debug)]
pub struct ForwardView<'a> {
    p: &'a Product,
}

impl ForwardView<'_> {
    /// The class of event `e` in the tables.
    #[inline]
    pub fn class(&self, e: Event) -> u32 {
        self.p.class(e) as u32
    }
    /// The state of a path that has left the camera (as [`Tracker::camera`]).
    #[inline]
    pub fn camera(&self) -> u32 {
        self.p.step(0, Event::CAMERA)
    }
    /// The state after event class `c` in state `q` (as [`Tracker::push`]).
    #[inline(always)]
    pub fn step(&self, q: u32, c: u32) -> u32 {
        self.p.table[q as usize * self.p.n_classes + c as usize]
    }
    /// The layers that take a path in state `q` ending with event class `c` (as [`Tracker::ends`]).
    #[inline(always)]
    pub fn ends(&self, q: u32, c: u32) -> LayerMask {
        self.p.ends[q as usize * self.p.n_classes + c as usize]
    }
}

impl<'a> ForwardView<'a> {
    /// The tables of [`Self::step`] and [`Self::ends`] (entry `q * classes + c`) and the
    /// number of classes, for lookups of several paths at once.
    pub fn tables(&self) -> (&'a [u32], &'a [LayerMask], usize) {
        (&self.p.table, &self.p.ends, self.p.n_classes)
    }
}

/// The automata's states along a camera subpath (forward automata, camera first): one
/// product state when the set has its product automaton, else one state per automaton.
#[derive(Clone, Copy, Debug)]
pub struct Tracker<'a> {
    set: &'a AovSet,
    q: u32,
    st: [u32; MAX_LAYERS + 1],
}

impl Product {
    #[inline(always)]
    fn class(&self, e: Event) -> usize {
        let k = if e.labels == 0 { 0 } else { self.masks.iter().position(|&m| m == e.labels).unwrap_or(0) };
        e.base as usize + super::automaton::BASE_COUNT * k
    }
    #[inline(always)]
    fn step(&self, q: u32, e: Event) -> u32 {
        self.table[q as usize * self.n_classes + self.class(e)]
    }
    #[inline(always)]
    fn ends(&self, q: u32, e: Event) -> LayerMask {
        self.ends[q as usize * self.n_classes + self.class(e)]
    }
}

impl<'a> Tracker<'a> {
    /// A path that has left the camera (its first event, `C`, read).
    #[inline]
    pub fn camera(set: &'a AovSet) -> Self {
        let mut t = Tracker { set, q: 0, st: [Lpe::START; MAX_LAYERS + 1] };
        t.push(Event::CAMERA);
        t
    }
    #[inline(always)]
    pub fn push(&mut self, e: Event) {
        match &self.set.product {
            Some(p) => self.q = p.step(self.q, e),
            None => {
                for (s, l) in self.st.iter_mut().zip(&self.set.lpes) {
                    *s = l.step(*s, e);
                }
            }
        }
    }
    /// The layers that take a path ending here with event `e`.
    #[inline(always)]
    pub fn ends(&self, e: Event) -> LayerMask {
        if let Some(p) = &self.set.product {
            return p.ends(self.q, e);
        }
        let mut m = self.set.base_mask();
        for (i, (s, l)) in self.st.iter().zip(&self.set.lpes).enumerate() {
            if l.accepts(l.step(*s, e)) {
                m |= self.set.bit(i);
            }
        }
        m
    }
    /// The layers that take a path ending with events `a` then `b` (next-event estimation:
    /// the scattering vertex, then the light).
    #[inline(always)]
    pub fn ends2(&self, a: Event, b: Event) -> LayerMask {
        if let Some(p) = &self.set.product {
            return p.ends(p.step(self.q, a), b);
        }
        let mut t = *self;
        t.push(a);
        t.ends(b)
    }
    /// Each automaton's own state.
    #[inline]
    fn states(&self) -> &[u32; MAX_LAYERS + 1] {
        match &self.set.product {
            Some(p) => &p.states[self.q as usize],
            None => &self.st,
        }
    }
    pub fn set(&self) -> &'a AovSet {
        self.set
    }
    /// The same states held with a longer borrow of `set`, which must be the set the tracker
    /// was made from (the states index its automata).
    #[inline]
    pub fn rebind<'s>(&self, set: &'s AovSet) -> Tracker<'s> {
        debug_assert!(std::ptr::eq(self.set, set));
        Tracker { set, q: self.q, st: self.st }
    }
    /// The layers that take this camera prefix joined to a light subpath whose reverse
    /// product state is `r` ([`LightTracker::state`]; see [`AovSet::light_states_fit`]).
    #[inline]
    pub fn meets_state(&self, r: u32) -> LayerMask {
        match self.set.product.as_ref().and_then(|p| p.rev.as_ref()) {
            // A state from elsewhere (photon bytes from another machine) that no automaton
            // of this set has meets nothing.
            Some(rp) => rp.meets.get(self.q as usize * rp.states + r as usize).copied().filter(|_| (r as usize) < rp.states).unwrap_or(0),
            None => self.set.base_mask(),
        }
    }
}

/// Which layers take a class of paths after a camera prefix (see [`AovSet::class_router`]).
#[derive(Clone, Debug)]
pub struct ClassRouter {
    classes: usize,
    /// Per class, per expression, per state: whether the expression takes the class there.
    verdicts: Vec<Vec<Vec<bool>>>,
    /// Per product state, per class: the layers (when the set has its product automaton).
    product: Option<Vec<LayerMask>>,
}

impl ClassRouter {
    /// The layers that take class `c` (an index into the router's classes) after the prefix
    /// `t` has read. A state that no prefix of the router's reaches goes nowhere.
    #[inline]
    pub fn layers(&self, t: &Tracker, c: usize) -> LayerMask {
        if let Some(p) = &self.product {
            return p[t.q as usize * self.classes + c];
        }
        let set = t.set;
        let mut m = set.base_mask();
        for (i, (s, v)) in t.st.iter().zip(&self.verdicts[c]).enumerate() {
            if v.get(*s as usize).copied().unwrap_or(false) {
                m |= set.bit(i);
            }
        }
        m
    }
}

/// The reverse automata's states along a light subpath (light first).
#[derive(Clone, Copy, Debug)]
pub struct LightTracker<'a> {
    set: &'a AovSet,
    /// The reverse product state, when the set has one.
    r: u32,
    st: [u32; MAX_LAYERS + 1],
}

impl<'a> LightTracker<'a> {
    /// A subpath whose events so far are `path`'s first `n` vertices as sampled (vertex 0 the
    /// light endpoint).
    pub fn along(set: &'a AovSet, scene: &Scene, path: &[crate::path::Vertex], n: usize) -> Self {
        let mut t = LightTracker::light(set, set.endpoint_event(scene, &path[0]));
        for v in &path[1..n] {
            if let Some(e) = set.sampled_event(v) {
                t.push(e);
            }
        }
        t
    }

    /// A subpath that starts at a light with event `e` (L or B).
    #[inline]
    pub fn light(set: &'a AovSet, e: Event) -> Self {
        let mut t = LightTracker { set, r: 0, st: [Lpe::START; MAX_LAYERS + 1] };
        t.push(e);
        t
    }
    #[inline]
    fn rev(&self) -> Option<(&'a Product, &'a RevProduct)> {
        let p = self.set.product.as_ref()?;
        Some((p, p.rev.as_ref()?))
    }
    #[inline]
    pub fn push(&mut self, e: Event) {
        if let Some((p, rp)) = self.rev() {
            self.r = rp.table[self.r as usize * p.n_classes + p.class(e)];
            return;
        }
        for (s, l) in self.st.iter_mut().zip(&self.set.lpes) {
            *s = l.rev_step(*s, e);
        }
    }
    /// The layers that take the camera prefix `cam` joined to this subpath.
    #[inline]
    pub fn meets(&self, cam: &Tracker) -> LayerMask {
        if let Some((_, rp)) = self.rev() {
            return rp.meets[cam.q as usize * rp.states + self.r as usize];
        }
        let mut m = self.set.base_mask();
        for (i, ((r, q), l)) in self.st.iter().zip(cam.states()).zip(&self.set.lpes).enumerate() {
            if l.meets(*q, *r) {
                m |= self.set.bit(i);
            }
        }
        m
    }
    /// The reverse product state: all a photon needs to carry of its subpath's events
    /// (meaningful where [`AovSet::light_states_fit`]).
    #[inline]
    pub fn state(&self) -> u32 {
        self.r
    }
    /// The layers that take this subpath ending at the camera (light tracing, t = 1).
    #[inline]
    pub fn meets_camera(&self) -> LayerMask {
        self.meets(&Tracker::camera(self.set))
    }
}

/// What one camera sample adds to each AOV and to the (restricted) beauty.
#[derive(Clone, Copy, Debug)]
pub struct LayerSample {
    pub aov: [Rgb; MAX_LAYERS],
    /// The sum of contributions the beauty takes.
    pub beauty: Rgb,
    /// Bit i: AOV i may have been added to (the film skips the others).
    pub touched: u32,
}

impl Default for LayerSample {
    fn default() -> Self {
        LayerSample { aov: [Rgb::BLACK; MAX_LAYERS], beauty: Rgb::BLACK, touched: 0 }
    }
}

impl LayerSample {
    /// Add `other` times `k` (a throughput), for the first `n` AOVs.
    #[inline]
    pub fn add_scaled(&mut self, other: &LayerSample, k: Rgb, n: usize) {
        self.beauty += other.beauty * k;
        self.touched |= other.touched;
        for (a, b) in self.aov[..n].iter_mut().zip(&other.aov[..n]) {
            *a += *b * k;
        }
    }

    /// Multiply every layer and the beauty by `k` (the untouched layers stay zero, whatever
    /// `k` is: [`Self::clear`] relies on it).
    #[inline]
    pub fn scale(&mut self, k: f32) {
        self.beauty *= k;
        self.each_touched(|a| *a *= k);
    }

    /// Back to black for the next sample, clearing only the layers it touched: the others
    /// are zero already (every write marks its layer).
    #[inline]
    pub fn clear(&mut self) {
        self.each_touched(|a| *a = Rgb::BLACK);
        self.beauty = Rgb::BLACK;
        self.touched = 0;
    }

    #[inline]
    fn each_touched(&mut self, mut f: impl FnMut(&mut Rgb)) {
        let mut m = self.touched;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            if let Some(a) = self.aov.get_mut(i) {
                f(a);
            }
        }
    }

    /// Route `value` to the layers of `mask`.
    #[inline]
    pub fn add(&mut self, mask: LayerMask, value: Rgb) {
        if mask & BEAUTY != 0 {
            self.beauty += value;
        }
        let mut m = mask & !BEAUTY;
        self.touched |= m;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            self.aov[i] += value;
            m &= m - 1;
        }
    }
}
