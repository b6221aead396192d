//! Painting on an RBVH: the device (`glsl/paint.comp`) and the CPU reference agree texel for
//! texel, a stroke lands where it was aimed and nowhere else — across leaf borders too — and
//! painted data survives a save and a load. Every RBVH here samples every triangle
//! ([`common::sampled_preset`], as `rbvh paint` builds them): the presets trace the cube's faces
//! exactly, and exact triangles have no texels to paint.

mod common;

use glam::{Vec3, Vec4};
use rbvh::geom::Ray;
use rbvh::gpu::{Painter, Query, Tracer, MAX_BRUSHES_PER_PASS};
use rbvh::rbvh::{Rbvh, RbvhParams};
use rbvh::rgba;
use rbvh::scene::Scene;
use rbvh::structure::Structure;
use rbvh::surface::Brush;
use std::sync::Arc;

const RED: u32 = 0xFF00_00FF;

fn cube() -> Rbvh {
    Rbvh::build(&Scene::load("cube").unwrap(), &common::sampled_preset(2)).unwrap()
}

/// Every surface texel: (atlas index, world sample point, leaf index, stored normal).
fn surface_texels(r: &Rbvh) -> Vec<(usize, Vec3, usize, Vec3)> {
    let mut out = Vec::new();
    for (l, leaf) in r.heightfields.iter().enumerate() {
        for j in 0..leaf.res_v {
            for i in 0..leaf.res_u {
                let k = (leaf.atlas_base + j * r.atlas.pitch + i) as usize;
                let t = r.atlas.texels[k];
                if !t.is_hole() {
                    out.push((k, leaf.sample_point(i, j, t.height_code()), l, t.normal()));
                }
            }
        }
    }
    out
}

#[test]
fn a_stroke_on_a_cube_edge_paints_both_faces_and_nothing_else() {
    let ctx = common::context();
    let mut r = Arc::new(cube());
    assert!(
        r.colours.is_none(),
        "a scene without materials has no colour channel"
    );
    // Aim at the edge between the +x and +y faces, through the device tracer.
    let target = Vec3::new(1.0, 1.0, 0.1);
    let from = Vec3::new(3.0, 3.0, 0.1);
    let ray = Ray::new(from, target - from, 0.0, f32::INFINITY);
    let hits = Tracer::new(&ctx, &Structure::from(r.clone()))
        .unwrap()
        .trace(&[ray], Query::Closest)
        .unwrap()
        .hits;
    assert!(hits[0].is_hit());
    let centre = from + (target - from) * hits[0].t;
    assert!((centre - target).length() < 2.0 * r.texel_size, "{centre}");
    let radius = 0.3;
    let brushes = [Brush::new(centre, radius, RED)];

    let mut painter = Painter::new(&ctx, &r).unwrap();
    let stats = painter.paint(&brushes).unwrap();
    assert!(
        stats.leaves >= 2 && (stats.leaves as usize) < r.heightfields.len(),
        "{stats:?}"
    );
    let gpu = painter.colours().unwrap();
    let mut cpu = Rbvh::clone(&r);
    let painted = cpu.paint_cpu(&brushes);
    assert!(painted > 0);
    let cpu_colours = cpu.colours.as_ref().unwrap();
    let differ = gpu.iter().zip(cpu_colours).filter(|(a, b)| a != b).count();
    assert_eq!(differ, 0, "GPU and CPU painting differ in {differ} texels");

    // Within the radius painted, beyond it by more than a texel untouched; the painted texels lie
    // on both faces (by their stored normals) and in more than one leaf (at Q2 the cube's leaves
    // are corner pieces projected along the diagonals, and the brush spans the z = 0 border).
    let white = rgba::from_bytes([255; 4]);
    let mut faces = [0u32; 2];
    let mut leaves = std::collections::BTreeSet::new();
    for (k, p, leaf, n) in surface_texels(&r) {
        let d = (p - centre).length();
        if d <= radius * 0.999 {
            assert_eq!(
                gpu[k], RED,
                "texel at {p} ({d} from the centre) not painted"
            );
            faces[0] += u32::from(n.x > 0.9);
            faces[1] += u32::from(n.y > 0.9);
            leaves.insert(leaf);
        } else if d > radius + r.texel_size {
            assert_eq!(gpu[k], white, "texel at {p} ({d} from the centre) painted");
        }
    }
    assert!(
        faces[0] > 10 && faces[1] > 10,
        "painted texels per face: {faces:?}"
    );
    assert!(leaves.len() >= 2, "painted leaves: {leaves:?}");

    // The aimed hit's own texel is painted, and reads back as red.
    Arc::make_mut(&mut r).colours = Some(gpu);
    let loc = r.locate(&ray, &hits[0]).expect("a height-field hit");
    assert_eq!(r.surface_colour(loc), Some(Vec4::new(1.0, 0.0, 0.0, 1.0)));
}

#[test]
fn many_brushes_take_several_passes_and_the_last_one_wins() {
    let ctx = common::context();
    let r = cube();
    let mut rng = common::Rng::new(7);
    let mut brushes: Vec<Brush> = (0..5000)
        .map(|k| {
            let c = rng.unit_vector() * 1.2;
            Brush::new(c, 0.05 + 0.2 * rng.next_f32(), 0x0100_0000 * (k % 200) + k)
        })
        .collect();
    // One big brush last overrides the ones under it.
    brushes.push(Brush::new(Vec3::new(0.0, 0.0, 1.0), 0.4, RED));
    let mut painter = Painter::new(&ctx, &r).unwrap();
    painter.paint(&brushes).unwrap();
    let gpu = painter.colours().unwrap();
    let mut cpu = r.clone();
    cpu.paint_cpu(&brushes);
    assert_eq!(&gpu, cpu.colours.as_ref().unwrap());
    let centre_texel = surface_texels(&r)
        .into_iter()
        .find(|(_, p, _, _)| (*p - Vec3::new(0.0, 0.0, 1.0)).length() < 0.1)
        .unwrap();
    assert_eq!(gpu[centre_texel.0], RED);
}

#[test]
fn painted_colours_survive_save_and_load() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = cube();
    r.paint_cpu(&[Brush::new(Vec3::new(1.0, 0.2, 0.0), 0.4, RED)]);
    let path = dir.path().join("painted.rbvh");
    r.save(&path).unwrap();
    let back = Rbvh::load(&path).unwrap();
    assert_eq!(back.colours, r.colours);
    assert!(back.colours.unwrap().contains(&RED));
}

#[test]
fn a_colour_channel_that_does_not_match_the_atlas_is_refused() {
    let ctx = common::context();
    let scene = Scene::builtin("cube").unwrap();
    let mut r = Rbvh::build(&scene, &common::sampled_preset(1)).unwrap();
    r.colours = Some(vec![0; 3]);
    let e = Painter::new(&ctx, &r).err().unwrap().to_string();
    assert!(
        e.contains("colour words") && e.contains("atlas texels"),
        "{e}"
    );
    // The CPU reference loses the paint past the channel's end instead of panicking.
    let brush = Brush::new(Vec3::ZERO, 10.0, 0xFF00_00FF);
    r.paint_cpu(&[brush]);
}

#[test]
fn a_height_only_rbvh_has_no_colours_to_paint() {
    let ctx = common::context();
    let scene = Scene::builtin("cube").unwrap();
    let params = RbvhParams {
        texels: rbvh::rbvh::TexelFormat::Height,
        ..common::sampled_preset(1)
    };
    let r = Arc::new(Rbvh::build(&scene, &params).unwrap());
    let tracer = Tracer::new(&ctx, &Structure::from(r.clone())).unwrap();
    for e in [
        Painter::new(&ctx, &r).err().unwrap(),
        Painter::sharing(&tracer, &r).err().unwrap(),
    ] {
        let e = e.to_string();
        assert!(e.contains("height-only") && e.contains("colours"), "{e}");
    }
}

#[test]
fn a_recorded_paint_matches_the_submitted_one() {
    let ctx = common::context();
    let r = cube();
    let brushes = [
        Brush::new(Vec3::new(1.0, 1.0, 0.1), 0.3, RED),
        Brush::new(
            Vec3::new(-1.0, 0.2, 0.5),
            0.2,
            rgba::from_bytes([0, 0, 255, 255]),
        ),
    ];
    let mut submitted = Painter::new(&ctx, &r).unwrap();
    submitted.paint(&brushes).unwrap();
    let expected = submitted.colours().unwrap();

    let mut made = None;
    ctx.submit("recorded paint", |_, cmd| {
        made = Some(
            Painter::record_new(&ctx, &r, cmd).and_then(|(painter, staging)| {
                let recording = painter.record(cmd, &brushes)?;
                Ok((painter, staging, recording))
            }),
        );
    })
    .unwrap();
    let (mut painter, staging, recording) = made.unwrap().unwrap();
    drop((staging, recording));
    assert_eq!(painter.colours().unwrap(), expected);
    let too_many = vec![brushes[0]; MAX_BRUSHES_PER_PASS + 1];
    ctx.submit("too many brushes", |_, cmd| {
        assert!(painter.record(cmd, &too_many).is_err());
    })
    .unwrap();
}

#[test]
fn translucent_brushes_composite_in_order_on_the_device_as_on_the_cpu() {
    let ctx = common::context();
    let mut r = cube();
    let half_blue = rgba::from_bytes([0, 0, 255, 128]);
    let brushes = [
        Brush::new(Vec3::new(1.0, 0.0, 0.0), 0.6, RED),
        Brush::new(Vec3::new(1.0, 0.2, 0.0), 0.3, half_blue),
        Brush::new(Vec3::new(1.0, -0.2, 0.0), 0.3, half_blue),
    ];
    let mut painter = Painter::new(&ctx, &r).unwrap();
    painter.paint(&brushes).unwrap();
    let gpu = painter.colours().unwrap();
    r.paint_cpu(&brushes);
    assert_eq!(Some(&gpu), r.colours.as_ref());
    // Red under one half-blue dab, and under two where they overlap: distinct, in order.
    let once = rgba::over(half_blue, RED);
    let twice = rgba::over(half_blue, once);
    for word in [RED, once, twice] {
        assert!(gpu.contains(&word), "{word:#010x} nowhere");
    }
    assert_ne!(once, twice);
}

#[test]
fn a_painter_sharing_the_tracers_atlas_paints_the_same_and_uploads_only_colours() {
    let ctx = common::context();
    let r = Arc::new(cube());
    let brushes = [
        Brush::new(Vec3::new(1.0, 1.0, 0.1), 0.3, RED),
        Brush::new(Vec3::new(-1.0, 0.2, 0.5), 0.4, 0x80FF_0000),
    ];
    let mut own = Painter::new(&ctx, &r).unwrap();
    own.paint(&brushes).unwrap();
    let expected = own.colours().unwrap();
    // The atlas as the tracer holds it (its narrow band a byte or three a texel).
    let atlas_bytes = r.atlas_bytes();
    let colour_bytes = 4 * r.atlas.texels.len() as u64;
    assert_eq!(own.device_bytes(), atlas_bytes + colour_bytes);

    let tracer = Tracer::new(&ctx, &Structure::from(r.clone())).unwrap();
    let mut shared = Painter::sharing(&tracer, &r).unwrap();
    assert_eq!(shared.device_bytes(), colour_bytes, "no second atlas");
    shared.paint(&brushes).unwrap();
    assert_eq!(shared.colours().unwrap(), expected);

    // Recorded into a command buffer, as an engine would.
    let mut made = None;
    ctx.submit("recorded shared paint", |_, cmd| {
        made = Some(
            Painter::record_sharing(&tracer, &r, cmd).and_then(|(painter, staging)| {
                let recording = painter.record(cmd, &brushes)?;
                Ok((painter, staging, recording))
            }),
        );
    })
    .unwrap();
    let (mut recorded, staging, recording) = made.unwrap().unwrap();
    drop((staging, recording));
    assert_eq!(recorded.colours().unwrap(), expected);

    // The painter keeps the atlas alive after the tracer is gone.
    drop(tracer);
    shared.paint(&brushes[..1]).unwrap();

    // A tracer of another RBVH, or of the exact BVH, is refused.
    let other = Rbvh::build(&Scene::load("cube").unwrap(), &common::sampled_preset(0)).unwrap();
    let e = Painter::sharing(&Tracer::new(&ctx, &Structure::from(other)).unwrap(), &r)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("not this RBVH"), "{e}");
    let exact = Tracer::new(
        &ctx,
        &Structure::from(rbvh::bvh::Bvh::build(&Scene::load("cube").unwrap()).unwrap()),
    )
    .unwrap();
    let e = Painter::sharing(&exact, &r).err().unwrap().to_string();
    assert!(e.contains("no atlas"), "{e}");
    ctx.check_validation().unwrap();
}

/// Tiles of 12- and 10-bit heights (the sphere's, sampled at Q2) are painted on the device as on
/// the CPU: the paint shader reads each texel's field, across two words where it crosses one.
#[test]
fn packed_heights_paint_as_on_the_cpu() {
    let ctx = common::context();
    let r = Rbvh::build(&Scene::load("sphere").unwrap(), &common::sampled_preset(2)).unwrap();
    let brushes = [Brush::new(Vec3::new(0.0, 0.0, 1.0), 0.8, RED)];
    let mut painter = Painter::new(&ctx, &r).unwrap();
    painter.paint(&brushes).unwrap();
    let gpu = painter.colours().unwrap();
    let mut cpu = r.clone();
    assert!(cpu.paint_cpu(&brushes) > 0);
    let differ = gpu
        .iter()
        .zip(cpu.colours.as_ref().unwrap())
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(differ, 0, "GPU and CPU painting differ in {differ} texels");
    let mut painted_by_bits = std::collections::BTreeMap::new();
    for (k, ..) in surface_texels(&r) {
        if gpu[k] == RED {
            *painted_by_bits.entry(r.atlas.bits_at(k)).or_insert(0) += 1;
        }
    }
    assert!(
        painted_by_bits.keys().any(|&bits| bits == 10 || bits == 12),
        "painted texels by bits of height: {painted_by_bits:?}"
    );
}
