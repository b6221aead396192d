//! Reproducible random numbers without shared state, for the secondary rays ([`crate::rays`]) and
//! the image-based lighting ([`crate::ibl`]): each ray or sample owns a short SplitMix64 stream
//! (Steele, Lea & Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014) started
//! at a hash of what identifies it, so a direction depends on nothing but those numbers — not on
//! threads, order, image size or which other rays exist.
//!
//! Cosine-distributed directions use Malley's method: uniform points on the unit disk lifted to
//! the hemisphere (Pharr, Jakob & Humphreys, *Physically Based Rendering*, 4th ed., §A.5.3).

use std::f32::consts::TAU;

use glam::Vec3;

/// SplitMix64's increment, ⌊2⁶⁴/φ⌋.
pub const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function (Stafford's "Mix13" variant of MurmurHash3's finalizer): a
/// bijection of `u64` in which every input bit affects every output bit. Callers also hash the
/// identity of a stream with it, nested, rather than adding indices to a seed: neighbouring
/// SplitMix states would make one stream's second number its neighbour's first.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A SplitMix64 stream: a counter stepped by [`GOLDEN_GAMMA`] and passed through [`mix64`].
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// The stream whose counter starts at `state` (already a hash of the stream's identity).
    pub fn new(state: u64) -> SplitMix64 {
        SplitMix64(state)
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

/// [`cosine_direction`] from the next two numbers of `rng`.
pub fn cosine_direction_from(normal: Vec3, rng: &mut SplitMix64) -> Vec3 {
    let u1 = rng.next_f32();
    let u2 = rng.next_f32();
    cosine_direction(normal, u1, u2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stream_is_splitmix64() {
        // The first outputs of SplitMix64 seeded with 0 (Vigna's reference splitmix64.c).
        let mut rng = SplitMix64::new(0);
        assert_eq!(rng.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(rng.next_u64(), 0x6E78_9E6A_A1B9_65F4);
    }

    #[test]
    fn cosine_directions_are_unit_in_the_hemisphere_with_cosine_mean() {
        let n = Vec3::new(0.3, -0.5, 0.8).normalize();
        let mut rng = SplitMix64::new(mix64(7));
        let count = 20_000;
        let mut sum_cos = 0.0f64;
        for _ in 0..count {
            let d = cosine_direction_from(n, &mut rng);
            assert!((d.length() - 1.0).abs() < 1e-5);
            let c = d.dot(n);
            assert!(c > 0.0, "{d} leaves below the surface");
            sum_cos += f64::from(c);
        }
        // E[cos θ] under a cosine distribution is 2/3.
        let mean = sum_cos / count as f64;
        assert!((mean - 2.0 / 3.0).abs() < 0.01, "{mean}");
    }
}
