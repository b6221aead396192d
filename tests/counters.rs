//! Per-ray counters (`rbvh::probe`): the device's counting pipeline and the CPU twins count the
//! same work ray by ray, for the exact BVH, the RBVH (with block jumps and without) and the RBVH
//! with level of detail; the counting pipeline returns the timed pipeline's hits; the twin's jumping walk
//! returns the plain walk's hits with fewer cells; and the reads the twins report match their
//! counters, array by array.

mod common;

use rbvh::bvh::Bvh;
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{Query, Tracer};
use rbvh::lod::{Cones, Lod, LodParams, RayCone};
use rbvh::probe::{Array, RayCounters, Read, TraceStats};
use rbvh::rbvh::{Rbvh, RbvhParams, TexelFormat};
use rbvh::scene::Scene;
use rbvh::structure::Structure;
use std::sync::Arc;

fn rays_for(scene: &Scene, side: u32, random: usize, seed: u64) -> Vec<Ray> {
    let mut rays = scene.camera_or_framed(1.0).primary_rays(side, side);
    rays.extend(common::random_rays(
        scene,
        random,
        &mut common::Rng::new(seed),
    ));
    rays
}

/// Rays whose device counters differ from the twin's, with the first such ray for the message.
/// The hits of the two agree bit for bit except, rarely, in the last bit of a division on the
/// device (`tests/rbvh_agreement.rs`); a ray whose hit differs may count differently too.
fn mismatches(
    gpu: &[RayCounters],
    gpu_hits: &[Hit],
    twin: &[(Hit, TraceStats)],
) -> (usize, Option<String>) {
    let mut count = 0;
    let mut first = None;
    for (i, ((g, gh), (th, ts))) in gpu.iter().zip(gpu_hits).zip(twin).enumerate() {
        assert!(!ts.overflow, "ray {i} overflowed on the twin");
        if *g != ts.counters {
            count += 1;
            first.get_or_insert_with(|| {
                format!(
                    "ray {i}: device {g:?} (t {}), twin {:?} (t {})",
                    gh.t, ts.counters, th.t
                )
            });
        }
    }
    (count, first)
}

#[test]
fn device_and_cpu_twin_count_the_same_work() {
    let ctx = common::context();
    let (mut total, mut differing) = (0usize, 0usize);
    for (k, name) in ["default", "blob", "sphere"].into_iter().enumerate() {
        let scene = Scene::builtin(name).unwrap();
        let rays = rays_for(&scene, 64, 2000, 40 + k as u64);
        let structure = Structure::from(Bvh::build(&scene).unwrap());
        let bvh = structure.bvh().unwrap();
        let mut exact = Tracer::new(&ctx, &structure).unwrap();
        assert!(!exact.block_jumps());
        let e = exact.set_block_jumps(true).unwrap_err().to_string();
        assert!(e.contains("no march"), "{e}");
        // Height-only texels are read two (8-bit: four) to a word, and the block ranges after them.
        let builds = [
            (0, TexelFormat::HeightNormal),
            (2, TexelFormat::HeightNormal),
            (2, TexelFormat::Height),
            (4, TexelFormat::HeightNormal),
        ];
        for (level, texels) in builds {
            // The presets on the default scene (exact triangles beside height fields); the blob
            // and the sphere with every triangle sampled, or from Q3 on the sphere would march
            // nothing.
            let params = RbvhParams {
                texels,
                exact_when_cheaper: name == "default",
                ..RbvhParams::quality(level).unwrap()
            };
            let r = Arc::new(Rbvh::build(&scene, &params).unwrap());
            let mut tracer = Tracer::new(&ctx, &Structure::from(r.clone())).unwrap();
            // Off is this CPU device's default; both are what some device runs.
            assert_eq!(tracer.block_jumps(), !ctx.limits().cpu);
            for (jumping, query) in [
                (false, Query::Closest),
                (false, Query::Any),
                (true, Query::Closest),
                (true, Query::Any),
            ] {
                tracer.set_block_jumps(jumping).unwrap();
                assert_eq!(tracer.block_jumps(), jumping);
                let twin = r.device_twin().with_block_jumps(jumping);
                let any = query == Query::Any;
                let gpu = tracer.trace_with(&rays, Cones::None, query, true).unwrap();
                let cpu: Vec<_> = rays
                    .iter()
                    .map(|ray| twin.trace(ray, any, &mut ()))
                    .collect();
                let counters = gpu.counters.as_ref().unwrap();
                let (n, first) = mismatches(counters, &gpu.hits, &cpu);
                assert!(
                    n * 10_000 <= rays.len(),
                    "{name} Q{level} {query:?} jumps {jumping}: {n} rays differ; {first:?}"
                );
                total += rays.len();
                differing += n;
                // The counting pipeline is the timed one with counting compiled in: same hits.
                let timed = tracer.trace(&rays, query).unwrap().hits;
                assert!(
                    timed
                        .iter()
                        .zip(&gpu.hits)
                        .all(|(a, b)| a.t.to_bits() == b.t.to_bits() && a.id == b.id),
                    "{name} Q{level} {query:?}: counting changed a hit"
                );
                let jumps: u64 = counters.iter().map(|c| u64::from(c.jumps)).sum();
                let walks: u64 = counters.iter().map(|c| u64::from(c.walks)).sum();
                assert!(walks > 0, "{name} Q{level}: nothing marched");
                assert_eq!(jumps > 0, jumping, "{name} Q{level}: {jumps} jumps");
            }
        }
        for query in [Query::Closest, Query::Any] {
            let gpu = exact.trace_with(&rays, Cones::None, query, true).unwrap();
            let cpu: Vec<_> = rays
                .iter()
                .map(|ray| bvh.trace_probed(ray, query == Query::Any, &mut ()))
                .collect();
            let counters = gpu.counters.as_ref().unwrap();
            let (n, first) = mismatches(counters, &gpu.hits, &cpu);
            assert_eq!(n, 0, "{name} exact {query:?}: {first:?}");
            total += rays.len();
            assert!(counters.iter().all(|c| c.leaves == 0 && c.cells == 0));
        }
    }
    println!("device vs twin counters: {differing} of {total} rays differ");
}

#[test]
fn level_of_detail_counts_agree_too() {
    let ctx = common::context();
    let scene = Scene::builtin("grove").unwrap();
    let r = Arc::new(Rbvh::build(&scene, &RbvhParams::quality(2).unwrap()).unwrap());
    let with_lod = Structure::with_lod(r.clone(), Lod::build(&r, &LodParams::default()).unwrap());
    let lod = with_lod.lod().unwrap();
    let tracer = Tracer::new(&ctx, &with_lod).unwrap();
    let camera = scene.camera_or_framed(1.0);
    let rays = camera.primary_rays(96, 96);
    // A wide cone, so that many coarse nodes are chosen.
    let cone = RayCone {
        width: 0.0,
        spread: 40.0 * RayCone::pixel(&camera, 96).spread,
    };
    let cones = vec![cone; rays.len()];
    let gpu = tracer
        .trace_with(&rays, &cones, Query::Closest, true)
        .unwrap();
    let twin = lod
        .device_twin(&r)
        .unwrap()
        .with_block_jumps(tracer.block_jumps());
    let cpu: Vec<_> = rays
        .iter()
        .map(|ray| twin.trace(ray, false, &cone, &mut ()))
        .collect();
    let coarse = gpu
        .hits
        .iter()
        .filter(|h| h.is_hit() && h.id & rbvh::lod::LOD_BIT != 0)
        .count();
    assert!(coarse > 100, "only {coarse} coarse hits");
    let (n, first) = mismatches(gpu.counters.as_ref().unwrap(), &gpu.hits, &cpu);
    assert!(n * 1000 <= rays.len(), "{n} rays differ; {first:?}");
}

/// The twin jumps over blocks as the device does; the plain walk is the referee: same hits to the
/// bit, never more cells, and many fewer on rays grazing the sphere.
#[test]
fn the_twins_block_jumps_change_no_hit_and_save_cells() {
    let scene = Scene::builtin("sphere").unwrap();
    let mut rng = common::Rng::new(77);
    let mut rays = rays_for(&scene, 64, 3000, 78);
    rays.extend((0..4000).map(|_| {
        let angle = std::f32::consts::TAU * rng.next_f32();
        let radius = 0.97 + 0.05 * rng.next_f32();
        let origin = glam::Vec3::new(-3.0, radius * angle.cos(), radius * angle.sin());
        Ray::new(origin, glam::Vec3::X, 0.0, f32::INFINITY)
    }));
    for level in [0, 2, 4] {
        let r = Rbvh::build(&scene, &common::sampled_preset(level)).unwrap();
        let twin = r.device_twin();
        let (mut plain_cells, mut twin_cells) = (0u64, 0u64);
        for any in [false, true] {
            for ray in &rays {
                let (plain, ps) = if any {
                    r.any_hit(ray)
                } else {
                    r.closest_hit(ray)
                };
                let (jumping, js) = twin.trace(ray, any, &mut ());
                assert_eq!(
                    (plain.t.to_bits(), plain.id),
                    (jumping.t.to_bits(), jumping.id),
                    "Q{level} any {any}: {ray:?}"
                );
                assert!(js.counters.cells <= ps.counters.cells, "{ray:?}");
                assert_eq!(ps.counters.jumps, 0);
                plain_cells += u64::from(ps.counters.cells);
                twin_cells += u64::from(js.counters.cells);
            }
        }
        println!("Q{level}: cells plain {plain_cells}, with jumps {twin_cells}");
        // A fifth saved at least: the jumps saved 35–48% before the tiles' planes, which cut the
        // plain walk's cells here by 2–7× by themselves (511,343 / 675,797 / 880,198 → 259,100 /
        // 222,911 / 126,462 at Q0 / Q2 / Q4), and 23%, 37% and 35% since.
        assert!(
            twin_cells * 5 < plain_cells * 4,
            "Q{level}: {twin_cells} of {plain_cells}"
        );
    }
}

/// Reads per array follow from the counters: a node read per node visited (and a node's leaf child
/// and count read again where a leaf comes off the stack), a leaf record per leaf marched, four
/// texels per cell (and a height field's hit's normal once the ray is done: its place in the rank
/// directory, the codes before it in its group, its word) and a range word per block entered, a triangle per triangle tested (and once more for a triangle hit's id
/// and normal): the exact BVH's in one read, the RBVH's indexed in four (its slot, its vertices).
#[test]
fn the_twins_reads_match_their_counters() {
    let scene = Scene::builtin("default").unwrap();
    let rays = rays_for(&scene, 48, 1000, 5);
    let r = Rbvh::build(&scene, &RbvhParams::quality(2).unwrap()).unwrap();
    let twin = r.device_twin();
    let bvh = Bvh::build(&scene).unwrap();
    let count = |reads: &[Read], array: Array| reads.iter().filter(|r| r.array == array).count();
    let node_bytes = std::mem::size_of::<rbvh::bvh::GpuNode>() as u64;
    // Node visits read the whole record; a popped leaf reads its parent's child and count again.
    let visits = |reads: &[Read]| {
        reads
            .iter()
            .filter(|r| r.array == Array::Nodes && u64::from(r.bytes) == node_bytes)
            .count()
    };
    let leaf_rereads = |reads: &[Read]| {
        reads
            .iter()
            .filter(|r| r.array == Array::Nodes && r.bytes == 8)
            .count()
    };
    let mut rereads = [0usize; 2];
    let parts = r.atlas.device_parts(r.params.texels);
    let (code_bytes, ranks_bytes) = (4 * parts.ranges as u64, 4 * parts.ranks as u64);
    for ray in &rays {
        let mut reads = Vec::new();
        let (hit, s) = twin.trace(ray, false, &mut reads);
        let c = s.counters;
        assert_eq!(visits(&reads), c.nodes as usize);
        assert!(leaf_rereads(&reads) <= (c.leaves + c.triangle_leaves) as usize);
        rereads[0] += leaf_rereads(&reads);
        assert_eq!(count(&reads, Array::Heightfields), c.leaves as usize);
        // The RBVH's triangles are indexed: a 16-byte slot and its three 16-byte vertices after
        // the slots.
        let triangle_hit = hit.is_hit() && hit.id & rbvh::bvh::LEAF_BIT == 0;
        let triangle_reads = (c.triangles + u32::from(triangle_hit)) as usize;
        let slot_bytes = 16 * r.triangles.len() as u64;
        let slots = reads
            .iter()
            .filter(|r| r.array == Array::Triangles && r.offset < slot_bytes)
            .count();
        assert_eq!(slots, triangle_reads);
        assert_eq!(count(&reads, Array::Triangles), 4 * triangle_reads);
        let in_atlas = |from: u64, to: u64| {
            reads
                .iter()
                .filter(|r| r.array == Array::Atlas && (from..to).contains(&r.offset))
                .count()
        };
        let codes = in_atlas(0, code_bytes);
        // A cell's corners are two reads, a row's two codes together; a height field's hit reads
        // its normal once the ray is done, for up to five corners when the nearest faces away:
        // each one or two words of the rank directory and its word, and the codes of at most 16
        // texels of its group of 32, a row of two at a time.
        let height_field_hit = hit.is_hit() && hit.id & rbvh::bvh::LEAF_BIT != 0;
        let normal_reads = in_atlas(ranks_bytes, u64::MAX);
        let counted = codes - (2 * c.cells as usize).min(codes);
        assert!(codes >= 2 * c.cells as usize, "{ray:?}");
        if height_field_hit {
            assert!((2..=15).contains(&normal_reads), "{normal_reads}: {ray:?}");
            assert!(counted <= 8 * normal_reads / 2, "{counted}: {ray:?}");
        } else {
            assert_eq!(normal_reads + counted, 0, "{ray:?}");
        }
        let ranges = in_atlas(code_bytes, ranks_bytes);
        assert!(ranges >= c.jumps as usize && ranges <= (c.jumps + c.cells) as usize);
        assert!(reads.iter().all(|r| r.offset % 4 == 0 && r.bytes % 4 == 0));

        let mut reads = Vec::new();
        let (hit, s) = bvh.trace_probed(ray, false, &mut reads);
        assert_eq!(visits(&reads), s.counters.nodes as usize);
        assert!(leaf_rereads(&reads) <= s.counters.triangle_leaves as usize);
        rereads[1] += leaf_rereads(&reads);
        assert_eq!(
            count(&reads, Array::Triangles),
            (s.counters.triangles + u32::from(hit.is_hit())) as usize
        );
        // Whole records: a 48-byte node or a 48-byte triangle, each at its own offset; or a node's
        // child and count (a_child at byte 28, b_child at 36).
        let record = |r: &Read| match r.array {
            Array::Nodes => node_bytes,
            Array::Triangles => std::mem::size_of::<rbvh::bvh::GpuTriangle>() as u64,
            _ => 0,
        };
        assert!(reads.iter().all(|r| record(r) > 0
            && ((u64::from(r.bytes) == record(r) && r.offset % record(r) == 0)
                || (r.array == Array::Nodes
                    && r.bytes == 8
                    && [28, 36].contains(&(r.offset % node_bytes))))));
    }
    // Leaves come off the stack on both structures' rays here.
    assert!(rereads.iter().all(|&n| n > 0), "{rereads:?}");
}
