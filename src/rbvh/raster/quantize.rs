//! Step 5 of rasterizing a leaf (see [`super`]): **quantization** of its heights into the packed
//! [`Texel`]s of `layout.rs` — 8-, 10- or 12-bit codes for a tile whose heights span few enough
//! quanta, 16-bit ones otherwise (issue "Small and valid at every scale": bytes per texel that
//! fit the surface), the parity of each code
//! telling a sampled height from an extrapolated one. The heights are measured from the tile's
//! least-squares plane where that narrows their range ([`Tile::slope`]).

use glam::{DVec3, Vec2, Vec3};

use super::{Frame, Tile, NONE};
use crate::rbvh::layout::{Texel, MIN_PLANE_SLOPE, PACKED_BITS};

/// Largest quantization step, in texels, of a tile's packed heights (step 5 of the module docs):
/// a tile whose heights span at most `2^b − 2` such steps stores `b` bits per height for the
/// narrowest `b` of [`PACKED_BITS`] that holds them — 254 steps (two texels) in 8 bits, 1,022 (8
/// texels) in 10, 4,094 (32 texels) in 12 — instead of 16 (issue "Small and valid at every
/// scale", bytes per texel that fit the surface). The
/// step is what accuracy allows, measured (`rbvh bench`, default scene and dragon close-up, Q0,
/// Q2 and Q4, 256 × 192): at 1/16 of a texel the default scene's t p99 rose by 14–83% (Q2
/// 0.0217 → 0.0266% of the diagonal), at 1/32 and 1/64 by up to 13% and 4%; at 1/128 every
/// figure of the default scene is unchanged and the dragon's t p99 within 0.4%, its mean within
/// 1.2% (its scanned detail errs far more than any quantum). The paper-scale scene's Q2 then keeps 72% of its texels in
/// 8-bit tiles (89% at 1/64).
pub const NARROW_QUANTUM_TEXELS: f32 = 1.0 / 128.0;

/// Step 5 of the module docs: packed or 16-bit heights over the tile's own range, measured from its
/// plane where that narrows the range ([`plane_slope`]), origin moved to the lowest.
pub(in crate::rbvh) fn quantize(
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    sampled: &[bool],
    normals: &[Vec3],
    covered: u32,
) -> Tile {
    let res_u = frame.res_u.max(1) as usize;
    let centre = |k: usize| DVec3::new((k % res_u) as f64 + 0.5, (k / res_u) as f64 + 0.5, 0.0);
    let residual = |slope: Vec2, k: usize| {
        let c = centre(k);
        height[k] as f64 - f64::from(slope.x) * c.x - f64::from(slope.y) * c.y
    };
    let range_over = |slope: Vec2| {
        let (lo, hi) = (0..height.len())
            .filter(|&k| source[k] != NONE)
            .map(|k| residual(slope, k))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| {
                (lo.min(r), hi.max(r))
            });
        (lo, if lo <= hi { hi - lo } else { 0.0 })
    };
    // The plane is kept where it narrows the range by a narrow quantum or more (less would not
    // change a tile's format) and its steeper slope is one the record tells from none
    // (`MIN_PLANE_SLOPE`, texels a texel).
    let fitted = plane_slope(height, source, res_u);
    let quantum = f64::from(NARROW_QUANTUM_TEXELS) * f64::from(frame.texel);
    let steep_enough = fitted.abs().max_element() >= MIN_PLANE_SLOPE * frame.texel;
    let (level, over_plane) = (range_over(Vec2::ZERO), range_over(fitted));
    let (slope, (h_lo, range)) = if steep_enough && over_plane.1 + quantum <= level.1 {
        (fitted, over_plane)
    } else {
        (Vec2::ZERO, level)
    };
    let h_lo = if h_lo.is_finite() { h_lo as f32 } else { 0.0 };
    let bits = PACKED_BITS
        .into_iter()
        .rev()
        .find(|&b| range <= f64::from((1u32 << b) - 2) * quantum)
        .unwrap_or(16);
    let h_scale = (range / f64::from(Texel::top(bits))) as f32;
    let texels = (0..height.len())
        .zip(source)
        .zip(sampled)
        .map(|((k, &s), &sampled)| {
            if s == NONE {
                return Texel::HOLE;
            }
            let q = if h_scale > 0.0 {
                (residual(slope, k) - h_lo as f64) / h_scale as f64
            } else {
                0.0
            };
            Texel::new(Texel::code_of(q, sampled, bits), normals[s as usize])
        })
        .collect();
    Tile {
        frame: Frame {
            origin: frame.origin + h_lo * frame.w,
            ..*frame
        },
        texels,
        h_scale,
        slope,
        bits,
        covered,
        sources: Vec::new(),
        exposed: Vec::new(),
    }
}

/// The slopes `(a, b)` of the least-squares plane `h ≈ c + a·s + b·t` through the valid heights
/// over their sample centres `(s, t) = (i + ½, j + ½)`, in world height per texel, rounded to f32
/// (what [`Tile::slope`] and the record keep, so that the codes are made from the plane the
/// tracers decode). Zero where the samples do not determine a plane (fewer than three, or all on
/// a line). A plane per tile, not per block: the tile's record carries it for free, sheared into
/// its height axis, where a block's would cost bytes (docs/paper-scale.md, "What smaller units of
/// 8-bit heights would keep").
fn plane_slope(height: &[f32], source: &[u32], res_u: usize) -> Vec2 {
    let valid: Vec<(f64, f64, f64)> = (0..height.len())
        .filter(|&k| source[k] != NONE)
        .map(|k| {
            let (i, j) = (k % res_u, k / res_u);
            (i as f64 + 0.5, j as f64 + 0.5, f64::from(height[k]))
        })
        .collect();
    let n = valid.len() as f64;
    if valid.len() < 3 {
        return Vec2::ZERO;
    }
    let mean = valid
        .iter()
        .fold(DVec3::ZERO, |m, &(s, t, h)| m + DVec3::new(s, t, h) / n);
    let (mut ss, mut tt, mut st, mut sh, mut th) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(s, t, h) in &valid {
        let (s, t, h) = (s - mean.x, t - mean.y, h - mean.z);
        (ss, tt, st, sh, th) = (ss + s * s, tt + t * t, st + s * t, sh + s * h, th + t * h);
    }
    // Samples on one line (or one point) determine no plane (NaN sums neither).
    let det = ss * tt - st * st;
    if det.partial_cmp(&(1e-9 * ss * tt)) != Some(std::cmp::Ordering::Greater) {
        return Vec2::ZERO;
    }
    let slope = Vec2::new(
        ((sh * tt - th * st) / det) as f32,
        ((th * ss - sh * st) / det) as f32,
    );
    if slope.is_finite() {
        slope
    } else {
        Vec2::ZERO
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::tests::{decoded, plain, quantum, square, world_sample, xy_frame};
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

    /// A roof over `frame`'s `[0, 16]²` texels: heights `rise · |s − 8|` (world units per texel
    /// of `s`), two rectangles of two triangles each. Its least-squares plane over the sample
    /// centres is level, so the plane takes nothing off its range.
    fn roof(frame: &Frame, rise: f32) -> Vec<[Vec3; 3]> {
        let p = |s: f32, t: f32| {
            frame.origin
                + s * frame.texel * frame.u
                + t * frame.texel * frame.v
                + rise * (s - 8.0).abs() * frame.w
        };
        let rect = |a: f32, b: f32| {
            [
                [p(a, 0.0), p(b, 0.0), p(b, 16.0)],
                [p(a, 0.0), p(b, 16.0), p(a, 16.0)],
            ]
        };
        [rect(0.0, 8.0), rect(8.0, 16.0)].concat()
    }

    /// Heights spanning up to `2^b − 2` steps of [`NARROW_QUANTUM_TEXELS`] over the tile's plane
    /// take `b`-bit codes for the narrowest `b` of [`PACKED_BITS`] that holds them, and err by at
    /// most that step; a span past 4,094 steps keeps 16-bit codes.
    #[test]
    fn packed_tiles_err_by_at_most_their_quantum() {
        let frame = Frame {
            texel: 0.5,
            ..xy_frame(16)
        };
        // The roof over the sample centres 0.5..15.5 of s spans 7 · rise world units.
        for (steps, bits) in [
            (0.0, 8),
            (127.0, 8),
            (251.0, 8),
            (259.0, 10),
            (1010.0, 10),
            (1035.0, 12),
            (4050.0, 12),
            (4150.0, 16),
        ] {
            let rise = steps * NARROW_QUANTUM_TEXELS * frame.texel / 7.0;
            let tile = plain(&roof(&frame, rise), &frame, 0.01).unwrap();
            assert_eq!(tile.bits, bits, "a span of {steps} steps");
            assert_eq!(tile.slope, Vec2::ZERO, "a span of {steps} steps");
            assert!(
                quantum(&tile) <= NARROW_QUANTUM_TEXELS * frame.texel * 1.0001 || bits == 16,
                "a span of {steps} steps"
            );
            for k in 0..256usize {
                let want = rise * ((k % 16) as f32 + 0.5 - 8.0).abs();
                let got = decoded(&tile, k, frame.origin);
                assert!((got - want).abs() <= quantum(&tile) + 1e-5, "{steps}: {k}");
                assert!(
                    Texel::fits(tile.texels[k].height_code(), bits),
                    "{steps}: {k}"
                );
            }
        }
    }

    /// A tilted plane spanning several texels is measured from its own plane: its heights are
    /// 8-bit codes, within the narrow quantum of the plane, and the record's sheared height row
    /// and [`GpuHeightfield::grid`] map each sample to the same point as the tile.
    #[test]
    fn a_tilted_plane_is_measured_from_its_plane() {
        let frame = Frame {
            origin: Vec3::new(3.0, -2.0, 0.5),
            texel: 0.25,
            ..xy_frame(16)
        };
        // 0.3 and 0.2 texels of height a texel: 7.5 texels of range over the tile.
        let plane = |s: f32, t: f32| (0.3 * s - 0.2 * t) * frame.texel + 1.0;
        let tile = plain(&square(&frame, 0.0, 16.0, plane), &frame, 0.01).unwrap();
        assert_eq!(tile.bits, 8);
        assert!(
            (tile.slope - Vec2::new(0.3, -0.2) * frame.texel).length() < 1e-5,
            "{}",
            tile.slope
        );
        assert!(quantum(&tile) <= NARROW_QUANTUM_TEXELS * frame.texel * 1.0001);
        let record = tile.heightfield(0);
        let grid = record.grid();
        assert!((grid.axis_w - frame.w).length() < 1e-6);
        for j in 0..16 {
            for i in 0..16 {
                let k = (j * 16 + i) as usize;
                let want = plane(i as f32 + 0.5, j as f32 + 0.5);
                let got = decoded(&tile, k, frame.origin);
                assert!(
                    (got - want).abs() <= quantum(&tile) + 1e-5,
                    "({i}, {j}): {got} vs {want}"
                );
                let code = tile.texels[k].height_code();
                let p = world_sample(&tile, i, j);
                assert!((grid.point(i, j, code) - p).length() < 1e-5, "({i}, {j})");
                let f = record.to_frame(p);
                let h = f32::from(code) * tile.h_scale;
                let expected = Vec3::new(i as f32 + 0.5, j as f32 + 0.5, h);
                assert!(
                    (f - expected).length() < 1e-4,
                    "({i}, {j}): {f} vs {expected}"
                );
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
