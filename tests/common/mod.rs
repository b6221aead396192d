//! Helpers shared by the integration tests.
#![allow(dead_code)]

use rbvh::gpu::{Addressing, Context, ContextOptions, Validation};

/// A context with the validation layer on whenever it is installed: any error it reports fails the
/// submission that caused it (see `Context::submit`), and so the test.
/// Where Debian's vulkan-validationlayers (installed by .ci/setup) puts the layer.
const LAYER_MANIFEST: &str = "/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json";

pub fn context() -> Context {
    context_with(Addressing::Auto)
}

/// As [`context`], with the given way for shaders to reach structures.
pub fn context_with(addressing: Addressing) -> Context {
    let ctx = Context::new(&ContextOptions {
        device_name: None,
        validation: Validation::IfInstalled,
        addressing,
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

/// Preset `level` with every triangle a height field can hold sampled (`exact_when_cheaper` off,
/// the paper's rule; the CLI's `--sample-all`, `Q2s`), for the tests whose subject is the height
/// fields on the built-in single meshes: the presets trace their few large triangles exactly
/// where that costs fewer bytes (the cube, cylinder, cone and plane at every level, the torus
/// from Q2, the sphere from Q3, the blob at Q4), and such a test would referee no height field.
pub fn sampled_preset(level: u32) -> rbvh::rbvh::RbvhParams {
    rbvh::rbvh::RbvhParams {
        exact_when_cheaper: false,
        ..rbvh::rbvh::RbvhParams::quality(level).unwrap()
    }
}

/// The built-in plane's oracle: a point on it, its normal and its half extent.
pub fn plane_oracle() -> (glam::Vec3, glam::Vec3, f32) {
    match rbvh::scene::builtin::analytic("plane") {
        Some(rbvh::scene::builtin::Analytic::Plane {
            point,
            normal,
            half_extent,
        }) => (point, normal, half_extent),
        _ => panic!("the built-in plane has no plane oracle"),
    }
}

/// The built-in sphere's oracle: centre, radius and the worst chord error of its tessellation.
pub fn sphere_oracle() -> (glam::Vec3, f32, f32) {
    match rbvh::scene::builtin::analytic("sphere") {
        Some(rbvh::scene::builtin::Analytic::Sphere {
            center,
            radius,
            max_chord_error,
        }) => (center, radius, max_chord_error),
        _ => panic!("the built-in sphere has no sphere oracle"),
    }
}

/// Deterministic pseudo-random numbers in [0, 1): the library's SplitMix64, so tests need no RNG
/// crate.
pub struct Rng(rbvh::random::SplitMix64);

impl Rng {
    /// The stream whose counter starts at `seed`.
    pub fn new(seed: u64) -> Rng {
        Rng(rbvh::random::SplitMix64::new(seed))
    }

    pub fn next_f32(&mut self) -> f32 {
        self.0.next_f32()
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

/// `n` rays from random points around `scene` (0.3 to 1.8 times its half-diagonal from the centre)
/// towards random points inside its bounding sphere's inner half: hits and misses at every angle.
pub fn random_rays(scene: &rbvh::scene::Scene, n: usize, rng: &mut Rng) -> Vec<rbvh::geom::Ray> {
    let b = scene.bounds();
    let (c, r) = (b.center(), 0.5 * b.diagonal());
    (0..n)
        .map(|_| {
            let origin = c + rng.unit_vector() * r * (0.3 + 1.5 * rng.next_f32());
            let target = c + rng.unit_vector() * r * 0.5;
            rbvh::geom::Ray::new(origin, target - origin, 0.0, f32::INFINITY)
        })
        .collect()
}

/// A running comparison of GPU hits with the CPU reference's on the same rays.
#[derive(Debug, Default)]
pub struct Agreement {
    pub total: usize,
    /// Rays one side hits and the other misses.
    pub hit_miss: usize,
    /// Worst relative difference of a shared closest hit's `t`.
    pub worst_t: f32,
}

impl Agreement {
    /// Adds one batch. Hit/miss disagreements are counted (the caller bounds their rate); for
    /// closest hits (`any` false) a hit both report must agree in `t` to 1e-4 relative and in its
    /// normal to 1e-3, or the test fails naming `what` and the ray.
    pub fn add(&mut self, what: &str, gpu: &[rbvh::geom::Hit], cpu: &[rbvh::geom::Hit], any: bool) {
        assert_eq!(gpu.len(), cpu.len(), "{what}: hit counts");
        for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
            self.total += 1;
            if g.is_hit() != c.is_hit() {
                self.hit_miss += 1;
                continue;
            }
            if !g.is_hit() || any {
                continue;
            }
            let rel = (g.t - c.t).abs() / c.t.abs().max(1e-30);
            self.worst_t = self.worst_t.max(rel);
            assert!(rel <= 1e-4, "{what} ray {i}: t GPU {} vs CPU {}", g.t, c.t);
            assert!(
                g.normal().dot(c.normal()) > 1.0 - 1e-3,
                "{what} ray {i}: normals"
            );
        }
    }

    /// The rate of hit/miss disagreements.
    pub fn rate(&self) -> f64 {
        self.hit_miss as f64 / self.total.max(1) as f64
    }
}

/// Runs `check` on every case of a table and fails once, listing every case that failed with its
/// message, rather than stopping at the first: a table-driven test reports the whole table.
pub fn every_case<T>(
    cases: impl IntoIterator<Item = T>,
    mut check: impl FnMut(T) -> Result<(), String>,
) {
    let failures: Vec<String> = cases.into_iter().filter_map(|c| check(c).err()).collect();
    assert!(
        failures.is_empty(),
        "{} case(s) failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// `Ok` when `condition` holds, else the message `why` makes: a case check of [`every_case`].
pub fn ensure(condition: bool, why: impl FnOnce() -> String) -> Result<(), String> {
    if condition {
        Ok(())
    } else {
        Err(why())
    }
}

/// Whether Mesa's RADV is installed, whose null device compiles for AMD GPUs without one
/// (`RADV_FORCE_FAMILY`); where it is not, says that the test is skipped and why, unless
/// `RBVH_REQUIRE_NULL_DEVICE` is set (as `.ci/run` sets it: CI installs RADV through
/// `.ci/setup`), which fails the test instead.
pub fn radv_or_skip() -> bool {
    const MANIFESTS: [&str; 2] = [
        "/usr/share/vulkan/icd.d/radeon_icd.x86_64.json",
        "/usr/share/vulkan/icd.d/radeon_icd.aarch64.json",
    ];
    if MANIFESTS.iter().any(|m| std::path::Path::new(m).exists()) {
        return true;
    }
    let reason = "RADV is not installed (Debian: mesa-vulkan-drivers), so there is no null device";
    assert!(
        std::env::var_os("RBVH_REQUIRE_NULL_DEVICE").is_none(),
        "RBVH_REQUIRE_NULL_DEVICE is set but {reason}"
    );
    eprintln!("skipped: {reason}");
    false
}

/// The hits of `rays` through `tracer` once it has moved its instances (`update_instances`): a
/// fresh upload of `moved` (the same structure after `set_transforms`) hits the same, bit for
/// bit, and not what the tracer hit before (`before`).
pub fn moved_as_fresh(
    ctx: &Context,
    tracer: &rbvh::gpu::Tracer,
    moved: rbvh::structure::Structure,
    rays: &[rbvh::geom::Ray],
    before: &[rbvh::geom::Hit],
) -> Vec<rbvh::geom::Hit> {
    use rbvh::gpu::{Query, Tracer};
    let after = tracer.trace(rays, Query::Closest).unwrap().hits;
    let fresh = Tracer::new(ctx, &moved)
        .unwrap()
        .trace(rays, Query::Closest)
        .unwrap()
        .hits;
    assert_eq!(after, fresh);
    assert_ne!(after, before, "the instances moved");
    after
}

/// Checks that struct `name` of the reflected SPIR-V `r` has the members and byte offsets `rust`
/// (its `#[repr(C)]` mirror's, from `offset_of!`) and is an array element of stride `size`.
pub fn check_struct_layout(
    r: &rbvh::gpu::spirv::Reflection,
    name: &str,
    size: usize,
    rust: &[(&str, usize)],
) {
    let glsl = r
        .structs
        .get(name)
        .unwrap_or_else(|| panic!("struct {name} not in SPIR-V: {:?}", r.structs.keys()));
    let glsl: Vec<(&str, usize)> = glsl
        .iter()
        .map(|(m, o)| (m.as_str(), *o as usize))
        .collect();
    assert_eq!(glsl, rust, "{name}: GLSL member offsets differ from Rust");
    assert_eq!(
        r.array_strides.get(name).copied(),
        Some(size as u32),
        "{name}: array stride"
    );
}

/// `RayCounters`' fields and byte offsets, in order: what `RbvhCounters` (glsl/common.glsl) and the
/// trace shaders' two records (glsl/trace_io.glsl) must mirror.
pub fn ray_counter_fields() -> [(&'static str, usize); 10] {
    use rbvh::probe::RayCounters;
    use std::mem::offset_of;
    [
        ("nodes", offset_of!(RayCounters, nodes)),
        ("leaves", offset_of!(RayCounters, leaves)),
        ("walks", offset_of!(RayCounters, walks)),
        ("cells", offset_of!(RayCounters, cells)),
        ("cells_tested", offset_of!(RayCounters, cells_tested)),
        ("jumps", offset_of!(RayCounters, jumps)),
        ("triangle_leaves", offset_of!(RayCounters, triangle_leaves)),
        ("triangles", offset_of!(RayCounters, triangles)),
        ("instances", offset_of!(RayCounters, instances)),
        ("top_nodes", offset_of!(RayCounters, top_nodes)),
    ]
}
