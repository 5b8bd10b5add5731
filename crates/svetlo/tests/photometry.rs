//! Luminaire files: the flux integrated from real manufacturers' files against the
//! reference lumens of an independent program (Photometric Toolbox, listed in
//! `../shared/photometry/README.md`), small files of our own whose flux follows in closed
//! form (EULUMDAT of every symmetry code, IES types A and B, every tilt form, every header
//! version), and bad input (typed errors naming the file and line).

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use svetlo::photometry::{self, ies, Opening, PhotometricType};
use svetlo::Error;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/photometry").join(name)
}

fn shared_photometry() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/photometry/ies");
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("SKIPPED: {} not found (the shared folder must sit beside the repository)", p.display());
        None
    }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn shared_files_integrate_to_their_reference_lumens() {
    let Some(dir) = shared_photometry() else { return };
    for (file, lm) in [("rab_1.ies", 9217.18), ("rab_3.ies", 13359.57), ("rab_5.ies", 753.8), ("rab_7.ies", 531.98)] {
        let p = photometry::load(&dir.join(file)).unwrap();
        let e = rel(p.flux(), lm);
        eprintln!("{file}: {:.2} lm against {lm} ({:+.3} %)", p.flux(), 100.0 * (p.flux() - lm) / lm);
        assert!(e < 0.002, "{file}: {} lm, reference {lm}", p.flux());
        assert!(p.summary().contains("luminous flux"));
    }
    // Radiance's example: two 2900 lm lamps; a luminaire gives out less than its lamps, and
    // this one (a direct-indirect pendant) a plausible fraction of them.
    let p = photometry::load(&dir.join("radiance_examp1.ies")).unwrap();
    let lor = p.flux() / 5800.0;
    eprintln!("radiance_examp1.ies: {:.1} lm, light output ratio {:.3}", p.flux(), lor);
    assert!(lor > 0.5 && lor < 1.0, "{lor}");
    assert_eq!(p.lamp_lumens, Some(5800.0));
    match p.opening {
        Opening::Rectangle { length, width, height } => {
            assert!((width - 0.85 * 0.3048).abs() < 1e-9 && (length - 4.04 * 0.3048).abs() < 1e-9 && (height - 0.292 * 0.3048).abs() < 1e-9)
        }
        o => panic!("{o:?}"),
    }
}

#[test]
fn eulumdat_symmetries_integrate_in_closed_form() {
    // Intensities constant along γ within each C-plane and linear between planes (the
    // interpolation svetlo uses), so Φ = (mean over C of I) × solid angle of the γ range,
    // with the mean by the trapezoid rule over the expanded planes (exact for linear).
    let cases: [(&str, f64); 6] = [
        // Isym 1: 100 cd/klm × 2000 lm over the sphere.
        ("isotropic_sym1.ldt", 200.0 * 4.0 * PI),
        // Isym 4: C0 100, C90 300 (mirrored to 180, 270), γ 0-90: mean 200 over 2π sr.
        ("quadrant_sym4.ldt", 200.0 * 2.0 * PI),
        // Isym 2: planes C0..C180 by 45° of 50, 100, …, 250 cd/klm × 1.5 klm, mirrored:
        // mean (25 + 100 + 150 + 200 + 125)/4 = 150 → × 1.5.
        ("bilateral_sym2.ldt", 150.0 * 1.5 * 4.0 * PI),
        // Isym 3: planes C90..C270 of 40..200 × 1.2 klm, mirrored about C90-C270: the same
        // trapezoid over a half period: (20 + 80 + 120 + 160 + 100)/4 = 120.
        ("bilateral_sym3.ldt", 120.0 * 1.2 * 4.0 * PI),
        // Isym 0: C0..C270 of 10, 20, 30, 40, closed at C360 by C0: mean 25, × 3 klm × 1.5.
        ("asymmetric_sym0.ldt", 25.0 * 3.0 * 1.5 * 4.0 * PI),
        // Absolute photometry (negative lamp count): 500 cd over γ 0-90.
        ("absolute_sym1.ldt", 500.0 * 2.0 * PI),
    ];
    for (f, want) in cases {
        let p = photometry::load(&data(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(rel(p.flux(), want) < 1e-9, "{f}: {} against {want}", p.flux());
        assert_eq!(p.format, photometry::Format::Eulumdat);
    }
    let p = photometry::load(&data("quadrant_sym4.ldt")).unwrap();
    assert!((p.table.eval_angles(270.0, 45.0) - 300.0).abs() < 1e-6);
    assert!((p.table.eval_angles(135.0, 45.0) - 200.0).abs() < 1e-6);
    assert!(p.table.eval_angles(0.0, 120.0) == 0.0);
    assert_eq!(p.opening, Opening::Rectangle { length: 0.6, width: 0.6, height: 0.0 });
    // Isym 3's mirror: C0 equals C180 (the plane of symmetry is C90-C270).
    let p = photometry::load(&data("bilateral_sym3.ldt")).unwrap();
    assert!((p.table.eval_angles(0.0, 90.0) - p.table.eval_angles(180.0, 90.0)).abs() < 1e-9);
    assert!((p.table.eval_angles(90.0, 90.0) - 40.0 * 1.2).abs() < 1e-6);
}

#[test]
fn ies_versions_types_and_tilts_integrate_in_closed_form() {
    let cases: [(&str, f64, PhotometricType); 6] = [
        // Isotropic 100 cd × multiplier 2 × ballast 0.9 (2002: the second factor is unused).
        ("tilt_include.ies", 100.0 * 2.0 * 0.9 * 4.0 * PI, PhotometricType::C),
        // Tilt file: factor 0.5 at 0°.
        ("tilt_file.ies", 100.0 * 0.5 * 4.0 * PI, PhotometricType::C),
        // Type B, 100 cd over the front half (|H| ≤ 90°): 2π sr.
        ("type_b.ies", 100.0 * 2.0 * PI, PhotometricType::B),
        // Type A, 1986, both halves mirrored: 50 cd × ballast-lamp factor 0.5 over 2π sr.
        ("type_a_1986.ies", 50.0 * 0.5 * 2.0 * PI, PhotometricType::A),
        // 1991, quadrant type C: C0 100, C90 200 over γ 0-90: mean 150 over 2π sr.
        ("iesna91.ies", 150.0 * 2.0 * PI, PhotometricType::C),
        // 2019: the second factor (file generation type 1.1) does not multiply.
        ("lm63_2019.ies", 10.0 * 4.0 * PI, PhotometricType::C),
    ];
    for (f, want, kind) in cases {
        let p = photometry::load(&data(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(rel(p.flux(), want) < 1e-9, "{f}: {} against {want}", p.flux());
        assert_eq!(p.table.kind(), kind);
    }
    // The tilt factor at an installed tilt of 45°: 0.8.
    let b = std::fs::read(data("tilt_include.ies")).unwrap();
    let p = ies::parse_with_tilt(&b, &data("tilt_include.ies"), 45.0).unwrap();
    assert!(rel(p.flux(), 0.8 * 720.0 * PI) < 1e-9);
    // Feet converted, the 2019 disk read from negative dimensions.
    let p = photometry::load(&data("iesna91.ies")).unwrap();
    assert_eq!(p.opening, Opening::Rectangle { length: 2.0 * 0.3048, width: 0.3048, height: 0.0 });
    assert!(matches!(p.format, photometry::Format::Ies { ref version } if version == "LM-63-1991"));
    let p = photometry::load(&data("lm63_2019.ies")).unwrap();
    assert!(matches!(p.opening, Opening::Disk { diameter, .. } if (diameter - 0.2).abs() < 1e-12));
    // Type B aims along −Z: H = 90° is +X, and nothing goes behind.
    let p = photometry::load(&data("type_b.ies")).unwrap();
    assert!((p.table.eval(glam::Vec3::NEG_Z) - 100.0).abs() < 1e-6);
    assert!((p.table.eval(glam::Vec3::new(0.7, 0.0, 0.7).normalize()) - 0.0).abs() < 1e-6);
}

fn ies_error(text: &str) -> (u32, String) {
    match ies::parse(text.as_bytes(), Path::new("bad.ies")) {
        Err(Error::Photometry { file, line, msg }) => {
            assert_eq!(file, Path::new("bad.ies"));
            (line, msg)
        }
        other => panic!("expected a photometry error, got {other:?}"),
    }
}

const GOOD: &str = "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 1 2 0 0 0\n1 1 40\n0 90 180\n0\n100 100 100\n";

#[test]
fn bad_ies_files_give_errors_naming_the_line() {
    assert!(ies::parse(GOOD.as_bytes(), Path::new("good.ies")).is_ok());
    // Truncated in the candela values: the last line.
    let (line, msg) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 1 2 0 0 0\n1 1 40\n0 90 180\n0\n100 100\n");
    assert!(line == 7 && msg.contains("ends early"), "{line} {msg}");
    // Wrong counts: 0 vertical angles.
    let (line, msg) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 0 1 1 2 0 0 0\n1 1 40\n");
    assert!(line == 3 && msg.contains("vertical angles"), "{line} {msg}");
    // A count that is not whole.
    let (line, _) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3.5 1 1 2 0 0 0\n1 1 40\n");
    assert_eq!(line, 3);
    // Non-monotonic angles.
    let (line, msg) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 1 2 0 0 0\n1 1 40\n0 90 60\n0\n100 100 100\n");
    assert!(line == 5 && msg.contains("increasing"), "{line} {msg}");
    // Negative candela.
    let (line, msg) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 1 2 0 0 0\n1 1 40\n0 90 180\n0\n100\n-5 100\n");
    assert!(line == 8 && msg.contains("negative"), "{line} {msg}");
    // Unknown symmetry: horizontal angles 0 to 45.
    let (line, msg) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 2 2 1 2 0 0 0\n1 1 40\n0 90\n0 45\n1 1 1 1\n");
    assert!(line == 6 && msg.contains("symmetry"), "{line} {msg}");
    // Unknown photometric type, garbage number, no TILT line.
    let (line, msg) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 7 2 0 0 0\n");
    assert!(line == 3 && msg.contains("photometric type"), "{line} {msg}");
    let (line, msg) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 1 2 0 0 0\n1 1 40\n0 9O 180\n");
    assert!(line == 5 && msg.contains("9O"), "{line} {msg}");
    let (_, msg) = ies_error("IESNA:LM-63-2002\n[TEST] nothing\n");
    assert!(msg.contains("TILT"));
    // Lumens per lamp zero (neither positive nor -1).
    let (line, _) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 0 1 3 1 1 2 0 0 0\n");
    assert_eq!(line, 3);
    // A missing tilt file: named, at the TILT= line.
    match photometry::load(&data("missing_tilt.ies")) {
        Err(Error::Photometry { line, msg, .. }) => assert!(line == 2 && msg.contains("no_such_tilt.dat"), "{line} {msg}"),
        other => panic!("{other:?}"),
    }
    // Truncated tilt data.
    let (line, msg) = ies_error("IESNA:LM-63-2002\nTILT=INCLUDE\n1\n3\n0 45 90\n1 0.5\n");
    assert!(line == 6 && msg.contains("ends early"), "{line} {msg}");
    // Hostile sizes are refused before allocation.
    let (_, msg) = ies_error("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 99999 99999 1 2 0 0 0\n");
    assert!(msg.contains("more than"), "{msg}");
}

#[test]
fn bad_eulumdat_files_give_errors_naming_the_line() {
    let good = std::fs::read_to_string(data("quadrant_sym4.ldt")).unwrap();
    let lines: Vec<&str> = good.lines().collect();
    let with = |k: usize, v: &str| {
        let mut l = lines.clone();
        l[k] = v;
        l.join("\n")
    };
    let err = |text: String| match photometry::eulumdat::parse(text.as_bytes(), Path::new("bad.ldt")) {
        Err(Error::Photometry { line, msg, .. }) => (line, msg),
        other => panic!("{other:?}"),
    };
    // Unknown symmetry code on line 3.
    let (line, msg) = err(with(2, "7"));
    assert!(line == 3 && msg.contains("symmetry"), "{line} {msg}");
    // Truncated: the intensities stop early.
    let (_, msg) = err(lines[..lines.len() - 2].join("\n"));
    assert!(msg.contains("ends early"), "{msg}");
    // Non-monotonic C angles (Mc = 4 of them on lines 43-46).
    let (line, msg) = err(with(43, "0"));
    assert!(line == 43 && msg.contains("increasing"), "{line} {msg}");
    // Negative intensity.
    let n = lines.len();
    let (line, msg) = err(with(n - 1, "-3"));
    assert!(line as usize == n && msg.contains("negative"), "{line} {msg}");
    // Mc not a multiple of 4 with Isym 4.
    let (line, _) = err(with(3, "6"));
    assert_eq!(line, 4);
    // Not a number.
    let (line, msg) = err(with(5, "twelve"));
    assert!(line == 6 && msg.contains("twelve"), "{line} {msg}");
}
