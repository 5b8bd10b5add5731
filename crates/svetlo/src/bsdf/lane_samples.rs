//! What a BSDF model's eight-lane vector step (`rough_conductor_lanes`, `rough_plastic_lanes`,
//! `rough_dielectric_lanes`) gives per lane, and a lane read back as the scalar BSDF gives it.

use super::{BsdfSample, LobeFlags};
use crate::spectrum::Rgb;
use glam::Vec3;

/// Per lane, in radiance mode: the BSDF's value and density toward the lane's light sample
/// (`nee_f`, `nee_pdf`), and its own sample where `sampled`: `wi`, `f`, `pdf`, whether it took
/// the glossy reflection (`glossy`; else the model's other lobe) and its relative IOR `eta`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LaneSamples<const N: usize> {
    pub nee_f: [[f32; N]; 3],
    pub nee_pdf: [f32; N],
    pub sampled: [bool; N],
    pub glossy: [bool; N],
    pub eta: [f32; N],
    pub wi: [[f32; N]; 3],
    pub f: [[f32; N]; 3],
    pub pdf: [f32; N],
}

impl<const N: usize> LaneSamples<N> {
    /// No light-sample value, no sample, every lane of the lobe `glossy` says, eta 1: what a
    /// vector step fills in.
    #[inline(always)]
    pub(crate) fn empty(glossy: bool) -> Self {
        LaneSamples {
            nee_f: [[0.0; N]; 3],
            nee_pdf: [0.0; N],
            sampled: [false; N],
            glossy: [glossy; N],
            eta: [1.0; N],
            wi: [[0.0; N]; 3],
            f: [[0.0; N]; 3],
            pdf: [0.0; N],
        }
    }

    /// Lane `l` as (`eval_pdf` where it was given a light sample, `nee`; `sample`) give it;
    /// `other`: the model's lobe besides the glossy reflection (a plastic's diffuse one, a
    /// dielectric's transmission).
    #[inline]
    pub(crate) fn lane(&self, l: usize, nee: bool, other: LobeFlags) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        let rgb = |a: &[[f32; N]; 3]| Rgb::new(a[0][l], a[1][l], a[2][l]);
        let s = self.sampled[l].then(|| BsdfSample {
            wi: Vec3::new(self.wi[0][l], self.wi[1][l], self.wi[2][l]),
            f: rgb(&self.f),
            pdf: self.pdf[l],
            lobe: if self.glossy[l] { LobeFlags::GLOSSY_REFLECTION } else { other },
            eta: self.eta[l],
        });
        (nee.then(|| (rgb(&self.nee_f), self.nee_pdf[l])), s)
    }
}
