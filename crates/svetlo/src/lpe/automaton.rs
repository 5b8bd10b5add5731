//! Expression tree -> Thompson NFA -> subset-construction DFA -> minimised DFA (Moore's
//! partition refinement), and the reverse automaton that reads light subpaths from the light.
//!
//! The alphabet is the event classes: 9 base classes times every subset of the expression's
//! custom labels (class = base + 9 * label_mask), so that one table step handles a vertex.

use super::parse::{Ast, Atom};
use super::LpeError;
use std::collections::HashMap;

/// Most NFA states an expression may expand to (counted repetitions multiply).
pub const MAX_NFA_STATES: usize = 100_000;
/// Most states of the deterministic automata (forward before minimisation, and reverse).
pub const MAX_DFA_STATES: usize = 4096;
/// Most distinct custom labels in one expression (the alphabet doubles with each).
pub const MAX_LABELS: usize = 6;

pub const BASE_COUNT: usize = 9;

/// A set of classes as bits.
type ClassSet = Vec<u64>;

struct Nfa {
    /// Per state: epsilon targets.
    eps: Vec<Vec<u32>>,
    /// Per state: at most one symbol edge (class set index, target).
    edge: Vec<Option<(u32, u32)>>,
    sets: Vec<ClassSet>,
    n_classes: usize,
    labels: Vec<String>,
}

impl Nfa {
    fn state(&mut self, src: &str) -> Result<u32, LpeError> {
        if self.eps.len() >= MAX_NFA_STATES {
            return Err(LpeError::at(src, 0, format!("expression too large: more than {MAX_NFA_STATES} automaton states (reduce counted repetitions)")));
        }
        self.eps.push(Vec::new());
        self.edge.push(None);
        Ok(self.eps.len() as u32 - 1)
    }

    fn atom_holds(&self, a: &Atom, class: usize) -> bool {
        let (base, mask) = (class % BASE_COUNT, class / BASE_COUNT);
        match a {
            Atom::Base(m) => m >> base & 1 == 1,
            Atom::Label(l) => self.labels.iter().position(|x| x == l).is_some_and(|i| mask >> i & 1 == 1),
            Atom::All(v) => v.iter().all(|a| self.atom_holds(a, class)),
        }
    }

    /// A fragment (entry, exit) for `ast`.
    fn build(&mut self, ast: &Ast, src: &str) -> Result<(u32, u32), LpeError> {
        match ast {
            Ast::Leaf { atoms, negated } => {
                let mut set = vec![0u64; self.n_classes.div_ceil(64)];
                for c in 0..self.n_classes {
                    if atoms.iter().any(|a| self.atom_holds(a, c)) != *negated {
                        set[c / 64] |= 1 << (c % 64);
                    }
                }
                let id = self.sets.len() as u32;
                self.sets.push(set);
                let (a, b) = (self.state(src)?, self.state(src)?);
                self.edge[a as usize] = Some((id, b));
                Ok((a, b))
            }
            Ast::Concat(items) => {
                let (first, mut last) = self.build(&items[0], src)?;
                for it in &items[1..] {
                    let (a, b) = self.build(it, src)?;
                    self.eps[last as usize].push(a);
                    last = b;
                }
                Ok((first, last))
            }
            Ast::Alt(arms) => {
                let (a, b) = (self.state(src)?, self.state(src)?);
                for arm in arms {
                    let (x, y) = self.build(arm, src)?;
                    self.eps[a as usize].push(x);
                    self.eps[y as usize].push(b);
                }
                Ok((a, b))
            }
            Ast::Repeat { inner, min, max } => {
                let entry = self.state(src)?;
                let mut last = entry;
                // X{n,} is n - 1 copies and one that loops back on itself: one copy for X+, so
                // that nested repetitions ((X+)+...) do not double the automaton at each level.
                let copies = if max.is_none() { min.saturating_sub(1) } else { *min };
                for _ in 0..copies {
                    let (a, b) = self.build(inner, src)?;
                    self.eps[last as usize].push(a);
                    last = b;
                }
                match max {
                    None if *min >= 1 => {
                        let (a, b) = self.build(inner, src)?;
                        let out = self.state(src)?;
                        self.eps[last as usize].push(a);
                        self.eps[b as usize].push(a);
                        self.eps[b as usize].push(out);
                        last = out;
                    }
                    None => {
                        // Kleene star on one more copy.
                        let (a, b) = self.build(inner, src)?;
                        let out = self.state(src)?;
                        self.eps[last as usize].push(a);
                        self.eps[last as usize].push(out);
                        self.eps[b as usize].push(a);
                        self.eps[b as usize].push(out);
                        last = out;
                    }
                    Some(m) => {
                        let out = self.state(src)?;
                        for _ in *min..*m {
                            let (a, b) = self.build(inner, src)?;
                            self.eps[last as usize].push(a);
                            self.eps[last as usize].push(out);
                            last = b;
                        }
                        self.eps[last as usize].push(out);
                        last = out;
                    }
                }
                Ok((entry, last))
            }
        }
    }

    /// Epsilon closure of `set`, sorted (iterative: no recursion on long chains).
    fn closure(&self, set: &mut Vec<u32>, seen: &mut [bool]) {
        let mut stack: Vec<u32> = set.clone();
        for &s in set.iter() {
            seen[s as usize] = true;
        }
        while let Some(s) = stack.pop() {
            for &t in &self.eps[s as usize] {
                if !seen[t as usize] {
                    seen[t as usize] = true;
                    set.push(t);
                    stack.push(t);
                }
            }
        }
        for &s in set.iter() {
            seen[s as usize] = false;
        }
        set.sort_unstable();
    }

    fn has(&self, set: u32, class: usize) -> bool {
        self.sets[set as usize][class / 64] >> (class % 64) & 1 == 1
    }
}

/// A minimised DFA over event classes, with its reverse automaton.
#[derive(Clone, Debug)]
pub struct Dfa {
    pub n_classes: usize,
    /// `table[state * n_classes + class]`; state 0 is the start.
    pub table: Vec<u32>,
    pub accept: Vec<bool>,
    /// The reverse automaton: state r stands for the set of forward states from which the
    /// events read so far (light first) lead to acceptance.
    pub rev_table: Vec<u32>,
    pub rev_words: usize,
    pub rev_sets: Vec<u64>,
    /// The expression's custom labels, in class-mask bit order.
    pub labels: Vec<String>,
}

impl Dfa {
    pub fn states(&self) -> usize {
        self.accept.len()
    }
    pub fn rev_states(&self) -> usize {
        self.rev_table.len() / self.n_classes
    }
    /// Whether forward state `q` is in reverse state `r`'s set.
    #[inline]
    pub fn meets(&self, q: u32, r: u32) -> bool {
        self.rev_sets[r as usize * self.rev_words + q as usize / 64] >> (q % 64) & 1 == 1
    }
    /// Whether some path can reach acceptance from the start.
    pub fn can_match(&self) -> bool {
        let mut seen = vec![false; self.states()];
        let mut stack = vec![0u32];
        seen[0] = true;
        while let Some(s) = stack.pop() {
            if self.accept[s as usize] {
                return true;
            }
            for c in 0..self.n_classes {
                let t = self.table[s as usize * self.n_classes + c];
                if !seen[t as usize] {
                    seen[t as usize] = true;
                    stack.push(t);
                }
            }
        }
        false
    }
}

/// Compile a (camera-first) tree whose labels are `labels`.
pub fn compile(ast: &Ast, labels: Vec<String>, src: &str) -> Result<Dfa, LpeError> {
    if labels.len() > MAX_LABELS {
        return Err(LpeError::at(src, 0, format!("more than {MAX_LABELS} distinct labels in one expression")));
    }
    let n_classes = BASE_COUNT << labels.len();
    let mut nfa = Nfa { eps: Vec::new(), edge: Vec::new(), sets: Vec::new(), n_classes, labels };
    let (start, end) = nfa.build(ast, src)?;
    let too_many = || LpeError::at(src, 0, format!("expression too complex: its automaton needs more than {MAX_DFA_STATES} states"));

    // Subset construction.
    let mut seen = vec![false; nfa.eps.len()];
    let mut s0 = vec![start];
    nfa.closure(&mut s0, &mut seen);
    let mut ids: HashMap<Vec<u32>, u32> = HashMap::new();
    let mut subsets = vec![s0.clone()];
    ids.insert(s0, 0);
    let mut table: Vec<u32> = Vec::new();
    let mut i = 0;
    while i < subsets.len() {
        for c in 0..n_classes {
            let mut next: Vec<u32> = subsets[i].iter().filter_map(|&s| nfa.edge[s as usize].filter(|&(set, _)| nfa.has(set, c)).map(|(_, t)| t)).collect();
            next.sort_unstable();
            next.dedup();
            nfa.closure(&mut next, &mut seen);
            let id = match ids.get(&next) {
                Some(&id) => id,
                None => {
                    if subsets.len() >= MAX_DFA_STATES {
                        return Err(too_many());
                    }
                    let id = subsets.len() as u32;
                    ids.insert(next.clone(), id);
                    subsets.push(next);
                    id
                }
            };
            table.push(id);
        }
        i += 1;
    }
    let accept: Vec<bool> = subsets.iter().map(|s| s.binary_search(&end).is_ok()).collect();
    let (table, accept) = minimise(&table, &accept, n_classes);
    let (rev_table, rev_words, rev_sets) = reverse(&table, &accept, n_classes).ok_or_else(too_many)?;
    Ok(Dfa { n_classes, table, accept, rev_table, rev_words, rev_sets, labels: nfa.labels })
}

/// Moore's partition refinement; the start state stays 0.
fn minimise(table: &[u32], accept: &[bool], nc: usize) -> (Vec<u32>, Vec<bool>) {
    let n = accept.len();
    let mut block: Vec<u32> = accept.iter().map(|&a| a as u32).collect();
    let mut count = 0;
    loop {
        let mut sig: HashMap<Vec<u32>, u32> = HashMap::new();
        let mut next = vec![0u32; n];
        for s in 0..n {
            let mut key = Vec::with_capacity(nc + 1);
            key.push(block[s]);
            key.extend(table[s * nc..(s + 1) * nc].iter().map(|&t| block[t as usize]));
            let l = sig.len() as u32;
            next[s] = *sig.entry(key).or_insert(l);
        }
        let c = sig.len();
        block = next;
        if c == count {
            break;
        }
        count = c;
    }
    // Renumber so that the start's block is 0, in order of first appearance.
    let mut order = vec![u32::MAX; count];
    let mut reps = Vec::new();
    let mut queue = vec![0usize];
    order[block[0] as usize] = 0;
    reps.push(0usize);
    while let Some(s) = queue.pop() {
        for c in 0..nc {
            let t = table[s * nc + c] as usize;
            if order[block[t] as usize] == u32::MAX {
                order[block[t] as usize] = reps.len() as u32;
                reps.push(t);
                queue.push(t);
            }
        }
    }
    // Only blocks reachable from the start survive.
    let mut t2 = Vec::with_capacity(reps.len() * nc);
    for &r in &reps {
        t2.extend(table[r * nc..(r + 1) * nc].iter().map(|&t| order[block[t as usize] as usize]));
    }
    let a2 = reps.iter().map(|&r| accept[r]).collect();
    (t2, a2)
}

/// The reverse automaton by subset construction over the minimised forward DFA.
fn reverse(table: &[u32], accept: &[bool], nc: usize) -> Option<(Vec<u32>, usize, Vec<u64>)> {
    let n = accept.len();
    let words = n.div_ceil(64);
    let mut start = vec![0u64; words];
    for (q, _) in accept.iter().enumerate().filter(|(_, &a)| a) {
        start[q / 64] |= 1 << (q % 64);
    }
    let mut ids: HashMap<Vec<u64>, u32> = HashMap::new();
    let mut sets = vec![start.clone()];
    ids.insert(start, 0);
    let mut rev = Vec::new();
    let mut i = 0;
    while i < sets.len() {
        for c in 0..nc {
            let mut next = vec![0u64; words];
            for p in 0..n {
                let t = table[p * nc + c] as usize;
                if sets[i][t / 64] >> (t % 64) & 1 == 1 {
                    next[p / 64] |= 1 << (p % 64);
                }
            }
            let id = match ids.get(&next) {
                Some(&id) => id,
                None => {
                    if sets.len() >= MAX_DFA_STATES {
                        return None;
                    }
                    let id = sets.len() as u32;
                    ids.insert(next.clone(), id);
                    sets.push(next);
                    id
                }
            };
            rev.push(id);
        }
        i += 1;
    }
    Some((rev, words, sets.concat()))
}
