//! Light path expressions (Heckbert's notation, OSL's syntax): which light paths an image
//! or an AOV holds.
//!
//! An expression is parsed ([`parse`]), compiled once into a minimised DFA over vertex
//! event classes ([`automaton`]), and then matched one table step per path vertex
//! ([`Lpe::step`]), with no allocation. Light-first expressions (`L ... E`, the lecture's
//! and Heckbert's order) are recognised by their first vertex (only emitters can start
//! them) and their tree is reversed before compilation, so every automaton reads paths
//! camera first. Light subpaths (light tracing, BDPT, photons) use the reverse automaton
//! ([`Lpe::rev_step`]) and meet a camera prefix with [`Lpe::meets`].

pub mod aov;
pub mod automaton;
pub mod parse;

pub use aov::{AovSet, ClassRouter, ForwardView, LayerMask, LightTracker, ProductView, Tracker, MAX_LAYERS};

use automaton::{Dfa, BASE_COUNT};

/// `--aov-preset lecture`: one AOV per method class of the lecture, camera first (the
/// lecture's S, any directional lobe, is `[GS]`; its S_M, the ideal mirror, is `S`). The
/// classes nest (local ⊂ Whitted ⊂ Cook; radiosity beside them); `rest` is every path in
/// none of them, so that `cook`, `radiosity` and `rest` less their overlap `C D? [LB]`
/// cover everything.
pub const LECTURE_PRESET: &[(&str, &str)] = &[
    ("local", "C [DG]? [LB]"),
    ("whitted", "C S* [DG]? [LB]"),
    ("cook", "C [GS]* D? [LB]"),
    ("radiosity", "C D* [LB]"),
    ("rest", "C .* D .* [GS] .* [LB] | C .* [GS] .* D .* D .* [LB]"),
];

/// A malformed expression: the message, and the expression with a caret under the column.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{msg} (column {})\n  {expr}\n  {caret}^", col + 1, caret = " ".repeat(*col))]
pub struct LpeError {
    pub expr: String,
    /// Zero-based column, in characters.
    pub col: usize,
    pub msg: String,
}

impl LpeError {
    pub(crate) fn at(expr: &str, col: usize, msg: String) -> Self {
        LpeError { expr: expr.to_string(), col: col.min(expr.chars().count()), msg }
    }
}

/// What happened at one vertex: one of the nine base classes (camera, light, background,
/// reflection or transmission times diffuse, glossy or singular) and the custom labels of
/// the surface (bits of an [`AovSet`]'s label list).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Event {
    pub base: u8,
    pub labels: u32,
}

impl Event {
    pub const CAMERA: Event = Event { base: 0, labels: 0 };
    pub const LIGHT: Event = Event { base: 1, labels: 0 };
    pub const BACKGROUND: Event = Event { base: 2, labels: 0 };

    /// A scattering event. `singular`: a delta lobe; otherwise the BSDF's non-delta lobes
    /// decide (glossy if it has a glossy one, else diffuse), so that the same path gets the
    /// same label whichever strategy (BSDF sampling, light sampling, a connection) made it.
    #[inline]
    pub fn scatter(flags: crate::bsdf::LobeFlags, singular: bool, transmission: bool, labels: u32) -> Event {
        use crate::bsdf::LobeFlags;
        let kind = if singular {
            2
        } else if flags.intersects(LobeFlags::GLOSSY) {
            1
        } else {
            0
        };
        Event { base: 3 + kind + 3 * transmission as u8, labels }
    }

    /// One token of a labelled path as the tests write it: `C`, `L`, `B`, `D`/`RD`, `G`/`RG`,
    /// `S`/`RS`, `TD`, `TG`, `TS`, optionally followed by `@label-bits` (a decimal mask).
    pub fn parse_token(tok: &str) -> Option<Event> {
        let (t, labels) = match tok.split_once('@') {
            Some((t, m)) => (t, m.parse().ok()?),
            None => (tok, 0),
        };
        let base = match t {
            "C" | "E" => 0,
            "L" => 1,
            "B" => 2,
            "D" | "RD" => 3,
            "G" | "RG" => 4,
            "S" | "RS" => 5,
            "TD" => 6,
            "TG" => 7,
            "TS" => 8,
            _ => return None,
        };
        Some(Event { base, labels })
    }

    /// The symbol a user would write for the event (`D`, `TS`, `L`...).
    pub fn symbol(self) -> &'static str {
        ["C", "L", "B", "D", "G", "S", "TD", "TG", "TS"][self.base as usize % BASE_COUNT]
    }
}

/// One part of a class of paths (see [`Lpe::class_verdict_of`]): `min` events, each any of
/// `events`, and with `more` any number of further ones.
#[derive(Clone, Copy, Debug)]
pub struct ClassPart<'a> {
    pub events: &'a [Event],
    pub min: usize,
    pub more: bool,
}

impl<'a> ClassPart<'a> {
    /// Exactly the event `e`.
    pub fn one(e: &'a Event) -> Self {
        ClassPart { events: std::slice::from_ref(e), min: 1, more: false }
    }
    /// Exactly one of `events`.
    pub fn any(events: &'a [Event]) -> Self {
        ClassPart { events, min: 1, more: false }
    }
    /// Any number (none too) of `events`.
    pub fn star(events: &'a [Event]) -> Self {
        ClassPart { events, min: 0, more: true }
    }
}

/// A compiled expression.
#[derive(Clone, Debug)]
pub struct Lpe {
    pub source: String,
    /// Whether the expression was written light first (and reversed).
    pub light_first: bool,
    dfa: Dfa,
    /// For each of the expression's labels, its bit in the events' label masks.
    label_bits: Vec<u8>,
}

impl Lpe {
    /// Parse and compile. Labels get bits in the order [`Lpe::labels`] lists them until
    /// [`Lpe::bind_labels`] maps them to a set's bits.
    pub fn new(src: &str) -> Result<Lpe, LpeError> {
        let ast = parse::parse(src)?;
        let mut labels = Vec::new();
        ast.labels(&mut labels);
        let dfa = automaton::compile(&ast, labels.clone(), src)?;
        let (dfa, light_first) = if starts_at_emitter(&dfa) { (automaton::compile(&ast.reversed(), labels, src)?, true) } else { (dfa, false) };
        let label_bits = (0..dfa.labels.len() as u8).collect();
        Ok(Lpe { source: src.to_string(), light_first, dfa, label_bits })
    }

    pub fn labels(&self) -> &[String] {
        &self.dfa.labels
    }
    /// Bit `bits[i]` of an event's label mask means label `labels()[i]`.
    pub fn bind_labels(&mut self, bits: Vec<u8>) {
        debug_assert_eq!(bits.len(), self.dfa.labels.len());
        self.label_bits = bits;
    }
    /// States of the minimised automaton and of its reverse; classes of its alphabet.
    pub fn size(&self) -> (usize, usize, usize) {
        (self.dfa.states(), self.dfa.rev_states(), self.dfa.n_classes)
    }
    /// False when no path can match (a warning for the user).
    pub fn can_match(&self) -> bool {
        self.dfa.can_match()
    }

    #[inline]
    fn class(&self, e: Event) -> usize {
        let mut mask = 0usize;
        for (i, &b) in self.label_bits.iter().enumerate() {
            mask |= ((e.labels >> b) as usize & 1) << i;
        }
        e.base as usize + BASE_COUNT * mask
    }
    /// The start state (nothing read).
    pub const START: u32 = 0;
    /// One vertex, camera first.
    #[inline]
    pub fn step(&self, state: u32, e: Event) -> u32 {
        self.dfa.table[state as usize * self.dfa.n_classes + self.class(e)]
    }
    #[inline]
    pub fn accepts(&self, state: u32) -> bool {
        self.dfa.accept[state as usize]
    }
    /// One vertex of a light subpath, light first (from [`Self::START`]).
    #[inline]
    pub fn rev_step(&self, state: u32, e: Event) -> u32 {
        self.dfa.rev_table[state as usize * self.dfa.n_classes + self.class(e)]
    }
    /// Whether a camera prefix in forward state `q` joined to a light subpath in reverse
    /// state `r` makes a matching path.
    #[inline]
    pub fn meets(&self, q: u32, r: u32) -> bool {
        self.dfa.meets(q, r)
    }
    /// Whether a whole path, camera first, matches.
    pub fn matches(&self, path: &[Event]) -> bool {
        self.accepts(path.iter().fold(Self::START, |s, &e| self.step(s, e)))
    }
    /// Whether a path matches when read light first by the reverse automaton.
    pub fn matches_from_light(&self, path: &[Event]) -> bool {
        let r = path.iter().rev().fold(Self::START, |s, &e| self.rev_step(s, e));
        self.meets(Self::START, r)
    }
    /// Whether the expression takes all (`Some(true)`), none (`Some(false)`) or only some
    /// (`None`) of the paths `prefix · r^n · end` with `n >= min_repeat`, each `r` any of
    /// `repeat` and `end` any of `ends`, camera first: how methods that solve for a whole
    /// class of paths at once (radiosity, the local model) learn which layers take it.
    pub fn class_verdict(&self, prefix: &[Event], repeat: &[Event], min_repeat: usize, ends: &[Event]) -> Option<bool> {
        let mut parts: Vec<ClassPart> = prefix.iter().map(ClassPart::one).collect();
        parts.push(ClassPart { events: repeat, min: min_repeat, more: true });
        self.class_verdict_of(&parts, ends)
    }

    /// [`Self::class_verdict`] of the class `parts` (concatenated, camera first) then one of `ends`.
    pub fn class_verdict_of(&self, parts: &[ClassPart], ends: &[Event]) -> Option<bool> {
        self.ends_verdict(&self.class_states(Self::START, parts), ends)
    }

    /// The states the automaton can be in after reading any path of `parts` from state `q`.
    pub fn class_states(&self, q: u32, parts: &[ClassPart]) -> Vec<bool> {
        let n = self.dfa.states();
        let mut set = vec![false; n];
        set[q as usize] = true;
        let step_all = |set: &[bool], events: &[Event]| {
            let mut out = vec![false; n];
            for q in (0..n).filter(|&q| set[q]) {
                for &e in events {
                    out[self.step(q as u32, e) as usize] = true;
                }
            }
            out
        };
        for p in parts {
            for _ in 0..p.min {
                set = step_all(&set, p.events);
            }
            if p.more && !p.events.is_empty() {
                // Any number of further events: the closure.
                loop {
                    let next = step_all(&set, p.events);
                    let grown: Vec<bool> = set.iter().zip(&next).map(|(a, b)| *a || *b).collect();
                    if grown == set {
                        break;
                    }
                    set = grown;
                }
            }
        }
        set
    }

    /// Whether paths in the states `set` that end with one of `ends` all match, none does,
    /// or some do (`None`).
    fn ends_verdict(&self, set: &[bool], ends: &[Event]) -> Option<bool> {
        let (mut any, mut all) = (false, true);
        for q in (0..set.len()).filter(|&q| set[q]) {
            for &e in ends {
                let a = self.accepts(self.step(q as u32, e));
                any |= a;
                all &= a;
            }
        }
        if all && any {
            Some(true)
        } else if !any {
            Some(false)
        } else {
            None
        }
    }

    /// Per automaton state q: the verdict on the paths `q · parts · end` (see
    /// [`Self::class_verdict`]), for a class that continues a path traced up to q.
    pub fn state_verdicts(&self, parts: &[ClassPart], ends: &[Event]) -> Vec<Option<bool>> {
        (0..self.dfa.states() as u32).map(|q| self.ends_verdict(&self.class_states(q, parts), ends)).collect()
    }

    /// The base classes (as symbols) that can occur in some matching path.
    pub fn useful_symbols(&self) -> Vec<&'static str> {
        let live = live_states(&self.dfa);
        let nc = self.dfa.n_classes;
        let reach = reachable(&self.dfa);
        let mut used = [false; BASE_COUNT];
        for s in 0..self.dfa.states() {
            for c in 0..nc {
                if live[s] && live[self.dfa.table[s * nc + c] as usize] && reach[s] {
                    used[c % BASE_COUNT] = true;
                }
            }
        }
        (0..BASE_COUNT).filter(|&b| used[b]).map(|b| Event { base: b as u8, labels: 0 }.symbol()).collect()
    }
}

fn reachable(d: &Dfa) -> Vec<bool> {
    let mut seen = vec![false; d.states()];
    let mut stack = vec![0usize];
    seen[0] = true;
    while let Some(s) = stack.pop() {
        for c in 0..d.n_classes {
            let t = d.table[s * d.n_classes + c] as usize;
            if !seen[t] {
                seen[t] = true;
                stack.push(t);
            }
        }
    }
    seen
}

/// States from which acceptance is reachable.
fn live_states(d: &Dfa) -> Vec<bool> {
    let mut live = d.accept.clone();
    loop {
        let mut changed = false;
        for s in 0..d.states() {
            if !live[s] && (0..d.n_classes).any(|c| live[d.table[s * d.n_classes + c] as usize]) {
                live[s] = true;
                changed = true;
            }
        }
        if !changed {
            return live;
        }
    }
}

/// Whether every first vertex that can lead to a match is an emitter (L or B): the
/// expression was written light first.
fn starts_at_emitter(d: &Dfa) -> bool {
    let live = live_states(d);
    let first: Vec<usize> = (0..d.n_classes).filter(|&c| live[d.table[c] as usize]).collect();
    !first.is_empty() && first.iter().all(|&c| matches!(c % BASE_COUNT, 1 | 2))
}

#[cfg(test)]
mod tests;
