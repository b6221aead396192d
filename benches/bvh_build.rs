//! Exact BVH build time on built-in scenes (CPU side; GPU throughput is measured by `rbvh render --stats`).

use criterion::{criterion_group, criterion_main, Criterion};
use rbvh::bvh::Bvh;
use rbvh::scene::Scene;

fn build(c: &mut Criterion) {
    let mut group = c.benchmark_group("exact_bvh_build");
    group.sample_size(10);
    for name in ["sphere", "default"] {
        let scene = Scene::builtin(name).expect("built-in scene");
        group.bench_function(
            format!("{name} ({} triangles)", scene.triangle_count()),
            |b| b.iter(|| Bvh::build(&scene).expect("build")),
        );
    }
    group.finish();
}

criterion_group!(benches, build);
criterion_main!(benches);
