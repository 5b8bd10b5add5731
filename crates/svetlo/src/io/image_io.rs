//! Image files: EXR (linear float32, the truth), PNG (sRGB 8-bit, for looking), PFM.

use crate::error::{Error, Result};
use crate::film::Image;
use crate::spectrum::Rgb;
use std::path::Path;

fn img_err(path: &Path, msg: impl std::fmt::Display) -> Error {
    Error::Image { file: path.to_path_buf(), msg: msg.to_string() }
}

pub fn write_exr(path: &Path, img: &Image) -> Result<()> {
    exr::prelude::write_rgb_file(path, img.width, img.height, |x, y| {
        let c = img.get(x, y);
        (c.r, c.g, c.b)
    })
    .map_err(|e| img_err(path, e))
}

/// sRGB-encoded 8-bit PNG, values clamped to [0, 1].
pub fn write_png(path: &Path, img: &Image) -> Result<()> {
    let mut buf = Vec::with_capacity(img.width * img.height * 3);
    for c in &img.data {
        for v in c.to_array() {
            buf.push((Rgb::linear_to_srgb(v).clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
        }
    }
    image::save_buffer(path, &buf, img.width as u32, img.height as u32, image::ColorType::Rgb8).map_err(|e| img_err(path, e))
}

/// Write by extension: .exr, .png or .pfm.
pub fn write_image(path: &Path, img: &Image) -> Result<()> {
    match ext(path).as_str() {
        "exr" => write_exr(path, img),
        "png" => write_png(path, img),
        other => Err(img_err(path, format!("unsupported output format '{other}' (exr, png)"))),
    }
}

fn ext(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase()
}

/// Read an EXR as linear RGB (alpha dropped, missing channels zero).
pub fn read_exr(path: &Path) -> Result<Image> {
    let img = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |res, _| Image::filled(res.width(), res.height(), Rgb::BLACK),
        |img: &mut Image, pos: exr::prelude::Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
            let w = img.width;
            img.data[pos.y() * w + pos.x()] = Rgb::new(r, g, b);
        },
    )
    .map_err(|e| img_err(path, e))?;
    Ok(img.layer_data.channel_data.pixels)
}

/// Read an image by extension. 8-bit formats are decoded from sRGB to linear.
pub fn read_image(path: &Path) -> Result<Image> {
    match ext(path).as_str() {
        "exr" => read_exr(path),
        _ => {
            let dynimg = image::open(path).map_err(|e| img_err(path, e))?;
            let rgb = dynimg.to_rgb32f();
            let (w, h) = (rgb.width() as usize, rgb.height() as usize);
            let data = rgb.pixels().map(|p| Rgb::new(Rgb::srgb_to_linear(p[0]), Rgb::srgb_to_linear(p[1]), Rgb::srgb_to_linear(p[2]))).collect();
            Ok(Image::new(w, h, data))
        }
    }
}
