//! Illuminance on work planes from luminaires, against closed forms in the spirit of
//! CIE 171:2006 (test case 5.2, a point source over a plane; and the closed room's
//! interreflected illuminance), by the two estimators of `photometry::illuminance`.

use std::path::Path;
use svetlo::integrator::RenderSettings;
use svetlo::io::mitsuba::load_scene_from_str;
use svetlo::photometry::illuminance::{gather, light_trace, WorkPlane};

fn data_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/photometry")
}

/// An isotropic 200 cd luminaire (isotropic_sym1.ldt) at height `h` above z = 0, optionally
/// inside a closed diffuse box of reflectance `rho`.
fn scene(h: f32, room: Option<f32>) -> svetlo::scene::Scene {
    let walls = match room {
        None => String::new(),
        Some(rho) => format!(
            r#"<bsdf type="diffuse" id="w"><rgb name="reflectance" value="{rho}"/></bsdf>
               <shape type="cube"><ref id="w"/><boolean name="flip_normals" value="true"/>
                 <transform name="to_world"><scale value="2"/><translate value="0,0,2"/></transform></shape>"#
        ),
    };
    let xml = format!(
        r#"<scene version="3.0.0">
          <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
          <emitter type="ies"><string name="filename" value="isotropic_sym1.ldt"/>
            <transform name="to_world"><translate value="0,0,{h}"/></transform></emitter>
          {walls}
        </scene>"#
    );
    load_scene_from_str(&xml, &data_dir().join("scene.xml"), &[]).expect("scene")
}

#[test]
fn point_source_over_a_plane_follows_the_inverse_square_cosine_law() {
    // E(x) = I cos γ / d² = I h / d³ with d² = h² + x² (CIE 171 case 5.2 in spirit).
    let (h, i) = (2.0f64, 200.0f64);
    let s = scene(h as f32, None);
    let plane = WorkPlane { origin: glam::Vec3::new(-2.0, -2.0, 0.0), u: glam::Vec3::new(4.0, 0.0, 0.0), v: glam::Vec3::new(0.0, 4.0, 0.0), spacing: 1.0 };
    let settings = RenderSettings::default();
    let g = gather(&s, &plane, 4, &settings);
    let (nu, nv) = plane.dims();
    for a in 0..nu {
        for b in 0..nv {
            let p = plane.point(a, b);
            let d2 = (p.x * p.x + p.y * p.y) as f64 + h * h;
            let want = i * h / d2.powf(1.5);
            let got = g.lux[a * nv + b];
            assert!((got - want).abs() < 1e-4 * want, "({a},{b}): {got} lx against {want}");
        }
    }
    // Light tracing estimates each cell's mean: ∫ I h / d³ over the cell / area, by a fine
    // midpoint rule; within 5 standard errors.
    let lt = light_trace(&s, &plane, 400_000, &settings);
    for a in 0..nu {
        for b in 0..nv {
            let c = plane.point(a, b);
            let m = 40;
            let mut acc = 0.0;
            for p in 0..m {
                for q in 0..m {
                    let x = c.x as f64 - 0.5 + (p as f64 + 0.5) / m as f64;
                    let y = c.y as f64 - 0.5 + (q as f64 + 0.5) / m as f64;
                    acc += i * h / (x * x + y * y + h * h).powf(1.5);
                }
            }
            let want = acc / (m * m) as f64;
            let (got, se) = (lt.lux[a * nv + b], lt.std_err[a * nv + b]);
            assert!((got - want).abs() < 5.0 * se + 1e-3 * want, "light tracing ({a},{b}): {got} ± {se} against {want}");
        }
    }
}

#[test]
fn closed_diffuse_room_interreflection_and_estimators_agree() {
    // A closed cube (side 4, area S = 96 m²) of reflectance ρ around a luminaire of flux Φ:
    // the interreflected illuminance is uniform, E_ind = ρ Φ / (S (1 − ρ)) (the integrating
    // sphere argument holds for any closed diffuse enclosure in the mean; for the floor
    // centre of a cube it holds to the few per cent that the first bounce's non-uniformity
    // leaves, so we compare the floor mean of total − direct).
    let rho = 0.5f64;
    let s = scene(2.0, Some(rho as f32));
    let phi = 200.0 * 4.0 * std::f64::consts::PI;
    let area = 96.0;
    let plane = WorkPlane { origin: glam::Vec3::new(-2.0, -2.0, 0.001), u: glam::Vec3::new(4.0, 0.0, 0.0), v: glam::Vec3::new(0.0, 4.0, 0.0), spacing: 1.0 };
    let settings = RenderSettings::default();
    let g = gather(&s, &plane, 128, &settings);
    let lt = light_trace(&s, &plane, 400_000, &settings);
    // Mean over the floor: direct part exactly Φ_floor / A_floor = I ∫ solid angle / 16:
    // the floor subtends 4π/6 from the centre of the cube, so Φ_floor = Φ / 6.
    let direct = phi / 6.0 / 16.0;
    let want = direct + rho * phi / (area * (1.0 - rho));
    for (name, grid) in [("gathering", &g), ("light tracing", &lt)] {
        let mean = grid.mean();
        let se = (grid.std_err.iter().map(|x| x * x).sum::<f64>()).sqrt() / grid.lux.len() as f64;
        eprintln!("{name}: floor mean {mean:.2} ± {se:.2} lx, closed form {want:.2} lx");
        assert!((mean - want).abs() < 5.0 * se + 0.03 * want, "{name}: {mean} ± {se} against {want}");
    }
}
