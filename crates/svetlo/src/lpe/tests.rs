//! The conformance table: (expression, labelled path, expected match), and bad input.

use super::*;

fn path(s: &str) -> Vec<Event> {
    s.split_whitespace().map(|t| Event::parse_token(t).unwrap_or_else(|| panic!("bad token {t}"))).collect()
}

/// Paths are written camera first; `@n` gives a vertex the label bits n, in the order the
/// expression first names its labels.
const TABLE: &[(&str, &str, bool)] = &[
    // Symbols and concatenation, camera first (OSL).
    ("C D L", "C D L", true),
    ("C D L", "C D D L", false),
    ("C D L", "C G L", false),
    ("C L", "C L", true),
    ("C B", "C B", true),
    ("C B", "C L", false),
    ("E D L", "C D L", true),
    ("CDL", "C D L", true),
    ("C G L", "C TG L", true),
    ("C R L", "C G L", true),
    ("C R L", "C TG L", false),
    ("C T L", "C TS L", true),
    ("C S L", "C TS L", true),
    ("C S L", "C G L", false),
    // Light first (the lecture's and Heckbert's order), reversed internally.
    ("L D E", "C D L", true),
    ("L D* E", "C D D D L", true),
    ("L D* E", "C S D L", false),
    ("L (D|S)* E", "C S D S L", true),
    ("L (D|S)* E", "C G L", false),
    ("L D S E", "C S D L", true),
    ("L D S E", "C D S L", false),
    ("B D E", "C D B", true),
    // Wildcards, repetition, optional.
    ("C .* L", "C L", true),
    ("C .* L", "C D G TS D L", true),
    ("C . .+ L", "C D L", false),
    ("C . .+ L", "C D G L", true),
    ("C D+ L", "C L", false),
    ("C D? L", "C L", true),
    ("C D? L", "C D D L", false),
    // Counted repetition.
    ("C .{2} L", "C D D L", true),
    ("C .{2} L", "C D L", false),
    ("C .{2} L", "C D D D L", false),
    ("C D{2,} L", "C D D D D L", true),
    ("C D{2,} L", "C D L", false),
    ("C D{1,2} L", "C D D L", true),
    ("C D{1,2} L", "C D D D L", false),
    ("C D{0} L", "C L", true),
    ("C (D G){2} L", "C D G D G L", true),
    ("C (D G){2} L", "C D G G D L", false),
    // Sets and negated sets.
    ("C [DG] L", "C G L", true),
    ("C [DG] L", "C S L", false),
    ("C [D|S]* L", "C S D L", true),
    ("C [^D] L", "C G L", true),
    ("C [^D] L", "C TD L", false),
    ("C [^D]* L", "C S G S L", true),
    ("C [^LB]+ [LB]", "C D B", true),
    ("C [^LB]+ [LB]", "C L", false),
    // Precedence: '|' is ordinary regular-expression alternation (loosest), not OSL's
    // neighbours-only binding: `C D|G L` is `(C D)|(G L)`.
    ("C D|G L", "C D L", false),
    ("C D|G L", "G L", true),
    ("C D|G L", "C D", true),
    ("C (D|G) L", "C D L", true),
    ("C D G* L", "C D G G L", true),
    ("C (D G)* L", "C D G D G L", true),
    ("C (D G)* L", "C D G G L", false),
    ("C D+|S+ L", "S S L", true),
    // Custom labels (bit 1 = the first label the expression names).
    ("C 'glass' L", "C TS@1 L", true),
    ("C 'glass' L", "C TS L", false),
    ("C 'glass'+ D L", "C TS@1 RS@1 D L", true),
    ("C [^'glass'] L", "C D L", true),
    ("C [^'glass'] L", "C D@1 L", false),
    ("C .* 'lamp'", "C D L@1", true),
    ("C .* 'lamp'", "C D L", false),
    ("C 'a' 'b' L", "C D@1 D@2 L", true),
    ("C 'a' 'b' L", "C D@2 D@1 L", false),
    // OSL's vertex form <type scattering 'label'>.
    ("C <R.> L", "C D L", true),
    ("C <R.> L", "C TD L", false),
    ("C <T S> L", "C TS L", true),
    ("C <T S> L", "C RS L", false),
    ("C <.D> L", "C TD L", true),
    ("C <..'glass'> L", "C TS@1 L", true),
    ("C <..'glass'> L", "C TS L", false),
    ("C <TS'glass'>+ <R D> L", "C TS@1 TS@1 D L", true),
    ("C <L>", "C L", true),
    ("C D <L.'lamp'>", "C D L@1", true),
    ("C [<TS>G] L", "C G L", true),
    ("C [<TS>G] L", "C RS L", false),
    // Whitted's class with point lights: S* then at most one local-model vertex.
    ("L [DG]? S* E", "C S S D L", true),
    ("L [DG]? S* E", "C D S L", false),
];

#[test]
fn conformance_table() {
    assert!(TABLE.len() >= 40);
    let mut failures = Vec::new();
    for &(expr, p, want) in TABLE {
        let lpe = Lpe::new(expr).unwrap_or_else(|e| panic!("{expr}: {e}"));
        let events = path(p);
        if lpe.matches(&events) != want {
            failures.push(format!("'{expr}' on '{p}': expected {want}"));
        }
        // The reverse automaton, reading from the light, agrees.
        if lpe.matches_from_light(&events) != want {
            failures.push(format!("'{expr}' on '{p}' read from the light: expected {want}"));
        }
        // Splitting the path anywhere and meeting the two halves agrees too.
        for k in 0..=events.len() {
            let q = events[..k].iter().fold(Lpe::START, |s, &e| lpe.step(s, e));
            let r = events[k..].iter().rev().fold(Lpe::START, |s, &e| lpe.rev_step(s, e));
            if lpe.meets(q, r) != want {
                failures.push(format!("'{expr}' on '{p}' split at {k}: expected {want}"));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn light_first_is_detected_and_reversed() {
    assert!(Lpe::new("L D* E").unwrap().light_first);
    assert!(Lpe::new("B D E").unwrap().light_first);
    assert!(!Lpe::new("C D* L").unwrap().light_first);
    assert!(!Lpe::new("C .* L").unwrap().light_first);
    // Both notations of one class compile to the same minimal automaton size.
    assert_eq!(Lpe::new("L (D|S)* E").unwrap().size().0, Lpe::new("C [DS]* L").unwrap().size().0);
}

#[test]
fn minimisation_merges_equivalent_states() {
    // (D|D D)* D* is D*: two states (reading, dead).
    assert_eq!(Lpe::new("C (D|D D)* D* L").unwrap().size().0, Lpe::new("C D* L").unwrap().size().0);
}

fn err(expr: &str) -> LpeError {
    match Lpe::new(expr) {
        Ok(_) => panic!("'{expr}' should not compile"),
        Err(e) => e,
    }
}

#[test]
fn bad_input_has_a_caret_under_the_column() {
    let e = err("C (D L");
    assert_eq!(e.col, 2, "{e}");
    assert!(e.to_string().contains("C (D L\n    ^"), "{e}");
    assert_eq!(err("C D) L").col, 3);
    assert_eq!(err("C [] L").col, 2);
    assert_eq!(err("C [^] L").col, 2);
    let e = err("C X L");
    assert_eq!(e.col, 2);
    assert!(e.msg.contains("unknown event symbol 'X'"), "{e}");
    assert_eq!(err("C 'glass L").col, 2);
    assert_eq!(err("C (*) L").col, 3);
    assert_eq!(err("C D{3,1} L").col, 3);
    assert_eq!(err("C D{x} L").col, 4);
    assert_eq!(err("C <Q> L").col, 3);
    assert_eq!(err("C <R D 'a' 'b'> L").col, 11);
    assert_eq!(err("C D||L").col, 4);
    assert_eq!(err("").col, 0);
    assert_eq!(err("C D{999} L").col, 4);
}

#[test]
fn deep_nesting_and_large_expressions_are_refused_not_overflowed() {
    let deep = format!("C {}D{} L", "(".repeat(100_000), ")".repeat(100_000));
    assert!(err(&deep).msg.contains("longer than"));
    let deep = format!("C {}D{} L", "(".repeat(2000), ")".repeat(2000));
    assert!(err(&deep).msg.contains("nested deeper"));
    let deep = format!("C {}D{} L", "[".repeat(2000), "]".repeat(2000));
    assert!(Lpe::new(&deep).is_err());
    // Counted repetitions that multiply past the NFA limit.
    assert!(err("C ((.{256}){256}){256} L").msg.contains("too large"));
    // The classic exponential DFA: (D|G)* D (D|G){12} needs 2^13 states.
    assert!(err("C (D|G)* D (D|G){12} L").msg.contains("too complex"));
    // One below the limits compiles.
    assert!(Lpe::new("C (D|G)* D (D|G){8} L").is_ok());
}

#[test]
fn an_expression_that_matches_nothing_is_reported() {
    assert!(!Lpe::new("C [^.] L").unwrap().can_match());
    assert!(Lpe::new("C D L").unwrap().can_match());
    assert_eq!(Lpe::new("C D L").unwrap().useful_symbols(), vec!["C", "L", "D", "TD"]);
}

/// The preset's `rest` is exactly the paths in none of the lecture's classes: every path of
/// up to six scattering events (D, G, S, reflection or transmission), to a light or the sky.
#[test]
fn lecture_rest_is_the_complement_of_the_classes() {
    let l: Vec<Lpe> = LECTURE_PRESET.iter().map(|(_, e)| Lpe::new(e).unwrap()).collect();
    let (classes, rest) = l.split_at(4);
    let scatter = ["D", "G", "S", "TD", "TG", "TS"];
    for n in 0..=5u32 {
        for code in 0..6usize.pow(n) {
            let mut p = vec![Event::CAMERA];
            let mut c = code;
            for _ in 0..n {
                p.push(Event::parse_token(scatter[c % 6]).unwrap());
                c /= 6;
            }
            for end in [Event::LIGHT, Event::BACKGROUND] {
                let mut q = p.clone();
                q.push(end);
                let any = classes.iter().any(|x| x.matches(&q));
                assert_eq!(rest[0].matches(&q), !any, "{:?}", q.iter().map(|e| e.symbol()).collect::<Vec<_>>());
            }
        }
    }
}

/// Nested repetitions (a fuzzer's find: `T.+*+++++++++++++` took over 10 s) compile to a small
/// automaton: `X+` is one copy of X with a loop, so nesting does not double it per level.
#[test]
fn nested_repetitions_stay_small() {
    let deep = format!("C D{} L", "+".repeat(40));
    let l = Lpe::new(&deep).expect("40 nested '+' compile");
    assert_eq!(l.size().0, Lpe::new("C D+ L").unwrap().size().0);
    let mixed = format!("C (D{})+ L", "+*?".repeat(12));
    assert_eq!(Lpe::new(&mixed).expect("mixed nesting compiles").size().0, Lpe::new("C D* L").unwrap().size().0);
}

#[test]
fn layer_sample_clear_leaves_every_layer_black() {
    use crate::lpe::aov::LayerSample;
    use crate::spectrum::Rgb;
    let mut s = LayerSample::default();
    s.add(0b1010 | crate::lpe::aov::BEAUTY, Rgb::new(1.0, 2.0, 3.0));
    s.add(0b0100, Rgb::new(0.5, 0.5, 0.5));
    assert_eq!(s.touched, 0b1110);
    // Scaling by a non-finite factor must not reach the untouched layers (a later sample
    // reusing the struct would inherit NaN there).
    s.scale(f32::INFINITY);
    assert!(s.aov[0] == Rgb::BLACK && s.aov[4] == Rgb::BLACK);
    assert!(s.aov[1].r.is_infinite() && s.aov[2].r.is_infinite());
    s.clear();
    assert_eq!(s.touched, 0);
    assert_eq!(s.beauty, Rgb::BLACK);
    assert!(s.aov.iter().all(|a| *a == Rgb::BLACK), "{:?}", s.aov);
}
