//! Mip chains of base-colour textures, for sampling a texture over an area rather than at a
//! point: the RBVH's colour bake gives each atlas texel the colour of the surface patch it
//! stands for, and at coarse levels that patch can span many texture texels. Point samples there
//! alias (a fine checker turns into noise of its two colours); the mean over the patch does not.
//!
//! The chain is the usual one (Williams 1983, "Pyramidal parametrics"): each level halves the
//! previous one with a 2×2 box filter, averaged in linear light and stored 8-bit sRGB-encoded as
//! the base texture is. Odd sides round up, the last column or row averaging with itself: the
//! levels of an odd-sized texture lean slightly towards its far edges, and its 1×1 level is the
//! texture's mean only for power-of-two sides. Building is sequential on purpose: the bake builds
//! a chain on first need inside a `OnceLock` from rayon workers, and parallel work nested there
//! lets a waiting worker steal a job that waits on the same lock, a deadlock.
//! Sampling is trilinear (bilinear in the two levels around the footprint's level, blended), the
//! isotropic filter of GPU samplers (Vulkan 1.3 §16.6.7, with λ = log2 of the footprint's longer
//! side in texels).

use std::sync::OnceLock;

use glam::{Vec2, Vec4};

use super::texture::{linear, Texture, Wrap};

/// A texture and its halved levels down to 1×1, built once and sampled over footprints.
#[derive(Clone, Debug)]
pub struct MipChain<'a> {
    base: &'a Texture,
    /// Levels 1, 2, …: each half the size of the one before (rounded up), the last 1×1.
    levels: Vec<Texture>,
}

impl<'a> MipChain<'a> {
    /// Builds every level below `base` by 2×2 box filtering in linear space (an odd side repeats
    /// its last texel), RGB re-encoded to the nearest sRGB code.
    pub fn new(base: &'a Texture) -> MipChain<'a> {
        let mut levels: Vec<Texture> = Vec::new();
        loop {
            let above = levels.last().unwrap_or(base);
            if above.width <= 1 && above.height <= 1 {
                break;
            }
            let next = halve(above);
            levels.push(next);
        }
        MipChain { base, levels }
    }

    /// Whether this is the chain of `texture` (the same texture, not an equal one).
    pub fn is_of(&self, texture: &Texture) -> bool {
        std::ptr::eq(self.base, texture)
    }

    /// Number of levels, the base included.
    fn len(&self) -> usize {
        1 + self.levels.len()
    }

    fn level(&self, k: usize) -> &Texture {
        match k {
            0 => self.base,
            k => &self.levels[(k - 1).min(self.levels.len() - 1)],
        }
    }

    /// Linear RGBA over a footprint `footprint` base texels wide centred at `uv`: the base
    /// texture's bilinear sample where the footprint is at most one texel (so fine samples are
    /// exactly [`Texture::sample`]'s), the trilinear blend of the levels around `log2(footprint)`
    /// beyond, and the 1×1 level's mean past the last. A non-finite footprint samples the base.
    pub fn sample(&self, uv: Vec2, wrap: [Wrap; 2], footprint: f32) -> Vec4 {
        let lambda = if footprint.is_finite() && footprint > 1.0 {
            footprint.log2().min((self.len() - 1) as f32)
        } else {
            0.0
        };
        let k = lambda.floor() as usize;
        let fine = self.level(k).sample(uv, wrap);
        let blend = lambda - k as f32;
        if blend > 0.0 && k + 1 < self.len() {
            fine.lerp(self.level(k + 1).sample(uv, wrap), blend)
        } else {
            fine
        }
    }
}

/// One level down: every texel the linear-light mean of the up to 2×2 texels above it.
fn halve(t: &Texture) -> Texture {
    let (w, h) = (t.width.div_ceil(2).max(1), t.height.div_ceil(2).max(1));
    let at = |i: u32, j: u32| {
        let (i, j) = (i.min(t.width - 1), j.min(t.height - 1));
        linear(t.texels[(j * t.width + i) as usize])
    };
    let texels = (0..w * h)
        .map(|k| {
            let (i, j) = (k % w, k / w);
            let sum = at(2 * i, 2 * j)
                + at(2 * i + 1, 2 * j)
                + at(2 * i, 2 * j + 1)
                + at(2 * i + 1, 2 * j + 1);
            let mean = sum * 0.25;
            [
                nearest_code(mean.x),
                nearest_code(mean.y),
                nearest_code(mean.z),
                (mean.w.clamp(0.0, 1.0) * 255.0).round() as u8,
            ]
        })
        .collect();
    Texture {
        name: t.name.clone(),
        width: w,
        height: h,
        texels,
    }
}

/// The 8-bit sRGB code whose linear value is nearest `linear` (clamped to `[0, 1]`; NaN gives
/// 0): a binary search over the midpoints between neighbouring codes' linear values, exact and
/// several times cheaper than the transfer function's power, which a 2048² texture's chain would
/// otherwise evaluate three million times.
fn nearest_code(linear: f32) -> u8 {
    static MIDPOINTS: OnceLock<[f32; 255]> = OnceLock::new();
    let midpoints = MIDPOINTS.get_or_init(|| {
        let value = |c: usize| super::texture::linear([c as u8, 0, 0, 0]).x;
        std::array::from_fn(|c| 0.5 * (value(c) + value(c + 1)))
    });
    // NaN compares false with every midpoint, so it lands on code 0.
    midpoints.partition_point(|&m| m < linear) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A black and white checker of single texels, `side` texels a side.
    fn checker(side: u32) -> Texture {
        Texture {
            name: "checker".into(),
            width: side,
            height: side,
            texels: (0..side * side)
                .map(|k| {
                    let white = (k % side + k / side) % 2 == 0;
                    let c = if white { 255 } else { 0 };
                    [c, c, c, 255]
                })
                .collect(),
        }
    }

    #[test]
    fn nearest_code_inverts_the_decode() {
        for c in 0..=255u8 {
            assert_eq!(nearest_code(linear([c, 0, 0, 0]).x), c);
        }
        assert_eq!(nearest_code(-1.0), 0);
        assert_eq!(nearest_code(2.0), 255);
        assert_eq!(nearest_code(f32::NAN), 0);
        assert_eq!(nearest_code(0.5), crate::srgb::encode_u8(0.5));
    }

    #[test]
    fn levels_halve_down_to_one_texel_and_keep_the_mean() {
        let t = checker(6);
        let chain = MipChain::new(&t);
        // 6 → 3 → 2 → 1.
        assert_eq!(chain.len(), 4);
        assert_eq!(
            (1..4)
                .map(|k| (chain.level(k).width, chain.level(k).height))
                .collect::<Vec<_>>(),
            [(3, 3), (2, 2), (1, 1)]
        );
        // Every 2×2 block of the checker is half white: mid grey in linear light.
        let grey = linear(chain.level(1).texels[0]).x;
        assert!((grey - 0.5).abs() < 0.005, "{grey}");
    }

    #[test]
    fn footprints_of_a_texel_or_less_sample_the_base_exactly() {
        let t = checker(8);
        let chain = MipChain::new(&t);
        let w = [Wrap::Repeat; 2];
        for uv in [Vec2::new(0.0625, 0.0625), Vec2::new(0.3, 0.71)] {
            for footprint in [0.0, 0.5, 1.0, f32::NAN, f32::INFINITY] {
                assert_eq!(
                    chain.sample(uv, w, footprint),
                    t.sample(uv, w),
                    "{footprint}"
                );
            }
        }
    }

    #[test]
    fn wide_footprints_average_the_checker_instead_of_picking_a_square() {
        let t = checker(64);
        let chain = MipChain::new(&t);
        let w = [Wrap::Repeat; 2];
        let (mut darkest, mut brightest) = (1f32, 0f32);
        for k in 0..50 {
            let uv = Vec2::new(k as f32 * 0.0173 + 0.003, k as f32 * 0.0291 + 0.007);
            let point = t.sample(uv, w).x;
            (darkest, brightest) = (darkest.min(point), brightest.max(point));
            let area = chain.sample(uv, w, 8.0).x;
            assert!((area - 0.5).abs() < 0.01, "{uv}: {area}");
        }
        // Point samples of the same places alias: they see single squares.
        assert!(brightest - darkest > 0.5, "{darkest}..{brightest}");
        // A footprint past the whole texture is the texture's mean.
        let all = chain.sample(Vec2::new(0.4, 0.4), w, 1e6).x;
        assert!((all - 0.5).abs() < 0.005, "{all}");
    }
}
