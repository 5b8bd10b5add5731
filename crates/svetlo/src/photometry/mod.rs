//! Photometry: luminaire files (IES LM-63, EULUMDAT) read into one intensity table, and the
//! photometric units at the edges of the renderer.
//!
//! Units (DESIGN.md): inside, radiometric linear Rec.709 RGB; outside, lumens, candela, lux and
//! cd/m², converted by [`LM_PER_W`] = 683 lm/W and the Rec.709 luminance weights
//! (`Rgb::luminance`). A white light of luminance 1 W/sr is 683 cd.
//!
//! The luminaire frame (as Radiance's `ies2rad`): γ = 0 (nadir) along −Z, the C = 0° plane
//! toward +X, C = 90° toward +Y, so that a luminaire with an identity transform hangs
//! pointing down in a Z-up scene. Types A and B use the same aim (0°, 0°) along −Z
//! (see [`table`]).
//!
//! This module's parsers depend only on `math`; the light that uses the table is
//! `light::luminaire`.

pub mod eulumdat;
pub mod false_colour;
pub mod glare;
pub mod ies;
pub mod illuminance;
pub mod sky;
pub mod table;

pub use table::{IntensityTable, PhotometricType};

use crate::error::{Error, Result};
use std::path::Path;

/// Luminous efficacy at 555 nm: lumens per watt of the radiometric quantities.
pub const LM_PER_W: f64 = 683.0;

/// A luminaire's luminous opening in metres (LM-63's width, length, height; EULUMDAT's
/// luminous area). Length runs along C0 (+X), width along C90 (+Y).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Opening {
    Point,
    Rectangle { length: f64, width: f64, height: f64 },
    Disk { diameter: f64, height: f64 },
}

impl Opening {
    /// Area of the emitting face seen from below, m².
    pub fn area(&self) -> f64 {
        match *self {
            Opening::Point => 0.0,
            Opening::Rectangle { length, width, .. } => length * width,
            Opening::Disk { diameter, .. } => std::f64::consts::PI * diameter * diameter / 4.0,
        }
    }
}

/// Which file format a luminaire came from, with the version it declares.
#[derive(Clone, Debug, PartialEq)]
pub enum Format {
    Ies { version: String },
    Eulumdat,
}

/// A luminaire file, read: its distribution in candela (multipliers applied) and what a
/// summary needs.
#[derive(Clone, Debug)]
pub struct Photometry {
    pub format: Format,
    pub table: IntensityTable,
    pub opening: Opening,
    /// Lamp lumens the file states (None for absolute photometry).
    pub lamp_lumens: Option<f64>,
    /// Input power in W, when given.
    pub input_watts: Option<f64>,
    /// Counts of angles as stored in the file (before the symmetry is expanded).
    pub file_angles: (usize, usize),
    /// Description of the stored symmetry.
    pub symmetry: &'static str,
    /// Manufacturer and luminaire name, when given.
    pub label: String,
}

impl Photometry {
    /// Luminous flux integrated from the candela table (lm).
    pub fn flux(&self) -> f64 {
        self.table.flux()
    }

    /// A text summary (what `svetlo info` prints).
    pub fn summary(&self) -> String {
        let fmt = match &self.format {
            Format::Ies { version } => format!("IES LM-63 ({version})"),
            Format::Eulumdat => "EULUMDAT".to_string(),
        };
        let opening = match self.opening {
            Opening::Point => "point".to_string(),
            Opening::Rectangle { length, width, height } => format!("rectangle {length:.3} m (C0) x {width:.3} m (C90), height {height:.3} m"),
            Opening::Disk { diameter, height } => format!("disk, diameter {diameter:.3} m, height {height:.3} m"),
        };
        let mut s = String::new();
        s += &format!("format: {fmt}\n");
        if !self.label.is_empty() {
            s += &format!("luminaire: {}\n", self.label);
        }
        s += &format!("photometric type: {:?}\n", self.table.kind());
        s += &format!("symmetry: {}\n", self.symmetry);
        s += &format!("angles in the file: {} horizontal x {} vertical\n", self.file_angles.0, self.file_angles.1);
        s += &format!("luminous opening: {opening}\n");
        s += &format!("maximum intensity: {:.1} cd\n", self.table.max_intensity());
        s += &format!("luminous flux (integrated): {:.2} lm\n", self.flux());
        match self.lamp_lumens {
            Some(l) if l > 0.0 => s += &format!("lamp lumens: {:.1} lm (light output ratio {:.1} %)\n", l, 100.0 * self.flux() / l),
            _ => s += "lamp lumens: absolute photometry\n",
        }
        if let Some(w) = self.input_watts.filter(|w| *w > 0.0) {
            s += &format!("input power: {w:.2} W ({:.1} lm/W)\n", self.flux() / w);
        }
        s
    }
}

/// Read a luminaire file, choosing the parser by extension (`.ies`, `.ldt`) and falling back
/// to content (an IES file starts with `IESNA` or has a `TILT=` line).
pub fn load(path: &Path) -> Result<Photometry> {
    let bytes = crate::limits::read_file(path)?;
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("ldt") => eulumdat::parse(&bytes, path),
        Some("ies") => ies::parse(&bytes, path),
        _ => {
            let text = String::from_utf8_lossy(&bytes);
            if text.starts_with("IES") || text.lines().any(|l| l.trim_start().starts_with("TILT")) {
                ies::parse(&bytes, path)
            } else {
                eulumdat::parse(&bytes, path)
            }
        }
    }
}

pub(crate) fn err(file: &Path, line: usize, msg: impl Into<String>) -> Error {
    Error::Photometry { file: file.to_path_buf(), line: line as u32, msg: msg.into() }
}
