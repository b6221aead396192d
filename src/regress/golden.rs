//! The golden files: an 8-bit sRGB PNG of the shaded image (`<case>.png`), and the primary hit
//! distances as a one-channel EXR (`<case>_depth.exr`, channel `Z`, +inf on a miss — the `Z` of
//! `rbvh render --exr`, without the colour and normal channels, which would triple its size and
//! which the PNG already covers).
//!
//! Readers report a missing file as `Ok(None)`, since that is an expected state (a case not
//! blessed yet) rather than a broken one, and any other problem as an error naming the file.

use std::io;
use std::path::Path;

use ::exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Layer, LayerAttributes, ReadChannels as _,
    ReadLayers as _, SmallVec, WritableImage,
};
use ::image::ImageFormat;

use crate::geom::Hit;
use crate::io::write_atomically;
use crate::output::Image;
use crate::{Error, Result};

/// An image as the tightly packed 8-bit sRGB bytes a PNG stores, row-major, top row first: the
/// form in which a render and its golden are compared, since it is what anyone looking at the
/// golden sees and what FLIP expects.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgb8 {
    pub width: u32,
    pub height: u32,
    pub bytes: Vec<u8>,
}

impl Rgb8 {
    /// `image` as `crate::output::write_png` stores it (the same sRGB encoder), computed rather
    /// than read back from a written file, so that passing cases write nothing.
    pub fn from_linear(image: &Image) -> Rgb8 {
        Rgb8 {
            width: image.width,
            height: image.height,
            bytes: image
                .pixels
                .iter()
                .flat_map(|p| p.to_array().map(crate::srgb::encode_u8))
                .collect(),
        }
    }

    /// Back to linear RGB, to be shown beside other pictures.
    pub fn to_linear(&self) -> Image {
        let channel = |b: u8| crate::srgb::decode(f32::from(b) / 255.0);
        Image {
            width: self.width,
            height: self.height,
            pixels: self
                .bytes
                .chunks_exact(3)
                .map(|c| glam::Vec3::new(channel(c[0]), channel(c[1]), channel(c[2])))
                .collect(),
        }
    }
}

/// Reads a golden PNG as 8-bit sRGB (any PNG colour type is converted; alpha is dropped).
pub fn read_png(path: &Path) -> Result<Option<Rgb8>> {
    let Some(bytes) = read_if_present(path)? else {
        return Ok(None);
    };
    let image = ::image::load_from_memory_with_format(&bytes, ImageFormat::Png)
        .map_err(|e| Error::parse(path, None, format!("not a readable PNG: {e}")))?
        .into_rgb8();
    Ok(Some(Rgb8 {
        width: image.width(),
        height: image.height(),
        bytes: image.into_raw(),
    }))
}

/// A depth image: one hit distance per pixel, +inf on a miss.
#[derive(Clone, Debug, PartialEq)]
pub struct Depth {
    pub width: u32,
    pub height: u32,
    pub z: Vec<f32>,
}

impl Depth {
    /// The primary hits' distances (`t`, in units of the unit ray directions), +inf on a miss so
    /// that a miss can never pass for a far hit.
    pub fn of_hits(hits: &[Hit], width: u32, height: u32) -> Depth {
        Depth {
            width,
            height,
            z: hits
                .iter()
                .map(|h| if h.is_hit() { h.t } else { f32::INFINITY })
                .collect(),
        }
    }
}

/// Writes `depth` as a one-channel (`Z`, 32-bit float) EXR, losslessly compressed, atomically.
pub fn write_depth(path: &Path, depth: &Depth) -> Result<()> {
    let channel = AnyChannel::new("Z", FlatSamples::F32(depth.z.clone()));
    let layer = Layer::new(
        (depth.width as usize, depth.height as usize),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    let image = ::exr::prelude::Image::from_layer(layer);
    write_atomically(path, |w| {
        image.write().to_buffered(w).map_err(io::Error::other)
    })
}

/// Reads channel `Z` of the first layer of a golden depth EXR (any sample type, as 32-bit float).
pub fn read_depth(path: &Path) -> Result<Option<Depth>> {
    let Some(bytes) = read_if_present(path)? else {
        return Ok(None);
    };
    let image = ::exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(io::Cursor::new(bytes))
        .map_err(|e| Error::parse(path, None, format!("not a readable EXR: {e}")))?;
    let layer = &image.layer_data;
    let z = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.eq("Z"))
        .ok_or_else(|| Error::parse(path, None, "the EXR has no channel Z"))?;
    let (width, height) = (layer.size.width(), layer.size.height());
    let (Ok(width), Ok(height)) = (u32::try_from(width), u32::try_from(height)) else {
        return Err(Error::parse(
            path,
            None,
            format!("{width}×{height} is too large"),
        ));
    };
    Ok(Some(Depth {
        width,
        height,
        z: z.sample_data.values_as_f32().collect(),
    }))
}

/// The file's bytes, or `None` when it does not exist; refused when it is no regular file.
fn read_if_present(path: &Path) -> Result<Option<Vec<u8>>> {
    match std::fs::metadata(path) {
        Ok(_) => crate::io::input::read(path).map(Some),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::io(path, e)),
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::output::write_png;

    #[test]
    fn blessed_goldens_read_back_as_rendered() {
        let dir = tempfile::tempdir().unwrap();
        let image = Image {
            width: 3,
            height: 2,
            pixels: vec![
                Vec3::ZERO,
                Vec3::ONE,
                Vec3::splat(0.5),
                Vec3::new(0.001, 0.2, 7.0),
                Vec3::splat(f32::NAN),
                Vec3::new(0.3, 0.6, 0.9),
            ],
        };
        let png = dir.path().join("x.png");
        write_png(&png, &image).unwrap();
        assert_eq!(read_png(&png).unwrap(), Some(Rgb8::from_linear(&image)));

        let depth = Depth {
            width: 3,
            height: 2,
            z: vec![1.0, f32::INFINITY, 0.0, 1e-7, 3.5e4, 2.25],
        };
        let exr = dir.path().join("x_depth.exr");
        write_depth(&exr, &depth).unwrap();
        assert_eq!(read_depth(&exr).unwrap(), Some(depth));

        assert_eq!(read_png(&dir.path().join("none.png")).unwrap(), None);
        assert_eq!(read_depth(&dir.path().join("none.exr")).unwrap(), None);
        std::fs::write(dir.path().join("bad.png"), b"not a png").unwrap();
        let err = read_png(&dir.path().join("bad.png")).unwrap_err();
        assert!(err.to_string().contains("bad.png"), "{err}");
    }
}
