//! Structures reached through buffer device addresses (`glsl/*_bda.comp`, src/gpu/addressing.rs)
//! trace and paint exactly as bound ones do, and an atlas larger than `maxStorageBufferRange`
//! (128 MiB on lavapipe) is traced and painted through them instead of being refused.

mod common;

use glam::Vec3;
use rbvh::bvh::{Bvh, LEAF_BIT};
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{Addressing, Painter, Query, Reach, Tracer};
use rbvh::lod::{Cones, Lod, LodParams, RayCone, LOD_BIT};
use rbvh::rbvh::{Rbvh, RbvhParams};
use rbvh::scene::Scene;
use rbvh::structure::Structure;
use rbvh::surface::Brush;
use rbvh::Error;
use std::sync::Arc;

/// Fails, naming the first ray that differs, unless both traces gave bit-identical hits.
fn assert_identical(what: &str, a: &[Hit], b: &[Hit]) {
    assert_eq!(a.len(), b.len(), "{what}: hit counts");
    let words = |h: &Hit| -> [u32; 8] { bytemuck::cast(*h) };
    if let Some(i) = (0..a.len()).find(|&i| words(&a[i]) != words(&b[i])) {
        panic!("{what}: ray {i} differs: {:?} vs {:?}", a[i], b[i]);
    }
}

/// Cones from a point to 96 texels wide, so that LOD selects coarse nodes for some rays only.
fn cones(rays: &[Ray], texel: f32) -> Vec<RayCone> {
    (0..rays.len())
        .map(|i| RayCone {
            width: texel * 16.0 * (i % 7) as f32,
            spread: 0.0,
        })
        .collect()
}

#[test]
fn every_tracer_gives_identical_hits_through_device_addresses() {
    let bound = common::context_with(Addressing::Bindings);
    let addressed = common::context_with(Addressing::DeviceAddress);
    let scene = Scene::load("default").unwrap();
    let rays = common::random_rays(&scene, 20_000, &mut common::Rng::new(7));
    let exact = Structure::from(Bvh::build(&scene).unwrap());
    let rbvh = Arc::new(Rbvh::build(&scene, &RbvhParams::quality(2).unwrap()).unwrap());
    let with_lod = Structure::with_lod(
        rbvh.clone(),
        Lod::build(&rbvh, &LodParams::default()).unwrap(),
    );
    let lod = with_lod.lod().unwrap();
    let cones = cones(&rays, rbvh.texel_size);
    let plain = Structure::from(rbvh.clone());
    for query in [Query::Closest, Query::Any] {
        let pairs = [
            (
                "exact",
                Tracer::new(&bound, &exact).unwrap(),
                Tracer::new(&addressed, &exact).unwrap(),
            ),
            (
                "rbvh",
                Tracer::new(&bound, &plain).unwrap(),
                Tracer::new(&addressed, &plain).unwrap(),
            ),
        ];
        for (what, b, a) in &pairs {
            assert_eq!(b.reach(), Reach::Bindings);
            assert_eq!(a.reach(), Reach::DeviceAddresses);
            let hb = b.trace_with(&rays, Cones::None, query, true).unwrap();
            let ha = a.trace_with(&rays, Cones::None, query, true).unwrap();
            assert!(hb.hits.iter().any(Hit::is_hit), "{what}: no hits at all");
            assert_identical(&format!("{what} {query:?}"), &hb.hits, &ha.hits);
            assert_eq!(hb.counters, ha.counters, "{what} {query:?}: counters");
        }
        let b = Tracer::new(&bound, &with_lod).unwrap();
        let a = Tracer::new(&addressed, &with_lod).unwrap();
        assert_eq!(a.reach(), Reach::DeviceAddresses);
        let hb = b.trace_with(&rays, &cones, query, true).unwrap();
        let ha = a.trace_with(&rays, &cones, query, true).unwrap();
        assert_identical(&format!("LOD {query:?}"), &hb.hits, &ha.hits);
        assert_eq!(hb.counters, ha.counters, "LOD {query:?}: counters");
        let any = query == Query::Any;
        let cpu = rbvh.trace_cpu_lod(lod, &rays, &cones, any).unwrap();
        let mut agreement = common::Agreement::default();
        agreement.add("LOD through addresses vs CPU", &ha.hits, &cpu, any);
        assert_eq!(agreement.hit_miss, 0, "{agreement:?}");
        let coarse = ha
            .hits
            .iter()
            .filter(|h| h.is_hit() && h.id & LOD_BIT != 0)
            .count();
        assert!(
            coarse > 0,
            "the cones selected no coarse node: the LOD arrays went unread"
        );
    }
    bound.check_validation().unwrap();
    addressed.check_validation().unwrap();
}

#[test]
fn painting_through_device_addresses_matches_the_cpu_reference() {
    let ctx = common::context_with(Addressing::DeviceAddress);
    // Every triangle sampled: the presets trace the cube's faces exactly, with no texels to paint.
    let mut r = Rbvh::build(&Scene::load("cube").unwrap(), &common::sampled_preset(2)).unwrap();
    let brushes = [
        Brush::new(Vec3::new(1.0, 1.0, 0.1), 0.3, 0xFF00_00FF),
        Brush::new(Vec3::new(-1.0, 0.2, 0.5), 0.4, 0x80FF_0000),
    ];
    let mut painter = Painter::new(&ctx, &r).unwrap();
    assert_eq!(painter.reach(), Reach::DeviceAddresses);
    painter.paint(&brushes).unwrap();
    let gpu = painter.colours().unwrap();
    assert!(r.paint_cpu(&brushes) > 0);
    assert_eq!(&gpu, r.colours.as_ref().unwrap());
    ctx.check_validation().unwrap();
}

/// A 2×2 square at `texels_per_diagonal` 10000: about 53M texels, flat, so 8-bit heights with
/// their normals: a 160 MB atlas on the device. Every triangle sampled: the presets would trace
/// its two triangles exactly, with no atlas at all.
fn big_square() -> Rbvh {
    let mut scene = Scene::new("big square");
    scene.push_object(
        "square",
        &[
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(-1.0, 0.0, 1.0),
        ],
        &[[0, 1, 2], [0, 2, 3]],
    );
    let params = RbvhParams {
        texels_per_diagonal: 10000.0,
        ..common::sampled_preset(0)
    };
    Rbvh::build(&scene, &params).unwrap()
}

#[test]
fn an_atlas_over_the_storage_buffer_range_is_traced_and_painted_through_device_addresses() {
    let ctx = common::context();
    let range = ctx.limits().max_storage_buffer_range;
    let r = Arc::new(big_square());
    let atlas_bytes = r.atlas_bytes();
    assert!(
        atlas_bytes > 100 << 20,
        "the square's atlas is {atlas_bytes} B"
    );
    if atlas_bytes <= range {
        // A device whose bindings reach this far (desktop GPUs: 4 GiB) needs no addresses here.
        eprintln!(
            "maxStorageBufferRange {range} B holds the {atlas_bytes} B atlas: nothing to test"
        );
        return;
    }
    assert!(ctx.limits().buffer_device_address, "lavapipe has them");

    // Bindings alone cannot hold it: a clear error naming the array and the limit.
    let bound = common::context_with(Addressing::Bindings);
    match Tracer::new(&bound, &Structure::from(r.clone())) {
        Err(Error::DeviceLimit {
            resource, limit, ..
        }) => {
            assert_eq!(resource, "RBVH atlas");
            assert_eq!(limit, "maxStorageBufferRange");
        }
        other => panic!("expected a DeviceLimit error, got {:?}", other.map(|_| ())),
    }

    // Auto reads it through its device address, and agrees with the CPU caster.
    let tracer = Tracer::new(&ctx, &Structure::from(r.clone())).unwrap();
    assert_eq!(tracer.reach(), Reach::DeviceAddresses);
    let mut rng = common::Rng::new(11);
    let rays: Vec<Ray> = (0..4096)
        .map(|_| {
            let target = Vec3::new(rng.next_f32() * 2.0 - 1.0, 0.0, rng.next_f32() * 2.0 - 1.0);
            let origin = target + Vec3::new(0.3, 1.0, -0.2) + rng.unit_vector() * 0.5;
            Ray::new(origin, target - origin, 0.0, f32::INFINITY)
        })
        .collect();
    let gpu = tracer.trace(&rays, Query::Closest).unwrap().hits;
    let cpu = r.trace_cpu(&rays, false);
    let mut agreement = common::Agreement::default();
    agreement.add("big atlas", &gpu, &cpu, false);
    assert_eq!(agreement.hit_miss, 0, "{agreement:?}");
    assert!(gpu.iter().all(Hit::is_hit), "every ray aims at the square");
    // Among them, hits on tiles that lie beyond what one binding could reach.
    let beyond = gpu
        .iter()
        .filter(|h| {
            let leaf = &r.heightfields[(h.id & !LEAF_BIT) as usize];
            u64::from(leaf.atlas_base) * 4 >= range
        })
        .count();
    assert!(beyond > 0, "no hit on a tile beyond maxStorageBufferRange");

    // Painting reaches the whole channel too.
    let brushes = [Brush::new(Vec3::new(0.9, 0.0, 0.9), 0.02, 0xFF00_FF00)];
    let mut painter = Painter::new(&ctx, &r).unwrap();
    assert_eq!(painter.reach(), Reach::DeviceAddresses);
    painter.paint(&brushes).unwrap();
    let painted = painter.colours().unwrap();
    let mut cpu_r = Rbvh::clone(&r);
    assert!(cpu_r.paint_cpu(&brushes) > 0);
    assert!(painted == *cpu_r.colours.as_ref().unwrap());
    ctx.check_validation().unwrap();
}

#[test]
fn arrays_beyond_every_limit_are_refused_before_anything_is_uploaded() {
    let auto = common::context();
    let limits = *auto.limits();
    let past_range = limits.max_storage_buffer_range + 4;
    let past_allocation = limits.max_memory_allocation_size + 4;
    assert_eq!(auto.reach(&[("small", 1024)]).unwrap(), Reach::Bindings);
    assert_eq!(
        auto.reach(&[("small", 1024), ("big", past_range)]).unwrap(),
        Reach::DeviceAddresses
    );
    let limit_of = |r: rbvh::Result<Reach>| match r {
        Err(Error::DeviceLimit {
            resource,
            limit,
            required,
            ..
        }) => (resource, limit, required),
        other => panic!("expected a DeviceLimit error, got {other:?}"),
    };
    assert_eq!(
        limit_of(auto.reach(&[("huge", past_allocation)])),
        (
            "huge".to_string(),
            "maxMemoryAllocationSize",
            past_allocation
        )
    );
    let bound = common::context_with(Addressing::Bindings);
    let e = bound.reach(&[("big", past_range)]).unwrap_err();
    assert!(e.to_string().contains("Addressing::Auto"), "{e}");
    assert_eq!(
        limit_of(Err(e)),
        ("big".to_string(), "maxStorageBufferRange", past_range)
    );
}
