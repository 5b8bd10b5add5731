//! Daylight (CIE skies, daylight factor) and glare (UGR) against closed forms in the spirit
//! of CIE 171:2006: the overcast sky's unobstructed horizontal illuminance, the daylight
//! factor below a skylight, and the UGR of one luminaire over a uniform background.

use glam::Vec3;
use std::f64::consts::PI;
use std::path::Path;
use svetlo::integrator::RenderSettings;
use svetlo::io::mitsuba::load_scene_from_str;
use svetlo::photometry::glare::{position_index, ugr};
use svetlo::photometry::illuminance::{gather, light_trace, WorkPlane};
use svetlo::photometry::sky::unobstructed_illuminance;

fn data_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/photometry")
}

fn load(body: &str) -> svetlo::scene::Scene {
    let xml = format!(
        r#"<scene version="3.0.0">
          <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
          {body}
        </scene>"#
    );
    load_scene_from_str(&xml, &data_dir().join("scene.xml"), &[]).expect("scene")
}

const BLACK: &str = r#"<bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>"#;

#[test]
fn overcast_sky_gives_seven_ninths_pi_lz_on_an_unobstructed_plane() {
    // CIE 171 case 5.13 in spirit: the traditional overcast sky L = Lz (1 + 2 cos Z)/3 gives
    // E_h = 7π Lz / 9 outdoors. The map's bilinear error is below 1.3e-5 (sky.rs), so the
    // estimators' own errors decide: 4 standard errors.
    let lz = 3000.0f64;
    let s = load(&format!(
        r#"<emitter type="cie_sky"><integer name="type" value="16"/><float name="zenith_luminance" value="{lz}"/></emitter>
           <shape type="rectangle">{BLACK}<transform name="to_world"><scale value="3"/><translate value="0,0,-0.01"/></transform></shape>"#
    ));
    let want = 7.0 * PI * lz / 9.0;
    let e_out = unobstructed_illuminance(&s, Vec3::Z);
    assert!((e_out / want - 1.0).abs() < 1e-4, "quadrature {e_out} against {want}");
    let plane = WorkPlane { origin: Vec3::new(-1.0, -1.0, 0.0), u: Vec3::new(2.0, 0.0, 0.0), v: Vec3::new(0.0, 2.0, 0.0), spacing: 1.0 };
    let settings = RenderSettings::default();
    let g = gather(&s, &plane, 1024, &settings);
    let lt = light_trace(&s, &plane, 400_000, &settings);
    for (name, grid) in [("gathering", &g), ("light tracing", &lt)] {
        for k in 0..grid.lux.len() {
            assert!((grid.lux[k] - want).abs() < 4.0 * grid.std_err[k] + 1e-4 * want, "{name} point {k}: {} ± {} against {want}", grid.lux[k], grid.std_err[k]);
        }
    }
    // Outdoors the daylight factor is 100 %.
    let df = g.clone().daylight_factor(e_out);
    assert!((df.mean() - 100.0).abs() < 4.0 * df.std_err.iter().cloned().fold(0.0, f64::max));
}

#[test]
fn daylight_factor_below_a_skylight_matches_the_sky_integrated_over_the_opening() {
    // A black room (6 × 6 × 1 m) whose ceiling has a 2 × 2 m opening above the origin, under
    // the traditional overcast sky: at a floor point the illuminance is the sky's luminance
    // integrated over the opening, E = ∫ L(Z) cos Z dω with cos Z = h / r and dω = cos Z dA / r²
    // over the opening's plane; a 400 × 400 midpoint rule evaluates it (error < 1e-5 for this
    // smooth integrand), and 7π Lz / 9 outdoors turns it into the daylight factor.
    let lz = 1000.0f64;
    let ceiling = |sx: f32, sy: f32, tx: f32, ty: f32| {
        format!(r#"<shape type="rectangle">{BLACK}<transform name="to_world"><scale x="{sx}" y="{sy}"/><translate value="{tx},{ty},1"/></transform></shape>"#)
    };
    let mut body = format!(r#"<emitter type="cie_sky"><float name="zenith_luminance" value="{lz}"/></emitter>"#);
    body += &ceiling(3.0, 1.0, 0.0, 2.0);
    body += &ceiling(3.0, 1.0, 0.0, -2.0);
    body += &ceiling(1.0, 1.0, 2.0, 0.0);
    body += &ceiling(1.0, 1.0, -2.0, 0.0);
    // Walls from the floor to the ceiling (no floor: the plane only looks up).
    for x in [-3, 3] {
        body += &format!(
            r#"<shape type="rectangle">{BLACK}<transform name="to_world"><scale x="0.5" y="3"/><rotate y="1" angle="90"/><translate value="{x},0,0.5"/></transform></shape>"#
        );
    }
    for y in [-3, 3] {
        body += &format!(
            r#"<shape type="rectangle">{BLACK}<transform name="to_world"><scale x="3" y="0.5"/><rotate x="1" angle="90"/><translate value="0,{y},0.5"/></transform></shape>"#
        );
    }
    let s = load(&body);
    let e_out = unobstructed_illuminance(&s, Vec3::Z);
    let reference = |px: f64, py: f64| {
        let (n, h) = (400, 1.0f64);
        let mut acc = 0.0;
        for i in 0..n {
            for j in 0..n {
                let x = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64 - px;
                let y = -1.0 + 2.0 * (j as f64 + 0.5) / n as f64 - py;
                let r2 = x * x + y * y + h * h;
                let cos_z = h / r2.sqrt();
                let l = lz * (1.0 + 2.0 * cos_z) / 3.0;
                // L cos Z dω with dω = cos Z dA / r².
                acc += l * cos_z * cos_z / r2;
            }
        }
        acc * (2.0 / n as f64) * (2.0 / n as f64)
    };
    let plane = WorkPlane { origin: Vec3::new(-0.75, -0.75, 0.001), u: Vec3::new(1.5, 0.0, 0.0), v: Vec3::new(0.0, 1.5, 0.0), spacing: 0.5 };
    let (nu, nv) = plane.dims();
    let settings = RenderSettings::default();
    let df = gather(&s, &plane, 4096, &settings).daylight_factor(e_out);
    for k in 0..nu * nv {
        let p = plane.point(k / nv, k % nv);
        let want = 100.0 * reference(p.x as f64, p.y as f64) / (7.0 * PI * lz / 9.0);
        assert!((df.lux[k] - want).abs() < 4.0 * df.std_err[k] + 1e-3 * want, "DF at {p}: {} ± {} % against {want} %", df.lux[k], df.std_err[k]);
    }
}

#[test]
fn ugr_of_one_luminaire_over_a_uniform_background_has_its_closed_form() {
    // CIE 117: UGR = 8 log10(0.25/Lb Σ L² ω / p²). An isotropic 200 cd luminaire with a
    // 0.6 × 0.6 m opening (isotropic_sym1.ldt) 1 m above and 3 m ahead of the eye (τ = 0,
    // σ = atan(1/3)); the background is a uniform sky of Lc W/(m² sr), so Lb = 683 Lc cd/m²
    // exactly (every gathering ray sees it). Seen from the eye the opening's projected area
    // is 0.36 cos γ with cos γ = 1/√10, r² = 10.
    let lc = 0.05f64;
    let s = load(&format!(
        r#"<emitter type="constant"><rgb name="radiance" value="{lc}"/></emitter>
           <emitter type="ies"><string name="filename" value="isotropic_sym1.ldt"/><transform name="to_world"><translate value="0,3,2.2"/></transform></emitter>"#
    ));
    let g = ugr(&s, Vec3::new(0.0, 0.0, 1.2), Vec3::Y, Vec3::Z, 256, &RenderSettings::default());
    let lb = 683.0 * lc;
    assert!((g.background - lb).abs() < 1e-4 * lb, "Lb {} against {lb}", g.background);
    assert_eq!(g.sources.len(), 1);
    let (i, r2, area) = (200.0f64, 10.0f64, 0.36 / 10f64.sqrt());
    let (l, omega) = (i / area, area / r2);
    let sigma = (1.0f64 / 3.0).atan().to_degrees();
    let p = ((35.2 - 1.22) * 1e-3 * sigma + 21e-5 * sigma * sigma).exp();
    assert!((position_index(0.0, sigma) - p).abs() < 1e-12);
    let want = 8.0 * (0.25 / lb * l * l * omega / (p * p)).log10();
    let got = g.ugr.expect("a rated luminaire");
    assert!((got - want).abs() < 1e-3, "UGR {got} against {want}");
    // Four times the intensity (scale 4): L² ω grows 16-fold, UGR by 8 log10 16.
    let s4 = load(&format!(
        r#"<emitter type="constant"><rgb name="radiance" value="{lc}"/></emitter>
           <emitter type="ies"><string name="filename" value="isotropic_sym1.ldt"/><float name="scale" value="4"/><transform name="to_world"><translate value="0,3,2.2"/></transform></emitter>"#
    ));
    let g4 = ugr(&s4, Vec3::new(0.0, 0.0, 1.2), Vec3::Y, Vec3::Z, 256, &RenderSettings::default()).ugr.unwrap();
    assert!((g4 - got - 8.0 * 16f64.log10()).abs() < 1e-3, "{g4} against {got} + 9.63");
    // Looking away, the luminaire is behind the observer: not rated, UGR undefined.
    let away = ugr(&s, Vec3::new(0.0, 0.0, 1.2), Vec3::NEG_Y, Vec3::Z, 64, &RenderSettings::default());
    assert!(away.ugr.is_none() && away.skipped == 1);
}
