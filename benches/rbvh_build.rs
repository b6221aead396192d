//! RBVH build time per quality preset Q0…Q4 on the built-in "default" scene (CPU side; tracing
//! speed, memory and error against the exact BVH are what `rbvh bench` measures). Each preset has
//! √2× the sampling rate of the previous one, so this shows what the atlas's doubling texel count
//! costs the builder. The exact BVH's build is in `bvh_build.rs`.

use criterion::{criterion_group, criterion_main, Criterion, SamplingMode};
use rbvh::rbvh::{Rbvh, RbvhParams, QUALITY_NAMES};
use rbvh::scene::Scene;

fn build(c: &mut Criterion) {
    let scene = Scene::builtin("default").expect("built-in scene");
    let mut group = c.benchmark_group(format!(
        "rbvh_build default ({} triangles)",
        scene.triangle_count()
    ));
    // Builds take tens to hundreds of milliseconds: flat sampling keeps 10 samples within the
    // measurement time instead of asking for ever more iterations per sample.
    group.sample_size(10).sampling_mode(SamplingMode::Flat);
    for (level, name) in QUALITY_NAMES.iter().enumerate() {
        let params = RbvhParams::quality(level as u32).expect("preset");
        group.bench_function(*name, |b| {
            b.iter(|| Rbvh::build(&scene, &params).expect("build"))
        });
    }
    group.finish();
}

criterion_group!(benches, build);
criterion_main!(benches);
