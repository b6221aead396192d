//! The sRGB transfer function (IEC 61966-2-1), both ways: images are linear in memory, PNGs are
//! sRGB-encoded, and colour maps are published as sRGB values.

use std::sync::OnceLock;

use glam::Vec4;

/// Linear `[0, 1]` → sRGB-encoded `[0, 1]`. Out-of-range values are clamped, and NaN becomes 0,
/// so that a stray invalid pixel shows as black instead of poisoning the conversion.
pub(crate) fn encode(linear: f32) -> f32 {
    let c = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB-encoded `[0, 1]` → linear, clamping like [`encode`].
pub(crate) fn decode(encoded: f32) -> f32 {
    let c = if encoded.is_nan() {
        0.0
    } else {
        encoded.clamp(0.0, 1.0)
    };
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear `[0, 1]` → the nearest 8-bit sRGB code.
pub(crate) fn encode_u8(linear: f32) -> u8 {
    // `encode` returns [0, 1], so the rounded product is in [0, 255].
    (encode(linear) * 255.0).round() as u8
}

/// An 8-bit sRGB-encoded RGB, linear alpha texel as linear RGBA: how textures (`scene`) and
/// packed texel colours ([`crate::rgba`]) decode, through one table of the 256 codes.
pub(crate) fn decode_rgba8(rgba: [u8; 4]) -> Vec4 {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    let table = TABLE.get_or_init(|| std::array::from_fn(|c| decode(c as f32 / 255.0)));
    Vec4::new(
        table[rgba[0] as usize],
        table[rgba[1] as usize],
        table[rgba[2] as usize],
        rgba[3] as f32 / 255.0,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values_and_round_trip() {
        assert_eq!(encode_u8(0.0), 0);
        assert_eq!(encode_u8(1.0), 255);
        assert_eq!(encode_u8(0.5), 188);
        assert_eq!(encode_u8(f32::NAN), 0);
        assert_eq!(encode_u8(7.0), 255);
        for i in 0..=100 {
            let x = i as f32 / 100.0;
            assert!((decode(encode(x)) - x).abs() < 1e-5, "{x}");
        }
    }
}
