//! RBVHs built from points (a scan's samples, `src/rbvh/splat.rs`), refereed by the analytic
//! sphere and by the exact BVH of the mesh the points were sampled from: error per level within
//! stated bounds, no ray aimed into the surface lost, normals estimated where none were given,
//! the GPU and CPU casters agreeing, a scan's colours carried into the colour channel.

mod common;

use glam::Vec3;
use rbvh::bvh::Bvh;
use rbvh::geom::Ray;
use rbvh::gpu::{Query, Tracer};
use rbvh::points::PointCloud;
use rbvh::rbvh::{Rbvh, RbvhParams};
use rbvh::scene::Scene;
use rbvh::structure::Structure;
use std::sync::Arc;

/// Points per unit sphere in these tests: a spacing of about 0.011, a little coarser than a Q4
/// texel (0.0034) and finer than a Q0 texel (0.0135), as scans are against the levels.
const SPHERE_POINTS: usize = 100_000;

fn q(level: u32) -> RbvhParams {
    RbvhParams::quality(level).unwrap()
}

/// Built-in scene `name` with `count` points sampled over its triangles.
fn sampled(name: &str, count: usize) -> Scene {
    let mut scene = Scene::builtin(name).unwrap();
    scene.points = Some(scene.sample_points(count, 7).unwrap());
    scene
}

/// Radial errors (sorted) of rays from outside the unit sphere aimed within 0.6 of its radius
/// of its centre, and how many of them missed.
fn radial_errors(r: &Rbvh, seed: u64) -> (Vec<f32>, usize) {
    let (center, radius, _) = common::sphere_oracle();
    let mut rng = common::Rng::new(seed);
    let mut misses = 0;
    let mut errors = Vec::new();
    for _ in 0..4000 {
        let origin = center + rng.unit_vector() * 3.0 * radius;
        let dir = (center + rng.unit_vector() * 0.6 * radius - origin).normalize();
        let hit = r.closest_hit(&Ray::new(origin, dir, 0.0, f32::INFINITY)).0;
        if hit.is_hit() {
            errors.push(((origin + hit.t * dir - center).length() - radius).abs());
        } else {
            misses += 1;
        }
    }
    errors.sort_by(f32::total_cmp);
    (errors, misses)
}

/// A point-built RBVH of the sphere lies on the sphere as closely as a triangle-built one must
/// (`tests/rbvh.rs`): every ray aimed into it hits, 99% of hits within a tenth of a texel plus
/// the sampled mesh's chord error, all within half a texel plus that (nearest-point splats on
/// tangent planes err by about spacing² / radius, far below a texel).
/// Against the exact BVH of the mesh on random rays, hit/miss disagreements stay below 0.5%
/// (rays grazing the silhouette, where a texel's rim decides).
#[test]
fn sphere_from_points_lies_on_the_sphere_at_every_level() {
    let scene = sampled("sphere", SPHERE_POINTS);
    let (_, _, chord) = common::sphere_oracle();
    let exact = Bvh::build(&scene).unwrap();
    let rays = common::random_rays(&scene, 4000, &mut common::Rng::new(3));
    common::every_case([0, 2, 4], |level| {
        let r = Rbvh::build(&scene, &q(level)).map_err(|e| e.to_string())?;
        let (errors, misses) = radial_errors(&r, level as u64);
        let p99 = errors[errors.len() * 99 / 100];
        let worst = errors[errors.len() - 1];
        let texel = r.texel_size;
        let mismatches = rays
            .iter()
            .filter(|ray| exact.closest_hit(ray).0.is_hit() != r.closest_hit(ray).0.is_hit())
            .count();
        println!(
            "Q{level}: {} leaves, texel {texel:.2e}, radial p99 {p99:.2e} max {worst:.2e}, {misses} misses, {mismatches} of {} random rays disagree with exact",
            r.heightfields.len(),
            rays.len()
        );
        common::ensure(misses == 0, || format!("Q{level}: {misses} rays missed"))?;
        common::ensure(r.stats.triangle_leaves == 0, || {
            format!("Q{level}: a point-built RBVH has triangle leaves")
        })?;
        common::ensure(p99 <= chord + 0.1 * texel, || {
            format!("Q{level}: radial p99 {p99} (texel {texel})")
        })?;
        common::ensure(worst <= chord + 0.5 * texel, || {
            format!("Q{level}: radial max {worst} (texel {texel})")
        })?;
        common::ensure(mismatches * 200 <= rays.len(), || {
            format!("Q{level}: {mismatches} hit/miss disagreements with exact")
        })
    });
}

/// Without normals in the input, they are estimated and oriented (`points::estimate`): the
/// RBVH is as accurate, and its hits face outward.
#[test]
fn estimated_normals_build_the_same_sphere_facing_outward() {
    let given = sampled("sphere", SPHERE_POINTS).points.unwrap();
    let cloud = PointCloud::new("sphere points", given.positions.clone(), None, None).unwrap();
    let mut scene = Scene::builtin("sphere").unwrap();
    scene.points = Some(cloud);
    let (center, radius, chord) = common::sphere_oracle();
    let r = Rbvh::build(&scene, &q(2)).unwrap();
    let (errors, misses) = radial_errors(&r, 11);
    assert_eq!(misses, 0);
    let p99 = errors[errors.len() * 99 / 100];
    assert!(p99 <= chord + 0.1 * r.texel_size, "radial p99 {p99}");
    let mut rng = common::Rng::new(5);
    let mut inward = 0;
    for _ in 0..2000 {
        let origin = center + rng.unit_vector() * 3.0 * radius;
        let dir = (center - origin).normalize();
        let hit = r.closest_hit(&Ray::new(origin, dir, 0.0, f32::INFINITY)).0;
        let outward = (origin + hit.t * dir - center).normalize();
        if hit.normal().dot(outward) < 0.9 {
            inward += 1;
        }
    }
    assert!(
        inward <= 20,
        "{inward} of 2000 hit normals do not face outward"
    );
}

/// No ray aimed into a closed scan slips between its splats or its leaves: 200,000 rays from all
/// sides at points within 0.95 of the radius, into a sphere of 20,000 points (at Q4 a spacing of
/// seven texels, where splats must reach across texels the points leave empty). A reach of one
/// spacing let 3 of them through at Q4; `splat::REACH_SPACINGS` lets none.
#[test]
fn no_ray_slips_through_a_sparse_closed_scan() {
    let scene = sampled("sphere", 20_000);
    let (center, radius, _) = common::sphere_oracle();
    let mut rng = common::Rng::new(21);
    let rays: Vec<Ray> = (0..200_000)
        .map(|_| {
            let origin = center + rng.unit_vector() * 3.0 * radius;
            let target = center + rng.unit_vector() * 0.95 * radius * rng.next_f32().sqrt();
            Ray::new(origin, (target - origin).normalize(), 0.0, f32::INFINITY)
        })
        .collect();
    common::every_case([0, 2, 4], |level| {
        let r = Rbvh::build(&scene, &q(level)).map_err(|e| e.to_string())?;
        let leaks = rays
            .iter()
            .filter(|ray| !r.closest_hit(ray).0.is_hit())
            .count();
        common::ensure(leaks == 0, || {
            format!("Q{level}: {leaks} of {} rays slipped through", rays.len())
        })
    });
}

/// The device march reads a point-built RBVH as any other: GPU and CPU casters agree as
/// `tests/rbvh_agreement.rs` requires of triangle-built ones.
#[test]
fn gpu_and_cpu_agree_on_point_built_rbvhs() {
    let ctx = common::context();
    let mut agreement = common::Agreement::default();
    for (name, count) in [("blob", 60_000), ("default", 80_000)] {
        let scene = sampled(name, count);
        for level in [0, 3] {
            let r = Arc::new(Rbvh::build(&scene, &q(level)).unwrap());
            let tracer = Tracer::new(&ctx, &Structure::from(r.clone())).unwrap();
            let mut rays = scene.camera_or_framed(1.0).primary_rays(96, 96);
            rays.extend(common::random_rays(
                &scene,
                3000,
                &mut common::Rng::new(level as u64),
            ));
            for (query, any) in [(Query::Closest, false), (Query::Any, true)] {
                let gpu = tracer.trace(&rays, query).unwrap().hits;
                let cpu = r.trace_cpu(&rays, any);
                agreement.add(&format!("{name} Q{level}"), &gpu, &cpu, any);
            }
        }
    }
    println!(
        "GPU/CPU agreement on point-built RBVHs: {} rays, {} hit/miss disagreements",
        agreement.total, agreement.hit_miss
    );
    assert!(agreement.rate() < 1e-4, "{agreement:?}");
}

/// A scan's colours become the colour channel: every texel that samples a point carries that
/// point's colour, here red on one half of a plane and blue on the other.
#[test]
fn point_colours_fill_the_colour_channel() {
    const RED: u32 = 0xff00_00ff;
    const BLUE: u32 = 0xffff_0000;
    let mut positions = Vec::new();
    let mut colours = Vec::new();
    for j in 0..100 {
        for i in 0..100 {
            let x = (i as f32 + 0.5) / 100.0;
            positions.push(Vec3::new(x, 0.0, (j as f32 + 0.5) / 100.0));
            colours.push(if x < 0.5 { RED } else { BLUE });
        }
    }
    let normals = vec![Vec3::Y; positions.len()];
    let cloud = PointCloud::new("plane", positions, Some(normals), Some(colours)).unwrap();
    let mut scene = Scene::new("coloured plane");
    scene.points = Some(cloud);
    let r = Rbvh::build(&scene, &q(1)).unwrap();
    let channel = r.colours.as_ref().expect("a colour channel");
    let (mut red, mut blue) = (0, 0);
    for (texel, &colour) in r.atlas.texels.iter().zip(channel) {
        if texel.is_hole() {
            continue;
        }
        match colour {
            RED => red += 1,
            BLUE => blue += 1,
            other => panic!("texel colour {other:#010x} is no point's"),
        }
    }
    assert!(
        red > 1000 && blue > 1000,
        "{red} red and {blue} blue texels"
    );
}

/// A closed speck of points smaller than a texel beside a plane, at Q0 and with a 5° cone and
/// no sampled judgement: no part of the speck, split by space or by facing (normals within
/// 54.7° of an axis), passes, so it can only end in forced leaves, splatted regardless. The
/// build completes, and a ray aimed at the speck hits it within a few texels.
#[test]
fn a_closed_speck_that_no_split_makes_a_height_field_ends_in_forced_leaves() {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut rng = common::Rng::new(9);
    for j in 0..60 {
        for i in 0..60 {
            positions.push(Vec3::new(i as f32 / 59.0, 0.0, j as f32 / 59.0));
            normals.push(Vec3::Y);
        }
    }
    let centre = Vec3::new(0.5, 0.3, 0.5);
    for _ in 0..200 {
        let n = rng.unit_vector();
        positions.push(centre + 0.002 * n);
        normals.push(n);
    }
    let cloud = PointCloud::new("plane and speck", positions, Some(normals), None).unwrap();
    let mut scene = Scene::new("plane and speck");
    scene.points = Some(cloud);
    let params = RbvhParams {
        refinement: rbvh::rbvh::Refinement::NormalCone { max_angle_deg: 5.0 },
        sampled_criterion_texels: 0.0,
        ..q(0)
    };
    let r = Rbvh::build(&scene, &params).unwrap();
    let hit = r
        .closest_hit(&Ray::new(centre + Vec3::Y, -Vec3::Y, 0.0, f32::INFINITY))
        .0;
    assert!(hit.is_hit());
    assert!(
        (hit.t - 1.0).abs() < 4.0 * r.texel_size,
        "the speck at t≈1, hit at {}",
        hit.t
    );
}

/// A thin sheet scanned from both sides (two layers half a spacing apart, facing away from each
/// other) is split by facing into two height fields, not cut along its length into a leaf per
/// point (20,000 leaves for these 20,000 points before the facing split took thin sets): at
/// most 2.5 times the leaves of one side alone (tiles of at most 64 texels a side), and each
/// side is hit from its side with its own normal.
#[test]
fn a_thin_sheet_scanned_from_both_sides_is_two_height_fields() {
    let sheet = |sides: &[(f32, Vec3)]| {
        let (mut positions, mut normals) = (Vec::new(), Vec::new());
        for &(y, normal) in sides {
            for j in 0..100 {
                for i in 0..100 {
                    positions.push(Vec3::new(i as f32 * 0.01, y, j as f32 * 0.01));
                    normals.push(normal);
                }
            }
        }
        let mut scene = Scene::new("sheet");
        scene.points = Some(PointCloud::new("sheet", positions, Some(normals), None).unwrap());
        scene
    };
    let one = sheet(&[(0.0, Vec3::Y)]);
    let two = sheet(&[(0.0, Vec3::Y), (-0.005, Vec3::NEG_Y)]);
    common::every_case([0, 2, 4], |level| {
        let single = Rbvh::build(&one, &q(level)).map_err(|e| e.to_string())?;
        let r = Rbvh::build(&two, &q(level)).map_err(|e| e.to_string())?;
        let (leaves, alone) = (r.heightfields.len(), single.heightfields.len());
        common::ensure(2 * leaves <= 5 * alone, || {
            format!("Q{level}: {leaves} leaves for both sides, {alone} for one")
        })?;
        for (origin, dir, side) in [
            (Vec3::new(0.5, 1.0, 0.5), Vec3::NEG_Y, Vec3::Y),
            (Vec3::new(0.3, -1.0, 0.6), Vec3::Y, Vec3::NEG_Y),
        ] {
            let hit = r.closest_hit(&Ray::new(origin, dir, 0.0, f32::INFINITY)).0;
            common::ensure(hit.is_hit() && hit.normal().dot(side) > 0.99, || {
                format!("Q{level}: from {origin}: {hit:?}")
            })?;
        }
        Ok(())
    });
}

/// A point cloud alone has nothing for the exact BVH: a clear error, not an empty tree.
#[test]
fn the_exact_bvh_of_a_point_cloud_is_refused_by_name() {
    let mut scene = Scene::new("scan.ply");
    scene.points = Some(sampled("sphere", 1000).points.unwrap());
    let e = Bvh::build(&scene).unwrap_err().to_string();
    assert!(e.contains("scan.ply") && e.contains("point cloud"), "{e}");
}

/// A point cloud has no triangles to trace exactly: the presets' `exact_when_cheaper` does
/// nothing there, and a cloud built with it is the cloud built without it.
#[test]
fn exact_when_cheaper_changes_nothing_for_points() {
    let scene = sampled("sphere", 2000);
    let with = Rbvh::build(&scene, &q(2)).unwrap();
    let without = Rbvh::build(
        &scene,
        &RbvhParams {
            exact_when_cheaper: false,
            ..q(2)
        },
    )
    .unwrap();
    assert!(with.params.exact_when_cheaper);
    assert!(with.triangles.is_empty() && without.triangles.is_empty());
    assert_eq!(
        (
            with.heightfields.len(),
            with.atlas.texels.len(),
            with.nodes.len()
        ),
        (
            without.heightfields.len(),
            without.atlas.texels.len(),
            without.nodes.len()
        )
    );
    assert_eq!(with.atlas.texels, without.atlas.texels);
}
