//! Helpers shared by the integration tests.
#![allow(dead_code)]

use rbvh::gpu::{Context, ContextOptions, Validation};

/// A context with the validation layer on whenever it is installed: any error it reports fails the
/// submission that caused it (see `Context::submit`), and so the test.
/// Where Debian's vulkan-validationlayers (installed by .ci/setup) puts the layer.
const LAYER_MANIFEST: &str = "/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json";

pub fn context() -> Context {
    let ctx = Context::new(&ContextOptions {
        device_name: None,
        validation: Validation::IfInstalled,
    })
    .expect("a Vulkan device (lavapipe: apt-get install mesa-vulkan-drivers)");
    if std::path::Path::new(LAYER_MANIFEST).exists() {
        assert!(
            ctx.validation_enabled(),
            "the validation layer is installed but was not enabled"
        );
    }
    ctx
}

/// Deterministic pseudo-random numbers in [0, 1) (SplitMix64), so tests need no RNG crate.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn unit_vector(&mut self) -> glam::Vec3 {
        loop {
            let v = glam::Vec3::new(self.next_f32(), self.next_f32(), self.next_f32()) * 2.0 - 1.0;
            let l = v.length_squared();
            if l > 1e-4 && l <= 1.0 {
                return v / l.sqrt();
            }
        }
    }
}
