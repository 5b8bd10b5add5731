//! Image files: EXR (linear float32, the truth), PNG (sRGB 8-bit, for looking), PFM (the
//! format of block-averaged references). Every error names the file.

use crate::error::{Error, Result};
use crate::film::Image;
use crate::spectrum::Rgb;
use crate::texture::Bitmap;
use std::io::Cursor;
use std::path::Path;

fn img_err(path: &Path, msg: impl std::fmt::Display) -> Error {
    Error::Image { file: path.to_path_buf(), msg: msg.to_string() }
}

/// An in-memory encoder's error, named after the file it was for.
fn for_file(path: &Path, e: Error) -> Error {
    match e {
        Error::Image { msg, .. } => img_err(path, msg),
        e => img_err(path, e),
    }
}

fn io_err(path: &Path, source: std::io::Error) -> Error {
    Error::Io { file: path.to_path_buf(), source }
}

/// Write `bytes` to `path` whole or not at all: into a temporary file beside it, flushed to
/// disk, then renamed over `path`. A full disk or an interrupted write leaves `path` as it
/// was (absent, or the previous image) and no temporary file behind.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let name = path.file_name().ok_or_else(|| img_err(path, "names no file"))?;
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".{}-{n}.tmp", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    let written = (|| {
        let mut f = std::fs::OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    written.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io_err(path, e)
    })
}

/// The bytes of an EXR file: linear RGB as 32-bit float channels R, G, B.
pub fn encode_exr(img: &Image) -> Result<Vec<u8>> {
    encode_exr_layers(img, &[])
}

/// Linear RGB as 32-bit float channels R, G, B.
pub fn write_exr(path: &Path, img: &Image) -> Result<()> {
    let bytes = encode_exr(img).map_err(|e| for_file(path, e))?;
    write_atomic(path, &bytes)
}

/// The bytes of [`write_exr_layers`]'s file.
pub fn encode_exr_layers(beauty: &Image, layers: &[(String, Image)]) -> Result<Vec<u8>> {
    use super::exr_encode::{encode_exr_channels, ExrChannel};
    let (w, h) = (beauty.width, beauty.height);
    if layers.iter().any(|(_, l)| l.width != w || l.height != h) {
        return Err(Error::Image { file: "(EXR in memory)".into(), msg: "AOV layers must have the beauty's size".into() });
    }
    let mut channels = Vec::with_capacity(3 * (1 + layers.len()));
    for (prefix, img) in std::iter::once((String::new(), beauty)).chain(layers.iter().map(|(n, l)| (format!("{n}."), l))) {
        for (component, c) in ["R", "G", "B"].iter().enumerate() {
            channels.push(ExrChannel { name: format!("{prefix}{c}"), data: &img.data, component });
        }
    }
    encode_exr_channels(w, h, &channels)
}

/// One EXR file with the beauty as channels R, G, B and each layer `NAME` as `NAME.R`,
/// `NAME.G`, `NAME.B` (OpenEXR's layer naming), 32-bit float, all the beauty's size; written
/// whole or not at all.
pub fn write_exr_layers(path: &Path, beauty: &Image, layers: &[(String, Image)]) -> Result<()> {
    let bytes = encode_exr_layers(beauty, layers).map_err(|e| for_file(path, e))?;
    write_atomic(path, &bytes)
}

/// Every channel of an EXR file's first layer by name (e.g. `caustic.R`), as f32.
pub fn read_exr_channels(path: &Path) -> Result<Vec<(String, Vec<f32>)>> {
    use exr::prelude::{read, ReadChannels, ReadLayers};
    let img =
        read().no_deep_data().largest_resolution_level().all_channels().first_valid_layer().all_attributes().from_file(path).map_err(|e| img_err(path, e))?;
    Ok(img.layer_data.channel_data.list.iter().map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect())).collect())
}

/// The beauty (channels R, G, B) and the layers (`NAME.R`, `NAME.G`, `NAME.B`, in the
/// file's channel order) of an EXR written by [`write_exr_layers`]. A layer lacking one of its
/// three channels is an error naming it.
pub fn read_exr_layers(path: &Path) -> Result<(Image, Vec<(String, Image)>)> {
    let beauty = read_exr(path)?;
    let n = beauty.width * beauty.height;
    let mut names: Vec<String> = Vec::new();
    let mut channels = std::collections::HashMap::new();
    for (name, data) in read_exr_channels(path)? {
        if let Some((layer, c)) = name.rsplit_once('.') {
            if !names.iter().any(|x| x == layer) {
                names.push(layer.to_string());
            }
            channels.insert((layer.to_string(), c.to_string()), data);
        }
    }
    let mut layers = Vec::with_capacity(names.len());
    for layer in names {
        let mut get = |c: &str| {
            channels
                .remove(&(layer.clone(), c.to_string()))
                .filter(|d| d.len() == n)
                .ok_or_else(|| Error::Image { file: path.to_path_buf(), msg: format!("layer '{layer}' has no channel {layer}.{c} of the image's size") })
        };
        let (r, g, b) = (get("R")?, get("G")?, get("B")?);
        let data = (0..n).map(|i| Rgb::new(r[i], g[i], b[i])).collect();
        layers.push((layer, Image::new(beauty.width, beauty.height, data)));
    }
    Ok((beauty, layers))
}

/// sRGB-encoded 8-bit PNG, values clamped to [0, 1] (NaN becomes 0).
pub fn write_png(path: &Path, img: &Image) -> Result<()> {
    let out = encode_png(img).map_err(|e| img_err(path, e))?;
    write_atomic(path, &out)
}

/// The bytes of [`write_png`]'s file (for pages that embed their images).
pub fn encode_png(img: &Image) -> std::result::Result<Vec<u8>, image::ImageError> {
    let mut buf = vec![0u8; img.data.len() * 3];
    for (d, c) in buf.chunks_exact_mut(3).zip(&img.data) {
        d.copy_from_slice(&c.to_array().map(Rgb::linear_to_srgb8));
    }
    let mut out = Vec::new();
    image::write_buffer_with_format(&mut Cursor::new(&mut out), &buf, img.width as u32, img.height as u32, image::ColorType::Rgb8, image::ImageFormat::Png)?;
    Ok(out)
}

/// PFM flavours: three channels (`PF`) or one (`Pf`, written as the pixel's luminance).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PfmChannels {
    Rgb,
    Grey,
}

/// The bytes of a PFM file: rows bottom to top, float32 in the byte order the scale's sign
/// announces (negative: little-endian).
pub fn encode_pfm(img: &Image, channels: PfmChannels, big_endian: bool) -> Vec<u8> {
    let (magic, nc) = match channels {
        PfmChannels::Rgb => ("PF", 3),
        PfmChannels::Grey => ("Pf", 1),
    };
    let scale = if big_endian { "1.0" } else { "-1.0" };
    let mut out = format!("{magic}\n{} {}\n{scale}\n", img.width, img.height).into_bytes();
    out.reserve(img.width * img.height * nc * 4);
    for y in (0..img.height).rev() {
        for x in 0..img.width {
            let c = img.get(x, y);
            let vals = [c.r, c.g, c.b];
            let vals: &[f32] = if nc == 3 { &vals } else { &[c.luminance()] };
            for &v in vals {
                out.extend_from_slice(&if big_endian { v.to_be_bytes() } else { v.to_le_bytes() });
            }
        }
    }
    out
}

/// Little-endian RGB PFM.
pub fn write_pfm(path: &Path, img: &Image) -> Result<()> {
    write_atomic(path, &encode_pfm(img, PfmChannels::Rgb, false))
}

/// Parse a PFM file's bytes; `path` is only used in messages. A grey file gives r = g = b.
pub fn decode_pfm(bytes: &[u8], path: &Path) -> Result<Image> {
    // Header: three whitespace-separated tokens after the magic, then exactly one whitespace byte.
    let mut pos = 0usize;
    let mut token = |what: &str| -> Result<String> {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() && pos - start < 64 {
            pos += 1;
        }
        if start == pos {
            return Err(img_err(path, format!("PFM header ends before the {what}")));
        }
        Ok(String::from_utf8_lossy(&bytes[start..pos]).into_owned())
    };
    let magic = token("magic number")?;
    let nc = match magic.as_str() {
        "PF" => 3usize,
        "Pf" => 1usize,
        m => return Err(img_err(path, format!("not a PFM file (magic '{m}', expected 'PF' or 'Pf')"))),
    };
    let parse_dim = |s: String, what: &str| -> Result<usize> {
        match s.parse::<usize>() {
            Ok(v) if v > 0 => Ok(v),
            _ => Err(img_err(path, format!("PFM {what} '{s}' is not a positive integer"))),
        }
    };
    let w = token("width")?;
    let w = parse_dim(w, "width")?;
    let h = token("height")?;
    let h = parse_dim(h, "height")?;
    let s = token("scale")?;
    let scale: f32 = s.parse().map_err(|_| img_err(path, format!("PFM scale '{s}' is not a number")))?;
    if scale == 0.0 || !scale.is_finite() {
        return Err(img_err(path, format!("PFM scale {scale} must be non-zero and finite")));
    }
    let little = scale < 0.0;
    // One whitespace byte separates the header from the raster.
    if pos >= bytes.len() || !bytes[pos].is_ascii_whitespace() {
        return Err(img_err(path, "PFM header is not followed by the pixel data"));
    }
    pos += 1;
    let need = w.checked_mul(h).and_then(|p| p.checked_mul(nc * 4)).ok_or_else(|| img_err(path, format!("PFM size {w}x{h} is too large")))?;
    crate::limits::check_items(format!("{}: a {w}x{h} PFM image", path.display()), (w * h) as u64, 12)?;
    let data = &bytes[pos..];
    if data.len() < need {
        return Err(img_err(path, format!("PFM {w}x{h} needs {need} bytes of pixel data, the file has {}", data.len())));
    }
    let mut pixels = vec![Rgb::BLACK; w * h];
    let val = |i: usize| {
        let b = [data[4 * i], data[4 * i + 1], data[4 * i + 2], data[4 * i + 3]];
        if little {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    for row in 0..h {
        // File row 0 is the image's bottom row.
        let y = h - 1 - row;
        for x in 0..w {
            let i = (row * w + x) * nc;
            pixels[y * w + x] = if nc == 3 { Rgb::new(val(i), val(i + 1), val(i + 2)) } else { Rgb::splat(val(i)) };
        }
    }
    Ok(Image::new(w, h, pixels))
}

pub fn read_pfm(path: &Path) -> Result<Image> {
    let bytes = crate::limits::read_file(path)?;
    decode_pfm(&bytes, path)
}

/// Write by extension: .exr, .png or .pfm.
pub fn write_image(path: &Path, img: &Image) -> Result<()> {
    match ext(path).as_str() {
        "exr" => write_exr(path, img),
        "png" => write_png(path, img),
        "pfm" => write_pfm(path, img),
        other => Err(img_err(path, format!("unsupported output format '{other}' (exr, png, pfm)"))),
    }
}

/// PNG, JPEG or BMP through the `image` crate, its size checked against the budget first
/// (the decoded image, its float copy and ours: 40 bytes per pixel).
pub fn decode_8bit(bytes: &[u8], path: &Path) -> Result<image::DynamicImage> {
    let reader = || image::ImageReader::new(Cursor::new(bytes)).with_guessed_format().map_err(|e| img_err(path, e));
    let (w, h) = reader()?.into_dimensions().map_err(|e| img_err(path, e))?;
    crate::limits::check_items(format!("{}: a {w}x{h} image", path.display()), w as u64 * h as u64, 40)?;
    let mut r = reader()?;
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(crate::limits::max_memory());
    r.limits(limits);
    r.decode().map_err(|e| img_err(path, e))
}

fn ext(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase()
}

/// The last component of a channel name ("diffuse.R" -> "R").
fn channel_base(name: &str) -> &str {
    name.rsplit('.').next().unwrap_or(name)
}

/// Decode an EXR's bytes as linear RGB: the first valid layer, at its largest resolution;
/// any sample type becomes f32. R, G and B are taken by name (a layer prefix is allowed,
/// unprefixed names win); a missing one is 0, except that a luminance-only image (Y) is grey.
/// Alpha and other channels are ignored.
pub fn decode_exr(bytes: &[u8], path: &Path) -> Result<Image> {
    use exr::prelude::{read, ReadChannels, ReadLayers, Vec2};
    // The header announces the size: check it against the budget before the decoder
    // allocates (a 2 KB file may claim 100 000 x 100 000 pixels).
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(|e| img_err(path, e))?;
    for h in &meta.headers {
        let (w, hh) = (h.layer_size.width() as u64, h.layer_size.height() as u64);
        let per_pixel = h.channels.list.len() as u64 * 4 + 12;
        crate::limits::check_items(format!("{}: a {w}x{hh} EXR layer", path.display()), w.saturating_mul(hh), per_pixel)?;
    }
    let img = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| img_err(path, e))?;
    let layer = &img.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let list = &layer.channel_data.list;
    let find = |want: &str| {
        let exact = list.iter().position(|c| c.name.to_string().eq_ignore_ascii_case(want));
        exact.or_else(|| list.iter().position(|c| channel_base(&c.name.to_string()).eq_ignore_ascii_case(want)))
    };
    let (ir, ig, ib) = (find("R"), find("G"), find("B"));
    let idx = if ir.is_none() && ig.is_none() && ib.is_none() {
        match find("Y") {
            Some(y) => [Some(y), Some(y), Some(y)],
            None => {
                let names: Vec<String> = list.iter().map(|c| c.name.to_string()).collect();
                return Err(img_err(path, format!("EXR has no R, G, B or Y channel (channels: {})", names.join(", "))));
            }
        }
    } else {
        [ir, ig, ib]
    };
    // Channels must be sampled at every pixel (no subsampled chroma).
    for i in idx.iter().flatten() {
        let c = &list[*i];
        if c.sampling != Vec2(1, 1) {
            return Err(img_err(path, format!("EXR channel {} is subsampled, which is not supported", c.name)));
        }
    }
    let chan: Vec<Option<Vec<f32>>> = idx.iter().map(|i| i.map(|i| list[i].sample_data.values_as_f32().collect())).collect();
    let mut data = vec![Rgb::BLACK; w * h];
    for (k, px) in data.iter_mut().enumerate() {
        let get = |c: &Option<Vec<f32>>| c.as_ref().and_then(|v| v.get(k).copied()).unwrap_or(0.0);
        *px = Rgb::new(get(&chan[0]), get(&chan[1]), get(&chan[2]));
    }
    Ok(Image::new(w, h, data))
}

pub fn read_exr(path: &Path) -> Result<Image> {
    let bytes = crate::limits::read_file(path)?;
    decode_exr(&bytes, path)
}

/// Read an image, recognising EXR and PFM by their magic bytes; other formats go to the
/// `image` crate, and 8-bit formats are decoded from sRGB to linear.
pub fn read_image(path: &Path) -> Result<Image> {
    decode_image(&crate::limits::read_file(path)?, path)
}

/// [`read_image`] for bytes held in memory; `path` names them in errors and, for formats
/// without a magic number, gives the extension.
pub fn decode_image(bytes: &[u8], path: &Path) -> Result<Image> {
    if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        return decode_exr(bytes, path);
    }
    if bytes.starts_with(b"PF") || bytes.starts_with(b"Pf") {
        return decode_pfm(bytes, path);
    }
    match ext(path).as_str() {
        "exr" => Err(img_err(path, "not an OpenEXR file (bad magic number)")),
        "pfm" => Err(img_err(path, "not a PFM file (bad magic number)")),
        _ => {
            let img = decode_8bit(bytes, path)?;
            let (w, h) = (img.width() as usize, img.height() as usize);
            let data = if matches!(img.color(), image::ColorType::Rgb8 | image::ColorType::Rgba8) {
                // Eight-bit colour: 256 possible values, decoded once each. (Grey images stay
                // on the float path: the crate's grey-to-float conversion rounds differently.)
                let lut = srgb8_to_linear_table();
                img.to_rgb8().pixels().map(|p| Rgb::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize])).collect()
            } else {
                img.to_rgb32f().pixels().map(|p| Rgb::new(Rgb::srgb_to_linear(p[0]), Rgb::srgb_to_linear(p[1]), Rgb::srgb_to_linear(p[2]))).collect()
            };
            Ok(Image::new(w, h, data))
        }
    }
}

/// Read an image as a texture: [`decode_bitmap`] of the file's bytes.
pub fn read_bitmap(path: &Path, raw: bool) -> Result<Bitmap> {
    decode_bitmap(&crate::limits::read_file(path)?, path, raw)
}

/// An image as a texture, decoded as [`decode_image`] does, or with `raw` (Mitsuba's option)
/// with 8-bit codes mapped to [0, 1] as stored, not from sRGB. Eight-bit colour images keep
/// their codes ([`Bitmap::from_8bit`]): lookups then read a quarter of the bytes, and the
/// same values.
pub fn decode_bitmap(bytes: &[u8], path: &Path, raw: bool) -> Result<Bitmap> {
    let float = |img: Image| Bitmap::new(img.width, img.height, img.data);
    if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        return decode_exr(bytes, path).map(float);
    }
    if bytes.starts_with(b"PF") || bytes.starts_with(b"Pf") {
        return decode_pfm(bytes, path).map(float);
    }
    if !raw && matches!(ext(path).as_str(), "exr" | "pfm") {
        // decode_image's error for a file whose name promises a float format.
        return decode_image(bytes, path).map(float);
    }
    let img = decode_8bit(bytes, path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    // Grey images stay on the float path: the crate's grey-to-float conversion rounds differently.
    if matches!(img.color(), image::ColorType::Rgb8 | image::ColorType::Rgba8) {
        let table = if raw { unorm8_table() } else { srgb8_to_linear_table() };
        let codes = img.into_rgb8().pixels().map(|p| [p[0], p[1], p[2], 0]).collect();
        return Ok(Bitmap::from_8bit(w, h, codes, table));
    }
    let data = img
        .to_rgb32f()
        .pixels()
        .map(|p| if raw { Rgb::new(p[0], p[1], p[2]) } else { Rgb::new(Rgb::srgb_to_linear(p[0]), Rgb::srgb_to_linear(p[1]), Rgb::srgb_to_linear(p[2])) })
        .collect();
    Ok(Bitmap::new(w, h, data))
}

/// Each 8-bit code as the `image` crate's conversion to float gives it (code / 255): Mitsuba's
/// `raw` textures.
fn unorm8_table() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let codes = image::RgbImage::from_fn(256, 1, |x, _| image::Rgb([x as u8; 3]));
        let floats = image::DynamicImage::ImageRgb8(codes).to_rgb32f();
        std::array::from_fn(|i| floats.get_pixel(i as u32, 0)[0])
    })
}

/// Linear value of each 8-bit sRGB code, exactly as the per-pixel path would give it (the
/// `image` crate's conversion to float, then [`Rgb::srgb_to_linear`]): a texture's millions
/// of texels then cost a lookup each instead of a `powf`.
fn srgb8_to_linear_table() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let codes = image::RgbImage::from_fn(256, 1, |x, _| image::Rgb([x as u8; 3]));
        let floats = image::DynamicImage::ImageRgb8(codes).to_rgb32f();
        std::array::from_fn(|i| Rgb::srgb_to_linear(floats.get_pixel(i as u32, 0)[0]))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn eight_bit_images_decode_as_the_float_path_does() {
        // Every code in every channel, through a PNG of each 8-bit colour type.
        let rgb = image::RgbImage::from_fn(256, 3, |x, y| image::Rgb([x as u8, (x as u8).wrapping_mul(7), (x as u8) ^ (y as u8 * 85)]));
        for img in [
            image::DynamicImage::ImageRgb8(rgb.clone()),
            image::DynamicImage::ImageRgba8(image::DynamicImage::ImageRgb8(rgb.clone()).to_rgba8()),
            image::DynamicImage::ImageLuma8(image::DynamicImage::ImageRgb8(rgb).to_luma8()),
        ] {
            let mut png = Vec::new();
            img.write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png).unwrap();
            let got = decode_image(&png, Path::new("t.png")).unwrap();
            let want: Vec<Rgb> =
                img.to_rgb32f().pixels().map(|p| Rgb::new(Rgb::srgb_to_linear(p[0]), Rgb::srgb_to_linear(p[1]), Rgb::srgb_to_linear(p[2]))).collect();
            assert_eq!(got.data.len(), want.len());
            for (g, w) in got.data.iter().zip(&want) {
                assert_eq!(g.to_array().map(f32::to_bits), w.to_array().map(f32::to_bits), "{:?}", img.color());
            }
        }
    }

    /// Textures decode to the values `decode_image` gives (or, `raw`, the crate's code / 255),
    /// and 8-bit colour ones keep their codes, whose lookups read those values back.
    #[test]
    fn bitmaps_decode_as_images_do_and_keep_eight_bit_codes() {
        let rgb = image::RgbImage::from_fn(256, 3, |x, y| image::Rgb([x as u8, (x as u8).wrapping_mul(7), (x as u8) ^ (y as u8 * 85)]));
        let rgb16 = image::DynamicImage::ImageRgb8(rgb.clone()).to_rgb16();
        let cases = [
            (image::DynamicImage::ImageRgb8(rgb.clone()), image::ImageFormat::Png, true),
            (image::DynamicImage::ImageRgba8(image::DynamicImage::ImageRgb8(rgb.clone()).to_rgba8()), image::ImageFormat::Png, true),
            (image::DynamicImage::ImageLuma8(image::DynamicImage::ImageRgb8(rgb.clone()).to_luma8()), image::ImageFormat::Png, false),
            (image::DynamicImage::ImageRgb16(rgb16), image::ImageFormat::Png, false),
            (image::DynamicImage::ImageRgb8(rgb), image::ImageFormat::Jpeg, true),
        ];
        for (img, format, eight_bit) in cases {
            let mut file = Vec::new();
            img.write_to(&mut Cursor::new(&mut file), format).unwrap();
            let name = Path::new(if format == image::ImageFormat::Png { "t.png" } else { "t.jpg" });
            let decoded = image::load_from_memory(&file).unwrap().to_rgb32f();
            for raw in [false, true] {
                let got = decode_bitmap(&file, name, raw).unwrap();
                assert_eq!(got.is_8bit(), eight_bit, "{:?} {format:?}", img.color());
                let want: Vec<Rgb> = if raw { decoded.pixels().map(|p| Rgb::new(p[0], p[1], p[2])).collect() } else { decode_image(&file, name).unwrap().data };
                assert_eq!((got.width, got.height), (256, 3));
                let bits = |c: Rgb| c.to_array().map(f32::to_bits);
                for (i, w) in want.iter().enumerate() {
                    assert_eq!(bits(got.data()[i]), bits(*w), "{:?} {format:?} raw {raw}: texel {i}", img.color());
                    assert_eq!(bits(got.texel(i % 256, i / 256)), bits(*w), "{:?} {format:?} raw {raw}: lookup {i}", img.color());
                }
            }
        }
        // Float files are float bitmaps.
        let exr = encode_exr(&test_image(4, 3)).unwrap();
        let got = decode_bitmap(&exr, Path::new("t.exr"), false).unwrap();
        assert!(!got.is_8bit());
        assert_eq!(got.data(), test_image(4, 3).data);
    }

    fn tmp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("svetlo-imgio-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    /// A test image with values over several orders of magnitude, negatives and a gradient.
    fn test_image(w: usize, h: usize) -> Image {
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                Rgb::new(x * 0.37 + 1e-6, y * 1234.5, (x - y) * 0.01 - 0.003)
            })
            .collect();
        Image::new(w, h, data)
    }

    #[test]
    fn exr_round_trip_is_exact() {
        let img = test_image(13, 7);
        let p = tmp("rt.exr");
        write_exr(&p, &img).unwrap();
        assert_eq!(read_exr(&p).unwrap(), img);
        assert_eq!(read_image(&p).unwrap(), img);
    }

    #[test]
    fn exr_half_with_alpha_and_missing_channel() {
        use exr::prelude::{f16, AnyChannel, AnyChannels, FlatSamples, SmallVec, WritableImage};
        // A half-float image with R, B and A but no G: G reads as 0, A is ignored.
        let (w, h) = (5usize, 3usize);
        let r: Vec<f16> = (0..w * h).map(|i| f16::from_f32(i as f32 * 0.5)).collect();
        let b: Vec<f16> = (0..w * h).map(|i| f16::from_f32(-(i as f32))).collect();
        let a: Vec<f16> = vec![f16::from_f32(0.25); w * h];
        let channels = AnyChannels::sort(SmallVec::from_vec(vec![
            AnyChannel::new("R", FlatSamples::F16(r)),
            AnyChannel::new("B", FlatSamples::F16(b)),
            AnyChannel::new("A", FlatSamples::F16(a)),
        ]));
        let image = exr::prelude::Image::from_channels((w, h), channels);
        let p = tmp("half.exr");
        image.write().to_file(&p).unwrap();
        let got = read_image(&p).unwrap();
        assert_eq!((got.width, got.height), (w, h));
        for i in 0..w * h {
            assert_eq!(got.data[i], Rgb::new(i as f32 * 0.5, 0.0, -(i as f32)));
        }
    }

    #[test]
    fn pfm_round_trip_both_endians() {
        let img = test_image(6, 4);
        for big in [false, true] {
            let bytes = encode_pfm(&img, PfmChannels::Rgb, big);
            assert_eq!(&bytes[..3], b"PF\n");
            let back = decode_pfm(&bytes, Path::new("mem.pfm")).unwrap();
            assert_eq!(back, img, "big endian: {big}");
        }
        let p = tmp("rt.pfm");
        write_pfm(&p, &img).unwrap();
        assert_eq!(read_pfm(&p).unwrap(), img);
        assert_eq!(read_image(&p).unwrap(), img);
    }

    #[test]
    fn pfm_layout_is_bottom_to_top_little_endian() {
        // 1x2 image: top pixel 1, bottom pixel 2; the file stores the bottom row first.
        let img = Image::new(1, 2, vec![Rgb::splat(1.0), Rgb::splat(2.0)]);
        let bytes = encode_pfm(&img, PfmChannels::Grey, false);
        let header = b"Pf\n1 2\n-1.0\n";
        assert_eq!(&bytes[..header.len()], header);
        assert_eq!(&bytes[header.len()..header.len() + 4], &2.0f32.to_le_bytes());
        assert_eq!(&bytes[header.len() + 4..], &1.0f32.to_le_bytes());
        let back = decode_pfm(&bytes, Path::new("g.pfm")).unwrap();
        assert_eq!(back, img);
        // Big-endian grey, as another tool would write it, with a different scale magnitude.
        let mut be = b"Pf 1 2 4.0\n".to_vec();
        be.extend_from_slice(&2.0f32.to_be_bytes());
        be.extend_from_slice(&1.0f32.to_be_bytes());
        assert_eq!(decode_pfm(&be, Path::new("g.pfm")).unwrap(), img);
    }

    #[test]
    fn pfm_errors_name_the_file() {
        let p = Path::new("bad.pfm");
        let cases: Vec<Vec<u8>> = vec![
            b"P6\n1 1\n-1\n....".to_vec(),
            b"PF\n2 2\n-1\n\0\0\0\0".to_vec(),
            b"PF\n0 2\n-1\n".to_vec(),
            b"PF\n99999999999 99999999999\n-1\n".to_vec(),
            b"PF\n1 1\n0\n\0\0\0\0\0\0\0\0\0\0\0\0".to_vec(),
            b"PF\n1".to_vec(),
            Vec::new(),
        ];
        for c in cases {
            let e = decode_pfm(&c, p).unwrap_err();
            let msg = e.to_string();
            assert!(msg.starts_with("bad.pfm: "), "{msg}");
        }
    }

    #[test]
    fn png_round_trip_within_quantisation() {
        let data = (0..16 * 4).map(|i| Rgb::new(i as f32 / 63.0, 1.0 - i as f32 / 63.0, 0.5)).collect();
        let img = Image::new(16, 4, data);
        let p = tmp("rt.png");
        write_png(&p, &img).unwrap();
        let back = read_image(&p).unwrap();
        assert_eq!((back.width, back.height), (16, 4));
        for (a, b) in img.data.iter().zip(&back.data) {
            for k in 0..3 {
                // Half an 8-bit step in sRGB is at most ~0.0077 in linear near 1.
                assert!((a[k] - b[k]).abs() < 0.008, "{a:?} vs {b:?}");
            }
        }
        // Out-of-range values clamp.
        let over = Image::new(2, 1, vec![Rgb::new(-1.0, 5.0, f32::NAN), Rgb::splat(1.0)]);
        write_png(&p, &over).unwrap();
        let back = read_image(&p).unwrap();
        assert_eq!(back.data[0], Rgb::new(0.0, 1.0, 0.0));
    }

    #[test]
    fn missing_and_corrupt_files_are_typed_errors() {
        let p = tmp("does-not-exist.exr");
        assert!(matches!(read_image(&p), Err(Error::Io { .. })));
        let p = tmp("garbage.exr");
        std::fs::write(&p, b"not an image at all").unwrap();
        let e = read_image(&p).unwrap_err();
        assert!(e.to_string().contains("garbage.exr"), "{e}");
        // A truncated EXR.
        let good = tmp("trunc-src.exr");
        write_exr(&good, &test_image(32, 32)).unwrap();
        let bytes = std::fs::read(&good).unwrap();
        let p = tmp("trunc.exr");
        std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
        let e = read_image(&p).unwrap_err();
        assert!(e.to_string().contains("trunc.exr"), "{e}");
        assert!(write_image(&tmp("x.tga"), &test_image(2, 2)).is_err());
    }
}
