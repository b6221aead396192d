//! The random directions of the IBL integrator, reproducible without any shared state.
//!
//! Each (seed, pixel, sample) triple owns its own SplitMix64 stream ([`crate::random`]), started
//! at a hash of the triple. So a pixel's `k`-th direction depends on nothing but those three
//! numbers: not on the thread that draws it, the order of the passes, the image size, or which
//! other pixels were hit — which is what makes a render bit-for-bit repeatable and lets two
//! structures (exact and RBVH) be compared with the same random numbers.
//!
//! Directions are cosine-distributed about the surface normal by Malley's method: uniform points
//! on the unit disk, lifted to the hemisphere (Pharr, Jakob & Humphreys, *Physically Based
//! Rendering*, 4th ed., §A.5.3). Their density `cos θ / π` cancels the cosine of the Lambertian
//! reflection integral, see [`mod@super::render`].

use glam::Vec3;

use crate::random::{cosine_direction_from, mix64, SplitMix64, GOLDEN_GAMMA};

/// The stream of sample `sample` of pixel `pixel` under `seed`: a nested hash of the three.
pub fn sample_rng(seed: u64, pixel: u64, sample: u32) -> SplitMix64 {
    let inner = mix64(u64::from(sample).wrapping_add(1).wrapping_mul(GOLDEN_GAMMA));
    SplitMix64::new(mix64(seed ^ mix64(pixel ^ inner)))
}

/// The cosine-distributed direction of sample `sample` of pixel `pixel` under `seed`.
pub fn sample_direction(normal: Vec3, seed: u64, pixel: u64, sample: u32) -> Vec3 {
    cosine_direction_from(normal, &mut sample_rng(seed, pixel, sample))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_are_unit_above_the_surface_with_the_cosine_mean() {
        let n = Vec3::new(0.3, -0.5, 0.8).normalize();
        let count = 20_000u32;
        let mut sum_cos = 0.0f64;
        for s in 0..count {
            let d = sample_direction(n, 11, 5, s);
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert!(d.dot(n) > 0.0, "{d} leaves below the surface");
            sum_cos += f64::from(d.dot(n));
        }
        // E[cos θ] under the density cos θ / π is 2/3; its standard deviation is √(1/18) ≈ 0.24,
        // so the mean's is 0.0017 and 0.01 is six of them.
        let mean = sum_cos / f64::from(count);
        assert!((mean - 2.0 / 3.0).abs() < 0.01, "{mean}");
    }

    #[test]
    fn streams_depend_on_seed_pixel_and_sample_only() {
        let first = |seed, pixel, sample| sample_rng(seed, pixel, sample).next_u64();
        assert_eq!(first(1, 2, 3), first(1, 2, 3));
        let variants = [
            first(1, 2, 3),
            first(2, 2, 3),
            first(1, 3, 3),
            first(1, 2, 4),
        ];
        for (i, a) in variants.iter().enumerate() {
            for b in &variants[i + 1..] {
                assert_ne!(a, b);
            }
        }
        // A pixel's second number is not its neighbour's first.
        let mut rng = sample_rng(1, 2, 3);
        rng.next_u64();
        assert_ne!(rng.next_u64(), first(1, 3, 3));
    }
}
