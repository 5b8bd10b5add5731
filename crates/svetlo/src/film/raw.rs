//! A film's raw sums as bytes, for a render split over processes or machines: the sums of a
//! node of the pass tree ([`crate::integrator::passes`]), not a normalised image, so that the
//! nodes combine into the local render's film bit for bit. Little-endian, versioned by its
//! magic; a malformed buffer is an error, never a panic, and nothing is allocated before its
//! length has been checked against what the header announces.

use super::{Film, Filter, Pixel};
use crate::bytes::ByteReader;
use crate::error::{Error, Result};
use crate::spectrum::Rgb;
use std::ops::Range;

const MAGIC: &[u8; 8] = b"SVLFILM2";
/// Bytes per pixel of the beauty: sum (3 f32), weight (f64), s1, s2 (3 f32 each), n (u32).
const PIXEL_BYTES: usize = 12 + 8 + 12 + 12 + 4;

/// The sums of passes `passes` of a render planned in `passes_total` passes (for Metropolis
/// methods, chain blocks: see `methods::render_passes`).
#[derive(Clone, Debug)]
pub struct PartialFilm {
    pub passes: Range<u32>,
    pub passes_total: u32,
    pub film: Film,
    /// Metropolis mutations done (0 for the other methods): the merged film's splats are
    /// normalised by their total, as a local render's are.
    pub mutations: u64,
}

fn bad(msg: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("partial film: {msg}"))
}

fn put_rgb(out: &mut Vec<u8>, c: Rgb) {
    for v in [c.r, c.g, c.b] {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// The splat normalisation of summed parts: their samples per pixel, or for Metropolis parts
/// the mutations per pixel exactly as `metropolis::run` sets it.
fn normalise(film: &mut Film, mutations: u64) {
    if mutations > 0 {
        crate::integrator::metropolis::set_splat_norm(film, mutations, film.width as u64 * film.height as u64);
    } else {
        film.splat_scale = film.spp_done.max(1) as f32;
    }
}

impl PartialFilm {
    /// The bytes of these sums.
    pub fn to_bytes(&self) -> Vec<u8> {
        let f = &self.film;
        let px = f.full.pixels.len();
        let mut out = Vec::with_capacity(64 + px * (PIXEL_BYTES + 12 * (1 + 2 * f.layer_names.len())));
        out.extend_from_slice(MAGIC);
        for v in [self.passes.start, self.passes.end, self.passes_total, f.width, f.height] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.mutations.to_le_bytes());
        let (kind, param) = match f.filter {
            Filter::Box => (0u8, 0.0f32),
            Filter::Tent { radius } => (1, radius),
            Filter::Gaussian { stddev } => (2, stddev),
        };
        out.push(kind);
        out.extend_from_slice(&param.to_le_bytes());
        out.extend_from_slice(&f.spp_done.to_le_bytes());
        out.extend_from_slice(&(f.layer_names.len() as u32).to_le_bytes());
        for n in &f.layer_names {
            out.extend_from_slice(&(n.len() as u32).to_le_bytes());
            out.extend_from_slice(n.as_bytes());
        }
        // The beauty's splats, then each layer's, each a whole buffer on the wire (the film
        // keeps them in one row per pixel).
        for _ in 0..=f.layer_names().len() {
            out.push(!f.splats.is_empty() as u8);
        }
        for p in &f.full.pixels {
            put_rgb(&mut out, p.sum);
            out.extend_from_slice(&p.weight.to_le_bytes());
            put_rgb(&mut out, p.s1);
            put_rgb(&mut out, p.s2);
            out.extend_from_slice(&p.n.to_le_bytes());
        }
        // Layer by layer on the wire (the tile keeps them pixel by pixel).
        let nl = f.full.n_layers;
        for i in 0..nl {
            if f.full.layers.is_empty() {
                // Never allocated: all zero.
                out.resize(out.len() + f.full.pixels.len() * 12, 0);
            } else {
                f.full.layers.chunks_exact(3).skip(i).step_by(nl).for_each(|c| put_rgb(&mut out, Rgb::new(c[0], c[1], c[2])));
            }
        }
        if !f.splats.is_empty() {
            for slot in 0..=nl {
                f.splats.chunks_exact(3).skip(slot).step_by(nl + 1).for_each(|c| put_rgb(&mut out, Rgb::new(c[0], c[1], c[2])));
            }
        }
        out
    }

    /// Read sums written by [`Self::to_bytes`].
    pub fn from_bytes(b: &[u8]) -> Result<PartialFilm> {
        let mut r = ByteReader::new(b, "partial film");
        if r.take(MAGIC.len()).ok() != Some(&MAGIC[..]) {
            return Err(bad("not svetlo film sums (bad magic)"));
        }
        let (start, end, total, width, height) = (r.u32()?, r.u32()?, r.u32()?, r.u32()?, r.u32()?);
        let mutations = u64::from_le_bytes(r.take(8)?.try_into().expect("8 bytes"));
        if start >= end || end > total {
            return Err(bad(format!("passes {start}..{end} of {total}")));
        }
        let filter = match (r.u8()?, r.f32()?) {
            (0, _) => Filter::Box,
            (1, radius) if radius > 0.0 && radius.is_finite() => Filter::Tent { radius },
            (2, stddev) if stddev > 0.0 && stddev.is_finite() => Filter::Gaussian { stddev },
            (k, p) => return Err(bad(format!("unknown filter {k} ({p})"))),
        };
        let spp_done = r.u32()?;
        let n_layers = r.u32()? as usize;
        // Each layer name takes at least its 4-byte length: bounds the count by the input.
        if n_layers > b.len() / 4 {
            return Err(bad(format!("{n_layers} layers in {} bytes", b.len())));
        }
        let mut names = Vec::with_capacity(n_layers);
        for _ in 0..n_layers {
            let len = r.u32()? as usize;
            let s = std::str::from_utf8(r.take(len)?).map_err(|_| bad("a layer name is not UTF-8"))?;
            names.push(s.to_string());
        }
        let has_splats = r.u8()? != 0;
        let layer_has: Vec<bool> = (0..n_layers).map(|_| r.u8().map(|v| v != 0)).collect::<Result<_>>()?;
        let px = (width as u64) * (height as u64);
        let buffers = n_layers as u64 + has_splats as u64 + layer_has.iter().filter(|&&h| h).count() as u64;
        let want = px.checked_mul(PIXEL_BYTES as u64 + 12 * buffers).ok_or_else(|| bad("size overflows"))?;
        if want != (r.left()) as u64 {
            return Err(bad(format!("{width}x{height} with {buffers} buffers needs {want} bytes of sums, got {}", r.left())));
        }
        let px = px as usize;
        let mut film = Film::with_layers(width, height, filter, &names);
        for p in film.full.pixels.iter_mut() {
            *p = Pixel { sum: r.rgb()?, weight: r.f64()?, s1: r.rgb()?, s2: r.rgb()?, n: r.u32()? };
        }
        film.full.blank = false;
        film.full.ensure_layers();
        for i in 0..n_layers {
            for (d, s) in film.full.layers.chunks_exact_mut(3).skip(i).step_by(n_layers).zip(r.rgbs(px)?) {
                d.copy_from_slice(&[s.r, s.g, s.b]);
            }
        }
        let has: Vec<bool> = std::iter::once(has_splats).chain(layer_has.iter().copied()).collect();
        if has.iter().any(|&h| h) {
            film.splats = vec![0.0; px * (n_layers + 1) * 3];
        }
        for (slot, &h) in has.iter().enumerate() {
            if h {
                for (d, s) in film.splats.chunks_exact_mut(3).skip(slot).step_by(n_layers + 1).zip(r.rgbs(px)?) {
                    d.copy_from_slice(&[s.r, s.g, s.b]);
                }
            }
        }
        film.spp_done = spp_done;
        film.splat_scale = spp_done.max(1) as f32;
        Ok(PartialFilm { passes: start..end, passes_total: total, film, mutations })
    }

    /// Combine partial films that partition one render's passes, in the pass tree's order:
    /// the film a local render of the same scene, seed and spp makes, bit for bit.
    pub fn merge(parts: Vec<PartialFilm>) -> Result<Film> {
        let first = parts.first().ok_or_else(|| bad("nothing to merge"))?;
        let (total, w, h, filter, names) = (first.passes_total, first.film.width, first.film.height, first.film.filter, first.film.layer_names.clone());
        for p in &parts {
            if (p.passes_total, p.film.width, p.film.height, p.film.filter) != (total, w, h, filter) || p.film.layer_names != names {
                return Err(bad(format!(
                    "parts of different renders: {}x{} {:?} of {} passes beside {w}x{h} {filter:?} of {total}",
                    p.film.width, p.film.height, p.film.filter, p.passes_total
                )));
            }
        }
        let mutations: u64 = parts.iter().map(|p| p.mutations).sum();
        let nodes = parts.into_iter().map(|p| (p.passes, p.film)).collect();
        let mut film = crate::integrator::passes::combine(nodes, total, &|a: &mut Film, b: Film| a.add(&b))?;
        normalise(&mut film, mutations);
        Ok(film)
    }

    /// The sum of two sibling nodes of the pass tree: `left` and `right` must be the two
    /// halves the tree splits their union into. This is the very addition the whole tree's
    /// merge makes there, so a client may join parts as they arrive (holding at most one part
    /// per level of the tree) and still end with the local render's bits.
    pub fn join(mut left: PartialFilm, right: PartialFilm) -> Result<PartialFilm> {
        let (l, r) = (&left.film, &right.film);
        if (left.passes_total, l.width, l.height, l.filter) != (right.passes_total, r.width, r.height, r.filter) || l.layer_names != r.layer_names {
            return Err(bad("parts of different renders"));
        }
        let union = left.passes.start..right.passes.end;
        let siblings = left.passes.end == right.passes.start
            && union.end - union.start >= 2
            && crate::integrator::passes::split(union.start, union.end) == left.passes.end
            && crate::integrator::passes::is_node(&union, left.passes_total);
        if !siblings {
            return Err(bad(format!(
                "passes {}..{} and {}..{} are not the two halves of a node of the pass tree",
                left.passes.start, left.passes.end, right.passes.start, right.passes.end
            )));
        }
        left.film.add(&right.film);
        left.mutations += right.mutations;
        left.passes = union;
        Ok(left)
    }

    /// The sum of any parts of one render, for a look at a render in progress: pass order,
    /// not the tree's, so close to the final image but not its bits.
    pub fn preview(parts: &[PartialFilm]) -> Result<Film> {
        let mut sorted: Vec<&PartialFilm> = parts.iter().collect();
        sorted.sort_by_key(|p| p.passes.start);
        let first = sorted.first().ok_or_else(|| bad("nothing to merge"))?;
        let mut film = first.film.clone();
        let mutations: u64 = sorted.iter().map(|p| p.mutations).sum();
        for p in &sorted[1..] {
            if (p.film.width, p.film.height, p.film.filter, p.film.layer_names.len()) != (film.width, film.height, film.filter, film.layer_names.len()) {
                return Err(bad("parts of different renders"));
            }
            film.add(&p.film);
        }
        normalise(&mut film, mutations);
        Ok(film)
    }
}
