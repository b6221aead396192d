//! Step 5 of rasterizing a leaf (see [`super`]): **quantization** of its heights into the packed
//! [`Texel`]s of `layout.rs` — 8-bit codes for a narrow tile, 16-bit ones otherwise (issue "Small
//! and valid at every scale": bytes per texel that fit the surface), the parity of each code
//! telling a sampled height from an extrapolated one.

use glam::Vec3;

use super::{Frame, Tile, NONE};
use crate::rbvh::layout::Texel;

/// Largest quantization step, in texels, of a tile's 8-bit heights (step 5 of the module docs):
/// a tile whose heights span at most 254 such steps (two texels) stores a byte per height instead
/// of two (issue "Small and valid at every scale", bytes per texel that fit the surface). The
/// step is what accuracy allows, measured (`rbvh bench`, default scene and dragon close-up, Q0,
/// Q2 and Q4, 256 × 192): at 1/16 of a texel the default scene's t p99 rose by 14–83% (Q2
/// 0.0217 → 0.0266% of the diagonal), at 1/32 and 1/64 by up to 13% and 4%; at 1/128 every
/// figure of the default scene is unchanged and the dragon's t p99 within 0.4%, its mean within
/// 1.2% (its scanned detail errs far more than any quantum). The paper-scale scene's Q2 then keeps 72% of its texels in
/// 8-bit tiles (89% at 1/64).
pub const NARROW_QUANTUM_TEXELS: f32 = 1.0 / 128.0;

/// Step 5 of the module docs: 8- or 16-bit heights over the tile's own range, origin moved to
/// `h_lo`.
pub(in crate::rbvh) fn quantize(
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    sampled: &[bool],
    normals: &[Vec3],
    covered: u32,
) -> Tile {
    let valid = || {
        height
            .iter()
            .zip(source)
            .filter(|(_, &s)| s != NONE)
            .map(|(&h, _)| h)
    };
    let h_lo = valid().fold(f32::INFINITY, f32::min);
    let h_hi = valid().fold(f32::NEG_INFINITY, f32::max);
    let range = if h_lo <= h_hi {
        h_hi as f64 - h_lo as f64
    } else {
        0.0
    };
    let narrow = range <= 254.0 * f64::from(NARROW_QUANTUM_TEXELS) * f64::from(frame.texel);
    let top = if narrow {
        Texel::NARROW_MAX
    } else {
        u32::from(Texel::MAX_CODE)
    };
    let (h_lo, h_scale) = if h_lo <= h_hi {
        (h_lo, (range / f64::from(top)) as f32)
    } else {
        (0.0, 0.0)
    };
    let texels = height
        .iter()
        .zip(source)
        .zip(sampled)
        .map(|((&h, &s), &sampled)| {
            if s == NONE {
                return Texel::HOLE;
            }
            let q = if h_scale > 0.0 {
                (h as f64 - h_lo as f64) / h_scale as f64
            } else {
                0.0
            };
            let code = if narrow {
                Texel::narrow_code_of(q, sampled)
            } else {
                Texel::code_of(q, sampled)
            };
            Texel::new(code, normals[s as usize])
        })
        .collect();
    Tile {
        frame: Frame {
            origin: frame.origin + h_lo * frame.w,
            ..*frame
        },
        texels,
        h_scale,
        narrow,
        covered,
        sources: Vec::new(),
        exposed: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::tests::{decoded, plain, quantum, square, xy_frame};
    use super::*;

    #[test]
    fn flat_square_is_exact() {
        let frame = xy_frame(8);
        let tile = plain(&square(&frame, 0.0, 8.0, |_, _| 2.0), &frame, 0.01).unwrap();
        assert_eq!(tile.covered, 64);
        assert_eq!(tile.h_scale, 0.0);
        assert_eq!(tile.frame.origin, Vec3::new(0.0, 0.0, 2.0));
        for t in &tile.texels {
            assert_eq!(t.height_code(), 0);
            assert!(t.normal().dot(Vec3::Z) > 0.9999);
        }
    }

    /// Heights spanning up to 254 steps of [`NARROW_QUANTUM_TEXELS`] take 8-bit codes, and err by
    /// at most that step; a span a little larger keeps 16-bit codes.
    #[test]
    fn narrow_tiles_err_by_at_most_their_quantum() {
        let frame = Frame {
            texel: 0.5,
            ..xy_frame(16)
        };
        // Heights over the sample centres 0.5..15.5 of s: a span of 15 · slope world units.
        let span_texels = 254.0 * NARROW_QUANTUM_TEXELS;
        for (span, narrow) in [(0.0, true), (0.5, true), (0.99, true), (1.02, false)] {
            let slope = span * span_texels * frame.texel / 15.0;
            let plane = |s: f32, _: f32| slope * s;
            let tile = plain(&square(&frame, 0.0, 16.0, plane), &frame, 0.01).unwrap();
            assert_eq!(tile.narrow, narrow, "a span of {span} × 254 steps");
            assert!(quantum(&tile) <= NARROW_QUANTUM_TEXELS * frame.texel * 1.0001 || !narrow);
            for k in 0..256usize {
                let want = plane((k % 16) as f32 + 0.5, 0.0);
                let got = decoded(&tile, k, frame.origin);
                assert!((got - want).abs() <= quantum(&tile) + 1e-5, "{span}: {k}");
                let code = u32::from(tile.texels[k].height_code());
                assert!(!narrow || code % Texel::NARROW_STEP == 0, "{span}: {k}");
            }
        }
    }

    #[test]
    fn tilted_plane_is_within_the_quantization_bound() {
        let frame = Frame {
            origin: Vec3::new(10.0, -3.0, 1.0),
            texel: 0.25,
            ..xy_frame(16)
        };
        let plane = |s: f32, t: f32| 0.3 * s + 0.2 * t + 1.0;
        let tile = plain(&square(&frame, 0.0, 16.0, plane), &frame, 0.01).unwrap();
        assert_eq!(tile.covered, 256);
        let bound = quantum(&tile) + 1e-5;
        for j in 0..16 {
            for i in 0..16 {
                let k = j * 16 + i;
                let want = plane(i as f32 + 0.5, j as f32 + 0.5);
                let got = decoded(&tile, k, frame.origin);
                assert!((got - want).abs() <= bound, "({i}, {j}): {got} vs {want}");
            }
        }
        let n = Vec3::new(-0.3 / 0.25, -0.2 / 0.25, 1.0).normalize();
        assert!(tile.texels[0].normal().dot(n) > 0.999);
    }
}
