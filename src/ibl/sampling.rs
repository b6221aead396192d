//! The random directions of the IBL integrator, reproducible without any shared state.
//!
//! Each (seed, pixel, sample) triple owns its own short SplitMix64 stream (Steele, Lea & Flood,
//! "Fast splittable pseudorandom number generators", OOPSLA 2014), started at a hash of the
//! triple. So a pixel's `k`-th direction depends on nothing but those three numbers: not on the
//! thread that draws it, the order of the passes, the image size, or which other pixels were hit —
//! which is what makes a render bit-for-bit repeatable and lets two structures (exact and RBVH)
//! be compared with the same random numbers.
//!
//! Directions are cosine-distributed about the surface normal by Malley's method: uniform points
//! on the unit disk, lifted to the hemisphere (Pharr, Jakob & Humphreys, *Physically Based
//! Rendering*, 4th ed., §A.5.3). Their density `cos θ / π` cancels the cosine of the Lambertian
//! reflection integral, see [`mod@super::render`].

use std::f32::consts::TAU;

use glam::Vec3;

/// SplitMix64's increment, ⌊2⁶⁴/φ⌋.
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function (Stafford's "Mix13" variant of MurmurHash3's finalizer): a
/// bijection of `u64` in which every input bit affects every output bit.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A SplitMix64 stream: a counter stepped by `GOLDEN_GAMMA` and passed through `mix64`.
#[derive(Clone, Debug)]
pub struct SampleRng(u64);

impl SampleRng {
    /// The stream of sample `sample` of pixel `pixel` under `seed`. The start is a nested hash
    /// rather than, say, `seed + pixel`, because neighbouring SplitMix states would make one
    /// pixel's second number its neighbour's first.
    pub fn new(seed: u64, pixel: u64, sample: u32) -> SampleRng {
        let inner = mix64(u64::from(sample).wrapping_add(1).wrapping_mul(GOLDEN_GAMMA));
        SampleRng(mix64(seed ^ mix64(pixel ^ inner)))
    }

    /// The next 64 uniformly distributed bits of the stream.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GOLDEN_GAMMA);
        mix64(self.0)
    }

    /// Uniform in `[0, 1)`: the top 24 bits, exactly representable in `f32`.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A cosine-distributed unit direction about the unit `normal` (density `cos θ / π`), by Malley's
/// method from two uniform numbers in `[0, 1)`. Since `u1 < 1`, the lifted component
/// `√(1 − u1)` is positive: the direction always leaves the surface on the normal's side.
pub fn cosine_direction(normal: Vec3, u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let phi = TAU * u2;
    let z = (1.0 - u1).max(0.0).sqrt();
    let (t, b) = normal.any_orthonormal_pair();
    (r * phi.cos() * t + r * phi.sin() * b + z * normal).normalize()
}

/// The cosine-distributed direction of sample `sample` of pixel `pixel` under `seed`.
pub fn sample_direction(normal: Vec3, seed: u64, pixel: u64, sample: u32) -> Vec3 {
    let mut rng = SampleRng::new(seed, pixel, sample);
    let u1 = rng.next_f32();
    let u2 = rng.next_f32();
    cosine_direction(normal, u1, u2)
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
        let first = |seed, pixel, sample| SampleRng::new(seed, pixel, sample).next_u64();
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
        let mut rng = SampleRng::new(1, 2, 3);
        rng.next_u64();
        assert_ne!(rng.next_u64(), first(1, 3, 3));
    }
}
