//! The in-memory image every visualisation produces and every writer takes.

use glam::Vec3;

use crate::Error;

/// A linear-RGB image, row-major with the top row first (pixel `(x, y)` is
/// `pixels[y * width + x]`), the order in which the camera emits its primary rays.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels; at least 1 for the writers.
    pub width: u32,
    /// Height in pixels; at least 1 for the writers.
    pub height: u32,
    /// Linear RGB values (not sRGB-encoded, not clamped), `width × height` of them.
    pub pixels: Vec<Vec3>,
}

/// The number of pixels of a `width × height` image, or an error when it does not fit in memory
/// indices.
pub(crate) fn pixel_count(width: u32, height: u32) -> crate::Result<usize> {
    usize::try_from(u64::from(width) * u64::from(height))
        .map_err(|_| Error::param("image size", format!("{width}×{height} pixels is too many")))
}

/// Checks that a per-pixel input (`what`: "rays", "hits", ...) has one entry per pixel, since a
/// mismatch means the buffers belong to different images and every pixel would be misplaced.
pub(crate) fn check_per_pixel(
    what: &str,
    len: usize,
    width: u32,
    height: u32,
) -> crate::Result<()> {
    let pixels = pixel_count(width, height)?;
    if len == pixels {
        Ok(())
    } else {
        Err(Error::param(
            what,
            format!("{len} {what} for a {width}×{height} image, which has {pixels} pixels"),
        ))
    }
}

/// Checks an image about to be written: the file formats cannot hold an empty image, and the
/// fields are public, so a caller may have built one whose pixel count disagrees with its size.
pub(crate) fn check_writable(image: &Image) -> crate::Result<()> {
    if image.width == 0 || image.height == 0 {
        return Err(Error::param(
            "image size",
            format!(
                "{}×{} is empty; images need at least one pixel",
                image.width, image.height
            ),
        ));
    }
    check_per_pixel("pixels", image.pixels.len(), image.width, image.height)
}

/// `pictures` left to right with `gap` black pixels between them, top-aligned; shorter pictures
/// are padded with black below. For comparisons that a viewer takes in at a glance. Fails with
/// [`Error::InvalidParameter`] when a picture's pixel count disagrees with its size (the fields
/// are public) or the result would be wider than `u32` counts.
pub fn side_by_side(pictures: &[&Image], gap: u32) -> crate::Result<Image> {
    for picture in pictures {
        check_per_pixel(
            "pixels",
            picture.pixels.len(),
            picture.width,
            picture.height,
        )?;
    }
    let height = pictures.iter().map(|p| p.height).max().unwrap_or(0);
    let too_wide = || Error::param("gap", "the pictures side by side are wider than 2³² pixels");
    let gaps = (pictures.len() as u32)
        .saturating_sub(1)
        .checked_mul(gap)
        .ok_or_else(too_wide)?;
    let width = pictures
        .iter()
        .try_fold(gaps, |sum, p| sum.checked_add(p.width))
        .ok_or_else(too_wide)?;
    let mut pixels = vec![Vec3::ZERO; pixel_count(width, height)?];
    let mut left = 0usize;
    for picture in pictures {
        for (y, row) in picture
            .pixels
            .chunks(picture.width.max(1) as usize)
            .enumerate()
        {
            let start = y * width as usize + left;
            pixels[start..start + row.len()].copy_from_slice(row);
        }
        left += picture.width as usize + gap as usize;
    }
    Ok(Image {
        width,
        height,
        pixels,
    })
}
