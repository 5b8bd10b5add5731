//! Typed parameter lists: `"type name" value` or `"type name" [ values ]`. The type decides
//! what the values must be and how many make one item (3 for `point3`, `rgb`, ...). Lookups
//! mark a parameter used, so that the loader can report the ones it ignored.

use super::lexer::{Lexer, Loc, Tok};
use crate::error::Result;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use std::cell::Cell;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamType {
    Integer,
    Float,
    Point2,
    Vector2,
    Point3,
    Vector3,
    Normal,
    Rgb,
    Spectrum,
    Blackbody,
    Bool,
    String,
    Texture,
}

impl ParamType {
    fn parse(s: &str) -> Option<ParamType> {
        Some(match s {
            "integer" => ParamType::Integer,
            "float" => ParamType::Float,
            "point2" => ParamType::Point2,
            "vector2" => ParamType::Vector2,
            "point3" | "point" => ParamType::Point3,
            "vector3" | "vector" => ParamType::Vector3,
            "normal" | "normal3" => ParamType::Normal,
            "rgb" | "color" => ParamType::Rgb,
            "spectrum" => ParamType::Spectrum,
            "blackbody" => ParamType::Blackbody,
            "bool" => ParamType::Bool,
            "string" => ParamType::String,
            "texture" => ParamType::Texture,
            _ => return None,
        })
    }
    pub fn name(self) -> &'static str {
        match self {
            ParamType::Integer => "integer",
            ParamType::Float => "float",
            ParamType::Point2 => "point2",
            ParamType::Vector2 => "vector2",
            ParamType::Point3 => "point3",
            ParamType::Vector3 => "vector3",
            ParamType::Normal => "normal",
            ParamType::Rgb => "rgb",
            ParamType::Spectrum => "spectrum",
            ParamType::Blackbody => "blackbody",
            ParamType::Bool => "bool",
            ParamType::String => "string",
            ParamType::Texture => "texture",
        }
    }
    /// Numbers per item of a numeric type.
    fn arity(self) -> usize {
        match self {
            ParamType::Point2 | ParamType::Vector2 => 2,
            ParamType::Point3 | ParamType::Vector3 | ParamType::Normal | ParamType::Rgb => 3,
            _ => 1,
        }
    }
}

#[derive(Clone, Debug)]
pub enum Values {
    Nums(Vec<f64>),
    Strs(Vec<String>),
    Bools(Vec<bool>),
}

#[derive(Clone, Debug)]
pub struct Param {
    pub ty: ParamType,
    pub name: String,
    pub values: Values,
    pub loc: Loc,
    used: Cell<bool>,
}

/// What a spectrum-valued parameter holds.
#[derive(Clone, Debug)]
pub enum SpectrumValue {
    Rgb(Rgb),
    /// (wavelength nm, value) pairs.
    Sampled(Vec<(f32, f32)>),
    /// A named spectrum (`metal-Ag-eta`, `glass-BK7`, `stdillum-D65`) or a file of pairs.
    Named(String),
    /// A blackbody of this temperature (K), normalised to a peak of 1 as pbrt-v4 does.
    Blackbody(f32),
    /// A constant over wavelength.
    Constant(f32),
}

#[derive(Debug, Default)]
pub struct ParamList {
    pub params: Vec<Param>,
}

impl Param {
    fn type_err(&self, want: &str) -> crate::error::Error {
        self.loc.err(format!("parameter '{}' is \"{} {}\" but {want} was expected", self.name, self.ty.name(), self.name))
    }
    fn nums(&self) -> &[f64] {
        match &self.values {
            Values::Nums(v) => v,
            _ => &[],
        }
    }
    /// The one value of a single-valued parameter.
    fn single_num(&self) -> Result<f64> {
        match self.nums() {
            [v] => Ok(*v),
            v => Err(self.loc.err(format!("parameter '{}' needs one value, got {}", self.name, v.len()))),
        }
    }
}

impl ParamList {
    /// Read `"type name" value` pairs until the next token is not a string.
    pub fn read(lex: &mut Lexer) -> Result<ParamList> {
        let mut params: Vec<Param> = Vec::new();
        while let Some((Tok::Str(_), _)) = lex.peek()? {
            let Some((Tok::Str(decl), loc)) = lex.next()? else { unreachable!("peeked a string") };
            let mut words = decl.split_whitespace();
            let (Some(ty), Some(name), None) = (words.next(), words.next(), words.next()) else {
                return Err(loc.err(format!("expected a parameter declaration \"type name\", got \"{decl}\"")));
            };
            let ty = ParamType::parse(ty).ok_or_else(|| loc.err(format!("unknown parameter type '{ty}' in \"{decl}\"")))?;
            let values = read_values(lex, ty, name, &loc)?;
            if params.iter().any(|p| p.name == name) {
                return Err(loc.err(format!("parameter '{name}' given twice")));
            }
            params.push(Param { ty, name: name.to_string(), values, loc, used: Cell::new(false) });
        }
        Ok(ParamList { params })
    }

    pub fn get(&self, name: &str) -> Option<&Param> {
        let p = self.params.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }

    /// Parameters no lookup asked for, as "file:line: 'name'".
    pub fn unused(&self) -> impl Iterator<Item = &Param> {
        self.params.iter().filter(|p| !p.used.get())
    }

    fn typed(&self, name: &str, tys: &[ParamType], want: &str) -> Result<Option<&Param>> {
        match self.get(name) {
            Some(p) if tys.contains(&p.ty) => Ok(Some(p)),
            Some(p) => Err(p.type_err(want)),
            None => Ok(None),
        }
    }

    pub fn float(&self, name: &str, default: f32) -> Result<f32> {
        Ok(self.opt_float(name)?.unwrap_or(default))
    }
    pub fn opt_float(&self, name: &str) -> Result<Option<f32>> {
        // pbrt accepts an integer where a float is asked (not the reverse).
        match self.typed(name, &[ParamType::Float, ParamType::Integer], "a float")? {
            Some(p) => Ok(Some(p.single_num()? as f32)),
            None => Ok(None),
        }
    }
    pub fn floats(&self, name: &str) -> Result<Option<Vec<f32>>> {
        Ok(self.typed(name, &[ParamType::Float, ParamType::Integer], "floats")?.map(|p| p.nums().iter().map(|&v| v as f32).collect()))
    }
    pub fn int(&self, name: &str, default: i64) -> Result<i64> {
        match self.typed(name, &[ParamType::Integer], "an integer")? {
            Some(p) => Ok(p.single_num()? as i64),
            None => Ok(default),
        }
    }
    pub fn ints(&self, name: &str) -> Result<Option<(&Loc, Vec<i64>)>> {
        Ok(self.typed(name, &[ParamType::Integer], "integers")?.map(|p| (&p.loc, p.nums().iter().map(|&v| v as i64).collect())))
    }
    pub fn bool(&self, name: &str, default: bool) -> Result<bool> {
        match self.typed(name, &[ParamType::Bool], "a bool")? {
            Some(p) => match &p.values {
                Values::Bools(b) if b.len() == 1 => Ok(b[0]),
                _ => Err(p.loc.err(format!("parameter '{name}' needs one bool"))),
            },
            None => Ok(default),
        }
    }
    pub fn string(&self, name: &str) -> Result<Option<&str>> {
        match self.typed(name, &[ParamType::String], "a string")? {
            Some(p) => match &p.values {
                Values::Strs(s) if s.len() == 1 => Ok(Some(&s[0])),
                _ => Err(p.loc.err(format!("parameter '{name}' needs one string"))),
            },
            None => Ok(None),
        }
    }
    pub fn strings(&self, name: &str) -> Result<Option<Vec<String>>> {
        match self.typed(name, &[ParamType::String], "strings")? {
            Some(p) => match &p.values {
                Values::Strs(s) => Ok(Some(s.clone())),
                _ => Ok(Some(Vec::new())),
            },
            None => Ok(None),
        }
    }
    pub fn points3(&self, name: &str) -> Result<Option<Vec<Vec3>>> {
        Ok(self
            .typed(name, &[ParamType::Point3, ParamType::Vector3, ParamType::Normal], "point3 values")?
            .map(|p| p.nums().chunks_exact(3).map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)).collect()))
    }
    pub fn point3(&self, name: &str, default: Vec3) -> Result<Vec3> {
        match self.typed(name, &[ParamType::Point3, ParamType::Vector3, ParamType::Normal], "a point3")? {
            Some(p) => match p.nums() {
                [x, y, z] => Ok(Vec3::new(*x as f32, *y as f32, *z as f32)),
                v => Err(p.loc.err(format!("parameter '{name}' needs one 3-vector, got {} numbers", v.len()))),
            },
            None => Ok(default),
        }
    }
    pub fn points2(&self, name: &str) -> Result<Option<Vec<Vec2>>> {
        Ok(self
            .typed(name, &[ParamType::Point2, ParamType::Vector2, ParamType::Float], "point2 values")?
            .map(|p| p.nums().chunks_exact(2).map(|c| Vec2::new(c[0] as f32, c[1] as f32)).collect()))
    }
    /// A texture reference (`"texture name"`).
    pub fn texture_ref(&self, name: &str) -> Option<(&str, &Loc)> {
        let p = self.params.iter().find(|p| p.name == name && p.ty == ParamType::Texture)?;
        p.used.set(true);
        match &p.values {
            Values::Strs(s) if s.len() == 1 => Some((&s[0], &p.loc)),
            _ => None,
        }
    }
    /// A spectrum-like parameter: `rgb`, `spectrum` (pairs, a name or a file), `blackbody`, or a float.
    pub fn spectrum(&self, name: &str) -> Result<Option<(SpectrumValue, &Loc)>> {
        let Some(p) = self.get(name) else { return Ok(None) };
        let v = match (p.ty, &p.values) {
            (ParamType::Rgb, Values::Nums(v)) if v.len() == 3 => SpectrumValue::Rgb(Rgb::new(v[0] as f32, v[1] as f32, v[2] as f32)),
            (ParamType::Blackbody, Values::Nums(v)) if !v.is_empty() => SpectrumValue::Blackbody(v[0] as f32),
            (ParamType::Float, Values::Nums(v)) if v.len() == 1 => SpectrumValue::Constant(v[0] as f32),
            (ParamType::Spectrum, Values::Nums(v)) if v.len() >= 2 && v.len() % 2 == 0 => {
                SpectrumValue::Sampled(v.chunks_exact(2).map(|c| (c[0] as f32, c[1] as f32)).collect())
            }
            (ParamType::Spectrum, Values::Strs(s)) if s.len() == 1 => SpectrumValue::Named(s[0].clone()),
            (ParamType::Texture, _) => return Ok(None),
            (ParamType::Rgb | ParamType::Blackbody | ParamType::Spectrum | ParamType::Float, _) => {
                return Err(p.loc.err(format!("parameter '{name}': wrong number of values for \"{} {name}\"", p.ty.name())))
            }
            _ => return Err(p.type_err("a spectrum (rgb, spectrum, blackbody or float)")),
        };
        Ok(Some((v, &p.loc)))
    }
}

fn read_values(lex: &mut Lexer, ty: ParamType, name: &str, decl: &Loc) -> Result<Values> {
    let bracketed = matches!(lex.peek()?, Some((Tok::Open, _)));
    if bracketed {
        lex.next()?;
    }
    let mut nums = Vec::new();
    let mut strs = Vec::new();
    let mut bools = Vec::new();
    loop {
        let Some((tok, loc)) = lex.next()? else {
            return Err(decl.err(format!("parameter '{name}': end of file inside its value list")));
        };
        match tok {
            Tok::Close if bracketed => break,
            Tok::Num(v) => nums.push((v, loc)),
            Tok::Str(s) => strs.push((s, loc)),
            Tok::Word(w) if w == "true" || w == "false" => bools.push(w == "true"),
            other => {
                return Err(loc.err(format!("parameter '{name}': unexpected {} in its values", other.describe())));
            }
        }
        if !bracketed {
            break;
        }
    }
    let mixed = usize::from(!nums.is_empty()) + usize::from(!strs.is_empty()) + usize::from(!bools.is_empty()) > 1;
    if mixed {
        return Err(decl.err(format!("parameter '{name}': numbers, strings and bools mixed in one list")));
    }
    match ty {
        ParamType::Bool => {
            // pbrt writes bools as "true" or as bare true.
            for (s, loc) in strs {
                match s.as_str() {
                    "true" => bools.push(true),
                    "false" => bools.push(false),
                    _ => return Err(loc.err(format!("parameter '{name}': \"{s}\" is not a bool (true or false)"))),
                }
            }
            if !nums.is_empty() {
                return Err(decl.err(format!("parameter '{name}' is a bool, not a number")));
            }
            Ok(Values::Bools(bools))
        }
        ParamType::String | ParamType::Texture => {
            if !nums.is_empty() || !bools.is_empty() {
                return Err(decl.err(format!("parameter '{name}' is a {} and needs quoted strings", ty.name())));
            }
            Ok(Values::Strs(strs.into_iter().map(|s| s.0).collect()))
        }
        ParamType::Spectrum if !strs.is_empty() => Ok(Values::Strs(strs.into_iter().map(|s| s.0).collect())),
        _ => {
            if !strs.is_empty() || !bools.is_empty() {
                return Err(decl.err(format!("parameter '{name}' is \"{}\" and needs numbers", ty.name())));
            }
            if ty == ParamType::Integer {
                if let Some((v, loc)) = nums.iter().find(|(v, _)| v.fract() != 0.0 || v.abs() > 9.0e15) {
                    return Err(loc.err(format!("parameter '{name}': {v} is not an integer")));
                }
            }
            if nums.len() % ty.arity() != 0 {
                return Err(decl.err(format!("parameter '{name}': {} values are not a whole number of {}s ({} each)", nums.len(), ty.name(), ty.arity())));
            }
            Ok(Values::Nums(nums.into_iter().map(|n| n.0).collect()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn params(s: &str) -> Result<ParamList> {
        ParamList::read(&mut Lexer::new(s, Path::new("p.pbrt")))
    }

    #[test]
    fn typed_values() {
        let p =
            params(r#""float r" 2 "integer n" [1 2 3] "rgb c" [0.1 0.2 0.3] "bool b" "true" "bool d" false "string s" "x" "point3 P" [0 0 0 1 1 1]"#).unwrap();
        assert_eq!(p.float("r", 0.0).unwrap(), 2.0);
        assert_eq!(p.ints("n").unwrap().unwrap().1, vec![1, 2, 3]);
        assert!(p.bool("b", false).unwrap() && !p.bool("d", true).unwrap());
        assert_eq!(p.string("s").unwrap(), Some("x"));
        assert_eq!(p.points3("P").unwrap().unwrap().len(), 2);
        assert!(matches!(p.spectrum("c").unwrap(), Some((SpectrumValue::Rgb(_), _))));
        assert_eq!(p.unused().count(), 0);
    }

    #[test]
    fn wrong_type_or_count_is_an_error_with_its_line() {
        let e = params("\n\"point3 P\" [0 1]").unwrap_err().to_string();
        assert!(e.contains("p.pbrt:2:1") && e.contains("whole number"), "{e}");
        let e = params(r#""integer n" [1.5]"#).unwrap_err().to_string();
        assert!(e.contains("not an integer"), "{e}");
        let e = params(r#""float x" "a""#).unwrap_err().to_string();
        assert!(e.contains("needs numbers"), "{e}");
        let e = params(r#""floot x" 1"#).unwrap_err().to_string();
        assert!(e.contains("unknown parameter type"), "{e}");
        let e = params(r#""float x" [1 2"#).unwrap_err().to_string();
        assert!(e.contains("end of file"), "{e}");
        let p = params(r#""string x" "a""#).unwrap();
        assert!(p.float("x", 0.0).unwrap_err().to_string().contains("expected"));
        let p = params(r#""float x" [1 2]"#).unwrap();
        assert!(p.float("x", 0.0).unwrap_err().to_string().contains("one value"));
    }
}
