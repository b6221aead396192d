//! The PNG writer, for pictures meant to be looked at.

use std::io;
use std::path::Path;

use ::image::codecs::png::PngEncoder;
use ::image::{ExtendedColorType, ImageEncoder};

use super::image::{check_writable, Image};
use crate::io::write_atomically;
use crate::srgb;

/// Writes `image` as an 8-bit RGB PNG, converting linear values to sRGB (clamped to `[0, 1]`,
/// NaN as 0), since that is what viewers assume an untagged PNG holds. Written atomically.
pub fn write_png(path: &Path, image: &Image) -> crate::Result<()> {
    check_writable(image)?;
    let bytes: Vec<u8> = image
        .pixels
        .iter()
        .flat_map(|p| p.to_array().map(srgb::encode_u8))
        .collect();
    write_atomically(path, |w| {
        PngEncoder::new(w)
            .write_image(&bytes, image.width, image.height, ExtendedColorType::Rgb8)
            .map_err(io::Error::other)
    })
}
