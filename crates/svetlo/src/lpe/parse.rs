//! Light path expressions: tokens and a recursive-descent parser with a depth limit, into an
//! expression tree whose leaves are predicates on vertex events.
//!
//! Grammar (ordinary regular-expression precedence, loosest first):
//! ```text
//! alt    := concat ('|' concat)*
//! concat := repeat+
//! repeat := atom ('*' | '+' | '?' | '{n}' | '{n,}' | '{n,m}')*
//! atom   := symbol | '.' | 'label' | '[' '^'? item+ ']' | '<' field{1,3} '>' | '(' alt ')'
//! ```

use super::LpeError;

/// Deepest nesting of groups, sets and vertex forms accepted: the parser recurses once per level.
pub const MAX_DEPTH: usize = 64;
/// Longest expression accepted, in characters.
pub const MAX_LEN: usize = 4096;
/// Largest bound of a counted repetition.
pub const MAX_COUNT: u32 = 256;

/// One vertex predicate before labels are numbered.
#[derive(Clone, Debug, PartialEq)]
pub enum Atom {
    /// A set of the nine base event classes (see [`super::BASE_CLASSES`]), as a bit mask.
    Base(u16),
    /// A custom label (a shape's id).
    Label(String),
    /// OSL's vertex form: all of its fields hold.
    All(Vec<Atom>),
}

#[derive(Clone, Debug, PartialEq)]
pub enum Ast {
    /// Any atom of the list matches (a set); `negated` takes the complement.
    Leaf {
        atoms: Vec<Atom>,
        negated: bool,
    },
    Concat(Vec<Ast>),
    Alt(Vec<Ast>),
    /// `min..=max` copies (`max` None: unbounded).
    Repeat {
        inner: Box<Ast>,
        min: u32,
        max: Option<u32>,
    },
}

impl Ast {
    /// The same language read backwards (light-first to camera-first).
    pub fn reversed(self) -> Ast {
        match self {
            Ast::Concat(mut v) => {
                v.reverse();
                Ast::Concat(v.into_iter().map(Ast::reversed).collect())
            }
            Ast::Alt(v) => Ast::Alt(v.into_iter().map(Ast::reversed).collect()),
            Ast::Repeat { inner, min, max } => Ast::Repeat { inner: Box::new(inner.reversed()), min, max },
            leaf => leaf,
        }
    }

    /// Every custom label the expression names, in first-appearance order.
    pub fn labels(&self, out: &mut Vec<String>) {
        fn atom(a: &Atom, out: &mut Vec<String>) {
            match a {
                Atom::Label(l) if !out.contains(l) => out.push(l.clone()),
                Atom::All(v) => v.iter().for_each(|a| atom(a, out)),
                _ => {}
            }
        }
        match self {
            Ast::Leaf { atoms, .. } => atoms.iter().for_each(|a| atom(a, out)),
            Ast::Concat(v) | Ast::Alt(v) => v.iter().for_each(|a| a.labels(out)),
            Ast::Repeat { inner, .. } => inner.labels(out),
        }
    }
}

// Base classes: 0 camera, 1 light, 2 background, 3-5 reflection D G S, 6-8 transmission D G S.
pub(crate) const CAMERA: u16 = 1 << 0;
pub(crate) const LIGHT: u16 = 1 << 1;
pub(crate) const BACKGROUND: u16 = 1 << 2;
pub(crate) const DIFFUSE: u16 = (1 << 3) | (1 << 6);
pub(crate) const GLOSSY: u16 = (1 << 4) | (1 << 7);
pub(crate) const SINGULAR: u16 = (1 << 5) | (1 << 8);
pub(crate) const REFLECT: u16 = 0b111 << 3;
pub(crate) const TRANSMIT: u16 = 0b111 << 6;
pub(crate) const ANY: u16 = 0x1ff;

fn symbol(c: char) -> Option<u16> {
    Some(match c {
        'C' | 'E' => CAMERA,
        'L' => LIGHT,
        'B' => BACKGROUND,
        'D' => DIFFUSE,
        'G' => GLOSSY,
        'S' => SINGULAR,
        'R' => REFLECT,
        'T' => TRANSMIT,
        '.' => ANY,
        _ => return None,
    })
}

struct Parser<'a> {
    src: &'a str,
    chars: Vec<char>,
    pos: usize,
    depth: usize,
}

/// Parse an expression into its tree.
pub fn parse(src: &str) -> Result<Ast, LpeError> {
    let chars: Vec<char> = src.chars().collect();
    if chars.len() > MAX_LEN {
        return Err(LpeError::at(src, MAX_LEN, format!("expression longer than {MAX_LEN} characters")));
    }
    let mut p = Parser { src, chars, pos: 0, depth: 0 };
    p.skip_ws();
    if p.pos == p.chars.len() {
        return Err(LpeError::at(src, 0, "empty expression".into()));
    }
    let ast = p.alt()?;
    p.skip_ws();
    if p.pos < p.chars.len() {
        let msg = if p.chars[p.pos] == ')' { "unbalanced ')': no group to close" } else { "unexpected character" };
        return Err(p.err(msg));
    }
    Ok(ast)
}

impl Parser<'_> {
    fn err(&self, msg: &str) -> LpeError {
        LpeError::at(self.src, self.pos, msg.into())
    }
    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }
    fn skip_ws(&mut self) {
        while self.peek().is_some_and(char::is_whitespace) {
            self.pos += 1;
        }
    }
    fn enter(&mut self) -> Result<(), LpeError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(self.err(&format!("nested deeper than {MAX_DEPTH} levels")));
        }
        Ok(())
    }

    fn alt(&mut self) -> Result<Ast, LpeError> {
        self.enter()?;
        let mut arms = vec![self.concat()?];
        loop {
            self.skip_ws();
            if self.peek() != Some('|') {
                break;
            }
            self.pos += 1;
            arms.push(self.concat()?);
        }
        self.depth -= 1;
        Ok(if arms.len() == 1 { arms.pop().expect("one arm") } else { Ast::Alt(arms) })
    }

    fn concat(&mut self) -> Result<Ast, LpeError> {
        let mut items = Vec::new();
        loop {
            self.skip_ws();
            match self.peek() {
                None | Some('|') | Some(')') => break,
                _ => items.push(self.repeat()?),
            }
        }
        match items.len() {
            0 => Err(self.err("expected an event here (an empty alternative or group)")),
            1 => Ok(items.pop().expect("one item")),
            _ => Ok(Ast::Concat(items)),
        }
    }

    fn repeat(&mut self) -> Result<Ast, LpeError> {
        let mut a = self.atom()?;
        loop {
            self.skip_ws();
            let (min, max) = match self.peek() {
                Some('*') => (0, None),
                Some('+') => (1, None),
                Some('?') => (0, Some(1)),
                Some('{') => {
                    let r = self.counted()?;
                    a = Ast::Repeat { inner: Box::new(a), min: r.0, max: r.1 };
                    continue;
                }
                _ => break,
            };
            self.pos += 1;
            a = Ast::Repeat { inner: Box::new(a), min, max };
        }
        Ok(a)
    }

    fn number(&mut self) -> Result<u32, LpeError> {
        self.skip_ws();
        let start = self.pos;
        while self.peek().is_some_and(|c| c.is_ascii_digit()) {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(self.err("expected a number"));
        }
        let s: String = self.chars[start..self.pos].iter().collect();
        match s.parse::<u32>() {
            Ok(n) if n <= MAX_COUNT => Ok(n),
            _ => Err(LpeError::at(self.src, start, format!("repetition count above {MAX_COUNT}"))),
        }
    }

    /// `{n}`, `{n,}` or `{n,m}`, at the `{`.
    fn counted(&mut self) -> Result<(u32, Option<u32>), LpeError> {
        let open = self.pos;
        self.pos += 1;
        let n = self.number()?;
        self.skip_ws();
        let r = match self.peek() {
            Some('}') => (n, Some(n)),
            Some(',') => {
                self.pos += 1;
                self.skip_ws();
                if self.peek() == Some('}') {
                    (n, None)
                } else {
                    let m = self.number()?;
                    if m < n {
                        return Err(LpeError::at(self.src, open, format!("repetition {{{n},{m}}}: the maximum is below the minimum")));
                    }
                    self.skip_ws();
                    (n, Some(m))
                }
            }
            _ => return Err(self.err("expected ',' or '}' in a counted repetition")),
        };
        if self.peek() != Some('}') {
            return Err(self.err("expected '}'"));
        }
        self.pos += 1;
        Ok(r)
    }

    fn label(&mut self) -> Result<String, LpeError> {
        let open = self.pos;
        let q = self.chars[open];
        self.pos += 1;
        let start = self.pos;
        while self.peek().is_some_and(|c| c != q) {
            self.pos += 1;
        }
        if self.peek().is_none() {
            return Err(LpeError::at(self.src, open, "unterminated label: no closing quote".into()));
        }
        let s: String = self.chars[start..self.pos].iter().collect();
        self.pos += 1;
        if s.is_empty() {
            return Err(LpeError::at(self.src, open, "empty label".into()));
        }
        Ok(s)
    }

    fn atom(&mut self) -> Result<Ast, LpeError> {
        self.skip_ws();
        let Some(c) = self.peek() else { return Err(self.err("expected an event")) };
        match c {
            '(' => {
                let open = self.pos;
                self.pos += 1;
                let inner = self.alt()?;
                self.skip_ws();
                if self.peek() != Some(')') {
                    return Err(LpeError::at(self.src, open, "unbalanced '(': this group is never closed".into()));
                }
                self.pos += 1;
                Ok(inner)
            }
            '[' => self.set(),
            '<' => self.vertex_form(),
            '\'' | '"' => Ok(Ast::Leaf { atoms: vec![Atom::Label(self.label()?)], negated: false }),
            '*' | '+' | '?' | '{' => Err(self.err("a repetition must follow an event or a group")),
            _ => match symbol(c) {
                Some(m) => {
                    self.pos += 1;
                    Ok(Ast::Leaf { atoms: vec![Atom::Base(m)], negated: false })
                }
                None => Err(self.err(&format!("unknown event symbol '{c}' (known: C E L B D G S R T . and 'labels')"))),
            },
        }
    }

    fn set(&mut self) -> Result<Ast, LpeError> {
        let open = self.pos;
        self.pos += 1;
        let negated = self.peek() == Some('^');
        if negated {
            self.pos += 1;
        }
        let mut atoms = Vec::new();
        loop {
            self.skip_ws();
            let Some(c) = self.peek() else { return Err(LpeError::at(self.src, open, "unbalanced '[': this set is never closed".into())) };
            match c {
                ']' => break,
                '|' => self.pos += 1, // the lecture writes sets as [D|S]
                '\'' | '"' => atoms.push(Atom::Label(self.label()?)),
                '<' => {
                    self.enter()?;
                    let Ast::Leaf { atoms: a, .. } = self.vertex_form()? else { unreachable!("a vertex form is a leaf") };
                    self.depth -= 1;
                    atoms.extend(a);
                }
                _ => match symbol(c) {
                    Some(m) => {
                        atoms.push(Atom::Base(m));
                        self.pos += 1;
                    }
                    None => return Err(self.err(&format!("unknown event symbol '{c}' in a set"))),
                },
            }
        }
        if atoms.is_empty() {
            return Err(LpeError::at(self.src, open, "empty set".into()));
        }
        self.pos += 1;
        Ok(Ast::Leaf { atoms, negated })
    }

    /// OSL's `<type scattering 'label'>`: type one of C E L B R T `.`, scattering one of D G S
    /// `.`, then an optional label or `.`; missing fields match anything.
    fn vertex_form(&mut self) -> Result<Ast, LpeError> {
        let open = self.pos;
        self.pos += 1;
        let mut fields = Vec::new();
        loop {
            self.skip_ws();
            let at = self.pos;
            let Some(c) = self.peek() else { return Err(LpeError::at(self.src, open, "unbalanced '<': this vertex is never closed".into())) };
            if c == '>' {
                break;
            }
            let field = fields.len();
            if field >= 3 {
                return Err(self.err("a vertex <type scattering 'label'> has at most three fields"));
            }
            let atom = match (field, c) {
                (_, '.') => {
                    self.pos += 1;
                    Atom::Base(ANY)
                }
                (0, 'C' | 'E' | 'L' | 'B' | 'R' | 'T') | (1, 'D' | 'G' | 'S') => {
                    self.pos += 1;
                    Atom::Base(symbol(c).expect("a symbol"))
                }
                (2, '\'' | '"') => Atom::Label(self.label()?),
                (0, _) => return Err(LpeError::at(self.src, at, format!("'{c}' is not an event type (C E L B R T or .)"))),
                (1, _) => return Err(LpeError::at(self.src, at, format!("'{c}' is not a scattering type (D G S or .)"))),
                _ => return Err(LpeError::at(self.src, at, "the third field of a vertex is a quoted label or '.'".into())),
            };
            fields.push(atom);
        }
        self.pos += 1;
        if fields.is_empty() {
            return Err(LpeError::at(self.src, open, "empty vertex <>".into()));
        }
        Ok(Ast::Leaf { atoms: vec![Atom::All(fields)], negated: false })
    }
}
