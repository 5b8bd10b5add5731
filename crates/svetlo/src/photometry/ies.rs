//! IES LM-63 (1986, 1991, 1995, 2002, 2019): keyword header, `TILT=` (NONE, INCLUDE or a
//! file beside the IES file), then whitespace-separated numbers. Header bytes that are not
//! UTF-8 (Latin-1 degree signs) are read lossily.
//!
//! Multipliers: candela × candela multiplier × ballast factor, × the ballast-lamp
//! photometric factor in the versions before 2002 (2002 calls that field "future use",
//! 2019 "file generation type": neither multiplies), × the tilt factor at the installed tilt
//! (0° unless the scene says otherwise). Lumens per lamp = −1 marks absolute photometry.

use super::{err, Format, Opening, PhotometricType, Photometry};
use crate::error::Result;
use crate::photometry::IntensityTable;
use std::path::{Path, PathBuf};

/// Upper bound on angle counts; real files have at most a few hundred.
const MAX_ANGLES: usize = 100_000;
const MAX_VALUES: usize = 10_000_000;

/// Numbers after the `TILT=` line, each with its 1-based line.
struct Numbers<'a> {
    file: &'a Path,
    toks: Vec<(usize, &'a str)>,
    pos: usize,
    last_line: usize,
}

impl<'a> Numbers<'a> {
    fn new(file: &'a Path, lines: &[&'a str], first_line: usize) -> Self {
        let mut toks = vec![];
        for (k, l) in lines.iter().enumerate() {
            for t in l.split(|c: char| c.is_whitespace() || c == ',').filter(|t| !t.is_empty()) {
                toks.push((first_line + k, t));
            }
        }
        let last_line = first_line + lines.len().saturating_sub(1);
        Numbers { file, toks, pos: 0, last_line }
    }

    fn line(&self) -> usize {
        self.toks.get(self.pos).map_or(self.last_line, |t| t.0)
    }

    fn next(&mut self, what: &str) -> Result<f64> {
        let Some(&(line, t)) = self.toks.get(self.pos) else {
            return Err(err(self.file, self.last_line, format!("file ends early: expected {what}")));
        };
        self.pos += 1;
        match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(err(self.file, line, format!("expected a number ({what}), found '{t}'"))),
        }
    }

    fn count(&mut self, what: &str, max: usize) -> Result<usize> {
        let line = self.line();
        let v = self.next(what)?;
        if v.fract() != 0.0 || v < 1.0 || v > max as f64 {
            return Err(err(self.file, line, format!("{what} must be a whole number from 1 to {max}, got {v}")));
        }
        Ok(v as usize)
    }

    fn list(&mut self, n: usize, what: &str) -> Result<Vec<f64>> {
        (0..n).map(|_| self.next(what)).collect()
    }
}

/// Tilt data: multiplying factor by the luminaire's tilt angle (degrees).
#[derive(Clone, Debug)]
pub struct Tilt {
    pub geometry: u32,
    pub angles: Vec<f64>,
    pub factors: Vec<f64>,
}

impl Tilt {
    /// Factor at `angle` degrees, linear between the tabulated angles, clamped at the ends.
    pub fn factor(&self, angle: f64) -> f64 {
        let (a, f) = (&self.angles, &self.factors);
        if angle <= a[0] {
            return f[0];
        }
        for k in 1..a.len() {
            if angle <= a[k] {
                let t = (angle - a[k - 1]) / (a[k] - a[k - 1]);
                return f[k - 1] + t * (f[k] - f[k - 1]);
            }
        }
        f[f.len() - 1]
    }
}

fn read_tilt(n: &mut Numbers) -> Result<Tilt> {
    let line = n.line();
    let geometry = n.next("lamp-to-luminaire geometry")?;
    if !(1.0..=3.0).contains(&geometry) || geometry.fract() != 0.0 {
        return Err(err(n.file, line, format!("lamp-to-luminaire geometry must be 1, 2 or 3, got {geometry}")));
    }
    let count = n.count("number of tilt angles", MAX_ANGLES)?;
    let line = n.line();
    let angles = n.list(count, "tilt angle")?;
    if !angles.windows(2).all(|w| w[1] > w[0]) {
        return Err(err(n.file, line, "tilt angles are not strictly increasing"));
    }
    let line = n.line();
    let factors = n.list(count, "tilt multiplying factor")?;
    if factors.iter().any(|f| *f < 0.0) {
        return Err(err(n.file, line, "negative tilt multiplying factor"));
    }
    Ok(Tilt { geometry: geometry as u32, angles, factors })
}

/// Parse an IES file's bytes (`file` names it in errors and locates a tilt file).
pub fn parse(bytes: &[u8], file: &Path) -> Result<Photometry> {
    parse_with_tilt(bytes, file, 0.0)
}

/// Parse, applying the tilt factor at `tilt_deg` (the luminaire's installed tilt).
pub fn parse_with_tilt(bytes: &[u8], file: &Path, tilt_deg: f64) -> Result<Photometry> {
    let text = String::from_utf8_lossy(bytes);
    let lines: Vec<&str> = text.lines().collect();
    let first = lines.first().map(|l| l.trim()).unwrap_or("");
    let version = if let Some(v) = first.strip_prefix("IESNA:") {
        v.trim().to_string()
    } else if let Some(v) = first.strip_prefix("IES:") {
        v.trim().to_string()
    } else if first.starts_with("IESNA91") {
        "LM-63-1991".into()
    } else if first.starts_with("IESNA95") {
        "LM-63-1995".into()
    } else {
        "LM-63-1986".into()
    };
    let pre_2002 = !(version.contains("2002") || version.contains("2019"));
    let Some(tilt_at) = lines.iter().position(|l| l.trim_start().to_ascii_uppercase().starts_with("TILT")) else {
        return Err(err(file, lines.len().max(1), "no TILT= line: not an IES LM-63 file"));
    };
    let keyword = |k: &str| {
        lines[..tilt_at].iter().find_map(|l| {
            let l = l.trim();
            l.strip_prefix(k).map(|v| v.trim().to_string())
        })
    };
    let label =
        [keyword("[MANUFAC]"), keyword("[LUMCAT]"), keyword("[LUMINAIRE]")].into_iter().flatten().filter(|s| !s.is_empty()).collect::<Vec<_>>().join(", ");
    let tilt_line = lines[tilt_at].trim();
    let tilt_value = tilt_line.split_once('=').map(|(_, v)| v.trim()).unwrap_or("");
    let mut n = Numbers::new(file, &lines[tilt_at + 1..], tilt_at + 2);
    let tilt = match tilt_value.to_ascii_uppercase().as_str() {
        "NONE" => None,
        "INCLUDE" => Some(read_tilt(&mut n)?),
        "" => return Err(err(file, tilt_at + 1, "TILT= names nothing (expected NONE, INCLUDE or a file name)")),
        _ => {
            let tilt_file: PathBuf = file.parent().unwrap_or(Path::new(".")).join(tilt_value);
            let tb = std::fs::read(&tilt_file).map_err(|e| err(file, tilt_at + 1, format!("cannot read tilt file {}: {e}", tilt_file.display())))?;
            let tt = String::from_utf8_lossy(&tb);
            let tl: Vec<&str> = tt.lines().collect();
            let mut tn = Numbers::new(&tilt_file, &tl, 1);
            Some(read_tilt(&mut tn)?)
        }
    };
    let lamps = n.next("number of lamps")?;
    let lm_line = n.line();
    let lumens_per_lamp = n.next("lumens per lamp")?;
    if lumens_per_lamp <= 0.0 && lumens_per_lamp != -1.0 {
        return Err(err(file, lm_line, format!("lumens per lamp must be positive or -1 (absolute photometry), got {lumens_per_lamp}")));
    }
    let multiplier = n.next("candela multiplier")?;
    let nv = n.count("number of vertical angles", MAX_ANGLES)?;
    let nh = n.count("number of horizontal angles", MAX_ANGLES)?;
    if nv * nh > MAX_VALUES {
        return Err(err(file, n.line(), format!("{nv} x {nh} intensities is more than {MAX_VALUES}")));
    }
    let type_line = n.line();
    let kind = match n.next("photometric type")? {
        1.0 => PhotometricType::C,
        2.0 => PhotometricType::B,
        3.0 => PhotometricType::A,
        t => return Err(err(file, type_line, format!("photometric type must be 1 (C), 2 (B) or 3 (A), got {t}"))),
    };
    let units_line = n.line();
    let to_m = match n.next("units type")? {
        1.0 => 0.3048,
        2.0 => 1.0,
        u => return Err(err(file, units_line, format!("units type must be 1 (feet) or 2 (metres), got {u}"))),
    };
    let width = n.next("width")? * to_m;
    let length = n.next("length")? * to_m;
    let height = n.next("height")? * to_m;
    let ballast = n.next("ballast factor")?;
    let second = n.next(if pre_2002 { "ballast-lamp photometric factor" } else { "future use" })?;
    let watts = n.next("input watts")?;
    let vline = n.line();
    let vertical = n.list(nv, "vertical angle")?;
    let hline = n.line();
    let horizontal = n.list(nh, "horizontal angle")?;
    let cline = n.line();
    let mut cd = Vec::with_capacity(nv * nh);
    for _ in 0..nv * nh {
        let line = n.line();
        let v = n.next("candela value")?;
        if v < 0.0 {
            return Err(err(file, line, format!("negative candela value {v}")));
        }
        cd.push(v);
    }
    if !vertical.windows(2).all(|w| w[1] > w[0]) {
        return Err(err(file, vline, "vertical angles are not strictly increasing"));
    }
    if !horizontal.windows(2).all(|w| w[1] > w[0]) {
        return Err(err(file, hline, "horizontal angles are not strictly increasing"));
    }
    let (table, symmetry) = IntensityTable::from_file_angles(kind, &horizontal, &vertical, &cd).map_err(|m| {
        let line = if m.contains("vertical") {
            vline
        } else if m.contains("horizontal") {
            hline
        } else {
            cline
        };
        err(file, line, m)
    })?;
    let mut k = multiplier * ballast;
    if pre_2002 {
        k *= second;
    }
    if let Some(t) = &tilt {
        k *= t.factor(tilt_deg);
    }
    if !(k >= 0.0 && k.is_finite()) {
        return Err(err(file, tilt_at + 2, format!("the multipliers give a negative or invalid scale {k}")));
    }
    let opening = if width == 0.0 && length == 0.0 {
        Opening::Point
    } else if width < 0.0 && length < 0.0 {
        Opening::Disk { diameter: width.abs().max(length.abs()), height: height.abs() }
    } else {
        Opening::Rectangle { length: length.abs(), width: width.abs(), height: height.abs() }
    };
    Ok(Photometry {
        format: Format::Ies { version },
        table: table.scaled(k),
        opening,
        lamp_lumens: (lumens_per_lamp > 0.0).then_some(lamps * lumens_per_lamp),
        input_watts: Some(watts),
        file_angles: (nh, nv),
        symmetry,
        label,
    })
}
