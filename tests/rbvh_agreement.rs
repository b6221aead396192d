//! The GPU RBVH tracer (`glsl/rbvh.glsl`) agrees with the CPU reference caster (`src/rbvh/march.rs`)
//! on the same rays: over 100k rays on several scenes at every quality level, closest and any hit.
//! The two run the same operations in the same order (`precise` in GLSL); what may still differ is
//! the last bit of a division or a `normalize` on the device. So a hit/miss disagreement is
//! allowed only at a rate below 1e-4, a shared hit's `t` agrees to 1e-4 relative, and its
//! normal to 1e-3. The rates are printed.

mod common;

use rbvh::geom::Ray;
use rbvh::gpu::{Query, Tracer};
use rbvh::rbvh::{Rbvh, RbvhParams};
use rbvh::scene::Scene;

fn rays_for(scene: &Scene, side: u32, random: usize, seed: u64) -> Vec<Ray> {
    let mut rays = scene.camera_or_framed(1.0).primary_rays(side, side);
    rays.extend(common::random_rays(scene, random, &mut common::Rng(seed)));
    rays
}

#[test]
fn gpu_and_cpu_rbvh_casters_agree_at_every_level() {
    let ctx = common::context();
    let mut agreement = common::Agreement::default();
    for (k, name) in ["default", "blob", "sphere"].into_iter().enumerate() {
        let scene = Scene::builtin(name).unwrap();
        for level in 0..5 {
            let r = Rbvh::build(&scene, &RbvhParams::quality(level).unwrap()).unwrap();
            let tracer = Tracer::rbvh(&ctx, &r).unwrap();
            let rays = rays_for(&scene, 96, 4000, (k * 5 + level as usize) as u64);
            for (query, any) in [(Query::Closest, false), (Query::Any, true)] {
                let gpu = tracer.trace(&rays, query).unwrap().hits;
                let cpu = r.trace_cpu(&rays, any);
                agreement.add(&format!("{name} Q{level}"), &gpu, &cpu, any);
            }
        }
    }
    let common::Agreement {
        total,
        hit_miss,
        worst_t,
    } = agreement;
    println!(
        "GPU/CPU RBVH agreement: {total} rays, {hit_miss} hit/miss disagreements ({:.2e}), worst relative t difference {worst_t:.2e}",
        agreement.rate()
    );
    assert!(total >= 100_000);
    assert!(agreement.rate() < 1e-4, "{hit_miss} of {total}");
}
