//! EULUMDAT (`.ldt`): one value per line in a fixed order. Intensities are in cd per
//! 1000 lm of lamp flux (the first lamp set's), times the file's conversion factor; a
//! negative number of lamps marks absolute photometry (intensities in cd), as some
//! writers do. Symmetry codes: 0 none (C0 … C360−Dc), 1 about the vertical axis (one plane),
//! 2 about the C0–C180 plane (C0–C180), 3 about C90–C270 (C90–C270), 4 both (C0–C90).

use super::{err, Format, Opening, PhotometricType, Photometry};
use crate::error::Result;
use crate::photometry::IntensityTable;
use std::path::Path;

const MAX_PLANES: usize = 100_000;

struct Lines<'a> {
    file: &'a Path,
    lines: Vec<&'a str>,
    pos: usize,
}

impl<'a> Lines<'a> {
    fn text(&mut self, what: &str) -> Result<&'a str> {
        let Some(l) = self.lines.get(self.pos) else {
            return Err(err(self.file, self.lines.len(), format!("file ends early: expected {what} on line {}", self.pos + 1)));
        };
        self.pos += 1;
        Ok(l.trim())
    }

    fn num(&mut self, what: &str) -> Result<f64> {
        let t = self.text(what)?;
        // Some writers use a decimal comma.
        let s = t.replace(',', ".");
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(err(self.file, self.pos, format!("expected a number ({what}), found '{t}'"))),
        }
    }

    fn int(&mut self, what: &str, lo: i64, hi: i64) -> Result<i64> {
        let v = self.num(what)?;
        if v.fract() != 0.0 || v < lo as f64 || v > hi as f64 {
            return Err(err(self.file, self.pos, format!("{what} must be a whole number from {lo} to {hi}, got {v}")));
        }
        Ok(v as i64)
    }
}

pub fn parse(bytes: &[u8], file: &Path) -> Result<Photometry> {
    let text = String::from_utf8_lossy(bytes);
    let mut l = Lines { file, lines: text.lines().collect(), pos: 0 };
    let company = l.text("company")?.to_string();
    let _ityp = l.int("type indicator Ityp", 0, 3)?;
    let isym_line = l.pos + 1;
    let isym = l.num("symmetry indicator Isym")?;
    if !(0.0..=4.0).contains(&isym) || isym.fract() != 0.0 {
        return Err(err(file, isym_line, format!("unknown symmetry indicator Isym {isym} (expected 0 to 4)")));
    }
    let isym = isym as usize;
    let mc = l.int("number of C-planes Mc", 0, MAX_PLANES as i64)? as usize;
    let dc = l.num("distance between C-planes Dc")?;
    let ng = l.int("number of intensities per C-plane Ng", 1, MAX_PLANES as i64)? as usize;
    let _dg = l.num("distance between intensities Dg")?;
    let _report = l.text("measurement report number")?;
    let name = l.text("luminaire name")?.to_string();
    let _number = l.text("luminaire number")?;
    let _fname = l.text("file name")?;
    let _date = l.text("date/user")?;
    let _dims = (l.num("length or diameter of luminaire")?, l.num("width of luminaire")?, l.num("height of luminaire")?);
    let la = l.num("length or diameter of luminous area")? / 1000.0;
    let wa = l.num("width of luminous area")? / 1000.0;
    let mut h = 0.0f64;
    for what in ["height of luminous area C0", "C90", "C180", "C270"] {
        h = h.max(l.num(what)? / 1000.0);
    }
    let _dff = l.num("downward flux fraction")?;
    let _lor = l.num("light output ratio")?;
    let conv = l.num("conversion factor for luminous intensities")?;
    if conv <= 0.0 {
        return Err(err(file, l.pos, format!("conversion factor must be positive, got {conv}")));
    }
    let _tilt = l.num("tilt of luminaire during measurement")?;
    let sets = l.int("number of standard sets of lamps", 1, 1000)? as usize;
    let mut first_set = None;
    let mut watts_total = 0.0;
    for s in 0..sets {
        let lamps = l.num("number of lamps")?;
        let _kind = l.text("type of lamps")?;
        let flux_line = l.pos + 1;
        let flux = l.num("total luminous flux of lamps")?;
        let _cct = l.text("colour temperature")?;
        let _cri = l.text("colour rendering index")?;
        let watts = l.num("wattage including ballast")?;
        if s == 0 {
            first_set = Some((lamps, flux, flux_line));
            watts_total = watts;
        }
    }
    for _ in 0..10 {
        l.num("direct ratio")?;
    }
    if isym != 1 && (mc == 0 || (isym >= 3 && !mc.is_multiple_of(4)) || (isym == 2 && !mc.is_multiple_of(2))) {
        return Err(err(file, 4, format!("number of C-planes Mc = {mc} does not suit symmetry {isym}")));
    }
    let c_line = l.pos + 1;
    let c_all: Vec<f64> = (0..mc).map(|_| l.num("C-plane angle")).collect::<Result<_>>()?;
    let g_line = l.pos + 1;
    let gamma: Vec<f64> = (0..ng).map(|_| l.num("gamma angle")).collect::<Result<_>>()?;
    if !c_all.windows(2).all(|w| w[1] > w[0]) {
        return Err(err(file, c_line, "C-plane angles are not strictly increasing"));
    }
    if !gamma.windows(2).all(|w| w[1] > w[0]) {
        return Err(err(file, g_line, "gamma angles are not strictly increasing"));
    }
    // The planes stored for each symmetry (indices into the Mc planes).
    let (i0, count) = match isym {
        0 => (0, mc),
        1 => (0, 1),
        2 => (0, mc / 2 + 1),
        3 => (mc / 4, mc / 2 + 1),
        _ => (0, mc / 4 + 1),
    };
    let planes: Vec<f64> = if isym == 1 { vec![0.0] } else { (i0..i0 + count).map(|i| c_all.get(i).copied().unwrap_or(i as f64 * dc)).collect() };
    let (lamps, lamp_flux, flux_line) = first_set.unwrap_or((1.0, 1000.0, 0));
    let absolute = lamps < 0.0;
    if !absolute && lamp_flux <= 0.0 {
        return Err(err(file, flux_line, format!("lamp flux must be positive, got {lamp_flux}")));
    }
    let mut cd = Vec::with_capacity(count * ng);
    for _ in 0..count * ng {
        let v = l.num("luminous intensity")?;
        if v < 0.0 {
            return Err(err(file, l.pos, format!("negative luminous intensity {v}")));
        }
        cd.push(v);
    }
    let scale = conv * if absolute { 1.0 } else { lamp_flux / 1000.0 };
    let (table, symmetry) = IntensityTable::from_file_angles(PhotometricType::C, &planes, &gamma, &cd).map_err(|m| {
        let line = if m.contains("vertical") { g_line } else { c_line };
        err(file, line, m)
    })?;
    let symmetry = match isym {
        0 => "none (Isym 0)",
        1 => "about the vertical axis (Isym 1)",
        2 => "about the C0-C180 plane (Isym 2)",
        3 => "about the C90-C270 plane (Isym 3)",
        _ => {
            let _ = symmetry;
            "about C0-C180 and C90-C270 (Isym 4)"
        }
    };
    let opening = if la == 0.0 {
        Opening::Point
    } else if wa == 0.0 {
        Opening::Disk { diameter: la, height: h }
    } else {
        Opening::Rectangle { length: la, width: wa, height: h }
    };
    Ok(Photometry {
        format: Format::Eulumdat,
        table: table.scaled(scale),
        opening,
        lamp_lumens: (!absolute).then_some(lamp_flux),
        input_watts: Some(watts_total),
        file_angles: (count, ng),
        symmetry,
        label: [company, name].into_iter().filter(|s| !s.is_empty()).collect::<Vec<_>>().join(", "),
    })
}
