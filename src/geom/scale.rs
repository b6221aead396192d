//! Scaling by powers of two, which float arithmetic carries exactly: `x · 2^k` rounds nowhere
//! while it stays a normal float, and every sum, product, quotient and square root of such values
//! scales with it. The RBVH builder squares lengths twice over (a triangle's area, its cross
//! product's squared length), so float32 overflows on scenes more than about 2^31 units across
//! and underflows below about 2^-31, where it builds another structure, traces everything exactly
//! or refuses. It builds such a scene scaled by a power of two into the range it is exact in, and
//! scales what it built back (`rbvh::build`): the same structure, scaled, bit for bit.

use std::ops::RangeInclusive;

/// Diagonals of the scenes the RBVH builder builds as they are: within them a scene scaled by a
/// power of two builds the same RBVH scaled (measured on the sphere from 2^-24 to 2^31 units
/// across; a scene's smallest triangles narrow it from below, so the lower end keeps a margin).
pub const NATIVE_DIAGONALS: RangeInclusive<f32> = pow2(-10)..=pow2(20);

/// Texels (world units) an RBVH may have and still be traced: its leaves' axes hold a tangent
/// over the texel, whose square the march takes, within float32's range with a margin. A scene
/// whose texel lies beyond is not rescaled, since no tracer could follow the result.
pub const TRACEABLE_TEXELS: RangeInclusive<f32> = pow2(-50)..=pow2(50);

/// `2^k` as a float32, exactly, for `k` in −126..=127 (a normal float).
pub const fn pow2(k: i32) -> f32 {
    assert!(k >= -126 && k <= 127, "2^k is not a normal float32");
    f32::from_bits(((k + 127) as u32) << 23)
}

/// The power of two `k` that takes `diagonal` into [1, 2) (`diagonal · 2^k`), where the scene lies
/// outside [`NATIVE_DIAGONALS`] and its `texel` within [`TRACEABLE_TEXELS`]; None where it is to
/// be built as it is. (A coordinate far from the rest may still leave float32 once scaled: the
/// builder checks the scaled scene, `rbvh/build/scale.rs`.)
pub fn rescale_exponent(diagonal: f32, texel: f32) -> Option<i32> {
    let outside = diagonal.is_normal() && diagonal > 0.0 && !NATIVE_DIAGONALS.contains(&diagonal);
    // floor(log2(diagonal)), from the float's exponent bits: exact where log2 may round.
    let k = 127 - ((diagonal.to_bits() >> 23) & 0xff) as i32;
    (outside && TRACEABLE_TEXELS.contains(&texel) && (-126..=126).contains(&k)).then_some(k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn powers_of_two_are_exact_and_scenes_outside_get_one() {
        assert_eq!(pow2(0), 1.0);
        assert_eq!(pow2(-3), 0.125);
        assert_eq!(pow2(40), 2f32.powi(40));
        assert_eq!(pow2(-126), f32::MIN_POSITIVE);
        assert_eq!(
            rescale_exponent(3.46, 0.0135),
            None,
            "a unit scene is built as it is"
        );
        for (diagonal, texel) in [(3.5e-12f32, 1.4e-14f32), (3.5e12, 1.4e10), (1.0e-4, 4e-7)] {
            let k = rescale_exponent(diagonal, texel).expect("outside");
            let unit = diagonal * 2f32.powi(k);
            assert!((1.0..2.0).contains(&unit), "{diagonal}: 2^{k} → {unit}");
        }
        assert_eq!(
            rescale_exponent(3.5e-18, 1.4e-20),
            None,
            "its texel is not traceable"
        );
        assert_eq!(rescale_exponent(f32::INFINITY, 1.0), None);
    }
}
