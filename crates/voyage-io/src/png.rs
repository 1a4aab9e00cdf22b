//! RGBA images as PNG: the rendered frames, screenshots and snapshots voyage writes.

use std::path::Path;

use voyage_core::{Error, Result};

use crate::atomic::write_atomic;

/// The RGBA image (`width` × `height`, row-major, top row first) as PNG bytes; `path` names
/// it in the error.
pub fn encode_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let want = width as u64 * height as u64 * 4;
    if width == 0 || height == 0 || rgba.len() as u64 != want {
        return Err(Error::format(
            path,
            format!(
                "an image of {width}×{height} pixels has {} bytes, not {want}",
                rgba.len()
            ),
        ));
    }
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(rgba, width, height, image::ExtendedColorType::Rgba8)
        .map_err(|e| Error::format(path, format!("cannot encode the image: {e}")))?;
    Ok(png)
}

/// Writes the RGBA image to `path` as PNG, whole or not at all.
pub fn write_png(path: &Path, rgba: &[u8], width: u32, height: u32) -> Result<()> {
    let png = encode_png(path, width, height, rgba)?;
    write_atomic(path, |w| w.write_all(&png))
}
