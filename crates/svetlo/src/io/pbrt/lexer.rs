//! Tokens of pbrt-v4's scene format: bare words (directives, `true`/`false`), numbers,
//! quoted strings, `[` and `]`; `#` starts a comment to the end of the line. Every token
//! carries its line and column so that errors can name them.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, PartialEq)]
pub enum Tok {
    Word(String),
    Num(f64),
    Str(String),
    Open,
    Close,
}

impl Tok {
    /// How the token reads in an error message.
    pub fn describe(&self) -> String {
        match self {
            Tok::Word(w) => format!("'{w}'"),
            Tok::Num(n) => format!("number {n}"),
            Tok::Str(s) => format!("string \"{s}\""),
            Tok::Open => "'['".into(),
            Tok::Close => "']'".into(),
        }
    }
}

/// Where a token starts.
#[derive(Clone, Debug)]
pub struct Loc {
    pub file: std::sync::Arc<PathBuf>,
    pub line: u32,
    pub col: u32,
}

impl Loc {
    pub fn err(&self, msg: impl Into<String>) -> Error {
        Error::SceneAt { file: self.file.as_ref().clone(), line: self.line, col: self.col, msg: msg.into() }
    }
    /// "file:line", for warnings.
    pub fn at(&self) -> String {
        format!("{}:{}", self.file.display(), self.line)
    }
    pub fn dir(&self) -> PathBuf {
        self.file.parent().map(Path::to_path_buf).unwrap_or_default()
    }
}

pub struct Lexer<'t> {
    text: &'t [u8],
    pos: usize,
    line: u32,
    line_start: usize,
    file: std::sync::Arc<PathBuf>,
    peeked: Option<(Tok, Loc)>,
}

impl<'t> Lexer<'t> {
    pub fn new(text: &'t str, file: &Path) -> Self {
        Lexer { text: text.as_bytes(), pos: 0, line: 1, line_start: 0, file: std::sync::Arc::new(file.to_path_buf()), peeked: None }
    }

    pub fn file(&self) -> &Path {
        &self.file
    }

    /// The location of the next character (end of file when there are none).
    pub fn here(&self) -> Loc {
        Loc { file: self.file.clone(), line: self.line, col: (self.pos - self.line_start + 1) as u32 }
    }

    pub fn peek(&mut self) -> Result<Option<&(Tok, Loc)>> {
        if self.peeked.is_none() {
            self.peeked = self.scan()?;
        }
        Ok(self.peeked.as_ref())
    }

    #[allow(clippy::should_implement_trait)] // fallible: Result<Option<..>>, not an Iterator
    pub fn next(&mut self) -> Result<Option<(Tok, Loc)>> {
        match self.peeked.take() {
            Some(t) => Ok(Some(t)),
            None => self.scan(),
        }
    }

    fn skip_space(&mut self) {
        while self.pos < self.text.len() {
            match self.text[self.pos] {
                b'\n' => {
                    self.pos += 1;
                    self.line += 1;
                    self.line_start = self.pos;
                }
                b' ' | b'\t' | b'\r' | 0x0c | 0x0b => self.pos += 1,
                b'#' => {
                    while self.pos < self.text.len() && self.text[self.pos] != b'\n' {
                        self.pos += 1;
                    }
                }
                _ => break,
            }
        }
    }

    fn scan(&mut self) -> Result<Option<(Tok, Loc)>> {
        self.skip_space();
        if self.pos >= self.text.len() {
            return Ok(None);
        }
        let loc = self.here();
        let c = self.text[self.pos];
        let tok = match c {
            b'[' => {
                self.pos += 1;
                Tok::Open
            }
            b']' => {
                self.pos += 1;
                Tok::Close
            }
            b'"' => self.string(&loc)?,
            _ => {
                let start = self.pos;
                while self.pos < self.text.len() && !matches!(self.text[self.pos], b' ' | b'\t' | b'\r' | b'\n' | b'[' | b']' | b'"' | b'#' | 0x0b | 0x0c) {
                    self.pos += 1;
                }
                // Split on byte classes that are ASCII, so the slice is valid UTF-8.
                let word = std::str::from_utf8(&self.text[start..self.pos]).map_err(|_| loc.err("invalid UTF-8 in the scene file"))?;
                if matches!(c, b'0'..=b'9' | b'-' | b'+' | b'.') {
                    let v: f64 = word.parse().map_err(|_| loc.err(format!("'{word}' is not a number")))?;
                    Tok::Num(v)
                } else if c.is_ascii_alphabetic() || c == b'_' {
                    Tok::Word(word.to_string())
                } else {
                    return Err(loc.err(format!("unexpected character '{}'", word.chars().next().unwrap_or('?'))));
                }
            }
        };
        Ok(Some((tok, loc)))
    }

    /// A quoted string with C escapes; it may not span lines (pbrt's rule), which also
    /// makes an unterminated string fail on its own line.
    fn string(&mut self, loc: &Loc) -> Result<Tok> {
        self.pos += 1;
        let mut out: Vec<u8> = Vec::new();
        loop {
            let Some(&c) = self.text.get(self.pos) else { return Err(loc.err("unterminated string")) };
            self.pos += 1;
            match c {
                b'"' => break,
                b'\n' => return Err(loc.err("unterminated string (a string cannot span lines)")),
                b'\\' => {
                    let Some(&e) = self.text.get(self.pos) else { return Err(loc.err("unterminated string")) };
                    self.pos += 1;
                    out.push(match e {
                        b'n' => b'\n',
                        b't' => b'\t',
                        b'r' => b'\r',
                        b'b' => 8,
                        b'f' => 12,
                        b'\\' | b'\'' | b'"' => e,
                        other => return Err(loc.err(format!("unknown escape '\\{}' in a string", other as char))),
                    });
                }
                _ => out.push(c),
            }
        }
        String::from_utf8(out).map(Tok::Str).map_err(|_| loc.err("invalid UTF-8 in a string"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(s: &str) -> Result<Vec<(Tok, u32, u32)>> {
        let mut l = Lexer::new(s, Path::new("t.pbrt"));
        let mut v = Vec::new();
        while let Some((t, loc)) = l.next()? {
            v.push((t, loc.line, loc.col));
        }
        Ok(v)
    }

    #[test]
    fn tokens_with_positions() {
        let v = all("Shape \"sphere\" # comment [\n  \"float radius\" [ -2.5e1 ]\n").unwrap();
        assert_eq!(v[0], (Tok::Word("Shape".into()), 1, 1));
        assert_eq!(v[1], (Tok::Str("sphere".into()), 1, 7));
        assert_eq!(v[2], (Tok::Str("float radius".into()), 2, 3));
        assert_eq!(v[3], (Tok::Open, 2, 18));
        assert_eq!(v[4], (Tok::Num(-25.0), 2, 20));
        assert_eq!(v[5], (Tok::Close, 2, 27));
        assert_eq!(v.len(), 6);
    }

    #[test]
    fn escapes_and_adjacent_brackets() {
        let v = all("[\"a\\\"b\"]1]").unwrap();
        assert_eq!(v.iter().map(|t| t.0.clone()).collect::<Vec<_>>(), vec![Tok::Open, Tok::Str("a\"b".into()), Tok::Close, Tok::Num(1.0), Tok::Close]);
    }

    #[test]
    fn bad_tokens_name_their_line() {
        let e = all("\n\nShape \"sph").unwrap_err().to_string();
        assert!(e.contains("t.pbrt:3:7") && e.contains("unterminated"), "{e}");
        let e = all("a \"x\ny\"").unwrap_err().to_string();
        assert!(e.contains(":1:3") && e.contains("unterminated"), "{e}");
        let e = all("1.2.3").unwrap_err().to_string();
        assert!(e.contains("not a number"), "{e}");
        let e = all("@").unwrap_err().to_string();
        assert!(e.contains("unexpected character"), "{e}");
    }
}
