//! The guard of issue "Small and valid at every scale": the built-in `hall` (a large room, 25
//! small, detailed, closed pieces; the paper-scale scene's shape with no files) at every preset.
//! Deterministic bounds, not snapshots: exact triangles stay a small share of the structure, the
//! structure a small share of the exact BVH, presets coarsest to finest, every preset valid as
//! `rbvh bench` judges it with a FLIP mean within 0.05, and no seam ray through a closed piece.
//! Before the per-object rates and the crest rule (`rbvh::rbvh::CREST_TEXELS`), the paper-scale
//! scene's exact triangles took 167.5 of its 210.8 MB at Q0, and no test noticed.

mod common;

use rbvh::bench::{self, BenchConfig, Device, RayType};
use rbvh::bvh::Bvh;
use rbvh::rbvh::{Rbvh, RbvhParams, RbvhSource, TexelFormat};
use rbvh::scene::Scene;

/// Bytes of every preset of the hall, Q0 to Q4: its exact parts (the triangles the seams keep
/// beside height fields, which took the paper-scale scene's memory) at most a twelfth of each,
/// all its exact triangles (with the room's walls and floor, traced exactly where that is
/// cheaper) at most a fifth, each preset at most `1 / LEAST_SAVING[level]` of the exact BVH, and
/// each finer preset larger than the coarser one. Measured (the exact triangles indexed, since
/// 683d5f4): parts 0.028–0.054 MB (1–6%), exact triangles 0.100–0.113 MB (4–13%), the structures
/// 33.9, 23.9, 16.2, 11.0 and 9.8 times smaller than the exact BVH's 30.38 MB (29.9, 18.7, 11.5,
/// 6.9 and 4.7 with every triangle sampled).
#[test]
fn every_preset_of_the_hall_is_small_and_mostly_height_fields() {
    const LEAST_SAVING: [f64; 5] = [25.0, 18.0, 12.0, 8.0, 7.0];
    let scene = Scene::builtin("hall").unwrap();
    let exact = Bvh::build(&scene).unwrap();
    let exact_bytes = (exact.tree_bytes() + exact.triangle_bytes()) as f64;
    let source = RbvhSource::new(&scene).unwrap();
    let mut previous = 0;
    for (level, params) in RbvhParams::presets().iter().enumerate() {
        let r = Rbvh::build_from(&source, params, &rbvh::progress::Quiet).unwrap();
        let (total, triangles, parts) = (r.total_bytes(), r.triangle_bytes(), r.part_bytes());
        println!(
            "hall Q{level}: {total} bytes, {triangles} of exact triangles ({parts} of parts), \
             {:.1}x smaller than the exact BVH",
            exact_bytes / total as f64
        );
        assert!(parts * 12 <= total, "Q{level}: {parts} of {total} bytes");
        assert!(
            triangles * 5 <= total,
            "Q{level}: {triangles} of {total} bytes"
        );
        assert!(
            total as f64 * LEAST_SAVING[level] <= exact_bytes,
            "Q{level}: {total} bytes against the exact BVH's {exact_bytes}"
        );
        assert!(
            total > previous,
            "Q{level} is not larger than the level below"
        );
        previous = total;
    }
}

/// What a texel of the hall costs on the device at every preset (`Rbvh::bytes_per_texel`: the
/// atlas, its unused texels and block ranges included, over the tiles' texels), with normals and
/// without: each tile stores its heights in the fewest bits of 8, 10, 12 and 16 that keep a
/// 128th of a texel over the tile's plane (`rbvh::rbvh::PACKED_BITS`), and the packing wastes a
/// few percent. Measured: with every triangle sampled (`Q2s`) 3.31–3.39 bytes with normals,
/// 1.24–1.29 without, 48–64% of the texels 8-bit; the presets, which trace the room's flat walls
/// and floor exactly (most of the 8-bit tiles), 3.43–3.68 and 1.26–1.52 bytes (8–20% 8-bit with
/// normals, 49% height-only at Q0), bounded at 3.75 and 1.6 bytes, and at Q2 height-only at the
/// issue's 1.5 ("Small and valid at every scale": 1.43 measured; 2.08 before the 10- and 12-bit
/// heights); at Q0 a tenth of the texels 8-bit at least.
#[test]
fn every_preset_of_the_hall_stores_texels_in_the_bytes_they_need() {
    let scene = Scene::builtin("hall").unwrap();
    let source = RbvhSource::new(&scene).unwrap();
    for level in 0..5 {
        for (texels, most, most_sampled) in [
            (TexelFormat::HeightNormal, 3.75, 3.45),
            (TexelFormat::Height, 1.6, 1.35),
        ] {
            for exact_when_cheaper in [true, false] {
                let params = RbvhParams {
                    texels,
                    exact_when_cheaper,
                    ..RbvhParams::quality(level).unwrap()
                };
                let r = Rbvh::build_from(&source, &params, &rbvh::progress::Quiet).unwrap();
                let (bytes, narrow) = (r.bytes_per_texel(), r.narrow_texels());
                let label = params.level_label();
                println!(
                    "hall {label}: {bytes:.2} bytes a texel, {narrow} of {} texels 8-bit",
                    r.stats.tile_texels
                );
                if exact_when_cheaper {
                    assert!(bytes <= most, "{label}: {bytes} bytes a texel");
                    assert!(
                        level != 2 || texels == TexelFormat::HeightNormal || bytes <= 1.5,
                        "{label}: {bytes} bytes a texel, past the issue's 1.5"
                    );
                    // At Q0 a tenth or more of the texels are 8-bit (20% and 49% height-only).
                    assert!(
                        level > 0 || narrow * 10 >= r.stats.tile_texels,
                        "{label}: {narrow} texels 8-bit"
                    );
                } else {
                    assert!(bytes <= most_sampled, "{label}: {bytes} bytes a texel");
                    assert!(
                        narrow * 5 >= r.stats.tile_texels * 2,
                        "{label}: {narrow} texels 8-bit"
                    );
                }
            }
        }
    }
}

/// Every preset of the hall is valid for primary rays as `rbvh bench` judges it (hit/miss
/// mismatches within 5%, t p99 within 1% of the diagonal), with a FLIP mean within 0.05, few
/// hits facing away where the exact ones face the ray, and no seam ray through a closed piece;
/// and its rays visit fewer inner nodes than the exact BVH's.
#[test]
fn every_preset_of_the_hall_is_valid() {
    let mut config = BenchConfig::new(vec!["hall".into()], Device::Existing(common::context()));
    config.levels = RbvhParams::presets();
    config.ray_types = vec![RayType::Primary];
    (config.width, config.height) = (160, 120);
    config.runs = 1;
    config.seam_rays = 20_000;
    config.steps = true;
    let report = bench::run(&config).unwrap();
    let exact = report.results.iter().find(|r| r.quality.is_none()).unwrap();
    let levels: Vec<_> = report
        .results
        .iter()
        .filter(|r| r.quality.is_some())
        .collect();
    assert_eq!(levels.len(), 5);
    for r in levels {
        let level = r.level_label();
        let e = r.error.as_ref().unwrap();
        println!("hall {level}: {e:?} {:?}", r.seams);
        // A tree that earns its leaves (issue of that name): fewer inner nodes a ray than the
        // exact BVH's (measured here, 160 × 120: 20.2–21.5 at Q0–Q4, the room's walls and floor
        // exact triangles, against 26.3; 15.4–18.5 with them sampled), and few leaves handed to
        // the march (0.48–0.61; 1.16–1.33 sampled), each accounted for by what came of it.
        let (c, steps) = (&r.counters, r.steps.unwrap());
        println!("hall {level}: {c:?} {steps:?}");
        assert!(
            c.nodes <= exact.counters.nodes,
            "{level}: {} inner nodes a ray against the exact BVH's {}",
            c.nodes,
            exact.counters.nodes
        );
        assert!(c.leaves <= 2.0, "{level}: {} leaves a ray", c.leaves);
        let accounted = steps.leaves_tile_missed
            + steps.leaves_no_surface
            + steps.leaves_behind
            + steps.leaves_nearest;
        assert!(
            (accounted - c.leaves).abs() <= 0.01 * c.leaves,
            "{level}: {accounted} leaves accounted for, {} counted",
            c.leaves
        );
        assert!(r.valid, "{level}: {:?}", r.invalid_reason);
        let flip = e.flip_mean.unwrap();
        assert!(flip <= 0.05, "{level}: FLIP {flip}");
        let back = e.back_facing_rate.unwrap();
        assert!(back <= 0.005, "{level}: {back} of the rays hit facing away");
        let seams = r.seams.unwrap();
        assert_eq!(seams.through, 0, "{level}: {seams:?}");
    }
}
