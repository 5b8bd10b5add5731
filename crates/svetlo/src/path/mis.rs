//! The MIS weight of one (s, t) connection by the power heuristic, in time linear in the
//! path's length: the densities of every other strategy that could have produced the same
//! path follow from the stored forward and reverse densities by a running product of ratios
//! (Veach §10.2; pbrt's "remapped" zero densities of delta vertices count as 1).

use super::{PathConfig, Vertex};
use crate::bsdf::TransportMode;
use crate::scene::Scene;

#[inline]
fn remap0(x: f32) -> f32 {
    if x != 0.0 {
        x
    } else {
        1.0
    }
}

/// The values of one vertex the weight reads, with the overrides this strategy implies.
#[derive(Clone, Copy)]
struct Pdfs {
    fwd: f32,
    rev: f32,
    delta: bool,
}

impl Pdfs {
    fn of(v: &Vertex) -> Self {
        Pdfs { fwd: v.pdf_fwd, rev: v.pdf_rev, delta: v.delta }
    }
}

/// Power-heuristic weight of strategy (s, t) for the path made of `light[..s]` and
/// `camera[..t]`, where `sampled` is the vertex the strategy sampled itself: the lens point
/// replacing `camera[0]` when t = 1, else the light point replacing `light[0]` when s = 1.
pub fn mis_weight(scene: &Scene, cfg: &PathConfig, light: &[Vertex], camera: &[Vertex], sampled: Option<&Vertex>, s: usize, t: usize) -> f32 {
    let (sampled_light, sampled_camera) = if t == 1 { (None, sampled) } else { (sampled, None) };
    debug_assert!(t >= 1 && s + t >= 2);
    let n = s + t;
    let qs: Option<&Vertex> = match s {
        0 => None,
        1 => Some(sampled_light.unwrap_or(&light[0])),
        _ => Some(&light[s - 1]),
    };
    let pt: &Vertex = if t == 1 { sampled_camera.unwrap_or(&camera[0]) } else { &camera[t - 1] };
    let qs_minus = if s >= 2 { Some(&light[s - 2]) } else { None };
    let pt_minus = if t >= 2 { Some(&camera[t - 2]) } else { None };

    // Reverse densities at the connection, for this strategy; the two asked at one vertex
    // (toward either neighbour) share their directions (`Vertex::pdf_pair`).
    let (lens, imp, rad) = (cfg.lens.as_ref(), TransportMode::Importance, TransportMode::Radiance);
    let (pt_rev, qs_minus_rev) = match (qs, qs_minus) {
        (Some(q), Some(qm)) => {
            let (to_pt, to_qm) = q.pdf_pair(scene, lens, qm, pt, imp, rad);
            (to_pt, Some(to_qm))
        }
        (Some(q), None) => (q.pdf_with_lens(scene, lens, None, pt, imp), None),
        (None, _) => (pt_minus.map_or(0.0, |pm| pt.pdf_light_origin(scene, pm)), None),
    };
    let (pt_minus_rev, qs_rev) = match (qs, pt_minus) {
        (Some(q), Some(pm)) => {
            let (to_pm, to_q) = pt.pdf_pair(scene, lens, q, pm, imp, rad);
            (Some(to_pm), Some(to_q))
        }
        (Some(q), None) => (None, Some(pt.pdf_with_lens(scene, lens, None, q, rad))),
        (None, Some(pm)) => (Some(pt.pdf_light(scene, pm)), None),
        (None, None) => (None, None),
    };

    let cam = |i: usize| -> Pdfs {
        if i == t - 1 {
            Pdfs { fwd: pt.pdf_fwd, rev: pt_rev, delta: false }
        } else if t >= 2 && i == t - 2 {
            Pdfs { rev: pt_minus_rev.unwrap_or(0.0), ..Pdfs::of(&camera[i]) }
        } else {
            Pdfs::of(&camera[i])
        }
    };
    let lig = |i: usize| -> Pdfs {
        if i == s - 1 {
            let q = qs.expect("s >= 1");
            Pdfs { fwd: q.pdf_fwd, rev: qs_rev.unwrap_or(0.0), delta: false }
        } else if s >= 2 && i == s - 2 {
            Pdfs { rev: qs_minus_rev.unwrap_or(0.0), ..Pdfs::of(&light[i]) }
        } else {
            Pdfs::of(&light[i])
        }
    };
    // The light endpoint of the full path: light[0] (or the sampled one), or, for s = 0,
    // the camera subpath's last vertex.
    let light_end: &Vertex = if s == 0 {
        pt
    } else if s == 1 {
        qs.expect("s = 1")
    } else {
        &light[0]
    };
    // Strategy (s', t') exists: no t' = 0; t' = 1 needs a camera that can be connected to,
    // and (1, 1) an area light.
    let exists = |s2: usize, t2: usize| -> bool {
        if t2 == 1 {
            cfg.camera_connectible && (s2 != 1 || light_end.is_area_light(scene))
        } else {
            true
        }
    };

    let mut sum = 0.0f32;
    // Camera side: strategies that end the camera subpath earlier, (n - i, i).
    let mut ri = 1.0f32;
    for i in (1..t).rev() {
        let v = cam(i);
        ri *= remap0(v.rev) / remap0(v.fwd);
        if !v.delta && !cam(i - 1).delta && exists(n - i, i) {
            sum += ri * ri;
        }
    }
    // Light side: strategies with shorter light subpaths, (i, n - i).
    let mut ri = 1.0f32;
    for i in (0..s).rev() {
        let v = lig(i);
        ri *= remap0(v.rev) / remap0(v.fwd);
        let delta_before = if i > 0 { lig(i - 1).delta } else { light_end.is_delta_light(scene) };
        if !v.delta && !delta_before && exists(i, n - i) {
            sum += ri * ri;
        }
    }
    let w = 1.0 / (1.0 + sum);
    if w.is_finite() {
        w
    } else {
        0.0
    }
}
