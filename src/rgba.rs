//! The 32-bit colour of a texel of [`crate::rbvh::Rbvh::colours`]: red in bits 0–7, green 8–15,
//! blue 16–23, alpha 24–31 (the byte order of an RGBA8 image, read as a little-endian word).
//! RGB are sRGB-encoded, so that 8 bits per channel spend their precision where the eye resolves
//! differences (IEC 61966-2-1), as 8-bit textures do; alpha is linear. In memory everything else
//! is linear: [`pack`] encodes and [`unpack`] decodes.

use glam::Vec4;

use crate::srgb::{decode_rgba8, encode_u8 as srgb_u8};

/// Linear RGBA (each clamped to `[0, 1]`, NaN as 0) → packed RGBA8.
pub fn pack(rgba: Vec4) -> u32 {
    let alpha = if rgba.w.is_nan() {
        0.0
    } else {
        rgba.w.clamp(0.0, 1.0)
    };
    from_bytes([
        srgb_u8(rgba.x),
        srgb_u8(rgba.y),
        srgb_u8(rgba.z),
        (alpha * 255.0).round() as u8,
    ])
}

/// Packed RGBA8 → linear RGBA.
pub fn unpack(word: u32) -> Vec4 {
    decode_rgba8(word.to_le_bytes())
}

/// `src` composited over `dst` (Porter & Duff, "Compositing Digital Images", SIGGRAPH 1984), per
/// byte in integer arithmetic, `(s·a + d·(255 − a) + 127) / 255`, so that `glsl/paint.comp` gets
/// the same bytes: an opaque `src` (a = 255) gives `src` exactly. Colours blend in their sRGB
/// encoding, as paint programs blend 8-bit layers.
pub fn over(src: u32, dst: u32) -> u32 {
    let (s, d) = (src.to_le_bytes(), dst.to_le_bytes());
    let a = u32::from(s[3]);
    let mix = |s: u8, d: u8| ((u32::from(s) * a + u32::from(d) * (255 - a) + 127) / 255) as u8;
    let alpha = ((255 * a + u32::from(d[3]) * (255 - a) + 127) / 255) as u8;
    from_bytes([mix(s[0], d[0]), mix(s[1], d[1]), mix(s[2], d[2]), alpha])
}

/// Four bytes (sRGB RGB, linear alpha) → packed RGBA8.
pub fn from_bytes(rgba: [u8; 4]) -> u32 {
    u32::from_le_bytes(rgba)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn over_is_exact_for_opaque_and_halves_for_half_alpha() {
        let red = from_bytes([255, 0, 0, 255]);
        let blue = from_bytes([0, 0, 255, 255]);
        assert_eq!(over(red, blue), red);
        let half_red = from_bytes([255, 0, 0, 128]);
        assert_eq!(over(half_red, blue), from_bytes([128, 0, 127, 255]));
        assert_eq!(over(from_bytes([9, 9, 9, 0]), blue), blue);
    }

    #[test]
    fn packing_round_trips_codes() {
        for word in [0u32, 0xFFFF_FFFF, 0x8040_20FF, 0x0102_0304] {
            assert_eq!(pack(unpack(word)), word);
        }
        assert_eq!(pack(Vec4::new(1.0, 0.0, 0.0, 1.0)), 0xFF00_00FF);
        assert_eq!(pack(Vec4::splat(f32::NAN)), 0);
    }
}
