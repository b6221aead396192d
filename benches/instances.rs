//! Moving 1,000 instances (issue "Instances", target: at most 5 ms to update the transforms,
//! rebuild the top level and upload it): the top level's rebuild alone
//! (`set_transforms`, CPU) and with its upload to the device (`Tracer::update_instances`, which
//! writes the top level's nodes and the instance records and waits), for the exact BVH and the
//! RBVH in two levels. The meshes' trees are built once, before timing. The device is the
//! default one (lavapipe where there is no GPU); without any, the upload is not measured.

use criterion::{criterion_group, criterion_main, Criterion};
use glam::{Mat4, Quat, Vec3};
use rbvh::bvh::InstancedBvh;
use rbvh::gpu::{Context, ContextOptions, Tracer};
use rbvh::rbvh::{InstancedRbvh, RbvhParams};
use rbvh::scene::{Instance, InstancedScene, Scene};
use rbvh::structure::Structure;

/// Instances placed in a 40 × 25 grid.
const INSTANCES: u32 = 1000;

/// The bumpy sphere placed `INSTANCES` times, each turned about y by `phase` plus its own angle.
fn placements(phase: f32) -> Vec<Mat4> {
    (0..INSTANCES)
        .map(|k| {
            let at = Vec3::new((k % 40) as f32 * 2.5, 0.0, (k / 40) as f32 * 2.5);
            let turn = Quat::from_rotation_y(phase + 0.1 * k as f32);
            Mat4::from_scale_rotation_translation(Vec3::splat(0.8), turn, at)
        })
        .collect()
}

fn update(c: &mut Criterion) {
    let scene = InstancedScene {
        name: "bumpy-sphere × 1000".into(),
        meshes: vec![Scene::builtin("bumpy-sphere").expect("built-in scene")],
        instances: placements(0.0)
            .into_iter()
            .map(|transform| Instance { mesh: 0, transform })
            .collect(),
        ..InstancedScene::default()
    };
    let moved = [placements(0.5), placements(1.0)];
    let mut exact = InstancedBvh::build(&scene).expect("two-level exact BVH");
    let mut rbvh =
        InstancedRbvh::build(&scene, &RbvhParams::quality(2).expect("preset")).expect("RBVH");
    let mut group = c.benchmark_group(format!("instance_update ({INSTANCES} instances)"));
    let mut frame = 0usize;
    group.bench_function("exact: set_transforms", |b| {
        b.iter(|| {
            frame += 1;
            exact.set_transforms(&moved[frame % 2]).expect("moved")
        })
    });
    group.bench_function("rbvh: set_transforms", |b| {
        b.iter(|| {
            frame += 1;
            rbvh.set_transforms(&moved[frame % 2]).expect("moved")
        })
    });
    let Ok(ctx) = Context::new(&ContextOptions::default()) else {
        eprintln!("no Vulkan device: the upload is not measured");
        return;
    };
    let mut exact_tracer =
        Tracer::new(&ctx, &Structure::from(exact.clone())).expect("uploaded exact BVH");
    group.bench_function("exact: set_transforms + update_instances", |b| {
        b.iter(|| {
            frame += 1;
            exact.set_transforms(&moved[frame % 2]).expect("moved");
            exact_tracer.update_instances(&exact).expect("uploaded")
        })
    });
    let mut rbvh_tracer = Tracer::new(&ctx, &Structure::from(rbvh.clone())).expect("uploaded RBVH");
    group.bench_function("rbvh: set_transforms + update_instances", |b| {
        b.iter(|| {
            frame += 1;
            rbvh.set_transforms(&moved[frame % 2]).expect("moved");
            rbvh_tracer.update_instances(&rbvh).expect("uploaded")
        })
    });
    group.finish();
}

criterion_group!(benches, update);
criterion_main!(benches);
