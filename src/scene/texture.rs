//! Base-colour textures: decoded once at load time (PNG, JPEG, TGA or BMP through the `image` crate) into
//! 8-bit RGBA, and sampled bilinearly in linear space.
//!
//! Texels stay 8-bit sRGB-encoded in memory (a quarter of the size of linear floats: the damaged
//! helmet's 2048² base colour is 16 MiB, not 64) and are decoded through a 256-entry table when
//! sampled. glTF 2.0 defines `baseColorTexture` as sRGB-encoded (§3.9.2); OBJ's `map_Kd` has no
//! colour space in its specification, and image files for it are sRGB in practice, so both are
//! decoded the same way. Alpha is linear in both.

use std::io::Cursor;
use std::path::Path;

use glam::{Vec2, Vec4};
use image::{DynamicImage, ImageDecoder, ImageFormat, ImageReader, Limits};

use crate::{Error, Result};

/// Largest side of a texture, in texels (the largest 2D image that Vulkan devices commonly take).
pub const MAX_TEXTURE_SIDE: u32 = 16_384;
/// Largest texel count of a texture (2²⁶ texels are 256 MiB as RGBA8): a bound on what an image
/// header may make us allocate, checked before decoding. The `image` crate's own default bound
/// (512 MiB for the decoded buffer) still lets a grey-scale image grow fourfold into RGBA.
pub const MAX_TEXTURE_TEXELS: u64 = 1 << 26;

/// How texture coordinates outside `[0, 1]` wrap (glTF samplers' `wrapS`/`wrapT`; OBJ repeats).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// Tile the image: only the fractional part of a coordinate counts (glTF `REPEAT`, 10497).
    #[default]
    Repeat,
    /// Clamp to the edge texels (glTF `CLAMP_TO_EDGE`, 33071).
    ClampToEdge,
    /// Tile, flipping every other copy (glTF `MIRRORED_REPEAT`, 33648).
    MirroredRepeat,
}

/// A decoded image: `width × height` texels, row-major, top row first; RGB sRGB-encoded, alpha
/// linear.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Where it came from (a file, or a glTF file and image index), for messages.
    pub name: String,
    /// Texels per row, 1..=[`MAX_TEXTURE_SIDE`].
    pub width: u32,
    /// Rows, 1..=[`MAX_TEXTURE_SIDE`].
    pub height: u32,
    /// `width × height` RGBA8 texels, row-major from the top row.
    pub texels: Vec<[u8; 4]>,
}

impl Texture {
    /// Decodes PNG, JPEG, TGA or BMP bytes. The format is sniffed from the bytes; TGA, which has
    /// no signature to sniff (and is common in OBJ datasets, Sibenik's for one), is taken from a
    /// `.tga` name. A failure
    /// is an [`Error::Parse`] naming `file` and saying what `what` (e.g. "image 2") was.
    /// Images larger than [`MAX_TEXTURE_SIDE`] or [`MAX_TEXTURE_TEXELS`] are refused from their
    /// header, before any texel is allocated.
    pub fn decode(bytes: &[u8], file: &Path, what: &str) -> Result<Texture> {
        let fail = |message: String| Error::parse(file, None, format!("{what}: {message}"));
        let undecodable = |e: image::ImageError| fail(format!("cannot decode the image: {e}"));
        let mut reader = ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| fail(format!("cannot decode the image: {e}")))?;
        if reader.format().is_none() && ImageFormat::from_path(file).ok() == Some(ImageFormat::Tga)
        {
            reader.set_format(ImageFormat::Tga);
        }
        let mut limits = Limits::default();
        limits.max_image_width = Some(MAX_TEXTURE_SIDE);
        limits.max_image_height = Some(MAX_TEXTURE_SIDE);
        reader.limits(limits);
        let decoder = reader.into_decoder().map_err(undecodable)?;
        let (width, height) = decoder.dimensions();
        if width == 0 || height == 0 {
            return Err(fail("the image is empty".into()));
        }
        if u64::from(width) * u64::from(height) > MAX_TEXTURE_TEXELS {
            return Err(fail(format!(
                "the image is {width}×{height}: at most {MAX_TEXTURE_TEXELS} texels"
            )));
        }
        let rgba = DynamicImage::from_decoder(decoder)
            .map_err(undecodable)?
            .into_rgba8();
        Ok(Texture {
            name: format!("{} ({what})", file.display()),
            width: rgba.width(),
            height: rgba.height(),
            texels: rgba.pixels().map(|p| p.0).collect(),
        })
    }

    /// Reads and decodes the image file at `path`: a missing file is [`Error::Io`] naming it, a
    /// corrupt one [`Error::Parse`] naming it.
    pub fn load(path: &Path) -> Result<Texture> {
        let bytes = crate::io::input::read(path)?;
        Self::decode(&bytes, path, "texture")
    }

    /// Bilinear sample at `uv` (`(0, 0)` = the top-left corner of the image, texel centres at
    /// `(x + ½) / width`), in linear RGBA. Filtering happens after the sRGB decode, so that
    /// blending two texels averages light, not codes.
    pub fn sample(&self, uv: Vec2, wrap: [Wrap; 2]) -> Vec4 {
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (fx, fy) = if fx.is_finite() && fy.is_finite() {
            (fx, fy)
        } else {
            (0.0, 0.0)
        };
        // `as` saturates and maps NaN to 0; clamping to ±2⁴⁰ keeps `x0 + 1` from overflowing
        // while leaving every texel index reachable (f32 cannot resolve texels beyond 2²⁴ anyway).
        let limit = 1i64 << 40;
        let (x0, y0) = (
            (x0 as i64).clamp(-limit, limit),
            (y0 as i64).clamp(-limit, limit),
        );
        let at = |i: i64, j: i64| {
            let i = wrap_index(i, self.width, wrap[0]);
            let j = wrap_index(j, self.height, wrap[1]);
            linear(self.texels[j * self.width as usize + i])
        };
        let top = at(x0, y0).lerp(at(x0 + 1, y0), fx);
        let bottom = at(x0, y0 + 1).lerp(at(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy)
    }
}

/// Index `i` wrapped into `0..n` (`n` ≥ 1).
fn wrap_index(i: i64, n: u32, wrap: Wrap) -> usize {
    let n = i64::from(n);
    let k = match wrap {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let k = i.rem_euclid(2 * n);
            if k < n {
                k
            } else {
                2 * n - 1 - k
            }
        }
    };
    k as usize
}

/// An 8-bit sRGB-encoded RGB, linear alpha texel as linear RGBA.
pub fn linear(rgba: [u8; 4]) -> Vec4 {
    crate::srgb::decode_rgba8(rgba)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// TGA has no signature: it is decoded when the name says `.tga`, and refused, with a clear
    /// message, when nothing says what it is.
    #[test]
    fn tga_is_decoded_by_its_name() {
        let pixels: [u8; 12] = [255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255];
        let mut bytes = Vec::new();
        image::codecs::tga::TgaEncoder::new(&mut bytes)
            .encode(&pixels, 2, 2, image::ExtendedColorType::Rgb8)
            .unwrap();
        let t = Texture::decode(&bytes, Path::new("wall.tga"), "texture").unwrap();
        assert_eq!((t.width, t.height), (2, 2));
        assert_eq!(
            t.texels,
            vec![
                [255, 0, 0, 255],
                [0, 255, 0, 255],
                [0, 0, 255, 255],
                [255, 255, 255, 255]
            ]
        );
        let e = Texture::decode(&bytes, Path::new("wall.bin"), "texture")
            .unwrap_err()
            .to_string();
        assert!(e.contains("wall.bin") && e.contains("cannot decode"), "{e}");
    }

    fn checker() -> Texture {
        Texture {
            name: "checker".into(),
            width: 2,
            height: 2,
            texels: vec![
                [255, 0, 0, 255],
                [0, 255, 0, 255],
                [0, 0, 255, 255],
                [255, 255, 255, 255],
            ],
        }
    }

    #[test]
    fn texel_centres_sample_exactly_and_wrap() {
        let t = checker();
        let w = [Wrap::Repeat; 2];
        assert_eq!(
            t.sample(Vec2::new(0.25, 0.25), w),
            Vec4::new(1.0, 0.0, 0.0, 1.0)
        );
        assert_eq!(
            t.sample(Vec2::new(0.75, 0.25), w),
            Vec4::new(0.0, 1.0, 0.0, 1.0)
        );
        assert_eq!(
            t.sample(Vec2::new(0.25, 0.75), w),
            Vec4::new(0.0, 0.0, 1.0, 1.0)
        );
        assert_eq!(
            t.sample(Vec2::new(1.25, -0.25), w),
            Vec4::new(0.0, 0.0, 1.0, 1.0)
        );
        // Half way between red and green, in linear light.
        let mid = t.sample(Vec2::new(0.5, 0.25), [Wrap::ClampToEdge; 2]);
        assert!((mid - Vec4::new(0.5, 0.5, 0.0, 1.0)).abs().max_element() < 1e-6);
        assert_eq!(wrap_index(-1, 4, Wrap::MirroredRepeat), 0);
        assert_eq!(wrap_index(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap_index(-3, 4, Wrap::ClampToEdge), 0);
        // Non-finite coordinates sample some texel instead of panicking.
        assert!(t.sample(Vec2::splat(f32::NAN), w).is_finite());
        assert!(t.sample(Vec2::splat(f32::INFINITY), w).is_finite());
    }
}
