//! Step 4 of rasterizing a leaf (see [`super`]), its first pass: **dilation**, the paper's crack
//! avoidance (Novák & Dachsbacher 2012: "allow overlaps + dilation filter"). Each hole beside a
//! written sample takes the linear extrapolation of its written 4-neighbours, so that
//! neighbouring leaves overlap and meet without gaps, and planes extend exactly.

use super::{written_at, NONE};

/// Step 4 of the module docs: one dilation pass, reading only the undilated state. Returns the
/// heights, the sources and, per sample, whether it was written before the pass (sampled, not
/// extrapolated: [`Texel::is_sampled`]).
pub(in crate::rbvh) fn dilate(
    height: &[f32],
    source: &[u32],
    res_u: usize,
    res_v: usize,
) -> (Vec<f32>, Vec<u32>, Vec<bool>) {
    let mut out_h = height.to_vec();
    let mut out_s = source.to_vec();
    let sampled = source.iter().map(|&s| s != NONE).collect();
    let at = |i: isize, j: isize| written_at(source, res_u, i as i64, j as i64);
    for j in 0..res_v {
        for i in 0..res_u {
            let k = j * res_u + i;
            if source[k] != NONE {
                continue;
            }
            let (mut sum, mut count, mut first) = (0.0f64, 0u32, NONE);
            for (di, dj) in [(-1isize, 0isize), (1, 0), (0, -1), (0, 1)] {
                let (i, j) = (i as isize, j as isize);
                let Some(k1) = at(i + di, j + dj) else {
                    continue;
                };
                let h1 = height[k1] as f64;
                sum += match at(i + 2 * di, j + 2 * dj) {
                    Some(k2) => 2.0 * h1 - height[k2] as f64,
                    None => h1,
                };
                count += 1;
                if first == NONE {
                    first = source[k1];
                }
            }
            if count > 0 {
                out_h[k] = (sum / count as f64) as f32;
                out_s[k] = first;
            }
        }
    }
    (out_h, out_s, sampled)
}

#[cfg(test)]
mod tests {
    use super::super::tests::{decoded, plain, quantum, square, xy_frame};

    #[test]
    fn dilation_fills_the_ring_and_extrapolates_linearly() {
        let frame = xy_frame(16);
        let plane = |s: f32, t: f32| 0.5 * s - 0.25 * t + 3.0;
        // Samples 4..=11 in each direction are covered (centres 4.5 ..= 11.5).
        let tile = plain(&square(&frame, 4.0, 12.0, plane), &frame, 0.01).unwrap();
        assert_eq!(tile.covered, 64);
        let core = |x: u32| (4..=11).contains(&x);
        let ring = |x: u32| x == 3 || x == 12;
        let bound = quantum(&tile) + 1e-5;
        for j in 0..16 {
            for i in 0..16 {
                let k = (j * 16 + i) as usize;
                let expect = (core(i) && core(j)) || (core(i) && ring(j)) || (ring(i) && core(j));
                assert_eq!(!tile.texels[k].is_hole(), expect, "({i}, {j})");
                assert_eq!(
                    tile.texels[k].is_sampled(),
                    core(i) && core(j),
                    "({i}, {j})"
                );
                if expect {
                    let want = plane(i as f32 + 0.5, j as f32 + 0.5);
                    let got = decoded(&tile, k, frame.origin);
                    assert!((got - want).abs() <= bound, "({i}, {j}): {got} vs {want}");
                }
            }
        }
    }
}
